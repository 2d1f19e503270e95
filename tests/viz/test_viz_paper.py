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


def test_an_export_that_does_not_finish_in_time_is_tried_again(monkeypatch):
    """kaleido is replaced by a stand-in whose first drawing never finishes, the way a browser that
    started but never answered left a busy CI machine waiting: the second try's bytes come back."""
    import asyncio

    import kaleido
    import plotly.graph_objects as go

    from gesturekit.viz.paper import static_image

    calls = []

    async def calc_fig(spec, opts=None, *, topojson=None, kopts=None):
        calls.append((opts, kopts))
        if len(calls) == 1:
            await asyncio.sleep(3600)
        return b"drawn"

    monkeypatch.setattr(kaleido, "calc_fig", calc_fig)
    fig = go.Figure(go.Scatter(x=[0, 1], y=[1, 0]))
    assert static_image(fig, "png", width=300, height=200, scale=2, timeout_s=0.3) == b"drawn"
    assert len(calls) == 2
    assert calls[0][0] == {"format": "png", "width": 300, "height": 200, "scale": 2.0}
    assert calls[0][1] == {"mathjax": False}  # nothing fetched from a CDN
    calls.clear()
    with pytest.raises(ConfigError, match=r"did not finish in 0 s, 1 times"):
        static_image(fig, "png", width=300, height=200, timeout_s=0.3, attempts=1)


@pytest.mark.slow  # two tries of 1.5 s
def test_a_browser_that_never_answers_is_ended_and_reported(tmp_path, monkeypatch):
    """A real kaleido driving a 'browser' that starts and never speaks: the export gives up with our
    error after its tries, and leaves no process of that browser running."""
    import os
    from pathlib import Path

    import plotly.graph_objects as go

    from gesturekit.viz.paper import static_image

    if not Path("/proc/self/stat").is_file():
        pytest.skip("finding the abandoned browser's processes reads Linux's /proc")
    pids = tmp_path / "pids"
    fake = tmp_path / "chromium"
    fake.write_text(f'#!/bin/sh\necho $$ >> "{pids}"\nexec sleep 600\n')
    fake.chmod(0o755)
    monkeypatch.setenv("BROWSER_PATH", str(fake))
    fig = go.Figure(go.Scatter(x=[0, 1], y=[1, 0]))
    with pytest.raises(ConfigError, match=r"did not finish in 2 s, 2 times"):
        static_image(fig, "png", width=300, height=200, timeout_s=1.5)
    started = [int(p) for p in pids.read_text().split()]
    assert len(started) == 2  # one browser per try

    def running(pid: int) -> bool:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            return False
        return state != "Z"

    from tests.waits import wait_until

    wait_until(lambda: not any(running(p) for p in started), what="the abandoned browsers end", timeout_s=30)
    assert os.getpid() not in started
