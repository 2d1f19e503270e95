"""User-study stimuli: every speech x system as an MP4 in one style, named by an opaque id.

:func:`make_stimuli` synthesises each speech with each system
(:mod:`gesturekit.evaluate.baselines`) and renders every result the same way:
one camera fixed on the same region for every clip (the house render style
without fitting the view to the motion), one character, one resolution and
frame rate, and the speech normalised to one loudness (EBU R 128 integrated
loudness, measured by ffmpeg's ``ebur128`` filter), so that nothing but the
motion tells the stimuli apart. No label is drawn on the videos. The character
is ours in the neutral grey, or the user's own (``character=``: every motion
retargeted onto it, in its own colours), the same in every stimulus; the study
records its file's name and SHA-256.

A study folder::

    videos/<id>.mp4   the stimuli; an id reveals neither the speech nor the system
    manifest.csv      id, file, audio, system, controls, seed, duration_s (the key: keep it from raters)
    order.csv         participant, trial, position, slot, id: the presentation order
    study.json        every setting that made the folder; its ``format`` (``gesturekit-study``)
                      lets a later ``--force`` recognise the folder as a study to replace

Ids are the first hex digits of an HMAC-SHA256, keyed by the seed, of the
speech and system names: the same seed gives the same ids (and the same
order), another seed other ids. The order is balanced: each participant hears
the speeches in the order of a row of a balanced Latin square (Williams
design) and, for each speech, sees the systems in the order of a row of
another one, so over a multiple of its rows every system appears equally often
at every position and directly after every other system.

Rendering runs in parallel: on all cores by default (a process pool), or on a
Dask distributed cluster given its scheduler address (or a
``distributed.Client``); both give the same files.
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import json
import math
import os
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np

from .._arguments import checks_arguments
from .._config import options_config
from .._io import atomic_write
from .._jobs import run_jobs
from .._optional import require
from ..errors import ConfigError
from ..export.loudness import measure_loudness, normalise_loudness
from ..motion import AUDIO_SR, Motion
from ..skeleton import JointPresence
from .config import StudyConfig

if TYPE_CHECKING:
    import pandas as pd
    from distributed import Client

    from ..character.target import Character
    from ..control import ControlTrack
    from ..database import MatchingDatabase
    from ..viz.render import RenderStyle

__all__ = [
    "StimulusSpeech",
    "StudyResult",
    "stimulus_id",
    "balanced_latin_square",
    "plan_stimuli",
    "measure_loudness",
    "normalise_loudness",
    "speech_sources",
    "stimulus_style",
    "StudyConfig",
    "make_stimuli",
]

_ID_DIGITS = 10


# ---- the design ---------------------------------------------------------------------------------


@checks_arguments
def stimulus_id(seed: int, speech: str, system: str, *, digits: int = _ID_DIGITS) -> str:
    """The opaque id of one stimulus: hex digits of HMAC-SHA256(key=seed, speech + system).

    Parameters
    ----------
    seed : int
        The study's seed (non-negative).
    speech, system : str
        Names of the speech (as in the manifest) and of the system.
    digits : int
        Hex digits kept (4..64).
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    if not 4 <= digits <= 64:
        raise ConfigError(f"digits must be within 4..64, got {digits}")
    key = f"gesturekit-stimuli:{int(seed)}".encode()
    msg = f"{speech}\0{system}".encode("utf-8", "surrogatepass")
    return hmac.new(key, msg, hashlib.sha256).hexdigest()[:digits]


@checks_arguments
def balanced_latin_square(n: int) -> np.ndarray:
    """A balanced Latin square (Williams design) of ``n`` conditions.

    Every row is an order of ``0 .. n-1``; every condition appears once at every
    position over ``n`` rows, and directly after every other condition equally
    often. For odd ``n`` that needs ``2 n`` rows (each row and its reverse).

    Returns
    -------
    np.ndarray, shape (n or 2n, n), int64
    """
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ConfigError(f"a Latin square needs at least one condition, got {n!r}")
    first, lo, hi = [0], 1, n - 1
    for k in range(1, n):
        if k % 2:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    rows = [[(f + r) % n for f in first] for r in range(n)]
    if n % 2 and n > 1:
        rows += [row[::-1] for row in rows]
    return np.asarray(rows, dtype=np.int64)


