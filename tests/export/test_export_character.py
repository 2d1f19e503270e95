"""A user's character written with our motion: their GLB/VRM with a 'gesturekit' animation, a BVH of their
skeleton, the synthesize --character command, and the reading paths a hostile character file takes.

Every file is read back by another path than the writer's (the GLB: scipy quaternions and our own forward
kinematics of the nodes; the BVH: the bvhio package) and compared with the retargeted positions.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import warnings
from pathlib import Path

import bvhio
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from gesturekit.character.glb import GlbBuffer, accessor_array, glb_bytes, read_glb
from gesturekit.character.retarget import Retargeted, retarget
from gesturekit.character.user import read_character
from gesturekit.datasets.bvh_file import parse_bvh
from gesturekit.errors import ConfigError, GestureKitWarning, InputFileError, OutputError
from gesturekit.export._character_bvh import bvh_joint_names, rotation_of
from gesturekit.export.character import ANIMATION, export_character_bvh, export_character_glb
from gesturekit.motion import Motion
from tests.character_rigs import CASES, RigSpec, custom_map, rig_files, write_rig
from tests.export.test_export_gltf import validator  # noqa: F401

MM = 1e-3
READABLE = [k for k in CASES if k != "missing_elbow"]
GLTF_CASES = [k for k in READABLE if CASES[k].fmt == "glb"]


@pytest.fixture(scope="module")
def motion() -> Motion:
    """40 frames of the demo database (15 fps)."""
    from gesturekit.demo import open_default_database

    db = open_default_database()
    return Motion(db.poses[:1].reshape(-1, 55, 3)[:40].astype(np.float32), 15.0, db.joint_presence)


@pytest.fixture(scope="module")
def rigs(tmp_path_factory, motion) -> dict[str, Retargeted]:
    """Each readable case written, read and retargeted."""
    folder = tmp_path_factory.mktemp("rigs")
    out = {}
    for case in READABLE:
        spec = CASES[case]
        path = write_rig(folder, spec, case)
        out[case] = retarget(
            motion, read_character(path, bone_map=custom_map(spec) if spec.naming == "custom" else None)
        )
    return out


def speech(frames: int) -> np.ndarray:
    t = np.arange(int(frames / 15.0 * 16000)) / 16000.0
    return 0.3 * np.sin(2 * np.pi * 220 * t)


def glb_positions(path: Path, r: Retargeted) -> np.ndarray:
    """Each bone's position (frames, M, 3) in our frame, read from the file with scipy's quaternions and
    forward kinematics written here (not the exporter's node_matrices)."""
    doc, binary = read_glb(path.read_bytes())
    (animation,) = [a for a in doc["animations"] if a["name"] == ANIMATION]
    tracks = {}
    for ch in animation["channels"]:
        s = animation["samplers"][ch["sampler"]]
        tracks[(ch["target"]["node"], ch["target"]["path"])] = accessor_array(doc, binary, s["output"])
        assert np.allclose(accessor_array(doc, binary, s["input"]), np.arange(r.n_frames) / r.fps, atol=1e-6)
        assert s["interpolation"] == "LINEAR"
    nodes = doc["nodes"]
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", ())}
    n = r.n_frames

    def local(i: int) -> np.ndarray:
        node = nodes[i]
        m = np.tile(np.eye(4), (n, 1, 1))
        if "matrix" in node:
            m[:] = np.reshape(node["matrix"], (4, 4)).T
            return m
        q = tracks.get((i, "rotation"), np.tile(node.get("rotation", [0, 0, 0, 1]), (n, 1)))
        m[:, :3, :3] = Rotation.from_quat(q).as_matrix() * np.asarray(node.get("scale", [1, 1, 1]))
        m[:, :3, 3] = tracks.get((i, "translation"), np.tile(node.get("translation", [0, 0, 0]), (n, 1)))
        return m

    def world(i: int) -> np.ndarray:
        return local(i) if i not in parent else world(parent[i]) @ local(i)

    assert r.character.gltf is not None
    pos = np.stack([world(int(i))[:, :3, 3] for i in r.character.gltf.nodes], axis=1)
    back = np.linalg.inv(r.character.to_file)
    return pos @ back[:3, :3].T + back[:3, 3]


def bvhio_positions(path: Path, r: Retargeted, units: float) -> tuple[list[str], np.ndarray]:
    """Joint names and positions (frames, J, 3) in our frame, metres, read with the bvhio package."""
    root = bvhio.readAsHierarchy(str(path))
    layout = [j for j, _, _ in root.layout()]
    out = np.zeros((r.n_frames, len(layout), 3))
    for t in range(r.n_frames):
        root.loadPose(t)
        for k, j in enumerate(layout):
            out[t, k] = tuple(j.PositionWorld)
    r_f = rotation_of(r.character.to_file[:3, :3])
    return [j.Name for j in layout], out / units @ r_f


# ----------------------------------------------------------------------------- GLB


@pytest.mark.slow
@pytest.mark.parametrize("case", GLTF_CASES)
def test_glb_of_each_rig_is_valid_and_read_back_to_its_report(case, rigs, tmp_path, validator):  # noqa: F811
    r = rigs[case]
    path = tmp_path / f"{case}{r.character.path.suffix}"
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)
        report = export_character_glb(path, r, audio=speech(r.n_frames))
    issues = validator(path)["issues"]
    err = np.linalg.norm(glb_positions(path, r) - r.position, axis=-1)
    print(
        f"{case}: validator {issues['numErrors']} errors, {issues['numWarnings']} warnings; read back max "
        f"{err.max() * 1e6:.3f} um, mean {err.mean() * 1e6:.3f} um; {len(report.animated)}/{len(report.bones)} "
        f"bones animated, {report.size} bytes"
    )
    assert issues["numErrors"] == 0, [m for m in issues["messages"] if m["severity"] == 0]
    assert err.max() < MM
    assert report.max_error == pytest.approx(err.max(), abs=1e-7)
    assert report.mean_error == pytest.approx(err.mean(), abs=1e-7)
    assert report.frames == r.n_frames and report.audio == path.with_suffix(".wav") and report.audio.is_file()
    assert report.summary().startswith(f"{path.name}: position error max ")
    # each bone's quaternions keep one sign from key to key: linear interpolation takes the short way
    doc, binary = read_glb(path.read_bytes())
    for sampler in doc["animations"][-1]["samplers"]:
        q = accessor_array(doc, binary, sampler["output"])
        if q.shape[1] == 4:
            assert (np.sum(q[1:] * q[:-1], axis=1) >= 0).all()


