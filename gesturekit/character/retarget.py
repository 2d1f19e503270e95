"""Our motion on a user's character: their bone lengths and rest pose, our bone directions, our hands' reach.

:func:`retarget` poses a :class:`~gesturekit.character.target.Character` frame
by frame from a motion of our 55 joints, in our frame (metres, Y up, facing
+Z). Their bones are visited parents first; each bone's world rotation at rest
is ``Q`` (:attr:`Character.rest_rotation`) and ``W(t)`` in the pose:

* **The pelvis** (their hips) stays where it rests, as our motions are
  relative to the pelvis; so do the legs and every bone not below the pelvis.
* **A bone at one of our joints with one matched child bone** takes our joint's
  rotation (:func:`gesturekit.character.rig.solve_pose`) through a fixed
  alignment ``A`` of its rest pose onto ours (the smallest turn of its rest
  direction onto our rest direction: a T-pose, an A-pose and any roll of the
  bone read alike), then the smallest turn that points it exactly along our
  bone: ``W = swing(W0 -> ours) W0`` with ``W0 = R_ours A Q``. So its direction
  is ours, and its twist (a forearm's roll) is ours.
* **A bone with several matched children** (the chest with the neck and the
  collars, a hand with its fingers) takes the rotation that best points all of
  them along ours (weighted Kabsch on unit directions), held to ``R_ours A`` by a
  small weight so that nearly parallel children do not leave its twist free.
* **A bone with no matched child** (a hand without fingers, the head) takes
  ``R_ours A Q``, ``A`` inherited from its nearest matched ancestor.
* **A bone that is none of ours** (a twist or extra spine bone, a leg, a finger
  the motion lacks) keeps its rest rotation relative to its parent.

**The arms** then reach as ours do, scaled to their arm: the wrist's target is
``shoulder + s (ours_wrist - ours_shoulder)`` with ``s`` their arm length (upper
arm plus forearm) over ours. Where their upper arm and forearm have the
proportions of ours, our directions put the wrist there. Where they differ, the
upper arm and forearm are solved for the target with two bones (law of
cosines), the elbow bent towards where ours points (off the line from shoulder
to wrist): the hands do exactly what ours do, and the two bones turn away from
ours by about a degree per percent that their upper-arm-to-forearm ratio differs
from ours. A ``wrist_slack`` lets the wrist stay up to that fraction of the arm's
length from the target, trading reach for direction: within that circle the
wrist goes where the two bones turn least from ours (the larger of their two
angles, :func:`gesturekit.character._arms.wrist_within`), which is where our directions put it when that
is close enough. The default, :data:`WRIST_SLACK` (5 %), was chosen on arms whose
upper-arm-to-forearm ratio is ours -24 % to +20 % (the range of real rigs): at
-20 % to +20 % every arm bone then stays within 2.9 degrees of ours in the median
and 6.8 at the 95th percentile (against 6.5 and 12.6 with no slack), at -24 %
within 4.4 and 9.8 (8.7 and 16.4 with none). At -24 % no wrist within 5 % of
the reach does better: with the same elbow angle a shorter upper arm points
further from the line from shoulder to wrist, and turning the arm back onto our
directions moves the hand sideways by about a tenth of the arm in a right-angled
elbow; no wrist off the arm's plane and no swivel of the elbow about the line to
the wrist does better (the tests search both), and a collar that took part of the
reach would move the target with the shoulder; a median of 4 degrees there needs 5.5 %. ``wrist_slack=0`` is the other
end: the hands exactly at our scaled reach (``bench/bench_arms.py``). A character carries its own slack
(:attr:`~gesturekit.character.target.Character.wrist_slack`: ``read_character(..., wrist_slack=)``, the
command line's ``--wrist-slack``, the app's slider); a call's ``wrist_slack`` overrides it.

**The torso proxy**: a capsule around their spine from the pelvis up, of radius
:data:`TORSO_RADIUS` times their shoulder width, and the same around ours. A
wrist target inside their capsule while our wrist is outside ours is moved out
to its surface (radially, from the nearest point of the spine); the frames are
counted in the report, as are those where our own hand is inside ours (left as
they are: the motion has it so).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..motion import Motion
from ..skeleton import JOINT_NAMES, joint_index
from ._arms import TORSO_RADIUS, Arms, distance_to_chain, unit
from .rig import Rig, rig_for, solve_pose
from .target import WRIST_SLACK, Character, check_wrist_slack

__all__ = ["TORSO_RADIUS", "WRIST_SLACK", "RetargetReport", "Retargeted", "retarget", "swing", "kabsch"]

#: Weight of ``R_ours A``'s axes in the fit of a bone with several children (the children weigh 1 each).
_HOLD = 0.05

#: The child a bone with several children points at exactly (the others are fitted together with it).
_MIDLINE = frozenset(("chest", "upper_chest", "neck", "neck_upper", "head", "left_middle1", "right_middle1"))


@dataclass(frozen=True)
class RetargetReport:
    """How closely the character follows the motion, and what it could not follow.

    Attributes
    ----------
    segments : tuple of str
        The bones, ``"Parent->Child"`` (their names): from each matched bone to the matched child it points at (its
        only one, or the one on the midline or the middle finger).
    direction_error : np.ndarray, shape (len(segments),), float64
        Largest angle over the frames between each segment and ours, degrees.
    side_segments : tuple of str
        From a bone with several matched children to the others (the collars on the chest, the other fingers on the
        hand): their angles to one another are the character's own, so they are fitted together, not each exactly.
    side_error : np.ndarray, shape (len(side_segments),), float64
        Largest angle over the frames between each of those and ours, degrees.
    wrist_error : float
        Largest distance of a wrist from its scaled target over the frames (both sides; frames whose target was
        moved out of the torso left out), as a fraction of that arm's length.
    reach_scale : tuple of float
        Left and right: their arm length over ours.
    torso_radius : float
        Radius of their torso capsule, metres.
    moved_out : tuple of int
        Left and right: frames whose wrist target was moved out of their torso (ours clear of our torso).
    inside : tuple of int
        Left and right: frames whose wrist is still inside their torso while ours is clear (the target was out of
        reach once moved out).
    ours_inside : tuple of int
        Left and right: frames whose wrist is inside our own torso capsule (left as the motion has it).
    missing : tuple of str
        Our joints the motion has but the character lacks a bone for (e.g. its fingers): they are not shown.
    still : tuple of str
        Their bones that keep their rest rotation relative to their parent (not below the pelvis, or none of ours).
    frames : int
    """

    segments: tuple[str, ...]
    direction_error: np.ndarray
    side_segments: tuple[str, ...]
    side_error: np.ndarray
    wrist_error: float
    reach_scale: tuple[float, float]
    torso_radius: float
    moved_out: tuple[int, int]
    inside: tuple[int, int]
    ours_inside: tuple[int, int]
    missing: tuple[str, ...]
    still: tuple[str, ...]
    frames: int

    @property
    def max_direction_error(self) -> float:
        """Largest direction error of any segment, degrees (0 without segments)."""
        return float(self.direction_error.max()) if len(self.direction_error) else 0.0

    @property
    def worst_segment(self) -> str:
        """The segment of :attr:`max_direction_error`."""
        return self.segments[int(np.argmax(self.direction_error))] if self.segments else ""

    def summary(self) -> str:
        """One paragraph for a person: directions, wrists, torso, what is missing."""
        lines = [
            f"{len(self.segments)} bones follow ours within {self.max_direction_error:.2f} degrees"
            + (f" (worst {self.worst_segment})" if self.segments else "")
            + (
                f", the {len(self.side_segments)} they carry beside those within {self.side_error.max():.2f}"
                if len(self.side_segments)
                else ""
            ),
            f"wrists within {100 * self.wrist_error:.2f} % of the arm's length of our reach scaled by "
            f"{self.reach_scale[0]:.3f} (left) and {self.reach_scale[1]:.3f} (right)",
            f"hands kept out of the torso in {sum(self.moved_out)} frames "
            f"(capsule radius {100 * self.torso_radius:.1f} cm); still inside in {sum(self.inside)}; "
            f"inside ours in {sum(self.ours_inside)} of {self.frames}",
        ]
        if self.missing:
            lines.append(
                f"not on the character (no bone): {', '.join(self.missing[:10])}"
                + (" ..." if len(self.missing) > 10 else "")
            )
        return "; ".join(lines)


@dataclass(frozen=True)
class Retargeted:
    """A character posed by a motion: every bone's world rotation and position per frame, in our frame.

    Attributes
    ----------
    character : Character
    fps : float
        Frames per second.
    rotation : np.ndarray, shape (frames, M, 3, 3), float64
        Each bone's rotation in the world (at rest: :attr:`Character.rest_rotation`).
    position : np.ndarray, shape (frames, M, 3), float64
        Each bone's position, metres.
    scale : float
        Their size over ours: the mean of :attr:`RetargetReport.reach_scale`.
    report : RetargetReport
    source : Motion
        The motion the character follows.
    alignment : np.ndarray, shape (M, 3, 3), float64
        Each bone's fixed turn ``A`` of its rest pose onto ours.
    """

    character: Character
    fps: float
    rotation: np.ndarray
    position: np.ndarray
    scale: float
    report: RetargetReport
    source: Motion
    alignment: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.rotation.shape[0])

    def turns(self) -> np.ndarray:
        """Each bone's rotation from its rest orientation, in the world: ``W Q^T``, shape (frames, M, 3, 3)."""
        return np.einsum("tmab,mcb->tmac", self.rotation, self.character.rest_rotation)

    def skinning(self) -> np.ndarray:
        """Skinning matrices of the character's rest-pose mesh, shape (frames, M, 3, 4): ``[N | P - N p]`` with
        ``N`` :meth:`turns` and ``p`` the rest positions; a rest point ``v`` of bone ``m`` goes to
        ``M[..., :3] @ v + M[..., 3]``."""
        n = self.turns()
        out = np.empty(n.shape[:2] + (3, 4))
        out[..., :3] = n
        out[..., 3] = self.position - np.einsum("tmab,mb->tma", n, self.character.rest_position)
        return out

    def local_turns(self) -> np.ndarray:
        """Each bone's :meth:`turns` relative to its parent's (a root's: the world), shape (frames, M, 3, 3): the
        rotations of a skeleton whose rest pose has no rotation (a BVH's, the page's)."""
        n = self.turns()
        out = n.copy()
        parents = self.character.parents
        has = parents >= 0
        out[:, has] = np.einsum("tmba,tmbc->tmac", n[:, parents[has]], n[:, has])
        return out

    def our_motion(self) -> Motion:
        """The character's pose on our skeleton, for measuring the controls on it: our bones turned as the
        character's, at the motion's own lengths.

        A bone of ours whose two joints the character has points along the character's bone between them; where
        that bone is one a joint carries beside the one it points at (a collar on the chest, a finger on the hand),
        whose angle to the others is the character's own shape, it is our shape turned by the character's joint. A
        wrist is where the character's reach puts it from its shoulder, divided by :attr:`RetargetReport.reach_scale`.
        So it says where the character's hands are relative to its body in our units: "left hand high" holds on it
        exactly when it holds here. Joints it lacks, and bones it lacks an end of, keep the motion's directions.
        """
        from ..skeleton import PARENTS

        ch = self.character
        x = self.source.positions.astype(np.float64)
        rest = rig_for(self.source).rest
        joint_at = np.full(ch.n_bones, -1, dtype=np.int64)
        joint_at[ch.bone_of[ch.bone_of >= 0]] = np.flatnonzero(ch.bone_of >= 0)
        kids = _kids(ch, joint_at >= 0)
        turns = self.turns()
        out = x.copy()
        for j in range(len(JOINT_NAMES)):
            pa = int(PARENTS[j])
            if pa < 0:
                continue
            length = np.linalg.norm(x[:, j] - x[:, pa], axis=1, keepdims=True)
            ours, _ = unit(x[:, j] - x[:, pa])
            b, bp = int(ch.bone_of[j]), int(ch.bone_of[pa])
            d = ours
            if b >= 0 and bp >= 0 and b in kids[bp] and b != _primary(kids[bp], joint_at):
                shape, _ = unit(self.alignment[bp].T @ (rest[j] - rest[pa]))
                d = turns[:, bp] @ shape
            elif b >= 0 and bp >= 0:
                d, ok = unit(self.position[:, b] - self.position[:, bp])
                d = np.where(ok[:, None], d, ours)
            out[:, j] = out[:, pa] + length * d
            side = JOINT_NAMES[j].removesuffix("_wrist")
            if side in ("left", "right") and b >= 0 and ch.bone(f"{side}_shoulder") >= 0:
                # the hand where the character's reach puts it, at our arm's length
                s = ch.bone(f"{side}_shoulder")
                scale = self.report.reach_scale[0 if side == "left" else 1]
                out[:, j] = (
                    out[:, joint_index(f"{side}_shoulder")] + (self.position[:, b] - self.position[:, s]) / scale
                )
        return Motion(out.astype(np.float32), self.fps, self.source.presence)


