"""A user's character's skeleton, moved by our motion, as a BVH file in the file's own frame and units.

The joints are the character's bones in the tree of its hips (names with
whitespace turned into ``_``), each leaf ending in an End Site; a BVH
character's End Sites (read as ``NAME_End`` bones) are End Sites again, where
they were; another leaf's End Site goes on along its bone by half its length. With ``R_F`` the
rotation of :attr:`~gesturekit.character.target.Character.to_file` and ``u``
the file's units per metre:

* ``OFFSET`` of a bone: ``R_F @ (p_b - p_parent) * u`` with ``p`` the rest positions, so the offsets of a BVH
  character are its own; the ROOT's OFFSET is zero and its position channels hold its position.
* rotation of a bone: ``R_F @ L @ R_F^T`` with ``L`` its
  :meth:`~gesturekit.character.retarget.Retargeted.local_turns`, as Euler angles in degrees, continuous over
  frames, in the channel order the BVH character had (``ZXY`` for others).
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._arguments import checks_arguments
from ..character.retarget import Retargeted
from ..character.solve import ROTATION_ORDERS, continuous_angles, euler_from_matrices
from ..character.target import Character
from ..errors import ConfigError, GestureKitError, OutputError
from ..outputs import check_output
from ._files import write_export
from .bvh import UNITS, WARN_ABOVE

__all__ = [
    "CharacterBvhReport",
    "export_character_bvh",
    "check_character_bvh",
    "character_bvh_joints",
    "bvh_joint_names",
    "rotation_of",
    "worst",
]


@dataclass(frozen=True, eq=False)
class CharacterBvhReport:
    """What a character's written BVH holds, and how well it reproduces the retargeted motion.

    Attributes
    ----------
    path : Path
    frames : int
    fps : float
    joints : tuple of str
        The joints written (sanitised names), in file order.
    units : float
        File units per metre (100 for centimetres).
    max_error, mean_error : float
        Largest and mean distance, metres, of a joint of the file (its forward kinematics, in our frame) from
        the bone's retargeted position.
    worst_bone : str
    worst_frame : int
    left_out : tuple of str
        Bones not under the root of the hips (a second tree of the file), not written.
    size : int
        Bytes of the file.
    """

    path: Path
    frames: int
    fps: float
    joints: tuple[str, ...]
    units: float
    max_error: float
    mean_error: float
    worst_bone: str
    worst_frame: int
    left_out: tuple[str, ...]
    size: int

    def summary(self) -> str:
        """One line: the file, its error, its joints and frames."""
        unit = {100.0: "cm", 1.0: "m"}.get(self.units, f"{self.units:g} per metre")
        parts = [
            f"{self.path.name}: position error max {self.max_error * 1000:.2f} mm "
            f"({self.worst_bone}, frame {self.worst_frame}), mean {self.mean_error * 1000:.2f} mm",
            f"{len(self.joints)} joints, {self.frames} frames at {self.fps:g} fps, units {unit}",
        ]
        if self.left_out:
            parts.append(f"{len(self.left_out)} bones outside the hips' tree left out")
        return "; ".join(parts)


def rotation_of(m: np.ndarray) -> np.ndarray:
    """The rotation part of 3x3 matrices (..., 3, 3): scale (and shear) taken out, the nearest rotation."""
    u, _, vt = np.linalg.svd(np.asarray(m, dtype=np.float64))
    r = u @ vt
    flip = np.linalg.det(r) < 0
    if np.any(flip):
        u[..., -1] *= np.where(flip, -1.0, 1.0)[..., None]
        r = u @ vt
    return r


def worst(err: np.ndarray) -> tuple[int, int]:
    """Frame and column of the largest entry of ``err`` (frames, n)."""
    frame, k = np.unravel_index(int(np.argmax(err)), err.shape)
    return int(frame), int(k)


def bvh_joint_names(names: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """BVH-safe joint names: whitespace as ``_``, an empty name as ``bone{i}``, repeats made unique (``_2``)."""
    out: list[str] = []
    seen: set[str] = set()
    for i, name in enumerate(names):
        base = re.sub(r"\s+", "_", str(name).strip()) or f"bone{i}"
        unique, k = base, 2
        while unique in seen:
            unique, k = f"{base}_{k}", k + 1
        seen.add(unique)
        out.append(unique)
    return tuple(out)


def _check_arguments(path: object, retargeted: object, function: str) -> None:
    """Our error, not a bare ``TypeError``, for a call given something else than a path and a retargeted motion."""
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"{function} writes to a file name or path, not {type(path).__name__}")
    if not isinstance(retargeted, Retargeted):
        raise ConfigError(
            f"{function} writes a Retargeted (gesturekit.character.retarget.retarget), not {type(retargeted).__name__}"
        )


@checks_arguments
def export_character_bvh(
    path: str | os.PathLike[str], retargeted: Retargeted, *, units: str | None = None, overwrite: bool = False
) -> CharacterBvhReport:
    """Write the character's skeleton with our motion as a BVH file, atomically, and measure it.

    Warns (:class:`~gesturekit.errors.GestureKitWarning`) when a joint read back is more than
    :data:`gesturekit.export.bvh.WARN_ABOVE` from its bone's retargeted position.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.bvh`` file to create.
    retargeted : Retargeted
        Our motion on the character (:func:`gesturekit.character.retarget.retarget`).
    units : {"cm", "m"}, optional
        The file's length units; default: a BVH character's own, centimetres for others.
    overwrite : bool
        Replace an existing file: one gesturekit wrote, or a BVH of this same skeleton (what writing the same
        character again replaces); never the character's own file.

    Returns
    -------
    CharacterBvhReport

    Raises
    ------
    ConfigError
        Units not ``"cm"`` or ``"m"``, or a file there that may not be replaced
        (:class:`~gesturekit.errors.OutputError`).
    """
    _check_arguments(path, retargeted, "export_character_bvh")
    path = Path(path)
    ch = retargeted.character
    if units is not None and units not in UNITS:
        raise ConfigError(f"units must be one of {', '.join(UNITS)}, got {units!r}", path=path)
    per_metre = UNITS[units] if units is not None else (1.0 / ch.bvh_units if ch.kind == "bvh" else UNITS["cm"])
    written, ends = _layout(ch)
    root = written[0]
    safe = bvh_joint_names(ch.names)
    check_character_bvh(path, character_bvh_joints(ch), overwrite=overwrite, inputs=[ch.path])

    r_f = rotation_of(ch.to_file[:3, :3])
    offsets = (ch.rest_position - ch.rest_position[np.maximum(ch.parents, 0)]) @ r_f.T * per_metre
    local = np.einsum("ab,tmbc,dc->tmad", r_f, retargeted.local_turns(), r_f)
    orders = _orders(ch) if ch.kind == "bvh" else {}
    angles = {}
    for b in written:
        if b in ends:
            continue
        order = orders.get(ch.names[b], "ZXY")
        a, other = euler_from_matrices(local[:, b], order)
        angles[b] = (order, np.degrees(continuous_angles(a, other)))
    root_position = retargeted.position[:, root] @ r_f.T * per_metre
    text = _text(ch.parents, written, ends, safe, offsets, angles, root_position, retargeted.fps)

    err = _measure(text, retargeted, path, written, ends, safe, r_f, per_metre)
    frame, k = worst(err)
    measured = [b for b in written if b not in ends]
    data = text.encode("ascii", "replace")
    report = CharacterBvhReport(
        path=path,
        frames=retargeted.n_frames,
        fps=float(retargeted.fps),
        joints=tuple(safe[b] for b in measured),
        units=per_metre,
        max_error=float(err.max()),
        mean_error=float(err.mean()),
        worst_bone=ch.names[measured[k]],
        worst_frame=frame,
        left_out=tuple(ch.names[b] for b in range(ch.n_bones) if b not in set(written)),
        size=len(data),
    )
    warning = None
    if report.max_error > WARN_ABOVE:
        warning = (
            f"the character's BVH is up to {report.max_error * 1000:.1f} mm off the retargeted motion "
            f"({report.worst_bone}, frame {report.worst_frame})"
        )
    write_export(path, data, overwrite=overwrite, warning=warning, stacklevel=2)
    return report


@checks_arguments
def check_character_bvh(
    path: Path, joints: list[str], *, overwrite: bool, inputs: list[Path | str | os.PathLike[str]]
) -> None:
    """Whether a character's BVH with ``joints`` may be written at ``path`` (see :func:`export_character_bvh`).

    Raises
    ------
    OutputError
        The file is an input, exists and ``overwrite`` is False, or is neither gesturekit's nor a BVH of
        these joints.
    """
    try:
        check_output(path, "file", overwrite=overwrite, inputs=inputs)
    except OutputError:
        if not (overwrite and path.is_file() and not path.is_symlink() and _same_skeleton(path, joints)):
            raise
        from ..outputs import check_not_input

        check_not_input(path, inputs)


def _same_skeleton(path: Path, joints: list[str]) -> bool:
    """Whether the BVH at ``path`` has exactly these joints (End Sites aside)."""
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 20).decode("ascii", "replace")
    except OSError:
        return False
    if not head.startswith("HIERARCHY"):
        return False
    found = re.findall(r"^\s*(?:ROOT|JOINT)\s+(\S+)", head.split("MOTION")[0], re.M)
    return sorted(found) == sorted(joints)


def _layout(ch: Character) -> tuple[list[int], set[int]]:
    """The bones written (the tree of the hips, root first) and those of them written as End Sites."""
    root = _root_of(ch.parents, ch.pelvis)
    written = [b for b in range(ch.n_bones) if _root_of(ch.parents, b) == root]
    return written, (_end_sites(ch.names, ch.parents, written) if ch.kind == "bvh" else set())


@checks_arguments
def character_bvh_joints(ch: Character) -> list[str]:
    """The JOINT and ROOT names of the character's BVH, in bone order (End Sites left out)."""
    written, ends = _layout(ch)
    safe = bvh_joint_names(ch.names)
    return [safe[b] for b in written if b not in ends]


