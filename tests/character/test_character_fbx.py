"""FBX characters (issue 38): read by the ufbx library from the files exporters write, as glTF characters.

The files are written here (:mod:`tests.fbx_files`) with the properties of real ones: FBX 6.1 ASCII and
7.4/7.5 binary, ``mixamorig:`` names, centimetres, a Z-up axis system, rest rotations split into PreRotation,
Lcl Rotation and PostRotation, quads, two materials, UVs by polygon vertex and a texture beside the file or
embedded. What a reader must find is the generated rig's truth (:func:`tests.character_rigs.truth`).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.character._user_fbx import fans
from gesturekit.character.glb import node_matrices
from gesturekit.character.user import read_character
from gesturekit.errors import ConfigError, InputFileError
from tests.badinput import run_cli
from tests.character_rigs import RigSpec, _bones, _tubes, truth
from tests.fbx_files import (
    AXES,
    FbxSpec,
    ObjectId,
    RawProperty,
    fbx_ascii_61,
    fbx_binary,
    fbx_scene,
    fbx_texture,
    node_bytes,
)

pytest.importorskip("ufbx", reason="reading FBX needs the ufbx package (pip install ufbx)")

FILES = {
    "ascii_61_cm_file_texture": (FbxSpec(), "ascii", 0),
    "binary_7400_z_up_embedded": (FbxSpec(up="z", texture="embedded"), "binary", 7400),
    "binary_7500_uncompressed": (FbxSpec(), "binary-raw", 7500),
    "binary_7400_blender_armature": (FbxSpec(armature=True, texture="embedded"), "binary", 7400),
}


def _write(folder: Path, spec: FbxSpec, form: str = "binary", version: int = 7400, name: str = "hero.fbx") -> Path:
    path = folder / name
    if form == "ascii":
        path.write_text(fbx_ascii_61(spec))
    else:
        path.write_bytes(fbx_binary(spec, version=version, compress=form == "binary"))
    if spec.texture == "file":
        (folder / "skin.png").write_bytes(fbx_scene(spec).png)
    return path


@pytest.mark.parametrize("case", list(FILES))
def test_an_fbx_character_reads_as_its_rig(tmp_path, case):
    spec, form, version = FILES[case]
    ch = read_character(_write(tmp_path, spec, form, version))
    t = truth(spec.rig)
    assert ch.kind == "fbx" and ch.matched_by == "mixamo names" and ch.notes == ()
    index = [ch.names.index(n) for n in t.bone_names]
    # every bone where the rig has it (metres, Y up, facing +Z): PreRotation, Lcl Rotation and PostRotation composed
    np.testing.assert_allclose(ch.rest_position[index], t.rest_world, atol=1e-6)
    assert [ch.names[p] if p >= 0 else None for p in ch.parents[index]] == [
        t.bone_names[p] if p >= 0 else None for p in t.parents
    ]
    for joint, bone in t.joint_map.items():
        assert ch.names[ch.bone(joint)] == bone, joint
    # the body: every vertex where the generated tube has it, finite, with weights summing to 1
    skin = ch.skin
    scene = fbx_scene(spec)
    assert skin is not None and len(skin.faces) == 2 * len(scene.polygons)  # each quad in two triangles
    assert skin.n_vertices == len(scene.vertices)  # one vertex per position (its UV and normal are one)
    assert np.isfinite(skin.vertices).all() and np.isfinite(skin.normals).all()
    tube = _tubes(_bones(spec.rig), spec.rig)[0].astype(np.float64)
    gap = np.linalg.norm(skin.vertices[:, None, :] - tube[None, :, :], axis=-1).min(axis=1)
    assert gap.max() < 1e-5
    np.testing.assert_allclose(skin.weights.sum(axis=1), 1.0, atol=1e-6)
    height = float(skin.vertices[:, 1].max() - min(skin.vertices[:, 1].min(), ch.rest_position[:, 1].min()))
    assert abs(ch.rest_position[:, 1].max() - spec.rig.height) < 1e-6 and 1.7 < height < 1.8
    # colours: the untextured material its DiffuseColor, the textured one its texels (V read upwards: the red
    # texel of the image's top-left corner is where the tubes' first ring starts)
    _, texel = fbx_texture(spec.rig.seed)
    colours = np.round(skin.colors * 255).astype(int)
    plain = np.all(np.abs(colours - np.array([0.87, 0.68, 0.57]) * 255) <= 1, axis=1)
    palette = {tuple(c) for c in texel.reshape(-1, 3).astype(int)}
    assert plain.any() and all(tuple(c) in palette for c in colours[~plain])
    assert (colours == (255, 0, 0)).all(axis=1).any()


@pytest.mark.slow
def test_the_z_up_file_reads_as_the_y_up_one(tmp_path):
    """The axis system is the file's: the same character written Z up (3ds Max's axes) reads the same."""
    y = read_character(_write(tmp_path, FbxSpec(), name="y.fbx"))
    z = read_character(_write(tmp_path, FbxSpec(up="z"), name="z.fbx"))
    np.testing.assert_allclose(z.rest_position, y.rest_position, atol=1e-6)
    # the same local turns in a Z-up frame: each bone's rotation is the Y-up one seen from the other axes
    a = AXES["z"][1]
    np.testing.assert_allclose(z.rest_rotation, a.T @ y.rest_rotation @ a, atol=1e-9)
    # in the glTF written from it, the head is above the hips along glTF's +Y
    doc = z.gltf.document
    world = node_matrices(doc["nodes"], {}, 1)[0]
    head, hips = (world[int(z.gltf.nodes[z.bone(k)]), :3, 3] for k in ("head", "pelvis"))
    assert head[1] - hips[1] > 0.5 and abs(head[2] - hips[2]) < 1e-6


@pytest.mark.parametrize(
    "unit,declared,note",
    [(0.01, None, ""), (1.0, None, ""), (0.0254, None, ""), (1.0, 1.0, "scaled by 100")],
    ids=["centimetres", "metres", "inches", "metres-said-centimetres"],
)
def test_the_unit_is_the_files_and_a_hundredfold_error_is_undone(tmp_path, unit, declared, note):
    """``UnitScaleFactor`` gives the unit (Mixamo: centimetres); a file whose numbers are metres but which says
    centimetres (1/100 of its size, as some converters write) is scaled back and says so."""
    path = _write(tmp_path, FbxSpec(unit=unit, declared=declared))
    if note:
        with pytest.warns(UserWarning, match=note):
            ch = read_character(path)
        assert note in " ".join(ch.notes)
    else:
        ch = read_character(path)
        assert ch.notes == ()
    assert abs(ch.rest_position[:, 1].max() - 1.75) < 1e-6


def test_a_missing_texture_is_drawn_in_its_plain_colour_with_a_warning(tmp_path):
    path = _write(tmp_path, FbxSpec(texture="none"))
    text = fbx_ascii_61(FbxSpec(), texture_name="gone.png")
    path.write_text(text)
    with pytest.warns(UserWarning, match="gone.png"):
        ch = read_character(path)
    assert ch.skin is not None and np.isfinite(ch.skin.colors).all()


@settings(max_examples=60)
@given(st.lists(st.integers(0, 7), max_size=30))
def test_fans_equal_the_plain_loop(counts):
    """The vectorised fans are the polygon-by-polygon loop's triangles, in its order."""
    count = np.array(counts, dtype=np.int64)
    begin = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64) if len(count) else count
    face, corners = fans(begin, count)
    want = [(f, (b, b + i + 1, b + i + 2)) for f, (b, c) in enumerate(zip(begin, count)) for i in range(c - 2)]
    assert face.tolist() == [w[0] for w in want]
    assert corners.reshape(-1, 3).tolist() == [list(w[1]) for w in want]


