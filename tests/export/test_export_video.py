"""Tests of gesturekit.export.video and the scene of gesturekit.viz.render it uses.

Videos are checked by reading them back: stream facts with ``probe_media``
(the ffmpeg binary), pixels decoded with ``imageio_ffmpeg.read_frames``. The
skeleton is a small hand-made pose whose right arm swings up; rendering is
offscreen and in software, so resolutions are kept small.
"""

from __future__ import annotations

import hashlib
import os

import imageio_ffmpeg
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from gesturekit.errors import ConfigError, GestureKitError, InputFileError, OutputError
from gesturekit.export.video import AUDIO_OUT_SR, probe_media, render_video
from gesturekit.motion import Motion
from gesturekit.skeleton import FINGERS, N_JOINTS, hand_indices, joint_index
from gesturekit.viz.appearance import APPEARANCE, DERIVED_POINTS
from gesturekit.viz.render import RenderStyle, SkeletonScene, render_image, view_bounds
from gesturekit.viz.render_pool import CHUNK_FRAMES, render_frames

FPS = 15.0
SR = 16000
#: The earlier figure, kept as a look: the tests of its capsules, head, floor and panels use it.
CAPSULES = RenderStyle(look="capsules")


# ----------------------------------------------------------------------------- fixtures


def rest_pose() -> np.ndarray:
    """A standing upper body with arms down and open hands, shape (55, 3), metres, facing +Z."""
    pose = np.zeros((N_JOINTS, 3))
    body = {
        "spine_mid": (0, 0.11, 0),
        "chest": (0, 0.23, 0),
        "upper_chest": (0, 0.35, 0),
        "neck": (0, 0.49, 0),
        "neck_upper": (0, 0.54, 0),
        "head": (0, 0.59, 0.01),
        "head_top": (0, 0.72, 0.02),
    }
    for name, p in body.items():
        pose[joint_index(name)] = p
    for side, sign in (("left", 1.0), ("right", -1.0)):
        pose[joint_index(f"{side}_collar")] = (sign * 0.03, 0.45, 0)
        pose[joint_index(f"{side}_shoulder")] = (sign * 0.18, 0.46, 0)
        pose[joint_index(f"{side}_elbow")] = (sign * 0.24, 0.18, 0.02)
        wrist = np.array([sign * 0.27, -0.07, 0.08])
        idx = hand_indices(side)
        pose[idx[0]] = wrist
        for f, _ in enumerate(FINGERS):
            spread = sign * 0.018 * (f - 2)
            for k in range(4):
                pose[idx[1 + 4 * f + k]] = wrist + (spread, -0.03 - 0.025 * k, 0.01 if f == 0 else 0.0)
    return pose


def swinging_motion(n_frames: int) -> Motion:
    """The rest pose with the right arm swinging up sideways, about the shoulder, by 0..100 degrees."""
    base = rest_pose()
    arm = np.concatenate([[joint_index("right_elbow")], hand_indices("right")])
    pivot = base[joint_index("right_shoulder")]
    frames = []
    for a in np.radians(np.linspace(0, 100, n_frames)):
        pose = base.copy()
        rel = base[arm] - pivot
        c, s = np.cos(a), np.sin(a)
        # rotation about +Z by -a moves the right arm (at -X) outwards and up
        pose[arm, 0] = pivot[0] + c * rel[:, 0] - s * rel[:, 1]
        pose[arm, 1] = pivot[1] + s * rel[:, 0] + c * rel[:, 1]
        frames.append(pose)
    return Motion(np.array(frames, dtype=np.float32), FPS)


def still_motion(n_frames: int) -> Motion:
    return Motion(np.repeat(rest_pose()[None], n_frames, axis=0).astype(np.float32), FPS)


def tone(seconds: float) -> np.ndarray:
    t = np.arange(int(round(seconds * SR))) / SR
    return (0.3 * np.sin(2 * np.pi * 220 * t)).astype(np.float32)


def decode(path) -> list[np.ndarray]:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    return [np.frombuffer(f, np.uint8).reshape(h, w, 3).copy() for f in reader]


def figure_mask(image: np.ndarray) -> np.ndarray:
    """Pixels of a figure: coloured, where background, floor and shadow are grey."""
    image = image.astype(int)
    return image.max(axis=-1) - image.min(axis=-1) > 40


