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
from .kernels import audio_estimate, clip_minimum, clip_minimum_within, dot32_at, resolve_clip, round_up32, threshold

#: Clips ahead whose scattered float32 rows the scan asks for before it reads them.
PREFETCH_AHEAD = 8
#: Largest magnitude of a frame copy's code (:func:`frame_clips`).
FRAME_LEVELS = 32767
#: At most this many rows asked for per open clip (most have a few starts that could be nearest).
PREFETCH_ROWS = 8


@intrinsic
def _prefetch(typingctx, array, c, s, j):
    """Ask the processor to bring ``array[c, s, j]``'s cache line in (``array[c, s]``'s for a 2-d
    array, ``j`` unused; a hint: no fault, no effect on values)."""
    if not (isinstance(array, types.Array) and array.ndim in (2, 3)):
        return None
    sig = types.void(array, types.intp, types.intp, types.intp)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        index = list(args[1 : 1 + aryty.ndim])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, index, wraparound=False)
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
        scan's; 0 where the clip was resolved exactly, see :func:`settle_open`); ``undecided``:
        False for every clip (kept for the callers of the batch scan, which leaves such clips
        to the decisions).
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
        n_open = open_clip(est, c, (arg, best, err, centred), (opened, first, last, least, zeros, t32s, bounds), n_open)
    settle_open(
        est,
        bias,
        (poses, query_pose, q_sqnorm),
        pose_bound,
        (opened, first, last, least, zeros, t32s, bounds, n_open),
        scan_out,
        tiered,
    )
    nearest_audio(est, bias, (poses, query_pose, q_sqnorm), pose_bound, scan_out, tiered, True, audio, audio_out)


@kernel(inline="always")  # numba's own inlining: a call here made the scans' main loops 5% slower
def open_clip(
    est: np.ndarray,
    c: int,
    least: tuple[int, float, float, float],
    opened_clips: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    n_open: int,
) -> int:
    """Record clip ``c``, left open by a first pass, for :func:`settle_open`; returns ``n_open + 1``.

    ``least`` is ``(arg, best, err, offset)``: the clip's start of least first-pass estimate, that
    estimate, its bound and offset (estimate plus offset is within the bound of the squared
    distance). The starts that could be nearest are those within twice the bound of the least
    estimate, or every admissible start where the least could be an exact zero; the others
    become +inf in ``est[c]``. ``opened_clips`` are the first seven arrays of
    :func:`settle_open`'s ``opened_clips``, written at ``n_open``.
    """
    arg, best, err, offset = least
    opened, first, last, least_start, zeros, t32s, bounds = opened_clips
    T = est.shape[1]
    inf = np.float32(np.inf)
    zero = np.float64(best) + offset <= err
    t32 = threshold(best, err)
    a, b = T, -1
    for s in range(T):
        if est[c, s] < inf and (zero or est[c, s] <= t32):
            a = min(a, s)
            b = s
        else:
            est[c, s] = inf
    opened[n_open], first[n_open], last[n_open], least_start[n_open] = c, a, b, arg
    zeros[n_open], t32s[n_open] = zero, t32
    bounds[n_open, 0], bounds[n_open, 1] = err, offset
    return n_open + 1


@kernel()
def settle_open(
    est: np.ndarray,
    bias: np.ndarray,
    pose: tuple[np.ndarray, np.ndarray, float],
    pose_bound: tuple[np.ndarray, float, float],
    opened_clips: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int],
    scan_out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    tiered: np.ndarray,
) -> None:
    """The float32 tier of the clips a first pass left open (:func:`scan_reduced`, :func:`scan_frames`).

    ``opened_clips`` is ``(opened, first, last, least, zeros, t32s, bounds, n)``: the first ``n``
    entries name an open clip, the first and last start that could be nearest (``est`` is +inf
    at the others), its start of least first-pass estimate, whether a start could be at distance
    zero, the first pass's threshold, and its bound and offset (a first-pass estimate plus the
    offset is within the bound of its start's squared distance). Writes ``scan_out`` and
    ``tiered`` for those clips; their ``est`` rows then hold float32 estimates ``|p|^2 - 2 p.q``.
    A clip the float32 tier leaves open (a near-tie, or a start that could be at distance zero)
    is resolved exactly here (:func:`~gesturekit.search.kernels.resolve_clip`: its nearest
    non-zero start and float64 distance, error bound 0; +inf where only zeros could be nearest),
    on the scan's thread while its rows are in cache, rather than by the decisions after the scan.
    """
    poses, query_pose, q_sqnorm = pose
    clip_max_sqnorm, err_factor, tiny = pose_bound
    best_start, best_d2, best_err, _ = scan_out
    opened, first, last, least, zeros, t32s, bounds, n_open = opened_clips
    T = est.shape[1]
    inf = np.float32(np.inf)
    # The float32 rows below are scattered: each loop asks for the rows a few clips ahead
    # (PREFETCH_AHEAD), so that their loads overlap the work on the clips at hand.
    # The open clips, first the start of least first-pass estimate in float32. Where no start
    # of the clip can be at distance zero, that start's distance is at most its float32
    # estimate plus its bound, and the nearest start's is no larger: a start whose first-pass
    # estimate minus its bound lies above that cannot be nearest (docs/METHOD.md, "Exact arithmetic").
    err32 = np.empty(max(1, n_open))
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
        tiered[c] = True
        if open_:  # exactly, while the clip's rows are in cache (and on the scan's threads)
            arg, d2 = resolve_clip(est[c], c, q_sqnorm, err32[i], poses, query_pose)
            best_start[c] = max(arg, 0)
            best_d2[c] = d2 if arg >= 0 else np.inf  # -1: only starts at distance zero could be nearest
            best_err[c] = 0.0
            continue
        best_start[c] = arg
        best_d2[c] = np.float64(best) + q_sqnorm
        best_err[c] = err32[i]


