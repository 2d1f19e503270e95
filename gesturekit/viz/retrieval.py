"""Why a clip was chosen: a search step's candidates drawn the way the paper's figures draw them.

A step of the search compares each database window's first frame with the query pose
``p_{t-1}`` (the last frame of the previous step's window) and its speech with the
step's speech. These figures put those things on screen, in the front view (X to the
right, Y up, metres; the character faces the viewer, so its left hand is on the right):

- :func:`candidate_figure`: one candidate large. Left, its window's first frame with
  the query pose as a grey ghost over it (their difference is the pose distance) and
  the wrist paths over the step. Right, its whole 64-frame database clip as a filmstrip
  with the window's frames in colour, and under it the clip's own speech with the
  window shaded, beside the step's input speech drawn over the window's time.
- :func:`candidates_strip`: every candidate small, side by side, each with the same
  ghost and wrist paths, the chosen one and the selected one marked.

Both return a :class:`plotly.graph_objects.Figure` and import nothing from streamlit.
Every trace carries ``meta = {"part": ..., "candidate": position}`` so pages and tests
find what they show; clicking a candidate's wrist markers selects it on a page
(``customdata`` holds its position in the combined ranking).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..motion import AUDIO_SR
from ..skeleton import BODY_JOINTS, N_JOINTS, joint_index
from ._plotly import ROLE_COLORS, plotly_safe
from .candidate_view import CandidateView

__all__ = [
    "CandidateView",
    "CHOSEN_COLOR",
    "SELECTED_COLOR",
    "OTHER_COLOR",
    "GHOST_COLOR",
    "front_view_lines",
    "candidate_figure",
    "candidates_strip",
]

#: The chosen candidate, in every view and figure: the palette's "chosen" role (gold, as its character's shirt).
CHOSEN_COLOR = ROLE_COLORS["chosen"]
#: The candidate selected for a closer look (when it is not the chosen one): the app's first motion colour.
SELECTED_COLOR = "#2c5d8f"
#: Every other candidate, as the candidates' scatter draws them.
OTHER_COLOR = "#6b7f99"
#: The query pose ``p_{t-1}`` drawn behind a candidate.
GHOST_COLOR = "#a8b0b9"
#: Frames of the clip outside the window in the filmstrip.
_OUTSIDE_COLOR = "#c5cad0"

_LEFT_WRIST, _RIGHT_WRIST = joint_index("left_wrist"), joint_index("right_wrist")
#: Where a hand is drawn to from its wrist (a simplified hand: the middle finger's tip).
_HAND_TIPS = ((_LEFT_WRIST, joint_index("left_middle4")), (_RIGHT_WRIST, joint_index("right_middle4")))


@checks_arguments
def front_view_lines(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pose's body seen from the front, as one polyline broken by NaN.

    The body bones (spine, head, collars, arms) from the pelvis (the origin) up, and a
    line from each wrist to its middle fingertip for the hand.

    Parameters
    ----------
    pose : np.ndarray, shape (55, 3)
        Pelvis-relative joint positions, metres.

    Returns
    -------
    (x, y) : np.ndarray, each shape (points,), float32
        X (the character's left is +X) and Y (up), metres, NaN between lines.
    """
    p = np.asarray(pose, dtype=np.float32)
    if p.shape != (N_JOINTS, 3):
        raise ConfigError(f"a pose must have shape ({N_JOINTS}, 3), got {p.shape}")
    xs: list[float] = []
    ys: list[float] = []
    origin = np.zeros(3, np.float32)
    names = [n for n, _ in BODY_JOINTS]
    for name, parent in BODY_JOINTS:
        a = origin if parent is None else p[names.index(parent)]
        b = p[names.index(name)]
        xs += [float(a[0]), float(b[0]), np.nan]
        ys += [float(a[1]), float(b[1]), np.nan]
    for side in ("left", "right"):  # forearm: elbow -> wrist
        a, b = p[joint_index(f"{side}_elbow")], p[joint_index(f"{side}_wrist")]
        xs += [float(a[0]), float(b[0]), np.nan]
        ys += [float(a[1]), float(b[1]), np.nan]
    for w, tip in _HAND_TIPS:
        xs += [float(p[w, 0]), float(p[tip, 0]), np.nan]
        ys += [float(p[w, 1]), float(p[tip, 1]), np.nan]
    return np.asarray(xs, np.float32), np.asarray(ys, np.float32)


