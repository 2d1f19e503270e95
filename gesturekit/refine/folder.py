"""A refiner folder's ``config.json``, read without torch (the app checks folders before loading them)."""
from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import InputFileError

__all__ = ["FORMAT", "FORMAT_VERSION", "read_refiner_config"]

FORMAT = "gesturekit-refiner"
FORMAT_VERSION = 1


def read_refiner_config(path: str | os.PathLike) -> dict:
    """The ``config.json`` of a refiner folder, checked for format and version.

    Raises
    ------
    InputFileError
        No folder, no or unreadable ``config.json``, another format or version.
    """
    path = Path(path)
    if not path.is_dir():
        raise InputFileError("no refiner folder here (train one with `gesturekit train-refiner`)", path=path)
    cfg_file = path / "config.json"
    if not cfg_file.is_file():
        raise InputFileError("not a refiner folder: config.json is missing", path=path)
    try:
        cfg = json.loads(cfg_file.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputFileError(f"config.json is not valid JSON ({exc})", path=path) from None
    if not isinstance(cfg, dict) or cfg.get("format") != FORMAT:
        raise InputFileError("config.json does not describe a gesturekit refiner", path=path)
    if cfg.get("format_version") != FORMAT_VERSION:
        raise InputFileError(
            f"refiner format version {cfg.get('format_version')} is not supported (this gesturekit reads "
            f"version {FORMAT_VERSION}); train it again",
            path=path,
        )
    return cfg
