"""Wrist height/speed plots (the paper's supplementary Figs. 2-3) and the candidates plot of a search step."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.control import parse_control
from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS, joint_index
from gesturekit.viz.figures import WRIST_ROWS, candidates_figure, waveform_figure, wrist_figure

THRESHOLDS = {
    "left_hand_height": (0.05, 0.4),
    "right_hand_height": (0.06, 0.41),
    "left_hand_speed": (0.1, 1.2),
    "right_hand_speed": (0.11, 1.3),
}


def _lifting(n: int, fps: float, *, speed: float) -> Motion:
    """The left wrist rises at ``speed`` m/s from 0; the right wrist holds still at 0.3 m."""
    pos = np.zeros((n, N_JOINTS, 3), dtype=np.float32)
    pos[:, joint_index("left_wrist"), 1] = speed * np.arange(n) / fps
    pos[:, joint_index("left_wrist"), 0] = 0.25
    pos[:, joint_index("right_wrist")] = (-0.25, 0.3, 0.1)
    return Motion(pos, fps)


def _trace(fig, motion: int, attribute: str):
    (t,) = [t for t in fig.data if t.meta == {"part": "wrist", "motion": motion, "attribute": attribute}]
    return t


def _shapes(fig, name: str) -> list:
    return [s for s in fig.layout.shapes if s.name == name]


def test_each_row_shows_each_motions_wrist_height_and_speed():
    fps = 15.0
    slow, fast = _lifting(30, fps, speed=0.2), _lifting(30, fps, speed=0.9)
    fig = wrist_figure([slow, fast], labels=["k-NN", "refined"])
    assert len(fig.data) == 2 * len(WRIST_ROWS)
    t = np.arange(30) / fps
    for i, v in enumerate((0.2, 0.9)):
        np.testing.assert_allclose(np.asarray(_trace(fig, i, "left_hand_height").y), v * t, atol=1e-5)
        np.testing.assert_allclose(np.asarray(_trace(fig, i, "left_hand_speed").y), v, atol=1e-4)
        np.testing.assert_allclose(np.asarray(_trace(fig, i, "right_hand_height").y), 0.3, atol=1e-6)
        np.testing.assert_allclose(np.asarray(_trace(fig, i, "right_hand_speed").y), 0.0, atol=1e-6)
        np.testing.assert_allclose(np.asarray(_trace(fig, i, "left_hand_speed").x), t, atol=1e-6)
    # the rows are stacked in WRIST_ROWS order, one y axis each, sharing time
    axes = {a: _trace(fig, 0, a).yaxis for a, _ in WRIST_ROWS}
    assert list(axes.values()) == ["y", "y2", "y3", "y4"]
    assert [t.name for t in fig.data if t.showlegend] == ["k-NN", "refined"]
    assert _trace(fig, 0, "left_hand_height").line.color != _trace(fig, 1, "left_hand_height").line.color


def test_thresholds_are_lines_in_their_own_row():
    fig = wrist_figure(_lifting(20, 15.0, speed=0.5), thresholds=THRESHOLDS)
    for r, (attr, _) in enumerate(WRIST_ROWS):
        axis = "y" if r == 0 else f"y{r + 1}"
        for which, value in zip(("low", "high"), THRESHOLDS[attr]):
            (line,) = _shapes(fig, f"{attr} {which}")
            assert line.type == "line" and line.yref == axis
            assert line.y0 == line.y1 == pytest.approx(value)
            assert (line.x0, line.x1) == (0, 1) and line.xref.endswith("domain")


def test_control_segments_shade_every_row_with_the_waveforms_colours():
    track = parse_control("0.5-1:left_hand=high,1.2-1.6:speed=slow,1.6-1.9:left_hand=high")
    fig = wrist_figure(_lifting(30, 15.0, speed=0.5), bands=track, thresholds=THRESHOLDS)
    high = _shapes(fig, "left_hand=high")
    slow = _shapes(fig, "speed=slow")
    assert len(high) == 2 * len(WRIST_ROWS) and len(slow) == len(WRIST_ROWS)
    assert sorted({(s.x0, s.x1) for s in high}) == [(0.5, 1.0), (1.6, 1.9)]
    assert {s.yref for s in slow} == {"y domain", "y2 domain", "y3 domain", "y4 domain"}
    assert len({s.fillcolor for s in high}) == 1 and high[0].fillcolor != slow[0].fillcolor
    assert sorted(a.text for a in fig.layout.annotations if a.text in ("left_hand=high", "speed=slow")) == [
        "left_hand=high",
        "left_hand=high",
        "speed=slow",
    ]
    # the same bands on the waveform get the same colours, so the two charts read together
    wave = waveform_figure(
        np.zeros(32000, np.float32), 16000, bands=[(s.start_s, s.end_s, s.label()) for s in track.segments]
    )
    assert {s.name: s.fillcolor for s in wave.layout.shapes} == {
        s.name: s.fillcolor for s in fig.layout.shapes if s.type == "rect"
    }


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(n=hst.integers(1, 80), fps=hst.sampled_from([7.5, 15.0, 30.0]), speed=hst.floats(0.0, 3.0))
def test_time_axis_covers_the_motion(n, fps, speed):
    fig = wrist_figure(_lifting(n, fps, speed=speed))
    for trace in fig.data:
        assert len(trace.x) == len(trace.y) == n
        assert np.isfinite(np.asarray(trace.y, float)).all()
    assert tuple(fig.layout.xaxis.range) == pytest.approx((0.0, n / fps))


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda m: wrist_figure([]), "at least one motion"),
        (lambda m: wrist_figure([m, m], labels=["one"]), "1 labels for 2 motions"),
        (lambda m: wrist_figure(m, thresholds={"left_hand_height": (0, 1)}), "thresholds lack right_hand_height"),
        (lambda m: wrist_figure(m, bands=[(2.0, 1.0, "x")]), r"end \(1\.0\) must be after start"),
        (lambda m: wrist_figure(m.positions), "takes Motion objects"),
    ],
)
def test_bad_arguments_are_config_errors(call, message):
    with pytest.raises(ConfigError, match=message):
        call(_lifting(10, 15.0, speed=0.1))


# ---- candidates_figure ---------------------------------------------------------------------------


def _record(position: int) -> SimpleNamespace:
    """Two steps of a search record with 4 columns; step 1 has only 3 candidates (padded)."""
    clip = np.array([[5, 6, 7, 8], [9, 3, 4, -1]])
    return SimpleNamespace(
        cand_clip=clip,
        cand_start=np.array([[0, 1, 2, 3], [4, 5, 6, -1]]),
        cand_pose_dist=np.array([[1.0, 2.0, 3.0, 4.0], [0.5, 1.5, 2.5, np.nan]]),
        cand_audio_dist=np.array([[0.4, 0.3, 0.2, 0.1], [0.9, 0.8, 0.7, np.nan]]),
        cand_pose_rank=np.array([[0, 1, 2, 3], [0, 1, 2, -1]]),
        cand_audio_rank=np.array([[3, 2, 1, 0], [2, 1, 0, -1]]),
        cand_combined=np.array([[3, 3, 3, 3], [2, 2, 2, -1]]),
        position=np.array([0, position]),
    )


def test_candidates_are_pose_against_audio_distance_with_the_chosen_one_ringed():
    fig = candidates_figure(_record(position=2), 1, names=["a", "b", "c", ""])
    (cands,) = [t for t in fig.data if t.meta["part"] == "candidates"]
    np.testing.assert_allclose(cands.x, [0.5, 1.5, 2.5])
    np.testing.assert_allclose(cands.y, [0.9, 0.8, 0.7])
    assert list(cands.text) == ["0", "1", "2"] and list(cands.hovertext) == ["a", "b", "c"]
    assert [list(r[:2]) for r in cands.customdata] == [[9, 4], [3, 5], [4, 6]]
    (chosen,) = [t for t in fig.data if t.meta["part"] == "chosen"]
    assert (chosen.x[0], chosen.y[0]) == (2.5, 0.7)


def test_a_pin_outside_the_table_has_no_ring():
    fig = candidates_figure(_record(position=-1), 1)
    assert [t.meta["part"] for t in fig.data] == ["candidates"]


@pytest.mark.parametrize("step, names, message", [(2, None, "step must be in 0..1"), (0, ["a"], "1 names for 4")])
def test_candidates_figure_rejects_bad_arguments(step, names, message):
    with pytest.raises(ConfigError, match=message):
        candidates_figure(_record(0), step, names=names)


@pytest.mark.parametrize("which", ["waveform", "wrists"])
def test_legends_sit_under_the_plot_clear_of_the_chart_toolbar(which):
    """A page's chart toolbar covers the top right: the legend goes to the bottom left, in room of its own."""
    if which == "waveform":
        fig = waveform_figure(np.sin(np.arange(16000, dtype=np.float32) / 30), 16000, bands=[(0.1, 0.5, "speed=slow")])
    else:
        m = _lifting(45, 15.0, speed=0.5)
        fig = wrist_figure([m, m], labels=["k-NN", "k-NN + refiner"])
    legend = fig.layout.legend
    assert (legend.xref, legend.yref) == ("container", "container")
    assert (legend.x, legend.xanchor, legend.y, legend.yanchor) == (0, "left", 0, "bottom")
    assert fig.layout.margin.b >= 30  # the legend's row, under the axis title
    assert any(t.showlegend is not False for t in fig.data)


