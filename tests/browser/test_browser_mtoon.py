"""A VRM's toon shading (MToon): the page and the MP4 against a plain three-vrm rendering of its GLB.

The character is generated (:class:`tests.character_rigs.RigSpec` ``mtoon``): a VRM 1.0 whose three textured
materials (as in :mod:`tests.browser.test_browser_materials`) are toon-shaded in ``VRMC_materials_mtoon``, and its
VRM 0.x twin with the same MToon in ``materialProperties``: each shade colour far from its base colour (the skin's
shade purple, the clothes' green), shading shifts and toony factors, the base texture as shade multiply texture, a
rim and a screen-space outline on the skin, a world-space outline lit half on the clothes, the masked sleeves
double-sided with a hard edge. Our motion is retargeted onto it and written with it
(:func:`gesturekit.character.export_character_glb`); the *reference* is that GLB opened by three.js's
``GLTFLoader`` with three-vrm's ``VRMLoaderPlugin`` in headless Chromium, its clip played to the time shown, drawn
with nothing of ours: the same camera, the look's ambient and directional lights. Against it, at 1280 x 800 pixels
and three times of the motion, as :mod:`tests.browser.test_browser_materials` measures:

- the page (:func:`gesturekit.viz.viewer.skeleton_viewer` with ``character=``), its canvas screenshotted;
- the MP4's renderer (:class:`gesturekit.viz.render.SkeletonScene`), the reference drawn through its camera;
- ``plain``: the same GLB drawn by three.js's ``GLTFLoader`` alone, which ignores MToon: it must fail the
  bounds, or the character would not tell a renderer that draws MToon from one that does not.

With a normal map on the clothes, the page still draws what three-vrm draws
(:func:`test_a_normal_map_under_mtoon_is_drawn_as_three_vrm_draws_it`). The parameters our reader takes from
both versions (a VRM 0.x keeps its MToon in other names and units) are those three-vrm gives its materials
(:func:`test_our_mtoon_parameters_are_three_vrms`).

``python -m tests.browser.test_browser_mtoon [--size 1280x800] [--out docs/screenshots] [--every] [--vrm0]``
prints the figures, and those of the page and the MP4 with the MToon left out for comparison; with ``--out``
it writes the page's and the MP4's pictures at the middle time (``character-mtoon-page.png``,
``character-mtoon-mp4.png``), with ``--every`` each picture and its reference at every time.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from gesturekit.character.glb import read_glb
from gesturekit.character.materials import materials_glb, read_materials
from tests import app_browser
from tests.browser.test_browser_materials import (
    MAX_DIFFERENCE,
    MIN_IOU,
    TIMES,
    Reference,
    _line,
    assert_within_bounds,
    comparison_parser,
    comparison_size,
    measure,
)
from tests.character_rigs import RigSpec, rig_files

pytestmark = [
    pytest.mark.skipif(app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"),
    pytest.mark.slow,
]

#: The generated toon-shaded VRM 1.0 (and its VRM 0.x twin).
TOON = RigSpec(naming="vrm1", rest="A", roll_seed=6, textured=True, mtoon=True)
TOON0 = RigSpec(naming="vrm0", rest="A", roll_seed=6, textured=True, mtoon=True)
#: The toon-shaded VRM 1.0 with a normal map on its clothes.
BUMPY = RigSpec(naming="vrm1", rest="A", roll_seed=6, textured=True, mtoon=True, normal_map=True)


def _fails(row: dict) -> bool:
    return not (row["iou"] >= MIN_IOU and row["difference"] <= MAX_DIFFERENCE)


#: The pictures' size, pixels: a laptop's browser window.
SIZE = (1280, 800)


@pytest.fixture(scope="module", params=["vrm1", "vrm0"])
def figures(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp("mtoon")
    spec = TOON if request.param == "vrm1" else TOON0
    try:
        return measure(folder, SIZE, spec=spec, vrm=True, plain=True, name="mtoon")
    except RuntimeError as exc:  # no node to bundle the reference with
        pytest.skip(f"no browser test: {exc}")


@pytest.mark.parametrize("picture", ["page", "mp4"])
def test_the_toon_shaded_vrm_matches_a_plain_three_vrm_rendering(figures, picture):
    assert_within_bounds(figures, picture)


def test_a_renderer_that_ignores_mtoon_fails_the_same_bounds(figures):
    rows = [r for r in figures if r["picture"] == "plain"]
    for r in rows:
        print(_line(r))
    assert len(rows) == len(TIMES)
    assert all(r["pixels"] > 2000 for r in rows)
    assert all(_fails(r) for r in rows), "the shade colours do not tell MToon from its glTF fallback"


def test_a_normal_map_under_mtoon_is_drawn_as_three_vrm_draws_it(tmp_path):
    """The clothes with a normal map (no tangents: three.js derives them, flipping the map's green as GLTFLoader
    does): the page as three-vrm draws it; the MP4, which leaves normal maps out, still within the bounds."""
    try:
        rows = measure(tmp_path, SIZE, spec=BUMPY, vrm=True, times=TIMES[1:2], name="bumpy")
    except RuntimeError as exc:
        pytest.skip(f"no browser test: {exc}")
    for r in rows:
        print(_line(r))
    page, mp4 = rows
    assert page["iou"] >= MIN_IOU and page["difference"] <= 1.0, _line(page)  # the same shading, as drawn
    assert mp4["iou"] >= MIN_IOU and mp4["difference"] <= MAX_DIFFERENCE, _line(mp4)


def _close(a, b) -> bool:
    return bool(np.allclose(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), atol=2e-5))


@pytest.mark.parametrize("spec", [TOON, TOON0], ids=["vrm1", "vrm0"])
def test_our_mtoon_parameters_are_three_vrms(tmp_path, spec):
    """Each material's MToon as we read it (VRM 1.0's extension, or VRM 0.x's properties converted) is what
    three-vrm's loader gives the material: colours, shift and toony, rim, emission, outline, textures, sides."""
    ((name, data),) = rig_files(spec).items()
    (tmp_path / name).write_bytes(data)
    doc, binary = read_glb(data)
    ours = {m.name: m for m in read_materials(materials_glb(doc, binary))[0] if m.mtoon is not None}
    try:
        ref = Reference(tmp_path)
    except RuntimeError as exc:
        pytest.skip(f"no browser test: {exc}")
    with app_browser.browser(width=320, height=200) as page:
        ref.open(page)
        theirs = page.evaluate("(u) => window.mtoon(u)", f"http://gesturekit.test/{name}")
    surfaces = {k: v for k, v in theirs.items() if not v["outline"]}
    assert set(surfaces) == set(ours) == {"skin", "cloth", "sleeves"}
    for key, mat in ours.items():
        t, m = surfaces[key], mat.mtoon
        assert m is not None
        assert _close(t["lit"], mat.color[:3]) and _close(t["opacity"], mat.color[3]), key
        assert _close(t["shade"], m.shade_color), key
        assert _close([t["shift"], t["toony"]], [m.shading_shift, m.shading_toony]), key
        assert _close(t["rim"], m.rim_color), key
        rim = [t["rimPower"], t["rimLift"], t["rimMix"]]
        assert _close(rim, [m.rim_fresnel_power, m.rim_lift, m.rim_lighting_mix]), key
        assert _close(t["emissive"], m.emissive), key
        assert t["outlineMode"] == m.outline_mode, key
        outline = [t["outlineWidth"], *t["outlineColor"], t["outlineMix"]]
        assert _close(outline, [m.outline_width, *m.outline_color, m.outline_lighting_mix]), key
        assert t["map"] is (mat.image is not None) and t["shadeMap"] is (mat.shade_image is not None), key
        assert t["doubleSided"] is mat.double_sided, key
        assert _close(t["alphaTest"], mat.alpha_cutoff if mat.alpha_mode == "MASK" else 0.0), key
    # three-vrm outlines exactly the outlined materials
    outlined = {k.removesuffix(" (Outline)") for k, v in theirs.items() if v["outline"]}
    assert outlined == {k for k, mat in ours.items() if mat.mtoon is not None and mat.mtoon.outlined}


def main(argv: list[str] | None = None) -> int:
    parser = comparison_parser("A toon-shaded VRM: the page and the MP4 against three-vrm.")
    parser.add_argument("--vrm0", action="store_true", help="the VRM 0.x twin of the character")
    args = parser.parse_args(argv)
    size = comparison_size(args)
    if size is None:
        return 1
    spec = TOON0 if args.vrm0 else TOON
    for drawn in ("own", "no mtoon"):
        print("with its MToon:" if drawn == "own" else "its MToon left out (the glTF materials alone):")
        with tempfile.TemporaryDirectory(prefix="gesturekit-mtoon-") as tmp:
            rows = measure(
                Path(tmp),
                size,
                spec=spec,
                vrm=True,
                drawn=drawn,
                plain=drawn == "own",
                out=args.out,
                every=args.every,
                name="mtoon",
            )
            for row in rows:
                print("  " + _line(row) + ("  (fails)" if _fails(row) else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