@dataclass
class _Plan:
    conditions: pd.DataFrame
    order: pd.DataFrame


@checks_arguments
def plan_stimuli(
    speeches: Sequence[str],
    systems: Sequence[str],
    *,
    seed: int = 0,
    participants: int | None = None,
    controls: str = "",
    synthesis_seed: int | None = None,
) -> _Plan:
    """The conditions of a study and each participant's presentation order (no rendering).

    Parameters
    ----------
    speeches : sequence of str
        Names of the speeches (unique).
    systems : sequence of str
        Names of the systems (unique).
    seed : int
        Seed of the ids and of the order.
    participants : int, optional
        Participants to plan for; default the rows of the systems' balanced Latin square.
    controls : str
        Control track shown in the manifest.
    synthesis_seed : int, optional
        Seed of the synthesis shown in the manifest (default ``seed``).

    Returns
    -------
    plan
        ``conditions``: one row per speech x system (``id``, ``file``, ``audio``, ``system``,
        ``controls``, ``seed``); ``order``: ``participant``, ``trial``, ``position``, ``slot``,
        ``id`` (1-based), ``trial`` being the speech's turn and ``position`` the system's place in it.
    """
    import pandas as pd

    speeches, systems = list(speeches), list(systems)
    for what, names in (("speech", speeches), ("system", systems)):
        if not names:
            raise ConfigError(f"a study needs at least one {what}")
        if len(set(names)) != len(names):
            raise ConfigError(f"{what} names must be unique, got {names}")
    ids = {(a, s): stimulus_id(seed, a, s) for a in speeches for s in systems}
    if len(set(ids.values())) != len(ids):
        raise ConfigError("two stimuli got the same id; choose another seed")
    syn_seed = seed if synthesis_seed is None else int(synthesis_seed)
    conditions = pd.DataFrame(
        [
            {
                "id": ids[(a, s)],
                "file": f"videos/{ids[(a, s)]}.mp4",
                "audio": a,
                "system": s,
                "controls": controls or "none",
                "seed": syn_seed,
            }
            for a in speeches
            for s in systems
        ]
    )
    sq_sys, sq_sp = balanced_latin_square(len(systems)), balanced_latin_square(len(speeches))
    if participants is None:
        participants = len(sq_sys)
    if isinstance(participants, bool) or not isinstance(participants, (int, np.integer)) or participants < 1:
        raise ConfigError(f"participants must be a positive integer, got {participants!r}")
    # the seed decides which condition plays which role in the squares
    rng = np.random.default_rng([int(seed), 0x57D1])
    perm_sys, perm_sp = rng.permutation(len(systems)), rng.permutation(len(speeches))
    rows = []
    for p in range(int(participants)):
        slot = 0
        for trial, a_idx in enumerate(sq_sp[p % len(sq_sp)]):
            speech = speeches[perm_sp[a_idx]]
            for position, s_idx in enumerate(sq_sys[(p + trial) % len(sq_sys)]):
                slot += 1
                rows.append(
                    {
                        "participant": p + 1,
                        "trial": trial + 1,
                        "position": position + 1,
                        "slot": slot,
                        "id": ids[(speech, systems[perm_sys[s_idx]])],
                    }
                )
    return _Plan(conditions, pd.DataFrame(rows, columns=["participant", "trial", "position", "slot", "id"]))


# ---- speeches -----------------------------------------------------------------------------------


