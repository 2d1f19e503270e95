"""The arms' reach on a user's character: the wrist's target from ours, the slack around it, the torso proxy and
the two-bone solve (what :func:`gesturekit.character.retarget.retarget` does for each arm; see its module's text)."""

from __future__ import annotations

import numpy as np

from ..skeleton import joint_index
from .rig import Rig
from .target import Character

__all__ = ["TORSO_RADIUS", "Arms", "unit", "distance_to_chain", "wrist_within"]

#: Radius of the torso capsule as a fraction of the shoulder width (the distance between the upper-arm joints).
TORSO_RADIUS = 0.3

_SPINE = ("spine_mid", "chest", "upper_chest")


def unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors of ``v`` (..., 3) and where they are defined (length above 1e-9)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = n[..., 0] > 1e-9
    return np.divide(v, n, out=np.zeros_like(v), where=n > 1e-9), ok


def distance_to_chain(x: np.ndarray, chain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance of points ``x`` (T, 3) to polylines ``chain`` (T, n, 3), and the nearest points (T, 3)."""
    best = np.full(len(x), np.inf)
    near = np.zeros_like(x)
    for i in range(chain.shape[1] - 1):
        a, b = chain[:, i], chain[:, i + 1]
        ab = b - a
        t = np.clip(np.einsum("ti,ti->t", x - a, ab) / np.maximum(np.einsum("ti,ti->t", ab, ab), 1e-18), 0, 1)
        q = a + t[:, None] * ab
        d = np.linalg.norm(x - q, axis=1)
        closer = d < best
        best[closer], near[closer] = d[closer], q[closer]
    return best, near


class Arms:
    """Each arm's reach: the scaled wrist target, kept out of the torso, and the two-bone solve for it."""

    def __init__(self, ch: Character, rig: Rig, x: np.ndarray, joint_at: np.ndarray, slack: float):
        self.slack = slack
        self.ch, self.x = ch, x
        p = ch.rest_position
        self.sides: dict[int, tuple[str, int, int, int]] = {}
        self.scale = [1.0, 1.0]
        self.targets: dict[str, np.ndarray] = {}
        self.moved: dict[str, np.ndarray] = {}
        self.ours_in: dict[str, np.ndarray] = {}
        ls, rs = ch.bone("left_shoulder"), ch.bone("right_shoulder")
        self.radius = TORSO_RADIUS * float(np.linalg.norm(p[ls] - p[rs]))
        ours_width = float(
            np.linalg.norm(rig.rest[joint_index("left_shoulder")] - rig.rest[joint_index("right_shoulder")])
        )
        self.ours_radius = TORSO_RADIUS * ours_width
        self.spine = [k for k in _SPINE if rig.in_rig[joint_index(k)] and ch.bone(k) >= 0]
        for i, side in enumerate(("left", "right")):
            s, e, w = (ch.bone(f"{side}_{k}") for k in ("shoulder", "elbow", "wrist"))
            js, je, jw = (joint_index(f"{side}_{k}") for k in ("shoulder", "elbow", "wrist"))
            if min(joint_at[s], joint_at[e], joint_at[w]) < 0:
                continue
            theirs = float(np.linalg.norm(p[e] - p[s]) + np.linalg.norm(p[w] - p[e]))
            ours = float(rig.lengths[je] + rig.lengths[jw])
            self.scale[i] = theirs / ours if ours > 1e-9 else 1.0
            self.sides[s] = (side, e, w, i)
            del js
        self.shoulders = set(self.sides)

    def torso(self, pos: np.ndarray) -> np.ndarray:
        """Their spine (frames, n, 3): the pelvis, then each matched spine bone."""
        ch = self.ch
        return np.stack([pos[:, ch.pelvis]] + [pos[:, ch.bone(k)] for k in self.spine], axis=1)

    def our_torso(self) -> np.ndarray:
        x = self.x
        return np.stack([np.zeros((len(x), 3))] + [x[:, joint_index(k)] for k in self.spine], axis=1)

    def reach(self, s: int, pos: np.ndarray) -> dict[int, np.ndarray]:
        """The wanted directions of the upper arm (bone ``s``) and the forearm, frames x 3 each."""
        side, e, w, i = self.sides[s]
        ch, x = self.ch, self.x
        p = ch.rest_position
        xs, xe, xw = (x[:, joint_index(f"{side}_{k}")] for k in ("shoulder", "elbow", "wrist"))
        shoulder = pos[:, s]
        a = float(np.linalg.norm(p[e] - p[s]))
        c = float(np.linalg.norm(p[w] - p[e]))
        target = shoulder + self.scale[i] * (xw - xs)
        self.targets[side] = target.copy()
        # where our directions alone put their wrist; the hand goes there unless that is further than the slack
        # from the scaled reach, so that the arm's bones turn away from ours only as much as the reach needs
        target = shoulder + wrist_within(target - shoulder, xe - xs, xw - xe, a, c, self.slack * (a + c))
        d_ours, _ = distance_to_chain(xw, self.our_torso())
        ours_in = d_ours < self.ours_radius
        d, near = distance_to_chain(target, self.torso(pos))
        moved = (d < self.radius) & ~ours_in
        if moved.any():
            out, ok = unit(target[moved] - near[moved])
            out[~ok] = [0.0, 0.0, 1.0]  # on the spine itself: forward
            target[moved] = near[moved] + out * (self.radius * 1.001)
        self.moved[side], self.ours_in[side] = moved, ours_in
        axis = target - shoulder
        dist = np.clip(np.linalg.norm(axis, axis=1), abs(a - c) + 1e-9, (a + c) * (1 - 1e-12))
        u, ok = unit(axis)
        u[~ok] = [0.0, -1.0, 0.0]
        target = shoulder + u * dist[:, None]
        bend = (xe - xs) - np.einsum("ti,ti->t", xe - xs, u)[:, None] * u
        bend, ok = unit(bend)
        if not ok.all():  # a straight arm: bend towards where our elbow is, else down
            alt = np.array([0.0, -1.0, 0.0]) - u[~ok, 1:2] * u[~ok]
            bend[~ok] = unit(alt)[0]
        along = (a * a - c * c + dist * dist) / (2 * dist)
        up = np.sqrt(np.clip(a * a - along * along, 0.0, None))
        elbow = shoulder + along[:, None] * u + up[:, None] * bend
        return {s: elbow - shoulder, e: target - elbow}


#: Points on the circle of the slack around the scaled reach at which the wrist is tried, and the finer turn tried
#: around the best of them (a wrist at most ``slack * 2 pi / _AROUND`` from the best point of the circle).
_AROUND = 72


def wrist_within(
    target: np.ndarray, upper: np.ndarray, fore: np.ndarray, a: float, c: float, radius: float
) -> np.ndarray:
    """Where the wrist goes, relative to the shoulder (frames, 3): the point within ``radius`` of ``target`` at which
    the two-bone solve turns the upper arm and the forearm least from ours (the larger of their two angles).

    Our directions put the wrist at ``a u + c f`` (``u``, ``f`` our upper arm's and forearm's directions), where the
    angles are 0: it is taken when within the radius. Else the best point is on the circle around the target: on
    the line to that point the elbow's angle is nearest ours, and off it the whole arm turns about the shoulder so
    that the two bones share the turn (their errors have opposite signs along the line). The target, ours and the
    solve's elbow are all in the plane of ``u`` and ``f``, so this is a search on a circle in that plane.

    Parameters
    ----------
    target : np.ndarray, shape (frames, 3)
        Our reach scaled to their arm, from their shoulder.
    upper, fore : np.ndarray, shape (frames, 3)
        Our upper arm (shoulder to elbow) and forearm (elbow to wrist).
    a, c : float
        Their upper arm's and forearm's lengths, metres.
    radius : float
        How far the wrist may be from ``target``, metres.
    """
    u, ok_u = unit(upper)
    f, ok_f = unit(fore)
    straight = a * u + c * f
    if radius <= 0.0:
        return target
    inside = np.linalg.norm(straight - target, axis=1) <= radius
    # the plane's axes: e1 along our upper arm, e2 towards our forearm's side of it (down for a straight arm)
    e2, ok2 = unit(f - np.einsum("ti,ti->t", f, u)[:, None] * u)
    down = np.array([0.0, -1.0, 0.0]) - u[:, 1:2] * u
    e2 = np.where(ok2[:, None], e2, unit(down)[0])
    e1 = u
    t2 = np.stack([np.einsum("ti,ti->t", target, e1), np.einsum("ti,ti->t", target, e2)], axis=1)
    u2 = np.stack([np.ones(len(u)), np.zeros(len(u))], axis=1)
    f2 = np.stack([np.einsum("ti,ti->t", f, e1), np.einsum("ti,ti->t", f, e2)], axis=1)
    # the circle in _AROUND steps, then finer around the best of them
    coarse = np.broadcast_to(np.arange(_AROUND) * (2 * np.pi / _AROUND), (len(u), _AROUND))
    best_phi = _best_turn(coarse, t2, u2, f2, a, c, radius)
    fine = best_phi[:, None] + np.linspace(-1.0, 1.0, 17)[None, :] * (2 * np.pi / _AROUND)
    best_phi = _best_turn(fine, t2, u2, f2, a, c, radius)
    w2 = t2 + radius * np.stack([np.cos(best_phi), np.sin(best_phi)], axis=1)
    out = w2[:, :1] * e1 + w2[:, 1:] * e2
    use = inside | ~(ok_u & ok_f)
    out[use] = np.where(inside[use, None], straight[use], target[use])
    return out


def _best_turn(
    phi: np.ndarray, t2: np.ndarray, u2: np.ndarray, f2: np.ndarray, a: float, c: float, radius: float
) -> np.ndarray:
    """Of the points ``t2 + radius (cos phi, sin phi)`` (phi: frames x K), the angle of the one with the least
    :func:`two_bone_error`, per frame."""
    w = t2[:, None, :] + radius * np.stack([np.cos(phi), np.sin(phi)], axis=2)
    err = two_bone_error(w, u2, f2, a, c)
    return np.take_along_axis(phi, np.argmin(err, axis=1)[:, None], axis=1)[:, 0]


def two_bone_error(w: np.ndarray, u: np.ndarray, f: np.ndarray, a: float, c: float) -> np.ndarray:
    """The larger angle (radians) of the upper arm and the forearm to ``u`` and ``f`` when a two-bone arm of lengths
    ``a``, ``c`` reaches for ``w`` (frames, K, 2) in the plane, its elbow on ``u``'s side; ``u``, ``f`` (frames, 2)."""
    d = np.linalg.norm(w, axis=2)
    dist = np.clip(d, abs(a - c) + 1e-9, (a + c) * (1 - 1e-12))
    axis = w / np.maximum(d, 1e-12)[..., None]
    normal = np.stack([-axis[..., 1], axis[..., 0]], axis=2)
    side = np.sign(np.einsum("tki,ti->tk", normal, u))
    normal = normal * np.where(side == 0, 1.0, side)[..., None]
    along = (a * a - c * c + dist * dist) / (2 * dist)
    up = np.sqrt(np.clip(a * a - along * along, 0.0, None))
    elbow = along[..., None] * axis + up[..., None] * normal
    wrist = dist[..., None] * axis
    cos_u = np.einsum("tki,ti->tk", elbow, u) / a
    fore = wrist - elbow
    cos_f = np.einsum("tki,ti->tk", fore, f) / np.maximum(np.linalg.norm(fore, axis=2), 1e-12)
    return np.maximum(np.arccos(np.clip(cos_u, -1, 1)), np.arccos(np.clip(cos_f, -1, 1)))
