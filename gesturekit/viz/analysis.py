"""Plotly figures of training logs, segment joins, speech beats and evaluation tables.

The notebooks' analysis plots, shared with anything else that shows the same
numbers: a refiner's loss curves (:func:`loss_curves_figure`), how motion moves
around the joins of concatenated segments (:func:`join_profile`,
:func:`join_profile_figure`), motion beats against speech onsets
(:func:`beats_figure`), and an evaluation's measures and control adherence per
system (:func:`metrics_figure`, :func:`adherence_figure`). Every function
returns a :class:`plotly.graph_objects.Figure`; traces carry a ``meta`` dict
saying what they show. Units: metres, seconds, m/s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..evaluate.metrics import KINEMATIC_JOINTS, audio_onsets, kinetic_velocity, motion_beats
from ..motion import AUDIO_SR, Motion
from ._plotly import MOTION_COLORS, _motions_and_labels, plotly_safe

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "LOSS_GROUPS",
    "loss_curves_figure",
    "join_profile",
    "join_profile_figure",
    "beats_figure",
    "metrics_figure",
    "adherence_figure",
]

#: The panels of :func:`loss_curves_figure`: (title, columns of the refiner's loss log).
LOSS_GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("critic", ("critic_loss", "wasserstein", "gradient_penalty")),
    ("generator", ("generator_loss",)),
    # logged on their own scales (the L1 term per value), so apart from the weighted total
    ("generator terms", ("generator_adversarial", "generator_l1")),
)


@checks_arguments
def loss_curves_figure(log: pd.DataFrame, *, smooth: int = 1, title: str | None = None, height: int = 380) -> go.Figure:
    """Training curves of a refiner: the critic's losses, the generator's loss and its terms.

    Parameters
    ----------
    log : pandas.DataFrame
        A refiner's loss log (:func:`gesturekit.refine.infer.read_loss_log`): an ``iteration``
        column and any of the loss columns of :data:`LOSS_GROUPS` (means over each logging
        interval).
    smooth : int
        Rows of a centred moving mean (1: none).
    title : str, optional
        Shown above the subplots.
    height : int
        Pixels.

    Returns
    -------
    plotly.graph_objects.Figure
        One subplot per group of :data:`LOSS_GROUPS` with a column in the log; one line per
        loss column present, ``meta = {"part": "loss", "column": name}``, x the iteration.

    Raises
    ------
    ConfigError
        No ``iteration`` column, no loss column, or ``smooth`` below 1.
    """
    if "iteration" not in getattr(log, "columns", ()):
        raise ConfigError("the loss log has no 'iteration' column")
    if int(smooth) < 1:
        raise ConfigError(f"smooth must be at least 1 row, got {smooth}")
    present = [(t, [c for c in cols if c in log.columns]) for t, cols in LOSS_GROUPS]
    present = [(t, cols) for t, cols in present if cols]
    if not present:
        known = ", ".join(c for _, g in LOSS_GROUPS for c in g)
        raise ConfigError(f"the loss log has none of the loss columns {known}")
    fig = make_subplots(rows=1, cols=len(present), subplot_titles=[t for t, _ in present], horizontal_spacing=0.07)
    x = np.asarray(log["iteration"], dtype=np.float64)
    k = 0
    for col, (_, cols) in enumerate(present, start=1):
        for name in cols:
            y = log[name].astype(float)
            if smooth > 1:
                y = y.rolling(int(smooth), center=True, min_periods=1).mean()
            fig.add_trace(
                go.Scatter(
                    x=x,
                    y=y.to_numpy(),
                    mode="lines",
                    name=name,
                    line=dict(color=MOTION_COLORS[k % len(MOTION_COLORS)], width=1.5),
                    meta={"part": "loss", "column": name},
                ),
                row=1,
                col=col,
            )
            k += 1
    fig.update_xaxes(title_text="iteration")
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=60 if title else 40, b=10),
        legend=dict(orientation="h", y=-0.2),
    )
    return fig


@checks_arguments
def join_profile(
    positions: npt.ArrayLike,
    boundaries: Sequence[int],
    *,
    fps: float,
    radius: int = 4,
    joints: Sequence[int] | None = KINEMATIC_JOINTS,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean joint speed frame by frame around the joins of concatenated segments.

    Offset 0 is the step across a join, from frame ``b - 1`` (the last of a
    segment) to frame ``b`` (the first of the next); offset ``o`` is the step
    from ``b - 1 + o`` to ``b + o``. A seamless motion has a flat profile; a
    jump at the joins makes a spike at 0.

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    boundaries : sequence of int
        First frame of every segment after the first; joins whose window of offsets leaves the
        motion are not counted.
    fps : float
        Frames per second (speeds in m/s).
    radius : int
        Offsets ``-radius .. radius``.
    joints : sequence of int or None
        Joints averaged (default the upper body and wrists; None: all).

    Returns
    -------
    offsets : np.ndarray, shape (2 * radius + 1,), int64
    speed : np.ndarray, shape (2 * radius + 1,), float64, m/s
        Mean over the counted joins and the joints of ``|x[b + o] - x[b - 1 + o]| * fps``;
        NaN when no join is counted.
    """
    x = np.asarray(positions, dtype=np.float64)
    if x.ndim != 3 or x.shape[-1] != 3:
        raise ConfigError(f"positions must have shape (frames, joints, 3), got {x.shape}")
    if not fps > 0 or int(radius) < 0:
        raise ConfigError(f"fps must be positive and radius >= 0, got fps={fps}, radius={radius}")
    if joints is not None:
        x = x[:, list(joints)]
    r = int(radius)
    offsets = np.arange(-r, r + 1)
    disp = np.linalg.norm(np.diff(x, axis=0), axis=2).mean(axis=1) * fps if x.shape[0] > 1 else np.zeros(0)
    b = np.unique(np.asarray(boundaries, dtype=np.int64).ravel())
    b = b[(b - 1 - r >= 0) & (b - 1 + r < disp.shape[0])]
    if b.size == 0:
        return offsets, np.full(offsets.shape, np.nan)
    return offsets, disp[(b - 1)[:, None] + offsets[None, :]].mean(axis=0)


