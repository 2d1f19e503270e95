"""How a motion looks as capsules: the appearance of the notebooks' figure and the MP4 (the page's viewer draws
the skinned character of :mod:`gesturekit.character`, taking only :attr:`Appearance.derived_color` from here).

A motion is drawn as a person, not as sticks: every bone of the 55-joint
skeleton becomes a capsule (a segment with a radius and round ends), the torso
gets volume from a few capsules between derived hip points and the shoulders,
and the head is a sphere. :meth:`Appearance.body` turns joint positions into
these shapes; :meth:`Appearance.shade` is the one lighting rule (Lambert with
ambient light, the light fixed to the camera); :meth:`Appearance.bounds` is the
one framing rule (the body's bounds over the whole motion, with a margin, fill
the view). The colours follow the app's: the first motion (k-NN) blue, the
second (refined) orange.

Everything here is plain numpy: each drawing backend (a plotly figure, a pyvista
render) reads the same numbers and draws them its own way.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .._arguments import checks_arguments
from ..character.look import FRAMINGS
from ..character.paint import DERIVED_COLOR
from ..errors import ConfigError
from ..skeleton import ABSENT, DERIVED, JOINT_NAMES, N_JOINTS, PARENTS, RECORDED, JointPresence, joint_index

__all__ = [
    "LOOKS",
    "RenderStyle",
    "APPEARANCE",
    "Appearance",
    "BodyShapes",
    "Capsule",
    "DERIVED_PART",
    "DERIVED_POINTS",
    "Sphere",
    "hex_to_rgb",
    "point_states",
    "rgb_to_hex",
]

#: Points :meth:`Appearance.body` adds after the 55 joints, in this order (indices 55, 56, ...).
DERIVED_POINTS: tuple[str, ...] = ("pelvis", "left_hip", "right_hip", "head_centre", "left_chest", "right_chest")

#: The part of every shape that touches a derived joint: drawn in :attr:`Appearance.derived_color`.
DERIVED_PART = "derived"

#: The joints each derived point is placed from (:meth:`Appearance.body`).
_POINT_SOURCES: tuple[tuple[str, ...], ...] = (
    ("spine_mid", "chest"),
    ("spine_mid", "chest", "left_shoulder", "right_shoulder"),
    ("spine_mid", "chest", "left_shoulder", "right_shoulder"),
    ("head", "head_top"),
    ("chest", "upper_chest", "left_shoulder", "right_shoulder"),
    ("chest", "upper_chest", "left_shoulder", "right_shoulder"),
)


@checks_arguments
def point_states(presence: JointPresence | None) -> tuple[str, ...]:
    """The state of each body point (the 55 joints, then :data:`DERIVED_POINTS`).

    A derived point is absent when a joint it is placed from is absent, derived when one
    is derived, else recorded. The pelvis and the hips extend the spine downwards: they
    are drawn only when ``spine_mid`` and ``chest`` are recorded, since an extension of a
    derived spine would show a body the data does not have.

    Parameters
    ----------
    presence : JointPresence or None
        None: every joint recorded.

    Returns
    -------
    tuple of str, length 55 + len(DERIVED_POINTS)
    """
    joints = (presence or JointPresence.full()).status
    out = list(joints)
    for k, sources in enumerate(_POINT_SOURCES):
        states = {joints[joint_index(n)] for n in sources}
        hips = DERIVED_POINTS[k] in ("pelvis", "left_hip", "right_hip")  # placed from the spine alone
        if ABSENT in states or (hips and states != {RECORDED}):
            out.append(ABSENT)
        else:
            out.append(DERIVED if DERIVED in states else RECORDED)
    return tuple(out)


@dataclass(frozen=True)
class Capsule:
    """A segment between two points, drawn with a radius and round ends.

    Attributes
    ----------
    a, b : int
        Indices into :attr:`BodyShapes.points` (a joint below 55, a derived point above).
    radius : float
        Metres.
    part : str
        The body part: ``"torso"``, ``"neck"``, ``"upper_arm"``, ``"forearm"``, ``"palm"``, ``"finger"``.
    """

    a: int
    b: int
    radius: float
    part: str


@dataclass(frozen=True)
class Sphere:
    """A ball around one point.

    Attributes
    ----------
    centre : int
        Index into :attr:`BodyShapes.points`.
    radius : float
        Metres.
    part : str
        The body part (``"head"``).
    covers : tuple of (int, int)
        The bones (child, parent joint indices) the sphere stands for; they get no capsule.
    """

    centre: int
    radius: float
    part: str
    covers: tuple[tuple[int, int], ...] = ()


@dataclass(frozen=True)
class BodyShapes:
    """What to draw for one motion.

    Attributes
    ----------
    points : numpy.ndarray
        Shape (frames, 55 + len(DERIVED_POINTS), 3), float32, metres: the joints, then the
        :data:`DERIVED_POINTS`.
    capsules : tuple of Capsule
        Only those to draw: none touching an absent point; those touching a derived one
        have the part :data:`DERIVED_PART`.
    spheres : tuple of Sphere
        As the capsules.
    drawn : numpy.ndarray
        Shape (55 + len(DERIVED_POINTS),) bool: the points that exist (recorded or derived);
        what the view frames.
    """

    points: np.ndarray
    capsules: tuple[Capsule, ...]
    spheres: tuple[Sphere, ...]
    drawn: np.ndarray

    def drawn_points(self) -> np.ndarray:
        """The points that exist, shape (frames, drawn points, 3), float32, metres."""
        return self.points[:, self.drawn]


@checks_arguments
def hex_to_rgb(color: str) -> np.ndarray:
    """``"#rrggbb"`` as floats in [0, 1], shape (3,)."""
    c = color.lstrip("#")
    return np.array([int(c[i : i + 2], 16) for i in (0, 2, 4)], dtype=np.float64) / 255.0


@checks_arguments
def rgb_to_hex(rgb: npt.ArrayLike) -> str:
    """Floats in [0, 1] (clipped), shape (3,), as ``"#rrggbb"``."""
    v = np.clip(np.round(np.asarray(rgb, dtype=np.float64) * 255.0), 0, 255).astype(int)
    return "#{:02x}{:02x}{:02x}".format(*v)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-9, n, 1.0)


@dataclass(frozen=True)
class Appearance:
    """The look of a motion as a person: colours, body part sizes, light, ground and framing.

    Lengths are in metres. Colours are ``"#rrggbb"``. The light direction is in the
    camera's frame (x to the right of the view, y up, z towards the viewer), so the
    figure stays lit from the front whichever way the view is turned.

    Attributes
    ----------
    motion_colors : tuple of str
        One colour per motion, in order (first k-NN blue, then refined orange, ...).
    part_tint : tuple of (str, float)
        Per body part, how far its colour is mixed towards white (0: the motion's colour).
    merged_parts : tuple of str
        Parts whose capsules are shaded as one surface: one cylinder along the spine
        (pelvis to upper chest), so the torso reads as one body rather than as tubes.
    torso_radius : float
        The spine capsules (pelvis to upper chest): the torso's depth.
    hip_radius : float
        The capsule between the hips.
    chest_radius : float
        The capsule across the chest (between the chest points).
    shoulder_radius : float
        The collar bones (upper chest to collar to shoulder).
    neck_base_radius : float
        The bone from upper chest to neck: the base of the neck, shaded as part of the torso.
    neck_radius : float
        The neck above it (neck to neck_upper to head).
    head_radius : float
        The head sphere, centred :attr:`head_centre` of the way from ``head`` to ``head_top``.
    head_centre : float
        Fraction, 0 at ``head``, 1 at ``head_top``.
    upper_arm_radius, forearm_radius : float
    palm_radius : float
        Wrist to each finger's root.
    finger_radius, fingertip_radius : float
        Finger bones; the last bone of each finger.
    pelvis_below : float
        The pelvis point lies this many spine_mid-to-chest lengths below spine_mid, along the spine.
    hip_half_width : float
        The hips lie this far either side of the pelvis, along the shoulders' left-right line.
    chest_half_width : float
        The chest points lie this far either side of a point :attr:`chest_height` of the way from
        ``chest`` to ``upper_chest``, along the same line.
    chest_height : float
        Fraction, 0 at ``chest``, 1 at ``upper_chest``.
    light_direction : tuple of float
        Towards the light, camera frame (normalised where used).
    ambient, diffuse : float
        Shading: ``colour * min(1, ambient + diffuse * max(0, normal . light))``.
    derived_color : str
        Every shape of a derived joint (placed from others, not recorded): grey, whatever the motion.
    background : str
    ground_color : str
        The floor a figure stands on (drawn as a band below it).
    shadow_color : str
        The contact shadow under each figure; :attr:`shadow_alpha` its opacity.
    shadow_alpha : float
    ground_gap : float
        The floor lies this far below the lowest surface over the whole motion.
    frame_margin : float
        Framing: the bounds over the whole motion grow by this fraction of their size on
        every side, and that box fills the view.
    """

    # colours
    motion_colors: tuple[str, ...] = ("#2c5d8f", "#c0502d", "#3a8a4e", "#7b4fa0", "#a07a1f", "#2a8a8a")
    part_tint: tuple[tuple[str, float], ...] = (("head", 0.22), ("palm", 0.12), ("finger", 0.12))
    merged_parts: tuple[str, ...] = ("torso",)
    # the body's shapes
    torso_radius: float = 0.12
    hip_radius: float = 0.09
    chest_radius: float = 0.09
    shoulder_radius: float = 0.06
    neck_base_radius: float = 0.06
    neck_radius: float = 0.048
    head_radius: float = 0.1
    head_centre: float = 0.45
    upper_arm_radius: float = 0.046
    forearm_radius: float = 0.037
    palm_radius: float = 0.014
    finger_radius: float = 0.0095
    fingertip_radius: float = 0.008
    # points the skeleton lacks, placed from its joints
    pelvis_below: float = 1.4
    hip_half_width: float = 0.045
    chest_half_width: float = 0.08
    chest_height: float = 0.7
    # shading
    light_direction: tuple[float, float, float] = (-0.45, 0.6, 0.66)
    ambient: float = 0.5
    diffuse: float = 0.62
    # the scene: a background, the floor the figure stands on and its contact shadow
    derived_color: str = DERIVED_COLOR
    background: str = "#f4f5f7"
    ground_color: str = "#e3e6ea"
    shadow_color: str = "#000000"
    shadow_alpha: float = 0.18
    ground_gap: float = 0.02
    # framing
    frame_margin: float = 0.05

    def color(self, motion: int) -> str:
        """The colour of the ``motion``-th motion (colours repeat after the last)."""
        return self.motion_colors[motion % len(self.motion_colors)]

    def part_color(self, motion: int, part: str) -> str:
        """The colour of one body part of the ``motion``-th motion, before shading.

        The :data:`DERIVED_PART` is :attr:`derived_color` for every motion."""
        if part == DERIVED_PART:
            return self.derived_color
        tint = dict(self.part_tint).get(part, 0.0)
        rgb = hex_to_rgb(self.color(motion))
        return rgb_to_hex(rgb + (1.0 - rgb) * tint)

    def light(self) -> np.ndarray:
        """The unit direction towards the light, camera frame, shape (3,)."""
        return _unit(np.asarray(self.light_direction, dtype=np.float64))

    def shade(self, color: str, normals: npt.ArrayLike) -> np.ndarray:
        """The lit colour of surface points.

        Parameters
        ----------
        color : str
            ``"#rrggbb"``, the unlit colour.
        normals : array_like
            Shape (..., 3), unit surface normals in the camera frame.

        Returns
        -------
        numpy.ndarray
            Shape (..., 3), RGB in [0, 1]: ``colour * min(1, ambient + diffuse * max(0, n . l))``.
        """
        n = np.asarray(normals, dtype=np.float64)
        lambert = np.maximum(0.0, n @ self.light())
        k = np.minimum(1.0, self.ambient + self.diffuse * lambert)
        return hex_to_rgb(color) * k[..., None]

    def shapes(self, presence: JointPresence | None = None) -> tuple[tuple[Capsule, ...], tuple[Sphere, ...]]:
        """The capsules and spheres of the body, independent of the pose.

        Every one of the 54 bones is a capsule, except ``head`` to ``head_top``, which the
        head sphere stands for (its ``covers``). The torso adds capsules between the
        derived points: the hips and across the chest.

        Parameters
        ----------
        presence : JointPresence, optional
            Which joints exist (default all recorded). Shapes touching an absent point
            (:func:`point_states`) are left out; those touching a derived one get the
            part :data:`DERIVED_PART`.
        """
        caps, spheres = self._all_shapes()
        if presence is None or presence.is_full:
            return caps, spheres
        state = point_states(presence)

        def look(ends: tuple[int, ...]) -> str | None:
            states = {state[e] for e in ends}
            return None if ABSENT in states else DERIVED_PART if DERIVED in states else ""

        kept_caps = []
        for c in caps:
            part = look((c.a, c.b))
            if part is not None:
                kept_caps.append(Capsule(c.a, c.b, c.radius, part or c.part))
        kept_spheres = []
        for sp in spheres:
            part = look((sp.centre,))
            if part is not None:
                kept_spheres.append(Sphere(sp.centre, sp.radius, part or sp.part, sp.covers))
        return tuple(kept_caps), tuple(kept_spheres)

    def _all_shapes(self) -> tuple[tuple[Capsule, ...], tuple[Sphere, ...]]:
        """Every capsule and sphere of a complete body."""
        j = joint_index
        n = N_JOINTS
        pelvis, lhip, rhip, head_c, lchest, rchest = (n + i for i in range(len(DERIVED_POINTS)))
        head_bone = (j("head_top"), j("head"))
        caps = [
            # the torso's volume: the spine down to the pelvis, across the hips and the chest
            Capsule(pelvis, j("spine_mid"), self.torso_radius, "torso"),
            Capsule(lhip, rhip, self.hip_radius, "torso"),
            Capsule(lchest, rchest, self.chest_radius, "torso"),
        ]
        radius = {
            "chest": self.torso_radius,
            "upper_chest": self.torso_radius,
            "neck": self.neck_base_radius,
            "neck_upper": self.neck_radius,
            "head": self.neck_radius,
            "left_collar": self.shoulder_radius,
            "left_shoulder": self.shoulder_radius,
            "right_collar": self.shoulder_radius,
            "right_shoulder": self.shoulder_radius,
            "left_elbow": self.upper_arm_radius,
            "right_elbow": self.upper_arm_radius,
        }
        part = {
            "chest": "torso",
            "upper_chest": "torso",
            "neck": "torso",
            "neck_upper": "neck",
            "head": "neck",
            "left_collar": "torso",
            "left_shoulder": "torso",
            "right_collar": "torso",
            "right_shoulder": "torso",
            "left_elbow": "upper_arm",
            "right_elbow": "upper_arm",
        }
        for child in range(1, N_JOINTS):
            parent = int(PARENTS[child])
            if parent < 0 or (child, parent) == head_bone:
                continue
            name = JOINT_NAMES[child]
            if name in radius:
                caps.append(Capsule(parent, child, radius[name], part[name]))
            elif name.endswith("wrist"):
                caps.append(Capsule(parent, child, self.forearm_radius, "forearm"))
            elif name.endswith("1"):
                caps.append(Capsule(parent, child, self.palm_radius, "palm"))
            else:
                r = self.fingertip_radius if name.endswith("4") else self.finger_radius
                caps.append(Capsule(parent, child, r, "finger"))
        spheres = (Sphere(head_c, self.head_radius, "head", covers=(head_bone,)),)
        return tuple(caps), spheres

    def body(self, positions: npt.ArrayLike, presence: JointPresence | None = None) -> BodyShapes:
        """The shapes to draw for a motion: its points (joints and derived points) and capsules.

        Parameters
        ----------
        positions : array_like
            Shape (frames, 55, 3), metres, Y up, the character facing +Z.
        presence : JointPresence, optional
            Which joints exist (a motion's :attr:`~gesturekit.motion.Motion.presence`);
            default all recorded. Absent joints get no shape; derived ones the derived look.

        Returns
        -------
        BodyShapes
            ``points`` of shape (frames, 61, 3) float32: the joints, then the
            :data:`DERIVED_POINTS` (pelvis, hips, head centre, chest points).

        Raises
        ------
        ConfigError
            If ``positions`` is not (frames, 55, 3) with at least one frame.
        """
        p = np.asarray(positions, dtype=np.float64)
        if p.ndim != 3 or p.shape[1:] != (N_JOINTS, 3) or p.shape[0] < 1:
            raise ConfigError(f"positions must have shape (frames, {N_JOINTS}, 3), got {p.shape}")
        j = joint_index
        spine, chest = p[:, j("spine_mid")], p[:, j("chest")]
        pelvis = spine + (spine - chest) * self.pelvis_below
        across = _unit(p[:, j("left_shoulder")] - p[:, j("right_shoulder")])
        head, top = p[:, j("head")], p[:, j("head_top")]
        breast = chest + (p[:, j("upper_chest")] - chest) * self.chest_height  # broadest high on the chest
        derived = np.stack(
            [
                pelvis,
                pelvis + across * self.hip_half_width,
                pelvis - across * self.hip_half_width,
                head + (top - head) * self.head_centre,
                breast + across * self.chest_half_width,
                breast - across * self.chest_half_width,
            ],
            axis=1,
        )
        caps, spheres = self.shapes(presence)
        points = np.concatenate([p, derived], axis=1).astype(np.float32)
        drawn = np.array([s != ABSENT for s in point_states(presence)], dtype=bool)
        return BodyShapes(points=points, capsules=caps, spheres=spheres, drawn=drawn)

    def bounds(self, points: npt.ArrayLike, *, margin: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """The box every drawn surface stays in over the whole motion: the framing rule.

        Parameters
        ----------
        points : array_like
            Shape (..., 3), metres: :attr:`BodyShapes.points` of one or several motions
            (finite values only are used).
        margin : bool
            Grow the box by :attr:`frame_margin` of its largest side on every side.

        Returns
        -------
        (lo, hi) : numpy.ndarray
            Each shape (3,), metres. The view is framed so that this box fills it.
        """
        q = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        q = q[np.isfinite(q).all(axis=1)]
        if len(q) == 0:
            raise ConfigError("no finite point to frame")
        pad = max(self.head_radius, self.torso_radius)  # the thickest surface around any point
        lo, hi = q.min(axis=0) - pad, q.max(axis=0) + pad
        if margin:
            m = self.frame_margin * float(np.max(hi - lo))
            lo, hi = lo - m, hi + m
        return lo, hi

    def ground_height(self, points: npt.ArrayLike) -> float:
        """The floor's height (Y, metres): :attr:`ground_gap` below the lowest surface of the motion.

        Parameters
        ----------
        points : array_like
            Shape (..., 3), metres (as :meth:`bounds`).
        """
        q = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        q = q[np.isfinite(q).all(axis=1)]
        return float(q[:, 1].min() - max(self.torso_radius, self.hip_radius) - self.ground_gap)

    def to_json(self) -> dict:
        """The appearance as a JSON-ready dict (what a page's script reads): colours, light,
        ambient, diffuse, background, ground, shadow and margin."""
        return {
            "light": [round(float(x), 6) for x in self.light()],
            "ambient": self.ambient,
            "diffuse": self.diffuse,
            "background": self.background,
            "derived": self.derived_color,
            "ground": self.ground_color,
            "shadow": self.shadow_color,
            "shadow_alpha": self.shadow_alpha,
            "margin": self.frame_margin,
            "merged": list(self.merged_parts),
        }


#: The appearance every view uses.
APPEARANCE = Appearance()


# ---- the style of a rendered scene ------------------------------------------------------------

#: What a scene draws: the page's skinned character, or the earlier capsule figure.
LOOKS = ("character", "capsules")


@dataclass(frozen=True)
class RenderStyle:
    """How a rendered scene looks and is framed.

    With ``look="character"`` (the default) the picture is the page's: the
    skinned character, the colour schemes, light, camera (vertical field of
    view :data:`gesturekit.character.look.FIELD_OF_VIEW`) and background of
    :mod:`gesturekit.character.look`, side-by-side characters standing on one
    floor with their contact shadows; ``appearance``, ``view_angle``,
    ``elevation``, the tessellation and ``text_color`` do not apply. With
    ``look="capsules"`` the figure is the notebooks' one: the appearance's
    capsules, head sphere, colours (first motion blue, second orange), light
    (fixed to the camera), floor and contact shadow, one panel per motion.

    Parameters
    ----------
    look : str
        One of :data:`LOOKS`.
    neutral : bool
        The character in the neutral colour scheme
        (:data:`gesturekit.character.look.NEUTRAL`), whatever its place: the
        look of study stimuli.
    appearance : Appearance
        The look of the body (:data:`gesturekit.viz.appearance.APPEARANCE` by default).
    text_color : colour
        Colour of the panel labels (anything PyVista accepts).
    view_box : ((xmin, xmax), (ymin, ymax), (zmin, zmax))
        Pelvis-relative region, metres, framed when ``fit_motion`` is off: a
        standing speaker's upper body and reach. Its bottom is the floor. On a
        user's character (``character=`` of :class:`SkeletonScene`), relative
        to its pelvis at rest.
    fit_motion : bool
        Frame every motion over the whole clip, so that the figure fills the
        view (the page's framing rule: the character's
        :func:`gesturekit.character.look.stage_layout`, the capsules'
        appearance bounds). Off, every
        clip is framed by ``view_box``, so that clips of different systems
        look alike (user-study stimuli).
    view_angle : float
        Vertical field of view of the perspective camera, degrees, in (0, 120).
    elevation : float
        How far the camera looks down at the figure, degrees in [0, 60): a
        little, so that the floor shows as a band.
    capsule_sides, sphere_resolution, head_resolution : int
        Tessellation of the capsules' tubes, their round ends and the head.
    multi_samples : int
        Multisample anti-aliasing samples per pixel, 0 for none. Smoother
        edges, but in software rendering (no GPU) 4 samples make each frame
        about five times slower.
    font_size : int
        Size of the panel labels, points.
    framing : str
        The character look's framing with ``fit_motion``: the presenter's upper body or the full body
        (:data:`gesturekit.character.look.FRAMINGS`, :func:`gesturekit.character.look.stage_layout`).
    """

    look: str = "character"
    neutral: bool = False
    appearance: Appearance = APPEARANCE
    text_color: object = "#202020"
    view_box: tuple = ((-0.6, 0.6), (-0.35, 0.85), (-0.3, 0.45))
    fit_motion: bool = True
    view_angle: float = 20.0
    elevation: float = 10.0
    capsule_sides: int = 10
    sphere_resolution: int = 8
    head_resolution: int = 20
    multi_samples: int = 0
    font_size: int = 14
    framing: str = "upper body"

    def __post_init__(self) -> None:
        if self.look not in LOOKS:
            raise ConfigError(f"unknown look {self.look!r}; choose one of {', '.join(LOOKS)}")
        if self.framing not in FRAMINGS:
            raise ConfigError(f"unknown framing {self.framing!r}; choose one of {', '.join(FRAMINGS)}")
        if not isinstance(self.appearance, Appearance):
            raise ConfigError(f"appearance must be an Appearance, got {type(self.appearance).__name__}")
        box = np.asarray(self.view_box, dtype=np.float64)
        if box.shape != (3, 2) or not np.all(np.isfinite(box)) or np.any(box[:, 1] <= box[:, 0]):
            raise ConfigError(
                f"view_box must be ((xmin, xmax), (ymin, ymax), (zmin, zmax)) with min < max, got {self.view_box}"
            )
        if not 0 < self.view_angle < 120:
            raise ConfigError(f"view_angle must be in (0, 120) degrees, got {self.view_angle}")
        if not 0 <= self.elevation < 60:
            raise ConfigError(f"elevation must be in [0, 60) degrees, got {self.elevation}")
        if self.capsule_sides < 3 or min(self.sphere_resolution, self.head_resolution) < 4:
            raise ConfigError("capsule_sides must be at least 3, sphere_resolution and head_resolution at least 4")
        if self.multi_samples < 0:
            raise ConfigError("multi_samples must not be negative")

    def to_json(self) -> dict:
        """The style as a JSON-ready dict (:meth:`from_json` reads it back)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> RenderStyle:
        """The style :meth:`to_json` wrote."""
        fields = {k: _to_tuples(v) for k, v in data.items() if k != "appearance"}
        appearance = Appearance(**{k: _to_tuples(v) for k, v in data["appearance"].items()})
        return cls(appearance=appearance, **fields)


def _to_tuples(value: Any) -> Any:
    """JSON lists back to tuples, recursively (the style's fields are tuples)."""
    if isinstance(value, list):
        return tuple(_to_tuples(v) for v in value)
    return value
