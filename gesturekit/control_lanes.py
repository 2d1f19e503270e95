"""Controls as lanes of a timeline: one lane per control, ranges painted in it, and curves drawn in it.

The app's control timeline shows one *lane* per control of :data:`gesturekit.control.CONSTRAINTS`
(left hand height, right hand height, both hands, speed, ...). A *range* is one stretch of one
lane at one level, written as a row of the control table: ``start_s``, ``end_s`` and
``constraint`` (``"left_hand=high"``). Ranges of different lanes may overlap in time; where
they do, all their constraints hold. :func:`track_from_ranges` turns ranges into the
:class:`~gesturekit.control.ControlTrack` the search uses (cut wherever a lane's range begins
or ends); :func:`ranges_from_track` gives them back, one range per lane and stretch.

:func:`ranges_from_curve` turns a curve drawn in a lane (a wrist height over time, say) into
ranges that hold per search step: each step takes the level whose band holds the curve's mean
over the step (``docs/guides/controls.md``, "A drawn curve").
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from ._arguments import checks_arguments
from .control import CONSTRAINTS, SEGMENT_COLUMNS, ControlTrack, Segment, empty_segments, filled_rows
from .errors import ConfigError
from .skeleton import FPS

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "LANES",
    "LANE_LABELS",
    "lane_levels",
    "curve_attribute",
    "track_from_ranges",
    "ranges_from_track",
    "ranges_frame",
    "ranges_from_curve",
    "replace_in_lane",
    "curve_span",
]

#: One lane per control, in the order of :data:`gesturekit.control.CONSTRAINTS`.
LANES: tuple[str, ...] = tuple(CONSTRAINTS)

#: What the timeline calls each lane.
LANE_LABELS: dict[str, str] = {
    "left_hand": "left hand height",
    "right_hand": "right hand height",
    "both_hands": "both hands height",
    "speed": "hand speed",
    "left_speed": "left hand speed",
    "right_speed": "right hand speed",
    "symmetry": "symmetry",
    "width": "hand width",
}

_EPS = 1e-6  # seconds: times closer than this are one time (the table keeps microseconds)


@checks_arguments
def lane_levels(lane: str) -> tuple[str, str]:
    """The levels of ``lane``: its "low" value first, its "high" value second (``("slow", "fast")``)."""
    if lane not in CONSTRAINTS:
        raise ConfigError(f"unknown control {lane!r}; known controls: {', '.join(CONSTRAINTS)}")
    by_side = {side: value for value, side in CONSTRAINTS[lane][1].items()}
    return by_side["low"], by_side["high"]


@checks_arguments
def curve_attribute(lane: str) -> str | None:
    """The one attribute a curve drawn in ``lane`` gives values of, or None for a lane of several
    (``both_hands`` tests two attributes at once: a curve of one value cannot say both)."""
    attrs = CONSTRAINTS[lane][0] if lane in CONSTRAINTS else ()
    return attrs[0] if len(attrs) == 1 else None


def _checked(records: Iterable[Mapping]) -> list[tuple[float, float, str, str]]:
    """(start, end, lane, level) of each filled row, in row order; a bad row raises, named from 1."""
    out = [(seg.start_s, seg.end_s, *seg.constraints[0], i) for i, seg in filled_rows(records)]
    by_lane: dict[str, list[tuple[float, float, int]]] = {}
    for start, end, lane, _, i in out:
        by_lane.setdefault(lane, []).append((start, end, i))
    for lane, spans in by_lane.items():
        spans.sort()
        for (a0, a1, ia), (b0, b1, ib) in zip(spans, spans[1:]):
            if b0 < a1 - _EPS:
                first, second = sorted((ia, ib))
                raise ConfigError(
                    f"control rows {first} and {second} both set {lane} over {max(a0, b0):g}-{min(a1, b1):g} s; "
                    "a lane holds one level at a time"
                )
    return [(s, e, lane, level) for s, e, lane, level, _ in out]


@checks_arguments
def track_from_ranges(ranges: pd.DataFrame | Sequence[Mapping]) -> ControlTrack:
    """The control track of a timeline's ranges (rows of the control table).

    The track is cut wherever a range begins or ends; each piece holds the
    constraints of every range over it, in the order of :data:`LANES`, and
    neighbouring pieces with the same constraints are one segment.

    Parameters
    ----------
    ranges : pandas.DataFrame or sequence of mappings
        Columns ``start_s``, ``end_s`` (seconds, ``0 <= start < end``) and
        ``constraint`` (``"lane=level"``, one of :data:`gesturekit.control.CONSTRAINT_CHOICES`).
        Rows whose cells are all empty are ignored. Rows of one lane must not overlap;
        rows of different lanes may.

    Returns
    -------
    ControlTrack

    Raises
    ------
    ConfigError
        A row with a missing or invalid value, or two rows of one lane that overlap; the
        message names the rows (counted from 1).

    Examples
    --------
    >>> from gesturekit.control_lanes import track_from_ranges
    >>> track = track_from_ranges([
    ...     {"start_s": 0.0, "end_s": 3.0, "constraint": "left_hand=high"},
    ...     {"start_s": 2.0, "end_s": 4.0, "constraint": "speed=slow"},
    ... ])
    >>> track.to_text()
    '0-2:left_hand=high,2-3:left_hand=high+speed=slow,3-4:speed=slow'
    """
    records = ranges.to_dict("records") if hasattr(ranges, "to_dict") else [dict(r) for r in ranges]
    rows = _checked(records)
    cuts = sorted({t for s, e, _, _ in rows for t in (s, e)})
    pieces: list[tuple[float, float, tuple[tuple[str, str], ...]]] = []
    for a, b in zip(cuts, cuts[1:]):
        mid = (a + b) / 2
        held = {lane: level for s, e, lane, level in rows if s <= mid < e}
        constraints = tuple((lane, held[lane]) for lane in LANES if lane in held)
        if not constraints:
            continue
        if pieces and pieces[-1][2] == constraints and abs(pieces[-1][1] - a) < _EPS:
            pieces[-1] = (pieces[-1][0], b, constraints)
        else:
            pieces.append((a, b, constraints))
    return ControlTrack(tuple(Segment(a, b, c) for a, b, c in pieces))


@checks_arguments
def ranges_from_track(track: ControlTrack) -> list[dict]:
    """A track's ranges: for each lane, one range per stretch of one level (touching segments joined).

    Returns
    -------
    list of dict
        ``start_s``, ``end_s`` (seconds) and ``constraint`` (``"lane=level"``), sorted by lane
        (the order of :data:`LANES`), then time. :func:`track_from_ranges` gives the track back
        (with touching segments of the same constraints joined).
    """
    out: list[dict] = []
    for lane in LANES:
        spans: list[list] = []
        for seg in track.segments:
            level = dict(seg.constraints).get(lane)
            if level is None:
                continue
            if spans and spans[-1][2] == level and abs(spans[-1][1] - seg.start_s) < _EPS:
                spans[-1][1] = seg.end_s
            else:
                spans.append([seg.start_s, seg.end_s, level])
        out.extend({"start_s": float(a), "end_s": float(b), "constraint": f"{lane}={v}"} for a, b, v in spans)
    return out


@checks_arguments
def ranges_frame(track: ControlTrack) -> pd.DataFrame:
    """:func:`ranges_from_track` as the control table (columns :data:`gesturekit.control.SEGMENT_COLUMNS`),
    sorted by start time."""
    import pandas as pd  # kept local: only the table needs pandas

    rows = ranges_from_track(track)
    if not rows:
        return empty_segments()
    table = pd.DataFrame(rows, columns=list(SEGMENT_COLUMNS)).astype({"start_s": "float64", "end_s": "float64"})
    return table.sort_values(["start_s", "end_s"], kind="stable").reset_index(drop=True)


@checks_arguments
def ranges_from_curve(
    lane: str,
    times_s: np.ndarray,
    values: np.ndarray,
    *,
    thresholds: Mapping[str, tuple[float, float]],
    n_frames: int,
    segment: int,
    fps: float = FPS,
) -> list[dict]:
    """Ranges of ``lane`` that follow a drawn curve, one level per search step.

    The curve is sampled at each output frame it spans (linearly between its
    points). A step (``segment`` frames) is decided by the curve when the curve
    spans the step's middle frame, the frame whose constraints the search
    applies to the whole step (:func:`gesturekit.control.step_masks`): the
    step takes the lane's low level when the curve's mean over the frames of
    the step it spans is below the attribute's low threshold, the high level
    when above the high threshold, and no constraint in between. Steps next
    to each other with the same level are one range.

    Parameters
    ----------
    lane : str
        A lane of one attribute (:func:`curve_attribute`), e.g. ``"left_hand"``.
    times_s : np.ndarray, shape (P,)
        The curve's times, seconds, increasing (the order it was drawn in is not needed).
    values : np.ndarray, shape (P,)
        The curve's values, in the attribute's unit (metres for a height).
    thresholds : mapping
        Attribute name -> (low, high) thresholds (the database's).
    n_frames : int
        Frames of the output.
    segment : int
        Frames per search step, N.
    fps : float
        Output frames per second.

    Returns
    -------
    list of dict
        ``start_s``, ``end_s``, ``constraint`` of each range, by time; the ranges start and end
        on step boundaries (or the output's end).

    Raises
    ------
    ConfigError
        A lane of several attributes, a curve of fewer than two finite points, or shapes that differ.

    Examples
    --------
    >>> import numpy as np
    >>> from gesturekit.control_lanes import ranges_from_curve
    >>> rows = ranges_from_curve("left_hand", np.array([0.0, 2.0]), np.array([-0.5, 0.5]),
    ...                          thresholds={"left_hand_height": (-0.2, 0.2)}, n_frames=30, segment=8)
    >>> [(r["start_s"], r["end_s"], r["constraint"]) for r in rows]
    [(0.0, 0.533333, 'left_hand=low'), (1.6, 2.0, 'left_hand=high')]
    """
    attribute = curve_attribute(lane)
    if attribute is None:
        raise ConfigError(f"a curve can be drawn only in a lane of one attribute, not {lane!r}")
    t = np.asarray(times_s, dtype=np.float64).ravel()
    v = np.asarray(values, dtype=np.float64).ravel()
    if t.shape != v.shape:
        raise ConfigError(f"a curve needs one value per time, got {t.size} times and {v.size} values")
    keep = np.isfinite(t) & np.isfinite(v)
    t, v = t[keep], v[keep]
    if t.size < 2 or np.ptp(t) <= 0:
        raise ConfigError("a curve needs at least two points at different times")
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    if segment < 1 or n_frames < 1:
        raise ConfigError(f"need n_frames >= 1 and segment >= 1, got {n_frames} and {segment}")
    low, high = thresholds[attribute]
    low_level, high_level = lane_levels(lane)
    frame_t = np.arange(n_frames) / fps
    spanned = (frame_t >= t[0] - 1e-9) & (frame_t <= t[-1] + 1e-9)
    sampled = np.interp(frame_t, t, v)
    pieces: list[list] = []
    for i in range(-(-n_frames // segment)):
        a, b = i * segment, min((i + 1) * segment, n_frames)
        if not spanned[(a + b - 1) // 2]:
            continue
        mean = float(sampled[a:b][spanned[a:b]].mean())
        level = low_level if mean < low else high_level if mean > high else None
        if level is None:
            continue
        start, end = round(a / fps, 6), round(b / fps, 6)
        if pieces and pieces[-1][2] == level and abs(pieces[-1][1] - start) < _EPS:
            pieces[-1][1] = end
        else:
            pieces.append([start, end, level])
    return [{"start_s": a, "end_s": b, "constraint": f"{lane}={level}"} for a, b, level in pieces]


@checks_arguments
def replace_in_lane(
    ranges: Sequence[Mapping], lane: str, new: Sequence[Mapping], *, start_s: float, end_s: float
) -> list[dict]:
    """``ranges`` with ``lane`` cleared over ``[start_s, end_s)`` (a range across it cut in two) and ``new`` added.

    How a drawn curve's ranges (:func:`ranges_from_curve`) take the place of what the lane held
    where the curve was drawn; other lanes are kept as they are.

    Parameters
    ----------
    ranges, new : sequence of mappings
        Rows of the control table (``start_s``, ``end_s``, ``constraint``).
    lane : str
        The lane cleared.
    start_s, end_s : float
        The stretch cleared, seconds.

    Returns
    -------
    list of dict
        The rows, sorted by start time.
    """
    out = []
    for r in ranges:
        a, b = float(r["start_s"]), float(r["end_s"])
        if str(r["constraint"]).partition("=")[0] != lane or b <= start_s + _EPS or a >= end_s - _EPS:
            out.append(dict(r))
            continue
        for lo, hi in ((a, min(b, start_s)), (max(a, end_s), b)):
            if hi - lo > _EPS:
                out.append({**r, "start_s": round(lo, 6), "end_s": round(hi, 6)})
    out.extend(dict(r) for r in new)
    return sorted(out, key=lambda r: (float(r["start_s"]), float(r["end_s"])))


@checks_arguments
def curve_span(times_s: np.ndarray, *, n_frames: int, segment: int, fps: float = FPS) -> tuple[float, float] | None:
    """The stretch of the steps a curve over ``times_s`` decides (:func:`ranges_from_curve`), seconds.

    Returns
    -------
    (float, float) or None
        From the first decided step's start to the last one's end; None when the curve spans
        no step's middle frame.
    """
    t = np.asarray(times_s, dtype=np.float64).ravel()
    t = t[np.isfinite(t)]
    if t.size == 0:
        return None
    lo, hi = float(t.min()), float(t.max())
    decided = [
        i
        for i in range(-(-n_frames // segment))
        if lo - 1e-9 <= ((i * segment + min((i + 1) * segment, n_frames) - 1) // 2) / fps <= hi + 1e-9
    ]
    if not decided:
        return None
    return round(decided[0] * segment / fps, 6), round(min((decided[-1] + 1) * segment, n_frames) / fps, 6)
