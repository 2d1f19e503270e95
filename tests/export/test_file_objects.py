"""The writers take a path (written atomically) or a binary file object, and write the same bytes to either."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest

from gesturekit.demo import open_default_database
from gesturekit.errors import ConfigError
from gesturekit.export.bvh import export_bvh, write_bvh
from gesturekit.export.gltf import export_gltf
from gesturekit.export.npz import load_npz, save_npz
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS


@pytest.fixture(scope="module")
def motion():
    """Two clips of the demo database, one after another (15 fps)."""
    db = open_default_database()
    return Motion(db.poses[:2].reshape(-1, N_JOINTS, 3).astype(np.float32), db.fps, db.joint_presence)


def quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kwargs)


def test_npz_into_a_file_object_is_the_files_bytes(tmp_path, motion):
    path = tmp_path / "m.npz"
    assert save_npz(path, motion=motion, config={"k": 0}) == path
    buf = io.BytesIO()
    assert save_npz(buf, motion=motion, config={"k": 0}) is None
    assert buf.getvalue() == path.read_bytes()
    back, _, config = load_npz(path)
    np.testing.assert_array_equal(back.positions, motion.positions)
    assert config == {"k": 0}


def test_bvh_into_a_file_object_is_the_files_bytes_and_its_report_names_the_object(tmp_path, motion):
    path = tmp_path / "m.bvh"
    on_disk = quiet(export_bvh, path, motion)
    buf = io.BytesIO(b"x")
    buf.seek(1)
    report = quiet(export_bvh, buf, motion)
    assert buf.getvalue() == b"x" + path.read_bytes()
    assert report.path.name == "motion.bvh" and report.max_error == on_disk.max_error
    named = io.BytesIO()
    named.name = "download.bvh"
    assert quiet(write_bvh, named, motion) is None and named.getvalue() == path.read_bytes()
    assert quiet(export_bvh, named, motion).path.name == "download.bvh"


def test_glb_into_a_file_object_is_the_files_bytes_and_refuses_speech(tmp_path, motion):
    path = tmp_path / "m.glb"
    on_disk = quiet(export_gltf, path, motion)
    buf = io.BytesIO()
    report = quiet(export_gltf, buf, motion)
    assert buf.getvalue() == path.read_bytes() and report.size == on_disk.size
    assert report.audio is None
    with pytest.raises(ConfigError, match="no folder for its speech"):
        export_gltf(io.BytesIO(), motion, audio=np.zeros(1600, np.float32))


def test_a_path_still_refuses_to_replace_a_file(tmp_path, motion):
    path = tmp_path / "m.bvh"
    quiet(export_bvh, path, motion)
    with pytest.raises(ConfigError, match="already exists"):
        quiet(export_bvh, path, motion)
