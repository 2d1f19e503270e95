"""MP4 videos of the rendered character with the speech as soundtrack, and a reader of media facts.

:func:`render_video` renders a motion (or two side by side) offscreen with
:class:`gesturekit.viz.render.SkeletonScene` and pipes the frames to the ffmpeg
binary shipped with ``imageio-ffmpeg``: H.264 video (``yuv420p``, the only
layout every browser plays) and AAC audio at 48 kHz, with the index at the
front of the file (``+faststart``) so that a browser can start playing before
the download ends. With audio, the video lasts as long as the audio: a motion
that is too short holds its last pose, one that is too long is cut.

:func:`probe_media` reads codecs, sizes, rates and durations of any media file
with the same binary; tests and the app use it to check what was written.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterator, Sequence
from fractions import Fraction
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from .._arguments import checks_arguments
from .._io import atomic_write
from .._optional import require
from ..datasets.audio import write_wav
from ..errors import ConfigError, GestureKitError, InputFileError
from ..motion import AUDIO_SR, Motion
from ..outputs import MP4_TAG

if TYPE_CHECKING:
    from ..character.target import Character
    from ..viz.render import RenderStyle

__all__ = ["render_video", "probe_media", "AUDIO_OUT_SR", "ffmpeg_executable", "check_resolution", "encode_command"]

#: Sample rate of the soundtrack in written videos, Hz: the usual rate of video audio,
#: and short AAC frames, so the audio stream ends within a millisecond of the speech.
AUDIO_OUT_SR = 48000

# x264 quality (lower is better; 18 is visually lossless for flat-shaded scenes)
_CRF = 18
_AUDIO_BITRATE = "96k"


@checks_arguments
def ffmpeg_executable() -> str:
    """The path of the ffmpeg binary shipped with ``imageio-ffmpeg`` (an optional extra; a clear error without it)."""
    # imported here: the binary is looked up (and checked) only when a video is made or read
    return require("imageio_ffmpeg", purpose="writing or reading a video").get_ffmpeg_exe()


@checks_arguments
def render_video(
    path: str | os.PathLike,
    motion: Motion,
    *,
    audio: np.ndarray | None = None,
    sr: int = AUDIO_SR,
    resolution: tuple[int, int] = (640, 480),
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
    side_by_side: Motion | None = None,
    labels: Sequence[str] | None = None,
    style: RenderStyle | None = None,
    workers: int | None = None,
    character: Character | None = None,
) -> Path:
    """Render a motion to an MP4 file (H.264 + AAC) that plays in a browser.

    Frames are rendered at the motion's frame rate. With ``audio`` the video
    lasts exactly as many frames as fit the audio (rounded to the nearest
    frame): a shorter motion holds its last pose, a longer one is cut, and the
    audio stream lasts as long as ``audio``. The file appears complete under
    its name or not at all.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mp4`` file to write; its folder must exist.
    motion : Motion
        The motion to show, positions (frames, 55, 3) in metres. Only the joints its
        :attr:`~gesturekit.motion.Motion.presence` says exist are drawn and framed;
        derived ones in grey (:attr:`~gesturekit.viz.appearance.Appearance.derived_color`). The picture is
        the page's (:class:`gesturekit.viz.render.RenderStyle`'s default look): the same character,
        shading, colours, camera and background.
    audio : np.ndarray, shape (samples,), float, optional
        Mono speech in [-1, 1] starting with the motion's first frame. Without
        it the video is silent and lasts as long as the motion.
    sr : int
        Sample rate of ``audio``, Hz.
    resolution : (int, int)
        Width and height of the video, pixels; both even (H.264 in ``yuv420p``
        needs it).
    overwrite : bool
        Replace ``path`` if it exists.
    progress : callable, optional
        ``progress(done, total)`` after each frame handed to the encoder, in order;
        the last call has ``done == total``.
    side_by_side : Motion, optional
        A second motion at the same fps shown to the right of ``motion``
        (for example the k-NN result next to the refined one).
    labels : sequence of str, optional
        One label per motion shown, drawn above it.
    style : gesturekit.viz.render.RenderStyle, optional
        Look of the scene; the house style by default.
    workers : int, optional
        Rendering processes; 1 renders in this process. By default one per
        core for clips of at least
        :data:`gesturekit.viz.render_pool.PARALLEL_MIN_FRAMES` frames. The file is
        the same, byte for byte, whatever the number.
    character : Character, optional
        A user's character (:func:`gesturekit.character.user.read_character`) shown instead of ours: every
        motion retargeted onto it (:func:`gesturekit.character.retarget.retarget`), its own skin posed by
        linear blend skinning in its own colours, shaded and lit as ours, framed on its bones that follow
        the motion (:class:`gesturekit.viz.character_render.CharacterStage`); a skeleton without a body (BVH)
        as tubes around its bones. The character look only.

    Returns
    -------
    pathlib.Path
        ``path``, the MP4 file written.

    Raises
    ------
    ConfigError
        ``path`` exists and ``overwrite`` is False, or its folder is missing;
        a bad resolution, audio array, sample rate, label list or motion.
    GestureKitError
        ffmpeg failed (its message is included).
    """
    path = Path(path)
    if path.is_dir():
        raise ConfigError("is a folder, not a file name", path=path)
    if not path.parent.is_dir():
        raise ConfigError(f"cannot write: folder {str(path.parent)!r} does not exist", path=path)
    # checked before rendering, so a long render does not end in this error
    from ..outputs import check_output

    check_output(path, "file", overwrite=overwrite)  # only an MP4 gesturekit wrote is replaced
    for m in [motion] + ([] if side_by_side is None else [side_by_side]):
        bad = ~np.isfinite(np.asarray(m.positions)).all(axis=(1, 2))
        if bad.any():
            raise ConfigError(
                f"not written: the motion holds NaN or infinite positions (from frame {int(np.argmax(bad))} on)",
                path=path,
            )
    width, height = check_resolution(resolution)
    if audio is not None:
        audio = _check_audio(audio, sr)
    motions = [motion] if side_by_side is None else [motion, side_by_side]

    require("pyvista", purpose="rendering a video")  # the rendering libraries load only when rendering
    from ..viz.render_pool import render_frames

    # checks the motions, labels and workers before anything starts
    frames = render_frames(
        motions, labels=labels, resolution=(width, height), style=style, workers=workers, character=character
    )
    with contextlib.closing(frames), tempfile.TemporaryDirectory(prefix="gesturekit-video-") as tmp:
        encoded = Path(tmp) / "video.mp4"
        fps = float(motions[0].fps)
        rendered = max(m.n_frames for m in motions)
        wav, seconds, n_frames = None, None, rendered
        if audio is not None:
            seconds = len(audio) / sr
            # the whole frames nearest to the audio's duration; at least one
            n_frames = max(1, int(math.floor(seconds * fps + 0.5)))
            wav = Path(tmp) / "audio.wav"
            # float samples: nothing is requantised before the AAC encoder
            write_wav(wav, audio, sr=int(sr), encoding="float32", overwrite=True)
        cmd = encode_command(encoded, width, height, fps, wav, seconds)
        _encode(cmd, frames, rendered, n_frames, progress, Path(tmp) / "ffmpeg.log", path)

        def copy(f: IO[bytes]) -> None:
            with open(encoded, "rb") as src:
                shutil.copyfileobj(src, f, length=1 << 20)

        return atomic_write(path, copy, overwrite=overwrite)


@checks_arguments
def check_resolution(resolution: Any) -> tuple[int, int]:
    """``(width, height)`` of a video in whole, even pixels, or a ConfigError saying what is wrong."""
    try:
        width, height = (int(v) for v in resolution)
        whole = len(resolution) == 2 and width == resolution[0] and height == resolution[1]
    except (TypeError, ValueError):
        whole = False
    if not whole:
        raise ConfigError(f"resolution must be (width, height) in whole pixels, got {resolution!r}")
    if width % 2 or height % 2 or not (16 <= width <= 7680 and 16 <= height <= 4320):
        raise ConfigError(
            f"video width and height must be even and within 16..7680 x 16..4320 pixels, got {width}x{height}"
        )
    return width, height


def _check_audio(audio: Any, sr: Any) -> np.ndarray:
    if isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or not 1000 <= sr <= 384000:
        raise ConfigError(f"sr must be a whole number of Hz within 1000..384000, got {sr!r}")
    audio = np.asarray(audio)
    if audio.ndim != 1 or not np.issubdtype(audio.dtype, np.floating):
        raise ConfigError(f"audio must be mono float samples, shape (samples,), got {audio.dtype} {audio.shape}")
    if audio.size == 0:
        raise ConfigError("audio is empty")
    if not np.all(np.isfinite(audio)):
        raise ConfigError("audio holds NaN or infinite samples")
    return audio.astype(np.float32, copy=False)


@checks_arguments
def encode_command(
    out: Path, width: int, height: int, fps: float, wav: Path | None, seconds: float | None
) -> list[str]:
    """The ffmpeg command that encodes raw RGB frames from stdin (and the WAV, if any) into ``out`` (H.264/AAC)."""
    rate = Fraction(fps).limit_denominator(1001)
    cmd = [
        ffmpeg_executable(),
        "-hide_banner",
        "-nostdin",
        "-loglevel",
        "error",
        "-y",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-s",
        f"{width}x{height}",
        "-framerate",
        f"{rate.numerator}/{rate.denominator}",
        "-i",
        "pipe:0",
    ]
    if wav is not None:
        cmd += ["-i", f"file:{wav}", "-map", "0:v:0", "-map", "1:a:0"]
    cmd += [
        # "veryfast": half the encoder's time of "medium" for a file about 3 % larger at the same quality
        "-c:v",
        "libx264",
        "-preset",
        "veryfast",
        "-crf",
        str(_CRF),
        "-pix_fmt",
        "yuv420p",
        # a key frame every two seconds, so a player can seek
        "-g",
        str(max(1, round(2 * fps))),
    ]
    if wav is not None:
        cmd += ["-c:a", "aac", "-b:a", _AUDIO_BITRATE, "-ar", str(AUDIO_OUT_SR), "-ac", "1", "-t", f"{seconds:.6f}"]
    cmd += [
        "-movflags",
        "+faststart",
        # no encoder versions or dates in the file: the same inputs give the same bytes
        "-map_metadata",
        "-1",
        "-fflags",
        "+bitexact",
        "-flags:v",
        "+bitexact",
        "-flags:a",
        "+bitexact",
        # the tag by which a later --force recognises the file as gesturekit's own
        "-metadata",
        f"comment={MP4_TAG}",
        "-f",
        "mp4",
        f"file:{out}",
    ]
    return cmd


def _encode(
    cmd: list[str],
    frames: Iterator[np.ndarray],
    rendered: int,
    n_frames: int,
    progress: Callable[[int, int], None] | None,
    log_path: Path,
    target: Path,
) -> None:
    """Write ``n_frames`` pictures into ffmpeg's standard input: the ``rendered`` ones of
    ``frames`` (at least one), then the last of them again."""
    with open(log_path, "w+b") as log:
        proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log)
        stdin = proc.stdin
        assert stdin is not None  # stdin=PIPE
        try:
            image = next(frames)
            for i in range(n_frames):
                # past the end of the motion the picture no longer changes
                if 0 < i < rendered:
                    image = next(frames)
                try:
                    stdin.write(image.data)
                except (BrokenPipeError, OSError):
                    break  # ffmpeg stopped; its log says why
                if progress is not None:
                    progress(i + 1, n_frames)
            try:
                stdin.close()
            except (BrokenPipeError, OSError):
                pass
            code = proc.wait()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if code != 0:
            log.seek(0)
            message = log.read().decode("utf-8", "replace").strip()[-2000:]
            raise GestureKitError(f"ffmpeg could not encode the video (exit code {code}): {message}", path=target)


# -- reading -------------------------------------------------------------------------------------

_STREAM_RE = re.compile(r"^\s*Stream #\d+:(\d+)\S*: (Video|Audio): (.*)$", re.MULTILINE)
_DURATION_RE = re.compile(r"Duration: (\d+):(\d+):(\d+(?:\.\d+)?)")
_LAYOUT_CHANNELS = {
    "mono": 1,
    "stereo": 2,
    "2.1": 3,
    "3.0": 3,
    "quad": 4,
    "4.0": 4,
    "5.0": 5,
    "5.1": 6,
    "6.1": 7,
    "7.1": 8,
}


@checks_arguments
def probe_media(path: str | os.PathLike, *, decode: bool = True) -> dict:
    """Codecs, sizes, rates and durations of a media file, read with the ffmpeg binary.

    Parameters
    ----------
    path : str or os.PathLike
        Any file ffmpeg reads (mp4, wav, ...).
    decode : bool
        Also decode the first video and audio streams to measure their exact
        durations (frames and samples actually played); without it those
        entries are None.

    Returns
    -------
    dict
        ``duration``: the container's duration, seconds (None if unknown);
        ``video``: None, or a dict of ``codec`` (e.g. ``"h264"``),
        ``pix_fmt``, ``width``, ``height`` (pixels), ``fps``, ``frames`` and
        ``duration`` (seconds) of the first video stream;
        ``audio``: None, or a dict of ``codec`` (e.g. ``"aac"``),
        ``sample_rate`` (Hz), ``channels``, ``samples`` and ``duration``
        (seconds) of the first audio stream.

    Raises
    ------
    InputFileError
        The file does not exist or ffmpeg cannot read it.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError("does not exist or is not a file", path=path)
    source = f"file:{path.resolve()}"
    header = subprocess.run(
        [ffmpeg_executable(), "-hide_banner", "-nostdin", "-i", source], stdin=subprocess.DEVNULL, capture_output=True
    ).stderr.decode("utf-8", "replace")
    info = _parse_header(header)
    if info["video"] is None and info["audio"] is None:
        last = header.strip().splitlines()[-1] if header.strip() else "no output"
        raise InputFileError(f"not a media file ffmpeg can read ({last})", path=path)
    if decode:
        _measure(source, info, path)
    return info


