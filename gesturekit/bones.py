"""Bone lengths of a motion: one length per bone, and positions that keep it.

Keypoints lifted from video have bones whose length changes from frame to frame.
:func:`normalise_bone_lengths` gives every bone one length (its median over the
frames) and rebuilds the positions along the chains from the root, keeping the
direction of every bone in every frame. :func:`fit_bone_lengths` is the length
it uses, also the one a BVH file is written with.

One skeleton for many takes
---------------------------
A database whose takes are normalised one by one still has several skeletons (a
take lifted larger than another keeps its larger bones), and a motion stitched
from its clips changes size mid-result. A :class:`Skeleton` is fitted over every
frame of every take (:func:`bone_samples` per take, :func:`fit_skeleton` over
them) and given to every take (``normalise_bone_lengths(..., skeleton=...)``):

- one length per bone, the median of its length over all frames of all takes;
- a fixed shape for each joint of :data:`RIGID_GROUPS`, the joints that carry
  several bones (a BVH joint turns its child bones as one rigid piece): the
  five finger roots on each wrist, the neck and collars on the upper chest.
  Each group has a frame per frame of the data (:func:`group_frames`): its
  first axis along the bone to the first child (the middle finger's root, the
  neck), its second across it, towards the first of the other two named
  children from the second (the index finger's root from the little finger's:
  the palm's plane), its third their cross product. Each child then sits at a
  fixed offset in that frame: its bone's fitted length along the normalised
  componentwise median of its bone's direction in the frame, over all frames
  of all takes; the offsets are then turned (one rotation for the group) so
  that the frame the offsets make is the frame itself, so that a normalised
  motion's frames are those of the data it was made from.

Normalised with a skeleton, every bone has the skeleton's length in every frame
and every group's children sit at their offsets in the group's frame: a BVH file
(one length per bone, one shape per joint) then holds the motion exactly.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ._arguments import checks_arguments
from .errors import ConfigError
from .skeleton import JOINT_NAMES, N_JOINTS, PARENTS, JointPresence, joint_index

__all__ = [
    "FIT_TOLERANCE",
    "RIGID_GROUPS",
    "BoneLengthReport",
    "Skeleton",
    "bone_length_spread",
    "bone_samples",
    "bones_like",
    "fit_bone_lengths",
    "fit_skeleton",
    "group_frames",
    "normalise_bone_lengths",
    "sample_rows",
]

# bones shorter than this (metres) are treated as zero: a hand root that repeats the wrist
_ZERO = 1e-6
# a group's frame is not defined where its line across is within about 3 degrees of its first axis
_MIN_SINE = 0.05

#: Joints that carry their child bones as one rigid shape in a :class:`Skeleton`: joint ->
#: (the child along the frame's first axis, and the two children whose difference sets its second).
RIGID_GROUPS: dict[str, tuple[str, str, str]] = {
    "upper_chest": ("neck", "left_collar", "right_collar"),
    "left_wrist": ("left_middle1", "left_index1", "left_pinky1"),
    "right_wrist": ("right_middle1", "right_index1", "right_pinky1"),
}

#: Largest relative difference between a take's median bone length and its skeleton's that a take
#: appended to a database may have (``build-db --append --normalize-bones``).
FIT_TOLERANCE = 0.25

# each group's joint, frame joints and children (every skeleton child, in skeleton order)
_GROUPS: tuple[tuple[str, int, tuple[int, int, int], tuple[int, ...]], ...] = tuple(
    (
        name,
        joint_index(name),
        (joint_index(a), joint_index(b), joint_index(c)),
        tuple(int(c) for c in np.flatnonzero(PARENTS == joint_index(name))),
    )
    for name, (a, b, c) in RIGID_GROUPS.items()
)


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


@checks_arguments
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


@checks_arguments
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
    misfit : float or None
        Normalised to a :class:`Skeleton`: the largest relative difference between a bone's median
        length in the input and the skeleton's (0.1 = 10 %); None without a skeleton.
    misfit_bone : str
        That bone (named by the joint it ends at); ``""`` without a skeleton.
    """

    lengths: np.ndarray
    spread_before: np.ndarray
    mean_shift: float
    max_shift: float
    worst_joint: str
    misfit: float | None = None
    misfit_bone: str = ""

    def summary(self) -> str:
        """One line for a build log."""
        worst_bone = JOINT_NAMES[int(np.argmax(self.spread_before))]
        to = ""
        if self.misfit is not None:
            to = (
                f" to the database's skeleton (median lengths up to {self.misfit * 100:.1f} % off it, "
                f"{self.misfit_bone})"
            )
        return (
            f"bone lengths normalised{to}: spread (standard deviation over the frames) before up to "
            f"{self.spread_before.max() * 1000:.1f} mm "
            f"({worst_bone}), joints moved by {self.mean_shift * 1000:.1f} mm on average and at most "
            f"{self.max_shift * 1000:.1f} mm ({self.worst_joint})"
        )


