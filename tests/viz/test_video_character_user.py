"""The MP4 with a user's character: our motion retargeted onto it, its own skin and colours, as the camera sees it.

The reference of a frame is written here from the retargeted bones alone: each vertex's blended 4x4 matrix
``sum_k w_k [W Q^T | P - W Q^T p]`` (rotations and positions of :func:`retarget`, rest rotations and positions
of the character) applied to the rest vertex in homogeneous coordinates, projected by a plain pinhole camera
built from :func:`gesturekit.character.look.camera_for` (not VTK's) and filled with PIL, as
tests/viz/test_video_character.py does for our character.
"""

from __future__ import annotations

import dataclasses
import functools

import imageio_ffmpeg
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image, ImageDraw

from gesturekit.character.mesh import build_mesh
from gesturekit.character.retarget import retarget
from gesturekit.character.rig import rig_for, solve_pose
from gesturekit.character.skin import pose_skin, skin_normals, skin_vertices
from gesturekit.character.target import CharacterSkin
from gesturekit.character.user import read_character
from gesturekit.errors import ConfigError
from gesturekit.export.video import render_video
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS
from gesturekit.viz.character_render import CharacterStage, shade, srgb_to_linear
from gesturekit.viz.character_user import character_arrays, character_from_arrays, framed_bones
from gesturekit.viz.render import RenderStyle, SkeletonScene, render_image, view_bounds
from gesturekit.viz.render_pool import render_frames
from tests.character_rigs import CASES, write_rig
from tests.viz.test_video_character import FPS, _demo, drawn, iou, pinhole, stage_alone

SIZE = (160, 120)


@functools.cache
def _folder():
    import tempfile
    from pathlib import Path

    return Path(tempfile.mkdtemp(prefix="gesturekit-rigs-"))


@functools.cache
def character(name: str):
    """A generated test character (tests/character_rigs.py), read."""
    return read_character(write_rig(_folder(), CASES[name], name=name))


def motion(start: int = 0, frames: int = 6) -> Motion:
    return Motion(_demo()[start : start + frames], FPS)


def reference_vertices(ch, skin: CharacterSkin, m: Motion, frame: int) -> np.ndarray:
    """The skin at ``frame`` from the retargeted bones: per vertex the weighted sum of its bones' 4x4 matrices."""
    r = retarget(m, ch)
    turn = r.rotation[frame] @ np.transpose(ch.rest_rotation, (0, 2, 1))  # W Q^T, (M, 3, 3)
    mat = np.zeros((ch.n_bones, 4, 4))
    mat[:, :3, :3] = turn
    mat[:, :3, 3] = r.position[frame] - np.einsum("mab,mb->ma", turn, ch.rest_position)
    blended = np.einsum("vk,vkab->vab", skin.weights.astype(np.float64), mat[skin.joints])
    rest = np.hstack([skin.vertices.astype(np.float64), np.ones((skin.n_vertices, 1))])
    return np.einsum("vab,vb->va", blended, rest)[:, :3]


def silhouette(points: np.ndarray, faces: np.ndarray, camera: dict, size=SIZE, fine: int = 8) -> np.ndarray:
    """Triangles projected and filled, (h, w) bool: the pixels at least half covered (filled ``fine`` times
    finer, since PIL also fills every pixel an edge touches; thin tubes need the finer grid)."""
    w, h = size
    canvas = Image.new("1", (w * fine, h * fine), 0)
    draw = ImageDraw.Draw(canvas)
    px = pinhole(points, camera, size) * fine - 0.5
    for tri in px[faces]:
        draw.polygon([tuple(p) for p in tri], fill=1)
    return np.asarray(canvas, dtype=float).reshape(h, fine, w, fine).mean(axis=(1, 3)) >= 0.5


