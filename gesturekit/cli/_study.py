"""``gesturekit study``: the subcommands that run a user study on a stimuli folder.

Each subcommand has its options in ``add_*`` and its work in ``_study_*`` (``init`` ->
:func:`_study_init`); :func:`run` calls the one given.
"""

from __future__ import annotations

import argparse
import sys

from ..errors import ConfigError

__all__ = ["add_study_parser", "run"]

_ABOUT = {
    "init": (
        "add a design to a stimuli folder: design.json and the attention- and audio-check media",
        "Write STUDY/design.json (the instructions, rating and/or pairwise pages, attention checks, the audio "
        "check, a questionnaire, the completion code) and make the check media from the stimuli into "
        "STUDY/checks/. Edit design.json afterwards; it is validated whenever it is read.",
    ),
    "serve": (
        "serve the study to participants: pages, videos, the researcher's view",
        "Start the participant web server (uvicorn): the entry URL takes Prolific's PROLIFIC_PID, STUDY_ID and "
        "SESSION_ID; responses go to STUDY/responses.sqlite3 or the PostgreSQL database of --db; /researcher "
        "(the design's password) shows progress and the responses as CSV. Binds 127.0.0.1 unless told.",
    ),
    "export-hemvip": (
        "write the study as HEMVIP configs: one JSON per participant",
        "Write one HEMVIP (webMUSHRA) experiment config per participant row into OUT, pages of type video "
        "(rating) and videopc (pairwise), the media referred to as URL/<id>.mp4.",
    ),
    "analyse": (
        "the study's answers: exclusions, per system statistics, tests, Bradley-Terry, a report",
        "Exclude participants by their attention and audio checks, then per system (and prompt) the mean and "
        "median rating with bootstrap 95 %% intervals over participants, Wilcoxon signed-rank tests of every pair "
        "of systems with Holm-Bonferroni and rank-biserial effect sizes, Bradley-Terry scores (Elo scale) for "
        "pairwise pages; CSVs, figures and a markdown and HTML report into STUDY/analysis/.",
    ),
    "import-hemvip": (
        "read HEMVIP result JSON into a CSV of responses the analysis reads",
        "Read HEMVIP result files (one session object or a list of them per file, as HEMVIP's export writes) "
        "and write the responses, one row per page, as a CSV.",
    ),
}


def _sub(sub, name: str) -> argparse.ArgumentParser:
    summary, description = _ABOUT[name]
    return sub.add_parser(name, help=summary, description=description)