@checks_arguments
def normalise_bone_lengths(
    positions: np.ndarray,
    presence: JointPresence | None = None,
    *,
    lengths: np.ndarray | None = None,
    skeleton: Skeleton | None = None,
) -> tuple[np.ndarray, BoneLengthReport]:
    """Give every bone one length, keeping its direction in every frame.

    Roots keep their positions; every other joint is placed at its (already placed) parent plus
    the bone's length along the bone's direction in the input. Where a bone has no direction in a
    frame (its two ends coincide) the direction of the nearest earlier frame is used (the first
    frame with one, before it).

    With a ``skeleton``, the lengths are its lengths, and the children of each of its rigid
    groups are placed at the group's offsets turned by the group's frame in the input
    (:func:`group_frames`; where a frame is not defined, the nearest earlier one, as for
    directions): the group keeps one shape, and turns as the data's does.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions in metres.
    presence : JointPresence, optional
        Absent joints stay on their parent (length 0).
    lengths : np.ndarray, shape (55,), optional
        The lengths to give (default :func:`fit_bone_lengths`); not with ``skeleton``.
    skeleton : Skeleton, optional
        One skeleton for several takes (:func:`fit_skeleton`): its lengths and rigid shapes.

    Returns
    -------
    positions : np.ndarray, shape (frames, 55, 3), float64
    report : BoneLengthReport
        With a skeleton, its ``misfit`` says how far the input's median lengths are from it.
    """
    pos = _check(positions)
    if skeleton is not None and lengths is not None:
        raise ConfigError("give either lengths or a skeleton, not both")
    given = skeleton.lengths if skeleton is not None else lengths
    target = fit_bone_lengths(pos, presence) if given is None else np.asarray(given, dtype=np.float64)
    if target.shape != (N_JOINTS,) or not np.isfinite(target).all() or (target < 0).any():
        raise ConfigError(f"lengths must be {N_JOINTS} finite lengths >= 0, got shape {target.shape}")
    spread = bone_length_spread(pos, presence)
    out = pos.copy()
    # each rigid group's frame in every frame of the input, by the group's joint
    turns: dict[int, np.ndarray] = {}
    if skeleton is not None:
        for name, joint, _frame, _children in _GROUPS:
            if name in skeleton.rigid:
                frames, ok = group_frames(pos, name)
                if ok.any():  # else no frame of this take shows the group: its bones keep their directions
                    turns[int(joint)] = frames[_carried(ok)]
    for j in range(N_JOINTS):  # parents precede children
        p = int(PARENTS[j])
        if p < 0:
            continue
        if p in turns:
            assert skeleton is not None
            out[:, j] = out[:, p] + turns[p] @ skeleton.offsets[j]
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
            unit = unit[_carried(ok)]
        out[:, j] = out[:, p] + target[j] * unit
    drawn = np.ones(N_JOINTS, bool) if presence is None else presence.drawn
    shift = np.linalg.norm(out - pos, axis=-1)[:, drawn]
    worst = int(np.flatnonzero(drawn)[np.unravel_index(int(np.argmax(shift)), shift.shape)[1]])
    misfit, misfit_bone = None, ""
    if skeleton is not None:
        misfit, misfit_bone = skeleton.misfit(np.median(_lengths(pos), axis=0))
    report = BoneLengthReport(
        lengths=target,
        spread_before=spread,
        mean_shift=float(shift.mean()),
        max_shift=float(shift.max()),
        worst_joint=JOINT_NAMES[worst],
        misfit=misfit,
        misfit_bone=misfit_bone,
    )
    return out, report


