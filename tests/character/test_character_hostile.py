"""Character files as real exporters and hostile hands write them (issue 38): each is read as a character, or
refused with one error naming the file and the node, before any work it would bound and with nothing written.

Every input is generated here with the property of the real file: a skeleton laid out as the common CMU mocap
BVH conversion (zero-length neck and collars), a GLB whose image is a data URI, NaN, infinite and zero-length
rotations, a mirrored or absurdly scaled node, negative indices, two bones of one name, a 5 000 000-vertex body,
an 8192 x 8192 texture, a ``.bin`` that is a link out of its folder.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from gesturekit.character.glb import FLOAT, GlbBuffer, glb_bytes, read_glb
from gesturekit.character.retarget import _check_finite, retarget
from gesturekit.character.user import read_character
from gesturekit.errors import ConfigError, GestureKitError, InputFileError, MotionFileError
from gesturekit.motion import Motion
from tests.badinput import run_cli
from tests.character_rigs import CASES, cmu_bvh, rig_files


@pytest.fixture(scope="module")
def motion() -> Motion:
    """Two clips of the demo database (128 frames at 15 fps)."""
    from gesturekit.demo import open_default_database

    db = open_default_database()
    return Motion(db.poses[:2].reshape(-1, 55, 3).astype(np.float32), 15.0, db.joint_presence)


def _edited(tmp_path: Path, case: str, change, name: str = "bad.glb") -> Path:
    ((_, data),) = rig_files(CASES[case]).items()
    doc, binary = read_glb(data)
    extra = change(doc, bytes(binary))
    path = tmp_path / name
    path.write_bytes(glb_bytes(doc, bytes(binary) if extra is None else extra))
    return path


def _node(doc, name: str) -> dict:
    return next(n for n in doc["nodes"] if n.get("name") == name)


# ----------------------------------------------------------------------------- zero-length bones


def test_zero_length_bones_of_a_cmu_bvh_are_aimed_through_not_nan(tmp_path, motion):
    """The CMU conversion's Neck and collars start where the chest does: the chest is aimed at the next bone with
    length, every pose is finite, and each bone follows ours (the bones of no length are reported through)."""
    from gesturekit.datasets.bvh_file import parse_bvh
    from gesturekit.export.character import export_character_bvh

    path = tmp_path / "cmu.bvh"
    path.write_bytes(cmu_bvh())
    ch = read_character(path)
    p = ch.rest_position
    chest = ch.names.index("Spine1")
    assert np.linalg.norm(p[ch.bone("neck")] - p[chest]) == 0.0  # the property under test
    assert np.linalg.norm(p[ch.bone("left_collar")] - p[chest]) == 0.0
    out = retarget(motion, ch)
    assert np.isfinite(out.rotation).all() and np.isfinite(out.position).all()
    rep = out.report
    print(rep.summary())
    assert "Neck->Head" in rep.segments and "Spine1->Neck" not in rep.segments
    assert np.isfinite(rep.direction_error).all() and len(rep.segments) >= 10
    assert rep.max_direction_error < 1.0
    # the head and the upper arms point as ours do, from the chest through the bones of no length
    for a, b in [("neck", "head"), ("left_collar", "left_shoulder")]:
        theirs = out.position[:, ch.bone(b)] - out.position[:, ch.bone(a)]
        ours = motion.positions[:, _j(b)] - motion.positions[:, _j(a)]
        cos = np.einsum("ti,ti->t", theirs, ours) / np.linalg.norm(theirs, axis=1) / np.linalg.norm(ours, axis=1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 1.0
    written = export_character_bvh(tmp_path / "out.bvh", out)
    assert written.max_error < 1e-4
    assert np.isfinite(parse_bvh(tmp_path / "out.bvh").offsets).all()


def _j(name: str) -> int:
    from gesturekit.skeleton import joint_index

    return joint_index(name)


def test_a_pose_that_is_not_finite_is_refused_naming_the_bone(tmp_path, motion):
    path = tmp_path / "cmu.bvh"
    path.write_bytes(cmu_bvh())
    ch = read_character(path)
    rot = ch.rest_rotation.copy()
    rot[ch.bone("left_elbow")] = np.nan
    with pytest.raises(ConfigError, match="rest pose of bone 'LeftForeArm' is not finite") as e:
        retarget(motion, dataclasses.replace(ch, rest_rotation=rot))
    assert "cmu.bvh" in str(e.value)
    # and where the solve itself would give one (the check every retarget ends with)
    good = retarget(motion, ch)
    position = good.position.copy()
    position[7, ch.bone("head")] = np.inf
    with pytest.raises(ConfigError, match="pose of bone 'Head' is not finite \\(frame 7\\)"):
        _check_finite(ch, good.rotation, position)


# ----------------------------------------------------------------------------- images


def test_a_glb_image_given_as_a_data_uri_reads_as_its_buffer_view(tmp_path):
    ((_, data),) = rig_files(CASES["zeggs_glb"]).items()
    plain = tmp_path / "plain.glb"
    plain.write_bytes(data)

    def to_uri(doc, binary):
        img = doc["images"][0]
        view = doc["bufferViews"][img.pop("bufferView")]
        png = binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
        img["uri"] = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
        assert png[:4] == b"\x89PNG"

    uri = _edited(tmp_path, "zeggs_glb", to_uri, "uri.glb")
    assert "uri" in read_glb(uri.read_bytes())[0]["images"][0]
    a, b = read_character(plain), read_character(uri)
    assert a.skin is not None and b.skin is not None
    np.testing.assert_array_equal(a.skin.colors, b.skin.colors)
    assert len(np.unique(a.skin.colors.round(3), axis=0)) > 2  # the texture is sampled, not a flat colour


# ----------------------------------------------------------------------------- hostile glTF


def _rotation(value):
    def change(doc, binary):
        _node(doc, "mixamorig:LeftForeArm")["rotation"] = value

    return change


def _translation_inf(doc, binary):
    _node(doc, "mixamorig:LeftForeArm")["translation"] = [float("inf"), 0.0, 0.0]


def _ibm_nan(doc, binary):
    skin = doc["skins"][0]
    view = doc["bufferViews"][doc["accessors"][skin["inverseBindMatrices"]]["bufferView"]]
    b = bytearray(binary)
    k = skin["joints"].index(doc["nodes"].index(_node(doc, "mixamorig:LeftHand")))
    at = view["byteOffset"] + 64 * k
    b[at : at + 4] = np.float32(np.nan).tobytes()
    return bytes(b)


def _mirrored(doc, binary):
    _node(doc, "mixamorig:Hips")["scale"] = [-1.0, 1.0, 1.0]


def _huge(doc, binary):
    _node(doc, "mixamorig:Hips")["scale"] = [1e30, 1e30, 1e30]


def _negative_indices(doc, binary):
    doc["meshes"][0]["primitives"][0]["indices"] = -1


def _negative_child(doc, binary):
    _node(doc, "mixamorig:Head")["children"] = [-1]


def _duplicate(doc, binary):
    _node(doc, "mixamorig:LeftUpLeg")["name"] = "mixamorig:Spine"


HOSTILE_IDS = ["nan_rotation", "zero_quaternion", "inf_translation", "nan_ibm", "mirrored", "1e30", "neg_index"]
HOSTILE_IDS += ["neg_child", "duplicate"]
HOSTILE = [
    (_rotation([float("nan"), 0.0, 0.0, 1.0]), "rotation of node .*LeftForeArm.* not finite"),
    (_rotation([0.0, 0.0, 0.0, 0.0]), "rotation of node .*LeftForeArm.* zero length"),
    (_translation_inf, "translation of node .*LeftForeArm.* not finite"),
    (_ibm_nan, "inverse bind matrix of node .*LeftHand.* not finite"),
    (_mirrored, "node .*Hips.* is mirrored"),
    (_huge, "node .*Hips.* is scaled by 1e\\+30"),
    (_negative_indices, "mesh 0's indices is -1, not an index"),
    (_negative_child, "a child of node .*Head.* is -1"),
    (_duplicate, "two bones are named 'mixamorig:Spine'"),
]


@pytest.mark.parametrize("change,message", HOSTILE, ids=HOSTILE_IDS)
def test_a_hostile_glb_is_refused_naming_the_file_and_the_node(tmp_path, change, message):
    path = _edited(tmp_path, "mixamo_t", change)
    with pytest.raises(InputFileError, match=message) as e:
        read_character(path)
    assert Path(e.value.path) == path, str(e.value)
    print(e.value)


@pytest.fixture(scope="module")
def cli_world(tmp_path_factory):
    from tests.export.test_export_bvh_report import _cli_world

    return _cli_world(tmp_path_factory.mktemp("world"), demo=True)


@pytest.mark.slow
@pytest.mark.parametrize("change,message", [HOSTILE[0], HOSTILE[3], HOSTILE[4]], ids=["nan", "ibm", "mirrored"])
def test_the_command_line_says_one_error_line_and_writes_nothing(tmp_path, cli_world, change, message):
    db, speech = cli_world
    bad = _edited(tmp_path, "mixamo_t", change)
    out = tmp_path / "out"
    run = run_cli("synthesize", speech, "--db", db, "--out", out, "--refiner", "none", "--character", bad)
    assert run.code == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gesturekit: error: ") and str(bad) in lines[0], run.stderr
    assert not out.exists()


@pytest.mark.slow
def test_a_bvh_with_offsets_of_1e308_is_refused_naming_the_joint(tmp_path, cli_world):
    text = cmu_bvh().decode("ascii")
    at = text.index("JOINT LeftForeArm")
    start = text.index("OFFSET", at)
    end = text.index("\n", start)
    path = tmp_path / "huge.bvh"
    path.write_text(text[:start] + "OFFSET 1e308 1e308 0" + text[end:])
    with pytest.raises(MotionFileError, match="joint 'LeftForeArm' has the offset") as e:
        read_character(path)
    assert Path(e.value.path) == path
    db, speech = cli_world
    out = tmp_path / "out"
    run = run_cli("synthesize", speech, "--db", db, "--out", out, "--refiner", "none", "--format", "npz,bvh")
    assert run.code == 0  # the same run without the character writes
    run = run_cli(
        "synthesize",
        speech,
        "--db",
        db,
        "--out",
        tmp_path / "o2",
        "--refiner",
        "none",
        "--format",
        "npz,bvh",
        "--character",
        path,
    )
    assert run.code == 2 and len(run.stderr.strip().splitlines()) == 1 and "huge.bvh" in run.stderr
    assert not (tmp_path / "o2").exists()


def test_a_gltf_buffer_linked_to_a_file_outside_its_folder_is_refused(tmp_path):
    ((_, data),) = rig_files(CASES["mixamo_t"]).items()
    doc, binary = read_glb(data)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "secret.bin").write_bytes(binary)
    folder = tmp_path / "char"
    folder.mkdir()
    (folder / "body.bin").symlink_to(tmp_path / "elsewhere" / "secret.bin")
    doc["buffers"] = [{"uri": "body.bin", "byteLength": len(binary)}]
    path = folder / "c.gltf"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputFileError, match="'body.bin' is a link to a file outside") as e:
        read_character(path)
    assert Path(e.value.path) == path
    (folder / "body.bin").unlink()
    (folder / "body.bin").write_bytes(binary)  # the same bytes beside it are read
    assert read_character(path).n_bones > 50


# ----------------------------------------------------------------------------- limits before the work


def _peak(fn) -> tuple[BaseException | None, int]:
    tracemalloc.start()
    try:
        fn()
        error = None
    except GestureKitError as e:
        error = e
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return error, peak


@pytest.mark.slow
def test_a_five_million_vertex_body_is_refused_before_it_is_read(tmp_path):
    n = 5_000_000

    def add_body(doc, binary):
        buf = GlbBuffer()
        rng = np.random.default_rng(0)
        buf.add(rng.normal(0.0, 0.1, (n, 3)).astype(np.float32), "VEC3", FLOAT)
        base = len(binary) + (-len(binary) % 4)
        doc["bufferViews"].append({**buf.views[0], "byteOffset": base})
        doc["accessors"].append({**buf.accessors[0], "bufferView": len(doc["bufferViews"]) - 1})
        doc["meshes"].append({"primitives": [{"attributes": {"POSITION": len(doc["accessors"]) - 1}}]})
        doc["nodes"].append({"name": "cloud", "mesh": len(doc["meshes"]) - 1})
        _node(doc, "mixamorig:Head").setdefault("children", []).append(len(doc["nodes"]) - 1)
        padded = binary + b"\0" * (base - len(binary)) + bytes(buf.data)
        doc["buffers"] = [{"byteLength": len(padded)}]
        return padded

    path = _edited(tmp_path, "mixamo_t", add_body, "cloud.glb")
    size = path.stat().st_size
    assert size > 12 * n
    error, peak = _peak(lambda: read_character(path))
    print(f"{size / 1e6:.0f} MB file refused with a peak of {peak / 1e6:.0f} MB: {error}")
    assert isinstance(error, InputFileError) and "5002304 vertices" in str(error) and "cloud.glb" in str(error)
    assert peak < 2.5 * size  # the file's bytes, not the float64 arrays of 5 000 000 vertices (over 1 GB)


@pytest.mark.slow
def test_an_8192_texture_is_refused_from_its_header_before_it_is_decoded(tmp_path):
    import io

    from PIL import Image

    side = 8192
    raw = io.BytesIO()
    Image.new("RGB", (side, side), (200, 120, 90)).save(raw, format="PNG", compress_level=1)
    png = raw.getvalue()

    def big(doc, binary):
        img = doc["images"][0]
        img.pop("bufferView")
        img["uri"] = "data:image/png;base64," + base64.b64encode(png).decode("ascii")

    path = _edited(tmp_path, "zeggs_glb", big, "big.glb")
    error, peak = _peak(lambda: read_character(path))
    print(f"{len(png) / 1e6:.2f} MB PNG of {side} x {side} refused with a peak of {peak / 1e6:.0f} MB: {error}")
    assert isinstance(error, InputFileError) and "8192 x 8192" in str(error) and "big.glb" in str(error)
    assert peak < 64e6  # a decoded image alone would be 201 MB, as floats 1.6 GB


# ----------------------------------------------------------------------------- the Python API


@pytest.mark.parametrize("value", [None, 3, b"x.glb"])
def test_the_python_api_given_no_path_says_so(value):
    with pytest.raises(ConfigError, match="file name or path"):
        read_character(value)


def test_retarget_given_other_things_says_so(tmp_path, motion):
    path = tmp_path / "cmu.bvh"
    path.write_bytes(cmu_bvh())
    ch = read_character(path)
    with pytest.raises(ConfigError, match="Motion"):
        retarget("speech.npz", ch)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="Character"):
        retarget(motion, None)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="bone_map"):
        read_character(path, bone_map=3)  # type: ignore[arg-type]


@pytest.mark.slow
def test_a_late_error_takes_back_every_file_the_run_wrote(tmp_path, cli_world, monkeypatch):
    """The npz, the glTF and its speech are written, then the BVH fails: none of them is left behind."""
    import gesturekit.export.result as result_module
    from gesturekit.errors import OutputError

    def fail(result, retargeted, path, **kwargs):
        raise OutputError("cannot write: the disk is full", path=path)

    db, speech = cli_world
    character = tmp_path / "avatar.glb"
    character.write_bytes(rig_files(CASES["mixamo_t"])["mixamo.glb"])
    out = tmp_path / "out"
    args = ["synthesize", speech, "--db", db, "--out", out, "--refiner", "none", "--character", character]
    args += ["--format", "npz,glb,bvh"]
    monkeypatch.setattr(result_module, "export_result_character_bvh", fail)
    run = run_cli(*args)
    assert run.code == 2 and "the disk is full" in run.stderr and "speech.bvh" in run.stderr, run.stderr
    assert sorted(p.name for p in out.iterdir()) == []
    monkeypatch.undo()
    run = run_cli(*args)
    assert run.code == 0, run.stderr
    assert sorted(p.name for p in out.iterdir()) == ["speech.bvh", "speech.glb", "speech.npz", "speech.wav"]


def test_the_writers_given_other_things_say_so(tmp_path, motion):
    from gesturekit.export.character import export_character_bvh, export_character_glb

    path = tmp_path / "cmu.bvh"
    path.write_bytes(cmu_bvh())
    posed = retarget(motion, read_character(path))
    for write in (export_character_glb, export_character_bvh):
        with pytest.raises(ConfigError, match="Retargeted"):
            write(tmp_path / "x", None)  # type: ignore[arg-type]
        with pytest.raises(ConfigError, match="file name or path"):
            write(None, posed)  # type: ignore[arg-type]
    assert not any(p.name.startswith("x") for p in tmp_path.iterdir())
