"""A user's character on the page viewer: their skeleton, their mesh and colours, posed by our motion.

The page's script (``web/src/character.js``) draws a skeleton whose rest pose
has no rotation: each bone sits at its rest position, offset from its parent,
bound by the inverse of that translation. A retargeted character
(:class:`gesturekit.character.retarget.Retargeted`) is drawn that way
unchanged: the bones at :attr:`Character.rest_position`, posed by
:meth:`Retargeted.local_turns` (each bone's turn from its rest orientation
relative to its parent's), so each bone's world matrix times its inverse bind
is :meth:`Retargeted.skinning`'s matrix, and the page skins the character's
rest-pose mesh exactly as the retargeting does. A character with several root
bones hangs them from one more bone at the origin (the page has one root). A
character without a mesh (a BVH skeleton) is drawn as
:func:`gesturekit.character.bone_body.bone_body`.

The page colours vertices through a palette of at most 256 colours
(:func:`palette`): the mesh's own sRGB colours exactly (to 8 bits) where it has
that few, else a median cut of them. A glTF or VRM body is then drawn in its
file's own materials: the page reads the materials GLB
(:mod:`gesturekit.character.materials`) with three.js's ``GLTFLoader`` and
puts each material, its textures on the file's UVs, on its triangles; the
palette is what shows until they are loaded (or where they cannot be).
"""

from __future__ import annotations

import base64
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..character.bone_body import bone_body
from ..character.look import NEUTRAL
from ..character.rig import rotation_to_quaternion
from ..character.target import Character, CharacterSkin
from ..errors import ConfigError

if TYPE_CHECKING:
    from ..character.retarget import Retargeted

__all__ = [
    "QUATERNION_SCALE",
    "typed_array",
    "MAX_COLORS",
    "PALETTE_ERROR",
    "ROOT_NAME",
    "palette",
    "page_skeleton",
    "page_character",
    "framed_points",
]

#: Colours a page's palette holds at most (its vertex colour indices are bytes).
MAX_COLORS = 256

#: The largest error of :func:`palette` per channel (sRGB in [0, 1]) beyond the 8-bit rounding: a median cut
#: worse than this falls back to a 6 x 6 x 6 grid, whose error is half its step.
PALETTE_ERROR = 0.1

#: The name of the bone added at the origin above a character's several roots.
ROOT_NAME = "gesturekit_root"


#: Joint rotations travel as int16 quaternions: ``round(q * QUATERNION_SCALE)`` (the page normalises them again).
QUATERNION_SCALE = 32767


def typed_array(values: np.ndarray, dtype: str) -> dict:
    """A typed-array spec ``{"dtype", "bdata", "shape"}`` of ``values`` as little-endian ``dtype`` (how the
    page receives every array: base64 of the raw bytes, the shape as ``"n,m"``).

    Parameters
    ----------
    values : np.ndarray
    dtype : str
        A numpy dtype code such as ``"f4"``, ``"u2"`` or ``"i2"``.
    """
    a = np.ascontiguousarray(values, dtype=np.dtype(dtype).newbyteorder("<"))
    return {
        "dtype": dtype,
        "bdata": base64.b64encode(a.tobytes()).decode("ascii"),
        "shape": ",".join(map(str, a.shape)),
    }


