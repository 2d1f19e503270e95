"""The rotation solve shared by the character, the BVH and the glTF: hierarchy, rest pose, joint rotations.

A hierarchy is given as ``parents``, shape (55,), int: each written joint's
parent in the file, ``-1`` for the root and :data:`LEFT_OUT` for a joint that is
not written. A joint's parent in the file is its nearest drawn ancestor in the
skeleton, so parents still precede children.

The page's character, the MP4, the BVH and the glTF all take their rotations from
this one solve (through :func:`gesturekit.character.rig.solve_pose`, or
:func:`gesturekit.export.bvh.export_bvh`), so they show one pose.

Rest pose
---------
Every bone has one length: :func:`gesturekit.bones.fit_bone_lengths`, the
median of its length over the frames. By default the rest pose is a T-pose
built from the data: spine and head straight up (+Y), collars, arms and
forearms sideways (the character's left is +X), palms down with the fingers
straight. The shapes that one rotation must carry rigidly (the neck and both
collars on ``upper_chest``, the five finger roots on a wrist) are the data's
own average shapes (over at most :data:`MEAN_SHAPE_FRAMES` frames spread
evenly over the motion), turned into that pose.

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

Each bone is aimed from the position forward kinematics reconstructs for its joint at
the joint's position in the data: of all the places a bone of the fitted
length can reach from there, the nearest to the data, so errors do not add up
along a chain. With constant bone lengths the rotations reproduce the positions to
floating-point precision (a file: to the precision of its numbers); with bone lengths that vary, each joint
is off by about the variation of its own bone. (Aiming every bone along its
direction in the data instead, as :func:`gesturekit.bones.normalise_bone_lengths`
does, lets the errors add up along the chains: on a demo take with every
bone's length scaled by up to 3 % frame by frame, 20.1 mm largest and 6.7 mm
mean error against 17.4 mm and 3.6 mm.)
"""

from __future__ import annotations

import os

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..skeleton import FINGERS, JOINT_NAMES, N_JOINTS, PARENTS, JointPresence, joint_index

__all__ = [
    "LEFT_OUT",
    "MEAN_SHAPE_FRAMES",
    "ROTATION_ORDERS",
    "TWIST_REFERENCES",
    "bvh_parents",
    "children_of",
    "depth_first",
    "rest_offsets",
    "solve_rotations",
    "euler_from_matrices",
    "continuous_angles",
]

#: Most frames a rigidly carried shape (neck and collars, finger roots) is averaged over for the rest pose.
MEAN_SHAPE_FRAMES = 2048

#: ``parents`` entry of a joint that is not written.
LEFT_OUT = -2

#: Rotation orders a BVH can be written in (intrinsic, channel order).
ROTATION_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")

#: Joints whose twist about their bone follows a line between two other joints (see the module notes).
TWIST_REFERENCES: dict[str, tuple[str, str]] = {
    "spine_mid": ("left_collar", "right_collar"),
    "chest": ("left_collar", "right_collar"),
    "left_elbow": ("left_index1", "left_pinky1"),
    "right_elbow": ("right_index1", "right_pinky1"),
}

_AXIS = {"X": 0, "Y": 1, "Z": 2}
_TWIST = {joint_index(j): (joint_index(a), joint_index(b)) for j, (a, b) in TWIST_REFERENCES.items()}
_UPPER_CHEST = joint_index("upper_chest")
_NECK = joint_index("neck")
_SPINE_MID = joint_index("spine_mid")


# ----------------------------------------------------------------------------- hierarchy


@checks_arguments
def bvh_parents(presence: JointPresence, *, path: str | os.PathLike[str] | None = None) -> np.ndarray:
    """The hierarchy of the drawn joints, shape (55,), int64.

    The root is ``spine_mid`` when it is drawn, else the neck. Every other drawn
    joint hangs from its nearest drawn ancestor; with the torso left out, the
    neck stands in for ``upper_chest``, so that the collars or shoulders hang
    from it (as in keypoint layouts with a neck and no spine).

    Raises
    ------
    ConfigError
        Neither ``spine_mid`` nor the neck is drawn, or a drawn joint has no
        drawn joint to hang from; the message names the joints.
    """
    drawn = presence.drawn
    if drawn[_SPINE_MID]:
        root = _SPINE_MID
    elif drawn[_NECK]:
        root = _NECK
    else:
        raise ConfigError(
            f"a BVH needs spine_mid or the neck as its root, and neither is drawn (joints: {presence.describe()})",
            path=path,
        )
    parents = np.full(N_JOINTS, LEFT_OUT, dtype=np.int64)
    parents[root] = -1
    orphans = []
    for j in range(N_JOINTS):
        if not drawn[j] or j == root:
            continue
        p = int(PARENTS[j])
        while p >= 0 and not drawn[p]:
            if p == _UPPER_CHEST and root == _NECK:
                break
            p = int(PARENTS[p])
        if p == _UPPER_CHEST and not drawn[p]:
            p = root  # the neck in place of the missing upper chest
        if p < 0:
            orphans.append(JOINT_NAMES[j])
        else:
            parents[j] = p
    if orphans:
        # everything hanging from an orphan is cut off with it
        cut = np.zeros(N_JOINTS, dtype=bool)
        for j in range(N_JOINTS):
            cut[j] = JOINT_NAMES[j] in orphans or (parents[j] >= 0 and cut[parents[j]])
        below = int(cut.sum()) - len(orphans)
        tail = f" (with {below} drawn joint{'s' if below != 1 else ''} below)" if below else ""
        raise ConfigError(
            f"the drawn joints do not form one tree: {', '.join(orphans)}{tail} "
            f"{'is' if len(orphans) == 1 else 'are'} not connected to the root {JOINT_NAMES[root]} "
            "through drawn joints (the joints between them are absent)",
            path=path,
        )
    return parents


