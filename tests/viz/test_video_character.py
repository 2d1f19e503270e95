"""The MP4's character is the page's picture: the skinned mesh through the shared camera, the shared shading.

The silhouette of a rendered frame (the pixels that differ from the picture of the stage alone:
backdrop, floor and shadows) is compared with the skinned vertices' and the still legs' triangles
projected by a plain pinhole camera built from :func:`gesturekit.character.look.camera_for` (not VTK's),
filled with PIL; the colours with the Lambert rule of the three lights written out per channel with
scalar maths.
"""

from __future__ import annotations

import base64
import functools
import math

import imageio_ffmpeg
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image, ImageDraw

from gesturekit.character.look import AMBIENT, LIGHTS, SCHEMES, part_colors
from gesturekit.character.mesh import PARTS, build_mesh
from gesturekit.character.rig import rig_for
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.export.video import render_video
from gesturekit.motion import Motion
from gesturekit.skeleton import JOINT_NAMES, N_JOINTS, JointPresence, joint_index
from gesturekit.study.stimuli import stimulus_style
from gesturekit.viz.character_render import CharacterStage, linear_to_srgb, shade, srgb_to_linear, visible_faces
from gesturekit.viz.render import RenderStyle, SkeletonScene, render_image, view_bounds
from gesturekit.viz.render_pool import render_frames

FPS = 15.0
THUMBS = tuple(f"{side}_thumb{k}" for side in ("left", "right") for k in range(1, 5))


@functools.cache
def _demo() -> np.ndarray:
    take, _ = generate_demo_take(seconds=2.0, seed=3, name="character")
    return np.asarray(take.motion.positions, dtype=np.float32)


def demo_motion(start: int = 0, frames: int = 8, presence: JointPresence | None = None) -> Motion:
    return Motion(_demo()[start : start + frames], FPS, presence)


def without_thumbs() -> JointPresence:
    return JointPresence.from_names(recorded=[n for n in JOINT_NAMES if n not in THUMBS])


def stage_alone(
    motions: list[Motion], size: tuple[int, int], style: RenderStyle | None = None, character=None
) -> np.ndarray:
    """The picture of the stage the motions stand on, without them (on a user's ``character`` where given)."""
    with SkeletonScene(motions, resolution=size, style=style, character=character) as scene:
        return scene.stage_image()


def drawn(image: np.ndarray, stage: np.ndarray, tolerance: int = 0) -> np.ndarray:
    """Pixels not of the stage's picture (``stage``: :func:`stage_alone`)."""
    return np.abs(image.astype(int) - stage.astype(int)).sum(axis=-1) > tolerance


def pinhole(points: np.ndarray, camera: dict, size: tuple[int, int]) -> np.ndarray:
    """Pixel (column, row) of points seen by a look-at camera with a vertical field of view, shape (n, 2)."""
    w, h = size
    eye, target, up = (np.asarray(camera[k], dtype=np.float64) for k in ("position", "target", "up"))
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    d = np.asarray(points, dtype=np.float64) - eye
    depth = d @ forward
    t = math.tan(math.radians(camera["fov"]) / 2)
    x = (d @ right) / (depth * t * (w / h))
    y = (d @ true_up) / (depth * t)
    return np.stack([(x + 1) / 2 * w, (1 - y) / 2 * h], axis=1)


def projected_silhouette(stage: CharacterStage, frame: int, size: tuple[int, int], fine: int = 4) -> np.ndarray:
    """Every character's visible triangles at ``frame``, projected and filled, shape (h, w) bool: the
    pixels at least half covered (filled ``fine`` times finer, since PIL also fills every pixel an edge
    touches)."""
    w, h = size
    canvas = Image.new("1", (w * fine, h * fine), 0)
    draw = ImageDraw.Draw(canvas)
    camera = stage.camera(w / h)
    for i, faces in enumerate(stage.faces):
        # sub-pixel k covers [k, k + 1): its centre, where PIL samples, is at k + 0.5
        px = pinhole(stage.vertices(i, frame), camera, size) * fine - 0.5
        for tri in px[faces]:
            draw.polygon([tuple(p) for p in tri], fill=1)
        legs = stage.stand(i)
        if legs is not None:
            px = pinhole(legs[0], camera, size) * fine - 0.5
            for tri in px[legs[1]]:
                draw.polygon([tuple(p) for p in tri], fill=1)
    cover = np.asarray(canvas, dtype=float).reshape(h, fine, w, fine).mean(axis=(1, 3))
    return cover >= 0.5


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


# ----------------------------------------------------------------------------- the silhouette


