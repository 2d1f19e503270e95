"""The resynchronisation cGAN ("ResyncNet"): it smooths and re-times the k-NN motion.

- :mod:`~gesturekit.refine.model`: the 1-D U-Net generator and the WGAN critic.
- :mod:`~gesturekit.refine.data`: training pairs (k-NN motion for each window of the overlapping cut).
- :mod:`~gesturekit.refine.train`: WGAN-GP training, presets, checkpoints, resume, loss log.
- :mod:`~gesturekit.refine.infer`: :class:`Refiner`, loading a trained folder and refining any length.

torch is imported by the submodules only, so ``import gesturekit.refine`` stays light.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["default_refiner_path", "load_refiner", "check_layout", "check_refiner"]


def default_refiner_path() -> Path:
    """The refiner shipped with gesturekit, trained on the default demo database.

    Reproduce it with
    ``gesturekit train-refiner --demo --preset quick --out gesturekit/assets/demo-refiner --force --no-train-state``.
    """
    return Path(__file__).resolve().parents[1] / "assets" / "demo-refiner"


def load_refiner(path=None, *, device: str = "cpu"):
    """A :class:`~gesturekit.refine.infer.Refiner` from a folder; ``None`` or ``"demo"``: the shipped one."""
    from .infer import Refiner

    if path is None or str(path) == "demo":
        path = default_refiner_path()
    return Refiner.load(path, device=device)


def check_layout(config: dict, db, *, where) -> None:
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


def check_refiner(path, db) -> Path:
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