@checks_arguments
def bones_like(positions: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``positions`` given the bones of ``reference``, frame by frame.

    Roots keep their positions; every other joint is placed at its (already placed) parent plus
    the bone's length in the same frame of ``reference`` along the bone's direction in
    ``positions`` (where that bone has no direction, along the reference's). The children of
    each :data:`RIGID_GROUPS` joint are placed at the reference's offsets in the group's frame
    (:func:`group_frames`) turned by the frame of ``positions``, so a group keeps the reference's
    shape. Motion blended from clips that a BVH file holds (one length per bone, one shape per
    group) is then held by it again.

    Parameters
    ----------
    positions, reference : np.ndarray, shape (frames, 55, 3)
        Joint positions, metres: e.g. blended motion and the motion it was blended from.

    Returns
    -------
    np.ndarray, shape (frames, 55, 3), float64
    """
    pos, ref = _check(positions), _check(reference)
    if pos.shape != ref.shape:
        raise ConfigError(f"positions {pos.shape} and reference {ref.shape} differ in shape")
    out = pos.copy()
    turns: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for name, joint, _frame, _children in _GROUPS:
        mine, ok_mine = group_frames(pos, name)
        theirs, ok_theirs = group_frames(ref, name)
        ok = ok_mine & ok_theirs
        turns[int(joint)] = (mine @ np.swapaxes(theirs, -1, -2), ok)  # reference frame -> this frame
    for j in range(N_JOINTS):  # parents precede children
        p = int(PARENTS[j])
        if p < 0:
            continue
        offset = ref[:, j] - ref[:, p]
        length = np.linalg.norm(offset, axis=-1, keepdims=True)
        d = pos[:, j] - pos[:, p]
        norm = np.linalg.norm(d, axis=-1, keepdims=True)
        has = norm > _ZERO
        placed = np.where(has, d / np.where(has, norm, 1.0) * length, offset)
        if p in turns:
            turn, ok = turns[p]
            placed = np.where(ok[:, None], np.einsum("tab,tb->ta", turn, offset), placed)
        out[:, j] = out[:, p] + placed
    return out


def _carried(ok: np.ndarray) -> np.ndarray:
    """Frame indices that carry the last frame where ``ok`` holds forward (the first one backward)."""
    idx = np.where(ok, np.arange(len(ok)), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = int(np.flatnonzero(ok)[0])
    return idx


# ---- one skeleton for many takes --------------------------------------------------------------------


@checks_arguments
def group_frames(positions: np.ndarray, group: str) -> tuple[np.ndarray, np.ndarray]:
    """The frame of a rigid group in every frame of the data (see the module notes).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions, metres.
    group : str
        A joint of :data:`RIGID_GROUPS`.

    Returns
    -------
    frames : np.ndarray, shape (frames, 3, 3)
        Rotations whose columns are the frame's axes in the data's coordinates (identity where
        not defined): a child at offset ``o`` in the frame is at ``joint + frames[t] @ o``.
    ok : np.ndarray, shape (frames,), bool
        Where the frame is defined: the first child away from the joint, and the line across
        more than about 3 degrees from the first axis.
    """
    if group not in RIGID_GROUPS:
        raise ConfigError(f"{group!r} is not a rigid group; choose one of {', '.join(RIGID_GROUPS)}")
    pos = np.asarray(positions, dtype=np.float64)
    j = joint_index(group)
    a, b, c = (joint_index(n) for n in RIGID_GROUPS[group])
    return _frames(pos[:, a] - pos[:, j], pos[:, b] - pos[:, c])


def _frames(first: np.ndarray, across: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (..., 3, 3) with columns: ``first`` normalised, ``across`` made orthogonal to it and
    normalised, their cross product; and where they are defined."""
    n1 = np.linalg.norm(first, axis=-1, keepdims=True)
    e1 = np.divide(first, n1, out=np.zeros_like(first), where=n1 > _ZERO)
    perp = across - e1 * np.sum(e1 * across, axis=-1, keepdims=True)
    n2 = np.linalg.norm(perp, axis=-1, keepdims=True)
    na = np.linalg.norm(across, axis=-1, keepdims=True)
    ok = (n1[..., 0] > _ZERO) & (n2[..., 0] > _ZERO) & (n2[..., 0] > _MIN_SINE * na[..., 0])
    e2 = np.divide(perp, n2, out=np.zeros_like(perp), where=n2 > _ZERO)
    frames = np.stack([e1, e2, np.cross(e1, e2)], axis=-1)
    frames[~ok] = np.eye(3)
    return frames, ok


@checks_arguments
def sample_rows() -> tuple[str, ...]:
    """What each row of :func:`bone_samples` holds: ``"length:JOINT"`` (the bone ending at the joint,
    metres) for the 55 joints, then ``"GROUP:CHILD:x|y|z"`` (the child's bone direction in the
    group's frame, a unit vector) for each rigid group's children."""
    rows = [f"length:{n}" for n in JOINT_NAMES]
    for name, _j, _f, children in _GROUPS:
        rows += [f"{name}:{JOINT_NAMES[c]}:{axis}" for c in children for axis in "xyz"]
    return tuple(rows)


_N_ROWS = len(sample_rows())


@checks_arguments
def bone_samples(positions: np.ndarray) -> np.ndarray:
    """What a skeleton is fitted from, per frame of one take (:func:`fit_skeleton`).

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions in metres, as read (before any normalisation).

    Returns
    -------
    np.ndarray, shape (rows, frames), float32
        Rows as :func:`sample_rows` names them: the length of every bone (0 for roots), then the
        unit direction of each rigid group's child bones in the group's frame (NaN where the
        frame or the bone's direction is not defined). Row-major by sample, so that one row of
        many takes is read without the others.
    """
    pos = _check(positions)
    out = np.full((_N_ROWS, pos.shape[0]), np.nan, dtype=np.float32)
    out[:N_JOINTS] = _lengths(pos).T
    row = N_JOINTS
    for name, joint, _frame, children in _GROUPS:
        frames, ok = group_frames(pos, name)
        for c in children:
            d = pos[:, c] - pos[:, joint]
            n = np.linalg.norm(d, axis=-1)
            good = ok & (n > _ZERO)
            local = np.einsum("tji,tj->ti", frames[good], d[good] / n[good, None])  # frames[t].T @ unit
            out[row : row + 3, good] = local.T
            row += 3
    return out


@dataclass(frozen=True, eq=False)
class Skeleton:
    """One skeleton for every take of a database (see the module notes).

    Attributes
    ----------
    lengths : np.ndarray, shape (55,), float64
        The length of the bone ending at each joint, metres (0 for roots and absent joints).
    offsets : np.ndarray, shape (55, 3), float64
        For each child of a rigid group: its fixed offset from the group's joint in the group's
        frame, metres (its norm is its length); zeros for every other joint.
    rigid : tuple of str
        The groups of :data:`RIGID_GROUPS` held rigid (those whose frame joints are drawn).
    takes, frames : int
        How many takes and frames it was fitted over.
    """

    lengths: np.ndarray
    offsets: np.ndarray
    rigid: tuple[str, ...]
    takes: int
    frames: int

    def __post_init__(self) -> None:
        lengths = np.asarray(self.lengths, dtype=np.float64)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        if lengths.shape != (N_JOINTS,) or not np.isfinite(lengths).all() or (lengths < 0).any():
            raise ConfigError(f"a skeleton's lengths must be {N_JOINTS} finite lengths >= 0, got {lengths.shape}")
        if offsets.shape != (N_JOINTS, 3) or not np.isfinite(offsets).all():
            raise ConfigError(f"a skeleton's offsets must be finite, of shape ({N_JOINTS}, 3), got {offsets.shape}")
        unknown = [g for g in self.rigid if g not in RIGID_GROUPS]
        if unknown:
            raise ConfigError(f"unknown rigid groups {unknown}; choose from {', '.join(RIGID_GROUPS)}")
        for name, _j, _f, children in _GROUPS:
            if name in self.rigid:
                norms = np.linalg.norm(offsets[list(children)], axis=-1)
                if not np.allclose(norms, lengths[list(children)], rtol=1e-6, atol=1e-9):
                    raise ConfigError(f"a skeleton's offsets on {name} must have the lengths of their bones")
        if not (self.takes >= 1 and self.frames >= 1):
            raise ConfigError(f"a skeleton is fitted over takes and frames, got {self.takes} and {self.frames}")
        lengths.setflags(write=False)
        offsets.setflags(write=False)
        object.__setattr__(self, "lengths", lengths)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "rigid", tuple(self.rigid))

    @property
    def n_bones(self) -> int:
        """Bones with a length (those between drawn joints)."""
        return int((self.lengths > 0).sum())

    def misfit(self, medians: np.ndarray) -> tuple[float, str]:
        """The largest relative difference of a take's median bone lengths from this skeleton's.

        Parameters
        ----------
        medians : np.ndarray, shape (55,)
            The take's median length of each bone, metres.

        Returns
        -------
        (float, str)
            ``|median / length - 1|`` of the bone where it is largest, and that bone (named by its
            joint); (0.0, "") when the skeleton has no bone.
        """
        m = np.asarray(medians, dtype=np.float64)
        has = self.lengths > 0
        if not has.any():
            return 0.0, ""
        rel = np.zeros(N_JOINTS)
        rel[has] = np.abs(m[has] / self.lengths[has] - 1.0)
        worst = int(np.argmax(rel))
        return float(rel[worst]), JOINT_NAMES[worst]

    def check_fits(self, medians: np.ndarray, *, take: str, tolerance: float = FIT_TOLERANCE) -> None:
        """Refuse a take whose bones do not fit this skeleton.

        Raises
        ------
        ConfigError
            A bone's median length in the take is more than ``tolerance`` (relative) from the
            skeleton's; the message names the take and the bone.
        """
        rel, bone = self.misfit(medians)
        if rel > tolerance:
            j = joint_index(bone)
            m = float(np.asarray(medians)[j])
            raise ConfigError(
                f"take {take!r} does not fit the database's skeleton: its bone {bone} is {m * 1000:.0f} mm long "
                f"(median), the skeleton's {self.lengths[j] * 1000:.0f} mm ({(m / self.lengths[j] - 1) * 100:+.0f} %, "
                f"more than the {tolerance * 100:.0f} % an appended take may differ); build the database again "
                "with every take (--force) to fit one skeleton over them all"
            )

    def describe(self) -> str:
        """One line, e.g. ``"one per database: 47 bones fitted over 3 takes (4050 frames); finger roots ..."``."""
        shapes = []
        if "left_wrist" in self.rigid or "right_wrist" in self.rigid:
            shapes.append("finger roots fixed in the wrist's frame")
        if "upper_chest" in self.rigid:
            shapes.append("neck and collars fixed in the upper chest's")
        tail = f"; {', '.join(shapes)}" if shapes else ""
        return (
            f"one per database: {self.n_bones} bones fitted over {self.takes} take{'s' if self.takes != 1 else ''} "
            f"({self.frames} frames), each the median of its length{tail}"
        )

    def to_json(self) -> dict:
        """The skeleton as JSON-able values (``database.json``'s ``"skeleton"``): lengths and offsets by
        joint name, metres."""
        has = self.lengths > 0
        grouped = {c for name, _j, _f, children in _GROUPS if name in self.rigid for c in children}
        return {
            "lengths": {JOINT_NAMES[j]: float(self.lengths[j]) for j in range(N_JOINTS) if has[j]},
            "offsets": {JOINT_NAMES[j]: [float(v) for v in self.offsets[j]] for j in sorted(grouped)},
            "rigid": list(self.rigid),
            "takes": int(self.takes),
            "frames": int(self.frames),
        }

    @classmethod
    def from_json(cls, data: object) -> Skeleton:
        """The skeleton :meth:`to_json` gives, checked.

        Raises
        ------
        ConfigError
            Not the structure :meth:`to_json` writes (the message says what is wrong).
        """
        if not isinstance(data, Mapping):
            raise ConfigError(f"a skeleton must be an object, found {type(data).__name__}")
        lengths_in, offsets_in = data.get("lengths"), data.get("offsets")
        rigid, takes, frames = data.get("rigid"), data.get("takes"), data.get("frames")
        if not isinstance(lengths_in, Mapping) or not isinstance(offsets_in, Mapping):
            raise ConfigError("a skeleton needs 'lengths' and 'offsets' objects keyed by joint name")
        if not (isinstance(rigid, list) and all(isinstance(g, str) for g in rigid)):
            raise ConfigError("a skeleton's 'rigid' must be a list of group names")
        if not all(isinstance(x, int) and not isinstance(x, bool) for x in (takes, frames)):
            raise ConfigError("a skeleton's 'takes' and 'frames' must be integers")
        lengths = np.zeros(N_JOINTS)
        offsets = np.zeros((N_JOINTS, 3))
        for table, what in ((lengths_in, "lengths"), (offsets_in, "offsets")):
            unknown = [k for k in table if k not in JOINT_NAMES]
            if unknown:
                raise ConfigError(f"a skeleton's {what} name unknown joints: {', '.join(map(str, unknown[:5]))}")
        for name, v in lengths_in.items():
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v >= 0):
                raise ConfigError(f"a skeleton's length of {name} must be a number >= 0, found {v!r}")
            lengths[joint_index(name)] = float(v)
        for name, v in offsets_in.items():
            if not (
                isinstance(v, list)
                and len(v) == 3
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in v)
            ):
                raise ConfigError(f"a skeleton's offset of {name} must be three numbers, found {v!r}")
            offsets[joint_index(name)] = [float(x) for x in v]
        assert isinstance(takes, int) and isinstance(frames, int)
        return cls(lengths=lengths, offsets=offsets, rigid=tuple(rigid), takes=takes, frames=frames)

    def digest(self) -> str:
        """A short digest of the skeleton (for the staging keys of a build)."""
        text = json.dumps(self.to_json(), sort_keys=True)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