@kernel()
def nearest_audio(
    est: np.ndarray,
    bias: np.ndarray,
    pose: tuple[np.ndarray, np.ndarray, float],
    pose_bound: tuple[np.ndarray, float, float],
    scan_out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    tiered: np.ndarray,
    again: bool,
    audio: tuple[np.ndarray, np.ndarray, np.ndarray, float],
    audio_out: tuple[np.ndarray, np.ndarray],
) -> None:
    """The last pass of a scan: each clip's audio estimate at its nearest start and, where
    ``again`` and the float32 tier did not make it, the nearest start's float32 estimate."""
    poses, query_pose, q_sqnorm = pose
    clip_max_sqnorm, err_factor, tiny = pose_bound
    best_start, best_d2, best_err, _ = scan_out
    features, sqnorms, query_audio, query_audio_sqnorm = audio
    audio_est, audio_inexact = audio_out
    nc = est.shape[0]
    # The nearest start's pose distance is estimated again in float32, so that the rankings
    # see the float32 bound: the wider reduced bound would leave far more clips to settle
    # exactly. And its audio estimate.
    for c in range(nc):
        ahead = c + PREFETCH_AHEAD
        if ahead < nc and best_d2[ahead] < np.inf:
            if again and not tiered[ahead]:
                prefetch_row(poses, ahead, best_start[ahead])
            prefetch_row(features, ahead, best_start[ahead])
            _prefetch(sqnorms, ahead, best_start[ahead], 0)  # type: ignore[call-arg]  # numba passes the typing context
        if best_d2[c] < np.inf:
            s = best_start[c]
            if again and not tiered[c]:
                est[c, s] = estimate32(bias, poses, c, s, query_pose)
                best_d2[c] = np.float64(est[c, s]) + q_sqnorm
                best_err[c] = err_factor * (clip_max_sqnorm[c] + q_sqnorm) + tiny
            audio_est[c], audio_inexact[c] = audio_estimate(features, sqnorms, c, s, query_audio, query_audio_sqnorm)


