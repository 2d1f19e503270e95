"""Benchmark of the k-NN search (gesturekit.search) at the scale of the paper's database.

Prints, measured in this one run on this machine:

* per search step vs one float32 matrix-vector product over the whole pose matrix
  (M T x 96), the memory-bound floor of a float32 scan (target <= 1.0x: one query's scan
  reads an 8-bit copy of the pose features, see gesturekit.search.reduced), and the same for
  pose features built of frames ahead as a database's are, whose scan reads the 16-bit frame
  copy (gesturekit.search.frames);
* the fast search vs the literal reference (gesturekit.search.reference), per
  clip-step (target >= 250x);
* end-to-end time for 60 s of speech (900 frames, 113 steps; target < 2 s);
* a batch of 32 query sequences vs 32 single runs (target >= 5x);
* peak extra memory of the search vs the database size, the 8-bit copy included (target < 25%).

The database is random: 9,624 clips x 64 frames (the "Oliver" database of the
paper), features drawn from a standard normal distribution, as the z-scored
features are; the second pose matrix is a random walk's joints at four frames ahead,
z-scored. Run: ``python bench/bench_search.py`` (a few minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import tracemalloc

import numpy as np

from gesturekit.search import SearchConfig, SearchIndex, search
from gesturekit.search.reference import search_reference

M_OLIVER, T, D, A = 9624, 64, 96, 112

#: Seconds for numpy's BLAS threads to stop polling after a product (OpenBLAS: about 0.1 s).
BLAS_IDLE = 0.3


def make_db(M: int, rng: np.random.Generator):
    P = rng.standard_normal((M, T, D), dtype=np.float32)
    F = rng.standard_normal((M, T, A), dtype=np.float32)
    valid = np.ones((M, T), bool)
    valid[:, -14:] = False  # the last frames of takes need padding; here every clip's, to be strict
    return P, F, valid


def make_built(M: int, rng: np.random.Generator) -> np.ndarray:
    """Pose features (M, T, D) built as a database builds them: 8 joints x 3 at t, t+2, t+4, t+6
    of a random walk (motion: each frame a small step from the last), z-scored per dimension,
    so that one query's scan reads the frame copy (gesturekit.search.frames)."""
    offsets = (0, 2, 4, 6)
    K = D // len(offsets)
    P = np.empty((M, T, D), np.float32)
    moments = np.zeros((2, D))
    for a in range(0, M, 1024):  # in parts: float64 trajectories of every clip at once would take GiBs
        b = min(M, a + 1024)
        walk = np.cumsum(0.05 * rng.standard_normal((b - a, T + offsets[-1], K)), axis=1) + rng.standard_normal(
            (b - a, 1, K)
        )
        P[a:b] = np.concatenate([walk[:, o : o + T] for o in offsets], axis=2)
    flat = P.reshape(-1, D).astype(np.float64)
    moments[0], moments[1] = flat.mean(axis=0), flat.std(axis=0)
    P -= moments[0].astype(np.float32)
    P /= moments[1].astype(np.float32)
    return P


def best_of(fn, reps: int) -> float:
    """Shortest of ``reps`` timings: on a shared machine, other load only ever adds time."""
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return min(ts)


def device_share(index, query: np.ndarray, cfg) -> tuple[float, float]:
    """One search on ``index`` (one with a ``device``): its seconds, and those spent in the device's scan
    (the product, the per-clip reduction and the copies back); the rest are the decisions here."""
    rows = index._device
    rows.scan_seconds = 0.0
    t0 = time.perf_counter()
    index.search(query, config=cfg)
    return time.perf_counter() - t0, rows.scan_seconds


