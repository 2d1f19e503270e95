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
"""
from __future__ import annotations

import base64
import math
from typing import Sequence

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from ..control import ATTRIBUTE_NAMES, ATTRIBUTE_UNITS, ControlTrack, frame_attributes
from ..errors import ConfigError
from ..motion import Motion
from ..skeleton import BODY_JOINTS, N_JOINTS, bones, joint_index
from .appearance import APPEARANCE

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


def _chains(pairs: np.ndarray) -> list[list[int]]:
    """The bones of ``pairs`` as joint paths, each bone in exactly one path.

    A path follows a joint's first child on down and starts again from a joint
    for each further child, so a finger is one path of 5 joints (4 bones) rather
    than 4 separate bones: about half the points to draw and to send.

    Parameters
    ----------
    pairs : np.ndarray, shape (bones, 2)
        (child, parent) joint indices; each child appears once.

    Returns
    -------
    list of list of int
        Joint indices along each path, parent first.
    """
    children: dict[int, list[int]] = {}
    for c, par in pairs.tolist():
        children.setdefault(par, []).append(c)
    child_set = {c for c, _ in pairs.tolist()}
    chains = []
    # a path starts at every joint that is not drawn as a child here, and once more at a
    # joint for each of its children after the first
    starts = [j for j in children if j not in child_set]
    stack = [(j, k) for j in sorted(starts) for k in range(len(children[j]))]
    while stack:
        top, k = stack.pop(0)
        path = [top, children[top][k]]
        while path[-1] in children:
            j = path[-1]
            stack.extend((j, i) for i in range(1, len(children[j])))
            path.append(children[j][0])
        chains.append(path)
    return chains


def _polylines(positions: np.ndarray, chains: list[list[int]]) -> np.ndarray:
    """Joint paths as one polyline broken by NaN rows.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3), metres
    chains : list of list of int
        From :func:`_chains`.

    Returns
    -------
    np.ndarray, shape (frames, points, 3), float32
        The joints of each path in order, then a NaN point (plotly leaves a gap there).
    """
    idx = np.concatenate([np.append(np.asarray(c), -1) for c in chains])
    out = np.asarray(positions, np.float32)[:, idx]
    out[:, idx < 0] = np.nan
    return out


def _typed(values: np.ndarray) -> dict:
    """A float32 array as plotly's typed-array spec (little-endian, base64), as plotly itself writes it."""
    return {"dtype": "f4", "bdata": base64.b64encode(np.ascontiguousarray(values, "<f4").tobytes()).decode("ascii")}


def _xyz(points: np.ndarray) -> dict:
    """x, y, z of ``points`` (n, 3) as typed-array specs."""
    return {"x": _typed(points[:, 0]), "y": _typed(points[:, 1]), "z": _typed(points[:, 2])}


def data_array(value) -> np.ndarray:
    """A plotly data array as numbers, whichever form it takes.

    Parameters
    ----------
    value : typed-array spec, sequence or np.ndarray
        A trace's ``x``/``y``/``z`` as a figure holds it (or as its JSON has it):
        plotly's typed-array dict ``{"dtype", "bdata"[, "shape"]}``, a list
        (``None`` for a gap) or an array.

    Returns
    -------
    np.ndarray, float64
        The values; gaps are NaN.
    """
    if isinstance(value, dict) and "bdata" in value:
        out = np.frombuffer(base64.b64decode(value["bdata"]), dtype=np.dtype(value["dtype"]).newbyteorder("<"))
        if value.get("shape"):
            out = out.reshape([int(d) for d in str(value["shape"]).split(",")])
        return out.astype(np.float64)
    return np.array([np.nan if v is None else v for v in np.asarray(value, dtype=object).ravel()],
                    dtype=np.float64).reshape(np.shape(value))