@pytest.mark.parametrize("frame", [0, 7])
def test_the_frame_is_the_skinned_mesh_seen_through_the_shared_camera(frame):
    motions = [demo_motion(0), demo_motion(10)]
    size = (320, 240)
    with SkeletonScene(motions, resolution=size) as scene:
        image = scene.render_frame(frame)
        alone = scene.stage_image()
    expected = projected_silhouette(CharacterStage(motions), frame, size)
    assert expected.sum() > 2000  # two bodies, not specks
    assert iou(drawn(image, alone), expected) >= 0.95
    # side by side: one character in each half, the first on the left
    cols = np.nonzero(drawn(image, alone))[1]
    assert (cols < size[0] / 2).sum() > 1000 and (cols >= size[0] / 2).sum() > 1000


@pytest.mark.slow
def test_the_mp4_frame_keeps_the_silhouette(tmp_path):
    motions = [demo_motion(0, 4), demo_motion(20, 4)]
    path = render_video(tmp_path / "pair.mp4", motions[0], side_by_side=motions[1], resolution=(320, 240))
    reader = imageio_ffmpeg.read_frames(str(path))
    next(reader)
    frames = [np.frombuffer(f, np.uint8).reshape(240, 320, 3) for f in reader]
    assert len(frames) == 4
    expected = projected_silhouette(CharacterStage(motions), 3, (320, 240))
    alone = stage_alone(motions, (320, 240))
    assert iou(drawn(frames[3], alone, tolerance=40), expected) >= 0.9  # coding noise blurs edges and flat areas


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    offsets=hnp.arrays(np.float64, (2, N_JOINTS, 3), elements=st.floats(-0.5, 0.5)),
    width=st.sampled_from([64, 160, 320]),
)
def test_every_joint_of_every_character_stays_in_frame(offsets, width):
    # the full body framed: every joint of a pose (the upper body's framing leaves hands below the hips out)
    motion = Motion((_demo()[:1] + offsets[:1]).astype(np.float32), FPS)
    other = Motion((_demo()[:1] + offsets[1:]).astype(np.float32), FPS)
    stage = CharacterStage([motion, other], framing="full body")
    camera = stage.camera(width / 120)
    for i, m in enumerate((motion, other)):
        px = pinhole(m.positions[0] + [stage.offsets[i], 0, 0], camera, (width, 120))
        assert np.all((px >= 0) & (px <= [width, 120]))


def test_view_bounds_of_the_character_are_the_stage_box():
    motions = [demo_motion(0), demo_motion(10)]
    np.testing.assert_array_equal(view_bounds(motions), CharacterStage(motions).box.T)
    fixed = RenderStyle(fit_motion=False)
    np.testing.assert_array_equal(view_bounds(motions, style=fixed), np.asarray(fixed.view_box))
    assert np.array_equal(CharacterStage(motions, view_box=fixed.view_box).box, np.asarray(fixed.view_box).T)


# ----------------------------------------------------------------------------- colours


def _lambert_srgb(hex_colour: str, n: np.ndarray) -> list[int]:
    """The shared rule written out per channel: linear albedo * (AMBIENT + sum of k * max(0, n.l)), to sRGB."""
    lit = AMBIENT
    for direction, strength in LIGHTS:
        norm = math.sqrt(sum(c * c for c in direction))
        lit += strength * max(0.0, sum(float(a) * b / norm for a, b in zip(n, direction)))
    out = []
    for k in range(3):
        s = int(hex_colour[1 + 2 * k : 3 + 2 * k], 16) / 255
        lin = s / 12.92 if s <= 0.04045 else ((s + 0.055) / 1.055) ** 2.4
        v = min(1.0, lin * lit)
        enc = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
        out.append(round(255 * enc))
    return out


@settings(max_examples=40, deadline=None)
@given(
    n=hnp.arrays(np.float64, 3, elements=st.floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 0.1),
    scheme=st.sampled_from(sorted(SCHEMES)),
    part=st.sampled_from(PARTS),
)
def test_shading_is_the_shared_lambert_rule_in_srgb(n, scheme, part):
    n = n / np.linalg.norm(n)
    albedo = srgb_to_linear(part_colors(scheme)[PARTS.index(part)])
    got = shade(n[None], albedo[None])[0]
    assert np.abs(got.astype(int) - _lambert_srgb(SCHEMES[scheme][part], n)).max() <= 1


def test_srgb_conversions_are_inverse():
    x = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-12)


