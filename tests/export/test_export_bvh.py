"""Tests of gesturekit.export.bvh (and the shared helpers of gesturekit._io).

Exported files are read back by readers that share no code with the writer:
the ``bvhio`` package, and a small parser with scipy forward kinematics
defined here.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from gesturekit._io import atomic_write, safe_filename
from gesturekit.errors import ConfigError, OutputError
from gesturekit.export import bvh as bvh_module
from gesturekit.export.bvh import ROTATION_ORDERS, euler_from_matrices, write_bvh
from gesturekit.motion import Motion
from gesturekit.skeleton import FINGERS, JOINT_NAMES, N_JOINTS, PARENTS, joint_index

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"
ZEGGS_BVH = SHARED / "zeggs" / "067_Speech_2_x_1_0.bvh"
MM = 1e-3


# ----------------------------------------------------------------------------- an independent reader


def parse_bvh(path):
    """(joints, fps, data): joints as dicts name/parent/offset/channels in file order, data (frames, channels)."""
    tokens = Path(path).read_text().split()
    joints, stack, i = [], [], 0
    assert tokens[i] == "HIERARCHY"
    i += 1
    while tokens[i] != "MOTION":
        tok = tokens[i]
        if tok in ("ROOT", "JOINT"):
            joints.append({"name": tokens[i + 1], "parent": stack[-1] if stack else -1, "channels": [], "end": None})
            i += 2
        elif tok == "End":
            assert (
                tokens[i + 1] == "Site" and tokens[i + 2] == "{" and tokens[i + 3] == "OFFSET" and tokens[i + 7] == "}"
            )
            joints[stack[-1]]["end"] = np.array(tokens[i + 4 : i + 7], dtype=float)
            i += 8
        elif tok == "{":
            stack.append(len(joints) - 1)
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            joints[stack[-1]]["offset"] = np.array(tokens[i + 1 : i + 4], dtype=float)
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            joints[stack[-1]]["channels"] = tokens[i + 2 : i + 2 + n]
            i += 2 + n
        else:
            raise AssertionError(f"unexpected token {tok!r}")
    assert not stack
    assert tokens[i + 1] == "Frames:" and tokens[i + 3 : i + 5] == ["Frame", "Time:"]
    frames, frame_time = int(tokens[i + 2]), float(tokens[i + 5])
    data = np.array(tokens[i + 6 :], dtype=float)
    n_channels = sum(len(j["channels"]) for j in joints)
    assert data.size == frames * n_channels
    return joints, 1.0 / frame_time, data.reshape(frames, n_channels)


def scipy_fk(path):
    """World positions of every joint, dict name -> (frames, 3), in the file's units."""
    joints, _, data = parse_bvh(path)
    out, rots, col = {}, [], 0
    for j in joints:
        chans = j["channels"]
        vals = data[:, col : col + len(chans)]
        col += len(chans)
        pos = np.broadcast_to(j["offset"], (len(data), 3)).copy()
        order, angles = "", []
        for c, name in enumerate(chans):
            if name.endswith("position"):
                pos[:, "XYZ".index(name[0])] = vals[:, c]
            else:
                order += name[0]
                angles.append(vals[:, c])
        local = (
            Rotation.from_euler(order, np.stack(angles, axis=1), degrees=True)
            if order
            else Rotation.identity(len(data))
        )
        if j["parent"] < 0:
            world, glob = pos, local
        else:
            parent = joints[j["parent"]]["name"]
            world = out[parent] + rots[j["parent"]].apply(pos)
            glob = rots[j["parent"]] * local
        out[j["name"]] = world
        rots.append(glob)
    return out


def bvhio_positions(path):
    """World positions (frames, 55, 3) in the file's units, read with the bvhio package."""
    bvhio = pytest.importorskip("bvhio")
    root = bvhio.readAsHierarchy(str(path))
    layout = [j for j, _, _ in root.layout()]
    frames = bvhio.readAsBvh(str(path), loadKeyFrames=False).FrameCount
    out = np.zeros((frames, N_JOINTS, 3))
    for t in range(frames):
        root.loadPose(t)
        for j in layout:
            out[t, joint_index(j.Name)] = tuple(j.PositionWorld)
    return out


def read_positions(path, scale=100.0):
    fk = scipy_fk(path)
    return np.stack([fk[name] for name in JOINT_NAMES], axis=1) / scale


# ----------------------------------------------------------------------------- motion made by forward kinematics


