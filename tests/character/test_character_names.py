"""Bones found by name in the common naming families, and by the hand's shape where names say nothing (issue 38).

Rigs are generated with each family's names (Blender ``.L/.R``, Unreal ``_l/_r``, Character Creator
``CC_Base_L_``, UMA ``LeftHandFinger02_01``), finger tips whose names give no phalanx, twist bones, spines of two
to four bones; each must be matched exactly as its truth says, without a map. A rig whose finger bones have
meaningless names gets its fingers from the five chains under each hand. Nameless glTF nodes are ``node{index}``
in a map, and a rig that cannot be matched carries its bone tree with positions for the message.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.character.glb import glb_bytes, read_glb
from gesturekit.character.humanoid import FAMILIES, _side_and_base, match_families
from gesturekit.character.retarget import retarget
from gesturekit.character.user import read_character, read_character_upload
from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.skeleton import FINGERS
from tests.character_rigs import FAMILY_NAMINGS, RigSpec, custom_map, rig_files, truth, write_rig


@pytest.mark.parametrize(
    "name,side,base",
    [
        ("mixamorig:LeftForeArm", "left", "forearm"),
        ("upper_arm.L", "left", "upperarm"),
        ("DEF-forearm.R", "right", "forearm"),
        ("CC_Base_L_Index1", "left", "index1"),
        ("hand_r", "right", "hand"),
        ("f_index.01.L", "left", "findex01"),
        ("LeftHandFinger02_01", "left", "handfinger0201"),
        ("lowerarm_twist_01_l", "left", "lowerarmtwist01"),
        ("R_Hand", "right", "hand"),
        ("LHand", "left", "hand"),
        ("Ring1", None, "ring1"),
        ("Head", None, "head"),
    ],
)
def test_a_name_splits_into_its_side_and_base(name, side, base):
    assert _side_and_base(name) == (side, base)


def _matched_names(ch) -> dict[str, str]:
    return ch.matched()


@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    naming=st.sampled_from(FAMILY_NAMINGS),
    rest=st.sampled_from(["T", "A"]),
    spine=st.integers(2, 4),
    twist=st.booleans(),
    fmt=st.sampled_from(["glb", "bvh"]),
)
def test_every_family_is_matched_as_its_truth_without_a_map(tmp_path_factory, naming, rest, spine, twist, fmt):
    spec = RigSpec(naming=naming, rest=rest, spine_bones=spine, twist_bones=twist, fmt=fmt, mesh=fmt == "glb")
    path = write_rig(tmp_path_factory.mktemp("rig"), spec, "rig")
    ch = read_character(path)
    assert ch.matched_by == FAMILIES
    assert _matched_names(ch) == truth(spec).joint_map


def _rename_fingers(data: bytes) -> bytes:
    """The UMA rig with every finger bone renamed ``Bone.NNN``: no name says which finger it is."""
    doc, binary = read_glb(data)
    for i, node in enumerate(doc["nodes"]):
        if "HandFinger" in node.get("name", "") or node.get("name", "").endswith("Tip"):
            node["name"] = f"Bone.{i:03d}"
    return glb_bytes(doc, bytes(binary))


@pytest.mark.parametrize("rest", ["T", "A"])
def test_fingers_without_names_are_found_by_the_hands_shape(tmp_path, rest):
    spec = RigSpec(naming="uma", rest=rest, roll_seed=3)
    path = tmp_path / "hands.glb"
    path.write_bytes(_rename_fingers(rig_files(spec)["uma.glb"]))
    ch = read_character(path)
    assert "the fingers of the left and right hands by their shape" in ch.matched_by
    want = truth(spec).joint_map
    got = ch.matched()
    fingers = [k for k in want if any(f in k for f in FINGERS)]
    assert len(fingers) == 40
    # the same bones (by place in the file) as the truth's fingers
    order = {n: i for i, n in enumerate(truth(spec).bone_names)}
    assert [order[want[k]] for k in fingers] == [_index_in_file(path, got[k]) for k in fingers]


def _index_in_file(path, name: str) -> int:
    doc, _ = read_glb(path.read_bytes())
    return next(i for i, n in enumerate(doc["nodes"]) if n.get("name") == name)


def test_nameless_nodes_are_matched_by_a_map_of_node_indices_and_the_error_shows_the_tree(tmp_path):
    # one arm without its collar: the hierarchy's shape cannot pair the arms, so only a map can say
    spec = RigSpec(naming="nameless", rest="A", drop=("left_collar",))
    path = write_rig(tmp_path, spec, "khronos")
    assert all("name" not in n for n in read_glb(path.read_bytes())[0]["nodes"][:-1])
    with pytest.raises(ConfigError, match="no bone found for pelvis") as e:
        read_character(path)
    tree = e.value.bone_tree  # type: ignore[attr-defined]
    first = tree.splitlines()[:3]
    print("\n".join(first))
    assert first[0].startswith("node0 (0.00, 0.98, 0.00)") and first[1].startswith("  node1 (")
    bone_map = custom_map(spec)
    assert bone_map["pelvis"] == "node0" and bone_map["joints"]["head"].startswith("node")
    ch = read_character(path, bone_map=bone_map)
    assert ch.matched() == truth(spec).joint_map
    # the upload path keeps the tree for the app's message
    with pytest.raises(ConfigError) as e:
        read_character_upload("khronos.glb", path.read_bytes())
    assert e.value.bone_tree == tree  # type: ignore[attr-defined]
    assert "khronos.glb" in str(e.value) and str(tmp_path) not in str(e.value)
    (tmp_path / "map.json").write_text(json.dumps(bone_map))


@pytest.mark.parametrize("naming", FAMILY_NAMINGS)
def test_a_family_rig_follows_our_motion(tmp_path, naming):
    from gesturekit.demo import open_default_database

    db = open_default_database()
    motion = Motion(db.poses[:1].reshape(-1, 55, 3).astype(np.float32), 15.0, db.joint_presence)
    ch = read_character(write_rig(tmp_path, RigSpec(naming=naming, rest="A", roll_seed=2), naming))
    out = retarget(motion, ch)
    assert out.report.max_direction_error < 1.0 and len(out.report.segments) >= 41, out.report.summary()


def test_match_families_on_a_bare_list_needs_a_head():
    assert match_families(["root", "a", "b"], [-1, 0, 1]) == {}