@checks_arguments
def swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotations taking unit vectors ``a`` onto unit vectors ``b``.

    Parameters
    ----------
    a, b : np.ndarray, shape (..., 3)
        Unit vectors.

    Returns
    -------
    np.ndarray, shape (..., 3, 3)
        ``R @ a = b``; for opposite vectors, a half turn about an axis perpendicular to ``a``.
    """
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    v = np.cross(a, b)
    c = np.einsum("...i,...i->...", a, b)
    s = np.linalg.norm(v, axis=-1)
    # the axis a x b, made exactly perpendicular to a: near opposite vectors a x b is short and
    # its direction rounded, and only an axis perpendicular to a keeps R @ a on b (to rounding);
    # where it vanishes, any axis perpendicular to a (a half turn for opposite vectors)
    other = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    axis = np.where((s > 1e-12)[..., None], v / np.maximum(s, 1e-300)[..., None], np.cross(a, other))
    axis = axis - np.einsum("...i,...i->...", axis, a)[..., None] * a
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    k = np.zeros(a.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = axis[..., 2], -axis[..., 1], axis[..., 0]
    # Rodrigues with sin = |a x b| and cos = a . b, both well-conditioned at every angle
    return np.eye(3) + s[..., None, None] * k + (1.0 - c)[..., None, None] * (k @ k)


@checks_arguments
def kabsch(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The rotations that best turn vectors ``u`` onto ``v`` (least squares, weights ``w``).

    Parameters
    ----------
    u, v : np.ndarray, shape (..., k, 3)
    w : np.ndarray, shape (..., k) or (k,)

    Returns
    -------
    np.ndarray, shape (..., 3, 3)
        ``R`` minimising ``sum w |R u - v|^2``, a proper rotation.
    """
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    h = np.einsum("...k,...ki,...kj->...ij", np.broadcast_to(w, u.shape[:-1]), v, u)
    s_u, _, s_vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(s_u @ s_vt))
    d = np.where(d == 0, 1.0, d)
    fix = np.ones(h.shape[:-1])
    fix[..., -1] = d
    return (s_u * fix[..., None, :]) @ s_vt


