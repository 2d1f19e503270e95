"""BVH files: forward kinematics, resampling, and the 55-joint motion.

A BVH file has a joint hierarchy (offsets in file units, a list of channels
per joint) and a motion section (one line of channel values per frame).
:func:`parse_bvh` (:mod:`gesturekit.datasets.bvh_file`) reads it into a
:class:`BvhData`; :func:`forward_kinematics`
turns channel values into world positions; :func:`load_bvh_motion` maps the
source skeleton onto our 55 joints (:mod:`gesturekit.datasets.presets`) and
returns a pelvis-relative :class:`~gesturekit.motion.Motion` in metres at
15 fps.

Conventions, as BVH defines them: angles are in degrees; the rotation channels
of a joint compose intrinsically in the order they are listed (``Zrotation
Xrotation Yrotation`` means ``R = Rz @ Rx @ Ry``); a joint's local transform
is a translation (its OFFSET, with any position channels replacing the
corresponding components) followed by that rotation. ``End Site`` entries
become joints named ``f"{parent}_End"`` with no channels. The file's up axis
is Y unless ``up`` says otherwise (a BVH exported with Z up: ``up="z"``); without
``up`` the motion must look upright, and the axis the body faces becomes +Z
(:mod:`gesturekit.datasets._axes`).

Resampling keeps bones rigid: when the source rate is a whole multiple of the
target rate frames are subsampled; otherwise local rotations are interpolated
by quaternion slerp (translations linearly) at the target times before
forward kinematics, so bone lengths stay exactly those of the skeleton.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from .. import limits
from .._arguments import checks_arguments
from ..errors import ConfigError, MotionFileError
from ..motion import Motion, output_frame_count
from ..skeleton import FPS
from ._axes import UNIT_SCALE, check_axes_options, check_given_units
from ._kinematics import quat_mul, quat_to_matrix, slerp, world_positions
from ._reading import Reading, convert_and_complete
from .bvh_file import BvhData, parse_bvh, parse_bvh_text
from .presets import JointMap, load_joint_map

__all__ = [
    "read_bvh_take",
    "BvhData",
    "parse_bvh",
    "parse_bvh_text",
    "forward_kinematics",
    "resample_world_positions",
    "unit_scale",
    "load_bvh_motion",
]
_AXIS = {"X": 0, "Y": 1, "Z": 2}

#: Frames per block in forward kinematics, to bound memory on long takes.
_FK_BLOCK = 8192

#: ``units="auto"``: a skeleton whose non-root offsets sum to more than this
#: (in file units) is in centimetres. A human skeleton sums to a few metres,
#: i.e. a few hundred centimetres; the threshold sits well between the two.
_AUTO_CM_THRESHOLD = 40.0


#: After forward kinematics, a joint farther than this from the origin (metres)
#: is absurd: far beyond any capture volume, and so large that the offsets of
#: bones (centimetres) would be lost to rounding when made pelvis-relative.
_MAX_FROM_ORIGIN_M = 1e6

#: A joint farther than this from the skeleton's pelvis (metres) is absurd.
_MAX_FROM_PELVIS_M = 1000.0

#: A rotation channel beyond this many degrees is absurd (thousands of turns, and
#: at 1e300 no digit of the angle within a turn is left).
_MAX_ANGLE_DEG = 1e6


def _local_pose(data: BvhData, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations as quaternions (4, J, F) and translations (3, J, F) of the given frames."""
    values = data.values[frames].T  # (C, F): one contiguous row per channel
    n = values.shape[1]
    quats = np.zeros((4, data.n_joints, n))
    quats[0] = 1.0
    trans = np.repeat(data.offsets.T[:, :, None], n, axis=2)
    for j, (start, chans) in enumerate(zip(data.channel_starts, data.channels)):
        q = None
        for k, ch in enumerate(chans):
            column = values[start + k]
            axis, kind = _AXIS[ch[0]], ch[1:]
            if kind == "position":
                trans[axis, j] = column  # position channels replace the offset
                continue
            half = np.radians(column) * 0.5
            qa = np.zeros((4, n))
            qa[0] = np.cos(half)
            qa[1 + axis] = np.sin(half)
            # intrinsic rotations compose left to right in channel order
            q = qa if q is None else quat_mul(q, qa)
        if q is not None:
            quats[:, j] = q
    return quats, trans


