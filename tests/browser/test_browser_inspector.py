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


def _rgb(hex_colour: str) -> str:
    """``#rrggbb`` as the browser's computed style writes it."""
    r, g, b = (int(hex_colour[i : i + 2], 16) for i in (1, 3, 5))
    return f"rgb({r}, {g}, {b})"


def test_the_chosen_candidate_is_drawn_in_the_palettes_chosen_colour(inspected):
    from gesturekit.character.look import ROLE_SCHEMES, SCHEMES

    page = inspected
    chosen = _rgb(SCHEMES[ROLE_SCHEMES["chosen"]]["shirt"])  # the shirt of the chosen candidate's character
    strip = app_browser.keyed(page, "inspect.strip")
    strip.locator(".js-plotly-plot").first.wait_for()
    assert chosen in strip.evaluate(_STROKES)  # the chosen candidate's first frame among the others
    scatter = app_browser.keyed(page, "inspect.candidates_plot").locator(".js-plotly-plot").first
    ring = scatter.evaluate(
        """(gd) => { const t = gd.querySelectorAll('.scatterlayer .trace');
        const i = gd._fullData.findIndex((d) => d.meta && d.meta.part === 'chosen');
        const p = t[i].querySelector('path.point'); return getComputedStyle(p).stroke; }"""
    )
    assert ring == chosen


def _set(page, key: str, value: str) -> None:
    field = app_browser.keyed(page, key).locator("input")
    with app_browser.run_after(page):
        field.fill(value)
        field.press("Enter")


def _choose(page, key: str, option: str) -> None:
    box = app_browser.keyed(page, key).locator('[data-testid="stSelectbox"] input')
    if box.input_value() == option:
        return
    with app_browser.run_after(page):  # typed, as a user may: the typed text filters the options
        box.click()
        page.keyboard.type(option)
        page.keyboard.press("Enter")


def test_a_figure_exported_from_the_page_downloads_as_an_image_of_the_stated_size(inspected, tmp_path):
    import io
    import xml.etree.ElementTree as ET

    from PIL import Image

    from gesturekit.viz.paper import CSS_PX_PER_MM

    page = inspected
    width_px = round(100 * CSS_PX_PER_MM)  # 100 mm at 96 CSS pixels per inch
    # the figures for a paper come with a comparison of k: the default ks
    compare = app_browser.button(page, "inspect.compare_go")
    compare.scroll_into_view_if_needed()
    with app_browser.run_after(page):
        compare.click()
    app_browser.keyed(page, "_w.inspect.fig_width").locator("input").wait_for()
    _set(page, "_w.inspect.fig_width", "100")
    _set(page, "_w.inspect.fig_dpi", "192")  # twice the CSS pixels
    got = {}
    for fmt in ("PNG", "SVG"):
        _choose(page, "_w.inspect.fig_format", fmt)
        button = app_browser.keyed(page, "inspect.export_wrists").get_by_role("button", name=f"Wrists ({fmt}, 100 mm)")
        button.scroll_into_view_if_needed()
        with page.expect_download() as info:
            button.click()
        download = info.value
        assert download.suggested_filename == f"wrists.{fmt.lower()}"
        path = tmp_path / download.suggested_filename
        download.save_as(path)
        got[fmt] = path.read_bytes()
    with Image.open(io.BytesIO(got["PNG"])) as im:
        assert im.format == "PNG" and im.width == 2 * width_px and im.height > 100
    svg = ET.fromstring(got["SVG"])
    assert svg.tag.endswith("svg") and float(svg.get("width")) == width_px
    assert app_browser.problems(page) == []
