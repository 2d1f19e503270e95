"""The method step by step: the tables and figures the walkthroughs show.

A search step taken apart for every clip of the database is computed beside the
search (:mod:`gesturekit.search.explain`: :func:`explain_step`,
:class:`StepExplanation`, re-exported here); :func:`explain_synthesis_step` takes
a step of a finished synthesis apart from the plan the synthesis kept, and
:func:`rankings_figure` draws it.

Tables gather what the walkthrough notebooks show as pandas DataFrames: what
each control constraint admits of a database (:func:`constraints_table`),
syntheses with different settings side by side (:func:`synthesis_table`),
joins, jerk and beats of motions for one speech (:func:`motion_measures`), and
the paper's control statistics (:func:`control_statistics`). The figures
(:func:`rankings_figure`, :func:`feature_figure`) are plotly, like
:mod:`gesturekit.viz.figures`, for the notebooks and the app.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import plotly.graph_objects as go

from .._arguments import checks_arguments
from ..control import ATTRIBUTE_NAMES, CONSTRAINTS, constraint_mask
from ..errors import ConfigError
from ..search.admissible import admissible_starts
from ..search.explain import StepExplanation, explain_plan_step, explain_step, plan_step_inputs
from ._plotly import ROLE_COLORS

if TYPE_CHECKING:
    import pandas as pd

    from ..control import ControlTrack
    from ..database import MatchingDatabase
    from ..features import FeatureLayout
    from ..motion import Motion
    from ..search.plan import SearchPlan
    from ..synthesis import SynthesisResult

__all__ = [
    "StepExplanation",
    "explain_step",
    "step_inputs",
    "explain_synthesis_step",
    "explain_plan_step",
    "constraints_table",
    "synthesis_table",
    "motion_measures",
    "control_statistics",
    "rankings_figure",
    "feature_blocks",
    "feature_figure",
]


def _plan(result: SynthesisResult, db: MatchingDatabase) -> SearchPlan:
    """The plan a synthesis searched with (made again only for a result that does not keep one)."""
    if result.plan is not None:
        return result.plan
    from ..synthesis import synthesizer_for

    stages = synthesizer_for(db)
    return stages.plan(stages.features(result.audio), result.config)


@checks_arguments
def step_inputs(result: SynthesisResult, db: MatchingDatabase, step: int) -> dict:
    """What step ``step`` of a synthesis searched with: the keyword arguments of :func:`explain_step`.

    Parameters
    ----------
    result : SynthesisResult
        A finished synthesis (:func:`gesturekit.synthesis.synthesize`); its plan is read.
    db : MatchingDatabase
        The database it searched.
    step : int
        ``0 <= step < result.search.n_steps``.

    Returns
    -------
    dict
        See :func:`gesturekit.search.explain.plan_step_inputs`.
    """
    return plan_step_inputs(_plan(result, db), result.search, db.P, step)


@checks_arguments
def explain_synthesis_step(result: SynthesisResult, db: MatchingDatabase, step: int) -> StepExplanation:
    """:func:`explain_step` for step ``step`` of a finished synthesis (see :func:`step_inputs`).

    A pinned step is explained by the search's rule; its actual window is the pin
    (``result.search.pinned``).
    """
    return explain_plan_step(db, _plan(result, db), result.search, step)


# ---- tables ---------------------------------------------------------------------------------------


@checks_arguments
def constraints_table(db: MatchingDatabase, *, segment: int = 8) -> pd.DataFrame:
    """Every constraint a control can set, with its threshold and how much of the database it admits.

    Parameters
    ----------
    db : MatchingDatabase
    segment : int
        Window length N for the window counts.

    Returns
    -------
    pandas.DataFrame
        One row per ``name=value`` of :data:`gesturekit.control.CONSTRAINTS`: ``constraint``,
        ``attributes`` (tested), ``side`` (``below`` the low or ``above`` the high threshold),
        ``threshold`` (its value(s), m or m/s), ``frames`` (fraction of clip frames meeting it),
        ``windows_ends`` and ``windows_all`` (windows of N frames with a valid start the search
        may use under the mask rules ``ends`` and ``all``), and ``clips`` (clips with at least
        one such window under ``ends``).
    """
    import pandas as pd

    attrs = np.asarray(db.attributes)
    valid = np.asarray(db.valid, dtype=bool)
    th = db.thresholds
    rows = []
    for name, (names, values) in CONSTRAINTS.items():
        for value, side in values.items():
            mask = constraint_mask(attrs, ((name, value),), th)
            ends = admissible_starts(valid, int(segment), mask=mask, rule="ends")
            every = admissible_starts(valid, int(segment), mask=mask, rule="all")
            rows.append(
                {
                    "constraint": f"{name}={value}",
                    "attributes": "+".join(names),
                    "side": "below" if side == "low" else "above",
                    "threshold": ", ".join(f"{th[a][0 if side == 'low' else 1]:.3f}" for a in names),
                    "frames": float(mask.mean()),
                    "windows_ends": int(ends.sum()),
                    "windows_all": int(every.sum()),
                    "clips": int(ends.any(axis=1).sum()),
                }
            )
    return pd.DataFrame(rows)


@checks_arguments
def synthesis_table(results: Sequence[SynthesisResult], *, labels: Sequence[str] | None = None) -> pd.DataFrame:
    """Syntheses side by side: their settings, the chosen windows' distances and the joins they make.

    Parameters
    ----------
    results : sequence of SynthesisResult
    labels : sequence of str, optional
        A name per result (default ``"k=K, N=N"``).

    Returns
    -------
    pandas.DataFrame
        One row per result: ``label``, ``k``, ``segment`` (N), ``steps``, ``clips_used``
        (distinct database clips), ``pose_dist`` and ``audio_dist`` (means over the steps of
        the chosen window's distances, pinned windows outside the record left out),
        ``relaxed_steps``, ``boundary_jump`` (mean joint displacement across the joins of the
        output, metres per frame), ``boundary_jump_ratio`` (that over the displacement between
        any other two frames) and ``mean_jerk`` (m/s^3), all of the output motion.
    """
    import pandas as pd

    from ..evaluate.metrics import boundary_jumps, mean_jerk

    results = list(results)
    if labels is None:
        labels = [f"k={r.config.k}, N={r.config.segment}" for r in results]
    if len(labels) != len(results):
        raise ConfigError(f"synthesis_table got {len(labels)} labels for {len(results)} results")
    rows = []
    for label, r in zip(labels, results):
        s = r.search
        pose_dist, audio_dist = s.chosen_distances()
        N = r.config.segment
        x = r.motion.positions
        joins = boundary_jumps(x, np.arange(1, s.n_steps) * N)
        rows.append(
            {
                "label": str(label),
                "k": r.config.k,
                "segment": N,
                "steps": s.n_steps,
                "clips_used": int(np.unique(s.clip).size),
                "pose_dist": pose_dist,
                "audio_dist": audio_dist,
                "relaxed_steps": len(r.relaxed_steps),
                "boundary_jump": joins["jump"],
                "boundary_jump_ratio": joins["ratio"],
                "mean_jerk": mean_jerk(x, fps=r.motion.fps),
            }
        )
    return pd.DataFrame(rows)


@checks_arguments
def motion_measures(
    motions: Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    boundaries: Sequence[int] = (),
    audio: np.ndarray | None = None,
    sr: int | None = None,
) -> pd.DataFrame:
    """Kinematic and timing measures of motions made for one speech, one row each.

    Parameters
    ----------
    motions : sequence of Motion
        (frames, 55, 3) metres, e.g. the k-NN output and its refined version.
    labels : sequence of str, optional
    boundaries : sequence of int
        First frame of every segment after the first (where the k-NN joins windows).
    audio : np.ndarray, shape (samples,), optional
        The speech, for the beat measures.
    sr : int, optional
        Its sample rate (default 16 kHz).

    Returns
    -------
    pandas.DataFrame
        ``label``, ``boundary_jump`` (metres per frame across the joins), ``boundary_jump_ratio``
        (over any other pair of frames), ``mean_acceleration`` (m/s^2), ``mean_jerk`` (m/s^3) of
        the upper body and wrists; with ``audio`` also ``beat_consistency`` (0..1) and
        ``motion_beats_per_s`` (see :mod:`gesturekit.evaluate.metrics`).
    """
    import pandas as pd

    from ..evaluate import metrics
    from ..motion import AUDIO_SR

    motions = list(motions)
    labels = [f"motion {i + 1}" for i in range(len(motions))] if labels is None else [str(x) for x in labels]
    if len(labels) != len(motions):
        raise ConfigError(f"motion_measures got {len(labels)} labels for {len(motions)} motions")
    sr = AUDIO_SR if sr is None else int(sr)
    speech = None if audio is None else np.asarray(audio, dtype=np.float32)
    onsets = None if speech is None else metrics.audio_onsets(speech, sr=sr)
    rows = []
    for label, m in zip(labels, motions):
        x, fps = m.positions, m.fps
        joins = metrics.boundary_jumps(x, boundaries)
        row = {
            "label": label,
            "boundary_jump": joins["jump"],
            "boundary_jump_ratio": joins["ratio"],
            "mean_acceleration": metrics.mean_acceleration(x, fps=fps),
            "mean_jerk": metrics.mean_jerk(x, fps=fps),
        }
        if speech is not None:
            row["beat_consistency"] = metrics.beat_consistency_score(x, speech, fps=fps, sr=sr, onsets=onsets)
            row["motion_beats_per_s"] = metrics.motion_beats(x, fps=fps).size / m.duration
        rows.append(row)
    return pd.DataFrame(rows)


@checks_arguments
def control_statistics(
    runs: Sequence[tuple[str, Motion, ControlTrack | str]], *, thresholds: Mapping[str, tuple[float, float]]
) -> pd.DataFrame:
    """The paper's control statistics: per run and control segment, adherence and wrist statistics.

    Parameters
    ----------
    runs : sequence of (str, Motion, ControlTrack or str)
        A label (e.g. the system), the motion (frames, 55, 3) in metres, and the control track
        whose segments are measured (seconds of the motion). An empty track measures the
        whole motion as one segment labelled ``"none"``.
    thresholds : dict of str -> (float, float)
        The database's thresholds (``MatchingDatabase.thresholds``).

    Returns
    -------
    pandas.DataFrame
        Rows of :func:`gesturekit.evaluate.metrics.control_adherence` (``start_s``, ``end_s``,
        ``constraint``, ``frames``, ``adherence`` and the mean and standard deviation of
        left-wrist height [m], left-wrist and hand speed [m/s] and asymmetry [m]) with the
        run's ``label`` first; ``adherence`` is NaN for ``"none"``.
    """
    import pandas as pd

    from ..control import frame_attributes, parse_control
    from ..evaluate.metrics import control_adherence

    missing = [a for a in ATTRIBUTE_NAMES if a not in thresholds]
    if missing:
        raise ConfigError(f"thresholds lack the attributes {', '.join(missing)}")
    parts = []
    for label, motion, track in runs:
        track = parse_control(track) if isinstance(track, str) else track
        table = control_adherence(motion.positions, track, thresholds=dict(thresholds), fps=motion.fps)
        if not track:
            # the whole motion as one segment, with the statistics control_adherence reports
            attrs = frame_attributes(motion.positions, fps=motion.fps).astype(np.float64)
            row = {
                "start_s": 0.0,
                "end_s": motion.n_frames / motion.fps,
                "constraint": "none",
                "frames": motion.n_frames,
                "adherence": np.nan,
            }
            for c in (c for c in table.columns if c.endswith(("_mean", "_std"))):
                name, stat = c.rsplit("_", 1)
                col = attrs[:, ATTRIBUTE_NAMES.index(name)]
                row[c] = float(col.mean() if stat == "mean" else col.std())
            table = pd.DataFrame([row], columns=table.columns)
        table.insert(0, "label", str(label))
        parts.append(table)
    if not parts:
        raise ConfigError("control_statistics needs at least one run")
    return pd.concat(parts, ignore_index=True)


# ---- figures --------------------------------------------------------------------------------------


@checks_arguments
def rankings_figure(
    explanation: StepExplanation, *, names: Mapping[int, str] | None = None, title: str | None = None, height: int = 420
) -> go.Figure:
    """Every surviving clip of a step placed by its pose rank (x) and audio rank (y).

    Clips on a line ``x + y = c`` share the combined rank ``c``; the dashed line passes
    through the chosen clip, so the clips below it ranked better overall.

    Parameters
    ----------
    explanation : StepExplanation
    names : mapping of clip -> str, optional
        A description per clip shown on hover (e.g. its take and time).
    title : str, optional
    height : int
        Figure height in pixels.

    Returns
    -------
    plotly.graph_objects.Figure
        A marker trace (``meta["part"] == "clips"``) with one point per surviving clip,
        coloured by its place in the combined ranking; a trace ``meta["part"] == "chosen"``
        with the chosen clip; a line shape named ``"combined rank"``.
    """
    r = explanation.ranking()
    hover = [
        f"clip {c} from frame {s}<br>pose distance {pd_:.3f} (rank {pr})<br>audio distance {ad:.4f} "
        f"(rank {ar})<br>combined {cb}, place {p}" + (f"<br>{names[c]}" if names and c in names else "")
        for c, s, pd_, ad, pr, ar, cb, p in zip(
            *(
                r[col]
                for col in (
                    "clip",
                    "start",
                    "pose_dist",
                    "audio_dist",
                    "pose_rank",
                    "audio_rank",
                    "combined",
                    "position",
                )
            )
        )
    ]
    fig = go.Figure()
    fig.add_trace(
        go.Scatter(
            x=r["pose_rank"].to_numpy(),
            y=r["audio_rank"].to_numpy(),
            mode="markers",
            marker=dict(
                size=7,
                color=r["position"].to_numpy(),
                colorscale="Viridis_r",
                showscale=True,
                colorbar=dict(title="place"),
            ),
            hovertext=hover,
            hoverinfo="text",
            name="clips",
            meta={"part": "clips"},
        )
    )
    c = r[r["chosen"]].iloc[0]
    fig.add_trace(
        go.Scatter(
            x=[int(c["pose_rank"])],
            y=[int(c["audio_rank"])],
            mode="markers",
            name="chosen",
            hoverinfo="skip",
            marker=dict(size=18, color="rgba(0,0,0,0)", line=dict(color=ROLE_COLORS["chosen"], width=3)),
            meta={"part": "chosen"},
        )
    )
    total = int(c["combined"])
    fig.add_shape(
        type="line",
        x0=0,
        y0=total,
        x1=total,
        y1=0,
        line=dict(color=ROLE_COLORS["chosen"], dash="dash", width=1),
        name="combined rank",
    )
    pad = 0.02 * len(r) + 1  # room for the ring of a clip at rank 0
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        showlegend=False,
        margin=dict(l=10, r=10, t=40 if title else 10, b=10),
        xaxis=dict(title="pose rank (0 = nearest pose)", range=[-pad, len(r) - 1 + pad]),
        yaxis=dict(title="audio rank (0 = nearest audio)", range=[-pad, len(r) - 1 + pad]),
    )
    return fig


@checks_arguments
def feature_blocks(kind: str, *, layout: FeatureLayout | None = None) -> dict[str, slice]:
    """Named column blocks of a search feature: one per time offset.

    Parameters
    ----------
    kind : {"audio", "pose"}
        ``audio``: ``f_t`` (112) in blocks ``m(t+0)``, ``m(t+2)``, ... of 14 values;
        ``pose``: ``p_t`` (96) in blocks ``t+0``, ... of 24 values (8 joints x 3).
    layout : FeatureLayout, optional
        Default :data:`gesturekit.features.LAYOUT`.
    """
    from ..features import LAYOUT

    layout = layout or LAYOUT
    if kind == "audio":
        size, offsets, fmt = layout.frame_dim, layout.audio_offsets, "m(t+{})"
    elif kind == "pose":
        size, offsets, fmt = len(layout.pose_joints) * 3, layout.pose_offsets, "joints(t+{})"
    else:
        raise ConfigError(f"kind must be 'audio' or 'pose', got {kind!r}")
    return {fmt.format(o): slice(i * size, (i + 1) * size) for i, o in enumerate(offsets)}


@checks_arguments
def feature_figure(
    values: np.ndarray,
    *,
    blocks: Mapping[str, slice] | None = None,
    fps: float = 15.0,
    title: str | None = None,
    zmax: float = 3.0,
    height: int = 360,
) -> go.Figure:
    """A feature sequence as a heatmap: time across, feature dimensions down, blocks marked.

    Parameters
    ----------
    values : np.ndarray, shape (frames, dims)
        z-scored features (e.g. a query's ``f_t`` or a clip's ``P``).
    blocks : mapping of str -> slice, optional
        Named column ranges (e.g. :func:`feature_blocks`), drawn as lines and labels.
    fps : float
        Frames per second (x is in seconds).
    zmax : float
        Colour range ``[-zmax, zmax]`` (z-scores).

    Returns
    -------
    plotly.graph_objects.Figure
        One heatmap trace (``meta["part"] == "features"``) of shape (dims, frames); per block
        a line shape at its first row named by the block and a y-axis tick at its centre.
    """
    v = np.asarray(values, dtype=np.float32)
    if v.ndim != 2 or v.shape[0] < 1:
        raise ConfigError(f"values must have shape (frames >= 1, dims), got {v.shape}")
    fig = go.Figure(
        go.Heatmap(
            z=v.T,
            x=(np.arange(v.shape[0]) / fps).astype(np.float32),
            y=np.arange(v.shape[1]),
            zmin=-zmax,
            zmax=zmax,
            colorscale="RdBu_r",
            colorbar=dict(title="z"),
            meta={"part": "features"},
            hovertemplate="%{x:.2f} s, dim %{y}: %{z:.2f}<extra></extra>",
        )
    )
    yaxis: dict[str, Any] = dict(title="dimension", autorange="reversed")
    if blocks:
        # each block labelled on the y axis at its centre, a line at its first row
        for name, sl in blocks.items():
            fig.add_shape(
                type="line",
                xref="x domain",
                x0=0,
                x1=1,
                y0=sl.start - 0.5,
                y1=sl.start - 0.5,
                line=dict(color="black", width=1),
                name=name,
            )
        yaxis.update(
            title=None, tickvals=[(sl.start + sl.stop - 1) / 2 for sl in blocks.values()], ticktext=list(blocks)
        )
    fig.update_layout(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=10, r=10, t=40 if title else 10, b=10),
        xaxis=dict(title="time [s]"),
        yaxis=yaxis,
    )
    return fig
