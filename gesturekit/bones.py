"""Bone lengths of a motion: one length per bone, and positions that keep it.

Keypoints lifted from video have bones whose length changes from frame to frame.
:func:`normalise_bone_lengths` gives every bone one length (its median over the
frames) and rebuilds the positions along the chains from the root, keeping the
direction of every bone in every frame. :func:`fit_bone_lengths` is the length
it uses, also the one a BVH file is written with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ConfigError
from .skeleton import JOINT_NAMES, N_JOINTS, PARENTS, JointPresence

__all__ = ["BoneLengthReport", "fit_bone_lengths", "normalise_bone_lengths", "bone_length_spread"]

# bones shorter than this (metres) are treated as zero: a hand root that repeats the wrist
_ZERO = 1e-6


def _check(positions: np.ndarray) -> np.ndarray:
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[1:] != (N_JOINTS, 3) or pos.shape[0] == 0:
        raise ConfigError(f"positions must have shape (frames, {N_JOINTS}, 3) with frames > 0, got {pos.shape}")
    return pos


def _lengths(pos: np.ndarray) -> np.ndarray:
    """(frames, 55) length of the bone ending at each joint; 0 for roots."""
    has_parent = PARENTS >= 0
    out = np.zeros(pos.shape[:2])
    child = np.flatnonzero(has_parent)
    out[:, child] = np.linalg.norm(pos[:, child] - pos[:, PARENTS[child]], axis=-1)
    return out


def fit_bone_lengths(positions: np.ndarray, presence: JointPresence | None = None) -> np.ndarray:
    """One length per bone: the median over the frames, shape (55,), metres (0 for roots and absent joints).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions in metres.
    presence : JointPresence, optional
        Absent joints get length 0 (they sit on their parent).
    """
    pos = _check(positions)
    lengths = np.median(_lengths(pos), axis=0)
    if presence is not None:
        lengths[presence.absent] = 0.0
    lengths[lengths < _ZERO] = 0.0
    return lengths


def bone_length_spread(positions: np.ndarray, presence: JointPresence | None = None) -> np.ndarray:
    """How much each bone's length varies: the standard deviation over frames, shape (55,), metres."""
    pos = _check(positions)
    spread = _lengths(pos).std(axis=0)
    if presence is not None:
        spread[presence.absent] = 0.0
    return spread


@dataclass(frozen=True)
class BoneLengthReport:
    """What :func:`normalise_bone_lengths` changed.

    Attributes
    ----------
    lengths : np.ndarray, shape (55,)
        The length given to the bone ending at each joint, metres.
    spread_before : np.ndarray, shape (55,)
        The standard deviation of each bone's length before, metres (0 after).
    mean_shift, max_shift : float
        Mean and largest distance a drawn joint moved, metres.
    worst_joint : str
        The joint that moved the most.
    """

    lengths: np.ndarray
    spread_before: np.ndarray
    mean_shift: float
    max_shift: float
    worst_joint: str

    def summary(self) -> str:
        """One line for a build log."""
        worst_bone = JOINT_NAMES[int(np.argmax(self.spread_before))]
        return (
            f"bone lengths normalised: spread before up to {self.spread_before.max() * 1000:.1f} mm "
            f"({worst_bone}), joints moved by {self.mean_shift * 1000:.1f} mm on average and at most "
            f"{self.max_shift * 1000:.1f} mm ({self.worst_joint})"
        )


def normalise_bone_lengths(
    positions: np.ndarray, presence: JointPresence | None = None, *, lengths: np.ndarray | None = None
) -> tuple[np.ndarray, BoneLengthReport]:
    """Give every bone one length, keeping its direction in every frame.

    Roots keep their positions; every other joint is placed at its (already placed) parent plus
    the bone's length along the bone's direction in the input. Where a bone has no direction in a
    frame (its two ends coincide) the direction of the nearest earlier frame is used (the first
    frame with one, before it).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions in metres.
    presence : JointPresence, optional
        Absent joints stay on their parent (length 0).
    lengths : np.ndarray, shape (55,), optional
        The lengths to give (default :func:`fit_bone_lengths`).

    Returns
    -------
    positions : np.ndarray, shape (frames, 55, 3), float64
    report : BoneLengthReport
    """
    pos = _check(positions)
    target = fit_bone_lengths(pos, presence) if lengths is None else np.asarray(lengths, dtype=np.float64)
    if target.shape != (N_JOINTS,) or not np.isfinite(target).all() or (target < 0).any():
        raise ConfigError(f"lengths must be {N_JOINTS} finite lengths >= 0, got shape {target.shape}")
    spread = bone_length_spread(pos, presence)
    out = pos.copy()
    for j in range(N_JOINTS):
        p = PARENTS[j]
        if p < 0:
            continue
        d = pos[:, j] - pos[:, p]
        norm = np.linalg.norm(d, axis=-1)
        ok = norm > _ZERO
        if target[j] == 0.0 or not ok.any():
            out[:, j] = out[:, p]
            continue
        unit = np.zeros_like(d)
        unit[ok] = d[ok] / norm[ok, None]
        if not ok.all():
            # carry the last known direction forward (the first known one backward)
            idx = np.where(ok, np.arange(len(ok)), -1)
            idx = np.maximum.accumulate(idx)
            idx[idx < 0] = int(np.flatnonzero(ok)[0])
            unit = unit[idx]
        out[:, j] = out[:, p] + target[j] * unit
    drawn = np.ones(N_JOINTS, bool) if presence is None else presence.drawn
    shift = np.linalg.norm(out - pos, axis=-1)[:, drawn]
    worst = int(np.flatnonzero(drawn)[np.unravel_index(int(np.argmax(shift)), shift.shape)[1]])
    report = BoneLengthReport(
        lengths=target,
        spread_before=spread,
        mean_shift=float(shift.mean()),
        max_shift=float(shift.max()),
        worst_joint=JOINT_NAMES[worst],
    )
    return out, report