@pytest.mark.parametrize("case", GLTF_CASES)
def test_glb_keeps_their_document_and_binary(case, rigs, tmp_path):
    r = rigs[case]
    source = r.character.gltf
    assert source is not None
    path = tmp_path / f"out{r.character.path.suffix}"
    export_character_glb(path, r)
    doc, binary = read_glb(path.read_bytes())
    theirs = source.document
    for key in set(theirs) - {"nodes", "accessors", "bufferViews", "buffers", "animations", "asset", "scenes"}:
        assert doc[key] == theirs[key], key  # meshes, materials, textures, images, skins, extensions ...
    assert doc["accessors"][: len(theirs["accessors"])] == theirs["accessors"]
    assert doc["bufferViews"][: len(theirs["bufferViews"])] == theirs["bufferViews"]
    assert binary[: len(source.binary)] == source.binary
    assert doc["asset"]["generator"].startswith("gesturekit ")
    animated = {c["target"]["node"] for a in doc["animations"] if a["name"] == ANIMATION for c in a["channels"]}
    for i, (mine, old) in enumerate(zip(doc["nodes"], theirs["nodes"], strict=True)):
        if i not in animated:
            assert mine == old
        else:
            assert {k: v for k, v in mine.items() if k != "rotation"} == {
                k: v for k, v in old.items() if k != "rotation"
            }
    if r.character.kind.startswith("vrm"):
        ext = "VRM" if r.character.kind == "vrm0" else "VRMC_vrm"
        assert doc["extensions"][ext] == theirs["extensions"][ext] and ext in doc["extensionsUsed"]
        assert read_character(path).kind == r.character.kind  # still a VRM, read as one


