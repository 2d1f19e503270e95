"""Linear blend skinning: a mesh's vertices in a pose, as a GPU places them.

One blend (:func:`linear_blend`) serves our character (:class:`~.mesh.CharacterMesh` on a
:class:`~.rig.Rig`) and a user's (:class:`~.target.CharacterSkin` posed by
:meth:`~.retarget.Retargeted.skinning`, :func:`pose_skin`).
"""

from __future__ import annotations

import numpy as np

from .._arguments import checks_arguments
from .mesh import CharacterMesh
from .rig import Pose, Rig
from .target import CharacterSkin

__all__ = ["linear_blend", "skin_vertices", "skin_normals", "pose_skin"]


@checks_arguments
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


@checks_arguments
def linear_blend(
    joints: np.ndarray, weights: np.ndarray, matrices: np.ndarray, x: np.ndarray, *, moves: bool
) -> np.ndarray:
    """``sum_k w_k (R_{j_k} x + moves * t_{j_k})`` per vertex: the linear blend of skinning matrices.

    Parameters
    ----------
    joints : np.ndarray, shape (V, 4), int
        The bones (indices into ``matrices``' second axis) each vertex follows.
    weights : np.ndarray, shape (V, 4), float
        Their weights; a zero weight's bone is never read.
    matrices : np.ndarray, shape (n, B, 3, 4)
        Skinning matrices ``[R | t]`` of ``n`` frames: a rest point ``v`` of bone ``b`` goes to ``R v + t``.
    x : np.ndarray, shape (V, 3)
        Rest points (``moves``) or directions (normals: the rotations only).
    moves : bool
        Points (add the translations) or directions.

    Returns
    -------
    np.ndarray, shape (n, V, 3), float64
    """
    x = np.asarray(x).astype(np.float64)
    out = np.zeros((matrices.shape[0], x.shape[0], 3))
    for k in range(4):
        w = weights[:, k].astype(np.float64)
        used = w > 0
        if not used.any():
            continue
        mk = matrices[:, joints[used, k]]  # (n, used, 3, 4)
        turned = np.einsum("tvab,vb->tva", mk[..., :3], x[used])
        out[:, used] += w[used, None] * (turned + mk[..., 3] if moves else turned)
    return out


def _blend(mesh: CharacterMesh, m: np.ndarray, frames: np.ndarray | None, x: np.ndarray, *, moves: bool) -> np.ndarray:
    """:func:`linear_blend` of our mesh, skinning matrices ``m`` (frames, 55, 3, 4), of the ``frames`` chosen."""
    if frames is not None:
        m = m[np.asarray(frames)]
    return linear_blend(mesh.joints, mesh.weights, m, x, moves=moves)


@checks_arguments
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
    return _unit(_blend(mesh, pose.skinning(rig), frames, mesh.normals, moves=False))


def _unit(n: np.ndarray) -> np.ndarray:
    """Unit vectors of ``n`` (..., 3) as float32; zero where ``n`` is zero."""
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0).astype(np.float32)


@checks_arguments
def pose_skin(skin: CharacterSkin, matrices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A user's character's mesh in a pose: its vertices and its normals, as for our mesh.

    Parameters
    ----------
    skin : CharacterSkin
        The mesh in its rest pose, bound to the character's bones.
    matrices : np.ndarray, shape (n, M, 3, 4)
        Skinning matrices of ``n`` frames, e.g. :meth:`gesturekit.character.retarget.Retargeted.skinning`.

    Returns
    -------
    vertices : np.ndarray, shape (n, V, 3), float32
        ``sum_k w_k (M_{j_k} [v; 1])``, metres.
    normals : np.ndarray, shape (n, V, 3), float32
        ``normalise(sum_k w_k R_{j_k} n)`` (zero where that is zero): skinned as :func:`skin_normals` does.
    """
    m = np.asarray(matrices, dtype=np.float64)
    vertices = linear_blend(skin.joints, skin.weights, m, skin.vertices, moves=True).astype(np.float32)
    return vertices, _unit(linear_blend(skin.joints, skin.weights, m, skin.normals, moves=False))
