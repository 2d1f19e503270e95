"""Interactive plotly figures of motions, databases and speech, for the app and notebooks.

Every function returns a :class:`plotly.graph_objects.Figure` and imports
nothing from streamlit, so the same figure can be shown with
``st.plotly_chart`` or ``fig.show()`` in a notebook. Coordinates follow
:mod:`gesturekit.skeleton`: metres, Y up, the character faces +Z and its
left is +X. Numeric arrays are handed to plotly as float32 numpy arrays, which
plotly serialises as compact typed arrays.

Traces carry a ``meta`` dict that says what they show (``{"motion": i,
"part": "body" | "hands" | "joints"}`` for skeletons, ``{"part": ...}``
elsewhere), so pages and tests can find them without relying on their order.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from ..errors import ConfigError
from ..motion import Motion
from ..skeleton import BODY_JOINTS, bones, joint_index

__all__ = [
    "DEFAULT_MAX_FRAMES",
    "MOTION_COLORS",
    "skeleton_figure",
    "attribute_histograms",
    "waveform_figure",
]

#: Most animation frames a skeleton figure holds (20 s at 15 fps). Longer motions are
#: shown at a lower frame rate; each frame then lasts longer, so playback keeps real time.
DEFAULT_MAX_FRAMES = 300

#: Colours of the motions of a skeleton figure, in order (repeated past the end).
MOTION_COLORS = ("#2c5d8f", "#c0502d", "#3a8a4e", "#7b4fa0", "#a07a1f", "#2a8a8a")

_BAND_COLORS = ("#4c78a8", "#f58518", "#54a24b", "#e45756", "#b279a2", "#72b7b2", "#eeca3b", "#9d755d")


def _bone_groups() -> tuple[np.ndarray, np.ndarray]:
    """(child, parent) pairs of the body bones (up to the wrists) and of the 40 finger bones."""
    pairs = bones()
    wrists = {joint_index("left_wrist"), joint_index("right_wrist")}
    body = np.array([c < len(BODY_JOINTS) or c in wrists for c in pairs[:, 0]])
    return pairs[body], pairs[~body]


def _segments(positions: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Line segments of bones as one polyline broken by NaN rows.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3), metres
    pairs : np.ndarray, shape (bones, 2), (child, parent) joint indices

    Returns
    -------
    np.ndarray, shape (frames, 3 * bones, 3), float32
        For each bone: child, parent, NaN (plotly leaves a gap at a NaN point).
    """
    out = np.full((positions.shape[0], len(pairs), 3, 3), np.nan, dtype=np.float32)
    out[:, :, 0] = positions[:, pairs[:, 0]]
    out[:, :, 1] = positions[:, pairs[:, 1]]
    return out.reshape(positions.shape[0], 3 * len(pairs), 3)


def _xyz(points: np.ndarray) -> dict:
    return {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}