def test_the_same_motion_and_character_give_the_same_bytes(rigs, tmp_path):
    r = rigs["vrm0_a"]
    one, two = tmp_path / "one.vrm", tmp_path / "two.vrm"
    export_character_glb(one, r)
    export_character_glb(two, retarget(r.source, read_character(r.character.path)))
    assert one.read_bytes() == two.read_bytes()
    export_character_bvh(one.with_suffix(".bvh"), r)
    export_character_bvh(two.with_suffix(".bvh"), r)
    assert one.with_suffix(".bvh").read_bytes() == two.with_suffix(".bvh").read_bytes()


def test_a_gltf_with_its_buffer_and_texture_beside_it_is_written_as_one_glb(rigs, tmp_path, validator):  # noqa: F811
    ((_, data),) = rig_files(CASES["vrm1_t"]).items()
    doc, binary = read_glb(data)
    (image,) = doc["images"]
    view = doc["bufferViews"][image.pop("bufferView")]
    (tmp_path / "skin.png").write_bytes(binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]])
    image["uri"] = "skin.png"
    (tmp_path / "avatar.bin").write_bytes(binary)
    doc["buffers"] = [{"uri": "avatar.bin", "byteLength": len(binary)}]
    src = tmp_path / "avatar.gltf"
    src.write_text(json.dumps(doc))
    r = retarget(rigs["vrm1_t"].source, read_character(src))
    path = tmp_path / "out.vrm"
    report = export_character_glb(path, r)
    err = np.linalg.norm(glb_positions(path, r) - r.position, axis=-1)
    issues = validator(path)["issues"]
    print(f"from a .gltf: read back max {err.max() * 1e6:.3f} um, validator {issues['numErrors']} errors")
    assert err.max() < MM and report.max_error < MM and issues["numErrors"] == 0
    out, _ = read_glb(path.read_bytes())
    assert all("uri" not in b for b in out["buffers"]) and "bufferView" in out["images"][0]


def _with(data: bytes, change) -> bytes:
    doc, binary = read_glb(data)
    extra = change(doc, binary)
    return glb_bytes(doc, binary if extra is None else extra)


def _add_wave(doc, binary):
    """A clip of their own, ``wave``: one rotation of node 1 over a second."""
    buf = GlbBuffer()
    t = buf.add(np.array([0.0, 1.0]), "SCALAR", 5126, bounds=True)
    q = buf.add(np.array([[0, 0, 0, 1], [0, 0.3826834, 0, 0.9238795]]), "VEC4", 5126)
    base = len(binary)
    doc["bufferViews"] += [{**v, "byteOffset": v["byteOffset"] + base} for v in buf.views]
    n = len(doc["accessors"])
    doc["accessors"] += [{**a, "bufferView": a["bufferView"] + len(doc["bufferViews"]) - 2} for a in buf.accessors]
    sampler = {"input": n + t, "output": n + q, "interpolation": "LINEAR"}
    doc["animations"] = [
        {"name": "wave", "samplers": [sampler], "channels": [{"sampler": 0, "target": {"node": 1, "path": "rotation"}}]}
    ]
    data2 = binary + bytes(buf.data)
    doc["buffers"][0]["byteLength"] = len(data2)
    return data2


def waving_glb(folder: Path) -> Path:
    """A Mixamo-like character with a clip of its own, ``wave``."""
    ((_, data),) = rig_files(CASES["mixamo_t"]).items()
    src = folder / "waving.glb"
    src.write_bytes(_with(data, _add_wave))
    return src


