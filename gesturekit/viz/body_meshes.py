"""The body's surfaces as PyVista meshes, built once per scene and moved every frame.

Every capsule of the appearance (:mod:`gesturekit.viz.appearance`) is an open
tube between its two points plus a ball of its radius at each end; the
appearance's spheres (the head) are balls. Each frame only rewrites the
meshes' points and normals in numpy. The capsule look of :class:`gesturekit.viz.render.SkeletonScene` draws them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pyvista as pv

if TYPE_CHECKING:
    from ..skeleton import JointPresence
    from .appearance import RenderStyle

__all__ = ["BodyMeshes"]


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


def _mesh_with_normals(n_points: int, polygons: list[np.ndarray]) -> pv.PolyData:
    """A mesh of ``n_points`` points (all at the origin) with a normal per point, from groups
    of polygons, each group of equal size, shape (k, n)."""
    faces = np.concatenate([_faces(p) for p in polygons])
    mesh = pv.PolyData(np.zeros((n_points, 3)), faces=faces)
    mesh.point_data["Normals"] = np.zeros((n_points, 3))
    mesh.point_data.active_normals_name = "Normals"
    return mesh


# balls smaller than this (metres; the fingers' and palms') get half the sphere resolution
_SMALL_BALL = 0.02


class BodyMeshes:
    """The surfaces of one motion's body, one mesh per body part, whose points are rewritten every frame.

    Every capsule of the appearance is an open tube between its two points
    plus a ball of its radius at each end (balls shared by capsules of one
    part that meet with the same radius); the appearance's spheres (the head)
    are balls. Normals are exact (radial), so shading is smooth at any
    tessellation.

    Attributes
    ----------
    parts : dict of str to pyvista.PolyData
        One mesh per body part (``"torso"``, ``"head"``, ``"finger"``, ..., and ``"derived"``
        for the shapes of derived joints), of the joints ``presence`` says exist (default all).
    """

    def __init__(self, style: RenderStyle, presence: JointPresence | None = None):
        a = style.appearance
        # absent joints get no surface; derived ones are their own part, in the derived colour
        capsules, spheres = a.shapes(presence)
        sides = style.capsule_sides
        angles = 2 * np.pi * np.arange(sides) / sides
        self._cos, self._sin = np.cos(angles), np.sin(angles)
        k = np.arange(sides)
        ring = np.stack([k, (k + 1) % sides, (k + 1) % sides + sides, k + sides], axis=1)
        self._ball, ball_tris = _unit_sphere(style.sphere_resolution)
        self._head, head_tris = _unit_sphere(style.head_resolution)
        self._small, small_tris = _unit_sphere(max(4, style.sphere_resolution // 2))

        self.parts: dict[str, pv.PolyData] = {}
        self._layout = []  # per part: (mesh, tube ends a, b, tube radii, ball centres, radii, template)
        names = sorted({c.part for c in capsules} | {s.part for s in spheres})
        for part in names:
            caps = [c for c in capsules if c.part == part]
            ends = sorted({(c.a, c.radius) for c in caps} | {(c.b, c.radius) for c in caps})
            # a finger's balls cover a few pixels: a coarse sphere is enough, and much cheaper
            balls = [
                (p, r, self._ball, ball_tris) if r >= _SMALL_BALL else (p, r, self._small, small_tris) for p, r in ends
            ]
            balls.sort(key=lambda ball: ball[2] is self._small)  # each template's balls in one run of points
            balls += [(s.centre, s.radius, self._head, head_tris) for s in spheres if s.part == part]
            polygons, n = [], 0
            for _ in caps:
                polygons.append(ring + n)
                n += 2 * sides
            ball_index = []
            for _, _, template, tris in balls:
                polygons.append(tris + n)
                ball_index.append(n)
                n += len(template)
            mesh = _mesh_with_normals(n, polygons)
            normals = mesh.point_data["Normals"]
            for (_, _, template, _), start in zip(balls, ball_index):
                # a ball's normals never change; pyvista's stubs type a slice index too narrowly
                normals[start : start + len(template)] = template  # type: ignore[index]
            # balls of one template are moved together: (centres, radii, template, first point)
            groups = []
            for template in (self._ball, self._small, self._head):
                mine = [(p, r, start) for (p, r, t, _), start in zip(balls, ball_index) if t is template]
                if mine:
                    groups.append(
                        (np.array([m[0] for m in mine]), np.array([m[1] for m in mine]), template, mine[0][2])
                    )
            self._layout.append(
                (
                    mesh,
                    np.array([c.a for c in caps], dtype=np.int64),
                    np.array([c.b for c in caps], dtype=np.int64),
                    np.array([c.radius for c in caps]),
                    groups,
                )
            )
            self.parts[part] = mesh

    def update(self, points: np.ndarray) -> None:
        """Move the meshes to one frame's body points, shape (61, 3) (:meth:`Appearance.body`), metres."""
        points = np.asarray(points, dtype=np.float64)
        for mesh, ia, ib, radii, groups in self._layout:
            # plain views of VTK's arrays: numpy writes straight into them
            xyz = np.asarray(mesh.points).view(np.ndarray)
            normals = np.asarray(mesh.point_data["Normals"]).view(np.ndarray)
            nt = len(ia) * 2 * len(self._cos)
            if len(ia):
                start, end = points[ia], points[ib]
                d = end - start
                length = np.linalg.norm(d, axis=1, keepdims=True)
                axis = np.where(length > 1e-9, d / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])
                # a vector far from parallel to the axis spans the ring's plane with it
                helper = np.where(np.abs(axis[:, 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
                u = np.cross(axis, helper)
                u /= np.linalg.norm(u, axis=1, keepdims=True)
                v = np.cross(axis, u)
                radial = self._cos[None, :, None] * u[:, None, :] + self._sin[None, :, None] * v[:, None, :]
                offset = radii[:, None, None] * radial
                rings = np.concatenate([start[:, None] + offset, end[:, None] + offset], axis=1)
                xyz[:nt] = rings.reshape(-1, 3)
                normals[:nt] = np.concatenate([radial, radial], axis=1).reshape(-1, 3)
            for centres, r, template, at in groups:
                balls = points[centres][:, None, :] + r[:, None, None] * template[None]
                xyz[at : at + balls.shape[0] * balls.shape[1]] = balls.reshape(-1, 3)
            mesh.GetPoints().Modified()
            mesh.GetPointData().GetNormals().Modified()
            mesh.Modified()
