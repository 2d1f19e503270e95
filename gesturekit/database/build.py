"""Building a database: takes made into clips, combined into the database's arrays.

Both builds go through :func:`assemble`:

- :func:`build_in_memory` (:meth:`MatchingDatabase.build <gesturekit.database.MatchingDatabase.build>`)
  makes each take into its clips in memory (:func:`~gesturekit.database.clips.take_clips`) and
  assembles them into arrays in memory (:class:`MemoryOut`): the database's parts, which
  :meth:`~gesturekit.database.MatchingDatabase.save` writes as a folder;
- a build from files (:mod:`gesturekit.database.sources`) stages each take's clips on disk first
  (:mod:`gesturekit.database.stage`, a take at a time, in parallel, resumable) and assembles
  the staged takes straight into the output folder, file by file
  (:class:`~gesturekit.database.folder.FolderOut`), so that only a few takes and one attribute
  column (8 bytes a frame) are in memory at once.

:func:`assemble` combines the takes' moments in name order (Chan et al.'s pairwise update,
float64) into the z-scoring statistics (:func:`combine_moments`), writes each array take by
take, z-scoring F and P on the way, and the thresholds from per-column percentiles of the
attributes: the same numbers either way, so a database built in memory and saved is the folder
a build from files gives.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from .._arguments import checks_arguments
from .._version import __version__
from ..control import ATTRIBUTE_NAMES
from ..errors import ConfigError, DatabaseError, GestureKitError
from ..features import LAYOUT, ZScore
from ..skeleton import FPS, JOINT_NAMES
from .audio import AudioStorage
from .clips import MOMENT_KEYS, TakeClips, take_clips
from .config import BuildConfig
from .folder import CLIP_ARRAYS, FORMAT, FORMAT_VERSION, INDEX_ARRAYS

if TYPE_CHECKING:
    from types import TracebackType

    from ..bones import Skeleton
    from ..motion import Take

__all__ = [
    "TakeRows",
    "RowWriter",
    "ArrayOut",
    "MemoryOut",
    "combine_moments",
    "check_takes",
    "assemble",
    "build_in_memory",
]

_FLOOR = 1e-6  # the z-scoring std floor of ZScore.fit: constant dimensions map to 0


class TakeRows(Protocol):
    """One take's clips as :func:`assemble` reads them: in memory
    (:class:`~gesturekit.database.clips.TakeClips`) or staged on disk
    (:class:`~gesturekit.database.stage.StagedTake`)."""

    @property
    def name(self) -> str: ...

    @property
    def record(self) -> dict[str, Any]: ...

    def load(self, what: str, *, header: bool = False) -> np.ndarray: ...

    def path(self, what: str) -> Path | None: ...


class RowWriter(Protocol):
    """One array written front to back: rows appended in order until its shape is full."""

    def write(self, rows: np.ndarray) -> None: ...

    def copy_from(self, path: Path) -> None: ...

    def __enter__(self) -> RowWriter: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None: ...


class ArrayOut(Protocol):
    """Where :func:`assemble` puts a database: in memory (:class:`MemoryOut`) or a folder
    (:class:`~gesturekit.database.folder.FolderOut`)."""

    def array(self, cut: str, name: str, dtype: np.dtype, shape: tuple[int, ...]) -> RowWriter: ...

    def thresholds(self, percentiles: tuple[float, float]) -> dict[str, list[float]]: ...

    def finish(self, meta: dict[str, Any], stats: dict[str, np.ndarray], *, n_clips: int) -> None: ...


class _Rows:
    """An array in memory filled front to back (the :class:`RowWriter` of :class:`MemoryOut`)."""

    def __init__(self, dtype: np.dtype, shape: tuple[int, ...]) -> None:
        self.array = np.empty(shape, dtype=dtype)
        self.rows = 0

    def write(self, rows: np.ndarray) -> None:
        n = rows.shape[0]
        self.array[self.rows : self.rows + n] = rows
        self.rows += n

    def copy_from(self, path: Path) -> None:
        self.write(np.load(path, allow_pickle=False))

    def __enter__(self) -> _Rows:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None and self.rows != self.array.shape[0]:
            raise GestureKitError(f"wrote {self.rows} rows of {self.array.shape[0]}")


class MemoryOut:
    """A database assembled in memory; :meth:`parts` are the keyword arguments of
    :class:`~gesturekit.database.MatchingDatabase`."""

    def __init__(self) -> None:
        self.cuts: dict[str, dict[str, _Rows]] = {}
        self.meta: dict[str, Any] | None = None
        self.stats: dict[str, np.ndarray] | None = None

    def array(self, cut: str, name: str, dtype: np.dtype, shape: tuple[int, ...]) -> _Rows:
        """An empty array of ``dtype`` and ``shape``, filled by the caller's writes."""
        rows = _Rows(dtype, shape)
        self.cuts.setdefault(cut, {})[name] = rows
        return rows

    def thresholds(self, percentiles: tuple[float, float]) -> dict[str, list[float]]:
        """Low and high percentiles of each attribute over every frame of the clips (float64, as
        :func:`~gesturekit.database.folder.column_percentiles` reads them from a folder)."""
        attrs = self.cuts[""]["attributes"].array.reshape(-1, len(ATTRIBUTE_NAMES))
        return {
            name: [float(v) for v in np.percentile(attrs[:, i].astype(np.float64), list(percentiles))]
            for i, name in enumerate(ATTRIBUTE_NAMES)
        }

    def finish(self, meta: dict[str, Any], stats: dict[str, np.ndarray], *, n_clips: int) -> None:
        """Keep ``database.json``'s content (without ``counts``, which saving adds) and the statistics."""
        self.meta, self.stats = meta, stats

    def parts(self) -> dict[str, Any]:
        """``meta``, ``arrays``, ``stats``, ``audio`` (or None) and ``overlap`` (or None), the arrays
        in the order a loaded database holds them."""
        if self.meta is None or self.stats is None:
            raise GestureKitError("the database is not assembled yet (assemble() has not finished)")
        main = {k: r.array for k, r in self.cuts[""].items()}
        order = CLIP_ARRAYS + INDEX_ARRAYS
        overlap = self.cuts.get("overlap")
        return {
            "meta": self.meta,
            "arrays": {k: main[k] for k in order},
            "stats": self.stats,
            "audio": main.get("audio"),
            "overlap": None if overlap is None else {k: overlap[k].array for k in order},
        }