def test_their_animations_stay_and_an_earlier_gesturekit_one_is_replaced(tmp_path, motion, validator):  # noqa: F811
    src = waving_glb(tmp_path)
    r = retarget(motion, read_character(src))
    first = tmp_path / "first.glb"
    report = export_character_glb(first, r)
    assert report.their_clips == ("wave",) and not report.dropped_clips and "after ours: wave" in report.summary()
    again = tmp_path / "again.glb"  # our own output as the character: one 'gesturekit' animation, not two
    export_character_glb(again, retarget(motion, read_character(first)))
    for path in (first, again):
        doc, binary = read_glb(path.read_bytes())
        names = [a["name"] for a in doc["animations"]]
        assert names == [ANIMATION, "wave"]  # ours first: the clip a viewer that plays one plays
        wave = doc["animations"][1]
        assert accessor_array(doc, binary, wave["samplers"][0]["output"])[1] == pytest.approx(
            [0, 0.3826834, 0, 0.9238795]
        )
        assert validator(path)["issues"]["numErrors"] == 0


def test_their_clips_can_be_left_out_and_ours_is_then_the_only_one(tmp_path, motion, validator):  # noqa: F811
    r = retarget(motion, read_character(waving_glb(tmp_path)))
    kept, dropped = tmp_path / "kept.glb", tmp_path / "dropped.glb"
    export_character_glb(kept, r, their_clips="keep")
    report = export_character_glb(dropped, r, their_clips="drop")
    assert report.dropped_clips == ("wave",) and not report.their_clips and "left out: wave" in report.summary()
    docs = {p.name: read_glb(p.read_bytes()) for p in (kept, dropped)}
    assert [a["name"] for a in docs["kept.glb"][0]["animations"]] == [ANIMATION, "wave"]
    assert [a["name"] for a in docs["dropped.glb"][0]["animations"]] == [ANIMATION]
    # the same motion either way, read back to the report's error
    assert docs["kept.glb"][0]["animations"][0] == docs["dropped.glb"][0]["animations"][0]
    assert report.max_error < 1e-4
    assert validator(dropped)["issues"]["numErrors"] == 0
    with pytest.raises(ConfigError, match="their_clips is one of keep, drop"):
        export_character_glb(tmp_path / "x.glb", r, their_clips="first")


def test_animated_matrix_nodes_become_trs_and_non_uniform_scales_are_refused(tmp_path, motion, validator):  # noqa: F811
    ((_, data),) = rig_files(CASES["mixamo_a_rolled"]).items()

    def as_matrices(doc, binary):
        for node in doc["nodes"]:
            if "mesh" in node:
                continue
            m = np.eye(4)
            m[:3, :3] = Rotation.from_quat(node.pop("rotation", [0, 0, 0, 1])).as_matrix() * node.pop(
                "scale", [1, 1, 1]
            )
            m[:3, 3] = node.pop("translation", [0, 0, 0])
            node["matrix"] = [float(x) for x in m.T.reshape(-1)]
        return None

    src = tmp_path / "matrices.glb"
    src.write_bytes(_with(data, as_matrices))
    r = retarget(motion, read_character(src))
    path = tmp_path / "out.glb"
    report = export_character_glb(path, r)
    doc, _ = read_glb(path.read_bytes())
    animated = {c["target"]["node"] for c in doc["animations"][0]["channels"]}
    assert animated and not any("matrix" in doc["nodes"][i] for i in animated)
    assert any("matrix" in n for n in doc["nodes"])  # the still ones keep theirs
    err = np.linalg.norm(glb_positions(path, r) - r.position, axis=-1)
    print(f"matrix nodes: read back max {err.max() * 1e6:.3f} um; report {report.max_error * 1e6:.3f} um")
    assert err.max() < MM and validator(path)["issues"]["numErrors"] == 0

    def stretch(doc, binary):
        (forearm,) = [n for n in doc["nodes"] if n.get("name") == "mixamorig:LeftForeArm"]
        forearm["scale"] = [1.0, 1.3, 1.0]

    src2 = tmp_path / "stretched.glb"
    src2.write_bytes(_with(data, stretch))
    with pytest.raises(ConfigError, match=r"mixamorig:LeftForeArm.*scale \(1, 1\.3, 1\)"):
        export_character_glb(tmp_path / "x.glb", retarget(motion, read_character(src2)))
    assert not (tmp_path / "x.glb").exists()


