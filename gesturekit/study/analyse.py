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

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..limits import parse_json

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "ELO_SCALE",
    "read_responses_csv",
    "ratings_table",
    "pairwise_table",
    "exclusions",
    "broken_videos",
    "participant_flow",
    "participant_means",
    "bootstrap_mean_median",
    "system_summary",
    "holm",
    "rank_biserial",
    "pairwise_tests",
    "bt_win_counts",
    "bt_fit",
    "bradley_terry",
    "comparison_groups",
    "wilcoxon_p",
]

#: fewer participants than this get no bootstrap interval: the percentile bootstrap of 4 or fewer values
#: has a handful of distinct resamples and covers the truth far less often than it claims
MIN_INTERVAL_N = 5

#: the Wilcoxon p-value is exact (all 2^n sign patterns) up to this many non-zero, untied differences
EXACT_MAX_N = 25

#: fewer pairs than this can never be significant at 0.05: the smallest two-sided exact p is 2 / 2^n
MIN_TEST_N = 6

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


@checks_arguments
def read_responses_csv(path: str | Path) -> pd.DataFrame:
    """Responses written as CSV (``answers`` as JSON text, e.g. by ``study import-hemvip``) as a frame.

    Returns
    -------
    DataFrame
        The columns of ``Store.responses_frame()``, ``answers`` as dicts.
    """

    import pandas as pd

    path = Path(path)
    try:
        frame = pd.read_csv(path, dtype={"token": str, "page_id": str, "kind": str}, keep_default_na=False)
        missing = {"token", "row", "page_id", "kind", "answers"} - set(frame.columns)
        if missing:
            raise ConfigError(f"not a responses file: it lacks the columns {sorted(missing)}", path=path)
        frame["answers"] = [
            parse_json(a, what=f"the answers of line {i + 2} ", error=ConfigError, path=path) if a else {}
            for i, a in enumerate(frame["answers"])
        ]
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


@checks_arguments
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


@checks_arguments
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
        if "choice" not in dict(r.answers):  # HEMVIP's broken-video report: no preference (broken_videos)
            continue
        (speech, left), (_, right) = key[page.media[0].id], key[page.media[1].id]
        rows.append((str(r.token), int(r.row), speech, left, right, float(dict(r.answers)["choice"])))
    return pd.DataFrame(rows, columns=PAIRWISE_COLUMNS)


@checks_arguments
def broken_videos(store_or_frames: Any) -> pd.DataFrame:
    """HEMVIP's broken-video reports among the answers: ``participant``, ``row``, ``page_id``."""
    import pandas as pd

    responses, _ = _frames(store_or_frames)
    rows = [
        (str(r.token), int(r.row), str(r.page_id))
        for r in responses.itertuples(index=False)
        if isinstance(r.answers, dict) and r.answers.get("broken_video")
    ]
    return pd.DataFrame(rows, columns=["participant", "row", "page_id"])


