"""Partial skeletons: a torso and head derived from the neck and shoulders, absent joints collapsed.

A source that holds only some of our 55 joints (keypoints lifted from video:
neck, arms and hands) is completed here, in our frame (Y up, metres):

- the neck, when not given, is the mid-shoulder point;
- the torso is straight below the neck, along -Y: ``upper_chest``, ``chest`` and
  ``spine_mid`` at 0.35, 0.75 and 1.2 shoulder widths;
- the head is straight above it, along +Y: ``neck_upper``, ``head`` and ``head_top``
  at 0.25, 0.55 and 0.9 shoulder widths;
- each collar lies 40 % of the way from the neck to its shoulder.

The shoulder width is the take's median (about 0.35 m for an adult, so the chest
sits 26 cm and the head 19 cm from the neck): the derived joints keep one place
relative to the neck throughout a take. They are marked ``derived``. Every other
joint the source lacks (fingers, say) is ``absent``: it sits on its parent.
"""

from __future__ import annotations

import numpy as np

from ..errors import MotionFileError
from ..skeleton import JOINT_NAMES, PARENTS, JointPresence, joint_index

__all__ = ["TORSO_BELOW_NECK", "HEAD_ABOVE_NECK", "COLLAR_FRACTION", "complete_skeleton"]

#: Derived torso joints: distance below the neck, in shoulder widths.
TORSO_BELOW_NECK: dict[str, float] = {"upper_chest": 0.35, "chest": 0.75, "spine_mid": 1.2}
#: Derived head joints: distance above the neck, in shoulder widths.
HEAD_ABOVE_NECK: dict[str, float] = {"neck_upper": 0.25, "head": 0.55, "head_top": 0.9}
#: A derived collar lies this fraction of the way from the neck to its shoulder.
COLLAR_FRACTION = 0.4

_NECK = joint_index("neck")
_LS, _RS = joint_index("left_shoulder"), joint_index("right_shoulder")


def complete_skeleton(positions: np.ndarray, recorded: np.ndarray) -> tuple[np.ndarray, JointPresence]:
    """Place the joints a source lacks: derive the torso, head and collars, collapse the rest.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Positions in our frame (Y up), metres; only the ``recorded`` joints are read.
    recorded : np.ndarray, shape (55,) bool
        Joints the source holds; must include both shoulders.

    Returns
    -------
    positions : np.ndarray, shape (frames, 55, 3)
        Every joint placed: recorded ones unchanged, derived ones as the module
        docstring says, absent ones on their parent.
    presence : JointPresence
    """
    pos = np.array(positions, dtype=np.float64, copy=True)
    rec = np.asarray(recorded, dtype=bool)
    if rec.all():
        return pos, JointPresence.full()
    names = {n for n, r in zip(JOINT_NAMES, rec, strict=True) if r}
    if "left_shoulder" not in names or "right_shoulder" not in names:
        raise MotionFileError("deriving the torso needs both shoulders")
    derived: list[str] = []
    if "neck" not in names:
        pos[:, _NECK] = 0.5 * (pos[:, _LS] + pos[:, _RS])
        derived.append("neck")
    width = float(np.median(np.linalg.norm(pos[:, _LS] - pos[:, _RS], axis=-1)))
    up = np.array([0.0, 1.0, 0.0])
    neck = pos[:, _NECK]
    for name, k in {**{n: -d for n, d in TORSO_BELOW_NECK.items()}, **HEAD_ABOVE_NECK}.items():
        if name not in names:
            pos[:, joint_index(name)] = neck + k * width * up
            derived.append(name)
    for side, shoulder in (("left", _LS), ("right", _RS)):
        name = f"{side}_collar"
        if name not in names:
            pos[:, joint_index(name)] = neck + COLLAR_FRACTION * (pos[:, shoulder] - neck)
            derived.append(name)
    placed = rec.copy()
    placed[[joint_index(n) for n in derived]] = True
    for j in range(len(JOINT_NAMES)):  # parents precede children
        if not placed[j]:
            pos[:, j] = pos[:, PARENTS[j]]
    return pos, JointPresence.from_names(recorded=names, derived=derived)
