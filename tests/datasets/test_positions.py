"""Tests of gesturekit.datasets.positions: joint-position files as 55-joint motions."""

from __future__ import annotations

import json
import tempfile

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.datasets.positions import (
    PositionJointMap,
    load_position_joint_map,
    load_positions_motion,
    read_position_array,
)
from gesturekit.errors import ConfigError, InputFileError, MotionFileError
from gesturekit.motion import resample_positions
from gesturekit.skeleton import JOINT_NAMES

N_SOURCE = 60  # 55 mapped joints, a pelvis and 4 unused ones
# random positions are no upright body of human size: read them with the axes as they are, unchecked
AS_IS = {"up": "y", "forward": "z", "check_plausible": False}


def source_layout(seed=0):
    """A shuffled source joint order: returns (names, our joint -> source column, pelvis column)."""
    rng = np.random.default_rng(seed)
    names = [f"src_{i}" for i in range(N_SOURCE)]
    columns = rng.permutation(N_SOURCE)
    ours = {name: int(columns[i]) for i, name in enumerate(JOINT_NAMES)}
    pelvis = int(columns[55])
    return names, ours, pelvis


def source_positions(n_frames, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, 0.3, (n_frames, N_SOURCE, 3)) + np.array([0.0, 1.0, 0.0])


def expected(array, ours, pelvis):
    idx = [ours[n] for n in JOINT_NAMES]
    out = array[:, idx]
    return out if pelvis is None else out - array[:, [pelvis]]


@pytest.fixture
def layout(tmp_path):
    names, ours, pelvis = source_layout()
    map_path = tmp_path / "map.json"
    map_path.write_text(json.dumps({"pelvis": pelvis, "joints": ours}))
    return names, ours, pelvis, map_path


def test_npy_at_15_fps_is_selected_and_pelvis_relative(tmp_path, layout):
    names, ours, pelvis, map_path = layout
    array = source_positions(20)
    path = tmp_path / "take.npy"
    np.save(path, array)
    motion = load_positions_motion(path, joint_map=map_path, fps=15, **AS_IS)
    assert motion.fps == 15 and motion.positions.shape == (20, 55, 3)
    np.testing.assert_allclose(motion.positions, expected(array, ours, pelvis), atol=1e-6)


def test_file_formats_agree(tmp_path, layout):
    names, ours, pelvis, map_path = layout
    array = source_positions(12, seed=1)
    np.save(tmp_path / "a.npy", array.reshape(12, -1))  # (frames, joints*3)
    np.savez(tmp_path / "b.npz", array)  # a single unnamed array
    np.savez(tmp_path / "c.npz", positions=array, fps=np.array(15), other=np.zeros(3))
    np.savetxt(tmp_path / "d.txt", array.reshape(12, -1))
    np.savetxt(tmp_path / "e.csv", array.reshape(12, -1), delimiter=",")
    want = expected(array, ours, pelvis)
    for name in ("a.npy", "b.npz", "c.npz", "d.txt", "e.csv"):
        motion = load_positions_motion(tmp_path / name, joint_map=map_path, fps=15, **AS_IS)
        np.testing.assert_allclose(motion.positions, want, atol=1e-6, err_msg=name)


def test_names_null_pelvis_and_units(tmp_path):
    names, ours, pelvis = source_layout(seed=2)
    array = source_positions(6, seed=2)
    path = tmp_path / "t.npy"
    np.save(path, array * 100.0)
    by_name = {"pelvis": None, "joints": {k: names[v] for k, v in ours.items()}, "names": names}
    motion = load_positions_motion(path, joint_map=by_name, fps=15, units="cm", **AS_IS)
    np.testing.assert_allclose(motion.positions, expected(array, ours, None), atol=1e-6)
    mixed = {"pelvis": names[pelvis], "joints": {**ours, "head": names[ours["head"]]}, "names": names}
    motion = load_positions_motion(path, joint_map=mixed, fps=15, units="cm", **AS_IS)
    np.testing.assert_allclose(motion.positions, expected(array, ours, pelvis), atol=1e-6)


@settings(max_examples=25, deadline=None)
@given(fps=st.sampled_from([15, 24, 25, 29.97, 30, 50, 60, 120]), n=st.integers(8, 90))
def test_resampled_to_15_fps(fps, n):
    names, ours, pelvis = source_layout(seed=3)
    array = source_positions(n, seed=n)
    jmap = PositionJointMap("m", pelvis, ours)
    with tempfile.TemporaryDirectory() as tmp:
        path = f"{tmp}/p.npy"
        np.save(path, array)
        if np.floor(n * 15 / fps + 1e-9) == 0:
            with pytest.raises(MotionFileError, match="too short"):
                load_positions_motion(path, joint_map=jmap, fps=fps, **AS_IS)
            return
        motion = load_positions_motion(path, joint_map=jmap, fps=fps, **AS_IS)
    assert motion.fps == 15
    assert motion.n_frames == int(np.floor(n * 15 / fps + 1e-9))
    want = resample_positions(expected(array, ours, pelvis), fps, 15)
    np.testing.assert_allclose(motion.positions, want, atol=1e-6)
    if fps in (30, 60, 120):  # whole multiples subsample exactly
        step = fps // 15
        np.testing.assert_allclose(
            motion.positions, expected(array, ours, pelvis)[::step][: motion.n_frames], atol=1e-6
        )


