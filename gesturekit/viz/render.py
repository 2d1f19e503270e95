"""Offscreen 3D renders of motions as bodies, with PyVista: the frames of the MP4 videos.

A :class:`SkeletonScene` draws one motion, or two side by side (for example the
k-NN result next to the refined one). By default (``RenderStyle(look="character")``)
it draws the page's picture: the skinned character of :mod:`gesturekit.character`,
side-by-side characters on one stage, with the page's shading, colours, camera
and background (:mod:`gesturekit.viz.character_render`). ``look="capsules"``
keeps the earlier figure, in the one appearance of the notebooks' figure
(:mod:`gesturekit.viz.appearance`): capsules with round ends for the limbs,
fingers and torso, a head ball, each motion in its colour (first blue, second
orange), lit by the appearance's light fixed to the camera, standing over a
floor with a contact shadow. The camera stands on the character's +Z side,
looks down a little and is framed on every drawn surface of the whole clip,
so the figure fills the view and no hand is ever cut; a fixed box instead
(``RenderStyle(fit_motion=False)``) frames the clips of every system of a user
study alike. The meshes are built once; each frame only rewrites their points
(in numpy), so a long clip costs little more than the rasterisation itself.
:func:`gesturekit.viz.render_pool.render_frames` renders a clip's frames on every
core, in order.

Rendering needs no display server. On Linux without ``DISPLAY`` or
``WAYLAND_DISPLAY`` the scene asks VTK for its EGL render window (Mesa's
software rasteriser, llvmpipe, when there is no GPU) unless the
``VTK_DEFAULT_OPENGL_WINDOW`` environment variable already names a window
class. The Debian packages ``libegl1``, ``libegl-mesa0`` and
``libgl1-mesa-dri`` provide EGL and the rasteriser; without EGL, VTK falls
back to OSMesa (``libosmesa6``).
"""

from __future__ import annotations

import contextlib
import ctypes.util
import math
import os
import sys
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import pyvista as pv
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkUnsignedCharArray

from .._arguments import checks_arguments
from ..character.look import BACKGROUND
from ..character.target import Character
from ..errors import ConfigError, GestureKitError
from ..motion import Motion
from ..skeleton import N_JOINTS, JointPresence
from .appearance import DERIVED_POINTS, LOOKS, Appearance, BodyShapes, RenderStyle, hex_to_rgb
from .body_meshes import BodyMeshes
from .character_render import CharacterDrawing, CharacterStage

__all__ = ["LOOKS", "RenderStyle", "SkeletonScene", "render_image", "view_bounds", "check_scene", "check_character"]

_WINDOW_ENV = "VTK_DEFAULT_OPENGL_WINDOW"


@contextlib.contextmanager
def _opengl_window_choice() -> Iterator[None]:
    """Ask VTK for its EGL window while render windows are created, on headless Linux.

    VTK reads ``VTK_DEFAULT_OPENGL_WINDOW`` when it creates a render window.
    Without it VTK first tries X, which on a machine without a display fails
    with a warning before VTK moves on to EGL. The variable is set only for the
    duration of the block and only if the user has not chosen a window class.
    """
    headless = (
        sys.platform.startswith("linux")
        and _WINDOW_ENV not in os.environ
        and not os.environ.get("DISPLAY")
        and not os.environ.get("WAYLAND_DISPLAY")
    )
    if not headless or ctypes.util.find_library("EGL") is None:
        # leave the choice to VTK, which falls back to OSMesa where EGL is missing
        yield
        return
    os.environ[_WINDOW_ENV] = "vtkEGLRenderWindow"
    try:
        yield
    finally:
        os.environ.pop(_WINDOW_ENV, None)


