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
``report.md``, ``report.html`` all of it in words and tables (the HTML with the figures)
``plotly.min.js``             the figures' library, once for every HTML file beside it
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

from .._arguments import checks_arguments
from .._io import atomic_write, csv_safe
from ..errors import ConfigError, OutputError
from .analyse import (
    MIN_INTERVAL_N,
    MIN_TEST_N,
    bradley_terry,
    broken_videos,
    comparison_groups,
    exclusions,
    pairwise_table,
    pairwise_tests,
    participant_flow,
    participant_means,
    ratings_table,
    read_responses_csv,
    system_summary,
)

if TYPE_CHECKING:
    import pandas as pd
    import plotly.graph_objects as go

__all__ = ["AnalysisReport", "analyse", "write_report", "analyse_study", "REPORT_FILES"]

#: the most bootstrap rounds an analysis takes (each round's estimates are kept in memory)
MAX_ROUNDS = 1_000_000

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
    "plotly.min.js",
)


@dataclass
class AnalysisReport:
    """A study's analysis.

    Attributes
    ----------
    participants : DataFrame
        :func:`~.analyse.exclusions`'s columns plus ``analysed`` and ``outcome``
        (:func:`~.analyse.participant_flow`): every participant, analysed or not.
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
    flow : dict
        The participant flow's counts (:func:`~.analyse.participant_flow`).
    broken_videos : int
        HEMVIP's broken-video reports (pages answered by the report button: no preference counted).
    warnings : list of str
        What limits the conclusions (too few participants, systems never compared, a disconnected
        comparison graph), in words; the report shows them above the tables.
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
    flow: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    broken_videos: int = 0
    files: list[Path] = field(default_factory=list)

    @property
    def included(self) -> int:
        """Participants analysed: not excluded, with at least one rating or pairwise answer kept."""
        return int(self.participants["analysed"].astype(bool).sum())

    def _family_line(self) -> str:
        """The Holm family's size per prompt, and the pairs not compared, in words."""
        assert self.tests is not None
        sizes = {str(p): int(m) for p, m in zip(self.tests["prompt"], self.tests["family"])}
        if len(set(sizes.values())) == 1:
            line = f"Holm family per prompt: {next(iter(sizes.values()))} tests."
        else:
            line = "Holm family per prompt: " + ", ".join(f"{p} {m} tests" for p, m in sizes.items()) + "."
        missing = self.tests[self.tests["result"] == "not compared"]
        if len(missing):
            pairs = ", ".join(dict.fromkeys(f"{r.system_a} vs {r.system_b}" for r in missing.itertuples()))
            line += f" Not compared (nobody rated both): {pairs}."
        return line

    def flow_lines(self) -> list[str]:
        """The participant flow in words, one line per step (started, ..., analysed)."""
        f = self.flow
        reasons = "; ".join(f"{r}: {n}" for r, n in f["excluded_reasons"].items())
        dropped = "".join(f"; dropped out after page {k}: {n}" for k, n in f["dropped_out"].items())
        return [
            f"Started: {f['started']}",
            f"Answered nothing: {f['answered_nothing']}",
            f"Excluded: {f['excluded']}" + (f" ({reasons})" if reasons else ""),
            f"No rating or pairwise answer: {f['no_kept_answer']}",
            f"Analysed: {f['analysed']} (finished: {f['analysed_finished']}{dropped})",
        ]

    @property
    def excluded(self) -> int:
        """Participants excluded by their checks."""
        return int(self.participants["excluded"].astype(bool).sum())

    def markdown(self) -> str:
        """The report as markdown."""
        lines = [
            "# Study analysis",
            "",
            "## Participant flow",
            "",
            *[f"- {line}" for line in self.flow_lines()],
            "",
            "Analysed: not excluded by the checks (more failed attention checks than allowed, or the audio "
            "check failed) and at least one rating or pairwise answer. Each participant is counted in one "
            "step; who dropped out is counted by the last page they answered.",
            "",
            f"Systems: {', '.join(self.systems)}. Bootstrap: {self.rounds} rounds over participants; "
            f"alpha = {self.alpha} (Holm-Bonferroni within each prompt).",
            "",
        ]
        if self.broken_videos:
            lines += [
                f"Broken-video reports: {self.broken_videos} (HEMVIP's report button; those pages count as no "
                "answer: look at the videos named in the responses).",
                "",
            ]
        if self.warnings:
            lines += ["## Warnings", ""]
            for w in self.warnings:
                lines += [f"> {w}", ""]
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
                "(positive: system_a rated higher; 1: higher for every participant). `result` follows the test "
                "(the sign of r where significant). p-values: exact (every sign pattern) up to 25 non-zero "
                "differences without ties, else the normal approximation with the tie correction (`method`); "
                "zero differences are dropped.",
                "",
                self._family_line(),
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
        cells = [("-" if not np.isfinite(v) else f"{v:.{digits}f}") if isinstance(v, float) else str(v) for v in row]
        out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(out)


