"""Plotly figures: skeleton bones and animation frames, attribute thresholds, waveform bands."""

from __future__ import annotations

import numpy as np
import plotly.graph_objects as go
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.control import ATTRIBUTE_NAMES
from gesturekit.database import MatchingDatabase
from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS, bones
from gesturekit.viz._plotly import _typed
from gesturekit.viz.figures import (
    DEFAULT_MAX_FRAMES,
    attribute_histograms,
    data_array,
    skeleton_figure,
    waveform_figure,
)
from gesturekit.viz.skeleton_figure import _chains


def _motion(n_frames: int, *, seed: int = 0, fps: float = 15.0) -> Motion:
    rng = np.random.default_rng(seed)
    pos = rng.normal(0, 0.3, size=(1, N_JOINTS, 3)) + np.cumsum(rng.normal(0, 0.01, (n_frames, N_JOINTS, 3)), 0)
    return Motion(pos.astype(np.float32), fps)


def _traces(fig, motion: int) -> dict:
    return {t.meta["part"]: t for t in fig.data if t.meta.get("motion") == motion}


def _segments(trace) -> np.ndarray:
    """(bones, 2, 3) (child, parent) from a trace of joint paths separated by NaN points,
    each path parent first: every pair of consecutive finite points is one bone."""
    pts = np.stack([data_array(trace.x), data_array(trace.y), data_array(trace.z)], axis=1)
    gap = np.isnan(pts).any(axis=1)
    assert gap[-1] and (np.isnan(pts[gap]).all())
    pairs = [(pts[i + 1], pts[i]) for i in range(len(pts) - 1) if not gap[i] and not gap[i + 1]]
    return np.array(pairs)


def _bone_set(segments: np.ndarray) -> set:
    return {tuple(np.round(np.asarray(s, np.float64).ravel(), 5)) for s in segments}


def _expected_bones(positions: np.ndarray) -> set:
    """Every bone of one frame (55, 3) as a (child, parent) segment."""
    return _bone_set(np.stack([positions[bones()[:, 0]], positions[bones()[:, 1]]], axis=1))


# ---- skeleton_figure -------------------------------------------------------------------------


def test_skeleton_draws_all_54_bones_at_the_joint_positions():
    m = _motion(20)
    fig = skeleton_figure(m)
    parts = _traces(fig, 0)
    assert set(parts) == {"body", "hands", "torso", "head"}
    body, hands = _segments(parts["body"]), _segments(parts["hands"])
    assert (len(body), len(hands)) == (14, 40)
    assert _bone_set(np.concatenate([body, hands])) == _expected_bones(m.positions[0])
    # joint paths, not one polyline per bone: fewer points to send and draw
    assert data_array(parts["body"].x).size + data_array(parts["hands"].x).size < 0.55 * 3 * 54


@settings(max_examples=50, deadline=None)
@given(hst.lists(hst.integers(0, 10**6), min_size=1, max_size=60), hst.booleans())
def test_joint_paths_draw_every_bone_once(draws, forest):
    # a random tree (or forest) of joints: joint j's parent is one of the joints before it
    n = len(draws) + 1
    parents = [d % j for j, d in zip(range(1, n), draws)]
    pairs = np.array([(j, p) for j, p in zip(range(1, n), parents) if not (forest and j % 7 == 0)]).reshape(-1, 2)
    chains = _chains(pairs)
    drawn = [(c[i + 1], c[i]) for c in chains for i in range(len(c) - 1)]
    assert sorted(drawn) == sorted(map(tuple, pairs.tolist()))
    assert all(len(c) >= 2 for c in chains)


@settings(max_examples=50, deadline=None)
@given(hst.lists(hst.one_of(hst.floats(width=32, allow_nan=False), hst.just(float("nan"))), max_size=200))
def test_typed_arrays_are_what_plotly_writes_and_read_back(values):
    import json

    import plotly.io as pio

    a = np.asarray(values, np.float32)
    # the figure's own encoding equals the one plotly makes of the same float32 array
    ours = json.loads(pio.to_json(go.Figure(go.Scatter3d(x=_typed(a), y=[], z=[])), validate=False))["data"][0]["x"]
    theirs = json.loads(pio.to_json(go.Figure(go.Scatter3d(x=a, y=[], z=[])), validate=False))["data"][0]["x"]
    if a.size:
        assert ours == theirs
    for read in (data_array(ours), data_array(a), data_array([None if np.isnan(v) else float(v) for v in a])):
        np.testing.assert_array_equal(read, a.astype(np.float64))


