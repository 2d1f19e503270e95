"""Tests of gesturekit.export.npz."""

from __future__ import annotations

import io
import json
import os
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from gesturekit.errors import ConfigError, MotionFileError, OutputError
from gesturekit.export import npz as npz_module
from gesturekit.export.npz import FORMAT_VERSION, RESERVED_KEYS, load_npz, save_npz
from gesturekit.motion import Motion
from gesturekit.skeleton import JOINT_NAMES, N_JOINTS, PARENTS


def make_motion(frames=6, seed=0, fps=15):
    rng = np.random.default_rng(seed)
    return Motion(rng.normal(scale=0.3, size=(frames, N_JOINTS, 3)).astype(np.float32), fps)


def write_zip(path, entries):
    """An npz written by hand: entries name -> array (object arrays pickled, as np.save would)."""
    with zipfile.ZipFile(path, "w") as zf:
        for name, arr in entries.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asarray(arr), allow_pickle=True)
            zf.writestr(f"{name}.npy", buf.getvalue())


def valid_entries(motion):
    return {
        "positions": motion.positions,
        "fps": np.array(15.0),
        "joint_names": np.array(JOINT_NAMES),
        "parents": PARENTS,
        "config": np.array("{}"),
    }


def test_round_trip(tmp_path):
    motion = make_motion()
    knn = make_motion(seed=1).positions
    arrays = {
        "knn_positions": knn,
        "refined_positions": knn + 1,
        "candidates": np.arange(12).reshape(3, 4),
        "chosen": np.array([True, False]),
        "labels": np.array(["a", "bé"]),
    }
    config = {"k": 5, "threshold": 0.25, "nested": {"list": [1, 2.5, "x"]}, "seed": None}
    path = save_npz(tmp_path / "out.npz", motion=motion, arrays=arrays, config=config)
    back, extras, cfg = load_npz(path)
    np.testing.assert_array_equal(back.positions, motion.positions)
    assert back.positions.dtype == np.float32 and back.fps == 15.0
    assert sorted(extras) == sorted(arrays)
    for name, arr in arrays.items():
        np.testing.assert_array_equal(extras[name], arr)
        assert extras[name].dtype == arr.dtype
    assert cfg == config


def test_plain_numpy_reads_it_without_pickles(tmp_path):
    path = save_npz(tmp_path / "out.npz", motion=make_motion(fps=30), config={"b": 1, "a": [1, 2]})
    with np.load(path, allow_pickle=False) as z:
        assert set(z.files) == set(RESERVED_KEYS)
        assert z["positions"].dtype == np.float32 and z["positions"].shape == (6, N_JOINTS, 3)
        assert z["fps"].shape == () and float(z["fps"]) == 30.0
        assert tuple(z["joint_names"]) == JOINT_NAMES
        np.testing.assert_array_equal(z["parents"], PARENTS)
        assert z["config"].shape == () and z["config"].dtype.kind == "U"
        assert json.loads(str(z["config"])) == {"a": [1, 2], "b": 1}
        assert int(z["format_version"]) == FORMAT_VERSION
    assert path.suffix == ".npz" and path.name == "out.npz"


def test_numpy_values_in_config_become_json(tmp_path):
    config = {"f": np.float32(0.5), "i": np.int64(3), "v": np.arange(3), "p": Path("a/b.wav"), "s": {2, 1}}
    _, _, cfg = load_npz(save_npz(tmp_path / "c.npz", motion=make_motion(), config=config))
    assert cfg == {"f": 0.5, "i": 3, "v": [0, 1, 2], "p": os.fspath(Path("a/b.wav")), "s": [1, 2]}


