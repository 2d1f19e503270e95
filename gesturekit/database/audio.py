"""How a matching database stores its takes' audio: raw int16, at a lower rate, or as FLAC.

The stored audio only serves listening to clips (the browser, the inspector)
and the held-out takes of an evaluation; the search never reads it. It is the
largest part of a database folder (16 kHz int16: 32 kB per second, more than
all the clip arrays together), so a database may keep it smaller:

=========  ===========================  ==============================================
format     ``audio.npy`` holds          take_audio returns
=========  ===========================  ==============================================
``pcm``    int16 samples at ``rate``    the samples, resampled to 16 kHz if ``rate`` is lower
``flac``   uint8: one FLAC stream per   the decoded samples, resampled likewise; at 16 kHz
           take, back to back           exactly what ``pcm`` returns (FLAC is lossless)
=========  ===========================  ==============================================

``database.json`` says which under ``"audio"`` (``{"format": ..., "rate": ...}``);
a database without that key holds ``pcm`` at 16 kHz, as every database did
before the choice existed, and a database built with that default is written
without the key, byte for byte as before. Each take's ``audio_offset`` is the
index of its first element in ``audio.npy`` and ``audio_samples`` its length at
16 kHz (what :meth:`~gesturekit.database.MatchingDatabase.take_audio` returns);
with another storage, ``audio_size`` is the number of elements it holds there.

A build that writes takes one at a time calls :func:`encode_take_audio` on each
take's audio and appends :attr:`EncodedAudio.data` to ``audio.npy``,
:func:`take_audio_fields` gives the take's entries of ``database.json`` and
:meth:`AudioStorage.to_meta` the ``"audio"`` entry; :func:`decode_take_audio` reads
a take back.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError, DatabaseError
from ..motion import AUDIO_SR

__all__ = [
    "AUDIO_FORMATS",
    "MIN_AUDIO_RATE",
    "AudioStorage",
    "EncodedAudio",
    "encode_take_audio",
    "decode_take_audio",
    "take_audio_fields",
    "read_take_audio",
    "to_int16",
]

#: Ways of storing the audio: raw int16 samples, or FLAC (lossless, about half the size on speech).
AUDIO_FORMATS = ("pcm", "flac")
#: The lowest stored rate, Hz: 4 kHz keeps speech up to 2 kHz, still intelligible for browsing.
MIN_AUDIO_RATE = 4000


@dataclass(frozen=True)
class AudioStorage:
    """How a database stores its audio.

    Parameters
    ----------
    format : {"pcm", "flac"}
        Raw int16 samples, or one FLAC stream per take (lossless).
    rate : int
        Stored sample rate, Hz, from 4000 to 16000 (the takes' audio is 16 kHz;
        a lower rate keeps what lies below half of it, for browsing).
    """

    format: str = "pcm"
    rate: int = AUDIO_SR

    def __post_init__(self) -> None:
        if self.format not in AUDIO_FORMATS:
            raise ConfigError(f"audio format must be one of {', '.join(AUDIO_FORMATS)}, got {self.format!r}")
        if isinstance(self.rate, bool) or not isinstance(self.rate, (int, np.integer)):
            raise ConfigError(f"audio rate must be an integer number of Hz, got {self.rate!r}")
        if not MIN_AUDIO_RATE <= self.rate <= AUDIO_SR:
            raise ConfigError(f"audio rate must be {MIN_AUDIO_RATE} to {AUDIO_SR} Hz, got {self.rate}")
        object.__setattr__(self, "rate", int(self.rate))

    @property
    def is_default(self) -> bool:
        """int16 at 16 kHz: the storage of a database whose ``database.json`` has no ``"audio"`` entry."""
        return self == AudioStorage()

    @property
    def is_exact(self) -> bool:
        """Whether :func:`decode_take_audio` gives back the 16 kHz int16 samples exactly."""
        return self.rate == AUDIO_SR

    @property
    def dtype(self) -> np.dtype:
        """The dtype of ``audio.npy``: int16 samples, or uint8 bytes of FLAC streams."""
        return np.dtype(np.int16 if self.format == "pcm" else np.uint8)

    def to_meta(self) -> dict[str, Any] | None:
        """The ``"audio"`` entry of ``database.json``; None for the default (the entry is left out)."""
        return None if self.is_default else {"format": self.format, "rate": self.rate}

    @classmethod
    def from_meta(cls, meta: dict) -> AudioStorage:
        """The storage ``database.json`` declares (no ``"audio"`` entry: int16 at 16 kHz).

        Raises
        ------
        DatabaseError
            The entry is not an object with a known format and a rate in range.
        """
        entry = meta.get("audio")
        if entry is None:
            return cls()
        if not isinstance(entry, dict) or set(entry) != {"format", "rate"}:
            raise DatabaseError(f"database.json: 'audio' must be an object of format and rate, found {entry!r}")
        try:
            return cls(format=entry["format"], rate=entry["rate"])
        except ConfigError as exc:
            raise DatabaseError(f"database.json: 'audio': {exc}") from None


@dataclass(frozen=True)
class EncodedAudio:
    """One take's audio as stored.

    Attributes
    ----------
    data : np.ndarray, shape (size,)
        The elements to append to ``audio.npy`` (int16 samples or uint8 FLAC bytes).
    samples : int
        Samples of the take at 16 kHz (its length when read back).
    """

    data: np.ndarray
    samples: int


@checks_arguments
def to_int16(audio: np.ndarray) -> np.ndarray:
    """Float samples in [-1, 1] as int16 (rounded, clipped), the database's sample format; shape kept."""
    return np.clip(np.round(np.asarray(audio, dtype=np.float32) * 32767), -32768, 32767).astype(np.int16)