def test_the_hips_get_a_translation_only_when_they_move(rigs, tmp_path):
    r = rigs["mixamo_a_rolled"]  # under an armature turned and scaled by 0.01
    still = tmp_path / "still.glb"
    export_character_glb(still, r)
    doc, _ = read_glb(still.read_bytes())
    assert all(c["target"]["path"] == "rotation" for c in doc["animations"][-1]["channels"])
    t = np.arange(r.n_frames) / r.fps
    shift = np.stack([0.1 * np.sin(t), 0.02 * t, -0.05 * np.cos(2 * t)], axis=1)
    moved = dataclasses.replace(r, position=r.position + shift[:, None])
    path = tmp_path / "moved.glb"
    report = export_character_glb(path, moved)
    doc, _ = read_glb(path.read_bytes())
    hips = int(r.character.gltf.nodes[r.character.pelvis])
    assert [c["target"]["node"] for c in doc["animations"][-1]["channels"] if c["target"]["path"] == "translation"] == [
        hips
    ]
    err = np.linalg.norm(glb_positions(path, moved) - moved.position, axis=-1)
    print(f"moving hips: read back max {err.max() * 1e6:.3f} um")
    assert err.max() < MM and report.max_error < MM


@settings(
    max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    roll=st.integers(0, 10_000),
    rest=st.sampled_from(["T", "A"]),
    armature=st.booleans(),
    naming=st.sampled_from(["mixamo", "vrm0", "vrm1"]),
)
def test_any_roll_rest_pose_and_armature_reads_back_within_a_millimetre(motion, tmp_path, roll, rest, armature, naming):
    spec = RigSpec(naming=naming, rest=rest, roll_seed=roll, armature=armature, mesh=False, fingers=False)
    src = write_rig(tmp_path, spec, f"r{roll}")
    r = retarget(motion, read_character(src))
    path = tmp_path / f"out{roll}.glb"
    report = export_character_glb(path, r, overwrite=True)
    err = np.linalg.norm(glb_positions(path, r) - r.position, axis=-1)
    assert err.max() < MM and abs(report.max_error - err.max()) < 1e-7


def test_overwrite_rules_suffixes_and_a_skeleton_without_body(rigs, tmp_path):
    r = rigs["vrm1_t"]
    path = tmp_path / "take.vrm"
    export_character_glb(path, r, audio=speech(r.n_frames))
    with pytest.raises(OutputError, match="already exists"):
        export_character_glb(path, r)
    export_character_glb(path, r, audio=speech(r.n_frames), overwrite=True)  # ours: replaced
    theirs = tmp_path / "theirs.glb"  # the character as another tool wrote it
    theirs.write_bytes(_with(r.character.path.read_bytes(), lambda doc, _: doc["asset"].update(generator="Blender")))
    with pytest.raises(OutputError, match="did not write"):
        export_character_glb(theirs, r, overwrite=True)
    with pytest.raises(OutputError, match="input"):
        export_character_glb(r.character.path, r, overwrite=True)  # its generator is gesturekit's test rigs'
    with pytest.raises(ConfigError, match="named .glb or .vrm"):
        export_character_glb(tmp_path / "take.gltf", r)
    with pytest.raises(ConfigError, match="skeleton without a body"):
        export_character_glb(tmp_path / "b.glb", rigs["bvh_zeggs_a"])


# ----------------------------------------------------------------------------- BVH


