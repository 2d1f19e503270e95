"""The Retrieval inspector in a real browser: a candidate selected by a click, its ghost and whole clip drawn."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests import app_browser

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

#: The pixel position of point ``i`` of the first trace whose meta matches, in a plotly chart.
_POINT_AT = """(gd, [part, candidate, i]) => {
  const t = gd._fullData.find((d) => d.meta && d.meta.part === part && d.meta.candidate === candidate);
  const xa = gd._fullLayout[t.xaxis.replace('x', 'xaxis')], ya = gd._fullLayout[t.yaxis.replace('y', 'yaxis')];
  const box = gd.getBoundingClientRect();
  return [box.left + xa._offset + xa.l2p(t.x[i]), box.top + ya._offset + ya.l2p(t.y[i])];
}"""

#: The colours of the lines a plotly chart drew (the SVG's strokes), once each.
_STROKES = """(el) => [...new Set([...el.querySelectorAll('.scatterlayer path.js-line')]
  .map((p) => getComputedStyle(p).stroke))]"""


@pytest.fixture(scope="module")
def inspected(tmp_path_factory):
    """The app with a result of 6 s of speech, a page open on the inspector."""
    home = tmp_path_factory.mktemp("inspector_home")
    wav = app_browser.write_speech(home / "speech.wav", seconds=6.0)
    with app_browser.app_server(home, demo_minutes=1.0) as url:
        with app_browser.browser() as page:
            app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
            app_browser.upload(page, wav)
            app_browser.run_and_wait(page)
            app_browser.go_to(page, "Retrieval inspector")
            app_browser.keyed(page, "inspect.candidate_large").locator(".js-plotly-plot").wait_for()
            yield page


def _out(tmp_path: Path) -> Path:
    if os.environ.get("GESTUREKIT_SCREENSHOTS") == "1":
        return app_browser.REPO / "docs" / "screenshots"
    return tmp_path


def test_a_click_in_the_strip_shows_that_candidate_large_over_the_querys_ghost(inspected, tmp_path):
    page = inspected
    large = app_browser.keyed(page, "inspect.candidate_large")
    assert large.locator(".gtitle", has_text="#0 ·").count() == 1  # k = 0: the best is the chosen one
    # the query pose's ghost is drawn (grey) under the candidate's first frame
    assert "rgb(168, 176, 185)" in large.evaluate(_STROKES)
    assert large.locator("text", has_text="the whole database clip: 64 frames").count() == 1

    strip = app_browser.keyed(page, "inspect.strip")
    strip.locator(".js-plotly-plot").scroll_into_view_if_needed()
    x, y = strip.locator(".js-plotly-plot").evaluate(_POINT_AT, ["left wrist path", 2, 0])
    with app_browser.run_after(page):
        page.mouse.click(x, y)
    large.locator(".gtitle", has_text="#2 ·").wait_for()
    assert app_browser.keyed(page, "inspect.candidates_plot").locator("text", has_text="2").count() >= 1
    assert "rgb(168, 176, 185)" in large.evaluate(_STROKES)
    assert app_browser.problems(page) == []
    out = _out(tmp_path)
    out.mkdir(parents=True, exist_ok=True)
    app_browser.screenshot(page, out / "inspector_why.png")
