"""The resynchronisation cGAN ("ResyncNet"): it smooths and re-times the k-NN motion.

- :mod:`~gesturekit.refine.model`: the 1-D U-Net generator and the WGAN critic.
- :mod:`~gesturekit.refine.data`: training pairs (k-NN motion for each window of the overlapping cut).
- :mod:`~gesturekit.refine.train`: WGAN-GP training, presets, checkpoints, resume, loss log.
- :mod:`~gesturekit.refine.infer`: :class:`Refiner`, loading a trained folder and refining any length.

torch is imported by the submodules only, so ``import gesturekit.refine`` stays light.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

from .._optional import require
from ..errors import GestureKitError

if TYPE_CHECKING:
    from ..database import MatchingDatabase
    from ..synthesize import MotionRefiner
    from .infer import Refiner

__all__ = [
    "default_refiner_path",
    "load_refiner",
    "open_refiner",
    "check_layout",
    "check_refiner",
    "trained_on",
    "refiner_for",
    "provenance",
    "describe_training",
]


def default_refiner_path() -> Path:
    """The refiner shipped with gesturekit, trained on the default demo database.

    Reproduce it with
    ``gesturekit train-refiner --demo --preset quick --out gesturekit/assets/demo-refiner --force --no-train-state``.
    """
    return Path(__file__).resolve().parents[1] / "assets" / "demo-refiner"


def load_refiner(path: str | os.PathLike[str] | None = None, *, device: str = "cpu") -> Refiner:
    """A :class:`~gesturekit.refine.infer.Refiner` from a folder; ``None`` or ``"demo"``: the shipped one."""
    require("torch", purpose="a refiner")
    from .infer import Refiner

    if path is None or str(path) == "demo":
        path = default_refiner_path()
    return Refiner.load(path, device=device)


def open_refiner(refiner: MotionRefiner | str | os.PathLike[str] | None) -> MotionRefiner | None:
    """A refiner to give to synthesis: a folder or ``"demo"`` is loaded (:func:`load_refiner`),
    a loaded refiner (any object with ``check_database`` and ``refine_motion``) and None pass through.

    The one place where the command line, the app, evaluation and studies turn a refiner they
    were given into the object :func:`gesturekit.synthesize.synthesize` takes.

    Raises
    ------
    MissingDependencyError
        A folder given, and torch (the ``refiner`` extra) is not installed.
    InputFileError
        No refiner folder there, or a damaged one.

    Examples
    --------
    >>> import tempfile
    >>> from gesturekit.demo import build_demo_database
    >>> from gesturekit.datasets.synthetic import generate_demo_take
    >>> from gesturekit.refine import open_refiner
    >>> from gesturekit.synthesize import synthesize
    >>> refiner = open_refiner("demo")  # the one shipped, trained on the demo speaker
    >>> open_refiner(refiner) is refiner and open_refiner(None) is None
    True
    >>> db = build_demo_database(tempfile.mkdtemp() + "/demo", minutes=0.5)
    >>> res = synthesize(generate_demo_take(seconds=2.0, seed=1, name="speech")[0].audio, db=db, refiner=refiner)
    >>> res.refined_motion is not None and res.motion is res.refined_motion
    True
    >>> res.knn_motion.positions.shape == res.motion.positions.shape
    True
    """
    if refiner is None or not isinstance(refiner, (str, os.PathLike)):
        return refiner
    return load_refiner(refiner)


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
    from ..errors import DatabaseError

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


def check_refiner(path: str | os.PathLike[str], db: MatchingDatabase) -> Path:
    """Check a refiner folder against a database without loading its weights (nor torch).

    Reads ``config.json`` (format, version) and compares the feature layout and
    skeleton with ``db``'s; the weights' hashes and contents are checked when the
    refiner is loaded (:func:`load_refiner`).

    Returns
    -------
    Path
        The folder, resolved.

    Raises
    ------
    InputFileError
        No refiner folder there, or an unreadable or foreign ``config.json``.
    DatabaseError
        Another feature layout than ``db``'s.
    """
    from .folder import read_refiner_config

    path = Path(path).expanduser().resolve()
    check_layout(read_refiner_config(path), db, where=path)
    return path


def _speaker(source: str) -> str:
    # the generated demo speaker is the same at any length: "demo (seed 0, 20 min)" -> "demo (seed 0)"
    return re.sub(r",\s*[0-9.]+\s*min\)", ")", source) if source.startswith("demo") else source


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


def describe_training(config: dict) -> str:
    """The training database of a refiner, as its ``config.json`` records it, in a few words."""
    t = config.get("database") or {}
    name = t.get("label") or t.get("source") or t.get("path") or "an unrecorded database"
    counts = f" ({t['takes']} takes, {t['clips']} clips)" if "takes" in t and "clips" in t else ""
    return f"{name}{counts}"


def refiner_for(db: MatchingDatabase) -> Path | None:
    """The refiner applied to ``db`` when none is named: one in ``<db>/refiner`` or the shipped
    demo refiner (:func:`default_refiner_path`), whichever was trained on ``db`` (:func:`trained_on`);
    None when neither was."""
    from .folder import read_refiner_config

    candidates = ([Path(db.path) / "refiner"] if db.path is not None else []) + [default_refiner_path()]
    for folder in candidates:
        if not (folder / "config.json").is_file():
            continue
        try:
            config = read_refiner_config(folder)
        except GestureKitError:
            continue
        if trained_on(config, db):
            return folder.resolve()
    return None


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
