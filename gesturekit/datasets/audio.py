"""Read any speech recording as mono float32 audio at 16 kHz.

:func:`load_audio` accepts whatever soundfile (libsndfile) can read: WAV with
8/16/24/32-bit integer or 32/64-bit float samples, FLAC, Ogg Vorbis/Opus, MP3
(libsndfile >= 1.1), AIFF and more, at any sample rate and channel count.
Only when soundfile cannot read the format at all does it fall back to
audioread, then to the ffmpeg binary shipped with ``imageio-ffmpeg`` (for
MP4/M4A, WebM, WMA, ...). Channels are averaged to mono and the result is
resampled with soxr's high-quality filter (:func:`resample`, equal to
``librosa.resample(res_type="soxr_hq")``).

Every problem a user can cause is an :class:`~gesturekit.errors.AudioFileError`
whose message names the file: missing, empty, not audio, truncated, damaged,
too short, or holding NaN/infinite samples. Silent audio is accepted with a
:class:`~gesturekit.errors.GestureKitWarning`.

What a file costs is estimated from its header before anything is decoded
(:mod:`gesturekit.limits`): a sample rate outside 4-384 kHz, speech longer than
60 minutes (a take longer than 4 hours) or more decoded samples than one input
may take are refused; a stream whose container states no length (only the
fallback decoders meet one) is decoded only up to the limit. Truncation is
detected from what the container states: the WAV/FLAC sample count, the MP3
Xing/VBRI byte count or ID3 length, an MP3 frame cut off at the end, and an
Ogg stream that ends without its end-of-stream page. An MP3 without such
headers cut exactly between two frames cannot be told from a shorter recording.
"""

from __future__ import annotations

import io
import os
import re
import struct
import subprocess
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal, TypedDict

import numpy as np
import numpy.typing as npt

from .. import limits
from .._arguments import checks_arguments
from .._io import Target, write_to
from .._optional import optional
from ..errors import AudioFileError, ConfigError, InputFileError, warn
from ..motion import AUDIO_SR
from ..outputs import MP4_TAG
from .audio_headers import Budget, check_file

if TYPE_CHECKING:
    from typing_extensions import Unpack  # typing.Unpack is Python 3.11+; only the type checker reads it

__all__ = [
    "AudioInfo",
    "LoadOptions",
    "load_audio",
    "load_audio_with_info",
    "resample",
    "SILENCE_PEAK",
    "WAV_ENCODINGS",
    "wav_bytes",
    "write_wav",
]

#: Peak amplitude (full scale = 1) at or below which audio counts as silent: -80 dBFS.
SILENCE_PEAK = 1e-4

_SF_ERR_MALFORMED_FILE = 3  # libsndfile: "Supported file format but file is malformed"


@dataclass(frozen=True)
class AudioInfo:
    """What the file held before conversion, for display.

    Parameters
    ----------
    path : str
        The file read.
    format : str
        Container, e.g. ``"WAV"``, ``"FLAC"``, ``"OGG"``, ``"MP3"``, ``"MP4"``.
    subtype : str or None
        Sample encoding as soundfile names it (``"PCM_16"``, ``"FLOAT"``,
        ``"VORBIS"``, ...); None when a fallback decoder read the file.
    sample_rate : int
        Sample rate of the file, Hz.
    channels : int
        Channels in the file (averaged to mono on loading).
    n_samples : int
        Samples per channel in the file.
    duration : float
        ``n_samples / sample_rate``, seconds.
    reader : str
        ``"soundfile"``, ``"audioread"`` or ``"ffmpeg"``.
    """

    path: str
    format: str
    subtype: str | None
    sample_rate: int
    channels: int
    n_samples: int
    duration: float
    reader: str

    def summary(self) -> str:
        """One line such as ``"WAV (PCM_16), 44100 Hz, 2 channels, 3.20 s"``."""
        kind = self.format if self.subtype is None else f"{self.format} ({self.subtype})"
        ch = "1 channel" if self.channels == 1 else f"{self.channels} channels"
        return f"{kind}, {self.sample_rate} Hz, {ch}, {self.duration:.2f} s"


# ---- writing ------------------------------------------------------------------------------------

#: Sample encodings :func:`wav_bytes` writes: 16-bit integer PCM (``round(32767 x)``) or 32-bit float.
WAV_ENCODINGS = ("pcm16", "float32")


