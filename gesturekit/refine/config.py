"""The refiner's training options (:class:`TrainConfig`), apart from the training that needs torch.

The command line reads its options' metadata to make its flags, on installs without torch too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._config import JsonConfig, option, option_of
from ..errors import ConfigError

__all__ = ["TrainConfig"]


@dataclass(frozen=True)
class TrainConfig(JsonConfig):
    """Training schedule and losses; saved in a refiner's ``config.json``.

    Parameters
    ----------
    iterations : int
        Critic iterations in total (the generator is updated on every ``generator_every``-th).
    batch_size : int
        Windows per iteration (paper: 100).
    lr : float
        Adam learning rate of both networks (paper: 1e-4).
    betas : (float, float)
        Adam betas (paper: (0, 0.9)).
    gp_weight : float
        Weight of the gradient penalty (paper: 100).
    l1_weight : float
        Weight of the L1 distance between refined and k-NN motion in the generator loss (paper: 0.1).
    l1_reduction : {"window_sum", "mean"}
        How the L1 distance is reduced. ``window_sum`` (default): summed over a window's
        frames and channels, averaged over the batch; per value its pull (0.1) then
        outweighs the critic's (whose gradient per window has norm about 1, spread
        over 64 x 165 values), so the refiner stays close to the k-NN motion and moves
        it only where the critic insists (joins, timing). ``mean``: averaged over every
        value, which makes the term about 10,000 times weaker and the output free to drift.
    generator_every : int
        The generator is updated on iterations that are multiples of this (paper: 5).
    checkpoint_every : int
        Iterations between checkpoints.
    log_every : int
        Iterations per row of the loss log (each row holds means over them).
    seed : int
        Seed of the initial weights and of every random draw of training.
    """

    OPTIONS_NAME = "training options"

    iterations: int = option(2000, help="critic iterations in total", low=1)
    batch_size: int = option(100, help="windows per iteration", low=1)
    lr: float = option(1e-4, help="Adam learning rate of both networks", low=0.0, low_open=True)
    betas: tuple = (0.0, 0.9)
    gp_weight: float = option(100.0, help="weight of the gradient penalty", low=0.0)
    l1_weight: float = option(0.1, help="weight of the L1 distance to the k-NN motion", low=0.0)
    l1_reduction: str = option("window_sum", help="how the L1 distance is reduced", choices=("window_sum", "mean"))
    generator_every: int = option(5, help="iterations per generator update", low=1)
    checkpoint_every: int = option(250, help="iterations between checkpoints", low=1)
    log_every: int = option(10, help="iterations per row of the loss log", low=1)
    seed: int = option(0, help="seed of the weights, batches and k draws", low=0)

    def __post_init__(self):
        object.__setattr__(self, "betas", tuple(float(b) for b in self.betas))
        for name in ("iterations", "batch_size", "generator_every", "checkpoint_every", "log_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < option_of(TrainConfig, name).low:
                raise ConfigError(f"{name} must be a positive integer, got {v!r}")
        if not self.lr > 0:
            raise ConfigError(f"lr must be positive, got {self.lr}")
        if len(self.betas) != 2 or not all(0 <= b < 1 for b in self.betas):
            raise ConfigError(f"betas must be two numbers in [0, 1), got {self.betas}")
        if self.l1_reduction not in (option_of(TrainConfig, "l1_reduction").choices or ()):
            raise ConfigError(f"l1_reduction must be 'window_sum' or 'mean', got {self.l1_reduction!r}")
        if self.gp_weight < 0 or self.l1_weight < 0:
            raise ConfigError("gp_weight and l1_weight must not be negative")