def _reach(a: Appearance, presence: JointPresence | None = None) -> np.ndarray:
    """How far the surface reaches around each body point, metres, shape (points,): the largest
    radius of the capsules and spheres drawn on it (0 where nothing is drawn)."""
    capsules, spheres = a.shapes(presence)
    reach = np.zeros(N_JOINTS + len(DERIVED_POINTS))
    for c in capsules:
        reach[[c.a, c.b]] = np.maximum(reach[[c.a, c.b]], c.radius)
    for sp in spheres:
        reach[sp.centre] = max(reach[sp.centre], sp.radius)
    return reach


_PELVIS = N_JOINTS + DERIVED_POINTS.index("pelvis")


def _shadow_centre(*bodies: BodyShapes) -> np.ndarray:
    """Where bodies stand on average over all their frames, shape (3,), metres: their pelvis,
    or, when one lacks a pelvis, the mean of the points drawn."""
    if all(b.drawn[_PELVIS] for b in bodies):
        return np.concatenate([b.points[:, _PELVIS] for b in bodies]).mean(axis=0)
    return np.concatenate([b.drawn_points().reshape(-1, 3) for b in bodies]).mean(axis=0)


@checks_arguments
def view_bounds(
    motions: Sequence[Motion], *, style: RenderStyle | None = None, character: Character | None = None
) -> np.ndarray:
    """The region a scene frames, shape (3, 2): (min, max) of x, y, z in metres.

    With a ``character`` (the character look only), that of its stage
    (:class:`~gesturekit.viz.character_render.CharacterStage`): fitted, the
    character's bones that follow the motions; fixed, ``view_box`` from the
    character's pelvis at rest.

    With ``style.fit_motion`` (the default), the appearance's framing rule:
    the bounds of every drawn surface of every motion over the whole clip
    (recorded and derived joints; absent ones are not drawn), the floor
    included, grown by its ``frame_margin`` on each side (per axis).
    Without it, the style's fixed ``view_box``. The floor lies at the bottom
    of the region.
    """
    style = style or RenderStyle()
    check_character(character, style)
    if character is not None:
        box = None if style.fit_motion else np.asarray(style.view_box)
        return CharacterStage(motions, view_box=box, character=character, framing=style.framing).box.T.copy()
    if not style.fit_motion:
        return np.asarray(style.view_box, dtype=np.float64).copy()
    if style.look == "character":
        # the page's stage: every drawn joint of every character in its place, framed by the one rule
        return CharacterStage(motions, framing=style.framing).box.T.copy()
    a = style.appearance
    # only what is drawn: absent joints sit on their parents and would only shift the box
    every = np.concatenate([a.body(m.positions, m.presence).drawn_points().reshape(-1, 3) for m in motions])
    lo, hi = a.bounds(every, margin=False)
    lo[1] = min(lo[1], a.ground_height(every))
    pad = a.frame_margin * (hi - lo)
    return np.stack([lo - pad, hi + pad], axis=1)


def _camera(
    points: np.ndarray, aspect: float, style: RenderStyle, *, pad: float | np.ndarray = 0.0, margin: float = 0.0
) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], tuple[float, float]]:
    """Camera in front of the points (+Z), looking down by ``style.elevation``, as close as it
    can be with every point (grown by ``pad`` metres) in view and a ``margin`` (a fraction of
    the view) left free on every side.

    Parameters
    ----------
    points : np.ndarray, shape (n, 3)
        What must be seen, metres.
    aspect : float
        Width over height of the view.
    pad : float or np.ndarray of shape (n,)
        Radius around each point that must be seen too, metres.

    Returns
    -------
    ``(position, focal_point, view_up, (near, far))``.
    """
    e = math.radians(style.elevation)
    back = np.array([0.0, math.sin(e), math.cos(e)])  # from the scene towards the camera
    up = np.array([0.0, math.cos(e), -math.sin(e)])
    right = np.cross(up, back)
    x, y, z = points @ right, points @ up, points @ back
    # centred on the points' extent across the view, then moved back until the widest point fits
    t = math.tan(math.radians(style.view_angle) / 2) / (1 + 2 * margin)
    cx, cy = 0.5 * ((x - pad).min() + (x + pad).max()), 0.5 * ((y - pad).min() + (y + pad).max())
    distance = float(np.max(np.maximum((np.abs(x - cx) + pad) / (t * aspect), (np.abs(y - cy) + pad) / t) + z + pad))
    focal = cx * right + cy * up
    position = focal + distance * back
    near = max(1e-3, 0.02 * distance)
    far = distance - float(z.min()) + 20.0  # the floor reaches far behind
    return tuple(position), tuple(focal), tuple(up), (near, far)


