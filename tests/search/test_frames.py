"""Tests of the frame copy (gesturekit.search.frames): it is made only for features built of
frames ahead, its estimates lie within their proven bound on features built the way the
database builds them (and on ones that break the structure a little), and searches that scan
it equal the reference, near-ties across the bound included."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.features import LAYOUT
from gesturekit.search import SearchConfig, SearchIndex, exact_pose_sqdist
from gesturekit.search.exact import TINY, pose_err_factor
from gesturekit.search.frames import FIT_TOLERANCE, fit_frame_map, frame_bias, frame_bounds, frame_pose, frame_query
from gesturekit.search.reduced import compiled_reduced
from tests.search.test_search import assert_same, run_both

OFFSETS = np.asarray(LAYOUT.pose_offsets, np.int64)
K = LAYOUT.pose_dim // OFFSETS.size
CLIP_KINDS = ["walk", "still", "grid", "offset", "jitter", "steps", "tiny", "huge", "noise"]


def _trajectory(kind: str, rng: np.random.Generator, frames: int) -> np.ndarray:
    """One clip's feature joints (frames, K) as a take gives them, ``frames`` past the clip's start."""
    if kind == "walk":  # motion capture: each frame a small step from the last
        return np.cumsum(0.05 * rng.standard_normal((frames, K)), axis=0) + rng.standard_normal(K)
    if kind == "still":  # a held pose: every start equal, exact ties
        return np.repeat(rng.standard_normal((1, K)), frames, axis=0)
    if kind == "grid":  # positions on a coarse grid: exact ties between some starts
        return np.round(np.cumsum(0.3 * rng.standard_normal((frames, K)), axis=0) * 2) / 2
    if kind == "offset":  # far from the origin: float32 cancellation
        return np.cumsum(0.05 * rng.standard_normal((frames, K)), axis=0) + 300.0
    if kind == "jitter":  # a held pose with sensor noise: near-ties at the scale of the bound
        return np.repeat(rng.standard_normal((1, K)), frames, axis=0) + 1e-4 * rng.standard_normal((frames, K))
    if kind == "steps":  # still stretches joined by jumps (a retargeted take's held frames)
        jumps = rng.standard_normal((frames, K)) * (rng.random((frames, 1)) < 0.1)
        return np.cumsum(jumps, axis=0)
    if kind == "tiny":
        return 1e-30 * np.cumsum(rng.standard_normal((frames, K)), axis=0)
    if kind == "huge":
        return 1e12 * np.cumsum(rng.standard_normal((frames, K)), axis=0)
    return rng.standard_normal((frames, K))  # "noise": no motion at all


def built_features(
    rng: np.random.Generator, kinds: list[str], T: int, broken: float = 0.0, offsets: np.ndarray = OFFSETS
) -> np.ndarray:
    """Pose features (M, T, D) float32 built as the database builds them: the feature joints at
    ``t + o_k`` (the take going on past each clip's end), z-scored per dimension with statistics
    of every frame, so that each offset's block has its own mean and scale. ``broken``: that much
    noise added to the features afterwards (what the map cannot know)."""
    reach = int(np.max(offsets))
    width = LAYOUT.pose_dim // len(offsets)
    joints = np.stack([_trajectory(k, rng, T + reach)[:, :width] for k in kinds])  # (M, T + reach, width)
    if width > K:  # fewer offsets: more values a frame
        extra = np.stack([_trajectory(k, rng, T + reach)[:, : width - K] for k in kinds])
        joints = np.concatenate([joints, extra], axis=2)
    raw = np.concatenate([joints[:, o : o + T] for o in offsets], axis=2)
    flat = raw.reshape(-1, raw.shape[2])
    mean, std = flat.mean(axis=0), flat.std(axis=0)
    z = (raw - mean) / np.where(std > 0, std, 1.0)
    if broken:
        z = z + broken * rng.standard_normal(z.shape)
    return z.astype(np.float32)


def _frame_estimates(P: np.ndarray, q: np.ndarray, valid: np.ndarray):
    """Per start, the scan's frame estimate of its squared distance and the clip's bound as the scan
    reports them, read by scanning with one start admissible at a time; NaN where the scan settled
    the start in float32 instead (a possible zero). Also the copy and the documented bound."""
    M, T, D = P.shape
    index = SearchIndex(P, np.ones((M, T, 1), np.float32), valid)
    framed = index.frames()
    assert framed is not None
    fq = frame_query(q, framed)
    k = compiled_reduced()
    q64 = np.asarray(q, np.float64)
    nq = float(q64 @ q64)
    est = np.full((M, T), np.nan)
    bound = np.full(M, np.nan)
    for s in range(framed.covered):
        bias = np.full((M, T), np.inf, np.float32)
        bias[:, s] = np.where(valid[:, s], index._np32.reshape(M, T)[:, s], np.inf)
        s0, d2, err, und = np.empty(M, np.int64), np.empty(M), np.empty(M), np.empty(M, bool)
        k.scan_frames(
            np.empty((M, T), np.float32),
            bias,
            (framed.codes, framed.steps, frame_bias(framed, bias), framed.stats, framed.offsets),
            (fq.weights, fq.offset, fq.norm, framed.shift_norm),
            (index._P3, q, nq),
            (index._npmax, pose_err_factor(D), TINY),
            (s0, d2, err, und),
            (np.ones((M, T, 1), np.float32), np.ones((M, T)), np.ones(1, np.float32), 1.0),
            (np.empty(M), np.empty(M, bool)),
        )
        frame_err = np.array(
            [k.frame_bound(framed.stats, c, fq.norm, framed.shift_norm, pose_err_factor(D), TINY) for c in range(M)]
        )
        by_frames = valid[:, s] & (err == frame_err)
        est[by_frames, s] = d2[by_frames]
        bound = np.where(np.isnan(bound) & valid[:, s], frame_err, bound)
    exact = exact_pose_sqdist(P.reshape(M * T, D), q).reshape(M, T)
    return est, bound, exact, framed, fq


@st.composite
def frame_cases(draw):
    T = draw(st.sampled_from([8, 20, 64]))
    kinds = draw(st.lists(st.sampled_from(CLIP_KINDS[:-1]), min_size=1, max_size=4))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    P = built_features(rng, kinds, T, broken=draw(st.sampled_from([0.0, 0.0, 1e-6, 1e-5])))
    valid = rng.random(P.shape[:2]) < draw(st.sampled_from([1.0, 0.6]))
    valid[:, 0] = True  # the fit needs a start
    where = draw(st.sampled_from(["row", "near", "normal", "far", "zero"]))
    m, s = rng.integers(0, P.shape[0]), rng.integers(0, T)
    if where == "row":
        q = P[m, s].copy()
    elif where == "near":
        q = (P[m, s] + 1e-3 * rng.standard_normal(P.shape[2])).astype(np.float32)
    elif where == "far":
        q = (100.0 * rng.standard_normal(P.shape[2])).astype(np.float32)
    elif where == "zero":
        q = np.zeros(P.shape[2], np.float32)
    else:
        q = rng.standard_normal(P.shape[2]).astype(np.float32)
    return P, q, valid


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frame_cases())
def test_frame_estimates_lie_within_their_bound(case):
    P, q, valid = case
    if fit_frame_map(P, valid, OFFSETS) is None:  # a sample the map does not fit: no copy to test
        return
    est, bound, exact, framed, fq = _frame_estimates(P, q, valid)
    np.testing.assert_allclose(  # the scan's bound is the documented one
        bound[np.isfinite(bound)],
        frame_bounds(framed.stats, fq, framed.shift_norm, P.shape[2])[np.isfinite(bound)],
        rtol=1e-12,
    )
    seen = ~np.isnan(est)  # none where every start could be the query's own (all settled in float32)
    gap = np.abs(est - exact)[seen]
    allowed = np.broadcast_to(bound[:, None], est.shape)[seen]
    assert np.all(gap <= allowed), float((gap / allowed).max())


def test_the_copy_is_made_only_for_features_built_of_frames_ahead():
    rng = np.random.default_rng(3)
    built = built_features(rng, ["walk"] * 6, 64)
    valid = np.ones(built.shape[:2], bool)
    framed = frame_pose(built, valid, OFFSETS)
    assert framed is not None and framed.covered == 64 - int(OFFSETS.max())
    # 16-bit codes: the residual is a few hundred-thousandths of the features' norm
    assert framed.stats[:, 0].max() < 1e-3 * framed.stats[:, 1].max()
    assert framed.codes.dtype == np.int16 and framed.codes.shape == (6, K, 64)
    # other features: random rows, the blocks in another order, a layout of other offsets
    assert frame_pose(rng.standard_normal(built.shape).astype(np.float32), valid, OFFSETS) is None
    swapped = np.concatenate([built[:, :, K : 2 * K], built[:, :, :K], built[:, :, 2 * K :]], axis=2)
    assert frame_pose(swapped, valid, OFFSETS) is None
    assert frame_pose(built, valid, np.array([0, 1, 2, 3])) is None
    assert frame_pose(built[:, :, :95], valid, OFFSETS) is None  # not four blocks
    # structure broken far beyond float32 rounding: the map's tolerance refuses it
    noisy = (built + 100 * FIT_TOLERANCE * rng.standard_normal(built.shape)).astype(np.float32)
    assert frame_pose(noisy, valid, OFFSETS) is None
    # the index uses it only where it is made and asked for
    F = rng.standard_normal((6, 64, 3)).astype(np.float32)
    assert SearchIndex(built, F, valid).frames() is not None
    assert SearchIndex(built, F, valid, pose_offsets=()).frames() is None


@st.composite
def frame_problems(draw):
    """Databases of built features with near-ties across the frame bound: held poses with
    sensor noise, equal starts, duplicated clips, a clip of noise among them, features a
    little off the map; windows that the copy covers and ones it does not."""
    M = draw(st.integers(2, 7))
    T = draw(st.sampled_from([16, 24, 64]))
    A = draw(st.sampled_from([3, 112]))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kinds = draw(
        st.lists(st.sampled_from(["walk", "still", "jitter", "steps", "grid", "offset"]), min_size=M, max_size=M)
    )
    P = built_features(rng, kinds, T, broken=draw(st.sampled_from([0.0, 1e-6, 1e-5]))).astype(np.float64)
    if draw(st.booleans()):  # duplicated clips: exact ties between clips
        P[rng.integers(0, M)] = P[rng.integers(0, M)]
    if draw(st.booleans()):  # one clip off the map altogether: its residual opens all its starts
        P[rng.integers(0, M)] = rng.standard_normal((T, P.shape[2]))
    P = P.astype(np.float32)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    if draw(st.booleans()):
        F[rng.integers(0, M)] = F[rng.integers(0, M)]
    valid = rng.random((M, T)) < draw(st.sampled_from([1.0, 0.7]))
    N = draw(st.sampled_from([7, 8, 8, 9, 3]))  # 3: starts the copy does not cover
    query = rng.standard_normal((draw(st.integers(1, 5 * N)), A)).astype(np.float32)
    kw = {}
    if draw(st.booleans()):
        n_steps = -(-query.shape[0] // N)
        kw["masks"] = rng.random((1, M, T)) < 0.5
        kw["step_mask_index"] = rng.integers(-1, 1, size=n_steps)
    init = "random"
    if draw(st.booleans()):  # a query pose on or just off a database frame
        m, s = rng.integers(0, M), rng.integers(0, T)
        init = tuple((P[m, s] + draw(st.sampled_from([0.0, 1e-5, 1e-2])) * rng.standard_normal(P.shape[2])).tolist())
    kw["config"] = SearchConfig(
        k=draw(st.integers(0, M)),
        segment=N,
        record=draw(st.integers(1, M + 1)),
        seed=draw(st.integers(0, 5)),
        init_pose=init,
    )
    return P, F, valid, query, kw


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frame_problems())
def test_searches_scanning_the_frame_copy_give_the_reference_result(problem):
    P, F, valid, query, kw = problem
    assert_same(*run_both(P, F, valid, query, **kw))


def test_held_poses_with_sensor_noise_give_the_reference_result():
    # every start of every clip within a few 1e-4 of the others: the nearest start is decided
    # by differences near the frame bound, the residual's share of it included
    rng = np.random.default_rng(5)
    M, T, A = 12, 64, 112
    P = built_features(rng, ["jitter"] * M, T, broken=1e-5)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    valid = np.ones((M, T), bool)
    index = SearchIndex(P, F, valid)
    assert index.frames() is not None
    q = P[3, 10]
    est, bound, exact, _, _ = _frame_estimates(P, q, valid)
    seen = ~np.isnan(est)
    near = np.sort(np.where(valid, exact, np.inf), axis=1)
    assert np.mean(near[:, 1] - near[:, 0] < 2 * bound) > 0.5  # most clips' two nearest starts lie within the bound
    assert np.all(np.abs(est - exact)[seen] <= np.broadcast_to(bound[:, None], est.shape)[seen])
    query = rng.standard_normal((48, A)).astype(np.float32)
    for k in (0, 2):
        cfg = SearchConfig(k=k, segment=8, record=4, seed=1, init_pose=tuple(q.tolist()))
        assert_same(*run_both(P, F, valid, query, config=cfg))


@pytest.mark.parametrize("copy", ["frames", "8-bit"])
def test_a_one_query_scan_settles_the_clips_it_leaves_open_exactly(copy):
    # held poses (exact ties, a query at distance zero from every start of its own clip), grids
    # and near-ties: the clips no tier decides are resolved by the scan itself, exactly (error
    # bound 0, the nearest non-zero start, ties to the first), and none is left to the decisions
    rng = np.random.default_rng(17)
    T = 64
    kinds = ["still", "jitter", "grid", "steps", "walk"] * 3
    P = built_features(rng, kinds, T)
    M = P.shape[0]
    P[5] = P[0]  # a duplicated clip: the query's zero distances twice
    F = rng.standard_normal((M, T, 5)).astype(np.float32)
    valid = rng.random((M, T)) < 0.9
    valid[:, T - 7 :] = False
    index = SearchIndex(P, F, valid, pose_offsets=None if copy == "frames" else ())
    assert (index.frames() is not None) == (copy == "frames")
    bias = np.where(valid.ravel(), index._np32, np.float32(np.inf))
    resolved = 0
    for q in (P[0, 12], P[1, 30] + np.float32(1e-4), P[2, 7]):
        s0, d2, err, _, undecided, _ = index._scan(q[None], [bias], F[0, :1], window=8)
        assert undecided[0][0].size == 0
        exact = np.where(valid, exact_pose_sqdist(P.reshape(M * T, -1), q).reshape(M, T), np.inf)
        exact[exact == 0] = np.inf  # Algorithm 1's nearest start is a non-zero one
        for m in range(M):
            if not np.isfinite(exact[m]).any():
                assert not np.isfinite(d2[0, m])
                continue
            assert s0[0, m] == int(np.argmin(exact[m]))
            if err[0, m] == 0:
                assert d2[0, m] == exact[m].min()
                resolved += 1
            else:
                assert abs(d2[0, m] - exact[m].min()) <= err[0, m]
    assert resolved > 0


@pytest.mark.parametrize("window", [1, 6])
def test_starts_the_copy_does_not_cover_are_settled_in_float32(window):
    # a scan told the window covers every start, given admissible starts past the covered ones,
    # still finds each clip's nearest start (those clips go to the float32 tier whole)
    rng = np.random.default_rng(8)
    M, T = 9, 24
    P = built_features(rng, ["walk", "still", "steps"] * 3, T)
    F = rng.standard_normal((M, T, 4)).astype(np.float32)
    valid = rng.random((M, T)) < 0.8
    index = SearchIndex(P, F, valid)
    assert index.frames() is not None
    adm = valid.copy()
    adm[:, T - window + 1 :] = False
    bias = np.where(adm.ravel(), index._np32, np.float32(np.inf))
    q = (P[2, 5] + 0.01).astype(np.float32)
    s0, d2, err, _, undecided, _ = index._scan(q[None], [bias], F[0, :1], window=8)
    exact = np.where(adm, exact_pose_sqdist(P.reshape(M * T, -1), q).reshape(M, T), np.inf)
    exact[exact == 0] = np.inf
    open_clips = set(undecided[0][0].tolist())
    for m in range(M):
        if not np.isfinite(exact[m]).any():
            assert not np.isfinite(d2[0, m])
        elif m not in open_clips:
            assert s0[0, m] == int(np.argmin(exact[m]))
            assert abs(d2[0, m] - exact[m].min()) <= err[0, m]


def test_a_start_off_the_map_is_found_through_the_residual():
    # the later blocks of one start moved towards the query, the frames the copy keeps untouched:
    # the copy's estimate of that start does not move, the start becomes the nearest of its clip,
    # and only the residual in the clip's bound can say so
    rng = np.random.default_rng(21)
    T, c = 64, 3
    P = built_features(rng, ["walk"] * 5, T)
    valid = np.ones(P.shape[:2], bool)
    valid[:, T - 7 :] = False
    q = (P[c, 10] + 0.5).astype(np.float32)
    est, bound, exact, framed, fq = _frame_estimates(P, q, valid)
    top = framed.stats[c, 1]
    float32_part = pose_err_factor(P.shape[2]) * (top**2 + (top + framed.shift_norm) ** 2 + fq.norm**2)
    row = est[c]
    nearest = int(np.nanargmin(row))
    moved = int(np.nanargmin(np.where(row > row[nearest] + 4 * float32_part, row, np.nan)))
    target = exact[c, nearest] - 0.5 * (row[moved] - row[nearest])
    q64, p64 = q.astype(np.float64), P[c, moved].astype(np.float64)
    base = np.sum((q64[:K] - p64[:K]) ** 2)
    r2 = np.sum((q64[K:] - p64[K:]) ** 2)
    t = 1.0 - np.sqrt((target - base) / r2)
    P2 = P.copy()
    P2[c, moved, K:] = (p64[K:] + t * (q64[K:] - p64[K:])).astype(np.float32)
    index = SearchIndex(P2, np.ones(P.shape[:2] + (3,), np.float32), valid)
    framed2 = index.frames()
    assert framed2 is not None and np.array_equal(framed2.codes, framed.codes)  # the copy's frames are untouched
    assert framed2.stats[c, 0] > 10 * float32_part / (2 * (top + fq.norm))
    truth = exact_pose_sqdist(P2[c], q)
    assert int(np.argmin(np.where(valid[c], truth, np.inf))) == moved
    bias = np.where(valid.ravel(), index._np32, np.float32(np.inf))
    s0, _, _, _, undecided, _ = index._scan(q[None], [bias], np.ones((1, 3), np.float32), window=8)
    assert c in set(undecided[0][0].tolist()) or s0[0, c] == moved
    cfg = SearchConfig(segment=8, record=5, seed=0, init_pose=tuple(q.tolist()))
    query = rng.standard_normal((16, 3)).astype(np.float32)
    assert_same(*run_both(P2, np.ones(P.shape[:2] + (3,), np.float32), valid, query, config=cfg))


@pytest.mark.parametrize("offsets", [(0, 3), (0, 2, 5), (0, 1, 2, 3, 4, 5)], ids=["two", "three", "six"])
def test_other_layouts_of_frames_ahead_give_the_reference_result(offsets):
    # a database built with other offsets, told to the index: the copy sums its blocks one by one
    rng = np.random.default_rng(len(offsets))
    offsets = np.asarray(offsets, np.int64)
    M, T, A = 6, 32, 5
    P = built_features(rng, ["walk", "steps", "jitter", "walk", "grid", "still"], T, offsets=offsets)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    valid = rng.random((M, T)) < 0.9
    index = SearchIndex(P, F, valid, pose_offsets=offsets)
    framed = index.frames()
    assert framed is not None and framed.codes.shape == (M, P.shape[2] // offsets.size, T)
    assert SearchIndex(P, F, valid).frames() is None  # the default layout's offsets do not fit it
    query = rng.standard_normal((40, A)).astype(np.float32)
    for k in (0, 2):
        cfg = SearchConfig(k=k, segment=8, record=4, seed=k, init_pose=tuple((P[1, 4] + 1e-3).tolist()))
        ref = run_both(P, F, valid, query, config=cfg)[1]
        assert_same((index.search(query, config=cfg), ref[1]), ref)
    assert index._reduced is None  # the frame copy served every step