def _split_top_level(text: str) -> list[str]:
    """Split ffmpeg's stream description at commas outside parentheses and brackets."""
    parts: list[str] = []
    current: list[str] = []
    depth = 0
    for ch in text:
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        if ch == "," and depth == 0:
            parts.append("".join(current).strip())
            current = []
        else:
            current.append(ch)
    parts.append("".join(current).strip())
    return parts


def _parse_header(text: str) -> dict:
    info: dict = {"duration": None, "video": None, "audio": None}
    m = _DURATION_RE.search(text)
    if m:
        info["duration"] = int(m[1]) * 3600 + int(m[2]) * 60 + float(m[3])
    for m in _STREAM_RE.finditer(text):
        kind, parts = m[2].lower(), _split_top_level(m[3])
        if info[kind] is not None:
            continue  # the first stream of each kind
        codec = parts[0].split()[0] if parts[0] else None
        if kind == "video":
            size = next((re.match(r"(\d+)x(\d+)", p) for p in parts if re.match(r"\d+x\d+", p)), None)
            fps = next((re.fullmatch(r"([\d.]+)(k?) fps", p) for p in parts if p.endswith(" fps")), None)
            info["video"] = {
                "codec": codec,
                "pix_fmt": parts[1].split("(")[0] if len(parts) > 1 else None,
                "width": int(size[1]) if size else None,
                "height": int(size[2]) if size else None,
                "fps": float(fps[1]) * (1000 if fps[2] else 1) if fps else None,
                "frames": None,
                "duration": None,
            }
        else:
            rate = next((re.fullmatch(r"(\d+) Hz", p) for p in parts if p.endswith(" Hz")), None)
            layout = parts[2] if len(parts) > 2 else ""
            channels = _LAYOUT_CHANNELS.get(layout.split("(")[0])
            if channels is None and re.match(r"\d+ channels", layout):
                channels = int(layout.split()[0])
            info["audio"] = {
                "codec": codec,
                "sample_rate": int(rate[1]) if rate else None,
                "channels": channels,
                "samples": None,
                "duration": None,
            }
    return info