@dataclass
class StimulusSpeech:
    """One speech of a study.

    Attributes
    ----------
    name : str
        As shown in the manifest: the file name, or the held-out part (``TAKE:START-END``).
    audio : np.ndarray, shape (samples,), float32 at 16 kHz
    gt : Motion or None
        The recorded motion (held-out parts of the database only).
    exclude_takes, exclude_ranges : tuple
        What every system's search must not use for this speech.
    """

    name: str
    audio: np.ndarray
    gt: Motion | None = None
    exclude_takes: tuple = ()
    exclude_ranges: tuple = ()


@checks_arguments
def speech_sources(
    db: MatchingDatabase, *, audio: Sequence[str | os.PathLike[str]] = (), holdouts: Sequence[Any] = ()
) -> list[StimulusSpeech]:
    """The speeches of a study: speech files (or folders of them) and held-out parts of the database.

    Parameters
    ----------
    db : MatchingDatabase
    audio : sequence of path
        Speech files in any format the readers take, or folders (their speech files, sorted).
    holdouts : sequence of str or Holdout
        ``TAKE`` or ``TAKE:START-END``: the database's own speech and recorded motion (``gt``),
        kept out of every system's search.
    """
    from ..datasets.audio import load_audio
    from ..evaluate.run import held_out
    from ..workspace import expand_speech

    out = [StimulusSpeech(f.name, load_audio(f)) for f in expand_speech(audio)]
    for h in holdouts:
        ref = held_out(db, h)
        out.append(StimulusSpeech(ref.holdout.to_text(), ref.audio, ref.motion, ref.exclude_takes, ref.exclude_ranges))
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ConfigError(f"two speeches have the same name ({', '.join(dup)}); rename one")
    if not out:
        raise ConfigError("a study needs speech: give speech files, a folder of them, or held-out parts")
    return out


# ---- rendering ----------------------------------------------------------------------------------


@checks_arguments
def stimulus_style(view_box: Sequence[Sequence[float]] | None = None) -> RenderStyle:
    """The one look of every stimulus: the page's character in the neutral grey scheme, with a fixed
    camera (never fitted to a motion), so that neither colour nor framing tells the systems apart.

    Parameters
    ----------
    view_box : ((xmin, xmax), (ymin, ymax), (zmin, zmax)), optional
        The region every stimulus frames, metres; default the style's pelvis-relative
        upper body. A partial skeleton (e.g. neck-relative) passes the box of all its
        stimuli together (:func:`_study_view_box`), so they still share one camera.
    """
    require("pyvista", purpose="rendering stimuli")
    from ..viz.render import RenderStyle

    if view_box is None:
        return RenderStyle(fit_motion=False, neutral=True)
    return RenderStyle(fit_motion=False, neutral=True, view_box=tuple(tuple(float(v) for v in row) for row in view_box))


def _study_view_box(motions: Sequence[Motion], character: Character | None = None) -> list[list[float]] | None:
    """One fixed box for all stimuli of a partial skeleton or a user's character: the fitted bounds of what
    every one of them draws, each where it stands alone, shape (3, 2) as lists, metres (a character's:
    from its pelvis at rest); None for complete skeletons on our character (the default box)."""
    if character is None and all(m.presence.is_full for m in motions):
        return None
    require("pyvista", purpose="rendering stimuli")
    from ..viz.render import RenderStyle, view_bounds

    # one at a time: given together, the stage would stand them side by side
    boxes = np.stack([view_bounds([m], style=RenderStyle(), character=character) for m in motions])
    if character is not None:
        boxes -= np.asarray(character.rest_position[character.pelvis], dtype=np.float64)[:, None]
    return np.stack([boxes[:, :, 0].min(axis=0), boxes[:, :, 1].max(axis=0)], axis=1).tolist()


