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
    return _blend(mesh, pose.skinning(rig), frames, mesh.vertices, moves=True).astype(np.float32)


def _blend(mesh: CharacterMesh, m: np.ndarray, frames: np.ndarray | None, x: np.ndarray, *, moves: bool) -> np.ndarray:
    """``sum_k w_k (R_{j_k} x + moves * t_{j_k})`` per vertex: skinning matrices ``m`` (frames, 55, 3, 4)
    applied to rest points (``moves``) or directions ``x`` (V, 3); shape (n, V, 3), float64."""
    if frames is not None:
        m = m[np.asarray(frames)]
    x = x.astype(np.float64)
    out = np.zeros((m.shape[0], mesh.n_vertices, 3))
    for k in range(4):
        w = mesh.weights[:, k].astype(np.float64)
        used = w > 0
        if not used.any():
            continue
        mk = m[:, mesh.joints[used, k]]  # (n, used, 3, 4)
        turned = np.einsum("tvab,vb->tva", mk[..., :3], x[used])
        out[:, used] += w[used, None] * (turned + mk[..., 3] if moves else turned)
    return out


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
    out = _blend(mesh, pose.skinning(rig), frames, mesh.normals, moves=False)
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0).astype(np.float32)
