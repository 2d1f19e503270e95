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
"""
from __future__ import annotations

import io
import os
import struct
import subprocess
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import AudioFileError, ConfigError, warn
from ..motion import AUDIO_SR

__all__ = ["AudioInfo", "load_audio", "load_audio_with_info", "resample", "SILENCE_PEAK"]

#: Peak amplitude (full scale = 1) at or below which audio counts as silent: -80 dBFS.
SILENCE_PEAK = 1e-4

_SF_ERR_MALFORMED_FILE = 3  # libsndfile: "Supported file format but file is malformed"

# First bytes of the audio containers we know; anything else that soundfile
# cannot open is reported as "not an audio file" rather than handed to a
# decoder that might turn arbitrary bytes into noise.
_SIGNATURES: tuple[tuple[int, bytes, str], ...] = (
    (0, b"RIFF", "WAV"),
    (0, b"RIFX", "WAV"),
    (0, b"RF64", "WAV"),
    (0, b"fLaC", "FLAC"),
    (0, b"OggS", "OGG"),
    (0, b"ID3", "MP3"),
    (0, b"FORM", "AIFF"),
    (0, b".snd", "AU"),
    (0, b"caff", "CAF"),
    (0, b"ADIF", "AAC"),
    (0, b"#!AMR", "AMR"),
    (0, b"\x1a\x45\xdf\xa3", "WEBM/MKV"),
    (0, b"\x30\x26\xb2\x75\x8e\x66\xcf\x11", "WMA"),
    (0, b"\x0b\x77", "AC3"),
    (4, b"ftyp", "MP4"),
)


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


class _Unreadable(Exception):
    """A decoder could not read the file; carries its reason for the final message."""


def load_audio(path: str | os.PathLike, *, sr: int = AUDIO_SR, min_duration: float = 1.0) -> np.ndarray:
    """Read an audio file as mono float32 at ``sr`` Hz.

    Parameters
    ----------
    path : str or os.PathLike
        Any audio file soundfile can read (WAV, FLAC, OGG, MP3, ...); other
        containers (M4A, WebM, ...) when audioread or ffmpeg can decode them.
    sr : int
        Output sample rate, Hz.
    min_duration : float
        Shortest accepted duration, seconds.

    Returns
    -------
    np.ndarray, shape (samples,), float32
        Channels averaged, resampled to ``sr``; nominally in [-1, 1].

    Raises
    ------
    AudioFileError
        The file is missing, empty, not audio, truncated, cannot be decoded,
        is shorter than ``min_duration`` or holds NaN/infinite samples.

    Warns
    -----
    GestureKitWarning
        The audio is silent (peak at or below :data:`SILENCE_PEAK`).
    """
    return load_audio_with_info(path, sr=sr, min_duration=min_duration)[0]


def load_audio_with_info(
    path: str | os.PathLike, *, sr: int = AUDIO_SR, min_duration: float = 1.0
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

    Returns
    -------
    audio : np.ndarray, shape (samples,), float32
        Mono audio at ``sr`` Hz.
    info : AudioInfo
        Format, sample rate, channels and duration of the file as stored.

    Raises
    ------
    AudioFileError, ConfigError
        As :func:`load_audio`; ConfigError for an invalid ``sr`` or ``min_duration``.
    """
    if isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or sr <= 0:
        raise ConfigError(f"sample rate must be a positive integer, got {sr!r}")
    if not np.isfinite(min_duration) or min_duration < 0:
        raise ConfigError(f"min_duration must be a finite number of seconds >= 0, got {min_duration!r}")
    path = Path(path)
    label = _check_file(path)
    data, info = _decode(path, label)

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
            f"the audio is {info.duration:.2f} s long, shorter than the minimum of {min_duration:.2f} s",
            path=path,
        )

    mono = data[:, 0] if data.shape[1] == 1 else data.mean(axis=1, dtype=np.float32)
    del data
    if float(np.max(np.abs(mono))) <= SILENCE_PEAK:
        warn(f"{path}: the audio is silent (peak level at or below -80 dBFS)", stacklevel=2)
    if info.sample_rate != sr:
        mono = resample(mono, info.sample_rate, int(sr))
    return np.ascontiguousarray(mono, dtype=np.float32), info


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


