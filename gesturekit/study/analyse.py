"""The analysis of a study's answers: exclusions, per system statistics, pairwise tests, Bradley-Terry.

The answers arrive as the store keeps them (one row per participant and page,
:meth:`Store.responses_frame`) and are turned into long-form tables joined
with the study's key (``manifest.csv``): :func:`ratings_table` (participant,
row, speech, system, prompt, value) and :func:`pairwise_table` (participant,
speech, system_left, system_right, value, -2 = clearly left .. +2 = clearly
right). :func:`exclusions` counts each participant's failed attention checks
and the audio check. Everything after that works on these tables, so a
simulated study (:mod:`gesturekit.study.simulate`) or an imported HEMVIP one
is analysed by the same code:

- per system (and per prompt) the mean and the median over participants of
  each participant's mean rating, with percentile bootstrap 95 % intervals
  over participants (:func:`system_summary`);
- for every pair of systems the Wilcoxon signed-rank test on the
  participants' means, Holm-Bonferroni adjusted within each prompt
  (:func:`holm`), with the matched-pairs rank-biserial correlation as the
  effect size (:func:`pairwise_tests`);
- for pairwise pages a Bradley-Terry model on an Elo-like scale, with a
  bootstrap over participants (:func:`bradley_terry`).

Each participant counts once: a participant's ratings of a system (over the
speeches) are averaged before anything is compared, as the paired tests
need one value per participant and system.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from itertools import combinations
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "ELO_SCALE",
    "read_responses_csv",
    "ratings_table",
    "pairwise_table",
    "exclusions",
    "participant_means",
    "bootstrap_mean_median",
    "system_summary",
    "holm",
    "rank_biserial",
    "pairwise_tests",
    "bt_win_counts",
    "bt_fit",
    "bradley_terry",
]

#: Elo points per natural-log unit of Bradley-Terry strength: 400 points = a factor of 10 in the odds
ELO_SCALE = 400.0 / math.log(10.0)

RATING_COLUMNS = ["participant", "row", "speech", "system", "prompt", "value"]
PAIRWISE_COLUMNS = ["participant", "row", "speech", "system_left", "system_right", "value"]
EXCLUSION_COLUMNS = ["participant", "row", "failed_checks", "audio_failed", "excluded"]


# ---- from the store's answers to long-form tables ---------------------------------------------------


def _frames(store_or_frames: Any) -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """(responses, participants or None) from a Store, a (responses, participants) pair or a responses frame."""
    import pandas as pd

    if hasattr(store_or_frames, "responses_frame"):
        return store_or_frames.responses_frame(), store_or_frames.participants_frame()
    if isinstance(store_or_frames, tuple) and len(store_or_frames) == 2:
        return store_or_frames[0], store_or_frames[1]
    if isinstance(store_or_frames, pd.DataFrame):
        return store_or_frames, None
    raise ConfigError(f"expected a Store, a responses frame or (responses, participants), got {type(store_or_frames)}")


def _manifest(design: Any, manifest: pd.DataFrame | None) -> dict[str, tuple[str, str]]:
    """media id -> (speech, system) from the study's manifest.csv (the key)."""
    import pandas as pd

    if manifest is None:
        path = Path(design.folder) / "manifest.csv"
        try:
            manifest = pd.read_csv(path, dtype=str, keep_default_na=False)
        except (OSError, ValueError) as e:
            raise ConfigError(f"cannot read the study's key: {e}", path=path) from e
        missing = {"id", "audio", "system"} - set(manifest.columns)
        if missing:
            raise ConfigError(f"the manifest lacks the columns {sorted(missing)}", path=path)
    return {str(i): (str(a), str(s)) for i, a, s in zip(manifest["id"], manifest["audio"], manifest["system"])}


def read_responses_csv(path: str | Path) -> pd.DataFrame:
    """Responses written as CSV (``answers`` as JSON text, e.g. by ``study import-hemvip``) as a frame.

    Returns
    -------
    DataFrame
        The columns of ``Store.responses_frame()``, ``answers`` as dicts.
    """
    import json

    import pandas as pd

    path = Path(path)
    try:
        frame = pd.read_csv(path, dtype={"token": str, "page_id": str, "kind": str}, keep_default_na=False)
        missing = {"token", "row", "page_id", "kind", "answers"} - set(frame.columns)
        if missing:
            raise ConfigError(f"not a responses file: it lacks the columns {sorted(missing)}", path=path)
        frame["answers"] = [json.loads(a) if a else {} for a in frame["answers"]]
    except (OSError, ValueError) as e:
        raise ConfigError(f"cannot read the responses: {e}", path=path) from e
    return frame


