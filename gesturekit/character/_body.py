"""The pieces of the default body, each a closed surface around the rig's rest pose (the T-pose).

Sizes follow the rig: the torso and arms scale with the shoulder width ``W``, the head with its
bone (head to head top), the palm and fingers with the hand's width (index to little-finger
root). Each piece needs its joints in the rig and is left out otherwise (no hands for a layout
without hands, no torso for a rig rooted at the neck).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import PchipInterpolator

from ..skeleton import FINGERS, N_JOINTS, PARENTS, joint_index
from ._loft import Chain, Piece, cap_stations, ellipsoid, loft, s_grid, smoothstep
from .rig import Rig

__all__ = ["SKIN", "SHIRT", "FACE", "body_pieces"]

SKIN, SHIRT, FACE = 0, 1, 2
_SPINE, _CHEST, _UPPER, _NECK = (joint_index(n) for n in ("spine_mid", "chest", "upper_chest", "neck"))
_NECK_UP, _HEAD, _HEAD_TOP = (joint_index(n) for n in ("neck_upper", "head", "head_top"))
_X, _Y, _Z = np.eye(3)

# torso: height along the spine (0 spine_mid, 1 neck) -> half-width, half-depth (shoulder widths)
_TORSO = np.array(
    [
        (-0.20, 0.36, 0.24),
        (0.00, 0.37, 0.255),
        (0.30, 0.39, 0.27),
        (0.55, 0.43, 0.28),
        (0.74, 0.46, 0.27),
        (0.86, 0.47, 0.245),
        (0.94, 0.46, 0.215),
        (1.00, 0.40, 0.17),
    ]
)
#: finger radius at its root, in hand widths (thumb, index, middle, ring, little finger)
_FINGER_RADIUS = dict(zip(FINGERS, (0.19, 0.15, 0.155, 0.145, 0.125), strict=True))


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else fallback


class _Frame:
    """What every piece reads of the rig: which joints exist, the rest pose, the body's sizes."""

    def __init__(self, rig: Rig, detail: float) -> None:
        self.rig = rig
        self.rest = np.asarray(rig.rest, dtype=np.float64)
        self.have = np.asarray(rig.parents) >= -1
        self.detail = detail
        ls, rs = joint_index("left_shoulder"), joint_index("right_shoulder")
        if self.have[ls] and self.have[rs]:
            self.width = float(np.linalg.norm(self.rest[ls] - self.rest[rs]))
            self.lateral = _unit(self.rest[ls] - self.rest[rs], _X)
        else:  # no pair of shoulders: a width from the torso, or an adult's
            torso = self._dist(_SPINE, _NECK)
            self.width = 0.95 * torso if torso > 0 else 0.36
            self.lateral = _X
        self.up = _unit(self._vec(_SPINE, _NECK), _Y) if self._dist(_SPINE, _NECK) > 0 else _Y
        self.front = _unit(np.cross(self.lateral, self.up), _Z)

    def _vec(self, a: int, b: int) -> np.ndarray:
        return self.rest[b] - self.rest[a]

    def _dist(self, a: int, b: int) -> float:
        return float(np.linalg.norm(self._vec(a, b))) if self.have[a] and self.have[b] else 0.0

    def n(self, count: float, least: int = 3) -> int:
        return max(least, int(round(count * self.detail)))