def _offsets():
    """A plausible 55-joint skeleton (metres), character facing +Z, its left +X."""
    o = {
        "chest": (0, 0.12, 0.01),
        "upper_chest": (0, 0.13, -0.01),
        "neck": (0, 0.16, -0.02),
        "neck_upper": (0, 0.05, 0.01),
        "head": (0, 0.06, 0.02),
        "head_top": (0, 0.13, 0.0),
        "left_collar": (0.05, 0.11, 0.0),
        "left_shoulder": (0.13, -0.01, -0.02),
        "left_elbow": (0.28, 0, 0),
        "left_wrist": (0.25, 0, 0.01),
    }
    hand = {
        "thumb": ((0.03, -0.01, 0.03), (0.035, 0.03, 0.025)),
        "index": ((0.09, 0.0, 0.025), (0.045, 0.025, 0.02)),
        "middle": ((0.09, 0.0, 0.005), (0.05, 0.03, 0.02)),
        "ring": ((0.085, 0.0, -0.015), (0.045, 0.028, 0.02)),
        "pinky": ((0.08, -0.005, -0.03), (0.035, 0.02, 0.018)),
    }
    for finger, (root, phalanges) in hand.items():
        o[f"left_{finger}1"] = root
        direction = np.array(root) / np.linalg.norm(root) + np.array([0.0, -0.1, 0.0])
        for k, length in enumerate(phalanges, start=2):
            o[f"left_{finger}{k}"] = tuple(length * direction / np.linalg.norm(direction))
    for name in list(o):
        if name.startswith("left_"):
            x, y, z = o[name]
            o["right_" + name[5:]] = (-x, y, z)
    out = np.zeros((N_JOINTS, 3))
    for name, v in o.items():
        out[joint_index(name)] = v
    return out


OFFSETS = _offsets()


def fk(root_pos, rotvecs, offsets=OFFSETS):
    """Positions (frames, 55, 3) from root positions (frames, 3) and local rotation vectors (frames, 55, 3)."""
    n = len(rotvecs)
    glob, pos = [None] * N_JOINTS, np.zeros((n, N_JOINTS, 3))
    for j in range(N_JOINTS):
        local = Rotation.from_rotvec(rotvecs[:, j])
        if PARENTS[j] < 0:
            glob[j], pos[:, j] = local, root_pos
        else:
            p = PARENTS[j]
            glob[j] = glob[p] * local
            pos[:, j] = pos[:, p] + glob[p].apply(np.tile(offsets[j], (n, 1)))
    return pos


