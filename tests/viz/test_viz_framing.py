"""One framing rule: a presenter's upper body fills most of the MP4's height; colours mean one thing everywhere.

The fill is measured on rendered frames of a real speaker (51 s of the demo database's clips): from the
topmost pixel of the character (the head, or a raised hand) down to where its pelvis projects, over the
picture's height. The character's pixels are those that differ from the picture of the stage alone.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.character import look
from gesturekit.character.paint import paint
from gesturekit.demo import open_default_database
from gesturekit.motion import Motion
from gesturekit.skeleton import hand_indices
from gesturekit.viz._plotly import MOTION_COLORS
from gesturekit.viz.appearance import RenderStyle
from gesturekit.viz.character_render import CharacterStage
from gesturekit.viz.render import SkeletonScene
from gesturekit.viz.viewer import viewer_data

#: The least share of the picture's height a presenter's upper body fills, alone in the picture (from the top
#: down to the pelvis; below it the picture holds the hips and every hand hanging down, never cut).
FILL = 0.55


@functools.cache
def speaker(start: int = 20, clips: int = 12) -> Motion:
    """Consecutive clips of the demo database: a speaker's upper body over 51 s, pelvis-relative."""
    db = open_default_database()
    poses = np.asarray(db.poses).reshape(len(db.poses), -1, 55, 3)
    return Motion(np.concatenate(poses[start : start + clips]).astype(np.float32), db.fps, db.joint_presence)


