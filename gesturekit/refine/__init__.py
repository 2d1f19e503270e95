"""The resynchronisation cGAN ("ResyncNet"): it smooths and re-times the k-NN motion.

- :mod:`~gesturekit.refine.model`: the 1-D U-Net generator and the WGAN critic.
- :mod:`~gesturekit.refine.data`: training pairs (k-NN motion for each window of the overlapping cut).
- :mod:`~gesturekit.refine.train`: WGAN-GP training, presets, checkpoints, resume, loss log.
- :mod:`~gesturekit.refine.infer`: :class:`Refiner`, loading a trained folder and refining any length.

torch is imported by the submodules only, so ``import gesturekit.refine`` stays light.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from .._arguments import checks_arguments
from .._optional import require
from ..errors import GestureKitError
from .folder import check_layout, describe_training, provenance, read_refiner_config, trained_on

if TYPE_CHECKING:
    from ..database import MatchingDatabase
    from ..synthesis import MotionRefiner
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


@checks_arguments
def default_refiner_path() -> Path:
    """The refiner shipped with gesturekit, trained on the default demo database.

    Reproduce it with
    ``gesturekit train-refiner --demo --preset quick --out gesturekit/assets/demo-refiner --force --no-train-state``.
    """
    return Path(__file__).resolve().parents[1] / "assets" / "demo-refiner"


@checks_arguments
def load_refiner(path: str | os.PathLike[str] | None = None, *, device: str = "cpu") -> Refiner:
    """A :class:`~gesturekit.refine.infer.Refiner` from a folder; ``None`` or ``"demo"``: the shipped one."""
    require("torch", purpose="a refiner")
    from .infer import Refiner

    if path is None or str(path) == "demo":
        path = default_refiner_path()
    return Refiner.load(path, device=device)


@checks_arguments
def open_refiner(refiner: MotionRefiner | str | os.PathLike[str] | None) -> MotionRefiner | None:
    """A refiner to give to synthesis: a folder or ``"demo"`` is loaded (:func:`load_refiner`),
    a loaded refiner (any object with ``check_database`` and ``refine_motion``) and None pass through.

    The one place where the command line, the app, evaluation and studies turn a refiner they
    were given into the object :func:`gesturekit.synthesis.synthesize` takes.

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
    >>> from gesturekit.synthesis import synthesize
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


@checks_arguments
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
    path = Path(path).expanduser().resolve()
    check_layout(read_refiner_config(path), db, where=path)
    return path


@checks_arguments
def refiner_for(db: MatchingDatabase) -> Path | None:
    """The refiner applied to ``db`` when none is named: one in ``<db>/refiner`` or the shipped
    demo refiner (:func:`default_refiner_path`), whichever was trained on ``db`` (:func:`trained_on`);
    None when neither was."""
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
