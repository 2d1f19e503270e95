"""Training pairs of the refiner: the k-NN search over the overlapping cut, as the authors made them."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError, DatabaseError
from gesturekit.refine.data import PairsConfig, draw_k, make_training_pairs, training_windows
from gesturekit.search import SearchConfig, search
from tests.conftest import make_take
from tests.refine_helpers import _one_torch_thread  # noqa: F401 (an autouse fixture)

pytestmark = pytest.mark.slow  # its module fixture builds a database and searches every window


@pytest.fixture(scope="module")
def db():
    takes = [make_take(16.0, seed=1, name="a"), make_take(12.0, seed=2, name="b"), make_take(10.0, seed=3, name="c")]
    return MatchingDatabase.build(takes, config=BuildConfig(overlap_stride=8, store_audio=False))


@pytest.fixture(scope="module")
def pairs(db):
    return make_training_pairs(db, config=PairsConfig(seed=0))


def _db_frame(db, frames):
    """(take, frame in take) of database (clip, frame) pairs."""
    return db.clip_take[frames[..., 0]], db.clip_start[frames[..., 0]] + frames[..., 1]


def test_one_pair_per_window_with_ground_truth_as_real(db, pairs):
    ov = db.overlap
    assert len(pairs) == ov["G"].shape[0] and pairs.dropped == 0
    assert pairs.audio.shape == (len(pairs), 64, 28) and pairs.knn.shape == pairs.real.shape == (len(pairs), 64, 165)
    np.testing.assert_array_equal(pairs.real, ov["G"][pairs.window])
    np.testing.assert_array_equal(pairs.audio, ov["A"][pairs.window])
    # the k-NN motion is made of database frames
    np.testing.assert_array_equal(pairs.knn, db.G[pairs.frames[..., 0], pairs.frames[..., 1]])


def test_a_window_never_gets_its_own_frames(db, pairs):
    ov = db.overlap
    take, frame = _db_frame(db, pairs.frames)
    w_take = ov["clip_take"][pairs.window][:, None]
    w_start = ov["clip_start"][pairs.window][:, None]
    own = (take == w_take) & (frame >= w_start) & (frame < w_start + 64)
    assert not own.any()
    assert not np.any(np.all(pairs.knn == pairs.real, axis=(1, 2)))


def test_each_pair_is_the_search_of_its_window(db, pairs):
    # the batched search equals a single search of the window's audio with its own frames excluded
    ov = db.overlap
    for i in (0, len(pairs) // 2, len(pairs) - 1):
        w = pairs.window[i]
        take, frame = db.clip_take[:, None], db.clip_start[:, None] + np.arange(64)[None, :]
        own = (take == ov["clip_take"][w]) & (frame >= ov["clip_start"][w]) & (frame < ov["clip_start"][w] + 64)
        res = search(
            db.P,
            db.F,
            db.valid,
            ov["F"][w],
            exclude=own,
            config=SearchConfig(k=int(pairs.k[i]), record=1, init_pose=ov["P"][w, 0], mask_rule="all"),
        )
        np.testing.assert_array_equal(res.frames, pairs.frames[i])


def test_k_is_one_half_of_the_time_else_uniform_in_2_to_15():
    k = draw_k(20000, PairsConfig(seed=5))
    assert set(np.unique(k)) == set(range(1, 16))
    assert abs(np.mean(k == 1) - 0.5) < 0.02
    counts = np.bincount(k[k > 1])[2:]
    assert counts.min() > 0.8 * counts.mean() and counts.max() < 1.2 * counts.mean()
    np.testing.assert_array_equal(k, draw_k(20000, PairsConfig(seed=5)))


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 300))
def test_k_values_stay_in_range(seed, n):
    k = draw_k(n, PairsConfig(seed=seed, k_max=15))
    assert k.shape == (n,) and k.min() >= 1 and k.max() <= 15


def test_pairs_are_deterministic(db, pairs):
    again = make_training_pairs(db, config=PairsConfig(seed=0))
    np.testing.assert_array_equal(again.frames, pairs.frames)
    other = make_training_pairs(db, config=PairsConfig(seed=1))
    assert not np.array_equal(other.k, pairs.k)


def test_held_out_stretches_are_neither_trained_on_nor_searched(db):
    cfg = PairsConfig(exclude_takes=("c",), exclude_ranges=(("a", 4.0, 9.0),))
    p = make_training_pairs(db, config=cfg)
    ov = db.overlap
    wt, ws = ov["clip_take"][p.window], ov["clip_start"][p.window]
    assert not np.any(wt == 2)
    in_a = wt == 0
    # window frames [s, s+64) must not meet frames 60..134 (4 s <= t < 9 s)
    assert np.all((ws[in_a] + 64 <= 60) | (ws[in_a] >= 135))
    take, frame = _db_frame(db, p.frames)
    assert not np.any(take == 2)
    assert not np.any((take == 0) & (frame >= 60) & (frame < 135))
    np.testing.assert_array_equal(p.window, training_windows(db, cfg))
    assert len(p) < ov["G"].shape[0]


def test_errors(db):
    with pytest.raises(ConfigError, match="no take named"):
        training_windows(db, PairsConfig(exclude_takes=("zz",)))
    with pytest.raises(ConfigError, match="no training window"):
        make_training_pairs(db, config=PairsConfig(exclude_takes=("a", "b", "c")))
    plain = MatchingDatabase.build([make_take(6.0, seed=4, name="x")], config=BuildConfig(store_audio=False))
    with pytest.raises(DatabaseError, match="overlap-stride"):
        make_training_pairs(plain)
    with pytest.raises(ConfigError):
        PairsConfig(k_max=1)
    assert PairsConfig.from_dict(PairsConfig(exclude_ranges=(("a", 1, 2),)).to_dict()) == PairsConfig(
        exclude_ranges=(("a", 1.0, 2.0),)
    )
