"""Simulated participants with a known ground truth, to check the analysis (:mod:`gesturekit.study.analyse`).

Each system has a true mean rating (on the scale) and a true Bradley-Terry
strength (Elo points). A participant's rating of a stimulus is the system's
true mean plus the participant's own offset (some raters are generous) plus
noise, rounded to the scale and clipped to its ends; a pairwise choice picks
the system that the Bradley-Terry model draws, clearly or slightly, or no
preference. A fraction of careless participants answer at random and fail
attention checks (and sometimes the audio check) far more often than the
attentive ones. The tables have the shapes of :func:`~.analyse.ratings_table`,
:func:`~.analyse.pairwise_table` and :func:`~.analyse.exclusions`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import combinations
from typing import TYPE_CHECKING

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from .analyse import EXCLUSION_COLUMNS, PAIRWISE_COLUMNS, RATING_COLUMNS

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["SCALES", "SimulatedStudy", "simulate_study"]

#: scale name -> (lowest, highest) answer; answers are whole numbers
SCALES: dict[str, tuple[int, int]] = {"likert7": (1, 7), "slider100": (0, 100)}


@dataclass(frozen=True)
class SimulatedStudy:
    """A simulated study's answers and the truth behind them.

    Attributes
    ----------
    ratings : DataFrame
        :func:`~.analyse.ratings_table`'s columns (empty without rating pages).
    pairwise : DataFrame
        :func:`~.analyse.pairwise_table`'s columns (empty without pairwise pages).
    exclusions : DataFrame
        :func:`~.analyse.exclusions`'s columns.
    careless : frozenset of str
        The participants who answered at random.
    true_means : dict of str to float
        Each system's true mean rating (before rounding and clipping).
    true_elo : dict of str to float
        Each system's true Bradley-Terry strength in Elo points.
    """

    ratings: pd.DataFrame
    pairwise: pd.DataFrame
    exclusions: pd.DataFrame
    careless: frozenset[str]
    true_means: dict[str, float]
    true_elo: dict[str, float]


@checks_arguments
def simulate_study(
    true_means: Sequence[float] = (5.0, 4.0, 3.0),
    *,
    systems: Sequence[str] | None = None,
    true_elo: Sequence[float] | None = None,
    participants: int = 24,
    speeches: int = 4,
    prompts: Sequence[str] = ("natural", "sync"),
    scale: str = "likert7",
    participant_sd: float = 0.7,
    noise_sd: float = 1.0,
    rating: bool = True,
    pairwise: bool = True,
    ties: float = 0.15,
    careless: float = 0.1,
    checks: int = 2,
    max_failures: int = 1,
    seed: int = 0,
) -> SimulatedStudy:
    """Simulate a study's answers.

    Parameters
    ----------
    true_means : sequence of float, shape (k,)
        Each system's true mean rating, in the scale's units.
    systems : sequence of str, optional
        The systems' names (default ``S1``, ``S2``, ...).
    true_elo : sequence of float, optional
        Each system's Bradley-Terry strength in Elo points (default: 100 points per unit of
        ``true_means`` on a 7-point scale, so both orders agree).
    participants, speeches : int
        Participants (each rates every speech x system, and compares every pair per speech).
    prompts : sequence of str
        The rating prompts (each answered the same way, with its own noise).
    scale : str
        ``"likert7"`` (1..7) or ``"slider100"`` (0..100).
    participant_sd, noise_sd : float
        Standard deviations of the participants' offsets and of each answer's noise (scale units).
    rating, pairwise : bool
        Which pages the study has.
    ties : float
        Probability of "no preference" on a pairwise page.
    careless : float
        Fraction of careless participants (answering uniformly at random; each fails an attention
        check with probability 0.7 and the audio check with 0.3; attentive ones 0.02 and 0.01).
    checks : int
        Attention checks per participant.
    max_failures : int
        Failed attention checks tolerated before exclusion.
    seed : int
        Seed of everything random.

    Returns
    -------
    SimulatedStudy
    """
    import pandas as pd

    if scale not in SCALES:
        raise ConfigError(f"scale must be one of {sorted(SCALES)}, got {scale!r}")
    means = np.asarray(true_means, dtype=np.float64)
    k = means.size
    names = [f"S{i + 1}" for i in range(k)] if systems is None else [str(s) for s in systems]
    if len(names) != k or k < 1:
        raise ConfigError(f"{len(names)} system names for {k} true means")
    lo, hi = SCALES[scale]
    elo = (means - means.mean()) * 100.0 * 6.0 / (hi - lo) if true_elo is None else np.asarray(true_elo, float)
    rng = np.random.default_rng([seed, 0x51])
    tokens = [f"sim-{p + 1:04d}" for p in range(participants)]
    is_careless = rng.random(participants) < careless
    offsets = rng.normal(0.0, participant_sd, participants)
    ratings, pairs, excl = [], [], []
    for p, token in enumerate(tokens):
        row = p + 1
        if rating:
            for a in range(speeches):
                for s in range(k):
                    for prompt in prompts:
                        if is_careless[p]:
                            value = float(rng.integers(lo, hi + 1))
                        else:
                            value = float(np.clip(np.rint(means[s] + offsets[p] + rng.normal(0, noise_sd)), lo, hi))
                        ratings.append((token, row, f"speech{a + 1}", names[s], str(prompt), value))
        if pairwise:
            for a in range(speeches):
                for i, j in combinations(range(k), 2):
                    left, right = (i, j) if rng.random() < 0.5 else (j, i)
                    if is_careless[p]:
                        value = float(rng.integers(-2, 3))
                    elif rng.random() < ties:
                        value = 0.0
                    else:
                        p_right = 1.0 / (1.0 + 10.0 ** ((elo[left] - elo[right]) / 400.0))
                        sign = 1.0 if rng.random() < p_right else -1.0
                        value = sign * (2.0 if rng.random() < 0.5 else 1.0)
                    pairs.append((token, row, f"speech{a + 1}", names[left], names[right], value))
        fail_p, audio_p = (0.7, 0.3) if is_careless[p] else (0.02, 0.01)
        failed = int(rng.binomial(checks, fail_p))
        audio = bool(rng.random() < audio_p)
        excl.append((token, row, failed, audio, failed > max_failures or audio))
    return SimulatedStudy(
        ratings=pd.DataFrame(ratings, columns=RATING_COLUMNS),
        pairwise=pd.DataFrame(pairs, columns=PAIRWISE_COLUMNS),
        exclusions=pd.DataFrame(excl, columns=EXCLUSION_COLUMNS),
        careless=frozenset(t for t, c in zip(tokens, is_careless) if c),
        true_means=dict(zip(names, means.tolist())),
        true_elo=dict(zip(names, elo.tolist())),
    )
