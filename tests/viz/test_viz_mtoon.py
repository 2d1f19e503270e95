"""The MP4's MToon shader against the plain rule: each fragment is :func:`gesturekit.character.mtoon.mtoon_shade`.

A grid of small squares faces the camera, each drawn by :class:`gesturekit.viz.character_mtoon.MToonActors`
with one normal of its own (the shader reads the normal from a vertex attribute, not from the square's
geometry), so each square's middle pixel is the rule at that normal: lit and shade colour (a one-colour sRGB
texture on the lit colour, to check the textures are sampled in linear light), every light's toony step, the
rim towards the camera, emission, written as sRGB. The outline's pushed-out points are checked against the
rule written out.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import pyvista as pv

from gesturekit.character.look import LIGHTS, linear_to_srgb, srgb_to_linear
from gesturekit.character.materials import SkinMaterial
from gesturekit.character.mtoon import MToon, mtoon_shade
from gesturekit.motion import Motion
from gesturekit.viz.character_mtoon import MToonActors, outline_points
from gesturekit.viz.render import _opengl_window_choice

SIZE = (480, 320)
CAMERA = {"position": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov": 30.0}
COLS, ROWS, SIDE, STEP = 8, 5, 0.22, 0.3


def _squares() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The squares' vertices (4 each), triangles (counter-clockwise seen from +Z) and middles."""
    xs = (np.arange(COLS) - (COLS - 1) / 2) * STEP
    ys = (np.arange(ROWS) - (ROWS - 1) / 2) * STEP
    middles = np.array([[x, y, 0.0] for y in ys for x in xs])
    corners = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) * SIDE / 2
    vertices = (middles[:, None] + corners[None]).reshape(-1, 3)
    base = 4 * np.arange(len(middles))[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]).reshape(-1, 3)
    return vertices.astype(np.float32), faces, middles


def _normals(n: int, seed: int) -> np.ndarray:
    """``n`` unit normals: many near the lights' terminators, some facing away from the camera."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


MATERIALS = {
    "soft": MToon(shade_color=(0.1, 0.3, 0.6), shading_shift=0.1, shading_toony=0.3),
    "hard": MToon(shade_color=(0.5, 0.1, 0.3), shading_shift=-0.2, shading_toony=0.95, emissive=(0.03, 0.02, 0.0)),
    "rim": MToon(
        shade_color=(0.2, 0.2, 0.1),
        shading_toony=0.8,
        rim_color=(0.3, 0.2, 0.1),
        rim_fresnel_power=2.0,
        rim_lift=0.1,
        rim_lighting_mix=0.4,
    ),
}


def _draw(mtoon: MToon, normals: np.ndarray, texel: np.ndarray | None) -> np.ndarray:
    vertices, faces, _ = _squares()
    lit = (0.9, 0.7, 0.5, 1.0)
    material = SkinMaterial(
        name="toon",
        color=lit,
        image=None if texel is None else 0,
        nearest=True,
        alpha_mode="OPAQUE",
        alpha_cutoff=0.5,
        double_sided=False,
        mtoon=mtoon,
    )
    images = [] if texel is None else [np.tile(np.append(texel, 255).astype(np.uint8), (4, 4, 1))]
    skin = SimpleNamespace(uvs=np.zeros((len(vertices), 2), np.float32), face_materials=np.zeros(len(faces), int))
    user = SimpleNamespace(skin=skin, materials=[material], images=images)
    with _opengl_window_choice():
        plotter = pv.Plotter(off_screen=True, window_size=list(SIZE))
    try:
        plotter.set_background("black")
        mesh = pv.PolyData(vertices.astype(np.float64), np.hstack([np.full((len(faces), 1), 3), faces]).ravel())
        toon = MToonActors(plotter, mesh, faces, user, CAMERA)  # type: ignore[arg-type]
        toon.update(vertices, np.repeat(normals, 4, axis=0).astype(np.float32))
        cam = plotter.renderer.GetActiveCamera()
        cam.SetPosition(*CAMERA["position"])
        cam.SetFocalPoint(*CAMERA["target"])
        cam.SetViewUp(*CAMERA["up"])
        cam.SetViewAngle(CAMERA["fov"])
        plotter.renderer.camera_set = True
        return np.asarray(plotter.screenshot(return_img=True))[..., :3]
    finally:
        plotter.close()


def _pixel_of(point: np.ndarray) -> tuple[int, int]:
    """The picture's row and column of a point of the plane z = 0, through :data:`CAMERA`."""
    depth = CAMERA["position"][2] - point[2]
    half = np.tan(np.radians(CAMERA["fov"]) / 2) * depth
    w, h = SIZE
    x = (point[0] / (half * w / h) + 1) / 2 * w
    y = (1 - point[1] / half) / 2 * h
    return int(y), int(x)


