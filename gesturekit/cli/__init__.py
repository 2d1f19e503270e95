"""The command line: ``gesturekit build-db``, ``gesturekit info``, ..., ``gesturekit app``; ``gesturekit --version``.

Every command turns errors of the gesturekit family into one line on stderr
(exit status 2) and prints warnings as ``warning: ...`` lines.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import sys
import time
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import ConfigError, GestureKitError, GestureKitWarning, warn
from ..paths import is_file
from ._app import run as _cmd_app  # noqa: F401  (main finds it by name; streamlit is imported only as it runs)
from ._options import flag_of, options_given
from ._parser import build_parser, join_axis_values

if TYPE_CHECKING:
    from ..database import BuildConfig, MatchingDatabase

__all__ = ["main", "build_parser"]


# control characters (an escape sequence in a file name would drive the terminal), shown escaped
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def shown(text: object) -> str:
    """``text`` as the terminal should see it: control characters escaped (``\\x1b``), newlines kept.

    Every line the command line prints goes through it, so a file or take name holding an
    escape sequence is shown, never obeyed.
    """
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", str(text))


def _print(*values: object, **options) -> None:
    print(*(shown(v) for v in values), **options)


def _progress_bar(total, unit, desc):
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=shown(desc), file=sys.stderr, dynamic_ncols=True, leave=False)


def _advance(bar, done, total=None, note: str | None = None) -> None:
    """Show ``done`` (of ``total``, when it is only known now) on a progress bar, with a note after it."""
    if total is not None:
        bar.total = total
    bar.n = done
    if note is not None:
        bar.set_postfix_str(shown(note), refresh=False)
    bar.refresh()


@contextlib.contextmanager
def _stage_bars():
    """Progress bars of a command's stages in turn: ``bar(desc, total, unit)`` is the stage's bar,
    made (and the one before closed) when the stage starts; all are closed when the block ends."""
    bars: dict = {}

    def bar(desc, total, unit):
        if desc not in bars:
            for earlier in bars.values():
                earlier.close()
            bars[desc] = _progress_bar(total, unit, desc)
        return bars[desc]

    try:
        yield bar
    finally:
        for each in bars.values():
            each.close()


def _cmd_build_db(args) -> int:
    from ..demo import build_demo_database
    from ..paths import default_database_path

    _check_positive("--fps", args.fps, "frame rate")
    notes: list[str] = []
    if args.demo:
        _check_positive("--minutes", args.minutes, "number of minutes")
        if args.folder is not None:
            raise ConfigError("give either a folder of takes or --demo, not both")
        given = [o for o, v in (("--append", args.append), ("--keep-stats", args.keep_stats)) if v]
        given += [o for o, v in (("--workers", args.workers), ("--scheduler", args.scheduler)) if v is not None]
        if given:
            raise ConfigError(f"{', '.join(given)} build from a folder of takes; --demo generates its takes")
        out = Path(args.out) if args.out else default_database_path()
        total = args.minutes * 60
        with _progress_bar(round(total), "s", "demo speaker") as bar:
            db = build_demo_database(
                out,
                minutes=args.minutes,
                seed=args.seed,
                overwrite=args.force,
                progress=lambda done, tot: _advance(bar, round(done)),
            )
    else:
        if args.folder is None:
            raise ConfigError("give a folder of takes to build from, or --demo for the generated demo speaker")
        if not args.out:
            raise ConfigError("give the database folder to write with --out")
        if args.fps is not None:
            from ..limits import check_fps

            check_fps(args.fps, what="the frame rate of the joint-position files", option="--fps")
        from ..outputs import check_output, output_lock

        out = Path(args.out)
        _check_scale_options(args)
        # before reading any take: the output must be free, ours to replace, and apart from the takes
        there = check_output(out, "database", overwrite=args.force or args.append, inputs=[args.folder])
        if args.append and not there:
            raise ConfigError(f"--append adds takes to a database, and there is none at {out}; build it first")
        from ..workspace import build_database

        config, label = _build_config(args)
        with output_lock(out), _stage_bars() as bar:  # the bar shows once the first take is read
            db = build_database(
                args.folder,
                out,
                config=config,
                joint_map=args.joint_map or args.preset,
                kind=args.kind,
                fps=args.fps,
                units=args.units,
                up=args.up,
                forward=args.forward,
                normalize_bones=args.normalize_bones,
                check_plausible=not args.no_plausibility_check,
                allow_duration_mismatch=args.allow_duration_mismatch,
                overwrite=args.force,
                locked=True,
                workers=args.workers,
                scheduler=args.scheduler,
                append=args.append,
                keep_stats=args.keep_stats,
                label=label,
                on_progress=lambda p: _advance(
                    bar("fitting the skeleton" if p.phase == "fit" else "reading takes", p.total, "take"),
                    p.done,
                    note=f"{p.seconds / 3600:.2f} h of data, {p.name[-24:]}",
                ),
                notes=notes.append,
            )
    _print(db.summary_text())
    _print_readings(db)
    for line in notes:  # staged takes reused, what --append did
        _print(line)
    return _done(args, "built")


def _check_scale_options(args: argparse.Namespace) -> None:
    """``--workers``, ``--scheduler``, ``--append`` and ``--keep-stats`` make sense together."""
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be a positive number of processes, got {args.workers}")
    if args.workers is not None and args.scheduler:
        raise ConfigError("give either --workers (processes here) or --scheduler (a Dask cluster), not both")
    if args.scheduler is not None and not args.scheduler.strip():
        raise ConfigError("--scheduler must be the address of a Dask scheduler, e.g. tcp://host:8786")
    if args.keep_stats and not args.append:
        raise ConfigError("--keep-stats keeps the statistics of a database appended to; it needs --append")
    if args.append and args.force:
        raise ConfigError("give either --append (add takes to the database) or --force (replace it), not both")


def _build_config(args: argparse.Namespace) -> tuple[BuildConfig | None, str | None]:
    """The build-db options as a BuildConfig (None: the database's, with ``--append`` and none given), and the label.

    Options left out take BuildConfig's defaults for a new database; with ``--append`` they
    are the database's, and those given are checked against the database's by the build. A
    label given replaces the database's (None: keep it).
    """
    from ..database import BuildConfig

    given = options_given(args, only_given=True)[BuildConfig]
    label = given.pop("label", None)
    if not given.get("store_audio", True):
        named = [flag_of(BuildConfig, k) for k in ("audio_format", "audio_rate") if k in given]
        if named:
            raise ConfigError(
                f"{' and '.join(named)} choose how the audio is kept, but --no-audio keeps none; give one or the other"
            )
    if args.append:
        if not given:  # --append alone: the database's options
            return None, label
        from dataclasses import replace

        from ..database.config import recorded_config
        from ..database.sources import recorded_build

        # those left out are the database's; those given must be (checked by the build, naming them)
        recorded = recorded_build(args.out)
        return replace(recorded_config(recorded) if recorded is not None else BuildConfig(), **given), label
    values = {k: v for k, v in options_given(args)[BuildConfig].items() if v is not None}  # None: not given
    return BuildConfig(**values), label


def _print_readings(db: MatchingDatabase) -> None:
    """How the takes were read (axes, units, derived and absent joints, bone lengths), when recorded."""
    from ..datasets.takes import reading_lines

    for line in reading_lines(db.meta.get("takes", [])):
        _print(line)


def _cmd_info(args) -> int:
    from ..database import MatchingDatabase
    from ..paths import default_database_path

    db = MatchingDatabase.load(args.database or default_database_path())
    _print(db.summary_text())
    _print_readings(db)
    if args.takes:
        _print()
        _print(db.takes_table().to_string(index=False))
    return 0


def _check_positive(option: str, value: float | None, what: str) -> None:
    """Refuse a numeric option that is given but not a finite number > 0 (nan, inf, 0, negative)."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{option} must be a positive {what}, got {value:g}")


