"""Partial skeletons in every view: absent joints are not drawn, derived ones look different, the camera
frames what exists, and npz archives keep which joints are real.

The partial motion is the demo speaker made into the kind of data lifted from video: positions
relative to the neck, the torso and head marked derived (placed from the neck and shoulders), the
thumbs absent (sitting on their wrists, as absent joints do).
"""

from __future__ import annotations

import functools

import imageio_ffmpeg
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.errors import ConfigError, MotionFileError
from gesturekit.export.npz import load_npz, save_npz
from gesturekit.export.video import render_video
from gesturekit.motion import Motion
from gesturekit.skeleton import (
    ABSENT,
    DERIVABLE_JOINTS,
    DERIVED,
    JOINT_NAMES,
    JOINT_STATES,
    N_JOINTS,
    PARENTS,
    RECORDED,
    JointPresence,
    joint_index,
)
from gesturekit.viz._plotly import data_array
from gesturekit.viz.appearance import APPEARANCE, DERIVED_PART, DERIVED_POINTS, point_states
from gesturekit.viz.figures import skeleton_figure
from gesturekit.viz.render import RenderStyle, SkeletonScene, render_image, view_bounds
from gesturekit.viz.render_pool import _write_job, scene_from_job
from gesturekit.viz.viewer import viewer_data

THUMBS = tuple(f"{side}_thumb{k}" for side in ("left", "right") for k in range(1, 5))
DERIVED_TORSO = tuple(n for n in DERIVABLE_JOINTS if n != "neck")


@functools.cache
def _demo() -> np.ndarray:
    take, _ = generate_demo_take(seconds=2.0, seed=3, name="partial")
    return np.asarray(take.motion.positions, dtype=np.float32)


def upper_body_presence() -> JointPresence:
    recorded = [n for n in JOINT_NAMES if n not in DERIVED_TORSO and n not in THUMBS]
    return JointPresence.from_names(recorded=recorded, derived=DERIVED_TORSO)


def collapse(positions: np.ndarray, presence: JointPresence) -> np.ndarray:
    """Absent joints onto their parents (parents precede children, so chains collapse whole)."""
    out = positions.copy()
    for j in np.flatnonzero(presence.absent):
        out[:, j] = out[:, PARENTS[j]]
    return out


def upper_body(frames: int | None = None, *, collapsed: bool = True) -> Motion:
    """The demo speaker, neck-relative, torso and head derived, thumbs absent."""
    p = _demo()[:frames]
    p = p - p[:, [joint_index("neck")]]
    presence = upper_body_presence()
    return Motion(collapse(p, presence) if collapsed else p, 15.0, presence)


def _points(trace) -> np.ndarray:
    pts = np.stack([data_array(trace.x), data_array(trace.y), data_array(trace.z)], axis=1)
    return pts[np.isfinite(pts).all(axis=1)]


def _has(points: np.ndarray, p: np.ndarray) -> bool:
    return bool(len(points)) and bool((np.abs(points - p).max(axis=1) < 1e-6).any())


# ----------------------------------------------------------------------------- plotly figure


def test_the_figure_leaves_absent_joints_out_and_draws_the_derived_torso_dashed_and_labelled():
    motion = upper_body(1, collapsed=False)  # absent thumbs away from the wrists: any drawing would show
    fig = skeleton_figure(motion)
    parts = {t.meta["part"]: t for t in fig.data}
    assert set(parts) == {"body", "hands", "torso", "head", DERIVED_PART}
    every = np.concatenate([_points(t) for t in fig.data])
    pose = motion.positions[0]
    for name in THUMBS:
        assert not _has(every, pose[joint_index(name)]), name
    derived = parts[DERIVED_PART]
    assert derived.line.dash == "dash" and derived.line.color == APPEARANCE.derived_color
    assert "derived" in derived.name and derived.showlegend and fig.layout.showlegend
    for name in DERIVED_TORSO:
        assert _has(_points(derived), pose[joint_index(name)]), name
        # recorded traces do not pass through derived joints
        assert not _has(np.concatenate([_points(parts["body"]), _points(parts["hands"])]), pose[joint_index(name)])
    # the head ball is there, grey, and says it is derived
    assert parts["head"].meta["derived"] and parts["head"].marker.color == APPEARANCE.derived_color
    assert "derived" in parts["head"].name
    # no pelvis or hips below a derived spine: the torso trace holds no recorded capsule here
    assert len(_points(parts["torso"])) == 0


