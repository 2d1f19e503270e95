"""Tests of gesturekit.datasets.presets: the built-in joint maps and JSON joint maps."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gesturekit.datasets.bvh import load_bvh_motion, parse_bvh
from gesturekit.datasets.presets import PRESETS, JointMap, load_joint_map, missing_and_unknown
from gesturekit.errors import ConfigError, InputFileError, MotionFileError
from gesturekit.skeleton import JOINT_NAMES, PARENTS

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
ZEGGS = DATA / "zeggs" / "067_Speech_2_x_1_0.bvh"

# random joint angles are no upright body: read them with the axes as they are
AS_IS = {"up": "y", "forward": "z", "check_plausible": False}


def _chain(names, first, step, *, last_children=(), end=(0, 0, 0)):
    """Nested nodes (name, offset, children, end_site) for a chain of joints."""
    node = (names[-1], first if len(names) == 1 else step, list(last_children), None if last_children else end)
    for i in range(len(names) - 2, -1, -1):
        node = (names[i], first if i == 0 else step, [node], None)
    return node


def _beat_tree():
    """BEAT's 75-joint hierarchy: metacarpal joints for index, ring and pinky, finger tips
    ``...4`` as joints followed by End Sites, and legs (offsets in centimetres)."""
    arms = []
    for side, sx in (("Right", -1), ("Left", 1)):
        fingers = [_chain([f"{side}HandMiddle{k}" for k in range(1, 5)], (9 * sx, 0, 0), (3 * sx, 0, 0))]
        for finger, z in (("Ring", -1), ("Pinky", -2), ("Index", 1)):
            fingers.append(
                _chain(
                    [f"{side}Hand{finger}"] + [f"{side}Hand{finger}{k}" for k in range(1, 5)],
                    (2 * sx, 0, z),
                    (3 * sx, 0, 0),
                )
            )
        fingers.append(_chain([f"{side}HandThumb{k}" for k in range(1, 5)], (3 * sx, -2, 3), (3 * sx, 0, 0)))
        arm = _chain(
            [f"{side}Shoulder", f"{side}Arm", f"{side}ForeArm", f"{side}Hand"],
            (3 * sx, 11, 0),
            (20 * sx, 0, 0),
            last_children=fingers,
        )
        arms.append(arm)
    head = _chain(["Neck", "Neck1", "Head", "HeadEnd"], (0, 15, 1), (0, 6, 0))
    spine = _chain(["Spine", "Spine1", "Spine2", "Spine3"], (0, 8, -2), (0, 12, 0), last_children=[head] + arms)
    legs = [
        _chain(
            [f"{s}UpLeg", f"{s}Leg", f"{s}Foot", f"{s}ForeFoot", f"{s}ToeBase", f"{s}ToeBaseEnd"],
            (10 * sx, 0, 0),
            (0, -20, 0),
        )
        for s, sx in (("Right", -1), ("Left", 1))
    ]
    return ("Hips", (0, 95, 0), [spine] + legs, None)


def beat_like_bvh(prefix="", n_frames=16, seed=0):
    """BVH text of :func:`_beat_tree` (XYZ rotation channels, 120 fps, random angles)."""
    lines = ["HIERARCHY"]
    n_channels = 0

    def write(node, root=False):
        nonlocal n_channels
        name, offset, children, end = node
        lines.extend(
            [f"{'ROOT' if root else 'JOINT'} {prefix}{name}", "{", "OFFSET " + " ".join(str(float(v)) for v in offset)]
        )
        if root:
            lines.append("CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation")
            n_channels += 6
        else:
            lines.append("CHANNELS 3 Xrotation Yrotation Zrotation")
            n_channels += 3
        for child in children:
            write(child)
        if end is not None:
            lines.extend(["End Site", "{", "OFFSET " + " ".join(str(float(v)) for v in end), "}"])
        lines.append("}")

    write(_beat_tree(), root=True)
    rng = np.random.default_rng(seed)
    values = rng.uniform(-25, 25, (n_frames, n_channels))
    values[:, :3] = [0, 95, 0]
    body = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in values)
    return "\n".join(lines) + f"\nMOTION\nFrames: {n_frames}\nFrame Time: 0.008333\n{body}\n"


def test_presets_map_all_55_joints():
    assert set(PRESETS) == {"zeggs", "beat"}
    for name, jmap in PRESETS.items():
        assert jmap.name == name
        assert missing_and_unknown(jmap.joints) == ([], [])
        assert len(jmap.source_names()) == 55
        assert len(set(jmap.source_names())) == 55  # no two of our joints share a source joint
        assert jmap.pelvis == "Hips"
    zeggs = PRESETS["zeggs"].joints
    assert zeggs["spine_mid"] == "Spine1" and zeggs["head_top"] == "HeadEnd"
    assert zeggs["left_collar"] == "LeftShoulder" and zeggs["left_shoulder"] == "LeftArm"
    assert zeggs["right_elbow"] == "RightForeArm" and zeggs["right_wrist"] == "RightHand"
    assert zeggs["left_pinky1"] == "LeftHandPinky1" and zeggs["right_thumb4"] == "RightHandThumb4"


def test_presets_are_read_only():
    with pytest.raises(TypeError):
        PRESETS["zeggs"].joints["head"] = "Neck"
    with pytest.raises(TypeError):
        PRESETS["new"] = PRESETS["zeggs"]


def test_zeggs_preset_bones_are_parent_child_pairs_in_the_real_file():
    if not ZEGGS.is_file():
        pytest.skip(f"shared test data not found: {ZEGGS}")
    data = parse_bvh(ZEGGS)
    jmap = PRESETS["zeggs"]
    for child, parent in enumerate(PARENTS):
        src = data.index(jmap.joints[JOINT_NAMES[child]])
        if parent < 0:
            # our root hangs below the pelvis in the source chain
            ancestors = []
            p = data.parents[src]
            while p >= 0:
                ancestors.append(data.names[p])
                p = data.parents[p]
            assert jmap.pelvis in ancestors
        else:
            assert data.names[data.parents[src]] == jmap.joints[JOINT_NAMES[parent]], JOINT_NAMES[child]


def test_beat_preset_reads_a_beat_like_file(tmp_path):
    path = tmp_path / "beat_like.bvh"
    path.write_text(beat_like_bvh())
    data = parse_bvh(path)
    assert data.n_joints == 75 + 1 + 10 + 2  # BEAT's 75 joints; End Sites of HeadEnd, 10 finger tips, 2 toes
    assert data.names[data.parents[data.index("LeftHandIndex1")]] == "LeftHandIndex"
    motion = load_bvh_motion(path, joint_map="beat", **AS_IS)
    assert motion.n_frames == 2 and motion.fps == 15  # 16 frames at 120 fps
    assert "HeadEnd_End" in data.names and "LeftHandPinky4_End" in data.names
    # every bone is rigid except wrist -> first joint of index, ring and pinky, which spans
    # BEAT's (moving) metacarpal joint
    lengths = motion.bone_lengths()
    children = np.flatnonzero(PARENTS >= 0)
    spanning = {JOINT_NAMES.index(f"{s}_{f}1") for s in ("left", "right") for f in ("index", "ring", "pinky")}
    rigid = np.array([c not in spanning for c in children])
    assert np.ptp(lengths[:, rigid], axis=0).max() < 1e-5
    with pytest.raises(MotionFileError, match="missing"):
        load_bvh_motion(
            path,
            joint_map={"pelvis": "Hips", "joints": {**PRESETS["beat"].joints, "left_index1": "LeftHandIndex0"}},
            **AS_IS,
        )


def test_json_joint_map_file_matches_the_preset(tmp_path):
    plain = tmp_path / "plain.bvh"
    plain.write_text(beat_like_bvh(seed=3))
    prefixed = tmp_path / "prefixed.bvh"
    prefixed.write_text(beat_like_bvh(prefix="mixamorig:", seed=3))
    spec = {"pelvis": "mixamorig:Hips", "joints": {k: f"mixamorig:{v}" for k, v in PRESETS["beat"].joints.items()}}
    map_path = tmp_path / "map.json"
    map_path.write_text(json.dumps(spec))
    jmap = load_joint_map(map_path)
    assert jmap.name == str(map_path) and jmap.pelvis == "mixamorig:Hips"
    expected = load_bvh_motion(plain, joint_map="beat", **AS_IS).positions
    np.testing.assert_array_equal(load_bvh_motion(prefixed, joint_map=map_path, **AS_IS).positions, expected)
    np.testing.assert_array_equal(load_bvh_motion(prefixed, joint_map=str(map_path), **AS_IS).positions, expected)
    np.testing.assert_array_equal(load_bvh_motion(prefixed, joint_map=spec, **AS_IS).positions, expected)
    # the map's own name appears when the file lacks its joints
    with pytest.raises(MotionFileError, match="map.json"):
        load_bvh_motion(plain, joint_map=map_path, **AS_IS)


def test_missing_joints_are_listed(tmp_path):
    joints = dict(PRESETS["zeggs"].joints)
    del joints["left_pinky4"], joints["head_top"]
    with pytest.raises(ConfigError) as info:
        load_joint_map({"pelvis": "Hips", "joints": joints})
    assert "left_pinky4" in str(info.value) and "head_top" in str(info.value) and "2 of our joints" in str(info.value)

    path = tmp_path / "partial.json"
    path.write_text(json.dumps({"pelvis": "Hips", "joints": {**joints, "left_pinky5": "X"}}))
    with pytest.raises(InputFileError) as info:
        load_joint_map(path)
    message = str(info.value)
    assert "partial.json" in message
    assert "left_pinky4" in message and "head_top" in message and "left_pinky5" in message


@pytest.mark.parametrize(
    "content, fragment",
    [
        ("{not json", "not valid JSON"),
        ("[1, 2]", "JSON object"),
        ('{"joints": {}}', "pelvis"),
        ('{"pelvis": "Hips", "joints": 3}', "joints"),
        ('{"pelvis": "Hips", "joints": {}, "extra": 1}', "unexpected keys"),
    ],
)
def test_bad_json_maps_name_the_file(tmp_path, content, fragment):
    path = tmp_path / "bad_map.json"
    path.write_text(content)
    with pytest.raises(InputFileError, match=fragment) as info:
        load_joint_map(path)
    assert "bad_map.json" in str(info.value)


def test_bad_specs():
    with pytest.raises(ConfigError, match="unknown joint map 'zeggz'"):
        load_joint_map("zeggz")
    with pytest.raises(InputFileError, match="not found"):
        load_joint_map("maps/none.json")
    with pytest.raises(ConfigError):
        load_joint_map(42)
    joints = dict(PRESETS["zeggs"].joints, head="")
    with pytest.raises(ConfigError, match="head"):
        load_joint_map({"pelvis": "Hips", "joints": joints})
    assert load_joint_map("ZEGGS") is PRESETS["zeggs"]
    custom = JointMap("custom", "Hips", PRESETS["zeggs"].joints)
    assert load_joint_map(custom) is custom
    with pytest.raises(ConfigError, match="broken"):
        load_joint_map(JointMap("broken", "Hips", {"head": "Head"}))
