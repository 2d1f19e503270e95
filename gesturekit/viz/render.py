"""Offscreen 3D renders of the 55-joint skeleton with PyVista.

A :class:`SkeletonScene` draws one motion, or two side by side (for example the
k-NN result next to the refined one), as bones (tubes) and joints (spheres),
every finger joint included, on a plain background, seen from the front: the
camera stands on the character's +Z side, looks along -Z and frames a fixed
box around the upper body, enlarged only where a motion leaves it, so that the
hands are always in the picture and the clips of every system look alike in a
user study. The meshes are built once; each frame only rewrites their points
(a few thousand, in numpy), so a long clip costs little more than the
rasterisation itself.

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
import dataclasses
import json
import math
import os
import queue
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np
import pyvista as pv
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkUnsignedCharArray

from ..errors import ConfigError, GestureKitError
from ..motion import Motion
from ..skeleton import N_JOINTS, bones, hand_indices, joint_index

__all__ = ["RenderStyle", "SkeletonScene", "default_workers", "render_frames", "render_image", "view_bounds"]

_WINDOW_ENV = "VTK_DEFAULT_OPENGL_WINDOW"


@dataclass(frozen=True)
class RenderStyle:
    """How a skeleton looks; the defaults are the project's one house style.

    Lengths are in metres; colours are anything PyVista accepts (names,
    ``"#rrggbb"``, RGB triples in 0..1).

    Parameters
    ----------
    background : colour
        Plain background of every panel.
    bone_color, joint_color, head_color : colour
        Colours of the tubes, the joint spheres and the head ball.
    text_color : colour
        Colour of the panel labels.
    body_bone_radius, finger_bone_radius : float
        Tube radius of the body bones (pelvis to wrist) and of the finger bones.
    body_joint_radius, wrist_joint_radius, finger_joint_radius : float
        Sphere radius of the body joints, the wrists and the finger joints.
    head_radius : float
        Radius of a ball centred between ``head`` and ``head_top`` that shows
        where the face is; 0 leaves it out.
    show_pelvis : bool
        Draw the pelvis (the origin of the pelvis-relative positions) and the
        bone from it to ``spine_mid``.
    view_box : ((xmin, xmax), (ymin, ymax), (zmin, zmax))
        Pelvis-relative region the camera always shows, metres: a standing
        speaker's head and reach. A motion that leaves it enlarges the view
        when ``fit_motion`` is set.
    fit_motion : bool
        Enlarge the view to every joint of every frame, so no hand is ever cut.
    view_angle : float
        Vertical field of view of the perspective camera, degrees, in (0, 120).
    margin : float
        Empty border around the framed region, as a fraction of its size.
    tube_sides, sphere_resolution, head_resolution : int
        Tessellation of the tubes, the joint spheres and the head ball.
    multi_samples : int
        Multisample anti-aliasing samples per pixel, 0 for none. Smoother
        edges, but in software rendering (no GPU) 4 samples make each frame
        about five times slower.
    font_size : int
        Size of the panel labels, points.
    """

    background: object = "#eeeeea"
    bone_color: object = "#5b7fa6"
    joint_color: object = "#2c4663"
    head_color: object = "#c9ced6"
    text_color: object = "#202020"
    body_bone_radius: float = 0.014
    finger_bone_radius: float = 0.0045
    body_joint_radius: float = 0.02
    wrist_joint_radius: float = 0.012
    finger_joint_radius: float = 0.006
    head_radius: float = 0.07
    show_pelvis: bool = True
    view_box: tuple = ((-0.6, 0.6), (-0.25, 0.8), (-0.2, 0.45))
    fit_motion: bool = True
    view_angle: float = 20.0
    margin: float = 0.04
    tube_sides: int = 10
    sphere_resolution: int = 10
    head_resolution: int = 24
    multi_samples: int = 0
    font_size: int = 14

    def __post_init__(self):
        box = np.asarray(self.view_box, dtype=np.float64)
        if box.shape != (3, 2) or not np.all(np.isfinite(box)) or np.any(box[:, 1] <= box[:, 0]):
            raise ConfigError(
                "view_box must be ((xmin, xmax), (ymin, ymax), (zmin, zmax)) with min < max, "
                f"got {self.view_box}"
            )
        if not 0 < self.view_angle < 120:
            raise ConfigError(f"view_angle must be in (0, 120) degrees, got {self.view_angle}")
        if self.tube_sides < 3 or min(self.sphere_resolution, self.head_resolution) < 4:
            raise ConfigError(
                "tube_sides must be at least 3, sphere_resolution and head_resolution at least 4"
            )
        if self.multi_samples < 0 or self.margin < 0:
            raise ConfigError("multi_samples and margin must not be negative")


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


def _faces(polygons: np.ndarray) -> np.ndarray:
    """VTK's flat face array from polygons of equal size, shape (k, n)."""
    n = polygons.shape[1]
    sizes = np.full((len(polygons), 1), n, dtype=np.int64)
    return np.hstack([sizes, polygons.astype(np.int64)]).ravel()


