"""Static figures for a paper: a filmstrip of a result and its alternatives, and print-size export.

:func:`filmstrip_figure` draws poses side by side, one row per motion (the result and
the results of other ``k``) and one column per chosen time, in the front view of
:func:`gesturekit.viz.retrieval.front_view_lines`. :func:`figure_bytes` writes any of
the package's plotly figures (this filmstrip, :func:`gesturekit.viz.figures.wrist_figure`)
as PNG, SVG or PDF at a printed size in millimetres, optionally zoomed to a time range,
so an 82 s wrist plot can be shown over the seconds a reader should look at.

Export uses plotly's static image export (the ``kaleido`` package), which draws in the
system's Chrome or Chromium (Debian's ``chromium`` is found on its own) and needs no
network. Where either is missing, :func:`figure_bytes` raises a
:class:`~gesturekit.errors.ConfigError` that says what to install. :func:`static_image` is the
export itself, with a deadline: on a busy machine the exporter's browser has been seen to start
and then never answer, so an export that has not finished in time is abandoned (its browser
closed) and tried once more, and then reported instead of waiting for ever.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import queue
import signal
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..motion import Motion
from ._plotly import MOTION_COLORS, _motions_and_labels, plotly_safe
from .retrieval import front_view_lines

__all__ = ["FORMATS", "filmstrip_figure", "figure_bytes", "static_image", "CSS_PX_PER_MM", "EXPORT_TIMEOUT_S"]

#: Seconds one static export may take (the browser's start included) before it is abandoned and
#: tried again: a quiet machine takes 2-5 s, one at a load of 12 about 30 s.
EXPORT_TIMEOUT_S = 120.0

#: Formats :func:`figure_bytes` writes: name -> MIME type.
FORMATS = {"png": "image/png", "svg": "image/svg+xml", "pdf": "application/pdf"}

#: CSS pixels per millimetre (96 per inch): the unit of plotly's layout.
CSS_PX_PER_MM = 96 / 25.4


@checks_arguments
def filmstrip_figure(
    motions: Motion | Sequence[Motion],
    times: Sequence[float],
    *,
    labels: Sequence[str] | None = None,
    title: str | None = None,
    cell_px: int = 150,
) -> go.Figure:
    """Poses of several motions at chosen times: one row per motion, one column per time.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        Pelvis-relative joint positions (frames, 55, 3), metres; e.g. the result and the
        results of other ``k`` (:func:`gesturekit.interactive.compare_k`).
    times : sequence of float
        Seconds; each motion shows its frame ``round(t * fps)`` (its last frame past its end).
    labels : sequence of str, optional
        A row name per motion.
    title : str, optional
    cell_px : int
        Pixels of one cell's side.

    Returns
    -------
    plotly.graph_objects.Figure
        One line trace per cell with ``meta = {"part": "pose", "motion": i, "time": t,
        "frame": f}``; every cell has the same equal-aspect range.

    Raises
    ------
    ConfigError
        No motion or no time, a negative or non-finite time, or labels of the wrong length.
    """
    motions, labels = _motions_and_labels(motions, labels, who="filmstrip_figure", label_one=True)
    times = [float(t) for t in times]
    if not times or not all(np.isfinite(t) and t >= 0 for t in times):
        raise ConfigError(f"filmstrip_figure needs one or more times >= 0 seconds, got {times}")
    rows, cols = len(motions), len(times)
    fig = make_subplots(
        rows=rows,
        cols=cols,
        column_titles=[f"{t:.2f} s" for t in times],
        row_titles=[plotly_safe(s) for s in labels],
        horizontal_spacing=0.005,
        vertical_spacing=0.02,
    )
    poses = []
    for i, m in enumerate(motions):
        for j, t in enumerate(times):
            f = min(int(round(t * m.fps)), m.n_frames - 1)
            pose = np.asarray(m.positions[f], dtype=np.float32)
            poses.append(pose)
            x, y = front_view_lines(pose)
            fig.add_trace(
                go.Scatter(
                    x=x,
                    y=y,
                    mode="lines",
                    line=dict(color=MOTION_COLORS[i % len(MOTION_COLORS)], width=2.2),
                    hoverinfo="skip",
                    showlegend=False,
                    meta={"part": "pose", "motion": i, "time": t, "frame": f},
                ),
                row=i + 1,
                col=j + 1,
            )
    allp = np.concatenate([p[:, :2] for p in poses] + [np.zeros((1, 2), np.float32)])
    lo, hi = allp.min(axis=0) - 0.08, allp.max(axis=0) + 0.08
    for k in range(1, rows * cols + 1):
        suffix = "" if k == 1 else str(k)
        fig.layout[f"xaxis{suffix}"].update(range=[float(lo[0]), float(hi[0])], visible=False)
        fig.layout[f"yaxis{suffix}"].update(
            range=[float(lo[1]), float(hi[1])], visible=False, scaleanchor=f"x{suffix}", scaleratio=1
        )
    fig.update_layout(
        title=dict(text=plotly_safe(title)) if title else None,
        height=cell_px * rows + (80 if title else 40),
        width=cell_px * cols + 60,
        margin=dict(l=10, r=40, t=70 if title else 30, b=10),
        plot_bgcolor="#ffffff",
        showlegend=False,
    )
    return fig


@checks_arguments
def figure_bytes(
    fig: go.Figure,
    fmt: str,
    *,
    width_mm: float = 170.0,
    height_mm: float | None = None,
    dpi: int = 300,
    time_range: tuple[float, float] | None = None,
) -> bytes:
    """A figure as a PNG, SVG or PDF file of a printed size.

    Parameters
    ----------
    fig : plotly.graph_objects.Figure
        Not changed (a copy is drawn).
    fmt : {"png", "svg", "pdf"}
    width_mm, height_mm : float
        Printed size in millimetres (170 mm: a two-column page's text width); the height
        defaults to the figure's own height scaled as its width is.
    dpi : int
        Dots per inch of a PNG (SVG and PDF are vector drawings).
    time_range : (float, float), optional
        Seconds: every x axis of a time plot zoomed to it (the wrist figure over 82 s is
        unreadable as a whole in print).

    Returns
    -------
    bytes
        The file.

    Raises
    ------
    ConfigError
        An unknown format, a size or time range that is not positive, or no exporter
        (the ``kaleido`` package, and Chrome or Chromium) on this machine.
    """
    fmt = str(fmt).lower()
    if fmt not in FORMATS:
        raise ConfigError(f"figures are exported as {', '.join(FORMATS)}, not {fmt!r}")
    if not (width_mm > 0 and (height_mm is None or height_mm > 0) and 30 <= int(dpi) <= 1200):
        raise ConfigError(
            f"a figure's size must be positive and its dpi in 30..1200, got {width_mm}, {height_mm}, {dpi}"
        )
    out = go.Figure(fig)
    own_w = fig.layout.width or 1000
    own_h = fig.layout.height or 450
    width = int(round(width_mm * CSS_PX_PER_MM))
    height = int(round(height_mm * CSS_PX_PER_MM)) if height_mm is not None else int(round(own_h * width / own_w))
    if time_range is not None:
        a, b = (float(v) for v in time_range)
        if not (np.isfinite(a) and np.isfinite(b) and b > a):
            raise ConfigError(f"a time range must end after it starts, got {time_range}")
        out.update_xaxes(range=[a, b], autorange=False)
    out.update_layout(width=width, height=height)
    scale = int(dpi) / 96 if fmt == "png" else 1.0
    return static_image(out, fmt, width=width, height=height, scale=scale)


def _in_own_loop(make: Any) -> Any:
    """``asyncio.run(make())`` in a thread of its own (the caller may be inside a running loop:
    a notebook); its exception is raised here."""
    box: queue.Queue[tuple[bool, Any]] = queue.Queue(maxsize=1)

    def run() -> None:
        try:
            box.put((True, asyncio.run(make())))
        except BaseException as exc:  # handed to the caller, who raises it
            box.put((False, exc))

    worker = threading.Thread(target=run, name="gesturekit-figure-export", daemon=True)
    worker.start()
    worker.join()
    ok, value = box.get()
    if not ok:
        raise value
    return value


def _processes() -> dict[int, int]:
    """Process id -> parent's id, from Linux's /proc (empty elsewhere)."""
    parent: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
            parent[int(stat.parent.name)] = int(text[text.rindex(")") + 2 :].split()[1])
        except (OSError, ValueError, IndexError):
            continue  # a process that ended meanwhile
    return parent


def _below(root: int, parent: dict[int, int]) -> set[int]:
    """The descendants of process ``root``."""
    found, todo = set(), [root]
    while todo:
        pid = todo.pop()
        kids = [c for c, p in parent.items() if p == pid and c not in found]
        found.update(kids)
        todo.extend(kids)
    return found


def _end_browsers(known: set[int]) -> None:
    """Kill the browsers an abandoned export left running: this process's descendants that were not
    in ``known``, started by kaleido's browser driver (choreographer), and everything under them.
    Other new children (another thread's work) are left alone."""
    parent = _processes()
    doomed: set[int] = set()
    for pid in _below(os.getpid(), parent) - known:
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        if b"choreographer" in command:
            doomed |= {pid} | _below(pid, parent)
    for pid in doomed:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)


@checks_arguments
def static_image(
    fig: go.Figure,
    fmt: str,
    *,
    width: int,
    height: int,
    scale: float = 1.0,
    timeout_s: float = EXPORT_TIMEOUT_S,
    attempts: int = 2,
) -> bytes:
    """A plotly figure as PNG, SVG or PDF bytes, drawn by kaleido, with a deadline.

    Parameters
    ----------
    fig : plotly.graph_objects.Figure
    fmt : {"png", "svg", "pdf"}
    width, height : int
        CSS pixels of the drawing.
    scale : float
        Pixels of a PNG per CSS pixel.
    timeout_s : float
        Seconds one try may take, the browser's start included; a try that takes longer is
        cancelled, which closes its browser.
    attempts : int
        Tries before giving up.

    Returns
    -------
    bytes
        The file.

    Raises
    ------
    ConfigError
        No kaleido or no browser, a drawing that failed, or ``attempts`` tries that each ran
        past ``timeout_s``.
    """
    if fmt not in FORMATS:
        raise ConfigError(f"figures are exported as {', '.join(FORMATS)}, not {fmt!r}")
    if not (timeout_s > 0 and attempts >= 1):
        raise ConfigError(f"an export needs a positive deadline and at least one try, got {timeout_s}, {attempts}")
    try:
        import kaleido
    except ImportError:
        raise ConfigError("exporting a figure needs the kaleido package: pip install 'kaleido>=1'") from None
    spec = fig.to_dict()
    opts = {"format": fmt, "width": int(width), "height": int(height), "scale": float(scale)}

    # no MathJax: kaleido's page would load it from a CDN (nothing is fetched at run time; no figure
    # of ours has TeX), and on a machine without a network that script tag can hold the page back
    kopts = {"mathjax": False}

    async def once() -> bytes:
        return await asyncio.wait_for(kaleido.calc_fig(spec, opts=opts, kopts=kopts), timeout_s)

    for _ in range(int(attempts)):
        before = _below(os.getpid(), _processes())
        start = time.monotonic()
        try:
            return bytes(_in_own_loop(once))
        except Exception as exc:  # kaleido's own errors (no browser, a failed drawing) have no common base
            if isinstance(exc, (TimeoutError, asyncio.TimeoutError)) or time.monotonic() - start >= timeout_s:
                # a browser that never answered (cancelled, it may say it "closed"): end what it left
                # running, and try a new one
                _end_browsers(before)
                continue
            raise ConfigError(
                f"could not draw the figure as {fmt.upper()}: {exc}. The export draws in Chrome or Chromium "
                "(apt-get install chromium, or set BROWSER_PATH to a Chrome)"
            ) from exc
    raise ConfigError(
        f"drawing the figure as {fmt.upper()} did not finish in {timeout_s:.0f} s, {int(attempts)} times; "
        "the machine may be very busy: try again"
    )