def _kids(ch: Character, mapped: np.ndarray) -> list[list[int]]:
    """For each bone, its nearest matched descendants (not through another matched bone)."""
    children: list[list[int]] = [[] for _ in range(ch.n_bones)]
    for b, p in enumerate(ch.parents):
        if p >= 0:
            children[p].append(b)
    out: list[list[int]] = []
    for b in range(ch.n_bones):
        found: list[int] = []
        stack = list(reversed(children[b]))
        while stack:
            c = stack.pop()
            if mapped[c]:
                found.append(c)
            else:
                stack.extend(reversed(children[c]))
        out.append(found)
    return out


def _below(ch: Character, top: int) -> np.ndarray:
    """Shape (M,), bool: the bones at or below ``top``."""
    out = np.zeros(ch.n_bones, dtype=bool)
    for b in range(ch.n_bones):  # parents before children
        out[b] = b == top or (ch.parents[b] >= 0 and out[ch.parents[b]])
    return out


@checks_arguments
def retarget(motion: Motion, character: Character, *, wrist_slack: float | None = None) -> Retargeted:
    """Pose ``character`` by ``motion``, frame by frame (see the module's text).

    Parameters
    ----------
    motion : Motion
        Joint positions (frames, 55, 3), metres, relative to the pelvis.
    character : Character
        From :func:`gesturekit.character.user.read_character`.
    wrist_slack : float, optional
        How far a wrist may stay from our reach scaled to their arm, as a fraction of the arm's length, in
        [0, 0.2]: 0 puts the hands exactly where ours reach; more keeps more of our arm directions. Default:
        the character's own (:attr:`Character.wrist_slack`, :data:`WRIST_SLACK` unless it was read with
        another).

    Returns
    -------
    Retargeted

    Raises
    ------
    ConfigError
        A motion without frames or with positions that are not finite, or a slack out of range.
    """
    if not isinstance(motion, Motion):
        raise ConfigError(f"retarget poses a character by a Motion, not {type(motion).__name__}")
    if not isinstance(character, Character):
        raise ConfigError(f"retarget poses a Character (read_character), not {type(character).__name__}")
    slack = character.wrist_slack if wrist_slack is None else check_wrist_slack(wrist_slack)
    _check_finite(character, character.rest_rotation[None], character.rest_position[None], what="rest pose")
    rig = rig_for(motion)
    pose = solve_pose(motion, rig)
    r_ours, _ = pose.world(rig)
    x = motion.positions.astype(np.float64)
    ch = character
    n, m = x.shape[0], ch.n_bones
    q, p = ch.rest_rotation, ch.rest_position
    usable = rig.in_rig & (ch.bone_of >= 0)
    joint_at = np.full(m, -1, dtype=np.int64)
    joint_at[ch.bone_of[usable]] = np.flatnonzero(usable)
    mapped = joint_at >= 0
    kids = _kids(ch, mapped)
    body = _below(ch, ch.pelvis)
    align = _alignment(ch, rig.rest, joint_at, kids)
    aimed = [[sd for sd in (_through(ch, kids, joint_at, b, c) for c in kids[b]) if sd[1] >= 0] for b in range(m)]

    rot = np.empty((n, m, 3, 3))
    pos = np.empty((n, m, 3))
    wants: dict[int, np.ndarray] = {}
    arms = Arms(ch, rig, x, joint_at, slack)
    for b in range(m):
        pa = int(ch.parents[b])
        if not body[b] or b == ch.pelvis or pa < 0:
            rot[:, b], pos[:, b] = q[b], p[b]
            continue
        carry = rot[:, pa] @ q[pa].T
        pos[:, b] = pos[:, pa] + carry @ (p[b] - p[pa])
        j = int(joint_at[b])
        if j < 0:
            rot[:, b] = carry @ q[b]
            continue
        if b in arms.shoulders:
            wants.update(arms.reach(b, pos))
        held = r_ours[:, j] @ align[b]
        if len(aimed[b]) >= 2:
            w0 = _fit(held, p, b, aimed[b], joint_at, x) @ q[b]
        else:
            w0 = held @ q[b]
        s, c = _through(ch, kids, joint_at, b, _primary(kids[b], joint_at)) if kids[b] else (-1, -1)
        if c >= 0:
            cur, _ = unit(w0 @ (q[b].T @ (p[c] - p[b])))
            want, ok = unit(x[:, joint_at[c]] - x[:, joint_at[s]])
            if b in wants:
                want, ok = unit(wants[b])
            want = np.where(ok[:, None], want, cur)
            w0 = swing(cur, want) @ w0
        rot[:, b] = w0
    _check_finite(ch, rot, pos)
    report = _report(ch, rig, x, joint_at, kids, rot, pos, arms, body)
    scale = float(np.mean(arms.scale))
    return Retargeted(
        character=ch,
        fps=float(motion.fps),
        rotation=rot,
        position=pos,
        scale=scale,
        report=report,
        source=motion,
        alignment=align,
    )