@checks_arguments
def exclusions(design: Any, store_or_frames: Any, *, max_failures: int | None = None) -> pd.DataFrame:
    """Each participant's failed checks, whether they are excluded, and how far they got.

    A participant is excluded who failed more than ``max_failures`` attention
    checks (the design's ``max_failures`` by default) or the audio check.

    Returns
    -------
    DataFrame
        ``participant``, ``row``, ``failed_checks`` (attention checks failed), ``audio_failed`` (bool),
        ``excluded`` (bool), ``reason`` (why excluded, else empty), ``answered`` (pages answered),
        ``pages`` (pages the participant's order has to answer), ``finished`` (bool: the store says so,
        or, without the store's participants, the last page answered); every participant of the store,
        also those who answered nothing.
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
    answered: dict[str, int] = {}
    furthest: dict[str, int] = {}
    finished: dict[str, bool] = {}
    if participants is not None:
        for token, row in zip(participants["token"], participants["row"]):
            rows[str(token)] = int(row)
        if "status" in participants.columns:
            finished = {str(t): s == "finished" for t, s in zip(participants["token"], participants["status"])}
    for r in responses.itertuples(index=False):
        token = str(r.token)
        rows[token] = int(r.row)
        answered[token] = answered.get(token, 0) + 1
        furthest[token] = max(furthest.get(token, -1), int(r.page_index))
        page = pages.page(int(r.row), r.page_id)
        if page is None:
            continue
        ok = check_answer(page, dict(r.answers))
        if ok is False and page.kind == "audio_check":
            audio[token] = True
        elif ok is False:
            failed[token] = failed.get(token, 0) + 1
    out = []
    for t, row in rows.items():
        pages.page(row, "")  # builds the row's pages
        todo = sum(1 for p in pages.rows[row].values() if p.kind != "done")
        last = max((p.index for p in pages.rows[row].values() if p.kind != "done"), default=0)
        f, a = failed.get(t, 0), audio.get(t, False)
        reasons = []
        if f > max_failures:
            reasons.append(REASON_ATTENTION)
        if a:
            reasons.append(REASON_AUDIO)
        n = answered.get(t, 0)
        # without the store's status (a responses CSV, HEMVIP's pages lacking the instructions and the
        # audio check): finished when the last page to answer was answered
        done = finished[t] if t in finished else furthest.get(t, -1) >= last
        out.append((t, row, f, a, bool(reasons), "; ".join(reasons), n, todo, bool(done)))
    return pd.DataFrame(out, columns=[*EXCLUSION_COLUMNS, "reason", "answered", "pages", "finished"])


#: why a participant is excluded (``exclusions``'s ``reason``; both, joined by "; ", where both hold)
REASON_ATTENTION = "failed more attention checks than allowed"
REASON_AUDIO = "failed the audio check"


@checks_arguments
def participant_flow(participants: pd.DataFrame, analysed: set[str]) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Where each participant ended up, and the counts of the flow (CONSORT style).

    Each participant is in exactly one of: answered nothing, excluded (by the checks), no rating or
    pairwise answer kept (stopped before the first stimulus page), analysed. The analysed who did
    not finish are counted by the last page they answered.

    Parameters
    ----------
    participants : DataFrame
        :func:`exclusions`'s columns (``answered``, ``pages``, ``finished``, ``reason`` may be absent,
        as in a simulated study: then everyone counts as finished).
    analysed : set of str
        The participants with at least one kept answer (rating or pairwise, not excluded).

    Returns
    -------
    table : DataFrame
        ``participants`` with ``analysed`` (bool) and ``outcome`` (in words) added.
    flow : dict
        ``started``, ``answered_nothing``, ``excluded``, ``excluded_reasons`` (reason -> count),
        ``no_kept_answer``, ``analysed``, ``analysed_finished``, ``dropped_out`` (last page answered ->
        analysed participants who stopped there).
    """
    table = participants.reset_index(drop=True).copy()
    n = len(table)
    answered = table["answered"].astype(int).tolist() if "answered" in table else [1] * n
    todo = table["pages"].astype(int).tolist() if "pages" in table else [0] * n
    finished = table["finished"].astype(bool).tolist() if "finished" in table else [True] * n
    reason = (
        table["reason"].astype(str).tolist()
        if "reason" in table
        else [REASON_ATTENTION if e else "" for e in table["excluded"].astype(bool)]
    )
    flow: dict[str, Any] = {
        "started": n,
        "answered_nothing": 0,
        "excluded": 0,
        "excluded_reasons": {},
        "no_kept_answer": 0,
        "analysed": 0,
        "analysed_finished": 0,
        "dropped_out": {},
    }
    outcomes, kept = [], []
    for token, excluded, k, m, done, why in zip(
        table["participant"].astype(str), table["excluded"].astype(bool), answered, todo, finished, reason
    ):
        stopped = "" if done else f"; dropped out after page {k} of {m}"
        kept.append(token in analysed and not excluded)
        if k == 0:
            flow["answered_nothing"] += 1
            outcomes.append("answered nothing")
        elif excluded:
            flow["excluded"] += 1
            for r in why.split("; "):
                flow["excluded_reasons"][r] = flow["excluded_reasons"].get(r, 0) + 1
            outcomes.append(f"excluded: {why}")
        elif not kept[-1]:
            flow["no_kept_answer"] += 1
            outcomes.append("no rating or pairwise answer" + stopped)
        else:
            flow["analysed"] += 1
            if done:
                flow["analysed_finished"] += 1
            else:
                flow["dropped_out"][k] = flow["dropped_out"].get(k, 0) + 1
            outcomes.append("analysed" + stopped)
    flow["dropped_out"] = dict(sorted(flow["dropped_out"].items()))
    table["analysed"] = kept
    table["outcome"] = outcomes
    return table, flow


# ---- ratings: per system statistics ------------------------------------------------------------------


@checks_arguments
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


@checks_arguments
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


