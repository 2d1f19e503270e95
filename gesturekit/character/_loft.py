"""Closed surfaces swept along a chain of joints, and the skin weights that blend them across each joint.

A *loft* is a stack of rings (super-ellipses) along a curve, closed at both ends by a pole vertex:
one closed, consistently oriented surface. Its rings sit at arc positions ``s`` along a polyline
through joints (a *chain*); each bone of the chain is driven by its upper joint, and a ring near
an inner joint blends the two bones' joints with a smoothstep over ``[S_k - h_k, S_k + h_k]``, so
the surface bends there without a crack or a fold.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Piece", "Chain", "smoothstep", "s_grid", "cap_stations", "loft", "ellipsoid", "signed_volume"]


def smoothstep(x: np.ndarray) -> np.ndarray:
    """``3x^2 - 2x^3`` of ``x`` clipped to [0, 1]: 0 below, 1 above, flat at both ends."""
    t = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass
class Piece:
    """One closed surface with its binding, before the pieces are joined into a mesh.

    Attributes
    ----------
    vertices : np.ndarray, shape (n, 3), float64
        Rest positions, metres.
    faces : np.ndarray, shape (m, 3), int64
        Indices into ``vertices``, counter-clockwise seen from outside.
    weights : np.ndarray, shape (n, 55), float64
        Skin weights per joint (at most four non-zero per row), rows summing to 1.
    part : np.ndarray, shape (n,), int64
        Index into the mesh's parts.
    """

    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    part: np.ndarray


class Chain:
    """A polyline through rest-pose points and the joints that drive its bones.

    Parameters
    ----------
    points : np.ndarray, shape (m + 1, 3)
        Stations, metres (joints' rest positions, or a point such as the knuckle line).
    drivers : sequence of int, length m
        The joint that drives each bone (its upper joint).
    blend : sequence of float, length m - 1
        Half-width ``h_k`` of the blend across each inner station, metres.
    reach : float
        A blend reaches at most this share (at most 0.5) of either bone beside it.
    """

    def __init__(self, points: np.ndarray, drivers: list[int], blend: list[float], reach: float = 0.45) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        seg = np.diff(self.points, axis=0)
        self.lengths = np.linalg.norm(seg, axis=-1)
        if len(drivers) != len(seg) or len(blend) != len(seg) - 1 or (self.lengths <= 0).any():
            raise ValueError("a chain needs one driver per bone, one blend per inner station, bones of length > 0")
        self.dirs = seg / self.lengths[:, None]
        self.stations = np.concatenate([[0.0], np.cumsum(self.lengths)])
        self.drivers = list(drivers)
        # two blends never overlap: each reaches at most this share of its neighbouring bones
        lim = reach * np.minimum(self.lengths[:-1], self.lengths[1:])
        self.blend = np.minimum(np.asarray(blend, dtype=np.float64), lim)

    @property
    def length(self) -> float:
        return float(self.stations[-1])

    def _steps(self, s: np.ndarray) -> np.ndarray:
        """Shape (n, m - 1): how far past each inner station (0 before its blend, 1 after)."""
        inner = self.stations[1:-1]
        return smoothstep((s[:, None] - (inner - self.blend)) / (2.0 * self.blend))

    def _bone_weights(self, s: np.ndarray) -> np.ndarray:
        """Shape (n, m): each bone's share at arc positions ``s`` (rows sum to 1)."""
        n = len(s)
        steps = np.concatenate([np.ones((n, 1)), self._steps(s), np.zeros((n, 1))], axis=1)
        return steps[:, :-1] - steps[:, 1:]

    def frame(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (n, 3) and unit tangents (n, 3) at arc positions ``s`` (extrapolated past both ends)."""
        s = np.asarray(s, dtype=np.float64)
        k = np.clip(np.searchsorted(self.stations, s, side="right") - 1, 0, len(self.lengths) - 1)
        points = self.points[k] + (s - self.stations[k])[:, None] * self.dirs[k]
        tangent = self._bone_weights(s) @ self.dirs
        return points, tangent / np.linalg.norm(tangent, axis=-1, keepdims=True)

    def weights(self, s: np.ndarray, n_joints: int) -> np.ndarray:
        """Skin weights (n, n_joints) at arc positions ``s``: bone ``i``'s driver, blended across stations."""
        bw = self._bone_weights(np.asarray(s, dtype=np.float64))
        w = np.zeros((len(bw), n_joints))
        for i, j in enumerate(self.drivers):
            w[:, j] += bw[:, i]
        return w


def s_grid(knots: list[float], step: float) -> np.ndarray:
    """Increasing arc positions through the knots, at most ``step`` apart.

    Knots closer than a quarter step to the previous one are dropped (the last one is kept), so that no
    two rings nearly coincide.
    """
    k = np.unique(np.asarray(knots, dtype=np.float64))
    keep = [float(k[0])]
    for x in k[1:]:
        if x - keep[-1] > 0.25 * step:
            keep.append(float(x))
        elif len(keep) > 1 and x == k[-1]:
            keep[-1] = float(x)
    out = [np.array(keep[:1])]
    for a, b in zip(keep[:-1], keep[1:], strict=True):
        n = max(1, int(np.ceil((b - a) / step - 1e-9)))
        out.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(out)


def cap_stations(n: int, start: bool) -> tuple[np.ndarray, np.ndarray]:
    """A rounded cap's rings: offsets along the axis (units of the cap's length) and radius factors.

    ``n`` rings, quarter-circle profile, ordered along the loft (for the start cap, from the pole's
    side towards the body). The pole itself is at offset -1 (start) or +1 (end).
    """
    phi = np.linspace(0.0, 0.5 * np.pi, n + 2)[1:-1]  # strictly between the body ring and the pole
    off, rad = np.sin(phi), np.cos(phi)
    if start:
        return -off[::-1], rad[::-1]
    return off, rad


def _sgnpow(x: np.ndarray, e: np.ndarray) -> np.ndarray:
    return np.sign(x) * np.abs(x) ** e


def loft(
    centers: np.ndarray,
    tangents: np.ndarray,
    ref: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    n_around: int,
    start_pole: np.ndarray,
    end_pole: np.ndarray,
    power: np.ndarray | float = 2.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A closed surface of rings between two poles.

    Parameters
    ----------
    centers, tangents : np.ndarray, shape (R, 3)
        Each ring's centre (metres) and unit axis.
    ref : np.ndarray, shape (3,) or (R, 3)
        The direction of each ring's ``a`` half-axis (made perpendicular to the tangent); the ``b``
        half-axis is along ``tangent x ref``.
    a, b : np.ndarray, shape (R,)
        Half-axes, metres.
    n_around : int
        Vertices per ring.
    start_pole, end_pole : np.ndarray, shape (3,)
        The closing vertices before the first ring and after the last.
    power : float or np.ndarray, shape (R,)
        Super-ellipse exponent per ring (2: ellipse; larger: boxier).

    Returns
    -------
    vertices : np.ndarray, shape (R * n_around + 2, 3)
        The rings in order, then the two poles.
    faces : np.ndarray, shape (2 * n_around * R, 3), int64
        Counter-clockwise seen from outside (outside: away from the axis).
    """
    t = np.asarray(tangents, dtype=np.float64)
    r = np.broadcast_to(np.asarray(ref, dtype=np.float64), t.shape)
    u = r - np.sum(r * t, axis=-1, keepdims=True) * t
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    w = np.cross(t, u)
    theta = 2.0 * np.pi * np.arange(n_around) / n_around
    e = 2.0 / np.broadcast_to(np.asarray(power, dtype=np.float64), (len(t),))[:, None]
    ca, sa = _sgnpow(np.cos(theta)[None], e), _sgnpow(np.sin(theta)[None], e)
    rings = (
        centers[:, None]
        + (np.asarray(a)[:, None] * ca)[..., None] * u[:, None]
        + (np.asarray(b)[:, None] * sa)[..., None] * w[:, None]
    )
    n_rings = len(t)
    verts = np.concatenate([rings.reshape(-1, 3), [start_pole, end_pole]])
    i = np.arange(n_rings - 1)[:, None] * n_around
    k = np.arange(n_around)[None]
    k1 = (k + 1) % n_around
    q0, q1, q2, q3 = i + k, i + k1, i + n_around + k1, i + n_around + k
    quads = np.concatenate([np.stack([q0, q1, q2], -1).reshape(-1, 3), np.stack([q0, q2, q3], -1).reshape(-1, 3)])
    sp, ep = n_rings * n_around, n_rings * n_around + 1
    last = (n_rings - 1) * n_around
    kk, kk1 = np.arange(n_around), (np.arange(n_around) + 1) % n_around
    start = np.stack([np.full(n_around, sp), kk1, kk], -1)
    end = np.stack([np.full(n_around, ep), last + kk, last + kk1], -1)
    return verts, np.concatenate([quads, start, end]).astype(np.int64)


def ellipsoid(
    center: np.ndarray, axes: np.ndarray, radii: np.ndarray, n_around: int, n_rings: int
) -> tuple[np.ndarray, np.ndarray]:
    """A closed ellipsoid: ``axes`` (3, 3) rows are its unit axes (the first is the loft axis), ``radii`` (3,)."""
    phi = np.linspace(-0.5 * np.pi, 0.5 * np.pi, n_rings + 2)[1:-1]
    c = np.asarray(center, dtype=np.float64)
    ax = np.asarray(axes, dtype=np.float64)
    centers = c + np.sin(phi)[:, None] * radii[0] * ax[0]
    tangents = np.broadcast_to(ax[0], centers.shape)
    # the b half-axis lies along tangent x ref: choose ref so that it is +axes[2]
    ref = ax[1] if np.dot(np.cross(ax[0], ax[1]), ax[2]) > 0 else -ax[1]
    return loft(
        centers,
        tangents,
        ref,
        radii[1] * np.cos(phi),
        radii[2] * np.cos(phi),
        n_around,
        c - radii[0] * ax[0],
        c + radii[0] * ax[0],
    )


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed volume of a closed triangle surface, cubic metres (positive: faces wind outward).

    ``vertices`` (..., V, 3), ``faces`` (F, 3); returns shape (...).
    """
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c = v[..., faces[:, 0], :], v[..., faces[:, 1], :], v[..., faces[:, 2], :]
    return np.einsum("...fi,...fi->...", a, np.cross(b, c)) / 6.0
