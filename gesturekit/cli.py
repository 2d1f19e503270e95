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
