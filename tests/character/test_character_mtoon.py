"""A VRM's MToon as read, kept in what we write, checked where the file is read, and the rule that shades with it.

The characters are generated (``tests/character_rigs.py``, ``mtoon``): a VRM 1.0 with ``VRMC_materials_mtoon``
in each material, and its VRM 0.x twin with the MToon in the ``VRM`` extension's material properties (Unity's
names, sRGB colours, the glTF materials ``KHR_materials_unlit``), as UniVRM writes them. That our reading of
both is three-vrm's is checked in the browser (``tests/browser/test_browser_mtoon.py``); here: what the file
says arrives, the written GLB keeps it, bad values are refused naming the file, and the shading rule's
properties hold.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gesturekit.character.glb import glb_bytes, read_glb
from gesturekit.character.look import AMBIENT, LIGHTS
from gesturekit.character.materials import materials_glb, read_materials
from gesturekit.character.mtoon import MToon, file_materials, from_vrm0, mtoon_shade, outline_color, read_mtoon
from gesturekit.character.retarget import retarget
from gesturekit.character.user import read_character
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.export.character import export_character_glb
from gesturekit.motion import Motion
from tests.character_rigs import RigSpec, rig_files, write_rig

TOON = RigSpec(naming="vrm1", rest="A", roll_seed=6, textured=True, mtoon=True)
TOON0 = RigSpec(naming="vrm0", rest="A", roll_seed=6, textured=True, mtoon=True)
PLAIN_TOON = RigSpec(naming="vrm1", mtoon=True)  # the two plain materials, no textures


def _doc(spec: RigSpec) -> tuple[dict, bytes]:
    ((_, data),) = rig_files(spec).items()
    return read_glb(data)


def test_a_vrm1s_mtoon_arrives_as_the_file_says():
    doc, binary = _doc(TOON)
    materials, _ = read_materials(materials_glb(doc, binary))
    for mat, m in zip(materials, doc["materials"]):
        ext = m["extensions"]["VRMC_materials_mtoon"]
        t = mat.mtoon
        assert t is not None, mat.name
        assert t.shade_color == tuple(ext["shadeColorFactor"])
        assert (t.shading_shift, t.shading_toony) == (ext["shadingShiftFactor"], ext["shadingToonyFactor"])
        assert t.outline_mode == ext.get("outlineWidthMode", "none")
        assert t.outline_width == ext.get("outlineWidthFactor", 0.0)
        assert t.emissive == tuple(m.get("emissiveFactor", (0.0, 0.0, 0.0)))
        # the shade multiply texture resolved to its image, as the base colour's is
        if "shadeMultiplyTexture" in ext:
            assert t.shade_texture == ext["shadeMultiplyTexture"]["index"]
            assert mat.shade_image == mat.image is not None and mat.shade_nearest == mat.nearest
        else:
            assert t.shade_texture is None and mat.shade_image is None
    assert materials[-1].mtoon is None  # glTF's default material stays Lambert
    assert [m.name for m in materials if m.mtoon is not None and m.mtoon.outlined] == ["skin", "cloth"]


def test_a_vrm0s_material_properties_become_its_mtoon_and_its_glTF_fallback_is_left():
    doc, binary = _doc(TOON0)
    props = doc["extensions"]["VRM"]["materialProperties"]
    assert all("KHR_materials_unlit" in m["extensions"] for m in doc["materials"])
    materials, _ = read_materials(materials_glb(doc, binary))
    for mat, p in zip(materials, props):
        assert mat.mtoon is not None
        shade = np.asarray(p["vectorProperties"]["_ShadeColor"][:3]) ** 2.2  # gamma space to linear
        np.testing.assert_allclose(mat.mtoon.shade_color, shade, rtol=1e-9)
        np.testing.assert_allclose(mat.color[:3], np.asarray(p["vectorProperties"]["_Color"][:3]) ** 2.2)
        assert mat.mtoon.outline_width == pytest.approx(0.01 * p["floatProperties"]["_OutlineWidth"])
        assert mat.double_sided is (p["floatProperties"]["_CullMode"] == 0)
        assert mat.alpha_mode == ("MASK" if p["keywordMap"].get("_ALPHATEST_ON") else "OPAQUE")
    # a material the properties do not cover, or a glTF-shaded one, is read as glTF describes it
    plain = {"name": "x", "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.3, 0.4, 1.0]}}
    assert from_vrm0({"shader": "VRM_USE_GLTFSHADER"}, plain) is plain
    assert file_materials({"materials": [plain], "extensions": {"VRM": {"materialProperties": []}}}) == [plain]


@given(shift=st.floats(-1.0, 1.0), toony=st.floats(0.0, 1.0))
def test_a_vrm0s_shade_edge_stays_where_its_shade_shift_puts_it(shift, toony):
    """0.x's pair becomes a 1.0 pair whose toony is no softer and whose step leaves the shade colour at
    ``n . l = _ShadeShift``, as 0.x's shade ends there."""
    out = from_vrm0({"shader": "VRM/MToon", "floatProperties": {"_ShadeShift": shift, "_ShadeToony": toony}}, {})
    ext = out["extensions"]["VRMC_materials_mtoon"]
    t1, s1 = ext["shadingToonyFactor"], ext["shadingShiftFactor"]
    assert toony - 1e-12 <= t1 <= 1.0 + 1e-12
    assert shift + s1 == pytest.approx(-1.0 + t1, abs=1e-9)  # the step's shade end: n . l + shift' = -1 + toony'


