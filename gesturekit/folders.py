"""gesturekit's own output folders: their kinds, their marker files, and telling one from any folder.

Each kind of folder gesturekit writes (a database, a refiner, a study, ...) holds a JSON
marker naming its format and version. :func:`read_json_marker` reads a marker for its
kind's reader; :func:`folder_kind` tells which kind a folder is, so that an output is
only ever replaced when it is one of ours.
"""

from __future__ import annotations

import os
from pathlib import Path

from ._arguments import checks_arguments
from .errors import GestureKitError
from .limits import read_json
from .paths import is_dir

__all__ = ["FOLDER_KINDS", "read_json_marker", "folder_kind"]

#: Folder kinds gesturekit writes: kind -> (marker file, its ``format`` value, what it is called in messages).
FOLDER_KINDS = {
    "database": ("database.json", "gesturekit-matching-database", "a matching database"),
    "refiner": ("config.json", "gesturekit-refiner", "a refiner folder"),
    "study": ("study.json", "gesturekit-study", "a study folder"),
    "fgd": ("fgd.json", "gesturekit-fgd-autoencoder", "an FGD model folder"),
    "evaluation": ("evaluation.json", "gesturekit-evaluation", "an evaluation folder"),
}

# every name a folder of each kind can hold, its marker included (a database's are
# gesturekit.database.folder.FOLDER_FILES, listed here too so that a folder is recognised below
# the database; tests/base/test_outputs.py checks that the two agree)
_FOLDER_NAMES = {
    "database": frozenset(
        [f"{a}.npy" for a in ("F", "P", "G", "A", "valid", "attributes", "pose_track", "clip_take", "clip_start")]
        + ["audio.npy", "stats.npz", "overlap", "database.json"]
    ),
    "refiner": frozenset(["config.json", "generator.pt", "critic.pt", "train_state.pt", "stats.npz", "loss_log.csv"]),
    "study": frozenset(["study.json", "manifest.csv", "order.csv", "videos"]),
    "fgd": frozenset(["fgd.json", "weights.pt"]),
    "evaluation": frozenset(["evaluation.json", "results.csv", "results.md", "controls.csv", "controls.md"]),
}


@checks_arguments
def read_json_marker(
    folder: str | os.PathLike,
    name: str,
    *,
    marker_format: str,
    version: int,
    error: type[GestureKitError],
    messages: dict[str, str],
) -> dict:
    """The JSON marker file ``name`` of an output folder (a database, a refiner), of the right format.

    Only the marker's ``format`` and ``format_version`` are checked; the caller
    checks the rest of its structure.

    Parameters
    ----------
    folder : str or os.PathLike
        The folder that should hold the marker.
    name : str
        The marker's file name, such as ``"database.json"``.
    marker_format : str
        The marker's expected ``format`` entry.
    version : int
        The ``format_version`` this gesturekit reads.
    error : type
        The :class:`~gesturekit.errors.GestureKitError` subclass to raise, naming ``folder``.
    messages : dict of str
        What to say when ``folder`` is no folder (``"no_folder"``), lacks the
        marker (``"no_file"``), holds another format (``"other_format"``) or
        another version (``"other_version"``, formatted with ``found`` and
        ``supported``); each says how to make the right folder.

    Returns
    -------
    dict
        The marker's content.

    Raises
    ------
    GestureKitError
        Of type ``error``: no folder, no marker file, a marker that is not
        readable UTF-8 JSON, or one of another format or version.
    """
    folder = Path(folder)
    marker = folder / name
    if not is_dir(folder):
        raise error(messages["no_folder"], path=folder)
    if not os.path.lexists(marker):
        raise error(messages["no_file"], path=folder)
    content = read_json(marker, what=f"{name} ", error=error, owner=folder)
    if not isinstance(content, dict) or content.get("format") != marker_format:
        raise error(messages["other_format"], path=folder)
    if content.get("format_version") != version:
        raise error(
            messages["other_version"].format(found=content.get("format_version"), supported=version), path=folder
        )
    return content


@checks_arguments
def folder_kind(path: str | os.PathLike[str]) -> str | None:
    """Which of gesturekit's folders (a key of :data:`FOLDER_KINDS`) ``path`` is, from its marker file.

    A marker that cannot be read (damaged, not JSON) or has no ``format`` (written by an
    earlier gesturekit) still counts when every name in the folder is one that kind of
    folder holds: a database whose ``database.json`` was cut short can be rebuilt in place.

    Parameters
    ----------
    path : str or os.PathLike
        An existing folder.

    Returns
    -------
    str or None
        The kind, or None when the folder is none of gesturekit's.
    """
    path = Path(path)
    names = None
    for kind, (marker, fmt, _) in FOLDER_KINDS.items():
        if not os.path.lexists(path / marker):
            continue
        if not os.path.isfile(path / marker):
            continue  # a FIFO or a device in a marker's place: nothing gesturekit wrote, never read
        try:
            meta = read_json(path / marker)
        except GestureKitError:  # not a regular file, too large, not JSON: a damaged marker
            meta = None
        if isinstance(meta, dict):
            if meta.get("format") == fmt:
                return kind
            if "format" in meta:
                continue
        if names is None:
            names = {p.name for p in path.iterdir()}
        if names and names <= _FOLDER_NAMES[kind]:
            return kind
    return None
