"""A search planned once: everything a synthesis searches with, built in one place.

:func:`plan_search` turns a database, the speech and a synthesis configuration into
a :class:`SearchPlan`: the query's audio features, the control masks and each
step's index into them, the exclusions, the search configuration (its initial
pose resolved) and the control track. The synthesis searches with it and keeps it
in its result; the baselines and the step explanations read the same plan, so
what they show is what the search was given.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..control import ControlTrack, step_masks
from ..errors import ConfigError
from ..features import n_audio_frames
from .checks import check_segment
from .types import SearchConfig

if TYPE_CHECKING:  # the synthesis sits above the search; only its type is named here
    from ..database import MatchingDatabase
    from ..synthesize import SynthesisConfig

__all__ = ["SearchPlan", "plan_search", "rest_pose_frame", "resolved_search_config", "exclusions"]


@dataclass(frozen=True, eq=False)
class SearchPlan:
    """The inputs of one speech's search.

    Attributes
    ----------
    query : np.ndarray, shape (T_out, 112), float32
        z-scored audio features of the speech, one row per output frame (15 fps).
    config : SearchConfig
        The search's options; ``init_pose`` is the rest pose's feature when the
        synthesis asked for it, else ``"random"``.
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


def plan_search(db: MatchingDatabase, speech: np.ndarray, config: SynthesisConfig) -> SearchPlan:
    """Everything the search of one speech needs, computed once.

    Parameters
    ----------
    db : MatchingDatabase
        The database to search.
    speech : np.ndarray, shape (samples,), float32
        Mono speech at 16 kHz; the output has ``floor(samples * 15 / 16000)`` frames.
    config : SynthesisConfig
        Its search options, initial pose (``"random"`` or ``"rest"``), control track and exclusions.

    Returns
    -------
    SearchPlan

    Raises
    ------
    ConfigError
        N longer than a database clip, or exclusions naming takes the database lacks.
    """
    samples = np.asarray(speech, dtype=np.float32)
    n = n_audio_frames(len(samples))
    search = config.search
    check_segment(search.segment, np.shape(db.valid)[1])
    query, _ = db.query_features(samples, n_frames=n)
    track = config.control_track
    masks, index = step_masks(track, np.asarray(db.attributes), db.thresholds, n_frames=n, segment=search.segment)
    return SearchPlan(
        query=np.ascontiguousarray(query, dtype=np.float32),
        config=resolved_search_config(db, config),
        control=track,
        masks=masks,
        step_mask_index=np.asarray(index, dtype=np.int64),
        exclude=exclusions(db, config),
    )


def resolved_search_config(db: MatchingDatabase, config: SynthesisConfig) -> SearchConfig:
    """The synthesis's search options with its initial pose resolved: the rest pose's
    feature (:func:`rest_pose_frame`) when ``config.init`` is ``"rest"``."""
    if config.init == "rest":
        return replace(config.search, init_pose=tuple(float(x) for x in db.P[rest_pose_frame(db)]))
    return config.search


def exclusions(db: MatchingDatabase, config: SynthesisConfig) -> np.ndarray | None:
    """Database frames no window may contain, shape (M, T) bool, or None when nothing is excluded."""
    if config.exclude_takes or config.exclude_ranges:
        return db.exclusion_mask(takes=config.exclude_takes, ranges=config.exclude_ranges)
    return None
