"""Hands in the head or the torso and crossed wrists (gesturekit.character.contact); the demo speaker keeps clear."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.character.contact import CROSS_MARGIN, HEAD_MARGIN, hand_joints, pose_contacts
from gesturekit.errors import ConfigError
from gesturekit.skeleton import joint_index

LW, RW = joint_index("left_wrist"), joint_index("right_wrist")
HEAD, TOP = joint_index("head"), joint_index("head_top")
LS, RS = joint_index("left_shoulder"), joint_index("right_shoulder")
SPINE, NECK = joint_index("spine_mid"), joint_index("neck")


@pytest.fixture(scope="module")
def pose() -> np.ndarray:
    """A standing frame of the demo speaker at rest (hands low beside the hips), (55, 3) metres."""
    from gesturekit.datasets.synthetic import generate_demo_take

    take = generate_demo_take(seconds=2.0, seed=1, name="t")[0]
    return np.asarray(take.motion.positions[0], np.float64)


def _move_hand(pose: np.ndarray, side_wrist: int, side: str, to: np.ndarray) -> np.ndarray:
    """The pose with one whole hand moved rigidly so that its wrist is at ``to``."""
    out = pose.copy()
    joints = hand_joints(side)
    out[joints] += to - pose[side_wrist]
    return out


def _head_centre_and_radius(p: np.ndarray) -> tuple[np.ndarray, float]:
    """The head ball of the module notes, written out."""
    s = np.linalg.norm(p[TOP] - p[HEAD])
    up = (p[TOP] - p[HEAD]) / s
    lat = (p[LS] - p[RS]) / np.linalg.norm(p[LS] - p[RS])
    front = np.cross(lat, up)
    front /= np.linalg.norm(front)
    return p[HEAD] + 0.38 * s * up + 0.05 * s * front, s * (0.5 * (0.66 + 0.92) + 0.68 + 0.54) / 3


def test_the_rest_pose_touches_nothing(pose):
    c = pose_contacts(pose[None])
    assert c.fractions() == {"hand_in_head": 0.0, "wrists_crossed": 0.0, "hand_in_torso": 0.0}
    assert c.summary() == "hands in the head 0.0 %, wrists crossed 0.0 %, hands in the torso 0.0 % of 1 frames"


def test_a_hand_at_the_edge_of_the_head_ball(pose):
    centre, radius = _head_centre_and_radius(pose)
    out = np.asarray(pose[LS] - pose[RS])
    out /= np.linalg.norm(out)
    # the wrist out to the left of the head: no hand joint is nearer the centre than the wrist
    near = _move_hand(pose, LW, "left", centre + (HEAD_MARGIN * radius - 0.005) * out)
    far = _move_hand(pose, LW, "left", centre + (HEAD_MARGIN * radius + 0.2) * out)
    got = pose_contacts(np.stack([near, far, pose]))
    assert got.hand_in_head.tolist() == [True, False, False]


def test_crossed_wrists_are_measured_along_the_shoulder_line(pose):
    lat = (pose[LS] - pose[RS]) / np.linalg.norm(pose[LS] - pose[RS])
    mid = 0.5 * (pose[LW] + pose[RW]) + np.array([0.0, 0.3, 0.3])  # in front of the chest

    def wrists(gap: float) -> np.ndarray:  # the left wrist ``gap`` metres to the left of the right one
        p = _move_hand(pose, LW, "left", mid + 0.5 * gap * lat)
        return _move_hand(p, RW, "right", mid - 0.5 * gap * lat)

    frames = np.stack([wrists(0.1), wrists(-CROSS_MARGIN / 2), wrists(-2 * CROSS_MARGIN), wrists(-0.2)])
    assert pose_contacts(frames).wrists_crossed.tolist() == [False, False, True, True]


def test_a_hand_in_the_chest_is_in_the_torso(pose):
    chest = pose[SPINE] + 0.5 * (pose[NECK] - pose[SPINE])
    lat = (pose[LS] - pose[RS]) / np.linalg.norm(pose[LS] - pose[RS])
    inside = _move_hand(pose, LW, "left", chest)
    beside = _move_hand(pose, LW, "left", chest + 0.5 * lat)  # half a metre to the left: clear of it
    got = pose_contacts(np.stack([inside, beside]))
    assert got.hand_in_torso.tolist() == [True, False]


@settings(max_examples=25, deadline=None)
@given(
    angle=st.floats(-np.pi, np.pi), shift=st.lists(st.floats(-2, 2), min_size=3, max_size=3), which=st.integers(0, 3)
)
def test_the_measures_turn_with_the_body(pose, angle, shift, which):
    # the same body turned about the vertical and moved: the same answers
    centre, _ = _head_centre_and_radius(pose)
    frames = np.stack(
        [
            pose,
            _move_hand(pose, LW, "left", centre),
            _move_hand(pose, RW, "right", pose[LW] + np.array([0.05, 0.0, 0.0]) + 0.1 * (pose[LS] - pose[RS])),
            _move_hand(pose, LW, "left", pose[SPINE] + 0.5 * (pose[NECK] - pose[SPINE])),
        ]
    )[which : which + 1]
    c, s = np.cos(angle), np.sin(angle)
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    moved = frames @ turn.T + np.asarray(shift)
    a, b = pose_contacts(frames), pose_contacts(moved)
    for name in ("hand_in_head", "wrists_crossed", "hand_in_torso"):
        assert getattr(a, name).tolist() == getattr(b, name).tolist(), name


def test_bad_positions_are_config_errors():
    with pytest.raises(ConfigError, match="shape"):
        pose_contacts(np.zeros((3, 54, 3)))
    with pytest.raises(ConfigError, match="finite"):
        pose_contacts(np.full((2, 55, 3), np.nan))
    with pytest.raises(ConfigError, match="side"):
        hand_joints("middle")


@pytest.mark.slow
def test_the_demo_speaker_and_its_results_keep_to_a_speakers_gesture_space(tmp_path):
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.demo import build_demo_database
    from gesturekit.synthesis import SynthesisConfig, synthesize

    db = build_demo_database(tmp_path / "demo", minutes=3)
    frames = np.asarray(db.G, np.float32).reshape(-1, 55, 3)
    c = pose_contacts(frames)
    assert not c.hand_in_head.any() and not c.wrists_crossed.any(), c.summary()
    speech = generate_demo_take(seconds=30.0, seed=77, name="q")[0].audio  # a speech the database never heard
    for control in ("", "0-30:both_hands=high", "0-30:width=narrow"):
        for blend in ("none", "dead"):
            res = synthesize(speech, db=db, config=SynthesisConfig(control=control, blend=blend))
            c = pose_contacts(res.motion.positions)
            assert not c.hand_in_head.any() and not c.wrists_crossed.any(), (control, blend, c.summary())