def _motions_and_labels(motions, labels, *, who: str) -> tuple[list[Motion], list[str]]:
    """One motion or a list of them, with one label each (checked; ``who`` names the caller in errors)."""
    motions = [motions] if isinstance(motions, Motion) else list(motions)
    if not motions:
        raise ConfigError(f"{who} needs at least one motion")
    for m in motions:
        if not isinstance(m, Motion):
            raise ConfigError(f"{who} takes Motion objects, got {type(m).__name__}")
        if m.n_frames < 1:
            raise ConfigError(f"{who} got a motion with no frame")
    if labels is None:
        labels = [f"motion {i + 1}" for i in range(len(motions))] if len(motions) > 1 else [""]
    labels = [str(s) for s in labels]
    if len(labels) != len(motions):
        raise ConfigError(f"{who} got {len(labels)} labels for {len(motions)} motions")
    return motions, labels


def _time_grid(motions: list[Motion], *, fps, max_frames: int) -> tuple[float, int, int, np.ndarray]:
    """The time grid a skeleton view plays on: ``(grid_fps, n_grid, step, times)``.

    ``grid_fps`` is ``fps`` or the fastest motion's frame rate; ``n_grid`` frames of it
    cover the longest motion; every ``step``-th grid time is shown so that at most
    ``max_frames`` remain; ``times`` are the shown times in seconds, shape (shown,).

    Raises
    ------
    ConfigError
        ``max_frames`` below 1, or a frame rate that is not a positive finite number.
    """
    if max_frames < 1:
        raise ConfigError(f"max_frames must be at least 1, got {max_frames}")
    grid_fps = float(fps) if fps is not None else max(float(m.fps) for m in motions)
    if not (math.isfinite(grid_fps) and grid_fps > 0):
        raise ConfigError(f"fps must be positive, got {fps}")
    duration = max(m.duration for m in motions)
    n_grid = max(1, int(math.ceil(duration * grid_fps - 1e-9)))
    step = int(math.ceil(n_grid / max_frames))
    return grid_fps, n_grid, step, np.arange(0, n_grid, step) / grid_fps


def _frames_at(motion: Motion, times: np.ndarray) -> np.ndarray:
    """Indices of ``motion``'s frames shown at ``times`` (seconds): sample and hold, the last frame past its end."""
    return np.minimum(np.floor(times * motion.fps + 1e-6).astype(np.int64), motion.n_frames - 1)


def _skeleton_paths(motions: list[Motion], *, fps, max_frames: int, spacing):
    """What a skeleton view shows: the time grid and each motion's joint paths at its times.

    Returns ``(grid_fps, step, times, offsets, parts, lo, hi)``: the time grid's frame
    rate, the decimation step (every ``step``-th grid time is shown), the shown times
    in seconds, the motions' X offsets in metres (side by side), per motion its
    (body, finger) polylines of :func:`_polylines` at those times (sample and hold,
    offset along X), each (len(times), points, 3) float32, and the bounds of every
    shown pose, 0.1 m added on each side.
    """
    grid_fps, n_grid, step, times = _time_grid(motions, fps=fps, max_frames=max_frames)
    shown = [np.asarray(m.positions[_frames_at(m, times)], dtype=np.float32) for m in motions]
    if spacing is None:
        widest = max(float(np.ptp(p[..., 0])) for p in shown)
        spacing = max(0.8, widest + 0.4)
    offsets = (np.arange(len(motions)) - (len(motions) - 1) / 2) * float(spacing)
    shown = [p + np.array([dx, 0, 0], dtype=np.float32) for p, dx in zip(shown, offsets)]
    allp = np.concatenate([p.reshape(-1, 3) for p in shown])
    body_chains, hand_chains = (_chains(pairs) for pairs in _bone_groups())
    parts = [(_polylines(p, body_chains), _polylines(p, hand_chains)) for p in shown]
    return grid_fps, step, times, offsets, parts, allp.min(axis=0) - 0.1, allp.max(axis=0) + 0.1


