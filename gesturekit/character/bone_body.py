"""A body for a character that has none (a BVH skeleton): a tapered capsule around each of its bones.

:func:`bone_body` gives a :class:`~gesturekit.character.target.CharacterSkin`
in the character's rest pose (our frame), so that every character is drawn
with a surface: each bone from a parent to a child becomes a capsule (a
tapered tube closed by two half spheres) that follows the parent bone alone,
and each bone without children (a finger tip, a head without a bone above
it) gets a short capsule of its own along its parent's direction. The bones
from the pelvis up to the neck are a thicker torso, the head's a round head. Bones above the pelvis in the
hierarchy (an armature's root at the floor) get none. The colours are one
scheme of :func:`gesturekit.character.look.part_colors`: the head, the neck
and the hands in its skin colour, the rest in its shirt colour.
"""

from __future__ import annotations

import numpy as np

from .._arguments import checks_arguments
from .look import NEUTRAL, part_colors
from .mesh import PARTS, vertex_normals
from .target import Character, CharacterSkin

__all__ = ["RADIUS", "TAPER", "TORSO", "HEAD", "bone_body"]

#: Radius of a bone's capsule at its parent's end: this fraction of the bone's length, within
#: (lower, upper) fractions of the character's height; the child's end is :data:`TAPER` of it.
RADIUS = (0.2, 0.012, 0.04)

#: The radius at a capsule's far end over the radius at its near end.
TAPER = 0.7

#: Radii of the torso's capsules (from the pelvis up to the neck) and of the head's, as fractions of the height.
TORSO, HEAD = 0.075, 0.055

_AROUND, _ALONG, _CAP = 12, 2, 3  # vertices around a ring, rings along the tube, rings in each half sphere