@checks_arguments
def join_profile_figure(
    motions: Motion | Sequence[Motion],
    boundaries: Sequence[int],
    *,
    labels: Sequence[str] | None = None,
    radius: int = 4,
    title: str | None = None,
    height: int = 340,
) -> go.Figure:
    """:func:`join_profile` of several motions with the same joins (e.g. k-NN and refined), overlaid.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        (frames, 55, 3) metres, each at its own fps.
    boundaries : sequence of int
        First frame of every segment after the first.
    labels : sequence of str, optional
    radius : int
        Frames either side of the join.

    Returns
    -------
    plotly.graph_objects.Figure
        One line per motion (``meta = {"part": "join", "motion": i}``), x the offset in frames
        from the join, y the mean joint speed (m/s); a vertical line shape named ``"join"`` at 0.
    """
    motions, labels = _motions_and_labels(motions, labels, who="join_profile_figure", empty_ok=True, label_one=True)
    labels = [plotly_safe(label) for label in labels]
    fig = go.Figure()
    for i, (m, label) in enumerate(zip(motions, labels)):
        off, v = join_profile(m.positions, boundaries, fps=m.fps, radius=radius)
        fig.add_trace(
            go.Scatter(
                x=off,
                y=v,
                mode="lines+markers",
                name=label,
                line=dict(color=MOTION_COLORS[i % len(MOTION_COLORS)], width=2),
                meta={"part": "join", "motion": i},
            )
        )
    fig.add_vline(x=0, line=dict(color="#888", dash="dot", width=1), name="join")
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=40 if title else 10, b=10),
        xaxis=dict(title="frames from the join (0: the step across it)", dtick=1),
        yaxis=dict(title="mean joint speed [m/s]", rangemode="tozero"),
    )
    return fig