def test_same_inputs_same_bytes_whatever_the_clock(tmp_path, monkeypatch):
    motion = make_motion()
    arrays = {"b": np.ones(3), "a": np.zeros((2, 2))}
    first = save_npz(tmp_path / "1.npz", motion=motion, arrays=arrays, config={"x": 1, "y": 2}).read_bytes()
    # a different day, and the extras and settings given in another order
    real_time = time.time
    monkeypatch.setattr(time, "time", lambda: real_time() + 86400 * 400)
    second = save_npz(
        tmp_path / "2.npz", motion=motion, arrays=dict(reversed(list(arrays.items()))), config={"y": 2, "x": 1}
    ).read_bytes()
    assert first == second
    stored = save_npz(tmp_path / "3.npz", motion=motion, arrays=arrays, config={"x": 1, "y": 2}, compress=False)
    assert stored.read_bytes() != first and len(stored.read_bytes()) > len(first)
    assert {info.date_time for info in zipfile.ZipFile(tmp_path / "1.npz").infolist()} == {(1980, 1, 1, 0, 0, 0)}


def test_different_content_different_bytes(tmp_path):
    motion = make_motion()
    a = save_npz(tmp_path / "a.npz", motion=motion, config={"x": 1}).read_bytes()
    b = save_npz(tmp_path / "b.npz", motion=motion, config={"x": 2}).read_bytes()
    assert a != b


names = st.from_regex(r"[a-z_][a-z0-9_]{0,15}", fullmatch=True).filter(lambda n: n not in RESERVED_KEYS)
arrays_strategy = st.dictionaries(
    names,
    hnp.arrays(
        dtype=st.sampled_from([np.float32, np.float64, np.int64, np.uint8, np.bool_]),
        shape=hnp.array_shapes(min_dims=0, max_dims=3, max_side=4),
    ),
    max_size=4,
)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(arrays=arrays_strategy, frames=st.integers(0, 3), fps=st.floats(1, 240))
def test_any_extra_arrays_round_trip(tmp_path, arrays, frames, fps):
    motion = make_motion(frames=frames, fps=fps)
    path = save_npz(tmp_path / "h.npz", motion=motion, arrays=arrays, overwrite=True)
    back, extras, cfg = load_npz(path)
    assert back.fps == fps and back.n_frames == frames and cfg == {}
    assert extras.keys() == arrays.keys()
    for name, arr in arrays.items():
        assert extras[name].dtype == arr.dtype and extras[name].shape == arr.shape
        np.testing.assert_array_equal(extras[name], arr)  # NaN compares equal here
    assert save_npz(tmp_path / "h2.npz", motion=motion, arrays=arrays, overwrite=True).read_bytes() == path.read_bytes()


# ----------------------------------------------------------------------------- what is refused when saving


@pytest.mark.parametrize("name", ["positions", "config", "fps"])
def test_reserved_names_refused(tmp_path, name):
    with pytest.raises(ConfigError, match="reserved"):
        save_npz(tmp_path / "r.npz", motion=make_motion(), arrays={name: np.zeros(2)})
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("name", ["", "1abc", "a/b", "../x", "a b", "a.npy"])
def test_bad_names_refused(tmp_path, name):
    with pytest.raises(ConfigError, match="letters, digits"):
        save_npz(tmp_path / "r.npz", motion=make_motion(), arrays={name: np.zeros(2)})


def test_object_arrays_and_odd_configs_refused(tmp_path):
    path = tmp_path / "o.npz"
    with pytest.raises(ConfigError, match=r"o\.npz.*'ragged'.*pickling"):
        save_npz(path, motion=make_motion(), arrays={"ragged": np.array([np.zeros(2), None], dtype=object)})
    with pytest.raises(ConfigError, match="JSON"):
        save_npz(path, motion=make_motion(), config={"f": object()})
    with pytest.raises(ConfigError, match="mapping"):
        save_npz(path, motion=make_motion(), config=[1, 2])
    with pytest.raises(ConfigError, match="Motion"):
        save_npz(path, motion=np.zeros((2, N_JOINTS, 3)))
    assert os.listdir(tmp_path) == []


def test_overwrite_protection(tmp_path):
    path = tmp_path / "out.npz"
    save_npz(path, motion=make_motion(seed=1))
    before = path.read_bytes()
    with pytest.raises(ConfigError, match=r"out\.npz.*already exists.*overwrite=True"):
        save_npz(path, motion=make_motion(seed=2))
    assert path.read_bytes() == before
    save_npz(path, motion=make_motion(seed=2), overwrite=True)
    np.testing.assert_array_equal(load_npz(path)[0].positions, make_motion(seed=2).positions)


