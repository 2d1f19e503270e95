"""Tests of gesturekit.datasets.bvh: parsing, forward kinematics, resampling, errors."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from gesturekit.datasets.bvh import (
    forward_kinematics,
    load_bvh_motion,
    parse_bvh,
    parse_bvh_text,
    resample_world_positions,
    unit_scale,
)
from gesturekit.datasets.presets import PRESETS
from gesturekit.errors import ConfigError, MotionFileError
from gesturekit.motion import output_frame_count
from gesturekit.skeleton import JOINT_NAMES, PARENTS, hand_indices, joint_index

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
ZEGGS = DATA / "zeggs" / "067_Speech_2_x_1_0.bvh"


# ----------------------------------------------------------------------------- writing test files

# random joint angles are no upright body: read them with the axes as they are
AS_IS = {"up": "y", "forward": "z", "check_plausible": False}


def bvh_text(joints, values, *, frame_time=1 / 30, newline="\n", indent="\t", frames_header=None):
    """BVH text of ``joints`` = [(name, parent, offset, channels, end_site_offset or None)] in preorder."""
    children = {i: [] for i in range(-1, len(joints))}
    for i, (_, parent, *_rest) in enumerate(joints):
        children[parent].append(i)
    out = ["HIERARCHY"]

    def write(i, depth):
        name, parent, offset, channels, end = joints[i]
        pad = indent * depth
        out.append(f"{pad}{'ROOT' if parent < 0 else 'JOINT'} {name}")
        out.append(pad + "{")
        out.append(f"{pad}{indent}OFFSET " + " ".join(f"{v:.9f}" for v in offset))
        if channels:
            out.append(f"{pad}{indent}CHANNELS {len(channels)} " + " ".join(channels))
        for c in children[i]:
            write(c, depth + 1)
        if end is not None:
            out.append(f"{pad}{indent}End Site")
            out.append(pad + indent + "{")
            out.append(f"{pad}{indent}{indent}OFFSET " + " ".join(f"{v:.9f}" for v in end))
            out.append(pad + indent + "}")
        out.append(pad + "}")

    for root in children[-1]:
        write(root, 0)
    values = np.atleast_2d(values)
    out.append("MOTION")
    out.append(f"Frames: {len(values) if frames_header is None else frames_header}")
    out.append(f"Frame Time: {frame_time:.10f}")
    out.extend(" ".join(f"{v:.9f}" for v in row) for row in values)
    return newline.join(out) + newline


ROT = ("Zrotation", "Yrotation", "Xrotation")
POS = ("Xposition", "Yposition", "Zposition")


def zeggs_like_skeleton(scale=1.0, drop=()):
    """A ZEGGS-named skeleton (centimetres at scale 1) in preorder, without legs but with one unused leg."""
    joints = []

    def add(name, parent, offset, channels=ROT, end=None):
        if name in drop:
            return None
        joints.append(
            (
                name,
                -1 if parent is None else parent,
                np.array(offset, float) * scale,
                channels,
                None if end is None else np.array(end, float) * scale,
            )
        )
        return len(joints) - 1

    hips = add("Hips", None, (0, 90, 0), POS + ROT)
    spine = add("Spine", hips, (0, 9, -2))
    s1 = add("Spine1", spine, (0, 9, 0))
    s2 = add("Spine2", s1, (0, 12, 0))
    s3 = add("Spine3", s2, (0, 12, 0))
    neck = add("Neck", s3, (0, 18, 0))
    neck1 = add("Neck1", neck, (0, 5, 0))
    head = add("Head", neck1, (0, 5, 0))
    add("HeadEnd", head, (0, 12, 0), end=(0, 0, 0))
    finger_roots = {
        "Thumb": (4, -3, 3),
        "Index": (10, 0, 2.3),
        "Middle": (9.5, 0, 0),
        "Ring": (9, 0, -2.3),
        "Pinky": (8, 0, -4.5),
    }
    for side, sx in (("Left", 1), ("Right", -1)):
        sh = add(f"{side}Shoulder", s3, (3 * sx, 11, 0))
        arm = add(f"{side}Arm", sh, (11 * sx, 0, 0))
        fore = add(f"{side}ForeArm", arm, (28 * sx, 0, 0))
        hand = add(f"{side}Hand", fore, (25 * sx, 0, 0))
        for finger, (x, y, z) in finger_roots.items():
            parent = hand
            for k in range(1, 5):
                off = (x * sx, y, z) if k == 1 else (3.2 * sx, 0, 0)
                tip = (0, 0, 0) if k == 4 else None
                j = add(f"{side}Hand{finger}{k}", parent, off, end=tip)
                parent = j if j is not None else parent
    add("RightUpLeg", hips, (-10, 0, 0), end=(0, -40, 0))
    return joints


def random_values(joints, n_frames, rng, *, angle=30.0, root_pos=(0.0, 90.0, 0.0)):
    cols = []
    for _, _, _, channels, _ in joints:
        for ch in channels:
            if ch.endswith("position"):
                base = root_pos["XYZ".index(ch[0])]
                cols.append(base + rng.uniform(-5, 5, n_frames))
            else:
                cols.append(rng.uniform(-angle, angle, n_frames))
    return np.stack(cols, axis=1) if cols else np.zeros((n_frames, 0))


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text, newline="")
    return path


# ----------------------------------------------------------------------------- independent FK


def scipy_fk(data, frame):
    """World positions of one frame by a per-joint loop with scipy rotations (uppercase = intrinsic)."""
    starts = data.channel_starts
    world_r, world_p = [], []
    for j in range(data.n_joints):
        chans = data.channels[j]
        vals = data.values[frame, starts[j] : starts[j] + len(chans)]
        offset = data.offsets[j].copy()
        axes, angles = "", []
        for ch, v in zip(chans, vals):
            if ch.endswith("position"):
                offset["XYZ".index(ch[0])] = v
            else:
                axes += ch[0]
                angles.append(v)
        local = Rotation.from_euler(axes, angles, degrees=True) if axes else Rotation.identity()
        p = data.parents[j]
        if p < 0:
            world_r.append(local)
            world_p.append(offset)
        else:
            world_r.append(world_r[p] * local)
            world_p.append(world_p[p] + world_r[p].apply(offset))
    return np.array(world_p)


# ----------------------------------------------------------------------------- the real ZEGGS take


@pytest.fixture(scope="module")
def zeggs():
    if not ZEGGS.is_file():
        pytest.skip(f"shared test data not found: {ZEGGS}")
    data = parse_bvh(ZEGGS)
    motion = load_bvh_motion(ZEGGS, joint_map="zeggs", **AS_IS)
    return data, motion


def test_zeggs_header_and_frame_count(zeggs):
    data, motion = zeggs
    assert data.n_frames == 2065 and data.fps == 30.0
    assert data.n_channels == 6 + 3 * (sum(1 for c in data.channels if c) - 1)
    assert motion.n_frames == 1032 and motion.fps == 15
    assert motion.positions.shape == (1032, 55, 3)
    assert unit_scale(data) == 0.01  # the file is in centimetres


def test_zeggs_bone_lengths_constant(zeggs):
    _, motion = zeggs
    lengths = motion.bone_lengths()
    assert np.ptp(lengths, axis=0).max() < 1e-4
    # forearm (elbow to wrist) of a human: between 15 and 40 cm
    bone = np.flatnonzero(PARENTS >= 0).tolist().index(joint_index("left_wrist"))
    assert 0.15 < lengths[0, bone] < 0.40


def test_zeggs_wrists_match_independent_fk(zeggs):
    data, motion = zeggs
    hips, lhand, rhand = data.index("Hips"), data.index("LeftHand"), data.index("RightHand")
    for t in (0, 1, 333, 700, 1031):
        ref = scipy_fk(data, 2 * t)  # 30 fps -> 15 fps: every second frame
        for ours, src in (("left_wrist", lhand), ("right_wrist", rhand)):
            expected = (ref[src] - ref[hips]) * 0.01
            np.testing.assert_allclose(motion.positions[t, joint_index(ours)], expected, atol=1e-5)


@pytest.mark.slow
def test_zeggs_wrist_matches_bvhio(zeggs):
    bvhio = pytest.importorskip("bvhio")
    _, motion = zeggs
    root = bvhio.readAsHierarchy(str(ZEGGS))
    lhand = root.filter("LeftHand")[0]
    for t in (0, 500, 1031):
        root.loadPose(2 * t)
        expected = (np.array(lhand.PositionWorld) - np.array(root.PositionWorld)) * 0.01
        np.testing.assert_allclose(motion.positions[t, joint_index("left_wrist")], expected, atol=1e-4)


def test_zeggs_hands_stay_near_wrists(zeggs):
    _, motion = zeggs
    for side in ("left", "right"):
        idx = hand_indices(side)
        dist = np.linalg.norm(motion.positions[:, idx[1:]] - motion.positions[:, idx[:1]], axis=-1)
        assert dist.max() < 0.3
        assert dist.min() > 0.005  # finger joints are not collapsed onto the wrist


def test_zeggs_y_is_up_and_left_is_plus_x_at_rest(zeggs):
    data, motion = zeggs
    pos = motion.positions
    assert (pos[:, joint_index("head_top"), 1] > pos[:, joint_index("spine_mid"), 1]).all()
    offsets = data.offsets
    assert offsets[data.index("LeftShoulder"), 0] > 0 > offsets[data.index("RightShoulder"), 0]


def test_zeggs_fk_is_fast(zeggs):
    data, _ = zeggs
    # the processor time of the work, not the wall clock: other work on a busy machine stretches the latter
    start = time.process_time()
    positions = forward_kinematics(data)
    elapsed = time.process_time() - start
    assert positions.shape == (2065, data.n_joints, 3)
    assert elapsed < 2.0, f"forward kinematics of the ZEGGS take took {elapsed:.2f} s of processor time"


def test_zeggs_end_sites_are_joints(zeggs):
    data, _ = zeggs
    assert "HeadEnd_End" in data.names
    end = data.index("LeftHandIndex4_End")
    assert data.names[data.parents[end]] == "LeftHandIndex4"
    assert data.channels[end] == ()


# ----------------------------------------------------------------------------- FK against scipy, random hierarchies

_LAYOUTS = st.sampled_from(["rot3", "rot6", "pos3", "rot2", "rot1", "none", "pos_rot_mixed"])


@st.composite
def hierarchies(draw):
    n = draw(st.integers(1, 6))
    parents, path = [], []
    for j in range(n):
        if j == 0:
            parents.append(-1)
            path = [0]
            continue
        pop = draw(st.integers(0, len(path) - 1))
        path = path[: len(path) - pop]
        parents.append(path[-1])
        path.append(j)
    joints = []
    for j in range(n):
        layout = draw(_LAYOUTS) if j else draw(st.sampled_from(["rot6", "pos_rot_mixed", "rot3"]))
        rot = list(draw(st.permutations(["Xrotation", "Yrotation", "Zrotation"])))
        pos = list(draw(st.permutations(["Xposition", "Yposition", "Zposition"])))
        channels = {
            "rot3": rot,
            "rot6": pos + rot,
            "pos3": pos,
            "rot2": rot[:2],
            "rot1": rot[:1],
            "none": [],
            "pos_rot_mixed": draw(st.permutations(pos + rot)),
        }[layout]
        offset = draw(st.lists(st.floats(-50, 50), min_size=3, max_size=3))
        is_leaf = j not in parents
        end = draw(st.lists(st.floats(-10, 10), min_size=3, max_size=3)) if is_leaf and draw(st.booleans()) else None
        joints.append((f"J{j}", parents[j], np.array(offset), channels, None if end is None else np.array(end)))
    n_frames = draw(st.integers(1, 3))
    n_ch = sum(len(c) for *_, c, _ in joints)
    values = np.array(
        draw(
            st.lists(st.lists(st.floats(-180, 180), min_size=n_ch, max_size=n_ch), min_size=n_frames, max_size=n_frames)
        ),
        dtype=float,
    ).reshape(n_frames, n_ch)
    style = draw(st.sampled_from([("\n", "\t"), ("\r\n", "  "), ("\n", " "), ("\r\n", "\t")]))
    return joints, values, style


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hierarchies())
def test_fk_equals_scipy_composition(case):
    joints, values, (newline, indent) = case
    data = parse_bvh_text(bvh_text(joints, values, newline=newline, indent=indent))
    expected_names = []
    for name, _, _, _, end in joints:
        expected_names.append(name)
        if end is not None:
            expected_names.append(f"{name}_End")
    assert list(data.names) == expected_names
    assert data.n_frames == values.shape[0]
    np.testing.assert_allclose(data.values, values, atol=1e-8)
    fk = forward_kinematics(data)
    for f in range(data.n_frames):
        np.testing.assert_allclose(fk[f], scipy_fk(data, f), atol=1e-6)


def test_fk_known_answer_intrinsic_order():
    # root rotates Z 90 then (intrinsic) X 90: the child at +Y goes to R(z90)R(x90) @ (0,1,0) = (0,0,1)
    joints = [
        ("A", -1, np.zeros(3), ["Zrotation", "Xrotation", "Yrotation"], None),
        ("B", 0, np.array([0.0, 1.0, 0.0]), ["Zrotation", "Xrotation", "Yrotation"], None),
    ]
    values = np.array([[90.0, 90.0, 0.0, 0.0, 0.0, 0.0]])
    data = parse_bvh_text(bvh_text(joints, values))
    np.testing.assert_allclose(forward_kinematics(data)[0, 1], [0.0, 0.0, 1.0], atol=1e-12)
    # the other order gives another answer: R(x90)R(z90) @ (0,1,0) = (-1,0,0)
    joints[0] = ("A", -1, np.zeros(3), ["Xrotation", "Zrotation", "Yrotation"], None)
    data = parse_bvh_text(bvh_text(joints, values))
    np.testing.assert_allclose(forward_kinematics(data)[0, 1], [-1.0, 0.0, 0.0], atol=1e-12)


def test_fk_frames_selects_frames():
    rng = np.random.default_rng(0)
    joints = zeggs_like_skeleton()[:12]
    values = random_values(joints, 7, rng)
    data = parse_bvh_text(bvh_text(joints, values))
    full = forward_kinematics(data)
    np.testing.assert_array_equal(forward_kinematics(data, frames=[1, 5, 6]), full[[1, 5, 6]])
    np.testing.assert_array_equal(forward_kinematics(data, frames=slice(0, 7, 3)), full[[0, 3, 6]])
    with pytest.raises(ConfigError):
        forward_kinematics(data, frames=[7])


# ----------------------------------------------------------------------------- file format variations


def test_parses_formatting_variations(tmp_path):
    text = (
        "\ufeffHIERARCHY  \r\n\r\n"
        "ROOT Hips\r\n{\r\n"
        "\tOFFSET\t0.0  1.0\t2.0   \r\n"
        "\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation\r\n"
        "  JOINT Chest {\r\n"
        "    OFFSET 0 10 0\r\n"
        "    CHANNELS 3 xROTATION yrotation zrotation\r\n"
        "    End Site\r\n    {\r\n      OFFSET 0 5 0\r\n    }\r\n"
        "  }\r\n}\r\n"
        "MOTION\r\n"
        "Frames:\t2\r\n"
        "Frame Time:0.0416667\r\n\r\n"
        "1 2 3 0 0 0 0 0 0   \r\n"
        "\t4\t5 6 0 0 90 0 0 0\r\n\r\n\r\n"
    )
    path = tmp_path / "variations.bvh"
    path.write_bytes(text.encode("utf-8"))
    data = parse_bvh(path)
    assert data.names == ("Hips", "Chest", "Chest_End")
    assert list(data.parents) == [-1, 0, 1]
    assert data.channels[1] == ("Xrotation", "Yrotation", "Zrotation")
    assert data.fps == 24.0  # 1 / 0.0416667 snapped
    pos = forward_kinematics(data)
    np.testing.assert_allclose(pos[0, 0], [1, 2, 3])  # position channels replace the root offset
    np.testing.assert_allclose(pos[1, 2], [4 - 15, 5, 6], atol=1e-9)  # Z 90: +Y chain points to -X


def test_position_channels_replace_offset_on_any_joint():
    joints = [
        ("A", -1, np.array([100.0, 100.0, 100.0]), ["Xposition", "Yposition", "Zposition"], None),
        ("B", 0, np.array([7.0, 8.0, 9.0]), ["Yposition", "Xrotation"], None),
    ]
    values = np.array([[1.0, 2.0, 3.0, 50.0, 0.0]])
    data = parse_bvh_text(bvh_text(joints, values))
    pos = forward_kinematics(data)[0]
    np.testing.assert_allclose(pos[0], [1, 2, 3])
    np.testing.assert_allclose(pos[1], [1 + 7, 2 + 50, 3 + 9])


# ----------------------------------------------------------------------------- units and pelvis


def test_cm_and_m_files_give_the_same_metres(tmp_path):
    rng = np.random.default_rng(1)
    joints_cm = zeggs_like_skeleton(1.0)
    values_cm = random_values(joints_cm, 6, rng)
    joints_m = zeggs_like_skeleton(0.01)
    values_m = values_cm.copy()
    pos_cols = [k for k, ch in enumerate(ch for *_, chans, _ in joints_cm for ch in chans) if ch.endswith("position")]
    values_m[:, pos_cols] *= 0.01
    cm = write(tmp_path, "cm.bvh", bvh_text(joints_cm, values_cm))
    m = write(tmp_path, "m.bvh", bvh_text(joints_m, values_m))
    auto_cm, auto_m = load_bvh_motion(cm, **AS_IS), load_bvh_motion(m, **AS_IS)
    np.testing.assert_allclose(auto_cm.positions, auto_m.positions, atol=1e-6)
    np.testing.assert_allclose(load_bvh_motion(cm, units="cm", **AS_IS).positions, auto_m.positions, atol=1e-6)
    np.testing.assert_allclose(load_bvh_motion(m, units="m", **AS_IS).positions, auto_m.positions, atol=1e-6)
    # forearm of the generated skeleton: 28 cm
    assert (
        abs(
            np.linalg.norm(
                auto_m.positions[0, joint_index("left_elbow")] - auto_m.positions[0, joint_index("left_shoulder")]
            )
            - 0.28
        )
        < 1e-5
    )
    with pytest.raises(ConfigError):
        load_bvh_motion(cm, units="inch", **AS_IS)


def test_output_is_pelvis_relative(tmp_path):
    rng = np.random.default_rng(2)
    joints = zeggs_like_skeleton()
    values = random_values(joints, 5, rng)
    moved = values.copy()
    moved[:, :3] += np.array([300.0, -20.0, 55.0])  # translate the whole body
    a = load_bvh_motion(write(tmp_path, "a.bvh", bvh_text(joints, values)), **AS_IS)
    b = load_bvh_motion(write(tmp_path, "b.bvh", bvh_text(joints, moved)), **AS_IS)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-5)
    # the pelvis-relative spine_mid is Spine + Spine1 above the hips at rest-ish angles: within 30 cm
    assert np.linalg.norm(a.positions[:, joint_index("spine_mid")], axis=-1).max() < 0.3


def test_integer_ratio_is_exact_subsampling(tmp_path):
    rng = np.random.default_rng(3)
    joints = zeggs_like_skeleton()
    values = random_values(joints, 9, rng)
    path = write(tmp_path, "s.bvh", bvh_text(joints, values, frame_time=1 / 60))
    data = parse_bvh(path)
    motion = load_bvh_motion(path, **AS_IS)
    full = forward_kinematics(data) * 0.01
    names = PRESETS["zeggs"].source_names()
    idx = [data.index(n) for n in names]
    expected = full[[0, 4], :][:, idx] - full[[0, 4], :][:, [data.index("Hips")]]
    assert motion.n_frames == 2  # 9 frames at 60 fps = 0.15 s -> 2 frames at 15 fps
    np.testing.assert_allclose(motion.positions, expected, atol=1e-6)


# ----------------------------------------------------------------------------- resampling


@pytest.mark.parametrize("fps_in", [24, 25, 29.97, 50, 60, 100, 120])
def test_resampling_frame_count_and_rigid_bones(tmp_path, fps_in):
    rng = np.random.default_rng(4)
    joints = zeggs_like_skeleton()
    n = 61
    values = random_values(joints, n, rng, angle=60.0)
    path = write(tmp_path, f"r{fps_in}.bvh", bvh_text(joints, values, frame_time=1 / fps_in))
    motion = load_bvh_motion(path, **AS_IS)
    assert motion.n_frames == output_frame_count(n, fps_in, 15) == math.floor(n * 15 / fps_in + 1e-9)
    assert motion.fps == 15
    lengths = motion.bone_lengths()
    assert np.ptp(lengths, axis=0).max() < 1e-5


def test_slerp_resampling_follows_a_constant_rotation():
    # the root turns about Y at 10 degrees per frame (24 fps); output frame t lies at source frame 1.6 t
    joints = [("A", -1, np.zeros(3), ["Yrotation"], None), ("B", 0, np.array([1.0, 0.0, 0.0]), [], None)]
    n = 20
    values = (10.0 * np.arange(n))[:, None]
    data = parse_bvh_text(bvh_text(joints, values, frame_time=1 / 24))
    out = resample_world_positions(data, fps=15)
    assert out.shape == (12, 2, 3)
    angles = np.radians(10.0 * 1.6 * np.arange(12))
    expected = np.stack([np.cos(angles), np.zeros(12), -np.sin(angles)], axis=1)
    np.testing.assert_allclose(out[:, 1], expected, atol=1e-9)


def test_slerp_takes_the_short_way_and_lerps_translation():
    # from 170 to -170 degrees the short way passes 180, not 0
    joints = [("A", -1, np.zeros(3), ["Xposition", "Yrotation"], None), ("B", 0, np.array([1.0, 0.0, 0.0]), [], None)]
    values = np.array([[0.0, 170.0], [10.0, -170.0], [10.0, -170.0], [10.0, -170.0]])
    data = parse_bvh_text(bvh_text(joints, values, frame_time=1 / 20))
    out = resample_world_positions(data, fps=40)  # frame 1 lies halfway between source frames 0 and 1
    np.testing.assert_allclose(out[1, 0], [5.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(out[1, 1], [5.0 - 1.0, 0.0, 0.0], atol=1e-9)


# ----------------------------------------------------------------------------- errors


GOOD = bvh_text(
    [("A", -1, np.zeros(3), list(POS + ROT), None), ("B", 0, np.ones(3), list(ROT), (0, 1, 0))], np.zeros((2, 9))
)


def _bad_files():
    lines = GOOD.splitlines()
    motion = lines.index("MOTION")
    frames = GOOD.replace("Frames: 2", "Frames: 0").splitlines()[: motion + 3]
    return {
        "empty": "",
        "blank": "  \n\n\t\n",
        "not_bvh": "hello, I am a text file\nwith two lines\n",
        "bad_offset": GOOD.replace("OFFSET 1.000000000 1.000000000 1.000000000", "OFFSET 1.0 abc 1.0"),
        "bad_value": "\n".join(lines[:-1] + [lines[-1].replace("0.000000000", "0.0.1", 1)]) + "\n",
        "short_line": "\n".join(lines[:-1] + [" ".join(lines[-1].split()[:-1])]) + "\n",
        "long_line": "\n".join(lines[:-1] + [lines[-1] + " 1.0"]) + "\n",
        "zero_frames": "\n".join(frames) + "\n",
        "nan": "\n".join(lines[:-1] + [lines[-1].replace("0.000000000", "nan", 1)]) + "\n",
        "inf": "\n".join(lines[:-1] + [lines[-1].replace("0.000000000", "-inf", 1)]) + "\n",
        "truncated": "\n".join(lines[:-1]) + "\n",
        "no_motion": "\n".join(lines[:motion]) + "\n",
        "unbalanced": GOOD.replace("MOTION", "}\nMOTION"),
        "unclosed": "\n".join(lines[: motion - 1] + lines[motion:]) + "\n",
        "bad_channel": GOOD.replace("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation"),
        "bad_count": GOOD.replace("CHANNELS 3", "CHANNELS three"),
        "bad_frame_time": GOOD.replace("Frame Time: ", "Frame Time: x"),
        "zero_frame_time": GOOD.replace("Frame Time: 0.0333333333", "Frame Time: 0"),
    }


def test_good_fixture_parses():
    data = parse_bvh_text(GOOD)
    assert data.names == ("A", "B", "B_End") and data.n_frames == 2


@pytest.mark.parametrize("case", sorted(_bad_files()))
def test_malformed_files_raise_motion_file_error_naming_the_file(tmp_path, case):
    path = write(tmp_path, f"bad_{case}.bvh", _bad_files()[case])
    with pytest.raises(MotionFileError, match=f"bad_{case}.bvh"):
        parse_bvh(path)
    with pytest.raises(MotionFileError, match=f"bad_{case}.bvh"):
        load_bvh_motion(path, **AS_IS)


def test_specific_error_messages(tmp_path):
    bad = _bad_files()
    cases = {
        "short_line": "8 values on a frame line",
        "zero_frames": "no frames",
        "nan": "NaN",
        "bad_offset": "malformed number 'abc'",
        "not_bvh": "not a BVH",
        "empty": "empty",
        "truncated": "header says 2 frames",
    }
    for case, fragment in cases.items():
        with pytest.raises(MotionFileError, match=fragment):
            parse_bvh(write(tmp_path, f"{case}.bvh", bad[case]))


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(MotionFileError, match="nothere.bvh.*not found"):
        parse_bvh(tmp_path / "nothere.bvh")
    with pytest.raises(MotionFileError, match="nothere.bvh"):
        load_bvh_motion(tmp_path / "nothere.bvh", **AS_IS)
    binary = tmp_path / "binary.bvh"
    binary.write_bytes(b"\x00\x01\x02HIERARCHY\x00")
    with pytest.raises(MotionFileError, match="binary.bvh"):
        parse_bvh(binary)
    with pytest.raises(MotionFileError, match="directory"):
        parse_bvh(tmp_path)


def test_missing_map_joints_are_all_listed_in_one_error(tmp_path):
    rng = np.random.default_rng(5)
    drop = ("HeadEnd", "LeftHandPinky4", "RightHandIndex4")
    joints = zeggs_like_skeleton(drop=drop)
    path = write(tmp_path, "incomplete.bvh", bvh_text(joints, random_values(joints, 3, rng)))
    with pytest.raises(MotionFileError) as info:
        load_bvh_motion(path, joint_map="zeggs", **AS_IS)
    message = str(info.value)
    assert "incomplete.bvh" in message and "'zeggs'" in message
    for name in drop:
        assert name in message
    assert "3 joints" in message


def test_too_short_for_one_output_frame(tmp_path):
    rng = np.random.default_rng(6)
    joints = zeggs_like_skeleton()
    path = write(tmp_path, "short.bvh", bvh_text(joints, random_values(joints, 1, rng), frame_time=1 / 30))
    with pytest.raises(MotionFileError, match="short.bvh.*too short"):
        load_bvh_motion(path, **AS_IS)


def test_all_55_joints_come_from_the_map(tmp_path):
    # each of our joints sits where its source joint is: compare one finger tip by hand
    rng = np.random.default_rng(7)
    joints = zeggs_like_skeleton()
    path = write(tmp_path, "map.bvh", bvh_text(joints, random_values(joints, 2, rng), frame_time=1 / 15))
    data = parse_bvh(path)
    motion = load_bvh_motion(path, **AS_IS)
    full = forward_kinematics(data) * 0.01
    hips = data.index("Hips")
    for ours in JOINT_NAMES:
        src = data.index(PRESETS["zeggs"].joints[ours])
        np.testing.assert_allclose(motion.positions[:, joint_index(ours)], full[:, src] - full[:, hips], atol=1e-6)