#: Shortest bone a direction is taken from, metres: a child closer than this to its bone (a zero offset, as the
#: ``Neck`` of the CMU BVH conversions has) is aimed through, at the next matched bone down its chain with length.
_MIN_LENGTH = 1e-6


def _through(ch: Character, kids: list[list[int]], joint_at: np.ndarray, b: int, c: int) -> tuple[int, int]:
    """The bones whose joints give the direction from ``b`` to its matched child ``c``: ``(b, c)`` itself, or, where
    ``c`` rests on ``b`` (a zero-length bone), ``(s, d)``: ``d`` the first matched bone down ``c``'s chain (its only
    or midline child) away from ``b``, ``s`` the last one before it that still rests on ``b``. Their ``b -> d`` is
    then ``s -> d``, so it follows our ``s -> d``. ``(-1, -1)`` where nothing below has length."""
    p = ch.rest_position
    s = b
    while np.linalg.norm(p[c] - p[b]) <= _MIN_LENGTH:
        s, c = c, _primary(kids[c], joint_at)
        if c < 0:
            return -1, -1
    return s, c


def _primary(kids: list[int], joint_at: np.ndarray) -> int:
    """The child a bone points at exactly: its only one, or of several the one on the body's midline (the neck of
    the chest) or the middle finger (of a hand); ``-1`` for none."""
    if len(kids) == 1:
        return kids[0]
    for c in kids:
        if JOINT_NAMES[joint_at[c]] in _MIDLINE:
            return c
    return -1