class SkeletonScene:
    """An offscreen window showing one or two motions as bodies, updated frame by frame.

    Build it once per clip, call :meth:`render_frame` for every frame, then
    :meth:`close` it (or use it as a context manager). The character look
    shows two motions side by side on one stage, as the page does
    (:func:`gesturekit.character.look.stage_layout`), each in its colour scheme
    with its label above in its shirt's colour; the capsule look shows them in
    two panels framed by the same camera. :meth:`project` maps world points
    (the character look's stage coordinates) to pixels.

    Parameters
    ----------
    motions : sequence of Motion
        One or two motions of equal fps. A motion shorter than the longest
        holds its last pose. Each is drawn as its ``presence`` says: absent
        joints not at all (nor framed), derived ones in the derived grey.
    labels : sequence of str, optional
        One label per motion, drawn above it (the capsules: at the top of its panel).
    resolution : (int, int)
        Width and height of the whole picture, pixels.
    style : RenderStyle, optional
        Look of the scene; :class:`RenderStyle()` by default.
    character : Character, optional
        A user's character every motion is retargeted onto (the character look only): its own skin and
        colours (:class:`~gesturekit.viz.character_render.CharacterStage`).

    Attributes
    ----------
    n_frames : int
        Frames of the longest motion.
    fps : float
        Frame rate of the motions.
    """

    def __init__(
        self,
        motions: Sequence[Motion],
        *,
        labels: Sequence[str] | None = None,
        resolution: tuple[int, int] = (640, 480),
        style: RenderStyle | None = None,
        character: Character | None = None,
    ):
        motions = list(motions)
        self.style = style or RenderStyle()
        check_scene(motions, labels, resolution)
        check_character(character, self.style)
        self.motions = motions
        self.fps = float(motions[0].fps)
        self.n_frames = max(m.n_frames for m in motions)
        self.resolution = (int(resolution[0]), int(resolution[1]))
        s = self.style
        theme = pv.themes.Theme()  # a fresh theme: the user's global theme must not change the look
        staged = s.look == "character"
        theme.background = BACKGROUND if staged else s.appearance.background
        theme.multi_samples = int(s.multi_samples)
        theme.anti_aliasing = "msaa" if s.multi_samples > 0 else None
        with _opengl_window_choice():
            self._plotter: pv.Plotter | None = pv.Plotter(
                off_screen=True,
                shape=(1, 1) if staged else (1, len(motions)),
                border=False,
                window_size=list(self.resolution),
                theme=theme,
                lighting="none",  # the appearance's one light, added with the meshes
            )
        self._character: CharacterDrawing | None = None
        self._bodies: list[BodyMeshes] = []
        self._points: list[np.ndarray] = []
        try:
            if staged:
                stage = CharacterStage(
                    motions,
                    neutral=s.neutral,
                    view_box=None if s.fit_motion else np.asarray(s.view_box),
                    character=character,
                    framing=s.framing,
                )
                self._character = CharacterDrawing(
                    stage, self._live(), self.resolution, labels=labels, font_size=s.font_size
                )
            else:
                self._build(labels)
        except BaseException:
            self.close()
            raise
        self._frame = 0  # the meshes hold the first frame's pose
        self._pixels = vtkUnsignedCharArray()

    def _build(self, labels: Sequence[str] | None) -> None:
        """Add every body's meshes, the floor, the shadows, the labels, the light and the camera."""
        pl, s, motions = self._live(), self.style, self.motions
        a = s.appearance
        shapes = [a.body(m.positions, m.presence) for m in motions]
        self._points = [b.points for b in shapes]  # (frames, 61, 3) each
        box = view_bounds(motions, style=s)
        # only the points that exist are framed (a neck-relative upper body fills the view too)
        drawn = [b.drawn_points() for b in shapes]
        every = np.concatenate([p.reshape(-1, 3) for p in drawn])
        aspect = (self.resolution[0] / len(motions)) / self.resolution[1]
        if s.fit_motion:
            # the framing rule on what is drawn: every surface over the clip, and the floor under it
            ground = a.ground_height(every)
            under = _shadow_centre(*shapes) * [1, 0, 1] + [0, ground, 0]  # where the shadow lies
            reach = np.concatenate(
                [np.tile(_reach(a, m.presence)[b.drawn], len(b.points)) for m, b in zip(motions, shapes)]
            )
            position, focal, up, clip = _camera(
                np.vstack([every, under]), aspect, s, pad=np.append(reach, 0.0), margin=a.frame_margin
            )
        else:
            ground = float(box[1, 0])
            corners = np.array([[x, y, z] for x in box[0] for y in box[1] for z in box[2]])
            position, focal, up, clip = _camera(corners, aspect, s)
        # the appearance's rule, colour * (ambient + diffuse * max(0, n . l)), light fixed to the camera
        light = a.light()
        for i in range(len(motions)):
            pl.subplot(0, i)
            self._floor_and_shadow(box, ground, shapes[i])
            body = BodyMeshes(s, motions[i].presence)
            body.update(self._points[i][0])
            for part, mesh in body.parts.items():
                actor = pl.add_mesh(
                    mesh, color=a.part_color(i, part), ambient=a.ambient, diffuse=a.diffuse, specular=0.0
                )
                actor.prop.interpolation = "gouraud"  # our own normals, smoothly interpolated
            if labels is not None:
                pl.add_text(str(labels[i]), position="upper_edge", font_size=s.font_size, color=a.color(i))
            pl.renderer.add_light(
                pv.Light(position=tuple(light), focal_point=(0.0, 0.0, 0.0), light_type="camera light", intensity=1.0)
            )
            camera = pl.renderer.GetActiveCamera()
            camera.SetPosition(*position)
            camera.SetFocalPoint(*focal)
            camera.SetViewUp(*up)
            camera.SetViewAngle(s.view_angle)
            camera.SetClippingRange(*clip)
            pl.renderer.camera_set = True
            self._bodies.append(body)

    def _floor_and_shadow(self, box: np.ndarray, ground: float, body: BodyShapes) -> None:
        """The floor, unlit, from behind the framed region to under the camera, and a soft
        contact shadow on it under the body (where its pelvis stands on average; none for a
        body without a pelvis, which stands on nothing)."""
        pl, a = self._live(), self.style.appearance
        width = box[0, 1] - box[0, 0]
        floor = pv.Plane(
            center=(box[0].mean(), ground, box[2, 1]),
            direction=(0, 1, 0),
            i_size=width * 6,
            j_size=2 * (box[2, 1] - box[2, 0]) + 20.0,
        )
        pl.add_mesh(floor, color=a.ground_color, lighting=False)
        if not body.drawn[_PELVIS]:
            return
        pelvis = _shadow_centre(body)
        half = 2.2 * a.hip_half_width + a.hip_radius  # the shadow's half width, metres, across X
        # three stacked discs, each darker and smaller: a shadow that fades at its rim; opaque, the
        # colour of the floor seen through the shadow, since translucency costs a render pass
        ground_rgb, shadow_rgb = hex_to_rgb(a.ground_color), hex_to_rgb(a.shadow_color)
        for k, scale in enumerate((1.0, 0.75, 0.5)):
            alpha = a.shadow_alpha * (k + 1) / 3
            disc = pv.Disc(center=(0.0, 0.0, 0.0), inner=0.0, outer=half * scale, normal=(0, 1, 0), c_res=48)
            disc.points[:, 2] *= 0.5  # flat ellipse: shallower than wide
            disc.points[:] += (pelvis[0], ground + 1e-3 * (k + 1), pelvis[2])
            pl.add_mesh(disc, color=tuple(ground_rgb * (1 - alpha) + shadow_rgb * alpha), lighting=False)

    @property
    def backend(self) -> str:
        """Class name of VTK's render window, e.g. ``"vtkEGLRenderWindow"`` when headless."""
        return type(self._live().render_window).__name__

    # -- per frame ---------------------------------------------------------------------------
    def set_frame(self, frame: int) -> None:
        """Pose every skeleton at ``frame`` (a motion past its end holds its last pose)."""
        if not 0 <= frame < self.n_frames:
            raise ConfigError(f"frame {frame} is outside the clip's {self.n_frames} frames")
        frame = int(frame)
        if frame == self._frame:
            return
        if self._character is not None:
            self._character.update(frame)
        for body, points in zip(self._bodies, self._points):
            body.update(points[min(frame, len(points) - 1)])
        self._frame = frame

    def render_frame(self, frame: int) -> np.ndarray:
        """The picture of one frame, shape (height, width, 3), uint8 RGB, top row first."""
        self.set_frame(frame)
        window = self._live().render_window
        if window is None:
            raise GestureKitError("the scene's render window is gone")
        window.Render()
        w, h = self.resolution
        window.GetPixelData(0, 0, w - 1, h - 1, 0, self._pixels, 0)
        image = vtk_to_numpy(self._pixels)
        if image.size != w * h * 3:
            raise GestureKitError(f"the render window gave {image.size} values instead of {w}x{h}x3")
        # OpenGL's first row is the bottom one
        return np.ascontiguousarray(image.reshape(h, w, 3)[::-1])

    def stage_image(self) -> np.ndarray:
        """The picture of the stage alone (the character look: the backdrop, the floor and the shadows,
        without the characters), shape (height, width, 3), uint8 RGB: what every pixel a character does not
        cover shows. The characters are shown again afterwards."""
        if self._character is None:
            raise ConfigError("only the character look has a stage of its own")
        self._character.set_characters_visible(False)
        try:
            window = self._live().render_window
            if window is None:
                raise GestureKitError("the scene's render window is gone")
            window.Render()
            w, h = self.resolution
            window.GetPixelData(0, 0, w - 1, h - 1, 0, self._pixels, 0)
            image = vtk_to_numpy(self._pixels).reshape(h, w, 3)[::-1]
            return np.ascontiguousarray(image)
        finally:
            self._character.set_characters_visible(True)

    def frames(self, progress: Callable[[int, int], None] | None = None) -> Iterator[np.ndarray]:
        """Every frame's picture in order; ``progress(done, total)`` after each one."""
        for frame in range(self.n_frames):
            image = self.render_frame(frame)
            if progress is not None:
                progress(frame + 1, self.n_frames)
            yield image

    def project(self, points: np.ndarray, *, panel: int = 0) -> np.ndarray:
        """Pixel coordinates of 3D points in a panel's picture.

        Parameters
        ----------
        points : np.ndarray, shape (n, 3)
            Pelvis-relative positions, metres.
        panel : int
            Which motion's panel (0 left, 1 right).

        Returns
        -------
        np.ndarray, shape (n, 2), float
            Column (from the left) and row (from the top) in the whole
            picture, pixels.
        """
        renderer = self._live().renderers[panel]
        x0, y0, x1, y1 = renderer.GetViewport()
        w, h = self.resolution
        pw, ph = (x1 - x0) * w, (y1 - y0) * h
        m = renderer.GetActiveCamera().GetCompositeProjectionTransformMatrix(pw / ph, -1, 1)
        matrix = np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        clip = np.hstack([p, np.ones((len(p), 1))]) @ matrix.T
        ndc = clip[:, :2] / clip[:, 3:4]
        col = x0 * w + (ndc[:, 0] + 1) / 2 * pw
        row = h - (y0 * h + (ndc[:, 1] + 1) / 2 * ph)
        return np.stack([col, row], axis=1)

    # -- lifetime ----------------------------------------------------------------------------
    def _live(self) -> pv.Plotter:
        """The scene's plotter; a closed scene draws nothing more."""
        if self._plotter is None:
            raise GestureKitError("the scene is closed")
        return self._plotter

    def close(self) -> None:
        """Release the render window and its OpenGL context."""
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None

    def __enter__(self) -> SkeletonScene:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@checks_arguments