def skeleton_figure(
    motions: Motion | Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    title: str | None = None,
    max_frames: int = DEFAULT_MAX_FRAMES,
    spacing: float | None = None,
    height: int = 520,
) -> go.Figure:
    """An animated 3D view of one or several skeletons, side by side, seen from the front.

    Each motion is drawn as its 54 bones (14 body bones up to the wrists as
    thick lines, the 40 finger bones as thin lines) with its joints as dots. Several
    motions are offset copies in one scene, placed along X (the first on the
    viewer's left), so they share one camera. The camera stands on the
    characters' +Z side, looking along -Z, with Y up. The figure has play/pause
    buttons and a time slider; its axis ranges stay fixed over all frames.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        Joint positions, shape (frames, 55, 3), metres, each at its own fps.
        Motions of different lengths are shown together; a shorter one holds
        its last pose.
    labels : sequence of str, optional
        One name per motion, shown above it and in the legend.
    fps : float, optional
        Frame rate of the animation's time grid, frames per second; default
        the highest fps of the motions. Each motion shows, at time ``t``, its
        last frame at or before ``t``.
    title : str, optional
        Figure title.
    max_frames : int
        Most animation frames (default :data:`DEFAULT_MAX_FRAMES`). A longer
        time grid keeps every ``ceil(n / max_frames)``-th time; frame durations
        grow by the same factor so playback stays in real time.
    spacing : float, optional
        Distance in metres between neighbouring motions along X; default the
        widest motion's X extent plus 0.4 m (at least 0.8 m).
    height : int
        Figure height in pixels.

    Returns
    -------
    plotly.graph_objects.Figure
        Two line-and-marker traces per motion: ``meta["part"] == "body"``
        (14 bones) and ``"hands"`` (40 bones), each bone a (child, parent, NaN)
        triple of points, so the joints are the markers at the bone ends.
        One ``go.Frame`` per shown time (named by its index,
        ``layout.meta`` holds ``{"fps", "frame_step", "times"}`` with the
        times in seconds), and a scene camera with ``up = (0, 1, 0)`` and the
        eye on the +Z side.

    Raises
    ------
    ConfigError
        No motion, a motion with no frame, labels of the wrong length, or a
        non-positive ``fps``/``max_frames``.
    """
    motions = [motions] if isinstance(motions, Motion) else list(motions)
    if not motions:
        raise ConfigError("skeleton_figure needs at least one motion")
    for m in motions:
        if not isinstance(m, Motion):
            raise ConfigError(f"skeleton_figure takes Motion objects, got {type(m).__name__}")
        if m.n_frames < 1:
            raise ConfigError("skeleton_figure got a motion with no frame")
    if labels is None:
        labels = [f"motion {i + 1}" for i in range(len(motions))] if len(motions) > 1 else [""]
    labels = [str(s) for s in labels]
    if len(labels) != len(motions):
        raise ConfigError(f"skeleton_figure got {len(labels)} labels for {len(motions)} motions")
    if max_frames < 1:
        raise ConfigError(f"max_frames must be at least 1, got {max_frames}")
    grid_fps = float(fps) if fps is not None else max(float(m.fps) for m in motions)
    if not grid_fps > 0:
        raise ConfigError(f"fps must be positive, got {fps}")

    duration = max(m.duration for m in motions)
    n_grid = max(1, int(math.ceil(duration * grid_fps - 1e-9)))
    step = int(math.ceil(n_grid / max_frames))
    times = np.arange(0, n_grid, step) / grid_fps

    # the poses shown at each time, per motion (sample and hold)
    shown = []
    for m in motions:
        idx = np.minimum(np.floor(times * m.fps + 1e-6).astype(np.int64), m.n_frames - 1)
        shown.append(np.asarray(m.positions[idx], dtype=np.float32))
    if spacing is None:
        widest = max(float(np.ptp(p[..., 0])) for p in shown)
        spacing = max(0.8, widest + 0.4)
    offsets = (np.arange(len(motions)) - (len(motions) - 1) / 2) * float(spacing)
    shown = [p + np.array([dx, 0, 0], dtype=np.float32) for p, dx in zip(shown, offsets)]

    body_pairs, hand_pairs = _bone_groups()
    # per motion: (body segments, finger segments), each (frames, points, 3); markers at the
    # segment ends draw every joint, since every joint ends a bone
    parts = [(_segments(p, body_pairs), _segments(p, hand_pairs)) for p in shown]

    traces = []
    for i, (label, (body, hands)) in enumerate(zip(labels, parts)):
        color = MOTION_COLORS[i % len(MOTION_COLORS)]
        group = f"motion{i}"
        common = dict(legendgroup=group, hoverinfo="skip")
        traces.append(
            go.Scatter3d(
                **_xyz(body[0]), mode="lines+markers", line=dict(color=color, width=7),
                marker=dict(color=color, size=3), name=label or "body",
                showlegend=len(motions) > 1, meta={"motion": i, "part": "body"}, **common,
            )
        )
        traces.append(
            go.Scatter3d(
                **_xyz(hands[0]), mode="lines+markers", line=dict(color=color, width=3),
                marker=dict(color=color, size=1.5), name=f"{label} hands".strip(),
                showlegend=False, meta={"motion": i, "part": "hands"}, **common,
            )
        )

    frames = []
    if len(times) > 1:
        trace_ids = list(range(len(traces)))
        for k in range(len(times)):
            data = [dict(type="scatter3d", **_xyz(a[k])) for part in parts for a in part]
            frames.append(dict(data=data, traces=trace_ids, name=str(k)))

    # fixed ranges over every shown frame: the view must not jump while playing
    allp = np.concatenate([p.reshape(-1, 3) for p in shown])
    lo, hi = allp.min(axis=0) - 0.1, allp.max(axis=0) + 0.1
    centre, extent = (lo + hi) / 2, np.maximum(hi - lo, 0.3)
    lo, hi = centre - extent / 2, centre + extent / 2
    aspect = extent / extent.max()
    axis = dict(visible=False, showbackground=False, showspikes=False)
    annotations = []
    if any(labels) and len(motions) > 1:
        top = float(hi[1]) - 0.02
        annotations = [
            dict(x=float(dx), y=top, z=0.0, text=label, showarrow=False, font=dict(size=13))
            for dx, label in zip(offsets, labels)
        ]
    scene = dict(
        xaxis=dict(range=[float(lo[0]), float(hi[0])], **axis),
        yaxis=dict(range=[float(lo[1]), float(hi[1])], **axis),
        zaxis=dict(range=[float(lo[2]), float(hi[2])], **axis),
        aspectmode="manual",
        aspectratio=dict(x=float(aspect[0]), y=float(aspect[1]), z=float(aspect[2])),
        # in front of the character (+Z), slightly above, looking at the scene centre
        camera=dict(up=dict(x=0, y=1, z=0), eye=dict(x=0.0, y=0.15, z=1.9), center=dict(x=0, y=0, z=0),
                    projection=dict(type="perspective")),
        annotations=annotations,
        dragmode="turntable"  # rotates about the up (Y) axis,
    )
    frame_ms = 1000.0 * step / grid_fps
    layout = dict(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=0, r=0, t=40 if title else 10, b=0),
        scene=scene,
        showlegend=len(motions) > 1,
        legend=dict(orientation="h", y=1.0, x=0.5, xanchor="center"),
        uirevision="skeleton",  # keep the user's camera when the figure is redrawn
        meta={"fps": grid_fps, "frame_step": step, "times": [round(float(t), 4) for t in times]},
    )
    if frames:
        play = dict(frame=dict(duration=frame_ms, redraw=True), fromcurrent=True, mode="immediate",
                    transition=dict(duration=0))
        pause = dict(frame=dict(duration=0, redraw=False), mode="immediate", transition=dict(duration=0))
        layout["updatemenus"] = [
            dict(
                type="buttons", direction="left", x=0.0, y=0.0, xanchor="left", yanchor="top",
                pad=dict(t=45, r=10), showactive=False,
                buttons=[dict(label="▶ Play", method="animate", args=[None, play]),
                         dict(label="❚❚ Pause", method="animate", args=[[None], pause])],
            )
        ]
        layout["sliders"] = [
            dict(
                active=0, x=0.18, y=0.0, len=0.82, xanchor="left", yanchor="top", pad=dict(t=30),
                currentvalue=dict(prefix="t = ", suffix=" s", visible=True),
                steps=[
                    dict(label=f"{t:.2f}", method="animate",
                         args=[[str(k)], dict(frame=dict(duration=0, redraw=True), mode="immediate",
                                              transition=dict(duration=0))])
                    for k, t in enumerate(times)
                ],
            )
        ]
        layout["margin"]["b"] = 70
    fig = go.Figure(data=traces, frames=frames, layout=layout)
    return fig


