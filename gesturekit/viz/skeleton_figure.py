"""The 3D skeleton figure: motions side by side, animated on one time grid, in plotly.

The bones are drawn as a few polylines per motion (body and fingers), the
torso and head as the house appearance draws them; frames hold the same traces
at each shown time. Part of :mod:`gesturekit.viz.figures`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import plotly.graph_objects as go

from .._arguments import checks_arguments
from ..motion import Motion
from ..skeleton import BODY_JOINTS, N_JOINTS, JointPresence, joint_index
from ._plotly import _frames_at, _motions_and_labels, _time_grid, _xyz, plotly_safe
from .appearance import APPEARANCE, DERIVED_PART

#: Most animation frames a skeleton figure holds (20 s at 15 fps). Longer motions are
#: shown at a lower frame rate; each frame then lasts longer, so playback keeps real time.
DEFAULT_MAX_FRAMES = 300


def _bone_groups(presence: JointPresence | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(child, parent) pairs of the body bones (up to the wrists), of the finger bones, and of the
    derived bones (an end derived), each shape (B, 2); bones with an absent end are in none.
    A complete skeleton has 14 body bones, 40 finger bones and no derived bone."""
    presence = presence or JointPresence.full()
    pairs = presence.drawn_bones()
    derived = presence.derived[pairs].any(axis=1)
    wrists = {joint_index("left_wrist"), joint_index("right_wrist")}
    body = np.array([c < len(BODY_JOINTS) or c in wrists for c in pairs[:, 0]], dtype=bool)
    return pairs[body & ~derived], pairs[~body & ~derived], pairs[derived]


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
    if not chains:
        return np.zeros((len(positions), 0, 3), np.float32)
    idx = np.concatenate([np.append(np.asarray(c), -1) for c in chains])
    out = np.asarray(positions, np.float32)[:, idx]
    out[:, idx < 0] = np.nan
    return out


