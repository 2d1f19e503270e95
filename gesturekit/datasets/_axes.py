"""Axes and units of motion files: conversion to our frame, the upright check, unit detection.

Our frame: Y up, the character faces +Z, its left is +X (left = up x forward),
metres. A source names its up axis (``y``, ``-y``, ``z``, ``-z``) and its
forward axis (the way the character faces; ``auto`` finds it from the
shoulders). Without an up axis the data must look upright as it is
(:func:`check_upright`); lying or upside-down data is refused with the option
that would read it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError, MotionFileError
from ..skeleton import joint_index

__all__ = [
    "UP_CHOICES",
    "FORWARD_CHOICES",
    "UNIT_CHOICES",
    "UNIT_SCALE",
    "axis_vector",
    "axes_rotation",
    "auto_forward",
    "to_our_frame",
    "upright_scores",
    "check_upright",
    "body_axis",
    "body_size",
    "detect_units",
    "check_axes_options",
]

UP_CHOICES: tuple[str, ...] = ("y", "-y", "z", "-z")
FORWARD_CHOICES: tuple[str, ...] = ("auto", "x", "-x", "y", "-y", "z", "-z")
UNIT_CHOICES: tuple[str, ...] = ("auto", "m", "cm", "mm")
UNIT_SCALE: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_SIGNED_AXES = ("x", "-x", "y", "-y", "z", "-z")

_LS, _RS = joint_index("left_shoulder"), joint_index("right_shoulder")
_LE, _RE = joint_index("left_elbow"), joint_index("right_elbow")
_LW, _RW = joint_index("left_wrist"), joint_index("right_wrist")
_HEAD_JOINTS = tuple(joint_index(n) for n in ("head_top", "head", "neck_upper"))

# The upright check (see check_upright): an upper arm hangs this far down along the up axis
# (a fraction of its length, median over frames and sides), ...
_ARMS_DOWN = 0.25
# ... the shoulder line tilts less than this (fraction of the shoulder width, median) ...
_SHOULDERS_LEVEL = 0.5
# ... and a recorded head is above the mid-shoulder point by this fraction of the shoulder width ...
_HEAD_ABOVE = 0.1
# ... and the body's axis (body_axis) is within this angle of the up axis, degrees.
_MAX_TILT_DEG = 45.0

# units="auto": a body size (see body_size) in metres that a human can have
_PLAUSIBLE_SIZE_M = (0.08, 0.7)


def axis_vector(name: str) -> np.ndarray:
    """The unit vector of a signed axis name (``"x"``, ``"-z"``, ...), shape (3,)."""
    sign = -1.0 if name.startswith("-") else 1.0
    out = np.zeros(3)
    out["xyz".index(name.lstrip("-"))] = sign
    return out


def _name_of(vector: np.ndarray) -> str:
    i = int(np.argmax(np.abs(vector)))
    return ("-" if vector[i] < 0 else "") + "xyz"[i]


def check_axes_options(up: str | None, forward: str, units: str) -> None:
    """Refuse an unknown ``up``, ``forward`` or ``units`` value, or a forward axis along the up axis.

    Raises
    ------
    ConfigError
        The message names the option (``--up``, ``--forward``, ``--units``) and its choices.
    """
    if up is not None and up not in UP_CHOICES:
        raise ConfigError(f"--up must be one of {', '.join(UP_CHOICES)}, got {up!r}")
    if forward not in FORWARD_CHOICES:
        raise ConfigError(f"--forward must be one of {', '.join(FORWARD_CHOICES)}, got {forward!r}")
    if units not in UNIT_CHOICES:
        raise ConfigError(f"--units must be one of {', '.join(UNIT_CHOICES)}, got {units!r}")
    if forward != "auto" and forward.lstrip("-") == (up or "y").lstrip("-"):
        raise ConfigError(f"--forward {forward} lies along the up axis ({up or 'y'}); give an axis across it")


def axes_rotation(up: str, forward: str) -> np.ndarray:
    """Rotation taking source coordinates to ours, shape (3, 3): ``ours = R @ source``.

    The rows are the source's left (up x forward), up and forward axes.
    """
    u, f = axis_vector(up), axis_vector(forward)
    if abs(float(u @ f)) > 0.5:
        raise ConfigError(f"--forward {forward} lies along the up axis {up}; give an axis across it")
    return np.stack([np.cross(u, f), u, f])


def auto_forward(positions: np.ndarray, up: str) -> str:
    """The source axis across ``up`` nearest to the way the shoulders face.

    The facing direction of a frame is ``(left_shoulder - right_shoulder) x up``;
    its median over the frames, with its up component removed, is rounded to the
    nearest signed axis.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions in source axes.
    up : str
        The source's up axis.
    """
    u = axis_vector(up)
    across = positions[:, _LS] - positions[:, _RS]
    facing = np.median(np.cross(across, u), axis=0)
    facing = facing - (facing @ u) * u
    if not np.any(np.abs(facing) > 0):
        return "z" if up.lstrip("-") != "z" else "y"
    return _name_of(facing)


def to_our_frame(positions: np.ndarray, *, up: str, forward: str) -> tuple[np.ndarray, str]:
    """Positions (frames, 55, 3) in source axes rotated into ours, and the forward axis used.

    ``forward="auto"`` takes :func:`auto_forward`.
    """
    fwd = auto_forward(positions, up) if forward == "auto" else forward
    rot = axes_rotation(up, fwd)
    return positions @ rot.T, fwd


def _median_ratio(num: np.ndarray, den: np.ndarray) -> float:
    ok = den > 1e-9
    if not ok.any():
        return 0.0
    return float(np.median(num[ok] / den[ok]))


def upright_scores(positions: np.ndarray, recorded: np.ndarray | None = None) -> dict[str, dict[str, float]]:
    """For each signed axis taken as up, how upright the body is; ``{axis: {test: value}}``.

    The tests, medians over the frames (scale free):

    - ``arms_down``: how far the elbows hang below the shoulders, in upper-arm lengths
      (1 = straight down; gesturing arms stay well above 0.25);
    - ``level``: the shoulder line's tilt along the axis, in shoulder widths (0 = level);
    - ``head``: how far a recorded head (head_top, head or neck_upper) is above the
      mid-shoulder point, in shoulder widths (``nan`` without one).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
    recorded : np.ndarray, shape (55,) bool, optional
        Joints the data holds (default: all).
    """
    pos = np.asarray(positions, dtype=np.float64)
    rec = np.ones(pos.shape[1], dtype=bool) if recorded is None else np.asarray(recorded, dtype=bool)
    width = np.linalg.norm(pos[:, _LS] - pos[:, _RS], axis=-1)
    mid = 0.5 * (pos[:, _LS] + pos[:, _RS])
    head = next((j for j in _HEAD_JOINTS if rec[j]), None)
    out: dict[str, dict[str, float]] = {}
    for name in _SIGNED_AXES:
        u = axis_vector(name)
        down = []
        for s, e in ((_LS, _LE), (_RS, _RE)):
            down.append(_median_ratio((pos[:, s] - pos[:, e]) @ u, np.linalg.norm(pos[:, s] - pos[:, e], axis=-1)))
        level = abs(_median_ratio((pos[:, _LS] - pos[:, _RS]) @ u, width))
        head_above = float("nan") if head is None else _median_ratio((pos[:, head] - mid) @ u, width)
        out[name] = {"arms_down": float(np.mean(down)), "level": level, "head": head_above}
    return out


def body_axis(positions: np.ndarray, recorded: np.ndarray | None = None) -> np.ndarray:
    """The direction the body stands along, a unit vector (3,), from medians over the frames.

    Per frame: the direction from the mid-shoulder point to a recorded head (without
    one: the mean direction the upper arms hang in, negated, i.e. from elbows to
    shoulders), with its component along the shoulder line removed (the body's
    axis is across the shoulders). The median of each coordinate over the
    frames, normalised.
    """
    pos = np.asarray(positions, dtype=np.float64)
    rec = np.ones(pos.shape[1], dtype=bool) if recorded is None else np.asarray(recorded, dtype=bool)
    across = pos[:, _LS] - pos[:, _RS]
    across /= np.maximum(np.linalg.norm(across, axis=-1, keepdims=True), 1e-12)
    head = next((j for j in _HEAD_JOINTS if rec[j]), None)
    if head is not None:
        d = pos[:, head] - 0.5 * (pos[:, _LS] + pos[:, _RS])
    else:
        d = np.zeros_like(across)
        for s, e in ((_LS, _LE), (_RS, _RE)):
            arm = pos[:, s] - pos[:, e]
            d += arm / np.maximum(np.linalg.norm(arm, axis=-1, keepdims=True), 1e-12)
    d = d - np.sum(d * across, axis=-1, keepdims=True) * across
    d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
    axis = np.median(d, axis=0)
    norm = float(np.linalg.norm(axis))
    return axis / norm if norm > 0 else np.array([0.0, 1.0, 0.0])


def _passes(score: dict[str, float]) -> bool:
    head_ok = np.isnan(score["head"]) or score["head"] > _HEAD_ABOVE
    return score["arms_down"] > _ARMS_DOWN and score["level"] < _SHOULDERS_LEVEL and bool(head_ok)


def check_upright(
    positions: np.ndarray,
    *,
    recorded: np.ndarray | None = None,
    path: str | os.PathLike[str] | None = None,
    what: str = "the motion",
) -> None:
    """Refuse a motion that does not stand upright along +Y.

    Upright means (see :func:`upright_scores` and :func:`body_axis`): the body's
    axis is within 45 degrees of +Y, the upper arms hang below the shoulders most
    of the time, the shoulders are level, and a recorded head is above them.
    When the body stands along another axis, the message says which ``--up``
    to pass.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions, read with Y as up.
    recorded : np.ndarray, shape (55,) bool, optional
        Joints the data holds.
    path : path, optional
        The file, named in the message.
    what : str
        How the message names the data.

    Raises
    ------
    MotionFileError
        Not upright; the message names ``--up`` and, where one axis passes, its value.
    """
    scores = upright_scores(positions, recorded)
    axis = body_axis(positions, recorded)
    tilt = float(np.degrees(np.arccos(np.clip(axis[1], -1.0, 1.0))))
    if tilt <= _MAX_TILT_DEG and _passes(scores["y"]):
        return
    along = _name_of(axis)
    y = scores["y"]
    seen = f"body {tilt:.0f} degrees from y, elbows below shoulders {y['arms_down']:+.2f} upper arms, "
    seen += f"shoulder tilt {y['level']:.2f} widths"
    if not np.isnan(y["head"]):
        seen += f", head above shoulders {y['head']:+.2f} widths"
    if along == "y":
        hint = "check the joint map, or pass --up y if the data is upright after all"
    elif along in UP_CHOICES and _passes(scores[along]):
        hint = f"it looks like its up axis is {along}: pass --up {along}"
    elif _passes(scores[along]):
        hint = f"its up axis looks like {along}, which --up does not take; rotate the data so that y or z is up"
    else:
        hint = "no axis makes it upright; check the joint map, or pass --up if the axes are known"
    raise MotionFileError(f"{what} does not stand upright with y as up ({seen}); {hint}", path=path)


def body_size(positions: np.ndarray) -> float:
    """A body size in the file's units: the median of shoulder width and both upper-arm lengths.

    About 0.3 m for an adult (shoulders 0.3-0.4 m, upper arms 0.25-0.35 m).
    """
    pos = np.asarray(positions, dtype=np.float64)
    parts = np.stack(
        [
            np.linalg.norm(pos[:, _LS] - pos[:, _RS], axis=-1),
            np.linalg.norm(pos[:, _LE] - pos[:, _LS], axis=-1),
            np.linalg.norm(pos[:, _RE] - pos[:, _RS], axis=-1),
        ]
    )
    return float(np.median(parts))


@dataclass(frozen=True)
class _Units:
    name: str
    size: float


def detect_units(positions: np.ndarray, *, path: str | os.PathLike[str] | None = None) -> str:
    """The unit (``"m"``, ``"cm"`` or ``"mm"``) in which :func:`body_size` is a human's.

    Raises
    ------
    MotionFileError
        No unit gives a body size between 8 and 70 cm; the message names ``--units``.
    """
    size = body_size(positions)
    lo, hi = _PLAUSIBLE_SIZE_M
    fits = [_Units(u, size * s) for u, s in UNIT_SCALE.items() if lo <= size * s <= hi]
    if len(fits) != 1:
        raise MotionFileError(
            f"cannot tell the units: the shoulder width and upper arms measure {size:.4g} file units, "
            f"which is no human size ({lo * 100:g}-{hi * 100:g} cm) in m, cm or mm; "
            "check the joint map, or pass --units m, cm or mm",
            path=path,
        )
    return fits[0].name