def _resample(x: np.ndarray, up: int, down: int, n_out: int) -> np.ndarray:
    """``x`` (float64, 1-D) resampled by ``up / down`` with a polyphase low-pass, exactly ``n_out`` samples."""
    from scipy.signal import resample_poly

    g = math.gcd(up, down)
    y = resample_poly(x, up // g, down // g) if x.size else np.zeros(0)
    out = np.zeros(n_out)
    out[: min(n_out, y.size)] = y[:n_out]
    return out


@checks_arguments
def encode_take_audio(audio: np.ndarray, storage: AudioStorage) -> EncodedAudio:
    """One take's audio in the form ``storage`` keeps it.

    Parameters
    ----------
    audio : np.ndarray, shape (samples,), float32 in [-1, 1] or int16
        The take's audio at 16 kHz (float samples are rounded to int16 first, as the
        default storage does).
    storage : AudioStorage

    Returns
    -------
    EncodedAudio
        The same bytes for the same input (a streaming or parallel build stores what a
        serial one does).
    """
    a = np.asarray(audio)
    if a.ndim != 1:
        raise ConfigError(f"take audio must be mono, shape (samples,), got {a.shape}")
    pcm = a if a.dtype == np.int16 else to_int16(a)
    n = int(pcm.shape[0])
    if storage.rate != AUDIO_SR:
        n_low = int(math.ceil(n * storage.rate / AUDIO_SR))
        low = _resample(pcm.astype(np.float64), storage.rate, AUDIO_SR, n_low)
        pcm = np.clip(np.round(low), -32768, 32767).astype(np.int16)
    if storage.format == "pcm":
        return EncodedAudio(np.ascontiguousarray(pcm), n)
    import soundfile as sf

    buf = io.BytesIO()
    if pcm.size:
        sf.write(buf, pcm, storage.rate, format="FLAC", subtype="PCM_16")
    return EncodedAudio(np.frombuffer(buf.getvalue(), dtype=np.uint8).copy(), n)


@checks_arguments
def decode_take_audio(data: np.ndarray, samples: int, storage: AudioStorage) -> np.ndarray:
    """A take's stored audio back as float32 at 16 kHz.

    Parameters
    ----------
    data : np.ndarray, shape (size,)
        The take's elements of ``audio.npy`` (may be a memory-mapped slice).
    samples : int
        Its length at 16 kHz (``audio_samples`` in ``database.json``).
    storage : AudioStorage

    Returns
    -------
    np.ndarray, shape (samples,), float32
        int16 samples / 32767; resampled to 16 kHz when stored at a lower rate.

    Raises
    ------
    DatabaseError
        The stored data does not decode (a damaged FLAC stream) or is shorter than declared.
    """
    if storage.format == "pcm":
        pcm = np.asarray(data)
    elif data.size == 0:
        pcm = np.zeros(0, np.int16)
    else:
        import soundfile as sf

        try:
            pcm, rate = sf.read(io.BytesIO(np.asarray(data, dtype=np.uint8).tobytes()), dtype="int16")
        except (sf.LibsndfileError, RuntimeError, ValueError) as exc:
            raise DatabaseError(f"audio.npy: a take's FLAC stream cannot be decoded ({exc})") from None
        if rate != storage.rate or pcm.ndim != 1:
            raise DatabaseError(
                f"audio.npy: a take's FLAC stream is {rate} Hz with shape {pcm.shape}; "
                f"database.json declares mono at {storage.rate} Hz"
            )
    need = samples if storage.rate == AUDIO_SR else int(math.ceil(samples * storage.rate / AUDIO_SR))
    if pcm.shape[0] < need:
        raise DatabaseError(f"audio.npy: a take holds {pcm.shape[0]} samples, database.json declares {need}")
    if storage.rate == AUDIO_SR:
        return pcm[:samples].astype(np.float32) / np.float32(32767.0)
    up = _resample(pcm[:need].astype(np.float64), AUDIO_SR, storage.rate, samples)
    return (up / 32767.0).astype(np.float32)


@checks_arguments
def take_audio_fields(encoded: EncodedAudio, offset: int, storage: AudioStorage) -> dict[str, int]:
    """A take's audio entries of ``database.json``, its data starting at element ``offset`` of ``audio.npy``.

    Returns
    -------
    dict
        ``audio_offset`` and ``audio_samples`` (16 kHz), and ``audio_size`` (elements) unless
        the storage is the default (where the size is the number of samples).
    """
    fields = {"audio_offset": int(offset), "audio_samples": int(encoded.samples)}
    if not storage.is_default:
        fields["audio_size"] = int(encoded.data.size)
    return fields


@checks_arguments
def read_take_audio(
    audio: np.ndarray, take: dict, storage: AudioStorage, *, path: str | os.PathLike[str] | None = None
) -> np.ndarray:
    """One take's audio from a database's ``audio.npy``, float32 at 16 kHz, shape (samples,).

    Parameters
    ----------
    audio : np.ndarray, shape (size,)
        ``audio.npy`` (memory-mapped: only the take's part is read).
    take : dict
        The take's entry of ``database.json`` (``name``, ``audio_offset``, ``audio_samples``,
        and ``audio_size`` unless the storage is the default).
    storage : AudioStorage
    path : path, optional
        The database folder, named by an error.

    Raises
    ------
    DatabaseError
        The take's stored audio does not decode (see :func:`decode_take_audio`).
    """
    start = take["audio_offset"]
    size = take["audio_samples"] if storage.is_default else take["audio_size"]
    try:
        return decode_take_audio(audio[start : start + size], take["audio_samples"], storage)
    except DatabaseError as exc:
        raise DatabaseError(f"take {take['name']!r}: {exc.problem}", path=path) from None