@checks_arguments
def beats_figure(
    motions: Motion | Sequence[Motion],
    audio: np.ndarray,
    *,
    labels: Sequence[str] | None = None,
    sr: int = AUDIO_SR,
    start_s: float = 0.0,
    end_s: float | None = None,
    title: str | None = None,
    height: int = 360,
) -> go.Figure:
    """Kinetic velocity of motions with their beats (velocity minima) against the speech's onsets.

    The quantities of :func:`gesturekit.evaluate.metrics.beat_consistency_score`: a beat
    near every onset scores high.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        (frames, 55, 3) metres, starting with the speech.
    audio : np.ndarray, shape (samples,)
        The speech, mono at ``sr`` Hz.
    labels : sequence of str, optional
    start_s, end_s : float
        The time range shown, seconds (default the whole longest motion).

    Returns
    -------
    plotly.graph_objects.Figure
        Per motion a line trace (``meta = {"part": "velocity", "motion": i}``) and a marker
        trace of its beats (``{"part": "beats", "motion": i}``); one marker trace of the onsets
        (``{"part": "onsets"}``) at the bottom, with vertical line shapes named ``"onset"``.
    """
    motions, labels = _motions_and_labels(motions, labels, who="beats_figure", empty_ok=True, label_one=True)
    labels = [plotly_safe(label) for label in labels]
    end = max(m.duration for m in motions) if end_s is None else float(end_s)
    if not end > start_s >= 0:
        raise ConfigError(f"need 0 <= start_s < end_s, got {start_s}-{end}")
    onsets = audio_onsets(np.asarray(audio, dtype=np.float32), sr=sr)
    onsets = onsets[(onsets >= start_s) & (onsets <= end)]
    fig = go.Figure()
    top = 0.0
    for i, (m, label) in enumerate(zip(motions, labels)):
        color = MOTION_COLORS[i % len(MOTION_COLORS)]
        v = kinetic_velocity(m.positions, fps=m.fps)
        t = np.arange(m.n_frames) / float(m.fps)
        keep = (t >= start_s) & (t <= end)
        beats = motion_beats(m.positions, fps=m.fps)
        beats = beats[(beats >= start_s) & (beats <= end)]
        bi = np.round(beats * m.fps).astype(np.int64)
        top = max(top, float(v[keep].max()) if keep.any() else 0.0)
        fig.add_trace(
            go.Scatter(
                x=t[keep],
                y=v[keep],
                mode="lines",
                name=label,
                line=dict(color=color, width=1.6),
                legendgroup=f"m{i}",
                meta={"part": "velocity", "motion": i},
            )
        )
        fig.add_trace(
            go.Scatter(
                x=beats,
                y=v[bi],
                mode="markers",
                name=f"{label} beats",
                legendgroup=f"m{i}",
                marker=dict(color=color, size=7, symbol="triangle-up"),
                showlegend=False,
                meta={"part": "beats", "motion": i},
            )
        )
    fig.add_trace(
        go.Scatter(
            x=onsets,
            y=np.zeros_like(onsets),
            mode="markers",
            name="speech onsets",
            marker=dict(color="#444", size=8, symbol="line-ns-open"),
            meta={"part": "onsets"},
        )
    )
    fig.update_layout(
        shapes=[
            dict(
                type="line",
                x0=float(o),
                x1=float(o),
                yref="y domain",
                y0=0,
                y1=1,
                line=dict(color="#bbb", width=1),
                layer="below",
                name="onset",
            )
            for o in onsets
        ]
    )
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=40 if title else 10, b=10),
        xaxis=dict(title="time [s]", range=[start_s, end]),
        yaxis=dict(title="kinetic velocity [m/s]", range=[-0.05 * top, 1.05 * top if top else 1]),
        legend=dict(orientation="h", y=1.02, x=1, xanchor="right", yanchor="bottom"),
    )
    return fig


