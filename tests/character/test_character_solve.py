"""The shared rotation solve: its rest pose from a long motion, and the rig's forward kinematics."""

from __future__ import annotations

import numpy as np
import pytest

from gesturekit.character import solve
from gesturekit.character.rig import rig_for, rotation_to_quaternion, solve_pose
from gesturekit.demo import open_default_database
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS, PARENTS


def _long_motion() -> Motion:
    db = open_default_database()
    return Motion(np.asarray(db.poses).reshape(-1, N_JOINTS, 3)[:9000], 15.0, db.joint_presence)


@pytest.mark.slow
def test_a_long_motions_rest_pose_from_a_spread_of_frames_is_the_whole_motions(monkeypatch):
    motion = _long_motion()
    assert motion.n_frames > solve.MEAN_SHAPE_FRAMES
    spread = rig_for(motion)
    monkeypatch.setattr(solve, "MEAN_SHAPE_FRAMES", 10**9)  # every frame
    whole = rig_for(motion)
    worst = np.abs(spread.rest - whole.rest).max()
    assert worst < 5e-4, f"rest poses differ by {worst * 1000:.3f} mm"
    # and the pose from either reproduces the motion as closely
    errors = []
    for rig in (spread, whole):
        _, pos = solve_pose(motion.slice(0, 600), rig).world(rig)
        errors.append(np.abs(pos - motion.positions[:600]).max())
    assert abs(errors[0] - errors[1]) < 5e-4, errors


def test_forward_kinematics_of_the_solved_pose_gives_back_the_positions():
    motion = _long_motion().slice(0, 256)
    rig = rig_for(motion)
    rot, pos = solve_pose(motion, rig).world(rig)
    assert np.abs(pos - motion.positions).max() < 1e-4
    # world rotations are rotations, and every joint sits at its parent plus its turned rest offset
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-9)
    j = np.flatnonzero(PARENTS >= 0)
    placed = pos[:, PARENTS[j]] + np.einsum("tjab,jb->tja", rot[:, PARENTS[j]], rig.offsets[j])
    np.testing.assert_allclose(placed, pos[:, j], atol=1e-9)


def test_quaternions_turn_as_their_matrices():
    from scipy.spatial.transform import Rotation

    r = Rotation.random(500, random_state=3)
    q = rotation_to_quaternion(r.as_matrix())
    assert (q[:, 3] >= 0).all()
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), r.as_matrix(), atol=1e-12)
    # half turns, where the w component vanishes
    half = Rotation.from_rotvec(np.pi * np.eye(3)).as_matrix()
    np.testing.assert_allclose(Rotation.from_quat(rotation_to_quaternion(half)).as_matrix(), half, atol=1e-12)