def check_scene(motions: list[Motion], labels: Sequence[str] | None, resolution: tuple[int, int]) -> None:
    """Refuse a scene :class:`SkeletonScene` cannot draw (one or two motions, labels, resolution): ConfigError."""
    if not 1 <= len(motions) <= 2:
        raise ConfigError(f"a scene shows one or two motions, got {len(motions)}")
    for m in motions:
        if not isinstance(m, Motion):
            raise ConfigError(f"expected a gesturekit Motion, got {type(m).__name__}")
        if m.n_frames == 0:
            raise ConfigError("cannot render a motion with no frames")
        if not m.presence.drawn.any():
            raise ConfigError("cannot render a motion whose joints are all absent: nothing to draw")
        if not np.all(np.isfinite(m.positions)):
            raise ConfigError("cannot render a motion with NaN or infinite positions")
    if len(motions) == 2 and motions[0].fps != motions[1].fps:
        raise ConfigError(
            f"motions shown side by side must have the same fps, got {motions[0].fps} and {motions[1].fps}"
        )
    if labels is not None and (isinstance(labels, str) or len(labels) != len(motions)):
        raise ConfigError(f"give one label per motion ({len(motions)}), got {labels!r}")
    try:
        w, h = (int(v) for v in resolution)
        ok = len(resolution) == 2 and w == resolution[0] and h == resolution[1]
    except (TypeError, ValueError):
        ok = False
    if not ok or not (16 <= w <= 7680 and 16 <= h <= 4320):
        raise ConfigError(
            f"resolution must be (width, height) in whole pixels, 16..7680 x 16..4320, got {resolution!r}"
        )


