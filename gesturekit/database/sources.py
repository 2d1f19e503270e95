"""A database built from take files: out of core, in parallel, resumable, and by appending.

:func:`build_from_sources` is what :func:`gesturekit.workspace.build_database`
(``gesturekit build-db FOLDER``) runs once the folder's takes are found:

1. the takes are staged beside the output (:mod:`gesturekit.database.stage`),
   by this process, worker processes or a Dask cluster; units an interrupted
   build staged already are reused;
2. the database is written from the staged takes in order of take name
   (:func:`gesturekit.database.build.assemble`) into the output's temporary
   folder, which is swapped into place (:func:`gesturekit.outputs.write_folder`);
3. the staging folder is removed.

Appending (``--append``) adds the takes of a folder that the database does not
hold (by name). By default the statistics and thresholds are recomputed over
every take, the database's takes being read again from the files they were
read from (recorded in ``database.json``): the result is the database a build
of all the takes gives, byte for byte. With ``keep_stats`` (``--keep-stats``)
the database's statistics and thresholds are kept, the new takes z-scored with
them and put after the old ones, whose arrays are copied unchanged.

With ``--normalize-bones`` the database has one skeleton (:mod:`gesturekit.bones`): the
takes are read once first to fit it (:func:`~gesturekit.database.stage.sample_job`,
staged like the takes, so a resumed build reuses it; the fit reads the samples one row
at a time), then read again and staged normalised with it, and it is stored in
``database.json``. Appending keeps the database's skeleton: the new takes are read once
to check that every bone's median length is within
:data:`~gesturekit.bones.FIT_TOLERANCE` of the skeleton's (else the append is refused,
naming the take and the bone, before anything is written), and every take staged is
normalised with the stored skeleton (the result is then not the database a build of
all the takes gives, whose skeleton would be fitted over them all).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arguments import checks_arguments
from ..bones import Skeleton, fit_skeleton
from ..errors import ConfigError, DatabaseError, InputFileError
from ..skeleton import JointPresence
from .build import assemble
from .config import BuildConfig, recorded_config
from .folder import FolderOut, read_database
from .stage import (
    BuildProgress,
    StagedTake,
    StageJob,
    job_key,
    open_staging,
    reemit,
    remove_staging,
    run_jobs,
    sample_job,
    staged_takes,
    staging_folder,
)

if TYPE_CHECKING:
    from distributed import Client

    from ..datasets.takes import TakeSource

__all__ = ["build_from_sources", "recorded_build", "recorded_reading"]

# build options an appended take must share with the database's: attribute -> the option that sets it
_SHARED_OPTIONS = {
    "clip_frames": "clip_frames",
    "overlap_stride": "--overlap-stride",
    "percentiles": "--percentiles",
    "store_audio": "--no-audio",
    "audio_format": "--audio-format",
    "audio_rate": "--audio-rate",
    "joint_map": "--preset/--joint-map",
}


@checks_arguments
def recorded_build(out: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The build options recorded by the database at ``out`` (None when there is no readable database)."""
    try:
        build = read_database(Path(out), mmap=True)["meta"]["build"]
    except DatabaseError:
        return None
    return build if isinstance(build, dict) else None


#: The reading options --append takes from the database: key -> (the option, its value when not given).
_READING_OPTIONS = {
    "kind": ("--kind", "auto"),
    "fps": ("--fps", None),
    "units": ("--units", "auto"),
    "up": ("--up", None),
    "forward": ("--forward", "auto"),
}