def test_a_complete_skeleton_has_no_derived_trace_and_no_legend():
    fig = skeleton_figure(Motion(_demo()[:2], 15.0))
    assert [t.meta["part"] for t in fig.data] == ["body", "hands", "torso", "head"]
    assert not fig.layout.showlegend


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(JOINT_STATES), min_size=N_JOINTS, max_size=N_JOINTS))
def test_the_figure_draws_exactly_the_joints_that_exist(status):
    presence = JointPresence(tuple(status))
    motion = Motion(_demo()[:1], 15.0, presence)  # every joint at its own place
    fig = skeleton_figure(motion)
    joints = np.concatenate([_points(t) for t in fig.data if t.meta["part"] in ("body", "hands", DERIVED_PART)])
    pose = motion.positions[0]
    for j in range(N_JOINTS):
        assert _has(joints, pose[j]) == bool(presence.drawn[j]), (JOINT_NAMES[j], status[j])
    # the recorded traces hold recorded joints only
    recorded = np.concatenate([_points(t) for t in fig.data if t.meta["part"] in ("body", "hands")])
    assert all(any(np.abs(pose[j] - q).max() < 1e-6 for j in np.flatnonzero(presence.recorded)) for q in recorded)
    assert (DERIVED_PART in {t.meta["part"] for t in fig.data}) == bool(presence.derived.any())


def test_the_scene_ranges_fit_a_neck_relative_upper_body():
    motion = upper_body(5)
    scene = skeleton_figure(motion).layout.scene
    lo, hi = scene.yaxis.range
    drawn = motion.positions[:, motion.presence.drawn, 1]
    # the box hugs what is drawn (0.1 m and a head's radius at most around it), not a pelvis below
    assert drawn.min() - 0.25 < lo < drawn.min() and drawn.max() < hi < drawn.max() + 0.25


# ----------------------------------------------------------------------------- appearance and viewer


@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from(JOINT_STATES), min_size=N_JOINTS, max_size=N_JOINTS))
def test_shapes_never_touch_an_absent_point_and_derived_ones_are_marked(status):
    presence = JointPresence(tuple(status))
    states = point_states(presence)
    caps, spheres = APPEARANCE.shapes(presence)
    for ends, part in [((c.a, c.b), c.part) for c in caps] + [((s.centre,), s.part) for s in spheres]:
        touched = {states[e] for e in ends}
        assert ABSENT not in touched
        assert (part == DERIVED_PART) == (DERIVED in touched)
    # nothing that exists is dropped: every capsule of the full body with both ends drawn is kept
    full_caps, _ = APPEARANCE.shapes()
    kept = {(c.a, c.b) for c in caps}
    assert kept == {(c.a, c.b) for c in full_caps if ABSENT not in (states[c.a], states[c.b])}


def test_a_complete_skeleton_keeps_its_shapes():
    assert APPEARANCE.shapes(JointPresence.full()) == APPEARANCE.shapes()
    body = APPEARANCE.body(_demo()[:1])
    assert body.drawn.all() and body.drawn_points().shape == body.points.shape


