"""Linear blend skinning: a mesh's vertices in a pose, as a GPU places them."""

from __future__ import annotations

import numpy as np

from .mesh import CharacterMesh
from .rig import Pose, Rig

__all__ = ["skin_vertices", "skin_normals"]


def skin_vertices(mesh: CharacterMesh, rig: Rig, pose: Pose, frames: np.ndarray | None = None) -> np.ndarray:
    """The mesh's vertices in the pose's frames.

    Parameters
    ----------
    mesh : CharacterMesh
        Bound to ``rig``'s rest pose.
    rig : Rig
    pose : Pose
    frames : np.ndarray, shape (n,), int, optional
        Frames to place; default all.

    Returns
    -------
    np.ndarray, shape (n, V, 3), float32
        ``sum_k w_k (M_{j_k} [v; 1])`` with the skinning matrices of :meth:`Pose.skinning`, metres.
    """
    m = pose.skinning(rig)
    if frames is not None:
        m = m[np.asarray(frames)]
    v = mesh.vertices.astype(np.float64)
    out = np.zeros((m.shape[0], mesh.n_vertices, 3))
    for k in range(4):
        w = mesh.weights[:, k].astype(np.float64)
        used = w > 0
        if not used.any():
            continue
        mk = m[:, mesh.joints[used, k]]  # (n, used, 3, 4)
        out[:, used] += w[used, None] * (np.einsum("tvab,vb->tva", mk[..., :3], v[used]) + mk[..., 3])
    return out.astype(np.float32)


def skin_normals(mesh: CharacterMesh, rig: Rig, pose: Pose, frames: np.ndarray | None = None) -> np.ndarray:
    """The mesh's rest normals carried into the pose's frames, as a GPU skins them.

    Parameters
    ----------
    mesh, rig, pose, frames
        As for :func:`skin_vertices`.

    Returns
    -------
    np.ndarray, shape (n, V, 3), float32
        ``normalise(sum_k w_k R_{j_k} n)``, with ``R`` the rotation part of the skinning matrices
        (:meth:`Pose.skinning`): three.js's skinned normal, so the MP4 shades as the page does.
    """
    m = pose.skinning(rig)[..., :3]
    if frames is not None:
        m = m[np.asarray(frames)]
    n = mesh.normals.astype(np.float64)
    out = np.zeros((m.shape[0], mesh.n_vertices, 3))
    for k in range(4):
        w = mesh.weights[:, k].astype(np.float64)
        used = w > 0
        if used.any():
            out[:, used] += w[used, None] * np.einsum("tvab,vb->tva", m[:, mesh.joints[used, k]], n[used])
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0).astype(np.float32)