# ----------------------------------------------------------------------------- one blend for both


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frame=st.integers(0, 29), offsets=hnp.arrays(np.float64, (N_JOINTS, 3), elements=st.floats(-0.05, 0.05)))
def test_a_user_skin_and_our_mesh_are_posed_by_the_one_blend(frame, offsets):
    m = Motion((_demo()[frame : frame + 1] + offsets).astype(np.float32), FPS)
    rig = rig_for(m)
    mesh = build_mesh(rig)
    pose = solve_pose(m, rig)
    as_user = CharacterSkin(
        vertices=mesh.vertices,
        normals=mesh.normals,
        faces=mesh.faces.astype(np.int64),
        joints=mesh.joints.astype(np.int64),
        weights=mesh.weights,
        colors=np.zeros((mesh.n_vertices, 3), np.float32),
    )
    vertices, normals = pose_skin(as_user, pose.skinning(rig))
    np.testing.assert_array_equal(vertices, skin_vertices(mesh, rig, pose))
    np.testing.assert_array_equal(normals, skin_normals(mesh, rig, pose))


@pytest.mark.parametrize("name", ["mixamo_a_rolled", "vrm0_a", "bvh_zeggs_a"])
def test_the_stage_poses_the_retargeted_skin_in_its_own_shaded_colours(name):
    ch, m = character(name), motion(0, 5)
    stage = CharacterStage([m], character=ch)
    skin = stage.users[0].skin
    if name != "bvh_zeggs_a":
        assert skin is ch.skin
    for frame in (0, 4, 9):  # past the end: the last pose
        expected = reference_vertices(ch, skin, m, min(frame, 4))
        np.testing.assert_allclose(stage.vertices(0, frame), expected + [stage.offsets[0], 0, 0], atol=2e-5)
    # colours: the skin's own, lit by the shared rule with its normals skinned by the bones' turns
    r = retarget(m, ch)
    turn = r.rotation[2] @ np.transpose(ch.rest_rotation, (0, 2, 1))
    n = np.einsum("vk,vkab,vb->va", skin.weights.astype(np.float64), turn[skin.joints], skin.normals)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    expected = shade(n, srgb_to_linear(skin.colors))
    assert np.abs(stage.colors(0, 2).astype(int) - expected).max() <= 1


# ----------------------------------------------------------------------------- the picture


@pytest.mark.parametrize("name", ["mixamo_a_rolled", "vrm1_t", "bvh_zeggs_a"])
def test_the_frame_is_the_retargeted_skin_seen_through_the_shared_camera(name):
    ch, m = character(name), motion(0, 4)
    with SkeletonScene([m], resolution=SIZE, character=ch) as scene:
        image = scene.render_frame(3)
        alone = scene.stage_image()
    stage = CharacterStage([m], character=ch)
    skin = stage.users[0].skin
    expected = silhouette(
        reference_vertices(ch, skin, m, 3) + [stage.offsets[0], 0, 0], skin.faces, stage.camera(4 / 3)
    )
    assert expected.sum() > 800
    # about 2000 pixels of thin limbs in the upper-body framing: a pixel along each edge is about 5 % of IoU
    assert iou(drawn(image, alone), expected) >= 0.93


def test_a_bvh_skeleton_is_drawn_as_tubes_along_its_bones():
    ch, m = character("bvh_zeggs_a"), motion(0, 2)
    assert ch.skin is None
    stage = CharacterStage([m], character=ch)
    image = render_image(m, frame=1, resolution=(320, 240), character=ch)
    r = retarget(m, ch)
    framed = framed_bones(ch, m.presence)
    camera = stage.camera(4 / 3)
    bones = [b for b in range(ch.n_bones) if ch.parents[b] >= 0 and framed[ch.parents[b]] and framed[b]]
    ends = r.position[1][bones], r.position[1][ch.parents[bones]]
    long = np.linalg.norm(ends[0] - ends[1], axis=1) > 0.05
    mid = pinhole(((ends[0] + ends[1]) / 2)[long] + [stage.offsets[0], 0, 0], camera, (320, 240))
    body = drawn(image, stage_alone([m], (320, 240), character=ch))
    # the middle of every framed bone is on the picture and drawn
    assert len(mid) > 10
    for col, row in np.rint(mid).astype(int):
        assert body[row - 1 : row + 2, col - 1 : col + 2].any()