def test_skeleton_figure_sends_typed_arrays():
    # every coordinate array of every frame travels as base64 float32, not as a list of numbers
    import json

    import plotly.io as pio

    fig = skeleton_figure([_motion(40, seed=1), _motion(40, seed=2)])
    spec = json.loads(pio.to_json(fig, validate=False))
    arrays = [t[c] for f in [spec] + spec["frames"] for t in f["data"] for c in "xyz"]
    assert len(arrays) == 3 * 8 * 41
    assert all(isinstance(a, dict) and a["dtype"] == "f4" for a in arrays)


def test_skeleton_frames_follow_the_motion():
    m = _motion(64)
    fig = skeleton_figure(m)
    assert len(fig.frames) == 64
    assert len(fig.layout.sliders[0].steps) == 64
    k = 37
    frame = fig.frames[k]
    assert list(frame.traces) == [0, 1, 2, 3]
    shown = np.concatenate([_segments(t) for t in frame.data[:2]])
    assert _bone_set(shown) == _expected_bones(m.positions[k])
    play = fig.layout.updatemenus[0].buttons[0]
    assert play.method == "animate" and play.args[1]["frame"]["duration"] == pytest.approx(1000 / 15)


def test_long_motion_is_decimated_and_plays_in_real_time():
    m = _motion(1000)
    fig = skeleton_figure(m, max_frames=300)
    step = int(np.ceil(1000 / 300))
    assert len(fig.frames) == len(range(0, 1000, step)) <= 300
    assert fig.layout.meta["frame_step"] == step
    assert fig.layout.updatemenus[0].buttons[0].args[1]["frame"]["duration"] == pytest.approx(1000 * step / 15)
    # frame j shows source frame j*step
    j = 10
    shown = _bone_set(_segments(fig.frames[j].data[0]))
    body = _segments(skeleton_figure(m.slice(j * step, j * step + 1)).data[0])
    assert shown == _bone_set(body)


@settings(max_examples=25, deadline=None)
@given(n=hst.integers(1, 400), max_frames=hst.integers(1, 120), fps=hst.sampled_from([15.0, 30.0, 60.0]))
def test_frames_never_exceed_max_and_cover_the_motion(n, max_frames, fps):
    m = Motion(np.zeros((n, N_JOINTS, 3), np.float32), fps)
    fig = skeleton_figure(m, max_frames=max_frames)
    times = np.asarray(fig.layout.meta["times"])
    assert 1 <= len(times) <= max_frames
    assert len(fig.frames) == (len(times) if len(times) > 1 else 0)
    step = fig.layout.meta["frame_step"]
    assert times[0] == 0 and times[-1] > m.duration - step / fps - 1e-3  # times are rounded to 0.1 ms


def test_side_by_side_motions_are_offset_and_the_shorter_holds_its_last_pose():
    a, b = _motion(30, seed=1), _motion(10, seed=2)
    fig = skeleton_figure([a, b], labels=["kNN", "refined"])
    assert len(fig.data) == 8 and fig.layout.showlegend
    assert [t.text for t in fig.layout.scene.annotations] == ["kNN", "refined"]
    xa = np.nanmean(data_array(_traces(fig, 0)["body"].x))
    xb = np.nanmean(data_array(_traces(fig, 1)["body"].x))
    assert xb - xa > 0.5  # the second motion stands to the viewer's right (+X)
    last = _segments(fig.frames[-1].data[4])  # motion 1's body at the last time
    held = _segments(fig.frames[9].data[4])
    np.testing.assert_allclose(last, held)


def test_camera_faces_the_character_with_y_up_and_ranges_are_fixed():
    m = _motion(40)
    fig = skeleton_figure(m)
    cam = fig.layout.scene.camera
    assert (cam.up.x, cam.up.y, cam.up.z) == (0, 1, 0)
    assert cam.eye.z > 0 and abs(cam.eye.z) > 3 * max(abs(cam.eye.x), abs(cam.eye.y))
    pts = m.positions.reshape(-1, 3)
    for i, ax in enumerate((fig.layout.scene.xaxis, fig.layout.scene.yaxis, fig.layout.scene.zaxis)):
        lo, hi = ax.range
        assert lo < pts[:, i].min() and hi > pts[:, i].max()
    go.Figure(fig.to_dict())  # the whole figure, frames included, is valid plotly