@checks_arguments
def system_summary(ratings: pd.DataFrame, *, rounds: int = 10_000, seed: int = 0, level: float = 0.95) -> pd.DataFrame:
    """Per prompt and system: participants, mean and median of the participants' means, bootstrap intervals.

    Returns
    -------
    DataFrame
        ``prompt`` (each prompt, then ``"all"``), ``system``, ``n`` (participants), ``mean``, ``mean_lo``,
        ``mean_hi``, ``median``, ``median_lo``, ``median_hi``; sorted by prompt then mean, best first.
        An interval is NaN (none) below :data:`MIN_INTERVAL_N` participants, and where it would have
        zero width (every participant's mean the same): a point is not an interval.
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
            stats = list(bootstrap_mean_median(v, rounds=rounds, seed=[seed, p_i, s_i], level=level))
            for lo in (1, 4):  # no interval from too few values, none of zero width
                if v.size < MIN_INTERVAL_N or not stats[lo + 1] > stats[lo]:
                    stats[lo] = stats[lo + 1] = math.nan
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


@checks_arguments
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


@checks_arguments
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


@checks_arguments
def wilcoxon_p(d: np.ndarray) -> tuple[float, str]:
    """Two-sided Wilcoxon signed-rank p-value of the paired differences ``d``, by a method chosen here.

    Zero differences are dropped (Wilcoxon's own treatment). With at most :data:`EXACT_MAX_N` differences
    left and no ties among their absolute values, the p-value is exact (the null distribution of every
    sign pattern); otherwise it is the normal approximation with the tie correction of the variance and
    no continuity correction. The choice is made here, not left to scipy's default, which has changed
    between versions (newer ones use the exact distribution even with ties, where it does not hold).

    Parameters
    ----------
    d : np.ndarray, shape (n,)
        Paired differences; at least one non-zero.

    Returns
    -------
    p : float
    method : str
        ``"exact"`` or ``"normal, tie-corrected"``.
    """
    from scipy.stats import wilcoxon

    d = np.asarray(d, dtype=np.float64)
    nonzero = d[d != 0]
    if nonzero.size <= EXACT_MAX_N and np.unique(np.abs(nonzero)).size == nonzero.size:
        return float(wilcoxon(nonzero, alternative="two-sided", method="exact").pvalue), "exact"
    res = wilcoxon(nonzero, alternative="two-sided", method="approx", correction=False, zero_method="wilcox")
    return float(res.pvalue), "normal, tie-corrected"


@checks_arguments
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
        ``r`` (rank-biserial; positive: a rated higher), ``method`` (of the p-value, :func:`wilcoxon_p`),
        ``family`` (tests in the prompt's Holm family), ``result`` (``"a higher"``, ``"b higher"``: the
        test's direction, the sign of r; ``"no difference found"``; ``"not compared"``: nobody rated
        both, no test, not in the family, NaN statistics).
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
        family, missing = [], []
        for a, b in combinations(systems, 2):
            both = block.reindex(columns=[a, b])[[a, b]].dropna()
            n = len(both)
            if n == 0:
                missing.append([prompt, a, b])
                continue
            x, y = both[a].to_numpy(), both[b].to_numpy()
            if np.all(x == y):  # nothing to rank: no evidence of a difference
                stat, p, method = 0.0, 1.0, "none: no difference"
            else:
                p, method = wilcoxon_p(x - y)
                stat = float(wilcoxon(x, y, alternative="two-sided", method="approx").statistic)
            family.append([prompt, a, b, n, float(np.mean(x - y)), stat, p, rank_biserial(x, y), method])
        adjusted = holm([f[6] for f in family])
        for f, q in zip(family, adjusted):
            significant = bool(q <= alpha)
            result = ("a higher" if f[7] > 0 else "b higher") if significant else "no difference found"
            out.append(f[:7] + [float(q), significant, f[7], f[8], len(family), result])
        for prompt_, a, b in missing:
            nan = math.nan
            out.append([prompt_, a, b, 0, nan, nan, nan, nan, False, nan, "", len(family), "not compared"])
    cols = ["prompt", "system_a", "system_b", "n", "mean_diff", "statistic", "p", "p_holm", "significant", "r"]
    return pd.DataFrame(out, columns=[*cols, "method", "family", "result"])


# Bradley-Terry lives in its own module; its names stay importable from here
from .bradley_terry import ELO_SCALE, bradley_terry, bt_fit, bt_win_counts, comparison_groups  # noqa: E402