def _alignment(ch: Character, ours_rest: np.ndarray, joint_at: np.ndarray, kids: list[list[int]]) -> np.ndarray:
    """``A`` per bone: the fixed turn of their rest pose onto ours (the identity for bones none of ours)."""
    p = ch.rest_position
    out = np.tile(np.eye(3), (ch.n_bones, 1, 1))
    for b in range(ch.n_bones):
        j = int(joint_at[b])
        if j < 0:
            pa = int(ch.parents[b])
            out[b] = out[pa] if pa >= 0 else np.eye(3)
            continue
        aimed = [sd for sd in (_through(ch, kids, joint_at, b, c) for c in kids[b]) if sd[1] >= 0]
        theirs, ok_t = unit(np.array([p[c] - p[b] for _, c in aimed]).reshape(-1, 3))
        ours, ok_o = unit(np.array([ours_rest[joint_at[c]] - ours_rest[joint_at[s]] for s, c in aimed]).reshape(-1, 3))
        ok = ok_t & ok_o
        if ok.sum() >= 2:
            out[b] = kabsch(theirs[ok], ours[ok], np.ones(int(ok.sum())))
        elif ok.sum() == 1:
            out[b] = swing(theirs[ok][0], ours[ok][0])
        else:
            pa = int(ch.parents[b])
            out[b] = out[pa] if pa >= 0 else np.eye(3)
    return out


