"""From joint positions to the rotations that drive a character: the one solve every consumer shares.

A :class:`Rig` is the hierarchy of a motion's drawn joints
(:func:`gesturekit.character.solve.bvh_parents`), its bone lengths
(medians over the motion) and a rest pose: a T-pose facing +Z, arms along
X, spine and head up (Y), fingers straight. A :class:`Pose` is every joint's
rotation relative to its parent and the root's position, per frame, found by
:func:`gesturekit.character.solve.solve_rotations`: each bone is swung from
its rest direction onto the motion's, a joint with several children takes
the rotation that best fits them all, and the twist of the spine and the
forearms follows the collars and the knuckles. Forward kinematics of the rig
with the pose gives back the motion's joint positions (to within the bone
lengths' spread).

Skinning uses, for joint ``j``, the matrix ``G_j(t) @ inv(B_j)``: ``G_j`` is the
joint's world transform in the pose (rotation and position), ``B_j`` its world
transform in the rest pose (identity rotation at :attr:`Rig.rest`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._arguments import checks_arguments
from ..bones import fit_bone_lengths
from ..errors import ConfigError
from ..motion import Motion
from ..skeleton import N_JOINTS, PARENTS

__all__ = ["Rig", "Pose", "rig_for", "solve_pose", "rotation_to_quaternion"]


@dataclass(frozen=True)
class Rig:
    """A motion's joint hierarchy, bone lengths and rest pose.

    Attributes
    ----------
    parents : np.ndarray, shape (55,), int64
        Each joint's parent in the rig, ``-1`` for the root and ``-2`` for a joint that is not in it
        (absent from the data).
    offsets : np.ndarray, shape (55, 3), float64
        Offset of every joint from its parent in the rest pose, metres (zero for the root and joints
        not in the rig).
    rest : np.ndarray, shape (55, 3), float64
        World position of every joint in the rest pose, metres, the root at the origin (joints not in
        the rig sit on their nearest ancestor in it).
    lengths : np.ndarray, shape (55,), float64
        Length of each joint's bone from its parent in the rig, metres.
    """

    parents: np.ndarray
    offsets: np.ndarray
    rest: np.ndarray
    lengths: np.ndarray

    @property
    def root(self) -> int:
        """Index of the root joint."""
        return int(np.flatnonzero(self.parents == -1)[0])

    @property
    def in_rig(self) -> np.ndarray:
        """Shape (55,), bool: the joints the rig animates."""
        return self.parents >= -1


@dataclass(frozen=True)
class Pose:
    """Joint rotations over time.

    Attributes
    ----------
    local : np.ndarray, shape (frames, 55, 3, 3), float64
        Rotation of every joint relative to its parent (the root's: in the world); the identity for
        joints not in the rig.
    root : np.ndarray, shape (frames, 3), float64
        Position of the root joint, metres.
    """

    local: np.ndarray
    root: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.local.shape[0])

    def world(self, rig: Rig) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: every joint's rotation and position in the world.

        Returns
        -------
        rotations : np.ndarray, shape (frames, 55, 3, 3)
        positions : np.ndarray, shape (frames, 55, 3)
            Metres. Joints not in the rig take their nearest ancestor's transform.
        """
        n = self.n_frames
        rot = np.empty((n, N_JOINTS, 3, 3))
        pos = np.empty((n, N_JOINTS, 3))
        for j in range(N_JOINTS):
            p = int(rig.parents[j])
            if p == -1:
                rot[:, j] = self.local[:, j]
                pos[:, j] = self.root
            elif p >= 0:
                rot[:, j] = rot[:, p] @ self.local[:, j]
                pos[:, j] = pos[:, p] + rot[:, p] @ rig.offsets[j]
        for j in range(N_JOINTS):  # parents precede children, so an ancestor is already placed
            if rig.parents[j] == -2:
                a = _anchor(rig, j)
                rot[:, j], pos[:, j] = rot[:, a], pos[:, a]
        return rot, pos

    def skinning(self, rig: Rig) -> np.ndarray:
        """Skinning matrices ``G_j @ inv(B_j)``, shape (frames, 55, 3, 4): a rest-pose point ``v`` bound
        to joint ``j`` goes to ``M[..., :3] @ v + M[..., 3]``."""
        rot, pos = self.world(rig)
        m = np.empty((self.n_frames, N_JOINTS, 3, 4))
        m[..., :3] = rot
        m[..., 3] = pos - np.einsum("tjab,jb->tja", rot, rig.rest)
        return m


def _anchor(rig: Rig, j: int) -> int:
    """The nearest ancestor of ``j`` in the rig (the root when none)."""
    p = int(PARENTS[j])
    while p >= 0 and rig.parents[p] == -2:
        p = int(PARENTS[p])
    return p if p >= 0 else rig.root


@checks_arguments
def rig_for(motion: Motion, *, rest: np.ndarray | None = None) -> Rig:
    """The rig of a motion: its drawn joints' hierarchy, median bone lengths and a T-pose.

    Parameters
    ----------
    motion : Motion
        Positions (frames, 55, 3), metres; at least one frame, all finite.
    rest : np.ndarray, shape (55, 3), optional
        Joint positions whose bone directions make the rest pose (as for
        :func:`gesturekit.export.bvh.export_bvh`); default the T-pose.

    Raises
    ------
    ConfigError
        No frame, positions not finite, or drawn joints that do not form one tree.
    """
    from .solve import bvh_parents, rest_offsets

    positions = _checked(motion)
    parents = bvh_parents(motion.presence)
    lengths = fit_bone_lengths(positions, motion.presence)
    # a joint hanging from an ancestor other than its skeleton parent (absent joints between): its bone is
    # the distance to that ancestor
    for b in np.flatnonzero((parents >= 0) & (parents != PARENTS)):
        lengths[b] = float(np.median(np.linalg.norm(positions[:, b] - positions[:, parents[b]], axis=-1)))
    offsets, _ = rest_offsets(positions, lengths=lengths, parents=parents, rest=rest)
    rest_pos = np.zeros((N_JOINTS, 3))
    for j in range(N_JOINTS):
        if parents[j] >= 0:
            rest_pos[j] = rest_pos[parents[j]] + offsets[j]
    rig = Rig(parents=parents, offsets=offsets, rest=rest_pos, lengths=lengths)
    for j in range(N_JOINTS):
        if parents[j] == -2:
            rest_pos[j] = rest_pos[_anchor(rig, j)]
    return rig


@checks_arguments
def solve_pose(motion: Motion, rig: Rig | None = None) -> Pose:
    """The rotations that move ``rig``'s rest pose onto the motion's joint positions, frame by frame.

    Parameters
    ----------
    motion : Motion
        Positions (frames, 55, 3), metres.
    rig : Rig, optional
        Default :func:`rig_for` of the motion.

    Returns
    -------
    Pose
    """
    from .solve import solve_rotations

    positions = _checked(motion)
    rig = rig_for(motion) if rig is None else rig
    local, root = solve_rotations(positions, rig.offsets, rig.parents)
    return Pose(local=local, root=root)


def _checked(motion: Motion) -> np.ndarray:
    if not isinstance(motion, Motion):
        raise ConfigError(f"a character needs a gesturekit Motion, got {type(motion).__name__}")
    if motion.n_frames == 0:
        raise ConfigError("a character cannot be posed by a motion without frames")
    positions = motion.positions.astype(np.float64)
    bad = ~np.isfinite(positions).all(axis=(1, 2))
    if bad.any():
        raise ConfigError(f"positions are not finite (NaN or infinite) from frame {int(np.argmax(bad))} on")
    return positions


@checks_arguments
def rotation_to_quaternion(r: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)`` (glTF's and three.js's order) of rotation matrices.

    Parameters
    ----------
    r : np.ndarray, shape (..., 3, 3)

    Returns
    -------
    np.ndarray, shape (..., 4)
        With ``w >= 0``.
    """
    r = np.asarray(r, dtype=np.float64)
    m = r.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    # Shepperd's method: divide by the largest of 4w^2, 4x^2, 4y^2, 4z^2, so no branch loses precision
    case = np.argmax(np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=-1), axis=-1)
    q = np.empty((len(m), 4))
    d21, d02, d10 = m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]
    s21, s02, s10 = m[:, 2, 1] + m[:, 1, 2], m[:, 0, 2] + m[:, 2, 0], m[:, 1, 0] + m[:, 0, 1]
    for k in range(4):
        i = case == k
        if not i.any():
            continue
        a = m[i]
        if k == 0:
            t = 1 + tr[i]
            q[i] = np.stack([d21[i], d02[i], d10[i], t], axis=-1)
        elif k == 1:
            t = 1 + a[:, 0, 0] - a[:, 1, 1] - a[:, 2, 2]
            q[i] = np.stack([t, s10[i], s02[i], d21[i]], axis=-1)
        elif k == 2:
            t = 1 - a[:, 0, 0] + a[:, 1, 1] - a[:, 2, 2]
            q[i] = np.stack([s10[i], t, s21[i], d02[i]], axis=-1)
        else:
            t = 1 - a[:, 0, 0] - a[:, 1, 1] + a[:, 2, 2]
            q[i] = np.stack([s02[i], s21[i], t, d10[i]], axis=-1)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q *= np.where(q[:, 3:] < 0, -1.0, 1.0)
    return q.reshape(r.shape[:-2] + (4,))
