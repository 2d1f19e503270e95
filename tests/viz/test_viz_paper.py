"""Static figures for a paper: the filmstrip of a result and its alternatives, and print-size export."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest

from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.errors import ConfigError
from gesturekit.viz.figures import wrist_figure
from gesturekit.viz.paper import CSS_PX_PER_MM, figure_bytes, filmstrip_figure
from gesturekit.viz.retrieval import front_view_lines


def _motions():
    return [generate_demo_take(seconds=3.0, seed=s, name="t")[0].motion for s in (1, 2, 3)]


def test_the_filmstrip_shows_each_motion_at_each_time():
    motions = _motions()
    times = [0.0, 1.0, 2.5, 10.0]  # the last lies past the end: the last frame
    fig = filmstrip_figure(motions, times, labels=["result", "k = 1", "k = 2"])
    cells = [t for t in fig.data if t.meta["part"] == "pose"]
    assert len(cells) == 3 * 4
    for t in cells:
        m = motions[t.meta["motion"]]
        f = min(round(t.meta["time"] * 15), m.n_frames - 1)
        assert t.meta["frame"] == f
        x, y = front_view_lines(m.positions[f])
        np.testing.assert_array_equal(np.asarray(t.x, np.float32), x)
        np.testing.assert_array_equal(np.asarray(t.y, np.float32), y)
    names = {a.text for a in fig.layout.annotations}
    assert {"0.00 s", "10.00 s", "result", "k = 2"} <= names
    with pytest.raises(ConfigError, match="times"):
        filmstrip_figure(motions, [])
    with pytest.raises(ConfigError, match="times"):
        filmstrip_figure(motions, [float("nan")])


def test_export_refuses_what_it_cannot_draw():
    fig = filmstrip_figure(_motions()[:1], [1.0])
    with pytest.raises(ConfigError, match="png, svg, pdf"):
        figure_bytes(fig, "gif")
    with pytest.raises(ConfigError, match="positive"):
        figure_bytes(fig, "png", width_mm=0)
    with pytest.raises(ConfigError, match="end after"):
        figure_bytes(fig, "svg", time_range=(3.0, 1.0))


def _kaleido_or_skip():
    try:
        import kaleido  # noqa: F401
    except ImportError:
        pytest.skip("no figure export here: the kaleido package is not installed")


@pytest.mark.slow  # draws in a headless Chromium (a few seconds per file)
def test_the_wrist_figure_exports_at_print_size_zoomed_to_a_range():
    _kaleido_or_skip()
    from PIL import Image

    motions = _motions()[:2]
    fig = wrist_figure(motions, labels=["k-NN", "refined"])
    png = figure_bytes(fig, "png", width_mm=170, height_mm=120, dpi=300, time_range=(1.0, 2.0))
    image = Image.open(io.BytesIO(png))
    # 170 x 120 mm at 300 dpi (to the pixel: the layout's size is whole CSS pixels)
    assert image.size == pytest.approx((170 / 25.4 * 300, 120 / 25.4 * 300), abs=1.5)
    svg = figure_bytes(fig, "svg", width_mm=170, height_mm=120, time_range=(1.0, 2.0)).decode()
    assert svg.startswith("<svg") and f'width="{round(170 * CSS_PX_PER_MM)}"' in svg
    # the time axis's tick labels (text-anchor middle, under the plots)
    ticks = [float(t) for t in re.findall(r'<text text-anchor="middle"[^>]*>([0-9.]+)</text>', svg)]
    assert ticks and min(ticks) >= 1.0 and max(ticks) <= 2.0  # the axis shows the chosen range
    assert fig.layout.xaxis.range[0] == 0  # the figure itself is not changed
    pdf = figure_bytes(filmstrip_figure(motions, [0.5, 1.5]), "pdf", width_mm=85)
    assert pdf.startswith(b"%PDF")
