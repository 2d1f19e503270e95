"""The compiled loops of :mod:`gesturekit.search.index` (numba, a dependency of librosa).

Imported by :func:`gesturekit.search.exact.compiled` when a search first runs, not with the
package (numba is heavy). The loops are module-level functions so that numba's on-disk
cache serves them in every later process, including those that call each other.

``scan_one(P3, q, bias, nq, npmax, c_err, tiny, G, s0, amin, undecided, F3, na2, fq, nb, av, inexact)``:
the scan of one query in one pass per clip: float32 estimates ``G`` of the admissible
starts only (+inf elsewhere, their rows unread), the reductions of :func:`gesturekit.search.index._reduce_chunk`,
and the audio estimate ``av`` of the chosen start ``s0`` (``inexact``: False where it is
exact, at a zero norm).
``reduce_many(G3, bias, nq, npmax, c_err, tiny, s0, amin, undecided)``:
:func:`gesturekit.search.index._reduce_chunk` for several queries in one pass over each clip's (T, queries)
block (numpy's reductions along the strided axis are slow).
``audio_at(F3, na2, s0, amin, fq, nb, av, inexact)``: the audio estimates of each clip's
``s0`` for several queries (one clip's rows serve all of them).
``prefix_groups(v, err, order, L, lo, hi, glo, ghi)``: the ranges of sorted positions whose exact
order is unknown (groups of near-equal estimates), over a sorted prefix of the order (see ``rank_top``).
``admissible_ends(bias2)``: per clip, one past its last admissible start (0: none).
``row_stats(x2, norms)``: float64 squared norms of the rows of ``x2``, whether all
values are finite, and the largest magnitude (one pass for validation and norms).
``survivors(...)`` and ``rank_top(...)``: the exact decisions of one query after the
scan (see :meth:`gesturekit.search.index.SearchIndex._decide`), with the exact distances of
:mod:`gesturekit.search.reference` (float64, left to right).
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def reduce_many(G3, bias, nq, npmax, c_err, tiny, s0, amin, undecided):
    nc, T, nb = G3.shape
    best = np.empty(nb, dtype=np.float32)
    thr = np.empty(nb, dtype=np.float32)
    arg = np.empty(nb, dtype=np.int32)  # 32-bit lanes like the values: wider vectors
    count = np.empty(nb, dtype=np.int32)
    for c in range(nc):
        for j in range(nb):
            best[j] = np.inf
            count[j] = 0
            arg[j] = 0
        for s in range(T):  # the inner loop runs along contiguous queries: vectorised
            p2 = bias[c, s]
            row = G3[c, s]
            for j in range(nb):
                a = row[j] + p2  # float32, as the error bound assumes
                best[j] = a if a < best[j] else best[j]
        for j in range(nb):
            t64 = np.float64(best[j]) + 2.0 * (c_err * (npmax[c] + nq[j]) + tiny)
            t32 = np.float32(t64)
            if t32 < t64:  # round the float32 threshold up
                t32 = np.nextafter(t32, np.float32(np.inf))
            thr[j] = t32
        for s in range(T - 1, -1, -1):  # backwards: arg ends at the first minimum
            p2 = bias[c, s]
            row = G3[c, s]
            si = np.int32(s)
            for j in range(nb):
                a = row[j] + p2
                count[j] += np.int32(1) if a <= thr[j] else np.int32(0)
                arg[j] = si if a == best[j] else arg[j]
        for j in range(nb):
            err = c_err * (npmax[c] + nq[j]) + tiny
            s0[c, j] = arg[j]
            amin[c, j] = best[j]
            undecided[c, j] = np.isfinite(best[j]) and (count[j] > 1 or np.float64(best[j]) + nq[j] <= err)


# float32 products in any order (reassociation, FMA, SIMD lanes): the pose error bound allows it
@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def dot32(p, q):
    acc = np.float32(0.0)
    for j in range(p.shape[0]):
        acc += p[j] * q[j]
    return acc


@numba.njit(cache=True, nogil=True)
def scan_one(P3, q, bias, nq, npmax, c_err, tiny, G, s0, amin, undecided, F3, na, fq, nb, av, inexact):
    nc, T, _ = P3.shape
    inf = np.float32(np.inf)
    for c in range(nc):
        best = inf
        for s in range(T):
            b = bias[c, s]
            if b == inf:  # not admissible: its row is never read
                G[c, s] = inf
                continue
            a = b + np.float32(-2.0) * dot32(P3[c, s], q)  # exact scaling by -2, then one float32 add
            G[c, s] = a
            best = min(best, a)
        err = c_err * (npmax[c] + nq) + tiny
        t64 = np.float64(best) + 2.0 * err
        t32 = np.float32(t64)
        if t32 < t64:  # round the float32 threshold up
            t32 = np.nextafter(t32, inf)
        count = 0
        arg = 0
        for s in range(T - 1, -1, -1):  # backwards: arg ends at the first minimum
            a = G[c, s]
            count += a <= t32
            if a == best:
                arg = s
        s0[c] = arg
        amin[c] = best
        undecided[c] = np.isfinite(best) and (count > 1 or np.float64(best) + nq <= err)
        # the audio estimate of that start (while the clip is at hand): float32 product, float64 norms
        if best < inf:
            d = na[c, arg] * nb
            if d == 0.0:
                av[c] = 1.0
                inexact[c] = False
            else:
                av[c] = 1.0 - np.float64(dot32(F3[c, arg], fq)) / np.sqrt(d)
                inexact[c] = True


@numba.njit(cache=True, nogil=True)
def admissible_ends(bias2):
    M, T = bias2.shape
    ends = np.zeros(M, np.int64)
    for c in range(M):
        for s in range(T - 1, -1, -1):  # from the end: only the last few starts are read
            if bias2[c, s] < np.inf:
                ends[c] = s + 1
                break
    return ends


@numba.njit(cache=True, nogil=True)
def row_stats(x2, norms):
    finite = True
    top = 0.0
    for r in range(x2.shape[0]):
        acc = 0.0
        for j in range(x2.shape[1]):
            v = np.float64(x2[r, j])
            if not np.isfinite(v):
                finite = False
            top = max(top, abs(v))
            acc += v * v
        norms[r] = acc
    return finite, top


@numba.njit(cache=True, nogil=True)
def prefix_groups(v, err, order, L, lo, hi, glo, ghi):
    # Each v[k] lies within err[k] of its exact value. Groups over the first L positions of
    # ``order`` (those sorted; the rest in any order, each above them by estimate; L = n: the
    # whole order, every group complete). A split before position i is proven when the
    # largest upper end before i lies below the smallest lower end from i on, the rest
    # included. Returns s: positions before s are in complete groups (exact lo, hi);
    # every other element gets lo = s, hi = n - 1 (its rank lies somewhere there).
    n = order.shape[0]
    m = np.inf
    for i in range(L, n):
        k = order[i]
        m = min(m, v[k] - err[k])
    low = np.empty(L + 1)
    low[L] = m
    for i in range(L - 1, -1, -1):
        k = order[i]
        m = min(m, v[k] - err[k])
        low[i] = m
    start = 0
    top = -np.inf
    for i in range(1, L + 1):
        k = order[i - 1]
        top = max(top, v[k] + err[k])
        if top < low[i]:
            for r in range(start, i):  # by position; glo, ghi: int64 scratch of >= L values
                glo[r] = start
                ghi[r] = i - 1
            start = i
    for i in range(n):
        lo[i] = start
        hi[i] = n - 1
    for r in range(start):
        k = order[r]
        lo[k] = glo[r]
        hi[k] = ghi[r]
    return start


@numba.njit(cache=True, nogil=True)
def audio_at(F3, na2, s0, amin, fq, nb, av, inexact):
    nc, nq = s0.shape
    for c in range(nc):  # one clip's rows serve all its queries while they are in cache
        for j in range(nq):
            if amin[c, j] < np.inf:
                s = s0[c, j]
                d = na2[c, s] * nb[j]
                if d == 0.0:  # a zero vector: the definition's value, exactly
                    av[c, j] = 1.0
                    inexact[c, j] = False
                else:
                    av[c, j] = 1.0 - np.float64(dot32(F3[c, s], fq[j])) / np.sqrt(d)
                    inexact[c, j] = True


# -- the exact decisions of one query (steps 1-4 of Algorithm 1 after the scan) --------------
# No fastmath below: these are the exact values, the same operations in the same order as
# gesturekit.search.reference (float64, left to right).


@numba.njit(cache=True, nogil=True)
def pose_d2(P3, c, s, q):
    acc = 0.0
    for j in range(q.shape[0]):
        d = np.float64(P3[c, s, j]) - np.float64(q[j])
        acc += d * d
    return acc


@numba.njit(cache=True, nogil=True)
def sq64(f):
    acc = 0.0
    for j in range(f.shape[0]):
        y = np.float64(f[j])
        acc += y * y
    return acc


@numba.njit(cache=True, nogil=True)
def cos_d(F3, c, s, f, nb):
    dot = 0.0
    na = 0.0
    for j in range(f.shape[0]):
        x = np.float64(F3[c, s, j])
        dot += x * np.float64(f[j])
        na += x * x
    if na == 0.0 or nb == 0.0:
        return 1.0
    return 1.0 - dot / np.sqrt(na * nb)


@numba.njit(cache=True, nogil=True)
def resolve_clip(row, c, nq, e, P3, q):
    # exact values tier by tier: the starts within 2 e of the smallest unknown estimate,
    # until the best non-zero exact value is proven (no unknown start could reach it)
    T = row.shape[0]
    a = np.empty(T)
    known = np.full(T, np.nan)
    for s in range(T):
        a[s] = np.float64(row[s]) + nq
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
                if (a[s] - e <= best) if np.isfinite(best) else (a[s] <= nearest + 2.0 * e):
                    known[s] = pose_d2(P3, c, s, q)
                    pend = True
        if not pend:
            break
    if not np.isfinite(best):
        return -1, np.nan
    for s in range(T):  # ties: the smallest start
        if known[s] == best:
            return s, best
    return -1, np.nan


@numba.njit(cache=True, nogil=True)
def survivors(s0, amin, nq, npmax, c_err, tiny, cclips, crows, P3, q, F3, f, av_col, inexact_col, audio_e,
              clips, start, v, e, av, ae):
    M = s0.shape[0]
    crow = np.full(M, -1, np.int64)
    for i in range(cclips.shape[0]):
        crow[cclips[i]] = i
    nb = sq64(f)
    n = 0
    for m in range(M):
        err = c_err * (npmax[m] + nq) + tiny
        if crow[m] >= 0:
            st, val = resolve_clip(crows[crow[m]], m, nq, err, P3, q)
            if st < 0:
                continue
            vm, em = val, 0.0
        elif np.isfinite(amin[m]):
            st, vm, em = s0[m], np.float64(amin[m]) + nq, err
        else:
            continue
        clips[n] = m
        start[n] = st
        v[n] = vm
        e[n] = em
        if st == s0[m]:  # the scan's estimate of this start
            av[n] = av_col[m]
            ae[n] = audio_e if inexact_col[m] else 0.0
        else:  # an exact near-tie moved the start: its exact audio distance
            av[n] = cos_d(F3, m, st, f, nb)
            ae[n] = 0.0
        n += 1
    return n


@numba.njit(cache=True, nogil=True)
def settle(v, err, order, lo, hi, cand, pose, clips, start, P3, F3, q, f, nb):
    # make the order exact inside the group of every element of ``cand``: exact values,
    # then sorted by (value, index); each group once
    for ci in range(cand.shape[0]):
        a = lo[cand[ci]]
        b = hi[cand[ci]]
        if b == a:
            continue
        done = False
        for cj in range(ci):
            if lo[cand[cj]] == a:
                done = True
                break
        if done:
            continue
        members = np.sort(order[a : b + 1])
        for k in members:
            if err[k] > 0.0:
                if pose:
                    v[k] = pose_d2(P3, clips[k], start[k], q)
                else:
                    v[k] = cos_d(F3, clips[k], start[k], f, nb)
                err[k] = 0.0
        vals = np.empty(members.shape[0])
        for r in range(members.shape[0]):
            vals[r] = v[members[r]]
        idx = np.argsort(vals, kind="mergesort")  # stable: equal values by index
        for r in range(members.shape[0]):
            order[a + r] = members[idx[r]]


@numba.njit(cache=True, nogil=True)
def position(order, lo, hi, i):
    # the position of element i in ``order``: inside its group [lo, hi]
    for r in range(lo[i], hi[i] + 1):
        if order[r] == i:
            return r
    return -1


@numba.njit(cache=True, nogil=True)
def kth_smallest(x, k):
    # the k-th smallest value (k >= 1) by a sorted buffer of the k smallest so far:
    # one pass, and for the small k of a candidate table far cheaper than a partition
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


@numba.njit(cache=True, nogil=True)
def rank_top(v, e, av, ae, porder, Lp, aorder, La, clips, start, P3, F3, q, f, width, out_i, out_f, work):
    # porder, aorder: the survivors, the first Lp (La) sorted by pose (audio) estimate.
    # Returns -1, changing nothing, when those prefixes cannot decide the table (the
    # caller then passes whole orders, which always can); else the table's length.
    # work: (7, >= n) int64 scratch, reused between calls (fresh memory costs page faults)
    n = v.shape[0]
    w = min(width, n)
    nb = sq64(f)
    plo = work[0, :n]
    phi = work[1, :n]
    alo = work[2, :n]
    ahi = work[3, :n]
    sp = prefix_groups(v, e, porder, Lp, plo, phi, work[4], work[5])
    sa = prefix_groups(av, ae, aorder, La, alo, ahi, work[4], work[5])
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
    cand = np.empty(nc, np.int64)
    nc = 0
    for i in range(n):
        if plo[i] + alo[i] <= bound:
            cand[nc] = i
            nc += 1
    settle(v, e, porder, plo, phi, cand, True, clips, start, P3, F3, q, f, nb)
    settle(av, ae, aorder, alo, ahi, cand, False, clips, start, P3, F3, q, f, nb)
    prank = np.empty(nc, np.int64)
    arank = np.empty(nc, np.int64)
    key = np.empty(nc, np.int64)
    for r in range(nc):
        i = cand[r]
        prank[r] = position(porder, plo, phi, i)
        arank[r] = position(aorder, alo, ahi, i)
        key[r] = (prank[r] + arank[r]) * n + i  # unique: ties go to the lower clip index
    best = np.argsort(key)[:w]
    for r in range(w):
        c = best[r]
        i = cand[c]
        if e[i] > 0.0:
            v[i] = pose_d2(P3, clips[i], start[i], q)
        if ae[i] > 0.0:
            av[i] = cos_d(F3, clips[i], start[i], f, nb)
        out_i[0, r] = clips[i]
        out_i[1, r] = start[i]
        out_i[2, r] = prank[c]
        out_i[3, r] = arank[c]
        out_i[4, r] = prank[c] + arank[c]
        out_f[0, r] = np.sqrt(v[i])
        out_f[1, r] = av[i]
    return w
