"""Algorithm 1 of the paper, written out loop for loop: the definition of the search.

This module is deliberately plain: loops over steps, clips and frames, Python
floats, no vectorisation. It is slow (use it on databases of a few hundred
clips at most) and it is what :func:`gesturekit.search.search` must reproduce
exactly, decision for decision; the tests compare the two.

The rules (Algorithm 1 of the supplementary material, with the choices of the
authors' code and ours, see ``docs/METHOD.md``, "Search"):

1. A window start ``s`` of clip ``m`` is admissible for a window of ``N``
   frames iff ``s + N <= T``, ``valid[m, s]``, no frame of ``[s, s + N)`` is
   excluded, and the step's control mask holds (rule ``"ends"``: at ``s`` and
   ``s + N - 1``; rule ``"all"``: at every frame of the window).
2. Per clip, the admissible ``s`` whose pose feature is nearest ``p_{t-1}``;
   a candidate at distance exactly 0 is skipped (it is the query's own frame);
   ties go to the smallest ``s``; a clip with no (non-zero) admissible ``s``
   drops out.
3. The audio distance of a surviving clip is the cosine distance between its
   audio feature at ``s`` and ``f_t``.
4. Surviving clips are ranked by pose distance and separately by audio
   distance (ordinal ranks from 0, ties by clip index); the ranks are added and
   the clips sorted by the sum (ties by clip index); the ``k``-th is taken (the
   last one when fewer than ``k + 1`` survive, recorded as ``short``).
5. Its frames ``s .. s + N - 1`` are appended; ``p_{t-1}`` becomes the pose
   feature at ``s + N - 1``. The last step is cut to the query's length.
6. When no clip survives a step under its control, the control is dropped for
   that step (exclusions stay), the step is marked ``relaxed`` and a
   :class:`~gesturekit.errors.GestureKitWarning` is emitted; when none
   survives even then, :class:`~gesturekit.errors.ConfigError` is raised.

Exact arithmetic (shared with the fast search, which re-checks its float32
shortlist with the same definitions):

* pose: ``d2(a, b) = (((0 + e_0*e_0) + e_1*e_1) + ... + e_{D-1}*e_{D-1})`` with
  ``e_j = float64(a_j) - float64(b_j)``, every operation an IEEE float64
  operation, left to right (:func:`pose_sqdist`). Pose decisions compare
  ``d2``; the reported distance is ``sqrt(d2)``.
* audio: ``dot``, ``|a|^2`` and ``|b|^2`` summed the same way, and
  ``1 - dot / sqrt(|a|^2 * |b|^2)``; 1 when either norm is 0 (:func:`cosine_distance`).

Fidelity to the authors' code (GestureKNN). Compared step by step with stable
sorts, their loop makes the choices these rules make, except where it departs
from the algorithm as written; these rules follow the algorithm:

* Their per-clip scan, ``while pose_cand_ctr < len(sorted_idx_list) - 1``,
  never examines a clip's last-ranked frame: a clip whose only admissible start
  ranks last drops out of the step there and survives here (rule 2).
* Their random initial frame is any database frame satisfying the active control
  at that frame only; it may be one that cannot start a window (``s > T - N``).
  Here ``p_{-1}`` is drawn from the admissible starts of step 0 (rule 1, with the
  control held by the mask rule).
* Their features are zero-padded inside each 64-frame clip and z-scored over all
  frames, padding included, and every start ``s <= T - N`` is eligible, so a start
  whose look-ahead is padding can be chosen. Here the statistics come from the
  frames that can start a segment and such starts are never admissible (``valid``).
* Their search stops with an error unless the output's frame count is 0 or 1
  modulo N, and when fewer than ``k + 1`` clips survive; here the last step is cut
  to the query's length (rule 5) and the last survivor is taken (rule 4, ``short``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError, warn
from .checks import SearchOptions, validate
from .types import SearchResult, describe_steps

if TYPE_CHECKING:  # typing.Unpack is Python 3.11+; only the type checker reads it
    from typing_extensions import Unpack

__all__ = ["pose_sqdist", "cosine_distance", "window_admissible", "search_reference"]


@checks_arguments
def pose_sqdist(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """Squared Euclidean distance, exactly as defined for the search.

    Parameters
    ----------
    a, b : sequence of float, length D
        Two pose features (float32 values).

    Returns
    -------
    float
        ``sum_j (a_j - b_j)**2`` accumulated in float64 from left to right.
    """
    total = 0.0
    for x, y in zip(a, b):
        d = float(x) - float(y)
        total += d * d
    return total


@checks_arguments
def cosine_distance(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """Cosine distance ``1 - a.b / (|a| |b|)`` of two audio features (A float32 values each),
    exactly as defined for the search: in [0, 2], and 1 when either vector is all zeros."""
    dot = na = nb = 0.0
    for x, y in zip(a, b):
        x, y = float(x), float(y)
        dot += x * y
        na += x * x
        nb += y * y
    if na == 0.0 or nb == 0.0:
        return 1.0
    return 1.0 - dot / math.sqrt(na * nb)


@checks_arguments
def window_admissible(
    m: int,
    s: int,
    n: int,
    *,
    valid: np.ndarray,
    exclude: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    rule: str = "ends",
) -> bool:
    """Whether the window of ``n`` frames starting at frame ``s`` of clip ``m`` may be used.

    Parameters
    ----------
    m, s, n : int
        Clip, start frame, window length.
    valid : np.ndarray, shape (M, T), bool
        Frames whose features needed no padding.
    exclude : np.ndarray, shape (M, T), bool, optional
        Frames that must never be used.
    mask : np.ndarray, shape (M, T), bool, optional
        The step's control mask (``None``: no control).
    rule : {"ends", "all"}
        Where the mask must hold: at ``s`` and ``s + n - 1``, or on every frame.
    """
    if s + n > valid.shape[1] or not valid[m, s]:
        return False
    if exclude is not None and any(exclude[m, s + j] for j in range(n)):
        return False
    if mask is None:
        return True
    if rule == "ends":
        return bool(mask[m, s] and mask[m, s + n - 1])
    return all(mask[m, s + j] for j in range(n))


def _nearest_per_clip(P, p_prev, n, *, valid, exclude, mask, rule):
    """Lines 4-12 of Algorithm 1: per clip the nearest admissible, non-zero start.

    Returns a list of ``(clip, start, d2)`` in clip order (clips that drop out are absent).
    """
    M, T = valid.shape
    survivors = []
    for m in range(M):
        best_s, best_d2 = -1, math.inf
        for s in range(T):
            if not window_admissible(m, s, n, valid=valid, exclude=exclude, mask=mask, rule=rule):
                continue
            d2 = pose_sqdist(P[m, s].tolist(), p_prev)
            if d2 == 0.0:  # the query's own frame
                continue
            if d2 < best_d2:  # strict: ties keep the smallest s
                best_s, best_d2 = s, d2
        if best_s >= 0:
            survivors.append((m, best_s, best_d2))
    return survivors


@checks_arguments
def search_reference(
    P: np.ndarray, F: np.ndarray, valid: np.ndarray, query: np.ndarray, **options: Unpack[SearchOptions]
) -> SearchResult:
    """Algorithm 1, loop for loop: the literal search the fast one is tested against.

    Takes what :func:`gesturekit.search.search` takes: the database's z-scored pose
    features ``P`` (M, T, D) and audio features ``F`` (M, T, A), float32, the frames
    ``valid`` (M, T) that may start a segment, the query's z-scored audio features
    (T_out, A) at 15 fps and the keywords of :class:`~gesturekit.search.checks.SearchOptions`;
    returns the same :class:`SearchResult`.
    """
    v = validate(P, F, valid, query, **options)
    assert v.P is not None and v.F is not None and v.valid is not None  # set by validate
    P, F, valid, query, cfg = v.P, v.F, v.valid, v.query, v.config
    exclude, masks, step_mask_index = v.exclude, v.masks, v.step_mask_index
    M, T = valid.shape
    N, k = cfg.segment, cfg.k
    K = cfg.table_width
    T_out = query.shape[0]
    n_steps = -(-T_out // N)

    def control(i):
        j = -1 if step_mask_index is None else int(step_mask_index[i])
        return None if j < 0 else masks[j]

    # p_{-1}
    if cfg.init_pose == "random":
        frames = []
        for mask in (control(0), None):
            frames = [
                (m, s)
                for m in range(M)
                for s in range(T)
                if window_admissible(m, s, N, valid=valid, exclude=exclude, mask=mask, rule=cfg.mask_rule)
            ]
            if frames or mask is None:
                break
        if not frames:
            raise ConfigError("no admissible database frame to draw the initial pose from")
        rng = np.random.default_rng(cfg.seed)
        m0, s0 = frames[int(rng.integers(len(frames)))]
        init_pose = P[m0, s0].copy()
        init_frame = (m0, s0)
    else:
        init_pose = np.asarray(cfg.init_pose, dtype=np.float32)
        init_frame = (-1, -1)
    p_prev = init_pose.tolist()

    res = SearchResult.empty(n_steps, T_out, K, config=cfg, init_pose=init_pose, init_frame=init_frame)
    relaxed_steps = []
    for i in range(n_steps):
        t = i * N
        f_t = query[t].tolist()
        mask = control(i)
        survivors = _nearest_per_clip(P, p_prev, N, valid=valid, exclude=exclude, mask=mask, rule=cfg.mask_rule)
        if not survivors and mask is not None:
            res.relaxed[i] = True
            relaxed_steps.append(i)
            survivors = _nearest_per_clip(P, p_prev, N, valid=valid, exclude=exclude, mask=None, rule=cfg.mask_rule)
        if not survivors and i not in cfg.pins:
            raise ConfigError(
                f"step {i}: no database window is admissible (valid start, {N} frames inside the clip, "
                "no excluded frame) other than the query's own frame"
            )

        n = len(survivors)
        audio = [cosine_distance(F[m, s].tolist(), f_t) for m, s, _ in survivors]
        # survivors are in clip order, so the index c is the clip-index tie-break
        by_pose = sorted(range(n), key=lambda c: (survivors[c][2], c))
        by_audio = sorted(range(n), key=lambda c: (audio[c], c))
        pose_rank = [0] * n
        audio_rank = [0] * n
        for r, c in enumerate(by_pose):
            pose_rank[c] = r
        for r, c in enumerate(by_audio):
            audio_rank[c] = r
        combined = [pose_rank[c] + audio_rank[c] for c in range(n)]
        order = sorted(range(n), key=lambda c: (combined[c], c))

        for j, c in enumerate(order[:K]):
            m, s, d2 = survivors[c]
            res.cand_clip[i, j] = m
            res.cand_start[i, j] = s
            res.cand_pose_dist[i, j] = math.sqrt(d2)
            res.cand_audio_dist[i, j] = audio[c]
            res.cand_pose_rank[i, j] = pose_rank[c]
            res.cand_audio_rank[i, j] = audio_rank[c]
            res.cand_combined[i, j] = combined[c]
        res.n_candidates[i] = n
        res.short[i] = k >= n

        if i in cfg.pins:
            m, s = cfg.pins[i]
            res.pinned[i] = True
            res.position[i] = -1
            for j in range(min(K, n)):
                if res.cand_clip[i, j] == m and res.cand_start[i, j] == s:
                    res.position[i] = j
        else:
            pos = min(k, n - 1)
            m, s, _ = survivors[order[pos]]
            res.position[i] = pos
        res.clip[i] = m
        res.start[i] = s
        for j in range(min(N, T_out - t)):
            res.frames[t + j] = (m, s + j)
        p_prev = P[m, s + N - 1].tolist()

    if relaxed_steps:
        warn(
            f"control relaxed at {describe_steps(relaxed_steps, segment=N)}: no database window satisfies it",
            stacklevel=2,
        )
    return res
