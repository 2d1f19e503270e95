"""The command line: ``gesturekit build-db``, ``gesturekit info``, ...

Every command turns errors of the gesturekit family into one line on stderr
(exit status 2) and prints warnings as ``warning: ...`` lines.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

from .errors import ConfigError, GestureKitError, GestureKitWarning

__all__ = ["main", "build_parser"]


def _progress_bar(total, unit, desc):
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, dynamic_ncols=True, leave=False)


def _cmd_build_db(args) -> int:
    from .database import BuildConfig, MatchingDatabase
    from .demo import build_demo_database
    from .paths import default_database_path

    t0 = time.perf_counter()
    if args.demo:
        if args.folder is not None:
            raise ConfigError("give either a folder of takes or --demo, not both")
        out = Path(args.out) if args.out else default_database_path()
        total = args.minutes * 60
        with _progress_bar(round(total), "s", "demo speaker") as bar:
            def progress(done, tot):
                bar.n = round(done)
                bar.refresh()

            db = build_demo_database(out, minutes=args.minutes, seed=args.seed, overwrite=args.force, progress=progress)
    else:
        from .datasets.takes import count_takes, discover_takes, iter_takes

        if args.folder is None:
            raise ConfigError("give a folder of takes to build from, or --demo for the generated demo speaker")
        if not args.out:
            raise ConfigError("give the database folder to write with --out")
        out = Path(args.out)
        if out.exists() and not args.force:
            raise GestureKitError(f"{out}: a database already exists here; add --force to replace it")
        joint_map = args.joint_map or args.preset
        sources = discover_takes(args.folder, kind=args.kind)
        n = count_takes(sources)
        config = BuildConfig(
            overlap_stride=args.overlap_stride,
            percentiles=tuple(args.percentiles),
            store_audio=not args.no_audio,
            label=args.label or "",
            source=str(Path(args.folder).resolve()),
            joint_map=None if joint_map is None else str(joint_map),
        )
        with _progress_bar(n, "take", "reading takes") as bar:
            def progress(i, name):
                bar.set_postfix_str(name[-30:])
                bar.update(1)

            takes = iter_takes(sources, joint_map=joint_map, fps_in=args.fps, units=args.units)
            db = MatchingDatabase.build(takes, config=config, progress=progress)
        db.save(out, overwrite=args.force)
    print(db.summary_text())
    print(f"built in {time.perf_counter() - t0:.1f} s")
    return 0


def _cmd_info(args) -> int:
    from .database import MatchingDatabase
    from .paths import default_database_path

    db = MatchingDatabase.load(args.database or default_database_path())
    print(db.summary_text())
    if args.takes:
        print()
        print(db.takes_table().to_string(index=False))
    return 0


def _parse_range(text: str) -> tuple[str, float, float]:
    """``TAKE:START-END`` (seconds) -> (take, start, end)."""
    import re

    m = re.match(r"^(.+):\s*([0-9.]+)\s*-\s*([0-9.]+)\s*$", text)
    if not m:
        raise ConfigError(f"--exclude-range {text!r} must look like TAKE:START-END (seconds)")
    return m.group(1), float(m.group(2)), float(m.group(3))


def _speech_files(inputs: list[str]) -> list[Path]:
    from .datasets.takes import AUDIO_EXTENSIONS
    from .errors import InputFileError

    files: list[Path] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in AUDIO_EXTENSIONS)
            if not found:
                raise InputFileError(f"no speech files ({'/'.join(AUDIO_EXTENSIONS)}) in this folder", path=p)
            files += found
        else:
            files.append(p)
    return files


def _cmd_synthesize(args) -> int:
    from .control import load_control_file, parse_control
    from .database import MatchingDatabase
    from .datasets.audio import load_audio
    from .demo import open_default_database
    from .export.files import safe_filename
    from .synthesize import SynthesisConfig, synthesize_batch

    t0 = time.perf_counter()
    files = _speech_files(args.speech)
    db = MatchingDatabase.load(args.db) if args.db else open_default_database()
    control = ""
    if args.control:
        if Path(args.control).is_file():
            control = load_control_file(args.control).to_text()
        else:
            control = parse_control(args.control).to_text()
    config = SynthesisConfig(
        k=args.k, step=args.step, topk=args.topk, seed=args.seed, init=args.init_pose,
        mask_rule=args.mask_rule, blend=args.blend, control=control,
        exclude_takes=tuple(args.exclude_take or ()),
        exclude_ranges=tuple(_parse_range(r) for r in (args.exclude_range or ())),
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stems = [safe_filename(f.stem) for f in files]
    if len(set(stems)) != len(stems):
        raise ConfigError("two speech files have the same name; synthesise them in separate runs")
    kinds = ["npz", "bvh"] + (["mp4"] if args.video else [])
    targets = {(stem, kind): out / f"{stem}.{kind}" for stem in stems for kind in kinds}
    existing = [str(p) for p in targets.values() if p.exists()]
    if existing and not args.force:
        raise GestureKitError(f"{existing[0]}: exists already ({len(existing)} output file(s) would be replaced); add --force")
    audios = [load_audio(f) for f in files]
    results = synthesize_batch(audios, db=db, config=config)
    for f, stem, res in zip(files, stems, results):
        res.source = f.name
        res.save_npz(targets[(stem, "npz")], overwrite=args.force)
        res.save_bvh(targets[(stem, "bvh")], overwrite=args.force)
        written = [targets[(stem, "npz")], targets[(stem, "bvh")]]
        if args.video:
            with _progress_bar(res.n_frames, "frame", f"rendering {stem}") as bar:
                res.save_video(targets[(stem, "mp4")], overwrite=args.force,
                               progress=lambda done, total: (setattr(bar, "n", done), bar.refresh()))
            written.append(targets[(stem, "mp4")])
        relaxed = res.relaxed_steps
        note = f"; control relaxed at {len(relaxed)} step(s)" if relaxed else ""
        print(f"{f.name}: {res.n_frames} frames ({res.n_frames / res.motion.fps:.2f} s), "
              f"{res.search.n_steps} steps{note} -> {', '.join(str(w) for w in written)}")
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gesturekit",
        description="Controllable speech-driven gesture synthesis by motion matching.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    b = sub.add_parser(
        "build-db",
        help="build a matching database from a folder of takes (or the generated demo speaker)",
        description="Build a matching database from a folder of takes: BVH + speech (ZEGGS, BEAT, any BVH with a "
        "joint map), joint-position files + speech, or npz files of the Habibie et al. 2021 layout.",
    )
    b.add_argument("folder", nargs="?", help="folder of takes")
    b.add_argument("--out", help="database folder to write (default for --demo: the app's default path)")
    b.add_argument("--preset", choices=["zeggs", "beat"], help="joint naming preset of the BVH files")
    b.add_argument("--joint-map", help="JSON joint map for other skeletons or joint-position files")
    b.add_argument("--kind", default="auto", choices=["auto", "bvh", "positions", "habibie2021"])
    b.add_argument("--fps", type=float, help="frame rate of joint-position files")
    b.add_argument("--units", default="auto", choices=["auto", "cm", "m"], help="units of the motion files")
    b.add_argument("--overlap-stride", type=int, help="also store an overlapping cut (stride in frames) for the refiner")
    b.add_argument("--percentiles", type=float, nargs=2, default=(15.0, 85.0), metavar=("LOW", "HIGH"),
                   help="attribute percentiles that define low/high controls (default 15 85)")
    b.add_argument("--no-audio", action="store_true", help="do not keep the takes' audio in the database")
    b.add_argument("--label", help="a description stored with the database")
    b.add_argument("--force", action="store_true", help="replace an existing database")
    b.add_argument("--demo", action="store_true", help="build the generated demo speaker's database")
    b.add_argument("--minutes", type=float, default=20.0, help="minutes of demo speaker (with --demo)")
    b.add_argument("--seed", type=int, default=0, help="seed of the demo speaker (with --demo)")
    b.set_defaults(func=_cmd_build_db)

    i = sub.add_parser("info", help="describe a matching database")
    i.add_argument("database", nargs="?", help="database folder (default: the demo database)")
    i.add_argument("--takes", action="store_true", help="also list the takes")
    i.set_defaults(func=_cmd_info)

    y = sub.add_parser(
        "synthesize",
        help="gesture motion for speech: npz + BVH (+ MP4 with --video)",
        description="Synthesise gesture motion for one or more speech files (or folders of them) by motion "
        "matching. Several files are searched together, scanning the database once per step.",
    )
    y.add_argument("speech", nargs="+", help="speech files (wav, flac, ogg, mp3; any rate) or folders of them")
    y.add_argument("--db", help="matching database folder (default: the demo database)")
    y.add_argument("--out", default="out", help="output folder (default: out)")
    y.add_argument("--k", type=int, default=0, help="take the k-th best candidate of each step (default 0)")
    y.add_argument("--step", type=int, default=8, help="frames per search step, N (default 8)")
    y.add_argument("--topk", type=int, default=10, help="candidates per step to record (default 10)")
    y.add_argument("--seed", type=int, default=0, help="seed of the random initial pose (default 0)")
    y.add_argument("--init-pose", choices=["random", "rest"], default="random",
                   help="initial pose: a random admissible database frame (the paper) or the rest pose")
    y.add_argument("--control", help='control track: "0-3:left_hand=low,3-6:speed=slow+symmetry=symmetric" '
                   "(seconds) or a CSV/JSON file with start_s, end_s, constraint")
    y.add_argument("--mask-rule", choices=["ends", "all"], default="ends",
                   help="a control must hold at a window's first and last frame (ends: the paper) or every frame")
    y.add_argument("--blend", choices=["none", "offset"], default="none",
                   help="none: the paper's hard joins; offset: a short fade at each join (ours)")
    y.add_argument("--exclude-take", action="append", metavar="TAKE", help="keep a database take out of the search")
    y.add_argument("--exclude-range", action="append", metavar="TAKE:START-END",
                   help="keep a stretch of a take (seconds) out of the search")
    y.add_argument("--video", action="store_true", help="also render an MP4 of the skeleton with the speech")
    y.add_argument("--force", action="store_true", help="replace existing output files")
    y.set_defaults(func=_cmd_synthesize)
    return p


def _format_warning(message, category, filename, lineno, line=None):
    return f"warning: {message}\n"


def main(argv=None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("always", GestureKitWarning)
        old = warnings.formatwarning
        warnings.formatwarning = _format_warning
        try:
            return args.func(args)
        except GestureKitError as exc:
            print(f"gesturekit: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("gesturekit: interrupted", file=sys.stderr)
            return 130
        finally:
            warnings.formatwarning = old


if __name__ == "__main__":
    sys.exit(main())
