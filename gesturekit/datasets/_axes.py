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
    "check_given_units",
    "check_given_up",
    "check_skeleton",
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


_OVERRIDE = "--no-plausibility-check reads it as given"


def check_given_units(positions: np.ndarray, units: str, *, path: str | os.PathLike[str] | None = None) -> None:
    """Refuse a given unit in which the body has no human size (as ``units="auto"`` would find none).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Positions in the file's units.
    units : {"m", "cm", "mm"}
        The unit given.

    Raises
    ------
    MotionFileError
        The message gives the size and names the unit that gives a human size, if one does.
    """
    size = body_size(positions)
    lo, hi = _PLAUSIBLE_SIZE_M
    if lo <= size * UNIT_SCALE[units] <= hi:
        return
    fits = [u for u, s in UNIT_SCALE.items() if lo <= size * s <= hi]
    hint = f"in {fits[0]} it is a human's: pass --units {fits[0]}" if len(fits) == 1 else "check the joint map"
    raise MotionFileError(
        f"--units {units} makes the shoulder width and upper arms {size * UNIT_SCALE[units] * 100:.4g} cm, "
        f"no human size ({lo * 100:g}-{hi * 100:g} cm); {hint} ({_OVERRIDE})",
        path=path,
    )


def _stands_along(positions: np.ndarray, recorded: np.ndarray | None, up: str) -> bool:
    """Whether the body stands upright with ``up`` (source axes) as up: the tests of :func:`check_upright`."""
    tilt = float(np.degrees(np.arccos(np.clip(body_axis(positions, recorded) @ axis_vector(up), -1.0, 1.0))))
    return tilt <= _MAX_TILT_DEG and _passes(upright_scores(positions, recorded)[up])


def check_given_up(
    positions: np.ndarray, up: str, *, recorded: np.ndarray | None = None, path: str | os.PathLike[str] | None = None
) -> None:
    """Refuse a given up axis with which the body does not stand upright (the tests of :func:`check_upright`).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Positions in the file's axes.
    up : {"y", "-y", "z", "-z"}
        The up axis given.

    Raises
    ------
    MotionFileError
        The message names the up axis that stands it upright, if one does.
    """
    if _stands_along(positions, recorded, up):
        return
    fits = [a for a in UP_CHOICES if a != up and _stands_along(positions, recorded, a)]
    along = _name_of(body_axis(positions, recorded))
    hint = f"it stands upright with {fits[0]} as up: pass --up {fits[0]}" if fits else "check the joint map"
    raise MotionFileError(
        f"--up {up} does not stand the motion upright (its body stands along {along}); {hint} ({_OVERRIDE})", path=path
    )


# check_skeleton: median lengths a human's arm bones and shoulder width have, metres ...
_ARM_BONE_M = (0.08, 0.7)
# ... and the torso (pelvis to mid-shoulder point), which may vary this much (std over median)
_TORSO_M = (0.15, 1.0)
_TORSO_SPREAD = 0.25
# ... and along an arm, a child's median distance from the mid-shoulder point is at least this
# fraction of its parent's (a hand held near the chest brings a wrist about as near as its elbow;
# swapped joints bring the elbow far nearer than the wrist)
_CHAIN_MARGIN = 0.85


def check_skeleton(
    positions: np.ndarray,
    recorded: np.ndarray,
    *,
    sources: dict[str, str],
    pelvis: bool,
    path: str | os.PathLike[str] | None = None,
) -> None:
    """Refuse a joint map whose skeleton is no human's: arm bones and shoulders of no human length,
    an arm whose joints do not get farther from the shoulders joint by joint (within a margin),
    a torso (with a
    mapped pelvis) of no human length or that stretches as the body moves.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Metres, our frame, relative to the pelvis when ``pelvis``.
    recorded : np.ndarray, shape (55,) bool
    sources : dict
        Our joint name -> the source column it was read from, named in messages.
    pelvis : bool
        The positions are relative to a mapped pelvis (its column is ``sources["pelvis"]``).

    Raises
    ------
    MotionFileError
        The message names the joints, their source columns and what was measured.
    """
    pos = np.asarray(positions, dtype=np.float64)

    def name(j: str) -> str:
        return f"{j} ({sources.get(j, '?')})"

    def length(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.linalg.norm(a - b, axis=-1)

    mid = 0.5 * (pos[:, _LS] + pos[:, _RS])
    lo, hi = _ARM_BONE_M
    for side in ("left", "right"):
        s, e, w = (joint_index(f"{side}_{j}") for j in ("shoulder", "elbow", "wrist"))
        for (pa, ch), (a, b) in ((("shoulder", "elbow"), (s, e)), (("elbow", "wrist"), (e, w))):
            if not (recorded[a] and recorded[b]):
                continue
            bone = float(np.median(length(pos[:, a], pos[:, b])))
            if not lo <= bone <= hi:
                raise MotionFileError(
                    f"the joint map gives the bone {name(f'{side}_{pa}')} to {name(f'{side}_{ch}')} a median length of "
                    f"{bone * 100:.3g} cm, no human's ({lo * 100:g}-{hi * 100:g} cm); check the joint map "
                    f"({_OVERRIDE})",
                    path=path,
                )
        chain = [j for j in (s, e, w) if recorded[j]]
        reach = [float(np.median(length(pos[:, j], mid))) for j in chain]
        for (parent, ra), (child, rc) in zip(zip(chain, reach), zip(chain[1:], reach[1:])):
            if rc < _CHAIN_MARGIN * ra:
                from ..skeleton import JOINT_NAMES

                raise MotionFileError(
                    f"the joint map's {name(JOINT_NAMES[child])} is nearer the shoulders ({rc * 100:.3g} cm, median) "
                    f"than its parent {name(JOINT_NAMES[parent])} ({ra * 100:.3g} cm): are they swapped? check the "
                    f"joint map ({_OVERRIDE})",
                    path=path,
                )
    width = float(np.median(length(pos[:, _LS], pos[:, _RS])))
    if not lo <= width <= hi:
        raise MotionFileError(
            f"the joint map puts {name('left_shoulder')} and {name('right_shoulder')} {width * 100:.3g} cm apart "
            f"(median), no human's shoulder width ({lo * 100:g}-{hi * 100:g} cm); check the joint map ({_OVERRIDE})",
            path=path,
        )
    if pelvis:
        torso = np.linalg.norm(mid, axis=-1)
        median = float(np.median(torso))
        spread = float(np.std(torso)) / max(median, 1e-9)
        tlo, thi = _TORSO_M
        if not tlo <= median <= thi or spread > _TORSO_SPREAD:
            raise MotionFileError(
                f"the joint map's pelvis ({sources.get('pelvis', '?')}) is {median * 100:.3g} cm from the mid-shoulder "
                f"point (median, varying by {spread:.0%}): a torso is {tlo * 100:g}-{thi * 100:g} cm and keeps its "
                f"length; is the pelvis another joint? check the joint map ({_OVERRIDE})",
                path=path,
            )
