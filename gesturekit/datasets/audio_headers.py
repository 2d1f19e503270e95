"""Audio files checked before decoding: which container a file is, and whether it is whole.

:func:`check_file` refuses a missing, empty or truncated file from what its
container states (the WAV/RF64 data chunk, the MP3 Xing/VBRI byte count, ID3
length and frame headers, the Ogg end-of-stream page and page checksums) and
returns the container sniffed from its first bytes; :class:`Budget` refuses,
from a header, a sample rate, duration or decoded size beyond
:mod:`gesturekit.limits`. Decoding is :mod:`gesturekit.datasets.audio`'s part.
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .. import limits
from .._arguments import checks_arguments
from ..errors import AudioFileError

if TYPE_CHECKING:
    import mmap

__all__ = ["Budget", "check_file"]

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
class Budget:
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
        limits.check_duration(seconds, what=what, path=self.path, speech=not self.take, max_seconds=self.max_seconds)

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
        limits.check_bytes(
            decoded, what=f"the {fmt} header says {frames} samples of {channels} channels", path=self.path
        )


@checks_arguments
def check_file(path: Path, budget: Budget) -> str | None:
    """Fail early on a missing, empty, truncated or too long file; return the sniffed container name."""
    if not path.exists():
        raise AudioFileError("file not found", path=path)
    if path.is_dir():
        raise AudioFileError("is a folder, not an audio file", path=path)
    limits.check_regular(path, error=AudioFileError)  # a FIFO would never end, a device never be empty
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
        size = sum((b & 0x7F) << (7 * (3 - i)) for i, b in enumerate(raw)) if major == 4 else int.from_bytes(raw, "big")
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


def _mp3_truncation(path: Path, size: int, budget: Budget) -> str | None:
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
    if cut is not None and samples is not None:  # a walk that finds a cut frame has counted its samples
        return (
            f"the file is truncated: the last MP3 frame is cut off ({cut} of its bytes are missing); "
            f"the audio ends after {samples / rate:.1f} s"
        )
    declared_ms = _id3v2_length_ms(tag) if tag else None
    if samples is not None and declared_ms is not None and samples / rate < 0.98 * declared_ms / 1000 - 0.1:
        return (
            f"the file is truncated: it ends after {samples / rate:.1f} s of the "
            f"{declared_ms / 1000:.1f} s its ID3 tag declares"
        )
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


def _mp3_walk(
    data: mmap.mmap, start: int, size: int, first: tuple[int, int, int, tuple[int, int]]
) -> tuple[int | None, int | None]:
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
        body = first[27 + first[26] :]
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
    if pos < 0 or page is None:
        return None  # no whole page in the last 128 KB: not for us to judge; the decoder decides
    flags, granule, length, _ = page
    if flags & 0x04:
        return None
    where = f" after {granule / rate:.1f} s" if rate and granule >= 0 else ""
    how = "the last page is cut off" if cut_after or pos + length < len(tail) else "there is no end-of-stream page"
    return f"the file is truncated: the Ogg stream ends{where} and {how}"