def test_the_viewer_gets_each_motions_own_character_and_frames_what_exists():
    partial, full = upper_body(3), Motion(_demo()[:3], 15.0)
    data = viewer_data([partial, full])
    mine, other = data["motions"]
    absent = [joint_index(n) for n in THUMBS]
    assert not any(mine["rig"]["in_rig"][j] for j in absent) and all(other["rig"]["in_rig"])
    # no body around an absent joint: no vertex is bound to one
    joints, weights = (data_array(mine["mesh"][k]) for k in ("joints", "weights"))
    assert not np.isin(joints.reshape(-1), absent)[weights.reshape(-1) > 0].any()
    # vertices led by a derived joint are drawn in the derived colour, the last of the motion's colours
    parts = data_array(mine["mesh"]["parts"])
    derived_colour = [int(APPEARANCE.derived_color[i : i + 2], 16) / 255 for i in (1, 3, 5)]
    assert (parts == len(mine["colors"]) - 1).any() and mine["colors"][-1] == pytest.approx(derived_colour)
    assert not (data_array(other["mesh"]["parts"]) == len(other["colors"]) - 1).any()
    assert mine["derived"] == list(DERIVED_TORSO) and other["derived"] == []
    # alone, a neck-relative body is framed on itself: the box top is near its head, not a pelvis-based guess
    alone = viewer_data(partial)
    top = partial.positions[:, joint_index("head_top"), 1].max()
    assert top < alone["box"][1][1] < top + 0.3


# ----------------------------------------------------------------------------- renders and video


def foreground(image: np.ndarray) -> np.ndarray:
    """Pixels of a body, grey derived parts included: far from the background's and the floor's colours."""
    img = image.astype(int)
    far = [
        np.abs(img - np.round(255 * c)).sum(axis=-1) > 45
        for c in (_rgb(APPEARANCE.background), _rgb(APPEARANCE.ground_color))
    ]
    return far[0] & far[1]


def _rgb(color: str) -> np.ndarray:
    return np.array([int(color[i : i + 2], 16) for i in (1, 3, 5)]) / 255.0


def test_a_neck_relative_upper_body_renders_upright_and_fills_the_frame():
    motion = upper_body(1)
    w, h = 160, 120
    with SkeletonScene([motion], resolution=(w, h), style=RenderStyle(look="capsules")) as scene:
        image = scene.render_frame(0)
        body = APPEARANCE.body(motion.positions, motion.presence).points[0]
        head = scene.project(body[[N_JOINTS + DERIVED_POINTS.index("head_centre")]])[0]
        neck = scene.project(motion.positions[0, [joint_index("neck")]])[0]
        wrists = scene.project(motion.positions[0, [joint_index("left_wrist"), joint_index("right_wrist")]])
    mask = foreground(image)
    rows, cols = np.nonzero(mask)
    assert rows.max() - rows.min() >= 0.6 * h  # fills the frame
    assert head[1] < neck[1] < wrists[:, 1].min()  # upright: rows count down
    for col, row in np.round([head, neck]).astype(int):
        assert mask[row, col]
    # the derived head is grey (no hue), the recorded arms the motion's blue
    r, g, b = image[int(head[1]) - 1 : int(head[1]) + 2, int(head[0]) - 1 : int(head[0]) + 2].reshape(-1, 3).mean(0)
    assert max(r, g, b) - min(r, g, b) < 30
    arms = image[mask].astype(int)
    assert ((arms[:, 2] - arms[:, 0]) > 40).sum() > 50


def test_absent_joints_change_no_pixel_wherever_they_are():
    """Absent thumbs far out to the side or on their wrists: the same picture (neither drawn nor framed);
    recorded there, they show."""
    near = upper_body(1)
    far_pos = near.positions.copy()
    for name in THUMBS:
        far_pos[:, joint_index(name), 0] += 0.4 * np.sign(far_pos[:, joint_index(name), 0])
    far = Motion(far_pos, 15.0, near.presence)
    size = (96, 72)
    a, b = render_image(near, resolution=size), render_image(far, resolution=size)
    assert np.array_equal(a, b)
    shown = Motion(
        far_pos,
        15.0,
        JointPresence.from_names(recorded=[n for n in JOINT_NAMES if n not in DERIVED_TORSO], derived=DERIVED_TORSO),
    )
    assert not np.array_equal(a, render_image(shown, resolution=size))


