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

import functools
import io
import os
import re
import struct
import subprocess
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import limits
from ..errors import AudioFileError, ConfigError, InputFileError, warn
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


@dataclass(frozen=True)
class _Budget:
    """What one file may cost: the duration limit that applies to it and the memory limit."""

    path: Path
    sr: int
    take: bool
    max_seconds: float | None

    def seconds(self) -> float:
        """The duration limit, seconds."""
        if self.max_seconds is not None:
            return float(self.max_seconds)
        return limits.max_take_seconds() if self.take else limits.max_speech_seconds()

    def check_duration(self, seconds: float, what: str) -> None:
        limits.check_duration(seconds, what=what, path=self.path, speech=not self.take,
                              max_seconds=self.max_seconds)

    def check_header(self, fmt: str, rate: int, channels: int, frames: int) -> None:
        """Refuse before decoding what the header says: rate, duration, decoded bytes.

        Parameters
        ----------
        fmt : str
            Container, for the message.
        rate : int
            Sample rate, Hz.
        channels : int
        frames : int
            Samples per channel.
        """
        limits.check_sample_rate(rate, what=f"the {fmt} header", path=self.path)
        seconds = frames / rate
        self.check_duration(seconds, f"the {fmt} header says {frames} samples at {rate} Hz")
        # float32 samples of every channel, plus the mono float32 copy at the output rate
        decoded = 4.0 * frames * max(channels, 1) + 4.0 * seconds * self.sr
        limits.check_bytes(decoded, what=f"the {fmt} header says {frames} samples of {channels} channels",
                           path=self.path)


def load_audio(
    path: str | os.PathLike,
    *,
    sr: int = AUDIO_SR,
    min_duration: float = 1.0,
    max_duration: float | None = None,
    take: bool = False,
) -> np.ndarray:
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
    max_duration : float, optional
        Longest accepted duration, seconds, checked from the header before
        decoding. Default: the limit for speech
        (:func:`gesturekit.limits.max_speech_seconds`, 60 minutes), or for a
        take with ``take=True`` (:func:`gesturekit.limits.max_take_seconds`).
    take : bool
        The audio of a database take rather than speech to synthesise for:
        only which default limit applies and what the message says.

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
    return load_audio_with_info(path, sr=sr, min_duration=min_duration, max_duration=max_duration, take=take)[0]


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
    budget = _Budget(path, sr=int(sr), take=take, max_seconds=max_duration)
    label = _check_file(path, budget)
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


def _check_file(path: Path, budget: _Budget) -> str | None:
    """Fail early on a missing, empty, truncated or too long file; return the sniffed container name."""
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
        problem = _mp3_truncation(path, size, budget)
    elif label == "OGG":
        problem = _ogg_truncation(path, size)
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


# MPEG audio Layer III: bitrates (kbit/s) by index, for MPEG-1 and for MPEG-2/2.5
_MP3_BITRATES = {
    True: (0, 32, 40, 48, 56, 64, 80, 96, 112, 128, 160, 192, 224, 256, 320),
    False: (0, 8, 16, 24, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160),
}
# sample rates (Hz) by version bits (0: MPEG-2.5, 2: MPEG-2, 3: MPEG-1) and index
_MP3_RATES = {0: (11025, 12000, 8000), 2: (22050, 24000, 16000), 3: (44100, 48000, 32000)}
# the most bytes per second a Layer III stream can hold (MPEG-1 at 320 kbit/s)
_MP3_MAX_BYTES_PER_S = 320_000 / 8


def _mp3_frame(head: bytes) -> tuple[int, int, int, tuple[int, int]] | None:
    """(frame length in bytes, samples, sample rate, stream kind) of a Layer III frame header, or None."""
    if len(head) < 4 or head[0] != 0xFF or head[1] & 0xE0 != 0xE0:
        return None
    version, layer = (head[1] >> 3) & 3, (head[1] >> 1) & 3
    rate_idx, bitrate_idx = (head[2] >> 2) & 3, head[2] >> 4
    if version == 1 or layer != 1 or rate_idx == 3 or bitrate_idx in (0, 15):
        return None  # reserved, not Layer III, or free format (length unknown)
    mpeg1 = version == 3
    rate = _MP3_RATES[version][rate_idx]
    bitrate = _MP3_BITRATES[mpeg1][bitrate_idx] * 1000
    padding = (head[2] >> 1) & 1
    length = (144 if mpeg1 else 72) * bitrate // rate + padding
    return length, 1152 if mpeg1 else 576, rate, (version, rate_idx)


