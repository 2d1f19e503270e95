"""Joint-position files (.npy, .npz, .txt, .csv) as 55-joint motions.

A position file holds an array of shape (frames, joints, 3) or
(frames, joints * 3) in some source joint order. A position joint map says
which source joint is each of ours and which is the pelvis:

.. code-block:: json

    {"pelvis": 0,
     "joints": {"neck": 0, "left_shoulder": "LShoulder", "spine_mid": null, ...},
     "names": ["Neck", "LShoulder", ...]}

Joints are given by column index (0-based, in joints) or by name; names need
the optional ``"names"`` list (one per source joint). ``"pelvis"`` may be
``null`` when the positions are already relative to a root (the pelvis, or the
neck of keypoints lifted from video). A map may leave joints out, or map them
to ``null``, as long as it has the joints the matching needs
(:data:`gesturekit.skeleton.REQUIRED_JOINTS`); the torso, head and collars a
source lacks are derived from the neck and shoulders, other joints it lacks are
absent (see :mod:`gesturekit.datasets._partial`). Axes and units are converted
to ours (:mod:`gesturekit.datasets._axes`). Positions are resampled to 15 fps
by linear interpolation (:func:`gesturekit.motion.resample_positions`), which
shortens bones slightly between samples when the source rate is not a multiple
of 15.
"""

from __future__ import annotations

import math
import os
import warnings
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import NoReturn

import numpy as np

from .. import limits
from .._arguments import checks_arguments
from ..errors import ConfigError, InputFileError, MotionFileError
from ..motion import Motion, resample_positions
from ..paths import is_file
from ..skeleton import FPS, JOINT_NAMES, joint_index, missing_required
from ._axes import UNIT_SCALE, check_axes_options, check_skeleton
from ._reading import Reading, convert_and_complete
from .presets import missing_and_unknown

__all__ = [
    "POSITION_EXTENSIONS",
    "PositionJointMap",
    "load_position_joint_map",
    "read_position_array",
    "load_positions_motion",
    "read_positions_take",
]

#: The files a folder of takes is searched for as joint-position takes.
POSITION_EXTENSIONS = (".npy", ".npz", ".txt", ".csv")


@dataclass(frozen=True)
class PositionJointMap:
    """Which source column is each of our joints, for position files.

    Parameters
    ----------
    name : str
        Where the map came from (a file path or ``"joint map"``), for messages.
    pelvis : int, str or None
        Source joint (index or name) subtracted from every joint; ``None`` when
        the positions are already pelvis-relative.
    joints : Mapping[str, int or str or None]
        Our joint name -> source joint index or name; joints left out or
        ``None`` are not in the source.
    names : tuple of str or None
        Source joint names, one per source joint, needed to resolve names.
    """

    name: str
    pelvis: int | str | None
    joints: Mapping[str, int | str | None]
    names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "joints", MappingProxyType({k: v for k, v in self.joints.items() if v is not None}))
        if self.names is not None:
            object.__setattr__(self, "names", tuple(self.names))

    def resolve(self, n_source: int, *, path: str | os.PathLike[str] | None = None) -> tuple[np.ndarray, int | None]:
        """Source indices of our 55 joints (shape (55,), 0 for joints not mapped) and of the pelvis (or None).

        Raises
        ------
        MotionFileError
            A name or index does not exist among the ``n_source`` source joints
            of the file at ``path``, or ``names`` has the wrong length.
        """
        if self.names is not None and len(self.names) != n_source:
            raise MotionFileError(
                f"joint map {self.name!r} lists {len(self.names)} source joint names "
                f"but the file has {n_source} joints",
                path=path,
            )
        lookup = {} if self.names is None else {n: i for i, n in enumerate(self.names)}
        problems: list[str] = []

        def one(label: str, ref: int | str) -> int:
            if isinstance(ref, str):
                if self.names is None:
                    problems.append(f"{label} -> {ref!r} (a name, but the map has no 'names' list)")
                    return 0
                if ref not in lookup:
                    problems.append(f"{label} -> {ref!r} (no such source joint)")
                    return 0
                return lookup[ref]
            if not 0 <= ref < n_source:
                problems.append(f"{label} -> {ref} (index out of range for {n_source} joints)")
                return 0
            return ref

        refs = {n: r for n, r in self.joints.items() if r is not None}
        idx = np.array([one(n, refs[n]) if n in refs else 0 for n in JOINT_NAMES], dtype=np.int64)
        pelvis = None if self.pelvis is None else one("pelvis", self.pelvis)
        if problems:
            raise MotionFileError(f"joint map {self.name!r} does not fit the file: {'; '.join(problems)}", path=path)
        return idx, pelvis

    @property
    def recorded(self) -> np.ndarray:
        """Shape (55,) bool: our joints the map takes from the source."""
        return np.array([n in self.joints for n in JOINT_NAMES], dtype=bool)


