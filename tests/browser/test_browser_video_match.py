"""The page and the MP4 show one picture: a screenshot of the viewer and the MP4's frame at the same time overlap.

Two demo-database motions side by side are rendered to an MP4 (:func:`gesturekit.export.video.render_video`)
and shown in the viewer's page (:func:`gesturekit.viz.viewer.skeleton_viewer`, three.js) in headless Debian
Chromium driven by Playwright (see ``tests/app_browser.py``; skipped, with the reason, where either is
missing). The page is seeked to a time, its drawing screenshotted; the MP4's frame at that time is decoded
with imageio-ffmpeg. Their silhouettes (pixels not of the background) are compared after scaling to one
size.
"""

from __future__ import annotations

import io

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from gesturekit.character import look
from gesturekit.character.look import BACKGROUND
from gesturekit.demo import open_default_database
from gesturekit.export.video import render_video
from gesturekit.motion import Motion
from tests import app_browser

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

#: The MP4's size, pixels; the page's drawing is as large in CSS pixels, at a device pixel ratio of 1.
WIDTH, HEIGHT = 640, 480
BG = np.array([int(BACKGROUND[i : i + 2], 16) for i in (1, 3, 5)])

_PAINTED = "() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))"


def silhouette(image: np.ndarray) -> np.ndarray:
    """Pixels clearly not of the background (H.264's coding noise and edge blur stay below the bar)."""
    return np.abs(image[..., :3].astype(int) - BG).sum(axis=-1) > 40


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def to_size(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """An RGB picture scaled to (width, height)."""
    if image.shape[1::-1] == size:
        return image
    return np.asarray(Image.fromarray(image[..., :3]).resize(size, Image.Resampling.BILINEAR))


@pytest.fixture(scope="module")
def pair() -> list[Motion]:
    """Two demo-database clips, side by side (about 4 s each)."""
    db = open_default_database()
    clips = np.asarray(db.poses).reshape(len(db.poses), -1, 55, 3)
    return [Motion(clips[k], db.fps, db.joint_presence) for k in (3, 7)]


def mp4_frame(path, index: int) -> np.ndarray:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    try:
        for i, data in enumerate(reader):
            if i == index:
                return np.frombuffer(data, np.uint8).reshape(h, w, 3).copy()
    finally:
        reader.close()
    raise AssertionError(f"the MP4 has no frame {index}")


def test_a_screenshot_of_the_page_and_the_mp4_frame_overlap(pair, tmp_path):
    from gesturekit.viz.viewer import read_viewer_data, skeleton_viewer

    fps = pair[0].fps
    # no labels on either: the characters are compared, not two fonts
    page_file = tmp_path / "view.html"
    page_file.write_text(skeleton_viewer(pair, labels=("", ""), height=HEIGHT, key="match"), encoding="utf-8")
    # side by side, the page's drawing is no higher than the characters fill: the MP4 is made as large (even)
    high = look.fitted_height(
        read_viewer_data(page_file.read_text(encoding="utf-8"))["boxes"][look.UPPER_BODY], WIDTH, HEIGHT
    )
    high -= high % 2
    page_file.write_text(skeleton_viewer(pair, labels=("", ""), height=high, key="match"), encoding="utf-8")
    video = render_video(tmp_path / "pair.mp4", pair[0], side_by_side=pair[1], resolution=(WIDTH, high))
    with app_browser.browser(width=WIDTH, height=HEIGHT + 200) as page:
        page.goto(page_file.as_uri())
        page.locator('body[data-drawn="1"]').wait_for(state="attached")
        assert page.evaluate("() => window.devicePixelRatio") == 1
        for t in (0.0, 1.5, 3.2):
            k = int(np.floor(t * fps + 1e-6))  # the frame both show at time t
            shown = page.evaluate(
                """(k) => { const s = document.getElementById("s"); s.value = String(k);
                s.dispatchEvent(new Event("input")); return gk.frame; }""",
                k,
            )
            assert shown == k
            page.evaluate(_PAINTED)
            canvas = page.locator("canvas#c")
            shot = np.asarray(Image.open(io.BytesIO(canvas.screenshot(type="png"))).convert("RGB"))
            frame = mp4_frame(video, k)
            a, b = silhouette(to_size(shot, (WIDTH, high))), silhouette(frame)
            assert b.sum() > 0.02 * b.size, "the MP4 frame shows (almost) nothing"
            assert a.sum() > 0.02 * a.size, "the page shows (almost) nothing: is WebGL drawing?"
            overlap = iou(a, b)
            assert overlap >= 0.9, (t, overlap)
            # and the colours: the same shading, up to H.264's coding and three.js's per-pixel lighting
            both = a & b
            assert np.abs(to_size(shot, (WIDTH, high)).astype(int) - frame)[both].mean() < 15