def test_the_characters_own_colours_appear_where_its_parts_are():
    base = character("mixamo_t")
    skin = base.skin
    left = {i for i, n in enumerate(base.names) if "Left" in n and ("Arm" in n or "Hand" in n)}
    lead = skin.joints[np.arange(skin.n_vertices), np.argmax(skin.weights, axis=1)]
    red_vertex = np.isin(lead, sorted(left))
    colours = np.where(red_vertex[:, None], [0.85, 0.1, 0.1], [0.2, 0.35, 0.8]).astype(np.float32)
    ch = dataclasses.replace(base, skin=dataclasses.replace(skin, colors=colours))
    m = motion(0, 1)
    image = render_image(m, resolution=(320, 240), character=ch).astype(int)
    red = (image[..., 0] - image[..., 2] > 60) & (image[..., 0] - image[..., 1] > 60)
    blue = image[..., 2] - image[..., 0] > 60
    assert red.sum() > 100 and blue.sum() > 300
    # the red pixels are where the left arm's triangles project, and the character's left is the picture's right
    stage = CharacterStage([m], character=ch)
    arm = skin.faces[red_vertex[skin.faces].all(axis=1)]
    where = silhouette(stage.vertices(0, 0), arm, stage.camera(4 / 3), size=(320, 240))
    grown = where | np.roll(where, 1, 0) | np.roll(where, -1, 0) | np.roll(where, 1, 1) | np.roll(where, -1, 1)
    assert (red & ~grown).sum() <= 0.02 * red.sum()
    assert np.nonzero(red)[1].mean() > np.nonzero(blue)[1].mean()
    # each pixel between the darkest and the brightest shaded vertex of its colour (Gouraud blends them)
    shaded = stage.colors(0, 0).astype(int)
    for mask, vertices in ((red, red_vertex), (blue, ~red_vertex)):
        lo, hi = shaded[vertices].min(axis=0) - 2, shaded[vertices].max(axis=0) + 2
        inside = ((image[mask] >= lo) & (image[mask] <= hi)).all(axis=1)
        assert inside.mean() > 0.97  # edges blend with the background and the other colour


@pytest.mark.parametrize("name", ["mixamo_a_rolled", "vrm0_a", "bvh_zeggs_a"])
def test_the_camera_frames_every_bone_that_follows_the_motion_with_its_skin(name):
    ch, m = character(name), motion(0, 30)
    stage = CharacterStage([m], character=ch)
    skin = stage.users[0].skin
    lead = skin.joints[np.arange(skin.n_vertices), np.argmax(skin.weights, axis=1)]
    framed = framed_bones(ch, m.presence)
    framed[ch.pelvis] = False
    keep = framed[lead]
    for size in ((160, 120), (96, 160)):
        camera = stage.camera(size[0] / size[1])
        for frame in range(0, 30, 3):
            px = pinhole(stage.vertices(0, frame)[keep], camera, size)
            assert np.all((px >= -0.5) & (px <= np.array(size) + 0.5))
    # the legs (the bones well below the pelvis at rest) are not framed: the half body, as for our character
    legs = ch.rest_position[:, 1] < ch.rest_position[ch.pelvis, 1] - 0.2
    assert legs.sum() >= 4 and not framed[legs].any()


def test_side_by_side_motions_on_one_character_and_a_fixed_box_from_its_pelvis():
    ch = character("vrm0_a")
    a, b = motion(0, 2), motion(20, 2)
    image = render_image(a, side_by_side=b, labels=("k-NN", "refined"), resolution=(320, 240), character=ch)
    cols = np.nonzero(drawn(image, stage_alone([a, b], (320, 240), character=ch)))[1]
    assert (cols < 160).sum() > 500 and (cols >= 160).sum() > 500
    stage = CharacterStage([a, b], character=ch)
    assert stage.offsets[0] < 0 < stage.offsets[1]
    np.testing.assert_array_equal(view_bounds([a, b], character=ch), stage.box.T)
    fixed = RenderStyle(fit_motion=False)
    pelvis = ch.rest_position[ch.pelvis]
    expected = np.asarray(fixed.view_box) + pelvis[:, None]
    np.testing.assert_allclose(view_bounds([a], style=fixed, character=ch), expected)


