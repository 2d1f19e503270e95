"""A user's character in our frame: its bones, rest pose, matched joints and body (what :mod:`.user` reads).

Every array is in *our* frame: metres, Y up, the character facing +Z with its
left at +X, as our motions are. The file's own frame is found from its rest
pose (up: from the pelvis to the head; left: from the right upper arm to the
left one) and :attr:`Character.to_file` takes points back to it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError, warn
from ..skeleton import JOINT_NAMES, PARENTS, joint_index
from .humanoid import PELVIS

__all__ = [
    "CharacterSkin",
    "GltfSource",
    "Character",
    "WRIST_SLACK",
    "WRIST_SLACK_MAX",
    "check_wrist_slack",
    "FileSkeleton",
    "facing_frame",
    "topological",
    "reorder",
    "empty_skin",
]

#: How far a wrist may stay from our reach scaled to the character's arm, as a fraction of the arm's length,
#: by default (:attr:`Character.wrist_slack`; why 5 %: :mod:`gesturekit.character.retarget`).
WRIST_SLACK = 0.05
#: The largest :attr:`Character.wrist_slack`: beyond it the hands no longer do what ours do.
WRIST_SLACK_MAX = 0.2


@dataclass(frozen=True)
class CharacterSkin:
    """A character's skinned mesh in its rest pose, in our frame.

    Attributes
    ----------
    vertices : np.ndarray, shape (V, 3), float32
        Rest-pose positions, metres.
    normals : np.ndarray, shape (V, 3), float32
        Unit normals in the rest pose.
    faces : np.ndarray, shape (F, 3), int64
        Vertex indices of the triangles.
    joints : np.ndarray, shape (V, 4), int64
        The bones (indices into :attr:`Character.names`) each vertex follows.
    weights : np.ndarray, shape (V, 4), float32
        Their weights, non-negative, each row summing to 1.
    colors : np.ndarray, shape (V, 3), float32
        sRGB in [0, 1]: the material's base colour times its texture at the vertex (and the vertex colour).
    uvs : np.ndarray or None, shape (V, 2), float32
        The file's ``TEXCOORD_0`` (zeros where a primitive has none), glTF's convention: the image's top left
        at (0, 0). None where the body has no materials of its own.
    face_materials : np.ndarray or None, shape (F,), int64
        Each triangle's material in :attr:`materials`.
    materials : bytes
        The file's materials, textures and images as a materials GLB
        (:func:`gesturekit.character.materials.materials_glb`); empty where the body is drawn in
        :attr:`colors` alone.
    """

    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    colors: np.ndarray
    uvs: np.ndarray | None = None
    face_materials: np.ndarray | None = None
    materials: bytes = b""

    @property
    def has_materials(self) -> bool:
        """Whether the body is drawn in its file's own materials (else in :attr:`colors`)."""
        return bool(self.materials) and self.uvs is not None and self.face_materials is not None

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])


@dataclass(frozen=True)
class GltfSource:
    """What writing the character back as a GLB needs: the file's document and binary chunk.

    Attributes
    ----------
    document : dict
        The glTF JSON.
    binary : bytes
        The binary chunk (GLB) or the one buffer (glTF).
    nodes : np.ndarray, shape (M,), int64
        The node of each bone.
    """

    document: dict[str, Any]
    binary: bytes
    nodes: np.ndarray