def test_an_uploaded_fbx_reads_with_its_embedded_texture(tmp_path):
    """The app's upload: only the file itself, so its texture is the embedded one."""
    from gesturekit.character.user import read_character_upload

    data = fbx_binary(FbxSpec(texture="embedded"))
    ch = read_character_upload("my hero.fbx", data)
    assert ch.path == Path("my hero.fbx") and ch.kind == "fbx"
    assert (np.round(ch.skin.colors * 255) == (255, 0, 0)).all(axis=1).any()  # the texture's red corner


# ----------------------------------------------------------------------------- bad files


def _ascii_with(tmp_path: Path, old: str, new: str) -> Path:
    text = fbx_ascii_61(FbxSpec())
    assert old in text
    path = tmp_path / "bad.fbx"
    path.write_text(text.replace(old, new, 1))
    (tmp_path / "skin.png").write_bytes(fbx_scene(FbxSpec()).png)
    return path


def _hostile_array(tmp_path: Path) -> Path:
    """A binary FBX whose vertex array declares 2**31 - 1 doubles (16 GB) in a few bytes of deflated zeros."""
    body = zlib.compress(b"\0" * 64)
    vertices = RawProperty(b"d" + struct.pack("<III", 2**31 - 1, 1, len(body)) + body)
    out = bytearray(b"Kaydara FBX Binary  \x00\x1a\x00" + struct.pack("<I", 7400))
    node_bytes(out, ("FBXHeaderExtension", [], [("FBXVersion", [7400], [])]), wide=False)
    geometry = ("Geometry", [ObjectId(1), "x\x00\x01Geometry", "Mesh"], [("Vertices", [vertices], [])])
    node_bytes(out, ("Objects", [], [geometry]), wide=False)
    out += b"\0" * 13
    path = tmp_path / "huge.fbx"
    path.write_bytes(bytes(out))
    return path


_PLAIN = FbxSpec(texture="none")
_T = '"Lcl Translation", "Lcl Translation", "A+",'
_S = '"Lcl Scaling", "Lcl Scaling", "A+",'