def _frame_indices(data: BvhData, frames: slice | Sequence[int] | np.ndarray | None) -> np.ndarray:
    if frames is None:
        return np.arange(data.n_frames)
    if isinstance(frames, slice):
        return np.arange(data.n_frames)[frames]
    idx = np.asarray(frames)
    if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer):
        raise ConfigError("frames must be None, a slice or a 1-D array of frame indices")
    if idx.size and (idx.min() < -data.n_frames or idx.max() >= data.n_frames):
        raise ConfigError(f"frame index out of range for {data.n_frames} frames")
    return idx


@checks_arguments
def forward_kinematics(data: BvhData, *, frames: slice | Sequence[int] | np.ndarray | None = None) -> np.ndarray:
    """World positions of every joint.

    Parameters
    ----------
    data : BvhData
    frames : None, slice or array of int, optional
        Frames to compute (default: all).

    Returns
    -------
    np.ndarray, shape (frames, J, 3), float64
        Positions in file units, in the order of ``data.names``.
    """
    idx = _frame_indices(data, frames)
    out = np.empty((idx.size, data.n_joints, 3))
    for s in range(0, idx.size, _FK_BLOCK):
        block = idx[s : s + _FK_BLOCK]
        quats, trans = _local_pose(data, block)
        out[s : s + block.size] = world_positions(data.parents, quat_to_matrix(quats), trans)
    return out


@checks_arguments
def resample_world_positions(data: BvhData, *, fps: float = FPS) -> np.ndarray:
    """World positions at another frame rate, with rigid bones.

    Output frame ``t`` lies at ``t / fps`` seconds, ``t = 0 ..
    output_frame_count(n, data.fps, fps) - 1``. If ``data.fps / fps`` is a whole
    number this subsamples frames exactly; otherwise each joint's local
    rotation is slerped and its translation lerped between the two source frames
    around that time (times past the last frame hold it), then forward
    kinematics runs on the result.

    Parameters
    ----------
    data : BvhData
    fps : float
        Target frame rate, frames per second.

    Returns
    -------
    np.ndarray, shape (frames_out, J, 3), float64
        World positions in file units.
    """
    _check_fps(fps)
    fps_in = data.fps
    n_in = data.n_frames
    n_out = output_frame_count(n_in, fps_in, fps)
    ratio = fps_in / fps
    step = round(ratio)
    if step >= 1 and abs(ratio - step) < 1e-9:
        return forward_kinematics(data, frames=np.arange(n_out) * step)
    out = np.empty((n_out, data.n_joints, 3))
    for s in range(0, n_out, _FK_BLOCK):
        src = np.arange(s, min(s + _FK_BLOCK, n_out)) * ratio
        i0 = np.clip(np.floor(src + 1e-9).astype(np.int64), 0, n_in - 1)
        i1 = np.minimum(i0 + 1, n_in - 1)
        w = np.clip(src - i0, 0.0, 1.0)
        w = np.where((w < 1e-9) | (i1 == i0), 0.0, w)
        needed, inverse = np.unique(np.concatenate([i0, i1]), return_inverse=True)
        quats, trans = _local_pose(data, needed)
        a, b = inverse[: i0.size], inverse[i0.size :]
        q = slerp(quats[..., a], quats[..., b], w)
        t = trans[..., a] * (1.0 - w) + trans[..., b] * w
        out[s : s + src.size] = world_positions(data.parents, quat_to_matrix(q), t)
    return out


@checks_arguments
def unit_scale(data: BvhData, *, units: str = "auto") -> float:
    """Factor that converts the file's length units to metres.

    Parameters
    ----------
    data : BvhData
    units : {"auto", "cm", "m", "mm"}
        ``"auto"`` reads centimetres when the non-root offsets sum to more than
        40 file units (a human skeleton is a few metres of bones in all), and
        metres otherwise.

    Returns
    -------
    float
        0.01 for centimetres, 1.0 for metres, 0.001 for millimetres.
    """
    _check_units(units)
    if units == "auto":
        total = float(np.linalg.norm(data.offsets[data.parents >= 0], axis=1).sum())
        return UNIT_SCALE["cm"] if total > _AUTO_CM_THRESHOLD else UNIT_SCALE["m"]
    return UNIT_SCALE[units]


def _check_units(units) -> None:
    if not (units == "auto" or (isinstance(units, str) and units in UNIT_SCALE)):
        raise ConfigError(f"units must be 'auto', 'cm', 'm' or 'mm', got {units!r}")


