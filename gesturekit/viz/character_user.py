"""A user's character in the MP4: our motion retargeted onto it, its own skin posed, lit and framed.

:class:`UserBody` is one motion on a :class:`~gesturekit.character.target.Character`
(:func:`gesturekit.character.user.read_character`): the motion retargeted
(:func:`gesturekit.character.retarget.retarget`), the character's skinned mesh
posed frame by frame by :meth:`~gesturekit.character.retarget.Retargeted.skinning`
with the one linear blend of :mod:`gesturekit.character.skin`, and its own
colours (:attr:`CharacterSkin.colors`) shaded by the shared Lambert rule
(:func:`gesturekit.viz.character_render.shade`). A character without a body (a
BVH skeleton) is drawn as :func:`gesturekit.character.bone_body.bone_body` in the
scheme's colours, as the page draws it.

The camera frames the bones that follow the motion (:meth:`UserBody.framing_points`):
the pelvis, the bones at the motion's drawn joints and every bone below them,
each with the box of the skin it leads, so that the picture is the
presenter's half body, as for our character.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from ..character.bone_body import bone_body
from ..character.materials import SkinMaterial, read_materials
from ..character.retarget import Retargeted, retarget
from ..character.skin import pose_skin
from ..character.target import Character, CharacterSkin
from ..motion import Motion
from ..skeleton import JointPresence

__all__ = ["UserBody", "framed_bones", "framing_points", "skin_extent", "character_arrays", "character_from_arrays"]


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
        The character's own body, or capsules around its bones (:func:`~gesturekit.character.bone_body.bone_body`).
    """

    def __init__(self, motion: Motion, character: Character, scheme: str):
        self.motion = motion
        self.retargeted: Retargeted = retarget(motion, character)
        has_body = character.skin is not None and len(character.skin.faces) > 0
        self.skin: CharacterSkin = character.skin if has_body else bone_body(character, scheme=scheme)  # type: ignore[assignment]
        self._matrices = self.retargeted.skinning()
        from ..character.look import srgb_to_linear

        self._albedo = srgb_to_linear(self.skin.colors)
        #: The body's own materials and their images (:func:`~gesturekit.character.materials.read_materials`),
        #: empty where it is drawn in its colours alone.
        self.materials: list[SkinMaterial] = []
        self.images: list[np.ndarray] = []
        if self.skin.has_materials:
            self.materials, self.images = read_materials(self.skin.materials)
            # a textured material's vertices are shaded in its factor alone: the MP4 multiplies in the texture
            # texel by texel (gesturekit.viz.character_render), as the page does
            faces, which = self.skin.faces, np.asarray(self.skin.face_materials)
            vertex_material = np.full(self.skin.n_vertices, -1, dtype=np.int64)
            vertex_material[faces.reshape(-1)] = np.repeat(which, 3)
            for k, mat in enumerate(self.materials):
                if mat.image is not None:
                    self._albedo[vertex_material == k] = np.clip(mat.color[:3], 0.0, 1.0)
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

    def normals(self, frame: int) -> np.ndarray:
        """The skin's unit normals at ``frame`` (its last past its end), shape (V, 3), float32 (a fresh array;
        zero where a vertex has no area around it)."""
        n = self._pose(frame)[1].astype(np.float32)
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, length, out=np.zeros_like(n), where=length > 0)

    def colors(self, frame: int) -> np.ndarray:
        """The skin's own colours at ``frame``, shaded by its skinned normals, shape (V, 3), uint8 sRGB; where
        the body has textures (:attr:`materials`), a textured material's vertices carry its factor shaded, which
        the texture multiplies in linear light."""
        from ..character.look import shade

        return shade(self._pose(frame)[1], self._albedo)

    def framing_points(self) -> np.ndarray:
        """What the camera frames: :func:`framing_points` of this motion on the character."""
        return framing_points(self.retargeted, self.skin, self.motion.presence)


def framing_points(retargeted: Retargeted, skin: CharacterSkin, presence: JointPresence) -> np.ndarray:
    """What the camera frames of a retargeted character, the same for the MP4 and the page.

    Parameters
    ----------
    retargeted : Retargeted
        The character posed by a motion.
    skin : CharacterSkin
        The body drawn (the character's own, or its bone body).
    presence : JointPresence
        The motion's joints (which are drawn).

    Returns
    -------
    np.ndarray, shape (frames, 8 n + 1, 3)
        Metres: the corners of each framed bone's box of skin (:func:`framed_bones` but the pelvis,
        :func:`skin_extent`) carried by the bone's turn (:meth:`Retargeted.turns`), and the pelvis itself
        (the frame's foot, as the waist is our character's).
    """
    ch = retargeted.character
    framed = framed_bones(ch, presence)
    framed[ch.pelvis] = False
    bones = np.flatnonzero(framed)
    lo, hi = skin_extent(skin, ch.rest_position)
    pick = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], dtype=bool)  # (8 corners, 3 axes)
    corners = np.where(pick[None], hi[bones, None], lo[bones, None])  # (n, 8, 3)
    pos = retargeted.position
    turned = np.einsum("tnab,nkb->tnka", retargeted.turns()[:, bones], corners)
    grown = pos[:, bones, None, :] + turned
    return np.concatenate([grown.reshape(len(pos), -1, 3), pos[:, [ch.pelvis]]], axis=1)


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
        "character_numbers": np.array([float(ch.pelvis), float(ch.bvh_units), ch.wrist_slack]),
        "character_to_file": np.asarray(ch.to_file),
    }
    if ch.skin is not None:
        for name in ("vertices", "normals", "faces", "joints", "weights", "colors"):
            out[f"character_skin_{name}"] = np.asarray(getattr(ch.skin, name))
        if ch.skin.has_materials:
            out["character_skin_uvs"] = np.asarray(ch.skin.uvs)
            out["character_skin_face_materials"] = np.asarray(ch.skin.face_materials)
            out["character_skin_materials"] = np.frombuffer(ch.skin.materials, dtype=np.uint8)
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
        if "character_skin_materials" in data:
            skin = dataclasses.replace(
                skin,
                uvs=data["character_skin_uvs"],
                face_materials=data["character_skin_face_materials"],
                materials=np.asarray(data["character_skin_materials"], dtype=np.uint8).tobytes(),
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
        wrist_slack=float(numbers[2]),
    )
