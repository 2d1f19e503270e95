"""Bone lengths: one length per bone, directions kept (gesturekit.bones) and joint presence (skeleton)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.bones import bone_length_spread, fit_bone_lengths, normalise_bone_lengths
from gesturekit.errors import ConfigError
from gesturekit.skeleton import JOINT_NAMES, N_JOINTS, PARENTS, JointPresence, missing_required


def _random_motion(seed: int, frames: int = 12) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pos = np.zeros((frames, N_JOINTS, 3))
    for j in range(N_JOINTS):
        if PARENTS[j] >= 0:
            pos[:, j] = pos[:, PARENTS[j]] + rng.normal(0, 0.1, (frames, 3))
    return pos


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), frames=st.integers(1, 20))
def test_normalised_bones_have_one_length_and_keep_their_directions(seed, frames):
    pos = _random_motion(seed, frames)
    out, report = normalise_bone_lengths(pos)
    child = np.flatnonzero(PARENTS >= 0)
    d_in = pos[:, child] - pos[:, PARENTS[child]]
    d_out = out[:, child] - out[:, PARENTS[child]]
    lengths = np.linalg.norm(d_out, axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(report.lengths[child], lengths.shape), atol=1e-9)
    cos = np.sum(d_in * d_out, axis=-1) / (np.linalg.norm(d_in, axis=-1) * lengths)
    np.testing.assert_allclose(cos, 1.0, atol=1e-9)
    np.testing.assert_array_equal(out[:, PARENTS < 0], pos[:, PARENTS < 0])
    assert np.allclose(bone_length_spread(out), 0.0, atol=1e-9)
    assert report.max_shift >= report.mean_shift >= 0


def test_constant_bones_are_left_as_they_are():
    pos = _random_motion(3, 1).repeat(5, axis=0)
    out, report = normalise_bone_lengths(pos)
    np.testing.assert_allclose(out, pos, atol=1e-12)
    assert report.max_shift < 1e-9


def test_the_length_is_the_median_and_a_zero_length_bone_borrows_an_earlier_direction():
    pos = _random_motion(5, 5)
    j = JOINT_NAMES.index("left_elbow")
    p = PARENTS[j]
    pos[2, j] = pos[2, p]  # the bone vanishes in frame 2
    lengths = np.linalg.norm(pos[:, j] - pos[:, p], axis=-1)
    assert fit_bone_lengths(pos)[j] == pytest.approx(np.median(lengths))
    out, _ = normalise_bone_lengths(pos)
    before = out[1, j] - out[1, p]
    during = out[2, j] - out[2, p]
    np.testing.assert_allclose(during, before, atol=1e-12)


def test_absent_joints_sit_on_their_parent():
    presence = JointPresence.from_names(recorded=[n for n in JOINT_NAMES if n != "left_thumb4"])
    out, report = normalise_bone_lengths(_random_motion(2), presence)
    j = JOINT_NAMES.index("left_thumb4")
    np.testing.assert_array_equal(out[:, j], out[:, PARENTS[j]])
    assert report.lengths[j] == 0.0


def test_bad_shapes_are_refused():
    with pytest.raises(ConfigError, match="shape"):
        normalise_bone_lengths(np.zeros((4, 10, 3)))
    with pytest.raises(ConfigError, match="lengths"):
        normalise_bone_lengths(_random_motion(1), lengths=np.full(N_JOINTS, -1.0))


def test_presence_states_and_drawn_bones():
    presence = JointPresence.from_names(
        recorded=[n for n in JOINT_NAMES if not n.startswith(("spine", "chest", "head")) and "thumb" not in n],
        derived=["spine_mid", "chest", "head", "head_top"],
    )
    assert presence.derived.sum() == 4 and presence.absent.sum() == 8
    assert not presence.is_full and JointPresence.full().is_full
    drawn = presence.drawn
    for child, parent in presence.drawn_bones():
        assert drawn[child] and drawn[parent]
    assert "4 derived (spine_mid, chest, head, head_top)" in presence.describe()
    assert JointPresence(tuple(presence.to_list())) == presence
    with pytest.raises(ValueError, match="status"):
        JointPresence(("recorded",) * 54 + ("missing",))
    with pytest.raises(ValueError, match="one status per joint"):
        JointPresence(("recorded",) * 3)


def test_missing_required_names_each_need_and_joint():
    everything = set(JOINT_NAMES)
    assert missing_required(everything) == []
    lines = missing_required(everything - {"left_pinky1", "right_wrist"})
    assert any("pose feature" in line and "left_pinky1" in line and "right_wrist" in line for line in lines)
    assert any("hand controls" in line and "right_wrist" in line and "left_pinky1" not in line for line in lines)


def test_the_database_keeps_which_joints_are_real(tmp_path):
    from dataclasses import replace

    from gesturekit.database import BuildConfig, MatchingDatabase
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.motion import Motion

    presence = JointPresence.from_names(
        recorded=[n for n in JOINT_NAMES if "thumb" not in n and n != "head_top"], derived=["head_top"]
    )
    takes = []
    for i in range(2):
        take, _ = generate_demo_take(seconds=12, seed=i, name=f"t{i}")
        takes.append(replace(take, motion=Motion(take.motion.positions, take.motion.fps, presence)))
    db = MatchingDatabase.build(takes, config=BuildConfig())
    db.save(tmp_path / "db")
    loaded = MatchingDatabase.load(tmp_path / "db")
    assert loaded.joint_presence == presence

    mixed = [takes[0], replace(takes[1], motion=Motion(takes[1].motion.positions, takes[1].motion.fps))]
    with pytest.raises(ConfigError, match="'t1' holds other joints"):
        MatchingDatabase.build(mixed, config=BuildConfig())
