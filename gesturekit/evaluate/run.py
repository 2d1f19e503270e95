"""Evaluate systems on a held-out part of a database: one table of every measure for every system.

:func:`run_evaluation` (and its short form :func:`evaluate`, which returns only
the table) takes a database and a held-out part of it (a whole take, or a time
range of one), keeps that part out of the database (with a margin before it,
so that no window's one-second audio look-ahead reads held-out speech),
synthesises the held-out speech with each system, and measures every output
(:mod:`gesturekit.evaluate.metrics`) against the recorded motion:

=========================  =====================================================================
``beat_consistency``       Gaussian beat alignment with the speech's onsets (higher: better)
``motion_beats_per_s``     motion beats (velocity minima) per second, to read the line above by
``diversity_l1``           L1 diversity over 1-s windows, metres (the recording's value is the aim)
``fgd``                    Fréchet Gesture Distance to the recording (lower: better)
``hellinger_velocity``     Hellinger distance of speed histograms to the recording (lower: better)
``hellinger_acceleration`` same for acceleration magnitudes
``mean_acceleration``      m/s^2 over the upper body and wrists
``mean_jerk``              m/s^3
``boundary_jump``          mean joint displacement across segment joins, metres per frame
``boundary_jump_ratio``    that over the displacement between any other two frames (1: seamless)
``adherence_controlled``   fraction of frames meeting the control track, synthesised with it
``adherence_uncontrolled`` the same measure for the output made without the control
=========================  =====================================================================

The control track is the user's, or by default six equal stretches of the
held-out speech asking in turn for the left hand low and high, slow and fast
hands, symmetric and asymmetric hands. :attr:`Evaluation.controls` holds the
per-segment statistics (left-wrist height, speed, asymmetry) like the paper's
control table.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arguments import checks_arguments
from .._config import check_option, option, options_config
from ..control import ControlTrack, Segment, parse_control, parse_time_range
from ..errors import ConfigError, warn
from ..features import LAYOUT
from ..motion import AUDIO_SR, HoldsMotion, Motion
from ..refine import open_refiner
from . import metrics
from .baselines import SYSTEMS, SystemOutput, SystemUnavailable, parse_systems, refiner_unavailable_reason, run_system

if TYPE_CHECKING:
    import pandas as pd

    from ..database import MatchingDatabase
    from ..synthesis import MotionRefiner, SynthesisConfig
    from .fgd import FGDModel

__all__ = [
    "DEFAULT_SYSTEMS",
    "METRIC_COLUMNS",
    "Holdout",
    "HeldOut",
    "parse_holdout",
    "held_out",
    "default_control_track",
    "Evaluation",
    "EvaluationConfig",
    "run_evaluation",
    "evaluate",
    "markdown_table",
    "write_csv",
    "write_text",
]

DEFAULT_SYSTEMS: tuple[str, ...] = SYSTEMS

#: Columns of the evaluation table after ``system`` and ``frames``.
METRIC_COLUMNS: tuple[str, ...] = (
    "beat_consistency",
    "motion_beats_per_s",
    "diversity_l1",
    "fgd",
    "hellinger_velocity",
    "hellinger_acceleration",
    "mean_acceleration",
    "mean_jerk",
    "boundary_jump",
    "boundary_jump_ratio",
    "adherence_controlled",
    "adherence_uncontrolled",
)

#: The default control track's constraints, one per equal stretch of the speech.
DEFAULT_CONTROLS: tuple[tuple[str, str], ...] = (
    ("left_hand", "low"),
    ("left_hand", "high"),
    ("speed", "slow"),
    ("speed", "fast"),
    ("symmetry", "symmetric"),
    ("symmetry", "asymmetric"),
)


# ---- held-out data ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Holdout:
    """A held-out part of a database: a whole take, or ``start_s``-``end_s`` seconds of it.

    Parse the command-line forms ``TAKE`` and ``TAKE:START-END`` with :func:`parse_holdout`.
    """

    take: str
    start_s: float | None = None
    end_s: float | None = None

    def __post_init__(self):
        if not self.take:
            raise ConfigError("a held-out part needs a take name")
        if (self.start_s is None) != (self.end_s is None):
            raise ConfigError("give both the start and the end of a held-out range, or neither")
        if self.start_s is not None and self.end_s is not None and not (0 <= self.start_s < self.end_s):
            raise ConfigError(f"held-out range {self.start_s}-{self.end_s} s: need 0 <= start < end")

    def to_text(self) -> str:
        if self.start_s is None:
            return self.take
        return f"{self.take}:{self.start_s:g}-{self.end_s:g}"


@checks_arguments
def parse_holdout(text: str | Holdout) -> Holdout:
    """``"TAKE"`` or ``"TAKE:START-END"`` (seconds) -> :class:`Holdout`.

    Text after the last ``:`` is the time range (see
    :func:`gesturekit.control.parse_time_range`), so a take name holding ``:``
    cannot be held out whole.

    Raises
    ------
    ConfigError
        No take name, or a range that is not ``START-END`` with ``0 <= START < END``.
    """
    if isinstance(text, Holdout):
        return text
    text = str(text).strip()
    if not text:
        raise ConfigError("a held-out part must be TAKE or TAKE:START-END (seconds)")
    take, colon, times = text.rpartition(":")
    if not colon:
        return Holdout(text)
    what = f"held-out part {text!r}"
    if not take.strip():
        raise ConfigError(f"{what} must look like TAKE or TAKE:START-END in seconds")
    start, end = parse_time_range(times, what=what, form="TAKE or TAKE:START-END")
    return Holdout(take.strip(), start, end)


@dataclass
class HeldOut(HoldsMotion):
    """A held-out part resolved against a database.

    Attributes
    ----------
    holdout : Holdout
    first_frame : int
        First held-out frame of the take (at the database's fps).
    motion : Motion
        The recorded motion of the held-out frames that lie in the database's clips.
    audio : np.ndarray, shape (samples,), float32
        The speech of exactly those frames (16 kHz): the query.
    exclude_takes, exclude_ranges : tuple
        What the search must not use (the held-out part and the margin before it).
    """

    holdout: Holdout
    first_frame: int
    motion: Motion
    audio: np.ndarray
    exclude_takes: tuple
    exclude_ranges: tuple

    def describe(self) -> dict:
        fps = self.motion.fps
        return {
            "holdout": self.holdout.to_text(),
            "take": self.holdout.take,
            "first_frame": self.first_frame,
            "frames": self.n_frames,
            "start_s": self.first_frame / fps,
            "end_s": (self.first_frame + self.n_frames) / fps,
            "exclude_takes": list(self.exclude_takes),
            "exclude_ranges": [list(r) for r in self.exclude_ranges],
        }


@checks_arguments
def held_out(db: MatchingDatabase, holdout: Holdout | str, *, margin_s: float | None = None) -> HeldOut:
    """Resolve a held-out part: its recorded motion, its speech, and what to exclude.

    Parameters
    ----------
    db : MatchingDatabase
        Must store its takes' audio.
    holdout : Holdout or str
    margin_s : float, optional
        Seconds before a held-out range also kept out of the search; default the feature
        look-ahead plus one step (22 frames), so no admissible window's features read held-out
        frames.

    Raises
    ------
    ConfigError
        Unknown take, or a range holding no frame of the database's clips.
    DatabaseError
        The database was built without audio.
    """
    h = parse_holdout(holdout)
    names = db.take_names
    if h.take not in names:
        raise ConfigError(
            f"no take named {h.take!r} in the database; takes: {', '.join(names[:10])}"
            + (" ..." if len(names) > 10 else "")
        )
    ti = names.index(h.take)
    fps = db.fps
    L = db.clip_frames
    clip_take = np.asarray(db.clip_take)
    clips = np.flatnonzero(clip_take == ti)
    starts = np.asarray(db.clip_start)[clips]
    order = np.argsort(starts)
    clips, starts = clips[order], starts[order]
    # frames of the take covered by its clips (non-overlapping, from frame 0)
    covered = int(starts[-1] + L) if clips.size else 0
    if clips.size and not np.array_equal(starts, np.arange(clips.size) * L):
        raise ConfigError(f"take {h.take!r}: its clips are not a contiguous cut from frame 0")
    ex_takes: tuple[str, ...]
    ex_ranges: tuple[tuple[str, float, float], ...]
    if h.start_s is None or h.end_s is None:  # a whole take (a Holdout has both ends or neither)
        f0, f1 = 0, covered
        ex_takes, ex_ranges = (h.take,), ()
    else:
        f0 = int(math.ceil(h.start_s * fps - 1e-9))
        f1 = min(int(math.ceil(h.end_s * fps - 1e-9)), covered)
        margin = (LAYOUT.audio_lookahead + 8) / fps if margin_s is None else float(margin_s)
        if margin < 0:
            raise ConfigError(f"margin_s must be >= 0, got {margin}")
        ex_takes, ex_ranges = (), ((h.take, max(0.0, h.start_s - margin), float(h.end_s)),)
    if f1 - f0 < 2:
        raise ConfigError(
            f"held-out part {h.to_text()} holds no frames of the database's clips "
            f"(its clips cover 0-{covered / fps:.2f} s)"
        )
    G = np.asarray(db.G[clips]).reshape(-1, np.asarray(db.G).shape[-1])
    motion = Motion.from_flat(G[f0:f1], fps, db.joint_presence)
    take_audio = db.take_audio(ti)
    s0 = int(round(f0 * AUDIO_SR / fps))
    s1 = int(math.ceil(f1 * AUDIO_SR / fps))
    audio = np.zeros(s1 - s0, np.float32)
    part = take_audio[s0:s1]
    audio[: part.size] = part  # a take's audio may end a fraction of a frame early
    return HeldOut(h, f0, motion, audio, ex_takes, ex_ranges)


@checks_arguments
def default_control_track(duration_s: float, *, controls: Sequence[tuple[str, str]] = DEFAULT_CONTROLS) -> ControlTrack:
    """Equal stretches of ``duration_s`` seconds, each asking for one constraint in turn."""
    if not duration_s > 0:
        raise ConfigError(f"duration must be positive, got {duration_s}")
    n = len(controls)
    edges = [round(duration_s * i / n, 6) for i in range(n + 1)]
    segs = [Segment(edges[i], edges[i + 1], (controls[i],)) for i in range(n) if edges[i + 1] > edges[i]]
    return ControlTrack(tuple(segs))


# ---- evaluation ---------------------------------------------------------------------------------


@dataclass
class Evaluation:
    """What :func:`run_evaluation` measured.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per system: ``system``, ``frames``, then :data:`METRIC_COLUMNS` and
        ``relaxed_steps`` (steps of the controlled run whose control was dropped).
    controls : pandas.DataFrame
        One row per system, run (``controlled`` / ``uncontrolled``) and control segment:
        adherence and the mean and standard deviation of left-wrist height and speed, hand
        speed and asymmetry (see :func:`gesturekit.evaluate.metrics.control_adherence`).
    held_out : HeldOut
    outputs : dict of str -> SystemOutput
        Each system's uncontrolled output.
    notes : list of str
        Systems that could not run, and why; how the FGD model was obtained.
    settings : dict
        Everything that made the numbers (JSON-able).
    """

    table: pd.DataFrame
    controls: pd.DataFrame
    held_out: HeldOut
    outputs: dict
    notes: list = field(default_factory=list)
    settings: dict = field(default_factory=dict)

    def to_markdown(self) -> str:
        """The report: the measures table, then the per-control statistics."""
        h = self.held_out.describe()
        lines = [
            f"Held out: {h['holdout']} (frames {h['first_frame']}-{h['first_frame'] + h['frames']}, "
            f"{h['frames'] / self.held_out.motion.fps:.2f} s)",
            "",
            markdown_table(self.table),
            "",
            "Control track: " + self.settings.get("control", ""),
            "",
            markdown_table(self.controls[[c for c in self.controls.columns if not c.endswith("_std")]]),
        ]
        if self.notes:
            lines += [""] + [f"Note: {n}" for n in self.notes]
        return "\n".join(lines) + "\n"

    def save(self, folder: str | os.PathLike, *, overwrite: bool = False) -> list[Path]:
        """Write ``results.csv``, ``results.md``, ``controls.csv``, ``controls.md`` and ``evaluation.json``.

        The folder is written whole (see :mod:`gesturekit.outputs`): an empty or new folder, or,
        with ``overwrite``, an earlier evaluation folder; any other folder is refused.
        """
        from ..outputs import write_folder

        folder = Path(folder)
        meta = {
            "format": "gesturekit-evaluation",
            "held_out": self.held_out.describe(),
            "settings": self.settings,
            "notes": self.notes,
        }

        def fill(tmp: Path) -> None:
            write_csv(self.table, tmp / "results.csv")
            write_text(markdown_table(self.table) + "\n", tmp / "results.md")
            write_csv(self.controls, tmp / "controls.csv")
            write_text(markdown_table(self.controls) + "\n", tmp / "controls.md")
            write_text(json.dumps(meta, indent=1) + "\n", tmp / "evaluation.json")

        # the folder is written whole and swapped in; overwrite replaces only an evaluation folder
        write_folder(folder, "evaluation", fill, overwrite=overwrite)
        return [folder / n for n in ("results.csv", "results.md", "controls.csv", "controls.md", "evaluation.json")]


#: Training steps of the FGD autoencoder an evaluation trains for itself when given none.
RUN_FGD_STEPS = 600


def _fgd_model(
    db: MatchingDatabase,
    fgd_model: FGDModel | str | os.PathLike[str] | None,
    exclude: np.ndarray | None,
    notes: list[str],
) -> FGDModel:
    from .fgd import FGDConfig, FGDModel, load_fgd_model, train_fgd_model

    if isinstance(fgd_model, FGDModel):
        return fgd_model
    if fgd_model is not None:
        return load_fgd_model(fgd_model)
    notes.append(
        "FGD autoencoder trained for this run on the database without the held-out part "
        "(save one with `gesturekit train-fgd` and pass it with --fgd-model to reuse it)"
    )
    # a model for this run only: fewer steps than a saved one's (FGDConfig.steps), so an evaluation stays quick
    return train_fgd_model(db, config=FGDConfig(steps=RUN_FGD_STEPS), exclude=exclude)


def _measure(out: SystemOutput, ref: HeldOut, onsets: np.ndarray, fgd_model: FGDModel | None, sigma: float) -> dict:
    x = out.motion.positions[: ref.n_frames]
    gt = ref.motion.positions[: x.shape[0]]
    fps = ref.motion.fps
    jumps = metrics.boundary_jumps(x, out.boundaries)
    row = {
        "beat_consistency": metrics.beat_consistency_score(x, ref.audio, fps=fps, sigma=sigma, onsets=onsets),
        "motion_beats_per_s": metrics.motion_beats(x, fps=fps).size / (x.shape[0] / fps),
        "diversity_l1": metrics.diversity_l1(x, window=int(fps)),
        "fgd": float("nan"),
        "hellinger_velocity": metrics.kinematic_hellinger(x, gt, fps=fps, order=1),
        "hellinger_acceleration": metrics.kinematic_hellinger(x, gt, fps=fps, order=2),
        "mean_acceleration": metrics.mean_acceleration(x, fps=fps),
        "mean_jerk": metrics.mean_jerk(x, fps=fps),
        "boundary_jump": jumps["jump"],
        "boundary_jump_ratio": jumps["ratio"],
    }
    if fgd_model is not None:
        from .fgd import fgd

        row["fgd"] = fgd(fgd_model, x, gt)
    return row


@dataclass(frozen=True)
class EvaluationConfig:
    """Every option of an evaluation (:func:`run_evaluation`); ``evaluation.json`` records them.

    Parameters
    ----------
    holdout : Holdout or str
        ``"TAKE"`` or ``"TAKE:START-END"`` (seconds).
    systems : str or sequence of str
        Of :data:`gesturekit.evaluate.baselines.SYSTEMS`. A system that cannot run (``knn+cgan``
        without a refiner) is left out of the table with a :class:`GestureKitWarning` and a note.
    synthesis : SynthesisConfig, optional
        k, N, seed, initial pose, mask rule, blending; its control and exclusions are replaced
        by the evaluation's.
    control : ControlTrack or str, optional
        Control track of the controlled runs (seconds of the held-out speech); default
        :func:`default_control_track`.
    fgd_model : FGDModel or path, optional
        The FGD autoencoder; default: one trained here on the database without the held-out part.
    refiner : optional
        For ``knn+cgan``.
    sigma : float
        Beat-consistency tolerance, seconds (> 0).
    margin_s : float, optional
        See :func:`held_out`.
    """

    holdout: Holdout | str = option(
        help="held-out take, or time range of one in seconds (e.g. 067_Speech_2_x_1_0:50-68.8)",
        kind=str,
        metavar="TAKE[:START-END]",
    )
    systems: str | Sequence[str] = option(DEFAULT_SYSTEMS, help="comma-separated systems", kind=str)
    synthesis: SynthesisConfig | None = None
    control: ControlTrack | str | None = option(
        None,
        help="control track of the controlled runs (seconds of the held-out speech)",
        kind=str,
        default_help="six equal stretches asking for left hand low/high, slow/fast, symmetric/asymmetric",
    )
    fgd_model: FGDModel | str | os.PathLike[str] | None = option(
        None, help="FGD autoencoder from `gesturekit train-fgd`", kind=str, default_help="train one now"
    )
    refiner: MotionRefiner | str | os.PathLike[str] | None = option(
        None, help="trained refiner folder, for knn+cgan", kind=str, default_help="none"
    )
    sigma: float = option(
        0.1, help="beat-consistency tolerance, seconds", low=0.0, low_open=True, unit="s", flag="--beat-sigma"
    )
    margin_s: float | None = None

    def __post_init__(self) -> None:
        check_option(EvaluationConfig, "sigma", self.sigma)


@checks_arguments
def run_evaluation(
    db: MatchingDatabase,
    config: EvaluationConfig | None = None,
    *,
    progress: Callable[[int, int, str], None] | None = None,
    **options: Any,
) -> Evaluation:
    """Synthesise a held-out part of a database with each system and measure every output.

    Parameters
    ----------
    db : MatchingDatabase
        With its takes' audio stored.
    config : EvaluationConfig, optional
        What is held out, the systems, their synthesis options and the measures'.
    progress : callable(done, total, what), optional
    **options
        Fields of :class:`EvaluationConfig`, replacing those of ``config``
        (``run_evaluation(db, holdout="take", systems="knn")``).

    Returns
    -------
    Evaluation
        Same inputs and seeds give the same numbers.
    """
    if config is not None and not isinstance(config, EvaluationConfig):  # earlier versions': the synthesis's
        config, options = None, {"synthesis": config, **options}
    config = options_config(EvaluationConfig, config, options)
    holdout, systems, control, sigma = config.holdout, config.systems, config.control, config.sigma
    fgd_model, refiner = config.fgd_model, config.refiner
    import pandas as pd

    from ..synthesis import SynthesisConfig

    systems = parse_systems(systems)
    ref = held_out(db, holdout, margin_s=config.margin_s)
    base = config.synthesis or SynthesisConfig()
    base = replace(
        base,
        search=replace(base.search, pins={}),
        control="",
        exclude_takes=ref.exclude_takes,
        exclude_ranges=ref.exclude_ranges,
    )
    track = control if control is not None else default_control_track(ref.duration)
    if isinstance(track, str):
        track = parse_control(track)
    notes: list[str] = []
    total = 2 * len(systems) + 2
    done = 0

    def tick(what):
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, what)

    if "knn+cgan" in systems and refiner is not None and refiner_unavailable_reason(refiner) is None:
        refiner = open_refiner(refiner)  # opened once for both runs
    exclude = db.exclusion_mask(takes=ref.exclude_takes, ranges=ref.exclude_ranges)
    model = _fgd_model(db, fgd_model, exclude, notes)
    tick("FGD autoencoder")
    onsets = metrics.audio_onsets(ref.audio)
    tick("speech onsets")
    rows, control_rows, outputs = [], [], {}
    t0 = time.perf_counter()
    for system in systems:
        before = done
        try:
            free = run_system(
                system, db=db, audio=ref.audio, config=base, control=ControlTrack(()), gt=ref.motion, refiner=refiner
            )
            tick(f"{system}")
            ctrl = None
            if system != "gt":
                ctrl = run_system(
                    system, db=db, audio=ref.audio, config=base, control=track, gt=ref.motion, refiner=refiner
                )
            tick(f"{system} with the control")
        except SystemUnavailable as exc:
            warn(str(exc), stacklevel=2)
            notes.append(str(exc))
            done = before + 2
            continue
        outputs[system] = free
        row = {"system": system, "frames": min(free.motion.n_frames, ref.n_frames)}
        row.update(_measure(free, ref, onsets, model, sigma))
        for mode, out in (("controlled", ctrl), ("uncontrolled", free)):
            if out is None:
                row[f"adherence_{mode}"] = float("nan")
                continue
            table = metrics.control_adherence(
                out.motion.positions[: ref.n_frames], track, thresholds=db.thresholds, fps=db.fps
            )
            row[f"adherence_{mode}"] = metrics.overall_adherence(table)
            table.insert(0, "run", mode)
            table.insert(0, "system", system)
            control_rows.append(table)
        row["relaxed_steps"] = 0 if ctrl is None else ctrl.relaxed_steps
        rows.append(row)
    table = pd.DataFrame(rows, columns=["system", "frames", *METRIC_COLUMNS, "relaxed_steps"])
    controls = (
        pd.concat(control_rows, ignore_index=True)
        if control_rows
        else pd.DataFrame(columns=["system", "run", "start_s", "end_s", "constraint", "frames", "adherence"])
    )
    settings = {
        "database": str(db.path) if db.path is not None else (db.label or "in-memory database"),
        "holdout": ref.holdout.to_text(),
        "systems": list(systems),
        "synthesis": base.to_dict(),
        "control": track.to_text(),
        "beat_sigma_s": sigma,
        "fgd": {"window": model.config.window, "latent": model.config.latent, **model.info},
        "seconds": round(time.perf_counter() - t0, 3),
    }
    return Evaluation(table, controls, ref, outputs, notes, settings)


@checks_arguments
def evaluate(db: MatchingDatabase, config: EvaluationConfig | None = None, **options: Any) -> pd.DataFrame:
    """:func:`run_evaluation`'s table: one row per system, one column per measure."""
    return run_evaluation(db, config, **options).table


# ---- writers ------------------------------------------------------------------------------------


def _cell(v: object, floatfmt: str) -> str:
    if isinstance(v, (float, np.floating)):
        if math.isnan(v):
            return "–"
        return format(float(v), floatfmt)
    return str(v).replace("|", "\\|")


@checks_arguments
def markdown_table(df: pd.DataFrame, *, floatfmt: str = ".4g") -> str:
    """A pandas DataFrame as a GitHub-flavoured markdown table (numbers right-aligned; NaN as "–")."""
    cols = list(df.columns)
    body = [[_cell(v, floatfmt) for v in row] for row in df.itertuples(index=False, name=None)]
    numeric = [
        bool(len(df))
        and all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in df[c])
        for c in cols
    ]
    widths = [max([len(str(c))] + [len(r[i]) for r in body]) for i, c in enumerate(cols)]

    def line(cells):
        return "| " + " | ".join(c.rjust(w) if num else c.ljust(w) for c, w, num in zip(cells, widths, numeric)) + " |"

    rule = "|" + "|".join(("-" * (w + 1) + ":") if num else ("-" * (w + 2)) for w, num in zip(widths, numeric)) + "|"
    return "\n".join([line([str(c) for c in cols]), rule] + [line(r) for r in body])


@checks_arguments
def write_text(text: str, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write a UTF-8 text file atomically."""
    from .._io import atomic_write

    data = text.encode("utf-8")
    return atomic_write(path, lambda f: f.write(data), overwrite=overwrite)


@checks_arguments
def write_csv(df: pd.DataFrame, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write a DataFrame as CSV (no index, full float precision) atomically."""
    return write_text(df.to_csv(index=False, lineterminator="\n"), path, overwrite=overwrite)