@pytest.mark.parametrize(
    "make, fragment",
    [
        (lambda p: np.save(p.with_suffix(".npy"), np.zeros((5, 60, 2))), "shape"),
        (lambda p: np.save(p.with_suffix(".npy"), np.zeros((5, 10))), "shape"),
        (lambda p: np.save(p.with_suffix(".npy"), np.zeros((0, 60, 3))), "no frames"),
        (lambda p: np.save(p.with_suffix(".npy"), np.full((5, 60, 3), np.nan)), "NaN"),
        (lambda p: np.save(p.with_suffix(".npy"), np.array([{"a": 1}], dtype=object)), "cannot read"),
        (lambda p: np.save(p.with_suffix(".npy"), np.array(["a", "b"])), "numbers"),
        (lambda p: np.savez(p.with_suffix(".npz"), a=np.zeros((5, 60, 3)), b=np.zeros(3)), "positions"),
        (lambda p: p.with_suffix(".txt").write_text("1 2 3\n4 5\n"), "cannot read"),
        (lambda p: p.with_suffix(".txt").write_text("1 2 x\n"), "cannot read"),
        (lambda p: p.with_suffix(".txt").write_text("\n\n"), "no frames"),
        (lambda p: p.with_suffix(".npy").write_bytes(b""), "empty"),
        (lambda p: p.with_suffix(".npy").write_bytes(b"not numpy at all"), "cannot read"),
        (lambda p: p.with_suffix(".npz").write_bytes(b"not a zip"), "cannot read"),
        (lambda p: p.with_suffix(".pkl").write_bytes(b"x"), "unsupported"),
    ],
)
def test_bad_files_raise_motion_file_error_naming_the_file(tmp_path, layout, make, fragment):
    _, _, _, map_path = layout
    make(tmp_path / "broken")
    path = next(tmp_path.glob("broken.*"))
    with pytest.raises(MotionFileError, match=fragment) as info:
        load_positions_motion(path, joint_map=map_path, fps=30, **AS_IS)
    assert "broken." in str(info.value)


def test_missing_file(tmp_path, layout):
    with pytest.raises(MotionFileError, match="gone.npy.*not found"):
        load_positions_motion(tmp_path / "gone.npy", joint_map=layout[3], fps=30, **AS_IS)


def test_map_that_does_not_fit_the_file(tmp_path):
    names, ours, pelvis = source_layout()
    path = tmp_path / "few.npy"
    np.save(path, source_positions(4)[:, :50])
    with pytest.raises(MotionFileError, match="few.npy.*out of range") as info:
        load_positions_motion(path, joint_map={"pelvis": pelvis, "joints": ours}, fps=15, **AS_IS)
    assert "index out of range for 50 joints" in str(info.value)
    by_name = {"pelvis": 0, "joints": dict(ours, head="nobody"), "names": names}
    np.save(path, source_positions(4))
    with pytest.raises(MotionFileError, match="'nobody'"):
        load_positions_motion(path, joint_map=by_name, fps=15, **AS_IS)
    with pytest.raises(MotionFileError, match="no 'names' list"):
        load_positions_motion(path, joint_map={"pelvis": 0, "joints": dict(ours, head="src_1")}, fps=15, **AS_IS)
    with pytest.raises(MotionFileError, match="lists 3 source joint names"):
        load_positions_motion(path, joint_map={"pelvis": 0, "joints": ours, "names": ["a", "b", "c"]}, fps=15, **AS_IS)


def test_incomplete_or_bad_joint_maps(tmp_path):
    _, ours, _ = source_layout()
    partial = dict(ours)
    del partial["left_wrist"], partial["right_ring3"]
    path = tmp_path / "pmap.json"
    path.write_text(json.dumps({"pelvis": 0, "joints": {**partial, "tail": 3}}))
    with pytest.raises(InputFileError) as info:
        load_position_joint_map(path)
    message = str(info.value)
    assert "pmap.json" in message and "hand controls needs left_wrist" in message and "tail" in message
    assert "right_ring3" not in message  # a finger may be left out: it is absent
    with pytest.raises(ConfigError, match="left_wrist"):
        load_position_joint_map({"pelvis": 0, "joints": partial})
    for content, fragment in [
        ("{oops", "not valid JSON"),
        ('{"joints": {}}', "pelvis"),
        ('{"pelvis": 1.5, "joints": {}}', "pelvis"),
        ('{"pelvis": 0, "joints": {}, "names": "abc"}', "names"),
    ]:
        path.write_text(content)
        with pytest.raises(InputFileError, match=fragment):
            load_position_joint_map(path)
    with pytest.raises(ConfigError, match="values must be joint indices"):
        load_position_joint_map({"pelvis": 0, "joints": dict(ours, head=True)})
    with pytest.raises(InputFileError, match="not found"):
        load_position_joint_map(tmp_path / "none.json")


def test_bad_options(tmp_path, layout):
    path = tmp_path / "ok.npy"
    np.save(path, source_positions(4))
    with pytest.raises(ConfigError):
        load_positions_motion(path, joint_map=layout[3], fps=0, **AS_IS)
    with pytest.raises(ConfigError):
        load_positions_motion(path, joint_map=layout[3], fps=15, units="ft", **AS_IS)


def test_read_position_array_shapes(tmp_path):
    np.save(tmp_path / "flat.npy", np.arange(2 * 9, dtype=np.int32).reshape(2, 9))
    array = read_position_array(tmp_path / "flat.npy")
    assert array.shape == (2, 3, 3) and array.dtype == np.float64
    np.testing.assert_array_equal(array[1, 2], [15, 16, 17])
