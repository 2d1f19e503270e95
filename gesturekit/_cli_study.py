"""``gesturekit study ...``: running a user study on a stimuli folder (each subcommand in its own function)."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_study_parser", "run_study"]


def add_study_parser(p: argparse.ArgumentParser) -> None:
    """Add the subcommands of ``gesturekit study`` (``args.study_command``) to its parser ``p``."""
    sub = p.add_subparsers(dest="study_command", metavar="SUBCOMMAND")
    sub.required = True
    _add_analyse(sub)


def run_study(args: argparse.Namespace) -> int:
    """Run the ``study`` subcommand named by ``args.study_command``; returns the exit status."""
    return {"analyse": _analyse}[args.study_command](args)


def _add_analyse(sub: argparse._SubParsersAction) -> None:
    a = sub.add_parser(
        "analyse",
        help="the study's answers: exclusions, per system statistics, tests, Bradley-Terry, a report",
        description="Exclude participants by their attention and audio checks, then per system (and prompt) the "
        "mean and median rating with bootstrap 95 %% intervals over participants, Wilcoxon signed-rank tests of "
        "every pair of systems with Holm-Bonferroni and rank-biserial effect sizes, Bradley-Terry scores (Elo "
        "scale) for pairwise pages; CSVs, figures and a markdown and HTML report into STUDY/analysis/.",
    )
    a.add_argument("study", help="the study folder")
    a.add_argument("--out", help="folder for the report (default STUDY/analysis)")
    a.add_argument("--rounds", type=int, default=10_000, help="bootstrap rounds over participants (default 10000)")
    a.add_argument("--alpha", type=float, default=0.05, help="family-wise error rate per prompt (default 0.05)")
    a.add_argument("--seed", type=int, default=0, help="seed of the bootstraps (default 0)")
    a.add_argument("--store", metavar="URL", help="the store's PostgreSQL URL (default: the study's SQLite file)")
    a.add_argument("--force", action="store_true", help="replace an earlier analysis")


def _analyse(args: argparse.Namespace) -> int:
    from .studies.report import analyse_study

    report = analyse_study(
        Path(args.study),
        out=args.out,
        rounds=args.rounds,
        alpha=args.alpha,
        seed=args.seed,
        force=args.force,
        store_url=args.store,
    )
    print(
        f"{len(report.participants)} participants, {report.excluded} excluded by the checks, "
        f"{report.included} analysed; systems: {', '.join(report.systems)}"
    )
    if report.summary is not None:
        best = report.summary[report.summary["prompt"] == "all"]
        print(
            "mean rating (95 % CI): "
            + "; ".join(f"{r.system} {r.mean:.2f} [{r.mean_lo:.2f}, {r.mean_hi:.2f}]" for r in best.itertuples())
        )
    if report.tests is not None:
        sig = report.tests[(report.tests["prompt"] == "all") & report.tests["significant"]]
        print(
            f"significant differences (all prompts, Holm, alpha={report.alpha}): {len(sig)} of "
            f"{int((report.tests['prompt'] == 'all').sum())} pairs"
        )
    if report.bradley_terry is not None:
        print(
            "Bradley-Terry (Elo, mean 0): "
            + "; ".join(
                f"{r.system} {r.elo:+.0f} [{r.elo_lo:+.0f}, {r.elo_hi:+.0f}]" for r in report.bradley_terry.itertuples()
            )
        )
    for f in report.files:
        print(f)
    return 0
