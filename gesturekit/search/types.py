"""What a search takes and gives: :class:`SearchConfig`, :class:`SearchResult`, step descriptions.

Both are plain data: the configuration is validated when it is made and saved
with every result (:meth:`SearchConfig.to_dict`); the result holds the chosen
window of every step and the table of its best candidates.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arguments import checks_arguments
from .._config import config_from_dict, config_to_dict, option, option_of
from ..errors import ConfigError

if TYPE_CHECKING:  # imported where the candidate table is made
    import pandas as pd

    from ..database import MatchingDatabase

__all__ = ["SearchConfig", "SearchResult", "CANDIDATE_FIELDS", "describe_steps", "window_source"]


@dataclass(frozen=True)
class SearchConfig:
    """Options of one search; JSON-able through :meth:`to_dict`, saved with every result.

    Parameters
    ----------
    k : int
        Which candidate of the combined ranking to take (0 = best).
    segment : int
        Frames per search step, ``N`` (8 in the authors' code): the length of the
        database segment each step copies. (Saved configurations of earlier
        versions call it ``step``; :meth:`from_dict` reads both.)
    record : int
        Candidates per step kept in the record (at least ``k + 1`` are kept).
        (Earlier versions' ``topk``; :meth:`from_dict` reads both.)
    seed : int
        Seed of the random initial pose.
    init_pose : "random" or sequence of float
        ``p_{-1}``. ``"random"``: the pose feature of a random admissible database
        frame satisfying step 0's control (seeded). Otherwise an explicit z-scored
        pose feature (D values, e.g. a rest pose), stored rounded to float32.
        (Saved configurations of earlier versions call it ``init``; :meth:`from_dict`
        reads both.)
    mask_rule : {"ends", "all"}
        Where a control mask must hold in a window: at its first and last
        frame (the authors' code) or on every frame (ours).
    pins : dict of int -> (int, int)
        Step -> (clip, start): forces the choice at that step; later steps
        continue from the pinned segment.

    Examples
    --------
    >>> from gesturekit.search import SearchConfig
    >>> config = SearchConfig(k=1, segment=8, mask_rule="all")
    >>> config.to_dict()
    {'k': 1, 'segment': 8, 'record': 10, 'seed': 0, 'init_pose': 'random', 'mask_rule': 'all', 'pins': {}}
    >>> SearchConfig.from_dict(config.to_dict()) == config
    True
    """

    k: int = option(0, help="take the k-th best candidate of each step", low=0)
    segment: int = option(
        8,
        help="frames per search step, N",
        low=1,
        unit="frames",
        aliases=("--step",),
        limit=lambda db: db.clip_frames,  # a step copies a window of one clip
    )
    record: int = option(10, help="candidates per step to record", low=1, aliases=("--topk",))
    seed: int = option(0, help="seed of the random initial pose", low=0)
    init_pose: str | tuple[float, ...] = "random"
    mask_rule: str = option(
        "ends",
        help="a control must hold at a window's first and last frame (ends: the paper) or every frame",
        choices=("ends", "all"),
    )
    pins: dict = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        for name in ("k", "segment", "record", "seed"):
            value, low = getattr(self, name), option_of(SearchConfig, name).low
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
                raise ConfigError(f"SearchConfig.{name} must be an integer >= {low}, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.mask_rule not in (option_of(SearchConfig, "mask_rule").choices or ()):
            raise ConfigError(f"SearchConfig.mask_rule must be 'ends' or 'all', got {self.mask_rule!r}")
        init = self.init_pose
        if isinstance(init, str):
            if init != "random":
                raise ConfigError(f"SearchConfig.init_pose must be 'random' or a pose feature vector, got {init!r}")
        else:
            try:
                arr = np.asarray(init, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"SearchConfig.init_pose must be 'random' or a pose feature vector: {exc}") from None
            if arr.ndim != 1 or arr.size == 0 or not np.all(np.isfinite(arr)):
                raise ConfigError(
                    f"SearchConfig.init_pose must be a finite 1-D pose feature vector, got shape {arr.shape}"
                )
            object.__setattr__(self, "init_pose", tuple(float(x) for x in arr.astype(np.float32)))
        if not isinstance(self.pins, Mapping):
            raise ConfigError(f"SearchConfig.pins must map step -> (clip, start), got {type(self.pins).__name__}")
        pins = {}
        for key, value in self.pins.items():
            try:
                step_i = int(key)
                clip, start = (int(x) for x in value)
            except (TypeError, ValueError):
                raise ConfigError(
                    f"SearchConfig.pins: expected step -> (clip, start), got {key!r}: {value!r}"
                ) from None
            if step_i < 0 or clip < 0 or start < 0:
                raise ConfigError(f"SearchConfig.pins: negative index in {key!r}: {value!r}")
            pins[step_i] = (clip, start)
        object.__setattr__(self, "pins", dict(sorted(pins.items())))

    def to_dict(self) -> dict:
        """A JSON-able dict (pin steps become strings) that :meth:`from_dict` reads back."""
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> SearchConfig:
        """Inverse of :meth:`to_dict` (also of earlier versions' ``init``, ``step`` and ``topk``);
        unknown keys raise :class:`ConfigError`."""
        if not isinstance(d, Mapping):
            raise ConfigError(f"SearchConfig keys must be a JSON object, got {type(d).__name__}")
        return config_from_dict(cls, renamed_search_keys(d), what="SearchConfig keys")

    @property
    def table_width(self) -> int:
        """Candidates recorded per step: ``max(record, k + 1)``, so the chosen one is always among them."""
        return max(self.record, self.k + 1)


#: Search options saved under other names by earlier versions: old key -> current field.
RENAMED_SEARCH_KEYS = {"init": "init_pose", "step": "segment", "topk": "record"}


def renamed_search_keys(d: Mapping[str, Any]) -> dict[str, Any]:
    """``d`` with the search options earlier versions saved under other names renamed
    (:data:`RENAMED_SEARCH_KEYS`); a current name given beside its old one wins."""
    out = dict(d)
    for old, new in RENAMED_SEARCH_KEYS.items():
        if old in out and new not in out:
            out[new] = out.pop(old)
    return out


CANDIDATE_FIELDS = (
    "cand_clip",
    "cand_start",
    "cand_pose_dist",
    "cand_audio_dist",
    "cand_pose_rank",
    "cand_audio_rank",
    "cand_combined",
)


@dataclass(eq=False)
class SearchResult:
    """The outcome of one search, with a record of every step's best candidates.

    Steps are indexed ``i = 0 .. n_steps - 1``; step ``i`` covers output frames
    ``[i N, min((i + 1) N, T_out))``. The candidate table of a step lists the
    surviving clips in combined-rank order (position 0 = best), ``K =
    config.table_width`` columns, padded with -1 (integers) and NaN (distances)
    when fewer clips survived.

    Attributes
    ----------
    clip, start : np.ndarray, shape (n_steps,), int64
        The chosen window of each step (database clip and start frame).
    frames : np.ndarray, shape (T_out, 2), int64
        ``(clip, frame)`` of the database frame used for each output frame.
    relaxed : np.ndarray, shape (n_steps,), bool
        The step's control admitted no window and was dropped for that step.
    short : np.ndarray, shape (n_steps,), bool
        Fewer than ``k + 1`` clips survived; the last one was taken.
    pinned : np.ndarray, shape (n_steps,), bool
        The choice was forced by ``config.pins``.
    position : np.ndarray, shape (n_steps,), int64
        Column of the chosen window in the candidate table (-1: a pin not in the table).
    n_candidates : np.ndarray, shape (n_steps,), int64
        Clips that survived the step.
    cand_clip, cand_start : np.ndarray, shape (n_steps, K), int64
    cand_pose_dist : np.ndarray, shape (n_steps, K), float64
        Euclidean distance between the candidate's pose feature and ``p_{t-1}`` (z-scored units).
    cand_audio_dist : np.ndarray, shape (n_steps, K), float64
        Cosine distance between the candidate's audio feature and ``f_t``, in [0, 2].
    cand_pose_rank, cand_audio_rank, cand_combined : np.ndarray, shape (n_steps, K), int64
        Ordinal ranks (0 = best) among the surviving clips, and their sum.
    init_pose : np.ndarray, shape (D,), float32
        ``p_{-1}``.
    init_frame : tuple of int
        ``(clip, frame)`` the random initial pose was taken from, ``(-1, -1)`` if given.
    config : SearchConfig
    """

    clip: np.ndarray
    start: np.ndarray
    frames: np.ndarray
    relaxed: np.ndarray
    short: np.ndarray
    pinned: np.ndarray
    position: np.ndarray
    n_candidates: np.ndarray
    cand_clip: np.ndarray
    cand_start: np.ndarray
    cand_pose_dist: np.ndarray
    cand_audio_dist: np.ndarray
    cand_pose_rank: np.ndarray
    cand_audio_rank: np.ndarray
    cand_combined: np.ndarray
    init_pose: np.ndarray
    init_frame: tuple[int, int]
    config: SearchConfig

    @classmethod
    def empty(
        cls,
        n_steps: int,
        n_frames: int,
        width: int,
        *,
        config: SearchConfig,
        init_pose: np.ndarray | Sequence[float],
        init_frame: tuple[int, int] | Sequence[int],
    ) -> SearchResult:
        """A result to fill in: every table entry padded, every flag False."""

        def ints(*shape: int) -> np.ndarray:
            return np.full(shape, -1, dtype=np.int64)

        def floats(*shape: int) -> np.ndarray:
            return np.full(shape, np.nan, dtype=np.float64)

        return cls(
            clip=ints(n_steps),
            start=ints(n_steps),
            frames=ints(n_frames, 2),
            relaxed=np.zeros(n_steps, bool),
            short=np.zeros(n_steps, bool),
            pinned=np.zeros(n_steps, bool),
            position=ints(n_steps),
            n_candidates=np.zeros(n_steps, np.int64),
            cand_clip=ints(n_steps, width),
            cand_start=ints(n_steps, width),
            cand_pose_dist=floats(n_steps, width),
            cand_audio_dist=floats(n_steps, width),
            cand_pose_rank=ints(n_steps, width),
            cand_audio_rank=ints(n_steps, width),
            cand_combined=ints(n_steps, width),
            init_pose=np.asarray(init_pose, dtype=np.float32).copy(),
            init_frame=(int(init_frame[0]), int(init_frame[1])),
            config=config,
        )

    @property
    def n_steps(self) -> int:
        """Search steps taken."""
        return int(self.clip.shape[0])

    def array_fields(self) -> dict[str, np.ndarray]:
        """Every array of the result by name (for saving with ``np.savez``; the config goes as JSON)."""
        names = ("clip", "start", "frames", "relaxed", "short", "pinned", "position", "n_candidates")
        out = {n: getattr(self, n) for n in names + CANDIDATE_FIELDS}
        out["init_pose"] = self.init_pose
        out["init_frame"] = np.asarray(self.init_frame, dtype=np.int64)
        return out

    def equals(self, other: SearchResult) -> bool:
        """Whether two results are identical (arrays bit for bit, NaN equal to NaN, same config)."""
        if self.config != other.config:
            return False
        a, b = self.array_fields(), other.array_fields()
        return all(a[n].shape == b[n].shape and np.array_equal(a[n], b[n], equal_nan=a[n].dtype.kind == "f") for n in a)

    def candidates_frame(self) -> pd.DataFrame:
        """The candidate record as a pandas DataFrame, one row per (step, position).

        Columns: ``step, position, clip, start, pose_dist, audio_dist, pose_rank,
        audio_rank, combined, chosen``; padding entries are left out.
        """
        import pandas as pd  # kept local: the search itself does not need pandas

        n_steps, width = self.cand_clip.shape
        steps = np.repeat(np.arange(n_steps), width)
        pos = np.tile(np.arange(width), n_steps)
        keep = self.cand_clip.ravel() >= 0
        chosen = pos == np.repeat(self.position, width)
        df = pd.DataFrame(
            {
                "step": steps,
                "position": pos,
                "clip": self.cand_clip.ravel(),
                "start": self.cand_start.ravel(),
                "pose_dist": self.cand_pose_dist.ravel(),
                "audio_dist": self.cand_audio_dist.ravel(),
                "pose_rank": self.cand_pose_rank.ravel(),
                "audio_rank": self.cand_audio_rank.ravel(),
                "combined": self.cand_combined.ravel(),
                "chosen": chosen,
            }
        )
        return df[keep].reset_index(drop=True)

    def chosen_distances(self) -> tuple[float, float]:
        """Mean pose and audio distance of the chosen windows over the steps.

        Returns
        -------
        (pose_dist, audio_dist) : tuple of float
            Means of ``cand_pose_dist`` (z-scored units) and ``cand_audio_dist`` (cosine, 0..2)
            at each step's chosen ``position``; steps whose choice is outside the record (a pin)
            are left out; NaN when no step is left.
        """
        idx = np.flatnonzero(self.position >= 0)
        if not idx.size:
            return float("nan"), float("nan")
        at = self.position[idx]
        return float(np.mean(self.cand_pose_dist[idx, at])), float(np.mean(self.cand_audio_dist[idx, at]))

    def candidates_table(self, step: int, db: MatchingDatabase) -> pd.DataFrame:
        """The recorded candidates of one step, best first, with their source take and time.

        Parameters
        ----------
        step : int
            ``0 <= step < n_steps``.
        db : MatchingDatabase
            The database the result was searched in.

        Returns
        -------
        pandas.DataFrame
            One row per recorded candidate (at most ``config.record``, at least
            ``k + 1``): ``position`` (in the combined ranking, 0 = best),
            ``clip``, ``start`` (frame in the clip), ``take``, ``source_s``
            (seconds into the take), ``pose_dist`` (z-scored units),
            ``audio_dist`` (cosine, 0..2), ``pose_rank``, ``audio_rank``,
            ``combined`` (their sum) and ``chosen``.

        Raises
        ------
        ConfigError
            A step out of range.
        """
        import pandas as pd

        if not 0 <= int(step) < self.n_steps:
            raise ConfigError(f"step must be in 0..{self.n_steps - 1}, got {step}")
        table = self.candidates_frame()
        table = table[table["step"] == int(step)].drop(columns="step").reset_index(drop=True)
        src = [window_source(db, c, s) for c, s in zip(table["clip"], table["start"])]
        table.insert(3, "take", pd.Series([t for t, _ in src], dtype="object"))
        table.insert(4, "source_s", pd.Series([t for _, t in src], dtype="float64"))
        return table


@checks_arguments
def window_source(db: MatchingDatabase, clip: int, start: int) -> tuple[str, float]:
    """Where a database window comes from: its take's name and the time of ``start`` in the take.

    Parameters
    ----------
    db : MatchingDatabase
    clip, start : int
        The window's clip and its first frame in the clip.

    Returns
    -------
    (take, seconds) : tuple of str and float
    """
    take = db.take_names[int(db.clip_take[int(clip)])]
    return take, (int(db.clip_start[int(clip)]) + int(start)) / db.fps


@checks_arguments
def describe_steps(steps: Iterable[int], *, segment: int, fps: float | None = None, most: int = 3) -> str:
    """Search steps said briefly: runs of consecutive steps joined, long lists cut short.

    Parameters
    ----------
    steps : iterable of int
        Step indices (step ``i`` covers output frames ``i * segment`` to ``(i + 1) * segment``).
    segment : int
        Frames per step (N).
    fps : float, optional
        Frame rate of the output; given, the runs are said in seconds.
    most : int
        Runs written out; further ones are counted.

    Returns
    -------
    str
        E.g. ``"0.53-4.80 s (8 steps)"`` with ``fps``, ``"steps 1-8"`` without.
    """
    indices = sorted({int(i) for i in steps})
    runs: list[list[int]] = []
    for i in indices:
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    if fps is None:
        parts = [f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:most]]
        head = "step " if len(indices) == 1 else "steps "
    else:
        parts = [f"{a * segment / fps:.2f}-{(b + 1) * segment / fps:.2f} s" for a, b in runs[:most]]
        head = ""
    if len(runs) > most:
        parts.append(f"and {len(runs) - most} more stretch{'es' if len(runs) - most > 1 else ''}")
    text = head + ", ".join(parts)
    if fps is not None:
        text += f" ({len(indices)} step{'s' if len(indices) != 1 else ''})"
    return text
