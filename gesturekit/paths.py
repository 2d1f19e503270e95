"""Where gesturekit keeps what it generates itself (the demo database, its refiner)."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["home", "default_database_path"]


def home() -> Path:
    """gesturekit's own folder: ``$GESTUREKIT_HOME``, else ``~/.cache/gesturekit``."""
    env = os.environ.get("GESTUREKIT_HOME")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "gesturekit"


def default_database_path() -> Path:
    """Where the embedded demo database is built and found by default."""
    return home() / "db" / "demo"
