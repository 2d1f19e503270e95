"""The resynchronisation cGAN ("ResyncNet"): it smooths and re-times the k-NN motion.

- :mod:`~gesturekit.refine.model`: the 1-D U-Net generator and the WGAN critic.
- :mod:`~gesturekit.refine.data`: training pairs (k-NN motion for each window of the overlapping cut).
- :mod:`~gesturekit.refine.train`: WGAN-GP training, presets, checkpoints, resume, loss log.
- :mod:`~gesturekit.refine.infer`: :class:`Refiner`, loading a trained folder and refining any length.

torch is imported by the submodules only, so ``import gesturekit.refine`` stays light.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["default_refiner_path", "load_refiner"]


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
