"""A user's character in the MP4: our motion retargeted onto it, its own skin posed, lit and framed.

:class:`UserBody` is one motion on a :class:`~gesturekit.character.target.Character`
(:func:`gesturekit.character.user.read_character`): the motion retargeted
(:func:`gesturekit.character.retarget.retarget`), the character's skinned mesh
posed frame by frame by :meth:`~gesturekit.character.retarget.Retargeted.skinning`
with the one linear blend of :mod:`gesturekit.character.skin`, and its own
colours (:attr:`CharacterSkin.colors`) shaded by the shared Lambert rule
(:func:`gesturekit.viz.character_render.shade`). A character without a body (a
BVH skeleton) is drawn as tubes around its bones in the scheme's shirt colour
(:func:`_bone_tubes`, which takes the arguments of the character layer's bone body to come).

The camera frames the bones that follow the motion (:meth:`UserBody.framing_points`):
the pelvis, the bones at the motion's drawn joints and every bone below them,
each with the box of the skin it leads, so that the picture is the
presenter's half body, as for our character.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..character.look import part_colors
from ..character.mesh import PARTS
from ..character.retarget import Retargeted, retarget
from ..character.skin import pose_skin
from ..character.target import Character, CharacterSkin
from ..motion import Motion
from ..skeleton import JointPresence

__all__ = ["TUBE_SIDES", "UserBody", "framed_bones", "skin_extent", "character_arrays", "character_from_arrays"]

#: Sides of the tubes drawn around a bodiless character's bones.
TUBE_SIDES = 10

_RING = 5  # latitude rings of a joint's ball


def framed_bones(character: Character, presence: JointPresence) -> np.ndarray:
    """The bones the camera frames, shape (M,), bool: the pelvis, the bones at the drawn joints of a motion
    of ``presence`` and every bone below one of those (finger tips, the head's end, twist bones); not the legs."""
    parents = character.parents
    framed = np.zeros(character.n_bones, dtype=bool)
    at = character.bone_of[presence.drawn & (character.bone_of >= 0)]
    framed[at] = True
    for b in range(character.n_bones):  # parents come before their children
        if parents[b] >= 0 and framed[parents[b]]:
            framed[b] = True
    framed[character.pelvis] = True
    return framed


def skin_extent(skin: CharacterSkin, rest_position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box around each bone of the skin it leads, at rest: lower and upper corners relative to the bone,
    shapes (M, 3) and (M, 3), metres, along our axes; a vertex is led by the bone of its largest weight. Zero
    for a bone that leads none."""
    lo, hi = np.zeros((len(rest_position), 3)), np.zeros((len(rest_position), 3))
    if not skin.n_vertices:
        return lo, hi
    lead = skin.joints[np.arange(skin.n_vertices), np.argmax(skin.weights, axis=1)]
    rel = skin.vertices.astype(np.float64) - rest_position[lead]
    np.minimum.at(lo, lead, rel)
    np.maximum.at(hi, lead, rel)
    return lo, hi


class UserBody:
    """One motion on a user's character: its skin frame by frame, shaded, and the points the camera frames.

    Parameters
    ----------
    motion : Motion
    character : Character
    scheme : str
        Colour scheme (:data:`gesturekit.character.look.SCHEMES`) of the tubes drawn around the bones of a
        character without a body; the character's own colours otherwise.

    Attributes
    ----------
    retargeted : Retargeted
        The character posed by the motion.
    skin : CharacterSkin
        The character's own body, or tubes around its bones (:func:`_bone_tubes`).
    """

    def __init__(self, motion: Motion, character: Character, scheme: str):
        self.motion = motion
        self.retargeted: Retargeted = retarget(motion, character)
        has_body = character.skin is not None and len(character.skin.faces) > 0
        self.skin: CharacterSkin = character.skin if has_body else _bone_tubes(character, scheme=scheme)  # type: ignore[assignment]
        self._matrices = self.retargeted.skinning()
        from .character_render import srgb_to_linear

        self._albedo = srgb_to_linear(self.skin.colors)
        self._posed: tuple[int, np.ndarray, np.ndarray] | None = None

    @property
    def n_frames(self) -> int:
        return self.retargeted.n_frames

    @property
    def faces(self) -> np.ndarray:
        """The triangles, shape (F, 3), int64."""
        return self.skin.faces

    def _pose(self, frame: int) -> tuple[np.ndarray, np.ndarray]:
        f = min(int(frame), self.n_frames - 1)
        if self._posed is None or self._posed[0] != f:
            # one frame at a time: a frame's vertices do not depend on which others are skinned with it
            vertices, normals = pose_skin(self.skin, self._matrices[f : f + 1])
            self._posed = (f, vertices[0], normals[0])
        return self._posed[1], self._posed[2]

    def vertices(self, frame: int) -> np.ndarray:
        """The skin at ``frame`` (its last past its end), shape (V, 3), float32, metres (a fresh array)."""
        return self._pose(frame)[0].copy()

    def colors(self, frame: int) -> np.ndarray:
        """The skin's own colours at ``frame``, shaded by its skinned normals, shape (V, 3), uint8 sRGB."""
        from .character_render import shade

        return shade(self._pose(frame)[1], self._albedo)

    def framing_points(self) -> np.ndarray:
        """What the camera frames, shape (frames, 8 n + 1, 3), metres: the corners of each framed bone's box
        of skin (:func:`framed_bones` but the pelvis, :func:`skin_extent`) carried by the bone's turn
        (:meth:`Retargeted.turns`), and the pelvis itself (the frame's foot, as the waist is our character's)."""
        ch = self.retargeted.character
        framed = framed_bones(ch, self.motion.presence)
        framed[ch.pelvis] = False
        bones = np.flatnonzero(framed)
        lo, hi = skin_extent(self.skin, ch.rest_position)
        pick = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], dtype=bool)  # (8 corners, 3 axes)
        corners = np.where(pick[None], hi[bones, None], lo[bones, None])  # (n, 8, 3)
        pos = self.retargeted.position
        turned = np.einsum("tnab,nkb->tnka", self.retargeted.turns()[:, bones], corners)
        grown = pos[:, bones, None, :] + turned
        return np.concatenate([grown.reshape(len(pos), -1, 3), pos[:, [ch.pelvis]]], axis=1)


