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

from ..skeleton import JOINT_NAMES, N_JOINTS, PARENTS
from .rig import Rig

__all__ = ["PARTS", "CharacterMesh", "build_mesh", "vertex_normals"]

#: What each vertex is made of; a colour scheme gives each its colour.
PARTS = ("skin", "shirt", "face")


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


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals, shape (..., V, 3), of vertices (..., V, 3) and faces (F, 3)."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c = v[..., faces[:, 0], :], v[..., faces[:, 1], :], v[..., faces[:, 2], :]
    fn = np.cross(b - a, c - a)
    flat = fn.reshape(-1, fn.shape[-2], 3)
    acc = np.zeros((flat.shape[0], v.shape[-2], 3))
    for k in range(3):
        for i in range(flat.shape[0]):
            np.add.at(acc[i], faces[:, k], flat[i])
    n = acc.reshape(v.shape)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


def _radius(j: int) -> float:
    name = JOINT_NAMES[j]
    if name.endswith(("1", "2", "3", "4")):
        return 0.008
    if "elbow" in name or "wrist" in name:
        return 0.035
    if "shoulder" in name:
        return 0.045
    if "collar" in name:
        return 0.05
    if "neck" in name:
        return 0.05
    return 0.12


def build_mesh(rig: Rig, *, segments: int = 12) -> CharacterMesh:
    """The character's body around a rig's rest pose.

    Parameters
    ----------
    rig : Rig
        Its rest pose and bone lengths; joints not in the rig get no body.
    segments : int
        Vertices around each limb's cross-section.

    Returns
    -------
    CharacterMesh
    """
    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    joints: list[np.ndarray] = []
    parts: list[np.ndarray] = []
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    for c in range(N_JOINTS):
        p = int(rig.parents[c])
        if p < 0:
            continue
        a, b = rig.rest[p], rig.rest[c]
        axis = b - a
        length = float(np.linalg.norm(axis))
        if length < 1e-6:
            continue
        axis = axis / length
        u = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(axis, u)
        r = _radius(int(PARENTS[c]) if PARENTS[c] >= 0 else c)
        ring = np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w
        base = int(sum(len(x) for x in verts))
        verts.append(np.concatenate([a + r * ring, b + r * ring, [a, b]]))
        k = np.arange(segments)
        k1 = (k + 1) % segments
        faces.append(
            np.concatenate(
                [
                    np.stack([k, k1, segments + k1], -1),
                    np.stack([k, segments + k1, segments + k], -1),
                    np.stack([np.full(segments, 2 * segments), k1, k], -1),
                    np.stack([np.full(segments, 2 * segments + 1), segments + k, segments + k1], -1),
                ]
            )
            + base
        )
        joints.append(np.full(2 * segments + 2, p))
        parts.append(np.full(2 * segments + 2, 0 if "wrist" in JOINT_NAMES[p] or "head" in JOINT_NAMES[p] else 1))
    v = np.concatenate(verts).astype(np.float32)
    f = np.concatenate(faces).astype(np.int32)
    j4 = np.zeros((len(v), 4), np.uint8)
    j4[:, 0] = np.concatenate(joints)
    w4 = np.zeros((len(v), 4), np.float32)
    w4[:, 0] = 1.0
    return CharacterMesh(
        vertices=v,
        normals=vertex_normals(v, f).astype(np.float32),
        faces=f,
        joints=j4,
        weights=w4,
        parts=np.concatenate(parts).astype(np.uint8),
    )
