"""Why a clip was chosen: the query pose each step matched against, the candidates' clips and their figures."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gesturekit import interactive as gs
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.search.explain import query_pose_frame
from gesturekit.skeleton import BODY_JOINTS, N_JOINTS, joint_index
from gesturekit.synthesis import SynthesisConfig, synthesize
from gesturekit.viz.retrieval import (
    CHOSEN_COLOR,
    GHOST_COLOR,
    SELECTED_COLOR,
    CandidateView,
    candidate_figure,
    candidates_strip,
    front_view_lines,
)
from gesturekit.viz.walkthrough import step_inputs
from tests.conftest import make_take

pytestmark = pytest.mark.slow  # the module's database and syntheses take a few seconds


@pytest.fixture(scope="module")
def db():
    takes = [make_take(20.0, seed=s, name=f"t{s}") for s in range(3)]
    return MatchingDatabase.build(takes, config=BuildConfig())


@pytest.fixture(scope="module", params=["rest", "random"])
def result(db, request):
    audio = make_take(5.0, seed=9).audio
    cfg = SynthesisConfig.from_dict({"init": request.param, "record": 6, "k": 1, "seed": 4})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GestureKitWarning)
        return synthesize(audio, db=db, config=cfg)


def test_the_query_pose_is_the_pose_every_candidate_was_measured_from(db, result):
    s = result.search
    for step in range(s.n_steps):
        clip, frame = query_pose_frame(db.P, s, step)
        # the very feature the search compared with (the plan's p_{t-1}) ...
        np.testing.assert_array_equal(db.P[clip, frame], step_inputs(result, db, step)["pose"])
        # ... so each recorded candidate's pose distance is its first frame's distance to it
        keep = s.cand_clip[step] >= 0
        d = np.linalg.norm(
            db.P[s.cand_clip[step][keep], s.cand_start[step][keep]].astype(np.float64) - db.P[clip, frame], axis=1
        )
        np.testing.assert_allclose(d, s.cand_pose_dist[step][keep], rtol=1e-5, atol=1e-5)
        q = gs.query_pose(db, result, step)
        np.testing.assert_array_equal(q.reshape(-1), db.G[clip, frame])
    with pytest.raises(ConfigError, match="step must be in"):
        query_pose_frame(db.P, s, s.n_steps)


def test_an_initial_pose_that_is_no_database_frame_has_no_ghost(db, result):
    s = result.search
    s0 = type(s)(**{**s.__dict__, "init_pose": s.init_pose + 1e3, "init_frame": (-1, -1)})
    assert query_pose_frame(db.P, s0, 0) is None
    assert query_pose_frame(db.P, s0, 1) == query_pose_frame(db.P, s, 1)


def test_candidate_views_hold_each_candidates_whole_clip_and_window(db, result):
    s, n = result.search, result.config.segment
    step = 2
    views = gs.candidate_views(db, result, step)
    keep = np.flatnonzero(s.cand_clip[step] >= 0)
    assert [v.position for v in views] == keep.tolist()
    assert [v.chosen for v in views] == [int(p) == int(s.position[step]) for p in keep]
    for v, p in zip(views, keep):
        clip, start = int(s.cand_clip[step][p]), int(s.cand_start[step][p])
        assert v.clip_positions.shape == (db.G.shape[1], N_JOINTS, 3) and v.start == start
        np.testing.assert_array_equal(v.clip_positions.reshape(db.G.shape[1], -1), db.G[clip])
        np.testing.assert_array_equal(v.window.reshape(len(v.window), -1), db.G[clip, start : start + n])
        assert v.pose_dist == pytest.approx(s.cand_pose_dist[step][p])
    audio = gs.clip_speech(db, int(s.cand_clip[step][0]))
    assert len(audio) == pytest.approx(db.G.shape[1] / db.fps * 16000, abs=2)


def _parts(fig, part):
    return [t for t in fig.data if t.meta and t.meta.get("part") == part]


def test_the_strip_draws_every_candidate_over_the_ghost_with_its_wrist_paths(db, result):
    step = 3
    views = gs.candidate_views(db, result, step)
    q = gs.query_pose(db, result, step)
    selected = next(v.position for v in views if not v.chosen)
    fig = candidates_strip(views, q, selected=selected)
    ghosts = _parts(fig, "ghost")
    assert len(ghosts) == len(views)
    gx, gy = front_view_lines(q)
    np.testing.assert_array_equal(np.asarray(ghosts[0].x, np.float32), gx)
    assert ghosts[0].line.color == GHOST_COLOR
    for v in views:
        (first,) = [t for t in _parts(fig, "first frame") if t.meta["candidate"] == v.position]
        x, y = front_view_lines(v.window[0])
        np.testing.assert_array_equal(np.asarray(first.x, np.float32), x)
        expected = CHOSEN_COLOR if v.chosen else SELECTED_COLOR if v.position == selected else first.line.color
        assert first.line.color == expected
        for side in ("left", "right"):
            (path,) = [t for t in _parts(fig, f"{side} wrist path") if t.meta["candidate"] == v.position]
            w = v.window[:, joint_index(f"{side}_wrist")]
            np.testing.assert_array_equal(np.asarray(path.x, np.float32), w[:, 0])
            np.testing.assert_array_equal(np.asarray(path.y, np.float32), w[:, 1])
            assert {int(c[0]) for c in path.customdata} == {v.position}  # a click selects this candidate
    # one range for every panel: sizes compare across candidates
    ranges = {tuple(fig.layout[f"xaxis{'' if c == 1 else c}"].range) for c in range(1, len(views) + 1)}
    assert len(ranges) == 1
    # rows of at most five stay readable
    assert candidates_strip(views, q, per_row=5).layout.height == 210 * -(-len(views) // 5)


def test_the_large_view_marks_the_window_in_the_whole_clip_beside_the_steps_speech(db, result):
    step = 1
    views = gs.candidate_views(db, result, step)
    v = views[-1]
    n, fps = result.config.segment, db.fps
    speech = gs.step_speech(result, step)
    fig = candidate_figure(v, gs.query_pose(db, result, step), fps=fps, clip_audio=gs.clip_speech(db, 0), speech=speech)
    strip = _parts(fig, "filmstrip")
    frames = [t.meta["frame"] for t in strip]
    inside = [t.meta["frame"] for t in strip if t.meta["in_window"]]
    end = min(v.start + n, v.clip_positions.shape[0])
    assert v.start in inside and end - 1 in inside and all(v.start <= f < end for f in inside)
    assert set(f for f in frames if not v.start <= f < end) == set(range(v.start % 8, 64, 8)) - set(range(v.start, end))
    # each pose is placed at its frame's time in the clip (the pelvis, x = 0, at frame / fps)
    for t in strip:
        pelvis_x = float(np.asarray(t.x)[0])
        assert pelvis_x == pytest.approx(t.meta["frame"] / fps, abs=1e-6)
    (band,) = [sh for sh in fig.layout.shapes if sh.name == "window"]
    assert (band.x0, band.x1) == (pytest.approx(v.start / fps), pytest.approx(end / fps))
    (step_speech,) = _parts(fig, "step speech")
    xs = np.asarray(step_speech.x)
    assert xs.min() >= v.start / fps - 1e-6 and xs.max() <= v.start / fps + len(speech) / 16000 + 1e-6
    (clip_speech,) = _parts(fig, "clip speech")
    assert np.asarray(clip_speech.x).max() == pytest.approx(64 / fps, abs=0.01)


@settings(max_examples=30, deadline=None)
@given(arrays(np.float32, (N_JOINTS, 3), elements=st.floats(-2, 2, width=32)))
def test_front_view_lines_join_joints_seen_from_the_front(pose):
    x, y = front_view_lines(pose)
    segments = np.split(np.stack([x, y], 1), np.flatnonzero(np.isnan(x)) + 1)
    segments = [sg[~np.isnan(sg[:, 0])] for sg in segments if (~np.isnan(sg[:, 0])).any()]
    assert len(segments) == len(BODY_JOINTS) + 4 and all(len(sg) == 2 for sg in segments)
    joints = np.concatenate([pose[:, :2], np.zeros((1, 2), np.float32)])
    for sg in segments:
        for point in sg:
            assert np.any(np.all(joints == point, axis=1))


def test_bad_inputs_are_refused_with_a_message():
    with pytest.raises(ConfigError, match="shape"):
        front_view_lines(np.zeros((54, 3)))
    clip = np.zeros((64, N_JOINTS, 3))
    with pytest.raises(ConfigError, match="outside a clip"):
        CandidateView(position=0, clip_positions=clip, start=64, segment=8, pose_dist=0, audio_dist=0)
    v = CandidateView(position=0, clip_positions=clip, start=3, segment=8, pose_dist=0, audio_dist=0)
    with pytest.raises(ConfigError, match="query pose"):
        candidates_strip([v], np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="at least one"):
        candidates_strip([], None)
    with pytest.raises(ConfigError, match="fps"):
        candidate_figure(v, None, fps=0)


def test_every_2d_view_draws_the_chosen_candidate_in_the_palettes_chosen_colour(db, result):
    from gesturekit.character.look import ROLE_SCHEMES, SCHEMES
    from gesturekit.viz.figures import candidates_figure
    from gesturekit.viz.walkthrough import explain_synthesis_step, rankings_figure

    chosen = SCHEMES[ROLE_SCHEMES["chosen"]]["shirt"]  # what the chosen candidate's character wears in 3D
    step = 2
    views = gs.candidate_views(db, result, step)
    q = gs.query_pose(db, result, step)
    (view,) = [v for v in views if v.chosen]
    # the large view and the strip: the chosen candidate's first frame
    large = candidate_figure(view, q, fps=db.fps)
    strip = candidates_strip(views, q)
    for fig in (large, strip):
        colours = {t.line.color for t in _parts(fig, "first frame") if t.meta.get("candidate") == view.position}
        assert colours == {chosen}
    # the pose-vs-audio scatter and the rankings: the ring around the chosen one (and the combined rank's line)
    (ring,) = _parts(candidates_figure(result.search, step), "chosen")
    assert ring.marker.line.color == chosen
    rankings = rankings_figure(explain_synthesis_step(result, db, step))
    assert _parts(rankings, "chosen")[0].marker.line.color == chosen
    assert {s.line.color for s in rankings.layout.shapes if s.name == "combined rank"} == {chosen}
    # and nothing on them in the colour that meant "chosen" before
    for fig in (large, strip, rankings):
        assert "#c0502d" not in fig.to_json()