def _bone_tubes(character: Character, *, scheme: str) -> CharacterSkin:
    """Tubes around a bodiless character's bones (parent to child) and a ball at every joint, each bound to
    one bone (a tube to its parent bone), in the scheme's shirt colour: a stand-in body for a BVH skeleton."""
    color = part_colors(scheme)[PARTS.index("shirt")]
    pos = np.asarray(character.rest_position, dtype=np.float64)
    height = max(float(np.ptp(pos[:, 1])), 1e-3)
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]] = []  # vertices, normals, faces, bone
    radius = np.zeros(character.n_bones)
    for b, p in enumerate(character.parents):
        if p < 0:
            continue
        axis = pos[b] - pos[p]
        length = float(np.linalg.norm(axis))
        if length < 1e-4 * height:
            continue
        r = float(np.clip(0.15 * length, 0.006 * height, 0.025 * height))
        radius[p], radius[b] = max(radius[p], r), max(radius[b], r)
        parts.append((*_tube(pos[p], pos[b], r), int(p)))
    for j in np.flatnonzero(radius > 0):
        parts.append((*_ball(pos[j], 1.1 * radius[j]), int(j)))
    vertices, normals, faces, joints, start = [], [], [], [], 0
    for v, n, f, bone in parts:
        vertices.append(v)
        normals.append(n)
        faces.append(f + start)
        joints.append(np.full(len(v), bone))
        start += len(v)
    n_v = start
    bone_of_vertex = np.concatenate(joints) if joints else np.zeros(0, np.int64)
    joint4 = np.zeros((n_v, 4), dtype=np.int64)
    joint4[:, 0] = bone_of_vertex
    weights = np.zeros((n_v, 4), dtype=np.float32)
    weights[:, 0] = 1.0
    return CharacterSkin(
        vertices=np.concatenate(vertices).astype(np.float32) if parts else np.zeros((0, 3), np.float32),
        normals=np.concatenate(normals).astype(np.float32) if parts else np.zeros((0, 3), np.float32),
        faces=np.concatenate(faces).astype(np.int64) if parts else np.zeros((0, 3), np.int64),
        joints=joint4,
        weights=weights,
        colors=np.tile(np.asarray(color, dtype=np.float32), (n_v, 1)),
    )