@checks_arguments
def check_character(character: object, style: RenderStyle) -> None:
    """Refuse a ``character=`` that is not a :class:`~gesturekit.character.target.Character` for this style."""
    if character is None:
        return
    if not isinstance(character, Character):
        raise ConfigError(f"character must be a Character (read_character), got {type(character).__name__}")
    if style.look != "character":
        raise ConfigError(f"a user's character is drawn in the character look, not {style.look!r}")


@checks_arguments
def render_image(
    motion: Motion,
    *,
    frame: int = 0,
    side_by_side: Motion | None = None,
    labels: Sequence[str] | None = None,
    resolution: tuple[int, int] = (640, 480),
    style: RenderStyle | None = None,
    character: Character | None = None,
) -> np.ndarray:
    """One frame as a picture, framed as in a whole-clip render of the same motion(s).

    Parameters
    ----------
    motion : Motion
        The motion to show.
    frame : int
        Which frame.
    side_by_side : Motion, optional
        A second motion shown to the right.
    labels : sequence of str, optional
        One label per motion shown.
    resolution : (int, int)
        Width and height, pixels.
    style : RenderStyle, optional
        Look of the scene.
    character : Character, optional
        A user's character the motions are retargeted onto (see :class:`SkeletonScene`).

    Returns
    -------
    np.ndarray, shape (height, width, 3), uint8
        RGB picture, top row first.
    """
    motions = [motion] if side_by_side is None else [motion, side_by_side]
    with SkeletonScene(motions, labels=labels, resolution=resolution, style=style, character=character) as scene:
        return scene.render_frame(frame)