@pytest.mark.parametrize("name", list(MATERIALS))
@pytest.mark.parametrize("textured", [False, True], ids=["factor", "texture"])
def test_each_fragment_is_the_mtoon_rule(name, textured):
    mtoon = MATERIALS[name]
    _, _, middles = _squares()
    normals = _normals(len(middles), seed=len(name))
    texel = np.array([200, 120, 60]) if textured else None
    picture = _draw(mtoon, normals, texel)
    lit = np.array([0.9, 0.7, 0.5])
    if texel is not None:
        lit = lit * srgb_to_linear(texel / 255)
    towards = np.asarray(CAMERA["position"]) - middles
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    want = mtoon_shade(
        normals, np.tile(lit, (len(middles), 1)), np.tile(mtoon.shade_color, (len(middles), 1)), mtoon, view=towards
    )
    want = np.rint(255 * linear_to_srgb(np.clip(want, 0, 1)))
    got = np.array([picture[_pixel_of(p)] for p in middles], dtype=float)
    assert np.abs(got - want).max() <= 2, np.abs(got - want).max(axis=1)
    # the normals reach both ends of the key light's step: squares in its shade and squares fully lit
    key = normals @ (np.asarray(LIGHTS[0][0]) / np.linalg.norm(LIGHTS[0][0])) + mtoon.shading_shift
    assert (key < -1 + mtoon.shading_toony).any() and (key > 1 - mtoon.shading_toony).any()


def test_an_outline_is_pushed_out_by_its_width_in_metres_or_in_the_pictures_height():
    v = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -2.0]])
    n = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    world = MToon(outline_mode="worldCoordinates", outline_width=0.01)
    np.testing.assert_allclose(outline_points(v, n, world, CAMERA), v + 0.01 * n)
    screen = MToon(outline_mode="screenCoordinates", outline_width=0.01)
    depth = np.array([5.0, 7.0])  # along the camera's view, from the camera
    want = v + (0.01 * depth * np.tan(np.radians(15.0)))[:, None] * n
    np.testing.assert_allclose(outline_points(v, n, screen, CAMERA), want)
    out = np.zeros_like(v)
    assert outline_points(v, n, screen, CAMERA, out=out) is out
    np.testing.assert_allclose(out, want)


@pytest.mark.slow
def test_the_rendering_processes_draw_the_toon_shaded_character_as_this_one_does(tmp_path):
    """The MToon travels with the character to the rendering processes: their frames are this process's, and
    not those of the same character with its MToon left out."""
    from gesturekit.character.user import read_character
    from gesturekit.viz.render_pool import render_frames
    from tests.browser.test_browser_materials import motion, without_mtoon
    from tests.character_rigs import RigSpec, write_rig

    ch = read_character(write_rig(tmp_path, RigSpec(naming="vrm1", rest="A", textured=True, mtoon=True), "toon"))
    full = motion()
    m = Motion(full.positions[:20], full.fps, full.presence)
    serial = list(render_frames([m], resolution=(96, 64), workers=1, character=ch))
    pooled = list(render_frames([m], resolution=(96, 64), workers=2, character=ch))
    assert len(serial) == len(pooled) == 20
    for one, other in zip(serial, pooled):
        np.testing.assert_array_equal(one, other)
    plain = next(render_frames([m], resolution=(96, 64), workers=1, character=without_mtoon(ch)))
    assert np.abs(serial[0].astype(int) - plain.astype(int)).mean() > 2