@pytest.mark.parametrize("case", READABLE)
def test_bvh_of_each_rig_reads_back_with_bvhio_to_its_report(case, rigs, tmp_path):
    r = rigs[case]
    path = tmp_path / f"{case}.bvh"
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)
        report = export_character_bvh(path, r)
    names, pos = bvhio_positions(path, r, report.units)
    safe = bvh_joint_names(r.character.names)
    column = {n: k for k, n in enumerate(names)}
    bones = [b for b, n in enumerate(safe) if n in column]
    err = np.linalg.norm(pos[:, [column[safe[b]] for b in bones]] - r.position[:, bones], axis=-1)
    print(
        f"{case}: bvhio read back max {err.max() * 1e6:.2f} um, mean {err.mean() * 1e6:.2f} um over {len(bones)} "
        f"joints; report max {report.max_error * 1e6:.2f} um; {report.size} bytes"
    )
    assert err.max() < MM
    assert report.max_error == pytest.approx(err.max(), abs=2e-6)  # bvhio computes in 32-bit floats
    assert set(report.joints) <= set(names) and report.units == 100.0  # the zeggs BVH's own centimetres too


def test_a_bvh_characters_offsets_channel_orders_and_end_sites_are_its_own(rigs, tmp_path):
    r = rigs["bvh_zeggs_a"]
    source = parse_bvh(r.character.path)
    text = source.path and Path(source.path).read_text()
    # a file of other rotation orders than ZXY: the written one keeps each joint's own
    reordered = tmp_path / "orders.bvh"
    reordered.write_text(text.replace("3 Zrotation Xrotation Yrotation", "3 Yrotation Xrotation Zrotation"))
    for src in (r.character.path, reordered):
        mine = retarget(r.source, read_character(src))
        out = tmp_path / f"out_{src.name}"
        assert export_character_bvh(out, mine).max_error < MM
        theirs, written = parse_bvh(src), parse_bvh(out)
        assert written.names == theirs.names  # End Sites where they were, as NAME_End
        np.testing.assert_allclose(written.offsets[1:], theirs.offsets[1:], atol=1e-6)
        rot = [tuple(c for c in ch if c.endswith("rotation")) for ch in theirs.channels]
        assert [tuple(c for c in ch if c.endswith("rotation")) for ch in written.channels] == rot
        assert (
            ("Yrotation", "Xrotation", "Zrotation") in rot
            if src == reordered
            else ("Zrotation", "Xrotation", "Yrotation") in rot
        )
    metres = tmp_path / "metres.bvh"
    export_character_bvh(metres, r, units="m")
    np.testing.assert_allclose(parse_bvh(metres).offsets[1:], source.offsets[1:] / 100.0, atol=1e-6)
    with pytest.raises(ConfigError, match="units"):
        export_character_bvh(tmp_path / "x.bvh", r, units="inch")


def test_bvh_names_are_sanitised_and_unique(rigs, tmp_path):
    assert bvh_joint_names(("Left Arm", "a\tb  c", "", "x", "x")) == ("Left_Arm", "a_b_c", "bone2", "x", "x_2")
    r = rigs["mixamo_t"]
    spaced = dataclasses.replace(r.character, names=tuple(n.replace(":", " ") for n in r.character.names))
    out = tmp_path / "spaced.bvh"
    report = export_character_bvh(out, dataclasses.replace(r, character=spaced))
    names = parse_bvh(out).names
    assert "mixamorig_Hips" in names and not any(" " in n for n in names) and report.max_error < MM


def test_bvh_replaces_only_ours_or_one_of_this_skeleton_never_the_character(rigs, tmp_path):
    r = rigs["bvh_zeggs_a"]
    path = tmp_path / "take.bvh"
    export_character_bvh(path, r)
    with pytest.raises(OutputError, match="already exists"):
        export_character_bvh(path, r)
    export_character_bvh(path, r, overwrite=True)
    other = tmp_path / "other.bvh"
    export_character_bvh(other, rigs["mixamo_t"])
    with pytest.raises(OutputError, match="did not write"):
        export_character_bvh(other, r, overwrite=True)  # another skeleton's file
    with pytest.raises(OutputError, match="input"):
        export_character_bvh(r.character.path, r, overwrite=True)


# ----------------------------------------------------------------------------- the command line


@pytest.fixture(scope="module")
def cli_world(tmp_path_factory):
    from tests.export.test_export_bvh_report import _cli_world

    return _cli_world(tmp_path_factory.mktemp("world"), demo=True)


