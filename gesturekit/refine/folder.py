"""A refiner folder's ``config.json``, read without torch (the app checks folders before loading them)."""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

from .._arguments import checks_arguments
from ..errors import DatabaseError, InputFileError
from ..folders import read_json_marker

if TYPE_CHECKING:
    from ..database import MatchingDatabase

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "read_refiner_config",
    "check_layout",
    "trained_on",
    "describe_training",
    "provenance",
]

FORMAT = "gesturekit-refiner"
FORMAT_VERSION = 1
_MESSAGES = {
    "no_folder": "no refiner folder here (train one with `gesturekit train-refiner`)",
    "no_file": "not a refiner folder: config.json is missing",
    "other_format": "config.json does not describe a gesturekit refiner",
    "other_version": "refiner format version {found} is not supported (this gesturekit reads version {supported}); "
    "train it again",
}


@checks_arguments
def read_refiner_config(path: str | os.PathLike) -> dict:
    """The ``config.json`` of a refiner folder, checked for format, version and structure.

    The structure is what training writes: ``model`` (sizes, positive integers),
    ``layout`` (an object), ``joint_names`` (strings), ``iteration`` (an integer
    >= 0), ``files`` (file name -> SHA-256 in hex), and, where present, the
    other sections as objects, flags as booleans and names as strings.

    Raises
    ------
    InputFileError
        No folder, no or unreadable ``config.json``, another format or version,
        or a key of the wrong type.
    """
    path = Path(path)
    cfg = read_json_marker(
        path, "config.json", marker_format=FORMAT, version=FORMAT_VERSION, error=InputFileError, messages=_MESSAGES
    )
    _check_structure(cfg, path)
    return cfg


_SHA256 = re.compile(r"[0-9a-f]{64}")
_MODEL_SIZES = ("audio_dim", "motion_dim", "window")
_MODEL_CHANNELS = ("generator_channels", "critic_channels")


def _positive_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x > 0


def _check_structure(cfg: dict, path: Path) -> None:
    def bad(what: str):
        return InputFileError(f"config.json: {what}; the refiner folder is damaged (train again)", path=path)

    def kind(x) -> str:
        return type(x).__name__

    for key in ("model", "layout", "files"):
        if not isinstance(cfg.get(key), dict):
            raise bad(f"'{key}' must be an object, found {kind(cfg.get(key))}")
    for key in ("training", "data", "database", "pairs", "time"):
        if key in cfg and not isinstance(cfg[key], dict):
            raise bad(f"'{key}' must be an object, found {kind(cfg[key])}")
    for key in ("resumable", "complete"):
        if key in cfg and not isinstance(cfg[key], bool):
            raise bad(f"'{key}' must be true or false, found {cfg[key]!r}")
    for key in ("preset", "device", "gesturekit_version", "torch_version"):
        if key in cfg and not isinstance(cfg[key], str):
            raise bad(f"'{key}' must be a string, found {kind(cfg[key])}")
    it = cfg.get("iteration")
    if not (isinstance(it, int) and not isinstance(it, bool) and it >= 0):
        raise bad(f"'iteration' must be an integer >= 0, found {it!r}")
    names = cfg.get("joint_names")
    if not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
        raise bad("'joint_names' must be a list of joint names")
    for name, digest in cfg["files"].items():
        if not (isinstance(digest, str) and _SHA256.fullmatch(digest)):
            raise bad(f"files.{name} must be the file's SHA-256 in hex, found {digest!r}")
    model = cfg["model"]
    for key in _MODEL_SIZES:
        if key in model and not _positive_int(model[key]):
            raise bad(f"model.{key} must be a positive integer, found {model[key]!r}")
    for key in _MODEL_CHANNELS:
        if key in model and not (isinstance(model[key], list) and all(_positive_int(c) for c in model[key])):
            raise bad(f"model.{key} must be a list of positive integers, found {model[key]!r}")


# ---- what a refiner folder's config.json says of its training ------------------------------------


@checks_arguments
def check_layout(config: dict, db: MatchingDatabase, *, where: str | os.PathLike[str]) -> None:
    """Refuse a database whose features have another layout than a refiner's training data.

    Parameters
    ----------
    config : dict
        The refiner's ``config.json``.
    db : MatchingDatabase
    where : str or path
        The refiner, as the message names it.

    Raises
    ------
    DatabaseError
        Naming the database and the refiner.
    """
    meta = db.meta
    mine = config.get("layout")
    theirs = meta.get("layout")
    if theirs != mine or list(meta.get("joint_names", [])) != list(config.get("joint_names", [])):
        diff = sorted(k for k in set(mine or {}) | set(theirs or {}) if (mine or {}).get(k) != (theirs or {}).get(k))
        detail = f" (differs in: {', '.join(diff)})" if diff else " (another skeleton)"
        raise DatabaseError(
            f"the database has another feature layout than refiner {where} was trained on{detail}; "
            "use a refiner trained on this database (`gesturekit train-refiner --db ...`)",
            path=db.path,
        )


def _speaker(source: str) -> str:
    # the generated demo speaker is the same at any length: "demo (seed 0, 20 min)" -> "demo (seed 0)"
    return re.sub(r",\s*[0-9.]+\s*min\)", ")", source) if source.startswith("demo") else source


@checks_arguments
def trained_on(config: dict, db: MatchingDatabase) -> bool:
    """Whether a refiner (its ``config.json``) was trained on ``db``: the same folder, or the same
    recorded source with the same takes and clips; for the generated demo speaker, the same
    generator seed at any length."""
    trained = config.get("database") or {}
    if db.path is not None and trained.get("path"):
        if Path(trained["path"]).expanduser().resolve() == Path(db.path).expanduser().resolve():
            return True
    source = str(db.meta.get("build", {}).get("source", ""))
    theirs = str(trained.get("source", ""))
    if not source or not theirs:
        return False
    if source.startswith("demo") and theirs.startswith("demo"):
        return _speaker(source) == _speaker(theirs)
    return source == theirs and trained.get("takes") == len(db.take_names) and trained.get("clips") == db.n_clips


@checks_arguments
def describe_training(config: dict) -> str:
    """The training database of a refiner, as its ``config.json`` records it, in a few words."""
    t = config.get("database") or {}
    name = t.get("label") or t.get("source") or t.get("path") or "an unrecorded database"
    counts = f" ({t['takes']} takes, {t['clips']} clips)" if "takes" in t and "clips" in t else ""
    return f"{name}{counts}"


@checks_arguments
def provenance(path: str | os.PathLike[str], config: dict) -> dict:
    """What reproduces a refined result: the refiner's folder, the database it was trained on
    (from its ``config.json``) and the sha256 of its weights (``generator.pt``), hex."""
    folder = Path(path).expanduser().resolve()
    digest = hashlib.sha256()
    with open(folder / "generator.pt", "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    trained = config.get("database") or {}
    return {
        "path": str(folder),
        "trained_on": {k: trained.get(k) for k in ("path", "label", "source", "takes", "clips")},
        "generator_sha256": digest.hexdigest(),
        "preset": config.get("preset"),
        "iteration": config.get("iteration"),
    }