def test_failure_while_writing_leaves_nothing(tmp_path, monkeypatch):
    path = tmp_path / "out.npz"
    save_npz(path, motion=make_motion(seed=1))
    before = path.read_bytes()
    calls = []

    def failing_write_array(fp, array, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise OSError("disk full")
        return real(fp, array, **kwargs)

    real = np.lib.format.write_array
    monkeypatch.setattr(npz_module.np.lib.format, "write_array", failing_write_array)
    with pytest.raises(OutputError, match="disk full"):
        save_npz(path, motion=make_motion(seed=2), overwrite=True)
    calls.clear()
    with pytest.raises(OutputError, match="disk full"):
        save_npz(tmp_path / "new.npz", motion=make_motion(seed=2))
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["out.npz"]


# ----------------------------------------------------------------------------- what is refused when loading


def test_missing_key_is_named(tmp_path):
    motion = make_motion()
    entries = valid_entries(motion)
    del entries["parents"], entries["fps"]
    write_zip(tmp_path / "m.npz", entries)
    with pytest.raises(MotionFileError, match=r"m\.npz: missing keys fps, parents"):
        load_npz(tmp_path / "m.npz")


def test_config_is_optional_but_must_be_json(tmp_path):
    motion = make_motion()
    entries = valid_entries(motion)
    del entries["config"]
    write_zip(tmp_path / "a.npz", entries)
    assert load_npz(tmp_path / "a.npz")[2] == {}
    write_zip(tmp_path / "b.npz", {**entries, "config": np.array("{not json")})
    with pytest.raises(MotionFileError, match=r"b\.npz.*JSON"):
        load_npz(tmp_path / "b.npz")
    write_zip(tmp_path / "c.npz", {**entries, "config": np.array("[1, 2]")})
    with pytest.raises(MotionFileError, match="JSON object"):
        load_npz(tmp_path / "c.npz")


def test_pickled_objects_are_refused(tmp_path):
    entries = valid_entries(make_motion())
    entries["evil"] = np.array([{"a": 1}, None], dtype=object)
    write_zip(tmp_path / "p.npz", entries)
    with pytest.raises(MotionFileError, match=r"p\.npz.*unpickling"):
        load_npz(tmp_path / "p.npz")


@pytest.mark.parametrize(
    "change,message",
    [
        ({"joint_names": np.array(JOINT_NAMES[::-1])}, "joint_names"),
        ({"parents": np.zeros(N_JOINTS, dtype=np.int64)}, "parents"),
        ({"positions": np.zeros((3, 13, 3))}, "positions must be"),
        ({"positions": np.array(["x"] * (N_JOINTS * 3)).reshape(1, N_JOINTS, 3)}, "positions must be"),
        ({"fps": np.array(-15.0)}, "fps"),
        ({"fps": np.array([15.0, 30.0])}, "fps"),
        ({"format_version": np.array(FORMAT_VERSION + 1)}, "newer"),
    ],
)
def test_invalid_content_is_reported(tmp_path, change, message):
    write_zip(tmp_path / "bad.npz", {**valid_entries(make_motion()), **change})
    with pytest.raises(MotionFileError, match=rf"bad\.npz.*{message}"):
        load_npz(tmp_path / "bad.npz")


def test_not_an_archive(tmp_path):
    with pytest.raises(MotionFileError, match=r"nothing\.npz: file not found"):
        load_npz(tmp_path / "nothing.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(MotionFileError, match=r"text\.npz: not an npz archive"):
        load_npz(tmp_path / "text.npz")
    np.save(tmp_path / "single.npy", np.zeros(3))
    with pytest.raises(MotionFileError, match=r"single\.npy: not an npz"):
        load_npz(tmp_path / "single.npy")
    good = save_npz(tmp_path / "good.npz", motion=make_motion()).read_bytes()
    (tmp_path / "cut.npz").write_bytes(good[: len(good) // 2])
    with pytest.raises(MotionFileError, match=r"cut\.npz"):
        load_npz(tmp_path / "cut.npz")
