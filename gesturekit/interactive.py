"""What the app's pages compute, kept free of streamlit so tests and notebooks can use it too.

The Synthesize page edits a control track as a table (one row per
constraint: ``start_s``, ``end_s``, ``constraint`` such as
``"left_hand=high"``), adds rows from a time range box-selected on the
waveform, reads uploaded speech through a temporary folder, offers generated
example speech and exports a result as bytes for download. The Retrieval
inspector describes each search step's candidates by their source take and
time and compares results for several ``k``.

Times are in seconds, motions are :class:`~gesturekit.motion.Motion` objects
(frames, 55, 3) in metres, audio is mono float32 at 16 kHz.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ._arguments import checks_arguments
from ._io import safe_filename
from .database import MatchingDatabase
from .datasets.audio import wav_bytes
from .errors import ConfigError, GestureKitError, collect_warnings, warn
from .evaluate.metrics import control_adherence, overall_adherence
from .export.bvh import BvhReport
from .export.result import export_result_bvh, save_result_npz, save_result_video
from .motion import AUDIO_SR, Motion
from .refine import open_refiner
from .search.explain import query_pose_frame
from .synthesis import SynthesisConfig, SynthesisResult, synthesize_batch
from .viz.candidate_view import CandidateView

if TYPE_CHECKING:
    from .datasets.audio import AudioInfo
    from .refine.infer import Refiner

__all__ = [
    "SPEECH_EXAMPLES",
    "BLEND_LABELS",
    "EXPORT_KINDS",
    "selected_time_range",
    "example_speech",
    "read_speech_upload",
    "display_motions",
    "export_filename",
    "export_bytes",
    "export_bvh_bytes",
    "render_mp4",
    "candidate_motion",
    "segment_in_context",
    "step_speech",
    "query_pose",
    "candidate_views",
    "clip_speech",
    "compare_k",
    "comparison_table",
    "parse_times",
]

#: Example speech the app offers: label -> (seconds, seed) of a take of the generated demo speaker.
#: The seeds are not among those of the demo database's takes, so the examples are unseen speech.
SPEECH_EXAMPLES: dict[str, tuple[float, int]] = {
    "demo speaker, 8 s (generated)": (8.0, 7001),
    "demo speaker, 20 s (generated)": (20.0, 7002),
    "demo speaker, 60 s (generated)": (60.0, 7003),
}

#: Downloadable forms of a result: kind -> (file name suffix, MIME type).
EXPORT_KINDS: dict[str, tuple[str, str]] = {
    "npz": (".npz", "application/octet-stream"),
    "bvh": (".bvh", "text/plain"),
    "glb": (".glb", "model/gltf-binary"),
    "csv": ("_control.csv", "text/csv"),
    "json": ("_config.json", "application/json"),
    "mp4": (".mp4", "video/mp4"),
    "wav": (".wav", "audio/wav"),
}

# a box selection shorter than one output frame is a click, not a range
_MIN_RANGE_S = 1.0 / 15.0
_TIME_DECIMALS = 2  # box-selected times are rounded to 10 ms


@checks_arguments
def selected_time_range(selection: Mapping | None, *, duration: float) -> tuple[float, float] | None:
    """The time range of the latest box selection on a chart whose x axis is time.

    Parameters
    ----------
    selection : mapping or None
        A plotly selection state as Streamlit reports it: ``{"box": [{"x":
        [x0, x1], ...}, ...], ...}`` (x in seconds).
    duration : float
        Length of the speech, seconds; the range is clipped to ``[0, duration]``.

    Returns
    -------
    (start_s, end_s) or None
        Rounded to 10 ms; None without a box or for one shorter than a frame.
    """
    boxes = list((selection or {}).get("box") or [])
    if not boxes:
        return None
    xs = [float(v) for v in (boxes[-1].get("x") or []) if v is not None]
    if len(xs) < 2 or not all(math.isfinite(v) for v in xs):
        return None
    a = round(min(max(min(xs), 0.0), duration), _TIME_DECIMALS)
    b = round(min(max(max(xs), 0.0), duration), _TIME_DECIMALS)
    if b - a < _MIN_RANGE_S:
        return None
    return a, b


# ---- speech -------------------------------------------------------------------------------------


@checks_arguments
def example_speech(label: str) -> np.ndarray:
    """Generated example speech of the demo speaker (deterministic).

    Parameters
    ----------
    label : str
        A key of :data:`SPEECH_EXAMPLES`.

    Returns
    -------
    np.ndarray, shape (samples,), float32
        Mono speech at 16 kHz.
    """
    from .datasets.synthetic import generate_demo_take

    if label not in SPEECH_EXAMPLES:
        raise ConfigError(f"no example speech {label!r}; examples: {', '.join(SPEECH_EXAMPLES)}")
    seconds, seed = SPEECH_EXAMPLES[label]
    take, _ = generate_demo_take(seconds=seconds, seed=seed, name=safe_filename(label))
    return take.audio


@checks_arguments
def read_speech_upload(name: str, data: bytes) -> tuple[np.ndarray, AudioInfo]:
    """Decode an uploaded speech file (any format the audio reader takes) via a temporary folder.

    Parameters
    ----------
    name : str
        The file name the user gave (only its sanitised form is used on disk;
        the suffix tells the decoder the format).
    data : bytes
        The file's content.

    Returns
    -------
    audio : np.ndarray, shape (samples,), float32
        Mono speech at 16 kHz.
    info : gesturekit.datasets.audio.AudioInfo
        What the file held (format, rate, channels, duration).

    Raises
    ------
    GestureKitError
        Not audio, truncated, too short, invalid samples...; the message names
        the uploaded file (not the temporary copy).

    Warns
    -----
    GestureKitWarning
        Silent audio (as :func:`gesturekit.datasets.audio.load_audio`), naming the upload.
    """
    from .datasets.audio import load_audio_with_info

    with tempfile.TemporaryDirectory(prefix="gesturekit-upload-") as tmp:
        path = Path(tmp) / safe_filename(Path(str(name)).name, default="upload")
        path.write_bytes(bytes(data))
        with collect_warnings() as caught:
            try:
                audio, info = load_audio_with_info(path)
            except GestureKitError as exc:
                raise type(exc)(exc.problem, path=str(name)) from None
    for message in caught:  # passed on, naming the upload rather than its temporary copy
        warn(message.replace(str(path), str(name)), stacklevel=2)
    return audio, dataclasses.replace(info, path=str(name))


# ---- what to show ------------------------------------------------------------------------------


#: What a page calls each blend mode's joins (:data:`gesturekit.blend.BLEND_MODES`).
BLEND_LABELS = {
    "none": "hard joins",
    "offset": "offset fade",
    "inertialize": "inertialized joins",
    "dead": "dead-blended joins",
}


@checks_arguments
def display_motions(result: SynthesisResult) -> tuple[list[Motion], list[str]]:
    """The motions to show for a result, with their labels.

    Refined: the k-NN motion (the paper's hard joins) and the refined one side by side. Without a
    refiner and with a blend (:mod:`gesturekit.blend`): the hard joins and the blended output side
    by side, so what the blend does is seen. Else the output alone.
    """
    if result.refined_motion is not None:
        return [result.knn_motion, result.refined_motion], ["k-NN", "k-NN + refiner"]
    if result.config.blend == "none":
        return [result.motion], ["k-NN"]
    return [result.knn_motion, result.motion], ["k-NN, hard joins", f"k-NN, {BLEND_LABELS[result.config.blend]}"]


# ---- exports ------------------------------------------------------------------------------------


@checks_arguments
def export_filename(result: SynthesisResult, kind: str) -> str:
    """A safe download name, e.g. ``"speech_k0_seed0.bvh"``, from the speech's name and the settings."""
    if kind not in EXPORT_KINDS:
        raise ConfigError(f"unknown export {kind!r}; one of {', '.join(EXPORT_KINDS)}")
    stem = Path(result.source).stem or "speech"
    c = result.config
    return safe_filename(f"{stem}_k{c.k}_seed{c.seed}", max_length=80, default="gesturekit") + EXPORT_KINDS[kind][0]


@checks_arguments
def export_bytes(result: SynthesisResult, kind: str) -> bytes:
    """A result in one downloadable form.

    Parameters
    ----------
    kind : {"npz", "bvh", "csv", "json", "wav"}
        ``npz``: :func:`~gesturekit.export.result.save_result_npz`; ``bvh``: the final motion;
        ``csv``: the control track (start_s, end_s, constraint); ``json``: how
        the result was made (:meth:`SynthesisResult.metadata`, with the
        synthesis config under ``"synthesis"``); ``wav``: the speech (16-bit PCM at
        16 kHz, :func:`gesturekit.datasets.audio.wav_bytes`). ``mp4`` is made by :func:`render_mp4`.
    """
    if kind == "wav":
        return wav_bytes(result.audio)
    if kind == "csv":
        return result.control.to_csv().encode("utf-8")
    if kind == "json":
        return (json.dumps(result.metadata(), indent=2) + "\n").encode("utf-8")
    if kind == "bvh":
        return export_bvh_bytes(result)[0]
    if kind != "npz":
        raise ConfigError(f"export_bytes makes npz, bvh, csv, json or wav, not {kind!r}")
    buf = io.BytesIO()
    save_result_npz(result, buf)
    return buf.getvalue()


@checks_arguments
def export_bvh_bytes(result: SynthesisResult, name: str = "result.bvh") -> tuple[bytes, BvhReport]:
    """The result's BVH file, and its report (:func:`~gesturekit.export.result.export_result_bvh`).

    Parameters
    ----------
    name : str
        The file name the report speaks of (the download's).

    Returns
    -------
    bytes
        The file.
    BvhReport
        Its position error against the motion (metres), root, joints left out and derived.
    """
    buf = io.BytesIO()
    buf.name = name  # the name the report and its warning speak of
    report = export_result_bvh(result, buf)
    return buf.getvalue(), report


@checks_arguments
def render_mp4(
    result: SynthesisResult,
    *,
    progress: Callable[[int, int], None] | None = None,
    resolution: tuple[int, int] = (640, 480),
    framing: str = "upper body",
) -> bytes:
    """The result as an MP4 (H.264 + AAC, the speech as soundtrack); k-NN and refined side by side if refined.

    Parameters
    ----------
    progress : callable(done, total), optional
        Called after each rendered frame.
    resolution : (int, int)
        Width and height in pixels (even numbers).
    framing : str
        The presenter's upper body and every hand, or the whole body (:data:`gesturekit.character.look.FRAMINGS`).
    """
    with tempfile.TemporaryDirectory(prefix="gesturekit-video-") as tmp:
        path = Path(tmp) / "result.mp4"
        save_result_video(
            result,
            path,
            progress=progress,
            side_by_side=result.refined_motion is not None,
            resolution=resolution,
            framing=framing,
        )
        return path.read_bytes()


# ---- the search record --------------------------------------------------------------------------


@checks_arguments
def candidate_motion(db: MatchingDatabase, clip: int, start: int, n_frames: int) -> Motion:
    """Frames ``start .. start + n_frames`` of a database clip (fewer at the clip's end)."""
    g = np.asarray(db.G[int(clip), int(start) : int(start) + int(n_frames)], dtype=np.float32)
    if g.shape[0] == 0:
        raise ConfigError(f"clip {clip} has no frame {start}")
    return Motion.from_flat(g, db.fps, db.joint_presence)


@checks_arguments
def segment_in_context(
    db: MatchingDatabase, clip: int, start: int, n_frames: int, *, context_s: float = 1.0
) -> tuple[np.ndarray, float, float, float]:
    """A database window's speech with up to ``context_s`` seconds of its take on either side.

    A step's window is short (8 frames: 0.53 s); the words around it tell
    whether its gesture suits the speech.

    Parameters
    ----------
    db : MatchingDatabase
        Built with audio.
    clip, start, n_frames : int
        The window: frames ``start .. start + n_frames`` of ``clip``.
    context_s : float
        Seconds before and after, fewer at the take's ends.

    Returns
    -------
    (audio, segment_start_s, segment_end_s, take_start_s)
        ``audio``: float32 at 16 kHz, shape (samples,); the window lies from
        ``segment_start_s`` to ``segment_end_s`` seconds into it; the excerpt
        begins ``take_start_s`` seconds into the take.

    Raises
    ------
    ConfigError
        A database without audio, or a negative ``context_s``.
    """
    if db.audio is None:
        raise ConfigError("this database was built without audio")
    if not context_s >= 0:
        raise ConfigError(f"context_s must be >= 0 seconds, got {context_s!r}")
    take = db.take_audio(int(db.arrays["clip_take"][clip]))
    f0 = int(db.arrays["clip_start"][clip]) + int(start)
    s0 = int(round(f0 * AUDIO_SR / db.fps))
    s1 = min(int(round((f0 + int(n_frames)) * AUDIO_SR / db.fps)), take.shape[0])
    pad = int(round(context_s * AUDIO_SR))
    a, b = max(0, s0 - pad), min(take.shape[0], s1 + pad)
    return np.asarray(take[a:b], dtype=np.float32), (s0 - a) / AUDIO_SR, (s1 - a) / AUDIO_SR, a / AUDIO_SR


@checks_arguments
def step_speech(result: SynthesisResult, step: int) -> np.ndarray:
    """The input speech under one step's output frames, float32 at 16 kHz."""
    n = result.config.segment
    fps = result.motion.fps
    a = int(round(step * n * AUDIO_SR / fps))
    b = int(round(min((step + 1) * n, result.n_frames) * AUDIO_SR / fps))
    return np.asarray(result.audio[a:b], dtype=np.float32)


@checks_arguments
def query_pose(db: MatchingDatabase, result: SynthesisResult, step: int) -> np.ndarray | None:
    """The pose step ``step`` matched its candidates against (``p_{t-1}``) as joints, or None.

    Returns
    -------
    np.ndarray, shape (55, 3), float32, or None
        Pelvis-relative joint positions in metres of the database frame
        :func:`gesturekit.search.explain.query_pose_frame` names; None when the initial
        pose of step 0 is no database frame.
    """
    frame = query_pose_frame(db.P, result.search, step)
    if frame is None:
        return None
    return candidate_motion(db, frame[0], frame[1], 1).positions[0]


@checks_arguments
def candidate_views(db: MatchingDatabase, result: SynthesisResult, step: int) -> list[CandidateView]:
    """The recorded candidates of one step, best first, each with its whole database clip.

    Parameters
    ----------
    db : MatchingDatabase
        The database the result was searched in.
    result : SynthesisResult
    step : int
        ``0 <= step < result.search.n_steps``.

    Returns
    -------
    list of CandidateView
        One per row of :meth:`~gesturekit.search.SearchResult.candidates_table`, in its
        order; ``label`` names the take and time, ``chosen`` marks the search's choice.
    """
    table = result.search.candidates_table(step, db)
    n = result.config.segment
    views = []
    for r in table.itertuples():
        clip = candidate_motion(db, int(r.clip), 0, db.G.shape[1]).positions
        views.append(
            CandidateView(
                position=int(r.position),
                clip_positions=clip,
                start=int(r.start),
                segment=n,
                pose_dist=float(r.pose_dist),
                audio_dist=float(r.audio_dist),
                label=f"{r.take} at {r.source_s:.2f} s",
                chosen=bool(r.chosen),
            )
        )
    return views


@checks_arguments
def clip_speech(db: MatchingDatabase, clip: int) -> np.ndarray | None:
    """A database clip's own speech over its frames, float32 at 16 kHz; None without audio."""
    if db.audio is None:
        return None
    return np.asarray(db.segment_audio(int(clip), 0, db.G.shape[1]), dtype=np.float32)


@checks_arguments
def compare_k(
    audio: str | os.PathLike[str] | np.ndarray,
    *,
    db: MatchingDatabase,
    config: SynthesisConfig,
    ks: Sequence[int],
    refiner: Refiner | str | os.PathLike[str] | None = None,
    source: str | None = None,
) -> list[SynthesisResult]:
    """Results for several ``k`` with everything else (speech, controls, pins, seed) the same.

    One batched search serves all (:func:`synthesize_batch`), refined by ``refiner`` if given.

    Parameters
    ----------
    audio : path or np.ndarray, shape (samples,)
        The speech.
    config : SynthesisConfig
        The settings; only ``k`` varies.
    ks : sequence of int
        The values of ``k`` (>= 0), in the order of the results.
    refiner : optional
        Applied to every result (see :func:`synthesize_batch`): a loaded refiner, or a folder
        (opened by :func:`gesturekit.refine.open_refiner`).
    source : str, optional
        Name of the speech stored in the results.

    Returns
    -------
    list of SynthesisResult, one per ``k``.
    """
    ks = [int(k) for k in ks]
    if not ks:
        raise ConfigError("choose at least one k to compare")
    configs = [dataclasses.replace(config, search=dataclasses.replace(config.search, k=k)) for k in ks]
    results = synthesize_batch([audio] * len(ks), db=db, config=configs, refiner=open_refiner(refiner))
    if source is not None:
        results = [dataclasses.replace(r, source=source) for r in results]
    return results


@checks_arguments
def comparison_table(results: Sequence[SynthesisResult], thresholds: Mapping[str, tuple[float, float]]) -> pd.DataFrame:
    """One row per result: k, the chosen windows' mean pose and audio distance, relaxed steps, control adherence.

    Returns
    -------
    pandas.DataFrame
        Columns ``k``, ``pose_dist`` and ``audio_dist`` (means over steps of the
        chosen window's distances; pinned windows outside the table are
        left out; :meth:`SearchResult.chosen_distances`), ``relaxed_steps``, ``pinned_steps``,
        ``control_met`` (fraction of constrained frames meeting their constraint, NaN without controls:
        :func:`~gesturekit.evaluate.metrics.overall_adherence` of
        :func:`~gesturekit.evaluate.metrics.control_adherence`).
    """
    rows = []
    for r in results:
        pose_dist, audio_dist = r.search.chosen_distances()
        rows.append(
            {
                "k": r.config.k,
                "pose_dist": pose_dist,
                "audio_dist": audio_dist,
                "relaxed_steps": len(r.relaxed_steps),
                "pinned_steps": int(np.count_nonzero(r.search.pinned)),
                "control_met": overall_adherence(
                    control_adherence(r.motion.positions, r.control, thresholds=dict(thresholds), fps=r.motion.fps)
                ),
            }
        )
    return pd.DataFrame(rows)


@checks_arguments
def parse_times(text: str, *, duration: float) -> list[float]:
    """Times typed as ``"1, 2.5, 4"`` (seconds, commas or spaces between them), in order.

    Raises
    ------
    ConfigError
        Nothing typed, something that is not a number, or a time outside ``0 .. duration``.
    """
    parts = [p for p in str(text).replace(",", " ").split() if p]
    if not parts:
        raise ConfigError("type one or more times in seconds, e.g. 1, 2.5, 4")
    times = []
    for p in parts:
        try:
            t = float(p)
        except ValueError:
            raise ConfigError(f"{p!r} is not a time in seconds") from None
        if not (math.isfinite(t) and 0 <= t <= duration):
            raise ConfigError(f"{p} s lies outside the result (0 to {duration:.2f} s)")
        times.append(t)
    return times
