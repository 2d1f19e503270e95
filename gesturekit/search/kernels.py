"""The compiled loops of :mod:`gesturekit.search.index` (numba, a dependency of librosa).

Imported by :func:`gesturekit.search.exact.compiled` when a search first runs, not with the
package (numba is heavy). The loops are module-level functions compiled by
:func:`~gesturekit.search.compile_cache.kernel`, so that the on-disk cache serves them in
every later process, including those that call each other, and stays whole when several
processes compile at once.

The scan: :func:`~gesturekit.search.reduced_kernels.scan_reduced` (one query, a few clips
at a time, from the reduced copy; in :mod:`gesturekit.search.reduced_kernels`), :func:`reduce_many` and
:func:`audio_at` (several queries after a matrix product), :func:`admissible_ends`,
:func:`row_stats` (validation and norms). The exact decisions of one query after the
scan (see :func:`gesturekit.search.decide.decide_query`): :func:`survivors` and
:func:`rank_top`, with the exact distances of :mod:`gesturekit.search.reference`
(float64, left to right: :func:`pose_d2`, :func:`cos_d`). Names: ``best_start`` /
``best_est`` the scan's per-clip minimum, ``*_est`` an estimate, ``*_err`` its error
bound, ``q_sqnorm`` ``|p_{t-1}|^2``.
"""

from __future__ import annotations

import numpy as np

from .compile_cache import kernel


