"""The generated demo speaker's body: a fixed rest skeleton, arm inverse kinematics, and the motion.

Keyposes of each arm (:data:`POSE_DIM` numbers, laid out below) are joined
by minimum-jerk interpolation, given a little drift, turned into joint
rotations by two-bone inverse kinematics and posed by forward kinematics
(:func:`gesturekit.datasets._kinematics.world_positions`, the BVH reader's) on
the rest skeleton, so bone lengths are exactly constant. The torso sways, leans
and the head nods on stressed syllables. Part of :mod:`gesturekit.datasets.synthetic`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from scipy.ndimage import gaussian_filter1d

from ..skeleton import FINGERS, FPS, N_JOINTS, PARENTS, joint_index
from ._demo_speech import Speech, smooth_noise
from ._kinematics import world_positions

# frames per block of forward kinematics, to bound memory on long takes
_FK_BLOCK = 8192


# ---------------------------------------------------------------------------------------------
# skeleton: rest offsets and forward kinematics
# ---------------------------------------------------------------------------------------------

_UPPER_ARM = 0.30  # shoulder to elbow, m
_FOREARM = 0.26  # elbow to wrist, m
_REACH = 0.985 * (_UPPER_ARM + _FOREARM)  # the elbow never quite straightens
# body offsets from the parent joint in the rest pose, metres (T-pose: arms along +-X, palms down)
_BODY_OFFSETS = {
    "spine_mid": (0.0, 0.11, -0.02),  # from the pelvis (implicit root)
    "chest": (0.0, 0.12, 0.0),
    "upper_chest": (0.0, 0.12, 0.0),
    "neck": (0.0, 0.14, -0.01),
    "neck_upper": (0.0, 0.05, 0.01),
    "head": (0.0, 0.05, 0.01),
    "head_top": (0.0, 0.14, 0.02),
    "left_collar": (0.03, 0.10, -0.01),
    "left_shoulder": (0.15, 0.0, 0.0),
    "left_elbow": (_UPPER_ARM, 0.0, 0.0),
}
# keyposes keep the wrist within this fraction of the reach; beyond it inverse kinematics
# pulls the wrist in smoothly
_COMFORT = 0.97
# upper_chest and the left shoulder in the upright rest pose, pelvis frame, m
_UPPER_CHEST = np.sum([_BODY_OFFSETS[n] for n in ("spine_mid", "chest", "upper_chest")], axis=0)
_SHOULDER = _UPPER_CHEST + np.sum([_BODY_OFFSETS[n] for n in ("left_collar", "left_shoulder")], axis=0)
# hand of the left side, wrist frame = world frame in the rest pose: fingers +X, thumb +Z, palm -Y
_FINGER_ROOTS = {
    "thumb": (0.028, -0.015, 0.024),
    "index": (0.095, 0.0, 0.026),
    "middle": (0.096, 0.0, 0.004),
    "ring": (0.089, -0.002, -0.016),
    "pinky": (0.081, -0.005, -0.034),
}
_FINGER_DIRS = {
    "thumb": (0.72, -0.2, 0.66),
    "index": (1.0, 0.0, 0.06),
    "middle": (1.0, 0.0, 0.0),
    "ring": (1.0, 0.0, -0.06),
    "pinky": (1.0, 0.0, -0.13),
}
_PHALANGES = {  # root->2, 2->3, 3->tip, metres
    "thumb": (0.040, 0.033, 0.028),
    "index": (0.041, 0.031, 0.025),
    "middle": (0.046, 0.034, 0.026),
    "ring": (0.042, 0.033, 0.025),
    "pinky": (0.034, 0.026, 0.022),
}
# flexion per unit curl of joints 1..3 (radians) and spread angles (per unit spread)
_CURL_ANGLES = {"thumb": (0.5, 0.7, 0.9), "other": (1.3, 1.65, 1.1)}
_SPREAD_ANGLES = {"thumb": 0.3, "index": 0.17, "middle": 0.03, "ring": -0.1, "pinky": -0.24}
_MIRROR = np.diag([-1.0, 1.0, 1.0])


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@functools.lru_cache(maxsize=1)
def _rest_offsets() -> np.ndarray:
    """Offset of every joint from its parent in the rest pose, shape (55, 3), metres."""
    off = np.zeros((N_JOINTS, 3))
    for name, o in _BODY_OFFSETS.items():
        off[joint_index(name)] = o
        if name.startswith("left_"):
            off[joint_index("right_" + name[5:])] = _MIRROR @ np.asarray(o)
    off[joint_index("left_wrist")] = (_FOREARM, 0.0, 0.0)
    off[joint_index("right_wrist")] = (-_FOREARM, 0.0, 0.0)
    for finger in FINGERS:
        d = unit(_FINGER_DIRS[finger])
        chain = [np.asarray(_FINGER_ROOTS[finger])] + [length * d for length in _PHALANGES[finger]]
        for i, link in enumerate(chain, start=1):
            off[joint_index(f"left_{finger}{i}")] = link
            off[joint_index(f"right_{finger}{i}")] = _MIRROR @ link
    off.setflags(write=False)
    return off


def _axis_angle(axis, angle: np.ndarray) -> np.ndarray:
    """Rotations about fixed unit ``axis`` (3,) by ``angle`` (T,) radians, shape (T, 3, 3)."""
    x, y, z = unit(axis)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    a = np.asarray(angle, dtype=np.float64)[:, None, None]
    return np.eye(3) + np.sin(a) * k + (1.0 - np.cos(a)) * (k @ k)


def _forward_kinematics(root_pos: np.ndarray, local: list[np.ndarray]) -> np.ndarray:
    """Joint positions from local rotations, by the forward kinematics the BVH reader uses.

    Parameters
    ----------
    root_pos : np.ndarray, shape (T, 3)
        Position of the root joint (``spine_mid``), metres.
    local : list of 55 np.ndarray, each shape (T, 3, 3)
        Rotation of each joint relative to its parent (the root's is global).

    Returns
    -------
    np.ndarray, shape (T, 55, 3), float64
    """
    n = len(root_pos)
    out = np.empty((n, N_JOINTS, 3))
    root = int(np.flatnonzero(PARENTS < 0)[0])  # spine_mid, the only root
    for s in range(0, n, _FK_BLOCK):
        e = min(s + _FK_BLOCK, n)
        # components first, frames last: the layout of gesturekit.datasets._kinematics
        rot = np.stack([np.broadcast_to(r[s:e], (e - s, 3, 3)) for r in local], axis=-1).transpose(1, 2, 3, 0)
        trans = np.repeat(_rest_offsets().T[:, :, None], e - s, axis=2)
        trans[:, root] = root_pos[s:e].T
        out[s:e] = world_positions(PARENTS, rot, trans)
    return out


# ---------------------------------------------------------------------------------------------
# keyposes: an arm's degrees of freedom, joined by minimum-jerk moves
# ---------------------------------------------------------------------------------------------

# keypose of one arm, in the left arm's convention (x is outward from the body axis):
# wrist target x, y, z (m, pelvis frame of an upright torso), elbow swivel, forearm roll
# (+ turns the palm down, - up), wrist flexion, wrist deviation (rad), 5 finger curls (0 open .. 1
# fist, thumb first), finger spread (0..1)
WRIST = slice(0, 3)
SWIVEL, ROLL, FLEX, DEV = 3, 4, 5, 6
CURL = slice(7, 12)
SPREAD = 12
POSE_DIM = 13


def reachable(pose: np.ndarray) -> np.ndarray:
    """A copy of ``pose`` with the wrist target pulled within comfortable reach of the shoulder."""
    pose = pose.copy()
    rel = pose[WRIST] - _SHOULDER
    dist = float(np.linalg.norm(rel))
    if dist > _COMFORT * _REACH:
        pose[WRIST] = _SHOULDER + rel * (_COMFORT * _REACH / dist)
    return pose


def _min_jerk_track(times: np.ndarray, poses: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Keyposes joined by minimum-jerk moves, sampled at ``t``.

    Parameters
    ----------
    times : np.ndarray, shape (K,), increasing
    poses : np.ndarray, shape (K, D)
    t : np.ndarray, shape (T,)

    Returns
    -------
    np.ndarray, shape (T, D); velocity and acceleration are zero at every keypose.
    """
    if len(times) == 1:
        return np.repeat(poses[:1], len(t), axis=0)
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    s = np.clip((t - times[i]) / (times[i + 1] - times[i]), 0.0, 1.0)
    w = s**3 * (10.0 - 15.0 * s + 6.0 * s**2)
    return poses[i] + w[:, None] * (poses[i + 1] - poses[i])


# ---------------------------------------------------------------------------------------------
# motion
# ---------------------------------------------------------------------------------------------


def _bumps(times: np.ndarray, heights: np.ndarray, n: int, sigma_frames: float) -> np.ndarray:
    """Sum of Gaussian bumps at ``times`` (in frames), sampled on frames 0..n-1, shape (n,)."""
    impulses = np.zeros(n + 2)
    f = np.clip(times, 0.0, n)
    i0 = np.floor(f).astype(np.int64)
    w = f - i0
    np.add.at(impulses, i0, heights * (1.0 - w))
    np.add.at(impulses, i0 + 1, heights * w)
    return gaussian_filter1d(impulses, sigma_frames, mode="constant")[:n] * (math.sqrt(2 * math.pi) * sigma_frames)


def _arm_rotations(pose: np.ndarray) -> dict[str, np.ndarray]:
    """Local rotations of one arm (left-arm convention) from its keypose track.

    Two-bone inverse kinematics in the frame of ``upper_chest``: the wrist
    reaches its target (pulled smoothly inside the arm's reach), the elbow lies
    in the plane set by the swivel angle.

    Parameters
    ----------
    pose : np.ndarray, shape (T, 13)
        Keyposes sampled per frame; the wrist target is in the pelvis frame of an
        upright torso and moves with the torso's sway.

    Returns
    -------
    dict of joint suffix -> np.ndarray, shape (T, 3, 3)
    """
    off = _rest_offsets()
    wrist_y = pose[:, 1]
    shrug = 0.03 + 0.2 * np.clip((wrist_y - 0.15) / 0.45, 0.0, 1.0) ** 2
    protract = 0.12 * np.clip(pose[:, 2] / 0.4, -0.5, 1.0)
    collar = _axis_angle((0, 0, 1), shrug) @ _axis_angle((0, -1, 0), protract)
    shoulder = off[joint_index("left_collar")] + collar @ off[joint_index("left_shoulder")]
    target = pose[:, WRIST] - _UPPER_CHEST
    d_vec = target - shoulder
    dist = np.linalg.norm(d_vec, axis=1)
    n = d_vec / dist[:, None]
    l1, l2 = _UPPER_ARM, _FOREARM
    d_max = _REACH
    d0 = _COMFORT * d_max
    d = np.where(dist > d0, d0 + (d_max - d0) * np.tanh((dist - d0) / (d_max - d0)), dist)
    d = np.maximum(d, 0.12)
    a = (l1**2 - l2**2 + d**2) / (2.0 * d)
    r = np.sqrt(np.maximum(l1**2 - a**2, 0.0))
    pole = unit([0.45, -0.8, -0.35])  # elbow down, out and a little back
    u0 = pole - (n @ pole)[:, None] * n
    u0 = u0 / np.linalg.norm(u0, axis=1, keepdims=True)
    sw = pose[:, SWIVEL][:, None]
    u = u0 * np.cos(sw) + np.cross(n, u0) * np.sin(sw)
    elbow = shoulder + a[:, None] * n + r[:, None] * u
    wrist = shoulder + d[:, None] * n
    x_u = unit(elbow - shoulder)
    x_f = unit(wrist - elbow)
    y_u = -unit(np.cross(x_u, x_f))  # elbow hinge axis
    upper = np.stack([x_u, y_u, np.cross(x_u, y_u)], axis=2)
    fore = np.stack([x_f, y_u, np.cross(x_f, y_u)], axis=2) @ _axis_angle((1, 0, 0), pose[:, ROLL])
    hand = _axis_angle((0, 0, -1), pose[:, FLEX]) @ _axis_angle((0, -1, 0), pose[:, DEV])
    rots = {
        "collar": collar,
        "shoulder": np.swapaxes(collar, 1, 2) @ upper,
        "elbow": np.swapaxes(upper, 1, 2) @ fore,
        "wrist": hand,
    }
    palm = np.array([0.0, -1.0, 0.0])
    for fi, finger in enumerate(FINGERS):
        curl = pose[:, CURL][:, fi]
        direction = unit(_FINGER_DIRS[finger])
        toward = unit([0.0, -0.6, -0.8]) if finger == "thumb" else palm
        axis = unit(np.cross(direction, toward))
        angles = _CURL_ANGLES["thumb" if finger == "thumb" else "other"]
        spread = _axis_angle((0, -1, 0), _SPREAD_ANGLES[finger] * (pose[:, SPREAD] - 0.3))
        rots[f"{finger}1"] = spread @ _axis_angle(axis, angles[0] * curl)
        rots[f"{finger}2"] = _axis_angle(axis, angles[1] * curl)
        rots[f"{finger}3"] = _axis_angle(axis, angles[2] * curl)
    return rots


class KeyposeTrack(Protocol):
    """One arm's keyposes: ``poses[i]`` (:data:`POSE_DIM` numbers, laid out above) at ``times[i]`` seconds."""

    times: list[float]
    poses: list[np.ndarray]


def render_motion(arms: Sequence[KeyposeTrack], speech: Speech, rng: np.random.Generator, n_frames: int) -> np.ndarray:
    """Positions of the take, shape (n_frames, 55, 3), float32, from the (left, right) arms' keypose tracks."""
    t = np.arange(n_frames) / FPS
    identity = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
    local = [identity] * N_JOINTS
    # torso: slow sway, a slight forward lean and a head nod on every stressed syllable
    stress_frames = speech.syl_nucleus[speech.syl_stressed] * FPS
    lean = _bumps(stress_frames, rng.uniform(0.01, 0.025, len(stress_frames)), n_frames, 2.5)
    nod = _bumps(stress_frames + 0.03 * FPS, rng.uniform(0.04, 0.09, len(stress_frames)), n_frames, 1.8)
    sway = smooth_noise(rng, n_frames, 12.0, 3) * np.array([0.025, 0.03, 0.02])  # lean, side, twist
    head = smooth_noise(rng, n_frames, 10.0, 3) * np.array([0.04, 0.07, 0.025])  # pitch, yaw, roll
    shares = {"spine_mid": 0.4, "chest": 0.3, "upper_chest": 0.3}
    for name, share in shares.items():
        local[joint_index(name)] = (
            _axis_angle((1, 0, 0), share * (sway[:, 0] + lean))
            @ _axis_angle((0, 0, 1), share * sway[:, 1])
            @ _axis_angle((0, 1, 0), share * sway[:, 2])
        )
    local[joint_index("neck")] = _axis_angle((1, 0, 0), 0.3 * (head[:, 0] + nod))
    local[joint_index("head")] = (
        _axis_angle((1, 0, 0), 0.7 * (head[:, 0] + nod))
        @ _axis_angle((0, 1, 0), head[:, 1])
        @ _axis_angle((0, 0, 1), head[:, 2])
    )
    root = local[joint_index("spine_mid")] @ np.asarray(_BODY_OFFSETS["spine_mid"])
    for side, arm in zip(("left", "right"), arms):
        pose = _min_jerk_track(np.asarray(arm.times), np.stack(arm.poses), t)
        # a living hold: the wrist and hand drift a little, never quite still
        pose[:, WRIST] += smooth_noise(rng, n_frames, 6.0, 3) * 0.008
        pose[:, ROLL] += smooth_noise(rng, n_frames, 8.0, 1)[:, 0] * 0.05
        pose[:, CURL] = np.clip(pose[:, CURL] + smooth_noise(rng, n_frames, 8.0, 5) * 0.03, 0.0, 1.0)
        for suffix, rot in _arm_rotations(pose).items():
            # the right arm is the mirror image of a left arm with the same keyposes
            local[joint_index(f"{side}_{suffix}")] = rot if side == "left" else _MIRROR @ rot @ _MIRROR
    return _forward_kinematics(root, local).astype(np.float32)
