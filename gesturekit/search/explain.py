"""One search step taken apart: every clip of the database accounted for.

:func:`explain_step` recomputes a single step of Algorithm 1 (see
:mod:`gesturekit.search.reference` for the rules) for *every* clip of the
database, not only the few candidates :class:`~gesturekit.search.SearchResult`
records, and returns the whole table: each clip's nearest admissible window to
the last pose, its pose and audio distances, its two ranks, their sum and its
place in the combined ranking. Distances use the exact definitions of the
search (:func:`~gesturekit.search.exact.exact_pose_sqdist`,
:func:`~gesturekit.search.exact.exact_cosine_distance`), windows its
admissibility (:func:`~gesturekit.search.admissible.admissible_starts`), and ties
are broken by the same rules, so the explained choice is the search's choice, bit
for bit. :func:`explain_plan_step` does it for a step of a finished search from
its :class:`~gesturekit.search.plan.SearchPlan`. The figures that draw it are in
:mod:`gesturekit.viz.walkthrough`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from .admissible import admissible_starts
from .checks import check_segment
from .exact import exact_cosine_distance, exact_pose_sqdist
from .plan import SearchPlan
from .types import SearchConfig, SearchResult

if TYPE_CHECKING:  # named in annotations only: pandas is imported where a table is made
    import pandas as pd

    from ..database import MatchingDatabase

__all__ = ["StepExplanation", "explain_step", "plan_step_inputs", "explain_plan_step", "query_pose_frame"]

#: Rows of pose features whose exact distances are computed at once (bounds the float64 scratch).
_CHUNK_ROWS = 1 << 15


@dataclass
class StepExplanation:
    """One search step, every clip of the database accounted for.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per clip, in clip order: ``clip``; ``start`` (its nearest admissible
        window's first frame, -1 when the clip drops out); ``admissible`` (windows of the
        clip the step may use); ``pose_dist`` (Euclidean distance of the window's pose
        feature to ``p_{t-1}``, z-scored units); ``audio_dist`` (cosine distance of its
        audio feature to ``f_t``, 0..2); ``pose_rank``, ``audio_rank`` (ordinal ranks among
        the surviving clips, 0 = best, ties by clip index); ``combined`` (their sum);
        ``position`` (place in the combined ranking, ties by clip index); ``chosen``.
        Clips that drop out have NaN distances and -1 ranks.
    clip, start : int
        The chosen window.
    position : int
        Its place in the combined ranking: ``min(k, survivors - 1)``.
    next_pose : np.ndarray, shape (D,), float32
        The pose feature at the chosen window's last frame: ``p_{t-1}`` of the next step.
    pose : np.ndarray, shape (D,), float32
        The pose feature the step matched against.
    audio : np.ndarray, shape (A,), float32
        ``f_t``, the speech's audio feature at the step's first frame.
    t, segment, k : int
        The step's first output frame, its length N and the k taken.
    relaxed : bool
        The control admitted no window and was dropped, as the search does.
    """

    table: pd.DataFrame
    clip: int
    start: int
    position: int
    next_pose: np.ndarray
    pose: np.ndarray
    audio: np.ndarray
    t: int
    segment: int
    k: int
    relaxed: bool = False

    @property
    def n_survivors(self) -> int:
        """Clips with an admissible window (the rest drop out of this step)."""
        return int(np.count_nonzero(self.table["start"].to_numpy() >= 0))

    def ranking(self) -> pd.DataFrame:
        """The surviving clips in combined-rank order (best first), as a DataFrame."""
        t = self.table[self.table["start"] >= 0]
        return t.sort_values("position").reset_index(drop=True)


def _nearest(P, pose, ok) -> tuple[np.ndarray, np.ndarray]:
    """Per clip the admissible start nearest ``pose`` (distance 0 skipped, ties to the smallest start).

    Returns
    -------
    start : (M,) int64, -1 where the clip drops out
    d2 : (M,) float64 squared distances, inf where it drops out
    """
    M, T, D = P.shape
    d2 = np.full(M * T, np.inf)
    flat_ok = ok.ravel()
    rows = np.flatnonzero(flat_ok)
    P2 = P.reshape(M * T, D)
    for a in range(0, rows.size, _CHUNK_ROWS):
        r = rows[a : a + _CHUNK_ROWS]
        d2[r] = exact_pose_sqdist(np.asarray(P2[r], dtype=np.float32), pose)
    d2[d2 == 0.0] = np.inf  # the query's own frame
    d2 = d2.reshape(M, T)
    start = np.argmin(d2, axis=1)  # first minimum: the smallest start on ties
    best = d2[np.arange(M), start]
    start = np.where(np.isfinite(best), start, -1)
    return start.astype(np.int64), best


@checks_arguments
def explain_step(
    db: MatchingDatabase,
    query_features: np.ndarray,
    pose: np.ndarray,
    *,
    t: int = 0,
    segment: int = 8,
    k: int = 0,
    mask: np.ndarray | None = None,
    exclude: np.ndarray | None = None,
    mask_rule: str = "ends",
) -> StepExplanation:
    """One step of Algorithm 1 for every clip: nearest windows, two rankings, the combined rank.

    Parameters
    ----------
    db : MatchingDatabase
        Anything with ``P`` (M, T, 96), ``F`` (M, T, 112) z-scored float32 features and
        ``valid`` (M, T) bool.
    query_features : np.ndarray, shape (T_out, 112)
        z-scored audio features of the speech (:meth:`MatchingDatabase.query_features`).
    pose : np.ndarray, shape (96,)
        ``p_{t-1}``, the z-scored pose feature of the last output frame.
    t : int
        The step's first output frame, ``0 <= t < T_out``; ``f_t = query_features[t]``.
    segment : int
        Frames per step, N.
    k : int
        Which place of the combined ranking to take (0 = best).
    mask : np.ndarray, shape (M, T), bool, optional
        The step's control: the database frames it admits.
    exclude : np.ndarray, shape (M, T), bool, optional
        Frames never to use.
    mask_rule : {"ends", "all"}
        Where ``mask`` must hold in a window: its first and last frame, or every frame.

    Returns
    -------
    StepExplanation
        Its ``clip``, ``start`` and candidate order equal those of
        :func:`gesturekit.search.search` for the same step and inputs.

    Raises
    ------
    ConfigError
        Bad shapes or options, or no admissible window even without the control.
    """
    import pandas as pd

    P, F, valid = db.P, db.F, np.asarray(db.valid, dtype=bool)
    M, T = valid.shape
    q = np.asarray(query_features, dtype=np.float32)
    pose = np.asarray(pose, dtype=np.float32).ravel()
    if q.ndim != 2 or q.shape[1] != F.shape[-1]:
        raise ConfigError(f"query_features must have shape (frames, {F.shape[-1]}), got {q.shape}")
    if pose.shape != (P.shape[-1],):
        raise ConfigError(f"pose must have {P.shape[-1]} values, got shape {pose.shape}")
    if not 0 <= int(t) < q.shape[0]:
        raise ConfigError(f"t must be in 0..{q.shape[0] - 1}, got {t}")
    options = SearchConfig(k=k, segment=segment, mask_rule=mask_rule)  # checks them as the search does
    check_segment(options.segment, T)
    for name, arr in (("mask", mask), ("exclude", exclude)):
        if arr is not None and np.shape(arr) != (M, T):
            raise ConfigError(f"{name} must have shape ({M}, {T}), got {np.shape(arr)}")
    t, n, k = int(t), options.segment, options.k
    exclude = None if exclude is None else np.asarray(exclude, dtype=bool)
    f_t = q[t]

    relaxed = False
    ok = admissible_starts(valid, n, exclude=exclude, mask=mask, rule=mask_rule)
    start, d2 = _nearest(P, pose, ok)
    if not (start >= 0).any() and mask is not None:
        relaxed = True  # as the search: drop the control for this step, keep the exclusions
        ok = admissible_starts(valid, n, exclude=exclude)
        start, d2 = _nearest(P, pose, ok)
    alive = np.flatnonzero(start >= 0)
    if alive.size == 0:
        raise ConfigError(
            f"no database window is admissible at t={t} (valid start, {n} frames inside "
            "the clip, no excluded frame) other than the query's own frame"
        )

    audio = exact_cosine_distance(np.asarray(F[alive, start[alive]], dtype=np.float32), f_t)
    n_alive = alive.size
    # ordinal ranks; alive is in clip order, so a stable sort breaks ties by clip index
    pose_rank = np.empty(n_alive, np.int64)
    pose_rank[np.argsort(d2[alive], kind="stable")] = np.arange(n_alive)
    audio_rank = np.empty(n_alive, np.int64)
    audio_rank[np.argsort(audio, kind="stable")] = np.arange(n_alive)
    combined = pose_rank + audio_rank
    order = np.argsort(combined, kind="stable")
    position = np.empty(n_alive, np.int64)
    position[order] = np.arange(n_alive)
    pos = min(k, n_alive - 1)
    chosen = int(alive[order[pos]])
    c_start = int(start[chosen])

    def full(values, fill, dtype):
        out = np.full(M, fill, dtype=dtype)
        out[alive] = values
        return out

    table = pd.DataFrame(
        {
            "clip": np.arange(M),
            "start": start,
            "admissible": ok.sum(axis=1),
            "pose_dist": full(np.sqrt(d2[alive]), np.nan, np.float64),
            "audio_dist": full(audio, np.nan, np.float64),
            "pose_rank": full(pose_rank, -1, np.int64),
            "audio_rank": full(audio_rank, -1, np.int64),
            "combined": full(combined, -1, np.int64),
            "position": full(position, -1, np.int64),
            "chosen": np.arange(M) == chosen,
        }
    )
    return StepExplanation(
        table=table,
        clip=chosen,
        start=c_start,
        position=pos,
        next_pose=np.asarray(P[chosen, c_start + n - 1], dtype=np.float32).copy(),
        pose=pose,
        audio=f_t.copy(),
        t=t,
        segment=n,
        k=k,
        relaxed=relaxed,
    )


@checks_arguments
def plan_step_inputs(plan: SearchPlan, result: SearchResult, pose_features: np.ndarray, step: int) -> dict:
    """What step ``step`` of a finished search searched with: the keyword arguments of :func:`explain_step`.

    Parameters
    ----------
    plan : SearchPlan
        The plan the search ran with.
    result : SearchResult
        Its result (the previous step's choice gives ``p_{t-1}``).
    pose_features : np.ndarray, shape (M, T, 96)
        The database's pose features (``db.P``).
    step : int
        ``0 <= step < plan.n_steps``.

    Returns
    -------
    dict
        ``query_features`` (T_out, 112), ``pose`` (``p_{t-1}``: the initial pose for step 0,
        else the pose feature at the last frame of the previous step's window), ``t``,
        ``segment`` (N), ``k``, ``mask`` (the step's control mask or None), ``exclude`` and
        ``mask_rule``.
    """
    i = plan.check_step(step)
    n = plan.segment
    if i == 0:
        pose = np.asarray(result.init_pose, dtype=np.float32)
    else:
        pose = np.asarray(pose_features[int(result.clip[i - 1]), int(result.start[i - 1]) + n - 1], dtype=np.float32)
    return {
        "query_features": plan.query,
        "pose": pose,
        "t": i * n,
        "segment": n,
        "k": plan.config.k,
        "mask": plan.mask_at(i),
        "exclude": plan.exclude,
        "mask_rule": plan.config.mask_rule,
    }


@checks_arguments
def explain_plan_step(db: MatchingDatabase, plan: SearchPlan, result: SearchResult, step: int) -> StepExplanation:
    """:func:`explain_step` for step ``step`` of a finished search (see :func:`plan_step_inputs`).

    A pinned step is explained by the search's rule; its actual window is the pin
    (``result.pinned``).
    """
    return explain_step(db, **plan_step_inputs(plan, result, db.P, step))


@checks_arguments
def query_pose_frame(P: np.ndarray, result: SearchResult, step: int) -> tuple[int, int] | None:
    """The database frame whose pose feature step ``step`` matched against: ``p_{t-1}`` as (clip, frame).

    Every candidate's pose distance is measured from this pose to the candidate's first frame,
    so drawing its joints next to a candidate shows that distance by eye.

    Parameters
    ----------
    P : np.ndarray, shape (M, T, 96)
        The database's pose features (``db.P``).
    result : SearchResult
        A finished search.
    step : int
        ``0 <= step < result.n_steps``.

    Returns
    -------
    (clip, frame) or None
        For a later step the last frame of the previous step's window (pinned or chosen);
        for step 0 the initial pose's frame (``result.init_frame``, or the frame whose pose
        feature equals ``result.init_pose``); None when the initial pose is no database frame
        (a pose given by its feature values).

    Raises
    ------
    ConfigError
        ``step`` out of range.
    """
    if not 0 <= int(step) < result.n_steps:
        raise ConfigError(f"step must be in 0..{result.n_steps - 1}, got {step}")
    i, n = int(step), int(result.config.segment)
    if i > 0:
        return int(result.clip[i - 1]), int(result.start[i - 1]) + n - 1
    if result.init_frame[0] >= 0:
        return int(result.init_frame[0]), int(result.init_frame[1])
    pose = np.asarray(result.init_pose, dtype=np.float32).ravel()
    M, T, D = np.shape(P)
    if pose.shape != (D,):
        return None
    per = max(1, _CHUNK_ROWS // T)  # clips compared at once (bounds the scratch of a large database)
    for a in range(0, M, per):
        hits = np.argwhere(np.all(np.asarray(P[a : a + per], dtype=np.float32) == pose, axis=2))
        if hits.size:
            return a + int(hits[0, 0]), int(hits[0, 1])
    return None