@checks_arguments
def wav_bytes(
    samples: npt.ArrayLike, *, sr: int = AUDIO_SR, encoding: Literal["pcm16", "float32"] = "pcm16", mark: bool = False
) -> bytes:
    """Mono audio as a WAV file's bytes (the one WAV encoder of the package).

    Parameters
    ----------
    samples : array_like, shape (samples,)
        Float samples in [-1, 1]; beyond that range clipped, NaN written as 0.
    sr : int
        Sample rate, Hz (positive).
    encoding : {"pcm16", "float32"}
        ``"pcm16"``: 16-bit integer PCM, ``x`` stored as ``round(32767 x)`` (what players and
        downloads get); ``"float32"``: IEEE float, nothing requantised (what an encoder is fed).
    mark : bool
        Add a RIFF ``LIST/INFO`` ``ISFT`` entry naming gesturekit (:data:`gesturekit.outputs.MP4_TAG`),
        by which :func:`gesturekit.outputs.check_output` knows the file may be replaced.

    Returns
    -------
    bytes
        The whole file: ``RIFF``/``WAVE`` with ``fmt `` (and ``fact`` for float), the optional
        ``LIST`` and ``data`` chunks.

    Raises
    ------
    ConfigError
        An unknown encoding or a sample rate that is not a positive integer.
    """
    if encoding not in WAV_ENCODINGS:
        raise ConfigError(f"encoding must be one of {', '.join(WAV_ENCODINGS)}, got {encoding!r}")
    if isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or sr <= 0:
        raise ConfigError(f"the sample rate must be a positive integer, got {sr!r}")
    rate = int(sr)
    x = np.clip(np.nan_to_num(np.asarray(samples, dtype=np.float64).ravel()), -1.0, 1.0)
    if encoding == "pcm16":
        data = np.round(x * 32767.0).astype("<i2").tobytes()
        fmt = b"fmt " + struct.pack("<IHHIIHH", 16, 1, 1, rate, 2 * rate, 2, 16)
    else:
        data = x.astype("<f4").tobytes()
        # a non-PCM format carries cbSize and a fact chunk (the sample count)
        fmt = b"fmt " + struct.pack("<IHHIIHHH", 18, 3, 1, rate, 4 * rate, 4, 32, 0)
        fmt += b"fact" + struct.pack("<II", 4, x.size)
    chunks = [fmt]
    if mark:
        tag = MP4_TAG.encode("ascii")
        tag += b"\0" * (2 - len(tag) % 2)  # a zero-terminated string, of even length
        info = b"INFO" + b"ISFT" + struct.pack("<I", len(tag)) + tag
        chunks.append(b"LIST" + struct.pack("<I", len(info)) + info)
    chunks.append(b"data" + struct.pack("<I", len(data)) + data + b"\0" * (len(data) % 2))
    body = b"WAVE" + b"".join(chunks)
    return b"RIFF" + struct.pack("<I", len(body)) + body


@checks_arguments
def write_wav(
    target: Target,
    samples: npt.ArrayLike,
    *,
    sr: int = AUDIO_SR,
    encoding: Literal["pcm16", "float32"] = "pcm16",
    mark: bool = False,
    overwrite: bool = False,
) -> None:
    """Write :func:`wav_bytes` to a path (atomically) or into a binary file object.

    Parameters
    ----------
    target : str, os.PathLike or binary file object
        See :func:`gesturekit._io.write_to`.
    samples, sr, encoding, mark
        As for :func:`wav_bytes`.
    overwrite : bool
        For a path: replace an existing file.
    """
    data = wav_bytes(samples, sr=sr, encoding=encoding, mark=mark)
    write_to(target, lambda f: f.write(data), overwrite=overwrite)


class _Unreadable(Exception):
    """A decoder could not read the file; carries its reason for the final message."""


class LoadOptions(TypedDict, total=False):
    """The keywords of :func:`load_audio`, which passes them on to :func:`load_audio_with_info`
    (the one signature that names them, with their defaults).

    Attributes
    ----------
    sr : int
    min_duration : float
    max_duration : float or None
    take : bool
    """

    sr: int
    min_duration: float
    max_duration: float | None
    take: bool