def _study_character(character: Any, bone_map: Any, wrist_slack: float) -> tuple[Character | None, dict | None]:
    """The character every stimulus shows (read from its file) and what study.json records of it: the
    names and SHA-256 of its file and bone map, how its bones were matched."""
    from ..character.target import WRIST_SLACK, Character
    from ..character.user import character_record, read_character

    if character is None:
        if bone_map is not None:
            raise ConfigError("a bone map (--character-map) needs a character (--character)")
        if wrist_slack != WRIST_SLACK:
            raise ConfigError("a wrist slack (--wrist-slack) says how a character's arms are posed: give one")
        return None, None
    if isinstance(character, Character):
        if bone_map is not None:
            raise ConfigError("a Character is already matched: give the bone map to read_character instead")
        character = dataclasses.replace(character, wrist_slack=wrist_slack)
    else:
        character = read_character(character, bone_map=bone_map, wrist_slack=wrist_slack)
    record = character_record(character, bone_map=bone_map)
    # the glTF document stays here: the rendering needs the bones and the skin only
    return dataclasses.replace(character, gltf=None), record


def _job_motion(job: dict) -> Motion:
    """A stimulus job's motion; the joints the database holds travel with the positions."""
    joints = job.get("joints")
    return Motion(job["positions"], job["fps"], None if joints is None else JointPresence(tuple(joints)))


def _render_stimulus(job: dict) -> str:
    """Render one stimulus (runs in a worker process or on a Dask worker)."""
    from ..export.video import render_video

    motion = _job_motion(job)
    # one process per stimulus already keeps every core busy
    render_video(
        job["path"],
        motion,
        audio=job["audio"],
        resolution=tuple(job["resolution"]),
        workers=1,
        overwrite=True,
        style=stimulus_style(job.get("view_box")),
        character=job.get("character"),
    )
    return job["id"]


