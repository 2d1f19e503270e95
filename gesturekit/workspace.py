"""A user's files as the command line and the app see them: databases and speech.

One place for what both front ends do with the folders a user names:

- :func:`open_database`: the database folder given, or the demo database at the
  default path (built first if it is missing);
- :func:`database_folders`: the databases a user can pick, the default first;
- :func:`is_generated`: whether a database holds the generated demo speaker;
- :func:`build_database`: read a folder of takes and save its database;
- :func:`speech_files` and :func:`expand_speech`: the speech files of a folder,
  and a list of files and folders as the speech files it names.

Nothing here draws or prints; progress is reported through callbacks.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._arguments import checks_arguments
from .database import BuildConfig, MatchingDatabase
from .datasets.takes import AUDIO_EXTENSIONS, ReadOptions, discover_takes
from .errors import InputFileError
from .paths import default_database_path, home, is_dir

if TYPE_CHECKING:
    from distributed import Client

    from .database import BuildProgress
    from .datasets.positions import PositionJointMap
    from .datasets.presets import JointMap

__all__ = [
    "DEMO_DATABASE_LABEL",
    "database_words",
    "build_database",
    "database_folders",
    "expand_speech",
    "is_generated",
    "open_database",
    "speech_files",
]

#: How :func:`database_folders` names the default (demo) database.
DEMO_DATABASE_LABEL = "demo (generated speaker)"
_GENERATOR_MODULE = "gesturekit.datasets.synthetic"  # what a generated take names as its source


@checks_arguments
def open_database(path: str | os.PathLike | None = None) -> MatchingDatabase:
    """The database at ``path``, or the demo database at the default path when ``path`` is None or empty.

    The demo database is built first when it is missing (see
    :func:`gesturekit.demo.open_default_database`).

    Raises
    ------
    DatabaseError
        No database at ``path``, or one that cannot be read (the message names the folder).
    """
    if path is not None and str(path):
        return MatchingDatabase.load(path)
    from .demo import open_default_database

    return open_default_database()


@checks_arguments
def is_generated(db: MatchingDatabase) -> bool:
    """Whether ``db`` holds the generated demo speaker (or takes of it) rather than recorded motion."""
    if str(db.meta.get("build", {}).get("source", "")).startswith("demo"):
        return True
    return any(
        str(t.get("sources", {}).get("generator", "")).startswith(_GENERATOR_MODULE) for t in db.meta.get("takes", [])
    )


@checks_arguments
def database_folders(*, cwd: str | os.PathLike | None = None) -> dict[str, str]:
    """Databases a user can pick: resolved folder (a string) -> label, the default demo database first.

    The others are the folders holding a ``database.json`` directly inside
    ``<cwd>/db`` and gesturekit's home ``db`` folder (see
    :func:`gesturekit.paths.home`), sorted by name within each, each labelled in words, without
    the server's paths: ``"a database you built: <name>"``, or ``"... (working folder)"`` for one
    in ``<cwd>/db`` whose name is also in the home folder. The default is listed whether or not it
    is built yet.

    Parameters
    ----------
    cwd : path, optional
        The working directory whose ``db`` folder is searched (default: the current one).
    """
    out = {str(default_database_path().expanduser().resolve()): DEMO_DATABASE_LABEL}
    found: list[tuple[Path, str]] = []
    for base, where in ((Path.cwd() if cwd is None else Path(cwd)) / "db", "working folder"), (home() / "db", ""):
        try:
            found += [(p, where) for p in sorted(base.iterdir()) if (p / "database.json").is_file()]
        except OSError:  # no such folder, or one that cannot be listed: nothing to offer there
            continue
    names = [p.name for p, _ in found]
    for p, where in found:
        label = f"a database you built: {p.name}"
        if where and names.count(p.name) > 1:  # the same name in both places: say which one
            label += f" ({where})"
        out.setdefault(str(p.resolve()), label)
    return out


@checks_arguments
def database_words(folder: str | os.PathLike) -> str:
    """A database said in words, as :func:`database_folders` labels it, for pages an audience sees
    (no server path): ``"a database you chose: <name>"`` for one typed in from elsewhere."""
    path = Path(folder).expanduser().resolve()
    return database_folders().get(str(path), f"a database you chose: {path.name}")


@checks_arguments
def build_database(
    folder: str | os.PathLike,
    out: str | os.PathLike,
    *,
    config: BuildConfig | None = None,
    joint_map: str | os.PathLike[str] | None = None,
    kind: str | None = None,
    fps: float | None = None,
    units: str | None = None,
    up: str | None = None,
    forward: str | None = None,
    normalize_bones: bool = False,
    check_plausible: bool = True,
    allow_duration_mismatch: bool = False,
    overwrite: bool = False,
    locked: bool = False,
    progress: Callable[[int, int, str], None] | None = None,
    workers: int | None = 1,
    scheduler: str | Client | None = None,
    append: bool = False,
    keep_stats: bool = False,
    label: str | None = None,
    on_progress: Callable[[BuildProgress], None] | None = None,
    notes: Callable[[str], None] | None = None,
) -> MatchingDatabase:
    """Read the takes of ``folder`` and save their matching database at ``out``.

    What ``gesturekit build-db FOLDER`` and the app's "build from a folder" do.
    The joint map is read before any take, so a bad one fails before the long part.

    Parameters
    ----------
    folder : path
        Folder of takes (see :func:`gesturekit.datasets.takes.discover_takes`).
    out : path
        Database folder to write.
    config : BuildConfig, optional
        How to build; its ``source`` (the folder, resolved) and ``joint_map`` are filled in here.
    joint_map : str, path or None
        ``"zeggs"``, ``"beat"``, the path of a JSON joint map, or None (BVH files: ``zeggs``).
    kind : {"auto", "bvh", "positions", "habibie2021"} or None
        The kind of takes (see :func:`~gesturekit.datasets.takes.discover_takes`); None: ``auto``
        (with ``append``: the database's).
    fps : float, optional
        Frame rate of joint-position files (they do not carry one), frames per second.
    units : {"auto", "m", "cm", "mm"} or None
        Units of the motion files (``auto`` detects them); None: ``auto`` (with ``append``: the
        database's).
    up : {"y", "-y", "z", "-z"} or None
        Up axis of the motion files; None: Y, and every take must look upright (with ``append``:
        the database's).
    forward : {"auto", "x", "-x", "y", "-y", "z", "-z"} or None
        The axis the bodies face; ``auto`` finds it from the shoulders; None: ``auto`` (with
        ``append``: the database's).
    normalize_bones : bool
        Give the database one skeleton (for keypoints whose bone lengths vary from frame to frame
        and take to take): one length per bone over all the takes, and one shape for the finger
        roots on each wrist and the neck and collars on the upper chest
        (:mod:`gesturekit.bones`); the takes are read twice, once to fit it. With ``append``
        the database's skeleton is kept, and a new take that does not fit it is refused.
    check_plausible : bool
        Check what was given against the data (:class:`~gesturekit.datasets.takes.ReadOptions`):
        the body's size in the given units, its uprightness with the given up axis, the joint
        map's skeleton, frames far from the body. False is for the rare data that fails them
        and is right.
    allow_duration_mismatch : bool
        Accept takes whose motion and speech durations differ by more than
        :data:`~gesturekit.datasets.takes.MAX_DURATION_MISMATCH` (else refused, naming the
        frame rate that would make them agree).
    overwrite : bool
        Replace an earlier database at ``out`` (only a database gesturekit built).
    locked : bool
        The caller holds ``out``'s output lock (:func:`gesturekit.outputs.output_lock`).
    progress : callable(done, total, take_name), optional
        Called after each take is read; ``total`` is the number of takes.
    workers : int or None
        Processes that read takes at once (None: all cores). The database is the same, byte for
        byte, for any number.
    scheduler : str, distributed.Client or None
        Read the takes on a Dask cluster instead (``"tcp://host:8786"``); the output's folder
        must be on a file system the cluster's workers share (the takes are staged beside it).
    append : bool
        Add the takes of ``folder`` that the database at ``out`` does not hold (by name). Every
        take, old and new, is read with the reading options the database recorded (``kind``,
        ``fps``, ``units``, ``up``, ``forward``): one left as None takes the database's, one given
        must be the database's (else :class:`~gesturekit.errors.ConfigError`, before anything is
        read); ``normalize_bones`` must be the database's, and ``joint_map`` None means the
        database's. A database built before the options were recorded is read with those given.
    keep_stats : bool
        With ``append``: keep the database's z-scoring statistics, thresholds and arrays (the new
        takes are z-scored with them); without it they are recomputed over every take, reading the
        old takes again from their files.
    label : str, optional
        A description stored with the database, instead of ``config``'s; with ``append`` it
        replaces the database's (None keeps it).
    on_progress : callable(BuildProgress), optional
        Called as takes are read, with takes done and total, hours of data done, takes reused (and
        with ``phase`` ``"fit"`` as they are first read to fit the skeleton).
    notes : callable(str), optional
        Given lines for the summary (takes reused from an interrupted build, what appending did).

    Notes
    -----
    The build is out of core: takes are read one at a time (``workers`` at once), staged beside
    ``out`` in ``.NAME.staging`` and written into the database take by take, so memory does not
    grow with the dataset. An interrupted build is resumed by the same call, which reuses the
    takes staged already (:mod:`gesturekit.database.sources`).

    Returns
    -------
    MatchingDatabase
        The database, saved.

    Raises
    ------
    GestureKitError
        A missing or empty folder, an unreadable joint map or take, an output
        that may not be written; the message names the path.
    """
    from .database.sources import build_from_sources, recorded_build, recorded_reading

    folder = Path(folder).expanduser()
    out = Path(out).expanduser()
    given: dict[str, Any] = {"kind": kind, "fps": fps, "units": units, "up": up, "forward": forward}
    recorded = recorded_build(out) if append else None
    if recorded is not None:
        given = recorded_reading(recorded, given, out)
    kind = given["kind"] or "auto"
    options = ReadOptions(
        units=given["units"] or "auto",
        up=given["up"],
        forward=given["forward"] or "auto",
        normalize_bones=normalize_bones,
        check_plausible=check_plausible,
        allow_duration_mismatch=allow_duration_mismatch,
    )
    sources = discover_takes(folder, kind=kind)
    if recorded is not None and joint_map is None and isinstance(recorded.get("joint_map"), str):
        joint_map = recorded["joint_map"]
    _read_joint_map(joint_map, {s.kind for s in sources})  # read here: a bad one fails before any take
    # what --append reads every take with later
    reading = {
        "kind": sources[0].kind,
        "fps": given["fps"],
        "units": options.units,
        "up": options.up,
        "forward": options.forward,
        "normalize_bones": normalize_bones,
    }
    if config is not None or not append:
        config = replace(
            config or BuildConfig(), source=str(folder.resolve()), joint_map=_recorded_map(joint_map), reading=reading
        )

    def on_take(p: BuildProgress) -> None:
        if progress is not None and p.phase == "read":
            progress(p.done, p.total, p.name)
        if on_progress is not None:
            on_progress(p)

    build_from_sources(
        sources,
        out,
        config=config,
        # the joint map as given: worker processes read it again (a read map does not travel between processes)
        reading={"joint_map": joint_map, "fps_in": given["fps"], "options": options},
        # (the skeleton, fitted in the build, joins the key there)
        reading_key={
            "joint_map": _joint_map_identity(joint_map),
            "fps": given["fps"],
            **{k: v for k, v in asdict(options).items() if k != "skeleton"},
        },
        inputs=[folder],
        workers=workers,
        scheduler=scheduler,
        overwrite=overwrite,
        locked=locked,
        append=append,
        keep_stats=keep_stats,
        label=label,
        on_progress=on_take,
        notes=notes,
    )
    return MatchingDatabase.load(out)


def _recorded_map(joint_map: str | os.PathLike[str] | None) -> str | None:
    """The joint map as ``database.json`` records it: a preset's name, or a file's absolute path
    (so that ``--append`` finds it from any directory)."""
    if joint_map is None:
        return None
    path = Path(joint_map)
    return os.path.abspath(path) if path.is_file() else str(joint_map)


def _joint_map_identity(joint_map: str | os.PathLike[str] | None) -> list | None:
    """A joint map as a staging key sees it: the name or path, and a file's size and modification time."""
    if joint_map is None:
        return None
    path = Path(joint_map)
    try:
        st = path.stat() if path.is_file() else None
    except OSError:
        st = None
    return [str(joint_map)] if st is None else [os.path.abspath(path), st.st_size, st.st_mtime_ns]


def _read_joint_map(
    joint_map: str | os.PathLike[str] | None, kinds: set[str]
) -> str | os.PathLike[str] | JointMap | PositionJointMap | None:
    """``joint_map`` read (and checked) for the kinds of takes found, so a bad one fails before any take
    is read; as given when no take needs it."""
    if joint_map is None:
        return None
    if "bvh" in kinds:
        from .datasets.presets import load_joint_map

        return load_joint_map(joint_map)
    if "positions" in kinds:
        from .datasets.positions import load_position_joint_map

        return load_position_joint_map(joint_map)
    return joint_map


@checks_arguments
def speech_files(folder: str | os.PathLike) -> list[Path]:
    """The speech files directly inside ``folder`` (not recursive), sorted by name.

    A speech file is a regular file whose suffix, in any case, is one of
    :data:`gesturekit.datasets.takes.AUDIO_EXTENSIONS`. The list may be empty.

    Raises
    ------
    InputFileError
        ``folder`` is not a folder.
    """
    folder = Path(folder)
    if not is_dir(folder):
        raise InputFileError("no such folder", path=folder)
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in AUDIO_EXTENSIONS and p.is_file())


@checks_arguments
def expand_speech(items: Iterable[str | os.PathLike]) -> list[Path]:
    """The speech files a list of files and folders names, in its order.

    A folder stands for its speech files (:func:`speech_files`); anything else
    is taken as a file (read, and checked, later).

    Raises
    ------
    InputFileError
        A folder without speech files (the message names it and the suffixes looked for).
    """
    files: list[Path] = []
    for item in items:
        path = Path(item)
        if not is_dir(path):
            files.append(path)
            continue
        found = speech_files(path)
        if not found:
            raise InputFileError(f"no speech files ({'/'.join(AUDIO_EXTENSIONS)}) in this folder", path=path)
        files += found
    return files