def _unit_sphere(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Points on the unit sphere, shape (m, 3) (also their normals), and its triangles (k, 3)."""
    sphere = pv.Sphere(radius=1.0, theta_resolution=resolution, phi_resolution=resolution)
    points = np.asarray(sphere.points, dtype=np.float64)
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    return points, np.asarray(sphere.faces).reshape(-1, 4)[:, 1:]


def _mesh_with_normals(n_points: int, polygons: np.ndarray) -> pv.PolyData:
    mesh = pv.PolyData(np.zeros((n_points, 3)), faces=_faces(polygons))
    mesh.point_data["Normals"] = np.zeros((n_points, 3))
    mesh.point_data.active_normals_name = "Normals"
    return mesh


def _write(mesh: pv.PolyData, points: np.ndarray, normals: np.ndarray | None = None) -> None:
    """Overwrite a mesh's points (and normals) in place and tell VTK they changed."""
    mesh.points[:] = points
    mesh.GetPoints().Modified()
    if normals is not None:
        mesh.point_data["Normals"][:] = normals
        mesh.GetPointData().GetNormals().Modified()
    mesh.Modified()


class _SkeletonMeshes:
    """Tube-and-sphere meshes of one skeleton whose points are rewritten every frame.

    Three meshes: ``bones`` (one open tube per bone), ``joints`` (one sphere
    per joint, plus the pelvis) and ``head`` (a ball, or None).
    """

    def __init__(self, style: RenderStyle):
        pelvis = N_JOINTS  # extra joint at the origin of the pelvis-relative positions
        pairs = [tuple(b) for b in bones()]  # (child, parent)
        if style.show_pelvis:
            pairs.append((joint_index("spine_mid"), pelvis))
        self._pairs = np.array(pairs, dtype=np.int64)
        self._joints = np.arange(N_JOINTS + 1 if style.show_pelvis else N_JOINTS)

        fingers = np.concatenate([hand_indices(side)[1:] for side in ("left", "right")])
        wrists = [joint_index("left_wrist"), joint_index("right_wrist")]
        radius = np.full(N_JOINTS + 1, style.body_joint_radius)
        radius[fingers] = style.finger_joint_radius
        radius[wrists] = style.wrist_joint_radius
        self._joint_r = radius[self._joints]
        self._bone_r = np.where(
            np.isin(self._pairs[:, 0], fingers), style.finger_bone_radius, style.body_bone_radius
        )
        self._head_r = float(style.head_radius)
        self._head_ends = (joint_index("head"), joint_index("head_top"))

        # spheres: one unit template, moved and scaled per joint; its normals never change
        self._sphere, tris = _unit_sphere(style.sphere_resolution)
        m, nj = len(self._sphere), len(self._joints)
        self.joints = _mesh_with_normals(nj * m, np.concatenate([tris + j * m for j in range(nj)]))
        self.joints.point_data["Normals"][:] = np.tile(self._sphere, (nj, 1))
        self.head = None
        if self._head_r > 0:
            self._head_sphere, head_tris = _unit_sphere(style.head_resolution)
            self.head = _mesh_with_normals(len(self._head_sphere), head_tris)
            self.head.point_data["Normals"][:] = self._head_sphere

        # tubes: two rings of ``sides`` points per bone joined by quads; no caps,
        # the joint spheres close the ends
        sides = style.tube_sides
        angles = 2 * np.pi * np.arange(sides) / sides
        self._cos, self._sin = np.cos(angles), np.sin(angles)
        k = np.arange(sides)
        ring = np.stack([k, (k + 1) % sides, (k + 1) % sides + sides, k + sides], axis=1)
        nb = len(self._pairs)
        self.bones = _mesh_with_normals(
            nb * 2 * sides, np.concatenate([ring + b * 2 * sides for b in range(nb)])
        )

    def update(self, positions: np.ndarray) -> None:
        """Move the meshes to one frame's joint positions, shape (55, 3), metres."""
        pos = np.zeros((N_JOINTS + 1, 3))  # the last row is the pelvis, at the origin
        pos[:N_JOINTS] = positions

        centres = pos[self._joints]
        spheres = centres[:, None, :] + self._joint_r[:, None, None] * self._sphere[None]
        _write(self.joints, spheres.reshape(-1, 3))
        if self.head is not None:
            centre = 0.5 * (pos[self._head_ends[0]] + pos[self._head_ends[1]])
            _write(self.head, centre + self._head_r * self._head_sphere)

        start = pos[self._pairs[:, 1]]
        end = pos[self._pairs[:, 0]]
        d = end - start
        length = np.linalg.norm(d, axis=1, keepdims=True)
        axis = np.where(length > 1e-9, d / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])
        # a vector far from parallel to the axis spans the ring's plane with it
        helper = np.where(np.abs(axis[:, 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
        u = np.cross(axis, helper)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        v = np.cross(axis, u)
        radial = self._cos[None, :, None] * u[:, None, :] + self._sin[None, :, None] * v[:, None, :]
        offset = self._bone_r[:, None, None] * radial
        rings = np.concatenate([start[:, None] + offset, end[:, None] + offset], axis=1)
        _write(self.bones, rings.reshape(-1, 3), np.concatenate([radial, radial], axis=1).reshape(-1, 3))


def view_bounds(motions: Sequence[Motion], *, style: RenderStyle | None = None) -> np.ndarray:
    """The pelvis-relative region a scene frames, shape (3, 2): (min, max) of x, y, z in metres.

    The style's ``view_box``, grown to contain every joint of every frame of
    ``motions`` (plus the joint radius) when ``style.fit_motion`` is set.
    Depends only on the arguments, so all motions rendered with the same style
    that stay inside the box are framed identically.
    """
    style = style or RenderStyle()
    box = np.asarray(style.view_box, dtype=np.float64).copy()
    if style.fit_motion:
        pad = max(style.body_joint_radius, style.head_radius)
        for motion in motions:
            pos = motion.positions.reshape(-1, 3)
            if pos.size == 0:
                continue
            box[:, 0] = np.minimum(box[:, 0], pos.min(axis=0) - pad)
            box[:, 1] = np.maximum(box[:, 1], pos.max(axis=0) + pad)
    return box


def _front_camera(box: np.ndarray, aspect: float, style: RenderStyle):
    """Camera on the +Z side looking along -Z at the box's centre, far enough to see all of it.

    Returns ``(position, focal_point, view_up, (near, far))``.
    """
    centre = box.mean(axis=1)
    half = 0.5 * (box[:, 1] - box[:, 0]) * (1 + style.margin)
    t = math.tan(math.radians(style.view_angle) / 2)
    # the box's near face (z = centre + half z) is the widest in perspective:
    # its half height must fit within t times its distance to the camera
    distance = half[2] + max(half[1] / t, half[0] / (t * aspect))
    position = centre + np.array([0.0, 0.0, distance])
    near = max(1e-3, distance - half[2] - 1.0)
    far = distance + half[2] + 1.0
    return tuple(position), tuple(centre), (0.0, 1.0, 0.0), (near, far)


class SkeletonScene:
    """An offscreen window showing one or two skeletons, updated frame by frame.

    Build it once per clip, call :meth:`render_frame` for every frame, then
    :meth:`close` it (or use it as a context manager). Two motions are shown
    in two panels side by side, each with its label above, framed by the same
    camera.

    Parameters
    ----------
    motions : sequence of Motion
        One or two motions of equal fps. A motion shorter than the longest
        holds its last pose.
    labels : sequence of str, optional
        One label per motion, drawn at the top of its panel.
    resolution : (int, int)
        Width and height of the whole picture, pixels.
    style : RenderStyle, optional
        Look of the scene; :class:`RenderStyle()` by default.

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
    ):
        motions = list(motions)
        self.style = style or RenderStyle()
        _check_scene(motions, labels, resolution)
        self.motions = motions
        self.fps = float(motions[0].fps)
        self.n_frames = max(m.n_frames for m in motions)
        self.resolution = (int(resolution[0]), int(resolution[1]))
        s = self.style
        theme = pv.themes.Theme()  # a fresh theme: the user's global theme must not change the look
        theme.background = s.background
        theme.multi_samples = int(s.multi_samples)
        theme.anti_aliasing = "msaa" if s.multi_samples > 0 else None
        with _opengl_window_choice():
            self._plotter = pv.Plotter(
                off_screen=True,
                shape=(1, len(motions)),
                border=False,
                window_size=list(self.resolution),
                theme=theme,
                lighting="three lights",
            )
        try:
            self._build(labels)
        except BaseException:
            self.close()
            raise
        self._frame = 0  # the meshes hold the first frame's pose
        self._pixels = vtkUnsignedCharArray()

    def _build(self, labels) -> None:
        """Add every skeleton's meshes, the labels and the camera to the window."""
        pl, s, motions = self._plotter, self.style, self.motions
        self._skeletons = []
        aspect = (self.resolution[0] / len(motions)) / self.resolution[1]
        position, focal, up, clip = _front_camera(view_bounds(motions, style=s), aspect, s)
        for i, motion in enumerate(motions):
            pl.subplot(0, i)
            meshes = _SkeletonMeshes(s)
            meshes.update(motion.positions[0])
            surface = dict(smooth_shading=False, specular=0.25, specular_power=20, ambient=0.15)
            for mesh, color in ((meshes.bones, s.bone_color), (meshes.joints, s.joint_color),
                                (meshes.head, s.head_color)):
                if mesh is not None:
                    actor = pl.add_mesh(mesh, color=color, **surface)
                    actor.prop.interpolation = "gouraud"  # our own normals, smoothly interpolated
            if labels is not None:
                pl.add_text(str(labels[i]), position="upper_edge", font_size=s.font_size, color=s.text_color)
            camera = pl.renderer.GetActiveCamera()
            camera.SetPosition(*position)
            camera.SetFocalPoint(*focal)
            camera.SetViewUp(*up)
            camera.SetViewAngle(s.view_angle)
            camera.SetClippingRange(*clip)
            pl.renderer.camera_set = True
            self._skeletons.append(meshes)

    @property
    def backend(self) -> str:
        """Class name of VTK's render window, e.g. ``"vtkEGLRenderWindow"`` when headless."""
        return type(self._plotter.render_window).__name__

    # -- per frame ---------------------------------------------------------------------------
    def set_frame(self, frame: int) -> None:
        """Pose every skeleton at ``frame`` (a motion past its end holds its last pose)."""
        if not 0 <= frame < self.n_frames:
            raise ConfigError(f"frame {frame} is outside the clip's {self.n_frames} frames")
        frame = int(frame)
        if frame == self._frame:
            return
        for meshes, motion in zip(self._skeletons, self.motions):
            meshes.update(motion.positions[min(frame, motion.n_frames - 1)])
        self._frame = frame

    def render_frame(self, frame: int) -> np.ndarray:
        """The picture of one frame, shape (height, width, 3), uint8 RGB, top row first."""
        self.set_frame(frame)
        window = self._plotter.render_window
        window.Render()
        w, h = self.resolution
        window.GetPixelData(0, 0, w - 1, h - 1, 0, self._pixels, 0)
        image = vtk_to_numpy(self._pixels)
        if image.size != w * h * 3:
            raise GestureKitError(f"the render window gave {image.size} values instead of {w}x{h}x3")
        # OpenGL's first row is the bottom one
        return np.ascontiguousarray(image.reshape(h, w, 3)[::-1])

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
        renderer = self._plotter.renderers[panel]
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
    def close(self) -> None:
        """Release the render window and its OpenGL context."""
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None

    def __enter__(self) -> "SkeletonScene":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _check_scene(motions: list, labels, resolution) -> None:
    if not 1 <= len(motions) <= 2:
        raise ConfigError(f"a scene shows one or two motions, got {len(motions)}")
    for m in motions:
        if not isinstance(m, Motion):
            raise ConfigError(f"expected a gesturekit Motion, got {type(m).__name__}")
        if m.n_frames == 0:
            raise ConfigError("cannot render a motion with no frames")
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


def render_image(
    motion: Motion,
    *,
    frame: int = 0,
    side_by_side: Motion | None = None,
    labels: Sequence[str] | None = None,
    resolution: tuple[int, int] = (640, 480),
    style: RenderStyle | None = None,
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

    Returns
    -------
    np.ndarray, shape (height, width, 3), uint8
        RGB picture, top row first.
    """
    motions = [motion] if side_by_side is None else [motion, side_by_side]
    with SkeletonScene(motions, labels=labels, resolution=resolution, style=style) as scene:
        return scene.render_frame(frame)


# -- many frames on every core ----------------------------------------------------------------------

#: Frames one rendering process renders in a row before the next process's turn (2 s at 15 fps).
CHUNK_FRAMES = 30
#: With ``workers=None``, clips shorter than this render in the calling process: starting
#: the rendering processes (about a second) would cost more than it saves.
PARALLEL_MIN_FRAMES = 150
# the most frame bytes waiting in the parent for their turn, all processes together
_BUFFER_BYTES = 256 << 20


def default_workers() -> int:
    """The cores this process may run on: the number of rendering processes used by default."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def render_frames(
    motions: Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    resolution: tuple[int, int] = (640, 480),
    style: RenderStyle | None = None,
    workers: int | None = None,
) -> Iterator[np.ndarray]:
    """Every frame of a scene's clip, in order, rendered on several cores.

    The frames are exactly those of :meth:`SkeletonScene.render_frame` for
    frames ``0 .. n_frames - 1``, whichever number of processes renders them.
    With more than one worker, each is a separate Python process
    (:mod:`gesturekit.viz.render_worker`) with its own offscreen window that
    renders every ``workers``-th chunk of :data:`CHUNK_FRAMES` frames; the
    frames come back through pipes and are handed out in order, at most about
    256 MB of them waiting at any time.

    Parameters
    ----------
    motions : sequence of Motion
        One or two motions of equal fps, as for :class:`SkeletonScene`.
    labels : sequence of str, optional
        One label per motion.
    resolution : (int, int)
        Width and height of the pictures, pixels.
    style : RenderStyle, optional
        Look of the scene.
    workers : int, optional
        Rendering processes; 1 renders in this process. By default one per
        core (:func:`default_workers`), or this process alone for clips
        shorter than :data:`PARALLEL_MIN_FRAMES` frames.

    Returns
    -------
    iterator of np.ndarray
        One picture per frame of the longest motion, each shape
        (height, width, 3), uint8 RGB, top row first. Close the iterator (or
        exhaust it) to stop the rendering processes early.

    Raises
    ------
    ConfigError
        Bad motions, labels, resolution or ``workers`` (raised by this call,
        before anything is rendered).
    GestureKitError
        A rendering process failed (raised while iterating; its message is included).
    """
    motions = list(motions)
    style = style or RenderStyle()
    _check_scene(motions, labels, resolution)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer))
                                or workers < 1):
        raise ConfigError(f"workers must be a positive whole number, got {workers!r}")
    n_frames = max(m.n_frames for m in motions)
    chunks = -(-n_frames // CHUNK_FRAMES)
    if workers is None:
        workers = default_workers() if n_frames >= PARALLEL_MIN_FRAMES else 1
    workers = min(int(workers), chunks)
    resolution = (int(resolution[0]), int(resolution[1]))
    if workers == 1:
        return _serial_frames(motions, labels, resolution, style)
    return _parallel_frames(motions, labels, resolution, style, workers)


def _serial_frames(motions, labels, resolution, style) -> Iterator[np.ndarray]:
    with SkeletonScene(motions, labels=labels, resolution=resolution, style=style) as scene:
        for frame in range(scene.n_frames):
            yield scene.render_frame(frame)


def _to_tuples(value):
    """JSON lists back to tuples, recursively (the style's fields are tuples)."""
    if isinstance(value, list):
        return tuple(_to_tuples(v) for v in value)
    return value


def _write_job(path: Path, motions, labels, resolution, style: RenderStyle) -> None:
    spec = {
        "fps": float(motions[0].fps),
        "labels": None if labels is None else [str(x) for x in labels],
        "resolution": list(resolution),
        "style": dataclasses.asdict(style),
    }
    arrays = {f"motion{i}": np.asarray(m.positions) for i, m in enumerate(motions)}
    np.savez(path, spec=np.array(json.dumps(spec)), **arrays)


def _scene_from_job(path: str) -> SkeletonScene:
    """The scene a job file written by :func:`_write_job` describes (in a rendering process)."""
    with np.load(path, allow_pickle=False) as data:
        spec = json.loads(str(data["spec"]))
        positions = [data[f"motion{i}"] for i in range(2) if f"motion{i}" in data.files]
    style = RenderStyle(**{k: _to_tuples(v) for k, v in spec["style"].items()})
    motions = [Motion(p, spec["fps"]) for p in positions]
    return SkeletonScene(motions, labels=spec["labels"], resolution=tuple(spec["resolution"]), style=style)


def _parallel_frames(motions, labels, resolution, style, workers: int) -> Iterator[np.ndarray]:
    width, height = resolution
    size = width * height * 3
    n_frames = max(m.n_frames for m in motions)
    waiting = max(2, min(CHUNK_FRAMES, _BUFFER_BYTES // (size * workers)))
    stop = threading.Event()

    def read(proc: subprocess.Popen, out: queue.Queue) -> None:
        """Move one process's frames into its queue, then None (end or failure)."""
        def put(item) -> bool:
            while not stop.is_set():
                try:
                    out.put(item, timeout=0.1)
                    return True
                except queue.Full:
                    continue
            return False

        try:
            while True:
                data = proc.stdout.read(size)
                if len(data) < size or not put(data):
                    break
        finally:
            put(None)

    # the package this module belongs to, first on the path: the processes render with this same code
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    # one rasteriser thread per process (Mesa's llvmpipe): the processes are the parallelism
    env.setdefault("LP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory(prefix="gesturekit-render-") as tmp:
        job = Path(tmp) / "job.npz"
        _write_job(job, motions, labels, resolution, style)
        procs, queues, threads, logs = [], [], [], []
        try:
            for k in range(workers):
                log = open(Path(tmp) / f"worker{k}.log", "w+b")
                logs.append(log)
                cmd = [sys.executable, "-m", "gesturekit.viz.render_worker", str(job), str(k), str(workers),
                       str(CHUNK_FRAMES)]
                procs.append(subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                              stderr=log, env=env))
                queues.append(queue.Queue(maxsize=waiting))
                threads.append(threading.Thread(target=read, args=(procs[k], queues[k]), daemon=True))
                threads[k].start()
            for frame in range(n_frames):
                k = (frame // CHUNK_FRAMES) % workers
                data = queues[k].get()
                if data is None:
                    code = procs[k].wait()
                    logs[k].seek(0)
                    message = logs[k].read().decode("utf-8", "replace").strip()[-2000:] or "no message"
                    raise GestureKitError(
                        f"a rendering process stopped at frame {frame} of {n_frames} (exit code {code}): {message}"
                    )
                yield np.frombuffer(data, dtype=np.uint8).reshape(height, width, 3)
        finally:
            stop.set()
            for proc in procs:
                if proc.poll() is None:
                    proc.kill()
                proc.wait()
            for thread in threads:
                thread.join()
            for proc in procs:
                proc.stdout.close()
            for log in logs:
                log.close()