@checks_arguments
def recorded_reading(build: dict[str, Any], given: dict[str, Any], out: Path) -> dict[str, Any]:
    """The reading options to append with: the database's recorded ones, which those given must equal.

    Parameters
    ----------
    build : dict
        The database's ``build`` record (:func:`recorded_build`).
    given : dict
        ``kind``, ``fps``, ``units``, ``up``, ``forward`` as given, None for those not given.
    out : Path
        The database, named in messages.

    Returns
    -------
    dict
        The same keys: the database's values (a database built before they were recorded:
        those given).

    Raises
    ------
    ConfigError
        A value given differs from the database's; the message names the option and both values.
    """
    recorded = build.get("reading")
    if not isinstance(recorded, dict):
        return dict(given)  # built before the options were recorded: read as told, as before
    out_options = {}
    for key, (option, default) in _READING_OPTIONS.items():
        theirs = recorded.get(key, default)
        if key == "kind" and given[key] == "auto":
            given = {**given, key: None}  # auto finds the database's kind, or says there is none
        if key == "fps" and given[key] is not None and theirs is not None and float(given[key]) == float(theirs):
            given = {**given, key: theirs}
        if given[key] is not None and given[key] != theirs:
            shown = "not given" if theirs is None else f"{theirs}"
            raise ConfigError(
                f"--append reads every take as the database at {out} was read: {option} is {given[key]} here and "
                f"{shown} in the database; leave {option} out (the database's is used) or build a new database"
            )
        out_options[key] = theirs
    return out_options


def _append_config(build: dict[str, Any], given: BuildConfig | None, out: Path) -> BuildConfig:
    """The database's build options, checked against those given for the new takes."""
    old = recorded_config(build)
    if given is not None:
        for attr, option in _SHARED_OPTIONS.items():
            if getattr(given, attr) != getattr(old, attr):
                raise ConfigError(
                    f"--append adds takes built as the database's: {option} is {getattr(given, attr)!r} here and "
                    f"{getattr(old, attr)!r} in the database at {out}; give the database's (or leave it out)"
                )
    return old


def _recorded_sources(takes: list[dict], out: Path) -> list[tuple[TakeSource, tuple[str, ...] | None]]:
    """The files the database's takes were read from (with, for a file of several takes, which of them)."""
    from ..datasets.takes import TakeSource

    units: dict[tuple[str, str], tuple[TakeSource, list[str] | None]] = {}
    for t in takes:
        src = t["sources"]
        if "motion" in src and "audio" in src:
            motion, audio = Path(src["motion"]), Path(src["audio"])
            kind = "bvh" if motion.suffix.lower() == ".bvh" else "positions"
            units[("one", src["motion"])] = (TakeSource(kind, motion, audio), None)
            files = [motion, audio]
        elif "file" in src and "sequence" in src:
            entry = units.setdefault(("file", src["file"]), (TakeSource("habibie2021", Path(src["file"]), None), []))
            names = entry[1]
            assert names is not None
            names.append(t["name"])
            files = [Path(src["file"])]
        else:
            raise ConfigError(
                f"take {t['name']!r} of the database at {out} was not read from files "
                f"({', '.join(f'{k}={v}' for k, v in src.items())}), so --append cannot read it again to recompute "
                "the statistics; add --keep-stats to keep the database's, or rebuild"
            )
        for f in files:
            if not f.is_file():
                raise InputFileError(
                    f"the database's take {t['name']!r} was read from this file, which is gone; --append reads the "
                    "old takes again to recompute the statistics: put it back, or add --keep-stats",
                    path=f,
                )
        _check_unchanged(t, src, out)
    return [(s, None if names is None else tuple(names)) for s, names in units.values()]


def _check_kept_stats(stats: dict[str, np.ndarray], out: Path) -> None:
    """Refuse to z-score new takes with statistics that give non-finite features (a zero or
    non-finite std, a non-finite mean): the database's ``stats.npz`` is damaged."""
    for key, value in sorted(stats.items()):
        a = np.asarray(value, dtype=np.float64)
        bad = ~np.isfinite(a) | ((a <= 0) if key.endswith("_std") else False)
        if bad.any():
            what = "zero, negative or non-finite" if key.endswith("_std") else "non-finite"
            raise DatabaseError(
                f"stats.npz: {key} has {int(bad.sum())} {what} values, which would give the new takes non-finite "
                "features; --keep-stats cannot keep these statistics: leave --keep-stats out to recompute them, "
                "or rebuild the database",
                path=out,
            )