def smooth_motion(n_frames, seed, max_angle=1.2, offsets=OFFSETS):
    """Smooth random motion: every local rotation vector a sum of slow sines, at most ``max_angle`` rad."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames)[:, None, None] / 15.0
    freq = rng.uniform(0.1, 0.8, (3, N_JOINTS, 3))
    phase = rng.uniform(0, 2 * np.pi, (3, N_JOINTS, 3))
    amp = rng.uniform(0.2, 1.0, (3, N_JOINTS, 3))
    rv = sum(amp[k] * np.sin(2 * np.pi * freq[k] * t + phase[k]) for k in range(3))
    norm = np.linalg.norm(rv, axis=-1, keepdims=True)
    rv = rv / np.maximum(norm, 1e-12) * np.minimum(norm, max_angle)
    root = np.array([0.0, 0.1, 0.0]) + 0.05 * np.sin(t[:, 0] * rng.uniform(0.2, 1, 3))
    return fk(root, rv, offsets)


def max_error(a, b):
    return float(np.linalg.norm(a - b, axis=-1).max())


# ----------------------------------------------------------------------------- round trips


def test_bvhio_reads_back_positions_within_1mm(tmp_path):
    pos = smooth_motion(12, seed=0)
    path = write_bvh(tmp_path / "take.bvh", Motion(pos, 15))
    back = bvhio_positions(path) / 100.0
    assert max_error(back, pos) < MM


def test_scipy_reader_agrees_with_bvhio(tmp_path):
    # two independent readers of the same file must agree; guards the reader used by the other tests
    path = write_bvh(tmp_path / "take.bvh", Motion(smooth_motion(5, seed=1), 15), rotation_order="YXZ")
    assert max_error(read_positions(path), bvhio_positions(path) / 100.0) < 1e-5


@pytest.mark.parametrize("order", ROTATION_ORDERS)
@pytest.mark.parametrize("units,scale", [("cm", 100.0), ("m", 1.0)])
def test_round_trip_every_order_and_unit(tmp_path, order, units, scale):
    pos = smooth_motion(60, seed=2)
    path = write_bvh(tmp_path / "take.bvh", Motion(pos, 15), rotation_order=order, units=units)
    assert max_error(read_positions(path, scale), pos) < MM


@st.composite
def poses(draw):
    """A few random poses: any root rotation, limbs anywhere from straight to strongly bent."""
    n = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**32 - 1))
    straightness = draw(st.sampled_from([0.0, 1e-6, 1e-3, 0.05, 1.0]))
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, N_JOINTS, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    # straightness scales every angle: 0 gives the exact rest pose (straight fingers and arms)
    angles = rng.uniform(0, 2.4, (n, N_JOINTS, 1)) * straightness
    rv = axes * angles
    rv[:, 0] = Rotation.random(n, random_state=seed % 2**31).as_rotvec()
    root = rng.uniform(-0.3, 0.3, (n, 3))
    return fk(root, rv)


@pytest.mark.slow
@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(pos=poses(), order=st.sampled_from(ROTATION_ORDERS))
def test_random_poses_round_trip(tmp_path, pos, order):
    path = write_bvh(tmp_path / "pose.bvh", Motion(pos, 30), rotation_order=order, overwrite=True)
    assert max_error(read_positions(path), pos) < MM


def test_near_straight_and_folded_fingers(tmp_path):
    rv = np.zeros((4, N_JOINTS, 3))
    for side in ("left", "right"):
        for finger in FINGERS:
            for k in (2, 3, 4):
                j = joint_index(f"{side}_{finger}{k}")
                rv[1, j] = [0, 0, 1e-7]  # straight to within a hair
                rv[2, j] = [0, 0, 1.6]  # folded
                rv[3, j] = [0, 0, -2.9]  # bent far back
    pos = fk(np.zeros((4, 3)), rv)
    path = write_bvh(tmp_path / "fingers.bvh", Motion(pos, 15))
    assert max_error(read_positions(path), pos) < MM


def test_bone_lengths_varying_by_one_percent(tmp_path):
    rng = np.random.default_rng(3)
    n = 40
    pos = smooth_motion(n, seed=3)
    # rebuild with every bone scaled by up to 1 % per frame
    factor = 1 + rng.uniform(-0.01, 0.01, (n, N_JOINTS, 1))
    varied = np.zeros_like(pos)
    varied[:, 0] = pos[:, 0]
    for j in range(1, N_JOINTS):
        varied[:, j] = varied[:, PARENTS[j]] + (pos[:, j] - pos[:, PARENTS[j]]) * factor[:, j]
    path = write_bvh(tmp_path / "varied.bvh", Motion(varied, 15))
    err = np.linalg.norm(read_positions(path) - varied, axis=-1)
    # each joint is off by at most the length variation (from the median) of the bones on its chain,
    # frame by frame: errors of a parent do not grow along the chain
    lengths = np.zeros((n, N_JOINTS))
    lengths[:, 1:] = np.linalg.norm(varied[:, 1:] - varied[:, PARENTS[1:]], axis=-1)
    deviation = np.abs(lengths - np.median(lengths, axis=0))
    chain = np.zeros_like(deviation)
    for j in range(1, N_JOINTS):
        chain[:, j] = chain[:, PARENTS[j]] + deviation[:, j]
    assert np.all(err <= chain + 1e-6)
    assert err.max() > 1e-4  # the variation is really there, and cannot be reproduced exactly


def test_zeggs_take_round_trips(tmp_path):
    if not ZEGGS_BVH.is_file():
        pytest.skip("shared test data (../shared/data/zeggs) not present")
    fk_world = scipy_fk(ZEGGS_BVH)
    names = {
        "spine_mid": "Spine1",
        "chest": "Spine2",
        "upper_chest": "Spine3",
        "neck": "Neck",
        "neck_upper": "Neck1",
        "head": "Head",
        "head_top": "HeadEnd",
    }
    for side, big in (("left", "Left"), ("right", "Right")):
        names.update(
            {
                f"{side}_collar": f"{big}Shoulder",
                f"{side}_shoulder": f"{big}Arm",
                f"{side}_elbow": f"{big}ForeArm",
                f"{side}_wrist": f"{big}Hand",
            }
        )
        for finger in FINGERS:
            for k in range(1, 5):
                names[f"{side}_{finger}{k}"] = f"{big}Hand{finger.capitalize()}{k}"
    pos = np.stack([fk_world[names[n]] - fk_world["Hips"] for n in JOINT_NAMES], axis=1)[::2] / 100.0
    motion = Motion(pos, 15)
    assert np.ptp(motion.bone_lengths(), axis=0).max() < 1e-4  # every mapped bone is a real bone: rigid
    path = write_bvh(tmp_path / "zeggs.bvh", motion)
    assert max_error(read_positions(path), motion.positions) < MM


def test_rest_given_as_first_frame(tmp_path):
    pos = smooth_motion(20, seed=4)
    path = write_bvh(tmp_path / "rest.bvh", Motion(pos, 15), rest=pos[0])
    assert max_error(read_positions(path), pos) < MM
    joints, _, data = parse_bvh(path)
    offsets = {j["name"]: j["offset"] / 100.0 for j in joints}
    for j in range(1, N_JOINTS):
        np.testing.assert_allclose(offsets[JOINT_NAMES[j]], pos[0, j] - pos[0, PARENTS[j]], atol=2e-5)
    # the first frame is the rest pose: every rotation but the root's is the identity
    assert np.abs(data[0, 6:]).max() < 1e-3


# ----------------------------------------------------------------------------- the file itself


def test_hierarchy_format(tmp_path):
    pos = smooth_motion(7, seed=5)
    path = write_bvh(tmp_path / "take.bvh", Motion(pos, 15))
    text = path.read_text()
    lines = [line.strip() for line in text.splitlines()]
    assert lines[0] == "HIERARCHY" and lines[1] == "ROOT spine_mid"
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" in lines
    assert lines.count("CHANNELS 3 Zrotation Xrotation Yrotation") == N_JOINTS - 1
    assert lines.count("End Site") == sum(1 for j in range(N_JOINTS) if j not in PARENTS)  # 11 leaves
    assert "Frames: 7" in lines and "Frame Time: 0.06666666667" in lines
    names = re.findall(r"^\s*(?:ROOT|JOINT) (\S+)\s*$", text, flags=re.M)
    assert sorted(names) == sorted(JOINT_NAMES) and all(" " not in n for n in names)
    joints, fps, data = parse_bvh(path)
    assert fps == pytest.approx(15) and data.shape == (7, 6 + 3 * (N_JOINTS - 1))
    # parents in the file are those of the skeleton
    for j in joints:
        parent = JOINT_NAMES[PARENTS[joint_index(j["name"])]] if j["parent"] >= 0 else None
        assert parent == (joints[j["parent"]]["name"] if j["parent"] >= 0 else None)
    # root position channels: spine_mid relative to the pelvis, in cm; root OFFSET zero
    np.testing.assert_allclose(data[:, :3], pos[:, 0] * 100, atol=1e-5)
    assert np.all(joints[0]["offset"] == 0)
    assert "-0.000000" not in text


def test_offsets_are_median_bone_lengths_in_a_tpose(tmp_path):
    pos = smooth_motion(9, seed=6)
    path = write_bvh(tmp_path / "take.bvh", Motion(pos, 15), units="m")
    joints, _, _ = parse_bvh(path)
    offsets = {j["name"]: j["offset"] for j in joints}
    lengths = np.median(Motion(pos, 15).bone_lengths(), axis=0)
    for k, j in enumerate(np.flatnonzero(PARENTS >= 0)):
        assert np.linalg.norm(offsets[JOINT_NAMES[j]]) == pytest.approx(lengths[k], abs=2e-6)
    unit = {n: v / np.linalg.norm(v) for n, v in offsets.items() if np.linalg.norm(v) > 0}
    for name in ("chest", "upper_chest", "neck_upper", "head", "head_top"):
        np.testing.assert_allclose(unit[name], [0, 1, 0], atol=1e-6)
    for name in ("shoulder", "elbow", "wrist"):
        np.testing.assert_allclose(unit[f"left_{name}"], [1, 0, 0], atol=1e-6)
        np.testing.assert_allclose(unit[f"right_{name}"], [-1, 0, 0], atol=1e-6)
    # palms down, fingers along the arm, index finger in front of the little finger, thumb forward
    for side, sign in (("left", 1), ("right", -1)):
        np.testing.assert_allclose(unit[f"{side}_middle1"][[1, 2]], [0, 0], atol=1e-6)
        assert sign * unit[f"{side}_middle1"][0] > 0.99
        assert offsets[f"{side}_index1"][2] > offsets[f"{side}_pinky1"][2]
        assert offsets[f"{side}_thumb1"][2] > 0
        np.testing.assert_allclose(unit[f"{side}_index4"], unit[f"{side}_index1"], atol=1e-4)
    assert offsets["left_collar"][0] > 0 > offsets["right_collar"][0]


def test_units_scale_offsets_and_positions(tmp_path):
    motion = Motion(smooth_motion(5, seed=7), 15)
    cm = parse_bvh(write_bvh(tmp_path / "cm.bvh", motion, units="cm"))
    m = parse_bvh(write_bvh(tmp_path / "m.bvh", motion, units="m"))
    for a, b in zip(cm[0], m[0]):
        np.testing.assert_allclose(a["offset"], b["offset"] * 100, atol=1e-4)
    np.testing.assert_allclose(cm[2][:, :3], m[2][:, :3] * 100, atol=1e-4)
    np.testing.assert_allclose(cm[2][:, 3:], m[2][:, 3:], atol=1e-5)


def test_angles_are_continuous_over_frames(tmp_path):
    # a root spinning about Y for two full turns must not jump by 360 degrees
    n = 120
    rv = np.zeros((n, N_JOINTS, 3))
    rv[:, 0, 1] = np.linspace(0, 4 * np.pi, n) % (2 * np.pi) - np.pi
    pos = fk(np.zeros((n, 3)), rv)
    _, _, data = parse_bvh(write_bvh(tmp_path / "spin.bvh", Motion(pos, 15)))
    assert np.abs(np.diff(data[:, 3:], axis=0)).max() < 20.0
    assert np.ptp(data[:, 3:6]) > 540.0  # unwrapped: the angle keeps growing
    # leaning forward past 90 degrees: the middle angle goes on growing instead of folding back
    lean = np.zeros((n, N_JOINTS, 3))
    lean[:, 0, 0] = np.linspace(0, np.radians(170), n)
    _, _, data = parse_bvh(write_bvh(tmp_path / "lean.bvh", Motion(fk(np.zeros((n, 3)), lean), 15)))
    # (the test skeleton's spine leans 4.8 degrees forward of the rest pose's straight up)
    np.testing.assert_allclose(data[:, 4] - data[0, 4], np.linspace(0, 170, n), atol=1e-3)
    np.testing.assert_allclose(data[:, [3, 5]], 0, atol=1e-3)
    smooth = parse_bvh(write_bvh(tmp_path / "smooth.bvh", Motion(smooth_motion(150, seed=8, max_angle=0.5), 15)))[2]
    assert np.abs(np.diff(smooth[:, 3:], axis=0)).max() < 30.0


def test_same_input_gives_same_bytes(tmp_path):
    motion = Motion(smooth_motion(10, seed=9), 15)
    a = write_bvh(tmp_path / "a.bvh", motion).read_bytes()
    b = write_bvh(tmp_path / "b.bvh", motion).read_bytes()
    assert a == b


def test_euler_decomposition_matches_scipy():
    m = Rotation.random(200, random_state=0).as_matrix()
    locked = Rotation.from_euler("ZXY", [[0.4, np.pi / 2, 0.3]]).as_matrix()
    for order in ROTATION_ORDERS:
        angles, other = euler_from_matrices(m, order)
        np.testing.assert_allclose(Rotation.from_euler(order, angles).as_matrix(), m, atol=1e-12)
        np.testing.assert_allclose(Rotation.from_euler(order, other).as_matrix(), m, atol=1e-12)
        assert np.all(np.abs(angles[:, 1]) <= np.pi / 2 + 1e-12)
    angles, _ = euler_from_matrices(locked, "ZXY")
    np.testing.assert_allclose(Rotation.from_euler("ZXY", angles).as_matrix(), locked, atol=1e-12)


def test_fast_for_a_minute_of_motion(tmp_path):
    motion = Motion(smooth_motion(900, seed=10), 15)
    write_bvh(tmp_path / "warm.bvh", motion)
    best = np.inf
    for k in range(2):  # the processor time of the work: other work on a busy machine stretches the wall clock
        start = time.process_time()
        write_bvh(tmp_path / f"timed{k}.bvh", motion)
        best = min(best, time.process_time() - start)
    assert best < 1.0


# ----------------------------------------------------------------------------- errors, overwrite, atomicity


def test_bad_input_is_reported(tmp_path):
    pos = smooth_motion(3, seed=11)
    pos[2, 5, 1] = np.nan
    with pytest.raises(ConfigError, match=r"bad\.bvh.*frame 2"):
        write_bvh(tmp_path / "bad.bvh", Motion(pos, 15))
    good = Motion(smooth_motion(3, seed=11), 15)
    with pytest.raises(ConfigError, match="units"):
        write_bvh(tmp_path / "x.bvh", good, units="inch")
    with pytest.raises(ConfigError, match="rotation_order"):
        write_bvh(tmp_path / "x.bvh", good, rotation_order="XYX")
    with pytest.raises(ConfigError, match="rest"):
        write_bvh(tmp_path / "x.bvh", good, rest=np.zeros((13, 3)))
    with pytest.raises(ConfigError, match="without frames"):
        write_bvh(tmp_path / "x.bvh", Motion(np.zeros((0, N_JOINTS, 3)), 15))
    with pytest.raises(ConfigError, match="does not exist"):
        write_bvh(tmp_path / "missing" / "x.bvh", good)
    assert sorted(os.listdir(tmp_path)) == []


def test_overwrite_protection(tmp_path):
    path = tmp_path / "take.bvh"
    path.write_text("precious")
    motion = Motion(smooth_motion(3, seed=12), 15)
    with pytest.raises(ConfigError, match=r"take\.bvh.*already exists.*overwrite"):
        write_bvh(path, motion)
    assert path.read_text() == "precious"
    # overwrite replaces only a BVH of gesturekit's skeleton
    with pytest.raises(OutputError, match=r"take\.bvh: is a file that gesturekit did not write"):
        write_bvh(path, motion, overwrite=True)
    assert path.read_text() == "precious"
    path.unlink()
    write_bvh(path, Motion(smooth_motion(3, seed=13), 15))
    write_bvh(path, motion, overwrite=True)
    assert path.read_text().startswith("HIERARCHY")
    assert sorted(os.listdir(tmp_path)) == ["take.bvh"]


def test_failure_leaves_no_partial_file(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(bvh_module, "_bvh_text", broken)
    motion = Motion(smooth_motion(3, seed=13), 15)
    with pytest.raises(RuntimeError):
        write_bvh(tmp_path / "take.bvh", motion)
    assert os.listdir(tmp_path) == []

    # a failure half-way through writing: neither the old file nor the folder is touched
    target = tmp_path / "old.bvh"
    target.write_text("old")

    def half(f):
        f.write(b"HIERARCHY\nROOT")
        raise OSError("no space left")

    with pytest.raises(OutputError, match="no space left"):
        atomic_write(target, half, overwrite=True)
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["old.bvh"]


def test_atomic_write_refuses_a_file_created_meanwhile(tmp_path):
    target = tmp_path / "late.bin"

    def racer(f):
        target.write_bytes(b"someone else")
        f.write(b"mine")

    with pytest.raises(ConfigError, match="already exists"):
        atomic_write(target, racer)
    assert target.read_bytes() == b"someone else" and os.listdir(tmp_path) == ["late.bin"]


# ----------------------------------------------------------------------------- file names


@given(st.text(max_size=300))
def test_safe_filename_is_safe(name):
    out = safe_filename(name)
    assert 0 < len(out) <= 100
    assert re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9._-]*", out)
    assert ".." not in out and out.split(".")[0].upper() not in {"CON", "PRN", "AUX", "NUL", "COM1", "LPT1"}
    assert safe_filename(name) == out  # deterministic


@given(st.text(min_size=101, max_size=200, alphabet="ab"))
def test_long_names_stay_distinct(name):
    assert safe_filename(name) != safe_filename(name[:-1] + ("a" if name[-1] == "b" else "b"))


@pytest.mark.parametrize(
    "name,expected",
    [
        ("../../etc/passwd", "etc_passwd"),
        ("my take 01", "my_take_01"),
        ("café", "cafe"),
        ("a..b.bvh", "a.b.bvh"),
        ("C:\\x\\y", "C_x_y"),
        ("line\nbreak\x00", "line_break"),
        ("con", "_con"),
        ("-rf", "rf"),
        (".hidden", "hidden"),
    ],
)
def test_safe_filename_examples(name, expected):
    assert safe_filename(name) == expected


def test_sanitised_name_stays_in_the_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    path = write_bvh(out / f"{safe_filename('../../escape')}.bvh", Motion(smooth_motion(2, seed=14), 15))
    assert path.resolve().parent == out.resolve() and os.listdir(tmp_path) == ["out"]
    assert safe_filename("日本") != safe_filename("中国") and safe_filename("").startswith("unnamed")
