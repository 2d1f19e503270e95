"""Tests of gesturekit.search: the fast search equals the loop-for-loop reference
(gesturekit.search.reference) decision for decision, and the rules of Algorithm 1
(exclusions, controls, relaxation, k beyond the survivors, pins, seeds, batches) hold."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.search import (
    SearchConfig,
    SearchIndex,
    describe_steps,
    exact_cosine_distance,
    exact_pose_sqdist,
    search,
    search_batch,
)
from gesturekit.search.reference import cosine_distance, pose_sqdist, search_reference

SLOW = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def run_both(P, F, valid, query, *, fast=search, **kw):
    """(fast, reference) results, or the two ConfigError messages; warnings recorded. ``fast`` is called as
    :func:`search` is (default: it)."""
    out = []
    for fn in (fast, search_reference):
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            try:
                r = fn(P, F, valid, query, **kw)
            except ConfigError as exc:
                r = f"ConfigError: {exc}"
        out.append((r, [str(x.message) for x in w if issubclass(x.category, GestureKitWarning)]))
    return out


def assert_same(a, b):
    (ra, wa), (rb, wb) = a, b
    if isinstance(ra, str) or isinstance(rb, str):
        assert ra == rb
        return
    for name, x in ra.array_fields().items():
        y = rb.array_fields()[name]
        assert x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
    assert ra.config == rb.config
    assert wa == wb


@st.composite
def databases(draw, *, max_clips=7):
    """A small database whose values sit on a coarse grid (exact ties, duplicated frames),
    optionally offset far from zero (float32 cancellation in ``|p|^2 - 2 p.q``)."""
    M = draw(st.integers(1, max_clips))
    T = draw(st.sampled_from([6, 12, 20, 64]))
    D = draw(st.sampled_from([2, 5, 96]))
    A = draw(st.sampled_from([1, 3, 112]))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    grid = draw(st.sampled_from([0.5, 0.25, 0.0]))  # 0: continuous values
    offset = draw(st.sampled_from([0.0, 0.0, 300.0]))

    def values(shape):
        x = rng.standard_normal(shape)
        if grid:
            x = np.round(x / grid) * grid
        return (x + offset).astype(np.float32)

    P = values((M, T, D))
    F = values((M, T, A))
    if draw(st.booleans()):  # duplicated frames and clips
        n = M * T
        src = rng.integers(0, n, size=max(1, n // 4))
        dst = rng.integers(0, n, size=src.size)
        P.reshape(n, D)[dst] = P.reshape(n, D)[src]
        F.reshape(n, A)[dst] = F.reshape(n, A)[src]
    if draw(st.booleans()):
        F.reshape(-1, A)[rng.integers(0, M * T, size=2)] = 0.0  # zero audio vectors (cosine = 1)
    valid = rng.random((M, T)) < draw(st.sampled_from([1.0, 0.9, 0.6]))
    return P, F, valid, rng


@st.composite
def problems(draw, *, max_clips=7):
    P, F, valid, rng = draw(databases(max_clips=max_clips))
    M, T, D = P.shape
    A = F.shape[2]
    N = draw(st.integers(1, min(T, 9)))
    T_out = draw(st.integers(1, 4 * N + 3))
    n_steps = -(-T_out // N)
    query = rng.standard_normal((T_out, A)).astype(np.float32)
    if draw(st.booleans()):  # query audio equal to database frames
        rows = F.reshape(-1, A)[rng.integers(0, M * T, size=T_out)]
        query[:] = rows
    kw = {}
    if draw(st.booleans()):
        n_masks = draw(st.integers(1, 2))
        kw["masks"] = rng.random((n_masks, M, T)) < draw(st.sampled_from([0.9, 0.5, 0.1]))
        kw["step_mask_index"] = rng.integers(-1, n_masks, size=n_steps)
    if draw(st.booleans()):
        kw["exclude"] = rng.random((M, T)) < 0.1
    init = "random"
    if draw(st.booleans()):  # p_{-1} equal to a database frame: its distance is exactly 0
        m, s = rng.integers(0, M), rng.integers(0, T)
        init = tuple(P[m, s].tolist())
    pins = {}
    if draw(st.booleans()):
        i = int(rng.integers(0, n_steps))
        pins[i] = (int(rng.integers(0, M)), int(rng.integers(0, T - N + 1)))
        if "exclude" in kw:
            kw["exclude"][pins[i][0], pins[i][1] : pins[i][1] + N] = False
    kw["config"] = SearchConfig(
        k=draw(st.integers(0, M + 1)),
        segment=N,
        record=draw(st.integers(1, 4)),
        seed=draw(st.integers(0, 5)),
        init_pose=init,
        mask_rule=draw(st.sampled_from(["ends", "all"])),
        pins=pins,
    )
    return P, F, valid, query, kw


# -- exact definitions ------------------------------------------------------------------------


@given(st.integers(0, 2**31 - 1), st.integers(1, 40), st.sampled_from([1, 7, 96, 112]), st.booleans())
def test_vectorised_exact_distances_equal_the_definitions(seed, n, dim, coarse):
    rng = np.random.default_rng(seed)
    rows = rng.standard_normal((n, dim)) * 10.0 ** rng.integers(-3, 4, size=(n, 1))
    if coarse:
        rows = np.round(rows)
    rows = rows.astype(np.float32)
    q = rows[rng.integers(0, n)].copy() if rng.random() < 0.3 else rng.standard_normal(dim).astype(np.float32)
    if rng.random() < 0.2:
        rows[0] = 0.0
    d2 = exact_pose_sqdist(rows, q)
    cos = exact_cosine_distance(rows, q)
    for i in range(n):
        assert d2[i] == pose_sqdist(rows[i].tolist(), q.tolist())
        assert cos[i] == cosine_distance(rows[i].tolist(), q.tolist())
    assert cos[0] == 1.0 if not rows[0].any() else True


def _whole_order_groups(est, err, order):
    """lo, hi of the groups of a whole order (every group complete)."""
    from gesturekit.search.kernels import prefix_groups

    n = est.size
    lo, hi = np.empty(n, np.int64), np.empty(n, np.int64)
    assert prefix_groups(est, err, order, n, lo, hi, np.empty(n + 1, np.int64), np.empty(n + 1, np.int64)) == n
    return lo, hi


def test_rank_groups_bound_the_exact_ranks():
    rng = np.random.default_rng(3)
    exact = np.round(rng.standard_normal(500), 2)  # many exact ties
    err = np.full(500, 0.004)
    est = exact + rng.uniform(-1, 1, 500) * err
    lo, hi = _whole_order_groups(est, err, np.argsort(est))
    exact_rank = np.empty(500, int)
    exact_rank[np.lexsort((np.arange(500), exact))] = np.arange(500)
    assert np.all(lo <= exact_rank) and np.all(exact_rank <= hi)
    assert (hi > lo).any() and (hi == lo).any()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 300), st.sampled_from([0.0, 0.004, 0.05]), st.integers(1, 320))
def test_prefix_groups_bound_the_exact_ranks(seed, n, err_size, L):
    # a sorted prefix of L positions (the rest only partitioned off): positions before the
    # returned s are in complete groups, every other element's rank lies in [s, n - 1]
    from gesturekit.search.kernels import prefix_groups

    rng = np.random.default_rng(seed)
    exact = np.round(rng.standard_normal(n), 2)  # exact ties
    err = np.full(n, err_size)
    est = exact + rng.uniform(-1, 1, n) * err
    L = min(L, n)
    key = est.astype(np.float32)
    order = np.argpartition(key, L - 1) if L < n else np.argsort(key)
    order[:L] = order[:L][np.argsort(key[order[:L]])]
    lo, hi = np.empty(n, np.int64), np.empty(n, np.int64)
    s = prefix_groups(est, err, order, L, lo, hi, np.empty(n + 1, np.int64), np.empty(n + 1, np.int64))
    exact_rank = np.empty(n, int)
    exact_rank[np.lexsort((np.arange(n), exact))] = np.arange(n)
    assert np.all(lo <= exact_rank) and np.all(exact_rank <= hi)
    head = order[:s]
    assert set(exact_rank[head]) == set(range(s))  # the complete groups hold exactly the first s ranks
    assert np.all(lo[order[s:]] == s) and np.all(hi[order[s:]] == n - 1)
    if L == n:
        assert s == n
    else:
        rest = order[L:]
        full_lo, full_hi = _whole_order_groups(est, err, np.concatenate([order[:L], rest[np.argsort(key[rest])]]))
        # a group complete within the prefix is the group of the whole order
        assert np.all(lo[head] == full_lo[head]) and np.all(hi[head] == full_hi[head])


def _prefix_problem(seed: int, offset: float):
    rng = np.random.default_rng(seed)
    M, T, D, A = 90, 20, 96, 112
    # offset 40: far from 0, large error bounds and wide groups; duplicated clips: exact ties
    P = (np.round(rng.standard_normal((M, T, D)) / 0.25) * 0.25 + offset).astype(np.float32)
    P[rng.integers(0, M, 20)] = P[rng.integers(0, M, 20)]
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    return P, F, np.ones((M, T), bool), rng.standard_normal((16, A)).astype(np.float32)


def _with_prefix(prefix, fn):
    import gesturekit.search.decide as decide_module

    saved = decide_module._PREFIX, decide_module._PREFIX_SHARE
    decide_module._PREFIX, decide_module._PREFIX_SHARE = prefix, 0.0
    try:
        return fn()
    finally:
        decide_module._PREFIX, decide_module._PREFIX_SHARE = saved


@pytest.mark.slow
@settings(max_examples=16, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([0.0, 40.0]), st.sampled_from([1, 3, 24, 60]), st.integers(0, 3))
def test_short_sorted_prefixes_give_the_reference_result(seed, offset, prefix, k):
    # the decisions sort only a prefix of each ranking and fall back to whole orders when
    # it cannot decide: short prefixes exercise both ways
    P, F, valid, query = _prefix_problem(seed, offset)
    cfg = SearchConfig(k=k, segment=4, record=3, seed=seed % 5)
    assert_same(*_with_prefix(prefix, lambda: run_both(P, F, valid, query, config=cfg)))


def test_the_sorted_prefix_grows_with_the_survivors(monkeypatch):
    # a query's decisions first sort a share of the survivors (at least _PREFIX): the ranks
    # that decide a step grow with the database, and a prefix too short costs a second attempt
    import gesturekit.search.decide as decide_module

    P, F, valid, query = _prefix_problem(3, 0.0)
    asked = []
    plain = decide_module.initial_order

    def spy(v, prefix):
        asked.append((v.size, prefix))
        return plain(v, prefix)

    monkeypatch.setattr(decide_module, "initial_order", spy)
    monkeypatch.setattr(decide_module, "_PREFIX", 2)
    monkeypatch.setattr(decide_module, "_PREFIX_SHARE", 0.25)
    cfg = SearchConfig(k=0, segment=4, record=3, seed=0)
    SearchIndex(P, F, valid).search(query, config=cfg)
    assert asked and all(prefix >= max(2, int(0.25 * n)) for n, prefix in asked)
    assert any(prefix == int(0.25 * n) > 2 for n, prefix in asked)


def _spy_kernel(monkeypatch, name, note, loader="compiled", module="gesturekit.search.index"):
    """Make the search call ``note(args, out)`` after each call of its compiled kernel ``name``
    (of the module that ``loader``, a loader ``module`` imports, gives)."""
    import importlib

    search_module = importlib.import_module(module)

    kernels = getattr(search_module, loader)()

    class Recording:
        def __getattr__(self, attr):
            if attr != name:
                return getattr(kernels, attr)

            def spied(*args):
                out = getattr(kernels, name)(*args)
                note(args, out)
                return out

            return spied

    monkeypatch.setattr(search_module, loader, lambda: Recording())


def test_prefixes_decide_when_they_can_and_whole_orders_otherwise(monkeypatch):
    seen = []

    def note(args, out):
        estimates, _, lp, _, la = args[:5]
        seen.append("whole" if min(lp, la) >= estimates.shape[1] else "prefix" if out >= 0 else "retry")

    _spy_kernel(monkeypatch, "rank_top", note, module="gesturekit.search.decide")
    P, F, valid, query = _prefix_problem(0, 0.0)
    cfg = SearchConfig(segment=4, record=3)
    results = {}
    for prefix, expected in ((60, {"prefix"}), (10**6, {"whole"}), (3, {"retry", "prefix", "whole"})):
        seen.clear()
        results[prefix] = _with_prefix(prefix, lambda: search(P, F, valid, query, config=cfg))
        assert set(seen) <= expected and set(seen) & expected - {"retry"}, (prefix, seen)
        # one decision per step: retries with longer prefixes (8 times as long) until one decides
        assert len(seen) - seen.count("retry") == results[prefix].n_steps
    assert "retry" in seen
    assert results[60].equals(results[10**6]) and results[3].equals(results[10**6])


# -- fast == reference --------------------------------------------------------------------------


@SLOW
@given(problems())
def test_fast_search_equals_reference(problem):
    P, F, valid, query, kw = problem
    assert_same(*run_both(P, F, valid, query, **kw))


@pytest.mark.slow
@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([0.0, 0.25]), st.integers(0, 3))
def test_fast_search_equals_reference_on_a_larger_database(seed, grid, k):
    # enough clips for the float32 shortlist, the rank groups and the contender pruning
    rng = np.random.default_rng(seed)
    M, T, D, A = 120, 20, 96, 112
    P = rng.standard_normal((M, T, D))
    if grid:
        P = np.round(P / grid) * grid
    P = (P + 40.0).astype(np.float32)  # far from 0: float32 estimates with large error bounds
    P[rng.integers(0, M, 30)] = P[rng.integers(0, M, 30)]  # duplicated clips: exact ties
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    F[rng.integers(0, M, 20)] = F[rng.integers(0, M, 20)]
    valid = np.ones((M, T), bool)
    query = rng.standard_normal((20, A)).astype(np.float32)
    cfg = SearchConfig(k=k, segment=4, record=3, seed=seed % 7)
    assert_same(*run_both(P, F, valid, query, config=cfg))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems(), st.sampled_from([1, 2, 3, 1024]))
def test_the_scan_gives_the_reference_result_whatever_clips_it_takes_at_a_time(problem, sub_clips):
    # one query's scan estimates and reduces a few clips at a time
    import gesturekit.search.index as search_module

    P, F, valid, query, kw = problem
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(search_module, "_SUB_CLIPS", sub_clips)
        assert_same(*run_both(P, F, valid, query, **kw))


def test_the_reduced_scan_reads_only_admissible_rows_where_few_starts_are_admissible(monkeypatch):
    seen = []
    _spy_kernel(
        monkeypatch,
        "scan_reduced",
        lambda args, out: seen.append(np.isfinite(args[1]).sum(axis=1)),
        loader="compiled_reduced",
    )
    rng = np.random.default_rng(3)
    M, T, D, A = 16, 20, 96, 112
    P = rng.standard_normal((M, T, D)).astype(np.float32)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    masks = np.ones((1, M, T), bool)
    masks[0, :8, 1:] = False  # the first 8 clips: one admissible start each
    query = rng.standard_normal((16, A)).astype(np.float32)
    cfg = SearchConfig(segment=4, record=3, init_pose=tuple(P[9, 2].tolist()))
    kw = dict(config=cfg, masks=masks, step_mask_index=np.zeros(4, int))
    valid = np.ones((M, T), bool)
    assert search(P, F, valid, query, **kw).equals(search_reference(P, F, valid, query, **kw))
    admitted = np.concatenate(seen)
    # both ways of estimating a clip's starts ran: the admissible rows alone, and every row
    assert (4 * admitted < T).any() and (4 * admitted >= T).any()


@pytest.mark.slow
@settings(max_examples=15, deadline=None)
@given(st.lists(problems(max_clips=5), min_size=1, max_size=1), st.integers(2, 4), st.integers(0, 2**31 - 1))
def test_batch_equals_single_runs(problem, n_queries, seed):
    P, F, valid, _, kw = problem[0]
    rng = np.random.default_rng(seed)
    A = F.shape[2]
    masks = kw.get("masks")
    queries, configs, step_masks = [], [], []
    for _ in range(n_queries):
        cfg = SearchConfig(
            k=int(rng.integers(0, 3)),
            segment=int(rng.integers(1, min(P.shape[1], 6) + 1)),
            record=int(rng.integers(1, 4)),
            seed=int(rng.integers(0, 9)),
            mask_rule=str(rng.choice(["ends", "all"])),
        )
        q = rng.standard_normal((int(rng.integers(1, 25)), A)).astype(np.float32)
        n_steps = -(-q.shape[0] // cfg.segment)
        sm = None if masks is None or rng.random() < 0.3 else rng.integers(-1, masks.shape[0], n_steps)
        queries.append(q)
        configs.append(cfg)
        step_masks.append(sm)
    common = dict(masks=masks, exclude=kw.get("exclude"))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GestureKitWarning)
            batch = search_batch(P, F, valid, queries, configs=configs, step_mask_indices=step_masks, **common)
    except ConfigError:
        # then some query alone must fail too
        with pytest.raises(ConfigError), warnings.catch_warnings():
            warnings.simplefilter("ignore", GestureKitWarning)
            for q, c, sm in zip(queries, configs, step_masks):
                search(P, F, valid, q, config=c, step_mask_index=sm, **common)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GestureKitWarning)
        singles = [
            search(P, F, valid, q, config=c, step_mask_index=sm, **common)
            for q, c, sm in zip(queries, configs, step_masks)
        ]
    assert all(a.equals(b) for a, b in zip(batch, singles))


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_batch_skips_inadmissible_starts_and_clips_without_any(threads):
    # a control that admits only early starts of the first clips: the batch multiplies only the
    # starts some query may use, and parts of the database with none at all are skipped whole
    rng = np.random.default_rng(11)
    M, T, D, A = 40, 24, 6, 5
    P = rng.standard_normal((M, T, D)).astype(np.float32)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    valid = np.ones((M, T), bool)
    masks = np.zeros((1, M, T), bool)
    masks[0, : M // 3, :10] = True
    queries = [rng.standard_normal((30, A)).astype(np.float32) for _ in range(3)]
    configs = [SearchConfig(k=k, segment=4, record=5, mask_rule="all") for k in range(3)]
    step_masks = [np.zeros(8, np.int64), np.where(np.arange(8) % 2, 0, -1), np.zeros(8, np.int64)]
    index = SearchIndex(P, F, valid)
    index._workers = threads
    batch = index.search_batch(queries, configs=configs, masks=masks, step_mask_indices=step_masks)
    for q, c, sm, b in zip(queries, configs, step_masks, batch):
        single = search(P, F, valid, q, config=c, masks=masks, step_mask_index=sm)
        assert b.equals(single)
        controlled = np.flatnonzero(sm >= 0)
        assert (b.clip[controlled] < M // 3).all() and (b.start[controlled] <= 6).all()


# -- rules of the search -------------------------------------------------------------------------


def small_db(seed=0, M=12, T=20, D=6, A=5):
    rng = np.random.default_rng(seed)
    P = rng.standard_normal((M, T, D)).astype(np.float32)
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    valid = np.ones((M, T), bool)
    valid[:, -3:] = False
    return P, F, valid, rng


def windows(res):
    N = res.config.segment
    return [(m, s + j) for m, s in zip(res.clip, res.start) for j in range(N)]


@given(st.integers(0, 2**31 - 1), st.sampled_from([0.05, 0.3, 0.6]))
@settings(max_examples=20, deadline=None)
def test_excluded_frames_are_never_used(seed, rate):
    P, F, valid, rng = small_db(seed)
    exclude = rng.random(valid.shape) < rate
    query = rng.standard_normal((37, F.shape[2])).astype(np.float32)
    try:
        res = search(P, F, valid, query, config=SearchConfig(segment=4, k=int(rng.integers(0, 4))), exclude=exclude)
    except ConfigError:
        # legitimate only when at most one window of 4 frames avoids the exclusions: that
        # window is then the random initial frame, at distance 0 from itself
        admissible = [
            (m, s)
            for m in range(P.shape[0])
            for s in range(P.shape[1] - 3)
            if valid[m, s] and not exclude[m, s : s + 4].any()
        ]
        assert len(admissible) <= 1
        return
    assert not any(exclude[m, f] for m, f in windows(res))
    assert not exclude[res.init_frame]
    # the candidate tables hold no excluded window either
    for i in range(res.n_steps):
        for m, s in zip(res.cand_clip[i], res.cand_start[i]):
            if m >= 0:
                assert not exclude[m, s : s + 4].any()


def test_unsatisfiable_control_is_relaxed_reported_and_warned():
    P, F, valid, rng = small_db(1)
    query = rng.standard_normal((40, F.shape[2])).astype(np.float32)  # 5 steps of 8
    masks = np.stack([np.zeros_like(valid), rng.random(valid.shape) < 0.7])
    step_mask = np.array([1, 0, 0, 1, -1])
    with pytest.warns(GestureKitWarning, match=r"relaxed at steps 1-2:"):
        res = search(P, F, valid, query, masks=masks, step_mask_index=step_mask)
    assert res.relaxed.tolist() == [False, True, True, False, False]
    for i in (0, 3):  # the satisfiable control is obeyed
        m, s = res.clip[i], res.start[i]
        assert masks[1, m, s] and masks[1, m, s + 7]


def test_a_control_relaxed_for_many_steps_builds_its_empty_mask_once(monkeypatch):
    import gesturekit.search.index as search_module
    from gesturekit.search.stream import StepSearch

    built = []
    real = search_module.control_starts
    monkeypatch.setattr(search_module, "control_starts", lambda mask, *a: built.append(mask) or real(mask, *a))
    P, F, valid, rng = small_db(4)
    query = rng.standard_normal((64, F.shape[2])).astype(np.float32)  # 8 steps of 8
    masks = np.zeros((1,) + valid.shape, bool)  # admits nothing: relaxed at every step
    with pytest.warns(GestureKitWarning, match="relaxed"):
        res = search(P, F, valid, query, masks=masks, step_mask_index=np.zeros(8, int))
    assert res.relaxed.all() and len(built) == 1
    built.clear()
    live = StepSearch(SearchIndex(P, F, valid), SearchConfig(seed=res.config.seed))
    j = live.add_mask(masks[0])
    for i in range(8):
        live.step(query[8 * i], j, 8)
    with pytest.warns(GestureKitWarning, match="relaxed"):
        streamed = live.result()
    assert len(built) == 1 and np.array_equal(streamed.frames, res.frames)


def test_the_query_frame_itself_is_skipped_and_nothing_left_is_an_error():
    P, F, valid, rng = small_db(2, M=3, T=10)
    valid[:] = False
    valid[1, 2] = valid[2, 1] = True  # the only admissible windows of the database
    query = rng.standard_normal((8, F.shape[2])).astype(np.float32)
    res = search(P, F, valid, query, config=SearchConfig(init_pose=tuple(P[1, 2].tolist())))
    assert (res.clip[0], res.start[0]) == (2, 1)  # (1, 2) is at distance 0: the query's own frame
    assert res.n_candidates[0] == 1
    valid[2, 1] = False
    with pytest.raises(ConfigError, match="no database window is admissible"):
        search(P, F, valid, query, config=SearchConfig(init_pose=tuple(P[1, 2].tolist())))
    with pytest.raises(ConfigError, match="no database window is admissible"):
        search(P, F, valid, query)  # the random initial pose can only be that frame too
    valid[:] = False
    with pytest.raises(ConfigError, match="no admissible database frame"):
        search(P, F, valid, query)


def test_k_beyond_the_survivors_takes_the_last_and_records_it():
    P, F, valid, rng = small_db(3, M=4)
    query = rng.standard_normal((24, F.shape[2])).astype(np.float32)
    res = search(P, F, valid, query, config=SearchConfig(k=9, record=2))
    assert res.cand_clip.shape == (3, 10)
    assert np.all(res.short) and np.all(res.n_candidates == 4)
    assert np.all(res.position == 3)
    assert np.array_equal(res.clip, res.cand_clip[:, 3]) and np.array_equal(res.start, res.cand_start[:, 3])
    assert np.all(res.cand_clip[:, 4:] == -1) and np.isnan(res.cand_pose_dist[:, 4:]).all()


def test_same_seed_same_result_other_seed_other_start():
    P, F, valid, rng = small_db(4, M=30)
    query = rng.standard_normal((50, F.shape[2])).astype(np.float32)
    a = search(P, F, valid, query, config=SearchConfig(seed=11))
    b = search(P, F, valid, query, config=SearchConfig(seed=11))
    assert a.equals(b)
    inits = {search(P, F, valid, query[:8], config=SearchConfig(seed=s)).init_frame for s in range(6)}
    assert len(inits) > 1


@given(st.integers(0, 2**31 - 1), st.integers(2, 6))
@settings(max_examples=20, deadline=None)
def test_all_rule_uses_only_frames_inside_the_mask(seed, N):
    P, F, valid, rng = small_db(seed, M=10)
    masks = rng.random((2,) + valid.shape) < 0.8
    query = rng.standard_normal((30, F.shape[2])).astype(np.float32)
    n_steps = -(-30 // N)
    step_mask = rng.integers(-1, 2, n_steps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GestureKitWarning)
        kw = dict(masks=masks, step_mask_index=step_mask)
        res = search(P, F, valid, query, config=SearchConfig(segment=N, mask_rule="all"), **kw)
        ends = search(P, F, valid, query, config=SearchConfig(segment=N, mask_rule="ends"), **kw)
    for i in range(n_steps):
        if step_mask[i] >= 0 and not res.relaxed[i]:
            assert masks[step_mask[i], res.clip[i], res.start[i] : res.start[i] + N].all()
        if step_mask[i] >= 0 and not ends.relaxed[i]:
            mk = masks[step_mask[i], ends.clip[i]]
            assert mk[ends.start[i]] and mk[ends.start[i] + N - 1]


def test_pins_force_the_choice_and_the_search_continues_from_them():
    P, F, valid, rng = small_db(5)
    query = rng.standard_normal((30, F.shape[2])).astype(np.float32)
    free = search(P, F, valid, query, config=SearchConfig(segment=6))
    alt = (int(free.cand_clip[1, 1]), int(free.cand_start[1, 1]))  # "use this candidate instead"
    pinned = search(P, F, valid, query, config=SearchConfig(segment=6, pins={1: alt}))
    assert (pinned.clip[1], pinned.start[1]) == alt and pinned.pinned.tolist() == [False, True, False, False, False]
    assert pinned.position[1] == 1
    assert np.array_equal(pinned.clip[:1], free.clip[:1])
    # step 2 searches from the pinned segment's last pose
    P2 = P.copy()
    expected = search(
        P2, F, valid, query[12:], config=SearchConfig(segment=6, init_pose=tuple(P[alt[0], alt[1] + 5].tolist()))
    )
    assert (pinned.clip[2], pinned.start[2]) == (expected.clip[0], expected.start[0])
    exclude = np.zeros_like(valid)
    exclude[alt[0], alt[1] + 2] = True
    with pytest.raises(ConfigError, match="excluded"):
        search(P, F, valid, query, config=SearchConfig(segment=6, pins={1: alt}), exclude=exclude)
    with pytest.raises(ConfigError, match="only 5 steps"):
        search(P, F, valid, query, config=SearchConfig(segment=6, pins={7: alt}))


def test_frames_follow_the_chosen_windows_and_the_last_step_is_cut():
    P, F, valid, rng = small_db(6)
    query = rng.standard_normal((21, F.shape[2])).astype(np.float32)
    res = search(P, F, valid, query, config=SearchConfig(segment=8))
    assert res.frames.shape == (21, 2) and res.n_steps == 3
    for t in range(21):
        i = t // 8
        assert tuple(res.frames[t]) == (res.clip[i], res.start[i] + t - 8 * i)
    # each step starts nearest (among admissible, non-zero) to the previous step's last pose
    for i in range(1, 3):
        prev = P[res.clip[i - 1], res.start[i - 1] + 7]
        d = np.linalg.norm(P[res.clip[i]] - prev, axis=1)
        best_in_clip = min(d[s] for s in range(P.shape[1] - 7) if valid[res.clip[i], s] and d[s] > 0)
        assert np.isclose(d[res.start[i]], best_in_clip)


def test_candidate_frame_and_config_round_trip():
    P, F, valid, rng = small_db(7)
    query = rng.standard_normal((16, F.shape[2])).astype(np.float32)
    cfg = SearchConfig(k=1, record=3, seed=2, init_pose=tuple(np.zeros(6)), mask_rule="all", pins={1: (2, 3)})
    res = search(P, F, valid, query, config=cfg)
    df = res.candidates_frame()
    assert list(df.columns) == [
        "step",
        "position",
        "clip",
        "start",
        "pose_dist",
        "audio_dist",
        "pose_rank",
        "audio_rank",
        "combined",
        "chosen",
    ]
    assert len(df) == 6 and df.chosen.sum() == 1  # step 1 is pinned to a window outside the table
    row = df[df.chosen].iloc[0]
    assert (row["step"], row["position"], row["clip"], row["start"]) == (0, 1, res.clip[0], res.start[0])
    assert (df.combined == df.pose_rank + df.audio_rank).all()
    assert (df.groupby("step").combined.diff().dropna() >= 0).all()
    back = SearchConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert back == cfg
    # configurations saved before the initial pose was called init_pose are read as they were
    old = {**cfg.to_dict(), "init": cfg.to_dict()["init_pose"]}
    del old["init_pose"]
    assert SearchConfig.from_dict(old) == cfg
    with pytest.raises(ConfigError, match="unknown"):
        SearchConfig.from_dict({"k": 1, "nope": 2})


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(P=np.zeros((3, 20, 6), np.float32)), "audio features must have shape"),
        (dict(valid=np.ones((12, 20), np.uint8)), "valid must be a bool array"),
        (dict(query=np.zeros((5, 4), np.float32)), "query audio features must have shape"),
        (dict(query=np.full((5, 5), np.nan, np.float32)), "NaN"),
        (dict(config=SearchConfig(segment=21)), "longer than a database clip"),
        (dict(config=SearchConfig(init_pose=(1.0, 2.0))), "initial pose must have 6 values"),
        (dict(step_mask_index=np.array([0, 0])), "step_mask_index entries must be -1 or an index below 0"),
        (dict(exclude=np.zeros((12, 19), bool)), "exclude must be a bool array"),
    ],
)
def test_bad_inputs_raise_config_errors(change, message):
    P, F, valid, rng = small_db(8)
    kw = dict(P=P, F=F, valid=valid, query=rng.standard_normal((16, 5)).astype(np.float32))
    kw.update(change)
    with pytest.raises(ConfigError, match=message):
        search(kw.pop("P"), kw.pop("F"), kw.pop("valid"), kw.pop("query"), **kw)


@pytest.mark.parametrize(
    "bad",
    [dict(k=-1), dict(segment=0), dict(mask_rule="middle"), dict(init_pose="rest"), dict(pins={0: 3}), dict(seed=True)],
)
def test_bad_config_values_raise(bad):
    with pytest.raises(ConfigError):
        SearchConfig(**bad)


def test_read_only_database_and_reused_index():
    P, F, valid, rng = small_db(9, M=40)
    P.setflags(write=False)
    F.setflags(write=False)
    idx = SearchIndex(P, F, valid)
    queries = [rng.standard_normal((n, 5)).astype(np.float32) for n in (9, 17, 33)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning about the read-only arrays
        batch = idx.search_batch(queries, configs=SearchConfig(segment=4, k=1))
    singles = [search_reference(P, F, valid, q, config=SearchConfig(segment=4, k=1)) for q in queries]
    assert all(a.equals(b) for a, b in zip(batch, singles))


def test_thread_settings_are_restored_after_a_search():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    torch = pytest.importorskip("torch")
    P, F, valid, rng = small_db(10, M=20)
    queries = [rng.standard_normal((12, 5)).astype(np.float32) for _ in range(5)]
    before = [(d["filepath"], d["num_threads"]) for d in threadpoolctl.threadpool_info()]
    torch_threads = torch.get_num_threads()
    search_batch(P, F, valid, queries)
    search(P, F, valid, queries[0])
    after = [(d["filepath"], d["num_threads"]) for d in threadpoolctl.threadpool_info()]
    # a library the search loads on its way (scipy's BLAS, when no earlier test loaded it) is not one it changed
    known = {path for path, _ in before}
    assert [a for a in after if a[0] in known] == before and torch.get_num_threads() == torch_threads


@settings(max_examples=80, deadline=None)
@given(st.sets(st.integers(0, 40), min_size=1, max_size=30), st.integers(1, 12))
def test_describe_steps_covers_exactly_the_steps_in_seconds(steps, N):
    fps = 15.0
    text = describe_steps(steps, segment=N, fps=fps, most=100)
    assert text.endswith(f"({len(steps)} step{'s' if len(steps) > 1 else ''})")
    covered = set()
    for part in text.rsplit(" (", 1)[0].split(", "):
        a, b = (float(v) for v in part.removesuffix(" s").split("-"))
        covered |= {i for i in range(41) if a - 0.005 <= i * N / fps < b - 0.005}  # times are rounded to 0.01 s
    assert covered == set(steps)


def test_describe_steps_joins_runs_and_shortens_long_lists():
    assert describe_steps(range(1, 9), segment=8, fps=15.0) == "0.53-4.80 s (8 steps)"
    assert describe_steps([1, 2], segment=8) == "steps 1-2"
    assert describe_steps([3], segment=8) == "step 3"
    many = describe_steps([0, 2, 4, 6, 8], segment=8, fps=15.0)
    assert many == "0.00-0.53 s, 1.07-1.60 s, 2.13-2.67 s, and 2 more stretches (5 steps)"
