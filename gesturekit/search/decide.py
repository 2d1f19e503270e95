"""Steps 1-4 of Algorithm 1 for one query, after the scan of a step (:mod:`gesturekit.search.index`).

Step 1 (per clip the nearest admissible non-zero start) takes the scan's minimum where it is
decisive and resolves the other clips exactly, tier by tier (a single query's scan has resolved
them already, on its threads: then there are none). Steps 2-4 rank the survivors by
pose and by audio distance: ranks are known up to groups of near-equal estimates, and only
groups holding a clip that could make the top ``width`` of the combined ranking are settled with
exact values. The compiled loops are in :mod:`gesturekit.search.kernels` (``survivors``,
``rank_top``).
"""

from __future__ import annotations

import threading
from concurrent.futures import Executor

import numpy as np

from .._arguments import checks_arguments
from .exact import TINY, compiled, initial_order

__all__ = ["decide_query"]

#: Survivors sorted first by each ranking in a query's decisions: at least ``_PREFIX``, at
#: least the share ``_PREFIX_SHARE`` of them; the rest is only partitioned off. Enough
#: whenever the top of the combined ranking lies within that head of both rankings; its
#: ranks grow with the database (on 100 hours, 86,184 clips, 1,024 sufficed in a third of
#: the steps, an eighth in all), and more when pose and audio disagree throughout or many
#: clips repeat others. Otherwise prefixes 8 times longer, up to the whole orders (same result).
_PREFIX = 1024
_PREFIX_SHARE = 1 / 8


@checks_arguments
def decide_query(
    db: tuple[np.ndarray, np.ndarray, np.ndarray, float, float],
    local: threading.local,
    scan: tuple,
    query: tuple[np.ndarray, np.ndarray],
    width: int,
    pool: Executor | None = None,
) -> dict | None:
    """One query's decisions of a step; None when no clip survives.

    Parameters
    ----------
    db : (poses, audio, clip_max_sqnorm, pose_err_factor, audio_err)
        The database's pose (M, T, D) and audio (M, T, A) features, per clip the largest
        ``|p|^2`` (M,), and the float32 scan's pose and audio error factors.
    local : threading.local
        Keeps each thread's scratch arrays between steps (fresh pages for every query cost
        page faults).
    scan : (best_start, best_d2, best_err, q_sqnorm, undecided, audio_est, audio_inexact)
        The scan's outputs for this query (see ``SearchIndex._scan``).
    query : (query_pose, query_audio)
        ``p_{t-1}`` (D,) and ``f_t`` (A,), float32.
    width : int
        The rows of the combined ranking to list.
    pool : Executor, optional
        Makes the audio ranking's initial order beside the pose one's.

    Returns
    -------
    dict
        ``n`` (survivors) and the table columns (top ``width`` in combined order).
    """
    poses, audio, clip_max_sqnorm, pose_err, audio_err = db
    best_start, best_d2, best_err, q_sqnorm, undecided, scan_audio_est, scan_audio_inexact = scan
    query_pose, query_audio = query
    M = poses.shape[0]
    k = compiled()
    scratch = getattr(local, "decide", None)
    if scratch is None or scratch[0].shape[1] != M:
        scratch = local.decide = (np.empty((9, M), np.int64), np.empty((4, M)))
    work, estimates = scratch
    windows = work[7:9]  # rows 0-6 are rank_top's scratch
    undecided_clips, undecided_rows = undecided
    n = k.survivors(
        best_start,
        best_d2,
        best_err,
        float(q_sqnorm),
        (clip_max_sqnorm, pose_err, TINY),
        undecided_clips,
        undecided_rows,
        poses,
        query_pose,
        audio,
        query_audio,
        scan_audio_est,
        scan_audio_inexact,
        audio_err,
        windows,
        estimates,
    )
    if n == 0:
        return None
    windows, estimates = windows[:, :n], estimates[:, :n]
    out_i = np.empty((5, min(width, n)), np.int64)
    out_f = np.empty((2, min(width, n)))
    prefix = max(_PREFIX, int(_PREFIX_SHARE * n))
    while True:  # sorted prefixes first; whole orders when they cannot decide
        # the two orders are independent: with a pool, the audio one is made beside the pose one
        later = None if pool is None else pool.submit(initial_order, estimates[2], prefix)
        pose_order, n_pose_sorted = initial_order(estimates[0], prefix)
        audio_order, n_audio_sorted = initial_order(estimates[2], prefix) if later is None else later.result()
        ranked = k.rank_top(
            estimates,
            pose_order,
            n_pose_sorted,
            audio_order,
            n_audio_sorted,
            windows,
            poses,
            audio,
            query_pose,
            query_audio,
            width,
            out_i,
            out_f,
            work,
        )
        if ranked >= 0:
            break
        if prefix >= n:  # pragma: no cover - whole orders always decide
            raise RuntimeError("rank_top could not decide with whole orders")
        prefix = min(n, 8 * prefix)  # longer prefixes first: whole orders cost a full sort each
    return {
        "n": n,
        "cand_clip": out_i[0],
        "cand_start": out_i[1],
        "cand_pose_dist": out_f[0],
        "cand_audio_dist": out_f[1],
        "cand_pose_rank": out_i[2],
        "cand_audio_rank": out_i[3],
        "cand_combined": out_i[4],
    }