@checks_arguments
def load_audio(path: str | os.PathLike, **options: Unpack[LoadOptions]) -> np.ndarray:
    """Read an audio file as mono float32 at ``sr`` Hz.

    Parameters
    ----------
    path : str or os.PathLike
        Any audio file soundfile can read (WAV, FLAC, OGG, MP3, ...); other
        containers (M4A, WebM, ...) when audioread or ffmpeg can decode them.
    sr : int
        Output sample rate, Hz (default 16000).
    min_duration : float
        Shortest accepted duration, seconds (default 1).
    max_duration : float, optional
        Longest accepted duration, seconds, checked from the header before
        decoding. Default: the limit for speech
        (:func:`gesturekit.limits.max_speech_seconds`, 60 minutes), or for a
        take with ``take=True`` (:func:`gesturekit.limits.max_take_seconds`).
    take : bool
        The audio of a database take rather than speech to synthesise for:
        only which default limit applies and what the message says (default False).

    Returns
    -------
    np.ndarray, shape (samples,), float32
        Channels averaged, resampled to ``sr``; nominally in [-1, 1].

    Raises
    ------
    AudioFileError
        The file is missing, empty, not audio, truncated, cannot be decoded,
        is shorter than ``min_duration`` or holds NaN/infinite samples.
    InputFileError
        The header states a sample rate, duration or size beyond the limits
        (:mod:`gesturekit.limits`).

    Warns
    -----
    GestureKitWarning
        The audio is silent (peak at or below :data:`SILENCE_PEAK`).
    """
    return load_audio_with_info(path, **options)[0]


@checks_arguments
def load_audio_with_info(
    path: str | os.PathLike,
    *,
    sr: int = AUDIO_SR,
    min_duration: float = 1.0,
    max_duration: float | None = None,
    take: bool = False,
) -> tuple[np.ndarray, AudioInfo]:
    """Like :func:`load_audio`, also returning what the file held.

    Parameters
    ----------
    path : str or os.PathLike
        The audio file.
    sr : int
        Output sample rate, Hz.
    min_duration : float
        Shortest accepted duration, seconds.
    max_duration : float, optional
        Longest accepted duration, seconds (see :func:`load_audio`).
    take : bool
        Apply the limit of a take instead of that of speech (see :func:`load_audio`).

    Returns
    -------
    audio : np.ndarray, shape (samples,), float32
        Mono audio at ``sr`` Hz.
    info : AudioInfo
        Format, sample rate, channels and duration of the file as stored.

    Raises
    ------
    AudioFileError, ConfigError
        As :func:`load_audio`; ConfigError for an invalid ``sr``, ``min_duration`` or ``max_duration``.
    """
    if isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or sr <= 0:
        raise ConfigError(f"sample rate must be a positive integer, got {sr!r}")
    if not np.isfinite(min_duration) or min_duration < 0:
        raise ConfigError(f"min_duration must be a finite number of seconds >= 0, got {min_duration!r}")
    if max_duration is not None and not (np.isfinite(max_duration) and max_duration > 0):
        raise ConfigError(f"max_duration must be a positive number of seconds, got {max_duration!r}")
    path = Path(path)
    budget = Budget(path, sr=int(sr), take=take, max_seconds=max_duration)
    label = check_file(path, budget)
    data, info = _decode(path, label, budget)

    if data.shape[0] == 0:
        raise AudioFileError("no audio samples could be read: the file holds none, or is damaged", path=path)
    finite = np.isfinite(data).all(axis=1)
    if not finite.all():
        first = int(np.argmin(finite))
        raise AudioFileError(
            f"the audio holds {int(np.count_nonzero(~finite))} invalid samples (NaN or infinity), "
            f"the first at {first / info.sample_rate:.3f} s",
            path=path,
        )
    if info.duration < min_duration:
        raise AudioFileError(
            f"the audio is {info.duration:.2f} s long, shorter than the minimum of {min_duration:.2f} s", path=path
        )

    mono = data[:, 0] if data.shape[1] == 1 else data.mean(axis=1, dtype=np.float32)
    del data
    if float(np.max(np.abs(mono))) <= SILENCE_PEAK:
        warn(f"{path}: the audio is silent (peak level at or below -80 dBFS)", stacklevel=2)
    if info.sample_rate != sr:
        mono = resample(mono, info.sample_rate, int(sr))
    return np.ascontiguousarray(mono, dtype=np.float32), info