@checks_arguments
def load_position_joint_map(spec: str | os.PathLike[str] | Mapping | PositionJointMap) -> PositionJointMap:
    """A position joint map from a JSON file or a dict.

    The map may leave out joints or map them to ``null``, but must map the
    joints :data:`gesturekit.skeleton.REQUIRED_JOINTS` lists.

    Parameters
    ----------
    spec : str, os.PathLike, Mapping or PositionJointMap
        A path to a JSON file ``{"pelvis": int|str|null, "joints": {...},
        "names": [...]}`` (see the module docstring), such a dict, or a map.

    Raises
    ------
    InputFileError
        The JSON file is missing, not JSON, or not a sound map (the message
        names the file and lists unknown joints, bad values, and the required
        joints missing, per need).
    ConfigError
        A dict that is not a sound map.
    """
    if isinstance(spec, PositionJointMap):
        spec = {
            "pelvis": spec.pelvis,
            "joints": dict(spec.joints),
            **({} if spec.names is None else {"names": list(spec.names)}),
        }
        return _validate(spec, name="joint map", path=None)
    if isinstance(spec, Mapping):
        return _validate(spec, name="joint map", path=None)
    if not isinstance(spec, (str, os.PathLike)):
        raise ConfigError(f"a position joint map must be a JSON file or a dict, got {type(spec).__name__}")
    path = Path(spec)
    if not is_file(path):
        raise InputFileError("joint map file not found", path=path)
    content = limits.read_json(path, what="joint map ", encoding="utf-8-sig")
    return _validate(content, name=os.fspath(path), path=path)


def _is_index(v: object) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _validate(content: object, *, name: str, path: Path | None) -> PositionJointMap:
    def fail(message: str) -> NoReturn:
        if path is not None:
            raise InputFileError(message, path=path)
        raise ConfigError(f"{name}: {message}")

    if not isinstance(content, Mapping):
        fail("a position joint map must be a JSON object with keys 'pelvis', 'joints' and optionally 'names'")
    extra = sorted(str(k) for k in set(content) - {"pelvis", "joints", "names"})
    if extra:
        fail(f"unexpected keys {extra}; a position joint map has 'pelvis', 'joints' and 'names'")
    if "pelvis" not in content:
        fail("'pelvis' is required (a source joint index or name, or null if already pelvis-relative)")
    pelvis = content["pelvis"]
    if not (pelvis is None or _is_index(pelvis) or (isinstance(pelvis, str) and pelvis)):
        fail(f"'pelvis' must be a joint index, a joint name or null, got {pelvis!r}")
    joints = content.get("joints")
    if not isinstance(joints, Mapping):
        fail("'joints' must map each of our joint names to a source joint index or name")
    names = content.get("names")
    if names is not None and not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
        fail("'names' must be a list of source joint names")
    if names is not None and len(set(names)) != len(names):
        fail("'names' has duplicates")
    _, unknown = missing_and_unknown(joints)
    problems = []
    if unknown:
        problems.append(f"not joints of our skeleton: {', '.join(unknown)}")
    bad = sorted(
        str(k) for k, v in joints.items() if not (v is None or _is_index(v) or (isinstance(v, str) and bool(v)))
    )
    if bad:
        problems.append(f"values must be joint indices, names or null: {', '.join(bad)}")
    mapped = [k for k, v in joints.items() if v is not None]
    lack = missing_required(mapped)
    if lack:
        problems.append(f"joints gesturekit needs are not mapped: {'; '.join(lack)}")
    if problems:
        fail("; ".join(problems))
    return PositionJointMap(
        name=name, pelvis=pelvis, joints=dict(joints), names=None if names is None else tuple(names)
    )