def _measure(source: str, info: dict, path: Path) -> None:
    """Decode the first video and audio streams and fill in frames, samples and durations."""
    maps = []
    if info["video"] is not None:
        maps += ["-map", "0:v:0"]
    if info["audio"] is not None:
        maps += ["-map", "0:a:0"]
    # framecrc lists every decoded frame with its time stamp and duration; no pixels are kept
    run = subprocess.run(
        [
            ffmpeg_executable(),
            "-hide_banner",
            "-nostdin",
            "-loglevel",
            "error",
            "-i",
            source,
            *maps,
            "-f",
            "framecrc",
            "-",
        ],
        stdin=subprocess.DEVNULL,
        capture_output=True,
    )
    if run.returncode != 0:
        message = run.stderr.decode("utf-8", "replace").strip()[-500:]
        raise InputFileError(f"ffmpeg could not decode it: {message}", path=path)
    time_base: dict[int, Fraction] = {}
    kinds: dict[int, str] = {}
    first: dict[int, int] = {}
    end: dict[int, int] = {}
    count: dict[int, int] = {}
    for line in run.stdout.decode("ascii", "replace").splitlines():
        if line.startswith("#tb "):
            stream, value = line[4:].split(":")
            time_base[int(stream)] = Fraction(value.strip())
        elif line.startswith("#media_type "):
            stream, value = line[12:].split(":")
            kinds[int(stream)] = value.strip()
        elif line and not line.startswith("#"):
            fields = [f.strip() for f in line.split(",")]
            index, pts, duration = int(fields[0]), int(fields[2]), int(fields[3])
            first.setdefault(index, pts)
            end[index] = max(end.get(index, pts + duration), pts + duration)
            count[index] = count.get(index, 0) + 1
    for index, kind in kinds.items():
        if kind not in ("video", "audio") or index not in count:
            continue
        seconds = float((end[index] - first[index]) * time_base[index])
        if kind == "video":
            info["video"]["frames"] = count[index]
            info["video"]["duration"] = seconds
        else:
            info["audio"]["duration"] = seconds
            sr = info["audio"]["sample_rate"]
            info["audio"]["samples"] = int(round(seconds * sr)) if sr else None
