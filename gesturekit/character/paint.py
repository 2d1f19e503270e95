"""The character's colours, vertex by vertex: one rule for the page and the MP4.

A vertex takes its part's colour in the scheme (:data:`gesturekit.character.mesh.PARTS`,
:func:`gesturekit.character.look.part_colors`), or :data:`DERIVED_COLOR` where the joint
with its largest weight is derived (placed from other joints, not recorded). Colours are
given per vertex (the page and the MP4 both interpolate them across a triangle), so
:func:`paint` first gives every triangle one colour: a corner whose colour differs from
its triangle's is replaced by a copy of its vertex, and each part keeps its colour up to
the seam, as one material per part would. The order of the palette decides which colour a
triangle between two takes: skin, then the shirt, then the face's marks, then the derived grey.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..skeleton import DERIVED, JointPresence
from .look import part_colors
from .mesh import PARTS, CharacterMesh

__all__ = ["DERIVED_COLOR", "EMPTY_BODY", "paint", "split_at_part_seams"]

#: The colour of the parts derived joints lead, sRGB hex: grey, whatever the scheme.
DERIVED_COLOR = "#a2a8af"

#: A body with no vertex: what a motion without a bone of any length (every joint at one point) gets.
EMPTY_BODY = CharacterMesh(
    vertices=np.zeros((0, 3), np.float32),
    normals=np.zeros((0, 3), np.float32),
    faces=np.zeros((0, 3), np.int32),
    joints=np.zeros((0, 4), np.uint8),
    weights=np.zeros((0, 4), np.float32),
    parts=np.zeros(0, np.uint8),
)


def split_at_part_seams(mesh: CharacterMesh, parts: np.ndarray) -> CharacterMesh:
    """The mesh with ``parts`` (V,), each triangle in one part.

    A triangle takes the lowest part among its corners, and a corner of another part is replaced
    by a copy of its vertex in the triangle's part. Between two rings of a limb in different parts,
    every triangle so takes the same part, and the seam runs along a ring (a majority rule would
    alternate triangle by triangle and draw a saw-tooth). Positions, normals and
    skinning of every triangle's corners are unchanged; the copies follow the original vertices
    (shape (V + copies, ...)).

    Parameters
    ----------
    mesh : CharacterMesh
    parts : np.ndarray, shape (V,), uint8
        Each vertex's part (any small integers: a palette index).

    Returns
    -------
    CharacterMesh
        With :attr:`~CharacterMesh.parts` the given parts (and the copies').
    """
    f = mesh.faces
    fp = parts[f]  # (F, 3)
    face_part = fp.min(axis=1)
    off = fp != face_part[:, None]
    if not off.any():
        return dataclasses.replace(mesh, parts=parts)
    # one copy per (vertex, part) that some triangle needs
    wanted = f[off].astype(np.int64) * 256 + np.broadcast_to(face_part[:, None], f.shape)[off]
    keys, slot = np.unique(wanted, return_inverse=True)
    src = keys // 256
    faces = f.copy()
    faces[off] = mesh.n_vertices + slot.reshape(-1)
    return CharacterMesh(
        vertices=np.concatenate([mesh.vertices, mesh.vertices[src]]),
        normals=np.concatenate([mesh.normals, mesh.normals[src]]),
        faces=faces.astype(np.int32),
        joints=np.concatenate([mesh.joints, mesh.joints[src]]),
        weights=np.concatenate([mesh.weights, mesh.weights[src]]),
        parts=np.concatenate([parts, (keys % 256).astype(np.uint8)]),
    )


def paint(mesh: CharacterMesh, presence: JointPresence, scheme: str) -> tuple[CharacterMesh, np.ndarray]:
    """The mesh ready to colour vertex by vertex, and its palette.

    Parameters
    ----------
    mesh : CharacterMesh
        A body from :func:`gesturekit.character.mesh.build_mesh`.
    presence : JointPresence
        Which joints the motion records, derives or lacks.
    scheme : str
        A key of :data:`gesturekit.character.look.SCHEMES`.

    Returns
    -------
    mesh : CharacterMesh
        Split at the seams between colours (:func:`split_at_part_seams`); its ``parts`` index the
        palette: the parts of :data:`~gesturekit.character.mesh.PARTS`, then ``len(PARTS)`` for a
        vertex led by a derived joint.
    palette : np.ndarray, shape (len(PARTS) + 1, 3)
        sRGB in [0, 1]: the scheme's part colours, then :data:`DERIVED_COLOR`.

    Raises
    ------
    ConfigError
        An unknown scheme.
    """
    palette = np.vstack([part_colors(scheme), [[int(DERIVED_COLOR[i : i + 2], 16) / 255 for i in (1, 3, 5)]]])
    derived = np.array([s == DERIVED for s in presence.status])
    lead = mesh.joints[np.arange(mesh.n_vertices), np.argmax(mesh.weights, axis=1)]
    return split_at_part_seams(mesh, np.where(derived[lead], len(PARTS), mesh.parts).astype(np.uint8)), palette
