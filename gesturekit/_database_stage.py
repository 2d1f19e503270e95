"""Building a database, first pass: each take read, featurised, cut and staged on disk.

A build never holds more than a few takes. Each unit of work (one take file, or
one file of several takes) is read, its per-frame arrays are computed
(:func:`take_features`), cut into clips (and, on request, the overlapping cut)
and written to a folder of its own in a *staging folder*, with the take's
z-scoring moments (count, mean and sum of squared deviations over the frames
that may start a segment, float64). The second pass
(:mod:`gesturekit._database_build`) combines the moments and writes the
database's arrays from the staged ones, one take at a time.

A folder build stages beside its output, in ``.NAME.staging`` (marked by
``staging.json``, so that nothing else is ever taken for it or removed). Each
unit's folder is named by a key of its source files (path, size, modification
time) and of every option that changes what is staged, and is written under a
temporary name and renamed when complete: a build that was interrupted is
resumed by the next identical command, which reuses the units already there.
The staging folder is removed when the database is written.

Staged unit ``KEY/``::

    takes.json            the takes of the unit (name, sources, frame and clip counts, ...), warnings
    J.F.npy ... J.pose_track.npy   take J's clip arrays, F and P not yet z-scored
    J.clip_start.npy      the clips' start frames
    J.overlap.*.npy       the overlapping cut (optional)
    J.audio.npy           the take's audio as the database keeps it (optional; :mod:`gesturekit._database_audio`)
    J.moments_F.npy ...   (2, dims) float64: mean and sum of squared deviations of F, P, A

A build with ``--normalize-bones`` first reads every take once to fit the database's
skeleton (:func:`sample_job`), in units of their own (another key), each take's
``J.bones.npy``: the samples a skeleton is fitted from
(:func:`gesturekit.bones.bone_samples`), then stages the takes normalised with it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import threading
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._database_audio import AudioStorage, encode_take_audio
from ._database_folder import CLIP_ARRAYS, STAGING_VERSION
from ._version import __version__
from .control import frame_attributes
from .errors import ConfigError, GestureKitError, collect_warnings, warn
from .features import (
    LAYOUT,
    FeatureLayout,
    audio_frame_features,
    cgan_audio_features,
    n_audio_frames,
    pose_features,
    stack_audio_features,
    valid_starts,
)
from .limits import check_regular, npy_header, read_json
from .motion import AUDIO_SR, Take, resample_positions
from .skeleton import POSE_FEATURE_INDICES

if TYPE_CHECKING:
    from .datasets.takes import TakeSource

__all__ = [
    "BuildConfig",
    "TakeFeatures",
    "take_features",
    "StageJob",
    "stage_job",
    "sample_job",
    "stage_take",
    "job_key",
    "MOMENT_KEYS",
]

#: The z-scored feature arrays whose moments each staged take carries: key -> the TakeFeatures attribute.
MOMENT_KEYS = {"F": "f", "P": "p", "A": "a"}


@dataclass
class BuildConfig:
    """How a database is built; stored in ``database.json``.

    Parameters
    ----------
    clip_frames : int
        Frames per clip (the paper's T_match = 64).
    overlap_stride : int or None
        If set, also store the overlapping cut with this stride (frames), for the refiner.
    percentiles : (float, float)
        Percentiles of each control attribute that define "low" and "high".
    store_audio : bool
        Keep the takes' audio (int16) so clips can be listened to.
    audio_format : {"pcm", "flac"}
        How the kept audio is stored: raw int16 samples, or FLAC (lossless, smaller).
    audio_rate : int
        Sample rate of the kept audio, Hz (4000 to 16000; below 16000 the audio is for
        browsing only: it is resampled back to 16 kHz when read). See :mod:`gesturekit._database_audio`.
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
    """

    clip_frames: int = 64
    overlap_stride: int | None = None
    percentiles: tuple[float, float] = (15.0, 85.0)
    store_audio: bool = True
    label: str = ""
    source: str = ""
    joint_map: str | None = None
    audio_format: str = "pcm"
    audio_rate: int = AUDIO_SR
    reading: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        if self.clip_frames < 16:
            raise ConfigError(f"clip_frames must be at least 16, got {self.clip_frames}")
        if self.overlap_stride is not None and not 1 <= self.overlap_stride <= self.clip_frames:
            raise ConfigError(f"overlap_stride must be in 1..{self.clip_frames}, got {self.overlap_stride}")
        lo, hi = self.percentiles
        if not 0 <= lo < hi <= 100:
            raise ConfigError(f"percentiles must satisfy 0 <= low < high <= 100, got {self.percentiles}")
        self.percentiles = (float(lo), float(hi))
        storage = AudioStorage(format=self.audio_format, rate=self.audio_rate)  # checks both
        if not self.store_audio and not storage.is_default:
            raise ConfigError("an audio format or rate was given, but the database keeps no audio (store_audio=False)")


@dataclass
class TakeFeatures:
    """Per-frame arrays of one take at 15 fps (features not yet z-scored).

    Attributes
    ----------
    positions : (T,55,3) metres; m : (T,14); f : (T,112); p : (T,96); a : (T,28);
    valid : (T,) bool; attributes : (T,9); track : (T,24) feature-joint positions.
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


def take_features(take: Take, *, layout: FeatureLayout = LAYOUT) -> TakeFeatures:
    """Compute every per-frame array of a take, trimming motion and audio to the shorter.

    Motion at another frame rate is resampled to 15 fps (linear in positions;
    readers with rotations resample before this). A length mismatch is trimmed
    with a :class:`GestureKitWarning` that says by how much.
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


def windows(n_frames: int, length: int, stride: int) -> np.ndarray:
    """Start frames of windows of ``length`` frames every ``stride`` frames inside ``n_frames``."""
    if n_frames < length:
        return np.zeros(0, dtype=np.int64)
    return np.arange(0, n_frames - length + 1, stride, dtype=np.int64)


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


# ---- one take -----------------------------------------------------------------------------------


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


def _moments(x: np.ndarray) -> np.ndarray:
    """(2, dims) float64: the mean and the sum of squared deviations of the rows of ``x`` (zeros for none)."""
    if x.shape[0] == 0:
        return np.zeros((2, x.shape[1]), dtype=np.float64)
    x64 = x.astype(np.float64)
    mean = x64.mean(axis=0)
    return np.stack([mean, ((x64 - mean) ** 2).sum(axis=0)])


def _save(path: Path, array: np.ndarray) -> None:
    """Write a staged array; a failed write (a full disk) is an :class:`OutputError` naming the file,
    whose unit's temporary folder is then removed (:func:`_run_unit`)."""
    from .outputs import write_errors

    with write_errors(path):
        np.save(path, np.ascontiguousarray(array), allow_pickle=False)


def stage_take(take: Take, folder: Path, index: int, config: BuildConfig) -> dict[str, Any]:
    """Featurise and cut one take and write its arrays into ``folder`` as ``INDEX.*.npy``.

    Returns
    -------
    dict
        The take's record: ``name``, ``sources``, ``n_frames``, ``n_clips``,
        ``n_windows`` (of the overlapping cut), ``audio_samples``, ``count``
        (frames in the moments), ``joints`` (the joint presence, or None when all
        are recorded), ``seconds`` (duration at 15 fps) and ``index``.

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
    for prefix, starts in cuts.items():
        arrays = cut(tf, starts, L, track_len)
        for k in CLIP_ARRAYS:
            a = arrays[k]
            if np.issubdtype(a.dtype, np.floating) and not np.isfinite(a).all():
                raise ConfigError(
                    f"take {take.name!r}: its {k} array holds NaN or infinite values (the motion or audio "
                    "is not finite); nothing was written"
                )
            _save(folder / f"{index}.{prefix}{k}.npy", a)
        _save(folder / f"{index}.{prefix}clip_start.npy", starts.astype(np.int32))
    samples, size = 0, 0
    if config.store_audio:
        # encoded here, in the first pass: the second only appends each take's stored elements
        encoded = encode_take_audio(tf.audio, AudioStorage(format=config.audio_format, rate=config.audio_rate))
        samples, size = int(encoded.samples), int(encoded.data.size)
        _save(folder / f"{index}.audio.npy", encoded.data)
    for key, attr in MOMENT_KEYS.items():
        _save(folder / f"{index}.moments_{key}.npy", _moments(getattr(tf, attr)[tf.valid]))
    presence = take.motion.presence
    return {
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


# ---- units of work ------------------------------------------------------------------------------


@dataclass(frozen=True)
class StageJob:
    """One unit of per-take work of a folder build: a source's takes, staged as ``staging/key``.

    Attributes
    ----------
    key : str
        The unit's staging key (:func:`job_key`).
    staging : str
        The staging folder (a string, so that jobs travel to cluster workers as they are).
    source : TakeSource
        The files to read.
    reading : dict
        Keyword options of :func:`gesturekit.datasets.takes.iter_takes`.
    config : BuildConfig
    only : tuple of str or None
        Stage only the takes of these names (a file of several takes that the database holds some of).
    skip : tuple of str
        Take names not to stage (in the database already).
    """

    key: str
    staging: str
    source: TakeSource
    reading: dict
    config: BuildConfig
    only: tuple[str, ...] | None = None
    skip: tuple[str, ...] = ()


def _file_identity(path: Path | None) -> list[Any]:
    if path is None:
        return [None]
    try:
        st = os.stat(path)
    except OSError:
        return [os.path.abspath(path), None, None]
    return [os.path.abspath(path), st.st_size, st.st_mtime_ns]


def job_key(
    source: TakeSource,
    reading_key: dict[str, Any],
    config: BuildConfig,
    *,
    only: tuple[str, ...] | None = None,
    skip: tuple[str, ...] = (),
) -> str:
    """The staging key of a unit: a digest of its files (path, size, modification time), of the
    reading options ``reading_key`` (JSON-able), of what the build stages (clip frames, overlap
    stride, audio), the feature layout and gesturekit's version."""
    record = {
        "staging": STAGING_VERSION,
        "gesturekit": __version__,
        "layout": LAYOUT.signature(),
        "kind": source.kind,
        "motion": _file_identity(source.motion),
        "audio": _file_identity(source.audio),
        "reading": reading_key,
        "build": [
            config.clip_frames,
            config.overlap_stride,
            config.store_audio,
            config.audio_format,
            config.audio_rate,
        ],
        "only": None if only is None else sorted(only),
        "skip": sorted(skip),
    }
    text = json.dumps(record, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:32]


def staged_takes(staging: Path, key: str) -> dict[str, Any] | None:
    """The record of a complete staged unit (``takes`` and ``warnings``), or None when it is not staged."""
    try:
        record = read_json(staging / key / "takes.json")
    except GestureKitError:  # missing, or damaged: the unit is staged again
        return None
    return record if isinstance(record, dict) else None


# ---- checking a staged unit before it is reused ------------------------------------------------------

#: Fields of a staged take's record (:func:`stage_take`) and of a sampled take's (:func:`sample_job`).
_STAGE_FIELDS = {
    "index": int,
    "name": str,
    "sources": dict,
    "n_frames": int,
    "n_clips": int,
    "n_windows": int,
    "audio_samples": int,
    "audio_size": int,
    "count": int,
    "seconds": (int, float),
}
_SAMPLE_FIELDS = {"index": int, "name": str, "frames": int, "seconds": (int, float), "medians": list}


class _Damaged(Exception):
    """A staged unit that cannot be reused; the message says why."""


def _staged_array(folder: Path, name: str, dtype: np.dtype, shape: tuple[int, ...], *, finite: bool) -> np.ndarray:
    """The staged array ``folder/name`` when it is a regular ``.npy`` file of ``dtype`` and ``shape``,
    complete, and (with ``finite``, for floats) without NaN or infinite values.

    Raises
    ------
    _Damaged
        Saying which file and what is wrong with it.
    """
    path = folder / name
    try:
        size = check_regular(path, error=ConfigError)
        with open(path, "rb") as f:
            got_shape, got_dtype, offset = npy_header(f, path=path)
    except (GestureKitError, OSError) as exc:
        problem = exc.problem if isinstance(exc, GestureKitError) else (exc.strerror or str(exc))
        raise _Damaged(f"{name}: {problem}") from None
    if got_dtype != dtype or got_shape != shape:
        raise _Damaged(f"{name}: holds {got_dtype} {got_shape}, expected {np.dtype(dtype)} {shape}")
    expected = offset + int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    if size != expected:
        raise _Damaged(f"{name}: has {size} bytes, expected {expected} (truncated or appended to)")
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise _Damaged(f"{name}: cannot be read ({exc})") from None
    if finite and array.dtype.kind == "f" and not np.isfinite(array).all():
        raise _Damaged(f"{name}: holds NaN or infinite values")
    return array


def _checked_records(folder: Path, fields: dict[str, Any]) -> list[dict[str, Any]]:
    """The take records of the staged unit ``folder`` (its ``takes.json``), each with ``fields``."""
    try:
        record = read_json(folder / "takes.json")
    except GestureKitError as exc:
        raise _Damaged(f"takes.json: {exc.problem}") from None
    if not isinstance(record, dict):
        raise _Damaged("takes.json: not a staged unit's record (no list of takes and warnings)")
    takes, messages = record.get("takes"), record.get("warnings")
    if not isinstance(takes, list) or not isinstance(messages, list):
        raise _Damaged("takes.json: not a staged unit's record (no list of takes and warnings)")
    for i, take in enumerate(takes):
        if not isinstance(take, dict) or take.get("index") != i:
            raise _Damaged(f"takes.json: take {i} is not a take's record")
        for key, kind in fields.items():
            value = take.get(key)
            if not isinstance(value, kind) or isinstance(value, bool) or (kind is int and value < 0):
                raise _Damaged(f"takes.json: take {i} has no valid {key!r}")
    if not all(isinstance(w, str) for w in messages):
        raise _Damaged("takes.json: its warnings are not text")
    return takes


def check_staged_unit(folder: Path, config: BuildConfig) -> None:
    """Check a unit :func:`stage_job` staged before it is reused: its record, and every array of each
    take present, a regular file, complete, of the dtype and shape the take's frame count gives, the
    clips' starts where the take's cut puts them, and no NaN or infinite value.

    Raises
    ------
    _Damaged
        Saying what is wrong (the unit is then staged again).
    """
    from .control import ATTRIBUTE_NAMES

    L = config.clip_frames
    track = L + LAYOUT.pose_lookahead
    f32, f64 = np.dtype(np.float32), np.dtype(np.float64)
    rows = {
        "F": (f32, (L, LAYOUT.audio_dim)),
        "P": (f32, (L, LAYOUT.pose_dim)),
        "G": (f32, (L, LAYOUT.motion_dim)),
        "A": (f32, (L, LAYOUT.cgan_audio_dim)),
        "valid": (np.dtype(bool), (L,)),
        "attributes": (f32, (L, len(ATTRIBUTE_NAMES))),
        "pose_track": (f32, (track, len(POSE_FEATURE_INDICES) * 3)),
    }
    dims = {"F": LAYOUT.audio_dim, "P": LAYOUT.pose_dim, "A": LAYOUT.cgan_audio_dim}
    for take in _checked_records(folder, _STAGE_FIELDS):
        i, n = take["index"], take["n_frames"]
        cuts = {"": (windows(n, L, L), "n_clips")}
        if config.overlap_stride:
            cuts["overlap."] = (windows(n, L, config.overlap_stride), "n_windows")
        if n < 1 or take["count"] > n:
            raise _Damaged(f"takes.json: take {i} has {n} frames and {take['count']} that start a segment")
        for prefix, (starts, count) in cuts.items():
            if take[count] != starts.shape[0]:
                raise _Damaged(f"takes.json: take {i} has {take[count]} {count[2:]}, its {n} frames give {len(starts)}")
            for k in CLIP_ARRAYS:
                dtype, row = rows[k]
                _staged_array(folder, f"{i}.{prefix}{k}.npy", dtype, (starts.shape[0], *row), finite=True)
            got = _staged_array(folder, f"{i}.{prefix}clip_start.npy", np.dtype(np.int32), starts.shape, finite=True)
            if not np.array_equal(got, starts):
                raise _Damaged(f"{i}.{prefix}clip_start.npy: does not hold the clips' start frames")
        if config.store_audio:
            storage = AudioStorage(format=config.audio_format, rate=config.audio_rate)
            _staged_array(folder, f"{i}.audio.npy", storage.dtype, (take["audio_size"],), finite=True)
        for key in MOMENT_KEYS:
            _staged_array(folder, f"{i}.moments_{key}.npy", f64, (2, dims[key]), finite=True)


def check_sampled_unit(folder: Path, config: BuildConfig) -> None:
    """Check a unit :func:`sample_job` wrote before it is reused: its record and each take's
    ``bones.npy`` (float32, a row per sample and a column per frame, finite bone lengths).

    Raises
    ------
    _Damaged
        Saying what is wrong (the unit is then read again).
    """
    from .bones import sample_rows
    from .skeleton import N_JOINTS

    for take in _checked_records(folder, _SAMPLE_FIELDS):
        i = take["index"]
        medians = take["medians"]
        if len(medians) != N_JOINTS or not all(isinstance(v, (int, float)) and np.isfinite(v) for v in medians):
            raise _Damaged(f"takes.json: take {i} has no valid bone medians")
        shape = (len(sample_rows()), take["frames"])
        samples = _staged_array(folder, f"{i}.bones.npy", np.dtype(np.float32), shape, finite=False)
        if np.isinf(samples).any() or not np.isfinite(samples[:N_JOINTS]).all():
            raise _Damaged(f"{i}.bones.npy: holds NaN or infinite bone lengths")


def _reusable(
    staging: Path, job: StageJob, check: Callable[[Path, BuildConfig], None]
) -> tuple[dict[str, Any] | None, str | None]:
    """The record of the unit ``job`` staged already and fit to reuse (or None), and why the one
    there is not (None when there is none); a damaged unit is removed."""
    folder = staging / job.key
    if not folder.exists() and not folder.is_symlink():
        return None, None
    try:
        if folder.is_symlink() or not folder.is_dir():
            raise _Damaged(f"{job.key}: not a folder")
        check(folder, job.config)
        done = staged_takes(staging, job.key)
        if done is None:  # read and checked just now: gone since
            raise _Damaged("takes.json: gone")
        return done, None
    except _Damaged as exc:
        reason = str(exc)
    record = staged_takes(staging, job.key)
    try:
        names = [t["name"] for t in record["takes"]] if record is not None else []
        what = ", ".join(f"take {n}" for n in names) if all(isinstance(n, str) for n in names) else ""
    except (TypeError, KeyError):  # a record of another shape: the unit is named by its file
        what = ""
    what = what or f"the takes of {job.source.motion.name}"
    # moved aside first, so that a removal cut short leaves a name open_staging clears
    aside = staging / f"{job.key}.tmp-damaged-{uuid.uuid4().hex[:12]}"
    os.replace(folder, aside)
    if aside.is_dir() and not aside.is_symlink():
        shutil.rmtree(aside, ignore_errors=True)
    else:
        aside.unlink()
    return None, f"{what}: staged copy damaged ({reason}), staged again"


def stage_job(job: StageJob) -> dict[str, Any]:
    """Stage one unit (the function a worker process or a cluster worker runs).

    A unit already staged (by an earlier, interrupted build) is not read again.

    Returns
    -------
    dict
        ``takes`` (the records of :func:`stage_take`), ``warnings`` (the
        messages reading and featurising issued), ``reused`` (whether the unit
        was staged already), ``damaged`` (a line saying that a staged copy was
        damaged and why, when it was staged again; else None).
    """

    def stage(take: Take, folder: Path, index: int) -> dict[str, Any]:
        return stage_take(take, folder, index, job.config)

    return _run_unit(job, stage, check_staged_unit, keep_warnings=True)


def sample_job(job: StageJob) -> dict[str, Any]:
    """Read one unit's takes for fitting a skeleton (``--normalize-bones``): each take's
    :func:`gesturekit.bones.bone_samples` as ``INDEX.bones.npy`` (rows, frames) float32.

    ``job.reading`` reads the takes without normalising them. A unit done already (by an
    interrupted build) is not read again; the warnings of reading are dropped (they are given
    when the takes are read again to be staged).

    Returns
    -------
    dict
        ``takes``: per take ``index``, ``name``, ``frames``, ``seconds``, ``joints`` (as
        :func:`stage_take`'s record) and ``medians`` (the median length of each of the 55 bones, metres);
        ``warnings`` (empty); ``reused``.
    """
    from .bones import bone_samples
    from .skeleton import N_JOINTS

    def sample(take: Take, folder: Path, index: int) -> dict[str, Any]:
        samples = bone_samples(take.motion.positions)
        _save(folder / f"{index}.bones.npy", samples)
        presence = take.motion.presence
        return {
            "index": index,
            "name": take.name,
            "frames": int(samples.shape[1]),
            "seconds": samples.shape[1] / float(take.motion.fps),
            "joints": None if presence.is_full else presence.to_list(),
            "medians": [float(v) for v in np.median(samples[:N_JOINTS].astype(np.float64), axis=1)],
        }

    return _run_unit(job, sample, check_sampled_unit, keep_warnings=False)


def _run_unit(
    job: StageJob,
    per_take: Callable[[Take, Path, int], dict[str, Any]],
    check: Callable[[Path, BuildConfig], None],
    *,
    keep_warnings: bool,
) -> dict:
    """Read the takes of a unit and write what ``per_take`` makes of each into the unit's folder,
    complete or not at all (a temporary folder renamed when done). A unit staged already is reused
    when ``check`` finds it whole, else removed and staged again (``damaged`` says why)."""
    from .datasets.takes import iter_takes
    from .outputs import write_errors

    staging = Path(job.staging)
    done, damaged = _reusable(staging, job, check)
    if done is not None:
        return {**done, "reused": True, "damaged": None}
    tmp = staging / f"{job.key}.tmp-{uuid.uuid4().hex[:12]}"
    tmp.mkdir()
    try:
        records: list[dict[str, Any]] = []
        with collect_warnings() as messages:
            for take in iter_takes([job.source], **job.reading):
                if take.name in job.skip or (job.only is not None and take.name not in job.only):
                    continue
                records.append(per_take(take, tmp, len(records)))
        result = {"takes": records, "warnings": list(messages) if keep_warnings else []}
        with write_errors(tmp / "takes.json"):
            (tmp / "takes.json").write_text(json.dumps(result), encoding="utf-8")
        os.replace(tmp, staging / job.key)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {**result, "reused": False, "damaged": damaged}