def palette(colors: npt.ArrayLike, *, max_colors: int = MAX_COLORS) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex colours as a palette and an index per vertex, deterministically.

    Parameters
    ----------
    colors : array_like, shape (V, 3)
        sRGB in [0, 1] (clipped).
    max_colors : int
        Most palette entries, at least 216 (the fallback grid's cells).

    Returns
    -------
    palette : np.ndarray, shape (K, 3), float64
        sRGB in [0, 1], ``K <= max_colors``.
    parts : np.ndarray, shape (V,), int64
        Each vertex's entry. ``|palette[parts] - colors|`` is at most ``0.5 / 255`` per channel where the colours
        (rounded to 8 bits) are ``max_colors`` or fewer, else at most :data:`PALETTE_ERROR` plus that.

    Raises
    ------
    ConfigError
        ``max_colors`` below 216.
    """
    if max_colors < 216:
        raise ConfigError(f"a palette holds at least 216 colours (a 6 x 6 x 6 grid), got {max_colors}")
    c = np.clip(np.nan_to_num(np.asarray(colors, dtype=np.float64).reshape(-1, 3)), 0.0, 1.0)
    if len(c) == 0:
        return np.zeros((1, 3)), np.zeros(0, dtype=np.int64)
    c8 = np.round(c * 255).astype(np.int64)
    uniq, inverse, counts = np.unique(c8, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    if len(uniq) <= max_colors:
        return uniq / 255.0, inverse
    boxes = _median_cut(uniq, counts, max_colors)
    box_of = np.empty(len(uniq), dtype=np.int64)
    pal = np.empty((len(boxes), 3))
    for i, b in enumerate(boxes):
        box_of[b] = i
        pal[i] = (uniq[b] * counts[b, None]).sum(0) / counts[b].sum() / 255.0
    parts = box_of[inverse]
    if np.abs(pal[parts] - c8 / 255.0).max() <= PALETTE_ERROR:
        return pal, parts
    # a 6 x 6 x 6 grid: every colour within half a step (0.1) of its cell's centre
    cell = np.round(c8 / 255.0 * 5).astype(np.int64)
    used, parts = np.unique(cell[:, 0] * 36 + cell[:, 1] * 6 + cell[:, 2], return_inverse=True)
    return np.stack([used // 36, used // 6 % 6, used % 6], 1) / 5.0, parts.ravel()


def _median_cut(points: np.ndarray, counts: np.ndarray, n: int) -> list[np.ndarray]:
    """Boxes (index arrays) of distinct ``points`` (P, 3): the box of the widest extent is split at its
    weighted median along that axis until there are ``n`` (or every box is one colour)."""
    boxes = [np.arange(len(points))]
    extent = [np.ptp(points, axis=0)]
    while len(boxes) < n:
        widest = [float(e.max()) for e in extent]
        i = int(np.argmax(widest))
        if widest[i] == 0:
            break
        b = boxes[i]
        axis = int(np.argmax(extent[i]))
        order = b[np.argsort(points[b, axis], kind="stable")]
        cum = np.cumsum(counts[order])
        k = int(np.clip(np.searchsorted(cum, cum[-1] / 2) + 1, 1, len(order) - 1))
        boxes[i], extent[i] = order[:k], np.ptp(points[order[:k]], axis=0)
        boxes.append(order[k:])
        extent.append(np.ptp(points[order[k:]], axis=0))
    return boxes


def page_skeleton(character: Character) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, bool]:
    """The skeleton the page draws: names, parents (one root), rest positions (B, 3), and whether a root was added.

    Where the character has one root these are its own; else a bone :data:`ROOT_NAME` at the origin comes first
    and every other index is one more.
    """
    parents, rest = character.parents.astype(np.int64), character.rest_position.astype(np.float64)
    if int((parents < 0).sum()) == 1:
        return character.names, parents, rest, False
    shifted = np.where(parents < 0, 0, parents + 1)
    return (ROOT_NAME, *character.names), np.concatenate([[-1], shifted]), np.vstack([np.zeros(3), rest]), True


def _skin(character: Character, scheme: str) -> CharacterSkin:
    skin = character.skin
    return skin if skin is not None and skin.n_vertices else bone_body(character, scheme=scheme)


def page_character(retargeted: Retargeted, *, scheme: str, skin: CharacterSkin | None = None) -> dict:
    """One motion's entry of :func:`gesturekit.viz.viewer.viewer_data` for a retargeted character.

    Parameters
    ----------
    retargeted : Retargeted
        The character posed by the motion over the shown frames.
    scheme : str
        The colour scheme of a generated body (a character without a mesh); a mesh keeps its own colours.
    skin : CharacterSkin, optional
        The body to draw (default the character's, or :func:`~gesturekit.character.bone_body.bone_body`).

    Returns
    -------
    dict
        ``scheme``, ``colors`` (the palette, sRGB in [0, 1]), ``rig`` (``names``, ``parents``, ``in_rig``,
        ``offsets`` and ``rest``, shape (B, 3), metres), ``mesh`` (``vertices``, ``normals``, ``faces``,
        ``joints`` (u1, or u2 for 256 bones or more), ``weights``, ``parts``; and where the character's body has
        its file's materials, ``uvs`` (V, 2), ``groups`` (``[first index, index count, material]`` of the faces,
        sorted by material) and ``materials``, the materials GLB's bytes), ``rotations`` ((frames, B, 4)
        int16 xyzw quaternions times 32767, relative to the parent) and ``root`` ((frames, 3), metres), as
        the page's typed-array specs; B is the character's bones (plus one added root).
    """
    ch = retargeted.character
    names, parents, rest, added = page_skeleton(ch)
    body = skin if skin is not None else _skin(ch, scheme)
    offsets = np.zeros_like(rest)
    has = parents >= 0
    offsets[has] = rest[has] - rest[parents[has]]
    local = retargeted.local_turns()
    root = retargeted.position[:, int(np.flatnonzero(ch.parents < 0)[0])]
    if added:
        local = np.concatenate([np.broadcast_to(np.eye(3), (len(local), 1, 3, 3)), local], axis=1)
        root = np.zeros((len(local), 3))
    quats = np.round(rotation_to_quaternion(local) * QUATERNION_SCALE).astype(np.int16)
    if skin is None and body is not ch.skin:
        # a generated body: its parts are those of the neutral scheme's, so side-by-side schemes share a mesh
        pal, parts = palette(bone_body(ch).colors)
        first = np.searchsorted(np.sort(parts), np.arange(len(pal)))
        pal = body.colors[np.argsort(parts, kind="stable")[first]].astype(np.float64)
    else:
        pal, parts = palette(body.colors)
    joints = body.joints + (1 if added else 0)
    n_bones = len(names)
    faces = body.faces
    own: dict = {}
    if body is ch.skin and body.has_materials:
        # the file's own materials (the page's GLTFLoader reads them): triangles grouped by material, in order
        which = np.asarray(body.face_materials, dtype=np.int64)
        order = np.argsort(which, kind="stable")
        faces = faces[order]
        kinds, starts, counts = np.unique(which[order], return_index=True, return_counts=True)
        own = {
            "uvs": typed_array(np.asarray(body.uvs), "f4"),
            "groups": [[int(3 * a), int(3 * c), int(k)] for k, a, c in zip(kinds, starts, counts)],
            "materials": typed_array(np.frombuffer(body.materials, dtype=np.uint8), "u1"),
        }
    return {
        "scheme": "character" if ch.skin is not None and ch.skin.n_vertices else scheme,
        "colors": [[round(float(x), 6) for x in row] for row in pal],
        "rig": {
            "names": list(names),
            "parents": [int(p) for p in parents],
            "in_rig": [True] * n_bones,
            "offsets": typed_array(offsets, "f4"),
            "rest": typed_array(rest, "f4"),
        },
        "mesh": {
            "vertices": typed_array(body.vertices, "f4"),
            "normals": typed_array(body.normals, "f4"),
            "faces": typed_array(faces, "u2" if body.n_vertices < 2**16 else "u4"),
            "joints": typed_array(joints, "u1" if n_bones < 256 else "u2"),
            "weights": typed_array(body.weights, "f4"),
            "parts": typed_array(parts, "u1"),
            **own,
        },
        "rotations": typed_array(quats, "i2"),
        "root": typed_array(root, "f4"),
    }


def framed_points(retargeted: Retargeted, skin: CharacterSkin | None = None) -> np.ndarray:
    """What the camera frames of a retargeted character, as the MP4 frames it
    (:func:`gesturekit.viz.character_user.framing_points`: each bone that follows the motion with the box of
    the skin it leads, and the pelvis); shape (frames, n, 3), metres. ``skin``: the body drawn (default the
    character's own, or its bone body)."""
    from .character_user import framing_points

    ch = retargeted.character
    body = skin if skin is not None else _skin(ch, NEUTRAL)
    return framing_points(retargeted, body, retargeted.source.presence)