def _root_of(parents: np.ndarray, b: int) -> int:
    while parents[b] >= 0:
        b = int(parents[b])
    return b


def _end_sites(names: tuple[str, ...], parents: np.ndarray, written: list[int]) -> set[int]:
    """The bones read from a BVH's End Sites: leaves named after their parent with ``_End``."""
    has_child = set(int(p) for p in parents if p >= 0)
    return {b for b in written if b not in has_child and parents[b] >= 0 and names[b] == f"{names[parents[b]]}_End"}


def _orders(ch: Character) -> dict[str, str]:
    """The rotation order of each joint of a BVH character's file (``"ZXY"`` where it has no three rotations)."""
    from ..datasets.bvh_file import parse_bvh

    try:
        data = parse_bvh(ch.path)
    except (GestureKitError, OSError):
        return {}
    out = {}
    for name, channels in zip(data.names, data.channels):
        order = "".join(c[0] for c in channels if c.endswith("rotation"))
        if order in ROTATION_ORDERS:
            out[name] = order
    return out


def _text(
    parents: np.ndarray,
    written: list[int],
    ends: set[int],
    names: tuple[str, ...],
    offsets: np.ndarray,
    angles: dict[int, tuple[str, np.ndarray]],
    root_position: np.ndarray,
    fps: float,
    decimals: int = 6,
) -> str:
    """The file: the hierarchy depth first (children in bone order), then one line of channels per frame."""
    num = f"{{:.{decimals}f}}"
    keep = set(written)
    children: dict[int, list[int]] = {b: [] for b in written}
    for b in written:
        if parents[b] >= 0 and int(parents[b]) in keep:
            children[int(parents[b])].append(b)
    out = io.StringIO()
    out.write("HIERARCHY\n")
    order: list[int] = []

    def vec(v: np.ndarray) -> str:
        return " ".join(num.format(x + 0.0) for x in np.round(v, decimals))

    def joint(b: int, depth: int) -> None:
        pad = "\t" * depth
        rot = " ".join(f"{a}rotation" for a in angles[b][0])
        order.append(b)
        if parents[b] < 0:
            out.write(f"{pad}ROOT {names[b]}\n{pad}{{\n{pad}\tOFFSET {vec(np.zeros(3))}\n")
            out.write(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rot}\n")
        else:
            out.write(f"{pad}JOINT {names[b]}\n{pad}{{\n{pad}\tOFFSET {vec(offsets[b])}\n")
            out.write(f"{pad}\tCHANNELS 3 {rot}\n")
        kids = [c for c in children[b] if c not in ends]
        for c in kids:
            joint(c, depth + 1)
        tips = [c for c in children[b] if c in ends]
        if tips or not kids:
            # a leaf without a tip of its own ends where its bone would go on
            tip = offsets[tips[0]] if tips else offsets[b] * 0.5
            out.write(f"{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET {vec(tip)}\n{pad}\t}}\n")
        out.write(f"{pad}}}\n")

    joint(written[0], 0)
    out.write(f"MOTION\nFrames: {len(root_position)}\nFrame Time: {1.0 / fps:.10g}\n")
    table = np.round(np.concatenate([root_position] + [angles[b][1] for b in order], axis=1), decimals) + 0.0
    line = " ".join([f"%.{decimals}f"] * table.shape[1])
    out.write("\n".join(line % tuple(row) for row in table.tolist()))
    out.write("\n")
    return out.getvalue()


def _measure(
    text: str,
    r: Retargeted,
    path: Path,
    written: list[int],
    ends: set[int],
    names: tuple[str, ...],
    r_f: np.ndarray,
    per_metre: float,
) -> np.ndarray:
    """Distances (frames, joints written), metres, of the file's joints from the retargeted bones."""
    from ..datasets.bvh import forward_kinematics
    from ..datasets.bvh_file import parse_bvh_text

    data = parse_bvh_text(text, path=path)
    world = forward_kinematics(data) / per_metre @ r_f  # file frame -> ours (r_f^T applied on the right)
    measured = [b for b in written if b not in ends]
    columns = [data.index(names[b]) for b in measured]
    return np.linalg.norm(world[:, columns] - r.position[:, measured], axis=-1)