def _color(view: CandidateView, selected: int | None) -> str:
    if view.chosen:
        return CHOSEN_COLOR
    return SELECTED_COLOR if view.position == selected else OTHER_COLOR


def _pose_panel(
    fig: go.Figure,
    view: CandidateView,
    query: np.ndarray | None,
    *,
    row: int,
    col: int,
    color: str,
    width: float,
    marker: int,
) -> None:
    """Ghost, first frame, wrist paths and clickable wrist markers of one candidate in one subplot."""
    meta = {"candidate": int(view.position)}
    if query is not None:
        gx, gy = front_view_lines(query)
        fig.add_trace(
            go.Scatter(
                x=gx,
                y=gy,
                mode="lines",
                line=dict(color=GHOST_COLOR, width=width + 2),
                opacity=0.75,
                hoverinfo="skip",
                showlegend=False,
                meta={**meta, "part": "ghost"},
            ),
            row=row,
            col=col,
        )
    window = view.window
    x, y = front_view_lines(window[0])
    fig.add_trace(
        go.Scatter(
            x=x,
            y=y,
            mode="lines",
            line=dict(color=color, width=width),
            hoverinfo="skip",
            showlegend=False,
            meta={**meta, "part": "first frame"},
        ),
        row=row,
        col=col,
    )
    for side, w, dash in (("left", _LEFT_WRIST, "solid"), ("right", _RIGHT_WRIST, "dot")):
        path = window[:, w]
        fig.add_trace(
            go.Scatter(
                x=path[:, 0],
                y=path[:, 1],
                mode="lines+markers",
                line=dict(color=color, width=max(1.0, width - 0.5), dash=dash),
                marker=dict(size=[marker] + [max(3, marker // 2)] * (len(path) - 1), color=color, symbol="circle"),
                customdata=np.full((len(path), 1), int(view.position)),
                hovertemplate=(
                    f"#{view.position}: {side} wrist over the step<br>frame %{{pointNumber}} of the window"
                    "<extra></extra>"
                ),
                showlegend=False,
                meta={**meta, "part": f"{side} wrist path"},
            ),
            row=row,
            col=col,
        )


def _pose_axes(fig: go.Figure, views: Sequence[CandidateView], query: np.ndarray | None, *, n_axes: int) -> None:
    """The same equal-aspect front-view range in the first ``n_axes`` subplots, so sizes compare across them."""
    pts = [np.asarray(v.window[:, :, :2]).reshape(-1, 2) for v in views]
    if query is not None:
        pts.append(np.asarray(query)[:, :2])
    allp = np.concatenate(pts + [np.zeros((1, 2), np.float32)])
    lo, hi = allp.min(axis=0) - 0.08, allp.max(axis=0) + 0.08
    for i in range(1, n_axes + 1):
        suffix = "" if i == 1 else str(i)
        fig.layout[f"xaxis{suffix}"].update(range=[float(lo[0]), float(hi[0])], visible=False)
        fig.layout[f"yaxis{suffix}"].update(
            range=[float(lo[1]), float(hi[1])], visible=False, scaleanchor=f"x{suffix}", scaleratio=1
        )


@checks_arguments
def candidates_strip(
    views: Sequence[CandidateView],
    query: np.ndarray | None,
    *,
    selected: int | None = None,
    per_row: int = 5,
    row_height: int = 210,
) -> go.Figure:
    """Every candidate of a step small, side by side: first frame over the query's ghost, wrist paths.

    Parameters
    ----------
    views : sequence of CandidateView
        The candidates, best first.
    query : np.ndarray, shape (55, 3), optional
        The query pose ``p_{t-1}`` (pelvis-relative, metres); None draws no ghost.
    selected : int, optional
        Position of the candidate selected for a closer look (drawn in
        :data:`SELECTED_COLOR` unless it is the chosen one, which is :data:`CHOSEN_COLOR`).
    per_row : int
        Candidates per row (more rows for more candidates).
    row_height : int
        Pixels per row of candidates.

    Returns
    -------
    plotly.graph_objects.Figure
        One subplot per candidate, rows of ``per_row``, titled ``#position`` with its distances; traces with
        ``meta["part"]`` in ``"ghost"``, ``"first frame"``, ``"left wrist path"``, ``"right
        wrist path"`` and ``meta["candidate"]`` its position.

    Raises
    ------
    ConfigError
        No candidate, or a query pose of the wrong shape.
    """
    views = list(views)
    if not views:
        raise ConfigError("candidates_strip needs at least one candidate")
    if int(per_row) < 1 or int(row_height) < 1:
        raise ConfigError(f"candidates_strip needs per_row and row_height >= 1, got {per_row} and {row_height}")
    query = _checked_query(query)
    titles = [
        f"<b>#{v.position}</b>{' chosen' if v.chosen else ''}<br>pose {v.pose_dist:.2f} · audio {v.audio_dist:.3f}"
        for v in views
    ]
    n_cols = min(len(views), per_row)
    n_rows = -(-len(views) // n_cols)
    fig = make_subplots(
        rows=n_rows, cols=n_cols, subplot_titles=titles, horizontal_spacing=0.01, vertical_spacing=0.12 / n_rows
    )
    for i, v in enumerate(views):
        row, col = divmod(i, n_cols)
        _pose_panel(fig, v, query, row=row + 1, col=col + 1, color=_color(v, selected), width=2.0, marker=9)
    _pose_axes(fig, views, query, n_axes=len(views))
    for a in fig.layout.annotations:
        a.font = dict(size=12)
    fig.update_layout(
        height=row_height * n_rows,
        margin=dict(l=4, r=4, t=44, b=4),
        showlegend=False,
        plot_bgcolor="#ffffff",
        clickmode="event+select",
    )
    return fig


def _checked_query(query: np.ndarray | None) -> np.ndarray | None:
    if query is None:
        return None
    q = np.asarray(query, dtype=np.float32)
    if q.shape != (N_JOINTS, 3):
        raise ConfigError(f"the query pose must have shape ({N_JOINTS}, 3), got {q.shape}")
    return q


def _envelope(audio: np.ndarray, t0: float, sr: int, bins: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A waveform's min/max per bin (a compact drawing of many samples): times [s], lows and highs."""
    a = np.asarray(audio, dtype=np.float32).ravel()
    if a.size == 0:
        return np.zeros(0, np.float32), np.zeros(0, np.float32), np.zeros(0, np.float32)
    n = min(bins, a.size)
    edges = np.linspace(0, a.size, n + 1).astype(np.int64)
    lo = np.minimum.reduceat(a, edges[:-1])
    hi = np.maximum.reduceat(a, edges[:-1])
    t = t0 + (edges[:-1] + edges[1:]) / 2 / sr
    return t.astype(np.float32), lo, hi


@checks_arguments
def candidate_figure(
    view: CandidateView,
    query: np.ndarray | None,
    *,
    fps: float,
    clip_audio: np.ndarray | None = None,
    speech: np.ndarray | None = None,
    sr: int = AUDIO_SR,
    every: int = 8,
    title: str | None = None,
    height: int = 420,
) -> go.Figure:
    """One candidate large: its first frame over the query's ghost, and its whole clip with the window marked.

    Parameters
    ----------
    view : CandidateView
        The candidate.
    query : np.ndarray, shape (55, 3), optional
        The query pose ``p_{t-1}``; None draws no ghost.
    fps : float
        Frames per second of the clip.
    clip_audio : np.ndarray, shape (samples,), optional
        The clip's own speech over its frames (float, ``sr`` Hz); drawn under the filmstrip
        with the window shaded.
    speech : np.ndarray, shape (samples,), optional
        The step's input speech (what the window's audio was matched against), drawn
        over the window's time range beside the clip's speech.
    sr : int
        Sample rate of both, Hz.
    every : int
        The filmstrip draws every ``every``-th frame of the clip, counted from the window's
        first frame (so it is drawn), and the window's last frame.
    title : str, optional
    height : int
        Figure height in pixels.

    Returns
    -------
    plotly.graph_objects.Figure
        Left (``x``/``y``): the pose panel (``meta["part"]`` ``"ghost"``, ``"first frame"``,
        ``"left wrist path"``, ``"right wrist path"``). Right top (``x2``/``y2``): the
        filmstrip, one trace per drawn frame with ``meta = {"part": "filmstrip", "frame": f,
        "in_window": bool}``, x in seconds into the clip. Right bottom (``x3``/``y3``, the same
        seconds): ``"clip speech"`` and ``"step speech"`` envelopes, and a rectangle shape named
        ``"window"`` from ``start / fps`` to the window's end.

    Raises
    ------
    ConfigError
        ``fps`` or ``every`` not positive, or a query pose of the wrong shape.
    """
    if not fps > 0 or int(every) < 1:
        raise ConfigError(f"candidate_figure needs fps > 0 and every >= 1, got {fps!r} and {every!r}")
    query = _checked_query(query)
    clip = np.asarray(view.clip_positions, dtype=np.float32)
    n_clip = clip.shape[0]
    a, b = int(view.start), min(int(view.start) + int(view.segment), n_clip)
    color = CHOSEN_COLOR if view.chosen else SELECTED_COLOR
    fig = make_subplots(
        rows=2,
        cols=2,
        column_widths=[0.28, 0.72],
        row_heights=[0.68, 0.32],
        specs=[[{"rowspan": 2}, {}], [None, {}]],
        horizontal_spacing=0.03,
        vertical_spacing=0.06,
        subplot_titles=[
            "first frame (colour) over the query pose (grey);<br>wrist paths over the step (left solid, right dotted)",
            f"the whole database clip: {n_clip} frames ({n_clip / fps:.2f} s), the window's frames in colour",
            "its speech (grey), the window shaded; the step's input speech (colour) over the window",
        ],
    )
    _pose_panel(fig, view, query, row=1, col=1, color=color, width=3.0, marker=11)
    _pose_axes(fig, [view], query, n_axes=1)

    # the filmstrip: poses along the clip's time, each squeezed into the seconds between drawn frames
    drawn = sorted(set(range(a % every, n_clip, every)) | {b - 1})
    width_m = max(0.6, float(np.ptp(clip[:, :, 0])) + 0.1)
    # a pose's width spans the time to the next drawn frame and a quarter more: neighbours overlap at the hands
    s_per_m = 1.25 * every / fps / width_m
    for f in drawn:
        x, y = front_view_lines(clip[f])
        inside = a <= f < b
        fig.add_trace(
            go.Scatter(
                x=f / fps + x * s_per_m,
                y=y,
                mode="lines",
                line=dict(color=color if inside else _OUTSIDE_COLOR, width=2.0 if inside else 1.4),
                opacity=1.0 if inside else 0.9,
                hoverinfo="skip",
                showlegend=False,
                meta={"part": "filmstrip", "frame": int(f), "in_window": bool(inside), "candidate": int(view.position)},
            ),
            row=1,
            col=2,
        )
    # true proportions: a metre up spans as many pixels as a metre across (s_per_m seconds)
    fig.update_yaxes(visible=False, scaleanchor="x2", scaleratio=s_per_m, row=1, col=2)
    fig.update_xaxes(range=[-width_m * s_per_m, n_clip / fps + width_m * s_per_m], showticklabels=False, row=1, col=2)

    speeches = (("clip speech", clip_audio, 0.0, _OUTSIDE_COLOR), ("step speech", speech, a / fps, color))
    for part, audio, t0, c in speeches:
        if audio is None:
            continue
        t, lo, hi = _envelope(audio, t0, sr, 600)
        fig.add_trace(
            go.Scatter(
                x=np.concatenate([t, t[::-1]]),
                y=np.concatenate([hi, lo[::-1]]),
                fill="toself",
                mode="lines",
                line=dict(color=c, width=0.5),
                fillcolor=c,
                opacity=0.55 if part == "step speech" else 0.9,
                hoverinfo="skip",
                showlegend=False,
                meta={"part": part, "candidate": int(view.position)},
            ),
            row=2,
            col=2,
        )
    fig.update_xaxes(
        range=[-width_m * s_per_m, n_clip / fps + width_m * s_per_m],
        title_text="time in the database clip [s]",
        matches="x2",
        row=2,
        col=2,
    )
    fig.update_yaxes(visible=False, row=2, col=2)
    band = dict(
        type="rect",
        xref="x3",
        yref="y3 domain",
        x0=a / fps,
        x1=b / fps,
        y0=0,
        y1=1,
        fillcolor=color,
        opacity=0.12,
        line=dict(width=0),
        name="window",
    )
    fig.update_layout(
        shapes=[band],
        title=dict(text=plotly_safe(title)) if title else None,
        height=height,
        margin=dict(l=6, r=6, t=70 if title else 50, b=10),
        showlegend=False,
        plot_bgcolor="#ffffff",
    )
    for ann in fig.layout.annotations:
        ann.font = dict(size=12)
    # the pose panel's title is wider than its narrow column: from the column's left edge, not centred on it
    # (centred, its longer line ran past the figure's left edge and lost its first letters)
    first = fig.layout.annotations[0]
    first.update(x=0.0, xanchor="left", align="left")
    return fig
