"""Left and right where names fail: the hierarchy's shape finds the humanoid, the rest pose its sides (issue 38).

A rig whose names say nothing (glTF nodes without names, ``bone_00``..) or say the part but not the side (``arm_a``,
``arm_b``) is matched from its tree: the pelvis carries two legs of one shape, the chest two arms of one shape, and
the arm on the character's left as it faces (where its feet point) is its left, whatever its order in the file. A
rig whose ``Left`` bones are on its right is taken by its rest pose, and a note says so.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from gesturekit.character.retarget import retarget
from gesturekit.character.shape import SHAPE, facing_from_feet, match_by_shape
from gesturekit.character.user import read_character
from gesturekit.errors import GestureKitWarning
from gesturekit.motion import Motion
from gesturekit.skeleton import joint_index
from tests.character_rigs import RigSpec, truth, write_rig

SHAPED = {
    "nameless_a": RigSpec(naming="nameless", rest="A"),
    "sideless_t": RigSpec(naming="sideless"),
    "sideless_rolled_armature": RigSpec(naming="sideless", rest="A", roll_seed=3, armature=True),
    "sideless_no_fingers": RigSpec(naming="sideless", fingers=False, spine_bones=2),
    "custom_bvh": RigSpec(naming="custom", fmt="bvh", rest="A"),
    "sideless_bvh": RigSpec(naming="sideless", fmt="bvh"),
}


@pytest.mark.parametrize("case", SHAPED)
def test_a_rig_whose_names_say_no_side_is_matched_by_its_shape(tmp_path, case):
    spec = SHAPED[case]
    ch = read_character(write_rig(tmp_path, spec, case))
    assert ch.matched_by.startswith(SHAPE)
    assert ch.matched() == truth(spec).joint_map
    # its left arm is on its left (+X in our frame, facing +Z)
    left, right = ch.rest_position[ch.bone("left_wrist")], ch.rest_position[ch.bone("right_wrist")]
    assert left[0] > 0.3 > -0.3 > right[0]


def _arrays(spec: RigSpec) -> tuple[list[int], np.ndarray, tuple[str, ...]]:
    t = truth(spec)
    return [int(p) for p in t.parents], t.rest_world, t.bone_names


@pytest.mark.parametrize("turn", [0, 90, 180, 270])
def test_the_sides_follow_the_rest_pose_not_the_files_order_or_axes(turn):
    parents, rest, names = _arrays(RigSpec(naming="sideless", rest="A"))
    a = np.radians(turn)
    about_y = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    turned = rest @ about_y.T
    found = {k: names[b] for k, b in match_by_shape(parents, turned).items()}
    assert found["left_shoulder"] == "upper_b" and found["right_wrist"] == "hand_a"
    # the same file mirrored (its 'b' arm now on its right as its feet face): the sides go with the body
    mirrored = (rest * np.array([-1.0, 1.0, 1.0])) @ about_y.T
    found = {k: names[b] for k, b in match_by_shape(parents, mirrored).items()}
    assert found["left_shoulder"] == "upper_a" and found["right_wrist"] == "hand_b"
    up = np.array([0.0, 1.0, 0.0])
    pelvis, spine = names.index("hips"), names.index("spine0")
    assert facing_from_feet(parents, turned, pelvis, spine, up) == pytest.approx(about_y @ [0, 0, 1], abs=1e-9)


def test_feet_that_point_nowhere_leave_the_facing_to_the_convention():
    parents, rest, names = _arrays(RigSpec(naming="sideless"))
    flat = rest.copy()
    for i, n in enumerate(names):  # toes pulled back under the ankles
        if n.startswith("toe"):
            flat[i, 2] = 0.0
    assert facing_from_feet(parents, flat, names.index("hips"), names.index("spine0"), np.array([0, 1.0, 0])) is None
    found = {k: names[b] for k, b in match_by_shape(parents, flat).items()}
    assert found["left_shoulder"] == "upper_b"  # +Z, glTF's forward


def test_a_tree_without_two_arms_of_one_shape_is_not_taken_for_a_humanoid():
    parents, rest, _ = _arrays(RigSpec(naming="nameless", drop=("left_collar",)))
    assert match_by_shape(parents, rest) == {}  # not a hand's fingers taken for arms


@pytest.mark.parametrize("fmt", ["glb", "bvh"])
def test_mirrored_names_are_taken_by_the_rest_pose_and_said(tmp_path, fmt):
    spec = RigSpec(naming="mirrored", rest="A", fmt=fmt)
    path = write_rig(tmp_path, spec, "mirrored")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        ch = read_character(path)
    (note,) = ch.notes
    assert "'mixamorig:LeftArm'" in note and "the other way round" in note and note.startswith(path.name)
    assert any(issubclass(w.category, GestureKitWarning) and "other way round" in str(w.message) for w in said)
    assert ch.matched_by.endswith("left and right from the rest pose")
    assert ch.matched() == truth(spec).joint_map  # the bone named LeftArm is our right shoulder
    assert ch.names[ch.bone("left_shoulder")] == "mixamorig:RightArm"
    # our left hand's motion goes to the arm on the character's left
    from gesturekit.demo import open_default_database

    db = open_default_database()
    motion = Motion(db.poses[:1].reshape(-1, 55, 3).astype(np.float32), 15.0, db.joint_presence)
    out = retarget(motion, ch)
    ours = motion.positions[:, joint_index("left_wrist")] - motion.positions[:, joint_index("left_shoulder")]
    theirs = out.position[:, ch.bone("left_wrist")] - out.position[:, ch.bone("left_shoulder")]
    cos = np.einsum("ti,ti->t", ours, theirs) / np.linalg.norm(ours, axis=1) / np.linalg.norm(theirs, axis=1)
    assert cos.min() > 0.95


def test_names_that_agree_with_the_rest_pose_are_left_alone(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)
        ch = read_character(write_rig(tmp_path, RigSpec(naming="mixamo", rest="A"), "fine"))
    assert ch.notes == () and ch.matched_by == "mixamo names"