def test_the_written_glb_keeps_the_mtoon_of_both_versions(tmp_path):
    from gesturekit.demo import open_default_database

    db = open_default_database()
    m = Motion(np.asarray(db.poses[:1]).reshape(-1, 55, 3).astype(np.float32), db.fps, db.joint_presence)
    for spec in (TOON, TOON0):
        path = write_rig(tmp_path, spec, f"toon_{spec.naming}")
        src, _ = read_glb(path.read_bytes())
        report = export_character_glb(tmp_path / f"out_{spec.naming}.vrm", retarget(m, read_character(path)))
        out, binary = read_glb(report.path.read_bytes())
        assert out["materials"] == src["materials"]  # every material's extensions, as written
        assert set(src["extensionsUsed"]) <= set(out["extensionsUsed"])
        assert out["extensions"] == src["extensions"]  # VRMC_vrm, or VRM with its material properties
        # the file read back draws as the source does
        again = read_materials(materials_glb(out, binary))[0]
        assert again == read_materials(materials_glb(src, read_glb(path.read_bytes())[1]))[0]
        # every extension a material uses is declared
        for mat in out["materials"]:
            assert set(mat.get("extensions", {})) <= set(out["extensionsUsed"])


@pytest.mark.parametrize(
    "spoil, where",
    [
        (
            lambda d: d["materials"][0]["extensions"]["VRMC_materials_mtoon"].update(shadeColorFactor=[np.nan, 0, 0]),
            "shade colour",
        ),
        (
            lambda d: d["materials"][1]["extensions"]["VRMC_materials_mtoon"].update(outlineWidthMode="thick"),
            "outline width mode",
        ),
        (
            lambda d: d["materials"][0]["extensions"]["VRMC_materials_mtoon"].update(shadingToonyFactor="hard"),
            "shading toony",
        ),
    ],
    ids=["nan colour", "unknown outline mode", "text toony"],
)
def test_a_bad_vrm1_mtoon_is_refused_naming_the_file(tmp_path, spoil, where):
    path = write_rig(tmp_path, TOON, "bad")
    doc, binary = read_glb(path.read_bytes())
    spoil(doc)
    path.write_bytes(glb_bytes(doc, binary))
    with pytest.raises(InputFileError, match=where) as caught:
        read_character(path)
    assert str(caught.value.path) == str(path)


@pytest.mark.parametrize(
    "key, value, where",
    [
        ("floatProperties", {"_ShadeToony": "x"}, "_ShadeToony"),
        ("vectorProperties", {"_ShadeColor": [1.0]}, "_ShadeColor"),
    ],
)
def test_bad_vrm0_material_properties_are_refused_naming_the_file(tmp_path, key, value, where):
    path = write_rig(tmp_path, TOON0, "bad0")
    doc, binary = read_glb(path.read_bytes())
    doc["extensions"]["VRM"]["materialProperties"][1][key].update(value)
    path.write_bytes(glb_bytes(doc, binary))
    with pytest.raises(InputFileError, match=where) as caught:
        read_character(path)
    assert str(caught.value.path) == str(path)


def test_an_unknown_mtoon_version_is_left_to_glTF():
    m = {"extensions": {"VRMC_materials_mtoon": {"specVersion": "2.0", "shadeColorFactor": [1, 0, 0]}}}
    assert read_mtoon(m) is None
    with pytest.raises(ConfigError, match="colour"):
        read_mtoon({"extensions": {"VRMC_materials_mtoon": {"specVersion": "1.0", "shadeColorFactor": [1, 0]}}})


# ---- the rule


