"""The three.js viewer in a real browser: it draws the characters in the shared look's exact Lambert light, orbits
and resets, and without WebGL says so while its clock still plays.

Headless Debian Chromium driven by Playwright (``tests/app_browser.py``) opens a
:func:`gesturekit.viz.viewer.skeleton_viewer` page as a file; skipped, with the
reason, where either is missing. Chromium without a GPU draws WebGL in software.
"""

from __future__ import annotations

import base64

import numpy as np
import pytest

from gesturekit.character import look
from gesturekit.demo import open_default_database
from gesturekit.motion import Motion
from gesturekit.viz.appearance import APPEARANCE
from gesturekit.viz.viewer import read_viewer_data, skeleton_viewer
from tests import app_browser

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

#: The drawing's pixels as the page made them (RGBA rows from the bottom), read back right after a draw.
_PIXELS = """() => {
  const s = document.getElementById("s"); s.dispatchEvent(new Event("input"));
  const gl = document.getElementById("c").getContext("webgl2");
  const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight, px = new Uint8Array(w * h * 4);
  gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
  let text = "";
  for (let i = 0; i < px.length; i += 32768) text += String.fromCharCode.apply(null, px.subarray(i, i + 32768));
  return {w: w, h: h, data: btoa(text)}; }"""


def _pixels(page) -> np.ndarray:
    got = page.evaluate(_PIXELS)
    return np.frombuffer(base64.b64decode(got["data"]), np.uint8).reshape(got["h"], got["w"], 4)[..., :3]


def _linear(srgb: np.ndarray) -> np.ndarray:
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def _srgb(linear: np.ndarray) -> np.ndarray:
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1 / 2.4) - 0.055)


def _hex(color: str) -> np.ndarray:
    return np.array([int(color[i : i + 2], 16) for i in (1, 3, 5)]) / 255.0


@pytest.fixture(scope="module")
def page_file(tmp_path_factory):
    db = open_default_database()
    clip = db.poses[:4].reshape(-1, 55, 3).astype(np.float32)
    motions = [Motion(clip, 15.0, db.joint_presence), Motion(clip[::-1].copy(), 15.0, db.joint_presence)]
    path = tmp_path_factory.mktemp("viewer") / "view.html"
    path.write_text(skeleton_viewer(motions, labels=["a", "b"]), encoding="utf-8")
    return path


def _open(page, path) -> None:
    page.goto(path.as_uri())
    page.wait_for_selector('body[data-drawn="1"]', state="attached")


def _characters(page) -> np.ndarray:
    """The pixels where the characters are, shape (h, w) bool: those that differ from the stage alone."""
    px = _pixels(page)
    page.evaluate("() => gk.showCharacters(false)")
    stage = _pixels(page)
    page.evaluate("() => gk.showCharacters(true)")
    return np.any(px != stage, axis=2)


def test_every_pixel_is_the_background_or_a_part_in_the_looks_lambert_light(page_file):
    with app_browser.browser(width=800, height=600) as page:
        _open(page, page_file)
        px = _pixels(page).reshape(-1, 3).astype(np.float64) / 255.0
        background = ~_characters(page).reshape(-1)
    body = px[~background]
    assert 0.03 < len(body) / len(px) < 0.8  # the characters are drawn, and framed
    # no antialiasing: every other pixel is one surface, albedo * (AMBIENT + KEY * max(0, n.l)) in linear light
    albedos = np.vstack([look.part_colors(s) for s in ("blue", "orange")] + [_hex(APPEARANCE.derived_color)[None]])
    lin, alb = _linear(body), _linear(albedos)
    shade = (lin @ alb.T) / np.sum(alb * alb, axis=1)  # the best light factor per pixel and albedo
    predicted = _srgb(np.clip(shade[:, :, None] * alb[None], 0, 1))  # (pixels, albedos, 3)
    error = np.abs(predicted - body[:, None]).max(axis=2)
    best = np.argmin(error, axis=1)
    factor = shade[np.arange(len(body)), best]
    fits = error[np.arange(len(body)), best] <= 2.5 / 255
    assert fits.mean() > 0.99
    factor = factor[fits & (error[np.arange(len(body)), best] < 1.5 / 255)]
    # three.js's light units set right: never below the ambient, never above ambient plus every light, and lit by
    # the key
    brightest = look.AMBIENT + sum(k for _, k in look.LIGHTS)
    assert factor.min() >= look.AMBIENT - 0.03 and factor.max() <= brightest + 0.03
    assert factor.max() > look.AMBIENT + 0.6 * look.KEY


def test_dragging_orbits_scrolling_zooms_and_a_double_click_resets(page_file):
    with app_browser.browser(width=800, height=600) as page:
        _open(page, page_file)
        first = _pixels(page)
        box = page.locator("canvas#c").bounding_box()
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        page.mouse.move(x, y)
        page.mouse.down()
        page.mouse.move(x + 150, y + 20, steps=5)
        page.mouse.up()
        orbited = _pixels(page)
        assert np.abs(orbited.astype(int) - first).sum() > 0
        page.mouse.wheel(0, -400)
        page.wait_for_function("() => gk.drawn > 0")
        zoomed = _pixels(page)
        assert np.abs(zoomed.astype(int) - orbited).sum() > 0
        page.mouse.dblclick(x, y)
        np.testing.assert_array_equal(_pixels(page), first)


def test_without_webgl_the_page_says_so_and_its_clock_still_plays(page_file):
    with app_browser.browser(width=800, height=600, flags=("--disable-3d-apis",)) as page:
        _open(page, page_file)
        note = page.locator("#nogl")
        assert note.is_visible() and "needs WebGL" in note.inner_text()
        page.locator("#play").click()
        page.wait_for_function("() => gk.frame >= 10")
        assert page.evaluate("() => gk.playing") is True


def test_a_new_size_frames_both_characters_again(page_file):
    with app_browser.browser(width=900, height=600) as page:
        _open(page, page_file)
        drawn = page.evaluate("() => gk.drawn")
        page.set_viewport_size({"width": 360, "height": 600})  # narrower: side by side, X decides the distance
        page.wait_for_function("(n) => gk.drawn > n", arg=drawn)
        body = _characters(page)
    cols = np.flatnonzero(body.any(axis=0))
    # nothing but a hand cut off at the sides (the framing holds the reach of most frames, not every gesture)
    assert len(cols) and body[:, [0, -1]].sum() < 0.02 * body.sum()
    assert cols.max() - cols.min() > 0.5 * body.shape[1]  # and the pair still fills the width


def test_the_camera_is_the_looks_camera_for_the_box_at_the_pages_aspect(page_file):
    data = read_viewer_data(page_file.read_text(encoding="utf-8"))
    with app_browser.browser(width=700, height=600) as page:
        _open(page, page_file)
        cam = page.evaluate("() => gk.camera")
    # the upper body's framing: the box's top at the picture's top, at most a little floor shown below it
    expected = look.camera_for(data["box"][0], data["box"][1], cam["aspect"], top=True, floor=data["ground"])
    # the drawing's own width over its height: side by side, no higher than the characters fill
    high = look.fitted_height(data["boxes"][look.UPPER_BODY], 700, 520)
    assert len(data["motions"]) == 1 or high < 520
    assert cam["aspect"] == pytest.approx(700 / high, rel=0.02)
    np.testing.assert_allclose(cam["position"], expected["position"], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(cam["target"], expected["target"], rtol=1e-9, atol=1e-9)
    assert cam["fov"] == expected["fov"]
