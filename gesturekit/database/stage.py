"""Building a database from files, first pass: each take read, featurised, cut and staged on disk.

A folder build never holds more than a few takes. Each unit of work (one take
file, or one file of several takes) is read, each take made into its clips
(:func:`gesturekit.database.clips.take_clips`: per-frame features, the cut into
clips and, on request, the overlapping cut, its audio as the database keeps it,
its z-scoring moments) and written to a folder of its own in a *staging
folder*. The second pass (:func:`gesturekit.database.build.assemble`) combines
the moments and writes the database's arrays from the staged ones, one take at
a time. The units run in this process, in a pool of worker processes or on a
Dask cluster (:func:`run_jobs`); the order in which they finish does not
matter, as the takes are put in order by name afterwards.

A folder build stages beside its output, in ``.NAME.staging`` (marked by
``staging.json``, so that nothing else is ever taken for it or removed). Each
unit's folder is named by a key of its source files (path, size, modification
time) and of every option that changes what is staged, and is written under a
temporary name and renamed when complete: a build that was interrupted is
resumed by the next identical command, which reuses the units already there
once :mod:`gesturekit.database.stage_check` finds them whole. The staging
folder is removed when the database is written.

Staged unit ``KEY/``::

    takes.json            the takes of the unit (name, sources, frame and clip counts, ...), warnings
    J.F.npy ... J.pose_track.npy   take J's clip arrays, F and P not yet z-scored
    J.clip_start.npy      the clips' start frames
    J.overlap.*.npy       the overlapping cut (optional)
    J.audio.npy           the take's audio as the database keeps it (optional; :mod:`gesturekit.database.audio`)
    J.moments_F.npy ...   (2, dims) float64: mean and sum of squared deviations of F, P, A

A build with ``--normalize-bones`` first reads every take once to fit the database's
skeleton (:func:`sample_job`), in units of their own (another key), each take's
``J.bones.npy``: the samples a skeleton is fitted from
(:func:`gesturekit.bones.bone_samples`), then stages the takes normalised with it.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import limits
from .._arguments import checks_arguments
from .._jobs import run_jobs as _run
from .._version import __version__
from ..errors import ConfigError, GestureKitError, OutputError, collect_warnings, warn
from ..features import LAYOUT
from ..limits import read_json
from ..motion import Take
from .clips import take_clips
from .config import BuildConfig
from .stage_check import DamagedUnit, check_sampled_unit, check_staged_unit

if TYPE_CHECKING:
    from distributed import Client

    from ..datasets.takes import TakeSource

__all__ = [
    "STAGING_FORMAT",
    "STAGING_VERSION",
    "BuildProgress",
    "StagedTake",
    "StageJob",
    "run_jobs",
    "stage_take",
    "stage_job",
    "sample_job",
    "job_key",
    "staged_takes",
    "reemit",
    "staging_folder",
    "is_staging",
    "open_staging",
    "remove_staging",
]

#: The staging folder of an out-of-core build (``.NAME.staging`` beside the database): its marker file
#: and format; a staged unit records the version, and one of another version is staged again.
STAGING_FORMAT = "gesturekit-database-staging"
STAGING_VERSION = 1
_MARKER = "staging.json"


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
    (see :func:`stage_take`)."""

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


# ---- running the units ------------------------------------------------------------------


@checks_arguments
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
        The work of a unit: :func:`stage_job` (the default),
        or :func:`sample_job` to fit a skeleton.
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


# ---- one take -----------------------------------------------------------------------------------


def _save(path: Path, array: np.ndarray) -> None:
    """Write a staged array; a failed write (a full disk) is an :class:`OutputError` naming the file,
    whose unit's temporary folder is then removed (:func:`_run_unit`)."""
    from ..outputs import write_errors

    with write_errors(path):
        np.save(path, np.ascontiguousarray(array), allow_pickle=False)


@checks_arguments
def stage_take(take: Take, folder: Path, index: int, config: BuildConfig) -> dict[str, Any]:
    """Make one take into its clips (:func:`~gesturekit.database.clips.take_clips`) and write every
    array into ``folder`` as ``INDEX.NAME.npy``.

    Returns
    -------
    dict
        The take's record (:attr:`~gesturekit.database.clips.TakeClips.record`).

    Raises
    ------
    ConfigError
        The take has NaN positions, non-finite features, or no frame.
    OutputError
        A file cannot be written (naming it).
    """
    clips = take_clips(take, index, config)
    for what, array in clips.arrays.items():
        _save(folder / f"{index}.{what}.npy", array)
    return clips.record


# ---- units of work ------------------------------------------------------------------------------