def _torso_and_head(motions: list[Motion], times: np.ndarray, offsets: np.ndarray):
    """Per motion, at the shown times (sample and hold, offset along X): the torso's capsules of
    the appearance as NaN-separated segments, shape (times, points, 3), and the head's centre,
    shape (times, 1, 3), float32, metres."""
    a = APPEARANCE
    capsules, spheres = a.shapes()
    torso = [(c.a, c.b) for c in capsules if c.a >= N_JOINTS or c.b >= N_JOINTS]
    idx = np.array([j for pair in torso for j in (*pair, -1)])
    out = []
    for m, dx in zip(motions, offsets):
        frames = np.minimum(np.floor(times * m.fps + 1e-6).astype(np.int64), m.n_frames - 1)
        points = a.body(m.positions[frames]).points + np.array([dx, 0, 0], dtype=np.float32)
        segments = points[:, idx]
        segments[:, idx < 0] = np.nan
        out.append((segments, points[:, [s.centre for s in spheres]]))
    return out


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

    Each motion is drawn in the one appearance (:mod:`gesturekit.viz.appearance`),
    as far as plotly's 3D lines allow: its 54 bones (14 body bones up to the
    wrists as thick lines, the 40 finger bones as thin lines, widths from the
    appearance's radii at the figure's scale) with round joints, the torso's
    capsules (pelvis, hips, chest) as wide lines, and the head as a ball; in the
    motion's colour (first blue, second orange), parts tinted as in the MP4. Several
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
        Four traces per motion: ``meta["part"] == "body"`` (14 bones) and
        ``"hands"`` (40 bones), drawn as joint paths (a finger from the wrist to
        its tip) separated by NaN points, every pair of consecutive finite
        points a bone and the joints its markers; ``"torso"`` (the
        appearance's torso capsules, NaN-separated segments); ``"head"`` (one
        marker at the head's centre).
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
    motions, labels = _motions_and_labels(motions, labels, who="skeleton_figure")
    # per motion: (body polylines, finger polylines), each (frames, points, 3); markers at the
    # points draw every joint, since every joint is on a bone
    grid_fps, step, times, offsets, parts, lo, hi = _skeleton_paths(motions, fps=fps, max_frames=max_frames,
                                                                    spacing=spacing)

    # the torso's volume and the head, as the render and the page draw them
    extras = _torso_and_head(motions, times, offsets)
    parts = [(body, hands, torso, head) for (body, hands), (torso, head) in zip(parts, extras)]
    every = np.concatenate([np.concatenate([t.reshape(-1, 3), h.reshape(-1, 3)]) for t, h in extras])
    every = every[np.isfinite(every).all(axis=1)]
    a = APPEARANCE
    lo = np.minimum(lo, every.min(axis=0) - a.head_radius)
    hi = np.maximum(hi, every.max(axis=0) + a.head_radius)
    # fixed ranges over every shown frame: the view must not jump while playing
    centre, extent = (lo + hi) / 2, np.maximum(hi - lo, 0.3)
    # plotly sizes 3D lines and markers in screen pixels: the appearance's radii (metres) become
    # pixels at the figure's scale (the scene's largest side spans about 0.6 of its height)
    px = 0.6 * height / float(extent.max())

    def width(radius: float) -> float:
        return max(1.0, 2 * radius * px)

    def size(radius: float) -> float:
        # a 3D marker comes out about three times its nominal size (measured in Chromium)
        return max(1.0, 2 * radius * px / 3)

    traces = []
    for i, (label, _) in enumerate(zip(labels, parts)):
        group = f"motion{i}"
        common = dict(legendgroup=group, hoverinfo="skip", meta=None)
        body, hands, torso, head = parts[i]
        looks = (
            ("body", body, a.part_color(i, "upper_arm"), width(a.forearm_radius), label or "body", len(motions) > 1),
            ("hands", hands, a.part_color(i, "finger"), width(a.finger_radius), f"{label} hands".strip(), False),
            ("torso", torso, a.part_color(i, "torso"), width(a.torso_radius), f"{label} torso".strip(), False),
        )
        for part, points, color, w, name, legend in looks:
            common["meta"] = {"motion": i, "part": part}
            traces.append(
                go.Scatter3d(
                    **_xyz(points[0]), mode="lines+markers", line=dict(color=color, width=w),
                    # markers at the joints, as wide as the line: round ends, as the capsules have
                    marker=dict(color=color, size=w / 3, line=dict(width=0)), name=name, showlegend=legend,
                    **common,
                )
            )
        common["meta"] = {"motion": i, "part": "head"}
        color = a.part_color(i, "head")
        traces.append(
            go.Scatter3d(
                **_xyz(head[0]), mode="markers", marker=dict(color=color, size=size(a.head_radius), opacity=1.0,
                                                             line=dict(width=0)),
                name=f"{label} head".strip(), showlegend=False, **common,
            )
        )

    frames = []
    if len(times) > 1:
        trace_ids = list(range(len(traces)))
        for k in range(len(times)):
            data = [dict(type="scatter3d", **_xyz(p[k])) for part in parts for p in part]
            frames.append(dict(data=data, traces=trace_ids, name=str(k)))

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
        dragmode="orbit"  # "turntable" assumes Z up and would draw this Y-up scene upside down
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


#: Where the line charts put their legend: under the plot, at the figure's bottom left, clear of
#: the chart toolbar a page shows at the top right (and of the control labels above the plot).
BOTTOM_LEGEND = dict(orientation="h", x=0, xanchor="left", xref="container", y=0, yanchor="bottom",
                     yref="container")
#: Pixels above the plots of :func:`attribute_histograms`: its two-line title, then the subplot titles.
HISTOGRAM_TOP = 100
#: Pixels kept at the bottom of a figure for :data:`BOTTOM_LEGEND`.
LEGEND_ROOM = 30


def _attribute_unit(name: str) -> str:
    return ATTRIBUTE_UNITS.get(name, "m/s" if "speed" in name else "m")


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
        # the title sits at the figure's top, the subplot titles in room of their own below it
        title=dict(text=f"Control attributes of the database frames<br><sup>{subtitle}</sup>",
                   y=1 - 16 / (230 * rows + HISTOGRAM_TOP), yref="container", yanchor="top"),
        height=230 * rows + HISTOGRAM_TOP, margin=dict(l=10, r=10, t=HISTOGRAM_TOP, b=10), bargap=0,
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
        margin=dict(l=10, r=10, t=40 if title or bands else 10, b=10 + LEGEND_ROOM),
        xaxis=dict(title="time [s]", range=[0, n / sr]), yaxis=dict(title="amplitude"),
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
    height : int
        Figure height in pixels.

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
    bands = _as_bands(bands)
    if thresholds is not None:
        missing = [a for a, _ in WRIST_ROWS if a not in thresholds]
        if missing:
            raise ConfigError(f"wrist_figure: thresholds lack {', '.join(missing)}")

    columns = [ATTRIBUTE_NAMES.index(a) for a, _ in WRIST_ROWS]
    n_rows = len(WRIST_ROWS)
    fig = make_subplots(rows=n_rows, cols=1, shared_xaxes=True, vertical_spacing=0.045,
                        subplot_titles=[t for _, t in WRIST_ROWS])
    traces, rows = [], []
    for i, (m, label) in enumerate(zip(motions, labels)):
        values = frame_attributes(m.positions, fps=m.fps)[:, columns]
        t = (np.arange(m.n_frames) / float(m.fps)).astype(np.float32)
        color = MOTION_COLORS[i % len(MOTION_COLORS)]
        for r, (attr, _) in enumerate(WRIST_ROWS):
            unit = _attribute_unit(attr)
            traces.append(go.Scatter(
                x=t, y=values[:, r], mode="lines", line=dict(color=color, width=1.6),
                name=label or "motion", legendgroup=f"motion{i}", showlegend=r == 0 and len(motions) > 1,
                meta={"part": "wrist", "motion": i, "attribute": attr},
                hovertemplate=f"{label + ': ' if label else ''}%{{x:.2f}} s, %{{y:.3f}} {unit}<extra></extra>"))
            rows.append(r + 1)
    fig.add_traces(traces, rows=rows, cols=[1] * len(rows))

    # shapes are collected and set once: plotly's add_hline/add_vrect copy every shape on each call
    def axes(r: int) -> tuple[str, str]:
        return ("x", "y") if r == 0 else (f"x{r + 1}", f"y{r + 1}")

    shapes, notes = [], []
    if thresholds is not None:
        for r, (attr, _) in enumerate(WRIST_ROWS):
            xa, ya = axes(r)
            lo, hi = thresholds[attr]
            for which, y, color in (("low", lo, "#1f4e79"), ("high", hi, "#a3222b")):
                shapes.append(dict(type="line", xref=f"{xa} domain", x0=0, x1=1, yref=ya, y0=float(y), y1=float(y),
                                   line=dict(color=color, dash="dash", width=1), name=f"{attr} {which}"))
    colors: dict[str, str] = {}
    for a, b, label in bands:
        color = colors.setdefault(label, _BAND_COLORS[len(colors) % len(_BAND_COLORS)])
        for r in range(n_rows):
            xa, ya = axes(r)
            shapes.append(dict(type="rect", xref=xa, x0=a, x1=b, yref=f"{ya} domain", y0=0, y1=1, fillcolor=color,
                               opacity=0.18, line=dict(width=0), layer="below", name=label))
        if label:
            notes.append(dict(x=(a + b) / 2, y=1.0, xref="x", yref="y domain", yanchor="top", text=label,
                              showarrow=False, font=dict(size=10, color=color)))
    fig.update_layout(shapes=shapes, annotations=list(fig.layout.annotations) + notes)
    duration = max(m.duration for m in motions)
    fig.update_xaxes(range=[0, duration])
    fig.update_xaxes(title_text="time [s]", row=n_rows, col=1)
    fig.update_layout(
        title=dict(text=title) if title else None, height=height,
        margin=dict(l=10, r=10, t=70 if title else 45, b=10 + (LEGEND_ROOM if len(motions) > 1 else 0)),
        legend=BOTTOM_LEGEND,
        showlegend=len(motions) > 1, uirevision="wrists",
    )
    return fig


def candidates_figure(search, step: int, *, names: Sequence[str] | None = None, title: str | None = None,
                      height: int = 320) -> go.Figure:
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

    Returns
    -------
    plotly.graph_objects.Figure
        A marker trace with ``meta["part"] == "candidates"``: one point per
        recorded candidate, x the pose distance (z-scored feature units), y the
        audio (cosine) distance, labelled by its position in the combined
        ranking; and, when the chosen window is in the table, a trace with
        ``meta["part"] == "chosen"`` of one point on it.

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
    custom = np.stack([np.asarray(getattr(search, f"cand_{c}")[step])[keep]
                       for c in ("clip", "start", "pose_rank", "audio_rank", "combined")], axis=1)
    hover = ("#%{text}: clip %{customdata[0]} from frame %{customdata[1]}<br>pose distance %{x:.3f} "
             "(rank %{customdata[2]})<br>audio distance %{y:.4f} (rank %{customdata[3]})<br>"
             "combined rank %{customdata[4]}")
    if names is not None:
        hover += "<br>%{hovertext}"
    fig = go.Figure()
    fig.add_trace(go.Scatter(
        x=x, y=y, mode="markers+text", text=[str(p) for p in keep], textposition="top center",
        customdata=custom, hovertext=None if names is None else [str(names[p]) for p in keep],
        hovertemplate=hover + "<extra></extra>", marker=dict(size=9, color="#6b7f99"),
        name="candidates", meta={"part": "candidates"},
    ))
    chosen = int(search.position[step])
    if chosen >= 0 and chosen in keep:
        j = int(np.flatnonzero(keep == chosen)[0])
        fig.add_trace(go.Scatter(
            x=[x[j]], y=[y[j]], mode="markers", name="chosen", hoverinfo="skip",
            marker=dict(size=18, color="rgba(0,0,0,0)", line=dict(color="#c0502d", width=3)),
            meta={"part": "chosen"},
        ))
    fig.update_layout(
        title=dict(text=title) if title else None, height=height,
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