BAD = {
    "truncated": (lambda d: _write(d, _PLAIN), lambda p: p.write_bytes(p.read_bytes()[:4000])),
    "wrong_magic": (lambda d: _write(d, _PLAIN), lambda p: p.write_bytes(b"Kaydara FBX Binarx" + p.read_bytes()[18:])),
    "not_fbx": (lambda d: d / "x.fbx", lambda p: p.write_bytes(bytes(range(256)) * 40)),
    "nan_translation": (lambda d: _ascii_with(d, _T + "0,98", _T + "nan,98"), None),
    "zero_scale": (lambda d: _ascii_with(d, _S + "1,1,1", _S + "0,0,0"), None),
    "hostile_array": (_hostile_array, None),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_fbx_is_refused_naming_the_file(tmp_path, case):
    make, spoil = BAD[case]
    path = make(tmp_path)
    if spoil is not None:
        spoil(path)
    with pytest.raises((InputFileError, ConfigError)) as e:
        read_character(path)
    assert str(path) in str(e.value), str(e.value)
    if case == "hostile_array":  # refused for its size, not read
        assert "memory allowed" in str(e.value), str(e.value)


@pytest.mark.skipif(__import__("os").name != "posix", reason="the reader's memory limit is set on POSIX")
def test_a_reader_that_runs_out_of_memory_is_a_clean_error(tmp_path, monkeypatch):
    """The FBX reader runs under a memory limit in its own process: when it dies, the caller does not."""
    import gesturekit.character._user_fbx as user_fbx

    path = _write(tmp_path, _PLAIN)
    monkeypatch.setattr(user_fbx, "_memory_limit", lambda: 40_000_000)  # too little for Python and numpy
    with pytest.raises(InputFileError) as e:
        read_character(path)
    assert str(path) in str(e.value) and "FBX reader" in str(e.value), str(e.value)
    monkeypatch.undo()
    assert read_character(path).kind == "fbx"


@pytest.mark.slow
def test_the_command_line_refuses_a_bad_fbx_in_one_line_and_writes_nothing(tmp_path):
    from tests.export.test_export_bvh_report import _cli_world

    db, speech = _cli_world(tmp_path / "world", demo=True)
    for case in ("truncated", "nan_translation", "hostile_array"):
        folder = tmp_path / case
        folder.mkdir()
        make, spoil = BAD[case]
        bad = make(folder)
        if spoil is not None:
            spoil(bad)
        out = folder / "out"
        run = run_cli("synthesize", speech, "--db", db, "--out", out, "--refiner", "none", "--character", bad)
        assert run.code == 2, run.stderr
        lines = run.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gesturekit: error: ") and str(bad) in lines[0], run.stderr
        assert not out.exists()


@pytest.mark.slow
def test_a_synthesis_result_exports_to_glb_on_an_fbx_character(tmp_path):
    """``synthesize --character hero.fbx --format npz,glb``: a GLB of their body animated by our motion, read back
    within a millimetre, and the character's BVH."""
    from tests.export.test_export_bvh_report import _cli_world

    db, speech = _cli_world(tmp_path / "world", demo=True)
    hero = _write(tmp_path, FbxSpec(up="z", texture="embedded"))
    out = tmp_path / "out"
    run = run_cli(
        "synthesize",
        speech,
        "--db",
        db,
        "--out",
        out,
        "--refiner",
        "none",
        "--character",
        hero,
        "--format",
        "npz,glb,bvh",
    )
    assert run.code == 0, run.stderr
    print(run.stdout)
    names = sorted(p.name for p in out.iterdir())
    stem = Path(speech).stem
    assert {f"{stem}.glb", f"{stem}.bvh", f"{stem}.npz"} <= set(names)
    from gesturekit.character.glb import accessor_array, read_glb

    doc, binary = read_glb((out / f"{stem}.glb").read_bytes())
    assert doc["animations"][0]["name"] == "gesturekit" and doc["images"] and doc["skins"]
    tracks = {}
    for channel in doc["animations"][0]["channels"]:
        sampler = doc["animations"][0]["samplers"][channel["sampler"]]
        key = (channel["target"]["node"], channel["target"]["path"])
        tracks[key] = accessor_array(doc, binary, sampler["output"]).astype(np.float64)
    n = len(next(iter(tracks.values())))
    world = node_matrices(doc["nodes"], tracks, n)
    assert np.isfinite(world).all()
    name = {node.get("name"): i for i, node in enumerate(doc["nodes"])}
    head, hips = world[:, name["mixamorig:Head"], :3, 3], world[:, name["mixamorig:Hips"], :3, 3]
    assert ((head - hips)[:, 1] > 0.4).all()  # upright in glTF's Y up on every frame
    rig = RigSpec()
    assert abs(float(np.linalg.norm(head[0] - hips[0])) - (1.58 - 0.98) * rig.height / 1.75) < 0.02
