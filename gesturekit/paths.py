"""Where gesturekit keeps what it generates itself (the demo database, its refiner)."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["home", "default_database_path", "is_file", "is_dir"]


def home() -> Path:
    """gesturekit's own folder: ``$GESTUREKIT_HOME``, else ``~/.cache/gesturekit``."""
    env = os.environ.get("GESTUREKIT_HOME")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "gesturekit"


def default_database_path() -> Path:
    """Where the embedded demo database is built and found by default."""
    return home() / "db" / "demo"


def is_file(path) -> bool:
    """Whether ``path`` names an existing regular file; never raises.

    For text a user typed that may be a file name or something else (a control
    track, a preset name): a name the system cannot look up (longer than 255
    characters, a NUL byte, a loop of links) is not a file rather than an error.
    """
    try:
        return Path(path).is_file()
    except (OSError, ValueError):
        return False


def is_dir(path) -> bool:
    """Whether ``path`` names an existing folder; never raises (see :func:`is_file`)."""
    try:
        return Path(path).is_dir()
    except (OSError, ValueError):
        return False
