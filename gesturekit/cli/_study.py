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
        "Write one HEMVIP experiment config per participant row into OUT (HEMVIP's configs/<test id>), pages of "
        "type video (rating) and videopc (pairwise), for HEMVIP's genea2022 branch (github.com/jonepatr/hemvip). "
        "HEMVIP plays Vimeo videos only: upload the media and give --vimeo a CSV of id,vimeo (each media id, its "
        "Vimeo id or URL). OUT/codes.jsonl is the completion for HEMVIP's codes collection (mongoimport).",
    ),
    "analyse": (
        "the study's answers: exclusions, per system statistics, tests, Bradley-Terry, a report",
        "Exclude participants by their attention and audio checks, then per system (and prompt) the mean and "
        "median rating with bootstrap 95 % intervals over participants, Wilcoxon signed-rank tests of every pair "
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
    p.add_argument("--vimeo", metavar="CSV", help="id,vimeo: the Vimeo video of every media id of the study")
    p.add_argument("--media-url", help=argparse.SUPPRESS)  # refused with the reason: HEMVIP plays Vimeo only
    p.add_argument("--force", action="store_true", help="replace configs written before")


def _study_export_hemvip(args: argparse.Namespace) -> int:
    from ..study.design import load_design
    from ..study.hemvip import HEMVIP_VERSION, export_hemvip, read_vimeo_map

    if args.media_url is not None or args.vimeo is None:
        raise ConfigError(
            f"HEMVIP ({HEMVIP_VERSION}) plays every video with Vimeo's player, so plain media URLs never play: "
            "upload the study's media to Vimeo and give --vimeo a CSV of id,vimeo (each media id, its Vimeo id)"
        )
    files = export_hemvip(load_design(args.study), args.out, vimeo=read_vimeo_map(args.vimeo), overwrite=args.force)
    print(f"{len(files)} HEMVIP configs for {HEMVIP_VERSION} in {args.out}; completion: {args.out}/codes.jsonl")
    return 0


def add_import_hemvip(p: argparse.ArgumentParser) -> None:
    """Options of ``study import-hemvip``."""
    p.add_argument("study", metavar="STUDY", help="study folder with design.json")
    p.add_argument("results", nargs="+", help="HEMVIP result JSON files")
    p.add_argument("--out", required=True, help="CSV to write (answers as JSON text)")
    p.add_argument("--force", action="store_true", help="replace the CSV")


def _study_import_hemvip(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..outputs import check_not_input
    from ..study.design import load_design
    from ..study.hemvip import import_hemvip, write_responses_csv

    folder = Path(args.study)
    inputs = [*args.results, *(folder / n for n in ("design.json", "manifest.csv", "order.csv", "responses.sqlite3"))]
    check_not_input(args.out, inputs)  # --force must never replace the study's key or a result file
    notes: list[str] = []
    frame = import_hemvip(load_design(args.study), args.results, notes=notes)
    for note in notes:
        print(note)
    write_responses_csv(frame, args.out, overwrite=args.force)
    broken = sum(1 for a in frame["answers"] if a.get("broken_video"))
    print(
        f"{len(frame)} responses of {frame['token'].nunique()} participants in {args.out}; "
        f"broken-video reports: {broken}"
    )
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
    flow = report.flow
    print(
        f"{flow['started']} started, {flow['answered_nothing']} answered nothing, {flow['excluded']} excluded by "
        f"the checks, {flow['no_kept_answer']} with no rating or pairwise answer, {flow['analysed']} analysed "
        f"({flow['analysed_finished']} finished); systems: {', '.join(report.systems)}"
    )
    for warning in report.warnings:
        print(f"warning: {warning}")

    def span(lo: float, hi: float, fmt: str) -> str:  # never a point printed as an interval
        return f"[{lo:{fmt}}, {hi:{fmt}}]" if lo < hi else "(no interval)"

    if report.summary is not None:
        every = report.summary[report.summary["prompt"] == "all"]
        cells = [f"{r.system} {r.mean:.2f} {span(r.mean_lo, r.mean_hi, '.2f')}" for r in every.itertuples()]
        print("mean rating, all prompts (95 % CI): " + "; ".join(cells))
    if report.tests is not None:
        every = report.tests[(report.tests["prompt"] == "all") & (report.tests["result"] != "not compared")]
        print(
            f"significantly different pairs (all prompts, Holm, alpha={report.alpha}): "
            f"{int(every['significant'].sum())} of {len(every)} compared"
        )
    if report.bradley_terry is not None:
        cells = [
            f"{r.system} {r.elo:+.0f} {span(r.elo_lo, r.elo_hi, '+.0f')}" for r in report.bradley_terry.itertuples()
        ]
        print("Bradley-Terry (Elo, mean 0 within each connected part): " + "; ".join(cells))
    for path in report.files:
        print(path)
    return 0
