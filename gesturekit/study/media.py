"""The check media of a study, made from its stimuli: attention-check videos and the audio check.

An attention-check video is a stimulus re-encoded exactly as the stimuli are (the same encoder
settings, resolution, frame rate, duration and metadata, see :mod:`gesturekit.export.video`), so
that neither its name, its size nor its metadata tells it apart:

``mismatched_audio``
    The motion of a stimulus of another speech (looped or cut to length) under this speech's
    sound: it sits on this speech's rating page and its synchrony should be rated poor.
``overlay``
    A stimulus of this speech with a visible text over its middle, "Please rate this clip 1 on
    every question" (rating pages) or "Please choose LEFT" (pairwise pages).

The audio check is a WAV of 3 to 7 beeps; the participant types how many they heard. Which
stimulus each check is made from, and the number of beeps, follow from the study's seed; the
files are named by opaque ids (the stimuli's HMAC, keyed by the seed).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from collections.abc import Callable, Generator, Mapping, Sequence
from pathlib import Path

import numpy as np

from .._arguments import checks_arguments
from .._optional import require
from ..datasets.audio import write_wav
from ..errors import GestureKitError
from ..export.video import encode_command, ffmpeg_executable, probe_media
from .stimuli import stimulus_id

__all__ = ["OVERLAY_TEXT", "check_media_id", "overlay_box", "draw_overlay", "make_check_videos", "make_audio_check"]

OVERLAY_TEXT = {"rating": "Please rate this clip 1 on every question", "pairwise": "Please choose LEFT"}
BEEP_SR = 48000
_BEEP_HZ, _BEEP_S, _GAP_S, _LEAD_S = 880.0, 0.2, 0.5, 0.5


@checks_arguments
def check_media_id(seed: int, speech: str, kind: str) -> str:
    """The opaque id of a check file: like a stimulus id (:func:`gesturekit.study.stimuli.stimulus_id`), keyed by the
    seed, of ``speech`` and a system name no stimulus can have."""
    return stimulus_id(seed, speech, f"\0check:{kind}")


@checks_arguments
def overlay_box(width: int, height: int) -> tuple[int, int, int, int]:
    """The band the overlay text is drawn in: ``(x0, y0, x1, y1)`` pixels, across the frame's middle."""
    return width // 20, int(height * 0.38), width - width // 20, int(height * 0.62)