@checks_arguments
def resample(x: np.ndarray, orig_sr: int, target_sr: int) -> np.ndarray:
    """Resample mono audio with soxr's high-quality filter.

    The result equals ``librosa.resample(x, orig_sr=..., target_sr=..., res_type="soxr_hq")``
    (tested): soxr's output cut or zero-padded to ``ceil(len(x) * target_sr / orig_sr)``
    samples, without importing librosa (seconds).

    Parameters
    ----------
    x : np.ndarray, shape (samples,), float32
    orig_sr, target_sr : int
        Sample rates, Hz.

    Returns
    -------
    np.ndarray, shape (ceil(samples * target_sr / orig_sr),), float32
    """
    import soxr  # a dependency of librosa

    x = np.asarray(x, dtype=np.float32)
    n = int(np.ceil(x.shape[0] * (float(target_sr) / orig_sr)))
    y = soxr.resample(x, orig_sr, target_sr, quality="soxr_hq")
    out = np.zeros(n, dtype=np.float32)
    out[: min(n, y.shape[0])] = y[:n]
    return out


def _decode(path: Path, label: str | None, budget: Budget) -> tuple[np.ndarray, AudioInfo]:
    """Samples of shape (frames, channels), float32, and the file's info.

    soundfile first; audioread and ffmpeg only when soundfile does not know the
    format or its encoding. A file soundfile recognises but finds malformed is
    reported as damaged instead: another decoder would return part of it silently.
    """
    import soundfile as sf

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            f = sf.SoundFile(os.fspath(path))
    except (sf.SoundFileError, RuntimeError, TypeError, ValueError) as e:
        if getattr(e, "code", None) == _SF_ERR_MALFORMED_FILE:
            raise AudioFileError(
                f"the {label or 'audio'} file is damaged or truncated ({_reason(e)})", path=path
            ) from None
        sf_reason = _reason(e)
    else:
        with f:
            fmt, subtype, rate, channels, declared = f.format, f.subtype, f.samplerate, f.channels, f.frames
            budget.check_header(fmt, rate, channels, declared)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    data = f.read(dtype="float32", always_2d=True)
            except (sf.SoundFileError, RuntimeError, ValueError) as e:
                raise AudioFileError(
                    f"the {fmt} data is damaged or truncated and cannot be decoded ({_reason(e)})", path=path
                ) from None
        if fmt not in ("MP3", "OGG") and 0 < data.shape[0] < declared:
            # WAV, FLAC, AIFF, ... headers state the sample count exactly; MP3 and Ogg
            # counts are estimated or read from the stream's end
            raise AudioFileError(
                f"the file is truncated: its header declares {declared} samples per channel "
                f"but only {data.shape[0]} could be read",
                path=path,
            )
        return data, _info(path, fmt, subtype, rate, channels, data.shape[0], "soundfile")

    if label is None:
        raise AudioFileError("is not an audio file: its content is not a recognised audio format", path=path)
    reasons = [f"soundfile: {sf_reason}"]
    for name, reader in (("audioread", _read_audioread), ("ffmpeg", _read_ffmpeg)):
        try:
            data, rate = reader(path, budget)
        except _Unreadable as e:
            reasons.append(f"{name}: {e}")
            continue
        return data, _info(path, label, None, rate, data.shape[1], data.shape[0], name)
    raise AudioFileError(f"looks like {label} audio but cannot be decoded ({'; '.join(reasons)})", path=path)


def _info(path: Path, fmt: str, subtype: str | None, rate: int, channels: int, n: int, reader: str) -> AudioInfo:
    """An :class:`AudioInfo` with the duration derived from ``n`` samples at ``rate`` Hz."""
    return AudioInfo(
        path=str(path),
        format=fmt,
        subtype=subtype,
        sample_rate=int(rate),
        channels=int(channels),
        n_samples=int(n),
        duration=n / rate if rate > 0 else 0.0,
        reader=reader,
    )


def _reason(e: BaseException) -> str:
    """The library's explanation without the path it repeats."""
    text = str(e).strip() or type(e).__name__
    for prefix in ("Error opening", "Error reading"):
        if text.startswith(prefix) and ": " in text:
            text = text.split(": ", 1)[1]
    if text.startswith("Error : "):
        text = text[len("Error : ") :]
    return text.rstrip(".")


