"""How the character looks, wherever it is drawn: colours, light and camera shared by the page and the MP4.

The page (three.js) and the MP4 (VTK) draw the same mesh with the same
Lambert shading: ``colour = albedo * (AMBIENT + KEY * max(0, n . l))``, with
``l`` the direction towards :data:`LIGHT_DIRECTION`, computed in linear light
and shown in sRGB; the same perspective camera (:func:`camera_for`, vertical
field of view :data:`FIELD_OF_VIEW`) and the same background.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError
from .mesh import PARTS

__all__ = [
    "SCHEMES",
    "SIDE_BY_SIDE",
    "NEUTRAL",
    "BACKGROUND",
    "LIGHT_DIRECTION",
    "AMBIENT",
    "KEY",
    "FIELD_OF_VIEW",
    "VIEW_DIRECTION",
    "scheme_for",
    "srgb_to_linear",
    "linear_to_srgb",
    "shade",
    "part_colors",
    "camera_for",
    "BODY_MARGIN",
    "FRAME_MARGIN",
    "stage_layout",
]

#: Colour schemes: each part of :data:`gesturekit.character.mesh.PARTS` as sRGB hex.
SCHEMES: dict[str, dict[str, str]] = {
    "blue": {"skin": "#d9b59b", "shirt": "#3c6db0", "face": "#3b2b22"},
    "orange": {"skin": "#d9b59b", "shirt": "#d0782a", "face": "#3b2b22"},
    "green": {"skin": "#d9b59b", "shirt": "#3f8f5a", "face": "#3b2b22"},
    "purple": {"skin": "#d9b59b", "shirt": "#7a55a8", "face": "#3b2b22"},
    # for studies: no colour tells the systems apart, and no skin tone is chosen
    "grey": {"skin": "#b4b4b4", "shirt": "#8c8c8c", "face": "#4a4a4a"},
}

#: Schemes of side-by-side motions, in order (the k-th motion takes the k-th, cycling).
SIDE_BY_SIDE = ("blue", "orange", "green", "purple")

#: The scheme of study stimuli.
NEUTRAL = "grey"

#: Background, sRGB hex.
BACKGROUND = "#f3f3f1"

#: Towards the key light from the character, in the world (Y up, the character faces +Z): above, front, left.
LIGHT_DIRECTION = (0.35, 0.75, 0.56)

#: Ambient and key light strengths (linear light; their sum is the brightest a surface gets).
AMBIENT, KEY = 0.42, 0.70

#: The camera's vertical field of view, degrees.
FIELD_OF_VIEW = 30.0

#: From the framed box's centre towards the camera: in front, a little above.
VIEW_DIRECTION = (0.0, 0.12, 1.0)


def scheme_for(index: int, *, neutral: bool = False) -> str:
    """The scheme of the ``index``-th of side-by-side motions (:data:`NEUTRAL` for all when ``neutral``)."""
    return NEUTRAL if neutral else SIDE_BY_SIDE[int(index) % len(SIDE_BY_SIDE)]


def part_colors(scheme: str) -> np.ndarray:
    """Shape (len(PARTS), 3), float: each part's sRGB colour in [0, 1], in the order of :data:`PARTS`.

    Raises
    ------
    ConfigError
        An unknown scheme.
    """
    if scheme not in SCHEMES:
        raise ConfigError(f"unknown colour scheme {scheme!r}; choose one of {', '.join(SCHEMES)}")
    return np.array([[int(SCHEMES[scheme][p][i : i + 2], 16) / 255 for i in (1, 3, 5)] for p in PARTS])


def camera_for(lo: npt.ArrayLike, hi: npt.ArrayLike, aspect: float, *, fov: float = FIELD_OF_VIEW) -> dict:
    """A perspective camera that shows the box ``lo``..``hi`` whole, from :data:`VIEW_DIRECTION`.

    Parameters
    ----------
    lo, hi : array_like, shape (3,)
        Corners of the box to frame, metres.
    aspect : float
        Width over height of the picture.
    fov : float
        Vertical field of view, degrees.

    Returns
    -------
    dict
        ``position``, ``target`` (the box's centre) and ``up`` (3 floats each, metres), ``fov`` (degrees).
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if not (aspect > 0 and np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ConfigError(f"a camera needs a finite box and a positive aspect ratio, got {lo}, {hi}, {aspect}")
    centre = (lo + hi) / 2
    half = np.maximum((hi - lo) / 2, 1e-3)
    d = np.asarray(VIEW_DIRECTION) / np.linalg.norm(VIEW_DIRECTION)
    tan_v = np.tan(np.radians(fov) / 2)
    # far enough that the box's front face fits both ways (the box's depth moves its front closer)
    dist = max(half[1] / tan_v, half[0] / (tan_v * aspect)) + half[2]
    return {
        "position": [float(x) for x in centre + dist * d],
        "target": [float(x) for x in centre],
        "up": [0.0, 1.0, 0.0],
        "fov": float(fov),
    }


#: Metres between the joints and the body's surface, at most: the chest's half-depth, the torso's reach below
#: spine_mid (the waist cut). Side-by-side characters keep this much to either side of their joints.
BODY_MARGIN = 0.14

#: Metres the framed box keeps around every joint: the arms' and the head's thickness; the box then reaches
#: down to the waist cut (:data:`BODY_MARGIN` below the lowest joint of the spine is more than the cut needs).
FRAME_MARGIN = 0.07


def stage_layout(points: Sequence[np.ndarray], *, spacing: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Where side-by-side characters stand and the box the camera frames, the same for the page and the MP4.

    Parameters
    ----------
    points : sequence of np.ndarray, each shape (frames, joints, 3)
        Each character's joint positions over the shown frames, metres (only drawn joints).
    spacing : float, optional
        Metres between neighbouring characters along X; default the widest character plus
        :data:`BODY_MARGIN` on each side and 0.1 m between them, at least 0.8 m.

    Returns
    -------
    offsets : np.ndarray, shape (characters,)
        Each character's shift along X, metres, centred on 0.
    box : np.ndarray, shape (2, 3)
        The framed box's lower and upper corners, metres: every shifted joint over every frame plus
        :data:`FRAME_MARGIN`, and 3 % of the box on each side: the half body, framed like a presenter.
    """
    if not points or any(np.asarray(p).size == 0 for p in points):
        raise ConfigError("a stage needs at least one character with at least one joint position")
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in points]
    if spacing is None:
        widest = max(float(np.ptp(p[:, 0])) for p in pts) + 2 * BODY_MARGIN
        spacing = max(0.8, widest + 0.1)
    offsets = (np.arange(len(pts)) - (len(pts) - 1) / 2) * float(spacing)
    every = np.concatenate([p + [dx, 0.0, 0.0] for p, dx in zip(pts, offsets)])
    lo, hi = every.min(axis=0) - FRAME_MARGIN, every.max(axis=0) + FRAME_MARGIN
    pad = 0.03 * (hi - lo)
    return offsets, np.stack([lo - pad, hi + pad])


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] to linear light, same shape (the sRGB transfer function's inverse)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] (clipped) to sRGB values in [0, 1], same shape."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def shade(normals: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """The shared Lambert shading of each vertex, in 8-bit sRGB.

    Parameters
    ----------
    normals : np.ndarray, shape (V, 3)
        Unit vertex normals in the world (zero for a vertex without area around it).
    albedo : np.ndarray, shape (V, 3)
        Each vertex's colour in linear light, in [0, 1].

    Returns
    -------
    np.ndarray, shape (V, 3), uint8
        ``albedo * (AMBIENT + KEY * max(0, n . l))`` with ``l`` the unit
        :data:`LIGHT_DIRECTION`, clipped to 1 and
        converted to sRGB, rounded to the nearest of 0..255.
    """
    light = np.asarray(LIGHT_DIRECTION, dtype=np.float64)
    light = light / np.linalg.norm(light)
    lit = AMBIENT + KEY * np.maximum(0.0, np.asarray(normals, dtype=np.float64) @ light)
    return np.rint(255 * linear_to_srgb(np.asarray(albedo) * lit[:, None])).astype(np.uint8)