def _skeleton_paths(
    motions: list[Motion], *, fps: float | None, max_frames: int, spacing: float | None
) -> tuple[float, int, np.ndarray, np.ndarray, list[tuple[np.ndarray, np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
    """What a skeleton view shows: the time grid and each motion's joint paths at its times.

    Returns ``(grid_fps, step, times, offsets, parts, lo, hi)``: the time grid's frame
    rate, the decimation step (every ``step``-th grid time is shown), the shown times
    in seconds, the motions' X offsets in metres (side by side), per motion its
    (body, finger, derived) polylines of :func:`_polylines` at those times (sample and
    hold, offset along X), each (len(times), points, 3) float32, and the bounds of every
    shown joint that exists (absent ones are not drawn), 0.1 m added on each side.
    """
    grid_fps, n_grid, step, times = _time_grid(motions, fps=fps, max_frames=max_frames)
    shown = [np.asarray(m.positions[_frames_at(m, times)], dtype=np.float32) for m in motions]
    drawn = [m.presence.drawn for m in motions]
    if spacing is None:
        widest = max(float(np.ptp(p[:, d, 0])) for p, d in zip(shown, drawn))
        spacing = max(0.8, widest + 0.4)
    offsets = (np.arange(len(motions)) - (len(motions) - 1) / 2) * float(spacing)
    shown = [p + np.array([dx, 0, 0], dtype=np.float32) for p, dx in zip(shown, offsets)]
    allp = np.concatenate([p[:, d].reshape(-1, 3) for p, d in zip(shown, drawn)])
    parts = []
    n_body = len(BODY_JOINTS)
    for m, p in zip(motions, shown):
        groups = [_chains(pairs) for pairs in _bone_groups(m.presence)]
        # a joint that exists but has no bone to a drawn joint is still shown, as a lone point
        on_bone = np.zeros(N_JOINTS, dtype=bool)
        on_bone[m.presence.drawn_bones().ravel()] = True
        for j in np.flatnonzero(m.presence.drawn & ~on_bone).tolist():
            group = 2 if m.presence.derived[j] else 0 if j < n_body else 1
            groups[group].append([j])
        body, hands, derived = (_polylines(p, chains) for chains in groups)
        parts.append((body, hands, derived))
    return grid_fps, step, times, offsets, parts, allp.min(axis=0) - 0.1, allp.max(axis=0) + 0.1


def _torso_and_head(
    motions: list[Motion], times: np.ndarray, offsets: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]]:
    """Per motion, at the shown times (sample and hold, offset along X): the torso's capsules of
    the appearance as NaN-separated segments, shape (times, points, 3), those of derived joints
    alike, the head's centre, shape (times, 0 or 1, 3), float32, metres, and whether the head is
    derived. Shapes of absent joints are left out."""
    a = APPEARANCE
    out = []
    for m, dx in zip(motions, offsets):
        capsules, spheres = a.shapes(m.presence)
        torso = [(c.a, c.b, c.part == DERIVED_PART) for c in capsules if c.a >= N_JOINTS or c.b >= N_JOINTS]
        points = a.body(m.positions[_frames_at(m, times)]).points + np.array([dx, 0, 0], dtype=np.float32)
        segs = []
        for derived in (False, True):
            idx = np.array([j for u, v, d in torso if d == derived for j in (u, v, -1)], dtype=np.int64)
            segments = points[:, idx]
            segments[:, idx < 0] = np.nan
            segs.append(segments)
        out.append(
            (segs[0], segs[1], points[:, [sp.centre for sp in spheres]], any(sp.part == DERIVED_PART for sp in spheres))
        )
    return out


@checks_arguments
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
        marker at the head's centre; ``meta["derived"]`` says whether it is derived, then
        grey). A motion with derived joints (placed from others) has a fifth trace,
        ``"derived"``: the bones and torso capsules touching them, grey, dashed and
        translucent, named "derived" in the legend. Absent joints are in no trace.
        One ``go.Frame`` per shown time (named by its index,
        ``layout.meta`` holds ``{"fps", "frame_step", "times"}`` with the
        times in seconds), and a scene camera with ``up = (0, 1, 0)`` and the
        eye on the +Z side.

    Raises
    ------
    ConfigError
        No motion, a motion with no frame or with every joint absent, labels of
        the wrong length, or a non-positive ``fps``/``max_frames``.
    """
    motions, labels = _motions_and_labels(motions, labels, who="skeleton_figure", drawn=True)
    labels = [plotly_safe(label) for label in labels]
    # per motion: (body, finger, derived polylines), each (frames, points, 3); markers at the
    # points draw every joint that exists (on a bone, or a lone point)
    grid_fps, step, times, offsets, parts, lo, hi = _skeleton_paths(
        motions, fps=fps, max_frames=max_frames, spacing=spacing
    )

    # the torso's volume and the head, as the render and the page draw them
    extras = _torso_and_head(motions, times, offsets)
    every = np.concatenate(
        [np.concatenate([t.reshape(-1, 3), d.reshape(-1, 3), h.reshape(-1, 3)]) for t, d, h, _ in extras]
    )
    every = every[np.isfinite(every).all(axis=1)]
    a = APPEARANCE
    if len(every):
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
    arrays: list[np.ndarray] = []  # each trace's points at every shown time, in trace order
    for i, label in enumerate(labels):
        group = f"motion{i}"
        common: dict[str, Any] = dict(legendgroup=group, hoverinfo="skip", meta=None)
        (body, hands, derived_bones), (torso, derived_torso, head, head_derived) = parts[i], extras[i]
        looks = (
            ("body", body, a.part_color(i, "upper_arm"), width(a.forearm_radius), label or "body", len(motions) > 1),
            ("hands", hands, a.part_color(i, "finger"), width(a.finger_radius), f"{label} hands".strip(), False),
            ("torso", torso, a.part_color(i, "torso"), width(a.torso_radius), f"{label} torso".strip(), False),
        )
        for part, points, color, w, name, legend in looks:
            common["meta"] = {"motion": i, "part": part}
            traces.append(
                go.Scatter3d(
                    **_xyz(points[0]),
                    mode="lines+markers",
                    line=dict(color=color, width=w),
                    # markers at the joints, as wide as the line: round ends, as the capsules have
                    marker=dict(color=color, size=w / 3, line=dict(width=0)),
                    name=name,
                    showlegend=legend,
                    **common,
                )
            )
            arrays.append(points)
        common["meta"] = {"motion": i, "part": "head", "derived": head_derived}
        color = a.part_color(i, DERIVED_PART if head_derived else "head")
        traces.append(
            go.Scatter3d(
                **_xyz(head[0]),
                mode="markers",
                marker=dict(color=color, size=size(a.head_radius), opacity=1.0, line=dict(width=0)),
                name=f"{label} head{' (derived)' if head_derived else ''}".strip(),
                showlegend=False,
                **common,
            )
        )
        arrays.append(head)
        if derived_bones.shape[1] or derived_torso.shape[1]:
            # joints placed from others (a torso and head from the neck and shoulders): thin,
            # grey and dashed, named in the legend, so nobody takes them for recorded data
            points = np.concatenate([derived_bones, derived_torso], axis=1)
            color = a.part_color(i, DERIVED_PART)
            traces.append(
                go.Scatter3d(
                    **_xyz(points[0]),
                    mode="lines+markers",
                    line=dict(color=color, width=width(a.forearm_radius), dash="dash"),
                    marker=dict(color=color, size=width(a.finger_radius) / 3, line=dict(width=0)),
                    opacity=0.7,
                    name=f"{label} derived".strip() if len(motions) > 1 else "derived (placed from neck and shoulders)",
                    showlegend=True,
                    hovertext="derived",
                    legendgroup=group,
                    hoverinfo="text",
                    meta={"motion": i, "part": DERIVED_PART},
                )
            )
            arrays.append(points)

    frames = []
    if len(times) > 1:
        trace_ids = list(range(len(traces)))
        for k in range(len(times)):
            data = [dict(type="scatter3d", **_xyz(p[k])) for p in arrays]
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
        camera=dict(
            up=dict(x=0, y=1, z=0),
            eye=dict(x=0.0, y=0.15, z=1.9),
            center=dict(x=0, y=0, z=0),
            projection=dict(type="perspective"),
        ),
        annotations=annotations,
        dragmode="orbit",  # "turntable" assumes Z up and would draw this Y-up scene upside down
    )
    frame_ms = 1000.0 * step / grid_fps
    layout: dict[str, Any] = dict(
        title=dict(text=title) if title else None,
        height=height,
        margin=dict(l=0, r=0, t=40 if title else 10, b=0),
        scene=scene,
        showlegend=len(motions) > 1 or any(not m.presence.is_full for m in motions),
        legend=dict(orientation="h", y=1.0, x=0.5, xanchor="center"),
        uirevision="skeleton",  # keep the user's camera when the figure is redrawn
        meta={"fps": grid_fps, "frame_step": step, "times": [round(float(t), 4) for t in times]},
    )
    if frames:
        play = dict(
            frame=dict(duration=frame_ms, redraw=True), fromcurrent=True, mode="immediate", transition=dict(duration=0)
        )
        pause = dict(frame=dict(duration=0, redraw=False), mode="immediate", transition=dict(duration=0))
        layout["updatemenus"] = [
            dict(
                type="buttons",
                direction="left",
                x=0.0,
                y=0.0,
                xanchor="left",
                yanchor="top",
                pad=dict(t=45, r=10),
                showactive=False,
                buttons=[
                    dict(label="▶ Play", method="animate", args=[None, play]),
                    dict(label="❚❚ Pause", method="animate", args=[[None], pause]),
                ],
            )
        ]
        layout["sliders"] = [
            dict(
                active=0,
                x=0.18,
                y=0.0,
                len=0.82,
                xanchor="left",
                yanchor="top",
                pad=dict(t=30),
                currentvalue=dict(prefix="t = ", suffix=" s", visible=True),
                steps=[
                    dict(
                        label=f"{t:.2f}",
                        method="animate",
                        args=[
                            [str(k)],
                            dict(frame=dict(duration=0, redraw=True), mode="immediate", transition=dict(duration=0)),
                        ],
                    )
                    for k, t in enumerate(times)
                ],
            )
        ]
        layout["margin"]["b"] = 70
    fig = go.Figure(data=traces, frames=frames, layout=layout)
    return fig