@checks_arguments
def metrics_figure(
    table: pd.DataFrame,
    *,
    columns: Sequence[str] | None = None,
    cols: int = 4,
    title: str | None = None,
    height: int | None = None,
) -> go.Figure:
    """An evaluation table as bars: one subplot per measure, one bar per system.

    Parameters
    ----------
    table : pandas.DataFrame
        One row per system with a ``system`` column (e.g. ``Evaluation.table``).
    columns : sequence of str, optional
        Measures to show; default every numeric column but ``frames`` and ``relaxed_steps``.
    cols : int
        Subplots per row.

    Returns
    -------
    plotly.graph_objects.Figure
        One bar trace per measure (``meta = {"part": "metric", "column": name}``), x the
        systems in the table's order; NaN values are left out of their bar trace.
    """
    if "system" not in getattr(table, "columns", ()):
        raise ConfigError("the table needs a 'system' column")
    if columns is None:
        columns = [
            c
            for c in table.columns
            if c not in ("system", "frames", "relaxed_steps") and np.issubdtype(np.asarray(table[c]).dtype, np.number)
        ]
    columns = list(columns)
    missing = [c for c in columns if c not in table.columns]
    if missing or not columns or cols < 1:
        raise ConfigError(f"metrics_figure: unknown or no columns ({', '.join(missing) or 'none given'})")
    cols = min(cols, len(columns))
    rows = int(math.ceil(len(columns) / cols))
    fig = make_subplots(
        rows=rows, cols=cols, subplot_titles=columns, vertical_spacing=0.5 / rows, horizontal_spacing=0.05
    )
    systems = [str(s) for s in table["system"]]
    colors = [MOTION_COLORS[i % len(MOTION_COLORS)] for i in range(len(systems))]
    for i, name in enumerate(columns):
        y = np.asarray(table[name], dtype=np.float64)
        ok = np.isfinite(y)
        fig.add_trace(
            go.Bar(
                x=[s for s, k in zip(systems, ok) if k],
                y=y[ok],
                marker=dict(color=[c for c, k in zip(colors, ok) if k]),
                name=name,
                showlegend=False,
                meta={"part": "metric", "column": name},
                hovertemplate="%{x}: %{y:.4g}<extra></extra>",
            ),
            row=i // cols + 1,
            col=i % cols + 1,
        )
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height or 260 * rows,
        margin=dict(l=10, r=10, t=60 if title else 30, b=10),
    )
    return fig


@checks_arguments
def adherence_figure(controls: pd.DataFrame, *, title: str | None = None, height: int = 420) -> go.Figure:
    """Control adherence per control segment and system, with and without the control.

    Parameters
    ----------
    controls : pandas.DataFrame
        ``Evaluation.controls`` or rows of :func:`gesturekit.evaluate.metrics.control_adherence`
        with ``system``, ``run`` (``controlled`` / ``uncontrolled``), ``start_s``, ``end_s``,
        ``constraint`` and ``adherence`` (fraction of frames meeting the constraint).

    Returns
    -------
    plotly.graph_objects.Figure
        Two subplots (the runs, top: controlled); one bar trace per system and run
        (``meta = {"part": "adherence", "system": s, "run": r}``), x the segments as
        ``"START-END s: constraint"``, y in [0, 1].
    """
    need = {"system", "run", "start_s", "end_s", "constraint", "adherence"}
    if not need <= set(getattr(controls, "columns", ())):
        raise ConfigError(f"controls needs the columns {', '.join(sorted(need))}")
    runs = [r for r in ("controlled", "uncontrolled") if (controls["run"] == r).any()]
    if not runs:
        raise ConfigError("controls has no 'controlled' or 'uncontrolled' row")
    fig = make_subplots(
        rows=len(runs), cols=1, shared_xaxes=True, vertical_spacing=0.12, subplot_titles=[f"{r} run" for r in runs]
    )
    systems = list(dict.fromkeys(controls["system"]))
    shown = set()
    for r, run in enumerate(runs, start=1):
        for i, system in enumerate(systems):
            part = controls[(controls["run"] == run) & (controls["system"] == system)]
            if part.empty:
                continue
            x = [f"{a:.3g}-{b:.3g} s: {c}" for a, b, c in zip(part["start_s"], part["end_s"], part["constraint"])]
            fig.add_trace(
                go.Bar(
                    x=x,
                    y=part["adherence"].to_numpy(dtype=float),
                    name=system,
                    marker=dict(color=MOTION_COLORS[i % len(MOTION_COLORS)]),
                    legendgroup=system,
                    showlegend=system not in shown,
                    meta={"part": "adherence", "system": system, "run": run},
                ),
                row=r,
                col=1,
            )
            shown.add(system)
    fig.update_yaxes(range=[0, 1.05], title_text="frames meeting it")
    fig.update_layout(
        barmode="group",
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=90 if title else 60, b=10),
        legend=dict(orientation="h", y=0.99, yanchor="top", yref="container", x=1, xanchor="right"),
    )
    return fig
