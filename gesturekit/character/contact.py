"""Poses a body cannot take: hands in the head or the torso, and crossed wrists, on the default body's shapes.

:func:`pose_contacts` measures, frame by frame, three things a viewer sees as wrong on the
character (:mod:`gesturekit.character.mesh`, the shapes of :mod:`._body`):

- **hand in the head**: a joint of a hand (the wrist and its 20 finger joints) within
  :data:`HEAD_MARGIN` (1.2) head radii of the head's centre. The head is the default body's:
  its centre ``head + 0.38 s up + 0.05 s front`` and its radius ``0.67 s``, the mean of the
  head's half-extents (0.79 s high, 0.68 s deep, 0.54 s wide), with ``s`` the head bone's
  length (head to head top) and ``up`` its direction;
- **crossed wrists**: the left wrist lies to the right of the right wrist, along the line
  from the right shoulder to the left one (the body's own left-right axis in that frame), by
  more than :data:`CROSS_MARGIN` (1 cm): the forearms cross;
- **hand in the torso**: a hand joint inside the default body's torso, a tube along the
  line from ``spine_mid`` to the neck whose elliptic cross-sections have the body's half-width
  and half-depth (in shoulder widths) at each height, the torso turned as the shoulders turn.

A real speaker's motion capture (the ZEGGS take) has no frame with a hand in the head or
crossed wrists; its hands rest on the belly, which is slimmer than the default body's, so
1.6 % of its frames put a hand in the default body's torso.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..skeleton import FINGERS, N_JOINTS, joint_index
from ._body import _TORSO

__all__ = ["CROSS_MARGIN", "HEAD_MARGIN", "PoseContacts", "hand_joints", "pose_contacts"]

#: A hand joint this many head radii from the head's centre, or nearer, is in the head.
HEAD_MARGIN = 1.2
#: Wrists crossed by more than this (metres, along the shoulder line) are crossed.
CROSS_MARGIN = 0.01
#: The default body's head: centre along the head bone and to the front, and its radius, in head-bone lengths.
_HEAD_UP, _HEAD_FRONT, _HEAD_RADIUS = 0.38, 0.05, (0.5 * (0.66 + 0.92) + 0.68 + 0.54) / 3.0

_SPINE, _NECK, _HEAD, _TOP = (joint_index(n) for n in ("spine_mid", "neck", "head", "head_top"))
_LS, _RS, _LW, _RW = (joint_index(n) for n in ("left_shoulder", "right_shoulder", "left_wrist", "right_wrist"))


@checks_arguments
def hand_joints(side: str) -> np.ndarray:
    """The joints of one hand (``"left"`` or ``"right"``): its wrist and 20 finger joints, shape (21,)."""
    if side not in ("left", "right"):
        raise ConfigError(f"side must be 'left' or 'right', got {side!r}")
    names = [f"{side}_wrist"] + [f"{side}_{f}{i}" for f in FINGERS for i in range(1, 5)]
    return np.array([joint_index(n) for n in names], dtype=np.int64)


@dataclass(frozen=True)
class PoseContacts:
    """Per frame, where a pose goes through the body (see :func:`pose_contacts`).

    Attributes
    ----------
    hand_in_head, wrists_crossed, hand_in_torso : np.ndarray, shape (frames,), bool
    """

    hand_in_head: np.ndarray
    wrists_crossed: np.ndarray
    hand_in_torso: np.ndarray

    @property
    def n_frames(self) -> int:
        return len(self.hand_in_head)

    def fractions(self) -> dict[str, float]:
        """Fraction of frames with each problem, in [0, 1] (NaN for no frames)."""
        return {
            name: float(getattr(self, name).mean()) if self.n_frames else float("nan")
            for name in ("hand_in_head", "wrists_crossed", "hand_in_torso")
        }

    def summary(self) -> str:
        """One line: the percentage of frames with each problem, and the frames counted."""
        f = self.fractions()
        return (
            f"hands in the head {100 * f['hand_in_head']:.1f} %, wrists crossed {100 * f['wrists_crossed']:.1f} %, "
            f"hands in the torso {100 * f['hand_in_torso']:.1f} % of {self.n_frames} frames"
        )


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 1e-12)


@checks_arguments
def pose_contacts(positions: np.ndarray) -> PoseContacts:
    """Hands in the head or the torso and crossed wrists, frame by frame (see the module notes).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions in metres, Y up (any root); the head, head top, spine, neck, shoulders
        and hands must be drawn.

    Returns
    -------
    PoseContacts

    Raises
    ------
    ConfigError
        Positions of another shape, or not finite.

    Examples
    --------
    >>> from gesturekit.datasets.synthetic import generate_demo_take
    >>> take = generate_demo_take(seconds=2.0, seed=1, name="t")[0]
    >>> pose_contacts(take.motion.positions[:1]).fractions()  # the speaker at rest: nothing touches
    {'hand_in_head': 0.0, 'wrists_crossed': 0.0, 'hand_in_torso': 0.0}
    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[1:] != (N_JOINTS, 3):
        raise ConfigError(f"positions must have shape (frames, {N_JOINTS}, 3), got {pos.shape}")
    if not np.isfinite(pos).all():
        raise ConfigError("positions must be finite")
    hands = pos[:, np.concatenate([hand_joints("left"), hand_joints("right")])]  # (T, 42, 3)

    # the head: a ball around the default body's head centre
    bone = pos[:, _TOP] - pos[:, _HEAD]
    size = np.linalg.norm(bone, axis=-1)
    up_h = _unit(bone)
    lateral = _unit(pos[:, _LS] - pos[:, _RS])
    front_h = _unit(np.cross(lateral, up_h))
    centre = pos[:, _HEAD] + _HEAD_UP * size[:, None] * up_h + _HEAD_FRONT * size[:, None] * front_h
    dist = np.linalg.norm(hands - centre[:, None], axis=-1)
    in_head = (dist <= HEAD_MARGIN * _HEAD_RADIUS * size[:, None]).any(axis=1)

    # crossed wrists: the left wrist to the right of the right one along the shoulder line
    crossed = np.einsum("ti,ti->t", pos[:, _LW] - pos[:, _RW], lateral) < -CROSS_MARGIN

    # the torso: elliptic sections along spine_mid -> neck, turned with the shoulders
    axis = pos[:, _NECK] - pos[:, _SPINE]
    height = np.linalg.norm(axis, axis=-1)
    up = _unit(axis)
    side = _unit(lateral - np.einsum("ti,ti->t", lateral, up)[:, None] * up)
    front = np.cross(side, up)
    width = np.linalg.norm(pos[:, _LS] - pos[:, _RS], axis=-1)
    rel = hands - pos[:, _SPINE][:, None]
    s = np.einsum("tji,ti->tj", rel, up) / np.maximum(height, 1e-9)[:, None]  # station, torso heights
    a = np.interp(s, _TORSO[:, 0], _TORSO[:, 1]) * width[:, None]  # half-width, metres
    b = np.interp(s, _TORSO[:, 0], _TORSO[:, 2]) * width[:, None]  # half-depth
    x = np.einsum("tji,ti->tj", rel, side)
    z = np.einsum("tji,ti->tj", rel, front)
    inside = (s >= _TORSO[0, 0]) & (s <= _TORSO[-1, 0]) & ((x / a) ** 2 + (z / b) ** 2 < 1.0)
    return PoseContacts(hand_in_head=in_head, wrists_crossed=crossed, hand_in_torso=inside.any(axis=1))