@checks_arguments
def read_position_array(path: str | os.PathLike, *, fps: float | None = None) -> np.ndarray:
    """Read joint positions from a file, shape (frames, joints, 3), float64.

    For ``.npy`` and ``.npz`` the array's shape and type are read from its
    header first, and an array of the wrong shape, or beyond the limits of one
    take or one input (:mod:`gesturekit.limits`), is refused before it is loaded.
    Text files are refused when the numbers they may hold (one per 2 bytes)
    could exceed the input limit.

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy`` (one array), ``.npz`` (a single array, or the key
        ``"positions"``), ``.txt`` (whitespace-separated) or ``.csv``
        (comma-separated) with one frame per row. Arrays of shape
        (frames, joints * 3) are reshaped.
    fps : float, optional
        Frame rate of the file, frames per second; with it the duration the
        header states is checked against the limit of one take.

    Raises
    ------
    MotionFileError
        Missing or unreadable file, unknown suffix, wrong shape, no frames,
        non-numeric or NaN/infinite values.
    InputFileError
        The header states more frames or bytes than the limits allow.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in POSITION_EXTENSIONS:
        raise MotionFileError(
            f"unsupported position file type {suffix!r} (expected {', '.join(POSITION_EXTENSIONS)})", path=path
        )
    if not path.is_file():
        raise MotionFileError("file not found", path=path)
    size = path.stat().st_size
    if size == 0:
        raise MotionFileError("empty file", path=path)
    if suffix in (".npy", ".npz"):
        _check_header(path, suffix, size, fps)
    else:
        # a number and its separator take at least 2 bytes of text and 8 once read
        limits.check_bytes(4.0 * size, what=f"the text file of {size} bytes may hold {size // 2} numbers", path=path)
    try:
        if suffix == ".npy":
            array = np.load(path, allow_pickle=False)
        elif suffix == ".npz":
            array = _from_npz(path)
        else:
            with warnings.catch_warnings():
                # a text file of blank lines: reported below as "no frames"
                warnings.simplefilter("ignore", UserWarning)
                array = np.loadtxt(path, delimiter="," if suffix == ".csv" else None, dtype=np.float64, ndmin=2)
    except MotionFileError:
        raise
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise MotionFileError(f"cannot read positions: {exc}", path=path) from None
    array = np.asarray(array)
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise MotionFileError(f"positions must be numbers, got dtype {array.dtype}", path=path)
    if array.ndim >= 1 and array.shape[0] == 0:
        raise MotionFileError("the file has no frames", path=path)
    if array.ndim == 2 and array.shape[1] % 3 == 0:
        array = array.reshape(array.shape[0], array.shape[1] // 3, 3)
    if array.ndim != 3 or array.shape[2] != 3 or array.shape[1] == 0:
        raise MotionFileError(
            f"positions must have shape (frames, joints, 3) or (frames, joints*3), got {array.shape}", path=path
        )
    array = array.astype(np.float64)
    finite = np.isfinite(array).all(axis=(1, 2))
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise MotionFileError(
            f"positions contain NaN or infinity in {bad.size} frames (first: frame {bad[0]})", path=path
        )
    return array


def _check_header(path: Path, suffix: str, size: int, fps: float | None) -> None:
    """Refuse, from the npy header, an array of the wrong shape or beyond the limits."""
    if suffix == ".npy":
        with open(path, "rb") as f:
            shape, dtype, offset = limits.npy_header(f, path=path)
        what = "the npy header says"
    else:
        headers = limits.npz_headers(path)
        key = "positions" if "positions" in headers else (next(iter(headers)) if len(headers) == 1 else None)
        if key is None:
            return  # reported when read
        shape, dtype = headers[key]
        what = f"the npz header of {key!r} says"
    if dtype.hasobject:
        raise MotionFileError(
            f"cannot read positions stored as Python objects ({what} dtype {dtype}); they must be numbers", path=path
        )
    if dtype.kind not in "biuf":
        raise MotionFileError(f"positions must be numbers, {what} dtype {dtype}", path=path)
    flat_ok = len(shape) == 2 and shape[1] % 3 == 0 and shape[1] > 0
    if not (flat_ok or (len(shape) == 3 and shape[2] == 3 and shape[1] > 0)) and not (shape and shape[0] == 0):
        raise MotionFileError(
            f"positions must have shape (frames, joints, 3) or (frames, joints*3), {what} {shape}", path=path
        )
    # float64 after conversion, and the array as stored
    limits.check_bytes(
        limits.array_bytes(shape, 8 + dtype.itemsize), what=f"{what} shape {shape} of {dtype}", path=path
    )
    if fps is not None and shape:
        limits.check_duration(shape[0] / fps, what=f"{what} {shape[0]} frames at {fps:g} fps", path=path)
    if suffix == ".npy":
        stored = limits.array_bytes(shape, dtype.itemsize)
        if offset + stored > size:
            raise MotionFileError(
                f"the file is truncated: the npy header says shape {shape} of {dtype} "
                f"({limits.describe_bytes(stored)}) but only {size - offset} bytes follow",
                path=path,
            )


def _from_npz(path: Path) -> np.ndarray:
    with np.load(path, allow_pickle=False) as npz:
        keys = list(npz.files)
        if "positions" in keys:
            return npz["positions"]
        if len(keys) == 1:
            return npz[keys[0]]
        raise MotionFileError(
            f"npz holds {len(keys)} arrays ({', '.join(keys) or 'none'}); expected one array or one named 'positions'",
            path=path,
        )


@checks_arguments
def load_positions_motion(
    path: str | os.PathLike[str],
    *,
    joint_map: str | os.PathLike[str] | Mapping | PositionJointMap,
    fps: float,
    units: str = "m",
    up: str | None = None,
    forward: str = "auto",
    check_plausible: bool = True,
) -> Motion:
    """Read a joint-position file as a 55-joint motion at 15 fps (see :func:`read_positions_take`)."""
    return read_positions_take(
        path, joint_map=joint_map, fps=fps, units=units, up=up, forward=forward, check_plausible=check_plausible
    )[0]


@checks_arguments
def read_positions_take(
    path: str | os.PathLike[str],
    *,
    joint_map: str | os.PathLike[str] | Mapping | PositionJointMap,
    fps: float,
    units: str = "auto",
    up: str | None = None,
    forward: str = "auto",
    check_plausible: bool = True,
) -> tuple[Motion, Reading]:
    """Read a joint-position file as a 55-joint motion at 15 fps, and say how it was read.

    Parameters
    ----------
    path : str or os.PathLike
        Positions of shape (frames, joints, 3) or (frames, joints*3)
        (see :func:`read_position_array`).
    joint_map : str, os.PathLike, Mapping or PositionJointMap
        The position joint map (see :func:`load_position_joint_map`).
    fps : float
        Frame rate of the file, frames per second.
    units : {"auto", "m", "cm", "mm"}
        Length unit of the file; ``auto`` picks the one in which the shoulder
        width and upper arms have a human size.
    up : {"y", "-y", "z", "-z"} or None
        The file's up axis. ``None``: Y, and the data must look upright
        (:func:`gesturekit.datasets._axes.check_upright`).
    forward : {"auto", "x", "-x", "y", "-y", "z", "-z"}
        The axis the body faces; ``auto`` takes it from the shoulders.
    check_plausible : bool
        Refuse what no human body gives, naming it: a given ``units`` or ``up`` that does not fit
        the data (:func:`gesturekit.datasets._axes.check_given_units`,
        :func:`~gesturekit.datasets._axes.check_given_up`); a map that reads two body joints (or
        the pelvis and a joint) from one column, or whose skeleton is no human's
        (:func:`~gesturekit.datasets._axes.check_skeleton`); frames with joints far from the body
        (:func:`check_outlier_frames`). False reads the data as it is.

    Returns
    -------
    motion : Motion
        Positions of shape (frames_out, 55, 3), metres, Y up, facing +Z,
        relative to the pelvis (if the map names one), at 15 fps, with the
        joints the source lacks derived or absent (``motion.joints``);
        ``frames_out = floor(frames / fps * 15)``.
    reading : Reading
        The axes, units and joints used.

    Raises
    ------
    MotionFileError
        The file is unreadable, malformed, too short for one output frame,
        does not have the joints the map names, is not upright (without
        ``up``), or has no human size in any unit (``units="auto"``).
    ConfigError, InputFileError
        Bad options or joint map; ``fps`` outside the accepted range, or a
        header beyond the limits (:mod:`gesturekit.limits`).
    """
    check_axes_options(up, forward, units)
    if not (isinstance(fps, (int, float, np.integer, np.floating)) and math.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps must be a positive number, got {fps!r}")
    limits.check_fps(fps, what="the frame rate of the position file", option="fps")
    jmap = load_position_joint_map(joint_map)
    array = read_position_array(path, fps=float(fps))
    idx, pelvis = jmap.resolve(array.shape[1], path=path)
    recorded = jmap.recorded
    columns = {n: _column(jmap, int(i)) for n, i, r in zip(JOINT_NAMES, idx, recorded, strict=True) if r}
    if pelvis is not None:
        columns["pelvis"] = _column(jmap, pelvis)
    if check_plausible:
        _check_distinct_sources(idx, recorded, pelvis, columns, path)
    positions = array[:, idx]
    if pelvis is not None:
        positions = positions - array[:, pelvis : pelvis + 1]
    positions[:, ~recorded] = 0.0
    out = resample_positions(positions, float(fps), float(FPS))
    if out.shape[0] == 0:
        raise MotionFileError(
            f"too short: {array.shape[0]} frames at {fps:g} fps give no frame at {FPS} fps", path=path
        )
    placed, reading = convert_and_complete(
        out, recorded, units=units, up=up, forward=forward, path=path, check_plausible=check_plausible
    )
    if check_plausible:
        check_outlier_frames(positions * UNIT_SCALE[reading.units], recorded, path=path)
        check_skeleton(placed, recorded, sources=columns, pelvis=pelvis is not None, path=path)
    return Motion(
        placed.astype(np.float32), float(FPS), None if reading.presence.is_full else reading.presence
    ), reading


def _column(jmap: PositionJointMap, index: int) -> str:
    """A source column as messages name it: ``column 3 'r_wrist'`` (or ``column 3``)."""
    return f"column {index}" + ("" if jmap.names is None else f" {jmap.names[index]!r}")


# the joints of the body (not the fingers) that must come from columns of their own
_BODY_JOINTS = tuple(n for n in JOINT_NAMES if not any(f in n for f in ("thumb", "index", "middle", "ring", "pinky")))
#: check_outlier_frames: a joint this far from the mid-shoulder point (metres) ...
OUTLIER_REACH_M = 2.0
#: ... or a body this far from where it is in the frames around (metres, the median of 9 frames).
OUTLIER_JUMP_M = 1.0


def _check_distinct_sources(
    idx: np.ndarray, recorded: np.ndarray, pelvis: int | None, columns: dict[str, str], path
) -> None:
    """Refuse a map that reads two body joints, or the pelvis and a joint, from one source column."""
    taken: dict[int, str] = {} if pelvis is None else {pelvis: "pelvis"}
    for name, i, r in zip(JOINT_NAMES, idx, recorded, strict=True):
        if not r or (name not in _BODY_JOINTS and int(i) not in taken):
            continue
        other = taken.get(int(i))
        if other is not None:
            raise MotionFileError(
                f"the joint map reads {other} and {name} from one source column ({columns[name]}); each joint "
                "needs its own column: check the joint map (--no-plausibility-check reads it as given)",
                path=path,
            )
        if name in _BODY_JOINTS:
            taken[int(i)] = name


def check_outlier_frames(
    positions: np.ndarray, recorded: np.ndarray, *, path: str | os.PathLike[str] | None = None
) -> None:
    """Refuse frames of a joint-position file that hold joints far from the body.

    A frame is an outlier when a recorded joint is more than :data:`OUTLIER_REACH_M` from its
    mid-shoulder point, or its mid-shoulder point is more than :data:`OUTLIER_JUMP_M` from
    the median of the 9 frames around (no body moves that far in a frame or two).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        The file's frames, in metres (any axes); only ``recorded`` joints are read.
    recorded : np.ndarray, shape (55,) bool

    Raises
    ------
    MotionFileError
        Naming the outlier frames (counting from 0).
    """
    left, right = joint_index("left_shoulder"), joint_index("right_shoulder")
    pos = np.asarray(positions, dtype=np.float64)
    mid = 0.5 * (pos[:, left] + pos[:, right])
    reach = np.linalg.norm(pos[:, recorded] - mid[:, None], axis=-1).max(axis=1)
    half = 4
    padded = np.pad(mid, ((half, half), (0, 0)), mode="edge")
    around = np.median(np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1, axis=0), axis=-1)
    jump = np.linalg.norm(mid - around, axis=-1)
    bad = np.flatnonzero((reach > OUTLIER_REACH_M) | (jump > OUTLIER_JUMP_M))
    if bad.size:
        shown = ", ".join(str(int(f)) for f in bad[:10]) + (f" and {bad.size - 10} more" if bad.size > 10 else "")
        raise MotionFileError(
            f"{bad.size} of {pos.shape[0]} frames hold joints far from the body (more than {OUTLIER_REACH_M:g} m from "
            f"the shoulders, or the body {OUTLIER_JUMP_M:g} m from where it is in the frames around): frame "
            f"{shown} (counting from 0); remove or repair them (--no-plausibility-check reads them as they are)",
            path=path,
        )
