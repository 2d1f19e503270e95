"""General file helpers: atomic writes and safe file names, for every writer in gesturekit.

A file either appears complete under its final name or not at all: the
bytes go to a temporary file in the target folder, are flushed to disk and the
temporary file is then renamed onto the target. An existing file is never
replaced unless the caller asks for it. The temporary file's name carries the
writer's process id, so that the next writer of the same file removes what a
killed one left (:func:`gesturekit.outputs.clean_stale`); an ``OSError`` while
writing (disk full, permission denied) is raised as an
:class:`~gesturekit.errors.OutputError` naming the file.
"""

from __future__ import annotations

import hashlib
import os
import re
import unicodedata
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

from .errors import ConfigError

__all__ = ["atomic_write", "write_to", "Target", "safe_filename", "csv_safe"]

# names Windows refuses whatever the extension, compared case-insensitively
_RESERVED_NAMES = frozenset(
    ["CON", "PRN", "AUX", "NUL"] + [f"COM{i}" for i in range(1, 10)] + [f"LPT{i}" for i in range(1, 10)]
)


def atomic_write(path: str | os.PathLike, write_fn: Callable[[BinaryIO], object], *, overwrite: bool = False) -> Path:
    """Write a file atomically: all of it under its final name, or nothing.

    ``write_fn`` receives a binary file object opened on a temporary file in
    the same folder as ``path``; after it returns the file is flushed, synced
    to disk and renamed onto ``path``. If ``write_fn`` raises, the temporary
    file is removed and the exception propagates; ``path`` is left as it was.

    Parameters
    ----------
    path : str or os.PathLike
        The file to create. Its folder must exist.
    write_fn : callable
        ``write_fn(fileobj)``; writes the whole content to ``fileobj`` (what it returns is ignored).
    overwrite : bool
        Replace ``path`` if it exists. When False an existing file is an error,
        also when it appears while ``write_fn`` runs.

    Returns
    -------
    pathlib.Path
        ``path``, complete.

    Raises
    ------
    ConfigError
        ``path`` exists and ``overwrite`` is False, is a folder, or its folder
        does not exist.
    OutputError
        Writing failed (an ``OSError``: disk full, permission denied, ...).
    """
    from .outputs import clean_stale, write_errors

    path = Path(path)
    folder = path.parent
    if path.is_dir():
        raise ConfigError("is a folder, not a file name", path=path)
    if not folder.is_dir():
        raise ConfigError(f"cannot write: folder {str(folder)!r} does not exist", path=path)
    if not overwrite and path.exists():
        raise _exists_error(path)

    with write_errors(path):
        clean_stale(path)
        tmp, fd = _create_temp(folder, path.name)
    try:
        with write_errors(path):
            with os.fdopen(fd, "wb") as f:
                write_fn(f)
                f.flush()
                os.fsync(f.fileno())
            if overwrite:
                os.replace(tmp, path)
            else:
                _move_no_clobber(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _sync_folder(folder)
    return path


#: Where a writer puts its bytes: a path (written atomically) or a binary file object opened for writing.
Target = str | os.PathLike | BinaryIO


def target_path(target: Target, default: str) -> Path:
    """The path a writer names in its messages and reports: ``target`` itself, or a file object's
    ``name`` (an open file's), else ``default`` (an ``io.BytesIO``)."""
    if isinstance(target, (str, os.PathLike)):
        return Path(target)
    name = getattr(target, "name", None)
    return Path(name) if isinstance(name, str) and name else Path(default)


def write_to(target: Target, write_fn: Callable[[BinaryIO], object], *, overwrite: bool = False) -> Path | None:
    """Write to a path atomically (:func:`atomic_write`) or into an open binary file object.

    Parameters
    ----------
    target : str, os.PathLike or binary file object
        A path, or an object with a ``write(bytes)`` method (``io.BytesIO``, an open file, a
        response stream): then ``write_fn`` writes into it at its current position and the
        caller owns it (nothing is flushed or closed).
    write_fn : callable
        ``write_fn(fileobj)``; writes the whole content.
    overwrite : bool
        For a path: replace it if it exists (see :func:`atomic_write`).

    Returns
    -------
    pathlib.Path or None
        The path written, None for a file object.
    """
    if isinstance(target, (str, os.PathLike)):
        return atomic_write(target, write_fn, overwrite=overwrite)
    write_fn(target)
    return None


def _exists_error(path: Path) -> ConfigError:
    return ConfigError("already exists; pass overwrite=True (--force on the command line) to replace it", path=path)


def _create_temp(folder: Path, name: str) -> tuple[Path, int]:
    # os.open with mode 0o666 lets the umask decide the permissions, as for any new file
    # (tempfile would make it private to the owner, and the rename would keep that)
    while True:
        # the process id lets a later writer tell a killed writer's leftover from a running one's file
        tmp = folder / f".{name[:64]}.{os.getpid()}-{uuid.uuid4().hex[:12]}.tmp"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        except FileExistsError:
            continue
        return tmp, fd


def _move_no_clobber(tmp: Path, path: Path) -> None:
    # a hard link fails if the target exists, so a file created meanwhile is never replaced;
    # filesystems without hard links fall back to check-then-rename
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise _exists_error(path) from None
    except OSError:
        if path.exists():
            raise _exists_error(path) from None
        os.replace(tmp, path)
        return
    os.unlink(tmp)


def _sync_folder(folder: Path) -> None:
    # makes the rename itself durable; folders cannot be opened like this on Windows
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def safe_filename(name: str, *, max_length: int = 100, default: str = "unnamed") -> str:
    """A file name made from a user-supplied name, safe on every common filesystem.

    Accents are dropped (``"café"`` -> ``"cafe"``); every character other than
    ASCII letters, digits, ``.``, ``_`` and ``-`` becomes ``_`` (so no path
    separators, control characters or spaces remain); runs of ``_`` and of
    ``.`` are collapsed (so ``..`` never appears); leading dots, underscores
    and hyphens and trailing dots and underscores are removed, and names Windows reserves (``CON``,
    ``NUL``, ...) get a leading ``_``. A name that ends up empty becomes
    ``default`` followed by a hash of the input; a name longer than
    ``max_length`` is cut and ends with such a hash, so that different long
    inputs give different names. The result depends only on the arguments.

    Parameters
    ----------
    name : str
        The user's name (a take name, a title), not a path.
    max_length : int
        Longest result, characters; at least 16.
    default : str
        Stem for names with no usable character.

    Returns
    -------
    str
        A non-empty name of at most ``max_length`` characters matching
        ``[A-Za-z0-9_][A-Za-z0-9._-]*``.
    """
    if not isinstance(name, str):
        raise ConfigError(f"a file name must be a string, got {type(name).__name__}")
    if max_length < 16:
        raise ConfigError(f"max_length must be at least 16, got {max_length}")
    digest = hashlib.sha1(name.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    ascii_name = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode("ascii")
    clean = re.sub(r"[^A-Za-z0-9._-]", "_", ascii_name)
    clean = re.sub(r"_+", "_", clean)
    clean = re.sub(r"\.+", ".", clean)
    # no hidden files, no names a command line would take for an option, no trailing dot
    clean = re.sub(r"^[._-]+", "", clean)
    clean = re.sub(r"[._]+$", "", clean)
    if not clean:
        return f"{_clean_default(default)}-{digest}"[:max_length]
    if clean.split(".")[0].upper() in _RESERVED_NAMES:
        clean = "_" + clean
    if len(clean) > max_length:
        clean = clean[: max_length - len(digest) - 1].rstrip("._-") + "-" + digest
    return clean


def _clean_default(default: str) -> str:
    clean = re.sub(r"[^A-Za-z0-9_-]", "_", default).strip("_")
    return clean or "unnamed"


#: what a spreadsheet takes for the start of a formula (and the tab and carriage return that hide one)
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_safe(frame: Any) -> Any:
    """A copy of a DataFrame whose text cells cannot run as spreadsheet formulas.

    A text cell that starts with ``= + - @``, a tab or a carriage return gets a leading ``'``
    (the OWASP advice for CSV injection), unless it is a plain number such as ``-2``; numbers
    themselves are left alone.
    """
    import pandas as pd

    def cell(value: Any) -> Any:
        if isinstance(value, str) and value.startswith(_FORMULA_START):
            try:
                float(value)
                return value
            except ValueError:
                return "'" + value
        return value

    out = frame.copy()
    for column in out.columns:
        if out[column].dtype == object or pd.api.types.is_string_dtype(out[column]):
            out[column] = out[column].map(cell)
    if out.columns.dtype == object:
        out.columns = [cell(c) for c in out.columns]
    return out
