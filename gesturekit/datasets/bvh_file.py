"""BVH files as text: the joint hierarchy and the motion section, parsed into a :class:`BvhData`.

A BVH file has a joint hierarchy (offsets in file units, a list of channels
per joint) and a motion section (one line of channel values per frame).
:func:`parse_bvh` reads it and checks what it can before converting a frame:
the MOTION header's frame rate and duration against :mod:`gesturekit.limits`
from the file's first megabyte, then every token of the hierarchy and every
frame line. ``End Site`` entries become joints named ``f"{parent}_End"`` with
no channels. Turning channel values into positions is
:mod:`gesturekit.datasets.bvh`'s part.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np

from .. import limits
from .._arguments import checks_arguments
from ..errors import MotionFileError

__all__ = ["BvhData", "parse_bvh", "parse_bvh_text"]

_CHANNEL_RE = re.compile(r"^([xyz])(rotation|position)$", re.IGNORECASE)
_FRAMES_RE = re.compile(r"^frames\s*:?\s*(\S+)\s*$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r"^frame\s*time\s*:?\s*(\S+)\s*$", re.IGNORECASE)


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


@checks_arguments
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


@checks_arguments
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


def _hierarchy_tokens(lines: list[str], start: int, stop: int) -> list[tuple[str, int]]:
    """(token, line number) pairs; a ROOT/JOINT name is one token (it may hold spaces)."""
    tokens: list[tuple[str, int]] = []
    for i in range(start, stop):
        line = lines[i].strip()
        if not line:
            continue
        lineno = i + 1
        head = line.split()[0]
        if head.upper() in ("ROOT", "JOINT"):
            rest = line[len(head) :].strip()
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


def _parse_hierarchy(
    lines: list[str], start: int, stop: int, path: str | os.PathLike | None
) -> tuple[list[str], list[int], list[list[float] | None], list[list[str]]]:
    """Joint names, parent indices (-1: a root), offsets and channel names of the HIERARCHY lines."""
    tokens = _hierarchy_tokens(lines, start, stop)
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float] | None] = []
    channels: list[list[str]] = []
    end_site: list[bool] = []
    stack: list[int] = []
    i = 0

    def fail(message: str, lineno: int) -> NoReturn:
        raise MotionFileError(f"line {lineno}: {message}", path=path)

    def take(what: str) -> tuple[str, int]:
        nonlocal i
        if i >= len(tokens):
            last = tokens[-1][1] if tokens else start
            fail(f"hierarchy ends early, expected {what}", last)
        tok = tokens[i]
        i += 1
        return tok

    def expect_brace() -> None:
        tok, lineno = take("'{'")
        if tok != "{":
            fail(f"expected '{{', found {tok!r}", lineno)

    def open_joint(name: str, parent: int, *, is_end_site: bool) -> None:
        # a joint's OFFSET and CHANNELS follow inside its braces
        parents.append(parent)
        names.append(name)
        offsets.append(None)
        channels.append([])
        end_site.append(is_end_site)
        stack.append(len(names) - 1)
        expect_brace()

    def number(what: str) -> float:
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
            open_joint(name, stack[-1] if stack else -1, is_end_site=False)
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
            open_joint(name, parent, is_end_site=True)
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
            seen: set[str] = set()
            for _ in range(count):
                ch, ch_line = take("a channel name")
                m = _CHANNEL_RE.match(ch)
                if m is None:
                    fail(
                        f"unknown channel {ch!r} of joint {names[stack[-1]]!r} "
                        f"(expected X/Y/Z rotation or position; CHANNELS says {count})",
                        ch_line,
                    )
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
    limits.check_fps(
        1.0 / frame_time, what=f"line {time_line}: 'Frame Time: {time_text}' gives a frame rate that", path=path
    )
    if lines_present is not None and n_frames > lines_present:
        raise MotionFileError(
            f"the header says {n_frames} frames but the file has {lines_present} frame lines (truncated?)", path=path
        )
    limits.check_duration(
        n_frames * frame_time,
        path=path,
        what=f"line {frames_line}: the header says {n_frames} frames of {frame_time:g} s",
    )


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
        raise MotionFileError(
            f"line {time_line}: expected 'Frame Time: <seconds>', found {time_text[:40]!r}", path=path
        )
    try:
        frame_time = float(m.group(1))
    except ValueError:
        raise MotionFileError(f"line {time_line}: malformed frame time {m.group(1)!r}", path=path) from None
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise MotionFileError(f"line {time_line}: frame time must be a positive number, got {m.group(1)}", path=path)
    if n_frames <= 0:
        raise MotionFileError(f"the file has no frames (Frames: {n_frames})", path=path)
    data = body[2:]
    _check_motion_limits(
        n_frames, frame_time, frames_line, time_line, m.group(1), path, lines_present=len(data) if n_channels else None
    )
    if n_channels == 0:
        return frame_time, np.zeros((n_frames, 0))
    if len(data) != n_frames:
        raise MotionFileError(
            f"the header says {n_frames} frames but the file has {len(data)} frame lines"
            + (" (truncated?)" if len(data) < n_frames else ""),
            path=path,
        )
    rows = [text.split() for _, text in data]
    for (lineno, _), row in zip(data, rows):
        if len(row) != n_channels:
            raise MotionFileError(
                f"line {lineno}: {len(row)} values on a frame line, the hierarchy has {n_channels} channels", path=path
            )
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
            path=path,
        )
    return frame_time, values
