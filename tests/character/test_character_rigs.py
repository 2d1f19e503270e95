"""The generated characters of tests/character_rigs.py are what they claim: valid files whose bones,
rest positions, skins and humanoid maps, read back from the bytes, equal :func:`truth`."""

from __future__ import annotations

import dataclasses
import json
import re
import struct
import zlib

import bvhio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.character.glb import accessor_array, node_matrices, read_glb
from gesturekit.datasets.bvh_file import parse_bvh, parse_bvh_text
from gesturekit.datasets.presets import PRESETS
from gesturekit.skeleton import JOINT_NAMES
from tests.character_rigs import CASES, RigSpec, custom_map, rig_files, truth, write_rig
from tests.export.test_export_gltf import validator  # noqa: F401

GLTF_CASES = [k for k, s in CASES.items() if s.fmt == "glb"]


def gltf_bones(data: bytes) -> tuple[dict, bytes, list[int], np.ndarray]:
    """(document, binary chunk, the skin's joint nodes, every node's rest world matrix (N, 4, 4))."""
    doc, binary = read_glb(data)
    return doc, binary, doc["skins"][0]["joints"], node_matrices(doc["nodes"], {}, 1)[0]


def read_back(spec: RigSpec) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Bone names, parents (-1 root) and rest world positions in metres, read from the file's bytes."""
    ((name, data),) = rig_files(spec).items()
    if name.endswith(".bvh"):
        bvh = parse_bvh_text(data.decode("ascii"))
        world = np.zeros_like(bvh.offsets)
        for j, p in enumerate(bvh.parents):
            world[j] = bvh.offsets[j] + (world[p] if p >= 0 else 0.0)
        keep = [j for j, c in enumerate(bvh.channels) if c]  # End Sites have no channels
        index = {j: i for i, j in enumerate(keep)}
        parents = np.array([index.get(int(bvh.parents[j]), -1) for j in keep])
        return tuple(bvh.names[j] for j in keep), parents, world[keep] / 100.0
    doc, _, joints, world = gltf_bones(data)
    parent_node = {c: i for i, n in enumerate(doc["nodes"]) for c in n.get("children", ())}
    slot = {node: i for i, node in enumerate(joints)}
    parents = np.array([slot.get(parent_node.get(node, -1), -1) for node in joints])
    return tuple(doc["nodes"][j]["name"] for j in joints), parents, world[joints, :3, 3]


@pytest.mark.parametrize("case", GLTF_CASES)
def test_gltf_cases_pass_the_khronos_validator(case, tmp_path, validator):  # noqa: F811
    path = write_rig(tmp_path, CASES[case], case)
    issues = validator(path)["issues"]
    assert issues["numErrors"] == 0, [m for m in issues["messages"] if m["severity"] == 0]


@pytest.mark.parametrize("case", list(CASES))
def test_bones_parents_and_rest_positions_read_back_as_the_truth(case):
    spec = CASES[case]
    names, parents, world = read_back(spec)
    t = truth(spec)
    assert names == t.bone_names
    np.testing.assert_array_equal(parents, t.parents)
    np.testing.assert_allclose(world, t.rest_world, atol=1e-6)
    assert set(t.joint_map.values()) <= set(names)
    assert np.all(t.parents < np.arange(len(names))), "parents precede children in file order"


def test_bvh_parses_with_bvhio_to_the_same_positions(tmp_path):
    spec = CASES["bvh_zeggs_a"]
    path = write_rig(tmp_path, spec)
    t = truth(spec)
    data = parse_bvh(path)
    assert data.n_frames == 2 and not data.values.any()
    assert data.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    assert sorted({len(c) for c in data.channels[1:]}) == [0, 3]  # End Sites, joints
    root = bvhio.readAsHierarchy(str(path))
    found = {j.Name: np.array(list(j.PositionWorld)) / 100.0 for j, _, _ in root.layout()}
    for name, pos in zip(t.bone_names, t.rest_world):
        np.testing.assert_allclose(found[name], pos, atol=1e-5)