@dataclass(frozen=True)
class Character:
    """A user's humanoid: its bones, their rest pose, which of our joints each is, and its body.

    Attributes
    ----------
    path : Path
        The file read.
    kind : str
        ``"gltf"`` (a glTF or GLB), ``"vrm0"``, ``"vrm1"`` or ``"bvh"``.
    names : tuple of str, length M
        Bone names, parents before children.
    parents : np.ndarray, shape (M,), int64
        Each bone's parent, ``-1`` for a root.
    rest_rotation : np.ndarray, shape (M, 3, 3), float64
        Each bone's rotation in the world at rest, our frame (the identity for a BVH's joints turned into our frame).
    rest_position : np.ndarray, shape (M, 3), float64
        Each bone's position at rest, our frame, metres.
    bone_of : np.ndarray, shape (55,), int64
        The bone at each of our joints, ``-1`` where the rig has none.
    pelvis : int
        The bone at the pelvis (their hips).
    matched_by : str
        How the bones were matched: ``"VRM 0.x humanoid"``, ``"VRM 1.0 humanoid"``, ``"mixamo names"``,
        ``"zeggs names"``, ``"JSON map NAME"``.
    to_file : np.ndarray, shape (4, 4), float64
        Takes a point of our frame to the file's world frame and units: a rotation times a uniform scale.
    skin : CharacterSkin or None
        The body of a glTF or VRM; ``None`` for a BVH or a glTF without a skinned mesh.
    gltf : GltfSource or None
        For a glTF or VRM.
    bvh_units : float
        Metres per unit of the file (for a BVH; for a glTF 1, unless its size said otherwise).
    notes : tuple of str
        What was changed to read it, for a person (a unit found from the character's size).
    wrist_slack : float
        How far its wrists may stay from our reach scaled to its arm when it is posed, as a fraction of the
        arm's length, in [0, :data:`WRIST_SLACK_MAX`]: 0 puts the hands exactly where ours reach, more keeps
        more of our arm directions (:func:`gesturekit.character.retarget.retarget`).
    """

    path: Path
    kind: str
    names: tuple[str, ...]
    parents: np.ndarray
    rest_rotation: np.ndarray
    rest_position: np.ndarray
    bone_of: np.ndarray
    pelvis: int
    matched_by: str
    to_file: np.ndarray
    skin: CharacterSkin | None = None
    gltf: GltfSource | None = field(default=None, repr=False)
    bvh_units: float = 1.0
    notes: tuple[str, ...] = ()
    wrist_slack: float = WRIST_SLACK

    def __post_init__(self) -> None:
        object.__setattr__(self, "wrist_slack", check_wrist_slack(self.wrist_slack))

    @property
    def n_bones(self) -> int:
        return len(self.names)

    def bone(self, joint: str) -> int:
        """The bone at our joint ``joint`` (or ``"pelvis"``), ``-1`` where there is none."""
        from ..skeleton import joint_index

        return self.pelvis if joint == PELVIS else int(self.bone_of[joint_index(joint)])

    def matched(self) -> dict[str, str]:
        """Our joint (and ``"pelvis"``) -> their bone name, for every joint matched."""
        from ..skeleton import JOINT_NAMES

        out = {PELVIS: self.names[self.pelvis]}
        out |= {JOINT_NAMES[j]: self.names[b] for j, b in enumerate(self.bone_of) if b >= 0}
        return out


def check_wrist_slack(value: object, *, name: str = "wrist_slack") -> float:
    """``value`` as a wrist slack (a fraction of the arm's length in [0, :data:`WRIST_SLACK_MAX`]).

    Raises
    ------
    ConfigError
        Not a real number, not finite, or out of that range; the message names ``name``.
    """
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if not ok or not (0.0 <= float(value) <= WRIST_SLACK_MAX):  # type: ignore[arg-type]
        raise ConfigError(
            f"{name} is how far a wrist may stay from our reach, a fraction of the arm's length from 0 to "
            f"{WRIST_SLACK_MAX:g}, got {value!r}"
        )
    return float(value)  # type: ignore[arg-type]


