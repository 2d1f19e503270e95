"""How the character looks, wherever it is drawn: colours, light, stage and camera shared by the page and the MP4.

The page (three.js) and the MP4 (VTK) draw the same mesh with the same
Lambert shading under three lights, a studio's key, fill and rim
(:data:`LIGHTS`): ``colour = albedo * (AMBIENT + sum_i strength_i * max(0, n . l_i))``,
with ``l_i`` the direction towards light ``i``, computed in linear light and
shown in sRGB; the same perspective camera (:func:`camera_for`, vertical field
of view :data:`FIELD_OF_VIEW`), framed by one rule (:func:`stage_layout`),
and the same stage (:func:`stage_meshes`): a calm backdrop of
:data:`BACKGROUND`, a floor that fades into it towards the back, and a soft
contact shadow under each character, all unlit and coloured per vertex.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from .._arguments import checks_arguments
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
    "LIGHTS",
    "FLOOR_COLOR",
    "SHADOW_COLOR",
    "FRAMINGS",
    "UPPER_BODY",
    "LEAST_VIEW_HEIGHT",
    "fitted_height",
    "HAND_MARGIN",
    "FULL_BODY",
    "stage_meshes",
    "FIELD_OF_VIEW",
    "VIEW_DIRECTION",
    "DEPTH_SHARE",
    "scheme_for",
    "srgb_to_linear",
    "linear_to_srgb",
    "shade",
    "part_colors",
    "camera_for",
    "BODY_MARGIN",
    "FRAME_MARGIN",
    "stage_layout",
    "ROLE_SCHEMES",
    "RANK_SCHEMES",
    "role_scheme",
    "rank_scheme",
]


#: Colour schemes: each part of :data:`gesturekit.character.mesh.PARTS` as sRGB hex.
def _scheme(shirt: str) -> dict[str, str]:
    return {"skin": "#d9b59b", "shirt": shirt, "face": "#3b2b22", "trousers": "#434852", "shoes": "#2e2a28"}


SCHEMES: dict[str, dict[str, str]] = {
    "blue": _scheme("#3c6db0"),
    "orange": _scheme("#d0782a"),
    "green": _scheme("#3f8f5a"),
    "purple": _scheme("#7a55a8"),
    "teal": _scheme("#2a8c8c"),
    "red": _scheme("#b8413c"),
    "olive": _scheme("#8a8a2e"),
    "rose": _scheme("#b5548f"),
    "gold": _scheme("#d9a81e"),
    # for studies: no colour tells the systems apart, and no skin tone is chosen
    "grey": {"skin": "#b4b4b4", "shirt": "#8c8c8c", "face": "#4a4a4a", "trousers": "#5e5e5e", "shoes": "#3f3f3f"},
}

#: Schemes of side-by-side motions, in order (the k-th motion takes the k-th, cycling).
SIDE_BY_SIDE = ("blue", "orange", "green", "purple")

#: The scheme of study stimuli.
NEUTRAL = "grey"

#: The backdrop, sRGB hex: a calm, warm light grey.
BACKGROUND = "#e7e5e1"

#: The floor under the characters, sRGB hex (it fades into :data:`BACKGROUND` towards the back).
FLOOR_COLOR = "#d3d0ca"

#: The contact shadow's colour at its darkest (its centre), sRGB hex.
SHADOW_COLOR = "#8f8b84"

#: Towards the key light from the character, in the world (Y up, the character faces +Z): above, front, left.
LIGHT_DIRECTION = (0.35, 0.75, 0.56)

#: Ambient and key light strengths (linear light).
AMBIENT, KEY = 0.30, 0.62

#: The three lights, each (direction towards it, strength in linear light): the key (:data:`LIGHT_DIRECTION`,
#: :data:`KEY`), a weaker fill from the front right, and a rim light from behind and above that lifts the
#: shoulders and the head off the backdrop.
LIGHTS: tuple[tuple[tuple[float, float, float], float], ...] = (
    (LIGHT_DIRECTION, KEY),
    ((-0.65, 0.2, 0.73), 0.24),
    ((-0.25, 0.65, -0.72), 0.32),
)

#: The camera's vertical field of view, degrees.
FIELD_OF_VIEW = 30.0

#: How much of the framed box's half-depth :func:`camera_for` keeps in front of the plane it fits: 1 fits the
#: box's front face (a presenter far back behind hands that rarely come forward), 0 its middle.
DEPTH_SHARE = 0.25

#: From the framed box's centre towards the camera: in front, a little above.
VIEW_DIRECTION = (0.0, 0.12, 1.0)


@checks_arguments
def scheme_for(index: int, *, neutral: bool = False) -> str:
    """The scheme of the ``index``-th of side-by-side motions (:data:`NEUTRAL` for all when ``neutral``)."""
    return NEUTRAL if neutral else SIDE_BY_SIDE[int(index) % len(SIDE_BY_SIDE)]


@checks_arguments
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


@checks_arguments
def camera_for(
    lo: npt.ArrayLike,
    hi: npt.ArrayLike,
    aspect: float,
    *,
    fov: float = FIELD_OF_VIEW,
    top: bool = False,
    floor: float | None = None,
) -> dict:
    """A perspective camera that shows the box ``lo``..``hi`` whole, from :data:`VIEW_DIRECTION`.

    Parameters
    ----------
    lo, hi : array_like, shape (3,)
        Corners of the box to frame, metres.
    aspect : float
        Width over height of the picture.
    fov : float
        Vertical field of view, degrees.
    top : bool
        Where the box is narrower than the picture's height (a wide box in a tall picture), keep its top
        at the picture's top and show more below it (a presenter's legs) rather than centring it.
    floor : float, optional
        With ``top``: the floor's height, metres; the picture shows at most 0.1 m below it (the rest of the
        extra height goes above the box).

    Returns
    -------
    dict
        ``position``, ``target`` and ``up`` (3 floats each, metres), ``fov`` (degrees).
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if not (aspect > 0 and np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ConfigError(f"a camera needs a finite box and a positive aspect ratio, got {lo}, {hi}, {aspect}")
    centre = (lo + hi) / 2
    half = np.maximum((hi - lo) / 2, 1e-3)
    d = np.asarray(VIEW_DIRECTION) / np.linalg.norm(VIEW_DIRECTION)
    tan_v = np.tan(np.radians(fov) / 2)
    # far enough that the box fits both ways halfway between its centre and its front face: a hand reaching
    # towards the camera at the box's very corner may leave the picture, the body never does
    dist = max(half[1] / tan_v, half[0] / (tan_v * aspect)) + DEPTH_SHARE * half[2]
    if top:  # the height shown beyond the box's own: below the box, down to a little below the floor
        extra = max(0.0, (dist - DEPTH_SHARE * half[2]) * tan_v - half[1])
        room = extra if floor is None else max(0.0, lo[1] - extra - float(floor) + 0.1)
        centre = centre - [0.0, min(extra, room), 0.0]
    return {
        "position": [float(x) for x in centre + dist * d],
        "target": [float(x) for x in centre],
        "up": [0.0, 1.0, 0.0],
        "fov": float(fov),
    }


#: The least height, pixels, of a view that :func:`fitted_height` makes less high than asked.
LEAST_VIEW_HEIGHT = 200


@checks_arguments
def fitted_height(box: npt.ArrayLike, width: float, most: float) -> int:
    """The height, pixels, of a view ``width`` pixels wide that its upper-body ``box`` fills both ways.

    Side-by-side characters make a box wider than high: a view as high as asked would frame it by its width and
    leave the characters a small part of the height (and empty floor under them). The page's 3D view
    (``web/src/viewer.js``, ``fittedHeight``) is therefore no higher than the box fills at :func:`camera_for`'s
    fit, ``width * height / width`` of the box, at most ``most`` (the height asked for) and at least
    :data:`LEAST_VIEW_HEIGHT` (or ``most``, if less). A box higher than wide keeps ``most``.

    Parameters
    ----------
    box : array_like, shape (2, 3)
        The framed box's lower and upper corners, metres (:func:`stage_layout`).
    width, most : float
        The view's width and the height asked for, pixels.

    Returns
    -------
    int
        Pixels, rounded as the page rounds them (half up).
    """
    b = np.asarray(box, dtype=np.float64).reshape(2, 3)
    wide = (b[1, 0] - b[0, 0]) / max(b[1, 1] - b[0, 1], 1e-3)
    return int(np.floor(min(most, max(min(most, LEAST_VIEW_HEIGHT), width / wide)) + 0.5))


#: Metres between the joints and the body's surface, at most: the chest's half-depth, the hips' half-width
#: beyond the spine. Side-by-side characters keep this much to either side of their joints.
BODY_MARGIN = 0.14

#: Metres the framed box keeps around every joint: the arms' and the head's thickness.
FRAME_MARGIN = 0.07

#: Metres the framed box keeps below the lowest joint of every frame with :data:`UPPER_BODY`: a hanging hand's
#: lowest joint is a fingertip (or a wrist, where the data hold no fingers), the hand's surface a little beyond it.
HAND_MARGIN = 0.03

#: The framings of :func:`stage_layout`: the presenter's upper body (and whatever the hands reach), or the
#: whole body down to the floor.
UPPER_BODY, FULL_BODY = "upper body", "full body"
FRAMINGS = (UPPER_BODY, FULL_BODY)

#: With :data:`UPPER_BODY`, the box reaches this fraction of the joints' height below the lowest joint: the
#: hips and the top of the legs.
BELOW_WAIST = 0.15

#: The fraction of frames whose reach sets the framed box and the spacing of side-by-side characters: a rare
#: wide (or raised, or forward) gesture may leave the picture or reach into the neighbour's space rather than
#: shrink every character for the whole clip. (A clip of one frame is framed whole.)
REACH_QUANTILE = 0.95


@checks_arguments
def stage_layout(
    points: Sequence[np.ndarray],
    *,
    spacing: float | None = None,
    framing: str = UPPER_BODY,
    ground: float | None = None,
    waist: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Where side-by-side characters stand and the box the camera frames, the same for the page and the MP4.

    The one framing rule of every view (the app's pages, notebooks, the MP4): the box holds every
    character's reach over :data:`REACH_QUANTILE` of the shown frames (each frame's leftmost, rightmost,
    highest, nearest and farthest drawn joint; a rare gesture beyond it may leave the picture)
    plus :data:`FRAME_MARGIN`; with :data:`UPPER_BODY` down from there to the pelvis (``waist``) and
    :data:`BELOW_WAIST` of that height below it (the hips), or lower where a hand hangs lower in any frame (the
    lowest drawn joint of every frame and :data:`HAND_MARGIN`: hands are never cut), with :data:`FULL_BODY`
    down to the floor and every joint of every frame.
    A camera (:func:`camera_for`) fitted to it makes a standing presenter's upper body fill most of the
    picture's height.

    Parameters
    ----------
    points : sequence of np.ndarray, each shape (frames, joints, 3)
        Each character's joint positions over the shown frames, metres (only drawn joints).
    spacing : float, optional
        Metres between neighbouring characters along X; default the widest character's reach across (over
        :data:`REACH_QUANTILE` of its frames) and 0.1 m, at least 0.7 m.
    framing : str
        One of :data:`FRAMINGS`.
    ground : float, optional
        Height of the floor (the soles), metres: the bottom of :data:`FULL_BODY` framing. Without it the
        full body is framed as the upper body.
    waist : float, optional
        Height of the lowest character's pelvis, metres: the upper body's lower end (lower where a hand hangs
        below it in any frame). Without it, the lowest joint of every frame.

    Returns
    -------
    offsets : np.ndarray, shape (characters,)
        Each character's shift along X, metres, centred on 0.
    box : np.ndarray, shape (2, 3)
        The framed box's lower and upper corners, metres, with 3 % of the box on each side.
    """
    if framing not in FRAMINGS:
        raise ConfigError(f"unknown framing {framing!r}; choose one of {', '.join(FRAMINGS)}")
    if not points or any(np.asarray(p).size == 0 for p in points):
        raise ConfigError("a stage needs at least one character with at least one joint position")
    frames = [np.asarray(p, dtype=np.float64).reshape(len(p), -1, 3) for p in points]
    # each frame's extremes: the reach of most frames, not of the one widest (or highest, or nearest) frame
    reach = [
        (np.quantile(f.min(axis=1), 1 - REACH_QUANTILE, axis=0), np.quantile(f.max(axis=1), REACH_QUANTILE, axis=0))
        for f in frames
    ]
    if spacing is None:
        spacing = max(0.7, max(float(hi[0] - lo[0]) for lo, hi in reach) + 0.1)
    offsets = (np.arange(len(frames)) - (len(frames) - 1) / 2) * float(spacing)
    shift = [np.array([dx, 0.0, 0.0]) for dx in offsets]
    lo = np.min([r[0] + d for r, d in zip(reach, shift)], axis=0) - FRAME_MARGIN
    hi = np.max([r[1] + d for r, d in zip(reach, shift)], axis=0) + FRAME_MARGIN
    if framing == FULL_BODY and ground is not None:
        lo[1] = min(float(f[..., 1].min()) for f in frames + [np.full((1, 1, 3), float(ground) - 0.02)])
    elif waist is not None:  # the upper body from the pelvis up, a little of the legs, and every hand hanging low
        lowest = min(float(f[..., 1].min()) for f in frames) - HAND_MARGIN
        lo[1] = min(float(waist) - BELOW_WAIST * (hi[1] - float(waist)), lowest)
    else:  # down to the lowest joint of every frame, and as far again below the joints' height
        low = min(float(f[..., 1].min()) for f in frames) - FRAME_MARGIN
        lo[1] = low - BELOW_WAIST * (hi[1] - low)
    pad = 0.03 * (hi - lo) * [1.0, 0.5, 1.0]
    return offsets, np.stack([lo - pad, hi + pad])


#: Colour schemes by what a character shows, the same on every page and in every MP4: the search's result, the
#: refined motion, the candidate a search step chose. Candidates by rank (``k = 0``, ``#0``, ...) take
#: :data:`RANK_SCHEMES`.
ROLE_SCHEMES: dict[str, str] = {"k-NN": "blue", "refined": "orange", "chosen": "gold"}

#: The schemes of candidates by rank (the k-th best candidate, the inspector's ``#k``), cycling: none of
#: :data:`ROLE_SCHEMES`' colours.
RANK_SCHEMES = ("green", "purple", "teal", "red", "olive", "rose")


@checks_arguments
def role_scheme(role: str) -> str:
    """The scheme of a character showing ``role``: a key of :data:`ROLE_SCHEMES`.

    Raises
    ------
    ConfigError
        An unknown role.
    """
    if role not in ROLE_SCHEMES:
        raise ConfigError(f"unknown role {role!r}; choose one of {', '.join(ROLE_SCHEMES)}")
    return ROLE_SCHEMES[role]


@checks_arguments
def rank_scheme(rank: int) -> str:
    """The scheme of the candidate of rank ``rank`` (0: the best), from :data:`RANK_SCHEMES`."""
    if int(rank) < 0:
        raise ConfigError(f"a candidate's rank is 0 or more, got {rank}")
    return RANK_SCHEMES[int(rank) % len(RANK_SCHEMES)]


def _rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[i : i + 2], 16) / 255 for i in (1, 3, 5)])


@checks_arguments
def stage_meshes(box: npt.ArrayLike, ground: float, feet: Sequence[npt.ArrayLike]) -> list[dict]:
    """The stage under side-by-side characters: the floor and a contact shadow under each, unlit.

    Parameters
    ----------
    box : array_like, shape (2, 3)
        The framed box (:func:`stage_layout`), metres: the floor reaches far beyond it.
    ground : float
        Height of the floor, metres.
    feet : sequence of array_like, shape (3,)
        Where each character stands (between its feet), metres: the centre of its shadow.

    Returns
    -------
    list of dict
        The floor, then one shadow per character: ``vertices`` (V, 3) float32 metres, ``faces`` (F, 3) int32
        counter-clockwise seen from above, ``colors`` (V, 3) uint8 sRGB. The floor is :data:`FLOOR_COLOR` under
        the characters and fades into :data:`BACKGROUND` towards the back and the sides; a shadow is
        :data:`SHADOW_COLOR` at its centre and fades into the floor at its rim. Each shadow lies 2 mm above the
        floor.
    """
    lo, hi = np.asarray(box, dtype=np.float64)
    cx, width = (lo[0] + hi[0]) / 2, max(hi[0] - lo[0], 1.0)
    xs = cx + np.linspace(-1.0, 1.0, 17) * (4 * width + 4)
    zs = np.linspace(-7.0, 8.0, 31)
    gx, gz = np.meshgrid(xs, zs)
    # 1 under and around the characters, 0 far back and far to the sides: the floor meets the backdrop softly
    near = np.clip(1 - (np.abs(gx - cx) - (width + 1)) / (2 * width + 2), 0, 1) * np.clip((gz + 6.0) / 4.5, 0, 1)
    near = near * near * (3 - 2 * near)
    floor, back = _rgb(FLOOR_COLOR), _rgb(BACKGROUND)
    colours = back + near.reshape(-1, 1) * (floor - back)
    verts = np.column_stack([gx.ravel(), np.full(gx.size, ground), gz.ravel()])
    n = len(xs)
    r, c = np.meshgrid(np.arange(len(zs) - 1), np.arange(n - 1), indexing="ij")
    a = (r * n + c).ravel()
    # counter-clockwise seen from above (+Y): x right, z towards the viewer
    faces = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    out = [_mesh(verts, faces, colours)]
    shadow = _rgb(SHADOW_COLOR)
    rings, around = 8, 40
    radius = np.linspace(0.0, 1.0, rings + 1)[1:]
    theta = 2 * np.pi * np.arange(around) / around
    for centre in feet:
        x0, _, z0 = np.asarray(centre, dtype=np.float64)
        ring = np.stack([np.cos(theta)[None] * radius[:, None] * 0.36, np.sin(theta)[None] * radius[:, None] * 0.26])
        v = np.concatenate(
            [
                [[x0, ground + 2e-3, z0]],
                np.stack([x0 + ring[0], np.full_like(ring[0], ground + 2e-3), z0 + ring[1]], -1).reshape(-1, 3),
            ]
        )
        dark = np.concatenate([[1.0], np.repeat((1 - radius**2) ** 2, around)])  # soft: no edge at the rim
        col = floor + dark[:, None] * 0.85 * (shadow - floor)
        k = np.arange(around)
        k1 = (k + 1) % around
        tris = [np.stack([np.zeros(around, int), 1 + k1, 1 + k], 1)]
        for i in range(rings - 1):
            p, q = 1 + i * around, 1 + (i + 1) * around
            tris += [np.stack([p + k, p + k1, q + k1], 1), np.stack([p + k, q + k1, q + k], 1)]
        f = np.concatenate(tris)
        out.append(_mesh(v, f[:, ::-1] if _up(v, f) < 0 else f, col))
    if _up(verts, faces) < 0:
        out[0]["faces"] = out[0]["faces"][:, ::-1].copy()
    return out


def _up(v: np.ndarray, f: np.ndarray) -> float:
    """The summed normal's Y of a flat mesh (positive: counter-clockwise seen from above)."""
    return float(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])[:, 1].sum())


def _mesh(v: np.ndarray, f: np.ndarray, colours: np.ndarray) -> dict:
    return {
        "vertices": np.asarray(v, dtype=np.float32),
        "faces": np.ascontiguousarray(f, dtype=np.int32),
        "colors": np.rint(255 * np.clip(colours, 0, 1)).astype(np.uint8),
    }


@checks_arguments
def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] to linear light, same shape (the sRGB transfer function's inverse)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


@checks_arguments
def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] (clipped) to sRGB values in [0, 1], same shape."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


@checks_arguments
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
        ``albedo * (AMBIENT + sum_i strength_i * max(0, n . l_i))`` over the unit
        directions of :data:`LIGHTS`, clipped to 1 and
        converted to sRGB, rounded to the nearest of 0..255.
    """
    n = np.asarray(normals, dtype=np.float64)
    lit = np.full(n.shape[:-1], AMBIENT)
    for direction, strength in LIGHTS:
        light = np.asarray(direction, dtype=np.float64)
        lit = lit + strength * np.maximum(0.0, n @ (light / np.linalg.norm(light)))
    return np.rint(255 * linear_to_srgb(np.asarray(albedo) * lit[:, None])).astype(np.uint8)