def test_synthesize_with_a_character_writes_their_files_and_prints_the_reports(tmp_path, cli_world, validator):  # noqa: F811
    from tests.badinput import run_cli

    db, speech_path = cli_world
    vrm = write_rig(tmp_path, CASES["vrm0_a"], "avatar")
    out = tmp_path / "out"
    args = ["synthesize", speech_path, "--db", db, "--out", out, "--refiner", "none", "--character", vrm]
    run = run_cli(*args, "--format", "npz,glb,bvh", "--control", "0-2:left_hand=high")
    print(run.stdout)
    assert run.code == 0, run.stderr
    assert sorted(p.name for p in out.iterdir()) == ["speech.bvh", "speech.glb", "speech.npz", "speech.wav"]
    lines = [line.strip() for line in run.stdout.splitlines()]
    assert any(line.startswith("on avatar.vrm (VRM 0.x humanoid): ") for line in lines)
    (glb,) = [line for line in lines if line.startswith("glTF speech.glb: position error max ")]
    (bvh,) = [line for line in lines if line.startswith("BVH speech.bvh: position error max ")]
    assert "0.00 mm" in glb and "0.00 mm" in bvh
    assert any(line.startswith("control met on ") and "avatar.vrm's" in line for line in lines)
    doc, _ = read_glb((out / "speech.glb").read_bytes())
    assert "VRM" in doc["extensions"] and doc["animations"][0]["name"] == ANIMATION
    assert validator(out / "speech.glb")["issues"]["numErrors"] == 0
    assert (
        parse_bvh(out / "speech.bvh").names == parse_bvh(out / "speech.bvh").names
        and "J_Bip_C_Hips" in parse_bvh(out / "speech.bvh").names
    )
    again = run_cli(*args, "--format", "glb,bvh")
    assert again.code == 2 and "exists already" in again.stderr
    assert run_cli(*args, "--format", "glb,bvh", "--force").code == 0


@pytest.mark.parametrize("clips,names", [(None, [ANIMATION, "wave"]), ("drop", [ANIMATION])])
def test_synthesize_keeps_or_drops_the_characters_own_clips(tmp_path, cli_world, clips, names):
    from tests.badinput import run_cli

    db, speech_path = cli_world
    out = tmp_path / "out"
    args = ["synthesize", speech_path, "--db", db, "--out", out, "--refiner", "none", "--format", "glb"]
    args += ["--character", waving_glb(tmp_path)] + ([] if clips is None else ["--character-clips", clips])
    run = run_cli(*args)
    assert run.code == 0, run.stderr
    doc, _ = read_glb((out / "speech.glb").read_bytes())
    assert [a["name"] for a in doc["animations"]] == names
    assert ("its own clips left out: wave" in run.stdout) == (clips == "drop")
    bad = run_cli(*args, "--character-clips", "first")
    assert bad.code == 2 and "--character-clips" in bad.stderr


def test_synthesize_refuses_a_character_missing_a_bone_or_a_glb_of_a_skeleton(tmp_path, cli_world):
    from tests.badinput import run_cli

    db, speech_path = cli_world
    base = ["synthesize", speech_path, "--db", db, "--out", tmp_path / "out", "--refiner", "none"]
    run = run_cli(*base, "--character", write_rig(tmp_path, CASES["missing_elbow"], "armless"))
    assert run.code == 2 and run.stderr.startswith("gesturekit: error: ") and "left_elbow" in run.stderr
    assert "armless.glb" in run.stderr and "Traceback" not in run.stderr
    run = run_cli(*base, "--format", "glb", "--character", write_rig(tmp_path, CASES["bvh_zeggs_a"], "skel"))
    assert run.code == 2 and "skel.bvh is a skeleton without a body" in run.stderr
    run = run_cli(*base, "--character-map", tmp_path / "map.json")
    assert run.code == 2 and "--character" in run.stderr
    run = run_cli(*base, "--wrist-slack", "0")
    assert run.code == 2 and "--wrist-slack" in run.stderr and "give the character too" in run.stderr
    assert not (tmp_path / "out").exists()


