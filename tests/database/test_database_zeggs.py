"""Acceptance on the real ZEGGS take: BVH + WAV folder -> matching database."""

import numpy as np
import pytest

from gesturekit.cli import main
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.datasets.bvh import forward_kinematics, parse_bvh
from gesturekit.datasets.takes import discover_takes, iter_takes
from gesturekit.motion import Motion
from gesturekit.skeleton import hand_indices, joint_index


@pytest.fixture(scope="module")
def zeggs_db(tmp_path_factory):
    from tests.conftest import ZEGGS_BVH

    if not ZEGGS_BVH.is_file():
        pytest.skip(f"ZEGGS take not found at {ZEGGS_BVH}")
    out = tmp_path_factory.mktemp("zeggs") / "db"
    assert main(["build-db", str(ZEGGS_BVH.parent), "--preset", "zeggs", "--out", str(out)]) == 0
    return MatchingDatabase.load(out)


def test_zeggs_frames_clips_and_shapes(zeggs_db):
    take = zeggs_db.meta["takes"][0]
    assert take["n_frames"] == 1032  # 2065 frames at 30 fps = 68.8 s -> 1032 frames at 15 fps
    assert zeggs_db.n_clips == 16
    assert zeggs_db.F.shape == (16, 64, 112)
    assert zeggs_db.P.shape == (16, 64, 96)
    assert zeggs_db.G.shape == (16, 64, 165)
    assert zeggs_db.clips_table()["start_s"].iloc[-1] == pytest.approx(15 * 64 / 15)


def test_zeggs_bone_lengths_constant(zeggs_db):
    g = np.asarray(zeggs_db.G).reshape(-1, 55, 3)
    lengths = Motion(g, 15).bone_lengths()
    assert np.ptp(lengths, axis=0).max() < 1e-4


def test_zeggs_wrists_are_pelvis_relative(zeggs_db, zeggs_files):
    bvh = parse_bvh(zeggs_files[0])
    world = forward_kinematics(bvh) / 100.0  # cm -> m, 30 fps
    hips, lw = world[:, bvh.index("Hips")], world[:, bvh.index("LeftHand")]
    g = np.asarray(zeggs_db.G).reshape(-1, 55, 3)  # 15 fps: frame t is BVH frame 2t
    t = np.arange(g.shape[0])
    np.testing.assert_allclose(g[:, joint_index("left_wrist")], (lw - hips)[2 * t], atol=1e-5)


def test_zeggs_hands_follow_wrists(zeggs_db):
    g = np.asarray(zeggs_db.G).reshape(-1, 55, 3)
    for side in ("left", "right"):
        idx = hand_indices(side)
        d = np.linalg.norm(g[:, idx[1:]] - g[:, idx[:1]], axis=-1)
        assert d.max() < 0.25  # every finger joint within a hand's length of its wrist, every frame
        wrist_path = np.linalg.norm(np.diff(g[:, idx[0]], axis=0), axis=-1).sum()
        tip_path = np.linalg.norm(np.diff(g[:, idx[8]], axis=0), axis=-1).sum()  # index finger tip
        assert wrist_path > 1.0 and tip_path > 0.8 * wrist_path  # the hand travels with the wrist


def test_zeggs_build_in_python_matches_cli(zeggs_db, zeggs_files):
    db = MatchingDatabase.build(
        iter_takes(discover_takes(zeggs_files[0].parent), joint_map="zeggs"), config=BuildConfig()
    )
    np.testing.assert_array_equal(db.G, zeggs_db.G)
    np.testing.assert_array_equal(db.F, zeggs_db.F)
