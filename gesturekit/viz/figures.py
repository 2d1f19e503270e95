"""Interactive plotly figures of motions, databases and speech, for the app and notebooks.

Every function returns a :class:`plotly.graph_objects.Figure` and imports
nothing from streamlit, so the same figure can be shown with
``st.plotly_chart`` or ``fig.show()`` in a notebook. Coordinates follow
:mod:`gesturekit.skeleton`: metres, Y up, the character faces +Z and its
left is +X. Numeric arrays are handed to plotly as float32 numpy arrays, which
plotly serialises as compact typed arrays; the skeleton figure's many small
per-frame arrays are handed over already encoded that way (see
:func:`data_array` to read them back), since plotly's own per-array checks and
conversions took most of a second for a 30 s motion.

Traces carry a ``meta`` dict that says what they show (``{"motion": i,
"part": "body" | "hands" | "joints"}`` for skeletons, ``{"part": ...}``
elsewhere), so pages and tests can find them without relying on their order.

The 2D charts are made here: the database's attribute histograms, speech
waveforms, wrist tracks and a step's candidates. Line charts put their legend
under the plot (:data:`BOTTOM_LEGEND`) and mark control segments as coloured
bands. The 3D skeleton is made in :mod:`gesturekit.viz.skeleton_figure`; this
module is the one place to import every figure from.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from .._arguments import checks_arguments
from ..control import ATTRIBUTE_NAMES, ATTRIBUTE_UNITS, ControlTrack, frame_attributes
from ..errors import ConfigError
from ..motion import Motion
from ._plotly import _BAND_COLORS, MOTION_COLORS, ROLE_COLORS, _motions_and_labels, data_array, plotly_safe
from .skeleton_figure import DEFAULT_MAX_FRAMES, skeleton_figure

if TYPE_CHECKING:
    from ..database import MatchingDatabase
    from ..search import SearchResult

__all__ = [
    "DEFAULT_MAX_FRAMES",
    "MOTION_COLORS",
    "skeleton_figure",
    "attribute_histograms",
    "waveform_figure",
    "WRIST_ROWS",
    "wrist_figure",
    "candidates_figure",
    "data_array",
    "BOTTOM_LEGEND",
]

#: Where the line charts put their legend: under the plot, at the figure's bottom left, clear of
#: the chart toolbar a page shows at the top right (and of the control labels above the plot).
BOTTOM_LEGEND = dict(orientation="h", x=0, xanchor="left", xref="container", y=0, yanchor="bottom", yref="container")

#: Pixels above the plots of :func:`attribute_histograms`: its two-line title, then the subplot titles.
HISTOGRAM_TOP = 100

#: Pixels kept at the bottom of a figure for :data:`BOTTOM_LEGEND`.
LEGEND_ROOM = 30


def _attribute_unit(name: str) -> str:
    return ATTRIBUTE_UNITS.get(name, "m/s" if "speed" in name else "m")


@checks_arguments
def attribute_histograms(
    db: MatchingDatabase, *, bins: int = 40, names: Sequence[str] | None = None, cols: int = 3
) -> go.Figure:
    """Histograms of the database's control attributes, with their low/high thresholds.

    Parameters
    ----------
    db : MatchingDatabase
        Anything with ``attribute_names``, ``thresholds`` (name -> (low, high))
        and ``attribute(name)`` returning the values of every clip frame,
        shape (M, 64).
    bins : int
        Bins per histogram (counted with numpy, so the figure holds
        ``bins`` bars, not every frame's value).
    names : sequence of str, optional
        Attributes to show, default all of ``db.attribute_names``.
    cols : int
        Subplots per row.

    Returns
    -------
    plotly.graph_objects.Figure
        One subplot per attribute (a bar trace with ``meta = {"part":
        "histogram", "attribute": name}``; bars below the low threshold and
        above the high one are coloured) and two vertical dashed line shapes
        per attribute, named ``"<name> low"`` and ``"<name> high"``, at the
        thresholds (x in the attribute's unit: m for heights, widths and
        asymmetry, m/s for speeds).

    Raises
    ------
    ConfigError
        An unknown attribute name or ``bins``/``cols`` below 1.
    """
    names = list(db.attribute_names if names is None else names)
    if bins < 1 or cols < 1:
        raise ConfigError(f"bins and cols must be at least 1, got bins={bins}, cols={cols}")
    if not names:
        raise ConfigError("attribute_histograms needs at least one attribute")
    thresholds = db.thresholds
    cols = min(cols, len(names))
    rows = int(math.ceil(len(names) / cols))
    fig = make_subplots(
        rows=rows,
        cols=cols,
        subplot_titles=[f"{n} [{_attribute_unit(n)}]" for n in names],
        horizontal_spacing=0.06,
        vertical_spacing=0.5 / rows,
    )
    for i, name in enumerate(names):
        values = np.asarray(db.attribute(name), dtype=np.float64).ravel()
        values = values[np.isfinite(values)]
        lo, hi = thresholds[name]
        counts, edges = np.histogram(values, bins=bins)
        centres = (edges[:-1] + edges[1:]) / 2
        colors = np.where(centres < lo, "#4c78a8", np.where(centres > hi, "#e45756", "#b8bcc2"))
        row, col = i // cols + 1, i % cols + 1
        fig.add_trace(
            go.Bar(
                x=centres.astype(np.float32),
                y=counts,
                width=np.diff(edges).astype(np.float32),
                marker=dict(color=colors.tolist(), line=dict(width=0)),
                name=name,
                showlegend=False,
                meta={"part": "histogram", "attribute": name},
                hovertemplate=f"{name}: %{{x:.3f}} {_attribute_unit(name)}<br>%{{y}} frames<extra></extra>",
            ),
            row=row,
            col=col,
        )
        for which, x, color in (("low", lo, "#1f4e79"), ("high", hi, "#a3222b")):
            fig.add_vline(
                x=float(x), row=row, col=col, line=dict(color=color, dash="dash", width=1.5), name=f"{name} {which}"
            )
    pct = (getattr(db, "meta", None) or {}).get("build", {}).get("percentiles")
    subtitle = (
        f"dashed lines: the {pct[0]:g}th (low) and {pct[1]:g}th (high) percentiles"
        if pct
        else "dashed lines: the low and high thresholds"
    )
    fig.update_layout(
        # the title sits at the figure's top, the subplot titles in room of their own below it
        title=dict(
            text=f"Control attributes of the database frames<br><sup>{subtitle}</sup>",
            y=1 - 16 / (230 * rows + HISTOGRAM_TOP),
            yref="container",
            yanchor="top",
        ),
        height=230 * rows + HISTOGRAM_TOP,
        margin=dict(l=10, r=10, t=HISTOGRAM_TOP, b=10),
        bargap=0,
    )
    return fig


def _band_check(bands) -> list[tuple[float, float, str]]:
    out = []
    for band in bands:
        if len(band) != 3:
            raise ConfigError(f"a band is (start_s, end_s, label), got {band!r}")
        a, b, label = float(band[0]), float(band[1]), str(band[2])
        if not (np.isfinite(a) and np.isfinite(b)) or not b > a:
            raise ConfigError(f"band {label!r}: end ({b}) must be after start ({a}), both finite")
        out.append((a, b, label))
    return out


def _band_marks(
    bands: Sequence[tuple[float, float, str]], axes: Sequence[tuple[str, str]], *, label_anchor: str
) -> tuple[list[dict], list[dict]]:
    """Layout shapes and annotations shading time bands (start_s, end_s, label).

    One rectangle per band on each (x axis, y axis) pair of ``axes``, over the axis's
    full height and below the traces; bands with the same label share a colour. Each
    labelled band gets its label at the top of the first row, anchored by
    ``label_anchor`` ("bottom": above the plot, "top": inside it).
    """
    shapes, notes = [], []
    colors: dict[str, str] = {}
    for a, b, label in bands:
        color = colors.setdefault(label, _BAND_COLORS[len(colors) % len(_BAND_COLORS)])
        style = dict(fillcolor=color, opacity=0.18, line=dict(width=0), layer="below", name=label)
        for xa, ya in axes:
            shapes.append(dict(type="rect", xref=xa, x0=a, x1=b, yref=f"{ya} domain", y0=0, y1=1, **style))
        if label:
            notes.append(
                dict(
                    x=(a + b) / 2,
                    y=1.0,
                    xref="x",
                    yref="y domain",
                    yanchor=label_anchor,
                    text=label,
                    showarrow=False,
                    font=dict(size=10, color=color),
                )
            )
    return shapes, notes


@checks_arguments
def waveform_figure(
    audio: np.ndarray,
    sr: int,
    *,
    bands: Sequence[tuple[float, float, str]] | None = None,
    max_points: int = 2000,
    envelope_ms: float = 50.0,
    title: str | None = None,
    height: int = 260,
) -> go.Figure:
    """Speech over time: its waveform (as a min/max envelope) and RMS energy, with labelled time bands.

    Parameters
    ----------
    audio : np.ndarray, shape (samples,)
        Mono audio, float in [-1, 1].
    sr : int
        Sample rate, Hz.
    bands : sequence of (start_s, end_s, label), optional
        Time ranges in seconds to shade (e.g. the database clips a synthesis
        used); bands with the same label get the same colour.
    max_points : int
        Most points of the waveform trace: longer audio is shown as the
        minimum and maximum of each of ``max_points`` equal bins.
    envelope_ms : float
        Window of the RMS energy curve, milliseconds.
    title : str, optional
        Shown above the waveform.
    height : int
        Figure height in pixels.

    Returns
    -------
    plotly.graph_objects.Figure
        Traces with ``meta["part"]`` ``"waveform_max"``, ``"waveform_min"``
        (filled between) and ``"rms"``; x is time in seconds. Each band is a
        rectangle shape (``xref="x"``, ``x0=start_s``, ``x1=end_s``, named by
        its label) with a text annotation.

    Raises
    ------
    ConfigError
        Audio that is not 1-D or is empty, a non-positive ``sr``, ``max_points``
        or ``envelope_ms``, or a band whose end is not after its start.
    """
    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim != 1 or audio.size == 0:
        raise ConfigError(f"waveform_figure needs 1-D, non-empty audio, got shape {audio.shape}")
    if not sr > 0 or max_points < 1 or not envelope_ms > 0:
        raise ConfigError(f"sr, max_points and envelope_ms must be positive, got {sr}, {max_points}, {envelope_ms}")
    bands = _band_check(bands or [])
    n = audio.size
    per_bin = max(1, int(math.ceil(n / max_points)))
    n_bins = int(math.ceil(n / per_bin))
    padded = np.pad(audio, (0, n_bins * per_bin - n), mode="edge").reshape(n_bins, per_bin)
    t_bins = (np.arange(n_bins) * per_bin + per_bin / 2) / sr
    win = max(1, int(round(envelope_ms / 1000 * sr)))
    n_win = int(math.ceil(n / win))
    sq = np.pad(audio.astype(np.float64) ** 2, (0, n_win * win - n)).reshape(n_win, win)
    counts = np.minimum(win, n - np.arange(n_win) * win)
    rms = np.sqrt(sq.sum(axis=1) / counts)
    t_rms = (np.arange(n_win) * win + counts / 2) / sr

    fig = go.Figure()
    line = dict(color="#6b7f99", width=1)
    # the envelope: the max line, then the min line filled up to it
    envelope = (
        ("waveform_max", padded.max(axis=1), dict(name="waveform")),
        (
            "waveform_min",
            padded.min(axis=1),
            dict(fill="tonexty", fillcolor="rgba(107,127,153,0.45)", showlegend=False),
        ),
    )
    for part, y, style in envelope:
        fig.add_trace(
            go.Scatter(
                x=t_bins.astype(np.float32),
                y=y,
                mode="lines",
                line=line,
                hoverinfo="skip",
                meta={"part": part},
                **style,
            )
        )
    fig.add_trace(
        go.Scatter(
            x=t_rms.astype(np.float32),
            y=rms.astype(np.float32),
            mode="lines",
            line=dict(color="#d1495b", width=1.5),
            name="RMS energy",
            meta={"part": "rms"},
            hovertemplate="%{x:.2f} s: RMS %{y:.3f}<extra></extra>",
        )
    )
    shapes, notes = _band_marks(bands, [("x", "y")], label_anchor="bottom")
    fig.update_layout(shapes=shapes, annotations=notes)
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=40 if title or bands else 10, b=10 + LEGEND_ROOM),
        xaxis=dict(title="time [s]", range=[0, n / sr]),
        yaxis=dict(title="amplitude"),
        legend=BOTTOM_LEGEND,
        uirevision="waveform",
    )
    return fig


#: The rows of :func:`wrist_figure`, top to bottom: (attribute of :mod:`gesturekit.control`, title).
WRIST_ROWS: tuple[tuple[str, str], ...] = (
    ("left_hand_height", "left wrist height [m]"),
    ("right_hand_height", "right wrist height [m]"),
    ("left_hand_speed", "left wrist speed [m/s]"),
    ("right_hand_speed", "right wrist speed [m/s]"),
)


def _as_bands(bands) -> list[tuple[float, float, str]]:
    if bands is None:
        return []
    if isinstance(bands, ControlTrack):
        return [(s.start_s, s.end_s, s.label()) for s in bands.segments]
    return _band_check(bands)


@checks_arguments
def wrist_figure(
    motions: Motion | Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    bands: ControlTrack | Sequence[tuple[float, float, str]] | None = None,
    thresholds: dict[str, tuple[float, float]] | None = None,
    title: str | None = None,
    height: int = 620,
) -> go.Figure:
    """Left and right wrist height and speed over time, with control bands and thresholds.

    The plots of the paper's supplementary Figs. 2 and 3: one row per
    quantity (see :data:`WRIST_ROWS`), one line per motion (for example the
    k-NN result and the refined one overlaid), the control segments as shaded
    time bands and the database's low/high thresholds of each quantity as
    horizontal dashed lines, so one sees whether the motion stays beyond the
    threshold while a control is active. The quantities are the control
    attributes of :func:`gesturekit.control.frame_attributes` (the same
    numbers the thresholds were computed from): wrist height above the pelvis
    and wrist speed.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        Pelvis-relative joint positions, shape (frames, 55, 3), metres, each
        at its own fps.
    labels : sequence of str, optional
        One legend name per motion; default ``"motion 1"``, ... (or none for one motion).
    bands : ControlTrack or sequence of (start_s, end_s, label), optional
        Time ranges in seconds to shade in every row, labelled once at the
        top; bands with the same label share a colour (the colours
        :func:`waveform_figure` gives the same bands in the same order).
    thresholds : dict of str -> (float, float), optional
        Attribute name -> (low, high), e.g. ``db.thresholds``; each row gets
        the lines of its attribute (heights in m, speeds in m/s).
    title : str, optional
        Shown above the four rows.
    height : int
        Figure height in pixels, all rows together.

    Returns
    -------
    plotly.graph_objects.Figure
        Four subplots sharing the time axis (seconds). One line trace per
        motion and row with ``meta = {"part": "wrist", "motion": i,
        "attribute": name}``; x is ``frame / fps``, y the attribute.
        Threshold lines are shapes named ``"<attribute> low"`` and
        ``"<attribute> high"`` (``y0 == y1`` the threshold); bands are
        rectangle shapes named by their label, one per row.

    Raises
    ------
    ConfigError
        No motion, a motion with no frame, labels of the wrong length, a band
        whose end is not after its start, or thresholds lacking an attribute
        of a row.
    """
    motions, labels = _motions_and_labels(motions, labels, who="wrist_figure")
    labels = [plotly_safe(label) for label in labels]
    bands = _as_bands(bands)
    if thresholds is not None:
        missing = [a for a, _ in WRIST_ROWS if a not in thresholds]
        if missing:
            raise ConfigError(f"wrist_figure: thresholds lack {', '.join(missing)}")

    columns = [ATTRIBUTE_NAMES.index(a) for a, _ in WRIST_ROWS]
    n_rows = len(WRIST_ROWS)
    fig = make_subplots(
        rows=n_rows, cols=1, shared_xaxes=True, vertical_spacing=0.045, subplot_titles=[t for _, t in WRIST_ROWS]
    )
    traces, rows = [], []
    for i, (m, label) in enumerate(zip(motions, labels)):
        values = frame_attributes(m.positions, fps=m.fps)[:, columns]
        t = (np.arange(m.n_frames) / float(m.fps)).astype(np.float32)
        color = MOTION_COLORS[i % len(MOTION_COLORS)]
        for r, (attr, _) in enumerate(WRIST_ROWS):
            unit = _attribute_unit(attr)
            traces.append(
                go.Scatter(
                    x=t,
                    y=values[:, r],
                    mode="lines",
                    line=dict(color=color, width=1.6),
                    name=label or "motion",
                    legendgroup=f"motion{i}",
                    showlegend=r == 0 and len(motions) > 1,
                    meta={"part": "wrist", "motion": i, "attribute": attr},
                    hovertemplate=f"{label + ': ' if label else ''}%{{x:.2f}} s, %{{y:.3f}} {unit}<extra></extra>",
                )
            )
            rows.append(r + 1)
    fig.add_traces(traces, rows=rows, cols=[1] * len(rows))

    # shapes are collected and set once: plotly's add_hline/add_vrect copy every shape on each call
    def axes(r: int) -> tuple[str, str]:
        return ("x", "y") if r == 0 else (f"x{r + 1}", f"y{r + 1}")

    shapes: list[dict] = []
    if thresholds is not None:
        for r, (attr, _) in enumerate(WRIST_ROWS):
            xa, ya = axes(r)
            lo, hi = thresholds[attr]
            for which, y, color in (("low", lo, "#1f4e79"), ("high", hi, "#a3222b")):
                shapes.append(
                    dict(
                        type="line",
                        xref=f"{xa} domain",
                        x0=0,
                        x1=1,
                        yref=ya,
                        y0=float(y),
                        y1=float(y),
                        line=dict(color=color, dash="dash", width=1),
                        name=f"{attr} {which}",
                    )
                )
    band_shapes, notes = _band_marks(bands, [axes(r) for r in range(n_rows)], label_anchor="top")
    shapes += band_shapes
    fig.update_layout(shapes=shapes, annotations=list(fig.layout.annotations) + notes)
    duration = max(m.duration for m in motions)
    fig.update_xaxes(range=[0, duration])
    fig.update_xaxes(title_text="time [s]", row=n_rows, col=1)
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=70 if title else 45, b=10 + (LEGEND_ROOM if len(motions) > 1 else 0)),
        legend=BOTTOM_LEGEND,
        showlegend=len(motions) > 1,
        uirevision="wrists",
    )
    return fig


@checks_arguments
def candidates_figure(
    search: SearchResult,
    step: int,
    *,
    names: Sequence[str] | None = None,
    title: str | None = None,
    height: int = 320,
    selected: int | None = None,
) -> go.Figure:
    """The candidates of one search step: pose distance against audio distance, the chosen one ringed.

    Parameters
    ----------
    search : SearchResult
        Anything with the candidate tables ``cand_clip``, ``cand_start``,
        ``cand_pose_dist``, ``cand_audio_dist``, ``cand_pose_rank``,
        ``cand_audio_rank``, ``cand_combined`` (shape (steps, K), padded with
        clip -1) and ``position`` (steps,) of :class:`gesturekit.search.SearchResult`.
    step : int
        The step, ``0 <= step < steps``.
    names : sequence of str, optional
        A description per table column (e.g. the candidate's take and time),
        shown on hover; length K.
    title : str, optional
    height : int
        Figure height in pixels.
    selected : int, optional
        Position of a candidate looked at closely: ringed in blue (when it is not the chosen one).

    Returns
    -------
    plotly.graph_objects.Figure
        A marker trace with ``meta["part"] == "candidates"``: one point per
        recorded candidate, x the pose distance (z-scored feature units), y the
        audio (cosine) distance, labelled by its position in the combined
        ranking; when the chosen window is in the table, a trace with
        ``meta["part"] == "chosen"`` of one point on it; and likewise ``"selected"``.

    Raises
    ------
    ConfigError
        ``step`` out of range or ``names`` of the wrong length.
    """
    n_steps, width = np.shape(search.cand_clip)
    if not 0 <= int(step) < n_steps:
        raise ConfigError(f"step must be in 0..{n_steps - 1}, got {step}")
    step = int(step)
    if names is not None and len(names) != width:
        raise ConfigError(f"candidates_figure got {len(names)} names for {width} candidates")
    keep = np.flatnonzero(np.asarray(search.cand_clip[step]) >= 0)
    x = np.asarray(search.cand_pose_dist[step], dtype=np.float64)[keep]
    y = np.asarray(search.cand_audio_dist[step], dtype=np.float64)[keep]
    custom = np.stack(
        [
            np.asarray(getattr(search, f"cand_{c}")[step])[keep]
            for c in ("clip", "start", "pose_rank", "audio_rank", "combined")
        ],
        axis=1,
    )
    hover = (
        "#%{text}: clip %{customdata[0]} from frame %{customdata[1]}<br>pose distance %{x:.3f} "
        "(rank %{customdata[2]})<br>audio distance %{y:.4f} (rank %{customdata[3]})<br>"
        "combined rank %{customdata[4]}"
    )
    if names is not None:
        hover += "<br>%{hovertext}"
    fig = go.Figure()
    fig.add_trace(
        go.Scatter(
            x=x,
            y=y,
            mode="markers+text",
            text=[str(p) for p in keep],
            textposition="top center",
            customdata=custom,
            hovertext=None if names is None else [plotly_safe(names[int(p)]) for p in keep],
            hovertemplate=hover + "<extra></extra>",
            marker=dict(size=9, color="#6b7f99"),
            name="candidates",
            meta={"part": "candidates"},
        )
    )
    chosen = int(search.position[step])
    if chosen >= 0 and chosen in keep:
        j = int(np.flatnonzero(keep == chosen)[0])
        fig.add_trace(
            go.Scatter(
                x=[x[j]],
                y=[y[j]],
                mode="markers",
                name="chosen",
                hoverinfo="skip",
                marker=dict(size=18, color="rgba(0,0,0,0)", line=dict(color=ROLE_COLORS["chosen"], width=3)),
                meta={"part": "chosen"},
            )
        )
    if selected is not None and int(selected) != chosen and int(selected) in keep:
        j = int(np.flatnonzero(keep == int(selected))[0])
        fig.add_trace(
            go.Scatter(
                x=[x[j]],
                y=[y[j]],
                mode="markers",
                name="selected",
                hoverinfo="skip",
                marker=dict(size=18, color="rgba(0,0,0,0)", line=dict(color="#2c5d8f", width=3)),
                meta={"part": "selected"},
            )
        )
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=40 if title else 10, b=10),
        xaxis=dict(title="pose distance (z-scored)", range=_padded(x, low=0.08, high=0.08)),
        # more room above: each point's label is written over it
        yaxis=dict(title="audio distance (cosine)", range=_padded(y, low=0.08, high=0.2)),
        showlegend=False,
    )
    return fig


def _padded(values: np.ndarray, *, low: float, high: float) -> list[float] | None:
    """An axis range around ``values`` with fractions of their span (or of their size, when they
    are all equal) added below and above, so no marker or label is cut at the plot's edge."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    lo, hi = float(v.min()), float(v.max())
    span = hi - lo if hi > lo else max(abs(hi), 1.0) * 0.1
    return [lo - low * span, hi + high * span]