def test_view_bounds_hold_only_what_is_drawn():
    motion = upper_body(4)
    drawn = APPEARANCE.body(motion.positions, motion.presence).drawn_points().reshape(-1, 3)
    # the whole person framed holds every drawn point (the upper-body framing may cut hands hanging low)
    box = view_bounds([motion], style=RenderStyle(framing="full body"))
    assert np.all(box[:, 0] < drawn.min(axis=0)) and np.all(box[:, 1] > drawn.max(axis=0))
    # a pelvis 1.4 spine lengths below a derived spine would reach far lower
    assert view_bounds([motion])[1, 0] > drawn[:, 1].min() - 0.3


def test_the_rendering_processes_get_the_joints_that_exist(tmp_path):
    """What a parallel render's processes read (the job file) keeps each motion's presence."""
    partial, full = upper_body(2), Motion(_demo()[:2], 15.0)
    path = tmp_path / "job.npz"
    _write_job(path, [partial, full], None, (64, 48), RenderStyle())
    with scene_from_job(str(path)) as scene:
        assert [m.joints for m in scene.motions] == [partial.joints, None]
        picture = scene.render_frame(1)
    with SkeletonScene([partial, full], resolution=(64, 48)) as direct:
        assert np.array_equal(picture, direct.render_frame(1))


