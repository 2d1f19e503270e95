"""Bone lengths: one length per bone, directions kept, one skeleton for many takes (gesturekit.bones) and
joint presence (skeleton)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.bones import (
    FIT_TOLERANCE,
    RIGID_GROUPS,
    Skeleton,
    bone_length_spread,
    bone_samples,
    fit_bone_lengths,
    fit_skeleton,
    group_frames,
    normalise_bone_lengths,
)
from gesturekit.errors import ConfigError
from gesturekit.skeleton import FINGERS, JOINT_NAMES, N_JOINTS, PARENTS, JointPresence, missing_required


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


# ---- one skeleton for many takes ---------------------------------------------------------------------


def _takes_of_one_body(seed: int, sizes: list[float], frames: int, jitter: float = 0.02) -> list[np.ndarray]:
    """Takes of one body lifted at different ``sizes``: every bone its base vector times the take's
    size, plus noise per frame (bone lengths and the fans of the rigid groups vary per frame)."""
    rng = np.random.default_rng(seed)
    base = rng.normal(0, 0.1, (N_JOINTS, 3))
    out = []
    for size in sizes:
        bones = size * (base + rng.normal(0, jitter, (frames, N_JOINTS, 3)))
        pos = np.zeros((frames, N_JOINTS, 3))
        for j in range(1, N_JOINTS):  # parents precede children
            pos[:, j] = pos[:, PARENTS[j]] + bones[:, j]
        out.append(pos)
    return out


def _in_group_frame(pos: np.ndarray, group: str) -> np.ndarray:
    """Every child of ``group`` relative to it, in the group's frame made from ``pos`` itself: (frames, children, 3)."""
    frames, ok = group_frames(pos, group)
    assert ok.all()
    j = JOINT_NAMES.index(group)
    children = np.flatnonzero(PARENTS == j)
    return np.einsum("tji,tcj->tci", frames, pos[:, children] - pos[:, j, None])


@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 10_000), sizes=st.lists(st.floats(0.6, 1.5), min_size=1, max_size=4), frames=st.integers(1, 30)
)
def test_one_skeleton_gives_every_take_its_lengths_and_shapes(seed, sizes, frames):
    takes = _takes_of_one_body(seed, sizes, frames)
    skeleton = fit_skeleton([bone_samples(p) for p in takes])
    assert set(skeleton.rigid) == set(RIGID_GROUPS)
    child = np.flatnonzero(PARENTS >= 0)
    for pos in takes:
        out, report = normalise_bone_lengths(pos, skeleton=skeleton)
        lengths = np.linalg.norm(out[:, child] - out[:, PARENTS[child]], axis=-1)
        # every bone the one fitted length, in every frame of every take
        np.testing.assert_allclose(lengths, np.broadcast_to(skeleton.lengths[child], lengths.shape), atol=1e-6)
        for group in RIGID_GROUPS:
            children = np.flatnonzero(PARENTS == JOINT_NAMES.index(group))
            # the children at their fixed offsets in the group's frame, which turns as the data's does
            np.testing.assert_allclose(
                _in_group_frame(out, group), np.broadcast_to(skeleton.offsets[children], (frames, len(children), 3)),
                atol=1e-6,
            )  # fmt: skip
            turned, ok = group_frames(pos, group)  # (where the data's frame is not defined, an earlier one's)
            np.testing.assert_allclose(group_frames(out, group)[0][ok], turned[ok], atol=1e-6)
        assert report.misfit is not None and report.misfit >= 0
        # bones outside the rigid groups keep their directions
        loose = np.array([j for j in child if JOINT_NAMES[PARENTS[j]] not in RIGID_GROUPS])
        d_in, d_out = pos[:, loose] - pos[:, PARENTS[loose]], out[:, loose] - out[:, PARENTS[loose]]
        cos = np.sum(d_in * d_out, axis=-1) / np.linalg.norm(d_in, axis=-1) / np.linalg.norm(d_out, axis=-1)
        np.testing.assert_allclose(cos, 1.0, atol=1e-9)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), sizes=st.lists(st.floats(0.6, 1.5), min_size=1, max_size=4))