@checks_arguments
def draw_overlay(frame: np.ndarray, text: str) -> np.ndarray:
    """``frame`` (H, W, 3) uint8 RGB with ``text`` in white on a dark band (:func:`overlay_box`), on one
    line or two, as large as fits."""
    from PIL import Image, ImageDraw, ImageFont

    h, w = frame.shape[:2]
    x0, y0, x1, y1 = overlay_box(w, h)
    # drawn on the band alone: a text too long for a tiny frame is cut, never drawn outside
    band = Image.new("RGB", (x1 - x0, y1 - y0), (24, 24, 24))
    draw = ImageDraw.Draw(band)
    words = text.split()
    half = max(1, len(words) // 2)
    layouts = [text, " ".join(words[:half]) + "\n" + " ".join(words[half:])] if len(words) > 1 else [text]
    best = None
    for size in range(max(8, (y1 - y0) // 2), 7, -1):
        try:
            font = ImageFont.load_default(size=size)
        except TypeError:  # Pillow before 10.1: one small bitmap font
            font = ImageFont.load_default()
        for layout in layouts:
            box = draw.multiline_textbbox((0, 0), layout, font=font, align="center")
            if box[2] - box[0] <= (x1 - x0) * 0.94 and box[3] - box[1] <= (y1 - y0) * 0.9:
                best = (layout, font, box)
                break
        if best is not None:
            break
    if best is None:  # nothing fits: the smallest, on two lines
        best = (layouts[-1], font, draw.multiline_textbbox((0, 0), layouts[-1], font=font, align="center"))
    layout, font, (left, top, right, bottom) = best
    at = ((x1 - x0 - (right - left)) / 2 - left, (y1 - y0 - (bottom - top)) / 2 - top)
    draw.multiline_text(at, layout, fill=(255, 255, 255), font=font, align="center")
    out = frame.copy()
    out[y0:y1, x0:x1] = np.asarray(band)
    return out


def _frames(path: Path) -> Generator[np.ndarray, None, None]:
    """The video's frames (H, W, 3) uint8, from the start again when they run out."""
    imageio_ffmpeg = require("imageio_ffmpeg", purpose="making check videos")
    while True:
        reader = imageio_ffmpeg.read_frames(f"file:{path}")
        try:
            w, h = next(reader)["size"]
            got = False
            for raw in reader:
                got = True
                yield np.frombuffer(raw, np.uint8).reshape(h, w, 3)
        finally:
            reader.close()  # ends its ffmpeg when we stop early
        if not got:
            raise GestureKitError("has no video frames", path=path)


def _write_check(
    out: Path, source: Path, host: Path, info: dict, *, text: str | None, tick: Callable[[], None]
) -> None:
    """``source``'s frames (with ``text`` drawn over them), as many as ``host`` has, under ``host``'s sound,
    encoded as every stimulus is; ``info``: ``host``'s :func:`probe_media`."""
    v, seconds = info["video"], info["audio"]["duration"]
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=".check-") as tmp:
        wav, encoded = Path(tmp) / "speech.wav", Path(tmp) / "check.mp4"
        subprocess.run(
            [ffmpeg_executable(), "-hide_banner", "-nostdin", "-loglevel", "error", "-i", f"file:{host}", "-vn", "-c:a"]
            + ["pcm_f32le", f"file:{wav}"],
            check=True,
            capture_output=True,
        )
        cmd = encode_command(encoded, v["width"], v["height"], v["fps"], wav, seconds)
        with open(Path(tmp) / "ffmpeg.log", "wb") as log:
            proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log)
            assert proc.stdin is not None
            frames = _frames(source)
            try:
                for _ in range(v["frames"]):
                    frame = next(frames)
                    if frame.shape[:2] != (v["height"], v["width"]):
                        raise GestureKitError(f"is not {v['width']}x{v['height']} as {host.name} is", path=source)
                    proc.stdin.write((frame if text is None else draw_overlay(frame, text)).tobytes())
                    tick()
            finally:
                frames.close()
                proc.stdin.close()
                code = proc.wait()
        if code != 0:
            message = (Path(tmp) / "ffmpeg.log").read_text(errors="replace").strip()
            raise GestureKitError(f"ffmpeg could not encode a check video: {message}", path=out)
        os.replace(encoded, out)


@checks_arguments
def make_check_videos(
    folder: str | os.PathLike,
    *,
    seed: int,
    stimuli: Mapping[str, tuple[str, str]],
    kinds: Sequence[str],
    pairwise: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> list[dict]:
    """Write an attention-check video of every kind for every speech into ``folder/checks/``.

    Parameters
    ----------
    folder : path
        The stimuli folder.
    seed : int
        The study's seed: which stimuli the checks are made from, and their ids.
    stimuli : mapping
        Stimulus id -> (speech, file relative to ``folder``).
    kinds : sequence of str
        ``"mismatched_audio"`` and/or ``"overlay"``.
    pairwise : bool
        The overlay asks to choose LEFT (checks on pairwise pages) instead of rating 1.
    progress : callable(done, total), optional
        Frames written, over all the videos.

    Returns
    -------
    list of dict
        ``{"id", "kind", "speech", "file"}`` per video, as design.json's ``checks``.
    """
    folder = Path(folder)
    by_speech: dict[str, list[str]] = {}
    for sid, (speech, _) in sorted(stimuli.items()):
        by_speech.setdefault(speech, []).append(sid)
    speeches = sorted(by_speech)
    rng = np.random.default_rng([int(seed), 0xC4EC])
    jobs = []
    for speech in speeches:
        for kind in kinds:
            host = by_speech[speech][int(rng.integers(len(by_speech[speech])))]
            source_id = host
            if kind == "mismatched_audio":
                others = [s for s in speeches if s != speech]
                if not others:
                    raise GestureKitError("a mismatched_audio check needs two speeches")
                other = others[int(rng.integers(len(others)))]
                source_id = by_speech[other][int(rng.integers(len(by_speech[other])))]
            cid = check_media_id(seed, speech, kind)
            jobs.append((cid, kind, speech, folder / stimuli[source_id][1], folder / stimuli[host][1]))
    infos = {j[4]: probe_media(j[4]) for j in jobs}
    total, done = sum(infos[j[4]]["video"]["frames"] for j in jobs), 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None and (done % 10 == 0 or done == total):
            progress(done, total)

    (folder / "checks").mkdir(exist_ok=True)
    out = []
    for cid, kind, speech, source_path, host_path in jobs:
        text = OVERLAY_TEXT["pairwise" if pairwise else "rating"] if kind == "overlay" else None
        _write_check(folder / "checks" / f"{cid}.mp4", source_path, host_path, infos[host_path], text=text, tick=tick)
        out.append({"id": cid, "kind": kind, "speech": speech, "file": f"checks/{cid}.mp4"})
    return out


def beep_samples(beeps: int) -> np.ndarray:
    """``beeps`` tones of 880 Hz, 0.2 s each, 0.5 s apart, after and before 0.5 s of silence:
    shape (samples,) float32 at :data:`BEEP_SR`."""
    n_beep, n_gap, n_lead = (round(s * BEEP_SR) for s in (_BEEP_S, _GAP_S, _LEAD_S))
    t = np.arange(n_beep) / BEEP_SR
    ramp = np.minimum(1.0, np.minimum(t, t[::-1]) / 0.01)  # 10 ms fades: no clicks to count
    tone = (0.5 * np.sin(2 * np.pi * _BEEP_HZ * t) * ramp).astype(np.float32)
    parts = [np.zeros(n_lead, np.float32)]
    for i in range(beeps):
        parts += [tone, np.zeros(n_gap if i < beeps - 1 else n_lead, np.float32)]
    return np.concatenate(parts)


@checks_arguments
def make_audio_check(folder: str | os.PathLike, *, seed: int) -> dict:
    """Write the audio check, ``folder/checks/<id>.wav``: 3 to 7 beeps (by the seed), 16-bit mono.

    Returns
    -------
    dict
        ``{"id", "file", "beeps"}`` as design.json's ``audio_check``.
    """
    folder = Path(folder)
    beeps = 3 + int(np.random.default_rng([int(seed), 0xBEE9]).integers(5))
    cid = check_media_id(seed, "", "audio")
    (folder / "checks").mkdir(exist_ok=True)
    write_wav(folder / "checks" / f"{cid}.wav", beep_samples(beeps), sr=BEEP_SR, overwrite=True)
    return {"id": cid, "file": f"checks/{cid}.wav", "beeps": beeps}
