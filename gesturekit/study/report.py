"""The analysis of a study as one object, and its files: CSVs, figures, a markdown and an HTML report.

:func:`analyse` runs :mod:`gesturekit.study.analyse` on the long-form tables
(from a study's store or simulated); :func:`analyse_study` reads a study folder
(its design and its store) and writes into ``STUDY/analysis/``:

============================  ===========================================================
``participants.csv``          each participant's failed checks and whether excluded
``summary.csv``               per prompt and system: mean, median, bootstrap 95 % intervals
``tests.csv``                 every pair of systems: Wilcoxon, Holm-adjusted p, effect size
``bradley_terry.csv``         pairwise pages: Elo-like scores with bootstrap intervals
``significance.html``         the significance matrix per prompt (plotly, self-contained)
``boxplots.html``             the participants' means per system and prompt
``report.md``, ``report.html`` all of it in words and tables
============================  ===========================================================

PNG copies of the figures are written only where plotly can render images (kaleido).
Every file is written atomically; an earlier analysis is replaced only with ``force``.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._io import atomic_write
from ..errors import ConfigError, OutputError
from .analyse import (
    bradley_terry,
    exclusions,
    pairwise_table,
    pairwise_tests,
    participant_means,
    ratings_table,
    read_responses_csv,
    system_summary,
)

if TYPE_CHECKING:
    import pandas as pd
    import plotly.graph_objects as go

__all__ = ["AnalysisReport", "analyse", "write_report", "analyse_study", "REPORT_FILES"]

#: the files an analysis writes (PNG figures besides, where a renderer exists)
REPORT_FILES = (
    "participants.csv",
    "summary.csv",
    "tests.csv",
    "bradley_terry.csv",
    "significance.html",
    "boxplots.html",
    "report.md",
    "report.html",
)


@dataclass
class AnalysisReport:
    """A study's analysis.

    Attributes
    ----------
    participants : DataFrame
        :func:`~.analyse.exclusions`'s columns: every participant, excluded or not.
    ratings : DataFrame
        The included participants' ratings (:func:`~.analyse.ratings_table`'s columns).
    pairwise : DataFrame
        The included participants' pairwise answers.
    summary : DataFrame or None
        :func:`~.analyse.system_summary` (None without ratings).
    tests : DataFrame or None
        :func:`~.analyse.pairwise_tests` (None without ratings).
    bradley_terry : DataFrame or None
        :func:`~.analyse.bradley_terry` (None without pairwise answers).
    systems : tuple of str
    alpha : float
    rounds : int
        Bootstrap rounds.
    files : list of Path
        What :func:`write_report` wrote.
    """

    participants: pd.DataFrame
    ratings: pd.DataFrame
    pairwise: pd.DataFrame
    summary: pd.DataFrame | None
    tests: pd.DataFrame | None
    bradley_terry: pd.DataFrame | None
    systems: tuple[str, ...]
    alpha: float
    rounds: int
    files: list[Path] = field(default_factory=list)

    @property
    def included(self) -> int:
        """Participants analysed."""
        return int((~self.participants["excluded"].astype(bool)).sum())

    @property
    def excluded(self) -> int:
        """Participants excluded by their checks."""
        return int(self.participants["excluded"].astype(bool).sum())

    def markdown(self) -> str:
        """The report as markdown."""
        lines = [
            "# Study analysis",
            "",
            f"Participants: {len(self.participants)}; excluded by the checks: {self.excluded} "
            f"(more failed attention checks than allowed, or the audio check failed); analysed: {self.included}.",
            f"Systems: {', '.join(self.systems)}. Bootstrap: {self.rounds} rounds over participants; "
            f"alpha = {self.alpha} (Holm-Bonferroni within each prompt).",
            "",
        ]
        if self.summary is not None:
            lines += [
                "## Ratings per system",
                "",
                "Each participant's ratings of a system are averaged over the speeches; the mean and the median "
                "of those averages, with percentile bootstrap 95 % intervals. Prompt `all` averages every prompt.",
                "",
                _md_table(self.summary, digits=3),
                "",
            ]
        if self.tests is not None:
            lines += [
                "## Pairwise differences (Wilcoxon signed-rank)",
                "",
                "Two-sided Wilcoxon signed-rank tests on the participants' averages; `p_holm` is adjusted by "
                "Holm-Bonferroni within each prompt; `r` is the matched-pairs rank-biserial correlation "
                "(positive: system_a rated higher; 1: higher for every participant).",
                "",
                _md_table(self.tests, digits=4),
                "",
            ]
        if self.bradley_terry is not None:
            lines += [
                "## Pairwise preferences (Bradley-Terry)",
                "",
                "Scores are 400 log10 of the Bradley-Terry strength (an Elo-like scale), anchored so that their "
                "mean is 0: a system 400 points above another is preferred with odds 10 : 1. A clear or slight "
                "preference is a win; no preference is half a win each way; intervals: bootstrap over participants.",
                "",
                _md_table(self.bradley_terry, digits=1),
                "",
            ]
        lines += ["## Participants", "", _md_table(self.participants, digits=0), ""]
        return "\n".join(lines)


def _md_table(table: pd.DataFrame, *, digits: int) -> str:
    """A DataFrame as a markdown table (floats rounded to ``digits``)."""
    cols = [str(c) for c in table.columns]
    out = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in table.itertuples(index=False):
        cells = [f"{v:.{digits}f}" if isinstance(v, float) else str(v) for v in row]
        out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(out)


def analyse(
    ratings: pd.DataFrame,
    pairwise: pd.DataFrame,
    participants: pd.DataFrame,
    *,
    rounds: int = 10_000,
    alpha: float = 0.05,
    seed: int = 0,
) -> AnalysisReport:
    """Analyse the long-form tables of a study (excluded participants dropped first).

    Parameters
    ----------
    ratings, pairwise, participants : DataFrame
        :func:`~.analyse.ratings_table`, :func:`~.analyse.pairwise_table` and
        :func:`~.analyse.exclusions` (or a simulated study's).
    rounds : int
        Bootstrap rounds (over participants).
    alpha : float
        Family-wise error rate of each prompt's tests.
    seed : int
        Seed of the bootstraps.

    Returns
    -------
    AnalysisReport

    Raises
    ------
    ConfigError
        Nothing to analyse: no answers, fewer than two systems, or fewer than two participants left.
    """
    if not 0 < alpha < 1:
        raise ConfigError(f"alpha must be in (0, 1), got {alpha}")
    if rounds < 1:
        raise ConfigError(f"the bootstrap needs at least one round, got {rounds}")
    out = set(participants.loc[participants["excluded"].astype(bool), "participant"].astype(str))
    ratings = ratings[~ratings["participant"].astype(str).isin(out)].reset_index(drop=True)
    pairwise = pairwise[~pairwise["participant"].astype(str).isin(out)].reset_index(drop=True)
    systems = sorted(set(ratings["system"]) | set(pairwise["system_left"]) | set(pairwise["system_right"]))
    people = set(ratings["participant"].astype(str)) | set(pairwise["participant"].astype(str))
    if not len(ratings) and not len(pairwise):
        raise ConfigError(
            f"nothing to analyse: no rating or pairwise answers from included participants "
            f"({len(participants)} participants, {len(out)} excluded)"
        )
    if len(systems) < 2 or len(people) < 2:
        raise ConfigError(
            f"too small to analyse: {len(people)} included participant(s) answered about {len(systems)} system(s); "
            "comparing systems needs at least two of each"
        )
    has_ratings = len(ratings) > 0
    return AnalysisReport(
        participants=participants.reset_index(drop=True),
        ratings=ratings,
        pairwise=pairwise,
        summary=system_summary(ratings, rounds=rounds, seed=seed) if has_ratings else None,
        tests=pairwise_tests(ratings, alpha=alpha) if has_ratings else None,
        bradley_terry=bradley_terry(pairwise, systems=systems, rounds=rounds, seed=seed) if len(pairwise) else None,
        systems=tuple(systems),
        alpha=float(alpha),
        rounds=int(rounds),
    )


# ---- figures ---------------------------------------------------------------------------------------


def significance_figure(report: AnalysisReport) -> go.Figure:
    """The significance matrix per prompt: a cell is green where the row's system is rated significantly
    higher than the column's (Holm-adjusted), red where lower, grey where no difference was found; its
    text gives the adjusted p-value and the effect size r.
    """
    from plotly.subplots import make_subplots

    from .._optional import require

    require("plotly", purpose="the analysis's figures")
    import plotly.graph_objects as go

    tests = report.tests
    if tests is None:
        raise ConfigError("the significance matrix needs rating answers")
    prompts = list(dict.fromkeys(tests["prompt"]))
    assert report.summary is not None
    fig = make_subplots(rows=1, cols=len(prompts), subplot_titles=prompts, horizontal_spacing=0.08)
    for c, prompt in enumerate(prompts, start=1):
        # best first, as in the summary
        order = list(report.summary.loc[report.summary["prompt"] == prompt, "system"])
        k = len(order)
        z = np.full((k, k), np.nan)
        text = [["" for _ in range(k)] for _ in range(k)]
        for t in tests[tests["prompt"] == prompt].itertuples(index=False):
            for a, b, sign in ((t.system_a, t.system_b, 1.0), (t.system_b, t.system_a, -1.0)):
                i, j = order.index(a), order.index(b)
                z[i, j] = sign * np.sign(t.mean_diff) if t.significant else 0.0
                text[i][j] = f"p={t.p_holm:.3g}<br>r={sign * t.r:+.2f}"
        fig.add_trace(
            go.Heatmap(
                z=z,
                x=order,
                y=order,
                text=text,
                texttemplate="%{text}",
                zmin=-1,
                zmax=1,
                colorscale=[[0, "#d62728"], [0.5, "#d9d9d9"], [1, "#2ca02c"]],
                showscale=False,
                hovertemplate="%{y} vs %{x}<br>%{text}<extra></extra>",
            ),
            row=1,
            col=c,
        )
        fig.update_yaxes(autorange="reversed", row=1, col=c)
    fig.update_layout(
        title=f"Row system vs column system (green: rated higher, red: lower; Holm, alpha={report.alpha})",
        height=420,
        width=max(500, 420 * len(prompts)),
    )
    return fig


def boxplot_figure(report: AnalysisReport) -> go.Figure:
    """Box plots of the participants' mean ratings, per system, one colour per prompt."""
    from .._optional import require

    require("plotly", purpose="the analysis's figures")
    import plotly.graph_objects as go

    means = participant_means(report.ratings)
    fig = go.Figure()
    for prompt in dict.fromkeys(means["prompt"]):
        m = means[means["prompt"] == prompt]
        fig.add_trace(go.Box(x=m["system"], y=m["value"], name=str(prompt), boxmean=True, boxpoints="all"))
    fig.update_layout(
        boxmode="group",
        title="Each participant's mean rating per system (box: quartiles; dashed: mean)",
        xaxis_title="system",
        yaxis_title="rating",
        xaxis={"categoryorder": "array", "categoryarray": list(report.systems)},
    )
    return fig


# ---- files -----------------------------------------------------------------------------------------


def _write_bytes(path: Path, data: bytes, force: bool) -> Path:
    return atomic_write(path, lambda f: f.write(data), overwrite=force)


def write_report(report: AnalysisReport, out: str | Path, *, force: bool = False) -> list[Path]:
    """Write the analysis's files into ``out`` (created; see the module's table).

    Raises
    ------
    OutputError
        ``out`` already holds an analysis's files and ``force`` is False (nothing is written then).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError("the analysis's output is a folder, and this is a file", path=out)
    there = [name for name in REPORT_FILES if (out / name).exists()]
    if there and not force:
        raise OutputError(f"an earlier analysis is there ({', '.join(there)}); replace it with --force", path=out)
    out.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []

    def csv(name: str, table: pd.DataFrame | None) -> None:
        if table is not None:
            files.append(_write_bytes(out / name, table.to_csv(index=False, lineterminator="\n").encode(), force))
        elif (out / name).exists():  # an earlier analysis's, no longer true
            (out / name).unlink()

    csv("participants.csv", report.participants)
    csv("summary.csv", report.summary)
    csv("tests.csv", report.tests)
    csv("bradley_terry.csv", report.bradley_terry)
    figures: list[tuple[str, go.Figure]] = []
    if report.tests is not None:
        figures = [("significance", significance_figure(report)), ("boxplots", boxplot_figure(report))]
    for name, fig in figures:
        files.append(_write_bytes(out / f"{name}.html", fig.to_html(include_plotlyjs=True).encode(), force))
        png = _png(fig)
        if png is not None:
            files.append(_write_bytes(out / f"{name}.png", png, force))
    md = report.markdown()
    files.append(_write_bytes(out / "report.md", md.encode(), force))
    files.append(_write_bytes(out / "report.html", _html(report, figures).encode(), force))
    report.files = files
    return files


def _png(fig: go.Figure) -> bytes | None:
    """The figure as PNG where plotly has an image renderer (kaleido); None otherwise."""
    from importlib.util import find_spec

    if find_spec("kaleido") is None:
        return None
    try:
        return fig.to_image(format="png")
    except Exception:  # a renderer that cannot start (no browser for kaleido 1.x): the HTML figures stand
        return None


def _html(report: AnalysisReport, figures: list[tuple[str, go.Figure]]) -> str:
    """One self-contained HTML page: the tables and the figures (plotly.js inlined once)."""
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>Study analysis</title>"]
    parts.append(
        "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}</style>"
    )
    parts.append("</head><body>")
    for i, (_, fig) in enumerate(figures):
        parts.append(fig.to_html(full_html=False, include_plotlyjs=(i == 0)))
    for block in report.markdown().split("\n\n"):
        if block.startswith("|"):
            rows = [r.strip("|").split(" | ") for r in block.splitlines() if not r.startswith("|---")]
            head, body = rows[0], rows[1:]
            parts.append(
                "<table><tr>"
                + "".join(f"<th>{html.escape(c.strip())}</th>" for c in head)
                + "</tr>"
                + "".join("<tr>" + "".join(f"<td>{html.escape(c.strip())}</td>" for c in r) + "</tr>" for r in body)
                + "</table>"
            )
        elif block.startswith("# "):
            parts.append(f"<h1>{html.escape(block[2:])}</h1>")
        elif block.startswith("## "):
            parts.append(f"<h2>{html.escape(block[3:])}</h2>")
        else:
            parts.append(f"<p>{html.escape(block)}</p>")
    parts.append("</body></html>")
    return "\n".join(parts)


def analyse_study(
    folder: str | Path,
    *,
    out: str | Path | None = None,
    rounds: int = 10_000,
    alpha: float = 0.05,
    seed: int = 0,
    force: bool = False,
    store_url: str | None = None,
    responses: str | Path | None = None,
) -> AnalysisReport:
    """Analyse a study folder's answers and write the report (default into ``folder/analysis``).

    Parameters
    ----------
    folder : path
        The study (design.json, manifest.csv, the store).
    out : path, optional
        Where the files go.
    rounds, alpha, seed
        As :func:`analyse`.
    force : bool
        Replace an earlier analysis.
    store_url : str, optional
        The store's database URL (PostgreSQL); default the folder's SQLite file.
    responses : path, optional
        A CSV of responses (``study import-hemvip``'s, answers as JSON text) analysed instead of the store.

    Returns
    -------
    AnalysisReport
        With ``files`` set.
    """
    from .design import load_design
    from .store import open_store

    folder = Path(folder)
    design = load_design(folder)
    if responses is not None:
        frames: tuple[pd.DataFrame, pd.DataFrame | None] = (read_responses_csv(responses), None)
    else:
        store = open_store(store_url, folder)
        frames = (store.responses_frame(), store.participants_frame())
    report = analyse(
        ratings_table(design, frames),
        pairwise_table(design, frames),
        exclusions(design, frames),
        rounds=rounds,
        alpha=alpha,
        seed=seed,
    )
    write_report(report, folder / "analysis" if out is None else out, force=force)
    return report
