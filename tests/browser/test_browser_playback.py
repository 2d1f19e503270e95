"""Playback in a real browser: an 82 s result's 3D view holds every frame and plays on its speech's clock.

Headless Debian Chromium driven by Playwright against ``streamlit run app/Home.py``
(see ``tests/app_browser.py``); skipped, with the reason, where either is missing.
The speech is the shared BEAT excerpt (82 s) when present, else 82 s of the
generated speaker.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tests import app_browser

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

BEAT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "speech" / "beat_lawrence_0_19_19.wav"
SECONDS = 82.0
FPS = 15

_STATE = """() => { const a = document.getElementById("gk-audio");
  return {frame: gk.frame, frames: gk.frames, playing: gk.playing, drawn: gk.drawn,
          t: a ? a.currentTime : null, paused: a ? a.paused : null, duration: a ? a.duration : null}; }"""


@pytest.fixture(scope="module")
def result_view(tmp_path_factory):
    """The app after a Run on 82 s of speech: yields (page, the result viewer's frame)."""
    home = tmp_path_factory.mktemp("playback_home")
    wav = BEAT if BEAT.is_file() else app_browser.write_speech(home / "speech_82s.wav", seconds=SECONDS)
    with app_browser.app_server(home, demo_minutes=1.0) as url, app_browser.browser() as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        app_browser.upload(page, wav)
        app_browser.run_and_wait(page)
        app_browser.wait_idle(page)
        assert app_browser.problems(page) == []
        yield page, app_browser.viewer_frame(page, "synth.skeleton")


def test_an_82_s_result_holds_all_1230_frames_and_its_speech(result_view):
    _, view = result_view
    state = view.evaluate(_STATE)
    assert state["frames"] == round(SECONDS * FPS) == 1230
    assert state["duration"] == pytest.approx(SECONDS, abs=0.1)  # the speech is in the page
    assert view.locator("#note").inner_text() == ""  # nothing dropped, nothing to say
    assert view.evaluate("() => document.querySelectorAll('audio').length") == 1


def test_play_starts_speech_and_view_together_and_they_stay_within_one_frame(result_view):
    _, view = result_view
    view.locator("#play").click()
    view.wait_for_function("() => gk.playing")
    early = view.evaluate(_STATE)
    assert early["playing"] and not early["paused"]  # one button started both
    # 3 s of the speech's clock later (it runs on the browser's audio clock, busy machine or not)
    view.wait_for_function("(t) => document.getElementById('gk-audio').currentTime >= t", arg=early["t"] + 3.0)
    late = view.evaluate(_STATE)
    view.locator("#play").click()  # pause
    assert not late["paused"]
    # the shown frame is the speech clock's frame, give or take the one being drawn
    assert abs(late["frame"] - math.floor(late["t"] * FPS)) <= 1, late
    assert late["drawn"] - early["drawn"] >= 2.5 * FPS * 0.8  # it drew (nearly) every frame on the way
    assert view.evaluate(_STATE)["paused"]


def test_seeking_either_moves_both(result_view):
    _, view = result_view
    # the slider seeks the speech
    view.evaluate("""() => { const s = document.getElementById("s"); s.value = "600";
                             s.dispatchEvent(new Event("input")); }""")
    state = view.evaluate(_STATE)
    assert state["frame"] == 600 and math.floor(state["t"] * FPS) == 600
    # seeking the speech moves the view (once the speech has seeked: an event of its own)
    view.evaluate("() => { document.getElementById('gk-audio').currentTime = 60.5; }")
    try:
        view.wait_for_function(f"() => gk.frame === {math.floor(60.5 * FPS)}")
    except Exception:  # noqa: BLE001  (a playwright timeout: the assertions below say what was shown)
        pass
    state = view.evaluate(_STATE)
    assert state["frame"] == math.floor(60.5 * FPS) and state["paused"]
    assert view.locator("#s").input_value() == str(state["frame"])
