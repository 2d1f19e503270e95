"""The search at scale: it reads a memory-mapped database in place, and what it allocates per
database frame stays a small fraction of the features it searches."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.search import SearchConfig, SearchIndex
from tests.conftest import make_take
from tests.search.test_frames import built_features

T, D, A = 64, 96, 112
# bytes per database frame the search reads: P and F float32, valid
SEARCHED_PER_FRAME = 4 * (D + A) + 1


def _features(M: int, seed: int = 0, built: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random features, or (``built``) pose features built of frames ahead, as a database's are."""
    rng = np.random.default_rng(seed)
    valid = np.ones((M, T), bool)
    valid[:, -14:] = False
    P = built_features(rng, ["walk"] * M, T) if built else rng.standard_normal((M, T, D), np.float32)
    return P, rng.standard_normal((M, T, A), np.float32), valid


@pytest.fixture(scope="module")
def mapped(tmp_path_factory):
    """A small database saved and opened memory-mapped."""
    takes = [make_take(20.0, seed=1, name="a"), make_take(13.0, seed=2, name="b")]
    path = MatchingDatabase.build(takes, config=BuildConfig()).save(tmp_path_factory.mktemp("db") / "db")
    return MatchingDatabase.load(path)


def test_the_index_reads_memory_mapped_features_in_place(mapped):
    assert isinstance(mapped.P, np.memmap) and isinstance(mapped.F, np.memmap)
    index = SearchIndex(mapped.P, mapped.F, mapped.valid)
    # plain ndarray views of the mapped files (the kernels take no np.memmap), no copies
    for mine, theirs in ((index._P3, mapped.P), (index._F3, mapped.F), (index.valid, mapped.valid)):
        assert type(mine) is np.ndarray and not mine.flags.owndata
        assert np.shares_memory(mine, theirs)
    query = mapped.query_features(mapped.take_audio("a")[: 16000 * 3])[0]
    res = index.search(query, config=SearchConfig(seed=3))
    plain = SearchIndex(np.array(mapped.P), np.array(mapped.F), np.array(mapped.valid)).search(
        query, config=SearchConfig(seed=3)
    )
    assert res.equals(plain)


def _allocated(M: int, masks: bool, built: bool = False) -> tuple[int, int]:
    """Bytes numpy allocates (traced peak) to prepare an index and to run a 20-step search, on M clips."""
    P, F, valid = _features(M, built=built)
    rng = np.random.default_rng(1)
    query = rng.standard_normal((160, A), np.float32)
    kw: dict = {}
    if masks:  # two control masks used in turn and held-out frames: the search's largest per-frame state
        kw = {
            "masks": rng.random((2, M, T)) < 0.6,
            "step_mask_index": np.arange(20) % 3 - 1,
            "exclude": rng.random((M, T)) < 0.01,
        }
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        index = SearchIndex(P, F, valid)
        prepared = tracemalloc.get_traced_memory()[0] - base
        tracemalloc.reset_peak()
        index.search(query, config=SearchConfig(seed=2), **kw)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return prepared, peak


@pytest.mark.parametrize(
    "masks, built",
    [(False, False), (True, False), (False, True)],
    ids=["plain", "controls and exclusions", "frame copy"],
)
def test_memory_beyond_the_database_grows_by_a_few_bytes_per_frame(masks, built):
    # the slope between two sizes is what a hundred hours (5.4 M frames) pays per frame;
    # fixed costs (the query, the record of each step) do not grow with the database
    small, large = 300, 1200
    _allocated(20, masks, built)  # compiled kernels load first
    (p0, s0), (p1, s1) = _allocated(small, masks, built), _allocated(large, masks, built)
    frames = (large - small) * T
    per_frame_index = (p1 - p0) / frames
    per_frame_search = (s1 - s0) / frames
    assert per_frame_index <= 12.5  # float32 and float64 squared norms of each frame
    # the index, admissible starts and biases of the base and of each control in use, a scan buffer
    # (here M T float32; never over 16 MB), the exclusions' window test: about 40 bytes, 5 %; and
    # the copy of the pose features a single query's scan reads: the 8-bit copy's D + 8 bytes, or
    # the frame copy's 2 D / 4 + 4 where the features are built of four frames ahead
    copy = 2 * D // 4 + 4 if built else D + 8
    assert per_frame_search <= 0.06 * SEARCHED_PER_FRAME + copy
    # at 5.4 M frames and with fixed costs of this size, under 25 % of the searched arrays
    at_100h = 5.4e6
    assert s1 + per_frame_search * (at_100h - large * T) < 0.25 * SEARCHED_PER_FRAME * at_100h


@settings(max_examples=40, deadline=None)
@given(
    a=st.floats(0.0, 25.0),
    length=st.floats(0.01, 10.0),
    take=st.sampled_from(["a", "b"]),
    whole=st.lists(st.sampled_from(["a", "b"]), max_size=2),
)
def test_exclusion_mask_is_the_per_frame_definition(mapped, a, length, take, whole):
    got = mapped.exclusion_mask(takes=whole, ranges=[(take, a, a + length)])
    ti = np.asarray(mapped.clip_take)
    sec = (np.asarray(mapped.clip_start)[:, None] + np.arange(T)) / mapped.fps
    names = mapped.take_names
    want = np.isin(ti, [names.index(w) for w in whole])[:, None] | (
        (ti == names.index(take))[:, None] & (sec >= a) & (sec < a + length)
    )
    np.testing.assert_array_equal(got, want)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 50), st.integers(1, 9))
def test_work_in_parts_covers_every_row_once_in_order(n, workers):
    # the index's one-off passes (norms, the 8-bit and frame copies) share rows out this way
    import threading

    from gesturekit.search.threads import in_parts

    seen = []
    out = in_parts(n, workers, lambda a, b: (a, b, threading.get_ident()))
    for a, b, _ in out:
        seen.extend(range(a, b))
    assert seen == list(range(n))
    assert len(out) == max(1, min(workers, n))
    if len(out) == 1:
        assert out[0][2] == threading.get_ident()  # one part runs here, no thread started
