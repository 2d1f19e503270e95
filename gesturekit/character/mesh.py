"""The character's body: one triangle mesh bound to a rig's rest pose.

:func:`build_mesh` makes the body around a :class:`~gesturekit.character.rig.Rig`
(so it takes the motion's bone lengths) out of gesturekit's own geometry: no
third-party asset. Each vertex is bound to at most four joints
(:attr:`CharacterMesh.joints`, :attr:`CharacterMesh.weights`), the layout glTF
and three.js skin with, and belongs to one of :data:`PARTS`, which
:mod:`gesturekit.character.look` colours.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix

from .._arguments import checks_arguments
from ..errors import ConfigError
from ._body import body_pieces
from ._loft import signed_volume
from .rig import Rig

__all__ = ["PARTS", "CharacterMesh", "build_mesh", "vertex_normals"]

#: What each vertex is made of; a colour scheme gives each its colour.
PARTS = ("skin", "shirt", "face", "trousers", "shoes")


@dataclass(frozen=True)
class CharacterMesh:
    """A skinned triangle mesh in a rig's rest pose.

    Attributes
    ----------
    vertices : np.ndarray, shape (V, 3), float32
        Rest-pose positions, metres, in the rig's frame (:attr:`Rig.rest`).
    normals : np.ndarray, shape (V, 3), float32
        Unit outward normals in the rest pose.
    faces : np.ndarray, shape (F, 3), int32
        Vertex indices, counter-clockwise seen from outside.
    joints : np.ndarray, shape (V, 4), uint8
        The joints each vertex is bound to (unused slots: weight 0).
    weights : np.ndarray, shape (V, 4), float32
        Their weights, non-negative, each row summing to 1.
    parts : np.ndarray, shape (V,), uint8
        Index into :data:`PARTS`.
    """

    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    parts: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])


@checks_arguments
def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals, shape (..., V, 3), of vertices (..., V, 3) and faces (F, 3)."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c = v[..., faces[:, 0], :], v[..., faces[:, 1], :], v[..., faces[:, 2], :]
    fn = np.cross(b - a, c - a)
    flat = np.moveaxis(fn.reshape(-1, fn.shape[-2], 3), 1, 0).reshape(fn.shape[-2], -1)  # (F, frames * 3)
    # each face's normal added to its three corners: one sparse product for every frame at once
    corners = np.asarray(faces, dtype=np.int64).T.ravel()
    rows = np.tile(np.arange(len(faces)), 3)
    incidence = csr_matrix((np.ones(len(corners)), (corners, rows)), shape=(v.shape[-2], len(faces)))
    acc = np.moveaxis((incidence @ flat).reshape(v.shape[-2], -1, 3), 1, 0)
    n = acc.reshape(v.shape)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


@checks_arguments
def build_mesh(rig: Rig, *, detail: float = 1.0) -> CharacterMesh:
    """The character's body around a rig's rest pose.

    A neutral, half-body presenter cut at the waist: torso (closed below
    ``spine_mid``), neck, a head with eyes, brows, nose and mouth (it shows
    which way it faces), arms whose forearms run into the palms, and five
    fingers per hand whose segments follow the finger joints (the thumb from
    its CMC). Every piece is one closed surface; pieces overlap where they
    meet (the fingers' roots in the palm, the shoulders' balls in the torso,
    the neck in the torso and head). Each limb's rings blend the two joints
    on either side of a joint across about a limb's radius, so elbows, wrists
    and finger joints bend without cracks; the shoulders and knuckles are
    balls that turn about their joint.

    Parameters
    ----------
    rig : Rig
        Its rest pose (T-pose) and bone lengths: the body scales with the
        shoulder width, the head's and the hand's sizes. Joints not in the rig
        (``parents == -2``) get no body: their pieces are left out.
    detail : float
        Scales the number of rings and of vertices around them (1: about
        5,500 vertices for a full skeleton).

    Returns
    -------
    CharacterMesh

    Raises
    ------
    ConfigError
        ``detail`` not positive, or a rig that places no piece at all.
    """
    if not detail > 0:
        raise ConfigError(f"a character mesh needs a positive detail, got {detail}")
    pieces = body_pieces(rig, float(detail))
    if not pieces:
        raise ConfigError("the rig's joints place no piece of the character's body (no torso, head or arm)")
    verts, faces, weights, parts = [], [], [], []
    base = 0
    for p in pieces:
        f = p.faces
        if signed_volume(p.vertices, f) < 0:
            f = f[:, ::-1]
        verts.append(p.vertices)
        faces.append(f + base)
        weights.append(p.weights)
        parts.append(p.part)
        base += len(p.vertices)
    v = np.concatenate(verts)
    f = np.concatenate(faces).astype(np.int32)
    joints, w = _top4(np.concatenate(weights), rig)
    return CharacterMesh(
        vertices=v.astype(np.float32),
        normals=vertex_normals(v, f).astype(np.float32),
        faces=f,
        joints=joints,
        weights=w,
        parts=np.concatenate(parts).astype(np.uint8),
    )


def _top4(weights: np.ndarray, rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """The four heaviest joints per vertex (ties: the lower index) and their weights, renormalised."""
    w = np.where(np.asarray(rig.parents)[None] >= -1, np.clip(weights, 0.0, None), 0.0)
    order = np.argsort(-w, axis=1, kind="stable")[:, :4]
    top = np.take_along_axis(w, order, axis=1)
    top[top < 1e-3] = 0.0  # a trace of a joint moves nothing visibly
    top /= top.sum(axis=1, keepdims=True)
    # unused slots point at the root, weight 0
    joints = np.where(top > 0, order, rig.root)
    return joints.astype(np.uint8), top.astype(np.float32)