def upper_body_fill(scene: SkeletonScene, frame: int, stage: np.ndarray, offset: float = 0.0) -> float:
    """The share of the picture's height from the character's topmost pixel down to its pelvis."""
    image = scene.render_frame(frame)
    h = image.shape[0]
    w = image.shape[1]
    pelvis = scene.project(np.array([[offset, 0.0, 0.0]]))[0]
    left, right = (0, w) if offset == 0 else ((0, w // 2) if offset < 0 else (w // 2, w))
    body = np.any(image != stage, axis=2)[:, left:right]
    top = int(np.nonzero(body.any(axis=1))[0].min())
    return (pelvis[1] - top) / h


@pytest.mark.slow
@pytest.mark.parametrize("size", [(640, 480), (1280, 720)])
def test_a_presenter_alone_fills_most_of_the_mp4s_height(size):
    motion = speaker()
    with SkeletonScene([motion], resolution=size) as scene:
        stage = scene.stage_image()
        fills = [upper_body_fill(scene, f, stage) for f in (0, motion.n_frames // 2, motion.n_frames - 1)]
    assert min(fills) >= FILL, fills


@pytest.mark.slow
def test_the_full_body_shows_the_feet_on_the_floor_and_the_head():
    motion = speaker()
    with SkeletonScene([motion], resolution=(640, 480), style=RenderStyle(framing=look.FULL_BODY)) as scene:
        stage = scene.stage_image()
        image = scene.render_frame(10)
        ground = CharacterStage([motion]).ground
        feet = scene.project(np.array([[0.0, ground, 0.1]]))[0]
    rows = np.nonzero(np.any(image != stage, axis=2).any(axis=1))[0]
    assert 0 < rows.min() and rows.max() < 480  # head and feet inside the picture
    assert feet[1] < 480 and rows.max() >= feet[1] - 3  # the shoes reach the floor's line
    assert (rows.max() - rows.min()) / 480 > 0.75  # the whole person fills the height


def _hands() -> np.ndarray:
    return np.concatenate([hand_indices("left"), hand_indices("right")])


@settings(max_examples=25)
@given(frame=st.integers(0, 63), drop=st.floats(0.0, 0.6), waist=st.floats(-0.05, 0.05))
def test_the_upper_body_box_reaches_below_every_hand_of_every_frame(frame, drop, waist):
    points = speaker().positions[:64].copy()
    points[frame, _hands(), 1] -= drop  # one frame's hands hang lower (a shrug, a bow)
    _, box = look.stage_layout([points], waist=waist)
    assert box[0, 1] <= points[..., 1].min() - look.HAND_MARGIN
    # the hips below the pelvis are in it whatever the hands do, and the top is that of the reach
    assert box[0, 1] <= waist - look.BELOW_WAIST * (box[1, 1] - waist) * 0.9
    _, still = look.stage_layout([speaker().positions[:64]], waist=waist)
    assert box[1, 1] == pytest.approx(still[1, 1], abs=0.05)


@pytest.mark.slow
def test_no_hand_leaves_the_mp4_where_the_hands_hang_below_the_hips():
    motion = speaker()
    hands = motion.positions[:, _hands()]
    # the clip's hands hang well below the pelvis: a medium shot cut at the hips would cut them
    assert hands[..., 1].min() < -0.2
    for size in [(640, 480), (1280, 720)]:
        with SkeletonScene([motion], resolution=size) as scene:
            px = scene.project(hands.reshape(-1, 3))
        w, h = size
        assert np.all((px[:, 0] >= 0) & (px[:, 0] < w)), (px[:, 0].min(), px[:, 0].max())
        assert np.all((px[:, 1] >= 0) & (px[:, 1] < h)), (px[:, 1].min(), px[:, 1].max())
        assert px[:, 1].max() > 0.8 * h  # and the picture ends a little below the lowest hand, not far below


@given(across=st.floats(0.3, 4.0), high=st.floats(0.3, 2.0), width=st.integers(200, 2000), most=st.integers(150, 900))
def test_a_view_is_no_higher_than_its_box_fills(across, high, width, most):
    box = np.array([[-across / 2, -0.3, -0.2], [across / 2, high - 0.3, 0.4]])
    h = look.fitted_height(box, width, most)
    assert min(most, look.LEAST_VIEW_HEIGHT) <= h <= most
    if h == most:  # as high as asked: the box is framed by its height, or the view could not be higher
        assert width / most >= across / high - 1e-9 or h >= width * high / across - 0.5
    elif h > look.LEAST_VIEW_HEIGHT:  # less high: the box fills it both ways, the camera's two fits agree
        cam = look.camera_for(box[0], box[1], width / h)
        by_height = (high / 2) / np.tan(np.radians(cam["fov"]) / 2)
        by_width = (across / 2) / (np.tan(np.radians(cam["fov"]) / 2) * width / h)
        assert by_width == pytest.approx(by_height, rel=1 / h + 1e-9)


def test_two_presenters_side_by_side_get_a_lower_view_than_one():
    motion = speaker()
    one = look.stage_layout([motion.positions], waist=0.0)[1]
    two = look.stage_layout([motion.positions, motion.positions], waist=0.0)[1]
    assert look.fitted_height(one, 640, 480) == 480
    assert look.fitted_height(two, 640, 480) < 0.8 * 480


def test_side_by_side_characters_stand_closer_than_their_widest_gesture():
    motion = speaker()
    x = motion.positions[..., 0]
    offsets, box = look.stage_layout([motion.positions, motion.positions])
    spacing = offsets[1] - offsets[0]
    widest = x.max() - x.min()
    assert spacing < widest + 0.1  # the reach of most frames, not of the widest one
    assert spacing >= 0.7


# ----------------------------------------------------------------------------- one palette


def test_every_role_and_rank_has_its_own_colour_on_the_page_in_the_mp4_and_the_plots():
    roles = [look.role_scheme(r) for r in ("k-NN", "refined", "chosen")]
    ranks = [look.rank_scheme(k) for k in range(len(look.RANK_SCHEMES))]
    shirts = [look.SCHEMES[s]["shirt"] for s in roles + ranks]
    assert len(set(shirts)) == len(shirts)  # "chosen" is no rank's colour, no rank is k-NN's or refined's
    assert look.rank_scheme(len(look.RANK_SCHEMES)) == look.rank_scheme(0)
    # the default side-by-side order is k-NN then refined, the plots' first two motion colours are theirs
    assert look.scheme_for(0) == look.role_scheme("k-NN") and look.scheme_for(1) == look.role_scheme("refined")
    assert list(MOTION_COLORS[:2]) == [look.SCHEMES["blue"]["shirt"], look.SCHEMES["orange"]["shirt"]]
    # the page and the MP4 paint a character of a given scheme alike
    motion = Motion(speaker().positions[:3], 15.0, speaker().presence)
    schemes = [look.role_scheme("chosen"), look.rank_scheme(3)]
    page = viewer_data([motion, motion], schemes=schemes)
    stage = CharacterStage([motion, motion], schemes=schemes)
    for i, scheme in enumerate(schemes):
        assert page["motions"][i]["scheme"] == scheme and stage.schemes[i] == scheme
        _, palette = paint(stage.meshes[i], motion.presence, scheme)
        np.testing.assert_allclose(np.asarray(page["motions"][i]["colors"]), palette, atol=1e-6)
        np.testing.assert_allclose(palette[: len(look.part_colors(scheme))], look.part_colors(scheme))


def test_unknown_roles_schemes_and_framings_are_refused():
    from gesturekit.errors import ConfigError

    motion = Motion(speaker().positions[:2], 15.0, speaker().presence)
    with pytest.raises(ConfigError, match="unknown role"):
        look.role_scheme("best")
    with pytest.raises(ConfigError, match="unknown colour scheme 'teal-ish'"):
        viewer_data([motion], schemes=["teal-ish"])
    with pytest.raises(ConfigError, match="2 motions need as many colour schemes"):
        viewer_data([motion, motion], schemes=["blue"])
    with pytest.raises(ConfigError, match="unknown framing"):
        RenderStyle(framing="waist")
    with pytest.raises(ConfigError, match="rank is 0 or more"):
        look.rank_scheme(-1)
