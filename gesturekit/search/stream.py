"""The fast exact search one step at a time, for a query that grows: :class:`StepSearch`.

:meth:`SearchIndex.search_batch <gesturekit.search.index.SearchIndex.search_batch>` needs
the whole query before its first step. A live synthesis learns the query as the speech
arrives; :class:`StepSearch` takes each step's audio feature and control when they are
known and decides that step with the same scan and the same exact decisions, so a
search made step by step equals the search of the whole query, decision for decision.
The past is never searched again: each step scans the database once, from the previous
step's pose.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from ..errors import ConfigError, warn
from .admissible import draw_initial_frame
from .checks import check_segment
from .exact import MAX_ABS
from .index import SearchIndex
from .threads import single_threaded_blas
from .types import SearchConfig, SearchResult, describe_steps

__all__ = ["StepSearch"]


class StepSearch:
    """Algorithm 1 step by step over a :class:`SearchIndex`.

    Parameters
    ----------
    index : SearchIndex
        The database, prepared for search.
    config : SearchConfig
        k, N, recorded candidates, seed, mask rule and initial pose. Pins are refused:
        a step's pin could name a step the speech never reaches.
    exclude : np.ndarray, shape (M, T), bool, optional
        Database frames no window may contain.

    Notes
    -----
    Control masks are added with :meth:`add_mask` as new constraint sets appear; a step
    names its mask by the index :meth:`add_mask` returned (-1: unconstrained).
    """

    def __init__(self, index: SearchIndex, config: SearchConfig, *, exclude: np.ndarray | None = None) -> None:
        if not isinstance(config, SearchConfig):
            raise ConfigError(f"config must be a SearchConfig, got {type(config).__name__}")
        if config.pins:
            raise ConfigError("pins are not taken by a search made step by step (the speech's length is not known)")
        M, T, D, _ = index.shape
        check_segment(config.segment, T)
        if exclude is not None:
            exclude = np.ascontiguousarray(exclude)
            if exclude.shape != (M, T) or exclude.dtype != bool:
                raise ConfigError(
                    f"exclude must be a bool array of shape ({M}, {T}), got {exclude.dtype} {exclude.shape}"
                )
        if not isinstance(config.init_pose, str) and len(config.init_pose) != D:
            raise ConfigError(f"initial pose must have {D} values, got {len(config.init_pose)}")
        self.index = index
        self.config = config
        self.exclude = exclude
        self.masks: list[np.ndarray] = []
        self._cache: dict = {}
        self._pose = np.empty((1, D), np.float32)
        self._res: SearchResult | None = None
        self._steps = 0
        self._frames = 0
        self._pool: ThreadPoolExecutor | None = None

    @property
    def n_steps(self) -> int:
        """Steps decided so far."""
        return self._steps

    @property
    def n_frames(self) -> int:
        """Output frames covered by the steps decided so far."""
        return self._frames

    def add_mask(self, mask: np.ndarray) -> int:
        """Add a control mask, shape (M, T) bool (admitted database frames); returns its index."""
        mask = np.ascontiguousarray(mask)
        if mask.shape != self.index.shape[:2] or mask.dtype != bool:
            raise ConfigError(f"a control mask must be a bool array of shape {self.index.shape[:2]}, got {mask.shape}")
        self.masks.append(mask)
        return len(self.masks) - 1

    def _key(self, j: int) -> tuple[np.ndarray, tuple]:
        cfg = self.config
        return self.index._admissible(self._cache, cfg.segment, cfg.mask_rule, j, self.masks, self.exclude)

    def _start(self, j: int) -> None:
        """Draw the initial pose under the first step's control ``j`` and make room for the record."""
        cfg = self.config
        if cfg.init_pose == "random":
            adm, _ = self._key(j)
            if not adm.any():
                adm, _ = self._key(-1)
            init_frame = draw_initial_frame(adm, cfg.seed)
            init_pose = self.index.P[init_frame]
        else:
            init_frame = (-1, -1)
            init_pose = np.asarray(cfg.init_pose, dtype=np.float32)
        self._pose[0] = init_pose
        self._res = SearchResult.empty(
            64, 64 * cfg.segment, cfg.table_width, config=cfg, init_pose=init_pose, init_frame=init_frame
        )

    def _room(self) -> SearchResult:
        """The record, grown (doubled) when the next step would not fit."""
        res = self._res
        assert res is not None
        if self._steps < res.n_steps:
            return res
        cfg = self.config
        bigger = SearchResult.empty(
            2 * res.n_steps,
            2 * res.n_steps * cfg.segment,
            cfg.table_width,
            config=cfg,
            init_pose=res.init_pose,
            init_frame=res.init_frame,
        )
        for name, value in res.array_fields().items():
            if name not in ("init_pose", "init_frame"):
                getattr(bigger, name)[: len(value)] = value
        self._res = bigger
        return bigger

    def step(self, query_row: np.ndarray, mask: int, n_frames: int) -> tuple[int, int]:
        """Decide the next step.

        Parameters
        ----------
        query_row : np.ndarray, shape (A,), float32
            The z-scored audio feature of the step's first output frame.
        mask : int
            Index of the step's control mask (:meth:`add_mask`), -1 for none.
        n_frames : int
            Output frames the step covers: N, or fewer for the last step.

        Returns
        -------
        (clip, start)
            The chosen window; its first ``n_frames`` frames are the step's output.
        """
        cfg = self.config
        row = np.ascontiguousarray(query_row, dtype=np.float32)
        if row.shape != (self.index.shape[3],) or not np.isfinite(row).all() or np.abs(row).max() > MAX_ABS:
            raise ConfigError(f"a step's audio feature must be {self.index.shape[3]} finite z-scored values")
        if not -1 <= mask < len(self.masks):
            raise ConfigError(f"mask must be -1 or an index below {len(self.masks)}, got {mask}")
        if not 1 <= n_frames <= cfg.segment:
            raise ConfigError(f"a step covers 1 to {cfg.segment} frames, got {n_frames}")
        if self._res is None:
            self._start(mask)
        if self._pool is None and self.index._workers > 1:
            self._pool = ThreadPoolExecutor(self.index._workers)
        res = self._room()
        i = self._steps
        adm, key = self._key(mask)
        asked = key  # kept in the cache even when relaxed: an empty mask is not rebuilt every step
        relaxed = False
        if key[2] >= 0 and not adm.any():  # the control admits no window at all
            relaxed = True
            adm, key = self._key(-1)
        queries = ({0: row}, {0: cfg.table_width})
        with single_threaded_blas():  # the scan's threads each run a product of their own
            decided = self.index._step([0], {0: key}, self._pose, queries, self._cache, self._pool)
            if decided[0] is None and key[2] >= 0:  # only the query's own frame was admissible under the control
                relaxed = True
                key = self._key(-1)[1]
                decided = self.index._step([0], {0: key}, self._pose, queries, self._cache, self._pool)
        # drop cached masks this step did not use (the scan's buffer is kept under a name)
        used = {asked, key, (key[0], "-", -1)}
        for stale in [k for k in self._cache if isinstance(k, tuple) and k not in used]:
            del self._cache[stale]
        res.relaxed[i] = relaxed
        self.index._record(res, self._frames + n_frames, i, decided[0], self._pose, 0)
        self._steps += 1
        self._frames += n_frames
        return int(res.clip[i]), int(res.start[i])

    def result(self, *, fps: float | None = None) -> SearchResult:
        """The steps decided so far as a :class:`SearchResult` (what the search of the whole
        query returns); warns of relaxed controls as that search does."""
        if self._res is None:
            raise ConfigError("no step has been searched yet")
        res, n, t = self._res, self._steps, self._frames
        fields = {
            name: value[:n].copy()
            for name, value in res.array_fields().items()
            if name not in ("init_pose", "init_frame")
        }
        fields["frames"] = res.frames[:t].copy()
        out = replace(res, **fields)
        if out.relaxed.any():
            where = describe_steps(np.flatnonzero(out.relaxed), segment=self.config.segment, fps=fps)
            warn(f"control relaxed at {where}: no database window satisfies it", stacklevel=3)
        return out

    def close(self) -> None:
        """Stop the search's threads (a later step starts them again)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
