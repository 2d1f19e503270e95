"""One take made into a database's rows: its per-frame arrays, cut into clips, with its moments.

:func:`take_features` computes every per-frame array of a take (features not yet
z-scored); :func:`take_clips` cuts them into non-overlapping clips of
``clip_frames`` frames (the tail that does not fill a clip is dropped) and, on
request, the overlapping cut of the refiner, encodes the take's audio as the
database keeps it and computes the take's z-scoring moments. A
:class:`TakeClips` is what both builds combine: in memory
(:func:`gesturekit.database.build.build_in_memory`) or staged on disk first
(:mod:`gesturekit.database.stage`). Features are computed on the whole take, so
look-ahead near a clip's end uses the real following frames.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..control import frame_attributes
from ..errors import ConfigError, warn
from ..features import (
    LAYOUT,
    FeatureLayout,
    audio_frame_features,
    cgan_audio_features,
    n_audio_frames,
    pose_features,
    stack_audio_features,
    valid_starts,
)
from ..motion import Take, resample_positions
from ..skeleton import POSE_FEATURE_INDICES
from .audio import AudioStorage, encode_take_audio
from .config import BuildConfig
from .folder import CLIP_ARRAYS

__all__ = ["MOMENT_KEYS", "TakeFeatures", "take_features", "windows", "cut", "moments", "TakeClips", "take_clips"]

#: The z-scored feature arrays whose moments each take carries: key -> the TakeFeatures attribute.
MOMENT_KEYS = {"F": "f", "P": "p", "A": "a"}


@dataclass
class TakeFeatures:
    """Per-frame arrays of one take at 15 fps (features not yet z-scored).

    Attributes
    ----------
    positions : (T,55,3) metres; m : (T,14); f : (T,112); p : (T,96); a : (T,28);
    valid : (T,) bool; attributes : (T,9); track : (T,24) feature-joint positions;
    audio : (samples,) float32 at 16 kHz.
    """

    name: str
    positions: np.ndarray
    m: np.ndarray
    f: np.ndarray
    p: np.ndarray
    a: np.ndarray
    valid: np.ndarray
    attributes: np.ndarray
    track: np.ndarray
    audio: np.ndarray
    sources: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])


@checks_arguments
def take_features(take: Take, *, layout: FeatureLayout = LAYOUT) -> TakeFeatures:
    """Compute every per-frame array of a take, trimming motion and audio to the shorter.

    Motion at another frame rate is resampled to 15 fps (linear in positions;
    readers with rotations resample before this). A length mismatch is trimmed
    with a :class:`GestureKitWarning` that says by how much.

    Raises
    ------
    ConfigError
        No frame is left after aligning motion and audio.
    """
    pos = take.motion.positions
    if take.motion.fps != layout.fps:
        pos = resample_positions(pos, take.motion.fps, layout.fps)
    n_motion = pos.shape[0]
    n_audio = n_audio_frames(len(take.audio), sr=layout.sr, fps=layout.fps)
    n = min(n_motion, n_audio)
    if n_motion != n_audio:
        longer = "motion" if n_motion > n_audio else "audio"
        warn(
            f"{take.name}: motion has {n_motion / layout.fps:.2f} s and audio {n_audio / layout.fps:.2f} s; "
            f"trimmed the {longer} by {abs(n_motion - n_audio) / layout.fps:.2f} s to {n / layout.fps:.2f} s",
            stacklevel=2,
        )
    if n < 1:
        raise ConfigError(f"take {take.name!r} has no frame after aligning motion and audio")
    pos = np.ascontiguousarray(pos[:n], dtype=np.float32)
    audio = np.asarray(take.audio, dtype=np.float32)[: int(np.ceil(n * layout.sr / layout.fps))]
    m = audio_frame_features(audio, n_frames=n, layout=layout)
    return TakeFeatures(
        name=take.name,
        positions=pos,
        m=m,
        f=stack_audio_features(m, layout=layout),
        p=pose_features(pos, layout=layout),
        a=cgan_audio_features(m),
        valid=valid_starts(n, layout=layout),
        attributes=frame_attributes(pos, fps=layout.fps),
        track=pos[:, POSE_FEATURE_INDICES].reshape(n, -1),
        audio=audio,
        sources=dict(take.sources),
    )


@checks_arguments
def windows(n_frames: int, length: int, stride: int) -> np.ndarray:
    """Start frames of windows of ``length`` frames every ``stride`` frames inside ``n_frames``, int64."""
    if n_frames < length:
        return np.zeros(0, dtype=np.int64)
    return np.arange(0, n_frames - length + 1, stride, dtype=np.int64)


@checks_arguments
def cut(tf: TakeFeatures, starts: np.ndarray, length: int, track_len: int) -> dict[str, np.ndarray]:
    """The clip arrays of the windows starting at ``starts``: each (len(starts), length, ...) and
    ``pose_track`` (len(starts), track_len, 24), its frames past the take's end held at the last."""
    idx = starts[:, None] + np.arange(length)[None, :]
    tidx = np.minimum(starts[:, None] + np.arange(track_len)[None, :], tf.n_frames - 1)
    return {
        "F": tf.f[idx],
        "P": tf.p[idx],
        "G": tf.positions.reshape(tf.n_frames, -1)[idx],
        "A": tf.a[idx],
        "valid": tf.valid[idx],
        "attributes": tf.attributes[idx],
        "pose_track": tf.track[tidx],
    }