def _capsule(a: np.ndarray, c: np.ndarray, ra: float, rc: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed capsule from ``a`` to ``c`` (radii ``ra`` and ``rc``): vertices (n, 3) and triangles (f, 3),
    counter-clockwise seen from outside."""
    axis = c - a
    u = axis / np.linalg.norm(axis)
    helper = np.eye(3)[int(np.argmin(np.abs(u)))]
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    phi = 2 * np.pi * np.arange(_AROUND) / _AROUND
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2  # (around, 3)
    rings = []
    # half sphere at a (from the pole towards the equator), the tube, half sphere at c
    for k in range(1, _CAP + 1):
        t = np.pi / 2 * k / _CAP
        rings.append(a - u * ra * np.cos(t) + radial * ra * np.sin(t))
    for k in range(1, _ALONG):
        s = k / _ALONG
        rings.append(a + axis * s + radial * (ra + (rc - ra) * s))
    for k in range(_CAP, 0, -1):
        t = np.pi / 2 * k / _CAP
        rings.append(c + u * rc * np.cos(t) + radial * rc * np.sin(t))
    n_rings = len(rings)
    verts = np.concatenate([[a - u * ra], np.concatenate(rings), [c + u * rc]])
    faces = []
    j = np.arange(_AROUND)
    nxt = (j + 1) % _AROUND
    ring = lambda r: 1 + r * _AROUND  # noqa: E731  (first vertex of ring r)
    # e1 x e2 = u: the rings turn counter-clockwise about u, so seen from outside ...
    faces.append(np.stack([np.zeros(_AROUND, int), ring(0) + nxt, ring(0) + j], 1))
    for r in range(n_rings - 1):
        lo, hi = ring(r), ring(r + 1)
        faces.append(np.stack([lo + j, lo + nxt, hi + nxt], 1))
        faces.append(np.stack([lo + j, hi + nxt, hi + j], 1))
    last = len(verts) - 1
    faces.append(np.stack([np.full(_AROUND, last), ring(n_rings - 1) + j, ring(n_rings - 1) + nxt], 1))
    return verts, np.concatenate(faces)


def _below(parents: np.ndarray, top: int) -> np.ndarray:
    """Whether each bone is ``top`` or below it (parents come before children)."""
    out = np.zeros(len(parents), dtype=bool)
    out[top] = True
    for b, p in enumerate(parents):
        if p >= 0 and out[p]:
            out[b] = True
    return out


@checks_arguments
def bone_body(character: Character, *, scheme: str = NEUTRAL) -> CharacterSkin:
    """A body of capsules around the character's bones, in its rest pose, skinned rigidly to them.

    Parameters
    ----------
    character : Character
        Any character (its own skin, if any, is not used).
    scheme : str
        The colour scheme (:data:`gesturekit.character.look.SCHEMES`); default the neutral one.

    Returns
    -------
    CharacterSkin
        Vertices (V, 3) float32 metres in the rest pose (our frame), outward unit normals, triangles
        counter-clockwise seen from outside (int64), each vertex following one bone (``joints[:, 0]``,
        weight 1), sRGB colours in [0, 1]. Empty (V = 0) for a character whose bones all sit at one point.
    """
    ch = character
    parents, rest = ch.parents, ch.rest_position.astype(np.float64)
    height = max(float(np.ptp(rest[:, 1])), 1e-3)
    frac, lo, hi = RADIUS
    body = _below(parents, ch.pelvis)
    skin_tone = np.zeros(ch.n_bones, dtype=bool)
    head = ch.bone("head")
    for joint in ("head", "neck", "left_wrist", "right_wrist"):
        b = ch.bone(joint)
        if b >= 0:
            skin_tone |= _below(parents, b)
    has_child = np.zeros(ch.n_bones, dtype=bool)
    has_child[parents[parents >= 0]] = True
    spine = np.zeros(ch.n_bones, dtype=bool)  # from the pelvis up to (not including) the neck
    top = ch.bone("neck") if ch.bone("neck") >= 0 else head
    b = int(parents[top]) if top >= 0 else -1
    while b >= 0 and body[b]:
        spine[b] = True
        b = int(parents[b])
    pieces: list[tuple[np.ndarray, np.ndarray, int]] = []
    for b in range(ch.n_bones):
        p = int(parents[b])
        if p < 0 or not body[p]:
            continue
        length = float(np.linalg.norm(rest[b] - rest[p]))
        if length < 1e-6 * height:
            continue
        r = float(np.clip(frac * length, lo * height, hi * height))
        rc = TAPER * r
        if spine[p] and (spine[b] or b == top):
            r, rc = TORSO * height, 0.9 * TORSO * height
        elif p == head:
            r = rc = HEAD * height
        elif p >= 0 and parents[p] >= 0 and int(parents[p]) == head and not has_child[b]:
            continue  # the head's own capsule holds its tip
        pieces.append((*_capsule(rest[p], rest[b], r, rc), p))
        if not has_child[b] and p != head:  # a tip: a capsule of its own, along its parent's direction
            grow, rb = (0.12 * height, HEAD * height) if b == head else (0.5 * length, TAPER * rc)
            tip = rest[b] + (rest[b] - rest[p]) / length * grow
            pieces.append((*_capsule(rest[b], tip, rb, TAPER * rb if b != head else rb), b))
    colours = part_colors(scheme)
    vertices, faces, joints, colors, start = [], [], [], [], 0
    for verts, tris, owner in pieces:
        vertices.append(verts)
        faces.append(tris + start)
        joints.append(np.full(len(verts), owner))
        colors.append(np.repeat(colours[[PARTS.index("skin" if skin_tone[owner] else "shirt")]], len(verts), 0))
        start += len(verts)
    if not pieces:
        v = np.zeros((0, 3), np.float32)
        none = np.zeros((0, 4), np.int64)
        return CharacterSkin(v, v.copy(), np.zeros((0, 3), np.int64), none, none.astype(np.float32), v.copy())
    verts = np.concatenate(vertices)
    tris = np.concatenate(faces).astype(np.int64)
    j = np.zeros((len(verts), 4), dtype=np.int64)
    j[:, 0] = np.concatenate(joints)
    w = np.zeros((len(verts), 4), dtype=np.float32)
    w[:, 0] = 1.0
    return CharacterSkin(
        vertices=verts.astype(np.float32),
        normals=vertex_normals(verts, tris).astype(np.float32),
        faces=tris,
        joints=j,
        weights=w,
        colors=np.concatenate(colors).astype(np.float32),
    )