def test_stimuli_are_the_neutral_grey_character():
    motion = demo_motion(0, 2)
    style = stimulus_style()
    assert style.neutral and style.look == "character"
    image = render_image(motion, resolution=(160, 120), style=style).astype(int)
    body = image[drawn(image, stage_alone([motion], (160, 120), style))]
    assert len(body) > 500
    assert (body.max(axis=1) - body.min(axis=1)).max() <= 1  # no hue anywhere
    # every pixel between the darkest and the brightest shaded vertex (Gouraud blends vertex colours)
    stage = CharacterStage([motion], neutral=True)
    colours = stage.colors(0, 0)[:, 0].astype(int)
    assert colours.min() - 1 <= body.min() and body.max() <= colours.max() + 1
    # the side-by-side look instead: a blue shirt
    coloured = render_image(motion, resolution=(160, 120)).astype(int)
    assert ((coloured[..., 2] - coloured[..., 0]) > 40).sum() > 200


def test_side_by_side_characters_wear_their_schemes_and_labels():
    image = render_image(
        demo_motion(0, 1), side_by_side=demo_motion(10, 1), labels=("k-NN", "refined"), resolution=(320, 240)
    ).astype(int)
    blue, orange = (image[..., 2] - image[..., 0]) > 60, (image[..., 0] - image[..., 2]) > 60
    half = 160
    assert blue[:, :half].sum() > 300 and orange[:, half:].sum() > 300
    assert blue[:, half:].sum() == 0
    # the labels above the bodies, in the shirts' colours
    top_blue, top_orange = np.nonzero(blue)[0].min(), np.nonzero(orange[:, half:])[0].min()
    plain = render_image(demo_motion(0, 1), side_by_side=demo_motion(10, 1), resolution=(320, 240))
    body = np.nonzero(drawn(plain, stage_alone([demo_motion(0, 1), demo_motion(10, 1)], (320, 240))))
    assert top_blue < body[0].min() and top_orange < body[0].min()


# ----------------------------------------------------------------------------- determinism, partial skeletons


def test_same_inputs_give_the_same_frames_in_any_order_and_any_process():
    motions = [demo_motion(0, 6), demo_motion(10, 4)]
    with SkeletonScene(motions, resolution=(96, 72)) as scene:
        forward = [scene.render_frame(f) for f in range(6)]
        backward = [scene.render_frame(f) for f in reversed(range(6))][::-1]
    with SkeletonScene(motions, resolution=(96, 72)) as again:
        fresh = [again.render_frame(f) for f in range(6)]
    pooled = list(render_frames(motions, resolution=(96, 72), workers=2))
    for a, b, c, d in zip(forward, backward, fresh, pooled):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
        np.testing.assert_array_equal(a, d)
    # the shorter motion holds its last pose
    np.testing.assert_array_equal(CharacterStage(motions).vertices(1, 5), CharacterStage(motions).vertices(1, 3))


def test_absent_parts_are_hidden_and_change_no_pixel_wherever_they_are():
    presence = without_thumbs()
    near = demo_motion(0, 1, presence)
    far_positions = near.positions.copy()
    for name in THUMBS:
        far_positions[:, joint_index(name), 0] += 0.4
    far = Motion(far_positions, FPS, presence)
    a, b = render_image(near, resolution=(96, 72)), render_image(far, resolution=(96, 72))
    np.testing.assert_array_equal(a, b)
    expected = projected_silhouette(CharacterStage([near]), 0, (96, 72))
    assert iou(drawn(a, stage_alone([near], (96, 72))), expected) >= 0.9


def test_faces_bound_to_joints_the_rig_lacks_are_not_drawn():
    full = demo_motion(0, 1)
    partial = demo_motion(0, 1, without_thumbs())
    mesh = build_mesh(rig_for(full))  # a body that has thumbs
    rig = rig_for(partial)
    kept = visible_faces(mesh, rig)
    thumbs = {joint_index(n) for n in THUMBS}
    # a vertex goes with the thumbs when more than half its weight is theirs
    on_thumb = np.array(
        [sum(float(w) for j, w in zip(js, ws) if int(j) in thumbs) > 0.5 for js, ws in zip(mesh.joints, mesh.weights)]
    )
    assert on_thumb.any() and len(kept) < len(mesh.faces)
    assert not on_thumb[kept].any()
    # every face away from the thumbs is kept
    assert len(kept) == (~on_thumb[mesh.faces].any(axis=1)).sum()
    np.testing.assert_array_equal(visible_faces(mesh, rig_for(full)), mesh.faces)