@dataclass(frozen=True)
class StageJob:
    """One unit of per-take work of a folder build: a source's takes, staged as ``staging/key``.

    Attributes
    ----------
    key : str
        The unit's staging key (:func:`job_key`).
    staging : str
        The staging folder (a string, so that jobs travel to cluster workers as they are).
    source : TakeSource
        The files to read.
    reading : dict
        Keyword options of :func:`gesturekit.datasets.takes.iter_takes`.
    config : BuildConfig
    only : tuple of str or None
        Stage only the takes of these names (a file of several takes that the database holds some of).
    skip : tuple of str
        Take names not to stage (in the database already).
    """

    key: str
    staging: str
    source: TakeSource
    reading: dict
    config: BuildConfig
    only: tuple[str, ...] | None = None
    skip: tuple[str, ...] = ()


def _file_identity(path: Path | None) -> list[Any]:
    if path is None:
        return [None]
    try:
        st = os.stat(path)
    except OSError:
        return [os.path.abspath(path), None, None]
    return [os.path.abspath(path), st.st_size, st.st_mtime_ns]


@checks_arguments
def job_key(
    source: TakeSource,
    reading_key: dict[str, Any],
    config: BuildConfig,
    *,
    only: tuple[str, ...] | None = None,
    skip: tuple[str, ...] = (),
) -> str:
    """The staging key of a unit: a digest of its files (path, size, modification time), of the
    reading options ``reading_key`` (JSON-able), of what the build stages (clip frames, overlap
    stride, audio), the feature layout and gesturekit's version."""
    record = {
        "staging": STAGING_VERSION,
        "gesturekit": __version__,
        "layout": LAYOUT.signature(),
        "kind": source.kind,
        "motion": _file_identity(source.motion),
        "audio": _file_identity(source.audio),
        "reading": reading_key,
        "build": [
            config.clip_frames,
            config.overlap_stride,
            config.store_audio,
            config.audio_format,
            config.audio_rate,
        ],
        "only": None if only is None else sorted(only),
        "skip": sorted(skip),
    }
    text = json.dumps(record, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:32]


@checks_arguments
def staged_takes(staging: Path, key: str) -> dict[str, Any] | None:
    """The record of a complete staged unit (``takes`` and ``warnings``), or None when it is not staged."""
    try:
        record = read_json(staging / key / "takes.json")
    except GestureKitError:  # missing, or damaged: the unit is staged again
        return None
    return record if isinstance(record, dict) else None


def _reusable(
    staging: Path, job: StageJob, check: Callable[[Path, BuildConfig], None]
) -> tuple[dict[str, Any] | None, str | None]:
    """The record of the unit ``job`` staged already and fit to reuse (or None), and why the one
    there is not (None when there is none); a damaged unit is removed."""
    folder = staging / job.key
    if not folder.exists() and not folder.is_symlink():
        return None, None
    try:
        if folder.is_symlink() or not folder.is_dir():
            raise DamagedUnit(f"{job.key}: not a folder")
        check(folder, job.config)
        done = staged_takes(staging, job.key)
        if done is None:  # read and checked just now: gone since
            raise DamagedUnit("takes.json: gone")
        return done, None
    except DamagedUnit as exc:
        reason = str(exc)
    record = staged_takes(staging, job.key)
    try:
        names = [t["name"] for t in record["takes"]] if record is not None else []
        what = ", ".join(f"take {n}" for n in names) if all(isinstance(n, str) for n in names) else ""
    except (TypeError, KeyError):  # a record of another shape: the unit is named by its file
        what = ""
    what = what or f"the takes of {job.source.motion.name}"
    # moved aside first, so that a removal cut short leaves a name open_staging clears
    aside = staging / f"{job.key}.tmp-damaged-{uuid.uuid4().hex[:12]}"
    os.replace(folder, aside)
    if aside.is_dir() and not aside.is_symlink():
        shutil.rmtree(aside, ignore_errors=True)
    else:
        aside.unlink()
    return None, f"{what}: staged copy damaged ({reason}), staged again"


@checks_arguments
def stage_job(job: StageJob) -> dict[str, Any]:
    """Stage one unit (the function a worker process or a cluster worker runs).

    A unit already staged (by an earlier, interrupted build) is not read again.

    Returns
    -------
    dict
        ``takes`` (the records of :func:`stage_take`), ``warnings`` (the
        messages reading and featurising issued), ``reused`` (whether the unit
        was staged already), ``damaged`` (a line saying that a staged copy was
        damaged and why, when it was staged again; else None).
    """

    def stage(take: Take, folder: Path, index: int) -> dict[str, Any]:
        return stage_take(take, folder, index, job.config)

    return _run_unit(job, stage, check_staged_unit, keep_warnings=True)


