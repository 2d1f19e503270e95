"""Motion as a BVH file for animation tools (Blender, MotionBuilder, Maya, Unity).

The hierarchy is the 55-joint skeleton of :mod:`gesturekit.skeleton` with its
joint names. ``spine_mid`` is the ROOT, with six channels: its pelvis-relative
position and its rotation; every other joint has three rotation channels, and
the leaves (``head_top`` and the ten finger tips) end in an End Site. The root's
OFFSET is zero, so its position channels are its position whichever way a
reader combines the two.

Rest pose
---------
Offsets have the median length of each bone over the frames. By default the
rest pose is a T-pose built from the data: spine and head straight up (+Y),
collars, arms and forearms sideways (the character's left is +X), palms down
with the fingers straight. The shapes that one rotation must carry rigidly (the
neck and both collars on ``upper_chest``, the five finger roots on a wrist) are
the data's own average shapes, turned into that pose.

Rotations
---------
For every frame the global rotation of each joint is solved so that forward
kinematics reproduces the positions:

* a joint with several children takes the rotation that best aligns all its
  child bones (Kabsch / SVD), which fixes the twist of the chest and hands;
* a joint with one child turns its bone onto the bone in the data exactly.
  The twist about the bone, which positions alone do not fix, comes from a
  line further down the chain where one is reliably visible
  (:data:`TWIST_REFERENCES`): the spine (``spine_mid``, ``chest``) turns with
  the line through the collars, and a forearm (the ``elbow`` joints) rolls
  with the hand's line from little finger to index finger. Every other such
  joint (neck and head, collars, upper arms, fingers) turns by the smallest
  rotation, in its parent's frame, from the rest direction of its bone: it
  keeps its parent's twist, and its rotation is smooth as long as the bone
  stays away from pointing opposite to its rest direction (limbs stay within
  about 150 degrees of a T-pose). As a twist line comes closer than about 24
  degrees to its bone, the joint eases over to keeping its parent's twist
  (fully so within 12 degrees), where the line no longer says much;
* leaves keep their parent's rotation.

Each bone is aimed from the position the file reconstructs for its joint, so
errors do not add up along a chain: with constant bone lengths the file
reproduces the positions to the precision of the written numbers, and with
bone lengths that vary, each joint is off by about the variation of its own
bone.

Local rotations are written as intrinsic Euler angles in degrees, in the order
given by ``rotation_order`` (the order of the channels: ``"ZXY"`` means
``R = Rz @ Rx @ Ry``, and a child's offset ``o`` is placed at
``parent + R_parent_global @ o``). Angles are kept continuous over frames
(no jumps of 360 degrees) for smooth curves in animation tools.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .._io import atomic_write
from ..errors import ConfigError
from ..motion import Motion
from ..skeleton import FINGERS, JOINT_NAMES, N_JOINTS, PARENTS, joint_index

__all__ = [
    "ROTATION_ORDERS",
    "TWIST_REFERENCES",
    "UNITS",
    "write_bvh",
    "rest_offsets",
    "solve_rotations",
    "euler_from_matrices",
]

#: Rotation orders that :func:`write_bvh` can write (intrinsic, channel order).
ROTATION_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")

#: Length units of the file and their size in metres^-1 (file value = metres * factor).
UNITS = {"m": 1.0, "cm": 100.0}

#: Joints whose twist about their bone follows a line between two other joints (see the module notes).
TWIST_REFERENCES: dict[str, tuple[str, str]] = {
    "spine_mid": ("left_collar", "right_collar"),
    "chest": ("left_collar", "right_collar"),
    "left_elbow": ("left_index1", "left_pinky1"),
    "right_elbow": ("right_index1", "right_pinky1"),
}

_AXIS = {"X": 0, "Y": 1, "Z": 2}
_TWIST = {joint_index(j): (joint_index(a), joint_index(b)) for j, (a, b) in TWIST_REFERENCES.items()}
_CHILDREN: tuple[tuple[int, ...], ...] = tuple(
    tuple(int(c) for c in np.flatnonzero(PARENTS == j)) for j in range(N_JOINTS)
)


def _depth_first() -> tuple[int, ...]:
    order: list[int] = []
    stack = [int(j) for j in np.flatnonzero(PARENTS < 0)][::-1]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(_CHILDREN[j]))
    return tuple(order)


#: Joints in the order of the BVH hierarchy (depth first, children in skeleton order).
_DFS = _depth_first()


def write_bvh(
    path: str | os.PathLike,
    motion: Motion,
    *,
    overwrite: bool = False,
    rest: np.ndarray | None = None,
    units: str = "cm",
    rotation_order: str = "ZXY",
    decimals: int = 6,
) -> Path:
    """Write a motion as a BVH file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The file to create (written exactly there; no suffix is added).
    motion : Motion
        Positions (frames, 55, 3) in metres, pelvis-relative, and fps. At least
        one frame; every value finite.
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

    Returns
    -------
    pathlib.Path
        ``path``, the BVH file written.

    Raises
    ------
    ConfigError
        Invalid motion, rest pose or option, or ``path`` exists and
        ``overwrite`` is False.
    """
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
    if overwrite:
        from ..outputs import check_output

        check_output(path, "file", overwrite=True)  # only a BVH of gesturekit's skeleton is replaced

    offsets, end_sites = rest_offsets(positions, rest=rest, path=path)
    local, root_position = solve_rotations(positions, offsets)
    angles = np.degrees(_continuous(*euler_from_matrices(local, rotation_order)))

    scale = UNITS[units]
    text = _bvh_text(
        offsets * scale,
        end_sites * scale,
        root_position * scale,
        angles,
        fps=float(motion.fps),
        rotation_order=rotation_order,
        decimals=int(decimals),
    )
    data = text.encode("ascii")

    def write(f: BinaryIO) -> None:
        f.write(data)

    return atomic_write(path, write, overwrite=overwrite)


# ----------------------------------------------------------------------------- rest pose


def rest_offsets(
    positions: np.ndarray, *, rest: np.ndarray | None = None, path: str | os.PathLike | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Offsets of the rest pose, and the End Site offsets of the leaves.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions, metres; bone lengths are their medians over frames.
    rest : np.ndarray, shape (55, 3), optional
        Joint positions whose bone directions make the rest pose; default a
        T-pose built from ``positions`` (see the module notes).
    path : str or os.PathLike, optional
        File named in errors.

    Returns
    -------
    offsets : np.ndarray, shape (55, 3)
        Offset of every joint from its parent in the rest pose (all rotations
        identity), metres; zero for the root.
    end_sites : np.ndarray, shape (55, 3)
        End Site offset of every leaf joint (a quarter of its bone, at least
        5 mm, along the bone); zero for other joints.
    """
    positions = np.asarray(positions, dtype=np.float64)
    child = np.flatnonzero(PARENTS >= 0)
    lengths = np.zeros(N_JOINTS)
    lengths[child] = np.median(np.linalg.norm(positions[:, child] - positions[:, PARENTS[child]], axis=-1), axis=0)

    if rest is None:
        directions = _tpose_directions(positions)
    else:
        rest = np.asarray(rest, dtype=np.float64)
        if rest.shape != (N_JOINTS, 3) or not np.isfinite(rest).all():
            raise ConfigError(
                f"rest must be finite joint positions of shape ({N_JOINTS}, 3), got {rest.shape}", path=path
            )
        directions = np.zeros((N_JOINTS, 3))
        directions[child] = rest[child] - rest[PARENTS[child]]
    norms = np.linalg.norm(directions, axis=-1, keepdims=True)
    unit = np.divide(directions, norms, out=np.zeros_like(directions), where=norms > 1e-12)
    offsets = unit * lengths[:, None]

    end_sites = np.zeros((N_JOINTS, 3))
    for j in range(N_JOINTS):
        if not _CHILDREN[j] and PARENTS[j] >= 0:
            d = unit[j] if norms[j, 0] > 1e-12 else np.array([0.0, 1.0, 0.0])
            end_sites[j] = d * max(0.25 * lengths[j], 0.005)
    return offsets, end_sites