def test_the_capsule_look_is_still_there():
    capsules = RenderStyle(look="capsules")
    image = render_image(demo_motion(0, 1), resolution=(96, 72), style=capsules)
    assert not np.array_equal(image, render_image(demo_motion(0, 1), resolution=(96, 72)))
    with pytest.raises(Exception, match="unknown look"):
        RenderStyle(look="stick")


@pytest.mark.slow
def test_the_command_line_and_the_result_video_choose_the_look(tmp_path, monkeypatch):
    from gesturekit.cli._parser import build_parser
    from gesturekit.demo import open_default_database
    from gesturekit.export import result as result_module
    from gesturekit.synthesis import synthesize

    parse = build_parser().parse_args
    assert parse(["synthesize", "a.wav", "--db", "db", "--video"]).video_style == "character"
    assert (
        parse(["synthesize", "a.wav", "--db", "db", "--video", "--video-style", "capsules"]).video_style == "capsules"
    )
    take, _ = generate_demo_take(seconds=2.0, seed=5, name="look")
    res = synthesize(take.audio, db=open_default_database())
    seen = []
    monkeypatch.setattr(result_module, "render_video", lambda path, motion, **kw: seen.append(kw["style"]) or path)
    for look in ("character", "capsules"):
        result_module.save_result_video(res, tmp_path / f"{look}.mp4", look=look)
    assert [s.look for s in seen] == ["character", "capsules"]
    # the framing: the upper body and every hand unless --video-full-body
    assert not parse(["synthesize", "a.wav", "--db", "db", "--video"]).video_full_body
    assert parse(["synthesize", "a.wav", "--db", "db", "--video", "--video-full-body"]).video_full_body
    result_module.save_result_video(res, tmp_path / "full.mp4", framing="full body")
    assert [s.framing for s in seen] == ["upper body", "upper body", "full body"]
    assert not any(s.neutral for s in seen)  # the app and the command line show the side-by-side schemes


def test_vertices_led_by_derived_joints_are_derived_grey_and_the_page_and_the_mp4_paint_alike():
    from gesturekit.character.paint import DERIVED_COLOR, paint
    from gesturekit.skeleton import DERIVABLE_JOINTS
    from gesturekit.viz.appearance import hex_to_rgb
    from gesturekit.viz.viewer import viewer_data

    torso = tuple(n for n in DERIVABLE_JOINTS if n != "neck")
    presence = JointPresence.from_names(recorded=[n for n in JOINT_NAMES if n not in torso], derived=torso)
    motion = demo_motion(0, 2, presence)
    body = build_mesh(rig_for(motion))
    mesh, palette = paint(body, presence, "blue")
    colours = palette[mesh.parts]
    derived = {joint_index(n) for n in torso}
    for v in range(body.n_vertices):  # the body's own vertices (copies at seams take their triangle's colour)
        lead = int(mesh.joints[v, int(np.argmax(mesh.weights[v]))])
        want = hex_to_rgb(DERIVED_COLOR) if lead in derived else part_colors("blue")[body.parts[v]]
        np.testing.assert_array_equal(colours[v], want)
    assert (colours == hex_to_rgb(DERIVED_COLOR)).all(axis=1).any()
    # every triangle in one colour: no colour is blended across a seam
    assert (mesh.parts[mesh.faces] == mesh.parts[mesh.faces][:, :1]).all()
    # the page's mesh and colours for the same motion are the MP4's, vertex by vertex
    page = viewer_data([motion])["motions"][0]
    parts = np.frombuffer(base64.b64decode(page["mesh"]["parts"]["bdata"]), np.uint8)
    np.testing.assert_array_equal(parts, mesh.parts)
    np.testing.assert_allclose(np.asarray(page["colors"])[parts], colours, atol=1e-6)
    stage = CharacterStage([motion])
    np.testing.assert_array_equal(stage.meshes[0].parts, mesh.parts)


def test_a_motion_without_bone_lengths_has_no_body_and_its_neighbour_is_drawn():
    point = Motion(np.zeros((3, N_JOINTS, 3), np.float32), FPS)  # every joint at one point
    alone = render_image(point, frame=2, resolution=(64, 48))
    assert not drawn(alone, stage_alone([point], (64, 48))).any()
    pair = render_image(point, side_by_side=demo_motion(0, 3), frame=2, resolution=(160, 120))
    cols = np.nonzero(drawn(pair, stage_alone([point, demo_motion(0, 3)], (160, 120))))[1]
    # only the right-hand character (its hands may reach a little past the middle: the spacing follows the reach)
    assert len(cols) > 200 and cols.min() >= 60
