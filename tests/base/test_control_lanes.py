"""Controls as lanes of a timeline (gesturekit.control_lanes): ranges to the search's track and back, and curves
turned into a level per step, each checked against a literal frame-by-frame reading."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.control import CONSTRAINTS, ControlTrack, Segment, step_masks
from gesturekit.control_lanes import (
    LANE_LABELS,
    LANES,
    curve_attribute,
    curve_span,
    lane_levels,
    ranges_frame,
    ranges_from_curve,
    ranges_from_track,
    replace_in_lane,
    track_from_ranges,
)
from gesturekit.errors import ConfigError
from gesturekit.skeleton import FPS

STEP = 8  # frames per search step


def test_every_control_has_a_lane_a_label_and_two_levels():
    assert LANES == tuple(CONSTRAINTS) and set(LANE_LABELS) == set(LANES)
    assert lane_levels("speed") == ("slow", "fast") and lane_levels("symmetry") == ("symmetric", "asymmetric")
    assert curve_attribute("left_hand") == "left_hand_height" and curve_attribute("both_hands") is None
    with pytest.raises(ConfigError, match="unknown control 'elbow'"):
        lane_levels("elbow")


@hst.composite
def lane_ranges(draw) -> list[dict]:
    """Ranges on a grid of steps: per lane, a few that do not overlap (they may touch), at random levels."""
    rows = []
    for lane in draw(hst.lists(hst.sampled_from(LANES), unique=True, max_size=4)):
        cuts = sorted(draw(hst.lists(hst.integers(0, 20), unique=True, min_size=2, max_size=8)))
        for a, b in zip(cuts, cuts[1:]):
            if draw(hst.booleans()):
                level = draw(hst.sampled_from(lane_levels(lane)))
                rows.append({"start_s": a * 0.5, "end_s": b * 0.5, "constraint": f"{lane}={level}"})
    return draw(hst.permutations(rows))


def held_at(rows: list[dict], t: float) -> dict[str, str]:
    """The literal reading: every range over time ``t`` gives its lane's level."""
    out = {}
    for r in rows:
        if r["start_s"] <= t < r["end_s"]:
            lane, _, level = r["constraint"].partition("=")
            out[lane] = level
    return out


@settings(max_examples=150)
@given(lane_ranges())
def test_the_track_holds_at_each_time_exactly_the_ranges_over_it(rows):
    track = track_from_ranges(rows)
    for t in np.arange(0.25, 10.5, 0.5):  # the middle of each half-second cell
        seg = next((s for s in track.segments if s.start_s <= t < s.end_s), None)
        assert (dict(seg.constraints) if seg else {}) == held_at(rows, t)
    for a, b in zip(track.segments, track.segments[1:]):  # touching pieces differ, or they would be one
        assert a.end_s < b.start_s or a.constraints != b.constraints
    for seg in track.segments:  # in the order of the lanes
        assert [n for n, _ in seg.constraints] == [lane for lane in LANES if lane in dict(seg.constraints)]


@settings(max_examples=150)
@given(lane_ranges())
def test_ranges_come_back_from_the_track_with_touching_ones_of_a_level_joined(rows):
    back = ranges_from_track(track_from_ranges(rows))
    assert track_from_ranges(back) == track_from_ranges(rows)
    for t in np.arange(0.25, 10.5, 0.5):
        assert held_at(back, t) == held_at(rows, t)
    assert len(back) <= len(rows)
    by_lane: dict[str, list[dict]] = {}
    for r in back:
        by_lane.setdefault(r["constraint"].partition("=")[0], []).append(r)
    for spans in by_lane.values():  # no two of a lane touch at the same level
        for a, b in zip(spans, spans[1:]):
            assert a["end_s"] < b["start_s"] or a["constraint"] != b["constraint"]


def test_a_table_of_segments_with_shared_times_reads_as_before():
    table = pd.DataFrame(
        [
            {"start_s": 0.5, "end_s": 2.0, "constraint": "left_hand=high"},
            {"start_s": None, "end_s": None, "constraint": None},  # a row just added in the editor
            {"start_s": 0.5, "end_s": 2.0, "constraint": "width=wide"},
            {"start_s": 3.0, "end_s": 4.0, "constraint": "speed=slow"},
        ]
    )
    assert track_from_ranges(table) == ControlTrack(
        (Segment(0.5, 2.0, (("left_hand", "high"), ("width", "wide"))), Segment(3.0, 4.0, (("speed", "slow"),)))
    )
    frame = ranges_frame(track_from_ranges(table))
    assert frame.to_dict("records") == [
        {"start_s": 0.5, "end_s": 2.0, "constraint": "left_hand=high"},
        {"start_s": 0.5, "end_s": 2.0, "constraint": "width=wide"},
        {"start_s": 3.0, "end_s": 4.0, "constraint": "speed=slow"},
    ]
    assert ranges_frame(ControlTrack(())).empty