def _frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across the unit direction ``d``."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(helper, d)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def _tube(a: np.ndarray, b: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An open tube of :data:`TUBE_SIDES` sides from ``a`` to ``b``: vertices, normals (V, 3), faces (F, 3),
    counter-clockwise seen from outside."""
    d = (b - a) / np.linalg.norm(b - a)
    u, v = _frame(d)
    theta = 2 * np.pi * np.arange(TUBE_SIDES) / TUBE_SIDES
    ring = np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * v  # (S, 3)
    vertices = np.concatenate([a + r * ring, b + r * ring])
    k = np.arange(TUBE_SIDES)
    k1 = (k + 1) % TUBE_SIDES
    s = TUBE_SIDES
    faces = np.concatenate([np.stack([k, k1, s + k1], 1), np.stack([k, s + k1, s + k], 1)])
    return vertices, np.concatenate([ring, ring]), faces


def _ball(c: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ball of :data:`TUBE_SIDES` meridians and :data:`_RING` rings around ``c``: vertices, normals, faces
    (counter-clockwise seen from outside)."""
    s = TUBE_SIDES
    lat = np.pi * np.arange(1, _RING + 1) / (_RING + 1) - np.pi / 2  # rings from the bottom up, poles apart
    lon = 2 * np.pi * np.arange(s) / s
    across, y = np.cos(lat)[:, None], np.repeat(np.sin(lat)[:, None], s, 1)
    ring = np.stack([across * np.cos(lon), y, -across * np.sin(lon)], -1).reshape(-1, 3)
    normals = np.concatenate([ring, [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]])
    bottom, top = len(ring), len(ring) + 1
    k = np.arange(s)
    k1 = (k + 1) % s
    last = (_RING - 1) * s
    faces = [np.stack([np.full(s, bottom), k1, k], 1), np.stack([np.full(s, top), last + k, last + k1], 1)]
    for i in range(_RING - 1):
        lo, hi = i * s, (i + 1) * s
        faces += [np.stack([lo + k, lo + k1, hi + k1], 1), np.stack([lo + k, hi + k1, hi + k], 1)]
    return c + r * normals, normals, np.concatenate(faces)


# ---- a character through a job file ------------------------------------------------------------


def character_arrays(character: Character) -> dict[str, np.ndarray]:
    """What the MP4 needs of a character as plain arrays (for a rendering process's job file; no glTF
    document): read back with :func:`character_from_arrays`, equal field by field."""
    ch = character
    text = {"path": str(ch.path), "kind": ch.kind, "matched_by": ch.matched_by, "names": list(ch.names)}
    import json

    out = {
        "character_text": np.array(json.dumps(text)),
        "character_parents": np.asarray(ch.parents),
        "character_rest_rotation": np.asarray(ch.rest_rotation),
        "character_rest_position": np.asarray(ch.rest_position),
        "character_bone_of": np.asarray(ch.bone_of),
        "character_numbers": np.array([float(ch.pelvis), float(ch.bvh_units)]),
        "character_to_file": np.asarray(ch.to_file),
    }
    if ch.skin is not None:
        for name in ("vertices", "normals", "faces", "joints", "weights", "colors"):
            out[f"character_skin_{name}"] = np.asarray(getattr(ch.skin, name))
    return out


def character_from_arrays(data: Any) -> Character | None:
    """The character :func:`character_arrays` wrote into ``data`` (a mapping or an open npz), or None."""
    import json

    if "character_text" not in data:
        return None
    text = json.loads(str(data["character_text"]))
    skin = None
    if "character_skin_faces" in data:
        skin = CharacterSkin(
            **{n: data[f"character_skin_{n}"] for n in ("vertices", "normals", "faces", "joints", "weights", "colors")}
        )
    numbers = data["character_numbers"]
    return Character(
        path=Path(text["path"]),
        kind=text["kind"],
        names=tuple(text["names"]),
        parents=data["character_parents"],
        rest_rotation=data["character_rest_rotation"],
        rest_position=data["character_rest_position"],
        bone_of=data["character_bone_of"],
        pelvis=int(numbers[0]),
        matched_by=text["matched_by"],
        to_file=data["character_to_file"],
        skin=skin,
        bvh_units=float(numbers[1]),
    )