def test_skeleton_figure_rejects_bad_input():
    with pytest.raises(ConfigError):
        skeleton_figure([])
    with pytest.raises(ConfigError, match="labels"):
        skeleton_figure([_motion(5), _motion(5)], labels=["one"])
    with pytest.raises(ConfigError):
        skeleton_figure(np.zeros((5, N_JOINTS, 3)))
    with pytest.raises(ConfigError):
        skeleton_figure(_motion(5), max_frames=0)


def test_default_frame_budget():
    fig = skeleton_figure(Motion(np.zeros((DEFAULT_MAX_FRAMES + 1, N_JOINTS, 3), np.float32), 15.0))
    assert len(fig.frames) <= DEFAULT_MAX_FRAMES and fig.layout.meta["frame_step"] == 2


# ---- attribute_histograms --------------------------------------------------------------------


class _FakeDB:
    """Two attributes with known values and thresholds."""

    attribute_names = ("left_hand_height", "hand_speed")
    meta = {"build": {"percentiles": (15.0, 85.0)}}

    def __init__(self):
        self.values = {
            "left_hand_height": np.linspace(0, 1, 128).reshape(2, 64),
            "hand_speed": np.linspace(-2, 3, 192).reshape(3, 64),
        }
        self.thresholds = {"left_hand_height": (0.2, 0.7), "hand_speed": (-1.0, 2.5)}

    def attribute(self, name):
        return self.values[name]


def test_histograms_have_one_subplot_per_attribute_and_threshold_lines():
    db = _FakeDB()
    fig = attribute_histograms(db, bins=16)
    bars = [t for t in fig.data if t.meta["part"] == "histogram"]
    assert [b.meta["attribute"] for b in bars] == list(db.attribute_names)
    for bar in bars:
        name = bar.meta["attribute"]
        assert np.sum(bar.y) == db.values[name].size
        lo, hi = db.thresholds[name]
        shapes = {s.name: s for s in fig.layout.shapes if s.name.startswith(name)}
        assert set(shapes) == {f"{name} low", f"{name} high"}
        for which, x in (("low", lo), ("high", hi)):
            s = shapes[f"{name} {which}"]
            assert s.type == "line" and s.x0 == s.x1 == pytest.approx(x)
            assert s.xref == bar.xaxis  # drawn on this attribute's subplot
            assert s.yref == f"{bar.yaxis} domain"
        # bars left of the low line and right of the high line are coloured apart from the middle
        colors = np.asarray(bar.marker.color)
        x = np.asarray(bar.x)
        assert len(set(colors[x < lo])) == 1 and len(set(colors[x > hi])) == 1
        assert set(colors[x < lo]).isdisjoint(colors[(x > lo) & (x < hi)])


@pytest.mark.parametrize("n", [1, 2, 4, 9])
def test_the_histograms_title_stays_above_the_subplot_titles(n):
    from gesturekit.control import ATTRIBUTE_NAMES

    class Many(_FakeDB):
        attribute_names = ATTRIBUTE_NAMES[:n]

        def attribute(self, name):
            return np.linspace(0, 1, 128).reshape(2, 64)

        @property
        def thresholds(self):
            return {a: (0.2, 0.7) for a in self.attribute_names}

        @thresholds.setter
        def thresholds(self, value):
            pass

    fig = attribute_histograms(Many())
    height, top = fig.layout.height, fig.layout.margin.t
    title = fig.layout.title
    assert (title.yref, title.yanchor) == ("container", "top")
    title_top = (1 - title.y) * height  # pixels from the figure's top
    # two lines of title (about 45 px) end well before the subplot titles (25 px above the plots)
    assert title_top + 45 <= top - 25
    subplot_titles = [a for a in fig.layout.annotations if "[" in a.text]
    assert len(subplot_titles) == n and all(a.text.endswith(("[m]", "[m/s]")) for a in subplot_titles)


def test_histograms_of_a_matching_database():
    # a MatchingDatabase made from arrays: its attribute API without the audio pipeline
    rng = np.random.default_rng(3)
    attrs = rng.gamma(2.0, 0.1, size=(5, 64, len(ATTRIBUTE_NAMES))).astype(np.float32)
    flat = attrs.reshape(-1, len(ATTRIBUTE_NAMES))
    thresholds = {
        n: [float(np.percentile(flat[:, i], 15)), float(np.percentile(flat[:, i], 85))]
        for i, n in enumerate(ATTRIBUTE_NAMES)
    }
    meta = {"attribute_names": list(ATTRIBUTE_NAMES), "thresholds": thresholds, "build": {"percentiles": [15.0, 85.0]}}
    db = MatchingDatabase(meta=meta, arrays={"attributes": attrs}, stats={})
    fig = attribute_histograms(db)
    assert len(fig.data) == len(db.attribute_names) == 9
    assert len(fig.layout.shapes) == 18
    lo, hi = db.thresholds["asymmetry"]
    xs = sorted(s.x0 for s in fig.layout.shapes if s.name.startswith("asymmetry"))
    assert xs == pytest.approx([lo, hi])
    with pytest.raises(ConfigError):
        attribute_histograms(db, bins=0)