@checks_arguments
def facing_frame(pelvis: np.ndarray, head: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The rotation from a file's world frame to ours, from its rest pose.

    Parameters
    ----------
    pelvis, head, left, right : np.ndarray, shape (3,)
        Rest positions of the pelvis, the head and the left and right upper-arm joints, in the file's frame.

    Returns
    -------
    np.ndarray, shape (3, 3)
        ``R`` with ``R @ left_dir = +X``, ``R @ up = +Y``, ``R @ forward = +Z``.

    Raises
    ------
    ConfigError
        The head is not away from the pelvis, or the arms are not side by side across it.
    """
    up = np.asarray(head, float) - np.asarray(pelvis, float)
    side = np.asarray(left, float) - np.asarray(right, float)
    if np.linalg.norm(up) < 1e-9 or np.linalg.norm(side) < 1e-9:
        raise ConfigError("the rest pose has the head on the pelvis or both arms at one point")
    up = up / np.linalg.norm(up)
    side = side - up * (side @ up)
    if np.linalg.norm(side) < 1e-6 * np.linalg.norm(up):
        raise ConfigError("the rest pose has the arms on the line from the pelvis to the head")
    side = side / np.linalg.norm(side)
    forward = np.cross(side, up)
    return np.stack([side, up, forward])


@dataclass
class FileSkeleton:
    """Bones in the file's frame and units: parents before children; ``world`` (M, 4, 4) at rest.

    ``humanoid`` is ``(label, our joint -> bone, our joint -> name looked for)`` where the file declares one (VRM).
    ``skin`` holds the mesh in the file's world frame: vertices, normals, faces, joints, weights, colors.
    """

    path: Path
    kind: str
    names: tuple[str, ...]
    parents: np.ndarray
    world: np.ndarray
    units: float = 1.0
    humanoid: tuple[str, dict[str, int], dict[str, str]] | None = None
    skin: dict[str, np.ndarray] | None = None
    gltf: GltfSource | None = field(default=None, repr=False)

    def character(
        self,
        found: Mapping[str, int],
        matched_by: str,
        expected: Mapping[str, str] | None,
        *,
        notes: Sequence[str] = (),
    ) -> Character:
        """The character in our frame, its bones matched by ``found`` (our joint or ``"pelvis"`` -> bone); ``notes``
        what the match changed, for a person (warned and kept in :attr:`Character.notes`)."""
        del expected
        _check_tree(self, found)
        if not np.isfinite(self.world).all():
            raise ConfigError(f"{self.path}: the rest pose is not finite")
        pos = self.world[:, :3, 3] * self.units
        rot = _rotations(self.world[:, :3, :3])
        try:
            turn = facing_frame(
                pos[found[PELVIS]], pos[found["head"]], pos[found["left_shoulder"]], pos[found["right_shoulder"]]
            )
        except ConfigError as e:
            why = "a character's rest pose must stand upright, arms apart"
            raise ConfigError(f"{self.path}: {e.problem}; {why}") from None
        notes = list(notes)
        for note in notes:
            warn(note)
        factor, note = _size_factor(self, pos, turn[1])
        if factor != 1.0:
            self.units *= factor
            pos = pos * factor
            notes.append(note)
            warn(note)
        _check_legs(self, found, pos, turn[1])
        bone_of = np.full(len(JOINT_NAMES), -1, dtype=np.int64)
        for k, b in found.items():
            if k != PELVIS:
                bone_of[joint_index(k)] = b
        to_file = np.eye(4)
        to_file[:3, :3] = turn.T / self.units
        skin = None
        if self.skin is not None and len(self.skin["faces"]):
            s = self.skin
            skin = CharacterSkin(
                vertices=(s["vertices"] * self.units @ turn.T).astype(np.float32),
                normals=(s["normals"] @ turn.T).astype(np.float32),
                faces=s["faces"].astype(np.int64),
                joints=s["joints"].astype(np.int64),
                weights=s["weights"].astype(np.float32),
                colors=s["colors"].astype(np.float32),
                uvs=s["uvs"].astype(np.float32) if "uvs" in s else None,
                face_materials=s["face_materials"].astype(np.int64) if "face_materials" in s else None,
                materials=s["materials"].tobytes() if "materials" in s else b"",
            )
        return Character(
            path=self.path,
            kind=self.kind,
            names=self.names,
            parents=self.parents.astype(np.int64),
            rest_rotation=np.einsum("ab,mbc->mac", turn, rot),
            rest_position=pos @ turn.T,
            bone_of=bone_of,
            pelvis=int(found[PELVIS]),
            matched_by=matched_by,
            to_file=to_file,
            skin=skin,
            gltf=self.gltf,
            bvh_units=self.units,
            notes=tuple(notes),
        )


#: A humanoid's height, metres: a character outside it is read in another unit where one fits, else refused.
HUMAN_HEIGHT = (0.5, 3.0)

#: Metres per unit a file's lengths may evidently be in: metres, centimetres, millimetres, inches, and the
#: length unit of the common BVH conversion of the CMU mocap database (inches / 0.45).
_UNITS = {"metres": 1.0, "centimetres": 0.01, "millimetres": 0.001, "inches": 0.0254, "CMU mocap units": 0.056444}


def _height(sk: FileSkeleton, pos: np.ndarray, up: np.ndarray) -> float:
    """The character's height along ``up`` (metres as read): its body's where it has one, else its bones'."""
    points = pos
    if sk.skin is not None and len(sk.skin["vertices"]):
        points = np.concatenate([pos, sk.skin["vertices"] * sk.units])
    along = points @ up
    return float(along.max() - along.min())


def _size_factor(sk: FileSkeleton, pos: np.ndarray, up: np.ndarray) -> tuple[float, str]:
    """The factor that brings a character of implausible size into :data:`HUMAN_HEIGHT`, and the note saying so.

    A BVH's unit was guessed from its offsets, so any of :data:`_UNITS` may be its own; a glTF is metres by its
    specification, and a converter that wrote it at 1/100 (or 100 times, or in millimetres) is undone.

    Raises
    ------
    ConfigError
        No unit gives a humanoid's height.
    """
    height = _height(sk, pos, up)
    low, high = HUMAN_HEIGHT
    if low <= height <= high:
        return 1.0, ""
    raw = height / sk.units  # in the file's own units
    if sk.kind == "bvh":
        options = {f"read in {name}": size / sk.units for name, size in _UNITS.items()}
    else:
        options = {"scaled by 100 (written at 1/100 of its size)": 100.0}
        options |= {"read in centimetres": 0.01, "read in millimetres": 0.001}
    fits = {name: f for name, f in options.items() if low <= height * f <= high}
    if not fits:
        raise ConfigError(
            f"{sk.path}: the character is {height:.3g} m tall as read ({raw:.4g} file units), and no unit "
            f"(metres, centimetres, millimetres, inches) makes it a humanoid of {low} to {high} m; scale it in "
            "the modelling tool and export again"
        )
    name = min(fits, key=lambda n: abs(np.log(height * fits[n] / 1.7)))
    factor = fits[name]
    read_as = {1.0: "metres", 0.01: "centimetres", 0.001: "millimetres"}.get(sk.units, f"units of {sk.units:g} m")
    note = (
        f"{sk.path.name}: {height:.3g} m tall as read in {read_as}, outside a humanoid's {low} to {high} m: "
        f"{name}, {height * factor:.2f} m tall"
    )
    return factor, note


def _check_legs(sk: FileSkeleton, found: Mapping[str, int], pos: np.ndarray, up: np.ndarray) -> None:
    """Refuse a rest pose with a leg (a chain from the pelvis that is not the spine) ending above the pelvis.

    Raises
    ------
    ConfigError
        Naming the bone at the end of the leg and how far above the pelvis it is.
    """
    pelvis, spine = found[PELVIS], found["spine_mid"]
    children: dict[int, list[int]] = {}
    for b, p in enumerate(sk.parents):
        children.setdefault(int(p), []).append(b)
    height = float((pos @ up).max() - (pos @ up).min())
    for first in children.get(pelvis, []):
        below = [first]
        for b in below:
            below.extend(children.get(b, []))
        if spine in below:
            continue
        ends = [b for b in below if b not in children]
        reach = max(float(np.linalg.norm(pos[b] - pos[pelvis])) for b in below)
        if reach < 0.2 * height:
            continue  # a short bone (a tail, a skirt bone) is no leg
        top = max(ends, key=lambda b: float(pos[b] @ up))
        rise = float((pos[top] - pos[pelvis]) @ up)
        if rise > 0.1 * height:
            raise ConfigError(
                f"{sk.path}: in the rest pose the leg from {sk.names[first]!r} ends at {sk.names[top]!r}, "
                f"{rise:.2f} m above the pelvis: it points up. A character's rest pose must stand, legs down "
                "(for a BVH: its pose with every rotation zero); pose it so in the modelling tool and export again"
            )


def _rotations(m: np.ndarray) -> np.ndarray:
    """The rotation part of each 3x3 (the nearest rotation: scale and shear taken out)."""
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    flip = np.linalg.det(r) < 0
    if flip.any():
        u[flip, :, -1] *= -1
        r[flip] = u[flip] @ vt[flip]
    return r


def _ancestors(parents: np.ndarray, b: int) -> list[int]:
    out = []
    while b >= 0:
        out.append(b)
        b = int(parents[b])
    return out


def _check_tree(sk: FileSkeleton, found: Mapping[str, int]) -> None:
    """Refuse a match that two of our joints share a bone in, or where a joint's bone is not below its parent's."""
    names = sk.names
    seen: dict[int, str] = {}
    for k, b in found.items():
        if b in seen:
            raise ConfigError(f"{sk.path}: {seen[b]} and {k} are matched to one bone, {names[b]!r}")
        seen[b] = k
    for k, b in found.items():
        if k == PELVIS:
            continue
        j = joint_index(k)
        p = int(PARENTS[j])
        while p >= 0 and JOINT_NAMES[p] not in found:
            p = int(PARENTS[p])
        above = found[JOINT_NAMES[p]] if p >= 0 else found[PELVIS]
        if above not in _ancestors(sk.parents, b)[1:]:
            what = JOINT_NAMES[p] if p >= 0 else PELVIS
            raise ConfigError(
                f"{sk.path}: the bone of {k} ({names[b]!r}) is not below the bone of {what} ({names[above]!r})"
            )


@checks_arguments
def topological(parents: list[int]) -> list[int]:
    """An order of the bones in which every parent comes before its children (depth first, file order kept)."""
    children: dict[int, list[int]] = {}
    for i, p in enumerate(parents):
        children.setdefault(p, []).append(i)
    order: list[int] = []
    stack = list(reversed(children.get(-1, [])))
    while stack:
        b = stack.pop()
        order.append(b)
        stack.extend(reversed(children.get(b, [])))
    if len(order) != len(parents):
        raise ConfigError("the bones do not form a tree (a bone is its own ancestor)")
    return order


@checks_arguments
def reorder(names: list[str], parents: list[int], order: list[int]) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Names and parents in ``order``; also the inverse (old index -> new)."""
    new = np.empty(len(order), dtype=np.int64)
    new[np.asarray(order, dtype=np.int64)] = np.arange(len(order))
    out_parents = np.array([-1 if parents[o] < 0 else int(new[parents[o]]) for o in order], dtype=np.int64)
    return tuple(names[o] for o in order), out_parents, new


@checks_arguments
def empty_skin() -> dict[str, Any]:
    """A skin without triangles."""
    return {
        "vertices": np.zeros((0, 3)),
        "normals": np.zeros((0, 3)),
        "faces": np.zeros((0, 3), dtype=np.int64),
        "joints": np.zeros((0, 4), dtype=np.int64),
        "weights": np.zeros((0, 4)),
        "colors": np.zeros((0, 3)),
    }