def _tube(
    f: _Frame,
    chain: Chain,
    knots: np.ndarray,
    ref: np.ndarray,
    n_around: int,
    step: float,
    caps: tuple[float, float],
    part_of: int | Callable[[np.ndarray], np.ndarray],
    power: np.ndarray | None = None,
    blend_rings: bool = True,
) -> Piece:
    """A closed tube along ``chain``: ``knots`` rows (s, a, b) give the half-axes along it (metres);
    rounded caps of the given lengths close it before the first knot and after the last; with
    ``blend_rings``, rings also sit across each joint's blend (where the tube bends)."""
    s0, s1 = float(knots[0, 0]), float(knots[-1, 0])
    inner, h = chain.stations[1:-1], chain.blend
    extra = np.concatenate([inner - h, inner - 0.5 * h, inner, inner + 0.5 * h, inner + h]) if blend_rings else inner
    body = s_grid([*knots[:, 0], *extra[(extra > s0) & (extra < s1)]], step)
    # a monotone cubic through the knots: smooth outlines without overshoot
    a, b = (PchipInterpolator(knots[:, 0], knots[:, k])(body) for k in (1, 2))
    n_cap = f.n(4, 2)
    off0, rad0 = cap_stations(n_cap, start=True)
    off1, rad1 = cap_stations(n_cap, start=False)
    s = np.concatenate([s0 + caps[0] * off0, body, s1 + caps[1] * off1])
    a = np.concatenate([a[0] * rad0, a, a[-1] * rad1])
    b = np.concatenate([b[0] * rad0, b, b[-1] * rad1])
    pw = np.full(len(s), 2.0) if power is None else np.interp(s, power[:, 0], power[:, 1])
    centers, tangents = chain.frame(s)
    ends = np.array([s0 - caps[0], s1 + caps[1]])
    poles, _ = chain.frame(ends)
    verts, faces = loft(centers, tangents, ref, a, b, n_around, poles[0], poles[1], power=pw)
    s_vert = np.concatenate([np.repeat(s, n_around), ends])
    part = part_of(s_vert) if callable(part_of) else np.full(len(s_vert), part_of)
    return Piece(verts, faces, chain.weights(s_vert, N_JOINTS), np.asarray(part, dtype=np.int64))


def _rigid(verts: np.ndarray, faces: np.ndarray, joint: int, part: int) -> Piece:
    w = np.zeros((len(verts), N_JOINTS))
    w[:, joint] = 1.0
    return Piece(verts, faces, w, np.full(len(verts), part, dtype=np.int64))


def _torso(f: _Frame) -> list[Piece]:
    if not (f.have[_SPINE] and f.have[_NECK]):
        return []
    joints = [j for j in (_SPINE, _CHEST, _UPPER, _NECK) if f.have[j]]
    lengths = [f._dist(a, b) for a, b in zip(joints[:-1], joints[1:], strict=True)]
    if min(lengths) <= 0:
        return []
    chain = Chain(f.rest[joints], joints[:-1], [0.35 * min(a, b) for a, b in zip(lengths[:-1], lengths[1:])])
    height, w = chain.length, f.width
    knots = np.column_stack([_TORSO[:, 0] * height, _TORSO[:, 1] * w, _TORSO[:, 2] * w])
    step, caps = height / f.n(16, 4), (0.05 * height, 0.06 * height)
    piece = _tube(f, chain, knots, f.lateral, f.n(30, 8), step, caps, SHIRT, blend_rings=False)
    # the shoulders' tops follow the collars (a shrug), the rest the spine
    rel = piece.vertices - f.rest[_SPINE]
    side = rel @ f.lateral
    t = (rel @ f.up) / height
    c = smoothstep((np.abs(side) - 0.2 * w) / (0.2 * w)) * smoothstep((t - 0.55) / 0.25)
    for side_name, sign in (("left", 1.0), ("right", -1.0)):
        j, shoulder = joint_index(f"{side_name}_collar"), joint_index(f"{side_name}_shoulder")
        if not f.have[j] or f.rig.parents[shoulder] != j:  # a collar turns with its shoulder, else not at all
            continue
        ci = np.where(side * sign > 0, c, 0.0)
        piece.weights *= (1.0 - ci)[:, None]
        piece.weights[:, j] += ci
    return [piece]