# ---- waveform_figure -------------------------------------------------------------------------


def test_waveform_envelope_rms_and_bands():
    sr = 16000
    t = np.arange(3 * sr) / sr
    audio = (0.5 * np.sin(2 * np.pi * 220 * t)).astype(np.float32)
    bands = [(0.5, 1.0, "clip 3"), (1.0, 2.2, "clip 7"), (2.5, 2.9, "clip 3")]
    fig = waveform_figure(audio, sr, bands=bands, max_points=500)
    parts = {tr.meta["part"]: tr for tr in fig.data}
    assert set(parts) == {"waveform_max", "waveform_min", "rms"}
    assert len(parts["waveform_max"].x) <= 500
    assert np.max(parts["waveform_max"].y) == pytest.approx(audio.max())
    assert np.min(parts["waveform_min"].y) == pytest.approx(audio.min())
    np.testing.assert_allclose(np.asarray(parts["rms"].y)[1:-1], 0.5 / np.sqrt(2), rtol=0.02)
    assert np.asarray(parts["rms"].x).max() <= 3.0
    rects = [s for s in fig.layout.shapes if s.type == "rect"]
    assert [(s.x0, s.x1, s.name) for s in rects] == bands
    assert all(s.xref == "x" for s in rects)
    assert rects[0].fillcolor == rects[2].fillcolor != rects[1].fillcolor  # one colour per label
    assert [a.text for a in fig.layout.annotations] == ["clip 3", "clip 7", "clip 3"]
    assert fig.layout.xaxis.range == (0, 3.0)


def test_short_audio_is_drawn_sample_by_sample():
    audio = np.array([0.0, 0.5, -0.25, 0.1], np.float32)
    fig = waveform_figure(audio, 4)
    top = fig.data[0]
    np.testing.assert_allclose(top.y, audio)
    np.testing.assert_allclose(top.x, [0.125, 0.375, 0.625, 0.875])
    assert len(fig.layout.shapes) == 0


def test_waveform_rejects_bad_input():
    with pytest.raises(ConfigError):
        waveform_figure(np.zeros(0), 16000)
    with pytest.raises(ConfigError):
        waveform_figure(np.zeros((10, 2)), 16000)
    with pytest.raises(ConfigError, match="after"):
        waveform_figure(np.zeros(100), 16000, bands=[(0.5, 0.5, "empty")])
    with pytest.raises(ConfigError):
        waveform_figure(np.zeros(100), 0)


def test_skeleton_figure_has_the_appearance_colours_a_head_and_thick_limbs():
    from gesturekit.viz.appearance import APPEARANCE

    a, b = _motion(5, seed=1), _motion(5, seed=2)
    fig = skeleton_figure([a, b], labels=["kNN", "refined"])
    for i in (0, 1):
        parts = _traces(fig, i)
        assert parts["body"].line.color == APPEARANCE.part_color(i, "upper_arm")
        assert parts["head"].marker.color == APPEARANCE.part_color(i, "head")
        # widths in proportion to the radii: torso > limbs > fingers, and the head the widest
        widths = {p: parts[p].line.width for p in ("torso", "body", "hands")}
        assert widths["torso"] > widths["body"] > widths["hands"] >= 1
        ratio = APPEARANCE.head_radius / APPEARANCE.torso_radius
        assert parts["head"].marker.size == pytest.approx(parts["torso"].marker.size * ratio)
    assert APPEARANCE.color(0) != APPEARANCE.color(1)
    # the head ball at the appearance's head centre (X aside: the figures stand apart)
    from gesturekit.viz.appearance import DERIVED_POINTS

    head = np.array([data_array(getattr(_traces(fig, 0)["head"], c))[0] for c in "xyz"])
    centre = APPEARANCE.body(a.positions[:1]).points[0, N_JOINTS + DERIVED_POINTS.index("head_centre")]
    np.testing.assert_allclose(head[1:], centre[1:], atol=1e-5)
