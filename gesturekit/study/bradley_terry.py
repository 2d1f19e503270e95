"""Bradley-Terry scores of pairwise answers: win counts, a vectorised fit, bootstrap intervals, and the
connected parts of the comparison graph (each scored on its own).

The pairwise table is :func:`gesturekit.study.analyse.pairwise_table`'s (``participant``, ``system_left``,
``system_right``, ``value`` in -2..2, negative: the left one preferred).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ELO_SCALE", "bt_win_counts", "bt_fit", "comparison_groups", "bradley_terry", "pairwise_systems"]

#: Elo points per natural-log unit of Bradley-Terry strength: 400 points = a factor of 10 in the odds
ELO_SCALE = 400.0 / math.log(10.0)


@checks_arguments
def bt_win_counts(pairwise: pd.DataFrame, systems: Sequence[str]) -> tuple[list[str], np.ndarray]:
    """Each participant's wins of system i over j.

    A clear or slight preference (|value| >= 1) counts 2 for the preferred system; no preference
    (0) counts 1 for each, so that a tie is half a win each way.

    Returns
    -------
    participants : list of str
    counts : np.ndarray, shape (participants, k, k), float
        ``counts[p, i, j]``: participant p's wins of ``systems[i]`` over ``systems[j]``.
    """
    index = {s: i for i, s in enumerate(systems)}
    participants = sorted(set(pairwise["participant"].astype(str)))
    p_index = {p: i for i, p in enumerate(participants)}
    counts = np.zeros((len(participants), len(systems), len(systems)))
    for p, left, right, v in zip(
        pairwise["participant"].astype(str), pairwise["system_left"], pairwise["system_right"], pairwise["value"]
    ):
        i, j, k = p_index[p], index[left], index[right]
        if v < 0:
            counts[i, j, k] += 2
        elif v > 0:
            counts[i, k, j] += 2
        else:
            counts[i, j, k] += 1
            counts[i, k, j] += 1
    return participants, counts


@checks_arguments
def bt_fit(wins: np.ndarray, *, prior: float = 1.0, tol: float = 1e-10, max_iter: int = 100) -> np.ndarray:
    """Maximum-likelihood Bradley-Terry log-strengths of many win matrices at once (Newton's method).

    P(i beats j) = 1 / (1 + exp(theta_j - theta_i)). Every pair starts with ``prior`` wins each
    way (``prior`` ties' worth: a weak pull towards equal strength that keeps the fit finite when
    a system wins every comparison).

    Parameters
    ----------
    wins : np.ndarray, shape (..., k, k)
        ``wins[..., i, j]``: wins of i over j (the diagonal is ignored).
    prior : float
        Pseudo-wins added both ways for every pair; > 0 unless every pair is compared both ways.
    tol : float
        Stop when no strength moves by more than this.
    max_iter : int
        Newton steps at most.

    Returns
    -------
    np.ndarray, shape (..., k)
        Log-strengths, mean 0 (natural-log units; times :data:`ELO_SCALE` for Elo points).
    """
    w = np.array(wins, dtype=np.float64)
    k = w.shape[-1]
    eye = np.eye(k, dtype=bool)
    w = np.where(eye, 0.0, w + prior)
    n = w + np.swapaxes(w, -1, -2)
    total = w.sum(axis=-1)
    theta = np.zeros(w.shape[:-1])
    centre = np.ones((k, k)) / k
    for _ in range(max_iter):
        sig = 1.0 / (1.0 + np.exp(theta[..., None, :] - theta[..., :, None]))  # P(i beats j)
        grad = total - (n * sig).sum(axis=-1)
        h = n * sig * (1.0 - sig)
        lap = np.where(eye, h.sum(axis=-1)[..., None] * eye, -h)  # the negative Hessian
        # the likelihood ignores a common shift: fix it by asking for mean 0 (the 1 1^T / k term)
        step = np.linalg.solve(lap + centre, grad[..., None])[..., 0]
        theta = theta + step
        theta -= theta.mean(axis=-1, keepdims=True)
        if np.max(np.abs(step)) < tol:
            break
    return theta


@checks_arguments
def comparison_groups(pairwise: pd.DataFrame) -> list[list[str]]:
    """The connected parts of the comparison graph (systems joined where some pair of them was compared).

    Returns
    -------
    list of list of str
        Each part's systems, sorted; the parts ordered by their first system. One part: every system
        can be placed on one scale; more: scores of different parts are not comparable.
    """
    parent: dict[str, str] = {}

    def root(x: str) -> str:
        while parent.setdefault(x, x) != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for left, right in zip(pairwise["system_left"].astype(str), pairwise["system_right"].astype(str)):
        parent[root(left)] = root(right)
    parts: dict[str, list[str]] = {}
    for system in sorted(parent):
        parts.setdefault(root(system), []).append(system)
    return sorted(parts.values())


@checks_arguments
def bradley_terry(
    pairwise: pd.DataFrame,
    *,
    systems: Sequence[str] | None = None,
    rounds: int = 10_000,
    seed: int = 0,
    level: float = 0.95,
    prior: float = 1.0,
) -> pd.DataFrame:
    """Bradley-Terry scores on an Elo-like scale, with percentile bootstrap intervals over participants.

    Each connected part of the comparison graph (:func:`comparison_groups`) is scored on its own: where
    no chain of comparisons joins two systems, the data say nothing about their order, and one fit would
    place them by the prior alone. The point estimate is fitted by choix (``ilsr_pairwise``); each
    bootstrap round resamples the part's participants with replacement and refits by :func:`bt_fit`,
    all rounds at once. Scores are 400 log10(strength), anchored so that their mean within the part is
    0: a system 400 points above another is preferred with odds 10 : 1.

    Parameters
    ----------
    systems : sequence of str, optional
        Order of the systems (default sorted); systems never compared pairwise are left out.

    Returns
    -------
    DataFrame
        ``system``, ``group`` (1-based part of the comparison graph), ``elo``, ``elo_lo``, ``elo_hi``,
        ``wins``, ``losses``, ``ties`` (comparisons), sorted by part, then best first.
    """
    import pandas as pd

    from .._optional import require

    choix = require("choix", purpose="Bradley-Terry scores")
    parts = comparison_groups(pairwise)
    if not parts:
        raise ConfigError("Bradley-Terry needs pairwise answers comparing at least two systems")
    order = {s: i for i, s in enumerate(sorted(pairwise_systems(pairwise)) if systems is None else systems)}
    tables = []
    for g, part in enumerate(parts):
        part = sorted(part, key=lambda s: (order.get(s, len(order)), s))
        mine = pairwise[pairwise["system_left"].astype(str).isin(part)]
        seeds = [seed, 0xB7] + ([g] if g else [])
        table = _bt_part(choix, mine, part, rounds=rounds, seed=seeds, level=level, prior=prior)
        table.insert(1, "group", g + 1)
        tables.append(table)
    table = pd.concat(tables, ignore_index=True)
    return table.sort_values(["group", "elo", "system"], ascending=[True, False, True]).reset_index(drop=True)


@checks_arguments
def pairwise_systems(pairwise: pd.DataFrame) -> set[str]:
    """Every system of a pairwise table."""
    return set(pairwise["system_left"].astype(str)) | set(pairwise["system_right"].astype(str))


def _bt_part(
    choix: Any, pairwise: pd.DataFrame, systems: list[str], *, rounds: int, seed: list[int], level: float, prior: float
) -> pd.DataFrame:
    """:func:`bradley_terry` of one connected part of the comparison graph."""
    import pandas as pd

    participants, counts = bt_win_counts(pairwise, systems)
    if not participants or len(systems) < 2:
        raise ConfigError("Bradley-Terry needs pairwise answers comparing at least two systems")
    total = counts.sum(axis=0)
    theta = _bt_choix(choix, total, prior)
    rng = np.random.default_rng(seed)
    boot = []
    block = max(1, 2_000_000 // max(1, len(participants) * len(systems) ** 2))
    flat = counts.reshape(len(participants), -1)
    for start in range(0, int(rounds), block):
        m = min(block, int(rounds) - start)
        pick = rng.integers(0, len(participants), size=(m, len(participants)))
        # how often each round drew each participant, all rounds in one bincount
        offsets = pick + len(participants) * np.arange(m)[:, None]
        weights = np.bincount(offsets.ravel(), minlength=m * len(participants)).reshape(m, -1).astype(np.float64)
        boot.append(bt_fit((weights @ flat).reshape(m, len(systems), len(systems)), prior=prior))
    q = [50 * (1 - level), 50 * (1 + level)]
    lo, hi = np.percentile(np.concatenate(boot) * ELO_SCALE, q, axis=0)
    zero = ~(hi > lo)  # one participant: every resample is the data itself, a point and no interval
    lo, hi = np.where(zero, np.nan, lo), np.where(zero, np.nan, hi)
    wins = {s: 0 for s in systems}
    losses = {s: 0 for s in systems}
    ties = {s: 0 for s in systems}
    for left, right, v in zip(pairwise["system_left"], pairwise["system_right"], pairwise["value"]):
        if v == 0:
            ties[left] += 1
            ties[right] += 1
        else:
            winner, loser = (left, right) if v < 0 else (right, left)
            wins[winner] += 1
            losses[loser] += 1
    return pd.DataFrame(
        {
            "system": systems,
            "elo": theta * ELO_SCALE,
            "elo_lo": lo,
            "elo_hi": hi,
            "wins": [wins[s] for s in systems],
            "losses": [losses[s] for s in systems],
            "ties": [ties[s] for s in systems],
        }
    )


def _bt_choix(choix: Any, wins: np.ndarray, prior: float) -> np.ndarray:
    """choix's maximum-likelihood log-strengths of one win matrix (with the prior as whole comparisons).

    choix takes a list of (winner, loser) comparisons: counts are scaled to whole numbers (wins
    count 2 and ties 1 each way, the prior ``prior`` each way, all integers when ``prior`` is).
    """
    k = wins.shape[0]
    data = []
    for i in range(k):
        for j in range(k):
            if i != j:
                data.extend([(i, j)] * int(round(wins[i, j] + prior)))
    theta = np.asarray(choix.ilsr_pairwise(k, data, alpha=0.0, tol=1e-12), dtype=np.float64)
    return theta - theta.mean()