@pytest.mark.parametrize(
    "rows, message",
    [
        (
            [
                {"start_s": 0, "end_s": 2, "constraint": "speed=slow"},
                {"start_s": 1, "end_s": 3, "constraint": "speed=fast"},
            ],
            "control rows 1 and 2 both set speed over 1-2 s",
        ),
        ([{"start_s": 1, "end_s": None, "constraint": "speed=slow"}], "control row 1: fill in end_s"),
        ([{"start_s": 2, "end_s": 1, "constraint": "speed=slow"}], "control row 1: .*end must be after start"),
        ([{"start_s": 0, "end_s": 1, "constraint": "elbow=up"}], "control row 1: unknown constraint 'elbow=up'"),
        ([{"start_s": "soon", "end_s": 1, "constraint": "speed=slow"}], "must be numbers of seconds"),
    ],
)
def test_bad_rows_are_refused_naming_them(rows, message):
    with pytest.raises(ConfigError, match=message):
        track_from_ranges(rows)


def literal_curve_levels(lane, t, y, low, high, n_frames, segment, fps):
    """Step by step, frame by frame, as the guide says: the band of the curve's mean over the frames it spans
    of each step whose middle frame it spans."""
    out = []
    lo_level, hi_level = lane_levels(lane)
    order = np.argsort(t, kind="stable")
    t, y = np.asarray(t)[order], np.asarray(y)[order]
    for i in range(-(-n_frames // segment)):
        frames = list(range(i * segment, min((i + 1) * segment, n_frames)))
        middle = frames[(len(frames) - 1) // 2]
        if not t[0] - 1e-9 <= middle / fps <= t[-1] + 1e-9:
            out.append(None)
            continue
        values = [np.interp(f / fps, t, y) for f in frames if t[0] - 1e-9 <= f / fps <= t[-1] + 1e-9]
        mean = sum(values) / len(values)
        out.append(lo_level if mean < low else hi_level if mean > high else None)
    return out


@settings(max_examples=100)
@given(
    hst.lists(hst.tuples(hst.floats(0, 6), hst.floats(-1, 1)), min_size=2, max_size=30),
    hst.integers(1, 95),
    hst.sampled_from([1, 4, 8, 16]),
)
def test_a_curve_gives_each_step_the_band_of_its_mean(points, n_frames, segment):
    t = np.array([p[0] for p in points])
    y = np.array([p[1] for p in points])
    thresholds = {"left_hand_height": (-0.3, 0.2)}
    if np.ptp(t) <= 0:
        with pytest.raises(ConfigError, match="two points at different times"):
            ranges_from_curve("left_hand", t, y, thresholds=thresholds, n_frames=n_frames, segment=segment)
        return
    rows = ranges_from_curve("left_hand", t, y, thresholds=thresholds, n_frames=n_frames, segment=segment)
    want = literal_curve_levels("left_hand", t, y, -0.3, 0.2, n_frames, segment, FPS)
    # what the search will apply to each step (its middle frame's constraints) is the step's band
    track = track_from_ranges(rows)
    _, index = step_masks(track, np.zeros((1, 64, 9)), thresholds, n_frames=n_frames, segment=segment)
    got = []
    for i in range(len(want)):
        a, b = i * segment, min((i + 1) * segment, n_frames)
        labels = track.frame_labels(n_frames)[(a + b - 1) // 2]
        got.append(dict(labels).get("left_hand"))
    assert got == want
    assert (index >= 0).sum() == sum(w is not None for w in want)
    for r in rows:  # on step boundaries (or the output's end)
        for edge in (r["start_s"], r["end_s"]):
            frames = edge * FPS
            assert abs(frames - round(frames)) < 1e-4 and (round(frames) % segment == 0 or round(frames) == n_frames)


def test_a_curve_needs_a_lane_of_one_attribute_and_matching_shapes():
    th = {"left_hand_height": (0.0, 1.0), "right_hand_height": (0.0, 1.0)}
    with pytest.raises(ConfigError, match="only in a lane of one attribute"):
        ranges_from_curve("both_hands", np.array([0, 1.0]), np.array([0, 1.0]), thresholds=th, n_frames=15, segment=8)
    with pytest.raises(ConfigError, match="one value per time"):
        ranges_from_curve("left_hand", np.array([0, 1.0]), np.array([0.0]), thresholds=th, n_frames=15, segment=8)


def test_a_curve_replaces_its_lane_where_it_decides_the_steps_only():
    rows = [
        {"start_s": 0.0, "end_s": 4.0, "constraint": "left_hand=low"},
        {"start_s": 0.0, "end_s": 4.0, "constraint": "speed=fast"},
    ]
    span = curve_span(np.array([1.1, 2.0]), n_frames=60, segment=8)
    # steps of 8 frames at 15 fps: 1.067-1.6 s (middle 1.267 s) and 1.6-2.133 s (middle 1.8 s) are spanned
    assert span == (round(16 / 15, 6), round(32 / 15, 6))
    new = [{"start_s": span[0], "end_s": span[1], "constraint": "left_hand=high"}]
    out = replace_in_lane(rows, "left_hand", new, start_s=span[0], end_s=span[1])
    assert held_at(out, 0.5) == {"left_hand": "low", "speed": "fast"}
    assert held_at(out, 1.5) == {"left_hand": "high", "speed": "fast"}
    assert held_at(out, 3.0) == {"left_hand": "low", "speed": "fast"}
    assert curve_span(np.array([0.0, 0.1]), n_frames=60, segment=8) is None  # spans no step's middle frame