@checks_arguments
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
    if not 1 <= rounds <= MAX_ROUNDS:
        raise ConfigError(
            f"the bootstrap takes 1 to at most {MAX_ROUNDS:,} rounds, got {rounds:,} (each round's estimates are "
            "kept: more would fill the memory, and intervals settle long before)"
        )
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
    table, flow = participant_flow(participants, people)
    summary = system_summary(ratings, rounds=rounds, seed=seed) if has_ratings else None
    tests = pairwise_tests(ratings, alpha=alpha) if has_ratings else None
    bt = bradley_terry(pairwise, systems=systems, rounds=rounds, seed=seed) if len(pairwise) else None
    return AnalysisReport(
        participants=table,
        ratings=ratings,
        pairwise=pairwise,
        summary=summary,
        tests=tests,
        bradley_terry=bt,
        systems=tuple(systems),
        alpha=float(alpha),
        rounds=int(rounds),
        flow=flow,
        warnings=_warnings(summary, tests, pairwise, alpha),
    )


def _warnings(
    summary: pd.DataFrame | None, tests: pd.DataFrame | None, pairwise: pd.DataFrame, alpha: float
) -> list[str]:
    """What limits the analysis's conclusions, in words (see :attr:`AnalysisReport.warnings`)."""
    out = []
    if summary is not None:
        few = summary[summary["n"] < MIN_INTERVAL_N]
        if len(few):
            named = ", ".join(dict.fromkeys(f"{r.system} ({r.n})" for r in few.itertuples()))
            out.append(
                f"Rated by fewer than {MIN_INTERVAL_N} participants: {named}. No interval is given for them: "
                "the bootstrap of so few values has a handful of distinct resamples and covers the truth far "
                "less often than 95 %."
            )
        flat = summary[(summary["n"] >= MIN_INTERVAL_N) & summary["mean_lo"].isna()]
        if len(flat):
            named = ", ".join(dict.fromkeys(f"{r.system} ({r.prompt})" for r in flat.itertuples()))
            out.append(f"Every participant's mean is the same for {named}: a point, no interval is given.")
    if tests is not None:
        small = tests[(tests["n"] > 0) & (tests["n"] < MIN_TEST_N)]
        if len(small) and alpha < 2.0 / 2**5:
            named = ", ".join(dict.fromkeys(f"{r.system_a} vs {r.system_b} ({r.n})" for r in small.itertuples()))
            out.append(
                f"Pairs rated together by fewer than {MIN_TEST_N} participants cannot be significant at "
                f"alpha = {alpha} (the smallest two-sided signed-rank p is 2 / 2^n): {named}."
            )
        missing = tests[tests["result"] == "not compared"]
        if len(missing):
            named = ", ".join(dict.fromkeys(f"{r.system_a} vs {r.system_b}" for r in missing.itertuples()))
            out.append(f"Not compared (nobody rated both): {named}; these pairs are not in the Holm family.")
    if len(pairwise):
        parts = comparison_groups(pairwise)
        if len(parts) > 1:
            named = " | ".join(", ".join(p) for p in parts)
            out.append(
                f"The pairwise comparison graph is disconnected ({named}): no chain of comparisons joins these "
                "parts, so each is scored on its own (mean 0 within it) and scores of different parts are not "
                "comparable."
            )
    return out


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
                if t.result == "not compared":
                    text[i][j] = "not compared"
                    continue
                # the test's direction (rank-biserial r), not the mean difference's: they can disagree
                z[i, j] = sign * np.sign(t.r) if t.significant else 0.0
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