def add_study_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``study`` subcommands to ``parser`` (``args.study_command`` names the one given)."""
    sub = parser.add_subparsers(dest="study_command", metavar="SUBCOMMAND")
    sub.required = True
    add_init(_sub(sub, "init"))
    add_serve(_sub(sub, "serve"))
    add_export_hemvip(_sub(sub, "export-hemvip"))
    add_import_hemvip(_sub(sub, "import-hemvip"))
    add_analyse(_sub(sub, "analyse"))


def run(args: argparse.Namespace) -> int:
    """Run the ``study`` subcommand ``args.study_command``; the exit status."""
    return globals()["_study_" + args.study_command.replace("-", "_")](args)


# ---- init ---------------------------------------------------------------------------------------


def add_init(p: argparse.ArgumentParser) -> None:
    """Options of ``study init``."""
    p.add_argument("study", metavar="STUDY", help="stimuli folder (gesturekit stimuli --out)")
    p.add_argument("--scale", choices=("likert7", "slider100"), default="likert7", help="the rating scale")
    p.add_argument("--pairwise", action="store_true", help="also pairwise pages: every pair of systems per speech")
    p.add_argument("--no-rating", action="store_true", help="no rating pages (pairwise pages only)")
    p.add_argument("--attention", type=int, default=2, help="attention checks per participant (default 2)")
    p.add_argument("--no-audio-check", action="store_true", help="no count-the-beeps page at the start")
    p.add_argument("--password", help="the researcher's password (kept as a scrypt hash)")
    p.add_argument("--redirect", metavar="URL", help="where participants go when done; {code} becomes the code")
    p.add_argument("--force", action="store_true", help="replace an existing design.json and its check media")


def _study_init(args: argparse.Namespace) -> int:
    from ..study.design import init_study, participant_pages

    if args.no_rating and not args.pairwise:
        raise ConfigError("--no-rating needs --pairwise: a study needs rating or pairwise pages")
    bar = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="frame", desc="check videos", file=sys.stderr, leave=False)
        bar.n = done
        bar.refresh()

    try:
        design = init_study(
            args.study,
            scale=args.scale,
            rating=not args.no_rating,
            pairwise=args.pairwise,
            attention=args.attention,
            audio_check=not args.no_audio_check,
            password=args.password,
            redirect=args.redirect,
            overwrite=args.force,
            progress=progress,
        )
    finally:
        if bar is not None:
            bar.close()
    pages = participant_pages(design, 1)
    print(f"design: {design.folder / 'design.json'} ({design.participants} participants, {len(pages)} pages each)")
    print(f"check media: {len(design.checks)} videos" + (", the audio check" if design.audio_check else ""))
    print(f"completion code: {design.completion_code}")
    return 0


# ---- serve ---------------------------------------------------------------------------------------


def add_serve(p: argparse.ArgumentParser) -> None:
    """Options of ``study serve``."""
    p.add_argument("study", metavar="STUDY", help="study folder with design.json (gesturekit study init)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    p.add_argument("--db", metavar="URL", help="postgresql://user:pass@host/db (default: STUDY/responses.sqlite3)")
    p.add_argument("--root-path", default="", help="URL prefix a reverse proxy serves the study under, e.g. /study")
    p.add_argument("--forwarded-allow-ips", default="127.0.0.1", help="proxies whose X-Forwarded-* headers are trusted")


def _study_serve(args: argparse.Namespace) -> int:
    from ..study.design import load_design
    from ..study.server import serve

    design = load_design(args.study)  # errors in design.json before anything listens
    url = f"http://{args.host}:{args.port}{args.root_path.rstrip('/')}/"
    print(f"serving {design.title!r} ({design.participants} order rows) at {url}", flush=True)
    print(f"participants: {url}?PROLIFIC_PID=...&STUDY_ID=...&SESSION_ID=...; researcher: {url}researcher", flush=True)
    serve(
        args.study,
        host=args.host,
        port=args.port,
        db=args.db,
        root_path=args.root_path.rstrip("/"),
        forwarded_allow_ips=args.forwarded_allow_ips,
    )
    return 0


# ---- HEMVIP -------------------------------------------------------------------------------------


def add_export_hemvip(p: argparse.ArgumentParser) -> None:
    """Options of ``study export-hemvip``."""
    p.add_argument("study", metavar="STUDY", help="study folder with design.json")
    p.add_argument("--out", required=True, help="folder to write the configs into")
    p.add_argument("--media-url", default="/media", help="URL prefix of the media files (default /media)")
    p.add_argument("--force", action="store_true", help="replace configs written before")


def _study_export_hemvip(args: argparse.Namespace) -> int:
    from ..study.design import load_design
    from ..study.hemvip import export_hemvip

    files = export_hemvip(load_design(args.study), args.out, media_url=args.media_url, overwrite=args.force)
    print(f"{len(files)} HEMVIP configs in {args.out}")
    return 0


def add_import_hemvip(p: argparse.ArgumentParser) -> None:
    """Options of ``study import-hemvip``."""
    p.add_argument("study", metavar="STUDY", help="study folder with design.json")
    p.add_argument("results", nargs="+", help="HEMVIP result JSON files")
    p.add_argument("--out", required=True, help="CSV to write (answers as JSON text)")
    p.add_argument("--force", action="store_true", help="replace the CSV")


def _study_import_hemvip(args: argparse.Namespace) -> int:
    from ..study.design import load_design
    from ..study.hemvip import import_hemvip, write_responses_csv

    frame = import_hemvip(load_design(args.study), args.results)
    write_responses_csv(frame, args.out, overwrite=args.force)
    print(f"{len(frame)} responses of {frame['token'].nunique()} participants in {args.out}")
    return 0


# ---- analyse ------------------------------------------------------------------------------------


def add_analyse(p: argparse.ArgumentParser) -> None:
    """Options of ``study analyse``."""
    p.add_argument("study", metavar="STUDY", help="study folder with design.json")
    p.add_argument("--out", help="folder for the report (default STUDY/analysis)")
    p.add_argument("--rounds", type=int, default=10_000, help="bootstrap rounds over participants (default 10000)")
    p.add_argument("--alpha", type=float, default=0.05, help="family-wise error rate per prompt (default 0.05)")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstraps (default 0)")
    p.add_argument("--store", metavar="URL", help="the store's PostgreSQL URL (default: the study's SQLite file)")
    p.add_argument(
        "--responses", metavar="CSV", help="analyse these responses (study import-hemvip --out) instead of the store"
    )
    p.add_argument("--force", action="store_true", help="replace an earlier analysis")


def _study_analyse(args: argparse.Namespace) -> int:
    from ..study.report import analyse_study

    report = analyse_study(
        args.study,
        out=args.out,
        rounds=args.rounds,
        alpha=args.alpha,
        seed=args.seed,
        force=args.force,
        store_url=args.store,
        responses=args.responses,
    )
    print(
        f"{len(report.participants)} participants, {report.excluded} excluded by the checks, "
        f"{report.included} analysed; systems: {', '.join(report.systems)}"
    )
    if report.summary is not None:
        every = report.summary[report.summary["prompt"] == "all"]
        cells = [f"{r.system} {r.mean:.2f} [{r.mean_lo:.2f}, {r.mean_hi:.2f}]" for r in every.itertuples()]
        print("mean rating, all prompts (95 % CI): " + "; ".join(cells))
    if report.tests is not None:
        every = report.tests[report.tests["prompt"] == "all"]
        print(
            f"significantly different pairs (all prompts, Holm, alpha={report.alpha}): "
            f"{int(every['significant'].sum())} of {len(every)}"
        )
    if report.bradley_terry is not None:
        cells = [
            f"{r.system} {r.elo:+.0f} [{r.elo_lo:+.0f}, {r.elo_hi:+.0f}]" for r in report.bradley_terry.itertuples()
        ]
        print("Bradley-Terry (Elo, mean 0): " + "; ".join(cells))
    for f in report.files:
        print(f)
    return 0
