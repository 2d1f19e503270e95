"""A user's character in the page viewer, in a real browser: drawn in its own colours, playing, and the same
whether its bones fit a byte and hang from one root or not.

Headless Debian Chromium driven by Playwright (``tests/app_browser.py``) opens
:func:`gesturekit.viz.viewer.skeleton_viewer` pages as files; skipped, with the
reason, where either is missing.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gesturekit.character import look
from gesturekit.character.user import read_character
from gesturekit.demo import open_default_database
from gesturekit.motion import Motion
from gesturekit.viz.viewer import read_viewer_data, skeleton_viewer
from tests import app_browser
from tests.browser.test_browser_viewer import _hex, _linear, _pixels, _srgb
from tests.character_rigs import CASES, write_rig

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    """Pages of a motion twice on the VRM 0.x character: as read, and with 260 more root bones (props at the
    floor)."""
    db = open_default_database()
    motion = Motion(db.poses[:4].reshape(-1, 55, 3).astype(np.float32), 15.0, db.joint_presence)
    folder = tmp_path_factory.mktemp("character")
    ch = read_character(write_rig(folder, CASES["vrm0_a"]))
    extra = 260
    many = dataclasses.replace(
        ch,
        names=(*ch.names, *(f"prop{i}" for i in range(extra))),
        parents=np.concatenate([ch.parents, np.full(extra, -1)]),
        rest_rotation=np.concatenate([ch.rest_rotation, np.broadcast_to(np.eye(3), (extra, 3, 3))]),
        rest_position=np.concatenate([ch.rest_position, np.zeros((extra, 3))]),
    )
    out = {}
    for name, who in (("one", ch), ("many", many)):
        path = folder / f"{name}.html"
        # side by side: the second shares the first's mesh
        page = skeleton_viewer([motion, motion], character=who, key=name, labels=["a", "b"])
        path.write_text(page, encoding="utf-8")
        out[name] = path
    return out


def _open(page, path) -> None:
    page.goto(path.as_uri())
    page.wait_for_selector('body[data-drawn="1"]', state="attached")


def test_the_character_is_drawn_in_its_own_colours_and_plays(pages):
    data = read_viewer_data(pages["one"].read_text(encoding="utf-8"))
    assert data["motions"][1]["mesh"]["vertices"] is data["motions"][0]["mesh"]["vertices"]
    albedos = np.asarray(data["motions"][0]["colors"])
    with app_browser.browser(width=800, height=600) as page:
        _open(page, pages["one"])
        first = _pixels(page)
        page.locator("#play").click()
        page.wait_for_function("() => gk.frame >= 20")
        page.locator("#play").click()  # paused: the drawing stays at one frame
        page.wait_for_function("() => !gk.playing")
        later = _pixels(page)
    px = first.reshape(-1, 3).astype(np.float64) / 255.0
    body = px[~np.all(np.abs(px - _hex(look.BACKGROUND)) <= 1 / 255, axis=1)]
    assert 0.03 < len(body) / len(px) < 0.8  # drawn, and framed
    # every drawn pixel is one of the character's colours in the look's Lambert light
    lin, alb = _linear(body), _linear(albedos)
    shade = (lin @ alb.T) / np.sum(alb * alb, axis=1)
    predicted = _srgb(np.clip(shade[:, :, None] * alb[None], 0, 1))
    error = np.abs(predicted - body[:, None]).max(axis=2)
    best = np.argmin(error, axis=1)
    assert (error[np.arange(len(body)), best] <= 2.5 / 255).mean() > 0.99
    # both of its colours show (its clothes and its skin), none of the default body's shirt
    assert len(set(best[error[np.arange(len(body)), best] <= 2.5 / 255])) == len(albedos) == 2
    default = _linear(look.part_colors("blue"))
    fit = (lin @ default.T) / np.sum(default * default, axis=1)
    off = np.abs(_srgb(np.clip(fit[:, :, None] * default[None], 0, 1)) - body[:, None]).max(axis=2).min(axis=1)
    assert (off <= 2.5 / 255).mean() < 0.5
    # the playing page moved the character
    assert np.abs(later.astype(int) - first).sum() > 0


def test_a_character_of_many_bones_and_roots_is_drawn_the_same(pages):
    """Bone indices as 16 bits and a root added above several: the same pixels as the plain character."""
    with app_browser.browser(width=640, height=480) as page:
        _open(page, pages["one"])
        one = _pixels(page)
        _open(page, pages["many"])
        assert page.evaluate("() => gk.frames") > 1
        many = _pixels(page)
    np.testing.assert_array_equal(many, one)


def test_the_app_draws_an_uploaded_character(tmp_path_factory):
    """In the served app: a character uploaded in the sidebar is named there, and the result's 3D view draws it
    (its bones in the view's data, its colours in the view's pixels)."""
    import io

    from PIL import Image

    folder = tmp_path_factory.mktemp("app_character")
    (folder / "home").mkdir()
    rig = write_rig(folder, CASES["vrm0_a"], name="avatar")
    ch = read_character(rig)
    wav = app_browser.write_speech(folder / "talk.wav", seconds=3.0)
    with app_browser.app_server(folder / "home", demo_minutes=1.0) as url, app_browser.browser() as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        side = app_browser.sidebar(page)
        side.get_by_text("Your character", exact=True).first.click()
        with app_browser.run_after(page):
            app_browser.keyed(page, "_gk.character_file.0").locator('input[type="file"]').set_input_files(str(rig))
        side.locator('[data-testid="stAlert"]', has_text=f"{rig.name} is shown").first.wait_for()
        assert "matched by VRM 0.x humanoid" in side.inner_text()
        app_browser.upload(page, wav)
        app_browser.run_and_wait(page)
        data = app_browser.viewer_args(page, "synth.skeleton")
        assert data["motions"][0]["rig"]["names"] == list(ch.names)
        canvas = app_browser.skeleton_canvas(page, "synth.skeleton")
        shot = np.asarray(Image.open(io.BytesIO(canvas.screenshot())).convert("RGB")).reshape(-1, 3) / 255.0
        assert app_browser.problems(page) == []
    body = shot[~np.all(np.abs(shot - _hex(look.BACKGROUND)) <= 2 / 255, axis=1)]
    assert len(body) > 0.02 * len(shot)
    # the character's colours, lit: most drawn pixels are a multiple of one of its albedos
    alb = _linear(np.asarray(data["motions"][0]["colors"]))
    lin = _linear(body)
    shade = (lin @ alb.T) / np.sum(alb * alb, axis=1)
    error = np.abs(_srgb(np.clip(shade[:, :, None] * alb[None], 0, 1)) - body[:, None]).max(axis=2).min(axis=1)
    assert (error <= 3 / 255).mean() > 0.9