def _parse_range(text: str) -> tuple[str, float, float]:
    """``TAKE:START-END`` (seconds; the range after the last ``:``) -> (take, start, end)."""
    from ..control import parse_time_range

    take, colon, times = text.rpartition(":")
    what = f"--exclude-range {text!r}"
    if not colon or not take.strip():
        raise ConfigError(f"{what} must look like TAKE:START-END in seconds")
    start, end = parse_time_range(times, what=what, form="TAKE:START-END")
    return take.strip(), start, end


#: What ``synthesize --format`` may list, in the order they are written.
SYNTHESIS_FORMATS = ("npz", "bvh", "glb")


def _parse_formats(text: str) -> list[str]:
    """``synthesize --format``: ``"npz,bvh,glb"`` -> the formats, each once, in :data:`SYNTHESIS_FORMATS`' order."""
    given = [f.strip().lower() for f in str(text).split(",")]
    for f in given:
        if f not in SYNTHESIS_FORMATS:
            shown = f"{f!r}" if f else "an empty entry"
            raise ConfigError(
                f"--format {text!r}: {shown} is not an output; list some of {', '.join(SYNTHESIS_FORMATS)}, "
                "separated by commas (e.g. npz,bvh,glb)"
            )
    return [f for f in SYNTHESIS_FORMATS if f in given]