def _check_file(path: Path) -> str | None:
    """Fail early on a missing, empty or truncated file; return the sniffed container name."""
    if not path.exists():
        raise AudioFileError("file not found", path=path)
    if path.is_dir():
        raise AudioFileError("is a folder, not an audio file", path=path)
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError as e:
        raise AudioFileError(f"cannot be opened ({e.strerror or e})", path=path) from None
    if size == 0:
        raise AudioFileError("the file is empty (0 bytes)", path=path)
    label = _sniff(head)
    if label == "WAV":
        problem = _wav_truncation(path, size)
    elif label == "MP3":
        problem = _mp3_truncation(path, size)
    else:
        problem = None
    if problem is not None:
        raise AudioFileError(problem, path=path)
    return label


def _sniff(head: bytes) -> str | None:
    """Container name from the first bytes of a file, or None if unknown."""
    for offset, magic, label in _SIGNATURES:
        if head[offset : offset + len(magic)] == magic:
            if label == "WAV" and len(head) >= 12 and head[8:12] != b"WAVE":
                return "RIFF"  # another RIFF kind (AVI, ...); shorter heads are cut-short WAVs
            return label
    if len(head) >= 2 and head[0] == 0xFF and head[1] & 0xE0 == 0xE0:
        # MPEG audio frame sync; layer bits 00 (with version bits) mark AAC in ADTS
        return "AAC" if head[1] & 0x06 == 0 else "MP3"
    return None


def _wav_truncation(path: Path, size: int) -> str | None:
    """Describe how a RIFF/RF64 WAVE file is cut short, or None if its data chunk is whole.

    libsndfile reads a truncated WAV without complaint, returning fewer
    samples than the header declares, so the header is checked here.
    """
    unknown = 0xFFFFFFFF  # size written by streaming writers that could not seek back
    with open(path, "rb") as f:
        head = f.read(12)
        if len(head) < 12:
            return f"the file is truncated: it holds only {size} bytes, less than a WAV header"
        if head[8:12] != b"WAVE":
            return None  # a RIFF file of another kind; soundfile decides
        endian = ">" if head[:4] == b"RIFX" else "<"
        rf64_data = None
        pos = 12
        while True:
            f.seek(pos)
            chunk = f.read(8)
            if len(chunk) < 8:
                return f"the file is truncated: it ends after {size} bytes, before the WAV data chunk"
            cid = chunk[:4]
            (csize,) = struct.unpack(endian + "I", chunk[4:])
            if cid == b"ds64" and head[:4] == b"RF64":
                ds64 = f.read(16)
                if len(ds64) == 16:
                    rf64_data = struct.unpack("<Q", ds64[8:16])[0]
            if cid == b"data":
                if csize == unknown and rf64_data is not None:
                    csize = rf64_data
                if csize == unknown:
                    return None
                available = size - (pos + 8)
                if csize > available:
                    return (
                        f"the file is truncated: its WAV header declares {csize} bytes of audio data "
                        f"but only {available} bytes follow"
                    )
                return None
            pos += 8 + csize + (csize & 1)  # chunks are padded to even length