def _neck(f: _Frame) -> list[Piece]:
    if not f.have[_NECK]:
        return []
    joints = [j for j in (_UPPER, _NECK, _NECK_UP, _HEAD) if f.have[j]]
    if joints[-1] == _NECK:
        return []
    lengths = [f._dist(a, b) for a, b in zip(joints[:-1], joints[1:], strict=True)]
    if min(lengths) <= 0:
        return []
    r = 0.16 * f.width
    blends = [0.5 * r if b == _NECK else 0.3 * min(lengths) for b in joints[1:-1]]
    chain = Chain(f.rest[joints], joints[:-1], blends)
    s_neck = float(chain.stations[joints.index(_NECK)])
    s0, s1 = s_neck - 0.12 * f.width, chain.length
    knots = np.array([(s0, r, 0.94 * r), (s1, 0.9 * r, 0.85 * r)])
    return [_tube(f, chain, knots, f.lateral, f.n(16, 6), (s1 - s0) / f.n(7, 3), (0.5 * r, 0.5 * r), SKIN)]


def _head(f: _Frame) -> list[Piece]:
    if not f.have[_HEAD]:
        return []
    h0 = f.rest[_HEAD]
    below = next((j for j in (_NECK_UP, _NECK) if f.have[j] and f._dist(j, _HEAD) > 0), None)
    if f.have[_HEAD_TOP] and f._dist(_HEAD, _HEAD_TOP) > 0:
        size = f._dist(_HEAD, _HEAD_TOP)
        up = _unit(f._vec(_HEAD, _HEAD_TOP), f.up)
    else:
        size = 0.39 * f.width
        up = _unit(f._vec(below, _HEAD), f.up) if below is not None else f.up
    front = _unit(f.front - (f.front @ up) * up, _Z)
    side = np.cross(up, front)
    center = h0 + 0.38 * size * up + 0.05 * size * front
    top, bottom, depth, width = 0.66 * size, 0.92 * size, 0.68 * size, 0.54 * size

    def shape(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height above the centre, half-depth and half-width of the head's ring at latitude ``phi``."""
        sin, cos = np.sin(phi), np.cos(phi)
        jaw = np.maximum(0.0, -sin)
        return np.where(sin > 0, top, bottom) * sin, depth * cos, width * cos * (1.0 - 0.25 * jaw)

    n_rings = f.n(18, 6)
    phi = np.linspace(-0.5 * np.pi, 0.5 * np.pi, n_rings + 2)[1:-1]
    height, a, b = shape(phi)
    centers = center + height[:, None] * up
    verts, faces = loft(
        centers,
        np.broadcast_to(up, centers.shape),
        front,
        a,
        b,
        f.n(24, 8),
        center - bottom * up,
        center + top * up,
        power=2.0,
    )
    pieces = [_rigid(verts, faces, _HEAD, SKIN)]

    def surface(x: float, y: float) -> np.ndarray:
        """The point of the face at ``x`` to the side and ``y`` above the head joint (in head sizes)."""
        rel = (y * size - 0.38 * size) / (top if y * size > 0.38 * size else bottom)
        p = np.arcsin(np.clip(rel, -1.0, 1.0))
        _, a1, b1 = shape(np.array([p]))
        z = float(a1[0]) * np.sqrt(max(0.0, 1.0 - (x * size / float(b1[0])) ** 2))
        return h0 + y * size * up + x * size * side + (0.05 * size + z) * front

    axes = np.stack([up, side, front])
    n_a, n_r = f.n(10, 6), f.n(6, 3)
    for x in (-0.2, 0.2):  # eyes and brows
        eye = surface(x, 0.25) - 0.03 * size * front
        pieces.append(_rigid(*ellipsoid(eye, axes, np.array([0.075, 0.085, 0.06]) * size, n_a, n_r), _HEAD, FACE))
        brow = surface(1.15 * x, 0.42) - 0.01 * size * front
        pieces.append(_rigid(*ellipsoid(brow, axes, np.array([0.028, 0.14, 0.04]) * size, n_a, n_r), _HEAD, FACE))
    mouth = surface(0.0, -0.2) - 0.015 * size * front
    pieces.append(_rigid(*ellipsoid(mouth, axes, np.array([0.025, 0.14, 0.04]) * size, n_a, n_r), _HEAD, FACE))
    nose_axis = _unit(up - 0.35 * front, up)
    nose_axes = np.stack([nose_axis, side, np.cross(nose_axis, side)])
    nose = surface(0.0, 0.1) - 0.02 * size * front
    pieces.append(_rigid(*ellipsoid(nose, nose_axes, np.array([0.17, 0.085, 0.12]) * size, n_a, n_r), _HEAD, SKIN))
    return pieces


def _hand_frame(f: _Frame, side: str, wrist: int, forearm: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """The knuckle line's centre, the hand's width and the palm's normal (sign free) in the rest pose."""
    roots = {fi: joint_index(f"{side}_{fi}1") for fi in FINGERS}
    have = {fi: j for fi, j in roots.items() if f.have[j] and fi != "thumb"}
    along = _unit(forearm, f.lateral)
    if "index" in have and "pinky" in have:
        across = f.rest[have["index"]] - f.rest[have["pinky"]]
        width = float(np.linalg.norm(across))
        normal = _unit(np.cross(along, across), f.up)
    else:
        width, normal = 0.17 * f.width, _unit(f.up - (f.up @ along) * along, _Y)
    if have:
        knuckles = np.mean([f.rest[j] for j in have.values()], axis=0)
        length = max(float((knuckles - f.rest[wrist]) @ along), 0.5 * width)
    else:
        length = 1.4 * width
    return f.rest[wrist] + length * along, max(width, 1e-3), normal


def _arm(f: _Frame, side: str) -> list[Piece]:
    """The upper arm, and the forearm running into the palm, with the fingers.

    The elbow bends up to about 160 degrees in speech, past what any blend of two joints' transforms
    keeps from folding, so the upper arm and the forearm are two capsules whose round ends share the
    elbow's centre: each turns rigidly about it and the pair never opens. The wrist, which mostly
    swings (the forearm's twist is on the elbow), is blended into the palm.
    """
    sh, el, wr = (joint_index(f"{side}_{n}") for n in ("shoulder", "elbow", "wrist"))
    joints = [j for j in (sh, el, wr) if f.have[j]]
    if not f.have[sh] or len(joints) < 2:
        return []
    if min(f._dist(a, b) for a, b in zip(joints[:-1], joints[1:], strict=True)) <= 0:
        return []
    w = f.width
    r_sh, r_el = 0.125 * w, 0.10 * w
    pieces = []
    mid = joints[1]  # the elbow, or the wrist when the rig has no elbow
    upper = f._dist(sh, mid) if mid == el else 0.53 * f._dist(sh, mid)

    def sleeve(s: np.ndarray) -> np.ndarray:
        return np.where(s < 0.5 * upper, SHIRT, SKIN)

    if mid == el:
        chain = Chain(f.rest[[sh, el]], [sh], [])
        knots = np.array(
            [(0.0, r_sh, r_sh), (0.3 * upper, 0.125 * w, 0.12 * w), (0.6 * upper, 0.118 * w, 0.112 * w)]
            + [(upper, r_el, r_el)]
        )
        step = upper / f.n(12, 4)
        pieces.append(_tube(f, chain, knots, f.up, f.n(20, 6), step, (r_sh, r_el), sleeve))
    if wr not in joints:
        return pieces
    knuckles, width, normal = _hand_frame(f, side, wr, f.rest[wr] - f.rest[mid if mid != wr else sh])
    palm = float(np.linalg.norm(knuckles - f.rest[wr]))
    palm_rows = [(0.45 * palm, 0.28 * width, 0.62 * width), (palm, 0.24 * width, 0.6 * width)]
    # the wrist blends into the palm only when it carries the finger roots (else its rotation may twist
    # freely about the forearm, from a lone finger joint hanging from it)
    kids = np.flatnonzero(f.rig.parents == wr)
    natural = bool(np.all(PARENTS[kids] == wr))
    if mid == el and natural:
        fore = f._dist(el, wr)
        chain = Chain(np.array([f.rest[el], f.rest[wr], knuckles]), [el, wr], [0.07 * w])
        rows = [(0.0, 0.97 * r_el, 0.97 * r_el), (0.3 * fore, 0.1 * w, 0.115 * w), (0.9 * fore, 0.065 * w, 0.09 * w)]
        rows += [(fore, 0.058 * w, 0.085 * w)] + [(fore + s, a, b) for s, a, b in palm_rows]
        power = np.array([(fore, 2.0), (fore + 0.4 * palm, 2.8), (fore + palm, 2.8)])
        step = (fore + palm) / f.n(13, 5)
        ends = (0.97 * r_el, 0.2 * width)
        pieces.append(_tube(f, chain, np.array(rows), normal, f.n(20, 6), step, ends, SKIN, power))
        return pieces + _fingers(f, side, width, normal)
    # else the forearm (the whole arm without an elbow) and the hand turn each about its own joint
    base = el if mid == el else sh
    arm = f._dist(base, wr)
    chain = Chain(f.rest[[base, wr]], [base], [])
    if mid == el:
        rows = [(0.0, 0.97 * r_el, 0.97 * r_el), (0.3 * arm, 0.1 * w, 0.115 * w)]
    else:
        rows = [(0.0, r_sh, r_sh), (0.3 * upper, 0.125 * w, 0.12 * w), (upper, r_el, r_el)]
    rows += [(0.8 * arm, 0.065 * w, 0.09 * w), (arm, 0.07 * w, 0.07 * w)]
    step = arm / f.n(14, 5)
    ends = (rows[0][1], 0.07 * w)
    pieces.append(_tube(f, chain, np.array(rows), normal, f.n(20, 6), step, ends, SKIN if mid == el else sleeve))
    chain = Chain(np.array([f.rest[wr], knuckles]), [wr], [])
    rows = [(0.0, 0.058 * w, 0.085 * w)] + palm_rows
    power = np.array([(0.0, 2.0), (0.4 * palm, 2.8), (palm, 2.8)])
    ends = (0.07 * w, 0.2 * width)
    pieces.append(_tube(f, chain, np.array(rows), normal, f.n(20, 6), palm / f.n(5, 3), ends, SKIN, power))
    return pieces + _fingers(f, side, width, normal)


def _fingers(f: _Frame, side: str, width: float, normal: np.ndarray) -> list[Piece]:
    pieces = []
    for finger in FINGERS:
        joints: list[int] = []
        for i in range(1, 5):
            j = joint_index(f"{side}_{finger}{i}")
            if not f.have[j] or (joints and f._dist(joints[-1], j) <= 0):
                break
            joints.append(j)
        if len(joints) < 2:
            continue
        r = _FINGER_RADIUS[finger] * width
        chain = Chain(f.rest[joints], joints[:-1], [1.8 * r] * (len(joints) - 2), reach=0.5)
        taper = np.array([1.0, 0.93, 0.85, 0.75])[: len(joints)]
        if finger == "thumb":
            taper[0] = 1.4  # the ball of the thumb
        rad = r * taper
        knots = np.column_stack([chain.stations, 0.82 * rad, rad])
        n_around = f.n(8, 5)
        pieces.append(_tube(f, chain, knots, normal, n_around, r * 1.15 / f.detail, (rad[0], 0.7 * rad[-1]), SKIN))
    return pieces


def body_pieces(rig: Rig, detail: float = 1.0) -> list[Piece]:
    """Every piece of the body that the rig's joints can place (see the module docstring)."""
    f = _Frame(rig, detail)
    return _torso(f) + _neck(f) + _head(f) + _arm(f, "left") + _arm(f, "right")