@pytest.mark.slow
def test_the_rendering_processes_draw_the_character_as_this_one_does():
    ch = dataclasses.replace(character("mixamo_a_rolled"), wrist_slack=0.0)  # the hands held exactly
    m = Motion(np.concatenate([_demo(), _demo()[::-1][:4]]), FPS)  # two chunks of frames
    arrays = character_arrays(ch)
    back = character_from_arrays(arrays)
    assert back.names == ch.names and back.gltf is None and back.wrist_slack == 0.0
    for field in ("parents", "rest_rotation", "rest_position", "bone_of", "to_file"):
        np.testing.assert_array_equal(getattr(back, field), getattr(ch, field))
    np.testing.assert_array_equal(back.skin.colors, ch.skin.colors)
    serial = list(render_frames([m], resolution=(64, 48), workers=1, character=ch))
    pooled = list(render_frames([m], resolution=(64, 48), workers=2, character=ch))
    assert len(serial) == len(pooled) == 34
    for one, other in zip(serial, pooled):
        np.testing.assert_array_equal(one, other)
    assert not np.array_equal(serial[0], next(render_frames([m], resolution=(64, 48), workers=1)))


def test_the_mp4_frame_at_a_known_time_is_the_retargeted_skin(tmp_path):
    ch, m = character("vrm1_t"), motion(0, 4)
    path = render_video(tmp_path / "user.mp4", m, resolution=SIZE, character=ch)
    reader = imageio_ffmpeg.read_frames(str(path))
    next(reader)
    frames = [np.frombuffer(f, np.uint8).reshape(SIZE[1], SIZE[0], 3) for f in reader]
    assert len(frames) == 4
    stage = CharacterStage([m], character=ch)
    expected = silhouette(
        reference_vertices(ch, ch.skin, m, 3) + [stage.offsets[0], 0, 0], ch.skin.faces, stage.camera(4 / 3)
    )
    assert (
        iou(drawn(frames[3], stage_alone([m], SIZE, character=ch), tolerance=40), expected) >= 0.9
    )  # coding noise blurs edges and flat areas


def test_a_character_is_refused_where_it_cannot_be_drawn(tmp_path):
    ch, m = character("mixamo_t"), motion(0, 1)
    with pytest.raises(ConfigError, match="character look"):
        render_image(m, resolution=SIZE, style=RenderStyle(look="capsules"), character=ch)
    with pytest.raises(ConfigError, match="must be a Character"):
        render_video(tmp_path / "x.mp4", m, resolution=SIZE, character=str(ch.path))  # type: ignore[arg-type]
    assert not (tmp_path / "x.mp4").exists()


def test_the_result_video_passes_the_character_on(tmp_path, monkeypatch):
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.demo import open_default_database
    from gesturekit.export import result as result_module
    from gesturekit.synthesis import synthesize

    take, _ = generate_demo_take(seconds=2.0, seed=5, name="look")
    res = synthesize(take.audio, db=open_default_database())
    ch = character("vrm0_a")
    seen = []
    monkeypatch.setattr(result_module, "render_video", lambda path, motion, **kw: seen.append(kw["character"]) or path)
    result_module.save_result_video(res, tmp_path / "theirs.mp4", character=ch)
    result_module.save_result_video(res, tmp_path / "ours.mp4")
    assert seen[0] is ch and seen[1] is None


@pytest.mark.parametrize("size", [(640, 480), (320, 240)])
@pytest.mark.parametrize("theirs", [False, True])
def test_side_by_side_labels_stand_whole_inside_the_picture(size, theirs):
    from gesturekit.viz.character_render import LABEL_MARGIN

    ch = character("mixamo_a_rolled") if theirs else None  # a user's character fills the view up to its head
    image = render_image(
        motion(0, 1), side_by_side=motion(10, 1), labels=("k-NN", "k-NN + refiner"), resolution=size, character=ch
    ).astype(int)
    w = size[0]
    orange = (image[..., 0] - image[..., 2]) > 60  # the second label, in the refined body's shirt colour
    lit = np.flatnonzero(orange.any(axis=1))
    gaps = np.flatnonzero(np.diff(lit) > 1)
    if gaps.size:  # the body's orange shirt is below the label: keep the label's band of rows only
        orange[lit[gaps[0]] + 1 :] = False
    rows, cols = np.nonzero(orange)
    assert rows.size > 30, "the label is drawn"
    assert rows.min() >= LABEL_MARGIN - 1 and rows.max() - rows.min() >= 5  # its top inside, its glyphs whole
    assert cols.min() > w // 2 and cols.max() < w - 1  # within its half, not cut at the right edge