@kernel()
def reduce_many(
    products: np.ndarray,
    bias: np.ndarray,
    q_sqnorm: np.ndarray,
    pose_bound: tuple[np.ndarray, float, float],
    scan_out: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """:func:`gesturekit.search.exact.reduce_chunk` for several queries, one pass per clip.

    Parameters
    ----------
    products : (nc, T, B) float32
        ``-2 q.p`` per clip, start and query.
    bias : (nc, T) float32
        ``|p|^2`` where the start is admissible, +inf elsewhere.
    q_sqnorm : (B,) float64
        ``|q|^2`` per query.
    pose_bound : (clip_max_sqnorm, err_factor, tiny)
        ``clip_max_sqnorm`` (nc,) float64, the largest ``|p|^2`` per clip, and two floats:
        the pose error bound is ``err_factor (clip_max_sqnorm + q_sqnorm) + tiny``.
    scan_out : (best_start, best_est, undecided), each (nc, B): int64, float32, bool
        Out: per clip and query the first start of least estimate, that estimate, and
        whether it is not decisive (another start within twice the bound, or a possible zero).
    """
    clip_max_sqnorm, err_factor, tiny = pose_bound
    best_start, best_est, undecided = scan_out
    nc, T, n_queries = products.shape
    best = np.empty(n_queries, dtype=np.float32)
    thr = np.empty(n_queries, dtype=np.float32)
    arg = np.empty(n_queries, dtype=np.int32)  # 32-bit lanes like the values: wider vectors
    count = np.empty(n_queries, dtype=np.int32)
    for c in range(nc):
        for j in range(n_queries):
            best[j] = np.inf
            count[j] = 0
            arg[j] = 0
        for s in range(T):  # the inner loop runs along contiguous queries: vectorised
            p2 = bias[c, s]
            row = products[c, s]
            for j in range(n_queries):
                a = row[j] + p2  # float32, as the error bound assumes
                best[j] = a if a < best[j] else best[j]
        for j in range(n_queries):
            t64 = np.float64(best[j]) + 2.0 * (err_factor * (clip_max_sqnorm[c] + q_sqnorm[j]) + tiny)
            t32 = np.float32(t64)
            if t32 < t64:  # round the float32 threshold up
                t32 = np.nextafter(t32, np.float32(np.inf))
            thr[j] = t32
        for s in range(T - 1, -1, -1):  # backwards: arg ends at the first minimum
            p2 = bias[c, s]
            row = products[c, s]
            si = np.int32(s)
            for j in range(n_queries):
                a = row[j] + p2
                count[j] += np.int32(1) if a <= thr[j] else np.int32(0)
                arg[j] = si if a == best[j] else arg[j]
        for j in range(n_queries):
            err = err_factor * (clip_max_sqnorm[c] + q_sqnorm[j]) + tiny
            best_start[c, j] = arg[j]
            best_est[c, j] = best[j]
            undecided[c, j] = np.isfinite(best[j]) and (count[j] > 1 or np.float64(best[j]) + q_sqnorm[j] <= err)


# float32 products in any order (reassociation, FMA, SIMD lanes): the error bounds allow it
@kernel(fastmath={"reassoc", "contract"})
def dot32_at(poses: np.ndarray, c: int, s: int, query: np.ndarray) -> float:
    """``poses[c, s] . query`` in float32, summed in any order, without making a view of the row
    (a view in a loop costs reference counting)."""
    acc = np.float32(0.0)
    for j in range(query.shape[0]):
        acc += poses[c, s, j] * query[j]
    return acc


@kernel()
def audio_estimate(
    audio: np.ndarray, audio_sqnorms: np.ndarray, clip: int, start: int, query_audio: np.ndarray, query_sqnorm: float
) -> tuple[float, bool]:
    """The cosine distance estimate of ``audio[clip, start]`` to ``query_audio`` (float32 product,
    float64 norms ``audio_sqnorms`` and ``query_sqnorm``) and whether it is inexact: a zero
    vector gets the definition's value 1, exactly."""
    d = audio_sqnorms[clip, start] * query_sqnorm
    if d == 0.0:
        return 1.0, False
    return 1.0 - np.float64(dot32_at(audio, clip, start, query_audio)) / np.sqrt(d), True


@kernel()
def clip_minimum(est: np.ndarray, c: int, offset: float, err: float) -> tuple[int, float, bool]:
    """The reduction of one clip's row of estimates ``est[c]`` (T,) float32.

    ``est[c, s] + offset`` estimates the squared distance of start ``s`` within ``err``.
    Returns the first start of least estimate, that estimate, and whether it is not
    decisive: another start within twice the error bound of it, or a possible exact zero.
    """
    return clip_minimum_within(est, c, 0, est.shape[1], offset, err)


@kernel()
def clip_minimum_within(
    est: np.ndarray, c: int, lo: int, hi: int, offset: float, err: float
) -> tuple[int, float, bool]:
    """:func:`clip_minimum` of a row whose estimates outside starts ``lo .. hi - 1`` are +inf
    (the same result, reading only those starts; the first start 0 where none is finite)."""
    inf = np.float32(np.inf)
    # Four running minima by selection: one would make a chain of dependent comparisons (the
    # estimates are never NaN, so any order gives the same least value; of equal zeros of either
    # sign, the first one's value is taken below).
    m0 = m1 = m2 = m3 = inf
    s = lo
    while s + 4 <= hi:
        v0, v1, v2, v3 = est[c, s], est[c, s + 1], est[c, s + 2], est[c, s + 3]
        m0 = v0 if v0 < m0 else m0
        m1 = v1 if v1 < m1 else m1
        m2 = v2 if v2 < m2 else m2
        m3 = v3 if v3 < m3 else m3
        s += 4
    while s < hi:
        v0 = est[c, s]
        m0 = v0 if v0 < m0 else m0
        s += 1
    m0 = m1 if m1 < m0 else m0
    m2 = m3 if m3 < m2 else m2
    best = m2 if m2 < m0 else m0
    if not best < inf:
        return 0, best, False
    arg = lo
    for s in range(lo, hi):  # the first minimum
        if est[c, s] == best:
            arg = s
            break
    best = est[c, arg]
    t32 = threshold(best, err)
    count = 0
    for s in range(lo, hi):
        count += est[c, s] <= t32
    return arg, best, bool(count > 1 or np.float64(best) + offset <= err)


@kernel()
def threshold(best: float, err: float) -> np.float32:
    """``best + 2 err`` rounded up to float32: no estimate within twice the bound of ``best`` lies above it."""
    return round_up32(np.float64(best) + 2.0 * err)


@kernel()
def round_up32(t64: float) -> np.float32:
    """The least float32 value not below ``t64``."""
    t32 = np.float32(t64)
    if t32 < t64:
        t32 = np.nextafter(t32, np.float32(np.inf))
    return t32


@kernel()
def admissible_ends(bias: np.ndarray) -> np.ndarray:
    """Per clip, one past its last admissible start (0: none); ``bias`` (M, T) is +inf where not admissible."""
    M, T = bias.shape
    ends = np.zeros(M, np.int64)
    for c in range(M):
        for s in range(T - 1, -1, -1):  # from the end: only the last few starts are read
            if bias[c, s] < np.inf:
                ends[c] = s + 1
                break
    return ends


@kernel()
def row_stats(rows: np.ndarray, sqnorms: np.ndarray) -> tuple[bool, float]:
    """Float64 squared norms of ``rows`` (n, d) into ``sqnorms`` (n,).

    Returns (whether all values are finite, the largest magnitude): one pass for validation and norms.
    """
    finite = True
    top = 0.0
    for r in range(rows.shape[0]):
        acc = 0.0
        for j in range(rows.shape[1]):
            v = np.float64(rows[r, j])
            if not np.isfinite(v):
                finite = False
            top = max(top, abs(v))
            acc += v * v
        sqnorms[r] = acc
    return finite, top


@kernel()
def prefix_groups(
    est: np.ndarray,
    err: np.ndarray,
    order: np.ndarray,
    n_sorted: int,
    lo: np.ndarray,
    hi: np.ndarray,
    scratch_lo: np.ndarray,
    scratch_hi: np.ndarray,
) -> int:
    """Groups of near-equal estimates over the sorted prefix of an order.

    Each ``est[k]`` lies within ``err[k]`` of its exact value. ``order`` lists the elements,
    its first ``n_sorted`` positions sorted by estimate and the rest in any order, each above
    them by estimate (``n_sorted = n``: the whole order). A split before position ``i`` is
    proven when the largest upper end before ``i`` lies below the smallest lower end from ``i``
    on, the rest included.

    Returns ``s``: the elements at positions before ``s`` are in complete groups, and
    ``lo[k]``, ``hi[k]`` bound their exact rank (the group's positions); every other element
    gets ``lo = s``, ``hi = n - 1``. ``scratch_lo``, ``scratch_hi``: int64 scratch of at least
    ``n_sorted`` values.
    """
    n = order.shape[0]
    m = np.inf
    for i in range(n_sorted, n):
        k = order[i]
        m = min(m, est[k] - err[k])
    low = np.empty(n_sorted + 1)
    low[n_sorted] = m
    for i in range(n_sorted - 1, -1, -1):
        k = order[i]
        m = min(m, est[k] - err[k])
        low[i] = m
    start = 0
    top = -np.inf
    for i in range(1, n_sorted + 1):
        k = order[i - 1]
        top = max(top, est[k] + err[k])
        if top < low[i]:
            for r in range(start, i):  # by position; scratch_lo, scratch_hi: int64 scratch of >= n_sorted values
                scratch_lo[r] = start
                scratch_hi[r] = i - 1
            start = i
    for i in range(n):
        lo[i] = start
        hi[i] = n - 1
    for r in range(start):
        k = order[r]
        lo[k] = scratch_lo[r]
        hi[k] = scratch_hi[r]
    return start


@kernel()
def audio_at(
    audio: np.ndarray,
    audio_sqnorms: np.ndarray,
    scan: tuple[np.ndarray, np.ndarray],
    query_audio: np.ndarray,
    query_audio_sqnorm: np.ndarray,
    out: tuple[np.ndarray, np.ndarray],
) -> None:
    """The audio estimates at each clip's best start, for several queries.

    ``audio`` (nc, T, A) and ``audio_sqnorms`` (nc, T) of the clips; ``scan``: ``best_start``
    and ``best_est`` (nc, B) from the scan; ``query_audio`` (B, A) and ``query_audio_sqnorm`` (B,).
    ``out``: ``audio_est`` (nc, B), the cosine distance estimates, and ``audio_inexact``
    (nc, B) (False: exact), written.
    """
    best_start, best_est = scan
    audio_est, audio_inexact = out
    nc, n_queries = best_start.shape
    for c in range(nc):  # one clip's rows serve all its queries while they are in cache
        for j in range(n_queries):
            if best_est[c, j] < np.inf:
                audio_est[c, j], audio_inexact[c, j] = audio_estimate(
                    audio, audio_sqnorms, c, best_start[c, j], query_audio[j], query_audio_sqnorm[j]
                )


# -- the exact decisions of one query (steps 1-4 of Algorithm 1 after the scan) --------------
# No fastmath below: these are the exact values, the same operations in the same order as
# gesturekit.search.reference (float64, left to right).


@kernel()
def pose_d2(poses: np.ndarray, clip: int, start: int, query_pose: np.ndarray) -> float:
    """Exact squared distance of ``poses[clip, start]`` to ``query_pose`` (float64, left to right)."""
    acc = 0.0
    for j in range(query_pose.shape[0]):
        d = np.float64(poses[clip, start, j]) - np.float64(query_pose[j])
        acc += d * d
    return acc


@kernel()
def sq64(x: np.ndarray) -> float:
    """Exact squared norm of ``x`` (float64, left to right)."""
    acc = 0.0
    for j in range(x.shape[0]):
        y = np.float64(x[j])
        acc += y * y
    return acc


@kernel()
def cos_d(audio: np.ndarray, clip: int, start: int, query_audio: np.ndarray, query_sqnorm: float) -> float:
    """Exact cosine distance of ``audio[clip, start]`` to ``query_audio`` (squared norm ``query_sqnorm``)."""
    dot = 0.0
    sqnorm = 0.0
    for j in range(query_audio.shape[0]):
        x = np.float64(audio[clip, start, j])
        dot += x * np.float64(query_audio[j])
        sqnorm += x * x
    if sqnorm == 0.0 or query_sqnorm == 0.0:
        return 1.0
    return 1.0 - dot / np.sqrt(sqnorm * query_sqnorm)


@kernel()
def resolve_clip(
    row_est: np.ndarray, clip: int, q_sqnorm: float, err: float, poses: np.ndarray, query_pose: np.ndarray
) -> tuple[int, float]:
    """A clip's nearest admissible non-zero start, exactly, from its row of estimates.

    Exact values are computed tier by tier (the starts within ``2 err`` of the smallest
    unknown estimate) until the best non-zero exact value is proven: no unknown start
    could reach it. ``row_est`` (T,) float32 holds ``|p|^2 - 2 p.q`` (+inf: not admissible).
    Returns ``(start, d2)``, ``(-1, nan)`` when the clip drops out; ties: the smallest start.
    """
    T = row_est.shape[0]
    a = np.empty(T)
    known = np.full(T, np.nan)
    for s in range(T):
        a[s] = np.float64(row_est[s]) + q_sqnorm
    while True:
        best = np.inf
        nearest = np.inf
        for s in range(T):
            if not np.isnan(known[s]):
                if known[s] > 0.0:
                    best = min(best, known[s])
            elif np.isfinite(a[s]):
                nearest = min(nearest, a[s])
        pend = False
        for s in range(T):
            if np.isnan(known[s]) and np.isfinite(a[s]):
                if (a[s] - err <= best) if np.isfinite(best) else (a[s] <= nearest + 2.0 * err):
                    known[s] = pose_d2(poses, clip, s, query_pose)
                    pend = True
        if not pend:
            break
    if not np.isfinite(best):
        return -1, np.nan
    for s in range(T):  # ties: the smallest start
        if known[s] == best:
            return s, best
    return -1, np.nan


@kernel()
def survivors(
    best_start: np.ndarray,
    best_d2: np.ndarray,
    best_err: np.ndarray,
    q_sqnorm: float,
    pose_bound: tuple[np.ndarray, float, float],
    undecided_clips: np.ndarray,
    undecided_rows: np.ndarray,
    poses: np.ndarray,
    query_pose: np.ndarray,
    audio: np.ndarray,
    query_audio: np.ndarray,
    scan_audio_est: np.ndarray,
    scan_audio_inexact: np.ndarray,
    audio_bound: float,
    windows: np.ndarray,
    estimates: np.ndarray,
) -> int:
    """Step 1 of Algorithm 1 for one query after the scan: each clip's nearest admissible start.

    Parameters
    ----------
    best_start, best_d2, best_err : (M,) int64, float64, float64
        The scan's start of least estimate per clip, its squared distance estimate (+inf:
        none) and that estimate's error bound.
    q_sqnorm, pose_bound
        As for :func:`reduce_many` (one query): the float32 bound of the undecided rows.
    undecided_clips, undecided_rows : (c,) int64, (c, T) float32
        Clips whose minimum was not decisive and their rows of float32 estimates
        ``|p|^2 - 2 p.q`` (resolved exactly).
    poses, query_pose, audio, query_audio
        The database's pose (M, T, D) and audio (M, T, A) features, ``p_{t-1}`` and ``f_t``.
    scan_audio_est, scan_audio_inexact : (M,) float64, bool
        The scan's audio estimates at ``best_start`` (see :func:`~gesturekit.search.reduced_kernels.scan_reduced`).
    audio_bound : float
        The error bound of an inexact audio estimate.
    windows : (2, >= M) int64
        Out: row 0 the surviving clips (in clip order), row 1 their starts.
    estimates : (4, >= M) float64
        Out, per survivor: the pose estimate ``d2`` and its error bound, the audio
        estimate and its error bound (0: exact).

    Returns
    -------
    int
        The number of survivors (the first columns of ``windows`` and ``estimates``).
    """
    clip_max_sqnorm, err_factor, tiny = pose_bound
    M = best_start.shape[0]
    clips, start = windows[0], windows[1]
    pose_est, pose_err, audio_est, audio_err = estimates[0], estimates[1], estimates[2], estimates[3]
    undecided_row = np.full(M, -1, np.int64)
    for i in range(undecided_clips.shape[0]):
        undecided_row[undecided_clips[i]] = i
    query_audio_sqnorm = sq64(query_audio)
    n = 0
    for m in range(M):
        err = err_factor * (clip_max_sqnorm[m] + q_sqnorm) + tiny
        if undecided_row[m] >= 0:
            st, val = resolve_clip(undecided_rows[undecided_row[m]], m, q_sqnorm, err, poses, query_pose)
            if st < 0:
                continue
            vm, em = val, 0.0
        elif np.isfinite(best_d2[m]):
            st, vm, em = best_start[m], best_d2[m], best_err[m]
        else:
            continue
        clips[n] = m
        start[n] = st
        pose_est[n] = vm
        pose_err[n] = em
        if st == best_start[m]:  # the scan's estimate of this start
            audio_est[n] = scan_audio_est[m]
            audio_err[n] = audio_bound if scan_audio_inexact[m] else 0.0
        else:  # an exact near-tie moved the start: its exact audio distance
            audio_est[n] = cos_d(audio, m, st, query_audio, query_audio_sqnorm)
            audio_err[n] = 0.0
        n += 1
    return n


@kernel()
def settle(
    ranking: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    candidates: np.ndarray,
    is_pose: bool,
    exact: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float],
) -> None:
    """Make ``order`` exact inside the group of every element of ``candidates``.

    ``ranking`` is ``(est, err, order, lo, hi)``: the survivors' estimates and their error
    bounds, their order and each one's group in it (as :func:`prefix_groups` leaves them).
    ``exact`` is ``(clips, start, poses, audio, query_pose, query_audio, query_audio_sqnorm)``:
    the survivors' windows and what their exact distances are computed from. The group's
    members get exact values (pose ``d2`` when ``is_pose``, else cosine distances; ``err``
    becomes 0) and are sorted by (value, index); each group once.
    """
    est, err, order, lo, hi = ranking
    clips, start, poses, audio, query_pose, query_audio, query_audio_sqnorm = exact
    for ci in range(candidates.shape[0]):
        a = lo[candidates[ci]]
        b = hi[candidates[ci]]
        if b == a:
            continue
        done = False
        for cj in range(ci):
            if lo[candidates[cj]] == a:
                done = True
                break
        if done:
            continue
        members = np.sort(order[a : b + 1])
        for k in members:
            if err[k] > 0.0:
                if is_pose:
                    est[k] = pose_d2(poses, clips[k], start[k], query_pose)
                else:
                    est[k] = cos_d(audio, clips[k], start[k], query_audio, query_audio_sqnorm)
                err[k] = 0.0
        vals = np.empty(members.shape[0])
        for r in range(members.shape[0]):
            vals[r] = est[members[r]]
        idx = np.argsort(vals, kind="mergesort")  # stable: equal values by index
        for r in range(members.shape[0]):
            order[a + r] = members[idx[r]]


