"""Where gesturekit keeps what it generates itself (the demo database, its refiner), and which
folders a served app may read and write (:func:`allowed_roots`, :func:`check_allowed`)."""

from __future__ import annotations

import os
from pathlib import Path

from ._arguments import checks_arguments
from .errors import ConfigError

__all__ = [
    "APP_ROOTS_ENV",
    "PathNotAllowedError",
    "allowed_roots",
    "assets",
    "check_allowed",
    "default_database_path",
    "home",
    "is_allowed",
    "is_dir",
    "is_file",
]

#: Environment variable listing more folders the app may read and write (``os.pathsep``-separated).
APP_ROOTS_ENV = "GESTUREKIT_APP_ROOTS"


class PathNotAllowedError(ConfigError):
    """A path lies outside the folders the app may use (see :func:`check_allowed`)."""


@checks_arguments
def home() -> Path:
    """gesturekit's own folder: ``$GESTUREKIT_HOME``, else ``~/.cache/gesturekit``."""
    env = os.environ.get("GESTUREKIT_HOME")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "gesturekit"


@checks_arguments
def default_database_path() -> Path:
    """Where the embedded demo database is built and found by default."""
    return home() / "db" / "demo"


@checks_arguments
def assets() -> Path:
    """The files shipped inside the package (the demo refiner); read-only for the app."""
    return Path(__file__).resolve().parent / "assets"


@checks_arguments
def allowed_roots(*, write: bool = False) -> tuple[Path, ...]:
    """The folders the app may use, resolved, in this order, without repeats.

    gesturekit's :func:`home`, ``./db`` of the working directory, and every
    folder listed in ``$GESTUREKIT_APP_ROOTS`` (separated by ``os.pathsep``;
    empty entries are skipped, relative ones are taken from the working
    directory). For reading, the package's :func:`assets` (the demo refiner)
    come last. The folders need not exist.

    Parameters
    ----------
    write : bool
        The roots for writing: the same without the package's assets.

    Returns
    -------
    tuple of Path
        Absolute paths with symbolic links and ``..`` resolved.
    """
    roots = [home(), Path.cwd() / "db"]
    roots += [Path(entry.strip()) for entry in os.environ.get(APP_ROOTS_ENV, "").split(os.pathsep) if entry.strip()]
    if not write:
        roots.append(assets())
    out: list[Path] = []
    for root in roots:
        resolved = root.expanduser().resolve()
        if resolved not in out:
            out.append(resolved)
    return tuple(out)


@checks_arguments
def is_allowed(path: str | os.PathLike, *, write: bool = False) -> bool:
    """Whether ``path``, with symbolic links and ``..`` resolved, lies in one of :func:`allowed_roots`."""
    return _inside(Path(path).expanduser().resolve(), allowed_roots(write=write))


def _inside(resolved: Path, roots: tuple[Path, ...]) -> bool:
    return any(resolved == root or resolved.is_relative_to(root) for root in roots)


@checks_arguments
def check_allowed(path: str | os.PathLike, *, what: str, write: bool = False) -> Path:
    """Refuse a path outside the folders the app may use; return it resolved.

    Whether the path exists plays no part: a refused path gets the same
    message either way, so that a user cannot learn which folders a server has.

    Parameters
    ----------
    path : str or os.PathLike
        As the user typed it (``~`` is expanded).
    what : str
        What the path is for, as the message should say it (``"database folder"``).
    write : bool
        The path will be written: the package's assets are not allowed.

    Returns
    -------
    Path
        The absolute path, symbolic links and ``..`` resolved.

    Raises
    ------
    ConfigError
        ``path`` is empty.
    PathNotAllowedError
        ``path`` lies outside :func:`allowed_roots`; the message names the
        path as typed and how to allow a folder, not the allowed folders
        (server paths).
    """
    if not str(path).strip():
        raise ConfigError(f"type the {what}")
    resolved = Path(path).expanduser().resolve()
    roots = allowed_roots(write=write)
    if _inside(resolved, roots):
        return resolved
    # the roots themselves are not listed: they are the server's paths (its home, where the package
    # is installed), which a visitor of a served app has no business knowing
    raise PathNotAllowedError(
        f"the {what} is outside the allowed folders{' for writing' if write else ''}; whoever runs the server "
        f"can allow a folder by adding it to the {APP_ROOTS_ENV} environment variable",
        path=path,
    )


@checks_arguments
def is_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names an existing regular file; never raises.

    For text a user typed that may be a file name or something else (a control
    track, a preset name): a name the system cannot look up (longer than 255
    characters, a NUL byte, a loop of links) is not a file rather than an error.
    """
    try:
        return Path(path).is_file()
    except (OSError, ValueError):
        return False


@checks_arguments
def is_dir(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names an existing folder; never raises (see :func:`is_file`)."""
    try:
        return Path(path).is_dir()
    except (OSError, ValueError):
        return False
