"""The page frames as the MP4 does: a presenter's upper body fills most of the view's height; the wheel zooms
towards the cursor.

The page of a real speaker (51 s of the demo database's clips) is drawn in headless Chromium; the character's
pixels are those that differ from the stage drawn alone (``gk.showCharacters(false)``), its pelvis is projected
through the page's own camera (``gk.camera``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gesturekit.viz.viewer import skeleton_viewer
from tests import app_browser
from tests.browser.test_browser_viewer import _pixels
from tests.viz.test_viz_framing import FILL, speaker

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)


def _row(point, camera: dict, height: int) -> float:
    """The picture row of a world point seen by the page's camera (a look-at camera, vertical fov)."""
    eye, target = np.asarray(camera["position"]), np.asarray(camera["target"])
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(point, dtype=np.float64) - eye
    y = (d @ up) / ((d @ forward) * math.tan(math.radians(camera["fov"]) / 2))
    return (1 - y) / 2 * height


def _characters(page) -> np.ndarray:
    px = _pixels(page)
    page.evaluate("() => gk.showCharacters(false)")
    stage = _pixels(page)
    page.evaluate("() => gk.showCharacters(true)")
    return np.any(px != stage, axis=2)


def test_a_presenter_alone_fills_most_of_the_pages_height_and_the_wheel_zooms_to_the_cursor(tmp_path):
    page_file = tmp_path / "view.html"
    page_file.write_text(skeleton_viewer(speaker(), height=480), encoding="utf-8")
    with app_browser.browser(width=640, height=560) as page:
        page.goto(page_file.as_uri())
        page.wait_for_selector('body[data-drawn="1"]', state="attached")
        body = _characters(page)
        camera = page.evaluate("() => gk.camera")
        h = body.shape[0]
        top = int(np.nonzero(body.any(axis=1))[0].min())
        fill = (_row([0.0, 0.0, 0.0], camera, h) - top) / h
        assert fill >= FILL, f"the upper body fills {fill:.0%} of the height"
        # the full body: the whole person in the picture, feet included
        page.locator("#framing").click()
        page.wait_for_function("() => gk.camera.framing === 'full body'")
        rows = np.nonzero(_characters(page).any(axis=1))[0]
        assert rows.min() > 0 and rows.max() < h - 1 and (rows.max() - rows.min()) / h > 0.7
        # the wheel zooms towards the point under the cursor: with the cursor left of the character, the character
        # (in the middle) moves away from it, to the right; a zoom to the centre would keep it in the middle
        w = body.shape[1]
        centre_before = np.nonzero(_characters(page).any(axis=0))[0].mean()
        box = page.locator("canvas#c").bounding_box()
        before = page.evaluate("() => gk.drawn")
        page.mouse.move(box["x"] + 0.15 * box["width"], box["y"] + 0.5 * box["height"])
        page.mouse.wheel(0, -300)
        page.wait_for_function("(n) => gk.drawn > n", arg=before)
        page.wait_for_timeout(300)
        centre_after = np.nonzero(_characters(page).any(axis=0))[0].mean()
        assert centre_after - centre_before > 0.03 * w