@checks_arguments
def fit_skeleton(
    samples: Sequence[np.ndarray] | Callable[[int], np.ndarray],
    *,
    presence: JointPresence | None = None,
    takes: int | None = None,
) -> Skeleton:
    """One skeleton over every frame of several takes (see the module notes).

    Parameters
    ----------
    samples : sequence of np.ndarray or callable
        Each take's :func:`bone_samples`, shape (rows, frames); or a function giving one row
        (by index) over the frames of all takes, shape (frames,), so that the takes' samples need
        not be in memory at once (a database build reads them row by row from disk).
    presence : JointPresence, optional
        Which joints the takes hold: absent joints get length 0, and a group whose frame joints
        are not all drawn is not held rigid.
    takes : int, optional
        The number of takes (required with a callable).

    Returns
    -------
    Skeleton
        The lengths are medians over all frames of all takes; a bone shorter than 1 micrometre
        gets 0.

    Raises
    ------
    ConfigError
        No takes or no frames.
    """
    if callable(samples):
        row = samples
        if takes is None:
            raise ConfigError("fit_skeleton needs the number of takes when given rows")
        n_takes = takes
    else:
        parts = [np.asarray(s, dtype=np.float32) for s in samples]
        if any(p.ndim != 2 or p.shape[0] != _N_ROWS for p in parts):
            raise ConfigError(f"bone samples must have shape ({_N_ROWS}, frames)")

        def row(i: int) -> np.ndarray:
            return np.concatenate([p[i] for p in parts])

        n_takes = len(parts)
    first = row(0)
    if n_takes < 1 or first.shape[0] == 0:
        raise ConfigError("a skeleton is fitted over at least one take of at least one frame")
    drawn = np.ones(N_JOINTS, bool) if presence is None else presence.drawn
    lengths = np.zeros(N_JOINTS)
    for j in range(N_JOINTS):
        if PARENTS[j] >= 0 and drawn[j]:
            lengths[j] = float(np.median(row(j).astype(np.float64)))
    lengths[lengths < _ZERO] = 0.0
    offsets = np.zeros((N_JOINTS, 3))
    rigid = []
    r = N_JOINTS
    for name, joint, frame_joints, children in _GROUPS:
        rows = {c: r + 3 * k for k, c in enumerate(children)}
        r += 3 * len(children)
        if not (drawn[joint] and all(drawn[f] and lengths[f] > 0 for f in frame_joints)):
            continue
        shape = np.zeros((N_JOINTS, 3))
        for c, at in rows.items():
            if lengths[c] == 0:
                continue
            direction = np.stack([row(at + k).astype(np.float64) for k in range(3)], axis=-1)
            direction = direction[np.isfinite(direction).all(axis=-1)]
            if direction.shape[0] == 0:
                break
            mid = np.median(direction, axis=0)
            n = np.linalg.norm(mid)
            if n < _ZERO:
                break
            shape[c] = lengths[c] * mid / n
        else:
            a, b, c3 = frame_joints
            turn, ok = _frames(shape[a], shape[b] - shape[c3])
            if not ok:
                continue  # the fitted shape does not define a frame: the group's bones keep their directions
            # expressed in its own frame, the shape's frame is the identity: normalised motion keeps the data's frames
            offsets[list(children)] = shape[list(children)] @ turn
            rigid.append(name)
    return Skeleton(lengths=lengths, offsets=offsets, rigid=tuple(rigid), takes=n_takes, frames=int(first.shape[0]))
