"""Live without a microphone, in a real browser: the page says so in its words; a file plays through Live."""

from __future__ import annotations

import pytest

from tests import app_browser
from tests.waits import patience

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)


def test_without_a_microphone_the_page_says_so_and_a_file_plays_through_live(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    # long enough to be still playing when a busy machine's browser first draws the body: the test
    # ends it with Stop once it has what it needs, so a quiet machine does not wait for its end
    wav = app_browser.write_speech(tmp_path / "talk.wav", seconds=40.0)
    with app_browser.app_server(home, demo_minutes=1.0) as url:
        with app_browser.browser() as page:  # headless Chromium with no capture device
            app_browser.open_app(page, url, "Live", heading="Live")
            main = app_browser.main_area(page)
            main.get_by_text("No microphone was found").wait_for()
            assert "NotFoundError" not in main.inner_text()
            assert app_browser.keyed(page, "live.mic").count() == 0  # no Start that would fail
            with app_browser.run_after(page):
                app_browser.keyed(page, "live.file").locator('input[type="file"]').set_input_files(str(wav))
            with app_browser.run_after(page):
                app_browser.button(page, "live.file_go").click()
            # the body moves with the file's speech; a control switches while it plays
            app_browser.skeleton_canvas(page, "live.skeleton")
            app_browser.button(page, "live.control.right_hand=high").click()
            held = app_browser.keyed(page, "live.control.right_hand=high")
            held.locator('[data-testid="stBaseButton-primary"]').wait_for(timeout=patience(120) * 1000)
            # Stop ends the file's play, and the performance is kept, with its downloads
            app_browser.button(page, "live.stop").click()
            app_browser.keyed(page, "live.download_wav").wait_for(timeout=patience(300) * 1000)
            assert app_browser.problems(page) == []