def _check_unchanged(take: dict, sources: dict, out: Path) -> None:
    """Refuse a recorded source file whose size or modification time is not what the build read.

    Databases built before these were recorded (no ``KEY_stat``) are not checked; their paths,
    relative to the directory the build ran in, are read relative to the current one, as before.
    """
    for key in ("motion", "audio", "file"):
        stat = sources.get(f"{key}_stat")
        if key not in sources or not isinstance(stat, str):
            continue
        path = Path(sources[key])
        st = path.stat()
        if stat != f"{st.st_size}:{st.st_mtime_ns}":
            size = stat.split(":")[0]
            raise InputFileError(
                f"the database's take {take['name']!r} was read from this file, which has changed since (then "
                f"{size} bytes, now {st.st_size}, and modified since); --append reads the old takes again to "
                "recompute the statistics: put the original back, add --keep-stats to keep the database's "
                f"arrays, or build the database at {out} again (--force)",
                path=path,
            )


@checks_arguments
def build_from_sources(
    sources: Sequence[TakeSource],
    out: Path,
    *,
    config: BuildConfig | None,
    reading: dict[str, Any],
    reading_key: dict[str, Any],
    inputs: Sequence[str | os.PathLike[str]] = (),
    workers: int | None = 1,
    scheduler: str | Client | None = None,
    overwrite: bool = False,
    locked: bool = False,
    append: bool = False,
    keep_stats: bool = False,
    label: str | None = None,
    on_progress: Callable[[BuildProgress], None] | None = None,
    notes: Callable[[str], None] | None = None,
) -> None:
    """Build (or append to) the database folder ``out`` from the takes of ``sources``.

    Parameters
    ----------
    sources : sequence of TakeSource
        The takes' files (:func:`gesturekit.datasets.takes.discover_takes`).
    out : Path
        The database folder.
    config : BuildConfig or None
        How to build (None: the defaults, or with ``append`` the database's).
    reading : dict
        Keyword options of :func:`gesturekit.datasets.takes.iter_takes` (the joint map read already).
    reading_key : dict
        The same options as JSON-able values, for the staging keys.
    inputs : sequence of path
        Folders the output must not overlap.
    workers : int or None
        Worker processes (None: all cores).
    scheduler : str, distributed.Client or None
        A Dask scheduler to stage the takes on instead; the staging folder (beside ``out``) must be
        on a file system every worker reads and writes.
    overwrite : bool
        Replace a database at ``out`` (never anything else).
    locked : bool
        The caller holds ``out``'s output lock.
    append : bool
        Add the takes the database at ``out`` does not hold.
    keep_stats : bool
        With ``append``: keep the database's statistics, thresholds and arrays.
    label : str, optional
        A description stored with the database, instead of ``config``'s (with ``append``:
        instead of the database's; None keeps it).
    on_progress : callable(BuildProgress), optional
        Called as takes are staged.
    notes : callable(str), optional
        Given lines for the build's summary: staged takes reused, what appending did.

    Raises
    ------
    GestureKitError
        Options that do not fit the database appended to, an output that may not be written, a take
        that cannot be read (the message names the file), a recorded source that is gone.
    """
    from ..datasets.takes import count_takes
    from ..outputs import check_output, output_lock, write_folder

    if keep_stats and not append:
        raise ConfigError("--keep-stats keeps the statistics of a database appended to; it needs --append")
    say = notes or (lambda line: None)
    lock = contextlib.nullcontext() if locked else output_lock(out)
    with lock:
        exists = check_output(out, "database", overwrite=overwrite or append, inputs=inputs)
        base: dict[str, Any] | None = None
        units: list[tuple[TakeSource, tuple[str, ...] | None, tuple[str, ...]]]
        if append:
            if not exists:
                raise DatabaseError(
                    "--append adds takes to a database, and there is none here; build it first without --append",
                    path=out,
                )
            base = read_database(out, mmap=True)
            base["path"] = out
            if keep_stats:
                _check_kept_stats(base["stats"], out)
            config = _append_config(base["meta"]["build"], config, out)
            old_label = config.label
            old_names = tuple(t["name"] for t in base["meta"]["takes"])
            units = [(s, None, old_names) for s in sources if s.kind == "habibie2021" or s.motion.stem not in old_names]
            new_units = list(units)
            if not keep_stats:
                units = [(s, o, ()) for s, o in _recorded_sources(base["meta"]["takes"], out)] + units
        else:
            config = config or BuildConfig()
            units = [(s, None, ()) for s in sources]
            new_units = units
        if label is not None:
            config = replace(config, label=label)
        staging = staging_folder(out)
        stored = _stored_skeleton(base, reading, out) if base is not None else None
        open_staging(staging)
        skeleton: Skeleton | None = None
        if reading.get("options") is not None and reading["options"].normalize_bones:
            # appending, only the new takes are read, to check them against the stored skeleton
            skeleton = _fit_skeleton(
                units if stored is None else new_units,
                stored,
                staging,
                reading,
                reading_key,
                config,
                workers,
                scheduler,
                on_progress,
                say,
            )
            reading = {**reading, "options": replace(reading["options"], skeleton=skeleton)}
            reading_key = {**reading_key, "skeleton": skeleton.digest()}
        jobs = _stage_jobs(units, reading, reading_key, config, staging)
        try:
            staged = _stage(jobs, count_takes([s for s, _, _ in units]), workers, scheduler, on_progress, say)
        except BaseException:
            # kept for the next run to resume from, unless nothing was staged (a first take that fails
            # leaves nothing behind)
            if not any(staged_takes(staging, j.key) is not None for j in jobs):
                remove_staging(staging)
            raise
        staged.sort(key=lambda s: s.name)
        n_new = 0
        if append and base is not None:
            n_new = sum(1 for s in staged if s.name not in old_names)
            if n_new == 0:
                unchanged = f"; its label is unchanged ({old_label!r})" if config.label != old_label else ""
                say(f"nothing to append: the database at {out} holds every take of the folder already{unchanged}")
                remove_staging(staging)
                return
        elif not staged:
            raise ConfigError("no takes to build a database from")
        cfg = config

        def fill(tmp: Path) -> None:
            assemble(FolderOut(tmp), staged, cfg, base=base if keep_stats else None, skeleton=skeleton)

        write_folder(out, "database", fill, overwrite=overwrite or append, inputs=inputs, locked=True)
        remove_staging(staging)
        if append and base is not None:
            old = len(old_names)
            if keep_stats:
                say(
                    f"appended {n_new} takes to the database's {old}; statistics and thresholds kept from the "
                    "database (--keep-stats): the new takes are z-scored with them, the old arrays are unchanged"
                )
            else:
                say(
                    f"appended {n_new} takes to the database's {old}; statistics and thresholds recomputed over "
                    f"all {old + n_new} takes (the old takes read again from their files)"
                )