@checks_arguments
def children_of(parents: np.ndarray) -> tuple[tuple[int, ...], ...]:
    """Children of every joint in the hierarchy ``parents``, in skeleton order."""
    return tuple(tuple(int(c) for c in np.flatnonzero(parents == j)) for j in range(N_JOINTS))


@checks_arguments
def depth_first(parents: np.ndarray) -> tuple[int, ...]:
    """The written joints in the order of the file (depth first, children in skeleton order)."""
    children = children_of(parents)
    order: list[int] = []
    stack = [int(j) for j in np.flatnonzero(parents == -1)][::-1]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j]))
    return tuple(order)


# ----------------------------------------------------------------------------- rest pose


@checks_arguments
def rest_offsets(
    positions: np.ndarray,
    *,
    lengths: np.ndarray,
    parents: np.ndarray = PARENTS,
    rest: np.ndarray | None = None,
    path: str | os.PathLike[str] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Offsets of the rest pose, and the End Site offsets of the leaves.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions, metres.
    lengths : np.ndarray, shape (55,)
        Length of the bone from each joint's parent in the file, metres
        (:func:`gesturekit.bones.fit_bone_lengths` of the positions).
    parents : np.ndarray, shape (55,)
        The hierarchy (:func:`bvh_parents`); default the whole skeleton.
    rest : np.ndarray, shape (55, 3), optional
        Joint positions whose bone directions make the rest pose; default a
        T-pose built from ``positions`` (see the module notes).
    path : str or os.PathLike, optional
        File named in errors.

    Returns
    -------
    offsets : np.ndarray, shape (55, 3)
        Offset of every joint from its parent in the rest pose (all rotations
        identity), metres; zero for the root and joints left out.
    end_sites : np.ndarray, shape (55, 3)
        End Site offset of every leaf joint (a quarter of its bone, at least
        5 mm, along the bone); zero for other joints.
    """
    positions = np.asarray(positions, dtype=np.float64)
    child = np.flatnonzero(parents >= 0)
    children = children_of(parents)
    if rest is None:
        directions = _tpose_directions(positions, parents, children)
    else:
        rest = np.asarray(rest, dtype=np.float64)
        if rest.shape != (N_JOINTS, 3) or not np.isfinite(rest).all():
            raise ConfigError(
                f"rest must be finite joint positions of shape ({N_JOINTS}, 3), got {rest.shape}", path=path
            )
        directions = np.zeros((N_JOINTS, 3))
        directions[child] = rest[child] - rest[parents[child]]
    norms = np.linalg.norm(directions, axis=-1, keepdims=True)
    unit = np.divide(directions, norms, out=np.zeros_like(directions), where=norms > 1e-12)
    offsets = np.zeros((N_JOINTS, 3))
    offsets[child] = unit[child] * lengths[child, None]

    end_sites = np.zeros((N_JOINTS, 3))
    for j in child:
        if not children[j]:
            d = unit[j] if norms[j, 0] > 1e-12 else np.array([0.0, 1.0, 0.0])
            end_sites[j] = d * max(0.25 * lengths[j], 0.005)
    return offsets, end_sites


def _tpose_directions(positions: np.ndarray, parents: np.ndarray, children: tuple[tuple[int, ...], ...]) -> np.ndarray:
    """Rest direction of every bone (row = child joint) for the T-pose; not normalised."""
    d = np.zeros((N_JOINTS, 3))
    # the character's left is +X: arms sideways, spine and head straight up
    sideways = {"left_": [1.0, 0.0, 0.0], "right_": [-1.0, 0.0, 0.0]}
    for bone in np.flatnonzero(parents >= 0):
        name = JOINT_NAMES[bone]
        d[bone] = next((v for prefix, v in sideways.items() if name.startswith(prefix)), [0.0, 1.0, 0.0])
    # a joint with several children carries them rigidly: the data's mean shape, turned into the pose
    for j in range(N_JOINTS):
        if len(children[j]) >= 2:
            shape = dict(zip(children[j], _mean_shape(positions, j, children[j]), strict=True))
            basis = _shape_basis(j, shape)
            for c, v in shape.items():
                d[c] = basis.T @ v
    # straight fingers, continuing the direction of each finger's first bone
    for side in ("left", "right"):
        for finger in FINGERS:
            first = None
            for k in (1, 2, 3, 4):
                f = joint_index(f"{side}_{finger}{k}")
                if parents[f] < 0:
                    continue
                if first is None:
                    first = d[f].copy()
                else:
                    d[f] = first
    return d


def _shape_basis(joint: int, shape: dict[int, np.ndarray]) -> np.ndarray:
    """Rotation turning the mean shape of ``joint``'s children into the T-pose.

    A wrist: middle finger along the arm, index finger forward (+Z). Another
    joint: its left child minus its right child along +X, its unsided child
    (the neck) up (+Y), or, without one, the left and right children below it.
    """
    by_name = {JOINT_NAMES[c]: v for c, v in shape.items()}
    name = JOINT_NAMES[joint]
    if name.endswith("_wrist"):
        side = name[: -len("_wrist")]
        sign = 1.0 if side == "left" else -1.0
        middle = by_name.get(f"{side}_middle1", sign * np.mean(list(shape.values()), axis=0))
        index, pinky = by_name.get(f"{side}_index1"), by_name.get(f"{side}_pinky1")
        across = index - pinky if index is not None and pinky is not None else np.zeros(3)
        return _basis(sign * middle, across, first="x", second="z")
    left = [v for n, v in by_name.items() if n.startswith("left_")]
    right = [v for n, v in by_name.items() if n.startswith("right_")]
    unsided = [v for n, v in by_name.items() if not n.startswith(("left_", "right_"))]
    if left and right:
        up = unsided[0] if unsided else -(left[0] + right[0])
        return _basis(left[0] - right[0], up, first="x", second="y")
    first = list(shape.values())
    return _basis(first[0], first[1], first="y", second="x")


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


def _mean_shape(positions: np.ndarray, joint: int, children: tuple[int, ...], *, iterations: int = 3) -> np.ndarray:
    """Average shape of the bones from ``joint`` to its ``children``, shape (children, 3), metres.

    Generalised Procrustes: every frame's bones are turned onto the current
    mean (Kabsch), then averaged; the orientation of the result is arbitrary.
    A motion longer than :data:`MEAN_SHAPE_FRAMES` is averaged over that many
    frames spread evenly over it.
    """
    if len(positions) > MEAN_SHAPE_FRAMES:  # a rigid shape's average settles long before; SVDs cost per frame
        positions = positions[np.linspace(0, len(positions) - 1, MEAN_SHAPE_FRAMES).round().astype(np.int64)]
    bones = positions[:, list(children)] - positions[:, joint, None]
    mean = bones[0]
    for _ in range(iterations):
        # rotation of each frame onto the mean: maximise <H, R> with H = sum mean_c bones_c^T
        h = np.einsum("ci,tcj->tij", mean, bones)
        rot = _nearest_rotation(h)
        mean = np.einsum("tij,tcj->ci", rot, bones) / len(bones)
    return mean


# ----------------------------------------------------------------------------- rotations


@checks_arguments
def solve_rotations(
    positions: np.ndarray, offsets: np.ndarray, parents: np.ndarray = PARENTS
) -> tuple[np.ndarray, np.ndarray]:
    """Local joint rotations that move the rest pose onto the positions.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Joint positions, metres.
    offsets : np.ndarray, shape (55, 3)
        Rest offsets from :func:`rest_offsets`, metres.
    parents : np.ndarray, shape (55,)
        The hierarchy (:func:`bvh_parents`); default the whole skeleton.

    Returns
    -------
    local : np.ndarray, shape (frames, 55, 3, 3)
        Rotation of every joint relative to its parent (the root's: global;
        the identity for joints left out).
    root_position : np.ndarray, shape (frames, 3)
        Position of the root joint, metres.
    """
    positions = np.asarray(positions, dtype=np.float64)
    n = positions.shape[0]
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    children_all = children_of(parents)
    rest_pos = np.zeros((N_JOINTS, 3))
    for j in range(N_JOINTS):
        if parents[j] >= 0:
            rest_pos[j] = rest_pos[parents[j]] + offsets[j]
    glob = np.empty((n, N_JOINTS, 3, 3))
    local = np.empty((n, N_JOINTS, 3, 3))
    local[:] = np.eye(3)
    rebuilt = np.empty((n, N_JOINTS, 3))
    for j in range(N_JOINTS):
        p = parents[j]
        if p == LEFT_OUT:
            continue
        if p < 0:
            parent_rot = eye
            rebuilt[:, j] = positions[:, j]
        else:
            parent_rot = glob[:, p]
            rebuilt[:, j] = rebuilt[:, p] + parent_rot @ offsets[j]
        children = list(children_all[j])
        # bones are aimed from the rebuilt joint, so that errors do not add up along a chain
        if not children:
            loc = eye
        elif len(children) == 1:
            c = children[0]
            target = np.einsum("tji,tj->ti", parent_rot, positions[:, c] - rebuilt[:, j])
            loc = _swing(offsets[c], target)
            if j in _TWIST and parents[_TWIST[j][0]] != LEFT_OUT and parents[_TWIST[j][1]] != LEFT_OUT:
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
    return local, positions[:, int(np.flatnonzero(parents == -1)[0])].copy()


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


@checks_arguments
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


@checks_arguments
def continuous_angles(angles: np.ndarray, other: np.ndarray) -> np.ndarray:
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