def step_vs_matvec(
    index: SearchIndex, P2: np.ndarray, query: np.ndarray, cfg: SearchConfig, *, runs: int, steps: int = 30
) -> tuple[float, float, list[float]]:
    """One search step vs one float32 matrix-vector product over the pose matrix ``P2`` (M T, D).

    Pairs are taken back to back (a search of ``steps`` steps bracketed by products), so
    both members of a pair see the same machine state; ``P2`` may be memory-mapped (the
    products then read it from the disk cache, as the search does). The product is numpy's
    (its BLAS's threads on all cores), whose idle threads keep polling the cores for about
    0.1 s after it returns: the search starts after they have gone to sleep, as it does in
    use, where it does not follow such a product.

    Returns
    -------
    (median seconds per step, median seconds per product, ratio of each pair)
    """
    q = np.array(P2[min(12345, P2.shape[0] - 1)], dtype=np.float32)
    out = np.empty(P2.shape[0], np.float32)
    part = query[: steps * cfg.segment]
    ratios, t_steps, gemvs = [], [], []
    for _ in range(runs):
        g0 = best_of(lambda: np.dot(P2, q, out=out), 3)
        time.sleep(BLAS_IDLE)
        t0 = time.perf_counter()
        r = index.search(part, config=cfg)
        step = (time.perf_counter() - t0) / r.n_steps
        g1 = best_of(lambda: np.dot(P2, q, out=out), 3)
        ratios.append(step / (0.5 * (g0 + g1)))
        t_steps.append(step)
        gemvs.append(0.5 * (g0 + g1))
    return float(np.median(t_steps)), float(np.median(gemvs)), ratios


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clips", type=int, default=M_OLIVER)
    ap.add_argument("--reps", type=int, default=3, help="repetitions of the timed searches")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--batch-reps", type=int, default=5, help="pairs of (batch, single runs) timed")
    ap.add_argument("--batch-seconds", type=float, default=5.0, help="length of each batched query")
    ap.add_argument("--device", help="also the search with its scan on this torch device (cuda)")
    args = ap.parse_args(argv)

    rng = np.random.default_rng(0)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}, "
        f"numpy {np.__version__}; load average {' '.join(f'{x:.1f}' for x in os.getloadavg())} "
        "(other processes share the cores: timings are medians or bests of repeated runs)"
    )
    M = args.clips
    P, F, valid = make_db(M, rng)
    db_bytes = P.nbytes + F.nbytes + valid.nbytes
    print(f"database: {M} clips x {T} frames, pose {D} + audio {A} float32 = {db_bytes / 2**20:.0f} MiB")
    query = rng.standard_normal((900, A), dtype=np.float32)  # 60 s at 15 fps
    cfg = SearchConfig(k=0, segment=8, seed=1)
    n_b = int(round(args.batch_seconds * 15))
    queries = [rng.standard_normal((n_b, A), dtype=np.float32) for _ in range(args.batch)]
    configs = [SearchConfig(k=int(i % 3), segment=8, seed=i) for i in range(args.batch)]

    # warm-up on a small database: compiled kernels and torch load outside every measurement
    Pw, Fw, vw = make_db(64, rng)
    SearchIndex(Pw, Fw, vw).search_batch(queries[:4], configs=configs[:4])

    # 1. memory: numpy's allocations are traced (MKL's small packing buffers inside torch are not)
    t0 = time.perf_counter()
    index = SearchIndex(P, F, valid)
    t_index = time.perf_counter() - t0
    tracemalloc.start()
    idx2 = SearchIndex(P, F, valid)
    index_bytes = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    idx2.search(query, config=cfg)
    peak_single = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    idx2.search_batch(queries, configs=configs)
    peak_batch = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    del idx2
    print(
        f"\n[memory] index (norms, bounds) {index_bytes / 2**20:.1f} MiB = {index_bytes / db_bytes:.1%} of the "
        f"database; peak extra during a search (tracemalloc; the 8-bit copy it makes included) "
        f"{peak_single / 2**20:.1f} MiB -> with the index {(index_bytes + peak_single) / db_bytes:.1%}; during a "
        f"batch of {args.batch}: {peak_batch / 2**20:.1f} MiB -> {(index_bytes + peak_batch) / db_bytes:.1%} "
        "(target < 25%)"
    )

    # 2. per step vs one matrix-vector product
    P2 = P.reshape(-1, D)
    t_step, t_gemv, ratios = step_vs_matvec(index, P2, query, cfg, runs=3 * args.reps)
    print(
        f"\n[per step] {cfg.segment} frames per step: {t_step * 1e3:.1f} ms per step (median of {len(ratios)} runs of "
        f"30 steps); one float32 matrix-vector product over ({P2.shape[0]}, {D}): {t_gemv * 1e3:.1f} ms; "
        f"ratio per pair: median {np.median(ratios):.2f}x, best {min(ratios):.2f}x (target <= 1.0x)"
    )

    # 2b. the same for pose features built of frames ahead, as a database's are: the frame copy
    Pb = make_built(M, rng)
    tracemalloc.start()
    built = SearchIndex(Pb, F, valid)
    base = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    built.search(query, config=cfg)
    peak_built = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    assert built.frames() is not None and built._reduced is None, "the frame copy is not used"
    b_step, b_gemv, b_ratios = step_vs_matvec(built, Pb.reshape(-1, D), query, cfg, runs=3 * args.reps)
    b_search = best_of(lambda: built.search(query, config=cfg), 2)
    print(
        f"[per step, features built of frames ahead] {b_step * 1e3:.1f} ms per step; one float32 matrix-vector "
        f"product {b_gemv * 1e3:.1f} ms; ratio per pair: median {np.median(b_ratios):.2f}x, best {min(b_ratios):.2f}x "
        f"(target <= 1.0x); 60 s of speech {b_search:.2f} s; peak extra during a search (the frame copy it makes "
        f"included) {peak_built / 2**20:.1f} MiB -> with the index {(index_bytes + peak_built) / db_bytes:.1%}"
    )

    # 3. end to end for 60 s of speech
    t_search = best_of(lambda: index.search(query, config=cfg), 2)
    t_e2e = best_of(lambda: search(P, F, valid, query, config=cfg), 2)
    print(
        f"[60 s of speech] 113 steps on a prepared index {t_search:.2f} s (index preparation {t_index:.2f} s); "
        f"search() from plain arrays, both included: {t_e2e:.2f} s (target < 2 s)"
    )

    # 3b. the scan on a torch device (a GPU), the same result
    if args.device:
        t0 = time.perf_counter()
        there = SearchIndex(P, F, valid, device=args.device)
        t_place = time.perf_counter() - t0
        assert there.search(query, config=cfg).equals(index.search(query, config=cfg)), "device and CPU disagree"
        d_step, _, d_ratios = step_vs_matvec(there, P2, query, cfg, runs=3 * args.reps)
        d_search = best_of(lambda: there.search(query, config=cfg), 2)
        t_all, t_there = device_share(there, query, cfg)
        print(
            f"[device {args.device}] {d_step * 1e3:.2f} ms per step = {np.median(d_ratios):.2f}x one float32 "
            f"matrix-vector product on the CPU; 60 s of speech {d_search:.2f} s on a prepared index (features "
            f"placed in {t_place:.2f} s), of which the scan there {t_there:.2f} s and the decisions here "
            f"{t_all - t_there:.2f} s; the same result as on the CPU"
        )

    # 4. fast vs the literal reference, per clip-step
    Ms = 60
    Ps, Fs, vs = P[:Ms], F[:Ms], valid[:Ms]
    qs = query[:48]  # 6 steps
    ref = search_reference(Ps, Fs, vs, qs, config=cfg)
    t_ref = best_of(lambda: search_reference(Ps, Fs, vs, qs, config=cfg), 2) / (Ms * ref.n_steps)
    small = SearchIndex(Ps, Fs, vs)
    assert small.search(qs, config=cfg).equals(ref), "fast and reference searches disagree"
    t_small = best_of(lambda: small.search(qs, config=cfg), 5) / (Ms * ref.n_steps)
    t_big = t_step / M
    print(
        f"[vs reference] reference {t_ref * 1e6:.0f} us per clip-step ({Ms} clips, {ref.n_steps} steps, identical "
        f"result); fast {t_big * 1e6:.2f} us per clip-step at {M} clips -> {t_ref / t_big:.0f}x (target >= 250x); "
        f"fast on the same {Ms} clips, where fixed per-step costs dominate: {t_small * 1e6:.1f} us -> "
        f"{t_ref / t_small:.0f}x"
    )

    # 5. a batch of 32 sequences vs 32 single runs, alternating, so that other load on the
    # machine falls on both alike; the ratio of each pair, and the median of them
    ratios, t_batch, t_singles = [], [], []
    for _ in range(args.batch_reps):
        t0 = time.perf_counter()
        batch = index.search_batch(queries, configs=configs)
        t_batch.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        singles = [index.search(qq, config=c) for qq, c in zip(queries, configs)]
        t_singles.append(time.perf_counter() - t0)
        ratios.append(t_singles[-1] / t_batch[-1])
    assert all(a.equals(b) for a, b in zip(batch, singles)), "batch and single runs disagree"
    print(
        f"[batch] {args.batch} sequences of {args.batch_seconds:g} s ({batch[0].n_steps} steps, k = 0..2): one batch "
        f"median {np.median(t_batch):.2f} s, {args.batch} single runs median {np.median(t_singles):.2f} s; "
        f"ratio per pair: median {np.median(ratios):.1f}x, best {max(ratios):.1f}x (target >= 5x)"
    )


if __name__ == "__main__":
    main()
