"""The app in a real browser: Debian's Chromium driven by Playwright against ``streamlit run app/Home.py``.

Skipped, with the reason, where the playwright package or Chromium is missing
(``.ci/run`` installs both). Screenshots of the pages go to
``docs/screenshots`` only when ``GESTUREKIT_SCREENSHOTS=1`` (``python -m
tests.app_browser`` makes them too); otherwise to the test's temporary folder.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path
from urllib.parse import urlparse

import pytest

from tests import app_browser

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """The app on 127.0.0.1 with a fresh home: it builds a one-minute demo database on the first view."""
    home = tmp_path_factory.mktemp("browser_home")
    with app_browser.app_server(home, demo_minutes=1.0) as url:
        yield url, home


def _shots(tmp_path: Path) -> Path:
    if os.environ.get("GESTUREKIT_SCREENSHOTS") == "1":
        return app_browser.REPO / "docs" / "screenshots"
    return tmp_path


def _other_addresses() -> list[str]:
    """This machine's IPv4 addresses other than loopback (empty where it has none)."""
    try:
        infos = socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)
    except OSError:
        return []
    return sorted({i[4][0] for i in infos if not i[4][0].startswith("127.")})


def _assert_what_a_user_sees(page, url: str) -> None:
    """The app's own settings hold (.streamlit/config.toml): local only, a viewer's toolbar."""
    port = urlparse(url).port
    assert page.evaluate("() => location.hostname") == "127.0.0.1"
    for address in _other_addresses():  # bound to 127.0.0.1 alone: not reachable from elsewhere
        with socket.socket() as s:
            s.settimeout(2)
            assert s.connect_ex((address, port)) != 0, f"the app answers on {address}:{port}"
    # no Deploy button; the main menu, if any, has no developer items (rerun, clear cache)
    assert page.locator('[data-testid="stAppDeployButton"]').count() == 0
    menu = page.locator('[data-testid="stMainMenu"]')
    if menu.count():
        menu.first.click()
        popover = page.locator('[data-testid="stMainMenuPopover"]')
        popover.first.wait_for()
        items = popover.first.inner_text()
        for developer in ("Rerun", "Clear cache", "Deploy"):
            assert developer not in items, items
        page.keyboard.press("Escape")


def test_upload_paint_a_control_run_then_inspect(served, tmp_path, machine):
    url, home = served
    wav = app_browser.write_speech(tmp_path / "my speech.wav", seconds=6.0)
    out = _shots(tmp_path)
    out.mkdir(parents=True, exist_ok=True)
    with app_browser.browser() as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        assert (home / "db" / "demo" / "database.json").is_file()  # built by the app on the first view
        _assert_what_a_user_sees(page, url)
        app_browser.upload(page, wav)
        main = app_browser.main_area(page)
        assert main.get_by_text("WAV (PCM_16), 16000 Hz, 1 channel, 6.00 s").count() == 1

        # a control range painted by dragging in the timeline's lane: it appears there, at its level
        app_browser.paint_range(page, "both_hands", 0.25, 0.6)
        assert [r[:2] for r in app_browser.timeline_ranges(page)] == [("both_hands", "high")]

        app_browser.run_and_wait(page)
        # the 3D view has drawn on a canvas of real size, and plays; the wrist plot has its four rows
        canvas = app_browser.skeleton_canvas(page, "synth.skeleton")
        box = canvas.bounding_box()
        assert box["width"] > 200 and box["height"] > 200
        assert canvas.get_attribute("data-frame") == "0"
        view = app_browser.viewer_locator(page, "synth.skeleton")
        view.locator("#play").click()
        # playing: the view draws later frames (times out, and fails, if it stays on frame 0)
        view.locator('canvas#c:not([data-frame="0"])').wait_for(state="attached")
        # a rerun that shows the same result keeps the drawn view: the same scene, not built again
        shown = app_browser.viewer_frame(page, "synth.skeleton")
        shown.evaluate("() => { window.__kept = window.gk; }")
        main.get_by_role("heading", name="Synthesize", exact=True).first.click()  # the keys go to the app
        with app_browser.run_after(page):
            page.keyboard.press("r")  # Streamlit's rerun key
        assert shown.evaluate("() => window.gk === window.__kept && document.body.dataset.drawn === '1'")
        wrists = app_browser.keyed(page, "synth.wrists")
        for row in ("left wrist height", "right wrist height", "left wrist speed", "right wrist speed"):
            assert wrists.locator("text", has_text=row).count() >= 1
        assert main.get_by_text("controls:").count() >= 1
        for kind, label in (
            ("npz", "Motion + search (npz)"),
            ("bvh", "Motion (BVH)"),
            ("csv", "Control track (CSV)"),
            ("json", "Config (JSON)"),
        ):
            assert app_browser.keyed(page, f"synth.download_{kind}").get_by_role("button", name=label).count() == 1
        assert app_browser.problems(page) == []
        app_browser.screenshot(page, out / "browser_synthesize.png")

        # the inspector sees this session's result (state kept across pages)
        app_browser.go_to(page, "Retrieval inspector")
        main.get_by_text("Step 0").first.wait_for()
        app_browser.skeleton_canvas(page, "inspect.views")
        assert app_browser.problems(page) == []
        app_browser.screenshot(page, out / "browser_inspector.png")
    assert (out / "browser_synthesize.png").stat().st_size > 10_000
    if machine is not None:  # it ran on a busy machine: the busy loops took their part throughout
        assert machine.share() > 0.1, machine.share()


def test_a_file_that_is_not_audio_is_an_error_message(served, tmp_path):
    url, _ = served
    bad = tmp_path / "notes.wav"
    bad.write_bytes(b"these are notes, not sound" * 40)
    with app_browser.browser() as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        with app_browser.run_after(page):
            app_browser.keyed(page, "synth.upload").locator('input[type="file"]').set_input_files(str(bad))
        alert = app_browser.main_area(page).locator('[data-testid="stAlert"]', has_text="notes.wav")
        assert alert.count() >= 1
        assert app_browser.problems(page) == []
        assert app_browser.button(page, "synth.go").count() == 0
