"""The scan on a torch device (gesturekit.search.device) gives the reference's result, decision for decision.

Run on torch's CPU device, as every machine has it: the path is the one a GPU takes (one float32
product over every start there, reduced there per clip under the same bound; only per clip values
and the open clips' rows come back); no test needs a GPU.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.errors import ConfigError
from gesturekit.search import SearchConfig, SearchIndex
from gesturekit.search.exact import pose_err_factor
from gesturekit.search.reference import search_reference
from gesturekit.search.stream import StepSearch
from tests.search.test_search import assert_same, databases, problems, run_both, small_db

torch = pytest.importorskip("torch")


def _on_device(P, F, valid, query, **kw):
    """:func:`gesturekit.search.search` with the scan on torch's CPU device."""
    return SearchIndex(P, F, valid, device="cpu").search(query, **kw)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems())
def test_the_scan_on_a_device_gives_the_reference_result(problem):
    # ties, duplicated frames, values far from zero, controls, exclusions, pins, k beyond the survivors
    P, F, valid, query, kw = problem
    assert_same(*run_both(P, F, valid, query, fast=_on_device, **kw))


@pytest.mark.slow
@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(0, 3))
def test_on_a_larger_database_with_duplicated_clips(seed, k):
    rng = np.random.default_rng(seed)
    M, T, D, A = 120, 20, 96, 112
    P = (np.round(rng.standard_normal((M, T, D)) / 0.25) * 0.25 + 40.0).astype(np.float32)  # wide bounds
    P[rng.integers(0, M, 30)] = P[rng.integers(0, M, 30)]  # exact ties
    F = rng.standard_normal((M, T, A)).astype(np.float32)
    valid = np.ones((M, T), bool)
    query = rng.standard_normal((20, A)).astype(np.float32)
    assert_same(
        *run_both(P, F, valid, query, fast=_on_device, config=SearchConfig(k=k, segment=4, record=3, seed=seed % 7))
    )


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(databases(max_clips=9), st.integers(1, 4), st.integers(0, 2**31 - 1))
def test_each_clip_reduced_there_agrees_with_the_exact_distances(db, B, seed):
    # the device's per-clip reduction, against the float64 definitions: a start it calls decided
    # is the clip's unique nearest within the bound, every estimate lies within the bound, an open
    # clip's row holds every start that could be nearest, and the audio within the audio bound
    P, F, valid, rng = db
    M, T, D = P.shape
    index = SearchIndex(P, F, valid, device="cpu")
    Q = P.reshape(-1, D)[rng.integers(0, M * T, B)] + rng.integers(-1, 2, (B, 1)).astype(np.float32)
    fq = F.reshape(-1, F.shape[2])[rng.integers(0, M * T, B)] * np.float32(0.5)
    np2 = (P.astype(np.float64) ** 2).sum(-1)
    biases = [
        np.where(valid & (rng.random(valid.shape) < 0.8), np2, np.inf).astype(np.float32).ravel() for _ in range(B)
    ]
    s0, d2, err, nq, undecided, (av, inexact) = index._scan(Q.astype(np.float32), biases, fq)
    exact = ((P[None].astype(np.float64) - Q[:, None, None].astype(np.float64)) ** 2).sum(-1)  # (B, M, T)
    u = F.astype(np.float64)
    for b in range(B):
        admitted = np.isfinite(biases[b]).reshape(M, T)
        d_b = np.where(admitted, exact[b], np.inf)
        open_clips, rows = undecided[b]
        for m in range(M):
            if not admitted[m].any():
                assert d2[b, m] == np.inf and np.isnan(av[b, m])
                continue
            s = s0[b, m]
            assert admitted[m, s] and abs(d2[b, m] - d_b[m, s]) <= err[b, m]
            near = d_b[m] <= d_b[m].min() + 2 * err[b, m]
            if m in open_clips:
                row = rows[list(open_clips).index(m)]
                assert np.all(np.isfinite(row[near]))  # no start that could be nearest is dropped
            else:
                assert near.sum() == 1 and near[s] and d_b[m, s] > err[b, m]
            a, f = u[m, s], fq[b].astype(np.float64)
            den = np.sqrt((a @ a) * (f @ f))
            want = 1.0 if den == 0 else 1.0 - (a @ f) / den
            assert inexact[b, m] == (den != 0)
            assert (
                abs(av[b, m] - want) <= (F.shape[2] + 16) * 2.0**-24 + 1e-12 or not inexact[b, m] and av[b, m] == want
            )
    assert err.shape == (B, M) and np.all(err >= pose_err_factor(D) * nq[:, None])


def test_only_per_clip_values_come_back_from_the_device(monkeypatch):
    # the full (M T, B) product stays there: a GPU's step moves a few values a clip, not T of them
    P, F, valid, rng = small_db(5, M=40, T=24)
    M, T = valid.shape
    query = rng.standard_normal((24, F.shape[2])).astype(np.float32)
    index = SearchIndex(P, F, valid, device="cpu")
    copied = []
    to_host = torch.Tensor.cpu

    def cpu(self, *args, **kwargs):
        copied.append(self.numel())
        return to_host(self, *args, **kwargs)

    monkeypatch.setattr(torch.Tensor, "cpu", cpu)
    cfg = SearchConfig(segment=4, k=2)
    assert index.search(query, config=cfg).equals(search_reference(P, F, valid, query, config=cfg))
    steps = 6  # 24 frames of 4
    assert len(copied) >= 5 * steps  # every step's per-clip values came back through here
    assert max(copied) < M * T // 4  # the rows of a few open clips at most, never every start's product


def test_a_batch_and_a_live_search_on_a_device_equal_the_searches_here():
    P, F, valid, rng = small_db(3, M=30, T=24)
    A = F.shape[2]
    queries = [rng.standard_normal((n, A)).astype(np.float32) for n in (17, 40, 8)]
    configs = [SearchConfig(k=k, segment=4, seed=k) for k in range(3)]
    here = SearchIndex(P, F, valid)
    there = SearchIndex(P, F, valid, device="cpu")
    batch = there.search_batch(queries, configs=configs)
    assert all(a.equals(here.search(q, config=c)) for a, q, c in zip(batch, queries, configs))
    live = StepSearch(there, configs[1])
    for i in range(0, 40, 4):
        live.step(queries[1][i], -1, 4)
    assert np.array_equal(live.result().frames, batch[1].frames)
    assert there._reduced is None  # the device's product scanned every step, not the 8-bit copy


def test_reduced_precision_products_and_unknown_devices_are_refused():
    P, F, valid, rng = small_db(1)
    query = rng.standard_normal((8, F.shape[2])).astype(np.float32)
    index = SearchIndex(P, F, valid, device="cpu")
    before = torch.get_float32_matmul_precision()
    try:
        torch.set_float32_matmul_precision("medium")  # bfloat16 products: the bound would not hold
        with pytest.raises(ConfigError, match="true float32 products"):
            index.search(query)
        with pytest.raises(ConfigError, match="true float32 products"):
            SearchIndex(P, F, valid, device="cpu")
    finally:
        torch.set_float32_matmul_precision(before)
    assert index.search(query).equals(search_reference(P, F, valid, query))
    with pytest.raises(ConfigError, match="not a torch device"):
        SearchIndex(P, F, valid, device="abacus")
    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="no CUDA device"):
            SearchIndex(P, F, valid, device="cuda")