def _id3v2_length_ms(tag: bytes) -> float | None:
    """The TLEN frame (length in milliseconds) of an ID3v2.3/2.4 tag's body, or None."""
    major = tag[3]
    pos, end = 10, len(tag)
    while pos + 10 <= end and major in (3, 4):
        fid = tag[pos : pos + 4]
        raw = tag[pos + 4 : pos + 8]
        size = (sum((b & 0x7F) << (7 * (3 - i)) for i, b in enumerate(raw)) if major == 4
                else int.from_bytes(raw, "big"))
        if not fid.strip(b"\x00") or size <= 0:
            return None
        if fid == b"TLEN":
            body = tag[pos + 10 : pos + 10 + size]
            text = body[1:].decode("latin-1", "replace").strip("\x00 ")
            try:
                ms = float(text)
            except ValueError:
                return None
            return ms if ms > 0 else None
        pos += 10 + size
    return None


def _mp3_truncation(path: Path, size: int, budget: _Budget) -> str | None:
    """Describe how an MP3 file is cut short, or None if nothing says so.

    What an MP3 can tell: the Xing/Info or VBRI header in the first frame
    (LAME, libsndfile, Fraunhofer) states the stream's length in bytes; an ID3v2
    ``TLEN`` frame states the duration; and every frame header gives the frame's
    length, so a last frame that runs past the end of the file is cut off. A file
    without those headers cut exactly between two frames cannot be told from a
    shorter recording. Also refuses, before any decoding, a file too large to be
    within the duration limit even at the highest bitrate.
    """
    import mmap

    with open(path, "rb") as f:
        head = f.read(10)
        start, tag = 0, b""
        if head[:3] == b"ID3" and len(head) == 10:
            # ID3v2 tag: its size is stored 7 bits per byte; a footer adds 10 bytes
            start = 10 + sum((b & 0x7F) << (7 * (3 - i)) for i, b in enumerate(head[6:10]))
            start += 10 if head[5] & 0x10 else 0
            if start > size:
                return f"the file is truncated: it ends after {size} bytes, inside its {start}-byte ID3 tag"
            f.seek(0)
            tag = f.read(min(start, 1 << 20))
        budget.check_duration(
            (size - start) / _MP3_MAX_BYTES_PER_S,
            f"the MP3 file holds {size} bytes, at least this long even at the highest bitrate",
        )
        f.seek(start)
        frame = f.read(64)
        first = _mp3_frame(frame)
        if first is None:
            return None  # not a Layer III frame where one should start; the decoder decides
        problem = _mp3_declared_bytes(frame, size - start)
        if problem is not None:
            return problem
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            samples, cut = _mp3_walk(data, start, size, first)
    rate = first[2]
    if cut is not None:
        return (f"the file is truncated: the last MP3 frame is cut off ({cut} of its bytes are missing); "
                f"the audio ends after {samples / rate:.1f} s")
    declared_ms = _id3v2_length_ms(tag) if tag else None
    if samples is not None and declared_ms is not None and samples / rate < 0.98 * declared_ms / 1000 - 0.1:
        return (f"the file is truncated: it ends after {samples / rate:.1f} s of the "
                f"{declared_ms / 1000:.1f} s its ID3 tag declares")
    return None


def _mp3_declared_bytes(frame: bytes, available: int) -> str | None:
    """Compare the byte count of a Xing/Info or VBRI header in the first frame with what follows."""
    mpeg1 = (frame[1] >> 3) & 3 == 3
    mono = (frame[3] >> 6) & 3 == 3
    pos = 4 + (2 if not frame[1] & 1 else 0) + ((17 if mono else 32) if mpeg1 else (9 if mono else 17))
    declared = None
    if frame[pos : pos + 4] in (b"Xing", b"Info"):
        flags = int.from_bytes(frame[pos + 4 : pos + 8], "big")
        field_at = pos + 8 + (4 if flags & 1 else 0)
        if flags & 2 and len(frame) >= field_at + 4:
            declared = int.from_bytes(frame[field_at : field_at + 4], "big")
    elif frame[36:40] == b"VBRI":  # always 32 bytes after the 4-byte frame header
        declared = int.from_bytes(frame[46:50], "big")
    if declared and declared - available > 0.01 * declared:  # decoders accept 1 % slack in this field
        return (
            f"the file is truncated: its MP3 header declares {declared} bytes of audio "
            f"but only {available} bytes follow"
        )
    return None


def _mp3_walk(data, start: int, size: int, first) -> tuple[int | None, int | None]:
    """Walk the frame headers from ``start``: (samples counted, bytes missing from a cut-off last frame).

    Samples are None when the walk lost the frames' rhythm (junk between frames,
    a change of stream kind): then nothing is concluded.
    """
    pos, samples = start, 0
    kind = first[3]
    while pos + 4 <= size:
        frame = _mp3_frame(data[pos : pos + 4])
        if frame is None or frame[3] != kind:
            tail = data[pos : pos + 8]
            if tail[:3] == b"TAG" or tail[:8] == b"APETAGEX" or tail[:6] == b"LYRICS":
                return samples, None  # ID3v1, APE or Lyrics3 tags follow the audio
            return None, None
        length = frame[0]
        if pos + length > size:
            return samples, pos + length - size
        samples += frame[1]
        pos += length
    return samples, None