def _read_audioread(path: Path, budget: Budget) -> tuple[np.ndarray, int]:
    """Decode with audioread (system ffmpeg, GStreamer, Core Audio or the stdlib), at most the duration limit."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # audioread imports deprecated stdlib modules
            import audioread

            with audioread.audio_open(os.fspath(path)) as f:
                rate, channels = int(f.samplerate), int(f.channels)
                stated = getattr(f, "duration", None)  # from the container, when it says
                if isinstance(stated, (int, float)) and stated > 0 and rate > 0:
                    budget.check_header("container", rate, channels, round(stated * rate))
                else:
                    limits.check_sample_rate(rate, what="the decoder", path=path)
                # audioread always yields 16-bit signed little-endian PCM; the duration is
                # known only once decoded, so decoding stops just past the limit
                cap = 2 * max(channels, 1) * int(rate * budget.seconds() + rate)
                bufs, n = [], 0
                for buf in f:
                    bufs.append(bytes(buf))
                    n += len(bufs[-1])
                    if n > cap:
                        break
                pcm = b"".join(bufs)
    except InputFileError:
        raise
    except Exception as e:  # noqa: BLE001 - any decoder failure means "cannot read"
        raise _Unreadable(_reason(e) if str(e) else "no decoder for this format") from None
    if n > cap:
        budget.check_duration(n / (2 * max(channels, 1) * rate), "decoding stopped past the limit, at")
    if channels < 1 or rate <= 0:
        raise _Unreadable("reported no channels or no sample rate")
    samples = np.frombuffer(pcm, dtype="<i2")
    samples = samples[: samples.size - samples.size % channels]
    return (samples.astype(np.float32) / 32768.0).reshape(-1, channels), rate


def _read_ffmpeg(path: Path, budget: Budget) -> tuple[np.ndarray, int]:
    """Decode the first audio stream with the ffmpeg binary of imageio-ffmpeg, at most the duration limit."""
    imageio_ffmpeg = optional("imageio_ffmpeg")
    if imageio_ffmpeg is None:
        raise _Unreadable("not installed")
    try:
        exe = imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError:
        raise _Unreadable("not installed") from None
    import soundfile as sf

    _probe_ffmpeg(exe, path, budget)
    cmd = [
        exe,
        "-nostdin",
        "-hide_banner",
        "-v",
        "error",
        "-protocol_whitelist",
        "file",  # never let a file make ffmpeg open URLs
        "-i",
        "file:" + os.path.abspath(path),
        "-map",
        "0:a:0",
        # the duration is known only once decoded: stop one second past the limit
        "-t",
        f"{budget.seconds() + 1.0:.3f}",
        "-f",
        "wav",
        "-c:a",
        "pcm_f32le",
        "-",
    ]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    if proc.returncode != 0 or len(proc.stdout) <= 44:
        lines = proc.stderr.decode("utf-8", "replace").strip().splitlines()
        raise _Unreadable(lines[-1] if lines else f"exit status {proc.returncode}")
    try:
        with sf.SoundFile(io.BytesIO(proc.stdout)) as f:
            rate = int(f.samplerate)
            data = f.read(dtype="float32", always_2d=True)
    except (sf.SoundFileError, RuntimeError) as e:
        raise _Unreadable(_reason(e)) from None
    limits.check_sample_rate(rate, what="the decoder", path=path)
    budget.check_duration(data.shape[0] / rate, "decoding stopped past the limit, at")
    return data, rate


_FFMPEG_DURATION = re.compile(r"Duration: (\d+):(\d\d):(\d\d(?:\.\d+)?)")
_FFMPEG_AUDIO = re.compile(r"Stream #0:\d+\S*: Audio: ([^,]+).*?, (\d+) Hz, (mono|stereo|(\d+) channels)?")


def _probe_ffmpeg(exe: str, path: Path, budget: Budget) -> None:
    """Check the duration, sample rate and channels the container states (ffmpeg's summary) before decoding.

    Nothing is decoded: ffmpeg is run without an output and prints what it read
    from the container's header. What it cannot state is left to the capped decode.
    """
    cmd = [exe, "-nostdin", "-hide_banner", "-protocol_whitelist", "file", "-i", "file:" + os.path.abspath(path)]
    try:
        proc = subprocess.run(cmd, capture_output=True, check=False, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return
    text = proc.stderr.decode("utf-8", "replace")
    duration, audio = _FFMPEG_DURATION.search(text), _FFMPEG_AUDIO.search(text)
    if duration is None or audio is None:
        return
    seconds = int(duration.group(1)) * 3600 + int(duration.group(2)) * 60 + float(duration.group(3))
    rate = int(audio.group(2))
    layout = audio.group(3)
    channels = 1 if layout in (None, "mono") else 2 if layout == "stereo" else int(audio.group(4))
    budget.check_header(f"{audio.group(1).split()[0].upper()} container", rate, channels, round(seconds * rate))