def _tpose_directions(positions: np.ndarray) -> np.ndarray:
    """Rest direction of every bone (row = child joint) for the T-pose; not normalised."""
    up, left, right = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    d = np.zeros((N_JOINTS, 3))
    for name in ("chest", "upper_chest", "neck_upper", "head", "head_top"):
        d[joint_index(name)] = up
    for side, out in (("left", left), ("right", right)):
        for name in ("shoulder", "elbow", "wrist"):
            d[joint_index(f"{side}_{name}")] = out

    # upper_chest carries neck and collars rigidly: the data's mean shape, collars along X, neck up
    uc = joint_index("upper_chest")
    shape = dict(zip(_CHILDREN[uc], _mean_shape(positions, uc)))
    basis = _basis(
        shape[joint_index("left_collar")] - shape[joint_index("right_collar")],
        shape[joint_index("neck")],
        first="x",
        second="y",
    )
    for c, v in shape.items():
        d[c] = basis.T @ v

    # a wrist carries the five finger roots: middle finger along the arm, index finger forward (+Z)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        w = joint_index(f"{side}_wrist")
        shape = dict(zip(_CHILDREN[w], _mean_shape(positions, w)))
        basis = _basis(
            sign * shape[joint_index(f"{side}_middle1")],
            shape[joint_index(f"{side}_index1")] - shape[joint_index(f"{side}_pinky1")],
            first="x",
            second="z",
        )
        for c, v in shape.items():
            d[c] = basis.T @ v
        # straight fingers, continuing the direction from the wrist to the finger root
        for finger in FINGERS:
            root = d[joint_index(f"{side}_{finger}1")]
            for k in (2, 3, 4):
                d[joint_index(f"{side}_{finger}{k}")] = root
    return d