def _parse_holdouts(texts) -> list:
    """Check ``--holdout`` values before any work starts; each as :class:`~gesturekit.evaluate.run.Holdout`."""
    from ..evaluate.run import parse_holdout

    out = []
    for text in texts or ():
        try:
            out.append(parse_holdout(text))
        except ConfigError as exc:
            raise ConfigError(f"--holdout: {exc}") from None
    return out


def _refiner_choice(given: str | None, db):
    """The refiner of ``synthesize``: the one named, none for ``none``, else one trained on ``db``
    (:func:`gesturekit.refine.refiner_for`; the app's default too)."""
    from .._optional import installed

    if given is not None:
        return None if given == "none" else given
    if not installed("torch"):  # a gesturekit installed without the refiner's torch
        return None
    from ..refine import refiner_for

    found = refiner_for(db)
    if found is not None:
        _print(f"refining with {found}, trained on this database (--refiner none: the k-NN motion alone)")
    return found


def _search_options(args: argparse.Namespace) -> dict:
    """The command's options of the search and the synthesis, as :class:`SynthesisConfig` keywords
    (it passes the search's on), checked against the fields' bounds."""
    from ..search import SearchConfig
    from ..synthesis import SynthesisConfig

    given = options_given(args)
    return {**given[SearchConfig], **given[SynthesisConfig]}


