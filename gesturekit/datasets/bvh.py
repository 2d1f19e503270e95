"""BVH files: parsing, forward kinematics, resampling, and the 55-joint motion.

A BVH file has a joint hierarchy (offsets in file units, a list of channels
per joint) and a motion section (one line of channel values per frame).
:func:`parse_bvh` reads it into a :class:`BvhData`; :func:`forward_kinematics`
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
is taken to be Y, as in nearly all BVH files.

Resampling keeps bones rigid: when the source rate is a whole multiple of the
target rate frames are subsampled; otherwise local rotations are interpolated
by quaternion slerp (translations linearly) at the target times before
forward kinematics, so bone lengths stay exactly those of the skeleton.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import limits
from ..errors import ConfigError, MotionFileError
from ..motion import Motion, output_frame_count
from ..skeleton import FPS
from .presets import JointMap, load_joint_map

__all__ = [
    "BvhData",
    "parse_bvh",
    "parse_bvh_text",
    "forward_kinematics",
    "resample_world_positions",
    "unit_scale",
    "load_bvh_motion",
]

_CHANNEL_RE = re.compile(r"^([xyz])(rotation|position)$", re.IGNORECASE)
_FRAMES_RE = re.compile(r"^frames\s*:?\s*(\S+)\s*$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r"^frame\s*time\s*:?\s*(\S+)\s*$", re.IGNORECASE)
_AXIS = {"X": 0, "Y": 1, "Z": 2}

#: Frames per block in forward kinematics, to bound memory on long takes.
_FK_BLOCK = 8192

#: ``units="auto"``: a skeleton whose non-root offsets sum to more than this
#: (in file units) is in centimetres. A human skeleton sums to a few metres,
#: i.e. a few hundred centimetres; the threshold sits well between the two.
_AUTO_CM_THRESHOLD = 40.0

_UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}

#: After forward kinematics, a joint farther than this from the origin (metres)
#: is absurd: far beyond any capture volume, and so large that the offsets of
#: bones (centimetres) would be lost to rounding when made pelvis-relative.
_MAX_FROM_ORIGIN_M = 1e6

#: A joint farther than this from the skeleton's pelvis (metres) is absurd.
_MAX_FROM_PELVIS_M = 1000.0

#: A rotation channel beyond this many degrees is absurd (thousands of turns, and
#: at 1e300 no digit of the angle within a turn is left).
_MAX_ANGLE_DEG = 1e6


@dataclass(frozen=True, eq=False)
class BvhData:
    """The content of a BVH file.

    Parameters
    ----------
    names : tuple of str, length J
        Joint names in file order (parents precede children); End Sites are
        joints named ``f"{parent}_End"``.
    parents : np.ndarray, shape (J,), int64
        Index of each joint's parent, ``-1`` for a root.
    offsets : np.ndarray, shape (J, 3), float64
        OFFSET of each joint from its parent, in file units.
    channels : tuple of tuple of str, length J
        Channels of each joint in file order, normalised to ``"Xrotation"``,
        ``"Yposition"`` etc.; empty for End Sites and joints without channels.
    frame_time : float
        Seconds per frame, as written in the file.
    values : np.ndarray, shape (frames, C), float64
        Channel values per frame, columns in the order of ``channels``
        (degrees for rotations, file units for positions).
    path : str or None
        The file read, for messages.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    frame_time: float
    values: np.ndarray
    path: str | None = None

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def n_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def n_channels(self) -> int:
        return int(self.values.shape[1])

    @property
    def channel_starts(self) -> np.ndarray:
        """Column of each joint's first channel in :attr:`values`, shape (J,)."""
        counts = np.array([len(c) for c in self.channels], dtype=np.int64)
        return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)

    @property
    def fps(self) -> float:
        """Frame rate, ``1 / frame_time``, snapped to a whole number within 1e-4 (relative).

        Files write the frame time rounded (``0.008333`` for 120 fps); the
        snap recovers the intended rate so that whole ratios subsample exactly.
        """
        fps = 1.0 / self.frame_time
        nearest = round(fps)
        if nearest > 0 and abs(fps - nearest) <= 1e-4 * nearest:
            return float(nearest)
        return fps

    def index(self, name: str) -> int:
        """Index of a joint by name (``KeyError`` if absent)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r}") from None


# ----------------------------------------------------------------------------- parsing


def parse_bvh(path: str | os.PathLike) -> BvhData:
    """Read a BVH file.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.bvh`` file.

    Returns
    -------
    BvhData

    Raises
    ------
    MotionFileError
        The file is missing, empty, not a BVH file, malformed (numbers, braces,
        channel counts, frame lines), has no frames, or holds NaN/infinite
        values. The message names the file and, where it can, the line.
    InputFileError
        The header's frame time is outside the accepted frame rates, or its
        frames last longer than one take may (:mod:`gesturekit.limits`);
        checked before the frames are read.
    """
    path = Path(path)
    if not path.exists():
        raise MotionFileError("file not found", path=path)
    if path.is_dir():
        raise MotionFileError("is a directory, not a BVH file", path=path)
    try:
        with open(path, "rb") as f:
            # the header's frame count and frame time are checked before the whole file is read
            _check_motion_header_early(f.read(_HEAD_BYTES), path)
        raw = path.read_bytes()
    except OSError as exc:
        raise MotionFileError(f"cannot read file: {exc.strerror or exc}", path=path) from None
    if not raw.strip():
        raise MotionFileError("empty file", path=path)
    if b"\x00" in raw[:4096]:
        raise MotionFileError("not a BVH file (binary content)", path=path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        # joint names from older tools may be Latin-1; numbers are ASCII either way
        text = raw.decode("latin-1")
    return parse_bvh_text(text, path=path)


def parse_bvh_text(text: str, *, path: str | os.PathLike | None = None) -> BvhData:
    """Parse the text of a BVH file (see :func:`parse_bvh`).

    Parameters
    ----------
    text : str
        The whole file content.
    path : str or os.PathLike, optional
        Named in error messages.
    """
    lines = text.lstrip("\ufeff").splitlines()  # handles \n, \r\n and \r
    first = next((i for i, line in enumerate(lines) if line.strip()), None)
    if first is None:
        raise MotionFileError("empty file", path=path)
    if lines[first].split()[0].upper() != "HIERARCHY":
        raise MotionFileError("not a BVH file: it does not start with HIERARCHY", path=path)
    motion_at = next((i for i, line in enumerate(lines) if line.strip().upper() == "MOTION"), None)
    if motion_at is None:
        raise MotionFileError("no MOTION section", path=path)
    names, parents, offsets, channels = _parse_hierarchy(lines, first + 1, motion_at, path)
    n_channels = sum(len(c) for c in channels)
    frame_time, values = _parse_motion(lines, motion_at + 1, n_channels, path)
    return BvhData(
        names=tuple(names),
        parents=np.asarray(parents, dtype=np.int64),
        offsets=np.asarray(offsets, dtype=np.float64).reshape(-1, 3),
        channels=tuple(tuple(c) for c in channels),
        frame_time=frame_time,
        values=values,
        path=None if path is None else os.fspath(path),
    )


def _hierarchy_tokens(lines, start, stop):
    """(token, line number) pairs; a ROOT/JOINT name is one token (it may hold spaces)."""
    tokens: list[tuple[str, int]] = []
    for i in range(start, stop):
        line = lines[i].strip()
        if not line:
            continue
        lineno = i + 1
        head = line.split()[0]
        if head.upper() in ("ROOT", "JOINT"):
            rest = line[len(head):].strip()
            brace = rest.endswith("{")
            if brace:
                rest = rest[:-1].strip()
            tokens.append((head.upper(), lineno))
            tokens.append((rest, lineno))
            if brace:
                tokens.append(("{", lineno))
            continue
        # braces may touch other tokens ("{OFFSET", "}}"): split them off
        for tok in re.findall(r"[{}]|[^\s{}]+", line):
            tokens.append((tok, lineno))
    return tokens


def _parse_hierarchy(lines, start, stop, path):
    tokens = _hierarchy_tokens(lines, start, stop)
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float] | None] = []
    channels: list[list[str]] = []
    end_site: list[bool] = []
    stack: list[int] = []
    i = 0

    def fail(message, lineno):
        raise MotionFileError(f"line {lineno}: {message}", path=path)

    def take(what):
        nonlocal i
        if i >= len(tokens):
            last = tokens[-1][1] if tokens else start
            fail(f"hierarchy ends early, expected {what}", last)
        tok = tokens[i]
        i += 1
        return tok

    def expect_brace():
        tok, lineno = take("'{'")
        if tok != "{":
            fail(f"expected '{{', found {tok!r}", lineno)

    def number(what):
        tok, lineno = take(what)
        try:
            value = float(tok)
        except ValueError:
            fail(f"malformed number {tok!r} in {what}", lineno)
        if not math.isfinite(value):
            fail(f"{what} is not finite ({tok})", lineno)
        return value

    while i < len(tokens):
        tok, lineno = tokens[i]
        i += 1
        key = tok.upper()
        if key in ("ROOT", "JOINT"):
            if key == "JOINT" and not stack:
                fail("JOINT outside of any ROOT", lineno)
            if key == "ROOT" and stack:
                fail("ROOT inside another joint", lineno)
            name, _ = take("a joint name")
            if not name or name in ("{", "}"):
                fail(f"{key} without a name", lineno)
            if name in names:
                fail(f"duplicate joint name {name!r}", lineno)
            if stack and end_site[stack[-1]]:
                fail("a joint inside an End Site", lineno)
            parents.append(stack[-1] if stack else -1)
            names.append(name)
            offsets.append(None)
            channels.append([])
            end_site.append(False)
            stack.append(len(names) - 1)
            expect_brace()
        elif key == "END":
            site, site_line = take("'Site'")
            if site.upper() != "SITE":
                fail(f"expected 'End Site', found 'End {site}'", site_line)
            if not stack or end_site[stack[-1]]:
                fail("End Site outside of a joint", lineno)
            parent = stack[-1]
            name, k = f"{names[parent]}_End", 2
            while name in names:  # a second End Site of the same joint
                name, k = f"{names[parent]}_End{k}", k + 1
            parents.append(parent)
            names.append(name)
            offsets.append(None)
            channels.append([])
            end_site.append(True)
            stack.append(len(names) - 1)
            expect_brace()
        elif key == "OFFSET":
            if not stack:
                fail("OFFSET outside of a joint", lineno)
            if offsets[stack[-1]] is not None:
                fail(f"second OFFSET for {names[stack[-1]]!r}", lineno)
            offsets[stack[-1]] = [number("OFFSET") for _ in range(3)]
        elif key == "CHANNELS":
            if not stack or end_site[stack[-1]]:
                fail("CHANNELS outside of a joint", lineno)
            if channels[stack[-1]]:
                fail(f"second CHANNELS for {names[stack[-1]]!r}", lineno)
            count_tok, count_line = take("a channel count")
            try:
                count = int(count_tok)
            except ValueError:
                fail(f"malformed channel count {count_tok!r}", count_line)
            if count < 0:
                fail(f"negative channel count {count}", count_line)
            seen = set()
            for _ in range(count):
                ch, ch_line = take("a channel name")
                m = _CHANNEL_RE.match(ch)
                if m is None:
                    fail(f"unknown channel {ch!r} of joint {names[stack[-1]]!r} "
                         f"(expected X/Y/Z rotation or position; CHANNELS says {count})", ch_line)
                norm = m.group(1).upper() + m.group(2).lower()
                if norm in seen:
                    fail(f"channel {norm} twice for joint {names[stack[-1]]!r}", ch_line)
                seen.add(norm)
                channels[stack[-1]].append(norm)
        elif key == "}":
            if not stack:
                fail("unmatched '}'", lineno)
            stack.pop()
        else:
            fail(f"unexpected {tok!r} in the hierarchy", lineno)
    if stack:
        raise MotionFileError(f"hierarchy not closed: '{{' of {names[stack[-1]]!r} has no '}}'", path=path)
    if not names:
        raise MotionFileError("the hierarchy has no joints", path=path)
    for name, off in zip(names, offsets):
        if off is None:
            raise MotionFileError(f"joint {name!r} has no OFFSET", path=path)
    return names, parents, offsets, channels


#: Bytes of a BVH file read first to check its MOTION header before the whole file is read.
_HEAD_BYTES = 1 << 20


def _check_motion_limits(n_frames, frame_time, frames_line, time_line, time_text, path, *, lines_present=None):
    """Refuse what the MOTION header asks for before any frame is converted.

    The frame time sets how many frames resampling makes (a frame rate within
    :func:`gesturekit.limits.check_fps`), and frames x frame time the take's
    duration (within :func:`gesturekit.limits.max_take_seconds`).
    """
    limits.check_fps(1.0 / frame_time, what=f"line {time_line}: 'Frame Time: {time_text}' gives a frame rate that",
                     path=path)
    if lines_present is not None and n_frames > lines_present:
        raise MotionFileError(
            f"the header says {n_frames} frames but the file has {lines_present} frame lines (truncated?)",
            path=path)
    limits.check_duration(n_frames * frame_time, path=path,
                          what=f"line {frames_line}: the header says {n_frames} frames of {frame_time:g} s")


def _check_motion_header_early(head: bytes, path) -> None:
    """Check the MOTION header found in the first bytes of a file; anything unclear is left to the parser."""
    lines = head.decode("latin-1").splitlines()
    if len(head) == _HEAD_BYTES:
        lines = lines[:-1]  # the last line may be cut
    motion_at = next((i for i, line in enumerate(lines) if line.strip().upper() == "MOTION"), None)
    if motion_at is None:
        return
    body = [(i + 1, lines[i].strip()) for i in range(motion_at + 1, len(lines)) if lines[i].strip()][:2]
    if len(body) < 2:
        return
    m_frames, m_time = _FRAMES_RE.match(body[0][1]), _FRAME_TIME_RE.match(body[1][1])
    if m_frames is None or m_time is None:
        return
    try:
        n_frames, frame_time = int(m_frames.group(1)), float(m_time.group(1))
    except ValueError:
        return
    if n_frames > 0 and math.isfinite(frame_time) and frame_time > 0:
        _check_motion_limits(n_frames, frame_time, body[0][0], body[1][0], m_time.group(1), path)


def _parse_motion(lines, start, n_channels, path):
    body = [(i + 1, lines[i].strip()) for i in range(start, len(lines)) if lines[i].strip()]
    if len(body) < 2:
        raise MotionFileError("MOTION section lacks the 'Frames:' and 'Frame Time:' lines", path=path)
    (frames_line, frames_text), (time_line, time_text) = body[0], body[1]
    m = _FRAMES_RE.match(frames_text)
    if m is None:
        raise MotionFileError(f"line {frames_line}: expected 'Frames: <count>', found {frames_text[:40]!r}", path=path)
    try:
        n_frames = int(m.group(1))
    except ValueError:
        raise MotionFileError(f"line {frames_line}: malformed frame count {m.group(1)!r}", path=path) from None
    m = _FRAME_TIME_RE.match(time_text)
    if m is None:
        raise MotionFileError(f"line {time_line}: expected 'Frame Time: <seconds>', found {time_text[:40]!r}",
                              path=path)
    try:
        frame_time = float(m.group(1))
    except ValueError:
        raise MotionFileError(f"line {time_line}: malformed frame time {m.group(1)!r}", path=path) from None
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise MotionFileError(f"line {time_line}: frame time must be a positive number, got {m.group(1)}",
                              path=path)
    if n_frames <= 0:
        raise MotionFileError(f"the file has no frames (Frames: {n_frames})", path=path)
    data = body[2:]
    _check_motion_limits(n_frames, frame_time, frames_line, time_line, m.group(1), path,
                         lines_present=len(data) if n_channels else None)
    if n_channels == 0:
        return frame_time, np.zeros((n_frames, 0))
    if len(data) != n_frames:
        raise MotionFileError(
            f"the header says {n_frames} frames but the file has {len(data)} frame lines"
            + (" (truncated?)" if len(data) < n_frames else ""), path=path)
    rows = [text.split() for _, text in data]
    for (lineno, _), row in zip(data, rows):
        if len(row) != n_channels:
            raise MotionFileError(
                f"line {lineno}: {len(row)} values on a frame line, the hierarchy has {n_channels} channels",
                path=path)
    try:
        values = np.array([tok for row in rows for tok in row], dtype=np.float64)
    except ValueError:
        for (lineno, _), row in zip(data, rows):
            for tok in row:
                try:
                    float(tok)
                except ValueError:
                    raise MotionFileError(f"line {lineno}: malformed number {tok!r}", path=path) from None
        raise  # unreachable: some token failed above
    values = values.reshape(n_frames, n_channels)
    bad = ~np.isfinite(values)
    if bad.any():
        frame, column = np.argwhere(bad)[0]
        raise MotionFileError(
            f"line {data[frame][0]}: motion values contain NaN or infinity "
            f"({int(bad.any(axis=1).sum())} frames affected; first at frame {frame}, column {column})",
            path=path)
    return frame_time, values


# ----------------------------------------------------------------------------- rotations


# Internal layout: components first, time last (quaternions (4, J, F),
# translations (3, J, F), matrices (3, 3, J, F)), so that every component is a
# contiguous vector over frames and the arithmetic below is a few dozen fast
# vector operations per joint rather than many tiny 3x3 products.


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (w, x, y, z) stored components first: (4, ...)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ])


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions (w, x, y, z): (4, ...) -> (3, 3, ...)."""
    w, x, y, z = q
    m = np.empty((3, 3) + q.shape[1:])
    m[0, 0] = 1 - 2 * (y * y + z * z)
    m[0, 1] = 2 * (x * y - w * z)
    m[0, 2] = 2 * (x * z + w * y)
    m[1, 0] = 2 * (x * y + w * z)
    m[1, 1] = 1 - 2 * (x * x + z * z)
    m[1, 2] = 2 * (y * z - w * x)
    m[2, 0] = 2 * (x * z - w * y)
    m[2, 1] = 2 * (y * z + w * x)
    m[2, 2] = 1 - 2 * (x * x + y * y)
    return m