@checks_arguments
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
            text = csv_safe(table).to_csv(index=False, lineterminator="\n")
            files.append(_write_bytes(out / name, text.encode(), force))
        elif (out / name).exists():  # an earlier analysis's, no longer true
            (out / name).unlink()

    csv("participants.csv", report.participants)
    csv("summary.csv", report.summary)
    csv("tests.csv", report.tests)
    csv("bradley_terry.csv", report.bradley_terry)
    figures: list[tuple[str, go.Figure]] = []
    if report.tests is not None:
        figures = [("significance", significance_figure(report)), ("boxplots", boxplot_figure(report))]
    if figures:
        from .._optional import require

        require("plotly", purpose="the analysis's figures")
        from plotly.offline import get_plotlyjs

        files.append(_write_bytes(out / "plotly.min.js", get_plotlyjs().encode(), force))
    for name, fig in figures:
        page = fig.to_html(include_plotlyjs="directory", config={"responsive": True})
        files.append(_write_bytes(out / f"{name}.html", page.encode(), force))
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
    from .._optional import require

    require("plotly", purpose="the analysis's figures")  # it drew fig already: here for the import's sake
    from ..viz.paper import static_image

    layout = fig.layout
    try:
        return static_image(fig, "png", width=layout.width or 700, height=layout.height or 500)
    except ConfigError:  # no browser, or one that never answered: the HTML figures stand
        return None


#: which figure goes under which section of the report (by the section's heading)
_FIGURE_SECTIONS = {"boxplots": "Ratings per system", "significance": "Pairwise differences"}

_REPORT_STYLE = (
    "body{font-family:sans-serif;max-width:1180px;margin:1.5em auto;padding:0 1em;box-sizing:border-box}"
    ".table{overflow-x:auto}table{border-collapse:collapse;font-size:0.9em}"
    "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}th{background:#f4f4f4}"
    "td:first-child,th:first-child{text-align:left}.figure{max-width:100%;overflow-x:auto}"
    ".warning{background:#fff4e5;border-left:4px solid #e69500;padding:0.4em 0.8em}"
)


def _inline(text: str) -> str:
    """Markdown's inline code and bold as HTML (the text escaped first)."""
    import re

    out = html.escape(text)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    return re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", out)


def _html(report: AnalysisReport, figures: list[tuple[str, go.Figure]]) -> str:
    """One HTML page: the title, then each section with its tables and its figures under it.

    plotly.js is not inlined: every figure refers to ``plotly.min.js`` beside the page (written once
    per analysis folder).
    """
    under: dict[str, list[go.Figure]] = {}
    for name, fig in figures:
        under.setdefault(_FIGURE_SECTIONS.get(name, ""), []).append(fig)
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'>"]
    parts.append("<meta name='viewport' content='width=device-width, initial-scale=1'>")
    parts.append(f"<title>Study analysis</title><style>{_REPORT_STYLE}</style>")
    parts.append("<script src='plotly.min.js'></script></head><body>")
    pending: list[go.Figure] = []

    def flush() -> None:
        for fig in pending:
            parts.append("<div class='figure'>" + _figure_div(fig) + "</div>")
        pending.clear()

    for block in report.markdown().split("\n\n"):
        block = block.strip("\n")
        if not block:
            continue
        if block.startswith("|"):
            rows = [r.strip().strip("|").split(" | ") for r in block.splitlines() if not r.startswith("|---")]
            head, body = rows[0], rows[1:]
            parts.append(
                "<div class='table'><table><tr>"
                + "".join(f"<th>{_inline(c.strip())}</th>" for c in head)
                + "</tr>"
                + "".join("<tr>" + "".join(f"<td>{_inline(c.strip())}</td>" for c in r) + "</tr>" for r in body)
                + "</table></div>"
            )
        elif block.startswith("# "):
            parts.append(f"<h1>{_inline(block[2:])}</h1>")
        elif block.startswith("## "):
            flush()
            title = block[3:]
            parts.append(f"<h2>{_inline(title)}</h2>")
            pending.extend(f for key, figs in under.items() if key and title.startswith(key) for f in figs)
        elif block.startswith("- "):
            items = [line[2:] for line in block.splitlines()]
            parts.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in items) + "</ul>")
        elif block.startswith("> "):
            text = " ".join(line[2:] for line in block.splitlines())
            parts.append(f"<p class='warning'>{_inline(text)}</p>")
        else:
            parts.append(f"<p>{_inline(block)}</p>")
    flush()
    parts.append("</body></html>")
    return "\n".join(parts)


def _figure_div(fig: go.Figure) -> str:
    """A figure as a div that fills the page's width (plotly.js loaded by the page); ``fig`` is left as it is."""
    from .._optional import require

    require("plotly", purpose="the analysis's figures")
    import plotly.graph_objects as go

    fig = go.Figure(fig)
    fig.update_layout(width=None, autosize=True)
    return str(fig.to_html(full_html=False, include_plotlyjs=False, config={"responsive": True}))


@checks_arguments
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
    report.broken_videos = len(broken_videos(frames))
    write_report(report, folder / "analysis" if out is None else out, force=force)
    return report