def _cmd_synthesize(args) -> int:
    from .._io import safe_filename
    from ..datasets.audio import load_audio
    from ..export.bvh import bvh_parents
    from ..export.gltf import audio_path_for
    from ..export.result import (
        export_result_bvh,
        export_result_glb,
        retarget_result,
        save_result_npz,
        save_result_video,
    )
    from ..outputs import output_lock, write_errors
    from ..refine import open_refiner
    from ..search import describe_steps
    from ..synthesis import SynthesisConfig, synthesize_batch
    from ..synthesis.synthesizer import open_search_device
    from ..workspace import expand_speech, open_database
    from ._character import check_target, read_character_option, write_character_files

    formats = _parse_formats(args.format)
    device = open_search_device(args.search_device)
    character = read_character_option(args, formats)  # None without --character; read before the search
    files = expand_speech(args.speech)
    control = _control_from_arg(args.control) or ""
    exclude_ranges = tuple(_parse_range(r) for r in (args.exclude_range or ()))
    out = Path(args.out)
    stems = [safe_filename(f.stem) for f in files]
    first: dict[str, Path] = {}
    for f, stem in zip(files, stems):  # checked before anything is written
        if stem in first:
            raise ConfigError(
                f"{first[stem]} and {f} would both be written as {out / stem}.npz; rename one, "
                "or synthesise them in separate runs"
            )
        first[stem] = f
    if args.video:  # before the search, so that nothing is written
        from .._optional import require

        require("pyvista", purpose="--video")
        require("imageio_ffmpeg", purpose="--video")
    db = open_database(args.db)
    tree = [f for f in formats if f in ("bvh", "glb")]
    try:  # a skeleton no BVH or glTF can hold is refused before the search
        if tree:
            bvh_parents(db.joint_presence)
    except ConfigError as exc:
        names = " and ".join(f.upper() if f == "bvh" else "glTF" for f in tree)
        raise ConfigError(f"synthesize writes a {names} of every result, and {exc.problem}", path=args.db) from None
    config = SynthesisConfig(
        **_search_options(args),
        control=control,
        exclude_takes=tuple(args.exclude_take or ()),
        exclude_ranges=exclude_ranges,
    )
    if out.exists() and not out.is_dir():
        raise GestureKitError(f"{out}: is a file, not a folder; give --out a folder for the results")
    kinds = formats + (["wav"] if "glb" in formats else []) + (["mp4"] if args.video else [])
    targets = {(stem, kind): out / f"{stem}.{kind}" for stem in stems for kind in kinds}
    if "glb" in formats:  # the speech beside each glTF file, where it names it
        targets.update({(stem, "wav"): audio_path_for(targets[(stem, "glb")]) for stem in stems})
    existing = [str(p) for p in targets.values() if p.exists()]
    if existing and not args.force:
        raise GestureKitError(
            f"{existing[0]}: exists already ({len(existing)} output file(s) would be replaced); add --force"
        )
    for (_, kind), p in targets.items():
        # with --force too: only files gesturekit wrote are replaced, and never a folder
        check_target(p, kind, character, overwrite=args.force, inputs=files)
    audios = [load_audio(f) for f in files]
    refiner = open_refiner(_refiner_choice(args.refiner, db))
    labels, device = [str(f) for f in files], device or "cpu"
    results = synthesize_batch(audios, db=db, config=config, refiner=refiner, names=labels, search_device=device)
    with write_errors(out):
        out.mkdir(parents=True, exist_ok=True)  # only once there is something to write
    with contextlib.ExitStack() as held:
        for (_, kind), p in targets.items():
            # a second synthesize writing the same files fails here and says so; checked again
            # under the lock, since another run may have written them while this one searched
            held.enter_context(output_lock(p))
            check_target(p, kind, character, overwrite=args.force, inputs=files)
        # a late error (a character that cannot carry a result, a disk that fills up) takes back what this run wrote
        held.enter_context(_taken_back_on_error(list(targets.values())))
        retargeted = [None if character is None else retarget_result(res, character) for res in results]
        for f, stem, res, on_theirs in zip(files, stems, results, retargeted):
            res.source = f.name
            reports: list[str] = []
            if "npz" in formats:
                save_result_npz(res, targets[(stem, "npz")], overwrite=args.force)
            if on_theirs is not None:  # their character in place of ours
                theirs = {k: targets[(stem, k)] for k in tree}
                options = {"overwrite": args.force, "thresholds": db.thresholds, "their_clips": args.character_clips}
                write_character_files(res, on_theirs, theirs, show=reports.append, **options)
            if "bvh" in formats and character is None:
                reports.append(
                    f"  BVH {export_result_bvh(res, targets[(stem, 'bvh')], overwrite=args.force).summary()}"
                )
            if "glb" in formats and character is None:
                glb = export_result_glb(res, targets[(stem, "glb")], overwrite=args.force)
                reports.append(f"  glTF {glb.summary()}")
            written = [targets[(stem, kind)] for kind in kinds if kind != "mp4"]
            if args.video:
                with _progress_bar(res.n_frames, "frame", f"rendering {stem}") as bar:
                    save_result_video(
                        res,
                        targets[(stem, "mp4")],
                        overwrite=args.force,
                        progress=lambda done, total: _advance(bar, done),
                        look=args.video_style,
                        framing="full body" if args.video_full_body else "upper body",
                        character=character,  # their character, as in the glTF and BVH
                    )
                written.append(targets[(stem, "mp4")])
            relaxed = res.relaxed_steps
            note = (
                f"; control relaxed at {describe_steps(relaxed, segment=res.config.segment, fps=res.motion.fps)}"
                if relaxed
                else ""
            )
            _print(
                f"{f.name}: {res.n_frames} frames ({res.n_frames / res.motion.fps:.2f} s), "
                f"{res.search.n_steps} steps{note} -> {', '.join(str(w) for w in written)}"
            )
            for line in reports:
                _print(line)
    return _done(args)


@contextlib.contextmanager
def _taken_back_on_error(paths: Sequence[Path]) -> Iterator[None]:
    """Remove the files of ``paths`` written inside the block when it fails, so a run leaves all its outputs or
    none (each file is itself written to a temporary name and renamed)."""
    before = {p: _stamp(p) for p in paths}
    try:
        yield
    except BaseException:
        for p in paths:
            if _stamp(p) != before[p] and p.is_file() and not p.is_symlink():
                with contextlib.suppress(OSError):
                    p.unlink()
        raise


