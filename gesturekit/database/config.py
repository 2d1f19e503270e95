"""How a database is built (:class:`BuildConfig`) and which of its data a search holds out.

A :class:`BuildConfig` is frozen: a changed build is a new one
(:func:`dataclasses.replace`), and the config stored in ``database.json`` is the
one the arrays were built with.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from .._config import option, option_of
from ..errors import ConfigError
from ..motion import AUDIO_SR
from .audio import AUDIO_FORMATS, MIN_AUDIO_RATE, AudioStorage

__all__ = ["BuildConfig", "recorded_config", "normalise_exclusions"]


@dataclass(frozen=True)
class BuildConfig:
    """How a database is built; stored in ``database.json``.

    Parameters
    ----------
    clip_frames : int
        Frames per clip (the paper's T_match = 64), at least 16.
    overlap_stride : int or None
        If set, also store the overlapping cut with this stride (frames, 1 to ``clip_frames``),
        for the refiner.
    percentiles : (float, float)
        Percentiles of each control attribute that define "low" and "high", ``0 <= low < high <= 100``.
    store_audio : bool
        Keep the takes' audio (int16) so clips can be listened to.
    audio_format : {"pcm", "flac"}
        How the kept audio is stored: raw int16 samples, or FLAC (lossless, smaller).
    audio_rate : int
        Sample rate of the kept audio, Hz (4000 to 16000; below 16000 the audio is for
        browsing only: it is resampled back to 16 kHz when read). See :mod:`gesturekit.database.audio`.
    label : str
        A description shown to users (e.g. that the data is generated).
    source : str
        Where the takes came from (a folder, ``"demo"``).
    joint_map : str or None
        The joint map or preset used to read the takes.
    reading : dict or None
        The options the takes were read with (``kind``, ``fps``, ``units``, ``up``, ``forward``,
        ``normalize_bones``), so that ``--append`` reads every take as the build did (None: not
        recorded, by a build before they were).

    Raises
    ------
    ConfigError
        A value out of its range, an unknown audio format, or an audio format or rate given
        with ``store_audio=False``.
    """

    clip_frames: int = option(64, help="frames per clip, T_match", low=16, unit="frames")
    overlap_stride: int | None = option(
        None,
        help="also store an overlapping cut (stride in frames) for the refiner",
        low=1,
        kind=int,
        unit="frames",
        limit=lambda config: config.clip_frames,
    )
    percentiles: tuple[float, float] = option(
        (15.0, 85.0),
        help="attribute percentiles that define low/high controls",
        low=0.0,
        high=100.0,
        kind=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
    )
    store_audio: bool = option(
        True,
        help="keep the takes' audio in the database",
        flag="--no-audio",
        switch_help="do not keep the takes' audio in the database",
    )
    label: str = option("", help="a description stored with the database")
    source: str = ""
    joint_map: str | None = None
    audio_format: str = option(
        "pcm",
        help="how the kept audio is stored: pcm (int16) or flac (lossless, about half the size)",
        choices=AUDIO_FORMATS,
    )
    audio_rate: int = option(
        AUDIO_SR,
        help="sample rate of the kept audio (lower rates are for listening only)",
        low=MIN_AUDIO_RATE,
        high=AUDIO_SR,
        unit="Hz",
        metavar="HZ",
    )
    reading: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        if self.clip_frames < (option_of(BuildConfig, "clip_frames").low or 0):
            raise ConfigError(f"clip_frames must be at least 16, got {self.clip_frames}")
        if self.overlap_stride is not None and not 1 <= self.overlap_stride <= self.clip_frames:
            raise ConfigError(f"overlap_stride must be in 1..{self.clip_frames}, got {self.overlap_stride}")
        lo, hi = self.percentiles
        if not 0 <= lo < hi <= 100:
            raise ConfigError(f"percentiles must satisfy 0 <= low < high <= 100, got {self.percentiles}")
        # stored as floats whatever was given, so that equal configs compare and serialise equal
        object.__setattr__(self, "percentiles", (float(lo), float(hi)))
        storage = AudioStorage(format=self.audio_format, rate=self.audio_rate)  # checks both
        if not self.store_audio and not storage.is_default:
            raise ConfigError("an audio format or rate was given, but the database keeps no audio (store_audio=False)")


@checks_arguments
def recorded_config(build: Mapping[str, Any]) -> BuildConfig:
    """The :class:`BuildConfig` a database's build record (``database.json``'s ``build``) says.

    Parameters
    ----------
    build : mapping
        The record; options a build before they were recorded lacks take their defaults then
        (percentiles 15 and 85, audio kept as 16 kHz PCM).

    Returns
    -------
    BuildConfig
    """
    lo, hi = build.get("percentiles") or (15.0, 85.0)
    reading = build.get("reading")
    return BuildConfig(
        clip_frames=int(build["clip_frames"]),
        overlap_stride=build.get("overlap_stride"),
        percentiles=(float(lo), float(hi)),
        store_audio=bool(build.get("store_audio", True)),
        label=str(build.get("label", "")),
        source=str(build.get("source", "")),
        joint_map=build.get("joint_map"),
        audio_format=str(build.get("audio_format", "pcm")),
        audio_rate=int(build.get("audio_rate", AUDIO_SR)),
        reading=reading if isinstance(reading, dict) else None,
    )


@checks_arguments
def normalise_exclusions(
    takes: Iterable[object], ranges: Iterable[Any]
) -> tuple[tuple[str, ...], tuple[tuple[str, float, float], ...]]:
    """Held-out takes and (take, start_s, end_s) ranges as plain tuples, for configs.

    Parameters
    ----------
    takes : iterable
        Names of takes held out whole (each made a string).
    ranges : iterable of (take, start_s, end_s)
        Time ranges held out, seconds.

    Returns
    -------
    (tuple of str, tuple of (str, float, float))

    Raises
    ------
    ConfigError
        A range entry is not a (take, start, end) triple of a name and two finite numbers
        with ``0 <= start < end``.
    """
    out = []
    for r in ranges:
        try:
            take, a, b = r
            take, a, b = str(take), float(a), float(b)
        except (TypeError, ValueError):
            raise ConfigError(f"exclude_ranges entries must be (take, start_s, end_s), got {r!r}") from None
        if not (np.isfinite(a) and np.isfinite(b) and 0 <= a < b):
            raise ConfigError(f"exclude range {take}:{a:g}-{b:g} s: need finite times with 0 <= start < end")
        out.append((take, a, b))
    return tuple(str(t) for t in takes), tuple(out)