@checks_arguments
def sample_job(job: StageJob) -> dict[str, Any]:
    """Read one unit's takes for fitting a skeleton (``--normalize-bones``): each take's
    :func:`gesturekit.bones.bone_samples` as ``INDEX.bones.npy`` (rows, frames) float32.

    ``job.reading`` reads the takes without normalising them. A unit done already (by an
    interrupted build) is not read again; the warnings of reading are dropped (they are given
    when the takes are read again to be staged).

    Returns
    -------
    dict
        ``takes``: per take ``index``, ``name``, ``frames``, ``seconds``, ``joints`` (as
        :func:`stage_take`'s record) and ``medians`` (the median length of each of the 55 bones, metres);
        ``warnings`` (empty); ``reused``.
    """
    from ..bones import bone_samples
    from ..skeleton import N_JOINTS

    def sample(take: Take, folder: Path, index: int) -> dict[str, Any]:
        samples = bone_samples(take.motion.positions)
        _save(folder / f"{index}.bones.npy", samples)
        presence = take.motion.presence
        return {
            "index": index,
            "name": take.name,
            "frames": int(samples.shape[1]),
            "seconds": samples.shape[1] / float(take.motion.fps),
            "joints": None if presence.is_full else presence.to_list(),
            "medians": [float(v) for v in np.median(samples[:N_JOINTS].astype(np.float64), axis=1)],
        }

    return _run_unit(job, sample, check_sampled_unit, keep_warnings=False)


def _run_unit(
    job: StageJob,
    per_take: Callable[[Take, Path, int], dict[str, Any]],
    check: Callable[[Path, BuildConfig], None],
    *,
    keep_warnings: bool,
) -> dict:
    """Read the takes of a unit and write what ``per_take`` makes of each into the unit's folder,
    complete or not at all (a temporary folder renamed when done). A unit staged already is reused
    when ``check`` finds it whole, else removed and staged again (``damaged`` says why)."""
    from ..datasets.takes import iter_takes
    from ..outputs import write_errors

    staging = Path(job.staging)
    done, damaged = _reusable(staging, job, check)
    if done is not None:
        return {**done, "reused": True, "damaged": None}
    tmp = staging / f"{job.key}.tmp-{uuid.uuid4().hex[:12]}"
    tmp.mkdir()
    try:
        records: list[dict[str, Any]] = []
        with collect_warnings() as messages:
            for take in iter_takes([job.source], **job.reading):
                if take.name in job.skip or (job.only is not None and take.name not in job.only):
                    continue
                records.append(per_take(take, tmp, len(records)))
        result = {"takes": records, "warnings": list(messages) if keep_warnings else []}
        with write_errors(tmp / "takes.json"):
            (tmp / "takes.json").write_text(json.dumps(result), encoding="utf-8")
        os.replace(tmp, staging / job.key)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {**result, "reused": False, "damaged": damaged}


@checks_arguments
def reemit(messages: Iterable[str]) -> None:
    """Issue again the warnings a worker collected while staging."""
    for message in messages:
        warn(message)


# ---- the staging folder -------------------------------------------------------------------------


@checks_arguments
def staging_folder(out: Path) -> Path:
    """The staging folder of a build of the database folder ``out``: ``.NAME.staging`` beside it."""
    from ..outputs import beside_name

    return out.parent / beside_name(out, ".staging")


@checks_arguments
def is_staging(path: Path) -> bool:
    """Whether ``path`` is a staging folder gesturekit made (its ``staging.json`` says so)."""
    try:
        marker = limits.read_json(path / _MARKER)
    except GestureKitError:
        return False
    return isinstance(marker, dict) and marker.get("format") == STAGING_FORMAT


@checks_arguments
def open_staging(path: Path) -> None:
    """Make the staging folder ``path``, or reuse the one an interrupted build left (its unfinished
    units removed).

    Raises
    ------
    OutputError
        Something that is not a gesturekit staging folder is at ``path``.
    """
    from ..outputs import write_errors

    with write_errors(path):
        if path.is_symlink() or (path.exists() and not is_staging(path)):
            raise OutputError(
                "is in the way of the build's staging folder and is not one gesturekit made; move it away", path=path
            )
        if not path.exists():
            tmp = path.parent / f"{path.name}.tmp-{uuid.uuid4().hex[:12]}"
            tmp.mkdir(parents=True)
            marker = {"format": STAGING_FORMAT, "version": STAGING_VERSION, "gesturekit": __version__}
            (tmp / _MARKER).write_text(json.dumps(marker), encoding="utf-8")
            os.replace(tmp, path)
            return
        for entry in path.iterdir():
            if ".tmp-" in entry.name:
                shutil.rmtree(entry, ignore_errors=True)


@checks_arguments
def remove_staging(path: Path) -> None:
    """Remove a staging folder gesturekit made (anything else is left alone)."""
    if is_staging(path) and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
