"""The default character stands: still hips, legs and shoes on a floor, under the moving upper body.

Built on real shapes: the demo database's clips (a speaker's pelvis-relative upper body), the
rig and pose of the shared solve, the body of :func:`gesturekit.character.mesh.build_mesh`.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from gesturekit.character._loft import signed_volume
from gesturekit.character.mesh import PARTS, build_mesh
from gesturekit.character.rig import rig_for, solve_pose
from gesturekit.character.skin import skin_vertices
from gesturekit.character.stand import HIP_HEIGHT, stand_mesh, standing_root
from gesturekit.demo import open_default_database
from gesturekit.motion import Motion
from gesturekit.skeleton import joint_index

SHOES, TROUSERS, SHIRT = PARTS.index("shoes"), PARTS.index("trousers"), PARTS.index("shirt")


@functools.cache
def _result() -> Motion:
    """Twelve consecutive clips of the demo database: 51 s of a speaker's upper body, as a result holds it."""
    db = open_default_database()
    clips = np.asarray(db.poses).reshape(len(db.poses), -1, 55, 3)
    return Motion(np.concatenate(clips[20:32]).astype(np.float32), db.fps, db.joint_presence)


def test_the_legs_stand_on_the_floor_a_person_tall():
    motion = _result()
    rig = rig_for(motion)
    stand = stand_mesh(rig, standing_root(solve_pose(motion, rig).root))
    assert stand is not None and {PARTS[p] for p in np.unique(stand.parts)} == {"trousers", "shoes"}
    v = stand.vertices.astype(np.float64)
    # the soles flat on the floor: the shoes' lowest vertices, nothing below them
    soles = v[stand.parts == SHOES]
    assert v[:, 1].min() == pytest.approx(stand.floor, abs=1e-6)
    assert np.sum(np.abs(soles[:, 1] - stand.floor) < 1e-3) > 20
    # two feet, one each side of the body, toes forward
    assert (soles[:, 0] > 0.05).any() and (soles[:, 0] < -0.05).any() and soles[:, 2].max() > 0.1
    # a person of 1.5-1.9 m: from the floor to the top of the head (pelvis-relative motion)
    top = motion.positions[:, joint_index("head_top"), 1].max()
    assert 1.5 < top - stand.floor < 1.9
    width = np.linalg.norm(rig.rest[joint_index("left_shoulder")] - rig.rest[joint_index("right_shoulder")])
    assert stand.floor == pytest.approx(standing_root(solve_pose(motion, rig).root)[1] - (0.3 + HIP_HEIGHT) * width)
    # closed surfaces facing out; unit normals
    assert signed_volume(v, stand.faces.astype(np.int64)) > 0
    np.testing.assert_allclose(np.linalg.norm(stand.normals, axis=1), 1.0, atol=1e-5)


@pytest.mark.slow
def test_over_a_whole_result_the_feet_stay_on_the_floor_and_the_torso_in_the_hips():
    motion = _result()
    rig = rig_for(motion)
    pose = solve_pose(motion, rig)
    stand = stand_mesh(rig, standing_root(pose.root))
    body = build_mesh(rig)
    moving = skin_vertices(body, rig, pose)  # (frames, V, 3): the skinned body of every frame
    # the feet: within 1 cm of the floor in every frame (the legs do not move)
    soles = stand.vertices[stand.parts == SHOES]
    assert np.abs(soles[:, 1].min() - stand.floor) < 0.01
    # the shirt's lowest point stays inside the hips in every frame: no gap at the waist, however the torso turns
    hips = stand.vertices[stand.parts == TROUSERS]
    hips = hips[hips[:, 1] > stand.floor + 0.8 * (hips[:, 1].max() - stand.floor)]  # the hips, not the legs
    top, half_width = hips[:, 1].max(), np.abs(hips[:, 0]).max()
    shirt = moving[:, body.parts == SHIRT]
    centre = np.abs(shirt[..., 0]) < 0.1  # the torso's middle, not the sleeves
    lowest = np.where(centre, shirt[..., 1], np.inf).min(axis=1)
    assert (lowest < top).all(), f"the torso leaves the hips in {(lowest >= top).sum()} of {len(lowest)} frames"
    below = shirt[..., 1] < top
    assert (np.abs(shirt[..., 0])[below] < half_width + 0.02).all()


def test_a_rig_without_a_spine_has_no_legs():
    motion = _result()
    rig = rig_for(motion)
    parents = rig.parents.copy()
    parents[joint_index("spine_mid")] = -2
    from dataclasses import replace

    assert stand_mesh(replace(rig, parents=parents), np.zeros(3)) is None