def blue(image: np.ndarray) -> np.ndarray:
    """Pixels of the first motion's colour (blue): clearly more blue than red."""
    image = image.astype(int)
    return image[..., 2] - image[..., 0] > 40


def orange(image: np.ndarray) -> np.ndarray:
    """Pixels of the second motion's colour (orange): clearly more red than blue."""
    image = image.astype(int)
    return image[..., 0] - image[..., 2] > 40


def changed_pixels(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pixels whose colour changed by more than coding noise."""
    return np.abs(a.astype(int) - b.astype(int)).sum(axis=-1) > 60


# ----------------------------------------------------------------------------- the video file


@pytest.mark.slow
def test_video_has_h264_and_aac_of_the_audio_duration(tmp_path):
    motion = swinging_motion(45)  # 3 s, longer than the audio: cut
    audio = tone(2.5)
    out = render_video(tmp_path / "clip.mp4", motion, audio=audio, sr=SR, resolution=(320, 240))
    info = probe_media(out)
    frame = 1 / FPS
    v, a = info["video"], info["audio"]
    assert (v["codec"], v["pix_fmt"], v["width"], v["height"]) == ("h264", "yuv420p", 320, 240)
    assert v["fps"] == pytest.approx(FPS)
    assert a["codec"] == "aac" and a["sample_rate"] == AUDIO_OUT_SR and a["channels"] == 1
    assert abs(v["duration"] - 2.5) <= frame
    assert abs(a["duration"] - 2.5) <= frame
    assert abs(info["duration"] - 2.5) <= frame
    assert v["frames"] == round(2.5 * FPS)


def test_short_motion_is_padded_with_its_last_pose(tmp_path):
    motion = swinging_motion(10)
    out = render_video(tmp_path / "pad.mp4", motion, audio=tone(2.0), sr=SR, resolution=(160, 120))
    info = probe_media(out)
    assert info["video"]["frames"] == 30
    assert abs(info["audio"]["duration"] - 2.0) <= 1 / FPS
    frames = decode(out)
    assert len(frames) == 30
    held = [np.abs(f.astype(int) - frames[9].astype(int)).mean() for f in frames[10:]]
    assert max(held) < 1.0  # the last pose, held
    assert np.abs(frames[0].astype(int) - frames[9].astype(int)).mean() > 1.0  # it did move before


def test_silent_video_lasts_as_long_as_the_motion(tmp_path):
    out = render_video(tmp_path / "silent.mp4", swinging_motion(12), resolution=(160, 120))
    info = probe_media(out)
    assert info["audio"] is None
    assert info["video"]["frames"] == 12
    assert info["video"]["duration"] == pytest.approx(12 / FPS)


@pytest.mark.slow
def test_frames_show_a_moving_skeleton(tmp_path):
    moving = render_video(tmp_path / "moving.mp4", swinging_motion(20), resolution=(320, 240))
    still = render_video(tmp_path / "still.mp4", still_motion(20), resolution=(320, 240))
    frames = decode(moving)
    first = figure_mask(frames[0])
    # not blank: a figure of some thousand pixels on a plain background
    assert frames[0].astype(float).var() > 50
    assert 1000 < first.sum() < 0.5 * first.size
    # the arm swings: many pixels change, mostly on the image's left
    # (the character's right side when it faces the camera)
    changed = changed_pixels(frames[0], frames[-1])
    assert changed.sum() > 500
    assert np.median(np.nonzero(changed)[1]) < 320 / 2
    # a still pose gives the same picture in every frame, up to coding noise on edges
    still_frames = decode(still)
    assert changed_pixels(still_frames[0], still_frames[-1]).sum() < 0.1 * changed.sum()


def test_side_by_side_has_both_figures_and_labels(tmp_path):
    out = render_video(
        tmp_path / "pair.mp4",
        still_motion(6),
        side_by_side=swinging_motion(6),
        labels=["k-NN", "refined"],
        resolution=(320, 160),
    )
    frame = decode(out)[0]
    mask = figure_mask(frame)
    assert mask[:, :160].sum() > 100 and mask[:, 160:].sum() > 100
    # the labels, each in its motion's colour, in the top rows of its panel
    assert blue(frame[:25, :160]).sum() > 10 and orange(frame[:25, 160:]).sum() > 10


def test_two_motions_have_their_own_colours_in_their_own_halves():
    image = render_image(
        still_motion(1), side_by_side=swinging_motion(3), frame=2, resolution=(200, 120), style=CAPSULES
    )
    left, right = image[:, :100], image[:, 100:]
    assert blue(left).sum() > 400 and orange(right).sum() > 400
    assert orange(left).sum() == 0 and blue(right).sum() == 0


def test_a_closed_scene_refuses_to_draw_and_closes_twice():
    scene = SkeletonScene([still_motion(2)], resolution=(48, 32))
    assert scene.render_frame(1).shape == (32, 48, 3)
    scene.close()
    scene.close()  # closing again is harmless
    for draw in (lambda: scene.render_frame(0), lambda: scene.project(np.zeros((1, 3))), lambda: scene.backend):
        with pytest.raises(GestureKitError, match="closed"):
            draw()


def test_the_body_has_a_head_above_its_neck_and_fills_the_view():
    motion = still_motion(1)
    with SkeletonScene([motion], resolution=(160, 120), style=CAPSULES) as scene:
        image = scene.render_frame(0)
        body = APPEARANCE.body(motion.positions).points[0]
        head = scene.project(body[[N_JOINTS + DERIVED_POINTS.index("head_centre")]])[0]
        neck = scene.project(motion.positions[0, [joint_index("neck")]])[0]
    mask = figure_mask(image)
    assert head[1] < neck[1] - 5  # rows count down: the head is drawn above the neck
    col, row = np.round(head).astype(int)
    assert mask[row, col]
    # the head is the motion's colour, lighter (its tint)
    r, g, b = image[row - 1 : row + 2, col - 1 : col + 2].reshape(-1, 3).mean(axis=0)
    assert b > r + 20
    # framed to fill the view: the figure spans most of the picture's height
    rows, cols = np.nonzero(mask)
    assert rows.max() - rows.min() > 0.6 * 120
    assert cols.max() - cols.min() > 0.2 * 160
    # a floor and a contact shadow under the figure: the bottom rows are darker than the sky
    floor = image[-5:].astype(int).sum(axis=-1).mean()
    sky = image[:5].astype(int).sum(axis=-1).mean()
    assert floor < sky - 10


def test_progress_counts_every_frame(tmp_path):
    calls = []
    render_video(
        tmp_path / "p.mp4",
        swinging_motion(5),
        audio=tone(0.6),
        sr=SR,
        resolution=(64, 48),
        progress=lambda done, total: calls.append((done, total)),
    )
    assert calls == [(i, 9) for i in range(1, 10)]


def test_same_inputs_give_the_same_bytes(tmp_path):
    a = render_video(tmp_path / "a.mp4", swinging_motion(8), audio=tone(0.5), sr=SR, resolution=(96, 64))
    b = render_video(tmp_path / "b.mp4", swinging_motion(8), audio=tone(0.5), sr=SR, resolution=(96, 64))
    assert hashlib.sha256(a.read_bytes()).digest() == hashlib.sha256(b.read_bytes()).digest()


@pytest.mark.slow
def test_parallel_render_gives_the_same_bytes_as_serial(tmp_path):
    # 70 frames are three chunks: each of two processes renders some, the parent puts them in order
    motion, other = swinging_motion(70), still_motion(64)
    calls = []
    same = dict(side_by_side=other, labels=["a", "b"], audio=tone(5.0), sr=SR, resolution=(96, 64))
    serial = render_video(tmp_path / "serial.mp4", motion, workers=1, **same)
    parallel = render_video(
        tmp_path / "parallel.mp4", motion, workers=2, progress=lambda done, total: calls.append((done, total)), **same
    )
    assert serial.read_bytes() == parallel.read_bytes()
    assert calls == [(i, 75) for i in range(1, 76)]  # in order, up to the audio's 75 frames


@pytest.mark.slow
def test_parallel_frames_are_the_scene_frames_in_order():
    motion = swinging_motion(CHUNK_FRAMES + 5)
    frames = list(render_frames([motion], resolution=(48, 32), workers=2))
    assert len(frames) == motion.n_frames
    with SkeletonScene([motion], resolution=(48, 32)) as scene:
        for i in (0, CHUNK_FRAMES - 1, CHUNK_FRAMES, motion.n_frames - 1):  # both sides of the chunk border
            np.testing.assert_array_equal(frames[i], scene.render_frame(i))


def test_a_failed_rendering_process_is_reported_and_leaves_no_file(tmp_path, monkeypatch):
    from gesturekit.viz import render

    monkeypatch.setattr(render.sys, "executable", "/bin/false")  # each process exits at once, with code 1
    path = tmp_path / "out.mp4"
    with pytest.raises(GestureKitError, match="rendering process stopped at frame 0 .*exit code 1"):
        render_video(path, swinging_motion(40), resolution=(48, 32), workers=2)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("workers", [0, -1, 1.5, True, "2"])
def test_bad_worker_counts_are_refused(tmp_path, workers):
    with pytest.raises(ConfigError, match="workers must be a positive whole number"):
        render_video(tmp_path / "w.mp4", still_motion(3), resolution=(64, 48), workers=workers)
    assert not (tmp_path / "w.mp4").exists()


def test_existing_file_is_kept_unless_overwrite(tmp_path):
    path = tmp_path / "taken.mp4"
    path.write_bytes(b"not a video")
    with pytest.raises(ConfigError, match="taken.mp4.*already exists"):
        render_video(path, still_motion(3), resolution=(64, 48))
    assert path.read_bytes() == b"not a video"
    # overwrite replaces only a video gesturekit wrote (recognised by its metadata tag)
    with pytest.raises(OutputError, match="taken.mp4: is a file that gesturekit did not write"):
        render_video(path, still_motion(3), resolution=(64, 48), overwrite=True)
    assert path.read_bytes() == b"not a video"
    path.unlink()
    render_video(path, still_motion(2), resolution=(64, 48))
    render_video(path, still_motion(3), resolution=(64, 48), overwrite=True)
    assert probe_media(path)["video"]["frames"] == 3
    assert [p.name for p in tmp_path.iterdir()] == ["taken.mp4"]  # no temporary file left


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(resolution=(321, 240)), "even"),
        (dict(resolution=(320,)), "resolution"),
        (dict(audio=np.zeros((2, 100), np.float32)), "mono"),
        (dict(audio=np.array([0.0, np.nan], np.float32)), "NaN"),
        (dict(audio=np.zeros(0, np.float32)), "empty"),
        (dict(audio=np.zeros(100, np.float32), sr=0), "sr"),
        (dict(labels=["only one", "two"]), "one label per motion"),
        (dict(side_by_side=Motion(np.zeros((3, N_JOINTS, 3), np.float32), 30.0)), "same fps"),
    ],
)
def test_bad_settings_raise_config_error(tmp_path, kwargs, message):
    path = tmp_path / "bad.mp4"
    with pytest.raises(ConfigError, match=message):
        render_video(path, still_motion(3), **{"resolution": (64, 48), **kwargs})
    assert not path.exists()


def test_missing_folder_names_the_file(tmp_path):
    with pytest.raises(ConfigError, match="missing.*does not exist"):
        render_video(tmp_path / "missing" / "x.mp4", still_motion(2), resolution=(64, 48))


def test_probe_rejects_missing_and_non_media_files(tmp_path):
    with pytest.raises(InputFileError, match="nothing.mp4"):
        probe_media(tmp_path / "nothing.mp4")
    text = tmp_path / "notes.mp4"
    text.write_text("hello, not a video\n" * 20)
    with pytest.raises(InputFileError, match="notes.mp4"):
        probe_media(text)
    assert issubclass(InputFileError, GestureKitError)


# ----------------------------------------------------------------------------- the scene


def test_front_view_shows_the_character_facing_the_camera():
    motion = still_motion(1)
    # the whole body framed (the upper body's medium shot leaves hands hanging below the hips out)
    with SkeletonScene([motion], resolution=(320, 240), style=RenderStyle(framing="full body")) as scene:
        image = scene.render_frame(0)
        px = scene.project(motion.positions[0])
    left, right = px[joint_index("left_wrist")], px[joint_index("right_wrist")]
    head, spine = px[joint_index("head_top")], px[joint_index("spine_mid")]
    assert left[0] > right[0]  # its left hand on the viewer's right
    assert head[1] < spine[1]  # head up
    # every joint lands on a drawn pixel, fingertips included
    mask = figure_mask(image)
    for col, row in np.round(px).astype(int):
        assert mask[row - 1 : row + 2, col - 1 : col + 2].any()


def test_stimuli_are_framed_identically_and_previews_fit_the_motion():
    fixed = RenderStyle(fit_motion=False)
    a, b = still_motion(2), swinging_motion(5)
    np.testing.assert_array_equal(view_bounds([a], style=fixed), np.asarray(fixed.view_box))
    np.testing.assert_array_equal(view_bounds([a], style=fixed), view_bounds([b], style=fixed))
    # fitted: every drawn surface of every frame inside, the swinging arm's reach included
    fitted_a, fitted_b = view_bounds([a], style=CAPSULES), view_bounds([b], style=CAPSULES)
    points = APPEARANCE.body(b.positions).points.reshape(-1, 3)
    assert np.all(points >= fitted_b[:, 0]) and np.all(points <= fitted_b[:, 1])
    assert np.ptp(fitted_b[0]) > np.ptp(fitted_a[0]) + 0.1  # the arm, raised sideways, widens the view


@pytest.mark.slow
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    offsets=hnp.arrays(np.float64, (2, N_JOINTS, 3), elements=st.floats(-1.2, 1.2)),
    width=st.sampled_from([64, 160, 320]),
)
def test_every_joint_is_in_frame(offsets, width):
    motion = Motion((rest_pose()[None] + offsets).astype(np.float32), FPS)
    with SkeletonScene([motion, motion], resolution=(width, 120), style=CAPSULES) as scene:
        for panel in (0, 1):
            px = scene.project(motion.positions.reshape(-1, 3), panel=panel)
            lo = panel * width / 2
            assert np.all((px[:, 0] >= lo) & (px[:, 0] <= lo + width / 2))
            assert np.all((px[:, 1] >= 0) & (px[:, 1] <= 120))


def test_render_image_is_deterministic_and_updates_in_place():
    motion = swinging_motion(6)
    once = render_image(motion, frame=5, resolution=(96, 72))
    with SkeletonScene([motion], resolution=(96, 72)) as scene:
        scene.render_frame(0)
        again = scene.render_frame(5)  # reached by moving the meshes, not by rebuilding
    np.testing.assert_array_equal(once, again)
    assert once.shape == (72, 96, 3) and once.dtype == np.uint8


def test_headless_rendering_uses_an_offscreen_window_and_leaves_the_environment(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("VTK_DEFAULT_OPENGL_WINDOW", raising=False)
    with SkeletonScene([still_motion(1)], resolution=(64, 48)) as scene:
        window = scene.backend
        assert figure_mask(scene.render_frame(0)).any()
    assert window in ("vtkEGLRenderWindow", "vtkOSOpenGLRenderWindow")
    assert "VTK_DEFAULT_OPENGL_WINDOW" not in os.environ


def test_encoder_failure_is_reported_and_leaves_no_file(tmp_path, monkeypatch):
    from gesturekit.export import video

    monkeypatch.setattr(video, "_CRF", "not-a-number")  # ffmpeg refuses this option value
    with pytest.raises(GestureKitError, match="out.mp4.*ffmpeg could not encode"):
        render_video(tmp_path / "out.mp4", still_motion(3), resolution=(64, 48))
    assert list(tmp_path.iterdir()) == []


def test_a_style_travels_to_the_rendering_processes_unchanged():
    import json

    from gesturekit.viz.appearance import Appearance

    style = RenderStyle(
        appearance=Appearance(motion_colors=("#112233", "#445566")),
        fit_motion=False,
        view_box=((-1, 1), (-0.5, 1), (-0.3, 0.5)),
        elevation=5.0,
    )
    assert RenderStyle.from_json(json.loads(json.dumps(style.to_json()))) == style
    with pytest.raises(ConfigError, match="appearance must be an Appearance"):
        RenderStyle(appearance="blue")
