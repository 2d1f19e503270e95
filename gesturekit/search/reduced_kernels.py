"""The compiled loops of the reduced scan (:mod:`gesturekit.search.reduced`), numba.

:func:`reduce_clips` makes the 8-bit copy of the pose features; :func:`scan_reduced` is one
query's scan of a few clips from it, with the float32 tier of :mod:`gesturekit.search.kernels`
where its bound leaves a clip's nearest start open. Imported on first use, as
:mod:`gesturekit.search.kernels` is, and cached on disk the same way.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from .compile_cache import kernel
from .kernels import audio_estimate, clip_minimum, clip_minimum_within, dot32_at, round_up32, threshold

#: Clips ahead whose scattered float32 rows the scan asks for before it reads them.
PREFETCH_AHEAD = 8
#: At most this many rows asked for per open clip (most have a few starts that could be nearest).
PREFETCH_ROWS = 8


@intrinsic
def _prefetch(typingctx, array, c, s, j):
    """Ask the processor to bring ``array[c, s, j]``'s cache line in (a hint: no fault, no effect on values)."""
    if not (isinstance(array, types.Array) and array.ndim == 3):
        return None
    sig = types.void(array, types.intp, types.intp, types.intp)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, list(args[1:]), wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = builder.module.declare_intrinsic(
            "llvm.prefetch", [i8p], ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
        )
        # a read, kept in every cache level, of data
        builder.call(fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return sig, codegen


@kernel()
def prefetch_row(array: np.ndarray, c: int, s: int) -> None:
    """Ask for every cache line of row ``array[c, s]`` (M, T, D): it is read soon."""
    for j in range(0, array.shape[2], max(1, 64 // array.itemsize)):
        _prefetch(array, c, s, j)  # type: ignore[call-arg]  # numba passes the typing context


@kernel()
def reduce_clips(poses: np.ndarray, out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> None:
    """The reduced copy of ``poses`` (nc, T, D) float32 (see :mod:`gesturekit.search.reduced`).

    ``out`` is ``(codes, coef, kappa, centre, stats)``: (nc, T, D) int8, (nc, T) float32 twice,
    (nc, D) float32 and (nc, 4) float64, written. The float64 sums below carry relative errors
    near 1e-16, far inside the float32 terms of the bound.
    """
    codes, coef, kappa, centre, stats = out
    nc, T, D = poses.shape
    centred = np.empty(D)
    for c in range(nc):
        for j in range(D):
            acc = 0.0
            for s in range(T):
                acc += np.float64(poses[c, s, j])
            centre[c, j] = np.float32(acc / T)
        lost_max = 0.0
        kept_max = 0.0
        kappa_max = 0.0
        centred_max = 0.0
        for s in range(T):
            top = 0.0
            for j in range(D):
                centred[j] = np.float64(poses[c, s, j]) - np.float64(centre[c, j])
                top = max(top, abs(centred[j]))
            scale = np.float32(top / 127.0)
            if not scale > 0.0:  # the row is its centre (or underflows): nothing is rounded
                scale = np.float32(1.0)
            scale64 = np.float64(scale)
            lost = 0.0
            kept = 0.0
            sq = 0.0
            cross = 0.0
            for j in range(D):
                code = min(127.0, max(-127.0, np.rint(centred[j] / scale64)))
                codes[c, s, j] = np.int8(code)
                v = scale64 * code  # exact: a 24-bit scale times a 7-bit code
                d = centred[j] - v
                lost += d * d
                kept += v * v
                sq += centred[j] * centred[j]
                cross += v * np.float64(centre[c, j])
            k = sq + 2.0 * cross
            coef[c, s] = np.float32(-2.0) * scale
            kappa[c, s] = np.float32(k)
            lost_max = max(lost_max, np.sqrt(lost))
            kept_max = max(kept_max, np.sqrt(kept))
            kappa_max = max(kappa_max, abs(k))
            centred_max = max(centred_max, sq)
        stats[c, 0] = lost_max
        stats[c, 1] = kept_max
        stats[c, 2] = kappa_max
        stats[c, 3] = centred_max


@kernel()
def dot8(row: np.ndarray, codes: np.ndarray) -> np.int32:
    """``row . codes`` of int8 and int16 codes, exactly (an int32 sum: ``127 * 32767 * D < 2**31``)."""
    acc = np.int32(0)
    for j in range(row.shape[0]):
        # each product and sum cast back to int32 (exact, by the bound above): numba would
        # widen them to int64 lanes, half as many per vector instruction
        acc = np.int32(acc + np.int32(np.int32(row[j]) * np.int32(codes[j])))
    return acc


@kernel()
def reduced_estimate(
    reduced: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    c: int,
    s: int,
    query_codes: np.ndarray,
    query_scale: np.float32,
) -> np.float32:
    """``|p - q|^2 - |q - c_m|^2`` estimated from the reduced copy for start ``s`` of clip ``c``:
    ``kappa - 2 s s_q (i . i_q)`` with three float32 roundings of the product and one of
    the sum, as the bound assumes (:mod:`gesturekit.search.reduced`)."""
    codes, coef, kappa = reduced[0], reduced[1], reduced[2]
    return kappa[c, s] + coef[c, s] * (query_scale * np.float32(dot8(codes[c, s], query_codes)))


# a float64 sum in any order: its rounding is far inside the bound's float32 terms
@kernel(fastmath={"reassoc", "contract"})
def centred_sqnorm(query: np.ndarray, centre: np.ndarray, c: int) -> float:
    """``|query - centre[c]|^2`` in float64."""
    acc = 0.0
    for j in range(query.shape[0]):
        d = np.float64(query[j]) - np.float64(centre[c, j])
        acc += d * d
    return acc


@kernel()
def reduced_bound(
    stats: np.ndarray, c: int, centred: float, query: tuple[float, float], factor: float, tiny: float
) -> float:
    """The error bound of clip ``c``'s reduced estimates (:func:`gesturekit.search.reduced.clip_bounds`)."""
    lost, norm = query
    return (
        2.0 * stats[c, 0] * np.sqrt(centred)
        + 2.0 * stats[c, 1] * lost
        + factor * (stats[c, 2] + 2.0 * stats[c, 1] * norm + 3.0 * centred + 2.0 * stats[c, 3])
        + tiny
    )


@kernel()
def threshold_above(e32: float, q_sqnorm: float, err32: float, err: float, centred: float) -> np.float32:
    """A float32 value no reduced estimate of a start nearer than the float32-estimated start lies above.

    ``e32 + q_sqnorm`` (float32 estimate ``|p|^2 - 2 p.q`` and ``|q|^2``) is within ``err32`` of a
    start's squared distance; a reduced estimate plus ``centred`` is within ``err`` of its start's.
    So a start at most as far has reduced estimate at most ``e32 + q_sqnorm + err32 + err - centred``:
    summed in float64 with a margin beyond the sum's rounding, then rounded up to float32.
    """
    t64 = np.float64(e32) + q_sqnorm + err32 + err - centred
    # four float64 roundings, each within 2**-53 of a partial sum no larger than the sum of magnitudes
    t64 += 1e-12 * (abs(np.float64(e32)) + abs(q_sqnorm) + err32 + err + abs(centred))
    return round_up32(t64)


@kernel()
def estimate32(bias: np.ndarray, poses: np.ndarray, c: int, s: int, query: np.ndarray) -> np.float32:
    """The float32 scan's estimate ``|p|^2 - 2 p.q`` of start ``s`` of clip ``c`` (+inf where not admissible)."""
    return bias[c, s] + np.float32(-2.0) * dot32_at(poses, c, s, query)


@kernel()
def scan_reduced(
    est: np.ndarray,
    bias: np.ndarray,
    reduced: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    query: tuple[np.ndarray, float, float, float],
    pose: tuple[np.ndarray, np.ndarray, float],
    pose_bound: tuple[np.ndarray, float, float],
    scan_out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    audio: tuple[np.ndarray, np.ndarray, np.ndarray, float],
    audio_out: tuple[np.ndarray, np.ndarray],
) -> None:
    """The scan of one query over a few clips: reduced estimates, the float32 tier where they
    leave the nearest start open, and the audio estimate at each clip's nearest start.

    Parameters
    ----------
    est : (nc, T) float32
        Scratch, out: per clip the row of estimates the clip was decided on (see ``scan_out``).
    bias : (nc, T) float32
        ``|p|^2`` where the start is admissible, +inf elsewhere.
    reduced : (codes, coef, kappa, centre, stats)
        The clips' part of the :class:`~gesturekit.search.reduced.ReducedPose`.
    query : (codes, scale, lost, norm)
        ``p_{t-1}`` rounded (:class:`~gesturekit.search.reduced.QueryCodes`).
    pose : (poses, query_pose, q_sqnorm)
        The clips' float32 pose features (nc, T, D), ``p_{t-1}`` (D,) float32 and ``|p_{t-1}|^2``.
    pose_bound : (clip_max_sqnorm, err_factor, tiny)
        As for :func:`reduce_many`: the float32 tier's bound.
    scan_out : (best_start, best_d2, best_err, undecided), each (nc,)
        Out: per clip a start of least estimate, its squared distance estimated in float32
        (float64, +inf: no admissible start) and that estimate's error bound (the float32
        scan's); ``undecided``: the float32 tier left a near-tie or a possible zero, and
        ``est[c]`` holds its float32 estimates ``|p|^2 - 2 p.q`` (+inf at starts that cannot
        be nearest) for an exact look.
    audio, audio_out
        As for :func:`audio_at`, for one query: the clips' audio features and squared norms,
        ``f_t`` and its squared norm; out the estimates at ``best_start`` and their exactness.

    Passes: the reduced estimates of every clip, read in order; for the clips they leave open,
    the start of least estimate in float32, which narrows the starts that could be nearest
    (:func:`threshold_above`), then those starts in float32; each clip's nearest start in
    float32 and its audio. All but the first read rows scattered over the database, and ask
    for them a few clips ahead (:func:`prefetch_row`).
    """
    centre, stats = reduced[3], reduced[4]
    query_codes, query_scale, query_lost, query_norm = query
    poses, query_pose, q_sqnorm = pose
    clip_max_sqnorm, err_factor, tiny = pose_bound
    best_start, best_d2, best_err, undecided = scan_out
    features, sqnorms, query_audio, query_audio_sqnorm = audio
    audio_est, audio_inexact = audio_out
    nc, T = est.shape
    inf = np.float32(np.inf)
    qs = np.float32(query_scale)
    # the clips the reduced estimates leave open: the first and last start that could be
    # nearest, the start of least estimate, and what the tighter test below needs
    opened = np.empty(nc, np.int64)
    first = np.empty(nc, np.int64)
    last = np.empty(nc, np.int64)
    least = np.empty(nc, np.int64)
    zeros = np.empty(nc, np.bool_)
    t32s = np.empty(nc, np.float32)
    bounds = np.empty((nc, 2))
    tiered = np.zeros(nc, np.bool_)  # the float32 estimate at best_start is made
    n_open = 0
    for c in range(nc):
        undecided[c] = False
        admitted = 0
        for s in range(T):
            admitted += bias[c, s] < inf
        if admitted == 0:
            best_start[c] = 0
            best_d2[c] = np.inf
            best_err[c] = 0.0
            continue
        if 4 * admitted < T:  # few admissible starts: the others' rows are not read
            for s in range(T):
                est[c, s] = reduced_estimate(reduced, c, s, query_codes, qs) if bias[c, s] < inf else inf
        else:  # every row, then the inadmissible masked: a branch in the loop would stop it vectorising
            for s in range(T):
                est[c, s] = reduced_estimate(reduced, c, s, query_codes, qs)
            for s in range(T):
                if bias[c, s] == inf:
                    est[c, s] = inf
        centred = centred_sqnorm(query_pose, centre, c)
        err = reduced_bound(stats, c, centred, (query_lost, query_norm), err_factor, tiny)
        arg, best, open_ = clip_minimum(est, c, centred, err)
        if not open_:
            best_start[c] = arg
            best_d2[c] = np.float64(best) + centred if best < inf else np.inf
            best_err[c] = err
            continue
        # the starts that could be nearest: within twice the bound of the least estimate, or
        # every admissible start where the least could be an exact zero; the others become +inf
        zero = np.float64(best) + centred <= err
        t32 = threshold(best, err)
        a, b = T, -1
        for s in range(T):
            if est[c, s] < inf and (zero or est[c, s] <= t32):
                a = min(a, s)
                b = s
            else:
                est[c, s] = inf
        opened[n_open], first[n_open], last[n_open], least[n_open] = c, a, b, arg
        zeros[n_open], t32s[n_open] = zero, t32
        bounds[n_open, 0], bounds[n_open, 1] = err, centred
        n_open += 1
    # The float32 rows below are scattered: each loop asks for the rows a few clips ahead
    # (PREFETCH_AHEAD), so that their loads overlap the work on the clips at hand.
    # The open clips, first the start of least reduced estimate in float32. Where no start of
    # the clip can be at distance zero, that start's distance is at most its float32
    # estimate plus its bound, and the nearest start's is no larger: a start whose reduced
    # estimate minus its bound lies above that cannot be nearest (docs/METHOD.md, "Exact arithmetic").
    err32 = np.empty(nc)
    for i in range(n_open):
        if i + PREFETCH_AHEAD < n_open:
            prefetch_row(poses, opened[i + PREFETCH_AHEAD], least[i + PREFETCH_AHEAD])
        c, b = opened[i], least[i]
        err32[i] = err_factor * (clip_max_sqnorm[c] + q_sqnorm) + tiny
        e = estimate32(bias, poses, c, b, query_pose)
        if not zeros[i]:
            t = min(t32s[i], threshold_above(e, q_sqnorm, err32[i], bounds[i, 0], bounds[i, 1]))
            lo, hi = T, -1
            for s in range(first[i], last[i] + 1):
                if est[c, s] < inf and (s == b or est[c, s] <= t):
                    lo = min(lo, s)
                    hi = s
                else:
                    est[c, s] = inf
            first[i], last[i] = lo, hi
        est[c, b] = e
    # then the other starts that could be nearest, in float32
    for i in range(n_open):
        if i + PREFETCH_AHEAD < n_open:
            ahead, b = opened[i + PREFETCH_AHEAD], least[i + PREFETCH_AHEAD]
            asked = 0
            for s in range(first[i + PREFETCH_AHEAD], last[i + PREFETCH_AHEAD] + 1):
                if asked < PREFETCH_ROWS and s != b and est[ahead, s] < inf:
                    prefetch_row(poses, ahead, s)
                    asked += 1
        c = opened[i]
        for s in range(first[i], last[i] + 1):
            if s != least[i] and est[c, s] < inf:
                est[c, s] = estimate32(bias, poses, c, s, query_pose)
        arg, best, open_ = clip_minimum_within(est, c, first[i], last[i] + 1, offset=q_sqnorm, err=err32[i])
        best_start[c] = arg
        best_d2[c] = np.float64(best) + q_sqnorm
        best_err[c] = err32[i]
        undecided[c] = open_
        tiered[c] = True
    # The nearest start's pose distance is estimated again in float32, so that the rankings
    # see the float32 bound: the wider reduced bound would leave far more clips to settle
    # exactly. And its audio estimate.
    for c in range(nc):
        ahead = c + PREFETCH_AHEAD
        if ahead < nc and best_d2[ahead] < np.inf:
            if not tiered[ahead]:
                prefetch_row(poses, ahead, best_start[ahead])
            prefetch_row(features, ahead, best_start[ahead])
        if best_d2[c] < np.inf:
            s = best_start[c]
            if not tiered[c]:
                est[c, s] = estimate32(bias, poses, c, s, query_pose)
                best_d2[c] = np.float64(est[c, s]) + q_sqnorm
                best_err[c] = err_factor * (clip_max_sqnorm[c] + q_sqnorm) + tiny
            audio_est[c], audio_inexact[c] = audio_estimate(features, sqnorms, c, s, query_audio, query_audio_sqnorm)