@checks_arguments
def combine_moments(staged: Sequence[TakeRows]) -> dict[str, np.ndarray]:
    """The z-scoring statistics of F, P and A from the takes' moments, combined in the order given.

    Chan, Golub and LeVeque's update of (count, mean, M2) in float64, take by
    take; the standard deviation is ``sqrt(M2 / count)`` floored at 1e-6, as
    :meth:`gesturekit.features.ZScore.fit`.

    Returns
    -------
    dict
        ``F_mean``, ``F_std``, ``P_mean``, ... : float32 vectors.

    Raises
    ------
    ConfigError
        No take has a frame that can start a segment.
    DatabaseError
        A take's moments are not finite (naming its staged file).
    """
    stats: dict[str, np.ndarray] = {}
    for key in MOMENT_KEYS:
        n = 0
        mean: np.ndarray | None = None
        m2: np.ndarray | None = None
        for s in staged:
            nb = int(s.record["count"])
            if nb == 0:
                continue
            mb, m2b = s.load(f"moments_{key}")
            if not (np.isfinite(mb).all() and np.isfinite(m2b).all()):
                raise DatabaseError(
                    f"take {s.name!r} has non-finite moments of {key}; nothing was written",
                    path=s.path(f"moments_{key}"),
                )
            if mean is None or m2 is None:
                n, mean, m2 = nb, mb.copy(), m2b.copy()
                continue
            total = n + nb
            delta = mb - mean
            mean = mean + delta * (nb / total)
            m2 = m2 + m2b + delta * delta * (n * nb / total)
            n = total
        if mean is None or m2 is None:
            raise ConfigError(f"every take is shorter than {LAYOUT.audio_lookahead + 1} frames; nothing can be matched")
        stats[f"{key}_mean"] = mean.astype(np.float32)
        stats[f"{key}_std"] = np.maximum(np.sqrt(m2 / n), _FLOOR).astype(np.float32)
    return stats


