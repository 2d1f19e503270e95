"""Training pairs of the refiner: k-NN motion for each window of the overlapping cut.

For every 64-frame window of the database's overlapping cut (``db.overlap``)
the k-NN search (Algorithm 1) runs over the matching database with the
window's own audio features as the query, as in the authors' code:

* the initial pose is the window's own first pose feature, so the search's
  distance-0 rule skips the window's own frame; in addition every frame of the
  window itself is kept out of that window's search (a per-window mask), so the
  k-NN motion never copies the ground truth it is paired with;
* ``k`` is 1 for half of the windows and uniform in 2..15 for the others
  (seeded), fixed for the whole window;
* the "real" example is the ground-truth window (its motion and its audio).

All windows are searched together with the batched search
(:meth:`gesturekit.search.SearchIndex.search_batch`), one scan of the database
per step for a whole chunk of windows; each window's own frames are excluded
through its own mask. Windows touching held-out takes or time ranges are not
used, and the search never uses held-out frames either.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from .._arguments import checks_arguments
from .._config import JsonConfig
from ..database import MatchingDatabase, normalise_exclusions
from ..errors import ConfigError, DatabaseError, collect_warnings
from ..search import SearchConfig, SearchIndex

__all__ = ["PairsConfig", "TrainingPairs", "make_training_pairs", "training_windows"]

#: Bytes of per-window masks and distance biases allowed per chunk of searched windows.
_CHUNK_BYTES = 96 << 20


@dataclass(frozen=True)
class PairsConfig(JsonConfig):
    """How training pairs are made; saved in a refiner's ``config.json``.

    Parameters
    ----------
    seed : int
        Seed of the per-window draw of ``k``.
    segment : int
        Frames per search step, N (8 in the paper). (Refiners saved by earlier
        versions call it ``step``; :meth:`from_dict` reads both.)
    k_one_fraction : float
        Fraction of windows searched with k = 1 (the authors: one half).
    k_max : int
        The other windows draw k uniformly from 2..k_max (the authors: 15).
    exclude_takes : tuple of str
        Database takes kept out of training (neither a training window nor used by the search).
    exclude_ranges : tuple of (str, float, float)
        (take, start_s, end_s) stretches kept out likewise.
    """

    OPTIONS_NAME = "training-data options"

    seed: int = 0
    segment: int = 8
    k_one_fraction: float = 0.5
    k_max: int = 15
    exclude_takes: tuple = ()
    exclude_ranges: tuple = ()

    def __post_init__(self):
        if not 0.0 <= self.k_one_fraction <= 1.0:
            raise ConfigError(f"k_one_fraction must be in [0, 1], got {self.k_one_fraction}")
        if self.k_max < 2:
            raise ConfigError(f"k_max must be at least 2, got {self.k_max}")
        if self.segment < 1:
            raise ConfigError(f"segment must be at least 1, got {self.segment}")
        takes, ranges = normalise_exclusions(self.exclude_takes, self.exclude_ranges)
        object.__setattr__(self, "exclude_takes", takes)
        object.__setattr__(self, "exclude_ranges", ranges)

    @classmethod
    def from_dict(cls, d: Mapping) -> PairsConfig:
        """Inverse of :meth:`to_dict` (also of earlier versions' ``step``); unknown options raise
        :class:`~gesturekit.errors.ConfigError`."""
        if isinstance(d, Mapping) and "step" in d and "segment" not in d:
            d = {("segment" if name == "step" else name): value for name, value in d.items()}
        return super().from_dict(d)


@dataclass
class TrainingPairs:
    """Inputs and targets of the refiner, one row per training window (W windows of 64 frames).

    Attributes
    ----------
    audio : np.ndarray, shape (W, 64, 28), float32
        cGAN audio features of the window (raw, not z-scored).
    knn : np.ndarray, shape (W, 64, 165), float32, metres
        The k-NN motion found for the window's audio (the generator's motion input).
    real : np.ndarray, shape (W, 64, 165), float32, metres
        The window's ground-truth motion.
    window : np.ndarray, shape (W,), int64
        Index of the window in the overlapping cut.
    k : np.ndarray, shape (W,), int64
        The k of each window's search.
    frames : np.ndarray, shape (W, 64, 2), int64
        (clip, frame) of the database frame behind each k-NN frame.
    dropped : int
        Windows left out because the search had to relax their own-frame exclusion.
    """

    audio: np.ndarray
    knn: np.ndarray
    real: np.ndarray
    window: np.ndarray
    k: np.ndarray
    frames: np.ndarray
    dropped: int = 0

    def __len__(self) -> int:
        return int(self.window.shape[0])


@checks_arguments
def training_windows(db: MatchingDatabase, config: PairsConfig = PairsConfig()) -> np.ndarray:
    """Indices of the overlapping-cut windows used for training (none touches held-out frames).

    Returns
    -------
    np.ndarray, shape (W,), int64
    """
    ov = _overlap(db)
    names = db.take_names
    for name in config.exclude_takes:
        db._take(name)  # raises ConfigError naming the known takes
    for name, a, b in config.exclude_ranges:
        db._take(name)
        if not b > a:
            raise ConfigError(f"held-out range {a}-{b} s of {name!r}: end must be after start")
    ti = np.asarray(ov["clip_take"], dtype=np.int64)
    st = np.asarray(ov["clip_start"], dtype=np.int64)
    T = ov["G"].shape[1]
    keep = np.ones(ti.shape[0], dtype=bool)
    for name in config.exclude_takes:
        keep &= ti != names.index(name)
    fps = db.fps
    for name, a, b in config.exclude_ranges:
        # frame t is held out when a <= t / fps < b (as MatchingDatabase.exclusion_mask)
        first = np.ceil(a * fps - 1e-9)
        last = np.ceil(b * fps - 1e-9) - 1
        hit = (ti == names.index(name)) & (st <= last) & (st + T - 1 >= first)
        keep &= ~hit
    return np.flatnonzero(keep).astype(np.int64)


def _overlap(db: MatchingDatabase) -> dict:
    if db.overlap is None:
        raise DatabaseError(
            "this database has no overlapping cut, which refiner training needs; rebuild it with "
            "`gesturekit build-db ... --overlap-stride 8 --force`",
            path=db.path,
        )
    if db.overlap["G"].shape[1] != db.clip_frames:
        raise DatabaseError("the overlapping cut's windows differ in length from the clips", path=db.path)
    return db.overlap


def draw_k(n: int, config: PairsConfig) -> np.ndarray:
    """Per window: k = 1 with probability ``k_one_fraction``, else uniform in 2..k_max (seeded).

    Returns
    -------
    np.ndarray, shape (n,), int64
    """
    rng = np.random.default_rng(config.seed)
    one = rng.random(n) < config.k_one_fraction
    other = rng.integers(2, config.k_max + 1, size=n)
    return np.where(one, 1, other).astype(np.int64)


@checks_arguments
def make_training_pairs(
    db: MatchingDatabase, *, config: PairsConfig = PairsConfig(), progress: Callable[[int, int], None] | None = None
) -> TrainingPairs:
    """Run the k-NN search for every training window of the overlapping cut.

    Parameters
    ----------
    db : MatchingDatabase
        Built with an overlapping cut (``overlap_stride``).
    config : PairsConfig
    progress : callable(done, total), optional
        Called after each chunk of windows with the number of windows searched.

    Returns
    -------
    TrainingPairs

    Raises
    ------
    DatabaseError
        The database has no overlapping cut.
    ConfigError
        Unknown held-out takes, or no training window left.
    """
    ov = _overlap(db)
    windows = training_windows(db, config)
    if windows.size == 0:
        raise ConfigError("no training window is left outside the held-out takes and ranges")
    k_all = draw_k(ov["G"].shape[0], config)  # drawn for every window: held-out ones do not shift the others
    index = SearchIndex(db.P, db.F, db.valid)
    M, T = db.valid.shape
    held = db.exclusion_mask(takes=config.exclude_takes, ranges=config.exclude_ranges)
    allowed = ~held
    clip_take = np.asarray(db.clip_take, dtype=np.int64)
    clip_frame = np.asarray(db.clip_start, dtype=np.int64)[:, None] + np.arange(T)[None, :]
    o_take = np.asarray(ov["clip_take"], dtype=np.int64)
    o_start = np.asarray(ov["clip_start"], dtype=np.int64)
    L = ov["G"].shape[1]
    P0 = np.asarray(ov["P"][:, 0], dtype=np.float32)

    chunk = int(max(8, min(512, _CHUNK_BYTES // (5 * M * T))))
    if progress is not None:
        progress(0, windows.size)
    frames_out = np.empty((windows.size, L, 2), np.int64)
    ok = np.ones(windows.size, dtype=bool)
    for c0 in range(0, windows.size, chunk):
        idx = windows[c0 : c0 + chunk]
        masks = np.empty((idx.size, M, T), dtype=bool)
        for j, w in enumerate(idx):
            own = (clip_take[:, None] == o_take[w]) & (clip_frame >= o_start[w]) & (clip_frame < o_start[w] + L)
            np.logical_and(allowed, ~own, out=masks[j])
        n_steps = -(-L // config.segment)
        configs = [
            SearchConfig(k=int(k_all[w]), segment=config.segment, record=1, init_pose=P0[w], mask_rule="all")
            for w in idx
        ]
        with collect_warnings():
            # a relaxed step could use the window's own frames: such windows are dropped below
            results = index.search_batch(
                [np.asarray(ov["F"][w]) for w in idx],
                configs=configs,
                masks=masks,
                step_mask_indices=[np.full(n_steps, j, np.int64) for j in range(idx.size)],
                exclude=held if held.any() else None,
            )
        for j, res in enumerate(results):
            frames_out[c0 + j] = res.frames
            ok[c0 + j] = not res.relaxed.any()
        if progress is not None:
            progress(min(c0 + chunk, windows.size), windows.size)

    windows, frames_out = windows[ok], frames_out[ok]
    if windows.size == 0:
        raise ConfigError("no training window has a k-NN motion outside its own frames")
    G = db.G
    knn = np.asarray(G[frames_out[..., 0], frames_out[..., 1]], dtype=np.float32)
    return TrainingPairs(
        audio=np.asarray(ov["A"][windows], dtype=np.float32),
        knn=knn,
        real=np.asarray(ov["G"][windows], dtype=np.float32),
        window=windows,
        k=k_all[windows],
        frames=frames_out,
        dropped=int((~ok).sum()),
    )