class _Pages:
    """Each participant row's pages by id, built once per row (pages are deterministic from the design)."""

    def __init__(self, design: Any):
        self.design = design
        self.rows: dict[int, dict[str, Any]] = {}

    def page(self, row: int, page_id: str) -> Any:
        if row not in self.rows:
            from .design import participant_pages

            self.rows[row] = {p.id: p for p in participant_pages(self.design, int(row))}
        return self.rows[row].get(str(page_id))


def ratings_table(design: Any, store_or_frames: Any, *, manifest: pd.DataFrame | None = None) -> pd.DataFrame:
    """The answers of the rating pages, one row per participant, stimulus and prompt.

    Parameters
    ----------
    design : StudyDesign
        The study (its folder holds manifest.csv).
    store_or_frames : Store, DataFrame or (DataFrame, DataFrame)
        The store, or its ``responses_frame()`` (and ``participants_frame()``).
    manifest : DataFrame, optional
        The key (``id``, ``audio``, ``system``); default the study's manifest.csv.

    Returns
    -------
    DataFrame
        ``participant`` (the token), ``row``, ``speech``, ``system``, ``prompt``, ``value`` (float).
        Attention check videos are no stimuli and give no rows.
    """
    import pandas as pd

    responses, _ = _frames(store_or_frames)
    key = _manifest(design, manifest)
    rows = []
    for r in responses[responses["kind"] == "rating"].itertuples(index=False):
        for media, prompts in dict(r.answers).items():
            if media not in key:  # an attention check, scored by exclusions()
                continue
            speech, system = key[media]
            for prompt, value in dict(prompts).items():
                rows.append((str(r.token), int(r.row), speech, system, str(prompt), float(value)))
    return pd.DataFrame(rows, columns=RATING_COLUMNS)


def pairwise_table(design: Any, store_or_frames: Any, *, manifest: pd.DataFrame | None = None) -> pd.DataFrame:
    """The answers of the pairwise pages, one row per participant and pair shown.

    Returns
    -------
    DataFrame
        ``participant``, ``row``, ``speech``, ``system_left``, ``system_right``, ``value`` in -2..2
        (negative: the left one preferred). Pages showing an attention check give no rows.
    """
    import pandas as pd

    responses, _ = _frames(store_or_frames)
    key = _manifest(design, manifest)
    pages = _Pages(design)
    rows = []
    for r in responses[responses["kind"] == "pairwise"].itertuples(index=False):
        page = pages.page(int(r.row), r.page_id)
        if page is None or len(page.media) != 2 or any(m.id not in key for m in page.media):
            continue
        (speech, left), (_, right) = key[page.media[0].id], key[page.media[1].id]
        rows.append((str(r.token), int(r.row), speech, left, right, float(dict(r.answers)["choice"])))
    return pd.DataFrame(rows, columns=PAIRWISE_COLUMNS)


def exclusions(design: Any, store_or_frames: Any, *, max_failures: int | None = None) -> pd.DataFrame:
    """Each participant's failed checks and whether they are excluded.

    A participant is excluded who failed more than ``max_failures`` attention
    checks (the design's ``max_failures`` by default) or the audio check.

    Returns
    -------
    DataFrame
        ``participant``, ``row``, ``failed_checks`` (attention checks failed), ``audio_failed`` (bool),
        ``excluded`` (bool); every participant of the store, also those who answered nothing.
    """
    import pandas as pd

    from .design import check_answer

    responses, participants = _frames(store_or_frames)
    if max_failures is None:
        max_failures = int(design.max_failures)
    pages = _Pages(design)
    failed: dict[str, int] = {}
    audio: dict[str, bool] = {}
    rows: dict[str, int] = {}
    if participants is not None:
        for token, row in zip(participants["token"], participants["row"]):
            rows[str(token)] = int(row)
    for r in responses.itertuples(index=False):
        token = str(r.token)
        rows[token] = int(r.row)
        page = pages.page(int(r.row), r.page_id)
        if page is None:
            continue
        ok = check_answer(page, dict(r.answers))
        if ok is False and page.kind == "audio_check":
            audio[token] = True
        elif ok is False:
            failed[token] = failed.get(token, 0) + 1
    table = pd.DataFrame(
        [(t, row, failed.get(t, 0), audio.get(t, False)) for t, row in rows.items()], columns=EXCLUSION_COLUMNS[:4]
    )
    table["excluded"] = (table["failed_checks"] > max_failures) | table["audio_failed"].astype(bool)
    return table


# ---- ratings: per system statistics ------------------------------------------------------------------