def _slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical interpolation of unit quaternions (4, ...) with weights ``w`` (...), shortest path."""
    dot = np.sum(q0 * q1, axis=0)
    q1 = np.where(dot < 0, -q1, q1)  # q and -q are the same rotation
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-8
    safe = np.where(small, 1.0, sin_theta)
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    q = a * q0 + b * q1
    return q / np.linalg.norm(q, axis=0)


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
            q = qa if q is None else _quat_mul(q, qa)
        if q is not None:
            quats[:, j] = q
    return quats, trans


def _chain(parents: np.ndarray, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """World positions (F, J, 3) from local rotations (3, 3, J, F) and translations (3, J, F)."""
    world_rot = np.empty_like(rot)
    world_pos = np.empty_like(trans)
    for j, p in enumerate(parents):
        if p < 0:
            world_rot[:, :, j] = rot[:, :, j]
            world_pos[:, j] = trans[:, j]
            continue
        a, b, t = world_rot[:, :, p], rot[:, :, j], trans[:, j]
        for r in range(3):
            for c in range(3):
                world_rot[r, c, j] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]
            world_pos[r, j] = world_pos[r, p] + a[r, 0] * t[0] + a[r, 1] * t[1] + a[r, 2] * t[2]
    return np.ascontiguousarray(world_pos.transpose(2, 1, 0))


def _frame_indices(data: BvhData, frames) -> np.ndarray:
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


def forward_kinematics(data: BvhData, *, frames=None) -> np.ndarray:
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
        block = idx[s:s + _FK_BLOCK]
        quats, trans = _local_pose(data, block)
        out[s:s + block.size] = _chain(data.parents, _quat_to_matrix(quats), trans)
    return out


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
        a, b = inverse[:i0.size], inverse[i0.size:]
        q = _slerp(quats[..., a], quats[..., b], w)
        t = trans[..., a] * (1.0 - w) + trans[..., b] * w
        out[s:s + src.size] = _chain(data.parents, _quat_to_matrix(q), t)
    return out


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
        return _UNIT_SCALE["cm"] if total > _AUTO_CM_THRESHOLD else _UNIT_SCALE["m"]
    return _UNIT_SCALE[units]


def _check_units(units) -> None:
    if not (units == "auto" or (isinstance(units, str) and units in _UNIT_SCALE)):
        raise ConfigError(f"units must be 'auto', 'cm', 'm' or 'mm', got {units!r}")


def _check_fps(fps) -> None:
    if not (isinstance(fps, (int, float, np.integer, np.floating)) and math.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps must be a positive number, got {fps!r}")


def load_bvh_motion(
    path: str | os.PathLike,
    *,
    joint_map: str | os.PathLike | dict | JointMap = "zeggs",
    fps: float = FPS,
    units: str = "auto",
) -> Motion:
    """Read a BVH file as a 55-joint motion.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.bvh`` file (Y up).
    joint_map : str, os.PathLike, dict or JointMap
        Which source joint is each of our joints: a preset name (``"zeggs"``,
        ``"beat"``), a JSON file or a dict (see
        :func:`gesturekit.datasets.presets.load_joint_map`).
    fps : float
        Output frame rate (default 15).
    units : {"auto", "cm", "m", "mm"}
        Length unit of the file (see :func:`unit_scale`).

    Returns
    -------
    Motion
        Positions of shape (frames, 55, 3), metres, relative to the world
        position of the map's pelvis joint in the same frame, at ``fps``.

    Raises
    ------
    MotionFileError
        The file is unreadable or malformed (see :func:`parse_bvh`), lacks
        joints the map names (all of them are listed), is too short to give
        one output frame, or holds values no pose can have: rotations beyond
        1e6 degrees, positions beyond 1000 km from the origin, or joints
        beyond 1 km from the pelvis after forward kinematics (the message
        names the first frame and joint).
    ConfigError, InputFileError
        The joint map or an option is invalid, or the file is beyond the
        limits (:mod:`gesturekit.limits`).
    """
    _check_units(units)
    _check_fps(fps)
    limits.check_fps(fps, what="the output frame rate", option="fps")
    jmap = load_joint_map(joint_map)
    data = parse_bvh(path)
    wanted = [jmap.pelvis] + jmap.source_names()
    present = set(data.names)
    missing = list(dict.fromkeys(n for n in wanted if n not in present))
    if missing:
        raise MotionFileError(
            f"{len(missing)} joints of the joint map {jmap.name!r} are missing from the file: "
            f"{', '.join(missing)}", path=path)
    scale = unit_scale(data, units=units)
    _check_channels(data, scale, path)
    positions = resample_world_positions(data, fps=fps)
    if positions.shape[0] == 0:
        raise MotionFileError(
            f"too short: {data.n_frames} frames at {data.fps:g} fps give no frame at {fps:g} fps", path=path)
    idx = np.array([data.index(n) for n in jmap.source_names()], dtype=np.int64)
    pelvis = data.index(jmap.pelvis)
    _check_positions(data, positions, scale, pelvis, fps, path)
    rel = (positions[:, idx] - positions[:, pelvis:pelvis + 1]) * scale
    return Motion(rel.astype(np.float32), float(fps))



def _check_channels(data: BvhData, scale: float, path) -> None:
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
        what = (f"absurd position: {channel} {value:g} file units ({abs(value) * scale:.3g} m, "
                f"more than {_MAX_FROM_ORIGIN_M / 1000:g} km)")
    raise MotionFileError(
        f"{what} for joint {data.names[joint]!r} at frame {frame} ({frame * data.frame_time:.2f} s); "
        f"{int(bad.any(axis=1).sum())} frames affected", path=path)


def _check_positions(data: BvhData, positions: np.ndarray, scale: float, pelvis: int, fps: float, path) -> None:
    """Refuse world positions (frames, J, 3) in file units that are not finite or absurdly far.

    Far is more than :data:`_MAX_FROM_ORIGIN_M` from the origin or
    :data:`_MAX_FROM_PELVIS_M` from the pelvis along any axis; the message
    names the first output frame and joint.
    """
    metres = positions * scale
    with np.errstate(over="ignore", invalid="ignore"):
        # the largest coordinate, not the norm: squares of 1e200 would overflow
        from_origin = np.abs(metres).max(axis=2)
        from_pelvis = np.abs(metres - metres[:, pelvis:pelvis + 1]).max(axis=2)
    bad = ~np.isfinite(from_origin) | ~np.isfinite(from_pelvis) | (from_origin > _MAX_FROM_ORIGIN_M) \
        | (from_pelvis > _MAX_FROM_PELVIS_M)
    if not bad.any():
        return
    frame, joint = (int(v) for v in np.argwhere(bad)[0])
    where = f"joint {data.names[joint]!r} at frame {frame} ({frame / fps:.2f} s)"
    if not (np.isfinite(from_origin[frame, joint]) and np.isfinite(from_pelvis[frame, joint])):
        what = "is not finite (NaN or infinity)"
    elif from_origin[frame, joint] > _MAX_FROM_ORIGIN_M:
        what = (f"lies {from_origin[frame, joint]:.3g} m from the origin along one axis "
                f"(more than {_MAX_FROM_ORIGIN_M / 1000:g} km)")
    else:
        what = (f"lies {from_pelvis[frame, joint]:.3g} m from the pelvis {data.names[pelvis]!r} along one axis "
                f"(more than {_MAX_FROM_PELVIS_M / 1000:g} km)")
    raise MotionFileError(
        f"absurd positions after forward kinematics: {where} {what}; "
        f"{int(bad.any(axis=1).sum())} frames affected", path=path)