def _mp3_truncation(path: Path, size: int) -> str | None:
    """Describe how an MP3 file with a Xing/Info header is cut short, or None.

    The Xing/Info tag (written by LAME and libsndfile) in the first frame
    states the stream's length in bytes; files without it cannot be checked.
    """
    with open(path, "rb") as f:
        head = f.read(10)
        start = 0
        if head[:3] == b"ID3" and len(head) == 10:
            # ID3v2 tag: its size is stored 7 bits per byte; a footer adds 10 bytes
            start = 10 + sum((b & 0x7F) << (7 * (3 - i)) for i, b in enumerate(head[6:10]))
            start += 10 if head[5] & 0x10 else 0
        f.seek(start)
        frame = f.read(64)
    if len(frame) < 4 or frame[0] != 0xFF or frame[1] & 0xE0 != 0xE0 or (frame[1] >> 1) & 3 != 1:
        return None  # not a Layer III frame
    mpeg1 = (frame[1] >> 3) & 3 == 3
    mono = (frame[3] >> 6) & 3 == 3
    pos = 4 + (2 if not frame[1] & 1 else 0) + ((17 if mono else 32) if mpeg1 else (9 if mono else 17))
    if frame[pos : pos + 4] not in (b"Xing", b"Info"):
        return None
    flags = int.from_bytes(frame[pos + 4 : pos + 8], "big")
    field_at = pos + 8 + (4 if flags & 1 else 0)
    if not flags & 2 or len(frame) < field_at + 4:
        return None
    declared = int.from_bytes(frame[field_at : field_at + 4], "big")
    available = size - start
    if declared - available > 0.01 * declared:  # decoders accept 1 % slack in this field
        return (
            f"the file is truncated: its MP3 header declares {declared} bytes of audio "
            f"but only {available} bytes follow"
        )
    return None


def _decode(path: Path, label: str | None) -> tuple[np.ndarray, AudioInfo]:
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
            data, rate = reader(path)
        except _Unreadable as e:
            reasons.append(f"{name}: {e}")
            continue
        return data, _info(path, label, None, rate, data.shape[1], data.shape[0], name)
    raise AudioFileError(f"looks like {label} audio but cannot be decoded ({'; '.join(reasons)})", path=path)


def _info(path: Path, fmt: str, subtype: str | None, rate: int, channels: int, n: int, reader: str) -> AudioInfo:
    """An :class:`AudioInfo` with the duration derived from ``n`` samples at ``rate`` Hz."""
    return AudioInfo(
        path=str(path), format=fmt, subtype=subtype, sample_rate=int(rate), channels=int(channels),
        n_samples=int(n), duration=n / rate if rate > 0 else 0.0, reader=reader,
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


def _read_audioread(path: Path) -> tuple[np.ndarray, int]:
    """Decode with audioread (system ffmpeg, GStreamer, Core Audio or the stdlib)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # audioread imports deprecated stdlib modules
            import audioread

            with audioread.audio_open(os.fspath(path)) as f:
                rate, channels = int(f.samplerate), int(f.channels)
                # audioread always yields 16-bit signed little-endian PCM
                pcm = b"".join(bytes(buf) for buf in f)
    except Exception as e:  # noqa: BLE001 - any decoder failure means "cannot read"
        raise _Unreadable(_reason(e) if str(e) else "no decoder for this format") from None
    if channels < 1 or rate <= 0:
        raise _Unreadable("reported no channels or no sample rate")
    samples = np.frombuffer(pcm, dtype="<i2")
    samples = samples[: samples.size - samples.size % channels]
    return (samples.astype(np.float32) / 32768.0).reshape(-1, channels), rate


def _read_ffmpeg(path: Path) -> tuple[np.ndarray, int]:
    """Decode the first audio stream with the ffmpeg binary of imageio-ffmpeg, if installed."""
    try:
        import imageio_ffmpeg

        exe = imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        raise _Unreadable("not installed") from None
    import soundfile as sf

    cmd = [
        exe, "-nostdin", "-hide_banner", "-v", "error",
        "-protocol_whitelist", "file",  # never let a file make ffmpeg open URLs
        "-i", "file:" + os.path.abspath(path),
        "-map", "0:a:0", "-f", "wav", "-c:a", "pcm_f32le", "-",
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
    return data, rate