def _fit(
    held: np.ndarray, p: np.ndarray, b: int, kids: list[tuple[int, int]], joint_at: np.ndarray, x: np.ndarray
) -> np.ndarray:
    """The turn (frames, 3, 3) that best points the children of ``b`` along ours, held to ``held`` a little.
    ``kids``: ``(s, c)`` of :func:`_through` for each child, ``s`` at ``b``'s place."""
    u, _ = unit(np.array([p[c] - p[b] for _, c in kids]).reshape(-1, 3))
    v, ok = unit(np.stack([x[:, joint_at[c]] - x[:, joint_at[s]] for s, c in kids], axis=1))
    n = x.shape[0]
    axes = np.tile(np.eye(3), (n, 1, 1))
    uu = np.concatenate([np.broadcast_to(u, (n,) + u.shape), axes], axis=1)
    vv = np.concatenate([v, np.swapaxes(held, 1, 2)], axis=1)  # held's columns: where it sends each axis
    w = np.concatenate([ok.astype(float), np.full((n, 3), _HOLD)], axis=1)
    return kabsch(uu, vv, w)


def _check_finite(ch: Character, rot: np.ndarray, pos: np.ndarray, *, what: str = "pose") -> None:
    """Refuse a pose (frames, M, 3, 3) and (frames, M, 3) that is not finite, naming the first bone and frame where
    it is not: a result that is not finite is never reported as a match."""
    bad = ~(np.isfinite(rot).all(axis=(2, 3)) & np.isfinite(pos).all(axis=2))
    if bad.any():
        t, b = (int(i[0]) for i in np.nonzero(bad))
        where = "" if what != "pose" else f" (frame {t}); the character's rest pose cannot carry this motion"
        raise ConfigError(f"{ch.path}: the {what} of bone {ch.names[b]!r} is not finite{where}")


