"""The app on a laptop's window (1280 x 800): no label cut off, every 3D view framed as a presenter.

After a synthesis run (so that every download exists), each page is drawn at 1280 x 800 and

- every select box's shown text and every download button's label is whole: no element of it is wider
  inside than it is shown (``scrollWidth`` over ``clientWidth``, where an ellipsis cuts the text), and a select
  box shows the whole text of its chosen option;
- the Synthesize page's side-by-side characters and the inspector's candidate fill most of their 3D view's
  height: from the characters' topmost pixel down to their pelvis, as the MP4's test measures it
  (tests/viz/test_viz_framing.py); the character's pixels are those that differ from the stage drawn alone
  (``gk.showCharacters``) in the view's screenshot.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests import app_browser
from tests.browser.test_browser_framing import _row
from tests.viz.test_viz_framing import FILL

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"),
]

LAPTOP = (1280, 800)


#: Each select box's, plot text's and download button's text and whether it is cut: a select box shows its chosen
#: option's whole text in its input (wider inside than shown: cut), a plot its titles and notes inside its box, a
#: download button its label (an element of it wider inside than shown).
_CUT_TEXT = """() => {
  const wider = (e) => e.clientWidth > 0 && e.scrollWidth > e.clientWidth + 1;
  const main = document.querySelector('[data-testid="stApp"]') || document.body;
  const out = [];
  for (const box of main.querySelectorAll('[data-testid="stSelectbox"]')) {
    const input = box.querySelector('input[role="combobox"]');
    if (!input || !input.offsetParent) continue;  // not shown (a closed expander)
    out.push({kind: "select box", label: box.querySelector("label")?.innerText.trim() || "", text: input.value,
              cut: wider(input)});
  }
  for (const plot of main.querySelectorAll('.js-plotly-plot')) {  // a plot's titles and notes inside its box
    if (!plot.offsetParent) continue;
    const box = plot.getBoundingClientRect();
    for (const t of plot.querySelectorAll('g.annotation-text-g, text.gtitle, text.xtitle, text.ytitle')) {
      const r = t.getBoundingClientRect();
      if (!r.width) continue;
      out.push({kind: "plot text", label: t.textContent.trim().slice(0, 60), text: t.textContent.trim(),
                cut: r.left < box.left - 1 || r.right > box.right + 1 || r.top < box.top - 1});
    }
  }
  for (const b of main.querySelectorAll('[data-testid="stDownloadButton"] button')) {
    if (!b.offsetParent) continue;
    out.push({kind: "download", label: b.innerText.trim(), text: b.innerText.trim(),
              cut: [b, ...b.querySelectorAll("*")].some(wider)});
  }
  return out;
}"""


def _texts(page) -> list[dict]:
    app_browser.wait_idle(page)
    return page.evaluate(_CUT_TEXT)


def _fill(page, key: str) -> float:
    """The share of the 3D view ``key``'s height from its characters' topmost pixel down to where their pelvis
    projects through the view's own camera (``gk.camera``), as tests/viz/test_viz_framing.py measures the MP4."""
    view = app_browser.viewer_frame(page, key)
    app_browser.viewer(page, key).scroll_into_view_if_needed()
    shots = []
    for visible in ("true", "false"):
        view.evaluate(f"() => gk.showCharacters({visible})")
        view.evaluate(app_browser._PAINTED)
        shots.append(np.asarray(_image(view.locator("canvas#c").screenshot(type="png"))))
    view.evaluate("() => gk.showCharacters(true)")
    body = np.any(np.abs(shots[0].astype(int) - shots[1].astype(int)) > 8, axis=2)
    rows = np.nonzero(body.any(axis=1))[0]
    assert len(rows), f"no character drawn in {key}"
    camera = view.evaluate("() => gk.camera")
    offsets = [m["offset"] for m in app_browser.viewer_args(page, key)["motions"]]
    pelvis = max(_row([dx, 0.0, 0.0], camera, body.shape[0]) for dx in offsets)
    return (pelvis - rows.min()) / body.shape[0]


def _image(png: bytes):
    import io

    from PIL import Image

    return Image.open(io.BytesIO(png)).convert("RGB")


@pytest.fixture(scope="module")
def laptop(tmp_path_factory):
    """The app at 1280 x 800 with a result of 8 s of speech (refined: k-NN and refined side by side)."""
    home = tmp_path_factory.mktemp("laptop_home")
    wav = app_browser.write_speech(home / "speech.wav", seconds=8.0)
    with app_browser.app_server(home, demo_minutes=1.0) as url, app_browser.browser(width=1280, height=800) as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        app_browser.upload(page, wav)
        app_browser.run_and_wait(page)
        app_browser.wait_idle(page)
        yield page


def test_no_select_box_plot_text_nor_download_label_is_cut_on_any_page(laptop):
    page = laptop
    seen: dict[str, list[dict]] = {}
    for i, title in enumerate(app_browser.APP_PAGES):
        if i:
            app_browser.go_to(page, title, heading_text="gesturekit" if title == "Home" else None)
        page.set_viewport_size({"width": LAPTOP[0], "height": LAPTOP[1]})
        texts = _texts(page)
        seen[title] = texts
        cut = [t for t in texts if t["cut"]]
        assert not cut, f"cut off on {title} at {LAPTOP[0]}x{LAPTOP[1]}: {cut}"
    # the pages that have them were looked at: the sidebar's database box on every page, downloads after a run
    # the pages that have them were looked at: the sidebar's database box (every page but the study's, which reads
    # a study's folder), the settings' choices, the candidate box, the downloads after a run
    has = {p: {t["label"] for t in seen[p]} for p in seen}
    assert all("Database" in has[p] for p in seen if p != "Study")
    assert {"Initial pose", "Blending", "A control must hold at"} <= has["Synthesize"]
    assert "Candidate" in has["Retrieval inspector"] and "Clips of" in has["Database"]
    assert any(t["kind"] == "plot text" and "wrist paths" in t["text"] for t in seen["Retrieval inspector"])
    assert sum(t["kind"] == "download" for t in seen["Synthesize"]) == 6  # every file of the result but the MP4


def test_side_by_side_and_the_inspectors_candidate_fill_most_of_their_views_height(laptop):
    page = laptop
    app_browser.go_to(page, "Synthesize")
    page.set_viewport_size({"width": LAPTOP[0], "height": LAPTOP[1]})
    assert len(app_browser.viewer_args(page, "synth.skeleton")["motions"]) == 2  # k-NN and refined
    side_by_side = _fill(page, "synth.skeleton")
    app_browser.go_to(page, "Retrieval inspector")
    page.set_viewport_size({"width": LAPTOP[0], "height": LAPTOP[1]})
    alone = _fill(page, "inspect.views")
    print(f"upper body over the view's height at {LAPTOP}: side by side {side_by_side:.0%}, inspector {alone:.0%}")
    assert side_by_side >= FILL and alone >= FILL, (side_by_side, alone)