def test_the_skeleton_lengths_are_medians_over_every_frame_of_every_take(seed, sizes):
    takes = _takes_of_one_body(seed, sizes, frames=7)
    samples = [bone_samples(p) for p in takes]
    skeleton = fit_skeleton(samples)
    every = np.concatenate(takes)
    child = np.flatnonzero(PARENTS >= 0)
    want = np.median(np.linalg.norm(every[:, child] - every[:, PARENTS[child]], axis=-1), axis=0)
    np.testing.assert_allclose(skeleton.lengths[child], want, rtol=1e-6)  # (samples are float32)
    assert (skeleton.takes, skeleton.frames) == (len(sizes), 7 * len(sizes))
    # read row by row (as a database build does, from disk) the fit is the same
    by_row = fit_skeleton(lambda i: np.concatenate([s[i] for s in samples]), takes=len(samples))
    np.testing.assert_array_equal(by_row.lengths, skeleton.lengths)
    np.testing.assert_array_equal(by_row.offsets, skeleton.offsets)


def test_a_skeleton_round_trips_through_json_and_bad_ones_are_refused():
    skeleton = fit_skeleton([bone_samples(p) for p in _takes_of_one_body(4, [1.0, 1.2], 9)])
    data = json.loads(json.dumps(skeleton.to_json()))
    again = Skeleton.from_json(data)
    np.testing.assert_array_equal(again.lengths, skeleton.lengths)
    np.testing.assert_array_equal(again.offsets, skeleton.offsets)
    assert again.digest() == skeleton.digest() and again.rigid == skeleton.rigid
    for broken, problem in [
        ({**data, "lengths": {"no_such_joint": 1.0}}, "unknown joints"),
        ({**data, "lengths": {**data["lengths"], "neck": -1.0}}, "length of neck"),
        ({**data, "offsets": {**data["offsets"], "neck": [0.0, 1.0]}}, "offset of neck"),
        ({**data, "rigid": ["pelvis"]}, "unknown rigid groups"),
        ({**data, "takes": "3"}, "integers"),
        ([], "must be an object"),
    ]:
        with pytest.raises(ConfigError, match=problem):
            Skeleton.from_json(broken)


def test_a_take_that_does_not_fit_the_skeleton_is_named_with_its_bone():
    skeleton = fit_skeleton([bone_samples(p) for p in _takes_of_one_body(8, [1.0], 9, jitter=0.0)])
    near = skeleton.lengths * (1 + FIT_TOLERANCE * 0.9)
    skeleton.check_fits(near, take="near")
    far = skeleton.lengths.copy()
    far[JOINT_NAMES.index("right_middle1")] *= 1 + FIT_TOLERANCE * 1.2
    with pytest.raises(ConfigError, match=r"take 'far' does not fit the database's skeleton: its bone right_middle1"):
        skeleton.check_fits(far, take="far")


def test_a_hand_without_finger_roots_is_not_held_rigid():
    hand = [n for n in JOINT_NAMES if n.startswith("left_") and n[5:].startswith(FINGERS)]
    presence = JointPresence.from_names(recorded=[n for n in JOINT_NAMES if n not in hand])
    takes = _takes_of_one_body(2, [1.0, 1.1], 6)
    skeleton = fit_skeleton([bone_samples(p) for p in takes], presence=presence)
    assert "left_wrist" not in skeleton.rigid and "right_wrist" in skeleton.rigid
    assert all(skeleton.lengths[JOINT_NAMES.index(n)] == 0 for n in hand)
    out, _ = normalise_bone_lengths(takes[0], presence, skeleton=skeleton)
    for n in hand:
        np.testing.assert_array_equal(out[:, JOINT_NAMES.index(n)], out[:, PARENTS[JOINT_NAMES.index(n)]])