def _basis(first_dir: np.ndarray, second_dir: np.ndarray, *, first: str, second: str) -> np.ndarray:
    """Rotation (columns = data directions of the X, Y, Z rest axes) putting ``first_dir`` on axis ``first``
    and ``second_dir``, made orthogonal to it, on axis ``second``; robust to degenerate inputs."""
    a = _unit_or(first_dir, np.eye(3)[_AXIS[first.upper()]])
    b = second_dir - a * (a @ second_dir)
    if np.linalg.norm(b) < 1e-9:
        # any direction orthogonal to a
        trial = np.eye(3)[int(np.argmin(np.abs(a)))]
        b = trial - a * (a @ trial)
    b = b / np.linalg.norm(b)
    axes = {first: a, second: b}
    third = ({"x", "y", "z"} - {first, second}).pop()
    # right-handed: x = y cross z, y = z cross x, z = x cross y
    nxt = {"x": ("y", "z"), "y": ("z", "x"), "z": ("x", "y")}[third]
    axes[third] = np.cross(axes[nxt[0]], axes[nxt[1]])
    return np.stack([axes["x"], axes["y"], axes["z"]], axis=1)


def _unit_or(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else fallback


def _mean_shape(positions: np.ndarray, joint: int, *, iterations: int = 3) -> np.ndarray:
    """Average shape of the bones from ``joint`` to its children, shape (children, 3), metres.

    Generalised Procrustes: every frame's bones are turned onto the current
    mean (Kabsch), then averaged; the orientation of the result is arbitrary.
    """
    bones = positions[:, list(_CHILDREN[joint])] - positions[:, joint, None]
    mean = bones[0]
    for _ in range(iterations):
        # rotation of each frame onto the mean: maximise <H, R> with H = sum mean_c bones_c^T
        h = np.einsum("ci,tcj->tij", mean, bones)
        rot = _nearest_rotation(h)
        mean = np.einsum("tij,tcj->ci", rot, bones) / len(bones)
    return mean


# ----------------------------------------------------------------------------- rotations


def solve_rotations(positions: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local joint rotations that move the rest pose onto the positions.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions, metres.
    offsets : np.ndarray, shape (55, 3)
        Rest offsets from :func:`rest_offsets`, metres.

    Returns
    -------
    local : np.ndarray, shape (frames, 55, 3, 3)
        Rotation of every joint relative to its parent (the root's: global).
    root_position : np.ndarray, shape (frames, 3)
        Position of the root joint, metres.
    """
    positions = np.asarray(positions, dtype=np.float64)
    n = positions.shape[0]
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    rest_pos = np.zeros((N_JOINTS, 3))
    for j in range(N_JOINTS):
        if PARENTS[j] >= 0:
            rest_pos[j] = rest_pos[PARENTS[j]] + offsets[j]
    glob = np.empty((n, N_JOINTS, 3, 3))
    local = np.empty((n, N_JOINTS, 3, 3))
    rebuilt = np.empty((n, N_JOINTS, 3))
    for j in range(N_JOINTS):
        p = PARENTS[j]
        if p < 0:
            parent_rot = eye
            rebuilt[:, j] = positions[:, j]
        else:
            parent_rot = glob[:, p]
            rebuilt[:, j] = rebuilt[:, p] + parent_rot @ offsets[j]
        children = list(_CHILDREN[j])
        # bones are aimed from the rebuilt joint, so that errors do not add up along a chain
        if not children:
            loc = eye
        elif len(children) == 1:
            c = children[0]
            target = np.einsum("tji,tj->ti", parent_rot, positions[:, c] - rebuilt[:, j])
            loc = _swing(offsets[c], target)
            if j in _TWIST:
                a, b = _TWIST[j]
                # the twist line in the parent's frame, like the bone
                line = np.einsum("tji,tj->ti", parent_rot, positions[:, a] - positions[:, b])
                loc = _twist_towards(loc, offsets[c], rest_pos[a] - rest_pos[b], line)
        else:
            targets = positions[:, children] - rebuilt[:, j, None]
            h = np.einsum("tci,cj->tij", targets, offsets[children])
            # a faint pull towards the parent's rotation decides the twist when the children lie on a line
            scale = np.linalg.norm(h, axis=(1, 2))[:, None, None]
            h = h + (1e-9 * scale + 1e-300) * parent_rot
            loc = np.einsum("tji,tjk->tik", parent_rot, _nearest_rotation(h))
        local[:, j] = loc
        glob[:, j] = parent_rot @ loc
    return local, positions[:, PARENTS.tolist().index(-1)].copy()


def _swing(rest: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Smallest rotations taking direction ``rest`` (3,) to directions ``target`` (frames, 3).

    Identity where either is zero; a half turn about an axis orthogonal to
    ``rest`` where they are opposite.
    """
    a = _unit_or(rest, np.zeros(3))
    tn = np.linalg.norm(target, axis=-1, keepdims=True)
    b = np.divide(target, tn, out=np.zeros_like(target), where=tn > 1e-12)
    # quaternion (w, v) = (1 + a.b, a x b), normalised, turns a onto b by the angle between them
    w = 1.0 + b @ a
    v = np.cross(a, b)
    q = np.concatenate([w[:, None], v], axis=1)
    qn = np.linalg.norm(q, axis=1)
    opposite = qn < 1e-12
    if opposite.any():
        trial = np.eye(3)[int(np.argmin(np.abs(a)))]
        axis = np.cross(a, trial)
        q[opposite] = np.concatenate([[0.0], axis / np.linalg.norm(axis)])
        qn[opposite] = 1.0
    return _quat_to_matrix(q / qn[:, None])


def _twist_towards(swing: np.ndarray, bone: np.ndarray, rest_line: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Turn rotations ``swing`` (frames, 3, 3) about the bone they produce so that the rest line
    (3,) lands on ``line`` (frames, 3) as nearly as a turn about the bone allows.

    The turn is scaled down to nothing as ``line`` comes within about 12 degrees of the bone
    (where it no longer says much about the twist), so the result stays continuous.
    """
    axis = swing @ _unit_or(bone, np.zeros(3))
    moved = swing @ rest_line
    # both lines projected on the plane across the bone; the signed angle between them
    p = moved - axis * np.einsum("ti,ti->t", axis, moved)[:, None]
    q = line - axis * np.einsum("ti,ti->t", axis, line)[:, None]
    angle = np.arctan2(np.einsum("ti,ti->t", axis, np.cross(p, q)), np.einsum("ti,ti->t", p, q))
    line_norm = np.linalg.norm(line, axis=-1)
    sine = np.divide(np.linalg.norm(q, axis=-1), line_norm, out=np.zeros_like(line_norm), where=line_norm > 1e-12)
    weight = np.clip((sine - 0.2) / 0.2, 0.0, 1.0)
    half = 0.5 * weight * angle
    turn = np.concatenate([np.cos(half)[:, None], np.sin(half)[:, None] * axis], axis=1)
    return _quat_to_matrix(turn) @ swing


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    m = np.empty((len(q), 3, 3))
    m[:, 0, 0] = 1 - 2 * (y * y + z * z)
    m[:, 0, 1] = 2 * (x * y - w * z)
    m[:, 0, 2] = 2 * (x * z + w * y)
    m[:, 1, 0] = 2 * (x * y + w * z)
    m[:, 1, 1] = 1 - 2 * (x * x + z * z)
    m[:, 1, 2] = 2 * (y * z - w * x)
    m[:, 2, 0] = 2 * (x * z - w * y)
    m[:, 2, 1] = 2 * (y * z + w * x)
    m[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def _nearest_rotation(h: np.ndarray) -> np.ndarray:
    """Rotations R maximising <H, R> (Kabsch), for H of shape (..., 3, 3)."""
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


# ----------------------------------------------------------------------------- Euler angles


def euler_from_matrices(m: np.ndarray, order: str) -> tuple[np.ndarray, np.ndarray]:
    """Intrinsic Euler angles of rotation matrices, and the other solution.

    For ``order = "ZXY"`` the angles ``(a, b, c)`` satisfy
    ``m = Rz(a) @ Rx(b) @ Ry(c)``; the middle angle is in [-pi/2, pi/2]. The
    second solution ``(a + pi, pi - b, c + pi)`` is the same rotation.

    Parameters
    ----------
    m : np.ndarray, shape (..., 3, 3)
        Rotation matrices.
    order : str
        One of :data:`ROTATION_ORDERS`.

    Returns
    -------
    angles, other : np.ndarray, shape (..., 3)
        Radians, in the order of ``order``.
    """
    i, j, k = (_AXIS[a] for a in order)
    # +1 for cyclic orders (XYZ, YZX, ZXY), -1 for the others
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    cos_b = np.hypot(m[..., i, i], m[..., i, j])
    b = np.arctan2(s * m[..., i, k], cos_b)
    a = np.arctan2(-s * m[..., j, k], m[..., k, k])
    c = np.arctan2(-s * m[..., i, j], m[..., i, i])
    # gimbal lock: only a + c (or a - c) is defined; put it all in a
    lock = cos_b < 1e-12
    if lock.any():
        a = np.where(lock, np.arctan2(s * m[..., k, j], m[..., j, j]), a)
        c = np.where(lock, 0.0, c)
    angles = np.stack([a, b, c], axis=-1)
    other = np.stack([a + np.pi, np.pi - b, c + np.pi], axis=-1)
    return angles, other


def _continuous(angles: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Per frame, the solution (and multiple of 2 pi) closest to the previous frame; shape (frames, ..., 3)."""
    out = np.empty_like(angles)
    out[0] = angles[0]
    two_pi = 2.0 * np.pi
    for t in range(1, len(angles)):
        prev = out[t - 1]
        c1 = angles[t] + two_pi * np.round((prev - angles[t]) / two_pi)
        c2 = other[t] + two_pi * np.round((prev - other[t]) / two_pi)
        pick = np.abs(c2 - prev).sum(axis=-1) < np.abs(c1 - prev).sum(axis=-1)
        out[t] = np.where(pick[..., None], c2, c1)
    return out


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
        if PARENTS[j] < 0:
            out.write(f"{pad}ROOT {JOINT_NAMES[j]}\n{pad}{{\n")
            out.write(f"{pad}\tOFFSET {vec(np.zeros(3))}\n")
            out.write(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rot_channels}\n")
        else:
            out.write(f"{pad}JOINT {JOINT_NAMES[j]}\n{pad}{{\n")
            out.write(f"{pad}\tOFFSET {vec(offsets[j])}\n")
            out.write(f"{pad}\tCHANNELS 3 {rot_channels}\n")
        for c in _CHILDREN[j]:
            joint(c, depth + 1)
        if not _CHILDREN[j]:
            out.write(f"{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET {vec(end_sites[j])}\n{pad}\t}}\n")
        out.write(f"{pad}}}\n")

    for r in np.flatnonzero(PARENTS < 0):
        joint(int(r), 0)

    n = len(angles)
    out.write(f"MOTION\nFrames: {n}\nFrame Time: {1.0 / fps:.10g}\n")
    columns = [root_position] + [angles[:, j] for j in _DFS]
    table = np.round(np.concatenate(columns, axis=1), decimals) + 0.0  # + 0.0 turns -0.0 into 0.0
    line = " ".join([f"%.{decimals}f"] * table.shape[1])
    out.write("\n".join(line % tuple(row) for row in table.tolist()))
    out.write("\n")
    return out.getvalue()