@checks_arguments
def moments(x: np.ndarray) -> np.ndarray:
    """(2, dims) float64: the mean and the sum of squared deviations of the rows of ``x`` (zeros for none)."""
    if x.shape[0] == 0:
        return np.zeros((2, x.shape[1]), dtype=np.float64)
    x64 = x.astype(np.float64)
    mean = x64.mean(axis=0)
    return np.stack([mean, ((x64 - mean) ** 2).sum(axis=0)])


_FEATURES_LOCK = threading.Lock()


@contextlib.contextmanager
def _one_blas_thread() -> Iterator[None]:
    """numpy's BLAS held to one thread while a take is featurised, then as it was.

    A matrix product's last bits depend on how many threads share it: a database must not
    depend on the machine's cores, the number of workers or other threads' settings. The
    limit is process-wide in some BLAS builds, so threads of one process (a Dask worker's)
    featurise one at a time (reading the files, the longer part, still overlaps).
    """
    from threadpoolctl import threadpool_limits

    with _FEATURES_LOCK, threadpool_limits(limits=1, user_api="blas"):
        yield


@dataclass(frozen=True)
class TakeClips:
    """One take's rows of a database, in memory.

    Attributes
    ----------
    record : dict
        The take's record: ``index``, ``name``, ``sources``, ``n_frames``, ``n_clips``,
        ``n_windows`` (of the overlapping cut), ``audio_samples`` (16 kHz), ``audio_size``
        (elements stored), ``count`` (frames in the moments), ``joints`` (the joint presence,
        or None when all are recorded) and ``seconds`` (duration at 15 fps).
    arrays : dict of str to np.ndarray
        ``F`` ... ``pose_track`` (clips first; F and P not yet z-scored) and ``clip_start``
        (int32), the same prefixed ``overlap.`` for the overlapping cut, ``audio`` (as stored;
        with ``store_audio``), ``moments_F``, ``moments_P``, ``moments_A`` ((2, dims) float64).
    """

    record: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def name(self) -> str:
        return str(self.record["name"])

    def load(self, what: str, *, header: bool = False) -> np.ndarray:
        """One array (``"F"``, ``"overlap.G"``, ``"audio"``, ``"moments_P"``, ...); ``header`` is
        accepted for the staged takes' interface (an array in memory costs nothing to hand out)."""
        return self.arrays[what]

    def path(self, what: str) -> Path | None:
        """No file: the take is in memory (a staged take names its file here)."""
        return None


@checks_arguments
def take_clips(take: Take, index: int, config: BuildConfig) -> TakeClips:
    """Featurise and cut one take, encode its audio, and compute its z-scoring moments.

    Parameters
    ----------
    take : Take
    index : int
        The take's index in its unit (``record["index"]``; a staged take's files are named by it).
    config : BuildConfig

    Returns
    -------
    TakeClips
        The same arrays for the same take, whatever the machine's cores or the process's threads.

    Raises
    ------
    ConfigError
        The take has NaN positions, non-finite features, or no frame.
    """
    with _one_blas_thread():
        tf = take_features(take)
    if np.isnan(tf.positions).any():
        raise ConfigError(f"take {take.name!r} has NaN positions")
    L = config.clip_frames
    track_len = L + LAYOUT.pose_lookahead
    cuts = {"": windows(tf.n_frames, L, L)}
    if config.overlap_stride:
        cuts["overlap."] = windows(tf.n_frames, L, config.overlap_stride)
    arrays: dict[str, np.ndarray] = {}
    for prefix, starts in cuts.items():
        clips = cut(tf, starts, L, track_len)
        for k in CLIP_ARRAYS:
            a = clips[k]
            if np.issubdtype(a.dtype, np.floating) and not np.isfinite(a).all():
                raise ConfigError(
                    f"take {take.name!r}: its {k} array holds NaN or infinite values (the motion or audio "
                    "is not finite); nothing was written"
                )
            arrays[prefix + k] = np.ascontiguousarray(a)
        arrays[prefix + "clip_start"] = starts.astype(np.int32)
    samples, size = 0, 0
    if config.store_audio:
        encoded = encode_take_audio(tf.audio, AudioStorage(format=config.audio_format, rate=config.audio_rate))
        samples, size = int(encoded.samples), int(encoded.data.size)
        arrays["audio"] = encoded.data
    for key, attr in MOMENT_KEYS.items():
        arrays[f"moments_{key}"] = moments(getattr(tf, attr)[tf.valid])
    presence = take.motion.presence
    record = {
        "index": index,
        "name": tf.name,
        "sources": {k: str(v) for k, v in tf.sources.items()},
        "n_frames": tf.n_frames,
        "n_clips": int(cuts[""].shape[0]),
        "n_windows": int(cuts["overlap."].shape[0]) if "overlap." in cuts else 0,
        "audio_samples": samples,
        "audio_size": size,
        "count": int(tf.valid.sum()),
        "joints": None if presence.is_full else presence.to_list(),
        "seconds": tf.n_frames / LAYOUT.fps,
    }
    return TakeClips(record, arrays)