def _stored_skeleton(base: dict, reading: dict[str, Any], out: Path) -> Skeleton | None:
    """The skeleton of the database appended to, checked against ``--normalize-bones``."""
    data = base["meta"].get("skeleton")
    normalize = reading.get("options") is not None and reading["options"].normalize_bones
    if data is None and normalize:
        raise ConfigError(
            f"--normalize-bones gives a database one skeleton, and the database at {out} has none (it was built "
            "without --normalize-bones, or by a gesturekit that normalised each take on its own); leave the option "
            "out, or build the database again with all the takes and --normalize-bones (--force)"
        )
    if data is not None and not normalize:
        raise ConfigError(
            f"the database at {out} gives every take one skeleton (built with --normalize-bones); give "
            "--normalize-bones with --append, so that the new takes get it too"
        )
    return None if data is None else Skeleton.from_json(data)


def _fit_skeleton(
    units: list[tuple[TakeSource, tuple[str, ...] | None, tuple[str, ...]]],
    stored: Skeleton | None,
    staging: Path,
    reading: dict[str, Any],
    reading_key: dict[str, Any],
    config: BuildConfig,
    workers: int | None,
    scheduler: str | Client | None,
    on_progress: Callable[[BuildProgress], None] | None,
    say: Callable[[str], None],
) -> Skeleton:
    """The database's skeleton: fitted over every take of ``units``, or, appending, the ``stored``
    one, which every take of ``units`` (the new ones) must fit.

    Raises
    ------
    ConfigError
        Appending: a take's median length of a bone is more than
        :data:`~gesturekit.bones.FIT_TOLERANCE` from the stored skeleton's (naming the take and bone).
    """
    from ..datasets.takes import count_takes

    plain = {**reading, "options": replace(reading["options"], normalize_bones=False, skeleton=None)}
    key = {**reading_key, "pass": "bone samples"}
    jobs = _stage_jobs(units, plain, key, config, staging)
    total = count_takes([s for s, _, _ in units])
    try:
        sampled = _stage(jobs, total, workers, scheduler, on_progress, say, fn=sample_job, phase="fit")
    except BaseException:
        # kept for the next run to resume from, unless nothing was read
        if not any(staged_takes(staging, j.key) is not None for j in jobs):
            remove_staging(staging)
        raise
    sampled.sort(key=lambda s: s.name)
    if stored is not None:
        try:
            for s in sampled:
                stored.check_fits(np.asarray(s.record["medians"]), take=s.name)
        except ConfigError:
            remove_staging(staging)  # a take that does not fit will not fit the next time either
            raise
        return stored
    if not sampled:
        raise ConfigError("no takes to build a database from")
    joints = sampled[0].record["joints"]
    presence = JointPresence.full() if joints is None else JointPresence(tuple(joints))

    def row(i: int) -> np.ndarray:
        # one row of every take's samples (memory-mapped), so that only one row is in memory
        return np.concatenate([s.load("bones", header=True)[i] for s in sampled])

    return fit_skeleton(row, presence=presence, takes=len(sampled))