def test_the_video_of_a_neck_relative_upper_body_is_upright_and_fills_the_frame(tmp_path):
    motion = upper_body(3)
    path = render_video(tmp_path / "partial.mp4", motion, resolution=(160, 120), workers=1)
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    frame = np.frombuffer(next(reader), np.uint8).reshape(h, w, 3)
    reader.close()
    mask = foreground(frame)
    rows = np.flatnonzero(mask.any(axis=1))
    assert rows.max() - rows.min() >= 0.6 * h
    # upright: the derived (grey) head on top, the recorded arms' blue sleeves below it (the derived torso
    # between the sleeves is grey too)
    img = frame.astype(int)
    grey = mask & (img.max(axis=-1) - img.min(axis=-1) < 25)
    blue = mask & (img[..., 2] - img[..., 0] > 40)
    assert grey.sum() > 50 and blue.sum() > 50
    assert np.flatnonzero(grey.any(axis=1)).min() < np.flatnonzero(blue.any(axis=1)).min()
    top = slice(rows.min(), rows.min() + max(2, (rows.max() - rows.min()) // 8))  # the figure's top eighth
    assert grey[top].sum() > 10 and not blue[top].any()


# ----------------------------------------------------------------------------- npz


def test_npz_keeps_which_joints_are_real_and_the_exact_positions(tmp_path):
    motion = upper_body(6)
    path = save_npz(tmp_path / "m.npz", motion=motion)
    back, _, _ = load_npz(path)
    assert back.presence == motion.presence and np.array_equal(back.positions, motion.positions)
    with np.load(path, allow_pickle=False) as z:
        status = z["joint_status"].tolist()
    assert [JOINT_NAMES[j] for j, s in enumerate(status) if s == ABSENT] == list(THUMBS)
    assert {JOINT_NAMES[j] for j, s in enumerate(status) if s == DERIVED} == set(DERIVED_TORSO)


@settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(st.lists(st.sampled_from(JOINT_STATES), min_size=N_JOINTS, max_size=N_JOINTS))
def test_npz_round_trips_any_presence(tmp_path, status):
    presence = JointPresence(tuple(status))
    path = save_npz(tmp_path / "any.npz", motion=Motion(_demo()[:2], 15.0, presence), overwrite=True)
    back, _, _ = load_npz(path)
    assert back.presence == presence
    assert back.joints is None if presence.is_full else back.joints == presence


def _rewrite(path, **changes) -> None:
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    data.update(changes)
    data = {k: v for k, v in data.items() if v is not None}
    path.unlink()
    np.savez(path, **data)


def test_an_npz_without_joint_status_reads_as_a_complete_skeleton(tmp_path):
    path = save_npz(tmp_path / "old.npz", motion=upper_body(2))
    _rewrite(path, joint_status=None)
    back, extras, _ = load_npz(path)
    assert back.joints is None and back.presence.is_full and "joint_status" not in extras


@pytest.mark.parametrize(
    "status, problem",
    [
        (np.array([RECORDED] * (N_JOINTS - 1)), "joint_status must be 55 strings"),
        (np.zeros(N_JOINTS, dtype=np.int64), "joint_status must be 55 strings"),
        (np.array([RECORDED] * (N_JOINTS - 1) + ["missing"]), r"joint_status holds \['missing'\]"),
    ],
)
def test_a_bad_joint_status_is_refused_naming_the_file(tmp_path, status, problem):
    path = save_npz(tmp_path / "bad.npz", motion=upper_body(2))
    _rewrite(path, joint_status=status)
    with pytest.raises(MotionFileError, match=rf"bad\.npz.*{problem}"):
        load_npz(path)


# ----------------------------------------------------------------------------- study stimuli


def test_stimuli_of_a_partial_skeleton_share_one_box_fitted_to_what_they_draw():
    from gesturekit.study.stimuli import _job_motion, _study_view_box, stimulus_style

    partial = upper_body(3)
    job = {"positions": partial.positions, "fps": 15.0, "joints": partial.presence.to_list()}
    motion = _job_motion(job)
    assert motion.joints == partial.joints
    assert _job_motion({**job, "joints": None}).joints is None
    assert _study_view_box([Motion(_demo()[:3], 15.0)]) is None  # complete skeletons keep the default box
    box = _study_view_box([motion, upper_body(2)])
    # every stimulus where it stands alone (not side by side): the union of their own boxes
    own = np.stack([view_bounds([motion]), view_bounds([upper_body(2)])])
    assert np.allclose(box, np.stack([own[:, :, 0].min(axis=0), own[:, :, 1].max(axis=0)], axis=1))
    assert np.ptp(np.asarray(box)[0]) < np.ptp(view_bounds([motion, upper_body(2)])[0])
    style = stimulus_style(box)
    assert not style.fit_motion
    h = 72
    image = render_image(motion, resolution=(96, h), style=style)
    rows = np.flatnonzero(foreground(image).any(axis=1))
    assert rows.max() - rows.min() >= 0.6 * h and rows.min() > 0
    # the default box assumes a pelvis origin: there a neck-relative body sits in the lower half
    default = np.flatnonzero(foreground(render_image(motion, resolution=(96, h), style=stimulus_style())).any(axis=1))
    assert default.min() > h / 3


@pytest.mark.parametrize("view", ["figure", "viewer", "render"])
def test_a_motion_with_every_joint_absent_is_refused_by_every_view(view):
    nothing = Motion(_demo()[:2], 15.0, JointPresence((ABSENT,) * N_JOINTS))
    draw = {
        "figure": lambda: skeleton_figure(nothing),
        "viewer": lambda: viewer_data(nothing),
        "render": lambda: render_image(nothing, resolution=(32, 24)),
    }[view]
    with pytest.raises(ConfigError, match="all absent: nothing to draw"):
        draw()


def test_the_app_says_under_a_view_what_is_derived_and_what_is_absent():
    from gesturekit.app import display

    partial, full = upper_body(2), Motion(_demo()[:2], 15.0)
    assert display.skeleton_note(full) == "" and display.skeleton_note([full, full]) == ""
    note = display.skeleton_note([partial, full, partial])  # one line per distinct partial skeleton
    assert note.startswith(f"grey: {len(DERIVED_TORSO)} derived joints") and "head_top" in note
    assert note.endswith(f"{len(THUMBS)} joints absent from the data, not drawn") and "|" not in note
