"""Checking a staged unit before a resumed build reuses it (:mod:`gesturekit.database.stage`).

A unit an interrupted build left is reused only when it is whole: its
``takes.json`` a record of the right fields, and every array of each take a
regular ``.npy`` file, complete, of the dtype and shape the take's frame count
gives, with no NaN or infinite value. Anything else is a :class:`DamagedUnit`
saying what is wrong, and the unit is staged again.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError, GestureKitError
from ..features import LAYOUT
from ..limits import check_regular, npy_header, read_json
from ..skeleton import POSE_FEATURE_INDICES
from .audio import AudioStorage
from .clips import MOMENT_KEYS, windows
from .config import BuildConfig
from .folder import CLIP_ARRAYS

__all__ = ["DamagedUnit", "check_staged_unit", "check_sampled_unit"]

#: Fields of a staged take's record (:func:`~gesturekit.database.stage.stage_take`) and of a sampled take's
#: (:func:`~gesturekit.database.stage.sample_job`).
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


class DamagedUnit(Exception):
    """A staged unit that cannot be reused; the message says why."""


def _staged_array(folder: Path, name: str, dtype: np.dtype, shape: tuple[int, ...], *, finite: bool) -> np.ndarray:
    """The staged array ``folder/name`` when it is a regular ``.npy`` file of ``dtype`` and ``shape``,
    complete, and (with ``finite``, for floats) without NaN or infinite values.

    Raises
    ------
    DamagedUnit
        Saying which file and what is wrong with it.
    """
    path = folder / name
    try:
        size = check_regular(path, error=ConfigError)
        with open(path, "rb") as f:
            got_shape, got_dtype, offset = npy_header(f, path=path)
    except (GestureKitError, OSError) as exc:
        problem = exc.problem if isinstance(exc, GestureKitError) else (exc.strerror or str(exc))
        raise DamagedUnit(f"{name}: {problem}") from None
    if got_dtype != dtype or got_shape != shape:
        raise DamagedUnit(f"{name}: holds {got_dtype} {got_shape}, expected {np.dtype(dtype)} {shape}")
    expected = offset + int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    if size != expected:
        raise DamagedUnit(f"{name}: has {size} bytes, expected {expected} (truncated or appended to)")
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise DamagedUnit(f"{name}: cannot be read ({exc})") from None
    if finite and array.dtype.kind == "f" and not np.isfinite(array).all():
        raise DamagedUnit(f"{name}: holds NaN or infinite values")
    return array


def _checked_records(folder: Path, fields: dict[str, Any]) -> list[dict[str, Any]]:
    """The take records of the staged unit ``folder`` (its ``takes.json``), each with ``fields``."""
    try:
        record = read_json(folder / "takes.json")
    except GestureKitError as exc:
        raise DamagedUnit(f"takes.json: {exc.problem}") from None
    if not isinstance(record, dict):
        raise DamagedUnit("takes.json: not a staged unit's record (no list of takes and warnings)")
    takes, messages = record.get("takes"), record.get("warnings")
    if not isinstance(takes, list) or not isinstance(messages, list):
        raise DamagedUnit("takes.json: not a staged unit's record (no list of takes and warnings)")
    for i, take in enumerate(takes):
        if not isinstance(take, dict) or take.get("index") != i:
            raise DamagedUnit(f"takes.json: take {i} is not a take's record")
        for key, kind in fields.items():
            value = take.get(key)
            if not isinstance(value, kind) or isinstance(value, bool) or (kind is int and value < 0):
                raise DamagedUnit(f"takes.json: take {i} has no valid {key!r}")
    if not all(isinstance(w, str) for w in messages):
        raise DamagedUnit("takes.json: its warnings are not text")
    return takes


@checks_arguments
def check_staged_unit(folder: Path, config: BuildConfig) -> None:
    """Check a unit :func:`~gesturekit.database.stage.stage_job` staged before it is reused: its
    record, and every array of each take present, a regular file, complete, of the dtype and shape
    the take's frame count gives, the clips' starts where the take's cut puts them, and no NaN or
    infinite value.

    Raises
    ------
    DamagedUnit
        Saying what is wrong (the unit is then staged again).
    """
    from ..control import ATTRIBUTE_NAMES

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
            raise DamagedUnit(f"takes.json: take {i} has {n} frames and {take['count']} that start a segment")
        for prefix, (starts, count) in cuts.items():
            if take[count] != starts.shape[0]:
                raise DamagedUnit(
                    f"takes.json: take {i} has {take[count]} {count[2:]}, its {n} frames give {len(starts)}"
                )
            for k in CLIP_ARRAYS:
                dtype, row = rows[k]
                _staged_array(folder, f"{i}.{prefix}{k}.npy", dtype, (starts.shape[0], *row), finite=True)
            got = _staged_array(folder, f"{i}.{prefix}clip_start.npy", np.dtype(np.int32), starts.shape, finite=True)
            if not np.array_equal(got, starts):
                raise DamagedUnit(f"{i}.{prefix}clip_start.npy: does not hold the clips' start frames")
        if config.store_audio:
            storage = AudioStorage(format=config.audio_format, rate=config.audio_rate)
            _staged_array(folder, f"{i}.audio.npy", storage.dtype, (take["audio_size"],), finite=True)
        for key in MOMENT_KEYS:
            _staged_array(folder, f"{i}.moments_{key}.npy", f64, (2, dims[key]), finite=True)


@checks_arguments
def check_sampled_unit(folder: Path, config: BuildConfig) -> None:
    """Check a unit :func:`~gesturekit.database.stage.sample_job` wrote before it is reused: its record and each take's
    ``bones.npy`` (float32, a row per sample and a column per frame, finite bone lengths).

    Raises
    ------
    DamagedUnit
        Saying what is wrong (the unit is then read again).
    """
    from ..bones import sample_rows
    from ..skeleton import N_JOINTS

    for take in _checked_records(folder, _SAMPLE_FIELDS):
        i = take["index"]
        medians = take["medians"]
        if len(medians) != N_JOINTS or not all(isinstance(v, (int, float)) and np.isfinite(v) for v in medians):
            raise DamagedUnit(f"takes.json: take {i} has no valid bone medians")
        shape = (len(sample_rows()), take["frames"])
        samples = _staged_array(folder, f"{i}.bones.npy", np.dtype(np.float32), shape, finite=False)
        if np.isinf(samples).any() or not np.isfinite(samples[:N_JOINTS]).all():
            raise DamagedUnit(f"{i}.bones.npy: holds NaN or infinite bone lengths")
