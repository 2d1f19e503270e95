"""A character's own materials as read: UVs, each triangle's material, the materials GLB and its images.

The character is generated (``tests/character_rigs.py``, ``textured``): three materials with PNG textures in
the GLB (one RGBA under alpha MASK), TEXCOORD_0 written as exporters write it. What is read is checked
against what was written: the UVs against the file's accessor, the triangles of each material against the
primitive's indices, the images' texels against the generated PNGs.
"""

from __future__ import annotations

import dataclasses
import io
import struct
import zlib

import numpy as np
import pytest

from gesturekit.character.glb import accessor_array, read_glb
from gesturekit.character.materials import MAX_TEXTURE_PIXELS, materials_glb, read_materials
from gesturekit.character.user import read_character
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.viz.character_page import page_character
from gesturekit.viz.character_user import character_arrays, character_from_arrays
from tests.character_rigs import CASES, RigSpec, write_rig

TEXTURED = RigSpec(textured=True, rest="A", roll_seed=6)


@pytest.fixture(scope="module")
def textured(tmp_path_factory):
    path = write_rig(tmp_path_factory.mktemp("materials"), TEXTURED, "textured")
    return path, read_character(path)


def test_the_uvs_and_materials_are_the_files(textured):
    path, ch = textured
    doc, binary = read_glb(path.read_bytes())
    prims = doc["meshes"][0]["primitives"]
    skin = ch.skin
    assert skin.has_materials
    uv = accessor_array(doc, binary, prims[0]["attributes"]["TEXCOORD_0"])
    # every primitive reads the shared accessor again: the UVs repeat once per primitive, in order
    np.testing.assert_array_equal(skin.uvs, np.tile(uv, (len(prims), 1)))
    counts = [int(doc["accessors"][p["indices"]]["count"]) // 3 for p in prims]
    want = np.concatenate([np.full(c, p["material"]) for c, p in zip(counts, prims)])
    np.testing.assert_array_equal(skin.face_materials, want)
    assert sorted(set(skin.face_materials.tolist())) == [0, 1, 2]


def test_the_materials_glb_holds_the_files_materials_and_images(textured):
    path, ch = textured
    from PIL import Image

    doc, binary = read_glb(path.read_bytes())
    materials, images = read_materials(ch.skin.materials)
    assert [m.name for m in materials[:-1]] == [m["name"] for m in doc["materials"]]
    default = materials[-1]  # glTF's default material, for primitives that name none
    assert (default.color, default.image, default.alpha_mode) == ((1.0, 1.0, 1.0, 1.0), None, "OPAQUE")
    skin, cloth, sleeves = materials[:3]
    assert skin.color == (1.0, 0.9, 0.85, 1.0) and skin.image == 0 and not skin.nearest
    assert cloth.image == 1 and cloth.nearest
    assert (sleeves.alpha_mode, sleeves.alpha_cutoff, sleeves.double_sided) == ("MASK", 0.5, True)
    for k, img in enumerate(doc["images"]):
        view = doc["bufferViews"][img["bufferView"]]
        data = binary[view.get("byteOffset", 0) : view.get("byteOffset", 0) + view["byteLength"]]
        want = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))
        np.testing.assert_array_equal(images[k], want)
    assert set(np.unique(images[2][..., 3]).tolist()) == {0, 255}  # the mask's cut and kept stripes


def test_a_glb_without_textures_keeps_its_factors(tmp_path):
    ch = read_character(write_rig(tmp_path, CASES["vrm0_a"]))
    materials, images = read_materials(ch.skin.materials)
    assert images == []
    assert [m.color[:3] for m in materials[:2]] == [(0.87, 0.68, 0.57), (0.25, 0.35, 0.6)]


def _png_header_only(width: int, height: int) -> bytes:
    """A PNG of ``width`` x ``height`` whose pixel data is one empty chunk (its header is all that is read)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b"")


def test_an_image_too_large_is_refused_from_its_header():
    side = int(MAX_TEXTURE_PIXELS**0.5) + 1
    png = _png_header_only(side, side)
    doc = {"images": [{"bufferView": 0}], "bufferViews": [{"buffer": 0, "byteLength": len(png)}], "materials": []}
    with pytest.raises(ConfigError, match=f"{side} x {side} pixels"):
        materials_glb(doc, png)
    doc["bufferViews"][0]["byteLength"] = len(png) + 8
    with pytest.raises(ConfigError, match="runs past"):
        materials_glb(doc, png)


def test_an_unreadable_image_names_the_file(tmp_path):
    path = write_rig(tmp_path, TEXTURED, "broken")
    doc, binary = read_glb(path.read_bytes())
    view = doc["bufferViews"][doc["images"][2]["bufferView"]]
    start = view.get("byteOffset", 0)
    spoiled = bytearray(binary)
    spoiled[start : start + 8] = b"notapng!"  # the masked material's image is no longer a PNG
    from gesturekit.character.glb import glb_bytes

    path.write_bytes(glb_bytes(doc, bytes(spoiled)))
    with pytest.raises(InputFileError, match="image 2") as caught:
        read_character(path)
    assert str(caught.value.path) == str(path)


def test_the_materials_travel_to_the_rendering_processes(textured):
    _, ch = textured
    back = character_from_arrays(character_arrays(ch))
    assert back is not None and back.skin is not None and back.skin.has_materials
    np.testing.assert_array_equal(back.skin.uvs, ch.skin.uvs)
    np.testing.assert_array_equal(back.skin.face_materials, ch.skin.face_materials)
    assert back.skin.materials == ch.skin.materials


@pytest.mark.slow
def test_the_page_groups_the_triangles_by_material(textured):
    import base64

    from gesturekit.character.retarget import retarget
    from gesturekit.motion import Motion
    from tests.viz.test_video_character import _demo

    _, ch = textured
    spec = page_character(retarget(Motion(_demo()[:3], 15.0), ch), scheme="blue")
    mesh = spec["mesh"]
    faces = np.frombuffer(base64.b64decode(mesh["faces"]["bdata"]), "<u2").reshape(-1, 3)
    starts = [g[0] for g in mesh["groups"]]
    assert starts == sorted(starts) and sum(g[1] for g in mesh["groups"]) == 3 * len(faces)
    for first, count, material in mesh["groups"]:
        got = faces[first // 3 : (first + count) // 3]
        want = ch.skin.faces[ch.skin.face_materials == material]
        np.testing.assert_array_equal(got, want)  # the file's order within a material
    assert base64.b64decode(mesh["materials"]["bdata"]) == ch.skin.materials
    # a body drawn in its colours alone (no materials) sends none of these
    plain = dataclasses.replace(ch, skin=dataclasses.replace(ch.skin, materials=b""))
    assert "groups" not in page_character(retarget(Motion(_demo()[:3], 15.0), plain), scheme="blue")["mesh"]
