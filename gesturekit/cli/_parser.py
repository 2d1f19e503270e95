"""The command line's options: one subparser per command, its help and its arguments.

:func:`build_parser` is used by :func:`gesturekit.cli.main`, which runs the command
named by ``args.command``; ``gesturekit COMMAND --help`` prints what is declared here.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from .._config import option_of
from .._version import __version__
from ..export.character import THEIR_CLIPS
from ._app import ABOUT as _APP_ABOUT
from ._app import add_app_parser
from ._options import add_options

__all__ = ["build_parser", "join_axis_values"]


def _add_max_speech(parser) -> None:
    parser.add_argument(
        "--max-speech-minutes",
        type=float,
        metavar="MIN",
        help="refuse speech files longer than this (default 60, or the environment "
        "variable GESTUREKIT_MAX_SPEECH_MINUTES)",
    )


#: Each command's line in ``gesturekit --help`` and the paragraph of its own ``--help``.
_ABOUT = {
    "build-db": (
        "build a matching database from a folder of takes (or the generated demo speaker)",
        "Build a matching database from a folder of takes: BVH + speech (ZEGGS, BEAT, any BVH with a joint "
        "map), joint-position files + speech, or npz files of the Habibie et al. 2021 layout.",
    ),
    "info": ("describe a matching database", None),
    "synthesize": (
        "gesture motion for speech: npz + BVH (--format: also or instead glTF; + MP4 with --video)",
        "Synthesise gesture motion for one or more speech files (or folders of them) by motion matching. "
        "Several files are searched together, scanning the database once per step.",
    ),
    "train-refiner": (
        "train the resynchronisation cGAN (refiner) on a database",
        "Train the paper's resynchronisation cGAN on a matching database built with --overlap-stride: k-NN "
        "motion for every window of the overlapping cut, then WGAN-GP training with a progress bar, "
        "checkpoints in the output folder (--resume goes on from the last one) and a loss log "
        "(loss_log.csv). Uses the GPU when torch sees one.",
    ),
    "evaluate": (
        "objective measures of every system on a held-out part of a database",
        "Keep a take or a time range of one out of the database, synthesise its speech with each system, and "
        "print and save (CSV + markdown) beat consistency, diversity, FGD, Hellinger distances of velocity "
        "and acceleration histograms, jerk, acceleration, boundary jumps and control adherence.",
    ),
    "train-fgd": (
        "train the motion autoencoder of the FGD measure on a database",
        "Train the small convolutional autoencoder whose latent space the Frechet Gesture Distance is "
        "measured in, on the poses of a matching database, leaving held-out parts out.",
    ),
    "stimuli": (
        "user-study videos: every speech x system, opaque ids, manifest and presentation order",
        "Render every speech with every system as an MP4 in one identical style (fixed camera, resolution, "
        "frame rate, loudness-normalised speech), named by opaque ids, with a manifest CSV kept apart from "
        "the videos and a balanced presentation order per participant (Latin squares).",
    ),
    "study": (
        "run a user study on a stimuli folder: design, hosting, analysis, HEMVIP interop",
        "Subcommands that turn a stimuli folder into a running study (see `gesturekit study SUBCOMMAND -h`).",
    ),
    "app": _APP_ABOUT,
}


def _command(sub, name: str) -> argparse.ArgumentParser:
    """Add the subcommand ``name`` (``args.command``), described by :data:`_ABOUT`."""
    summary, description = _ABOUT[name]
    return sub.add_parser(name, help=summary, description=description)


def _add_choice(parser, flag: str, choices: list[str], help: str) -> None:
    """An option that takes one of ``choices``, the first of them by default."""
    parser.add_argument(flag, choices=choices, default=choices[0], help=help)


def search_options() -> list[tuple[type, tuple[str, ...]]]:
    """(configuration class, its fields) of the search options ``synthesize`` and ``evaluate`` share, in
    the order ``--help`` lists them (``mask_rule`` is SearchConfig's; SynthesisConfig passes it on)."""
    from ..search import SearchConfig
    from ..synthesis import SynthesisConfig

    return [
        (SearchConfig, ("k", "segment", "seed")),
        (SynthesisConfig, ("init",)),
        (SearchConfig, ("mask_rule",)),
        (SynthesisConfig, ("blend", "blend_halflife", "blend_frames")),
    ]


def _add_search(parser, *, seed: str) -> None:
    """The options of the search that ``synthesize`` and ``evaluate`` share; ``seed``: what the seed seeds."""
    for cls, names in search_options():
        add_options(parser, cls, names, helps={"seed": f"seed of {seed}"})


def _add_search_device(parser) -> None:
    """``--search-device``: the torch device of the search's scan."""
    parser.add_argument(
        "--search-device",
        metavar="DEVICE",
        help="scan the database on this torch device (cuda, cuda:1): the same motion, for large databases "
        "(default: $GESTUREKIT_SEARCH_DEVICE if set, else the CPU)",
    )


def _add_exclusions(parser, *, out_of: str) -> None:
    """``--exclude-take`` and ``--exclude-range``, keeping parts of the database out of ``out_of``."""
    parser.add_argument("--exclude-take", action="append", metavar="TAKE", help=f"keep a database take out of {out_of}")
    parser.add_argument(
        "--exclude-range",
        action="append",
        metavar="TAKE:START-END",
        help=f"keep a stretch of a take (seconds) out of {out_of}",
    )


_AXIS_OPTIONS = ("--up", "--forward")


def join_axis_values(argv: Sequence[str]) -> list[str]:
    """``argv`` with ``--up -y`` written as ``--up=-y`` (also ``--forward``).

    argparse takes a value that starts with ``-`` for an option; a negative axis
    is the natural way to write these two.
    """
    out: list[str] = []
    args = list(argv)
    i = 0
    while i < len(args):
        if args[i] in _AXIS_OPTIONS and i + 1 < len(args) and args[i + 1] in ("-x", "-y", "-z"):
            out.append(f"{args[i]}={args[i + 1]}")
            i += 2
            continue
        out.append(args[i])
        i += 1
    return out


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``gesturekit``'s command line; ``args.command`` names the command given."""
    p = argparse.ArgumentParser(
        prog="gesturekit", description="Controllable speech-driven gesture synthesis by motion matching."
    )
    p.add_argument("--version", action="version", version=f"gesturekit {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    b = _command(sub, "build-db")
    b.add_argument("folder", nargs="?", help="folder of takes")
    b.add_argument("--out", help="database folder to write (default for --demo: the app's default path)")
    b.add_argument("--preset", choices=["zeggs", "beat"], help="joint naming preset of the BVH files")
    b.add_argument("--joint-map", help="JSON joint map for other skeletons or joint-position files")
    b.add_argument(
        "--kind",
        choices=["auto", "bvh", "positions", "habibie2021"],
        help="kind of takes (default auto: from the files; with --append: the database's)",
    )
    b.add_argument("--fps", type=float, help="frame rate of joint-position files")
    b.add_argument(
        "--units",
        choices=["auto", "m", "cm", "mm"],
        help="units of the motion files (default auto: detected from the body's size; with --append: the "
        "database's); a unit given must give the body a human size",
    )
    b.add_argument(
        "--up",
        choices=["y", "-y", "z", "-z"],
        help="up axis of the motion files (default: y, and each take must look upright; with --append: the "
        "database's); an axis given must stand the body upright",
    )
    b.add_argument(
        "--forward",
        choices=["auto", "x", "-x", "y", "-y", "z", "-z"],
        help="axis the body faces in the motion files (default auto: from the shoulders; with --append: the "
        "database's)",
    )
    b.add_argument(
        "--no-plausibility-check",
        action="store_true",
        help="accept data that fails the checks of what was given (a body of no human size in the given "
        "--units, not upright with the given --up, a joint map whose skeleton is no human's, frames far from "
        "the body): for the rare data that is right and fails them",
    )
    b.add_argument(
        "--allow-duration-mismatch",
        action="store_true",
        help="accept takes whose motion and speech durations differ by more than 5%% (the longer is trimmed)",
    )
    b.add_argument(
        "--normalize-bones",
        action="store_true",
        help="give every bone one length per take (for keypoints whose bone lengths vary)",
    )
    from ..database import BuildConfig

    add_options(
        b,
        BuildConfig,
        ["overlap_stride", "percentiles", "store_audio", "audio_format", "audio_rate", "label"],
        helps={"label": f"{option_of(BuildConfig, 'label').help} (with --append: replaces its label)"},
    )
    b.add_argument("--force", action="store_true", help="replace an existing database")
    b.add_argument(
        "--workers",
        type=int,
        help="processes that read takes at once (default: all cores); the database is the same for any number",
    )
    b.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="read the takes on a Dask cluster (tcp://host:8786); the output must be on a file system its "
        "workers share",
    )
    b.add_argument(
        "--append",
        action="store_true",
        help="add the folder's takes that the database at --out lacks (statistics and thresholds recomputed over "
        "all takes, the old ones read again from their files)",
    )
    b.add_argument(
        "--keep-stats",
        action="store_true",
        help="with --append: keep the database's statistics, thresholds and arrays (fast; the new takes are "
        "z-scored with them)",
    )
    b.add_argument("--demo", action="store_true", help="build the generated demo speaker's database")
    b.add_argument("--minutes", type=float, default=20.0, help="minutes of demo speaker (with --demo)")
    b.add_argument("--seed", type=int, default=0, help="seed of the demo speaker (with --demo)")

    i = _command(sub, "info")
    i.add_argument("database", nargs="?", help="database folder (default: the demo database)")
    i.add_argument("--takes", action="store_true", help="also list the takes")

    y = _command(sub, "synthesize")
    y.add_argument("speech", nargs="+", help="speech files (wav, flac, ogg, mp3; any rate) or folders of them")
    y.add_argument("--db", help="matching database folder (default: the demo database)")
    y.add_argument("--out", default="out", help="output folder (default: out)")
    _add_search(y, seed="the random initial pose")
    from ..search import SearchConfig
    from ..synthesis import SynthesisConfig

    add_options(y, SearchConfig, ["record"])
    y.add_argument(
        "--control",
        help='control track: "0-3:left_hand=low,3-6:speed=slow+symmetry=symmetric" '
        "(seconds) or a CSV/JSON file with start_s, end_s, constraint",
    )
    _add_exclusions(y, out_of="the search")
    y.add_argument(
        "--refiner",
        metavar="PATH",
        help="refine the k-NN motion with a trained refiner folder "
        "(from train-refiner), 'demo' for the one shipped with the demo database, or 'none'; "
        "default: a refiner trained on the database if there is one (DB/refiner, or the shipped "
        "one for the demo database), else none. The npz keeps both motions",
    )
    add_options(y, SynthesisConfig, ["refiner_keep_hz"])
    _add_search_device(y)
    y.add_argument(
        "--format",
        default="npz,bvh",
        metavar="LIST",
        help="the files to write per speech, a comma list of npz (motion + search), bvh (the motion), glb "
        "(glTF: the character, skinned and animated, with the speech as a WAV beside it) (default npz,bvh)",
    )
    y.add_argument(
        "--character",
        metavar="FILE",
        help="your own humanoid (.glb, .gltf, .vrm or .fbx with a skinned body, or a .bvh skeleton): glb then writes "
        "it animated by the motion (its meshes, materials and extensions kept, one animation 'gesturekit' "
        "added) and bvh its skeleton moved by the motion, in the file's own frame and units; the npz keeps "
        "our joints. Bones are matched by the VRM humanoid, Mixamo or ZEGGS names, or --character-map",
    )
    y.add_argument(
        "--character-map",
        metavar="JSON",
        help='bone map of --character: {"pelvis": "Hips", "joints": {"spine_mid": "Spine", ...}}',
    )
    y.add_argument(
        "--wrist-slack",
        type=float,
        metavar="FRACTION",
        help="how far --character's wrists may stay from our reach, a fraction of its arm's length from 0 to 0.2 "
        "(default 0.05: where its upper-arm-to-forearm ratio differs from ours, the arm keeps closer to our "
        "directions; 0: the hands exactly where ours reach)",
    )
    y.add_argument(
        "--character-clips",
        choices=THEIR_CLIPS,
        default=THEIR_CLIPS[0],
        help="the animations --character's file has of its own, in the glb: keep them after ours (default: "
        "viewers that play one play the first, ours) or drop them (ours is the only one)",
    )
    y.add_argument("--video", action="store_true", help="also render an MP4 of the character with the speech")
    y.add_argument(
        "--video-style",
        choices=("character", "capsules"),
        default="character",
        help="the MP4's look: the page's character (default) or the earlier capsule figure",
    )
    y.add_argument(
        "--video-full-body",
        action="store_true",
        help="frame the MP4 on the whole body down to the floor (default: the upper body and every hand)",
    )
    y.add_argument("--force", action="store_true", help="replace existing output files")
    _add_max_speech(y)

    r = _command(sub, "train-refiner")
    r.add_argument("--db", help="matching database folder (built with --overlap-stride)")
    r.add_argument("--demo", action="store_true", help="train on the default demo database (built if missing)")
    r.add_argument("--out", required=True, help="refiner folder to write")
    _add_choice(
        r,
        "--preset",
        ["quick", "paper"],
        "quick: small networks, ~10 min on a 2-core CPU; paper: the paper's sizes (GPU)",
    )
    r.add_argument(
        "--iterations",
        type=int,
        help="critic iterations (default: the preset's; with --resume: train on up to this many)",
    )
    r.add_argument("--resume", action="store_true", help="go on from the checkpoint in --out")
    r.add_argument("--device", default="auto", help="auto (GPU when present), cpu or cuda (default auto)")
    from ..refine.config import TrainConfig

    add_options(r, TrainConfig, ["seed"])
    _add_exclusions(r, out_of="training")
    r.add_argument(
        "--no-train-state",
        action="store_true",
        help="leave out the optimiser state at the end (a smaller folder that cannot be resumed)",
    )
    r.add_argument("--force", action="store_true", help="replace an existing refiner folder")
    e = _command(sub, "evaluate")
    e.add_argument("--db", help="matching database folder (default: the demo database)")
    from ..evaluate.run import EvaluationConfig

    add_options(e, EvaluationConfig, ["holdout", "systems", "refiner", "fgd_model", "control", "sigma"])
    _add_search(e, seed="the initial pose and the random baseline")
    e.add_argument("--out", default="evaluation", help="folder for the tables (default: evaluation)")
    e.add_argument("--force", action="store_true", help="replace existing tables")

    f = _command(sub, "train-fgd")
    f.add_argument("--db", help="matching database folder (default: the demo database)")
    f.add_argument("--out", required=True, help="model folder to write")
    f.add_argument(
        "--holdout",
        action="append",
        metavar="TAKE[:START-END]",
        help="leave a take or a time range out of training (repeatable)",
    )
    from ..evaluate.fgd import FGDConfig

    add_options(f, FGDConfig, ["steps", "window", "latent", "seed"])
    f.add_argument("--force", action="store_true", help="replace an existing model")

    s = _command(sub, "stimuli")
    s.add_argument("--db", help="matching database folder (default: the demo database)")
    from ..study.config import StudyConfig

    add_options(
        s,
        StudyConfig,
        ["audio", "holdouts", "systems"],
        helps={
            "holdouts": f"{option_of(StudyConfig, 'holdouts').help}; one part per --holdout (repeatable)",
            "systems": f"{option_of(StudyConfig, 'systems').help}, comma-separated",
        },
    )
    s.add_argument("--out", required=True, help="study folder to write")
    add_options(
        s,
        StudyConfig,
        ["seed", "participants", "control", "refiner", "resolution", "loudness_lufs", "workers", "scheduler"],
    )
    add_options(s, StudyConfig, ["character", "character_map", "wrist_slack"])
    s.add_argument("--force", action="store_true", help="replace an existing study")
    _add_max_speech(s)

    from ._study import add_study_parser

    add_study_parser(_command(sub, "study"))
    add_app_parser(_command(sub, "app"))
    return p