@kernel()
def position(order: np.ndarray, lo: np.ndarray, hi: np.ndarray, i: int) -> int:
    """The position of element ``i`` in ``order``: inside its group ``[lo[i], hi[i]]``."""
    for r in range(lo[i], hi[i] + 1):
        if order[r] == i:
            return r
    return -1


@kernel()
def kth_smallest(x: np.ndarray, k: int) -> float:
    """The ``k``-th smallest value of ``x`` (``k >= 1``).

    A sorted buffer of the ``k`` smallest so far: one pass, and for the small ``k`` of a
    candidate table far cheaper than a partition.
    """
    if k > 64:
        return np.partition(x, k - 1)[k - 1]
    buf = np.empty(k, x.dtype)
    m = 0
    for i in range(x.shape[0]):
        xi = x[i]
        if m == k:
            if xi >= buf[k - 1]:
                continue
            r = k - 1
        else:
            r = m
            m += 1
        while r > 0 and buf[r - 1] > xi:
            buf[r] = buf[r - 1]
            r -= 1
        buf[r] = xi
    return buf[k - 1]


@kernel()
def rank_top(
    estimates: np.ndarray,
    pose_order: np.ndarray,
    n_pose_sorted: int,
    audio_order: np.ndarray,
    n_audio_sorted: int,
    windows: np.ndarray,
    poses: np.ndarray,
    audio: np.ndarray,
    query_pose: np.ndarray,
    query_audio: np.ndarray,
    width: int,
    out_i: np.ndarray,
    out_f: np.ndarray,
    work: np.ndarray,
) -> int:
    """Steps 2-4 of Algorithm 1 for one query: the top ``width`` of the combined ranking.

    Parameters
    ----------
    estimates : (4, n) float64
        Per survivor (see :func:`survivors`): pose estimate, its error, audio estimate, its
        error; refined in place where exact values are needed.
    pose_order, audio_order : (n,) int64
        The survivors, the first ``n_pose_sorted`` (``n_audio_sorted``) sorted by estimate.
    windows : (2, n) int64
        The survivors' clips and starts.
    poses, audio, query_pose, query_audio
        As for :func:`survivors`.
    width : int
        Rows of the candidate table.
    out_i : (5, min(width, n)) int64
        Out: clip, start, pose rank, audio rank, combined rank, in combined order.
    out_f : (2, min(width, n)) float64
        Out: exact pose distance (``sqrt(d2)``) and audio distance.
    work : (7, >= n) int64
        Scratch, reused between calls (fresh memory costs page faults).

    Returns
    -------
    int
        The table's length, or -1, changing nothing, when the sorted prefixes cannot decide
        it (the caller then passes whole orders, which always can).
    """
    clips, start = windows[0], windows[1]
    v, e, av, ae = estimates[0], estimates[1], estimates[2], estimates[3]  # pose, audio: estimate, error
    n = v.shape[0]
    w = min(width, n)
    query_audio_sqnorm = sq64(query_audio)
    plo = work[0, :n]
    phi = work[1, :n]
    alo = work[2, :n]
    ahi = work[3, :n]
    sp = prefix_groups(v, e, pose_order, n_pose_sorted, plo, phi, work[4], work[5])
    sa = prefix_groups(av, ae, audio_order, n_audio_sorted, alo, ahi, work[4], work[5])
    # at least w clips have an exact rank sum at most the w-th smallest largest possible
    # sum; a clip whose smallest possible sum exceeds that cannot be among the first w,
    # so only the few others (the candidates) need exact ranks
    sums = work[6, :n]
    for i in range(n):
        sums[i] = phi[i] + ahi[i]
    bound = kth_smallest(sums, w)
    if (sp < n and bound >= sp) or (sa < n and bound >= sa):
        return -1  # a candidate could lie beyond a prefix's complete groups
    nc = 0
    for i in range(n):
        if plo[i] + alo[i] <= bound:
            nc += 1
    candidates = np.empty(nc, np.int64)
    nc = 0
    for i in range(n):
        if plo[i] + alo[i] <= bound:
            candidates[nc] = i
            nc += 1
    exact = (clips, start, poses, audio, query_pose, query_audio, query_audio_sqnorm)
    settle((v, e, pose_order, plo, phi), candidates, True, exact)
    settle((av, ae, audio_order, alo, ahi), candidates, False, exact)
    prank = np.empty(nc, np.int64)
    arank = np.empty(nc, np.int64)
    key = np.empty(nc, np.int64)
    for r in range(nc):
        i = candidates[r]
        prank[r] = position(pose_order, plo, phi, i)
        arank[r] = position(audio_order, alo, ahi, i)
        key[r] = (prank[r] + arank[r]) * n + i  # unique: ties go to the lower clip index
    best = np.argsort(key)[:w]
    for r in range(w):
        c = best[r]
        i = candidates[c]
        if e[i] > 0.0:
            v[i] = pose_d2(poses, clips[i], start[i], query_pose)
        if ae[i] > 0.0:
            av[i] = cos_d(audio, clips[i], start[i], query_audio, query_audio_sqnorm)
        out_i[0, r] = clips[i]
        out_i[1, r] = start[i]
        out_i[2, r] = prank[c]
        out_i[3, r] = arank[c]
        out_i[4, r] = prank[c] + arank[c]
        out_f[0, r] = np.sqrt(v[i])
        out_f[1, r] = av[i]
    return w
