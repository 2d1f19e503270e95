"""The default character's legs: hips, legs and feet that stand still on a floor under the moving upper body.

Our motions hold the upper body only (:mod:`gesturekit.skeleton`: 13 body joints, pelvis-relative), so
the body of :func:`gesturekit.character.mesh.build_mesh` ends at the waist. :func:`stand_mesh` adds
what a presenter stands on: a pelvis in trousers that reaches up under the torso, two legs a little
apart and two shoes flat on a floor. They do not move (the data have no legs to move them); the torso
turns about ``spine_mid`` above them and its closed end stays inside the hips. Sizes follow the rig's
shoulder width ``W``, as the rest of the body's do: the hip joints stand :data:`HIP_HEIGHT` ``W`` above
the floor (0.88 m for the demo speaker's 0.36 m), a person of about 1.65 m.

The mesh is in the motion's frame (metres, Y up, facing +Z), where the pelvis is the origin: the floor
lies at :attr:`StandMesh.floor`, below it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._arguments import checks_arguments
from ..skeleton import joint_index
from ._body import _Frame, _tube
from ._loft import Chain, loft, signed_volume
from .mesh import PARTS, vertex_normals
from .rig import Rig

__all__ = ["HIP_HEIGHT", "StandMesh", "stand_mesh", "standing_root"]

#: Height of the hip joints above the floor, in shoulder widths.
HIP_HEIGHT = 2.45

#: How far the pelvis (the hip joints' height) is below ``spine_mid``, in shoulder widths.
_PELVIS_DROP = 0.30

_SPINE = joint_index("spine_mid")
_TROUSERS, _SHOES = PARTS.index("trousers"), PARTS.index("shoes")


@dataclass(frozen=True)
class StandMesh:
    """The still lower body, in the motion's frame.

    Attributes
    ----------
    vertices : np.ndarray, shape (V, 3), float32
        Metres.
    normals : np.ndarray, shape (V, 3), float32
        Unit outward normals.
    faces : np.ndarray, shape (F, 3), int32
        Counter-clockwise seen from outside.
    parts : np.ndarray, shape (V,), uint8
        Index into :data:`gesturekit.character.mesh.PARTS` (trousers and shoes).
    floor : float
        Height of the soles (the lowest vertices), metres.
    pelvis : float
        Height of the hip joints, metres: where the upper body ends.
    """

    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    parts: np.ndarray
    floor: float
    pelvis: float

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])


@checks_arguments
def standing_root(root: np.ndarray) -> np.ndarray:
    """Where the legs stand under a motion's root (``spine_mid``) positions (frames, 3): their median, shape (3,),
    metres (a speaker's pelvis-relative spine barely moves; the median ignores a few odd frames)."""
    r = np.asarray(root, dtype=np.float64).reshape(-1, 3)
    return np.median(r, axis=0) if len(r) else np.zeros(3)


def _closed(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return faces[:, ::-1] if signed_volume(verts, faces) < 0 else faces


@checks_arguments
def stand_mesh(rig: Rig, root: np.ndarray, *, detail: float = 1.0) -> StandMesh | None:
    """Hips, legs and shoes standing under a rig whose ``spine_mid`` stands at ``root``.

    Parameters
    ----------
    rig : Rig
        Its shoulder width sizes the legs.
    root : np.ndarray, shape (3,)
        Where ``spine_mid`` stands in the motion's frame, metres (:func:`standing_root`).
    detail : float
        Scales the rings and the vertices around them, as :func:`~gesturekit.character.mesh.build_mesh`'s.

    Returns
    -------
    StandMesh or None
        None for a rig without ``spine_mid`` (no torso to stand under).
    """
    f = _Frame(rig, float(detail))
    if not f.have[_SPINE]:
        return None
    w = f.width
    x0, y0, z0 = (float(v) for v in np.asarray(root, dtype=np.float64))
    pelvis = y0 - _PELVIS_DROP * w
    floor = pelvis - HIP_HEIGHT * w
    down = np.array([0.0, -1.0, 0.0])
    pieces: list[tuple[np.ndarray, np.ndarray, int]] = []
    # the hips: from inside the torso's closed end down to the crotch, wider than the waist
    rows = np.array(
        [
            (y0 - 0.02 * w, 0.33 * w, 0.22 * w),
            (pelvis + 0.10 * w, 0.45 * w, 0.27 * w),
            (pelvis - 0.10 * w, 0.50 * w, 0.30 * w),
            (pelvis - 0.32 * w, 0.47 * w, 0.28 * w),
        ]
    )
    n_around = f.n(40, 10)
    centres = np.column_stack([np.full(len(rows), x0), rows[:, 0], np.full(len(rows), z0 - 0.02 * w)])
    top, bottom = centres[0] + [0, 0.06 * w, 0], centres[-1] - [0, 0.12 * w, 0]
    v, fc = loft(
        centres, np.broadcast_to(down, centres.shape), f.lateral, rows[:, 1], rows[:, 2], n_around, top, bottom, 2.6
    )
    pieces.append((v, _closed(v, fc), _TROUSERS))
    knee_y = floor + 0.53 * HIP_HEIGHT * w
    ankle_y = floor + 0.085 * w * HIP_HEIGHT
    for side in (1.0, -1.0):
        hip = np.array([x0 + side * 0.25 * w, pelvis - 0.2 * w, z0 - 0.02 * w])
        knee = np.array([x0 + side * 0.29 * w, knee_y, z0 + 0.01 * w])
        ankle = np.array([x0 + side * 0.31 * w, ankle_y, z0 - 0.03 * w])
        chain = Chain(np.stack([hip, knee, ankle]), [_SPINE, _SPINE], [0.3 * w])
        thigh, shin = chain.stations[1], chain.length
        knots = np.array(
            [
                (0.0, 0.21 * w, 0.23 * w),
                (0.45 * thigh, 0.19 * w, 0.21 * w),
                (thigh, 0.145 * w, 0.155 * w),
                (thigh + 0.3 * (shin - thigh), 0.15 * w, 0.165 * w),
                (shin, 0.11 * w, 0.115 * w),
            ]
        )
        piece = _tube(f, chain, knots, f.lateral, f.n(18, 6), shin / f.n(14, 5), (0.2 * w, 0.1 * w), _TROUSERS)
        pieces.append((piece.vertices, _closed(piece.vertices, piece.faces), _TROUSERS))
        pieces.append(_shoe(f, ankle, floor, side))
    verts, faces, parts, base = [], [], [], 0
    for v, fc, part in pieces:
        verts.append(v)
        faces.append(fc + base)
        parts.append(np.full(len(v), part, np.uint8))
        base += len(v)
    vv = np.concatenate(verts)
    ff = np.concatenate(faces).astype(np.int32)
    return StandMesh(
        vertices=vv.astype(np.float32),
        normals=vertex_normals(vv, ff).astype(np.float32),
        faces=ff,
        parts=np.concatenate(parts),
        floor=float(np.float32(vv[:, 1].min())),
        pelvis=float(pelvis),
    )


def _shoe(f: _Frame, ankle: np.ndarray, floor: float, side: float) -> tuple[np.ndarray, np.ndarray, int]:
    """A shoe under the ankle, its toe turned a little outwards, its sole flat on the floor."""
    w = f.width
    turn = np.radians(8.0) * side
    forward = np.array([np.sin(turn), 0.0, np.cos(turn)])
    heel, length = -0.20 * w, 0.74 * w
    s = np.linspace(0.0, 1.0, f.n(12, 5))
    # half-width, height above the sole along the shoe, from heel to toe
    half = 0.13 * w * np.sqrt(np.clip(np.sin(np.pi * (0.08 + 0.9 * s)), 0.05, 1.0))
    height = 0.26 * w * (1.0 - 0.55 * s**1.5)
    centres = (
        ankle * [1, 0, 1] + np.outer(heel + length * s, forward) + np.column_stack([0 * s, floor + height / 2, 0 * s])
    )
    ends = (centres[0] - 0.03 * w * forward, centres[-1] + 0.04 * w * forward)
    v, fc = loft(
        centres,
        np.broadcast_to(forward, centres.shape),
        np.array([0.0, 1.0, 0.0]),
        height / 2,
        half,
        f.n(16, 6),
        *ends,
        3.0,
    )
    v[:, 1] = np.maximum(v[:, 1], floor)  # a flat sole
    return v, _closed(v, fc), _SHOES
