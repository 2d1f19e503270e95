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

import numpy as np

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


def joint_index(name: str) -> int:
    """Index of a joint of the 55-joint skeleton by name."""
    try:
        return JOINT_NAMES.index(name)
    except ValueError:
        raise KeyError(f"no joint named {name!r} in the 55-joint skeleton") from None


POSE_FEATURE_INDICES = np.array([joint_index(n) for n in POSE_FEATURE_JOINTS], dtype=np.int64)


def bones() -> np.ndarray:
    """Bones as (child, parent) index pairs, shape (54, 2); the root has none."""
    child = np.flatnonzero(PARENTS >= 0)
    return np.stack([child, PARENTS[child]], axis=1)


def hand_indices(side: str) -> np.ndarray:
    """Indices of the 21 joints of the ``"left"`` or ``"right"`` hand, wrist first."""
    if side not in ("left", "right"):
        raise ValueError("side must be 'left' or 'right'")
    return np.array([joint_index(f"{side}_{s}") for s in HAND_JOINT_SUFFIXES], dtype=np.int64)
