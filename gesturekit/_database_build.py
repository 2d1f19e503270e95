"""Building a database, second pass: staged takes -> the database folder, one take at a time.

The first pass (:mod:`gesturekit._database_stage`) leaves every take's clip
arrays and z-scoring moments on disk. This module

- runs the first pass over the units of a folder build, in this process, in a
  pool of worker processes or on a Dask cluster (:func:`run_jobs`); the
  order in which units finish does not matter, as the takes are put in order
  by name afterwards;
- combines the takes' moments in that order (Chan et al.'s pairwise update,
  float64) into the z-scoring statistics (:func:`combine_moments`);
- writes the database's ``.npy`` files take by take, z-scoring F and P on the
  way, and the thresholds from per-column percentiles of the written
  attributes (:func:`assemble`). Only a few takes and one attribute column
  (8 bytes a frame) are in memory at once;
- builds a database in memory from :class:`~gesturekit.motion.Take` objects
  with the same two passes in a temporary folder (:func:`build_in_memory`):
  there is one builder.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from . import limits
from ._database_audio import AudioStorage
from ._database_folder import CLIP_ARRAYS, FORMAT, FORMAT_VERSION, read_database, write_meta, write_stats
from ._database_stage import MOMENT_KEYS, BuildConfig, StageJob, stage_job, stage_take
from ._jobs import run_jobs as _run
from ._version import __version__
from .control import ATTRIBUTE_NAMES
from .errors import ConfigError, DatabaseError, GestureKitError, warn
from .features import LAYOUT, ZScore
from .skeleton import FPS, JOINT_NAMES

if TYPE_CHECKING:
    from distributed import Client

    from .bones import Skeleton
    from .motion import Take

__all__ = ["BuildProgress", "StagedTake", "run_jobs", "combine_moments", "assemble", "build_in_memory"]

_FLOOR = 1e-6  # the z-scoring std floor of ZScore.fit: constant dimensions map to 0
_CHUNK_BYTES = 64 << 20  # attribute columns are read in pieces of this size


@dataclass(frozen=True)
class BuildProgress:
    """Where a build stands, after each unit of takes is staged.

    Attributes
    ----------
    done, total : int
        Takes staged so far, and of the build.
    name : str
        The last take staged.
    seconds : float
        Duration of the takes staged so far, seconds at 15 fps.
    reused : int
        Takes among ``done`` that an interrupted build had staged already.
    phase : {"read", "fit"}
        ``"read"``: the takes are read and staged; ``"fit"``: they are read first to fit the
        database's skeleton (``--normalize-bones``).
    """

    done: int
    total: int
    name: str
    seconds: float
    reused: int
    phase: str = "read"


@dataclass(frozen=True)
class StagedTake:
    """A staged take: its files ``folder/INDEX.*.npy`` and its record
    (see :func:`~gesturekit._database_stage.stage_take`)."""

    folder: Path
    record: dict

    @property
    def name(self) -> str:
        return str(self.record["name"])

    def path(self, what: str) -> Path:
        """The file of one staged array (``"F"``, ``"overlap.G"``, ...)."""
        return self.folder / f"{self.record['index']}.{what}.npy"

    def load(self, what: str, *, header: bool = False) -> np.ndarray:
        """One staged array (``"F"``, ``"overlap.G"``, ``"audio"``, ``"moments_P"``, ...); with
        ``header``, memory-mapped (for its dtype and shape, nothing read)."""
        path = self.path(what)
        limits.check_regular(path, what="a staged array ", error=ConfigError)
        return np.load(path, mmap_mode="r" if header else None, allow_pickle=False)


# ---- first pass: running the units ------------------------------------------------------------------


def run_jobs(
    jobs: Sequence[StageJob],
    *,
    workers: int | None,
    scheduler: str | Client | None,
    on_result: Callable[[StageJob, dict], None],
    fn: Callable[[StageJob], dict] | None = None,
) -> None:
    """Stage every unit: here (one worker), in worker processes, or on a Dask cluster
    (:func:`gesturekit._jobs.run_jobs`: the first failing unit in ``jobs``' order is the error
    raised, as in a serial build; units staged before it stay staged).

    Parameters
    ----------
    fn : callable, optional
        The work of a unit: :func:`~gesturekit._database_stage.stage_job` (the default, looked up
        when called), or :func:`~gesturekit._database_stage.sample_job` to fit a skeleton.
    workers : int or None
        Worker processes (None: all cores); 1 stages in this process.
    scheduler : str, distributed.Client or None
        The address of a Dask scheduler (``tcp://host:8786``) or a client; then ``workers`` is not used.
    """
    _run(
        stage_job if fn is None else fn,
        jobs,
        keys=[f"gesturekit-stage-{j.key}" for j in jobs],
        workers=workers,
        scheduler=scheduler,
        on_result=on_result,
        purpose="building a database on a Dask cluster (--scheduler)",
        died="a build worker process died (out of memory?); rerun the same command to resume, or pass --workers 1. "
        'From a script, put the call under `if __name__ == "__main__":` (worker processes import the main script)',
        initializer=_worker_setup,
    )


def _worker_setup() -> None:
    """A build worker process computes with one thread: the processes share the cores, and idle
    BLAS threads of several processes would spin against each other."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


# ---- second pass ------------------------------------------------------------------------------------


def combine_moments(staged: Sequence[StagedTake]) -> dict[str, np.ndarray]:
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


class _NpyWriter:
    """An ``.npy`` file written front to back: its header for the final shape, then rows in order.

    The bytes are those :func:`numpy.save` writes for the whole array. Rows are
    appended with plain writes, not through a memory map: pages of a mapped
    output count towards the process's resident memory until they are unmapped,
    which for a whole dataset is the dataset's size.
    """

    def __init__(self, path: Path, dtype: np.dtype, shape: tuple[int, ...]) -> None:
        self.path, self.dtype, self.shape = path, np.dtype(dtype), shape
        self.rows = 0
        self.file: IO[bytes] = open(path, "wb")  # noqa: SIM115 (closed by close(), the writers outlive one block)
        header = {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False, "shape": shape}
        np.lib.format.write_array_header_1_0(self.file, header)

    def write(self, rows: np.ndarray) -> None:
        if rows.dtype != self.dtype or rows.shape[1:] != self.shape[1:]:
            raise GestureKitError(f"{self.path.name}: staged rows of {rows.dtype} {rows.shape} do not fit {self.shape}")
        self.file.write(np.ascontiguousarray(rows).tobytes())
        self.rows += rows.shape[0]

    def copy_from(self, path: Path) -> None:
        """Append the rows of the ``.npy`` file ``path`` (of this dtype and row shape) byte for byte."""
        with open(path, "rb") as src:
            version = np.lib.format.read_magic(src)
            read_header = (
                np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            )
            shape, fortran, dtype = read_header(src)
            if fortran or dtype != self.dtype or tuple(shape[1:]) != self.shape[1:]:
                raise GestureKitError(f"{path} holds {dtype} {shape}; cannot append it to {self.shape}")
            shutil.copyfileobj(src, self.file, 16 << 20)
        self.rows += int(shape[0])

    def close(self) -> None:
        self.file.close()
        if self.rows != self.shape[0]:
            raise GestureKitError(f"{self.path.name}: wrote {self.rows} rows of {self.shape[0]}")

    def __enter__(self) -> _NpyWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:  # the error that stopped the writing is the one to report, not the rows missing after it
            self.file.close()


def _column_percentiles(path: Path, percentiles: tuple[float, float]) -> dict[str, list[float]]:
    """Low and high percentiles of each attribute over every frame of ``attributes.npy``, read a
    column at a time in pieces (float64, as the thresholds have always been computed)."""
    n_attr = len(ATTRIBUTE_NAMES)
    out: dict[str, list[float]] = {}
    with open(path, "rb") as f:
        np.lib.format.read_magic(f)
        shape, _fortran, dtype = np.lib.format.read_array_header_1_0(f)
        start = f.tell()
        frames = int(np.prod(shape[:-1]))
        step = max(1, _CHUNK_BYTES // (n_attr * dtype.itemsize))
        for i, name in enumerate(ATTRIBUTE_NAMES):
            col = np.empty(frames, dtype=np.float64)
            f.seek(start)
            for lo in range(0, frames, step):
                rows = np.fromfile(f, dtype=dtype, count=min(step, frames - lo) * n_attr)
                col[lo : lo + rows.shape[0] // n_attr] = rows.reshape(-1, n_attr)[:, i]
            out[name] = [float(v) for v in np.percentile(col, list(percentiles))]
    return out


def _check_takes(staged: Sequence[StagedTake], base: dict | None) -> list | None:
    """Unique names, the same joints in every take (and the base database); the joints' list or None."""
    names = [s.name for s in staged] + ([t["name"] for t in base["meta"]["takes"]] if base else [])
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ConfigError(f"take names must be unique; repeated: {', '.join(dup)}")
    # every take of a database holds the same joints: what a clip shows must not depend on its take
    joints = base["meta"].get("joints") if base else (staged[0].record["joints"] if staged else None)
    for s in staged:
        if s.record["joints"] != joints:
            from .skeleton import JointPresence

            def describe(j: list | None) -> str:
                return (JointPresence.full() if j is None else JointPresence(tuple(j))).describe()

            raise ConfigError(
                f"take {s.name!r} holds other joints than the takes before it ({describe(s.record['joints'])} "
                f"against {describe(joints)}); read every take with the same joint map"
            )
    return joints


def assemble(
    folder: Path,
    staged: Sequence[StagedTake],
    config: BuildConfig,
    *,
    base: dict | None = None,
    skeleton: Skeleton | None = None,
) -> tuple[dict, dict[str, np.ndarray]]:
    """Write a database folder's files into ``folder`` from staged takes, one take at a time.

    Parameters
    ----------
    folder : Path
        An empty folder (the output's temporary folder).
    staged : sequence of StagedTake
        The takes, in the database's order (by name).
    config : BuildConfig
    base : dict, optional
        A database to extend (the keyword arguments of
        :class:`~gesturekit.database.MatchingDatabase` as :func:`read_database` gives them, with its
        ``path``): its arrays are copied unchanged in front, its statistics and thresholds are
        kept and the staged takes are z-scored with them.
    skeleton : Skeleton, optional
        The skeleton the takes were normalised with (``--normalize-bones``), stored as
        ``database.json``'s ``"skeleton"`` (nothing is stored without one).

    Returns
    -------
    (dict, dict)
        ``database.json``'s content (without ``counts``) and the z-scoring statistics.
    """
    joints = _check_takes(staged, base)
    old_takes: list[dict] = list(base["meta"]["takes"]) if base else []
    stats = dict(base["stats"]) if base else combine_moments(staged)
    if not any(s.record["n_clips"] for s in staged) and not old_takes:
        L = config.clip_frames
        raise ConfigError(f"every take is shorter than one clip ({L} frames = {L / FPS:.1f} s)")
    zscore = {k: ZScore(stats[f"{k}_mean"], stats[f"{k}_std"]) for k in ("F", "P")}
    cuts = [("", "n_clips")] + ([("overlap.", "n_windows")] if config.overlap_stride else [])
    if config.overlap_stride:
        (folder / "overlap").mkdir()
    for prefix, count in cuts:
        sub = folder / "overlap" if prefix else folder
        old_path = None if base is None else Path(base["path"]) / ("overlap" if prefix else "")
        old_n = 0 if base is None else int(base["overlap" if prefix else "arrays"]["clip_take"].shape[0])
        total = old_n + sum(int(s.record[count]) for s in staged)
        for k in CLIP_ARRAYS + ("clip_start",):
            first = staged[0].load(prefix + k, header=True) if staged else None
            dtype, row = (first.dtype, first.shape[1:]) if first is not None else (np.dtype(np.float32), ())
            with _NpyWriter(sub / f"{k}.npy", dtype, (total, *row)) as w:
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
        with _NpyWriter(sub / "clip_take.npy", np.dtype(np.int32), (total,)) as w:
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
        with _NpyWriter(folder / "audio.npy", storage.dtype, (audio_offset,)) as w:
            if base is not None:
                w.copy_from(Path(base["path"]) / "audio.npy")
            for s in staged:
                w.write(s.load("audio"))
    # thresholds over every frame of the clips (the frames the search may use)
    thresholds = (
        dict(base["meta"]["thresholds"]) if base else _column_percentiles(folder / "attributes.npy", config.percentiles)
    )
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
    write_stats(folder / "stats.npz", stats)
    write_meta(folder, meta, n_clips=first_clip)
    return meta, stats


def build_in_memory(
    takes: Iterable[Take],
    *,
    config: BuildConfig,
    progress: Callable[[int, str], None] | None = None,
    skeleton: Skeleton | None = None,
) -> dict[str, Any]:
    """Build a database from takes with the two passes of a folder build, in a temporary folder, and
    read it back into memory; ``skeleton`` (the one the takes were normalised with) is stored with it.

    Returns
    -------
    dict
        The keyword arguments of :class:`~gesturekit.database.MatchingDatabase` (arrays in memory).
    """
    with tempfile.TemporaryDirectory(prefix="gesturekit-build-") as tmp:
        staging = Path(tmp) / "staging"
        staged: list[StagedTake] = []
        for i, take in enumerate(takes):
            unit = staging / f"{i:06d}"
            unit.mkdir(parents=True)
            staged.append(StagedTake(unit, stage_take(take, unit, 0, config)))
            _check_takes(staged, None)  # a take of other joints fails before the rest are read
            if progress is not None:
                progress(i + 1, take.name)
        if not staged:
            raise ConfigError("no takes to build a database from")
        staged.sort(key=lambda s: s.name)
        out = Path(tmp) / "database"
        out.mkdir()
        meta, _stats = assemble(out, staged, config, skeleton=skeleton)
        loaded = read_database(out, mmap=False)
    loaded["meta"] = meta
    return loaded


def reemit(messages: Iterable[str]) -> None:
    """Issue again the warnings a worker collected while staging."""
    for message in messages:
        warn(message)