_unit = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 0.1)
_colour = st.tuples(st.floats(0, 1), st.floats(0, 1), st.floats(0, 1))


@given(n=_unit, lit=_colour, shade=_colour, shift=st.floats(-0.5, 0.5), toony=st.floats(0.0, 0.99))
def test_each_light_mixes_shade_into_lit_colour_and_ambient_light_lights_the_lit_colour(n, lit, shade, shift, toony):
    mt = MToon(shade_color=shade, shading_shift=shift, shading_toony=toony)
    normal = np.asarray(n) / np.linalg.norm(n)
    got = mtoon_shade(normal[None], [lit], [shade], mt)[0]
    c, s = np.asarray(lit), np.asarray(shade)
    total = sum(k for _, k in LIGHTS)
    lo, hi = AMBIENT * c + total * np.minimum(c, s), AMBIENT * c + total * np.maximum(c, s)
    assert np.all(got >= lo - 1e-12) and np.all(got <= hi + 1e-12)
    # the loop written out: one light at a time, its step literal
    want = AMBIENT * c
    for d, k in LIGHTS:
        x = float(np.clip(normal @ (np.asarray(d) / np.linalg.norm(d)), -1, 1)) + shift
        t = min(1.0, max(0.0, (x - (-1 + toony)) / ((1 - toony) - (-1 + toony))))
        want = want + k * (s * (1 - t) + c * t)
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_facing_every_light_is_lit_and_facing_away_is_in_shade():
    lit, shade = np.array([0.8, 0.6, 0.5]), np.array([0.3, 0.1, 0.4])
    mt = MToon(shade_color=tuple(shade), shading_shift=0.0, shading_toony=0.9)
    one = [((0.0, 0.0, 1.0), 0.7)]
    toward, away = mtoon_shade([[0, 0, 1], [0, 0, -1]], [lit, lit], [shade, shade], mt, lights=one, ambient=0.2)
    np.testing.assert_allclose(toward, 0.2 * lit + 0.7 * lit)
    np.testing.assert_allclose(away, 0.2 * lit + 0.7 * shade)  # a light behind leaves the shade colour, not black
    # a hard step (toony 1) flips at n . l = -shift
    hard = MToon(shade_color=tuple(shade), shading_shift=0.25, shading_toony=1.0)
    side = np.array([[np.sqrt(1 - 0.2**2), 0, -0.2], [np.sqrt(1 - 0.3**2), 0, -0.3]])
    a, b = mtoon_shade(side, [lit, lit], [shade, shade], hard, lights=one, ambient=0.0)
    np.testing.assert_allclose(a, 0.7 * lit)
    np.testing.assert_allclose(b, 0.7 * shade)


def test_the_rim_lights_edges_and_the_outline_takes_its_lighting_mix():
    lit = np.array([[0.5, 0.5, 0.5]] * 2)
    mt = MToon(shade_color=(0.5, 0.5, 0.5), rim_color=(0.2, 0.1, 0.0), rim_fresnel_power=2.0, rim_lighting_mix=0.0)
    n = np.array([[0, 0, 1.0], [1.0, 0, 0]])
    view = np.array([[0, 0, 1.0], [0, 0, 1.0]])
    face_on, edge = mtoon_shade(n, lit, lit, mt, view=view) - mtoon_shade(n, lit, lit, mt)
    np.testing.assert_allclose(face_on, 0.0, atol=1e-12)  # 1 - n . v = 0 facing the camera
    np.testing.assert_allclose(edge, [0.2, 0.1, 0.0])  # 1 at the silhouette, to any power
    fixed = MToon(outline_color=(0.1, 0.2, 0.3), outline_lighting_mix=0.0)
    np.testing.assert_allclose(outline_color([[0.9, 0.1, 0.5]], fixed), [[0.1, 0.2, 0.3]])
    lit_outline = MToon(outline_color=(0.1, 0.2, 0.3), outline_lighting_mix=1.0)
    np.testing.assert_allclose(outline_color([[0.5, 0.5, 2.0]], lit_outline), [[0.05, 0.1, 0.6]])


def test_a_vrm_without_textures_draws_its_factors_toon_shaded():
    doc, binary = _doc(PLAIN_TOON)
    materials, images = read_materials(materials_glb(doc, binary))
    assert images == [] and [m.name for m in materials if m.mtoon is not None] == ["skin", "cloth"]
    assert all(m.image is None and m.shade_image is None for m in materials)
    # copying the document leaves the reader's input as it was
    before = copy.deepcopy(doc)
    materials_glb(doc, binary)
    assert doc == before