def test_synthesize_poses_the_arms_with_the_wrist_slack_asked_for(tmp_path, cli_world):
    from tests.badinput import run_cli

    db, speech_path = cli_world
    short = write_rig(tmp_path, RigSpec(arm=np.sqrt(0.8), forearm=1 / np.sqrt(0.8)), "short_upper")
    base = ["synthesize", speech_path, "--db", db, "--refiner", "none", "--format", "bvh", "--character", short]
    wrists = {}
    for slack in ("0", "0.2"):
        run = run_cli(*base, "--out", tmp_path / slack, "--wrist-slack", slack)
        assert run.code == 0, run.stderr
        (line,) = [x for x in run.stdout.splitlines() if x.strip().startswith("on short_upper.glb")]
        wrists[slack] = float(line.split("wrists within ")[1].split(" %")[0])
    assert wrists["0"] == 0.0 and 0.0 < wrists["0.2"] <= 20.0  # exactly our reach, or nearer our directions
    bad = run_cli(*base, "--out", tmp_path / "bad", "--wrist-slack", "0.25")
    assert bad.code == 2 and bad.stderr.startswith("gesturekit: error: --wrist-slack is how far")
    assert not (tmp_path / "bad").exists()


# ----------------------------------------------------------------------------- hostile files


def _bad(tmp_path: Path, change, name: str = "bad.glb") -> Path:
    ((_, data),) = rig_files(CASES["vrm1_t"]).items()
    path = tmp_path / name
    path.write_bytes(_with(data, change))
    return path


def _past_view(doc, binary):
    acc = doc["accessors"][0]
    acc["byteOffset"] = doc["bufferViews"][acc["bufferView"]]["byteLength"]  # inside the binary, past its view


def _past_binary(doc, binary):
    doc["bufferViews"][0]["byteOffset"] = len(binary) + 8


def _image_past(doc, binary):
    doc["bufferViews"][doc["images"][0]["bufferView"]]["byteOffset"] = len(binary) + 8


def _image_garbage(doc, binary):
    view = doc["bufferViews"][doc["images"][0]["bufferView"]]
    b = bytearray(binary)
    b[view["byteOffset"] : view["byteOffset"] + view["byteLength"]] = bytes(view["byteLength"])
    return bytes(b)


@pytest.mark.parametrize(
    "change,message",
    [
        (_past_view, "accessor 0 .* runs past its buffer view"),
        (_past_binary, "buffer view 0 .* runs past the"),
        (_image_past, "image 0's buffer view runs past"),
        (_image_garbage, "image 0 is not a readable PNG or JPEG"),
    ],
)
def test_a_glb_pointing_past_its_data_is_an_input_error_naming_it(tmp_path, change, message):
    path = _bad(tmp_path, change)
    with pytest.raises(InputFileError, match=message) as e:
        read_character(path)
    assert Path(e.value.path) == path
    print(f"{change.__name__}: {e.value}")


@pytest.mark.parametrize("uri", ["../x.bin", "/etc/hostname", "sub/x.bin", "https://example.com/x.bin", ".."])
def test_a_gltf_naming_a_file_outside_its_folder_is_refused(tmp_path, uri):
    ((_, data),) = rig_files(CASES["vrm1_t"]).items()
    doc, binary = read_glb(data)
    (tmp_path / "x.bin").write_bytes(binary)
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "x.bin").write_bytes(binary)
    doc["buffers"] = [{"uri": uri, "byteLength": len(binary)}]
    path = tmp_path / "sub" / "c.gltf"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputFileError, match="must lie beside it") as e:
        read_character(path)
    assert Path(e.value.path) == path
    doc["buffers"][0]["uri"] = "x.bin"  # beside it: read, and written out as one GLB
    path.write_text(json.dumps(copy.deepcopy(doc)))
    assert read_character(path).kind == "vrm1"