@kernel()
def frame_clips(
    poses: np.ndarray,
    valid: np.ndarray,
    offsets: np.ndarray,
    fit: tuple[np.ndarray, np.ndarray],
    out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """The frame copy of ``poses`` (nc, T, D) float32 (see :mod:`gesturekit.search.frames`).

    ``valid`` (nc, T) bool, ``offsets`` (n,) int64, ``fit`` the map's ``(scale, shift)``, each
    (n, K) float64; ``out`` is ``(codes, steps, kappa, stats)``: (nc, K, T) int16, (nc, K)
    float32, (nc, T) float32 and (nc, 2) float64, written. The float64 sums carry relative
    errors near 1e-16, far inside the float32 terms of the bound.
    """
    scale, shift = fit
    codes, steps, kappa, stats = out
    nc, T, D = poses.shape
    n = offsets.shape[0]
    K = D // n
    reach = 0
    for k in range(n):
        reach = max(reach, offsets[k])
    covered = T - reach
    kept = np.empty((K, T))
    for c in range(nc):
        for i in range(K):
            top = 0.0
            for f in range(T):
                top = max(top, abs(np.float64(poses[c, f, i])))
            step = np.float32(top / FRAME_LEVELS)
            if not step > 0.0:  # the value is 0 at every frame (or underflows): nothing is rounded
                step = np.float32(1.0)
            steps[c, i] = step
            for f in range(T):
                code = min(FRAME_LEVELS, max(-FRAME_LEVELS, np.rint(np.float64(poses[c, f, i]) / np.float64(step))))
                codes[c, i, f] = np.int16(code)
                kept[i, f] = np.float64(step) * code  # exact: a 24-bit step times a 16-bit code
        lost_max = 0.0
        norm_max = 0.0
        for s in range(T):
            if s >= covered:
                kappa[c, s] = np.inf
                continue
            sq = 0.0
            lost = 0.0
            for k in range(n):
                f = s + offsets[k]
                for i in range(K):
                    y = scale[k, i] * kept[i, f] + shift[k, i]
                    sq += y * y
                    d = np.float64(poses[c, s, k * K + i]) - y
                    lost += d * d
            kappa[c, s] = np.float32(sq)
            if valid[c, s]:
                lost_max = max(lost_max, np.sqrt(lost))
                norm_max = max(norm_max, np.sqrt(sq))
        stats[c, 0] = lost_max
        stats[c, 1] = norm_max


@kernel()
def frame_bound(stats: np.ndarray, c: int, query_norm: float, shift_norm: float, factor: float, tiny: float) -> float:
    """The error bound of clip ``c``'s frame estimates (:func:`gesturekit.search.frames.frame_bounds`)."""
    lost, top = stats[c, 0], stats[c, 1]
    return (
        factor * (top * top + (top + shift_norm) * (top + shift_norm) + query_norm * query_norm)
        + lost * (2.0 * (top + query_norm) + lost)
        + tiny
    )


# products along a clip's frames: one rounding per multiply-add is within the bound too
@kernel(fastmath={"contract"})
def frame_products(codes: np.ndarray, c: int, weights: np.ndarray, h: np.ndarray) -> None:
    """``h[k, f] = codes[c, :, f] . weights[k]`` in float32 (the codes exactly converted), for
    every frame ``f`` of clip ``c``.

    Four blocks and four values are taken per pass over the frames: each value loaded then
    serves four multiply-adds, and each load and store of ``h`` four (one at a time, the
    loop would wait on its loads and stores).
    """
    n, K = weights.shape
    T = h.shape[1]
    for k in range(n):
        for f in range(T):
            h[k, f] = np.float32(0.0)
    fours = n - n % 4
    whole = K - K % 4
    for k in range(0, fours, 4):
        for i in range(0, whole, 4):
            a0, a1, a2, a3 = weights[k, i], weights[k, i + 1], weights[k, i + 2], weights[k, i + 3]
            b0, b1, b2, b3 = weights[k + 1, i], weights[k + 1, i + 1], weights[k + 1, i + 2], weights[k + 1, i + 3]
            c0, c1, c2, c3 = weights[k + 2, i], weights[k + 2, i + 1], weights[k + 2, i + 2], weights[k + 2, i + 3]
            d0, d1, d2, d3 = weights[k + 3, i], weights[k + 3, i + 1], weights[k + 3, i + 2], weights[k + 3, i + 3]
            for f in range(T):
                x0, x1 = np.float32(codes[c, i, f]), np.float32(codes[c, i + 1, f])
                x2, x3 = np.float32(codes[c, i + 2, f]), np.float32(codes[c, i + 3, f])
                h[k, f] = (((h[k, f] + x0 * a0) + x1 * a1) + x2 * a2) + x3 * a3
                h[k + 1, f] = (((h[k + 1, f] + x0 * b0) + x1 * b1) + x2 * b2) + x3 * b3
                h[k + 2, f] = (((h[k + 2, f] + x0 * c0) + x1 * c1) + x2 * c2) + x3 * c3
                h[k + 3, f] = (((h[k + 3, f] + x0 * d0) + x1 * d1) + x2 * d2) + x3 * d3
        for i in range(whole, K):
            for j in range(k, k + 4):
                w = weights[j, i]
                for f in range(T):
                    h[j, f] += np.float32(codes[c, i, f]) * w
    for k in range(fours, n):
        for i in range(K):
            w = weights[k, i]
            for f in range(T):
                h[k, f] += np.float32(codes[c, i, f]) * w


@kernel()
def scan_frames(
    est: np.ndarray,
    bias: np.ndarray,
    framed: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    query: tuple[np.ndarray, float, float, float],
    pose: tuple[np.ndarray, np.ndarray, float],
    pose_bound: tuple[np.ndarray, float, float],
    scan_out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    audio: tuple[np.ndarray, np.ndarray, np.ndarray, float],
    audio_out: tuple[np.ndarray, np.ndarray],
) -> None:
    """The scan of one query over a range of clips from the frame copy, as :func:`scan_reduced` is
    from the 8-bit copy (the same parameters and outputs but these two).

    Parameters
    ----------
    framed : (codes, steps, marked, stats, offsets)
        The clips' part of the :class:`~gesturekit.search.frames.FramePose`, with ``kappa``
        marked by the admissible starts (:func:`~gesturekit.search.frames.frame_bias`: +inf
        where not admissible, -inf where admissible and not covered), and its offsets.
    query : (weights, offset, norm, shift_norm)
        ``p_{t-1}`` as :class:`~gesturekit.search.frames.FrameQuery` holds it, and ``|b|``.

    A clip's estimates are ``kappa - 2 sum_k h[k, s + o_k]`` (:func:`frame_products` of the
    clip's codes with the query's weights times the clip's steps); plus the
    query's offset they lie within :func:`frame_bound` of the squared distances. Where that
    leaves the nearest start open, the float32 tier settles it as in :func:`scan_reduced`; the
    clips with an admissible start the copy does not cover go to that tier whole. The nearest
    start's estimate is kept: its bound is a few times the float32 scan's.
    """
    codes, steps, marked, stats, offsets = framed
    weights, offset, query_norm, shift_norm = query
    poses, query_pose, q_sqnorm = pose
    clip_max_sqnorm, err_factor, tiny = pose_bound
    best_start, best_d2, best_err, undecided = scan_out
    nc, T = est.shape
    n, K = weights.shape
    inf = np.float32(np.inf)
    reach = 0
    for k in range(n):
        reach = max(reach, offsets[k])
    covered = T - reach
    h = np.empty((n, T), np.float32)
    total = np.empty(T, np.float32)
    scaled = np.empty(weights.shape, np.float32)
    opened = np.empty(nc, np.int64)
    first = np.empty(nc, np.int64)
    last = np.empty(nc, np.int64)
    least = np.empty(nc, np.int64)
    zeros = np.empty(nc, np.bool_)
    t32s = np.empty(nc, np.float32)
    bounds = np.empty((nc, 2))
    tiered = np.zeros(nc, np.bool_)
    n_open = 0
    for c in range(nc):
        undecided[c] = False
        beyond = 0
        for s in range(covered, T):
            beyond += marked[c, s] < inf
        if beyond > 0:  # a start whose frames run past the clip: every admissible start in float32
            # (nothing known of them: each estimate 0 within a bound 0, so any could be at zero)
            a = T
            for s in range(T):
                est[c, s] = np.float32(0.0) if bias[c, s] < inf else inf
                a = min(a, s if bias[c, s] < inf else T)
            n_open = open_clip(est, c, (a, 0.0, 0.0, 0.0), (opened, first, last, least, zeros, t32s, bounds), n_open)
            continue
        for k in range(n):
            for i in range(K):
                scaled[k, i] = weights[k, i] * steps[c, i]
        frame_products(codes, c, scaled, h)
        # the blocks' products at their frames, summed block after block along starts; unsigned
        # indices, for which numba adds no test for negative ones (that test stops vectorising).
        # Four blocks (the layout's) in one loop, other counts block by block.
        ucov = np.uint64(covered)
        if n == 4:
            o0, o1, o2, o3 = np.uint64(offsets[0]), np.uint64(offsets[1]), np.uint64(offsets[2]), np.uint64(offsets[3])
            for u in range(ucov):
                acc = ((h[0, u + o0] + h[1, u + o1]) + h[2, u + o2]) + h[3, u + o3]
                est[c, u] = marked[c, u] + np.float32(-2.0) * acc
        else:
            o = np.uint64(offsets[0])
            for u in range(ucov):
                total[u] = h[0, u + o]
            for k in range(1, n):
                o = np.uint64(offsets[k])
                for u in range(ucov):
                    total[u] += h[k, u + o]
            for u in range(ucov):
                est[c, u] = marked[c, u] + np.float32(-2.0) * total[u]
        for s in range(covered, T):
            est[c, s] = inf
        err = frame_bound(stats, c, query_norm, shift_norm, err_factor, tiny)
        arg, best, open_ = clip_minimum_within(est, c, 0, covered, offset, err)
        if not best < inf:  # no admissible start
            best_start[c] = 0
            best_d2[c] = np.inf
            best_err[c] = 0.0
            continue
        if not open_:
            best_start[c] = arg
            best_d2[c] = np.float64(best) + offset
            best_err[c] = err
            continue
        n_open = open_clip(est, c, (arg, best, err, offset), (opened, first, last, least, zeros, t32s, bounds), n_open)
    settle_open(
        est, bias, pose, pose_bound, (opened, first, last, least, zeros, t32s, bounds, n_open), scan_out, tiered
    )
    nearest_audio(est, bias, pose, pose_bound, scan_out, tiered, False, audio, audio_out)