def _run_jobs(
    jobs: list[dict],
    *,
    workers: int | None,
    scheduler: str | Client | None,
    progress: Callable[[int, int], None] | None,
) -> None:
    total = len(jobs)
    done = 0

    def tick(job: dict, result: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    run_jobs(
        _render_stimulus,
        jobs,
        keys=[f"stimulus-{j['id']}" for j in jobs],
        workers=workers,
        scheduler=scheduler,
        on_result=tick,
        purpose="rendering on a Dask cluster (a scheduler)",
        died="a rendering process died; if make_stimuli is called from a script, put the call under "
        '`if __name__ == "__main__":` (worker processes import the main script), or pass workers=1',
    )


# ---- the study ----------------------------------------------------------------------------------


@dataclass
class StudyResult:
    """A written study folder.

    Attributes
    ----------
    folder : Path
    manifest : pandas.DataFrame
        ``id, file, audio, system, controls, seed, duration_s``.
    order : pandas.DataFrame
        ``participant, trial, position, slot, id``.
    videos : list of Path
    settings : dict
    """

    folder: Path
    manifest: pd.DataFrame
    order: pd.DataFrame
    videos: list = field(default_factory=list)
    settings: dict = field(default_factory=dict)


def _write_text(path: Path, text: str) -> None:
    data = text.encode("utf-8")

    def write(f: BinaryIO) -> None:
        f.write(data)

    atomic_write(path, write, overwrite=True)


@checks_arguments
def make_stimuli(
    db: MatchingDatabase,
    config: StudyConfig | None = None,
    *,
    out: str | os.PathLike,
    overwrite: bool = False,
    progress: Callable[[str, int, int], None] | None = None,
    **options: Any,
) -> StudyResult:
    """Prepare a user study: every speech x system as an MP4, a manifest and the presentation order.

    Parameters
    ----------
    db : MatchingDatabase
    config : StudyConfig, optional
        The speeches, systems, design, synthesis and rendering options (see :class:`StudyConfig`).
    out : path
        The study folder (see the module documentation).
    overwrite : bool
        Replace an existing study in ``out`` (its videos not in the new plan are removed).
    progress : callable(stage, done, total), optional
        ``stage`` is ``"synthesis"`` or ``"rendering"``.
    **options
        Fields of :class:`StudyConfig`, replacing those of ``config``
        (``make_stimuli(db, out=..., audio=[folder], systems="knn")``).

    Returns
    -------
    StudyResult
        The same inputs and seed give the same ids, order and videos.
    """
    if config is not None and not isinstance(config, StudyConfig):  # earlier versions': the synthesis's
        config, options = None, {"synthesis": config, **options}
    study = options_config(StudyConfig, config, options)
    from ..control import parse_control
    from ..evaluate.baselines import SystemUnavailable, parse_systems, refiner_unavailable_reason
    from ..export.video import check_resolution
    from ..refine import open_refiner

    t0 = time.perf_counter()
    systems = parse_systems(study.systems)
    width, height = check_resolution(study.resolution)
    for needed in ("pyvista", "imageio_ffmpeg") + (("distributed",) if isinstance(study.scheduler, str) else ()):
        require(needed, purpose="rendering stimuli")  # before the long part (the workers import them again)
    if not math.isfinite(study.loudness_lufs):
        # a NaN target would scale every soundtrack to NaN samples
        raise ConfigError(f"the loudness must be a finite number of LUFS (e.g. -23), got {study.loudness_lufs!r}")
    track = parse_control(study.control)
    user_character, character_record = _study_character(study.character, study.character_map, study.wrist_slack)
    refiner = study.refiner
    refiner_name = None if refiner is None else str(getattr(refiner, "path", None) or refiner)
    if "knn+cgan" in systems:
        reason = refiner_unavailable_reason(refiner)
        if reason:
            raise SystemUnavailable(reason)
        refiner = open_refiner(refiner)
    from ..outputs import check_output, output_lock

    out = Path(out)
    # the study folder is never the database's or the speech's, nor inside or around them
    check_output(out, "study", overwrite=overwrite, inputs=[getattr(db, "path", None), *study.audio])
    with output_lock(out):
        check_output(out, "study", overwrite=overwrite, inputs=[getattr(db, "path", None), *study.audio])
        prepared = _Prepared(systems, track, refiner, refiner_name, width, height, user_character, character_record)
        return _make_stimuli_locked(db, study, prepared, out=out, progress=progress, t0=t0)


@dataclass(frozen=True)
class _Prepared:
    """What :func:`make_stimuli` made of a :class:`StudyConfig` before locking the folder: the systems
    parsed, the control track read, the refiner opened, the resolution checked, the character read."""

    systems: tuple[str, ...]
    track: ControlTrack
    refiner: Any
    refiner_name: str | None
    width: int
    height: int
    character: Any
    character_record: dict | None


def _make_stimuli_locked(
    db: MatchingDatabase,
    study: StudyConfig,
    prepared: _Prepared,
    *,
    out: Path,
    progress: Callable[[str, int, int], None] | None,
    t0: float,
) -> StudyResult:
    """:func:`make_stimuli` once the study folder is checked and locked."""
    from ..evaluate.baselines import SystemUnavailable, run_system
    from ..outputs import write_errors
    from ..synthesis import SynthesisConfig

    systems, track, refiner, character = prepared.systems, prepared.track, prepared.refiner, prepared.character
    seed, loudness_lufs = study.seed, study.loudness_lufs
    manifest_path, order_path, study_path = out / "manifest.csv", out / "order.csv", out / "study.json"
    speeches = speech_sources(db, audio=study.audio, holdouts=study.holdouts)
    if "gt" in systems:
        missing = [s.name for s in speeches if s.gt is None]
        if missing:
            raise SystemUnavailable(
                f"gt needs recorded motion, which only held-out parts of the database have "
                f"(--holdout TAKE:START-END); none for {', '.join(missing)}"
            )
    base = study.synthesis or SynthesisConfig(seed=int(seed))
    plan = plan_stimuli(
        [s.name for s in speeches],
        systems,
        seed=seed,
        participants=study.participants,
        controls=track.to_text(),
        synthesis_seed=base.seed,
    )
    with write_errors(out):
        (out / "videos").mkdir(parents=True, exist_ok=True)
        if not study_path.exists():
            # the marker first: a run killed while rendering leaves a folder that --force may replace
            _write_text(study_path, json.dumps({"format": "gesturekit-study", "complete": False}) + "\n")

    # synthesis here (cheap, needs the database); rendering goes to the workers
    jobs, durations = [], {}
    ids = dict(zip(zip(plan.conditions["audio"], plan.conditions["system"]), plan.conditions["id"]))
    n_total, n_done = len(speeches) * len(systems), 0
    for sp in speeches:
        cfg = SynthesisConfig.from_dict(
            {
                **base.to_dict(),
                "control": "",
                "pins": {},
                "exclude_takes": list(sp.exclude_takes),
                "exclude_ranges": [list(r) for r in sp.exclude_ranges],
            }
        )
        sound, _ = normalise_loudness(sp.audio, target_lufs=loudness_lufs)
        durations[sp.name] = len(sp.audio) / AUDIO_SR
        for system in systems:
            res = run_system(system, db=db, audio=sp.audio, config=cfg, control=track, gt=sp.gt, refiner=refiner)
            sid = ids[(sp.name, system)]
            jobs.append(
                {
                    "id": sid,
                    "path": str(out / "videos" / f"{sid}.mp4"),
                    "positions": res.motion.positions,
                    "fps": float(res.motion.fps),
                    "joints": None if res.motion.joints is None else res.motion.joints.to_list(),
                    "audio": sound,
                    "resolution": (prepared.width, prepared.height),
                    "character": character,
                }
            )
            n_done += 1
            if progress is not None:
                progress("synthesis", n_done, n_total)

    # videos of an earlier plan in this folder that the new one does not make
    if manifest_path.exists():
        import pandas as pd

        old = pd.read_csv(manifest_path, dtype=str)
        keep = set(plan.conditions["file"])
        for f in old.get("file", []):
            if isinstance(f, str) and f not in keep and re.fullmatch(r"videos/[0-9a-f]+\.mp4", f):
                (out / f).unlink(missing_ok=True)

    box = _study_view_box([_job_motion(j) for j in jobs], character)
    for j in jobs:
        j["view_box"] = box
    _run_jobs(
        jobs,
        workers=study.workers,
        scheduler=study.scheduler,
        progress=None if progress is None else (lambda d, t: progress("rendering", d, t)),
    )

    manifest = plan.conditions.copy()
    manifest["duration_s"] = [round(durations[a], 6) for a in manifest["audio"]]
    _write_text(manifest_path, manifest.to_csv(index=False, lineterminator="\n"))
    _write_text(order_path, plan.order.to_csv(index=False, lineterminator="\n"))
    settings: dict[str, Any] = {
        "format": "gesturekit-study",
        "database": str(db.path) if db.path is not None else (db.label or "in-memory database"),
        "systems": list(systems),
        "speeches": [s.name for s in speeches],
        "seed": int(seed),
        "participants": int(plan.order["participant"].max()),
        "control": track.to_text(),
        "synthesis": base.to_dict(),
        "resolution": [prepared.width, prepared.height],
        "fps": float(db.fps),
        "loudness_lufs": float(loudness_lufs),
        "render_style": "gesturekit house style, fixed camera (fit_motion=False), no labels",
        "refiner": prepared.refiner_name,
    }
    if prepared.character_record is not None:
        settings["render_style"] += "; the user's character in its own colours"
        settings["character"] = prepared.character_record
    if box is not None:
        settings["view_box"] = box  # a partial skeleton's stimuli share this fitted, fixed frame
    _write_text(study_path, json.dumps(settings, indent=1) + "\n")
    settings["seconds"] = round(time.perf_counter() - t0, 3)
    return StudyResult(out, manifest, plan.order, [out / f for f in manifest["file"]], settings)
