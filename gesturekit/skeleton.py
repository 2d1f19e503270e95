"""The 55-joint output skeleton of the paper: 13 upper-body joints and 21 per hand.

Positions are pelvis-relative, in metres, Y up; the character faces +Z and its
left is +X. Joint order: the 13 body joints, then the 21 joints of the left
hand, then the 21 joints of the right hand. Each hand is the wrist followed by
five fingers (thumb, index, middle, ring, pinky) of four joints each, from the
root (MCP; the thumb's CMC) to the tip.

The body joints do not include the pelvis itself: pelvis-relative positions
would make it the constant origin. ``spine_mid`` is therefore a root of the
joint tree (parent ``-1``); its offset from the pelvis is implicit.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ._arguments import checks_arguments

__all__ = [
    "BODY_JOINTS",
    "FINGERS",
    "HAND_JOINT_SUFFIXES",
    "JOINT_NAMES",
    "N_JOINTS",
    "PARENTS",
    "POSE_FEATURE_JOINTS",
    "POSE_FEATURE_INDICES",
    "FPS",
    "joint_index",
    "bones",
    "hand_indices",
    "RECORDED",
    "DERIVED",
    "ABSENT",
    "JOINT_STATES",
    "REQUIRED_JOINTS",
    "DERIVABLE_JOINTS",
    "JointPresence",
    "missing_required",
]

#: Frame rate of everything the search touches, frames per second.
FPS = 15

#: The 13 upper-body joints, with their parents (names), root first.
BODY_JOINTS: tuple[tuple[str, str | None], ...] = (
    ("spine_mid", None),
    ("chest", "spine_mid"),
    ("upper_chest", "chest"),
    ("neck", "upper_chest"),
    ("neck_upper", "neck"),
    ("head", "neck_upper"),
    ("head_top", "head"),
    ("left_collar", "upper_chest"),
    ("left_shoulder", "left_collar"),
    ("left_elbow", "left_shoulder"),
    ("right_collar", "upper_chest"),
    ("right_shoulder", "right_collar"),
    ("right_elbow", "right_shoulder"),
)

FINGERS = ("thumb", "index", "middle", "ring", "pinky")

#: Suffixes of the 21 joints of one hand, in order: wrist, then finger joints 1 (root) .. 4 (tip).
HAND_JOINT_SUFFIXES: tuple[str, ...] = ("wrist",) + tuple(f"{finger}{i}" for finger in FINGERS for i in range(1, 5))


def _build() -> tuple[tuple[str, ...], np.ndarray]:
    names = [n for n, _ in BODY_JOINTS]
    parent_names: list[str | None] = [p for _, p in BODY_JOINTS]
    for side in ("left", "right"):
        for suffix in HAND_JOINT_SUFFIXES:
            names.append(f"{side}_{suffix}")
            if suffix == "wrist":
                parent_names.append(f"{side}_elbow")
            elif suffix.endswith("1"):
                parent_names.append(f"{side}_wrist")
            else:
                parent_names.append(f"{side}_{suffix[:-1]}{int(suffix[-1]) - 1}")
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([-1 if p is None else index[p] for p in parent_names], dtype=np.int64)
    return tuple(names), parents


JOINT_NAMES, PARENTS = _build()
N_JOINTS = len(JOINT_NAMES)
assert N_JOINTS == 55 and np.all(PARENTS < np.arange(N_JOINTS)), "parents must precede children"

#: The 8 joints of the pose feature: left/right elbow, wrist, index root, little-finger root.
POSE_FEATURE_JOINTS: tuple[str, ...] = (
    "left_elbow",
    "left_wrist",
    "left_index1",
    "left_pinky1",
    "right_elbow",
    "right_wrist",
    "right_index1",
    "right_pinky1",
)


@checks_arguments
def joint_index(name: str) -> int:
    """Index of a joint of the 55-joint skeleton by name."""
    try:
        return JOINT_NAMES.index(name)
    except ValueError:
        raise KeyError(f"no joint named {name!r} in the 55-joint skeleton") from None


POSE_FEATURE_INDICES = np.array([joint_index(n) for n in POSE_FEATURE_JOINTS], dtype=np.int64)


@checks_arguments
def bones() -> np.ndarray:
    """Bones as (child, parent) index pairs, shape (54, 2); the root has none."""
    child = np.flatnonzero(PARENTS >= 0)
    return np.stack([child, PARENTS[child]], axis=1)


@checks_arguments
def hand_indices(side: str) -> np.ndarray:
    """Indices of the 21 joints of the ``"left"`` or ``"right"`` hand, wrist first."""
    if side not in ("left", "right"):
        raise ValueError("side must be 'left' or 'right'")
    return np.array([joint_index(f"{side}_{s}") for s in HAND_JOINT_SUFFIXES], dtype=np.int64)


# ---- joints a motion's data actually holds ------------------------------------------------------

#: A joint the source data holds.
RECORDED = "recorded"
#: A joint the source lacks, placed from the ones it has (the torso and head from the neck and
#: shoulders); shown, but marked as derived.
DERIVED = "derived"
#: A joint the source lacks and that is not derived: it sits on its parent and is not drawn.
ABSENT = "absent"
JOINT_STATES: tuple[str, ...] = (RECORDED, DERIVED, ABSENT)

#: Joints a motion must hold, by what needs them.
REQUIRED_JOINTS: dict[str, tuple[str, ...]] = {
    "the pose feature of the matching": POSE_FEATURE_JOINTS,
    "the hand controls": ("left_wrist", "right_wrist"),
    "placing the arms on the body (views, BVH, the derived torso)": ("left_shoulder", "right_shoulder"),
}

#: Joints that may be derived from the neck and the shoulders when a source lacks them.
DERIVABLE_JOINTS: tuple[str, ...] = (
    "spine_mid",
    "chest",
    "upper_chest",
    "neck",
    "neck_upper",
    "head",
    "head_top",
    "left_collar",
    "right_collar",
)


@checks_arguments
def missing_required(present: Iterable[str]) -> list[str]:
    """What each need lacks among the joints ``present``, one line per need; empty when none lacks.

    For example ``["the hand controls needs left_wrist"]``.
    """
    have = set(present)
    out = []
    for purpose, names in REQUIRED_JOINTS.items():
        lack = [n for n in names if n not in have]
        if lack:
            out.append(f"{purpose} needs {', '.join(lack)}")
    return out


@dataclass(frozen=True)
class JointPresence:
    """What the data holds of each of the 55 joints: recorded, derived or absent.

    Parameters
    ----------
    status : tuple of str, length 55
        One of :data:`JOINT_STATES` per joint, in the order of :data:`JOINT_NAMES`.
    """

    status: tuple[str, ...]

    def __post_init__(self) -> None:
        status = tuple(str(s) for s in self.status)
        if len(status) != N_JOINTS:
            raise ValueError(f"joint presence needs one status per joint ({N_JOINTS}), got {len(status)}")
        bad = sorted({s for s in status if s not in JOINT_STATES})
        if bad:
            raise ValueError(f"unknown joint status {bad}; expected one of {', '.join(JOINT_STATES)}")
        object.__setattr__(self, "status", status)

    @classmethod
    def full(cls) -> JointPresence:
        """Every joint recorded (a complete 55-joint source)."""
        return cls((RECORDED,) * N_JOINTS)

    @classmethod
    def from_names(cls, *, recorded: Iterable[str], derived: Iterable[str] = ()) -> JointPresence:
        """Presence from the names of the recorded and derived joints; the rest are absent."""
        rec, der = set(recorded), set(derived)
        unknown = sorted((rec | der) - set(JOINT_NAMES))
        if unknown:
            raise ValueError(f"no joints named {unknown} in the 55-joint skeleton")
        if rec & der:
            raise ValueError(f"joints both recorded and derived: {sorted(rec & der)}")
        return cls(tuple(RECORDED if n in rec else DERIVED if n in der else ABSENT for n in JOINT_NAMES))

    def _is(self, state: str) -> np.ndarray:
        return np.array([s == state for s in self.status], dtype=bool)

    @property
    def recorded(self) -> np.ndarray:
        """Shape (55,) bool: joints the data holds."""
        return self._is(RECORDED)

    @property
    def derived(self) -> np.ndarray:
        """Shape (55,) bool: joints placed from others."""
        return self._is(DERIVED)

    @property
    def absent(self) -> np.ndarray:
        """Shape (55,) bool: joints that are neither (not drawn, not written to BVH)."""
        return self._is(ABSENT)

    @property
    def drawn(self) -> np.ndarray:
        """Shape (55,) bool: joints to draw (recorded or derived)."""
        return ~self.absent

    @property
    def is_full(self) -> bool:
        """Every joint is recorded."""
        return all(s == RECORDED for s in self.status)

    def names(self, state: str) -> tuple[str, ...]:
        """Names of the joints in ``state`` (one of :data:`JOINT_STATES`), in skeleton order."""
        if state not in JOINT_STATES:
            raise ValueError(f"unknown joint status {state!r}")
        return tuple(n for n, s in zip(JOINT_NAMES, self.status, strict=True) if s == state)

    def drawn_bones(self) -> np.ndarray:
        """Bones whose two ends are drawn, as (child, parent) index pairs, shape (B, 2)."""
        b = bones()
        keep = self.drawn
        return b[keep[b[:, 0]] & keep[b[:, 1]]]

    def describe(self) -> str:
        """One line, e.g. ``"46 recorded, 9 derived (spine_mid, ...), 0 absent"``."""
        parts = []
        for state in JOINT_STATES:
            names = self.names(state)
            shown = f" ({', '.join(names)})" if names and state != RECORDED and len(names) <= 12 else ""
            parts.append(f"{len(names)} {state}{shown}")
        return ", ".join(parts)

    def to_list(self) -> list[str]:
        """The 55 statuses, for JSON."""
        return list(self.status)