@functools.lru_cache(maxsize=1)
def _ogg_crc_table() -> tuple[int, ...]:
    """CRC-32 lookup table of the Ogg page checksum (polynomial 0x04C11DB7, not reflected)."""
    table = []
    for i in range(256):
        r = i << 24
        for _ in range(8):
            r = ((r << 1) ^ 0x04C11DB7) & 0xFFFFFFFF if r & 0x80000000 else (r << 1) & 0xFFFFFFFF
        table.append(r)
    return tuple(table)


def _ogg_crc(page: bytes) -> int:
    """The Ogg page checksum of ``page`` (with its checksum field zeroed)."""
    table = _ogg_crc_table()
    crc = 0
    for b in page:
        crc = ((crc << 8) & 0xFFFFFFFF) ^ table[(crc >> 24) ^ b]
    return crc


def _ogg_page_at(data: bytes, pos: int) -> tuple[int, int, int, bool] | None:
    """(flags, granule position, page length, checksum correct) of the page starting at ``pos``, or None."""
    if data[pos : pos + 4] != b"OggS" or len(data) < pos + 27 or data[pos + 4] != 0:
        return None
    n_seg = data[pos + 26]
    if len(data) < pos + 27 + n_seg:
        return data[pos + 5], -1, pos + 27 + n_seg + 255 * n_seg - pos, False
    length = 27 + n_seg + sum(data[pos + 27 : pos + 27 + n_seg])
    page = data[pos : pos + length]
    granule = int.from_bytes(data[pos + 6 : pos + 14], "little", signed=True)
    ok = len(page) == length and _ogg_crc(page[:22] + b"\0\0\0\0" + page[26:]) == int.from_bytes(page[22:26], "little")
    return data[pos + 5], granule, length, ok


def _ogg_truncation(path: Path, size: int) -> str | None:
    """Describe how an Ogg stream is cut short, or None.

    An Ogg stream states no total length, but its last page carries the
    end-of-stream flag and each page the position (in samples) reached. A
    file whose last complete page lacks that flag, or that ends inside a page,
    is truncated; the granule position of the last complete page says how much
    audio is left.
    """
    tail_size = min(size, 65536 + 65307)  # a page is at most 65307 bytes
    with open(path, "rb") as f:
        first = f.read(min(size, 512))
        f.seek(size - tail_size)
        tail = f.read(tail_size)
    rate = None
    page = _ogg_page_at(first, 0)
    if page is not None:
        body = first[27 + first[26]:]
        if body[:7] == b"\x01vorbis" and len(body) >= 16:
            rate = int.from_bytes(body[12:16], "little")
        elif body[:8] == b"OpusHead":
            rate = 48000  # Opus granule positions count 48 kHz samples whatever the input rate
    # the last page with a correct checksum; a cut page after it means the file ends inside a page
    pos = tail.rfind(b"OggS")
    cut_after = False
    while pos >= 0:
        page = _ogg_page_at(tail, pos)
        if page is not None and page[3]:
            break
        if page is not None:
            cut_after = cut_after or pos + page[2] > len(tail)
        pos = tail.rfind(b"OggS", 0, pos)
    if pos < 0:
        return None  # no whole page in the last 128 KB: not for us to judge; the decoder decides
    flags, granule, length, _ = page
    if flags & 0x04:
        return None
    where = f" after {granule / rate:.1f} s" if rate and granule >= 0 else ""
    how = "the last page is cut off" if cut_after or pos + length < len(tail) else "there is no end-of-stream page"
    return f"the file is truncated: the Ogg stream ends{where} and {how}"


def _decode(path: Path, label: str | None, budget: _Budget) -> tuple[np.ndarray, AudioInfo]:
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


def _read_audioread(path: Path, budget: _Budget) -> tuple[np.ndarray, int]:
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


def _read_ffmpeg(path: Path, budget: _Budget) -> tuple[np.ndarray, int]:
    """Decode the first audio stream with the ffmpeg binary of imageio-ffmpeg, at most the duration limit."""
    try:
        import imageio_ffmpeg

        exe = imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        raise _Unreadable("not installed") from None
    import soundfile as sf

    _probe_ffmpeg(exe, path, budget)
    cmd = [
        exe, "-nostdin", "-hide_banner", "-v", "error",
        "-protocol_whitelist", "file",  # never let a file make ffmpeg open URLs
        "-i", "file:" + os.path.abspath(path),
        "-map", "0:a:0",
        # the duration is known only once decoded: stop one second past the limit
        "-t", f"{budget.seconds() + 1.0:.3f}",
        "-f", "wav", "-c:a", "pcm_f32le", "-",
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


def _probe_ffmpeg(exe: str, path: Path, budget: _Budget) -> None:
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