def _stamp(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns


def _cmd_train_refiner(args) -> int:
    from dataclasses import replace

    from .._optional import require

    require("torch", purpose="train-refiner")
    from ..refine.data import PairsConfig
    from ..refine.train import TrainConfig, preset, train_refiner
    from ..workspace import open_database

    if args.demo == bool(args.db):
        raise ConfigError("give the database to train on with --db, or --demo for the demo database")
    if args.resume and args.force:
        raise ConfigError("--resume goes on from the folder and --force replaces it; give one of them")
    exclude_ranges = tuple(_parse_range(x) for x in (args.exclude_range or ()))
    db = open_database(None if args.demo else args.db)
    if args.demo:
        from ..demo import DEMO_MINUTES, DEMO_SEED

        standard = f"demo (seed {DEMO_SEED}, {DEMO_MINUTES:g} min)"
        if db.meta["build"].get("source") != standard:
            warn(
                f"the default database at {db.path} is not the standard demo ({standard}); the shipped "
                "refiner was trained on the standard one (rebuild it with `gesturekit build-db --demo --force`)"
            )
    data = None
    if not args.resume or args.exclude_take or args.exclude_range:
        data = PairsConfig(seed=args.seed, exclude_takes=tuple(args.exclude_take or ()), exclude_ranges=exclude_ranges)
    train = replace(preset(args.preset).train, **options_given(args)[TrainConfig])
    with _stage_bars() as bar:

        def on_step(it, total, losses):
            note = (
                f"W {losses['wasserstein']:.2f} gp {losses['gradient_penalty']:.2f} L1 {losses['generator_l1']:.3f}"
                if "generator_l1" in losses
                else None
            )
            _advance(bar("training the refiner", total, "it"), it, note=note)

        out = train_refiner(
            db,
            args.out,
            preset_name=args.preset,
            iterations=args.iterations,
            train=train,
            data=data,
            resume=args.resume,
            overwrite=args.force,
            device=args.device,
            keep_train_state=not args.no_train_state,
            on_step=on_step,
            on_pairs=lambda done, total: _advance(bar("k-NN training pairs", total, "window"), done),
        )
    from ..refine.folder import read_refiner_config

    cfg = read_refiner_config(out)
    _print(f"refiner    {out}")
    _print(f"preset     {cfg['preset']}  ({cfg['iteration']} iterations on {cfg['device']})")
    _print(f"windows    {cfg['pairs']['windows']} training windows (k-NN search {cfg['time']['search_s']:.1f} s)")
    _print(f"training   {cfg['time']['train_s']:.1f} s; losses in {out / 'loss_log.csv'}")
    return _done(args)


def _control_from_arg(text: str | None) -> str | None:
    """A --control value (track text or a CSV/JSON file) as normalised track text; None if not given."""
    from ..control import load_control_file, parse_control

    if not text:
        return None
    if is_file(text):
        return load_control_file(text).to_text()
    if text.strip().lower().endswith((".csv", ".json")):
        from ..errors import InputFileError

        if os.path.exists(text):  # a FIFO or a device: refused by name, never read
            return load_control_file(text).to_text()
        raise InputFileError("control file not found", path=text)
    try:
        return parse_control(text).to_text()
    except ConfigError as exc:
        raise ConfigError(f"--control: {exc}") from None


def _cmd_evaluate(args) -> int:
    from ..evaluate.run import EvaluationConfig, run_evaluation
    from ..synthesis import SynthesisConfig
    from ..workspace import open_database

    out = Path(args.out)
    targets = [out / n for n in ("results.csv", "results.md", "controls.csv", "controls.md", "evaluation.json")]
    existing = [str(p) for p in targets if p.exists()]
    if existing and not args.force:
        raise GestureKitError(f"{existing[0]}: exists already; add --force to replace the evaluation in {out}")
    _parse_holdouts([args.holdout])
    given = options_given(args)[EvaluationConfig]  # --beat-sigma checked before the database is read
    control = _control_from_arg(args.control)
    db = open_database(args.db)
    from ..outputs import check_output

    check_output(out, "evaluation", overwrite=args.force, inputs=[db.path])  # before the long part
    config = EvaluationConfig(**{**given, "control": control, "synthesis": SynthesisConfig(**_search_options(args))})
    with _progress_bar(None, "step", "evaluating") as bar:
        ev = run_evaluation(db, config, progress=lambda done, total, what: _advance(bar, done, total, what[-30:]))
    _print(ev.to_markdown())
    written = ev.save(out, overwrite=args.force)
    _print(f"wrote {', '.join(str(p) for p in written)}")
    return _done(args)


def _cmd_train_fgd(args) -> int:
    from ..evaluate.fgd import FGDConfig, train_fgd_model
    from ..evaluate.run import held_out
    from ..workspace import open_database

    out = Path(args.out)
    if (out / "fgd.json").exists() and not args.force:
        raise GestureKitError(f"{out}: an FGD model exists here already; add --force to replace it")
    _parse_holdouts(args.holdout)
    db = open_database(args.db)
    from ..outputs import check_output

    check_output(out, "fgd", overwrite=args.force, inputs=[db.path])  # before training
    takes, ranges = [], []
    for h in args.holdout or ():
        ref = held_out(db, h)
        takes += list(ref.exclude_takes)
        ranges += list(ref.exclude_ranges)
    exclude = db.exclusion_mask(takes=takes, ranges=ranges) if (takes or ranges) else None
    config = FGDConfig(**options_given(args)[FGDConfig])
    with _progress_bar(config.steps, "step", "training the FGD autoencoder") as bar:
        model = train_fgd_model(
            db,
            config=config,
            exclude=exclude,
            progress=lambda step, steps, loss: _advance(bar, step, note=f"loss {loss:.4f}"),
        )
    model.info["held_out"] = list(args.holdout or ())
    model.save(out, overwrite=args.force)
    _print(
        f"FGD autoencoder: {model.info['clips_used']} clips used, {model.info['clips_held_out']} held out, "
        f"final reconstruction loss {model.info['final_loss']:.4f}"
    )
    return _done(args, f"saved to {out}")


def _cmd_stimuli(args) -> int:
    import re

    from ..study.stimuli import StudyConfig, make_stimuli
    from ..workspace import open_database

    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", args.resolution)
    if not m:
        raise ConfigError(f"--resolution must look like 640x480, got {args.resolution!r}")
    if not args.audio and not args.holdouts:
        raise ConfigError("give speech with --audio (files or folders) and/or --holdout TAKE:START-END")
    _parse_holdouts(args.holdouts)
    if not math.isfinite(args.loudness_lufs):
        raise ConfigError(f"--loudness must be a finite number of LUFS (e.g. -23), got {args.loudness_lufs:g}")
    given = options_given(args)[StudyConfig]
    given.update(audio=tuple(args.audio or ()), holdouts=tuple(args.holdouts or ()))
    control = _control_from_arg(args.control) or ""
    db = open_database(args.db)
    with _stage_bars() as bar:
        res = make_stimuli(
            db,
            StudyConfig(**{**given, "control": control, "resolution": (int(m.group(1)), int(m.group(2)))}),
            out=args.out,
            overwrite=args.force,
            progress=lambda stage, done, total: _advance(bar(stage, total, "stimulus"), done),
        )
    _print(
        f"{len(res.videos)} stimuli ({len(res.settings['speeches'])} speeches x {len(res.settings['systems'])} "
        f"systems) in {res.folder / 'videos'}"
    )
    _print(f"manifest (the key; keep it from raters): {res.folder / 'manifest.csv'}")
    _print(f"presentation order for {res.settings['participants']} participants: {res.folder / 'order.csv'}")
    return _done(args)


def _cmd_study(args) -> int:
    from ._study import run

    return run(args)


def _done(args, what: str = "done") -> int:
    """Say that the command is done and how long it took (since :func:`main` began it); exit status 0."""
    _print(f"{what} in {time.perf_counter() - args.started:.1f} s")
    return 0


def _format_warning(message, category, filename, lineno, line=None):
    return f"warning: {shown(message)}\n"


def _limits_of(args):
    """The input limits the command's options set (``--max-speech-minutes``), for the command's run."""
    from ..limits import SPEECH_MINUTES, override

    return override(SPEECH_MINUTES, getattr(args, "max_speech_minutes", None), option="--max-speech-minutes")


def _os_error_text(exc: OSError) -> str:
    """``PATH: strerror`` (both paths for a rename or copy), or the error's own text when it names no file."""
    problem = exc.strerror or str(exc)
    if exc.filename is None:
        return problem
    names = str(exc.filename) if exc.filename2 is None else f"{exc.filename} -> {exc.filename2}"
    return f"{names}: {problem}"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(join_axis_values(sys.argv[1:] if argv is None else argv))
    # the command's function, named after it (build-db -> _cmd_build_db; options: _cli_parser.py)
    command = globals()["_cmd_" + args.command.replace("-", "_")]
    args.started = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("always", GestureKitWarning)
        old = warnings.formatwarning
        warnings.formatwarning = _format_warning
        try:
            with _limits_of(args):
                return command(args)
        except GestureKitError as exc:
            _print(f"gesturekit: error: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:
            # the last net for a user's file that could not be read (a folder where a file was
            # expected, a name too long, an I/O error): one line naming it; other exceptions are
            # bugs and keep their traceback
            _print(f"gesturekit: error: {_os_error_text(exc)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            _print("gesturekit: interrupted", file=sys.stderr)
            return 130
        finally:
            warnings.formatwarning = old


if __name__ == "__main__":
    sys.exit(main())