def _check_fps(fps) -> None:
    if not (isinstance(fps, (int, float, np.integer, np.floating)) and math.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps must be a positive number, got {fps!r}")


@checks_arguments
def load_bvh_motion(
    path: str | os.PathLike,
    *,
    joint_map: str | os.PathLike | Mapping | JointMap = "zeggs",
    fps: float = FPS,
    units: str = "auto",
    up: str | None = None,
    forward: str = "auto",
    check_plausible: bool = True,
) -> Motion:
    """Read a BVH file as a 55-joint motion (see :func:`read_bvh_take`)."""
    return read_bvh_take(
        path, joint_map=joint_map, fps=fps, units=units, up=up, forward=forward, check_plausible=check_plausible
    )[0]


@checks_arguments
def read_bvh_take(
    path: str | os.PathLike,
    *,
    joint_map: str | os.PathLike | Mapping | JointMap = "zeggs",
    fps: float = FPS,
    units: str = "auto",
    up: str | None = None,
    forward: str = "auto",
    check_plausible: bool = True,
) -> tuple[Motion, Reading]:
    """Read a BVH file as a 55-joint motion, and say how it was read.

    A BVH joint map names all 55 joints (partial maps are for joint-position
    files), so every joint is recorded.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.bvh`` file (Y up).
    joint_map : str, os.PathLike, Mapping or JointMap
        Which source joint is each of our joints: a preset name (``"zeggs"``,
        ``"beat"``), a JSON file or a dict (see
        :func:`gesturekit.datasets.presets.load_joint_map`).
    fps : float
        Output frame rate (default 15).
    units : {"auto", "cm", "m", "mm"}
        Length unit of the file (see :func:`unit_scale`).
    up : {"y", "-y", "z", "-z"} or None
        The file's up axis. ``None``: Y, and the motion must look upright
        (:func:`gesturekit.datasets._axes.check_upright`).
    forward : {"auto", "x", "-x", "y", "-y", "z", "-z"}
        The axis the body faces; ``auto`` takes it from the shoulders.
    check_plausible : bool
        Refuse given ``units`` in which the body has no human size, and a given ``up`` with
        which it does not stand upright (:func:`gesturekit.datasets._axes.check_given_units`,
        :func:`~gesturekit.datasets._axes.check_given_up`).

    Returns
    -------
    motion : Motion
        Positions of shape (frames, 55, 3), metres, Y up, facing +Z, relative
        to the world position of the map's pelvis joint in the same frame, at ``fps``.
    reading : Reading
        The axes and units used.

    Raises
    ------
    MotionFileError
        The file is unreadable or malformed (see :func:`parse_bvh`), lacks
        joints the map names (all of them are listed), is too short to give
        one output frame, or holds values no pose can have: rotations beyond
        1e6 degrees, positions beyond 1000 km from the origin, or joints
        beyond 1 km from the pelvis after forward kinematics (the message
        names the first frame and joint), or is not upright (without ``up``).
    ConfigError, InputFileError
        The joint map or an option is invalid, or the file is beyond the
        limits (:mod:`gesturekit.limits`).
    """
    _check_units(units)
    check_axes_options(up, forward, "auto")
    _check_fps(fps)
    limits.check_fps(fps, what="the output frame rate", option="fps")
    jmap = load_joint_map(joint_map)
    data = parse_bvh(path)
    wanted = [jmap.pelvis] + jmap.source_names()
    present = set(data.names)
    missing = list(dict.fromkeys(n for n in wanted if n not in present))
    if missing:
        raise MotionFileError(
            f"{len(missing)} joints of the joint map {jmap.name!r} are missing from the file: {', '.join(missing)}",
            path=path,
        )
    scale = unit_scale(data, units=units)
    _check_channels(data, scale, path)
    positions = resample_world_positions(data, fps=fps)
    if positions.shape[0] == 0:
        raise MotionFileError(
            f"too short: {data.n_frames} frames at {data.fps:g} fps give no frame at {fps:g} fps", path=path
        )
    idx = np.array([data.index(n) for n in jmap.source_names()], dtype=np.int64)
    pelvis = data.index(jmap.pelvis)
    _check_positions(data, positions, scale, pelvis, fps, path)
    rel = positions[:, idx] - positions[:, pelvis : pelvis + 1]
    if units != "auto" and check_plausible:
        check_given_units(rel, units, path=path)
    rel = rel * scale
    placed, reading = convert_and_complete(
        rel,
        np.ones(rel.shape[1], dtype=bool),
        units="m",
        up=up,
        forward=forward,
        path=path,
        check_plausible=check_plausible,
        check_units=False,
    )
    found = units if units != "auto" else next((u for u, f in UNIT_SCALE.items() if f == scale), f"x{scale:g}")
    reading = replace(reading, units=found, units_given=units != "auto")
    return Motion(placed.astype(np.float32), float(fps)), reading


def _check_channels(data: BvhData, scale: float, path: str | os.PathLike | None) -> None:
    """Refuse channel values of any source frame that no pose can have, naming the first frame and joint.

    Rotations beyond :data:`_MAX_ANGLE_DEG` degrees, positions beyond
    :data:`_MAX_FROM_ORIGIN_M` metres. Checked on every frame of the file, also
    those that resampling skips.
    """
    rot = np.array([ch.endswith("rotation") for chans in data.channels for ch in chans], dtype=bool)
    if rot.size == 0:
        return
    bound = np.where(rot, _MAX_ANGLE_DEG, _MAX_FROM_ORIGIN_M / scale)
    bad = np.abs(data.values) > bound
    if not bad.any():
        return
    frame, column = (int(v) for v in np.argwhere(bad)[0])
    joint = int(np.searchsorted(data.channel_starts, column, side="right") - 1)
    while not data.channels[joint]:  # joints without channels share the next joint's start
        joint -= 1
    channel = data.channels[joint][column - int(data.channel_starts[joint])]
    value = data.values[frame, column]
    if rot[column]:
        what = f"absurd rotation: {channel} {value:g} degrees (more than {_MAX_ANGLE_DEG:g})"
    else:
        what = (
            f"absurd position: {channel} {value:g} file units ({abs(value) * scale:.3g} m, "
            f"more than {_MAX_FROM_ORIGIN_M / 1000:g} km)"
        )
    raise MotionFileError(
        f"{what} for joint {data.names[joint]!r} at frame {frame} ({frame * data.frame_time:.2f} s); "
        f"{int(bad.any(axis=1).sum())} frames affected",
        path=path,
    )


def _check_positions(
    data: BvhData, positions: np.ndarray, scale: float, pelvis: int, fps: float, path: str | os.PathLike | None
) -> None:
    """Refuse world positions (frames, J, 3) in file units that are not finite or absurdly far.

    Far is more than :data:`_MAX_FROM_ORIGIN_M` from the origin or
    :data:`_MAX_FROM_PELVIS_M` from the pelvis along any axis; the message
    names the first output frame and joint.
    """
    metres = positions * scale
    with np.errstate(over="ignore", invalid="ignore"):
        # the largest coordinate, not the norm: squares of 1e200 would overflow
        from_origin = np.abs(metres).max(axis=2)
        from_pelvis = np.abs(metres - metres[:, pelvis : pelvis + 1]).max(axis=2)
    bad = (
        ~np.isfinite(from_origin)
        | ~np.isfinite(from_pelvis)
        | (from_origin > _MAX_FROM_ORIGIN_M)
        | (from_pelvis > _MAX_FROM_PELVIS_M)
    )
    if not bad.any():
        return
    frame, joint = (int(v) for v in np.argwhere(bad)[0])
    where = f"joint {data.names[joint]!r} at frame {frame} ({frame / fps:.2f} s)"
    if not (np.isfinite(from_origin[frame, joint]) and np.isfinite(from_pelvis[frame, joint])):
        what = "is not finite (NaN or infinity)"
    elif from_origin[frame, joint] > _MAX_FROM_ORIGIN_M:
        what = (
            f"lies {from_origin[frame, joint]:.3g} m from the origin along one axis "
            f"(more than {_MAX_FROM_ORIGIN_M / 1000:g} km)"
        )
    else:
        what = (
            f"lies {from_pelvis[frame, joint]:.3g} m from the pelvis {data.names[pelvis]!r} along one axis "
            f"(more than {_MAX_FROM_PELVIS_M / 1000:g} km)"
        )
    raise MotionFileError(
        f"absurd positions after forward kinematics: {where} {what}; {int(bad.any(axis=1).sum())} frames affected",
        path=path,
    )