def test_rolled_rig_has_the_unrolled_world_positions():
    rolled = CASES["mixamo_a_rolled"]
    plain = dataclasses.replace(rolled, roll_seed=None, armature=False)
    np.testing.assert_allclose(read_back(rolled)[2], read_back(plain)[2], atol=1e-6)
    doc, _, joints, world = gltf_bones(rig_files(rolled)["mixamo.glb"])
    turns = [abs(doc["nodes"][j]["rotation"][3]) for j in joints]
    assert max(turns) < 0.999, "every bone carries a rest roll"
    # the bones' frames really are turned: their world rotations differ from the armature's
    armature_rot = world[0, :3, :3] / 0.01
    bone_rot = world[joints, :3, :3] / 0.01
    assert np.all(np.abs(bone_rot - armature_rot).max(axis=(1, 2)) > 1e-3)


@pytest.mark.parametrize("case", ["mixamo_a_rolled", "vrm0_a", "bvh_zeggs_a", "mixamo_t"])
def test_upper_arm_points_40_degrees_down_in_a_pose_and_level_in_t_pose(case):
    spec = CASES[case]
    t = truth(spec)
    names, _, world = read_back(spec)
    at = {n: world[names.index(b)] for n, b in t.joint_map.items()}
    want = 40.0 if spec.rest == "A" else 0.0
    for side in ("left", "right"):
        for a, b in (("shoulder", "elbow"), ("elbow", "wrist")):
            d = at[f"{side}_{b}"] - at[f"{side}_{a}"]
            below = np.degrees(np.arctan2(-d[1], np.hypot(d[0], d[2])))
            assert below == pytest.approx(want, abs=1e-6)
        length = np.linalg.norm(at[f"{side}_elbow"] - at[f"{side}_shoulder"]) + np.linalg.norm(
            at[f"{side}_wrist"] - at[f"{side}_elbow"]
        )
        assert length == pytest.approx(t.arm_length[0 if side == "left" else 1], abs=1e-6)