def participant_means(ratings: pd.DataFrame) -> pd.DataFrame:
    """Each participant's mean rating per prompt and system (over the speeches), plus prompt ``"all"``.

    Returns
    -------
    DataFrame
        ``participant``, ``prompt``, ``system``, ``value``; ``"all"`` is the mean over every prompt.
    """
    import pandas as pd

    per = ratings.groupby(["participant", "prompt", "system"], sort=True)["value"].mean().reset_index()
    every = ratings.groupby(["participant", "system"], sort=True)["value"].mean().reset_index()
    every.insert(1, "prompt", "all")
    return pd.concat([per, every], ignore_index=True)[["participant", "prompt", "system", "value"]]


def bootstrap_mean_median(
    values: np.ndarray, *, rounds: int = 10_000, seed: int | Sequence[int] = 0, level: float = 0.95
) -> tuple[float, float, float, float, float, float]:
    """Mean and median of ``values`` with percentile bootstrap intervals (resampling the values).

    Parameters
    ----------
    values : np.ndarray, shape (n,)
        One value per participant.
    rounds : int
        Bootstrap resamples, all drawn at once (in blocks of about 4 M values to bound memory).
    seed : int or sequence of int
        Seed of the resampling (``numpy.random.default_rng``).
    level : float
        Coverage of the intervals.

    Returns
    -------
    tuple of float
        (mean, mean_lo, mean_hi, median, median_lo, median_hi).
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    if x.size == 0:
        raise ConfigError("no values to summarise")
    rng = np.random.default_rng(seed)
    block = max(1, 4_000_000 // x.size)
    means, medians = [], []
    for start in range(0, int(rounds), block):
        idx = rng.integers(0, x.size, size=(min(block, int(rounds) - start), x.size))
        sample = x[idx]
        means.append(sample.mean(axis=1))
        medians.append(np.median(sample, axis=1))
    q = [50 * (1 - level), 50 * (1 + level)]
    m_lo, m_hi = np.percentile(np.concatenate(means), q)
    d_lo, d_hi = np.percentile(np.concatenate(medians), q)
    return float(x.mean()), float(m_lo), float(m_hi), float(np.median(x)), float(d_lo), float(d_hi)


def system_summary(ratings: pd.DataFrame, *, rounds: int = 10_000, seed: int = 0, level: float = 0.95) -> pd.DataFrame:
    """Per prompt and system: participants, mean and median of the participants' means, bootstrap intervals.

    Returns
    -------
    DataFrame
        ``prompt`` (each prompt, then ``"all"``), ``system``, ``n`` (participants), ``mean``, ``mean_lo``,
        ``mean_hi``, ``median``, ``median_lo``, ``median_hi``; sorted by prompt then mean, best first.
    """
    import pandas as pd

    means = participant_means(ratings)
    prompts = _prompts(ratings)
    out = []
    for p_i, prompt in enumerate(prompts):
        for s_i, system in enumerate(sorted(set(ratings["system"]))):
            v = means.loc[(means["prompt"] == prompt) & (means["system"] == system), "value"].to_numpy()
            if v.size == 0:
                continue
            stats = bootstrap_mean_median(v, rounds=rounds, seed=[seed, p_i, s_i], level=level)
            out.append((prompt, system, v.size, *stats))
    cols = ["prompt", "system", "n", "mean", "mean_lo", "mean_hi", "median", "median_lo", "median_hi"]
    table = pd.DataFrame(out, columns=cols)
    order = {p: i for i, p in enumerate(prompts)}
    table["_p"] = table["prompt"].map(order)
    return (
        table.sort_values(["_p", "mean", "system"], ascending=[True, False, True])
        .drop(columns="_p")
        .reset_index(drop=True)
    )


def _prompts(ratings: pd.DataFrame) -> list[str]:
    """The prompts in the order first seen, then ``"all"``."""
    return list(dict.fromkeys(str(p) for p in ratings["prompt"])) + ["all"]


# ---- ratings: tests between systems ------------------------------------------------------------------


def holm(pvalues: Sequence[float] | np.ndarray) -> np.ndarray:
    """Holm-Bonferroni adjusted p-values (step-down; reject where adjusted <= alpha).

    The i-th smallest of m p-values is multiplied by (m - i + 1); adjusted values are made
    non-decreasing in that order and capped at 1.

    Parameters
    ----------
    pvalues : sequence of float, shape (m,)

    Returns
    -------
    np.ndarray, shape (m,)
        Adjusted p-values in the input's order.
    """
    p = np.asarray(pvalues, dtype=np.float64).ravel()
    m = p.size
    if m == 0:
        return p.copy()
    order = np.argsort(p, kind="stable")
    scaled = np.minimum(1.0, (m - np.arange(m)) * p[order])
    adjusted = np.empty(m)
    adjusted[order] = np.maximum.accumulate(scaled)
    return adjusted


def rank_biserial(x: np.ndarray, y: np.ndarray) -> float:
    """Matched-pairs rank-biserial correlation of ``x - y`` (Kerby 2014): (R+ - R-) / (R+ + R-).

    R+ and R- are the sums of the ranks of |x - y| (ties averaged) over the positive and the negative
    differences; zero differences are dropped, as the Wilcoxon test drops them. +1: x above y for every
    participant; 0 (also when every difference is zero): no tendency.

    Parameters
    ----------
    x, y : np.ndarray, shape (n,)
        Paired values.

    Returns
    -------
    float
        In [-1, 1].
    """
    from scipy.stats import rankdata

    d = np.asarray(x, dtype=np.float64) - np.asarray(y, dtype=np.float64)
    d = d[d != 0]
    if d.size == 0:
        return 0.0
    ranks = rankdata(np.abs(d))
    return float((ranks[d > 0].sum() - ranks[d < 0].sum()) / ranks.sum())


def pairwise_tests(ratings: pd.DataFrame, *, alpha: float = 0.05) -> pd.DataFrame:
    """Wilcoxon signed-rank tests of every pair of systems on the participants' means, Holm-adjusted per prompt.

    Parameters
    ----------
    ratings : DataFrame
        :func:`ratings_table`'s columns.
    alpha : float
        Family-wise error rate of each prompt's family of tests.

    Returns
    -------
    DataFrame
        ``prompt``, ``system_a``, ``system_b``, ``n`` (participants who rated both), ``mean_diff`` (a - b),
        ``statistic`` (scipy's two-sided W), ``p``, ``p_holm``, ``significant`` (p_holm <= alpha),
        ``r`` (rank-biserial; positive: a rated higher).
    """
    import pandas as pd
    from scipy.stats import wilcoxon

    means = participant_means(ratings)
    wide = means.pivot_table(index=["prompt", "participant"], columns="system", values="value")
    systems = sorted(set(ratings["system"]))
    out = []
    for prompt in _prompts(ratings):
        if prompt not in wide.index.get_level_values(0):
            continue
        block = wide.loc[prompt]
        family = []
        for a, b in combinations(systems, 2):
            both = block[[a, b]].dropna()
            n = len(both)
            if n == 0:
                continue
            x, y = both[a].to_numpy(), both[b].to_numpy()
            if np.all(x == y):  # nothing to rank: no evidence of a difference
                stat, p = 0.0, 1.0
            else:
                res = wilcoxon(x, y, alternative="two-sided")
                stat, p = float(res.statistic), float(res.pvalue)
            family.append([prompt, a, b, n, float(np.mean(x - y)), stat, p, rank_biserial(x, y)])
        adjusted = holm([f[6] for f in family])
        for f, q in zip(family, adjusted):
            out.append(f[:7] + [float(q), bool(q <= alpha), f[7]])
    cols = ["prompt", "system_a", "system_b", "n", "mean_diff", "statistic", "p", "p_holm", "significant", "r"]
    return pd.DataFrame(out, columns=cols)


# ---- pairwise pages: Bradley-Terry -------------------------------------------------------------------


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

    The point estimate is fitted by choix (``ilsr_pairwise``); each bootstrap round resamples the
    participants with replacement and refits by :func:`bt_fit`, all rounds at once. Scores are
    400 log10(strength), anchored so that their mean is 0: a system 400 points above another is
    preferred with odds 10 : 1.

    Returns
    -------
    DataFrame
        ``system``, ``elo``, ``elo_lo``, ``elo_hi``, ``wins``, ``losses``, ``ties`` (comparisons),
        sorted best first.
    """
    import pandas as pd

    from .._optional import require

    choix = require("choix", purpose="Bradley-Terry scores")
    if systems is None:
        systems = sorted(set(pairwise["system_left"]) | set(pairwise["system_right"]))
    systems = list(systems)
    participants, counts = bt_win_counts(pairwise, systems)
    if not participants or len(systems) < 2:
        raise ConfigError("Bradley-Terry needs pairwise answers comparing at least two systems")
    total = counts.sum(axis=0)
    theta = _bt_choix(choix, total, prior)
    rng = np.random.default_rng([seed, 0xB7])
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
    table = pd.DataFrame(
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
    return table.sort_values(["elo", "system"], ascending=[False, True]).reset_index(drop=True)


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
