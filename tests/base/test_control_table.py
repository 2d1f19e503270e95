"""The control table: a control track as the app's editor and the inspector show it (gesturekit.control)."""

from __future__ import annotations

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.control import (
    CONSTRAINT_CHOICES,
    ControlTrack,
    Segment,
    add_segment,
    empty_segments,
    parse_control,
    segments_frame,
    track_from_segments,
)
from gesturekit.errors import ConfigError


def test_rows_with_the_same_times_form_one_segment_and_blank_rows_are_ignored():
    table = pd.DataFrame(
        [
            {"start_s": 3.0, "end_s": 4.0, "constraint": "speed=slow"},
            {"start_s": None, "end_s": None, "constraint": None},  # a row just added in the editor
            {"start_s": 0.5, "end_s": 2.0, "constraint": "left_hand=high"},
            {"start_s": 0.5, "end_s": 2.0, "constraint": "width=wide"},
        ]
    )
    track = track_from_segments(table)
    assert track.to_text() == "0.5-2:left_hand=high+width=wide,3-4:speed=slow"


@pytest.mark.parametrize(
    "rows, message",
    [
        ([{"start_s": 1.0, "end_s": None, "constraint": "speed=slow"}], "control row 1: fill in end_s"),
        (
            [
                {"start_s": 1.0, "end_s": 2.0, "constraint": "speed=slow"},
                {"start_s": 3.0, "end_s": 2.0, "constraint": "speed=fast"},
            ],
            "control row 2: .*end must be after start",
        ),
        ([{"start_s": 1.0, "end_s": 2.0, "constraint": "hands=up"}], "control row 1: unknown constraint 'hands=up'"),
        (
            [
                {"start_s": 1.0, "end_s": 2.0, "constraint": "speed=slow"},
                {"start_s": 1.0, "end_s": 2.0, "constraint": "speed=fast"},
            ],
            "control row 2: speed is set twice .*row 1",
        ),
        (
            [
                {"start_s": 1.0, "end_s": 3.0, "constraint": "speed=slow"},
                {"start_s": 2.0, "end_s": 4.0, "constraint": "width=wide"},
            ],
            "overlap",
        ),
        (
            [{"start_s": "soon", "end_s": 2.0, "constraint": "speed=slow"}],
            "control row 1: start_s and end_s must be numbers",
        ),
    ],
)
def test_invalid_rows_are_config_errors_naming_the_row(rows, message):
    with pytest.raises(ConfigError, match=message):
        track_from_segments(rows)


_constraint = hst.sampled_from(CONSTRAINT_CHOICES)


@hst.composite
def _tracks(draw):
    """Non-overlapping segments on a 0.05 s grid, each with 1-2 constraints of distinct controls."""
    cuts = sorted(draw(hst.sets(hst.integers(0, 400), min_size=0, max_size=10)))
    segs = []
    for a, b in zip(cuts[::2], cuts[1::2]):
        picked = draw(hst.lists(_constraint, min_size=1, max_size=2, unique_by=lambda c: c.split("=")[0]))
        segs.append(Segment(a * 0.05, b * 0.05, tuple(tuple(c.split("=")) for c in picked)))
    return ControlTrack(tuple(segs))


@settings(max_examples=60, deadline=None)
@given(track=_tracks())
def test_a_track_survives_the_table(track):
    assert track_from_segments(segments_frame(track)) == track


def test_adding_a_segment_cuts_what_it_overlaps():
    table = segments_frame(parse_control("0-4:speed=slow,5-6:width=wide"))
    out = add_segment(table, 1.0, 2.0, "left_hand=high")
    assert track_from_segments(out).to_text() == "0-1:speed=slow,1-2:left_hand=high,2-4:speed=slow,5-6:width=wide"
    out = add_segment(out, 3.5, 5.5, "speed=fast")
    assert (
        track_from_segments(out).to_text()
        == "0-1:speed=slow,1-2:left_hand=high,2-3.5:speed=slow,3.5-5.5:speed=fast,5.5-6:width=wide"
    )
    with pytest.raises(ConfigError, match="unknown constraint"):
        add_segment(out, 0, 1, "nonsense")


@settings(max_examples=60, deadline=None)
@given(adds=hst.lists(hst.tuples(hst.integers(0, 100), hst.integers(1, 30), _constraint), min_size=1, max_size=8))
def test_any_sequence_of_additions_leaves_a_valid_table_ending_with_the_last_range(adds):
    table = empty_segments()
    for a, length, constraint in adds:
        table = add_segment(table, a / 10, (a + length) / 10, constraint)
    track = track_from_segments(table)  # never overlapping
    a, length, constraint = adds[-1]
    name, value = constraint.split("=")
    covering = [s for s in track.segments if s.start_s <= a / 10 + 1e-9 and s.end_s >= (a + length) / 10 - 1e-9]
    assert len(covering) == 1 and covering[0].constraints == ((name, value),)
