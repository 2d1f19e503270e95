"""A search planned once: everything a search is given, built in one place.

:func:`plan_search` turns a database, a speech's query features and a
:class:`SearchRequest` (the search's options, the initial pose, the control track
and the exclusions) into a :class:`SearchPlan`: the query, the control masks and
each step's index into them, the exclusions and the search configuration (its
initial pose resolved). :meth:`SearchIndex.search_plans
<gesturekit.search.index.SearchIndex.search_plans>` searches plans; the synthesis
keeps each plan in its result, and the baselines and the step explanations read
the same plan, so what they show is what the search was given.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from .._arguments import checks_arguments
from ..control import ControlTrack, step_masks
from ..errors import ConfigError
from .checks import check_segment
from .types import SearchConfig

if TYPE_CHECKING:  # the database sits below the search; only its type is named here
    from ..database import MatchingDatabase

__all__ = [
    "SearchRequest",
    "SearchPlan",
    "PlanBatch",
    "plan_search",
    "stack_plans",
    "rest_pose_frame",
    "resolved_search_config",
    "exclusions",
]


@dataclass(frozen=True)
class SearchRequest:
    """What a search is asked for, besides the speech: what :func:`plan_search` needs.

    Attributes
    ----------
    search : SearchConfig
        k, N, recorded candidates, seed, mask rule and pins; its ``init_pose`` is
        ``"random"`` (the initial pose is chosen by ``init``).
    init : {"random", "rest"}
        ``random``: a random database frame that satisfies the first step's control;
        ``rest``: the database's rest pose (:func:`rest_pose_frame`).
    control : ControlTrack
        The control track (seconds of the output); empty: no control.
    exclude_takes : tuple of str
        Database takes no window may use.
    exclude_ranges : tuple of (str, float, float)
        (take, start_s, end_s) stretches no window may use.
    """

    search: SearchConfig = field(default_factory=SearchConfig)
    init: str = "random"
    control: ControlTrack = field(default_factory=ControlTrack)
    exclude_takes: tuple[str, ...] = ()
    exclude_ranges: tuple[tuple[str, float, float], ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.search, SearchConfig):
            raise ConfigError(f"search must be a SearchConfig, got {type(self.search).__name__}")
        if self.init not in ("random", "rest"):
            raise ConfigError(f"init must be 'random' or 'rest', got {self.init!r}")
        if not isinstance(self.control, ControlTrack):
            raise ConfigError(f"control must be a ControlTrack, got {type(self.control).__name__}")


@dataclass(frozen=True, eq=False)
class SearchPlan:
    """The inputs of one speech's search.

    Attributes
    ----------
    query : np.ndarray, shape (T_out, 112), float32
        z-scored audio features of the speech, one row per output frame (15 fps).
    config : SearchConfig
        The search's options; ``init_pose`` is the rest pose's feature when the
        request asked for it (``init="rest"``), else ``"random"``.
    control : ControlTrack
        The control track the masks were made from (seconds of the output).
    masks : np.ndarray, shape (n_masks, M, T), bool, or None
        One mask of admitted database frames per distinct constraint set; None without controls.
    step_mask_index : np.ndarray, shape (n_steps,), int64
        Per step, the index into ``masks`` (-1: the step is unconstrained).
    exclude : np.ndarray, shape (M, T), bool, or None
        Database frames no window may contain (held-out takes and ranges).
    """

    query: np.ndarray
    config: SearchConfig
    control: ControlTrack
    masks: np.ndarray | None
    step_mask_index: np.ndarray
    exclude: np.ndarray | None

    @property
    def n_frames(self) -> int:
        """Output frames, ``T_out``."""
        return int(self.query.shape[0])

    @property
    def segment(self) -> int:
        """Frames per search step, N."""
        return self.config.segment

    @property
    def n_steps(self) -> int:
        """Search steps: ``ceil(T_out / N)``."""
        return int(self.step_mask_index.shape[0])

    def step_first_frame(self, step: int) -> int:
        """The first output frame of step ``step``: ``step * N``."""
        return self.check_step(step) * self.segment

    def mask_at(self, step: int) -> np.ndarray | None:
        """The control mask of step ``step``, shape (M, T) bool, or None when it is unconstrained."""
        j = int(self.step_mask_index[self.check_step(step)])
        return None if self.masks is None or j < 0 else self.masks[j]

    def check_step(self, step: int) -> int:
        """``step`` as an int, refused unless ``0 <= step < n_steps``."""
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or not 0 <= step < self.n_steps:
            raise ConfigError(f"step must be in 0..{self.n_steps - 1}, got {step!r}")
        return int(step)


@checks_arguments
def rest_pose_frame(db: MatchingDatabase) -> tuple[int, int]:
    """The database frame used as the rest pose: hands lowest among the slowest frames.

    Among valid frames whose mean hand speed is below its low threshold, the one
    with the lowest sum of wrist heights (ties: first in clip order).

    Returns
    -------
    (clip, frame)
    """
    speed = np.asarray(db.attribute("hand_speed"))
    height = np.asarray(db.attribute("left_hand_height")) + np.asarray(db.attribute("right_hand_height"))
    ok = np.asarray(db.valid) & (speed <= db.thresholds["hand_speed"][0])
    if not ok.any():
        ok = np.asarray(db.valid)
    score = np.where(ok, height, np.inf)
    clip, frame = np.unravel_index(int(np.argmin(score)), score.shape)
    return int(clip), int(frame)


@checks_arguments
def plan_search(db: MatchingDatabase, query: np.ndarray, request: SearchRequest) -> SearchPlan:
    """Everything the search of one speech needs, computed once.

    Parameters
    ----------
    db : MatchingDatabase
        The database to search.
    query : np.ndarray, shape (T_out, 112), float32
        The speech's audio features z-scored with ``db``'s statistics, one row per output
        frame at 15 fps (:meth:`gesturekit.synthesis.synthesizer.Synthesizer.features` computes them).
    request : SearchRequest
        The search's options, initial pose, control track and exclusions.

    Returns
    -------
    SearchPlan

    Raises
    ------
    ConfigError
        A query that is not (T_out, 112) features, N longer than a database clip, or
        exclusions naming takes the database lacks.
    """
    if not isinstance(request, SearchRequest):
        raise ConfigError(f"request must be a SearchRequest, got {type(request).__name__}")
    query = np.asarray(query)
    width = np.shape(db.F)[-1]
    if query.ndim != 2 or query.shape[1] != width or query.shape[0] < 1:
        raise ConfigError(
            f"query must be the speech's features, shape (frames, {width}), got {query.shape} "
            "(speech samples are turned into them by Synthesizer.features)"
        )
    n = int(query.shape[0])
    search = request.search
    check_segment(search.segment, np.shape(db.valid)[1])
    masks, index = step_masks(
        request.control, np.asarray(db.attributes), db.thresholds, n_frames=n, segment=search.segment
    )
    return SearchPlan(
        query=np.ascontiguousarray(query, dtype=np.float32),
        config=resolved_search_config(db, request),
        control=request.control,
        masks=masks,
        step_mask_index=np.asarray(index, dtype=np.int64),
        exclude=exclusions(db, request),
    )


@checks_arguments
def resolved_search_config(db: MatchingDatabase, request: SearchRequest) -> SearchConfig:
    """The request's search options with its initial pose resolved: the rest pose's
    feature (:func:`rest_pose_frame`) when ``request.init`` is ``"rest"``."""
    if request.init == "rest":
        return replace(request.search, init_pose=tuple(float(x) for x in db.P[rest_pose_frame(db)]))
    return request.search


@checks_arguments
def exclusions(db: MatchingDatabase, request: SearchRequest) -> np.ndarray | None:
    """Database frames no window may contain, shape (M, T) bool, or None when nothing is excluded."""
    if request.exclude_takes or request.exclude_ranges:
        return db.exclusion_mask(takes=request.exclude_takes, ranges=request.exclude_ranges)
    return None


@dataclass(frozen=True, eq=False)
class PlanBatch:
    """Several plans as one batched search takes them (:func:`stack_plans`).

    Attributes
    ----------
    queries : list of np.ndarray, each shape (T_out_b, 112), float32
    configs : list of SearchConfig
    masks : np.ndarray, shape (n_masks, M, T), bool, or None
        Every plan's masks, one stack.
    step_mask_indices : list of np.ndarray, each shape (n_steps_b,), int64
        Per plan, each step's index into ``masks`` (-1: unconstrained).
    exclude : np.ndarray, shape (M, T), bool, or None
        The plans' common exclusions.
    """

    queries: list[np.ndarray]
    configs: list[SearchConfig]
    masks: np.ndarray | None
    step_mask_indices: list[np.ndarray]
    exclude: np.ndarray | None


@checks_arguments
def stack_plans(plans: Sequence[SearchPlan]) -> PlanBatch:
    """The plans' inputs as one batch: their masks in one stack, each step's index moved along.

    Raises
    ------
    ConfigError
        Plans that exclude different database frames (a batch shares its exclusions).
    """
    plans = list(plans)
    if not all(isinstance(plan, SearchPlan) for plan in plans):
        raise ConfigError("plans must be SearchPlans (made by plan_search)")
    exclude = plans[0].exclude if plans else None
    for plan in plans[1:]:
        same = (
            plan.exclude is exclude
            if plan.exclude is None or exclude is None
            else np.array_equal(plan.exclude, exclude)
        )
        if not same:
            raise ConfigError("all plans of one batch must exclude the same database frames")
    stack: list[np.ndarray] = []
    indices: list[np.ndarray] = []
    for plan in plans:
        index = plan.step_mask_index.copy()
        if plan.masks is not None:
            index[index >= 0] += len(stack)
            stack.extend(list(plan.masks))
        indices.append(index)
    return PlanBatch(
        queries=[plan.query for plan in plans],
        configs=[plan.config for plan in plans],
        masks=np.stack(stack) if stack else None,
        step_mask_indices=indices,
        exclude=exclude,
    )