def _report(
    ch: Character,
    rig: Rig,
    x: np.ndarray,
    joint_at: np.ndarray,
    kids: list[list[int]],
    rot: np.ndarray,
    pos: np.ndarray,
    arms: Arms,
    body: np.ndarray,
) -> RetargetReport:
    del rot
    found: dict[bool, tuple[list[str], list[float]]] = {True: ([], []), False: ([], [])}
    for b in range(ch.n_bones):
        if joint_at[b] < 0 or b == ch.pelvis:
            continue
        primary = _primary(kids[b], joint_at)
        for k in kids[b]:
            s, c = _through(ch, kids, joint_at, b, k)
            if c < 0 or s != b:
                continue  # of no length: its direction is that of the bone below, reported there
            theirs, ok_t = unit(pos[:, c] - pos[:, b])
            ours, ok_o = unit(x[:, joint_at[c]] - x[:, joint_at[b]])
            cos = np.clip(np.einsum("ti,ti->t", theirs, ours), -1.0, 1.0)
            ok = ok_t & ok_o
            names, errors = found[k == primary]
            names.append(f"{ch.names[b]}->{ch.names[c]}")
            errors.append(float(np.degrees(np.arccos(cos[ok])).max()) if ok.any() else 0.0)
    wrist, moved_out, inside, ours_inside = 0.0, [0, 0], [0, 0], [0, 0]
    for s, (side, e, w, i) in arms.sides.items():
        length = float(np.linalg.norm(ch.rest_position[e] - ch.rest_position[s]))
        length += float(np.linalg.norm(ch.rest_position[w] - ch.rest_position[e]))
        keep = ~arms.moved[side]
        if keep.any():
            miss = np.linalg.norm(pos[keep, w] - arms.targets[side][keep], axis=1).max()
            wrist = max(wrist, float(miss) / length)
        d, _ = distance_to_chain(pos[:, w], arms.torso(pos))
        moved_out[i] = int(arms.moved[side].sum())
        inside[i] = int(((d < arms.radius) & ~arms.ours_in[side]).sum())
        ours_inside[i] = int(arms.ours_in[side].sum())
    missing = tuple(JOINT_NAMES[j] for j in np.flatnonzero(rig.in_rig & (ch.bone_of < 0)))
    still = tuple(ch.names[b] for b in range(ch.n_bones) if joint_at[b] < 0 or not body[b])
    return RetargetReport(
        segments=tuple(found[True][0]),
        direction_error=np.asarray(found[True][1], dtype=np.float64),
        side_segments=tuple(found[False][0]),
        side_error=np.asarray(found[False][1], dtype=np.float64),
        wrist_error=wrist,
        reach_scale=(float(arms.scale[0]), float(arms.scale[1])),
        torso_radius=arms.radius,
        moved_out=(moved_out[0], moved_out[1]),
        inside=(inside[0], inside[1]),
        ours_inside=(ours_inside[0], ours_inside[1]),
        missing=missing,
        still=still,
        frames=int(x.shape[0]),
    )
