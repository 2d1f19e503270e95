"""The method step by step: one search step taken apart, and the tables the walkthroughs show.

:func:`explain_step` recomputes a single step of Algorithm 1 (see
:mod:`gesturekit.search.reference` for the rules) for *every* clip of the
database, not only the few candidates :class:`~gesturekit.search.SearchResult`
records, and returns the whole table: each clip's nearest admissible window to
the last pose, its pose and audio distances, its two ranks, their sum and its
place in the combined ranking. Distances use the exact definitions of the
search (:func:`gesturekit.search.exact_pose_sqdist`,
:func:`gesturekit.search.exact_cosine_distance`) and ties are broken by the same
rules, so the explained choice is the search's choice, bit for bit.
:func:`explain_synthesis_step` does it for a step of a finished synthesis.

Tables gather what the walkthrough notebooks show as pandas DataFrames: what
each control constraint admits of a database (:func:`constraints_table`),
syntheses with different settings side by side (:func:`synthesis_table`),
joins, jerk and beats of motions for one speech (:func:`motion_measures`), and
the paper's control statistics (:func:`control_statistics`). The figures
(:func:`rankings_figure`, :func:`feature_figure`) are plotly, like
:mod:`gesturekit.viz.figures`, for the notebooks and the app.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
import plotly.graph_objects as go

from ..control import ATTRIBUTE_NAMES, CONSTRAINTS, constraint_mask, step_masks
from ..errors import ConfigError
from ..search import exact_cosine_distance, exact_pose_sqdist

__all__ = [
    "StepExplanation",
    "explain_step",
    "step_inputs",
    "explain_synthesis_step",
    "constraints_table",
    "synthesis_table",
    "motion_measures",
    "control_statistics",
    "rankings_figure",
    "feature_blocks",
    "feature_figure",
]

#: Rows of pose features whose exact distances are computed at once (bounds the float64 scratch).
_CHUNK_ROWS = 1 << 15


@dataclass
class StepExplanation:
    """One search step, every clip of the database accounted for.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per clip, in clip order: ``clip``; ``start`` (its nearest admissible
        window's first frame, -1 when the clip drops out); ``admissible`` (windows of the
        clip the step may use); ``pose_dist`` (Euclidean distance of the window's pose
        feature to ``p_{t-1}``, z-scored units); ``audio_dist`` (cosine distance of its
        audio feature to ``f_t``, 0..2); ``pose_rank``, ``audio_rank`` (ordinal ranks among
        the surviving clips, 0 = best, ties by clip index); ``combined`` (their sum);
        ``position`` (place in the combined ranking, ties by clip index); ``chosen``.
        Clips that drop out have NaN distances and -1 ranks.
    clip, start : int
        The chosen window.
    position : int
        Its place in the combined ranking: ``min(k, survivors - 1)``.
    next_pose : np.ndarray, shape (D,), float32
        The pose feature at the chosen window's last frame: ``p_{t-1}`` of the next step.
    pose : np.ndarray, shape (D,), float32
        The pose feature the step matched against.
    audio : np.ndarray, shape (A,), float32
        ``f_t``, the speech's audio feature at the step's first frame.
    t, step, k : int
        The step's first output frame, its length N and the k taken.
    relaxed : bool
        The control admitted no window and was dropped, as the search does.
    """

    table: "pd.DataFrame"  # noqa: F821
    clip: int
    start: int
    position: int
    next_pose: np.ndarray
    pose: np.ndarray
    audio: np.ndarray
    t: int
    step: int
    k: int
    relaxed: bool = False

    @property
    def n_survivors(self) -> int:
        """Clips with an admissible window (the rest drop out of this step)."""
        return int(np.count_nonzero(self.table["start"].to_numpy() >= 0))

    def ranking(self):
        """The surviving clips in combined-rank order (best first), as a DataFrame."""
        t = self.table[self.table["start"] >= 0]
        return t.sort_values("position").reset_index(drop=True)


def _admissible(valid, n, *, exclude, mask, rule) -> np.ndarray:
    """``ok[m, s]``: the window of ``n`` frames at ``s`` of clip ``m`` may be used (rule 1 of the search)."""
    M, T = valid.shape
    ok = np.zeros((M, T), bool)
    if n > T:
        return ok
    last = T - n + 1  # starts with s + n <= T
    ok[:, :last] = valid[:, :last]
    if exclude is not None:
        ex = np.concatenate([np.zeros((M, 1), np.int64), np.cumsum(exclude, axis=1, dtype=np.int64)], axis=1)
        ok[:, :last] &= (ex[:, n:] - ex[:, :last]) == 0  # no excluded frame in [s, s + n)
    if mask is not None:
        if rule == "ends":
            ok[:, :last] &= mask[:, :last] & mask[:, n - 1:]
        else:
            bad = np.concatenate([np.zeros((M, 1), np.int64), np.cumsum(~mask, axis=1, dtype=np.int64)], axis=1)
            ok[:, :last] &= (bad[:, n:] - bad[:, :last]) == 0
    return ok


def _nearest(P, pose, ok) -> tuple[np.ndarray, np.ndarray]:
    """Per clip the admissible start nearest ``pose`` (distance 0 skipped, ties to the smallest start).

    Returns
    -------
    start : (M,) int64, -1 where the clip drops out
    d2 : (M,) float64 squared distances, inf where it drops out
    """
    M, T, D = P.shape
    d2 = np.full(M * T, np.inf)
    flat_ok = ok.ravel()
    rows = np.flatnonzero(flat_ok)
    P2 = P.reshape(M * T, D)
    for a in range(0, rows.size, _CHUNK_ROWS):
        r = rows[a:a + _CHUNK_ROWS]
        d2[r] = exact_pose_sqdist(np.asarray(P2[r], dtype=np.float32), pose)
    d2[d2 == 0.0] = np.inf  # the query's own frame
    d2 = d2.reshape(M, T)
    start = np.argmin(d2, axis=1)  # first minimum: the smallest start on ties
    best = d2[np.arange(M), start]
    start = np.where(np.isfinite(best), start, -1)
    return start.astype(np.int64), best


def explain_step(
    db,
    query_features: np.ndarray,
    pose: np.ndarray,
    *,
    t: int = 0,
    step: int = 8,
    k: int = 0,
    mask: np.ndarray | None = None,
    exclude: np.ndarray | None = None,
    mask_rule: str = "ends",
) -> StepExplanation:
    """One step of Algorithm 1 for every clip: nearest windows, two rankings, the combined rank.

    Parameters
    ----------
    db : MatchingDatabase
        Anything with ``P`` (M, T, 96), ``F`` (M, T, 112) z-scored float32 features and
        ``valid`` (M, T) bool.
    query_features : np.ndarray, shape (T_out, 112)
        z-scored audio features of the speech (:meth:`MatchingDatabase.query_features`).
    pose : np.ndarray, shape (96,)
        ``p_{t-1}``, the z-scored pose feature of the last output frame.
    t : int
        The step's first output frame, ``0 <= t < T_out``; ``f_t = query_features[t]``.
    step : int
        Frames per step, N.
    k : int
        Which place of the combined ranking to take (0 = best).
    mask : np.ndarray, shape (M, T), bool, optional
        The step's control: the database frames it admits.
    exclude : np.ndarray, shape (M, T), bool, optional
        Frames never to use.
    mask_rule : {"ends", "all"}
        Where ``mask`` must hold in a window: its first and last frame, or every frame.

    Returns
    -------
    StepExplanation
        Its ``clip``, ``start`` and candidate order equal those of
        :func:`gesturekit.search.search` for the same step and inputs.

    Raises
    ------
    ConfigError
        Bad shapes or options, or no admissible window even without the control.
    """
    import pandas as pd

    P, F, valid = db.P, db.F, np.asarray(db.valid, dtype=bool)
    M, T = valid.shape
    q = np.asarray(query_features, dtype=np.float32)
    pose = np.asarray(pose, dtype=np.float32).ravel()
    if q.ndim != 2 or q.shape[1] != F.shape[-1]:
        raise ConfigError(f"query_features must have shape (frames, {F.shape[-1]}), got {q.shape}")
    if pose.shape != (P.shape[-1],):
        raise ConfigError(f"pose must have {P.shape[-1]} values, got shape {pose.shape}")
    if not 0 <= int(t) < q.shape[0]:
        raise ConfigError(f"t must be in 0..{q.shape[0] - 1}, got {t}")
    if int(step) < 1 or int(k) < 0:
        raise ConfigError(f"step must be >= 1 and k >= 0, got step={step}, k={k}")
    if mask_rule not in ("ends", "all"):
        raise ConfigError(f"mask_rule must be 'ends' or 'all', got {mask_rule!r}")
    for name, arr in (("mask", mask), ("exclude", exclude)):
        if arr is not None and np.shape(arr) != (M, T):
            raise ConfigError(f"{name} must have shape ({M}, {T}), got {np.shape(arr)}")
    t, step, k = int(t), int(step), int(k)
    exclude = None if exclude is None else np.asarray(exclude, dtype=bool)
    f_t = q[t]

    relaxed = False
    ok = _admissible(valid, step, exclude=exclude, mask=None if mask is None else np.asarray(mask, bool),
                     rule=mask_rule)
    start, d2 = _nearest(P, pose, ok)
    if not (start >= 0).any() and mask is not None:
        relaxed = True  # as the search: drop the control for this step, keep the exclusions
        ok = _admissible(valid, step, exclude=exclude, mask=None, rule=mask_rule)
        start, d2 = _nearest(P, pose, ok)
    alive = np.flatnonzero(start >= 0)
    if alive.size == 0:
        raise ConfigError(f"no database window is admissible at t={t} (valid start, {step} frames inside "
                          "the clip, no excluded frame) other than the query's own frame")

    audio = exact_cosine_distance(np.asarray(F[alive, start[alive]], dtype=np.float32), f_t)
    n = alive.size
    # ordinal ranks; alive is in clip order, so a stable sort breaks ties by clip index
    pose_rank = np.empty(n, np.int64)
    pose_rank[np.argsort(d2[alive], kind="stable")] = np.arange(n)
    audio_rank = np.empty(n, np.int64)
    audio_rank[np.argsort(audio, kind="stable")] = np.arange(n)
    combined = pose_rank + audio_rank
    order = np.argsort(combined, kind="stable")
    position = np.empty(n, np.int64)
    position[order] = np.arange(n)
    pos = min(k, n - 1)
    chosen = int(alive[order[pos]])
    c_start = int(start[chosen])

    def full(values, fill, dtype):
        out = np.full(M, fill, dtype=dtype)
        out[alive] = values
        return out

    table = pd.DataFrame({
        "clip": np.arange(M),
        "start": start,
        "admissible": ok.sum(axis=1),
        "pose_dist": full(np.sqrt(d2[alive]), np.nan, np.float64),
        "audio_dist": full(audio, np.nan, np.float64),
        "pose_rank": full(pose_rank, -1, np.int64),
        "audio_rank": full(audio_rank, -1, np.int64),
        "combined": full(combined, -1, np.int64),
        "position": full(position, -1, np.int64),
        "chosen": np.arange(M) == chosen,
    })
    return StepExplanation(
        table=table, clip=chosen, start=c_start, position=pos,
        next_pose=np.asarray(P[chosen, c_start + step - 1], dtype=np.float32).copy(),
        pose=pose, audio=f_t.copy(), t=t, step=step, k=k, relaxed=relaxed,
    )


def step_inputs(result, db, step: int) -> dict:
    """What step ``step`` of a synthesis searched with: the keyword arguments of :func:`explain_step`.

    Parameters
    ----------
    result : SynthesisResult
        A finished synthesis (:func:`gesturekit.synthesize.synthesize`).
    db : MatchingDatabase
        The database it searched.
    step : int
        ``0 <= step < result.search.n_steps``.

    Returns
    -------
    dict
        ``query_features`` (T_out, 112), ``pose`` (``p_{t-1}``: the initial pose for step 0,
        else the pose feature at the last frame of the previous step's window), ``t``,
        ``step`` (N), ``k``, ``mask`` (the step's control mask or None), ``exclude`` and
        ``mask_rule``.
    """
    s = result.search
    if not 0 <= int(step) < s.n_steps:
        raise ConfigError(f"step must be in 0..{s.n_steps - 1}, got {step}")
    i = int(step)
    cfg = result.config
    N = cfg.step
    n = result.n_frames
    query, _ = db.query_features(result.audio, n_frames=n)
    if i == 0:
        pose = np.asarray(s.init_pose, dtype=np.float32)
    else:
        pose = np.asarray(db.P[int(s.clip[i - 1]), int(s.start[i - 1]) + N - 1], dtype=np.float32)
    masks, smask = step_masks(result.control, np.asarray(db.attributes), db.thresholds, n_frames=n, step=N)
    mask = None if masks is None or smask[i] < 0 else masks[smask[i]]
    exclude = None
    if cfg.exclude_takes or cfg.exclude_ranges:
        exclude = db.exclusion_mask(takes=cfg.exclude_takes, ranges=cfg.exclude_ranges)
    return {"query_features": query, "pose": pose, "t": i * N, "step": N, "k": cfg.k, "mask": mask,
            "exclude": exclude, "mask_rule": cfg.mask_rule}


def explain_synthesis_step(result, db, step: int) -> StepExplanation:
    """:func:`explain_step` for step ``step`` of a finished synthesis (see :func:`step_inputs`).

    A pinned step is explained by the search's rule; its actual window is the pin
    (``result.search.pinned``).
    """
    return explain_step(db, **step_inputs(result, db, step))


# ---- tables ---------------------------------------------------------------------------------------


def constraints_table(db, *, step: int = 8):
    """Every constraint a control can set, with its threshold and how much of the database it admits.

    Parameters
    ----------
    db : MatchingDatabase
    step : int
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
            ends = _admissible(valid, int(step), exclude=None, mask=mask, rule="ends")
            every = _admissible(valid, int(step), exclude=None, mask=mask, rule="all")
            rows.append({
                "constraint": f"{name}={value}",
                "attributes": "+".join(names),
                "side": "below" if side == "low" else "above",
                "threshold": ", ".join(f"{th[a][0 if side == 'low' else 1]:.3f}" for a in names),
                "frames": float(mask.mean()),
                "windows_ends": int(ends.sum()),
                "windows_all": int(every.sum()),
                "clips": int(ends.any(axis=1).sum()),
            })
    return pd.DataFrame(rows)


def synthesis_table(results, *, labels=None):
    """Syntheses side by side: their settings, the chosen windows' distances and the joins they make.

    Parameters
    ----------
    results : sequence of SynthesisResult
    labels : sequence of str, optional
        A name per result (default ``"k=K, N=N"``).

    Returns
    -------
    pandas.DataFrame
        One row per result: ``label``, ``k``, ``step`` (N), ``steps``, ``clips_used``
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
        labels = [f"k={r.config.k}, N={r.config.step}" for r in results]
    if len(labels) != len(results):
        raise ConfigError(f"synthesis_table got {len(labels)} labels for {len(results)} results")
    rows = []
    for label, r in zip(labels, results):
        s = r.search
        idx = np.flatnonzero(s.position >= 0)
        N = r.config.step
        x = r.motion.positions
        joins = boundary_jumps(x, np.arange(1, s.n_steps) * N)
        rows.append({
            "label": str(label), "k": r.config.k, "step": N, "steps": s.n_steps,
            "clips_used": int(np.unique(s.clip).size),
            "pose_dist": float(np.mean(s.cand_pose_dist[idx, s.position[idx]])) if idx.size else float("nan"),
            "audio_dist": float(np.mean(s.cand_audio_dist[idx, s.position[idx]])) if idx.size else float("nan"),
            "relaxed_steps": len(r.relaxed_steps),
            "boundary_jump": joins["jump"], "boundary_jump_ratio": joins["ratio"],
            "mean_jerk": mean_jerk(x, fps=r.motion.fps),
        })
    return pd.DataFrame(rows)


def motion_measures(motions, *, labels=None, boundaries=(), audio=None, sr: int | None = None):
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
    onsets = None if audio is None else metrics.audio_onsets(np.asarray(audio, dtype=np.float32), sr=sr)
    rows = []
    for label, m in zip(labels, motions):
        x, fps = m.positions, m.fps
        joins = metrics.boundary_jumps(x, boundaries)
        row = {"label": label, "boundary_jump": joins["jump"], "boundary_jump_ratio": joins["ratio"],
               "mean_acceleration": metrics.mean_acceleration(x, fps=fps), "mean_jerk": metrics.mean_jerk(x, fps=fps)}
        if onsets is not None:
            row["beat_consistency"] = metrics.beat_consistency_score(x, audio, fps=fps, sr=sr, onsets=onsets)
            row["motion_beats_per_s"] = metrics.motion_beats(x, fps=fps).size / m.duration
        rows.append(row)
    return pd.DataFrame(rows)


def control_statistics(runs, *, thresholds):
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
            row = {"start_s": 0.0, "end_s": motion.n_frames / motion.fps, "constraint": "none",
                   "frames": motion.n_frames, "adherence": np.nan}
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


def rankings_figure(explanation: StepExplanation, *, names: Mapping[int, str] | None = None,
                    title: str | None = None, height: int = 420) -> go.Figure:
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
        Pixels.

    Returns
    -------
    plotly.graph_objects.Figure
        A marker trace (``meta["part"] == "clips"``) with one point per surviving clip,
        coloured by its place in the combined ranking; a trace ``meta["part"] == "chosen"``
        with the chosen clip; a line shape named ``"combined rank"``.
    """
    r = explanation.ranking()
    hover = [f"clip {c} from frame {s}<br>pose distance {pd_:.3f} (rank {pr})<br>audio distance {ad:.4f} "
             f"(rank {ar})<br>combined {cb}, place {p}" + (f"<br>{names[c]}" if names and c in names else "")
             for c, s, pd_, ad, pr, ar, cb, p in zip(*(r[col] for col in (
                 "clip", "start", "pose_dist", "audio_dist", "pose_rank", "audio_rank", "combined", "position")))]
    fig = go.Figure()
    fig.add_trace(go.Scatter(
        x=r["pose_rank"].to_numpy(), y=r["audio_rank"].to_numpy(), mode="markers",
        marker=dict(size=7, color=r["position"].to_numpy(), colorscale="Viridis_r", showscale=True,
                    colorbar=dict(title="place")),
        hovertext=hover, hoverinfo="text", name="clips", meta={"part": "clips"},
    ))
    c = r[r["chosen"]].iloc[0]
    fig.add_trace(go.Scatter(
        x=[int(c["pose_rank"])], y=[int(c["audio_rank"])], mode="markers", name="chosen", hoverinfo="skip",
        marker=dict(size=18, color="rgba(0,0,0,0)", line=dict(color="#c0502d", width=3)), meta={"part": "chosen"},
    ))
    total = int(c["combined"])
    fig.add_shape(type="line", x0=0, y0=total, x1=total, y1=0, line=dict(color="#c0502d", dash="dash", width=1),
                  name="combined rank")
    pad = 0.02 * len(r) + 1  # room for the ring of a clip at rank 0
    fig.update_layout(
        title=dict(text=title) if title else None, height=height, showlegend=False,
        margin=dict(l=10, r=10, t=40 if title else 10, b=10),
        xaxis=dict(title="pose rank (0 = nearest pose)", range=[-pad, len(r) - 1 + pad]),
        yaxis=dict(title="audio rank (0 = nearest audio)", range=[-pad, len(r) - 1 + pad]),
    )
    return fig


def feature_blocks(kind: str, *, layout=None) -> dict[str, slice]:
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


def feature_figure(values: np.ndarray, *, blocks: Mapping[str, slice] | None = None, fps: float = 15.0,
                   title: str | None = None, zmax: float = 3.0, height: int = 360) -> go.Figure:
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
    fig = go.Figure(go.Heatmap(
        z=v.T, x=(np.arange(v.shape[0]) / fps).astype(np.float32), y=np.arange(v.shape[1]),
        zmin=-zmax, zmax=zmax, colorscale="RdBu_r", colorbar=dict(title="z"), meta={"part": "features"},
        hovertemplate="%{x:.2f} s, dim %{y}: %{z:.2f}<extra></extra>",
    ))
    yaxis = dict(title="dimension", autorange="reversed")
    if blocks:
        # each block labelled on the y axis at its centre, a line at its first row
        for name, sl in blocks.items():
            fig.add_shape(type="line", xref="x domain", x0=0, x1=1, y0=sl.start - 0.5, y1=sl.start - 0.5,
                          line=dict(color="black", width=1), name=name)
        yaxis.update(title=None, tickvals=[(sl.start + sl.stop - 1) / 2 for sl in blocks.values()],
                     ticktext=list(blocks))
    fig.update_layout(
        title=dict(text=title) if title else None, height=height,
        margin=dict(l=10, r=10, t=40 if title else 10, b=10),
        xaxis=dict(title="time [s]"), yaxis=yaxis,
    )
    return fig
