"""The fast exact search: :class:`SearchIndex`, :func:`search`, :func:`search_batch`.

:func:`search` runs the search of the paper (Algorithm 1 of the supplementary material, with the authors'
choices and ours, see ``docs/METHOD.md`` and :mod:`gesturekit.search.reference`) on plain arrays and returns a
:class:`SearchResult`: the chosen (clip, start) per step, the output frames as (clip, frame) indices, and a
record of every step's best candidates. :func:`search_batch` serves several query sequences (each with its own
configuration) with one scan of the database per step.

Exactness. The result equals :func:`gesturekit.search.reference.search_reference` decision for decision. Each
step scans the database once. One query's scan reads an 8-bit copy of the pose features
(:mod:`gesturekit.search.reduced`, a few clips at a time), whose estimates lie within a proven bound per clip;
where that bound leaves a clip's nearest start open, the starts that could be nearest are estimated again in
float32 (``||p||^2 - 2 p.q``), and the nearest start of every clip is. Several queries' scan, and every scan on
a torch device (:mod:`gesturekit.search.device`), is a float32 matrix product. Per clip the starts whose float32
value lies within a proven error bound of the clip's minimum are decided among with the exact float64
definitions of :mod:`gesturekit.search.reference`. The same bound-and-re-check is applied to the ordering of
clips by pose and by audio distance, so ties and near-ties are always settled by the exact values.

Error bound (pose). For a row ``p`` and the query ``q`` (both float32, D = 96 values), the float32 estimate ``A
= fl(np32 + fl(-2 q.p))`` with ``np32`` the float32 rounding of ``|p|^2`` satisfies, for any summation order of
the product (blocked, SIMD, FMA), ``|A + |q|^2 - d2| <= (gamma_D + 3u)(|p|^2 + |q|^2)`` with ``u = 2**-24`` and
``gamma_D = D u / (1 - D u)``; we use ``(D + 32) u (max_clip |p|^2 + |q|^2)``, which also covers the float64
rounding of the exact value. Features are limited to magnitudes below 1e15 so that no float32 product or sum
overflows.

Error bound (audio). The cosine distance is estimated from a float32 dot product (any summation order) and
float64 norms; its error is below ``(A + 16) u``.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError, warn
from ..features import LAYOUT
from .admissible import base_starts, control_starts, draw_initial_frame
from .checks import SearchOptions, checked_sqnorms, validate_call, validate_db
from .decide import decide_query
from .device import DeviceRows
from .exact import TINY, audio_err, compiled, pose_err_factor, reduce_chunk
from .frames import FramePose, frame_bias, frame_pose, frame_query
from .plan import SearchPlan, stack_plans
from .reduced import ReducedPose, compiled_reduced, quantise_query, reduce_pose
from .threads import matrix_product, single_threaded_blas, worker_count
from .types import CANDIDATE_FIELDS, SearchConfig, SearchResult, describe_steps

if TYPE_CHECKING:  # typing.Unpack is Python 3.11+; only the type checker reads it
    from typing_extensions import Unpack

__all__ = ["SearchIndex", "search", "search_batch"]

#: Clips scanned per chunk are chosen so that one chunk's float32 result holds this many bytes.
_CHUNK_BYTES = 16 << 20

#: Clips estimated and reduced at a time by one query's scan: their estimates stay in the
#: processor's cache between the estimates and the reduction.
_SUB_CLIPS = 1024


class SearchIndex:
    """A database prepared for fast exact search (norms and per-clip bounds computed once).

    Parameters
    ----------
    P : np.ndarray, shape (M, T, D), float32
        z-scored pose features of the clips (D = 96). Kept by reference (not copied)
        when it is a C-contiguous float32 array.
    F : np.ndarray, shape (M, T, A), float32
        z-scored audio features (A = 112), kept by reference likewise.
    valid : np.ndarray, shape (M, T), bool
        Frames whose features needed no padding; only these may start a segment.
    device : str, optional
        A torch device (``"cuda"``) keeping the pose and audio features, where every scan is one float32
        product reduced there per clip (:mod:`gesturekit.search.device`); the rest, and the result, as on
        the CPU (the default).
    pose_offsets : sequence of int, optional
        The frames ahead that the pose feature's blocks hold (default: gesturekit's layout,
        ``(0, 2, 4, 6)``, where D is 96). Where the features are built so, one query's scan
        reads the frame copy (:meth:`frames`); otherwise, or with ``()``, the 8-bit copy.

    Notes
    -----
    Extra memory: ``12 M T`` bytes of per-frame norms; from the first single query on,
    the frame copy of the pose features (:meth:`frames`, ``(2 D / n + 4) M T`` bytes for
    ``n`` offsets) or else the 8-bit copy (:meth:`reduced`, ``(D + 8) M T`` bytes and
    ``4 (D + 8) M`` per clip; with a ``device``, a few per-clip arrays a step instead, on the device
    the features and a step's ``4 M T B`` bytes of products);
    per search, a few arrays of ``4 M T`` bytes per control mask in use (with the frame copy, one
    more each, for at most four masks at a time) and a scan buffer of at most 16 MB (with the frame
    copy, ``4 M T`` bytes).
    """

    def __init__(
        self,
        P: np.ndarray,
        F: np.ndarray,
        valid: np.ndarray,
        *,
        device: str | None = None,
        pose_offsets: Sequence[int] | None = None,
    ) -> None:
        self.P, self.F, self.valid = validate_db(P, F, valid)
        M, T, D = self.P.shape
        self.shape = (M, T, D, self.F.shape[2])
        self._P3 = np.asarray(self.P)  # plain views (np.memmap is a subclass the kernels do not take)
        self._F3 = np.asarray(self.F)
        self._P2 = self._P3.reshape(M * T, D)
        self._F2 = self.F.reshape(M * T, -1)
        self._pose_c = pose_err_factor(D)
        self._audio_e = audio_err(self.shape[3])
        self._workers = worker_count()
        np64 = checked_sqnorms(np.asarray(self._P2), "pose", self._workers)
        self._np32 = np64.astype(np.float32)
        self._npmax = np64.reshape(M, T).max(axis=1)
        self._na64 = checked_sqnorms(np.asarray(self._F2), "audio", self._workers)
        self._na2 = self._na64.reshape(M, T)
        self._scratch = threading.local()
        self._reduced: ReducedPose | None = None
        self._reduced_lock = threading.Lock()
        if pose_offsets is None:
            pose_offsets = LAYOUT.pose_offsets if D == LAYOUT.pose_dim else ()
        self._pose_offsets = np.asarray(tuple(pose_offsets), np.int64)
        self._frames: FramePose | None = None
        self._frames_made = False
        self._device = None if device is None else DeviceRows(self._P2, self._F2, M, device)  # torch loads only then

    def reduced(self) -> ReducedPose:
        """The reduced pose copy one query's scan reads (:mod:`gesturekit.search.reduced`),
        made on first use: a batch's matrix product reads the float32 features instead."""
        with self._reduced_lock:
            if self._reduced is None:
                self._reduced = reduce_pose(self._P3, self._workers)
            return self._reduced

    def frames(self) -> FramePose | None:
        """The frame copy one query's scan reads (:mod:`gesturekit.search.frames`), made on
        first use; None where the pose features are not built of frames ``pose_offsets`` ahead."""
        with self._reduced_lock:
            if not self._frames_made:
                if self._pose_offsets.size:
                    self._frames = frame_pose(self._P3, np.asarray(self.valid), self._pose_offsets, self._workers)
                self._frames_made = True
            return self._frames

    # -- admissibility -------------------------------------------------------------------------

    def _admissible(self, cache, n, rule, j, masks, exclude):
        """Admissible window starts ``(M, T)`` for windows of ``n`` frames under mask ``j``
        (-1: no control) and mask rule ``rule``, and the cache key they are stored under."""
        key = (n, rule if j >= 0 else "-", j)
        if key not in cache:
            base_key = (n, "-", -1)
            if base_key not in cache:
                cache[base_key] = (base_starts(self.valid, n, exclude), None)
            adm = cache[base_key][0]
            if j >= 0:
                adm = adm & control_starts(masks[j], n, rule)
            cache[key] = (adm, None)
        return cache[key][0], key

    def _bias(self, cache, key):
        """What the scan needs of the admissible starts under ``key``: ``bias`` (M T,) float32,
        ``|p|^2`` where a start is admissible, +inf elsewhere."""
        adm, bias = cache[key]
        if bias is None:
            bias = np.where(adm.ravel(), self._np32, np.float32(np.inf))
            cache[key] = (adm, bias)
        return bias

    @staticmethod
    def _frame_bias(framed, bias, scratch):
        """:func:`~gesturekit.search.frames.frame_bias` of ``bias``, kept in ``scratch`` for the few
        biases last used (a search's steps mostly share one)."""
        kept = {} if scratch is None else scratch.setdefault("frame_bias", {})
        hit = kept.get(id(bias))
        if hit is not None and hit[0] is bias:
            return hit[1]
        marked = frame_bias(framed, bias)
        if len(kept) >= 4:
            kept.pop(next(iter(kept)))
        kept[id(bias)] = (bias, marked)  # the bias is kept with it, so that its id is not reused
        return marked

    # -- one scan of the database for several queries ------------------------------------------

    def _scan(self, Q, biases, fq, scratch=None, pool=None, window=0):
        """Per query and clip: the nearest start's estimate, its bound, and the rows needing an exact look.

        Parameters
        ----------
        Q : np.ndarray, shape (B, D), float32
            Query pose features.
        biases : list of B arrays, shape (M T,), float32
            ``|p|^2`` where the window is admissible for that query, else +inf.
        fq : np.ndarray, shape (B, A), float32
            The queries' audio features (see ``audio`` below).
        scratch : dict, optional
            Keeps a single query's product buffer between steps (fresh pages cost page faults).
        pool : ThreadPoolExecutor, optional
            Threads to share out each chunk's product and reductions by clips.
        window : int
            The fewest frames of a window among the queries: from ``max(pose_offsets) + 1`` on,
            every admissible start is one the frame copy covers.

        One query's scan reads the frame copy (:meth:`frames`, where the features allow it and
        ``window`` is long enough; :func:`~gesturekit.search.reduced_kernels.scan_frames`) or
        the reduced copy (:meth:`reduced`) of the admissible starts
        and, where its bound leaves a clip's nearest start open, the float32 features of
        the few starts that could be nearest (:func:`~gesturekit.search.reduced_kernels.scan_reduced`);
        several queries' scan (and every scan on a ``device``) is a float32 matrix product of the starts used.

        Returns
        -------
        s0 : (B, M) int64
            A start of least estimate per clip.
        d2 : (B, M) float64
            Its squared pose distance estimate (+inf: no admissible start).
        err : (B, M) float64
            The error bound of that estimate.
        nq : (B,) float64
            ``|q|^2``.
        undecided : list of B (clips, rows) pairs
            Clips whose minimum is not decisive; ``rows[i]`` holds float32 estimates
            ``|p|^2 - 2 p.q`` of the T starts of clip ``clips[i]`` (+inf: cannot be nearest).
            Empty for a single query's scan, which resolves such clips itself (``err`` 0).
        audio : (av, inexact)
            ``av[b, m]`` (B, M) float64 is the estimated cosine distance of clip ``m``'s start
            ``s0`` to query ``b``'s audio feature (float32 product, float64 norms; NaN
            where no start is admissible); ``inexact`` (bool, same shape) is False where the
            value is exact (a zero norm), else the audio error bound applies.

        Every (B, M) array is C-contiguous: a query's decisions read its own rows (a
        column of a (M, B) array would cost a cache line per clip).
        """
        if self._device is not None:
            return self._device.scan(Q, biases, fq, (self._npmax, self._pose_c, TINY), self._na2)
        M, T, D, _ = self.shape
        B = Q.shape[0]
        # queries sharing a bias become one contiguous range of columns
        groups: dict[int, list[int]] = {}
        for b, bias in enumerate(biases):
            groups.setdefault(id(bias), []).append(b)
        perm = np.concatenate([np.asarray(m, dtype=np.int64) for m in groups.values()])
        ranges, j = [], 0
        for members in groups.values():
            ranges.append((biases[members[0]], j, j + len(members)))
            j += len(members)
        Qp = Q[perm]
        W = np.float32(-2.0) * Qp  # exact scaling: the product gives -2 q.p directly
        nq = np.einsum("ij,ij->i", Qp.astype(np.float64), Qp.astype(np.float64))
        reduced_scan = B == 1
        framed = None
        if reduced_scan and self._pose_offsets.size and window > int(self._pose_offsets.max()):
            framed = self.frames()
        # the frame scan makes each clip's row and reduces it at once: one chunk (two threads
        # waiting for each other once a step), its buffer holding the rows of the clips left open
        per_chunk = M if framed is not None else max(1, min(M, _CHUNK_BYTES // (4 * T * B)))
        size = per_chunk * T * B
        buf = None if scratch is None else scratch.get("product")
        if buf is None or buf.size < size:
            buf = np.empty(size, np.float32)
            if scratch is not None and B == 1:  # a batch's larger buffer is freed before its decisions
                scratch["product"] = buf
        product = matrix_product(B)
        # per query group and clip: one past the last admissible start (0: none)
        range_ends = [] if reduced_scan else [compiled().admissible_ends(bias.reshape(M, T)) for bias, _, _ in ranges]
        s0 = np.empty((M, B), np.int64)
        d2 = np.empty((M, B))
        err = np.empty((M, B))
        if framed is not None:
            fqr = frame_query(Qp[0], framed)
            frame_args = (fqr.weights, fqr.offset, fqr.norm, framed.shift_norm)
            marked = self._frame_bias(framed, biases[0], scratch)
        elif reduced_scan:
            red = self.reduced()
            codes = quantise_query(Qp[0])
            query_codes = (codes.codes, codes.scale, codes.lost, codes.norm)
        # the audio estimate of each clip's s0 per query, made while the clip is at hand
        fqp = np.ascontiguousarray(np.asarray(fq, np.float32)[perm])
        f64 = fqp.astype(np.float64)
        nbp = np.einsum("ij,ij->i", f64, f64)
        av = np.full((M, B), np.nan)
        inexact = np.zeros((M, B), bool)

        def work(c0, c1, G):
            """Product and reductions for clips c0 .. c1 - 1 into ``G`` ((c1 - c0) T, B);
            returns the clips whose minimum is not decisive, as (clips, queries, rows)."""
            nc = c1 - c0
            r0, r1 = c0 * T, c1 * T
            found = []
            if reduced_scan:  # a few clips at a time, reduced while their estimates are in cache
                G2 = G.reshape(nc, T)
                bias2 = biases[0][r0:r1].reshape(nc, T)
                und = np.empty(nc, bool)
                # the frame scan reduces each clip's row as soon as it is made: one call takes all
                step = nc if framed is not None else _SUB_CLIPS
                for a in range(0, nc, step):
                    z = min(nc, a + step)
                    x0, x1 = c0 + a, c0 + z
                    common = (
                        (self._P3[x0:x1], Qp[0], float(nq[0])),
                        (self._npmax[x0:x1], self._pose_c, TINY),
                        (s0[x0:x1, 0], d2[x0:x1, 0], err[x0:x1, 0], und[a:z]),
                        (self._F3[x0:x1], self._na2[x0:x1], fqp[0], float(nbp[0])),
                        (av[x0:x1, 0], inexact[x0:x1, 0]),
                    )
                    if framed is not None:
                        compiled_reduced().scan_frames(
                            G2[a:z],
                            bias2[a:z],
                            (
                                framed.codes[x0:x1],
                                framed.steps[x0:x1],
                                marked[x0:x1],
                                framed.stats[x0:x1],
                                framed.offsets,
                            ),
                            frame_args,
                            *common,
                        )
                    else:
                        compiled_reduced().scan_reduced(
                            G2[a:z],
                            bias2[a:z],
                            (red.codes[x0:x1], red.coef[x0:x1], red.kappa[x0:x1], red.centre[x0:x1], red.stats[x0:x1]),
                            query_codes,
                            *common,
                        )
                ci = np.flatnonzero(und)
                if ci.size:
                    found.append((ci + c0, np.zeros(ci.size, np.int64), G2[ci]))
                return found
            # starts from L on are admissible for no query in these clips: their products are skipped
            L = int(max(ends[c0:c1].max() for ends in range_ends))
            if L == 0:
                s0[c0:c1] = 0
                d2[c0:c1] = np.inf
                err[c0:c1] = 0.0
                return found
            G3 = G[: nc * L].reshape(nc, L, B)
            product(self._P3[c0:c1, :L], W, G3)
            for bias, j0, j1 in ranges:
                bias2 = bias[r0:r1].reshape(nc, T)[:, :L]
                s0c, amc, und = reduce_chunk(G3[:, :, j0:j1], bias2, nq[j0:j1], self._npmax[c0:c1], self._pose_c)
                s0[c0:c1, j0:j1] = s0c
                nqj = nq[j0:j1]
                d2[c0:c1, j0:j1] = amc.astype(np.float64) + nqj  # +inf stays +inf
                err[c0:c1, j0:j1] = self._pose_c * (self._npmax[c0:c1, None] + nqj) + TINY
                compiled().audio_at(
                    self._F3[c0:c1],
                    self._na2[c0:c1],
                    (s0c, amc),
                    fqp[j0:j1],
                    nbp[j0:j1],
                    (av[c0:c1, j0:j1], inexact[c0:c1, j0:j1]),
                )
                ci, bj = np.nonzero(und)
                if ci.size:
                    rows = np.full((ci.size, T), np.float32(np.inf))
                    rows[:, :L] = G3[ci, :, bj + j0] if j1 - j0 == 1 else G3[ci, :, bj + j0] + bias2[ci]
                    found.append((ci + c0, perm[bj + j0], rows))
            return found

        # each chunk is shared out to the threads by clips: the memory-bound product of
        # one part overlaps the compute-bound reductions of another
        parts = 1 if pool is None else self._workers
        cx_m, cx_b, cx_rows = [], [], []
        for c0 in range(0, M, per_chunk):
            c1 = min(M, c0 + per_chunk)
            cuts = np.linspace(c0, c1, min(parts, c1 - c0) + 1).astype(int)
            pieces = []
            for a, b in zip(cuts[:-1], cuts[1:]):
                G = buf[(a - c0) * T * B : (b - c0) * T * B].reshape((b - a) * T, B)  # rows x queries
                pieces.append((int(a), int(b), G))
            jobs = [pool.submit(work, *p) for p in pieces[1:]] if len(pieces) > 1 else []
            found = work(*pieces[0])
            for job in jobs:
                found += job.result()
            for m_, b_, rows in found:
                cx_m.append(m_)
                cx_b.append(b_)
                cx_rows.append(rows)
        undecided = []
        if cx_b:
            mi, bi, rows = np.concatenate(cx_m), np.concatenate(cx_b), np.concatenate(cx_rows)
            for b in range(B):
                sel = bi == b
                undecided.append((mi[sel], rows[sel]))
        else:
            undecided = [(np.zeros(0, np.int64), np.zeros((0, T), np.float32))] * B
        if B == 1:  # (M, 1) arrays: their transposes are the one C-contiguous row already
            return s0.T, d2.T, err.T, nq, undecided, (av.T, inexact.T)
        inv = np.empty(B, np.int64)
        inv[perm] = np.arange(B)
        # back to the callers' query order, one C-contiguous row per query
        return s0.T[inv], d2.T[inv], err.T[inv], nq[inv], undecided, (av.T[inv], inexact.T[inv])

    # -- public ---------------------------------------------------------------------------------

    def search(self, query: np.ndarray, **options: Unpack[SearchOptions]) -> SearchResult:
        """Run Algorithm 1 for one query; see :func:`search` for the parameters."""
        c = validate_call(self.shape, query, **options)  # names the keywords, checks them once here
        return self.search_batch(
            [c.query], configs=[c.config], masks=c.masks, step_mask_indices=[c.step_mask_index], exclude=c.exclude
        )[0]

    def search_plans(self, plans: Sequence[SearchPlan], *, fps: float | None = None) -> list[SearchResult]:
        """Search each plan (:func:`~gesturekit.search.plan.plan_search`) with one scan per step for all.

        Plans of one batch must exclude the same frames; ``fps`` is as in :meth:`search_batch`.
        Returns one :class:`SearchResult` per plan, identical to searching each plan alone.
        """
        b = stack_plans(plans)
        indices, exclude = b.step_mask_indices, b.exclude
        return self.search_batch(
            b.queries, configs=b.configs, masks=b.masks, step_mask_indices=indices, exclude=exclude, fps=fps
        )

    def search_batch(
        self,
        queries: Sequence[np.ndarray],
        *,
        configs: SearchConfig | Sequence[SearchConfig | None] | None = None,
        masks: np.ndarray | None = None,
        step_mask_indices: Sequence[np.ndarray | None] | None = None,
        exclude: np.ndarray | None = None,
        fps: float | None = None,
    ) -> list[SearchResult]:
        """Run Algorithm 1 for several queries with one scan of the database per step.

        Parameters
        ----------
        queries : sequence of np.ndarray, each shape (T_out_b, A)
            z-scored audio features of each speech to synthesise.
        configs : SearchConfig or sequence of SearchConfig, optional
            One for all, or one per query (step length, k, pins ... may differ).
        masks : np.ndarray, shape (n_masks, M, T), bool, optional
            Control masks shared by the queries.
        step_mask_indices : sequence of (np.ndarray of shape (n_steps_b,), int, or None), optional
            Per query, the mask index of each step (-1: no control).
        exclude : np.ndarray, shape (M, T), bool, optional
            Frames no query may use.
        fps : float, optional
            Frame rate of the output: a relaxed control is then reported in seconds.

        Returns
        -------
        list of SearchResult
            Identical to running :func:`search` on each query.

        Notes
        -----
        Each step multiplies the pose matrix by all active queries at once (torch's
        matrix product when available). The search runs its own few threads (one per
        core, at most 8): they share out the scan by clips and, with four queries or
        more, the per-query decisions; numpy's BLAS and torch are limited to one
        thread each while it runs (their settings are restored afterwards).
        """
        if isinstance(queries, np.ndarray) and queries.ndim == 2:
            raise ConfigError("search_batch takes a sequence of query arrays; use search for a single query")
        queries = list(queries)
        B = len(queries)
        if B == 0:
            return []
        per_query: list[SearchConfig | None] = (
            [configs] * B if configs is None or isinstance(configs, SearchConfig) else list(configs)
        )
        indices = [None] * B if step_mask_indices is None else list(step_mask_indices)
        if len(per_query) != B or len(indices) != B:
            raise ConfigError(
                f"{B} queries need {B} configs and step mask indices, got {len(per_query)} and {len(indices)}"
            )
        calls = [
            validate_call(self.shape, q, config=c, masks=masks, step_mask_index=sm, exclude=exclude)
            for q, c, sm in zip(queries, per_query, indices)
        ]
        masks = calls[0].masks
        exclude = calls[0].exclude
        M, T, D, _ = self.shape
        cache: dict = {}

        def step_key(b, i, relaxed=False):
            c = calls[b]
            j = -1 if (relaxed or c.step_mask_index is None) else int(c.step_mask_index[i])
            return self._admissible(cache, c.config.segment, c.config.mask_rule, j, masks, exclude)

        results, poses = [], np.empty((B, D), np.float32)
        for b, c in enumerate(calls):
            cfg = c.config
            if cfg.init_pose == "random":
                adm, _ = step_key(b, 0)
                if not adm.any():
                    adm, _ = step_key(b, 0, relaxed=True)
                init_frame = draw_initial_frame(adm, cfg.seed)
                init_pose = self.P[init_frame]
            else:
                init_frame = (-1, -1)
                init_pose = np.asarray(cfg.init_pose, dtype=np.float32)
            poses[b] = init_pose
            results.append(
                SearchResult.empty(
                    c.n_steps, c.query.shape[0], cfg.table_width, config=cfg, init_pose=init_pose, init_frame=init_frame
                )
            )

        # a few threads share the scan and, in batches, the per-query decisions of each step
        pool = ThreadPoolExecutor(self._workers) if self._workers > 1 else None
        if B > 1:
            matrix_product(B)  # loads torch, if installed, before its threads are limited
        with contextlib.ExitStack() as stack:
            stack.enter_context(single_threaded_blas())
            if pool is not None:
                stack.callback(pool.shutdown)
            for i in range(max(c.n_steps for c in calls)):
                active = [b for b in range(B) if i < calls[b].n_steps]
                keys, asked = {}, set()
                for b in active:
                    adm, key = step_key(b, i)
                    asked.add(key)  # kept even when relaxed: an empty mask is not rebuilt every step
                    if key[2] >= 0 and not adm.any():  # the control admits no window at all
                        results[b].relaxed[i] = True
                        adm, key = step_key(b, i, relaxed=True)
                    keys[b] = key
                rows = {b: calls[b].query[i * calls[b].config.segment] for b in active}
                widths = {b: calls[b].config.table_width for b in active}
                decided = self._step(active, keys, poses, (rows, widths), cache, pool)
                retry = [b for b in active if decided[b] is None and keys[b][2] >= 0]
                if retry:  # only the query's own frame was admissible under the control
                    for b in retry:
                        results[b].relaxed[i] = True
                        keys[b] = step_key(b, i, relaxed=True)[1]
                    decided.update(self._step(retry, keys, poses, (rows, widths), cache, pool))
                # drop cached masks this step did not use (a long control track has many)
                used = asked | set(keys.values()) | {(k[0], "-", -1) for k in keys.values()}
                for key in [key for key in cache if isinstance(key, tuple) and key not in used]:
                    del cache[key]
                for b in active:
                    self._record(results[b], calls[b].query.shape[0], i, decided[b], poses, b)

        for r in results:
            if r.relaxed.any():
                where = describe_steps(np.flatnonzero(r.relaxed), segment=r.config.segment, fps=fps)
                warn(f"control relaxed at {where}: no database window satisfies it", stacklevel=3)
        return results

    def _step(self, active, keys, poses, queries, cache, pool=None):
        """One search step for several queries: one scan, then the exact decisions per query.

        ``queries`` is ``(rows, widths)``: per query, its audio feature at the step's first
        frame and its table width. ``pool`` (a thread pool) spreads the per-query decisions
        over the cores; they are independent, so the results do not depend on it.
        """
        rows, widths = queries
        run = map if pool is None or len(active) < 4 else pool.map
        biases = [self._bias(cache, keys[b]) for b in active]
        fq = np.stack([rows[b] for b in active])
        s0, d2, err, nq, undecided, (av, inexact) = self._scan(
            poses[active], biases, fq, cache.setdefault("scratch", {}), pool, min(keys[b][0] for b in active)
        )

        def decide(j):
            b = active[j]
            return decide_query(
                (self._P3, self._F3, self._npmax, self._pose_c, self._audio_e),
                self._scratch,
                (s0[j], d2[j], err[j], nq[j], undecided[j], av[j], inexact[j]),
                (poses[b], fq[j]),
                widths[b],
                lone,
            )

        lone = pool if len(active) == 1 else None  # one query: its decisions may share the threads

        return dict(zip(active, run(decide, range(len(active)))))

    def _record(self, res, n_frames, i, d, poses, b):
        """Write step ``i``'s table and choice (the k-th, or the pin) into ``res`` (a result of
        ``n_frames`` output frames); advance ``p_{t-1}``."""
        cfg = res.config
        N = cfg.segment
        if d is None and i not in cfg.pins:
            raise ConfigError(
                f"step {i}: no database window is admissible (valid start, {N} frames inside the clip, "
                "no excluded frame) other than the query's own frame"
            )
        n = 0 if d is None else d["n"]
        if d is not None:
            w = d["cand_clip"].size
            for name in CANDIDATE_FIELDS:
                getattr(res, name)[i, :w] = d[name]
        res.n_candidates[i] = n
        res.short[i] = cfg.k >= n
        if i in cfg.pins:
            m, s = cfg.pins[i]
            res.pinned[i] = True
            hit = np.flatnonzero((res.cand_clip[i] == m) & (res.cand_start[i] == s))
            res.position[i] = int(hit[0]) if hit.size else -1
        else:
            pos = min(cfg.k, n - 1)
            m, s = int(d["cand_clip"][pos]), int(d["cand_start"][pos])
            res.position[i] = pos
        res.clip[i], res.start[i] = m, s
        t = i * N
        L = min(N, n_frames - t)
        res.frames[t : t + L, 0] = m
        res.frames[t : t + L, 1] = s + np.arange(L)
        poses[b] = self.P[m, s + N - 1]


@checks_arguments
def search(
    P: np.ndarray, F: np.ndarray, valid: np.ndarray, query: np.ndarray, **options: Unpack[SearchOptions]
) -> SearchResult:
    """Algorithm 1: the k-NN motion search for one speech query.

    Parameters
    ----------
    P : np.ndarray, shape (M, T, 96), float32
        z-scored pose features of the database clips (T = 64 frames at 15 fps).
    F : np.ndarray, shape (M, T, 112), float32
        z-scored audio features of the database clips.
    valid : np.ndarray, shape (M, T), bool
        Frames whose features needed no padding (only these may start a segment).
    query : np.ndarray, shape (T_out, 112)
        z-scored audio features of the speech to synthesise (cast to float32).
    config : SearchConfig, optional
        Defaults: k = 0, N = 8, 10 candidates recorded, random initial pose with seed 0.
    masks : np.ndarray, shape (n_masks, M, T), bool, optional
        Control masks: which database frames may be used.
    step_mask_index : np.ndarray, shape (n_steps,), int, optional
        Per step (``n_steps = ceil(T_out / N)``), the index into ``masks``, -1 for no control.
    exclude : np.ndarray, shape (M, T), bool, optional
        Frames never to use (held-out takes); a window containing one is inadmissible.

    Returns
    -------
    SearchResult
        Equal to :func:`gesturekit.search.reference.search_reference` on the same inputs.

    Raises
    ------
    ConfigError
        Bad shapes or options, or a step where no window is admissible even without control.

    Warns
    -----
    GestureKitWarning
        When a step's control admits no window and is dropped for that step.

    Notes
    -----
    Builds a :class:`SearchIndex` on every call; keep one to search the same database repeatedly.
    """
    return SearchIndex(P, F, valid).search(query, **options)


@checks_arguments
def search_batch(
    P: np.ndarray,
    F: np.ndarray,
    valid: np.ndarray,
    queries: Sequence[np.ndarray],
    *,
    configs: SearchConfig | Sequence[SearchConfig | None] | None = None,
    masks: np.ndarray | None = None,
    step_mask_indices: Sequence[np.ndarray | None] | None = None,
    exclude: np.ndarray | None = None,
) -> list[SearchResult]:
    """Algorithm 1 for several queries with one scan of the database per step.

    Parameters are those of :func:`search`, with ``queries`` a sequence of query
    arrays, ``configs`` one :class:`SearchConfig` or one per query, and
    ``step_mask_indices`` one step mask index (or None) per query. Returns one
    :class:`SearchResult` per query, identical to separate :func:`search` calls.
    """
    return SearchIndex(P, F, valid).search_batch(
        queries, configs=configs, masks=masks, step_mask_indices=step_mask_indices, exclude=exclude
    )
