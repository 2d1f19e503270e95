"""The scan on a torch device (gesturekit.search.device) gives the reference's result, decision for decision.

Run on torch's CPU device, as every machine has it: the path is the one a GPU takes (one float32
product over every start there, copied back and reduced by the same kernels under the same bound);
no test needs a GPU.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.errors import ConfigError
from gesturekit.search import SearchConfig, SearchIndex
from gesturekit.search.reference import search_reference
from gesturekit.search.stream import StepSearch
from tests.search.test_search import assert_same, problems, run_both, small_db

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