def _attribute_unit(name: str) -> str:
    return "m/s" if "speed" in name else "m"


def attribute_histograms(db, *, bins: int = 40, names: Sequence[str] | None = None, cols: int = 3) -> go.Figure:
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
        rows=rows, cols=cols, subplot_titles=[f"{n} [{_attribute_unit(n)}]" for n in names],
        horizontal_spacing=0.06, vertical_spacing=0.5 / rows,
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
                x=centres.astype(np.float32), y=counts, width=np.diff(edges).astype(np.float32),
                marker=dict(color=colors.tolist(), line=dict(width=0)), name=name, showlegend=False,
                meta={"part": "histogram", "attribute": name},
                hovertemplate=f"{name}: %{{x:.3f}} {_attribute_unit(name)}<br>%{{y}} frames<extra></extra>",
            ),
            row=row, col=col,
        )
        for which, x, color in (("low", lo, "#1f4e79"), ("high", hi, "#a3222b")):
            fig.add_vline(x=float(x), row=row, col=col, line=dict(color=color, dash="dash", width=1.5),
                          name=f"{name} {which}")
    pct = (getattr(db, "meta", None) or {}).get("build", {}).get("percentiles")
    subtitle = (
        f"dashed lines: the {pct[0]:g}th (low) and {pct[1]:g}th (high) percentiles"
        if pct else "dashed lines: the low and high thresholds"
    )
    fig.update_layout(
        title=dict(text=f"Control attributes of the database frames<br><sup>{subtitle}</sup>"),
        height=230 * rows + 80, margin=dict(l=10, r=10, t=80, b=10), bargap=0,
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
    fig.add_trace(go.Scatter(x=t_bins.astype(np.float32), y=padded.max(axis=1), mode="lines", line=line,
                             name="waveform", hoverinfo="skip", meta={"part": "waveform_max"}))
    fig.add_trace(go.Scatter(x=t_bins.astype(np.float32), y=padded.min(axis=1), mode="lines", line=line,
                             fill="tonexty", fillcolor="rgba(107,127,153,0.45)", showlegend=False,
                             hoverinfo="skip", meta={"part": "waveform_min"}))
    fig.add_trace(go.Scatter(x=t_rms.astype(np.float32), y=rms.astype(np.float32), mode="lines",
                             line=dict(color="#d1495b", width=1.5), name="RMS energy", meta={"part": "rms"},
                             hovertemplate="%{x:.2f} s: RMS %{y:.3f}<extra></extra>"))
    colors: dict[str, str] = {}
    for a, b, label in bands:
        color = colors.setdefault(label, _BAND_COLORS[len(colors) % len(_BAND_COLORS)])
        fig.add_shape(type="rect", xref="x", yref="y domain", x0=a, x1=b, y0=0, y1=1, fillcolor=color,
                      opacity=0.18, line=dict(width=0), layer="below", name=label)
        if label:
            fig.add_annotation(x=(a + b) / 2, y=1, xref="x", yref="y domain", yanchor="bottom", text=label,
                               showarrow=False, font=dict(size=10, color=color))
    fig.update_layout(
        title=dict(text=title) if title else None, height=height,
        margin=dict(l=10, r=10, t=40 if title or bands else 10, b=10),
        xaxis=dict(title="time [s]", range=[0, n / sr]), yaxis=dict(title="amplitude"),
        legend=dict(orientation="h", y=1.02, x=1, xanchor="right", yanchor="bottom"),
        uirevision="waveform",
    )
    return fig
