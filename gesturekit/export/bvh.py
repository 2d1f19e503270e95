"""Motion as a BVH file for animation tools (Blender, MotionBuilder, Maya, Unity).

The hierarchy is the 55-joint skeleton of :mod:`gesturekit.skeleton` with its
joint names. ``spine_mid`` is the ROOT, with six channels: its pelvis-relative
position and its rotation; every other joint has three rotation channels, and
the leaves (``head_top`` and the ten finger tips) end in an End Site. The root's
OFFSET is zero, so its position channels are its position whichever way a
reader combines the two.

Partial skeletons
-----------------
Of a motion whose :attr:`~gesturekit.motion.Motion.presence` has absent joints,
only the drawn joints (recorded and derived) are written: each hangs from its
nearest drawn ancestor, and a joint whose children are all absent ends in an
End Site. The root is ``spine_mid`` when it is drawn (also as a derived torso),
else the neck, which then carries the collars or shoulders in place of the
missing upper chest. Drawn joints that cannot be connected to the root are
refused (:class:`~gesturekit.errors.ConfigError`, naming them).

Rest pose and rotations
-----------------------
The file holds the solve every character of gesturekit uses
(:mod:`gesturekit.character.solve`, whose notes say how): one length per bone
(the median over the frames), a T-pose built from the data, and per frame
the local rotations that move it onto the positions.

Error report
------------
:func:`export_bvh` reads the written text back with gesturekit's own BVH reader
(:func:`gesturekit.datasets.bvh_file.parse_bvh_text` and
:func:`gesturekit.datasets.bvh.forward_kinematics`) and compares every drawn
joint with the motion's positions: a :class:`BvhReport`. Over
:data:`WARN_ABOVE` (1 cm) it warns (:class:`~gesturekit.errors.GestureKitWarning`):
the npz keeps the exact positions, and ``build-db --normalize-bones`` gives the
bones one length before anything is written. For a motion from a database that has
one skeleton already, the caller names what would help instead (``remedy``;
:func:`gesturekit.export.result.export_result_bvh` names blending and the refiner,
which change the bones' lengths after the database).

Local rotations are written as intrinsic Euler angles in degrees, in the order
given by ``rotation_order`` (the order of the channels: ``"ZXY"`` means
``R = Rz @ Rx @ Ry``, and a child's offset ``o`` is placed at
``parent + R_parent_global @ o``). Angles are kept continuous over frames
(no jumps of 360 degrees) for smooth curves in animation tools.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from .._arguments import checks_arguments
from .._io import Target, target_path, write_to
from ..bones import fit_bone_lengths
from ..character.solve import (
    LEFT_OUT,
    ROTATION_ORDERS,
    TWIST_REFERENCES,
    bvh_parents,
    children_of,
    continuous_angles,
    depth_first,
    euler_from_matrices,
    rest_offsets,
    solve_rotations,
)
from ..errors import ConfigError, warn
from ..motion import Motion
from ..skeleton import DERIVED, FINGERS, JOINT_NAMES, N_JOINTS, PARENTS

__all__ = [
    "ROTATION_ORDERS",
    "TWIST_REFERENCES",
    "UNITS",
    "WARN_ABOVE",
    "BvhReport",
    "export_bvh",
    "write_bvh",
    "bvh_parents",
    "rest_offsets",
    "solve_rotations",
    "euler_from_matrices",
]

#: Length units of the file and their size in metres^-1 (file value = metres * factor).
UNITS = {"m": 1.0, "cm": 100.0}

#: Largest position error of a written file (metres) that passes without a warning.
WARN_ABOVE = 0.01

_FINGER_JOINTS = frozenset(f"{s}_{f}{k}" for s in ("left", "right") for f in FINGERS for k in range(1, 5))


@dataclass(frozen=True, eq=False)
class BvhReport:
    """What a written BVH file holds, and how well it reproduces the motion.

    The errors are measured on the file as written: read back with
    gesturekit's BVH reader and forward kinematics, every drawn joint of every
    frame against the motion's positions.

    Attributes
    ----------
    path : Path
        The file written.
    max_error, mean_error : float
        Largest and mean distance of a drawn joint from its position in the
        motion, metres.
    worst_joint : str
        The joint of the largest error.
    worst_frame : int
        Its frame.
    bone_lengths : np.ndarray, shape (55,)
        Length of the bone from each joint's parent in the file, metres (0 for
        the root and joints left out).
    root : str
        The root joint.
    left_out : tuple of str
        Joints not written (absent from the motion).
    derived : tuple of str
        Joints written that the data does not hold (placed from others).
    precision : float
        Half a unit of the last digit written, in metres: the error a motion
        with constant bone lengths stays within (plus rounding of the angles).
    remedy : str or None
        What the warning says would bring the file closer to the motion: None for
        the default (a database built with ``build-db --normalize-bones``), ``""``
        for nothing beyond the npz (see :func:`export_bvh`).
    """

    path: Path
    max_error: float
    mean_error: float
    worst_joint: str
    worst_frame: int
    bone_lengths: np.ndarray = field(repr=False)
    root: str
    left_out: tuple[str, ...]
    derived: tuple[str, ...]
    precision: float
    remedy: str | None = None

    @property
    def exceeds(self) -> bool:
        """The largest error is over :data:`WARN_ABOVE`."""
        return self.max_error > WARN_ABOVE

    def warning(self) -> str | None:
        """What the warning over :data:`WARN_ABOVE` says (without the file's path); None below it."""
        if not self.exceeds:
            return None
        return error_warning(
            f"the BVH file is up to {self.max_error * 100:.1f} cm off the motion",
            self,
            shapes=" (and the bones leaving one joint keep one shape)",
        )

    def summary(self) -> str:
        """One line, e.g. ``"take.bvh: position error max 0.00 mm ..., root at the derived spine_mid; ..."``."""
        error, root, left_out = summary_parts(self)
        parts = [error, f"root at {root}", *left_out]
        others = [d for d in self.derived if d != self.root]
        if others:
            parts.append(f"derived joints written: {_names(others)}")
        return "; ".join(parts)


class MeasuredFile(Protocol):
    """A written file's report of its accuracy (:class:`BvhReport`, :class:`~gesturekit.export.gltf.GltfReport`)."""

    @property
    def path(self) -> Path: ...
    @property
    def root(self) -> str: ...
    @property
    def derived(self) -> tuple[str, ...]: ...
    @property
    def left_out(self) -> tuple[str, ...]: ...
    @property
    def max_error(self) -> float: ...
    @property
    def mean_error(self) -> float: ...
    @property
    def worst_joint(self) -> str: ...
    @property
    def worst_frame(self) -> int: ...
    @property
    def remedy(self) -> str | None: ...


def error_warning(headline: str, report: MeasuredFile, *, shapes: str = "") -> str:
    """The warning of a file that misses its motion: ``headline``, the worst joint and frame, why, and the remedy.

    Parameters
    ----------
    headline : str
        What is off and by how much, e.g. "the BVH file is up to 1.2 cm off the motion".
    report : BvhReport or GltfReport
        Its ``worst_joint``, ``worst_frame``, ``mean_error`` (metres) and ``remedy`` (None: the default,
        ``build-db --normalize-bones``; "": nothing to name).
    shapes : str
        What else the file holds fixed, said after "its bones have one length each".
    """
    if report.remedy is None:
        remedy = "; a database built with `build-db --normalize-bones` gives every bone one length"
    else:
        remedy = f"; {report.remedy}" if report.remedy else ""
    return (
        f"{headline} ({report.worst_joint}, frame {report.worst_frame}; mean {report.mean_error * 1000:.1f} mm): "
        f"its bones have one length each{shapes}, the motion's vary. The npz keeps the exact positions{remedy}."
    )


def summary_parts(report: MeasuredFile) -> tuple[str, str, list[str]]:
    """What a BVH's and a glTF file's one-line summaries share.

    Returns
    -------
    error : str
        The file's name and its position error (max, worst joint and frame, mean), in mm.
    root : str
        The root joint's name, "the derived ..." when it is derived.
    left_out : list of str
        The joints left out, as one phrase (empty when none).
    """
    root = f"the derived {report.root}" if report.root in report.derived else report.root
    error = (
        f"{report.path.name}: position error max {report.max_error * 1000:.2f} mm "
        f"({report.worst_joint}, frame {report.worst_frame}), mean {report.mean_error * 1000:.2f} mm"
    )
    left_out = []
    if report.left_out:
        kind = "finger joint" if set(report.left_out) <= _FINGER_JOINTS else "joint"
        n = len(report.left_out)
        left_out.append(f"{n} {kind}{'s' if n > 1 else ''} left out: {_names(report.left_out)}")
    return error, root, left_out


def _names(names: tuple[str, ...] | list[str], most: int = 12) -> str:
    shown = ", ".join(names[:most])
    return shown + (f" and {len(names) - most} more" if len(names) > most else "")


@checks_arguments
def write_bvh(
    path: Target,
    motion: Motion,
    *,
    overwrite: bool = False,
    rest: np.ndarray | None = None,
    units: str = "cm",
    rotation_order: str = "ZXY",
    decimals: int = 6,
) -> Path | None:
    """Write a motion as a BVH file, atomically (or into a binary file object); :func:`export_bvh` without
    its report.

    The parameters, the warning over :data:`WARN_ABOVE` and the errors raised are those of
    :func:`export_bvh`.

    Returns
    -------
    pathlib.Path or None
        ``path``, the BVH file written; None for a file object.
    """
    report = export_bvh(
        path, motion, overwrite=overwrite, rest=rest, units=units, rotation_order=rotation_order, decimals=decimals
    )
    return report.path if isinstance(path, (str, os.PathLike)) else None


@checks_arguments
def export_bvh(
    path: Target,
    motion: Motion,
    *,
    overwrite: bool = False,
    rest: np.ndarray | None = None,
    units: str = "cm",
    rotation_order: str = "ZXY",
    decimals: int = 6,
    remedy: str | None = None,
) -> BvhReport:
    """Write a motion as a BVH file, atomically, and report how well the file reproduces it.

    Warns (:class:`~gesturekit.errors.GestureKitWarning`) when a drawn joint of
    the file is more than :data:`WARN_ABOVE` from its position in the motion.

    Parameters
    ----------
    path : str, os.PathLike or binary file object
        The file to create (written exactly there, atomically; no suffix is added), or where to write
        it (``io.BytesIO``, an open file: the same bytes at its position; the report names its
        ``name``, else ``motion.bvh``).
    motion : Motion
        Positions (frames, 55, 3) in metres, pelvis-relative, and fps. At least
        one frame; every value finite. Only its drawn joints are written (see
        the module notes on partial skeletons).
    overwrite : bool
        Replace an existing file.
    rest : np.ndarray, shape (55, 3), optional
        Joint positions of a rest pose (metres). The directions of its bones
        give the rest pose; lengths always come from the motion. Positions are
        reproduced exactly only if the shapes that one joint carries rigidly
        (the children of ``upper_chest`` and of the wrists) match the motion's.
        Default: a T-pose built from the motion (see the module notes).
    units : {"cm", "m"}
        Length unit of the file; centimetres suit most animation tools.
    rotation_order : str
        One of :data:`ROTATION_ORDERS`, the order of the rotation channels.
    decimals : int
        Digits after the decimal point of every number, 3 to 10.
    remedy : str, optional
        What the warning names as the way to a closer file, when the default (a database built
        with ``build-db --normalize-bones``) would not help: for a motion from a database that
        has one skeleton already, what changed its bones after the database (``""``: nothing
        to name).

    Returns
    -------
    BvhReport
        The file, its errors against the motion (metres), its bone lengths,
        root, and the joints left out and derived.

    Raises
    ------
    ConfigError
        Invalid motion, rest pose or option, drawn joints that do not form one
        tree, or ``path`` exists and ``overwrite`` is False.
    """
    target, path = path, target_path(path, "motion.bvh")
    if not isinstance(motion, Motion):
        raise ConfigError(f"motion must be a gesturekit Motion, got {type(motion).__name__}", path=path)
    if units not in UNITS:
        raise ConfigError(f"units must be one of {', '.join(UNITS)}, got {units!r}", path=path)
    if rotation_order not in ROTATION_ORDERS:
        raise ConfigError(
            f"rotation_order must be one of {', '.join(ROTATION_ORDERS)}, got {rotation_order!r}", path=path
        )
    if not isinstance(decimals, (int, np.integer)) or not 3 <= decimals <= 10:
        raise ConfigError(f"decimals must be an integer from 3 to 10, got {decimals!r}", path=path)
    if motion.n_frames == 0:
        raise ConfigError("cannot write a motion without frames", path=path)
    positions = motion.positions.astype(np.float64)
    bad = ~np.isfinite(positions).all(axis=(1, 2))
    if bad.any():
        raise ConfigError(f"positions are not finite (NaN or infinite) from frame {int(np.argmax(bad))} on", path=path)
    presence = motion.presence
    parents = bvh_parents(presence, path=path)
    if overwrite and isinstance(target, (str, os.PathLike)):
        from ..outputs import check_output

        check_output(path, "file", overwrite=True)  # only a BVH of gesturekit's skeleton is replaced

    lengths = _lengths_in_file(positions, motion, parents)
    offsets, end_sites = rest_offsets(positions, lengths=lengths, parents=parents, rest=rest, path=path)
    local, root_position = solve_rotations(positions, offsets, parents)
    angles = np.degrees(continuous_angles(*euler_from_matrices(local, rotation_order)))

    scale = UNITS[units]
    text = _bvh_text(
        offsets * scale,
        end_sites * scale,
        root_position * scale,
        angles,
        fps=float(motion.fps),
        rotation_order=rotation_order,
        decimals=int(decimals),
        parents=parents,
    )
    report = _measure(text, positions, path=path, parents=parents, lengths=lengths, scale=scale)
    report = replace(report, derived=presence.names(DERIVED), precision=0.5 * 10.0**-decimals / scale, remedy=remedy)
    data = text.encode("ascii")

    write_to(target, lambda f: f.write(data), overwrite=overwrite)
    message = report.warning()
    if message is not None:
        warn(f"{report.path}: {message}", stacklevel=2)
    return report


def _lengths_in_file(positions: np.ndarray, motion: Motion, parents: np.ndarray) -> np.ndarray:
    """Length of each bone in the file (from the joint's parent there), shape (55,), metres."""
    lengths = fit_bone_lengths(positions, motion.presence)
    # a joint hanging from an ancestor other than its skeleton parent (absent joints between them, which
    # sit on their parents): its bone in the file is the distance to that ancestor
    for j in np.flatnonzero((parents >= 0) & (parents != PARENTS)):
        d = np.linalg.norm(positions[:, j] - positions[:, parents[j]], axis=-1)
        lengths[j] = float(np.median(d))
    return lengths


def _measure(
    text: str, positions: np.ndarray, *, path: Path, parents: np.ndarray, lengths: np.ndarray, scale: float
) -> BvhReport:
    """The errors of the file ``text`` against ``positions``, read back with gesturekit's BVH reader."""
    from ..datasets.bvh import forward_kinematics
    from ..datasets.bvh_file import parse_bvh_text

    data = parse_bvh_text(text, path=path)
    world = forward_kinematics(data) / scale
    written = [j for j in range(N_JOINTS) if parents[j] != LEFT_OUT]
    columns = [data.index(JOINT_NAMES[j]) for j in written]
    err = np.linalg.norm(world[:, columns] - positions[:, written], axis=-1)
    frame, k = np.unravel_index(int(np.argmax(err)), err.shape)
    return BvhReport(
        path=path,
        max_error=float(err.max()),
        mean_error=float(err.mean()),
        worst_joint=JOINT_NAMES[written[int(k)]],
        worst_frame=int(frame),
        bone_lengths=np.where(parents >= 0, lengths, 0.0),
        root=JOINT_NAMES[int(np.flatnonzero(parents == -1)[0])],
        left_out=tuple(JOINT_NAMES[j] for j in range(N_JOINTS) if parents[j] == LEFT_OUT),
        derived=(),
        precision=0.0,
    )


# ----------------------------------------------------------------------------- text


def _bvh_text(
    offsets: np.ndarray,
    end_sites: np.ndarray,
    root_position: np.ndarray,
    angles: np.ndarray,
    *,
    fps: float,
    rotation_order: str,
    decimals: int,
    parents: np.ndarray,
) -> str:
    """The file: hierarchy in depth-first order, then one line of channels per frame."""
    num = f"{{:.{decimals}f}}"
    rot_channels = " ".join(f"{a}rotation" for a in rotation_order)
    out = io.StringIO()
    out.write("HIERARCHY\n")

    def vec(v: np.ndarray) -> str:
        return " ".join(num.format(x + 0.0) for x in np.round(v, decimals))

    def joint(j: int, depth: int) -> None:
        pad = "\t" * depth
        if parents[j] < 0:
            out.write(f"{pad}ROOT {JOINT_NAMES[j]}\n{pad}{{\n")
            out.write(f"{pad}\tOFFSET {vec(np.zeros(3))}\n")
            out.write(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rot_channels}\n")
        else:
            out.write(f"{pad}JOINT {JOINT_NAMES[j]}\n{pad}{{\n")
            out.write(f"{pad}\tOFFSET {vec(offsets[j])}\n")
            out.write(f"{pad}\tCHANNELS 3 {rot_channels}\n")
        for c in children[j]:
            joint(c, depth + 1)
        if not children[j]:
            out.write(f"{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET {vec(end_sites[j])}\n{pad}\t}}\n")
        out.write(f"{pad}}}\n")

    children = children_of(parents)
    joint(int(np.flatnonzero(parents == -1)[0]), 0)

    n = len(angles)
    out.write(f"MOTION\nFrames: {n}\nFrame Time: {1.0 / fps:.10g}\n")
    columns = [root_position] + [angles[:, j] for j in depth_first(parents)]
    table = np.round(np.concatenate(columns, axis=1), decimals) + 0.0  # + 0.0 turns -0.0 into 0.0
    line = " ".join([f"%.{decimals}f"] * table.shape[1])
    out.write("\n".join(line % tuple(row) for row in table.tolist()))
    out.write("\n")
    return out.getvalue()
