"""Rotations and forward kinematics shared by the BVH reader and the generated demo speaker.

Internal layout: components first, time last (quaternions (4, J, F),
translations (3, J, F), matrices (3, 3, J, F)), so that every component is a
contiguous vector over frames and the arithmetic below is a few dozen fast
vector operations per joint rather than many tiny 3x3 products.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["world_positions", "quat_mul", "quat_to_matrix", "slerp"]


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (w, x, y, z) stored components first: (4, ...)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions (w, x, y, z): (4, ...) -> (3, 3, ...)."""
    w, x, y, z = q
    m = np.empty((3, 3) + q.shape[1:])
    m[0, 0] = 1 - 2 * (y * y + z * z)
    m[0, 1] = 2 * (x * y - w * z)
    m[0, 2] = 2 * (x * z + w * y)
    m[1, 0] = 2 * (x * y + w * z)
    m[1, 1] = 1 - 2 * (x * x + z * z)
    m[1, 2] = 2 * (y * z - w * x)
    m[2, 0] = 2 * (x * z - w * y)
    m[2, 1] = 2 * (y * z + w * x)
    m[2, 2] = 1 - 2 * (x * x + y * y)
    return m


def slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical interpolation of unit quaternions (4, ...) with weights ``w`` (...), shortest path."""
    dot = np.sum(q0 * q1, axis=0)
    q1 = np.where(dot < 0, -q1, q1)  # q and -q are the same rotation
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-8
    safe = np.where(small, 1.0, sin_theta)
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    q = a * q0 + b * q1
    return q / np.linalg.norm(q, axis=0)


def world_positions(parents: Sequence[int] | np.ndarray, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """Forward kinematics: world positions of every joint from local rotations and translations.

    A joint's local transform is its translation followed by its rotation:
    ``world_rot[j] = world_rot[p] @ rot[j]`` and ``world_pos[j] = world_pos[p]
    + world_rot[p] @ trans[j]`` for the parent ``p``; a root (parent -1) is
    placed at its translation with its rotation.

    Parameters
    ----------
    parents : sequence of int, length J
        Parent of each joint, ``-1`` for a root; parents precede children.
    rot : np.ndarray, shape (3, 3, J, F)
        Each joint's rotation relative to its parent (a root's is global).
    trans : np.ndarray, shape (3, J, F)
        Each joint's offset from its parent, in the parent's frame (a root's
        is its world position), in any length unit.

    Returns
    -------
    np.ndarray, shape (F, J, 3)
        World positions, in the unit of ``trans``.
    """
    world_rot = np.empty_like(rot)
    world_pos = np.empty_like(trans)
    for j, p in enumerate(parents):
        if p < 0:
            world_rot[:, :, j] = rot[:, :, j]
            world_pos[:, j] = trans[:, j]
            continue
        a, b, t = world_rot[:, :, p], rot[:, :, j], trans[:, j]
        for r in range(3):
            for c in range(3):
                world_rot[r, c, j] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]
            world_pos[r, j] = world_pos[r, p] + a[r, 0] * t[0] + a[r, 1] * t[1] + a[r, 2] * t[2]
    return np.ascontiguousarray(world_pos.transpose(2, 1, 0))
