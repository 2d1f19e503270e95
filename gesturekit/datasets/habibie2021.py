"""The npz layout of Habibie et al. 2021, the data the paper's database was built from.

One ``.npz`` archive holds many fixed-length sequences of one speaker:

``wav``
    Speech, shape (sequences, samples) (or (sequences, samples, 1)), mono at
    16 kHz; float in [-1, 1] or int16.
``body``
    Joint positions, shape (sequences, frames, 165) (or (sequences, frames,
    55, 3)), 15 fps, pelvis-relative, in the joint order of
    :data:`gesturekit.skeleton.JOINT_NAMES` unless a ``joint_order`` is given.
``mfcc`` (optional)
    Precomputed audio features, shape (sequences, frames, coefficients); only
    its shape is checked (gesturekit computes its own features).
``joint_order`` (optional)
    Integer permutation of 0..54: our joint ``i`` is the file's joint
    ``joint_order[i]``.

Each sequence becomes one :class:`~gesturekit.motion.Take`.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .. import limits
from .._arguments import checks_arguments
from ..errors import ConfigError, MotionFileError, warn
from ..motion import AUDIO_SR, Motion, Take
from ..paths import is_file
from ..skeleton import FPS, N_JOINTS

__all__ = ["load_habibie2021", "is_habibie2021_npz", "count_sequences"]

# what a damaged archive raises while it is opened or read
_READ_ERRORS = (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error)

_UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}


@checks_arguments
def load_habibie2021(
    path: str | os.PathLike, *, units: str = "m", joint_order: np.ndarray | list[int] | None = None
) -> list[Take]:
    """Read an npz archive in the layout of Habibie et al. 2021 as takes.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.npz`` archive (see the module docstring for its keys).
    units : {"m", "cm", "mm"}
        Length unit of ``body``.
    joint_order : array of int, shape (55,), optional
        Our joint ``i`` is the file's joint ``joint_order[i]``; overrides a
        ``joint_order`` array stored in the file. Default: the file's, or the
        identity.

    Returns
    -------
    list of Take
        One per sequence, named ``f"{stem}_{i:04d}"``, with a
        :class:`~gesturekit.motion.Motion` of shape (frames, 55, 3) in metres
        at 15 fps, float32 audio at 16 kHz, and ``sources={"file": path,
        "sequence": i}``. Where motion and audio lengths differ by more than
        half a frame both are trimmed to the shorter and one
        :class:`~gesturekit.errors.GestureKitWarning` says by how much.

    Raises
    ------
    MotionFileError
        The file is missing, not an npz archive, lacks ``wav`` or ``body``,
        has arrays of the wrong shape or type, NaN/infinite values, or an
        invalid ``joint_order``.
    ConfigError
        Invalid ``units`` or ``joint_order`` argument.
    InputFileError
        The arrays' headers state sequences longer than one take may be, or
        more memory than one input may take (:mod:`gesturekit.limits`),
        checked before the arrays are loaded.
    """
    if units not in _UNIT_SCALE:
        raise ConfigError(f"units must be 'm', 'cm' or 'mm', got {units!r}")
    path = Path(path)
    if not is_file(path):
        raise MotionFileError("file not found", path=path)
    _check_limits(path)
    arrays = _read_npz(path)
    wav, body = arrays["wav"], arrays["body"]

    if wav.ndim == 3 and wav.shape[2] == 1:
        wav = wav[:, :, 0]
    if wav.ndim != 2:
        raise MotionFileError(f"'wav' must have shape (sequences, samples), got {wav.shape}", path=path)
    if body.ndim == 4 and body.shape[2:] == (N_JOINTS, 3):
        body = body.reshape(body.shape[0], body.shape[1], N_JOINTS * 3)
    if body.ndim != 3 or body.shape[2] != N_JOINTS * 3:
        raise MotionFileError(
            f"'body' must have shape (sequences, frames, {N_JOINTS * 3}), got {body.shape}", path=path
        )
    n_seq = body.shape[0]
    if wav.shape[0] != n_seq:
        raise MotionFileError(f"'wav' has {wav.shape[0]} sequences but 'body' has {n_seq}", path=path)
    if n_seq == 0 or body.shape[1] == 0 or wav.shape[1] == 0:
        raise MotionFileError(f"no data: 'body' has shape {body.shape} and 'wav' has shape {wav.shape}", path=path)
    if "mfcc" in arrays:
        mfcc = arrays["mfcc"]
        if mfcc.ndim != 3 or mfcc.shape[0] != n_seq:
            raise MotionFileError(
                f"'mfcc' must have shape ({n_seq}, frames, coefficients), got {mfcc.shape}", path=path
            )

    audio = _audio_float32(wav, path)
    motion = _numeric(body, "body", path).reshape(n_seq, body.shape[1], N_JOINTS, 3)
    order = _joint_order(joint_order, arrays.get("joint_order"), path)
    if order is not None:
        motion = motion[:, :, order]
    motion = motion * _UNIT_SCALE[units]
    _check_finite(motion, "body", path)
    _check_finite(audio, "wav", path)

    n_frames, n_samples = body.shape[1], audio.shape[1]
    frames, samples, gap = _aligned_lengths(n_frames, n_samples)
    if frames == 0:
        raise MotionFileError(f"the audio ({n_samples} samples) is shorter than one motion frame", path=path)
    if gap is not None:
        longer = "motion" if gap > 0 else "audio"
        warn(
            f"{path}: motion ({n_frames} frames, {n_frames / FPS:.3f} s) and audio "
            f"({n_samples} samples, {n_samples / AUDIO_SR:.3f} s) differ by {abs(gap):.3f} s in all "
            f"{n_seq} sequences; the {longer} was trimmed to the shorter",
            stacklevel=2,
        )
    stem = path.stem
    return [
        Take(
            name=f"{stem}_{i:04d}",
            motion=Motion(motion[i, :frames].astype(np.float32), float(FPS)),
            audio=np.ascontiguousarray(audio[i, :samples]),
            sources={"file": os.fspath(path), "sequence": i},
        )
        for i in range(n_seq)
    ]


def _open_npz(path: Path):
    try:
        loaded = np.load(path, allow_pickle=False)
    except _READ_ERRORS as exc:
        raise MotionFileError(f"not a readable npz archive ({exc}); is the file truncated?", path=path) from None
    return loaded


@checks_arguments
def is_habibie2021_npz(path: str | os.PathLike) -> bool:
    """Whether an ``.npz`` file holds the arrays ``wav`` and ``body`` (reads the archive's index only).

    Raises
    ------
    MotionFileError
        The file is not a readable npz archive (e.g. truncated).
    """
    path = Path(path)
    loaded = _open_npz(path)
    if not isinstance(loaded, np.lib.npyio.NpzFile):
        return False
    with loaded as npz:
        return "wav" in npz.files and "body" in npz.files


@checks_arguments
def count_sequences(path: str | os.PathLike) -> int:
    """Sequences (takes) of an archive, from the ``body`` array's header alone (no data is read).

    Raises
    ------
    MotionFileError
        Not a readable npz archive, no ``body``, or a ``body`` that is not a plain numeric
        array (an object array would need unpickling, which gesturekit never does).
    """
    from ..limits import npz_headers

    path = Path(path)
    headers = npz_headers(path)
    if "body" not in headers:
        raise MotionFileError("missing key body", path=path)
    shape, dtype = headers["body"]
    if dtype.hasobject:
        raise MotionFileError(
            "'body' holds Python objects (dtype object); gesturekit reads numbers only and never unpickles", path=path
        )
    return int(shape[0]) if len(shape) >= 3 else 1


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    loaded = _open_npz(path)
    if not isinstance(loaded, np.lib.npyio.NpzFile):
        raise MotionFileError("expected an npz archive with keys 'wav' and 'body', found a single array", path=path)
    with loaded as npz:
        keys = set(npz.files)
        missing = [k for k in ("wav", "body") if k not in keys]
        if missing:
            raise MotionFileError(
                f"missing key(s) {', '.join(missing)}; the archive has {', '.join(sorted(keys)) or 'no arrays'}",
                path=path,
            )
        try:
            return {k: npz[k] for k in ("wav", "body", "mfcc", "joint_order") if k in keys}
        except _READ_ERRORS as exc:
            # object arrays land here too: allow_pickle=False refuses them
            raise MotionFileError(f"cannot read the archive's arrays ({exc})", path=path) from None


def _check_limits(path: Path) -> None:
    """Refuse, from the arrays' npy headers, sequences or an archive beyond the limits, before loading.

    A sequence is a take: ``body`` frames at 15 fps and ``wav`` samples at
    16 kHz must fit :func:`gesturekit.limits.max_take_seconds`; all arrays,
    converted to float64 (body) and float32 (wav), must fit one input's memory.
    Headers that cannot be read are left to the loader to report.
    """
    try:
        headers = limits.npz_headers(path)
    except MotionFileError:
        return
    rates = {"body": (FPS, "frames", 8), "wav": (AUDIO_SR, "samples", 4)}
    total = 0.0
    for key, (shape, dtype) in headers.items():
        per, unit, converted = rates.get(key, (None, None, 0))
        total += limits.array_bytes(shape, dtype.itemsize + converted)
        if per is not None and len(shape) >= 2:
            limits.check_duration(
                shape[1] / per,
                path=path,
                what=f"the npz header of {key!r} says {shape[1]} {unit} per sequence at {per} Hz",
            )
    limits.check_bytes(
        total, what=f"the npz headers say {', '.join(f'{k} {v[0]}' for k, v in headers.items())}", path=path
    )


def _numeric(array: np.ndarray, key: str, path: str | os.PathLike | None) -> np.ndarray:
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise MotionFileError(f"'{key}' must hold numbers, got dtype {array.dtype}", path=path)
    return array.astype(np.float64, copy=False)


def _audio_float32(wav: np.ndarray, path: str | os.PathLike | None) -> np.ndarray:
    """Speech as float32 in [-1, 1]: int16 is scaled, floats are kept."""
    if wav.dtype == np.int16:
        return wav.astype(np.float32) / 32768.0
    if not np.issubdtype(wav.dtype, np.floating):
        raise MotionFileError(f"'wav' must be float or int16 samples, got dtype {wav.dtype}", path=path)
    return wav.astype(np.float32, copy=False)


def _check_finite(array: np.ndarray, key: str, path: str | os.PathLike | None) -> None:
    finite = np.isfinite(array).reshape(array.shape[0], -1).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise MotionFileError(
            f"'{key}' contains NaN or infinity in {bad.size} sequences (first: sequence {bad[0]})", path=path
        )


def _joint_order(
    argument: Sequence[int] | np.ndarray | None, stored: np.ndarray | None, path: str | os.PathLike | None
) -> np.ndarray | None:
    """The validated permutation, or None for the identity."""
    if argument is not None:
        order, source = np.asarray(argument), "joint_order argument"
    elif stored is not None:
        order, source = stored, "'joint_order' in the file"
    else:
        return None
    valid = (
        order.shape == (N_JOINTS,)
        and np.issubdtype(order.dtype, np.integer)
        and np.array_equal(np.sort(order), np.arange(N_JOINTS))
    )
    if not valid:
        message = f"{source} must be a permutation of 0..{N_JOINTS - 1}, got shape {order.shape}"
        if argument is not None:
            raise ConfigError(message)
        raise MotionFileError(message, path=path)
    return order.astype(np.int64)


def _aligned_lengths(n_frames: int, n_samples: int) -> tuple[int, int, float | None]:
    """Frames and samples to keep, and the gap in seconds (motion minus audio) if one was trimmed.

    Lengths within half a frame of each other count as equal: the motion is
    kept whole and the audio cut to the motion's duration at most.
    """
    gap = n_frames / FPS - n_samples / AUDIO_SR
    if abs(gap) <= 0.5 / FPS:
        return n_frames, min(n_samples, round(n_frames * AUDIO_SR / FPS)), None
    frames = min(n_frames, int(np.floor(n_samples * FPS / AUDIO_SR + 1e-9)))
    samples = min(n_samples, round(frames * AUDIO_SR / FPS))
    return frames, samples, gap