@pytest.mark.parametrize("case", GLTF_CASES)
def test_skin_weights_sum_to_one_and_inverse_binds_invert_the_rest(case):
    doc, binary, joints, world = gltf_bones(rig_files(CASES[case]).popitem()[1])
    ibm = accessor_array(doc, binary, doc["skins"][0]["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    eye = np.broadcast_to(np.eye(4), ibm.shape)
    np.testing.assert_allclose(world[joints] @ ibm, eye, atol=1e-5)
    node = next(n for n in doc["nodes"] if "mesh" in n)
    assert node["skin"] == 0 and not {"translation", "rotation", "scale", "matrix"} & set(node)
    for prim in doc["meshes"][node["mesh"]]["primitives"]:
        a = prim["attributes"]
        weights = accessor_array(doc, binary, a["WEIGHTS_0"])
        np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-6)
        assert accessor_array(doc, binary, a["JOINTS_0"]).max() < len(joints)
        normals = accessor_array(doc, binary, a["NORMAL"])
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
        pos = accessor_array(doc, binary, a["POSITION"])
        acc = doc["accessors"][a["POSITION"]]
        np.testing.assert_allclose([acc["min"], acc["max"]], [pos.min(0), pos.max(0)])
        # the body lies around the skeleton: from the floor to the head top
        assert pos[:, 1].min() > -0.05 and pos[:, 1].max() < CASES[case].height + 0.1


def vrm_humanoid(doc: dict) -> dict[str, str]:
    """VRM humanoid bone -> node name, from either version of the extension."""
    ext = doc["extensions"]
    if "VRM" in ext:
        assert ext["VRM"]["specVersion"] == "0.0" and "VRM" in doc["extensionsUsed"]
        pairs = [(b["bone"], b["node"]) for b in ext["VRM"]["humanoid"]["humanBones"]]
    else:
        vrm = ext["VRMC_vrm"]
        assert vrm["specVersion"] == "1.0" and "VRMC_vrm" in doc["extensionsUsed"]
        assert {"name", "licenseUrl", "authors"} <= set(vrm["meta"])
        pairs = [(b, v["node"]) for b, v in vrm["humanoid"]["humanBones"].items()]
    return {b: doc["nodes"][n]["name"] for b, n in pairs}


def expected_vrm(ours: str, version: int) -> str | None:
    """The VRM humanoid bone of one of our joints (None: not a humanoid bone), written out by hand."""
    plain = {"pelvis": "hips", "spine_mid": "spine", "chest": "chest", "neck": "neck", "head": "head"}
    plain["upper_chest"] = "upperChest"
    if ours in plain:
        return plain[ours]
    side, _, part = ours.partition("_")
    limb = {"collar": "Shoulder", "shoulder": "UpperArm", "elbow": "LowerArm", "wrist": "Hand"}
    if part in limb:
        return side + limb[part]
    m = re.fullmatch(r"(thumb|index|middle|ring|pinky)([1-4])", part)
    if m is None or m[2] == "4":
        return None
    finger = "Little" if m[1] == "pinky" else m[1].capitalize()
    if m[1] == "thumb" and version == 1:
        return side + finger + ("Metacarpal", "Proximal", "Distal")[int(m[2]) - 1]
    return side + finger + ("Proximal", "Intermediate", "Distal")[int(m[2]) - 1]


@pytest.mark.parametrize("case", ["vrm0_a", "vrm1_t"])
def test_vrm_humanoid_map_names_the_truths_bones_and_faces_the_right_way(case):
    spec = CASES[case]
    t = truth(spec)
    doc = read_glb(rig_files(spec).popitem()[1])[0]
    human = vrm_humanoid(doc)
    version = 0 if spec.naming == "vrm0" else 1
    for ours, bone in t.joint_map.items():
        want = expected_vrm(ours, version)
        if want is not None:
            assert human[want] == bone, ours
    assert {"leftUpperLeg", "rightToes", "leftThumbDistal", "rightLittleDistal"} <= set(human)
    assert ("upperChest" in human) == (spec.spine_bones >= 3)
    mixamo = set(truth(RigSpec(prefix="", twist_bones=True, spine_bones=4)).bone_names)
    assert not mixamo & set(t.bone_names) and not any("mixamo" in n for n in t.bone_names), "matched by name"
    names, _, world = read_back(spec)
    at = {n: world[names.index(b)] for n, b in human.items()}
    sign = -1.0 if version == 0 else 1.0  # VRM 0.x faces -Z: its left is -X
    np.testing.assert_array_equal(t.facing, [0, 0, sign])
    assert sign * at["leftUpperArm"][0] > 0.1 and sign * at["rightUpperArm"][0] < -0.1
    assert sign * (at["leftToes"][2] - at["leftFoot"][2]) > 0.05
    assert at["head"][1] > at["hips"][1] > at["leftFoot"][1]


def test_zeggs_names_are_the_presets():
    t = truth(CASES["bvh_zeggs_a"])
    preset = PRESETS["zeggs"]
    assert t.joint_map == {"pelvis": preset.pelvis, **preset.joints}
    assert set(t.joint_map) == {"pelvis", *JOINT_NAMES}


def test_mixamo_names_and_the_unmapped_legs():
    t = truth(CASES["mixamo_t"])
    assert set(t.joint_map) == {"pelvis", *JOINT_NAMES} - {"neck_upper"}
    assert t.joint_map["left_shoulder"] == "mixamorig:LeftArm"
    assert t.joint_map["right_collar"] == "mixamorig:RightShoulder"
    assert t.joint_map["upper_chest"] == "mixamorig:Spine2" and t.joint_map["head_top"] == "mixamorig:HeadTop_End"
    assert t.joint_map["left_pinky4"] == "mixamorig:LeftHandPinky4"
    assert {"mixamorig:LeftUpLeg", "mixamorig:RightToeBase"} <= set(t.bone_names)
    bare = truth(dataclasses.replace(CASES["mixamo_t"], prefix=""))
    assert bare.bone_names == tuple(n.removeprefix("mixamorig:") for n in t.bone_names)
    two = truth(dataclasses.replace(CASES["mixamo_t"], spine_bones=2))
    assert two.joint_map["chest"] == "mixamorig:Spine1" and "upper_chest" not in two.joint_map
    body = {"pelvis", *JOINT_NAMES[:13], "left_wrist", "right_wrist"} - {"neck_upper"}
    assert truth(CASES["no_fingers"]).joint_map.keys() == body


def test_a_dropped_bone_leaves_its_child_on_the_grandparent_in_place():
    t, full = truth(CASES["missing_elbow"]), truth(CASES["mixamo_t"])
    assert "left_elbow" not in t.joint_map and "mixamorig:LeftForeArm" not in t.bone_names
    hand = t.bone_names.index("mixamorig:LeftHand")
    assert t.bone_names[t.parents[hand]] == "mixamorig:LeftArm"
    for i, name in enumerate(t.bone_names):
        np.testing.assert_allclose(t.rest_world[i], full.rest_world[full.bone_names.index(name)])
    with pytest.raises(ValueError, match="neck_upper"):
        truth(dataclasses.replace(CASES["mixamo_t"], drop=("neck_upper",)))


def test_twist_bones_are_unmapped_intermediates():
    t, plain = truth(CASES["twist"]), truth(CASES["mixamo_t"])
    assert len(t.bone_names) == len(plain.bone_names) + 3 and t.joint_map == plain.joint_map
    for side in ("Left", "Right"):
        twist = t.bone_names.index(f"mixamorig:{side}ForeArmTwist")
        hand = t.bone_names.index(f"mixamorig:{side}Hand")
        assert t.bone_names[t.parents[twist]] == f"mixamorig:{side}ForeArm" and t.parents[hand] == twist
    extra = t.bone_names.index("mixamorig:Spine_extra")
    assert extra not in [t.bone_names.index(b) for b in t.joint_map.values()]
    chest = t.bone_names.index(t.joint_map["upper_chest"])
    assert t.parents[chest] == extra
    for ours, bone in t.joint_map.items():
        np.testing.assert_allclose(
            t.rest_world[t.bone_names.index(bone)], plain.rest_world[plain.bone_names.index(bone)], err_msg=ours
        )


def test_custom_names_come_with_their_json_map():
    spec = CASES["custom_names"]
    t = truth(spec)
    assert all(re.fullmatch(r"bone_\d\d", n) for n in t.bone_names)
    m = json.loads(json.dumps(custom_map(spec)))
    assert m["pelvis"] == t.bone_names[0] and set(m["joints"]) == set(JOINT_NAMES) - {"neck_upper"}
    assert {"pelvis": m["pelvis"], **m["joints"]} == t.joint_map


def test_proportions_are_human():
    for case in ("mixamo_t", "vrm1_t", "mixamo_a_rolled", "bvh_zeggs_a"):
        spec = CASES[case]
        t = truth(spec)
        at = {n: t.rest_world[t.bone_names.index(b)] for n, b in t.joint_map.items()}
        assert at["head_top"][1] == pytest.approx(spec.height)
        assert at["head"][1] > at["neck"][1] > at["chest"][1] > at["pelvis"][1] > 0.5 * spec.height
        if spec.rest == "T" and spec.height == 1.75:
            assert 0.72 <= abs(at["left_wrist"][0]) and abs(at["left_middle1"][0]) <= 0.85
    assert truth(CASES["mixamo_a_rolled"]).arm_length[0] == pytest.approx((0.30 + 0.26) * 1.08)
    wide = truth(CASES["vrm0_a"])
    shoulders = [wide.rest_world[wide.bone_names.index(wide.joint_map[f"{s}_shoulder"])] for s in ("left", "right")]
    assert np.linalg.norm(shoulders[0] - shoulders[1]) == pytest.approx(0.36 * 1.15)


def test_armature_holds_centimetre_bones_and_keeps_the_world_y_up():
    doc, _, joints, world = gltf_bones(rig_files(CASES["mixamo_a_rolled"])["mixamo.glb"])
    armature = doc["nodes"][0]
    assert armature["name"] == "Armature" and armature["children"] == [joints[0]]
    assert armature["scale"] == [0.01] * 3 and armature["rotation"] == pytest.approx([0.5**0.5, 0, 0, 0.5**0.5])
    hips = np.array(doc["nodes"][joints[0]]["translation"])
    assert np.linalg.norm(hips) == pytest.approx(98.0)  # centimetres inside the armature
    np.testing.assert_allclose(world[joints[0], :3, 3], [0, 0.98, 0], atol=1e-9)
    assert doc["scenes"][0]["nodes"][0] == 0


def decode_png(png: bytes) -> np.ndarray:
    """An 8-bit RGB PNG without filters, checking its signature and every chunk's CRC."""
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    at, chunks = 8, {}
    while at < len(png):
        (length,) = struct.unpack_from(">I", png, at)
        kind, data = png[at + 4 : at + 8], png[at + 8 : at + 8 + length]
        assert struct.unpack_from(">I", png, at + 8 + length)[0] == zlib.crc32(kind + data)
        chunks[kind] = chunks.get(kind, b"") + data
        at += 12 + length
    width, height, depth, colour = struct.unpack_from(">IIBB", chunks[b"IHDR"])
    assert (depth, colour) == (8, 2) and b"IEND" in chunks
    rows = np.frombuffer(zlib.decompress(chunks[b"IDAT"]), np.uint8).reshape(height, 1 + 3 * width)
    assert not rows[:, 0].any()
    return rows[:, 1:].reshape(height, width, 3)


def test_texture_is_a_png_on_the_material():
    doc, binary = read_glb(rig_files(CASES["vrm1_t"])["vrm1.vrm"])
    view = doc["bufferViews"][doc["images"][0]["bufferView"]]
    png = binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
    image = decode_png(png)
    assert image.shape == (8, 8, 3) and image.std() > 0
    assert any("baseColorTexture" in m["pbrMetallicRoughness"] for m in doc["materials"])
    assert all("TEXCOORD_0" in p["attributes"] for p in doc["meshes"][0]["primitives"])
    plain = read_glb(rig_files(CASES["mixamo_t"])["mixamo.glb"])[0]
    assert "images" not in plain and len(plain["materials"]) == 2


def test_same_spec_gives_the_same_bytes():
    for spec in CASES.values():
        assert rig_files(spec) == rig_files(dataclasses.replace(spec))
    assert rig_files(CASES["twist"]) != rig_files(dataclasses.replace(CASES["twist"], roll_seed=4))


def test_bad_specs_are_refused():
    with pytest.raises(ValueError, match="naming"):
        RigSpec(naming="fbx")
    with pytest.raises(ValueError, match="VRM"):
        RigSpec(naming="vrm0", fmt="bvh")
    with pytest.raises(ValueError, match="spine_bones"):
        RigSpec(spine_bones=5)


@settings(max_examples=15, deadline=None)
@given(
    naming=st.sampled_from(["mixamo", "vrm0", "vrm1", "zeggs", "custom"]),
    rest=st.sampled_from(["T", "A"]),
    roll=st.one_of(st.none(), st.integers(0, 1000)),
    armature=st.booleans(),
    spine=st.integers(2, 4),
    fingers=st.booleans(),
    twist=st.booleans(),
    drop=st.sampled_from([(), ("left_elbow",), ("right_collar", "chest")]),
    bvh=st.booleans(),
)
def test_any_spec_reads_back_as_its_truth(naming, rest, roll, armature, spine, fingers, twist, drop, bvh):
    fmt = "bvh" if bvh and naming not in ("vrm0", "vrm1") else "glb"
    spec = RigSpec(
        naming=naming,
        rest=rest,
        roll_seed=roll,
        armature=armature,
        spine_bones=spine,
        fingers=fingers,
        twist_bones=twist,
        drop=drop,
        fmt=fmt,
        mesh=False,
    )
    names, parents, world = read_back(spec)
    t = truth(spec)
    assert names == t.bone_names
    np.testing.assert_array_equal(parents, t.parents)
    np.testing.assert_allclose(world, t.rest_world, atol=1e-6)
    assert not set(drop) & set(t.joint_map)
    if fmt == "glb":
        doc, binary, joints, matrices = gltf_bones(rig_files(spec).popitem()[1])
        ibm = accessor_array(doc, binary, doc["skins"][0]["inverseBindMatrices"]).reshape(-1, 4, 4)
        np.testing.assert_allclose(
            matrices[joints] @ ibm.transpose(0, 2, 1), np.broadcast_to(np.eye(4), ibm.shape), atol=1e-5
        )
