"""Tests of the reduced pose copy (gesturekit.search.reduced): its estimates lie within their
proven bound on rows built to be hard for it, the bound is narrow enough to decide most clips,
and searches of databases made of near-ties across the bound equal the reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.search import SearchConfig, SearchIndex, exact_pose_sqdist
from gesturekit.search.exact import TINY, pose_err_factor
from gesturekit.search.reduced import clip_bounds, compiled_reduced, quantise_query, reduce_pose
from tests.search.test_search import assert_same, run_both

ROW_KINDS = ["normal", "offset", "grid", "edges", "constant", "tiny", "huge", "spike", "zero"]


def _rows(kind: str, rng: np.random.Generator, T: int, D: int) -> np.ndarray:
    """One clip's pose features (T, D) float32 of a kind that is hard for 8-bit rounding."""
    if kind == "normal":  # z-scored features
        return rng.standard_normal((T, D)).astype(np.float32)
    if kind == "offset":  # far from the origin: float32 cancellation
        return (rng.standard_normal((T, D)) + 300.0).astype(np.float32)
    if kind == "grid":  # exact ties between starts
        return (np.round(rng.standard_normal((T, D)) * 4) / 4).astype(np.float32)
    if kind == "edges":
        # rows in +/- pairs, so the clip's centre is exactly 0, each value half-way between two
        # rounding levels of its row's scale (a power of two): every value loses half a step
        half = np.empty((T // 2, D))
        scale = 2.0 ** rng.integers(-8, 2, size=(T // 2, 1))
        half[:] = (rng.integers(-126, 126, size=(T // 2, D)) + 0.5) * scale
        half[:, 0] = 127 * scale[:, 0]
        rows = np.zeros((T, D))
        rows[0 : 2 * (T // 2) : 2] = half
        rows[1 : 2 * (T // 2) : 2] = -half
        return rows.astype(np.float32)
    if kind == "constant":  # every row the centre: nothing to round
        return np.repeat(rng.standard_normal((1, D)), T, axis=0).astype(np.float32)
    if kind == "tiny":  # scales near float32's smallest normal numbers
        return (rng.standard_normal((T, D)) * 1e-36).astype(np.float32)
    if kind == "huge":
        return (rng.standard_normal((T, D)) * 1e12).astype(np.float32)
    if kind == "spike":  # one value sets the scale; the others round to 0
        rows = rng.standard_normal((T, D)) * 1e-3
        rows[:, rng.integers(0, D)] = 50.0
        return rows.astype(np.float32)
    return np.zeros((T, D), np.float32)


@st.composite
def reduced_cases(draw):
    T = draw(st.sampled_from([2, 7, 20, 64]))
    D = draw(st.sampled_from([1, 5, 96, 200]))
    kinds = draw(st.lists(st.sampled_from(ROW_KINDS), min_size=1, max_size=4))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    P = np.stack([_rows(k, rng, T, D) for k in kinds])
    where = draw(st.sampled_from(["row", "near", "normal", "far", "zero"]))
    if where == "row":
        q = P[rng.integers(0, P.shape[0]), rng.integers(0, T)].copy()
    elif where == "near":
        q = (P[rng.integers(0, P.shape[0]), rng.integers(0, T)] + 1e-3 * rng.standard_normal(D)).astype(np.float32)
    elif where == "far":
        q = (100.0 * rng.standard_normal(D)).astype(np.float32)
    elif where == "zero":
        q = np.zeros(D, np.float32)
    else:
        q = rng.standard_normal(D).astype(np.float32)
    return P, q


def _estimates(P: np.ndarray, q: np.ndarray):
    """The reduced estimates of every start (M, T), each clip's bound (M,) as the scan computes it
    and as :func:`clip_bounds` does, and the exact squared distances (M, T)."""
    M, T, D = P.shape
    red = reduce_pose(P)
    codes = quantise_query(q)
    k = compiled_reduced()
    arrays = (red.codes, red.coef, red.kappa, red.centre, red.stats)
    qs = np.float32(codes.scale)
    est = np.empty((M, T))
    scan_bound = np.empty(M)
    centred = np.empty(M)
    for c in range(M):
        centred[c] = k.centred_sqnorm(q, red.centre, c)
        scan_bound[c] = k.reduced_bound(red.stats, c, centred[c], (codes.lost, codes.norm), pose_err_factor(D), TINY)
        for s in range(T):
            est[c, s] = np.float64(k.reduced_estimate(arrays, c, s, codes.codes, qs)) + centred[c]
    exact = exact_pose_sqdist(P.reshape(M * T, D), q).reshape(M, T)
    return est, scan_bound, clip_bounds(red.stats, centred, codes, D), exact, red


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(reduced_cases())
def test_reduced_estimates_lie_within_their_bound(case):
    P, q = case
    est, scan_bound, bound, exact, red = _estimates(P, q)
    assert np.all(np.isfinite(est)) and np.all(np.isfinite(bound))
    np.testing.assert_allclose(scan_bound, bound, rtol=1e-12)  # the scan's bound is the documented one
    assert np.all(np.abs(est - exact) <= bound[:, None]), np.max(np.abs(est - exact) - bound[:, None])
    # the stored codes stay in range and the scale is exact: -2 s is a float32 with s > 0
    assert red.codes.min() >= -127 and red.codes.max() <= 127
    assert np.all(red.coef < 0)


def test_values_half_way_between_levels_lose_half_a_step_each():
    rng = np.random.default_rng(5)
    P = _rows("edges", rng, 8, 96)[None]
    red = reduce_pose(P)
    assert np.array_equal(red.centre, np.zeros((1, 96), np.float32))
    # each row's scale is its largest value / 127, a power of two, so every other value is off by s/2
    scale = -red.coef[0] / 2
    lost = np.sqrt(95) * scale / 2
    assert red.stats[0, 0] == pytest.approx(lost.max(), rel=1e-12)


def test_the_bound_decides_most_clips_of_z_scored_features():
    # the point of the copy: on z-scored features most clips' nearest start is decided
    # by the 8-bit estimates alone, and the bound is a small part of the distances
    rng = np.random.default_rng(0)
    P = rng.standard_normal((300, 64, 96)).astype(np.float32)
    q = P[17, 5].copy()
    est, _, bound, exact, _ = _estimates(P, q)
    assert np.median(bound) < 0.02 * np.median(exact)
    lowest = est.min(axis=1)
    open_ = np.count_nonzero(est <= (lowest + 2 * bound)[:, None], axis=1) > 1
    assert open_.mean() < 0.5
    # and it is not loose by orders of magnitude: the errors reach a tenth of it
    assert np.max(np.abs(est - exact) / bound[:, None]) > 0.1


@st.composite
def straddling_problems(draw):
    """Databases of near-ties across the reduced bound: starts of a clip closer than the 8-bit
    bound (or than the float32 one, or equal), clips duplicated, values on rounding edges."""
    M = draw(st.integers(2, 8))
    T = draw(st.sampled_from([12, 20]))
    D = draw(st.sampled_from([5, 96]))
    A = draw(st.sampled_from([3, 112]))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kinds = draw(st.lists(st.sampled_from(["normal", "grid", "edges", "offset"]), min_size=M, max_size=M))
    P = np.stack([_rows(k, rng, T, D) for k in kinds]).astype(np.float64)
    for _ in range(draw(st.integers(0, 3 * M))):  # a start nudged next to another of its clip
        m, s1, s2 = rng.integers(0, M), rng.integers(0, T), rng.integers(0, T)
        delta = draw(st.sampled_from([0.0, 1e-6, 1e-4, 1e-2, 0.1]))
        P[m, s2] = P[m, s1] + delta * rng.standard_normal(D)
    if draw(st.booleans()):  # duplicated clips: exact ties between clips
        P[rng.integers(0, M)] = P[rng.integers(0, M)]
    P = P.astype(np.float32)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    if draw(st.booleans()):  # equal audio too: ties in both rankings
        F[rng.integers(0, M)] = F[rng.integers(0, M)]
    valid = rng.random((M, T)) < draw(st.sampled_from([1.0, 0.7]))
    N = draw(st.integers(1, 5))
    query = rng.standard_normal((draw(st.integers(1, 4 * N)), A)).astype(np.float32)
    kw = {}
    if draw(st.booleans()):
        n_steps = -(-query.shape[0] // N)
        kw["masks"] = rng.random((1, M, T)) < 0.5
        kw["step_mask_index"] = rng.integers(-1, 1, size=n_steps)
    init = "random"
    if draw(st.booleans()):  # a query pose just off a database frame
        m, s = rng.integers(0, M), rng.integers(0, T)
        init = tuple((P[m, s] + draw(st.sampled_from([0.0, 1e-5, 1e-2])) * rng.standard_normal(D)).tolist())
    kw["config"] = SearchConfig(
        k=draw(st.integers(0, M)),
        segment=N,
        record=draw(st.integers(1, M + 1)),
        seed=draw(st.integers(0, 5)),
        init_pose=init,
    )
    return P, F, valid, query, kw


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(straddling_problems())
def test_near_ties_across_the_bound_give_the_reference_result(problem):
    P, F, valid, query, kw = problem
    assert_same(*run_both(P, F, valid, query, **kw))


@pytest.mark.slow  # loads the batch's kernels: about a second on 2 cores
def test_a_batch_does_not_make_the_reduced_copy():
    # several queries' scan is a float32 matrix product: the copy's memory is spent only for single queries
    rng = np.random.default_rng(2)
    P = rng.standard_normal((6, 12, 5)).astype(np.float32)
    F = rng.standard_normal((6, 12, 3)).astype(np.float32)
    index = SearchIndex(P, F, np.ones((6, 12), bool))
    queries = [rng.standard_normal((9, 3)).astype(np.float32) for _ in range(3)]
    batch = index.search_batch(queries, configs=SearchConfig(segment=3))
    assert index._reduced is None
    single = index.search(queries[0], config=SearchConfig(segment=3))
    assert index._reduced is not None and single.equals(batch[0])


def test_many_open_clips_give_the_reference_result():
    # the scan settles the open clips and reads the nearest starts in passes that ask for rows
    # several clips ahead: a database where far more clips than that are left open by the
    # 8-bit bound (adjacent starts a small step apart) must still give the reference result
    rng = np.random.default_rng(11)
    M, T, D, A = 48, 20, 96, 112
    walk = np.cumsum(0.005 * rng.standard_normal((M, T, D)), axis=1) + rng.standard_normal((M, 1, D))
    P = walk.astype(np.float32)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    init = P[7, 3] + np.float32(1e-3)
    est, bound, _, _, _ = _estimates(P, init)
    open_ = np.count_nonzero(est <= (est.min(axis=1) + 2 * bound)[:, None], axis=1) > 1
    assert open_.sum() > 2 * compiled_reduced().PREFETCH_AHEAD
    query = rng.standard_normal((24, A)).astype(np.float32)
    for k in (0, 3):
        cfg = SearchConfig(k=k, segment=4, record=5, seed=2, init_pose=tuple(init.tolist()))
        assert_same(*run_both(P, F, np.ones((M, T), bool), query, config=cfg))


@st.composite
def rows_finite_within(draw):
    """A (2, T) float32 row pair whose estimates are +inf outside starts lo .. hi - 1."""
    T = draw(st.integers(1, 40))
    lo = draw(st.integers(0, T))
    hi = draw(st.integers(lo, T))
    values = st.one_of(st.sampled_from([0.0, 1.0, -1.0, np.inf]), st.floats(-1e3, 1e3, width=32))
    row = np.full(T, np.inf, np.float32)
    row[lo:hi] = draw(st.lists(values, min_size=hi - lo, max_size=hi - lo))
    est = np.stack([np.full(T, np.float32(5.0)), row])
    return est, lo, hi, draw(st.sampled_from([0.0, 1e-3, 2.0])), draw(st.sampled_from([1e-6, 0.5, 3.0]))


@settings(max_examples=200, deadline=None)
@given(rows_finite_within())
def test_a_clips_minimum_within_its_finite_starts_is_its_minimum(case):
    # the open clips' float32 tier reduces only the starts that could be nearest; the rest are +inf
    from gesturekit.search.kernels import clip_minimum, clip_minimum_within

    est, lo, hi, offset, err = case
    assert clip_minimum_within(est, 1, lo, hi, offset, err) == clip_minimum(est, 1, offset, err)


def _plain_clip_minimum(row: np.ndarray, offset: float, err: float) -> tuple[int, float, bool]:
    """The reduction of one row as its definition says, in numpy and float64."""
    best = row.min()
    if not np.isfinite(best):
        return 0, float(best), False
    arg = int(np.flatnonzero(row == best)[0])  # the first start of least estimate
    t = np.float64(best) + 2.0 * err
    t32 = np.float32(t) if np.float32(t) >= t else np.nextafter(np.float32(t), np.float32(np.inf))
    near = int(np.count_nonzero(row <= t32))
    return arg, float(best), near > 1 or np.float64(best) + offset <= err


@settings(max_examples=300, deadline=None)
@given(rows_finite_within())
def test_a_clips_minimum_is_the_plain_reduction(case):
    # the compiled reduction (a running minimum by selection, loops without early exits) against
    # the definition: first start of least estimate, the estimate, and whether it is decisive
    from gesturekit.search.kernels import clip_minimum_within

    est, lo, hi, offset, err = case
    arg, best, open_ = clip_minimum_within(est, 1, lo, hi, offset, err)
    want = _plain_clip_minimum(est[1], offset, err)
    assert (arg, open_) == (want[0], want[2])
    assert best == want[1] or (np.isinf(best) and np.isinf(want[1]))


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-1e30, 1e30).map(np.float32).filter(np.isfinite),
    st.floats(0, 1e30),
    st.floats(0, 1e25),
    st.floats(0, 1e25),
    st.floats(0, 1e30),
)
def test_the_open_clips_threshold_lies_above_the_exact_sum(e32, q_sqnorm, err32, err, centred):
    # the float32 value below which a start nearer than the float32-estimated one must lie: the
    # exact (rational) sum of its terms, never above it, however float64 rounds the sum
    from fractions import Fraction

    t = compiled_reduced().threshold_above(np.float32(e32), q_sqnorm, err32, err, centred)
    exact = Fraction(float(np.float32(e32))) + Fraction(q_sqnorm) + Fraction(err32) + Fraction(err) - Fraction(centred)
    assert Fraction(float(t)) >= exact
    # and not loose: above it by at most the margin and one float32 step
    magnitude = abs(float(np.float32(e32))) + q_sqnorm + err32 + err + centred
    slack = Fraction(2e-12 * magnitude) + Fraction(abs(float(np.spacing(np.float32(t)))))
    assert Fraction(float(t)) - exact <= slack