@settings(max_examples=40, deadline=None)
@given(hst.lists(hst.tuples(hst.floats(0, 50), hst.floats(0, 2)), min_size=1, max_size=10))
def test_the_candidates_plot_holds_every_point_and_room_for_its_label(points):
    from types import SimpleNamespace

    n = len(points)
    col = lambda v, dt=np.int64: np.asarray([v], dtype=dt)  # noqa: E731  (one step)
    rec = SimpleNamespace(
        cand_clip=col(list(range(n))),
        cand_start=col([0] * n),
        cand_pose_rank=col(list(range(n))),
        cand_audio_rank=col(list(range(n))),
        cand_combined=col(list(range(n))),
        position=np.asarray([0]),
        cand_pose_dist=col([p for p, _ in points], np.float64),
        cand_audio_dist=col([a for _, a in points], np.float64),
    )
    fig = candidates_figure(rec, 0)
    (x0, x1), (y0, y1) = fig.layout.xaxis.range, fig.layout.yaxis.range
    xs, ys = [p for p, _ in points], [a for _, a in points]
    assert x0 < min(xs) and max(xs) < x1 and y0 < min(ys) and max(ys) < y1
    # above the highest point, room for a label: a fifth of the points' spread (or of their size)
    spread = (max(ys) - min(ys)) or max(abs(max(ys)), 1.0) * 0.1
    assert y1 - max(ys) >= 0.2 * spread - 1e-12


def test_take_names_and_labels_reach_plotly_as_text_not_markup():
    """plotly reads HTML (<a href> makes a link) in names and hover labels, and fills %{...}
    in hover templates: a take name or label from a file is shown as typed."""
    payload = "<a href='http://127.0.0.1:9/x'>take</a> %{x}"
    fig = candidates_figure(_record(position=2), 1, names=[payload, "b", "c", ""])
    (cands,) = [t for t in fig.data if t.meta["part"] == "candidates"]
    assert (
        "<a" not in cands.hovertext[0] and "&lt;a href='http://127.0.0.1:9/x'&gt;take&lt;/a&gt;" in cands.hovertext[0]
    )
    assert "%{x}" not in cands.hovertext[0]
    fig = wrist_figure([_lifting(30, 15.0, speed=0.2), _lifting(30, 15.0, speed=0.1)], labels=[payload, "plain"])
    names = {t.name for t in fig.data if t.name}
    assert not any("<a" in n or "%{x}" in n for n in names)
    assert any(n.startswith("&lt;a href=") for n in names) and "plain" in names
    assert not any("<a" in (t.hovertemplate or "") for t in fig.data)