def _stage_jobs(
    units: Sequence, reading: dict[str, Any], key: dict[str, Any], config: BuildConfig, staging: Path
) -> list[StageJob]:
    """One :class:`StageJob` per unit ``(source, only, skip)``, keyed by ``key`` (skips are for
    habibie2021 takes alone)."""
    jobs = []
    for s, only, skip in units:
        skip = skip if s.kind == "habibie2021" else ()
        jobs.append(
            StageJob(
                key=job_key(s, key, config, only=only, skip=skip),
                staging=str(staging),
                source=s,
                reading=reading,
                config=config,
                only=only,
                skip=skip,
            )
        )
    return jobs


def _stage(
    jobs: list[StageJob],
    total: int,
    workers: int | None,
    scheduler: str | Client | None,
    on_progress: Callable[[BuildProgress], None] | None,
    say: Callable[[str], None],
    *,
    fn: Callable[[StageJob], dict] | None = None,
    phase: str = "read",
) -> list[StagedTake]:
    """Run the staging jobs (or, with ``fn``, other work of the same units); the staged takes, in the
    order their units finished."""
    staged: list[StagedTake] = []
    seconds = 0.0
    reused = 0
    folders = {j.key: Path(j.staging) / j.key for j in jobs}

    def on_result(job: StageJob, result: dict) -> None:
        nonlocal seconds, reused
        reemit(result["warnings"])
        if result.get("damaged"):
            say(result["damaged"])
        for record in result["takes"]:
            staged.append(StagedTake(folders[job.key], record))
            seconds += float(record["seconds"])
            reused += bool(result["reused"])
        if on_progress is not None and result["takes"]:
            name = result["takes"][-1]["name"]
            on_progress(BuildProgress(len(staged), max(total, len(staged)), name, seconds, reused, phase))

    if fn is None:
        run_jobs(jobs, workers=workers, scheduler=scheduler, on_result=on_result)
    else:
        run_jobs(jobs, workers=workers, scheduler=scheduler, on_result=on_result, fn=fn)
    if reused and phase == "fit":
        say(f"reused the bone samples of {reused} takes read by an interrupted build")
    elif reused:
        say(f"reused {reused} takes staged by an interrupted build")
    return staged