@checks_arguments
def check_takes(staged: Sequence[TakeRows], base: dict | None) -> list | None:
    """Unique names, the same joints in every take (and the base database); the joints' list or None.

    Raises
    ------
    ConfigError
        Two takes of one name, or a take holding other joints than the takes before it.
    """
    names = [s.name for s in staged] + ([t["name"] for t in base["meta"]["takes"]] if base else [])
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ConfigError(f"take names must be unique; repeated: {', '.join(dup)}")
    # every take of a database holds the same joints: what a clip shows must not depend on its take
    joints = base["meta"].get("joints") if base else (staged[0].record["joints"] if staged else None)
    for s in staged:
        if s.record["joints"] != joints:
            from ..skeleton import JointPresence

            def describe(j: list | None) -> str:
                return (JointPresence.full() if j is None else JointPresence(tuple(j))).describe()

            raise ConfigError(
                f"take {s.name!r} holds other joints than the takes before it ({describe(s.record['joints'])} "
                f"against {describe(joints)}); read every take with the same joint map"
            )
    return joints


@checks_arguments
def assemble(
    out: ArrayOut,
    staged: Sequence[TakeRows],
    config: BuildConfig,
    *,
    base: dict | None = None,
    skeleton: Skeleton | None = None,
) -> tuple[dict, dict[str, np.ndarray]]:
    """Put a database's arrays into ``out`` from the takes' clips, one array and one take at a time.

    Parameters
    ----------
    out : ArrayOut
        Where the arrays go: :class:`MemoryOut`, or a
        :class:`~gesturekit.database.folder.FolderOut` of an empty folder (the output's temporary folder).
    staged : sequence of TakeRows
        The takes, in the database's order (by name).
    config : BuildConfig
    base : dict, optional
        A database folder to extend (the keyword arguments of
        :class:`~gesturekit.database.MatchingDatabase` as
        :func:`~gesturekit.database.folder.read_database` gives them, with its ``path``): its arrays
        are copied unchanged in front, its statistics and thresholds are kept and the takes are
        z-scored with them.
    skeleton : Skeleton, optional
        The skeleton the takes were normalised with (``--normalize-bones``), stored as
        ``database.json``'s ``"skeleton"`` (nothing is stored without one).

    Returns
    -------
    (dict, dict)
        ``database.json``'s content (without ``counts``) and the z-scoring statistics.

    Raises
    ------
    ConfigError
        Repeated take names, takes of other joints, or no take long enough for one clip.
    DatabaseError
        A take gives non-finite values once z-scored; nothing is written.
    """
    joints = check_takes(staged, base)
    old_takes: list[dict] = list(base["meta"]["takes"]) if base else []
    stats = dict(base["stats"]) if base else combine_moments(staged)
    if not any(s.record["n_clips"] for s in staged) and not old_takes:
        L = config.clip_frames
        raise ConfigError(f"every take is shorter than one clip ({L} frames = {L / FPS:.1f} s)")
    zscore = {k: ZScore(stats[f"{k}_mean"], stats[f"{k}_std"]) for k in ("F", "P")}
    cuts = [("", "n_clips")] + ([("overlap.", "n_windows")] if config.overlap_stride else [])
    for prefix, count in cuts:
        sub = "overlap" if prefix else ""
        old_path = None if base is None else Path(base["path"]) / ("overlap" if prefix else "")
        old_n = 0 if base is None else int(base["overlap" if prefix else "arrays"]["clip_take"].shape[0])
        total = old_n + sum(int(s.record[count]) for s in staged)
        for k in CLIP_ARRAYS + ("clip_start",):
            first = staged[0].load(prefix + k, header=True) if staged else None
            dtype, row = (first.dtype, first.shape[1:]) if first is not None else (np.dtype(np.float32), ())
            with out.array(sub, k, dtype, (total, *row)) as w:
                if old_path is not None:
                    w.copy_from(old_path / f"{k}.npy")
                for s in staged:
                    a = s.load(prefix + k)
                    a = zscore[k].apply(a) if k in zscore else a
                    if a.dtype.kind == "f" and not np.isfinite(a).all():
                        # nothing non-finite is written (a database's zero std, a damaged staged take)
                        raise DatabaseError(
                            f"take {s.name!r} gives non-finite values in {prefix.replace('.', '/')}{k}.npy; "
                            "nothing was written"
                            + ("" if base is None else " (the database's statistics may be damaged: rebuild it)"),
                            path=s.path(prefix + k) if base is None else base["path"],
                        )
                    w.write(a)
        with out.array(sub, "clip_take", np.dtype(np.int32), (total,)) as w:
            if old_path is not None:
                w.copy_from(old_path / "clip_take.npy")
            for ti, s in enumerate(staged):
                w.write(np.full(int(s.record[count]), len(old_takes) + ti, np.int32))
    take_meta = list(old_takes)
    first_clip = sum(t["n_clips"] for t in old_takes)
    storage = AudioStorage(format=config.audio_format, rate=config.audio_rate)
    # elements of audio.npy per take: samples for the default, else the encoded size
    audio_offset = max((t["audio_offset"] + t.get("audio_size", t["audio_samples"]) for t in old_takes), default=0)
    for s in staged:
        r = s.record
        size = int(r.get("audio_size", r["audio_samples"]))
        fields = {"audio_offset": audio_offset, "audio_samples": r["audio_samples"]}
        if not storage.is_default:
            fields["audio_size"] = size
        take_meta.append(
            {
                "name": r["name"],
                "sources": r["sources"],
                "n_frames": r["n_frames"],
                "first_clip": first_clip,
                "n_clips": r["n_clips"],
                **fields,
            }
        )
        first_clip += r["n_clips"]
        audio_offset += size
    if config.store_audio:
        with out.array("", "audio", storage.dtype, (audio_offset,)) as w:
            if base is not None:
                w.copy_from(Path(base["path"]) / "audio.npy")
            for s in staged:
                w.write(s.load("audio"))
    # thresholds over every frame of the clips (the frames the search may use)
    thresholds = dict(base["meta"]["thresholds"]) if base else out.thresholds(config.percentiles)
    meta: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "gesturekit_version": __version__,
        "layout": LAYOUT.signature(),
        "joint_names": list(JOINT_NAMES),
        # appending keeps the database's build record, but a label given replaces its label
        "build": {**base["meta"]["build"], "label": config.label} if base else asdict(config),
        "attribute_names": list(ATTRIBUTE_NAMES),
        "thresholds": thresholds,
        "takes": take_meta,
    }
    if joints is not None:
        meta["joints"] = list(joints)
    if skeleton is not None:
        meta["skeleton"] = skeleton.to_json()
    if config.store_audio and storage.to_meta() is not None:
        meta["audio"] = storage.to_meta()
    out.finish(meta, stats, n_clips=first_clip)
    return meta, stats


@checks_arguments
def build_in_memory(
    takes: Iterable[Take],
    *,
    config: BuildConfig,
    progress: Callable[[int, str], None] | None = None,
    skeleton: Skeleton | None = None,
) -> dict[str, Any]:
    """Build a database from takes in memory; ``skeleton`` (the one the takes were normalised with)
    is stored with it.

    Each take is made into its clips as it is read (a take of other joints fails before the rest
    are read); the takes are then put in order by name and assembled (:func:`assemble`).

    Returns
    -------
    dict
        The keyword arguments of :class:`~gesturekit.database.MatchingDatabase` (:meth:`MemoryOut.parts`).

    Raises
    ------
    ConfigError
        No takes, or see :func:`assemble` and :func:`~gesturekit.database.clips.take_clips`.
    """
    clips: list[TakeClips] = []
    for i, take in enumerate(takes):
        clips.append(take_clips(take, i, config))
        check_takes(clips, None)
        if progress is not None:
            progress(i + 1, take.name)
    if not clips:
        raise ConfigError("no takes to build a database from")
    clips.sort(key=lambda s: s.name)
    out = MemoryOut()
    assemble(out, clips, config, skeleton=skeleton)
    return out.parts()
