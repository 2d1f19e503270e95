"""Generated humanoid characters for the tests of putting our motion on a user's own character.

No third-party asset: every file is built here from a :class:`RigSpec` — a glTF binary (``.glb``,
Mixamo-like, ZEGGS-like or numbered bone names), a VRM 0.x or 1.0 file (``.vrm``, a glTF binary with
the humanoid extension and VRoid-like node names, so that matching must go through the humanoid
map) or a BVH skeleton (centimetres, Y up, facing +Z, two frames of zeros). :func:`truth` gives what a
reader should find in the file: bone names, parents, rest world positions in metres and which of our
joints each bone is.

The body is one template (metres, Y up, facing +Z, its left at +X, T-pose) scaled to the height; the
A-pose turns each arm (upper arm, forearm, hand and fingers) 40 degrees down about its shoulder. A
VRM 0.x character is the template turned 180 degrees about Y: it faces -Z, its left at -X.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gesturekit.character.glb import (
    ARRAY_BUFFER,
    ELEMENT_ARRAY_BUFFER,
    FLOAT,
    UBYTE,
    UINT,
    GlbBuffer,
    glb_bytes,
    node_matrices,
)
from gesturekit.skeleton import FINGERS

__all__ = ["RigSpec", "RigTruth", "rig_files", "write_rig", "truth", "custom_map", "cmu_bvh", "CASES", "NAMINGS"]

NAMINGS = (
    "mixamo",
    "vrm0",
    "vrm1",
    "zeggs",
    "custom",
    "blender",
    "unreal",
    "cc",
    "uma",
    "nameless",
    "sideless",
    "mirrored",
)
#: Naming families matched by their common words (:func:`gesturekit.character.humanoid.match_families`).
FAMILY_NAMINGS = ("blender", "unreal", "cc", "uma")
A_POSE_DEGREES = 40.0
_SIDES = (("L", "left", "Left", 1.0), ("R", "right", "Right", -1.0))
_VRM_FINGER = {"thumb": "Thumb", "index": "Index", "middle": "Middle", "ring": "Ring", "pinky": "Little"}
# finger roots (x along the hand, y, z towards the thumb side) from the wrist, and phalanx lengths, metres
_FINGER_ROOT = {
    "thumb": (0.025, -0.012, 0.025),
    "index": (0.085, 0.0, 0.028),
    "middle": (0.09, 0.0, 0.006),
    "ring": (0.085, 0.0, -0.015),
    "pinky": (0.077, -0.004, -0.034),
}
_FINGER_LENGTHS = {
    "thumb": (0.04, 0.032, 0.027),
    "index": (0.042, 0.025, 0.021),
    "middle": (0.046, 0.029, 0.022),
    "ring": (0.043, 0.027, 0.021),
    "pinky": (0.034, 0.02, 0.018),
}


@dataclass(frozen=True)
class RigSpec:
    """What character to generate; lengths in metres, factors on the default body.

    Attributes
    ----------
    naming : str
        ``"mixamo"`` (``prefix`` + Hips, Spine.., LeftArm, LeftHandIndex1..4, HeadTop_End), ``"zeggs"`` (our
        BVH preset's names: Spine, Spine1..Spine3, Neck, Neck1, HeadEnd), ``"vrm0"`` / ``"vrm1"`` (VRoid-like
        node names, matched through the humanoid map), ``"custom"`` (``bone_00``.., see :func:`custom_map`),
        ``"nameless"`` (glTF nodes without names), ``"sideless"`` (``arm_a`` on the right, ``arm_b`` on the left)
        or ``"mirrored"`` (Mixamo's names with ``Left`` on the character's right).
    prefix : str
        Mixamo's name prefix (``""`` allowed).
    rest : str
        ``"T"`` arms along +-X; ``"A"`` each arm turned 40 degrees down about its upper-arm joint.
    height : float
        Head top above the floor; the whole body scales with it.
    shoulder_width, arm, forearm : float
        Factors on the distance between the upper-arm joints, the upper-arm and the forearm lengths.
    spine_bones : int
        2..4 bones between hips and neck; the last up to three are our spine_mid, chest, upper_chest (the
        first of four is unmapped). ZEGGS names write one more, unmapped, ``Spine`` below them.
    fingers : bool
        Five fingers a hand, three bones and a tip node each (our finger joints 1..4).
    twist_bones : bool
        An unmapped bone in the middle of each forearm (between elbow and hand) and one in the spine
        (below the upper_chest bone).
    roll_seed : int or None
        None: rest local rotations identity; else a random rest rotation on every bone, children's
        translations in the rolled frame, so rest world positions do not change (glTF only).
    armature : bool
        glTF only: the bones inside an ``Armature`` node turned +90 degrees about X and scaled 0.01, in
        centimetres, Z up; the composed world is metres, Y up.
    drop : tuple of str
        Our joints whose bone is left out; its children hang from its parent, in place.
    mesh, texture : bool
        glTF: a skinned 8-sided tube around every bone segment (two materials); a generated 8 x 8 PNG
        base colour with TEXCOORD_0.
    textured : bool
        glTF: three textured materials, as a textured character's: the skin a 64 x 64 gradient with a checker
        (linear, mipmapped), the clothes a 64 x 64 checker (nearest), the forearms a striped RGBA image under
        alpha MASK (double-sided, every other stripe cut away); TEXCOORD_0 around and along each tube, the
        seam's vertices doubled as exporters write them.
    mtoon : bool
        VRM only: every material toon-shaded as VRoid exports them, its shade colour far from its base colour
        (VRM 1.0: ``VRMC_materials_mtoon`` in each material; VRM 0.x: the ``VRM`` extension's
        ``materialProperties``, shader ``VRM/MToon``, sRGB colours, the glTF materials ``KHR_materials_unlit``
        as UniVRM writes them): a shading shift and toony per material, the base texture as shade multiply
        texture, a rim and a screen-space outline on the skin, a world-space outline lit half on the clothes.
        With ``textured`` the most of it; alone, on the two plain materials.
    normal_map : bool
        With ``textured``: a tangent-space normal map on the clothes (tilted squares, no TANGENT attribute), as
        a textured character's clothes have.
    seed : int
        The texture's colours.
    fmt : str
        ``"glb"`` or ``"bvh"`` (VRM is always ``.vrm``, a glTF binary).
    """

    naming: str = "mixamo"
    prefix: str = "mixamorig:"
    rest: str = "T"
    height: float = 1.75
    shoulder_width: float = 1.0
    arm: float = 1.0
    forearm: float = 1.0
    spine_bones: int = 3
    fingers: bool = True
    twist_bones: bool = False
    roll_seed: int | None = None
    armature: bool = False
    drop: tuple[str, ...] = ()
    mesh: bool = True
    texture: bool = False
    textured: bool = False
    mtoon: bool = False
    normal_map: bool = False
    seed: int = 0
    fmt: str = "glb"

    def __post_init__(self) -> None:
        if self.naming not in NAMINGS:
            raise ValueError(f"naming must be one of {NAMINGS}, not {self.naming!r}")
        if self.rest not in ("T", "A"):
            raise ValueError(f"rest must be 'T' or 'A', not {self.rest!r}")
        if self.fmt not in ("glb", "bvh"):
            raise ValueError(f"fmt must be 'glb' or 'bvh', not {self.fmt!r}")
        if self.fmt == "bvh" and self.naming in ("vrm0", "vrm1"):
            raise ValueError("a VRM character is a glTF file, not BVH")
        if self.normal_map and not self.textured:
            raise ValueError("a normal map needs the textured materials' UVs")
        if self.mtoon and self.naming not in ("vrm0", "vrm1"):
            raise ValueError("MToon materials are a VRM's")
        if not 2 <= self.spine_bones <= 4:
            raise ValueError(f"spine_bones must be 2..4, not {self.spine_bones}")

    @property
    def suffix(self) -> str:
        """The file's extension: ``.vrm``, ``.bvh`` or ``.glb``."""
        return ".vrm" if self.naming in ("vrm0", "vrm1") else f".{self.fmt}"


@dataclass(frozen=True)
class RigTruth:
    """What a reader should find in a generated file.

    ``bone_names`` every bone (node of the skin, BVH joint) in file order; ``parents`` (M,) -1 root;
    ``rest_world`` (M, 3) rest positions in metres, Y up, in the file's world frame; ``facing`` (3,) the
    character's forward direction there; ``joint_map`` our joint name (and ``"pelvis"``) -> bone name for
    every mapped bone (finger joint 4 and ``head_top`` are the tip nodes); ``arm_length`` left, right:
    shoulder -> elbow -> wrist, metres.
    """

    bone_names: tuple[str, ...]
    parents: np.ndarray
    rest_world: np.ndarray
    facing: np.ndarray
    joint_map: dict[str, str]
    arm_length: tuple[float, float]


# ----------------------------------------------------------------------------- the body template


def _spine_count(spec: RigSpec) -> int:
    # ZEGGS names its spine Spine, Spine1..Spine3 and maps Spine1..: one unmapped bone below spine_bones
    return spec.spine_bones + 1 if spec.naming == "zeggs" else spec.spine_bones


def _template(spec: RigSpec) -> list[tuple[str, str | None, np.ndarray, str | None]]:
    """``(key, parent key, world position, our joint name or None)`` of every bone, parents first, before drop."""
    s = spec.height / 1.75
    bones: list[tuple[str, str | None, np.ndarray, str | None]] = []

    def add(key: str, parent: str | None, pos: Any, ours: str | None = None) -> None:
        bones.append((key, parent, np.asarray(pos, dtype=np.float64), ours))

    hips_y, neck_y = 0.98 * s, 1.47 * s
    add("hips", None, (0, hips_y, 0), "pelvis")
    n = _spine_count(spec)
    ours = ("spine_mid", "chest", "upper_chest")[: min(3, n)]
    spine_ours = [None] * (n - len(ours)) + list(ours)
    parent = "hips"
    for k in range(n):
        y = hips_y + (neck_y - hips_y) * (k + 1) / (n + 1)
        if spec.twist_bones and k == n - 1:
            prev_y = hips_y + (neck_y - hips_y) * k / (n + 1)
            add("spine_extra", parent, (0, (prev_y + y) / 2, 0))
            parent = "spine_extra"
        add(f"spine{k}", parent, (0, y, 0), spine_ours[k])
        parent = f"spine{k}"
    chest = parent
    add("neck", chest, (0, neck_y, 0), "neck")
    head_parent = "neck"
    if spec.naming == "zeggs":
        add("neck1", "neck", (0, 1.525 * s, 0), "neck_upper")
        head_parent = "neck1"
    add("head", head_parent, (0, 1.58 * s, 0), "head")
    add("head_top", "head", (0, spec.height, 0), "head_top")
    shoulder_x = 0.18 * s * spec.shoulder_width
    upper, fore = 0.30 * s * spec.arm, 0.26 * s * spec.forearm
    arm_y = 1.42 * s
    for key, side, _, sign in _SIDES:
        first = len(bones)
        add(f"{key}_collar", chest, (sign * 0.035 * s * spec.shoulder_width, arm_y, 0), f"{side}_collar")
        add(f"{key}_upper", f"{key}_collar", (sign * shoulder_x, arm_y, 0), f"{side}_shoulder")
        add(f"{key}_fore", f"{key}_upper", (sign * (shoulder_x + upper), arm_y, 0), f"{side}_elbow")
        wrist_x = shoulder_x + upper + fore
        hand_parent = f"{key}_fore"
        if spec.twist_bones:
            add(f"{key}_twist", f"{key}_fore", (sign * (wrist_x - fore / 2), arm_y, 0))
            hand_parent = f"{key}_twist"
        add(f"{key}_hand", hand_parent, (sign * wrist_x, arm_y, 0), f"{side}_wrist")
        if spec.fingers:
            for finger in FINGERS:
                root = np.array(_FINGER_ROOT[finger]) * s
                along = np.array([0.75, -0.1, 0.65]) if finger == "thumb" else np.array([1.0, 0.0, 0.0])
                along = along / np.linalg.norm(along)
                pos = np.array([wrist_x, arm_y, 0]) + root
                prev = f"{key}_hand"
                for i in range(1, 5):
                    add(f"{key}_{finger}{i}", prev, pos * (sign, 1, 1), f"{side}_{finger}{i}")
                    if i < 4:
                        pos = pos + along * _FINGER_LENGTHS[finger][i - 1] * s
                    prev = f"{key}_{finger}{i}"
        if spec.rest == "A":
            # the whole arm below the shoulder turns down about the upper-arm joint
            pivot = bones[first + 1][2]
            a = np.radians(A_POSE_DEGREES) * sign
            turn = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])
            for b in range(first + 2, len(bones)):
                k, p, pos, o = bones[b]
                bones[b] = (k, p, pivot + turn @ (pos - pivot), o)
    for key, _, _, sign in _SIDES:
        x = sign * 0.09 * s
        add(f"{key}_upleg", "hips", (x, 0.92 * s, 0))
        add(f"{key}_leg", f"{key}_upleg", (x, 0.5 * s, 0.005 * s))
        add(f"{key}_foot", f"{key}_leg", (x, 0.08 * s, -0.01 * s))
        add(f"{key}_toe", f"{key}_foot", (x, 0.015 * s, 0.12 * s))
        add(f"{key}_toe_end", f"{key}_toe", (x, 0.015 * s, 0.2 * s))
    return bones


# ----------------------------------------------------------------------------- names


def _sideless_name(key: str) -> str:
    """A name that says the part but not the side: ``arm_a`` (the right) and ``arm_b`` (the left), so that neither
    the names nor their order tells left from right."""
    if key[:2] in ("L_", "R_"):
        return f"{key[2:]}_{'b' if key[0] == 'L' else 'a'}"
    return key


def _mixamo_name(key: str, spec: RigSpec) -> str:
    fixed = {"hips": "Hips", "spine_extra": "Spine_extra", "neck": "Neck", "neck1": "Neck1", "head": "Head"}
    if key in fixed:
        name = fixed[key]
    elif key.startswith("spine"):
        k = int(key[5:])
        name = "Spine" if k == 0 else f"Spine{k}"
    elif key == "head_top":
        name = "HeadEnd" if spec.naming == "zeggs" else "HeadTop_End"
    else:
        side = "Left" if key[0] == "L" else "Right"
        part = key[2:]
        parts = {
            "collar": "Shoulder",
            "upper": "Arm",
            "fore": "ForeArm",
            "twist": "ForeArmTwist",
            "hand": "Hand",
            "upleg": "UpLeg",
            "leg": "Leg",
            "foot": "Foot",
            "toe": "ToeBase",
            "toe_end": "Toe_End",
        }
        name = side + (parts[part] if part in parts else f"Hand{part[:-1].capitalize()}{part[-1]}")
    return (spec.prefix if spec.naming in ("mixamo", "mirrored") else "") + name


_FAMILY_PARTS = {
    # key part: (blender "Part.L", unreal "part_l", CC "CC_Base_L_Part", UMA "LeftPart")
    "collar": ("Shoulder", "clavicle", "Clavicle", "Shoulder"),
    "upper": ("UpperArm", "upperarm", "Upperarm", "Arm"),
    "fore": ("LowerArm", "lowerarm", "Forearm", "ForeArm"),
    "twist": ("LowerArmTwist", "lowerarm_twist_01", "ForearmTwist01", "ForeArmTwist"),
    "hand": ("Hand", "hand", "Hand", "Hand"),
    "upleg": ("UpperLeg", "thigh", "Thigh", "UpLeg"),
    "leg": ("LowerLeg", "calf", "Calf", "Leg"),
    "foot": ("Foot", "foot", "Foot", "Foot"),
    "toe": ("Toe", "ball", "ToeBase", "ToeBase"),
    "toe_end": ("Toe_end", "ball_end", "ToeBaseNub", "Toe_End"),
}
_FAMILY_CENTRE = {
    "hips": ("Hips", "pelvis", "CC_Base_Hip", "Hips"),
    "spine_extra": ("SpineTwist", "spine_twist_01", "CC_Base_SpineTwist", "SpineTwist"),
    "neck": ("Neck", "neck_01", "CC_Base_NeckTwist01", "Neck"),
    "neck1": ("Neck.001", "neck_02", "CC_Base_NeckTwist02", "Neck1"),
    "head": ("Head", "head", "CC_Base_Head", "Head"),
    "head_top": ("Head_end", "head_end", "CC_Base_HeadNub", "HeadTop_End"),
}
_CC_FINGER = {"thumb": "Thumb", "index": "Index", "middle": "Mid", "ring": "Ring", "pinky": "Pinky"}


def _family_name(key: str, spec: RigSpec) -> str:
    """A bone's name in the Blender (``.L``/``.R``), Unreal (``_l``/``_r``), Character Creator (``CC_Base_L_``) or
    UMA (``Left``, fingers ``HandFinger02_01``) family; finger tips named so that no name says which they are."""
    f = FAMILY_NAMINGS.index(spec.naming)
    if key in _FAMILY_CENTRE:
        return _FAMILY_CENTRE[key][f]
    if key.startswith("spine"):
        k = int(key[5:])
        return (
            "Spine" if k == 0 else f"Spine.{k:03d}",
            f"spine_{k + 1:02d}",
            "CC_Base_" + ("Waist", "Spine01", "Spine02", "Spine03")[k],
            ("LowerBack", "Spine", "Spine1", "Spine2")[k],
        )[f]
    s, part = key[0], key[2:]
    if part in _FAMILY_PARTS:
        word = _FAMILY_PARTS[part][f]
        side = "Left" if s == "L" else "Right"
        return (f"{word}.{s}", f"{word}_{s.lower()}", f"CC_Base_{s}_{word}", side + word)[f]
    finger, i = part[:-1], int(part[-1])
    side = "Left" if s == "L" else "Right"
    if i == 4:  # the tip: a leaf whose name says no phalanx
        tips = (f"{finger}_tip.{s}", f"{finger}_leaf_{s.lower()}", f"CC_Base_{s}_{_CC_FINGER[finger]}Nub")
        return (*tips, f"{side}{finger}Tip")[f]
    return (
        f"{'' if finger == 'thumb' else 'f_'}{finger}.{i:02d}.{s}",
        f"{finger}_{i:02d}_{s.lower()}",
        f"CC_Base_{s}_{_CC_FINGER[finger]}{i}",
        f"{side}HandFinger{FINGERS.index(finger) + 1:02d}_{i:02d}",
    )[f]


def _vrm_names(key: str, spec: RigSpec, ours: str | None) -> tuple[str, str | None]:
    """(node name, humanoid bone name or None) of a VRM character's bone."""
    n = _spine_count(spec)
    centre = {"hips": "Hips", "neck": "Neck", "head": "Head"}
    if key in centre:
        return f"J_Bip_C_{centre[key]}", key
    if key == "head_top":
        return "J_Bip_C_Head_end", None
    if key == "spine_extra":
        return "J_Sec_C_SpineTwist", None
    if key.startswith("spine"):
        human = {"spine_mid": "spine", "chest": "chest", "upper_chest": "upperChest"}.get(ours or "")
        if human is None:
            return f"J_Sec_C_Spine{int(key[5:])}of{n}", None
        return f"J_Bip_C_{human[0].upper()}{human[1:]}", human
    side, lower = ("L", "left") if key[0] == "L" else ("R", "right")
    part = key[2:]
    limbs = {
        "collar": ("Shoulder", "Shoulder"),
        "upper": ("UpperArm", "UpperArm"),
        "fore": ("LowerArm", "LowerArm"),
        "hand": ("Hand", "Hand"),
        "upleg": ("UpperLeg", "UpperLeg"),
        "leg": ("LowerLeg", "LowerLeg"),
        "foot": ("Foot", "Foot"),
        "toe": ("ToeBase", "Toes"),
    }
    if part in limbs:
        node, human = limbs[part]
        return f"J_Bip_{side}_{node}", lower + human
    if part == "twist":
        return f"J_Sec_{side}_LowerArmTwist", None
    if part == "toe_end":
        return f"J_Bip_{side}_ToeBase_end", None
    finger, i = _VRM_FINGER[part[:-1]], int(part[-1])
    if i == 4:
        return f"J_Bip_{side}_{finger}3_end", None
    if finger == "Thumb" and spec.naming == "vrm1":
        phalanx = ("Metacarpal", "Proximal", "Distal")[i - 1]
    else:
        phalanx = ("Proximal", "Intermediate", "Distal")[i - 1]
    return f"J_Bip_{side}_{finger}{i}", f"{lower}{finger}{phalanx}"


def _bones(spec: RigSpec) -> list[tuple[str, int, np.ndarray, str | None, str | None]]:
    """``(name, parent index, world position, our joint, VRM humanoid bone)`` of the file's bones, file order."""
    template = _template(spec)
    ours_of = {k: o for k, _, _, o in template}
    dropped = set()
    for joint in spec.drop:
        keys = [k for k, _, _, o in template if o == joint]
        if not keys or joint == "pelvis":
            raise ValueError(f"cannot drop {joint!r}: no bone of this rig is that joint (or it is the root)")
        dropped.add(keys[0])
    parent_of = {k: p for k, p, _, _ in template}
    kept = [b for b in template if b[0] not in dropped]
    index = {b[0]: i for i, b in enumerate(kept)}
    out: list[tuple[str, int, np.ndarray, str | None, str | None]] = []
    for i, (key, parent, pos, ours) in enumerate(kept):
        while parent is not None and parent in dropped:
            parent = parent_of[parent]
        human: str | None = None
        if spec.naming in ("vrm0", "vrm1"):
            name, human = _vrm_names(key, spec, ours_of[key])
            pos = pos * (-1, 1, -1) if spec.naming == "vrm0" else pos  # VRM 0.x faces -Z
        elif spec.naming == "custom":
            name = f"bone_{i:02d}"
        elif spec.naming == "sideless":
            name = _sideless_name(key)
        elif spec.naming == "mirrored":  # Mixamo's names, Left on the character's right
            name = _mixamo_name(key.replace("L_", "X_").replace("R_", "L_").replace("X_", "R_"), spec)
        elif spec.naming == "nameless":
            name = f"node{i + (1 if spec.armature else 0)}"  # what a reader calls a glTF node without a name
        elif spec.naming in FAMILY_NAMINGS:
            name = _family_name(key, spec)
        else:
            name = _mixamo_name(key, spec)
        out.append((name, -1 if parent is None else index[parent], pos, ours, human))
    return out


def truth(spec: RigSpec) -> RigTruth:
    """What the file of ``spec`` holds (see :class:`RigTruth`)."""
    bones = _bones(spec)
    template = {o: p for _, _, p, o in _template(spec) if o is not None}
    lengths = tuple(
        float(
            np.linalg.norm(template[f"{s}_elbow"] - template[f"{s}_shoulder"])
            + np.linalg.norm(template[f"{s}_wrist"] - template[f"{s}_elbow"])
        )
        for s in ("left", "right")
    )
    return RigTruth(
        bone_names=tuple(b[0] for b in bones),
        parents=np.array([b[1] for b in bones], dtype=np.int64),
        rest_world=np.array([b[2] for b in bones], dtype=np.float64),
        facing=np.array([0.0, 0.0, -1.0 if spec.naming == "vrm0" else 1.0]),
        joint_map={b[3]: b[0] for b in bones if b[3] is not None},
        arm_length=(lengths[0], lengths[1]),
    )


def custom_map(spec: RigSpec) -> dict[str, Any]:
    """The JSON joint map of a rig: ``{"pelvis": bone, "joints": {our joint: bone}}``."""
    joints = dict(truth(spec).joint_map)
    return {"pelvis": joints.pop("pelvis"), "joints": joints}


# ----------------------------------------------------------------------------- glTF


def _random_rotations(n: int, seed: int) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _quaternion(r: np.ndarray) -> list[float]:
    """``(x, y, z, w)`` of a rotation matrix, ``w >= 0``."""
    w = np.sqrt(max(0.0, 1 + np.trace(r))) / 2
    x = np.copysign(np.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    q = np.array([x, y, z, w])
    q /= np.linalg.norm(q)
    return [float(v) for v in q]


def _png(width: int, height: int, rgb: np.ndarray) -> bytes:
    """A plain 8-bit RGB PNG of ``rgb`` (height, width, 3) uint8."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    rows = b"".join(b"\0" + rgb[y].tobytes() for y in range(height))
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b"")


_SKIN_PARTS = ("head", "wrist", "thumb", "index", "middle", "ring", "pinky")


def _tubes(bones: list, spec: RigSpec) -> tuple[np.ndarray, ...]:
    """An 8-sided open tube around every bone segment (parent -> child), weighted to the parent bone and
    blended with its neighbours at the ends: positions, normals, uvs, joints, weights, (skin, cloth) faces."""
    pos, nor, uv, jnt, wgt = [], [], [], [], []
    faces: tuple[list, list, list] = ([], [], [])
    parents = [b[1] for b in bones]
    for c, (_, p, end, _, _) in enumerate(bones):
        if p < 0:
            continue
        start = bones[p][2]
        axis = end - start
        length = float(np.linalg.norm(axis))
        if length < 1e-4:
            continue
        d = axis / length
        helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        u = np.cross(helper, d)
        u /= np.linalg.norm(u)
        v = np.cross(d, u)
        radius = float(np.clip(0.2 * length, 0.005, 0.075)) * spec.height / 1.75
        pp = parents[p]
        base = len(pos)
        for end_ring, centre in ((0, start), (1, end)):
            other = pp if end_ring == 0 else c
            for k in range(9):
                theta = 2 * np.pi * k / 8
                n = np.cos(theta) * u + np.sin(theta) * v
                pos.append(centre + radius * n)
                nor.append(n)
                uv.append((k / 8, float(end_ring)))
                if other >= 0:
                    jnt.append((p, other, 0, 0))
                    wgt.append((0.75, 0.25, 0, 0))
                else:
                    jnt.append((p, 0, 0, 0))
                    wgt.append((1.0, 0, 0, 0))
        name = bones[p][3] or ""
        part = faces[0] if any(s in name for s in _SKIN_PARTS) else faces[1]
        if spec.textured and "elbow" in name:
            part = faces[2]
        for k in range(8):
            i0, i1, j0, j1 = base + k, base + k + 1, base + 9 + k, base + 9 + k + 1
            part.extend([(i0, i1, j1), (i0, j1, j0)])
    return (
        np.array(pos, dtype=np.float32),
        np.array(nor, dtype=np.float32),
        np.array(uv, dtype=np.float32),
        np.array(jnt, dtype=np.uint8),
        np.array(wgt, dtype=np.float32),
        np.array(faces[0], dtype=np.uint32).reshape(-1),
        np.array(faces[1], dtype=np.uint32).reshape(-1),
        np.array(faces[2], dtype=np.uint32).reshape(-1),
    )


def _gltf(spec: RigSpec) -> bytes:
    bones = _bones(spec)
    m = len(bones)
    rot = (
        np.tile(np.eye(3), (m, 1, 1)) if spec.roll_seed is None else _random_rotations(m, spec.roll_seed)
    )  # each bone's rest local rotation
    if spec.armature:
        # FBX-style: bones in centimetres, Z up, inside a node turned +90 degrees about X and scaled 0.01
        inner = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]) * 100.0
        frame_pos = [inner @ b[2] for b in bones]
    else:
        frame_pos = [b[2] for b in bones]
    offset = 1 if spec.armature else 0
    nodes: list[dict[str, Any]] = []
    if spec.armature:
        h = float(np.sqrt(0.5))
        nodes.append({"name": "Armature", "rotation": [h, 0.0, 0.0, h], "scale": [0.01, 0.01, 0.01], "children": []})
    world_rot: list[np.ndarray] = []
    for i, (name, p, _, _, _) in enumerate(bones):
        parent_rot = world_rot[p] if p >= 0 else np.eye(3)
        t = parent_rot.T @ (frame_pos[i] - (frame_pos[p] if p >= 0 else 0.0))
        world_rot.append(parent_rot @ rot[i])
        node: dict[str, Any] = {"translation": [float(x) for x in t]}
        if spec.naming != "nameless":
            node = {"name": name, **node}
        if spec.roll_seed is not None:
            node["rotation"] = _quaternion(rot[i])
        nodes.append(node)
        if p >= 0:
            nodes[p + offset].setdefault("children", []).append(i + offset)
        elif spec.armature:
            nodes[0]["children"].append(i + offset)
    buf = GlbBuffer()
    joints = list(range(offset, offset + m))
    world = node_matrices(nodes, {}, 1)[0]
    inverse_bind = np.linalg.inv(world[offset : offset + m])
    ibm = buf.add(np.transpose(inverse_bind, (0, 2, 1)).reshape(m, 16), "MAT4", FLOAT)
    skin: dict[str, Any] = {"joints": joints, "inverseBindMatrices": ibm, "skeleton": offset}
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "gesturekit test rigs"},
        "scene": 0,
        "scenes": [{"name": spec.naming, "nodes": [0]}],
        "nodes": nodes,
        "skins": [skin],
    }
    if spec.mesh:
        pos, nor, uv, jnt, wgt, skin_faces, cloth_faces, mask_faces = _tubes(bones, spec)
        attributes = {
            "POSITION": buf.add(pos, "VEC3", FLOAT, target=ARRAY_BUFFER, bounds=True),
            "NORMAL": buf.add(nor, "VEC3", FLOAT, target=ARRAY_BUFFER),
            "JOINTS_0": buf.add(jnt, "VEC4", UBYTE, target=ARRAY_BUFFER),
            "WEIGHTS_0": buf.add(wgt, "VEC4", FLOAT, target=ARRAY_BUFFER),
        }
        materials = [
            {
                "name": "skin",
                "pbrMetallicRoughness": {"baseColorFactor": [0.87, 0.68, 0.57, 1.0], "metallicFactor": 0.0},
            },
            {
                "name": "cloth",
                "pbrMetallicRoughness": {"baseColorFactor": [0.25, 0.35, 0.6, 1.0], "metallicFactor": 0.0},
            },
        ]
        if spec.texture:
            attributes["TEXCOORD_0"] = buf.add(uv, "VEC2", FLOAT, target=ARRAY_BUFFER)
            rng = np.random.default_rng(spec.seed)
            size = 8
            checker = ((np.arange(size)[:, None] + np.arange(size)[None, :]) % 2).astype(np.uint8)
            tint = rng.integers(96, 256, size=3, dtype=np.uint8)
            rgb = np.where(checker[..., None] == 1, tint, 255 - tint // 2).astype(np.uint8)
            png = _png(size, size, rgb)
            buf.data.extend(b"\0" * (-len(buf.data) % 4))
            buf.views.append({"buffer": 0, "byteOffset": len(buf.data), "byteLength": len(png)})
            buf.data.extend(png)
            doc["images"] = [{"name": "checker", "bufferView": len(buf.views) - 1, "mimeType": "image/png"}]
            doc["samplers"] = [{"magFilter": 9728, "minFilter": 9728}]
            doc["textures"] = [{"sampler": 0, "source": 0}]
            materials[1]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
        if spec.textured:
            attributes["TEXCOORD_0"] = buf.add(uv, "VEC2", FLOAT, target=ARRAY_BUFFER)
            _textured_materials(doc, buf, materials)
            if spec.normal_map:
                _normal_map(doc, buf, materials[1])
        primitives = []
        for material, faces in enumerate((skin_faces, cloth_faces, mask_faces)):
            if len(faces):
                index = buf.add(faces, "SCALAR", UINT, target=ELEMENT_ARRAY_BUFFER)
                primitives.append({"attributes": attributes, "indices": index, "material": material})
        doc["materials"] = materials
        doc["meshes"] = [{"name": "body", "primitives": primitives}]
        nodes.append({"name": "body", "mesh": 0, "skin": 0})
        doc["scenes"][0]["nodes"].append(len(nodes) - 1)
    _vrm_extension(doc, spec, bones, offset)
    if spec.mtoon and spec.mesh:
        _mtoon_materials(doc, spec)
    doc["bufferViews"] = buf.views
    doc["accessors"] = buf.accessors
    doc["buffers"] = [{"byteLength": len(buf.data) + (-len(buf.data) % 4)}]
    return glb_bytes(doc, bytes(buf.data))


def _embed_png(buf: GlbBuffer, png: bytes) -> int:
    """Append a PNG to the binary chunk as a buffer view; the view's index."""
    buf.data.extend(b"\0" * (-len(buf.data) % 4))
    buf.views.append({"buffer": 0, "byteOffset": len(buf.data), "byteLength": len(png)})
    buf.data.extend(png)
    return len(buf.views) - 1


def _png_rgba(rgba: np.ndarray) -> bytes:
    """An 8-bit RGBA PNG of ``rgba`` (height, width, 4) uint8 (written by Pillow, as tools write them)."""
    import io

    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(out, format="PNG")
    return out.getvalue()


def _textured_materials(doc: dict[str, Any], buf: GlbBuffer, materials: list[dict[str, Any]]) -> None:
    """Three images, samplers and textures in ``doc``; the skin, cloth and a third, masked material."""
    n = 64
    y, x = np.mgrid[0:n, 0:n]
    checker = ((x // 8 + y // 8) % 2).astype(np.uint8)
    gradient = np.stack([64 + 3 * x, 96 + 2 * y, 140 + 60 * checker], axis=-1).clip(0, 255).astype(np.uint8)
    cloth = np.where(checker[..., None] == 1, [40, 70, 150], [230, 200, 90]).astype(np.uint8)
    stripes = np.zeros((n, n, 4), dtype=np.uint8)
    stripes[..., :3] = np.array([200, 60, 60]) + (y[..., None] * np.array([0, 2, 1]))
    stripes[..., 3] = np.where((x // 8) % 2 == 0, 255, 0)
    pngs = [_png(n, n, gradient), _png(n, n, cloth), _png_rgba(stripes)]
    doc["images"] = [
        {"name": name, "bufferView": _embed_png(buf, png), "mimeType": "image/png"}
        for name, png in zip(("skin", "cloth", "stripes"), pngs)
    ]
    linear, nearest = 9729, 9728
    doc["samplers"] = [
        {"magFilter": linear, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497},
        {"magFilter": nearest, "minFilter": nearest},
    ]
    doc["textures"] = [{"sampler": 0, "source": 0}, {"sampler": 1, "source": 1}, {"sampler": 0, "source": 2}]
    materials[0]["pbrMetallicRoughness"] = {
        "baseColorFactor": [1.0, 0.9, 0.85, 1.0],
        "baseColorTexture": {"index": 0},
        "metallicFactor": 0.0,
        "roughnessFactor": 1.0,
    }
    materials[1]["pbrMetallicRoughness"] = {
        "baseColorFactor": [0.9, 0.95, 1.0, 1.0],
        "baseColorTexture": {"index": 1},
        "metallicFactor": 0.0,
        "roughnessFactor": 1.0,
    }
    materials.append(
        {
            "name": "sleeves",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 2}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "alphaMode": "MASK",
            "alphaCutoff": 0.5,
            "doubleSided": True,
        }
    )


def _normal_map(doc: dict[str, Any], buf: GlbBuffer, material: dict[str, Any]) -> None:
    """A tangent-space normal map (64 x 64, squares tilted +-0.6 across and +-0.5 along) as ``material``'s."""
    n = 64
    y, x = np.mgrid[0:n, 0:n]
    nx, ny = np.where((x // 16) % 2 == 0, 0.6, -0.6), np.where((y // 16) % 2 == 0, 0.5, -0.5)
    rgb = np.stack([nx, ny, np.sqrt(1 - nx**2 - ny**2)], axis=-1) * 127.5 + 127.5
    doc["images"].append(
        {"name": "bumps", "bufferView": _embed_png(buf, _png(n, n, rgb.astype(np.uint8))), "mimeType": "image/png"}
    )
    doc["textures"].append({"sampler": 0, "source": len(doc["images"]) - 1})
    material["normalTexture"] = {"index": len(doc["textures"]) - 1, "scale": 1.0}


def _vrm_extension(doc: dict[str, Any], spec: RigSpec, bones: list, offset: int) -> None:
    humans = [(b[4], i + offset) for i, b in enumerate(bones) if b[4] is not None]
    if spec.naming == "vrm0":
        meta = {"title": "generated", "version": "1", "author": "gesturekit tests", "licenseName": "CC0"}
        human_bones = [{"bone": h, "node": n, "useDefaultValues": True} for h, n in humans]
        doc["extensionsUsed"] = ["VRM"]
        doc["extensions"] = {"VRM": {"specVersion": "0.0", "meta": meta, "humanoid": {"humanBones": human_bones}}}
    elif spec.naming == "vrm1":
        meta = {"name": "generated", "licenseUrl": "https://vrm.dev/licenses/1.0/", "authors": ["gesturekit tests"]}
        doc["extensionsUsed"] = ["VRMC_vrm"]
        doc["extensions"] = {
            "VRMC_vrm": {
                "specVersion": "1.0",
                "meta": meta,
                "humanoid": {"humanBones": {h: {"node": n} for h, n in humans}},
            }
        }


#: Each material's toon shading (VRM 1.0 form, linear colours), by the material's name: the shade colours far from
#: the base colours (a renderer that ignores MToon draws another picture), the skin with a rim and an outline in
#: screen coordinates, the clothes with an outline in world coordinates lit half, the sleeves a hard edge.
_MTOON = {
    "skin": {
        "shadeColorFactor": [0.55, 0.22, 0.45],
        "shadingShiftFactor": -0.1,
        "shadingToonyFactor": 0.9,
        "parametricRimColorFactor": [0.3, 0.22, 0.1],
        "parametricRimFresnelPowerFactor": 3.0,
        "parametricRimLiftFactor": 0.05,
        "rimLightingMixFactor": 0.5,
        "outlineWidthMode": "screenCoordinates",
        "outlineWidthFactor": 0.006,
        "outlineColorFactor": [0.12, 0.04, 0.08],
        "outlineLightingMixFactor": 0.0,
    },
    "cloth": {
        "shadeColorFactor": [0.08, 0.3, 0.12],
        "shadingShiftFactor": 0.15,
        "shadingToonyFactor": 0.75,
        "outlineWidthMode": "worldCoordinates",
        "outlineWidthFactor": 0.006,
        "outlineColorFactor": [0.05, 0.05, 0.2],
        "outlineLightingMixFactor": 0.5,
    },
    "sleeves": {"shadeColorFactor": [0.35, 0.02, 0.3], "shadingShiftFactor": 0.0, "shadingToonyFactor": 0.97},
}


def _srgb(values: list[float]) -> list[float]:
    """Linear colours as a VRM 0.x stores them (Unity's gamma space, three-vrm reads them back by ``** 2.2``)."""
    return [round(float(v) ** (1 / 2.2), 6) for v in values]


def _mtoon_materials(doc: dict[str, Any], spec: RigSpec) -> None:
    """Toon-shade every material of ``doc`` (:data:`_MTOON`), in the form of the spec's VRM version."""
    materials = doc["materials"]
    if spec.naming == "vrm1":
        for m in materials:
            ext = {"specVersion": "1.0", **_MTOON[m["name"]]}
            base = m["pbrMetallicRoughness"].get("baseColorTexture")
            if base is not None and m["name"] != "sleeves":
                ext["shadeMultiplyTexture"] = {"index": base["index"]}
            m["extensions"] = {"VRMC_materials_mtoon": ext}
            if m["name"] == "cloth":
                m["emissiveFactor"] = [0.02, 0.02, 0.06]
        doc["extensionsUsed"].append("VRMC_materials_mtoon")
        return
    # VRM 0.x, as UniVRM writes it: unlit glTF materials, the MToon beside them
    properties = []
    for m in materials:
        v1 = _MTOON[m["name"]]
        pbr = m["pbrMetallicRoughness"]
        color = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
        textures = {}
        if "baseColorTexture" in pbr:
            textures["_MainTex"] = pbr["baseColorTexture"]["index"]
            if m["name"] != "sleeves":
                textures["_ShadeTexture"] = pbr["baseColorTexture"]["index"]
        floats = {
            "_ShadeShift": -float(v1["shadingShiftFactor"]),
            "_ShadeToony": float(v1["shadingToonyFactor"]),
            "_CullMode": 0.0 if m.get("doubleSided") else 2.0,
            "_Cutoff": float(m.get("alphaCutoff", 0.5)),
            "_OutlineWidthMode": {"none": 0.0, "worldCoordinates": 1.0, "screenCoordinates": 2.0}[
                v1.get("outlineWidthMode", "none")
            ],
            "_OutlineWidth": 100.0 * float(v1.get("outlineWidthFactor", 0.0)),
            "_OutlineColorMode": 1.0 if v1.get("outlineLightingMixFactor", 0.0) > 0 else 0.0,
            "_OutlineLightingMix": float(v1.get("outlineLightingMixFactor", 0.0)),
            "_RimFresnelPower": float(v1.get("parametricRimFresnelPowerFactor", 1.0)),
            "_RimLift": float(v1.get("parametricRimLiftFactor", 0.0)),
            "_RimLightingMix": float(v1.get("rimLightingMixFactor", 0.0)),
            "_ZWrite": 1.0,
        }
        vectors = {
            "_Color": [*_srgb(color[:3]), float(color[3])],
            "_ShadeColor": [*_srgb(v1["shadeColorFactor"]), 1.0],
            "_RimColor": [*_srgb(v1.get("parametricRimColorFactor", [0.0, 0.0, 0.0])), 1.0],
            "_OutlineColor": [*_srgb(v1.get("outlineColorFactor", [0.0, 0.0, 0.0])), 1.0],
            "_MainTex": [0.0, 0.0, 1.0, 1.0],
        }
        keywords = {"_ALPHATEST_ON": True} if m.get("alphaMode") == "MASK" else {}
        properties.append(
            {
                "name": m["name"],
                "shader": "VRM/MToon",
                "renderQueue": 2450 if keywords else 2000,
                "floatProperties": floats,
                "vectorProperties": vectors,
                "textureProperties": textures,
                "keywordMap": keywords,
                "tagMap": {"RenderType": "TransparentCutout" if keywords else "Opaque"},
            }
        )
        m["extensions"] = {"KHR_materials_unlit": {}}
    doc["extensions"]["VRM"]["materialProperties"] = properties
    doc["extensionsUsed"].append("KHR_materials_unlit")


# ----------------------------------------------------------------------------- BVH


def _bvh(spec: RigSpec) -> bytes:
    """Rest offsets only (a BVH joint has no rest rotation, so ``roll_seed`` and ``armature`` do not apply)."""
    bones = _bones(spec)
    children: list[list[int]] = [[] for _ in bones]
    for i, b in enumerate(bones):
        if b[1] >= 0:
            children[b[1]].append(i)
    lines = ["HIERARCHY"]

    def cm(v: np.ndarray) -> str:
        return " ".join(f"{x * 100:.6f}" for x in v)

    def write(i: int, depth: int) -> None:
        pad = "\t" * depth
        name, p, pos, _, _ = bones[i]
        if p < 0:
            lines.append(f"ROOT {name}")
            lines.append(pad + "{")
            lines.append(f"{pad}\tOFFSET {cm(pos)}")
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}JOINT {name}")
            lines.append(pad + "{")
            lines.append(f"{pad}\tOFFSET {cm(pos - bones[p][2])}")
            lines.append(f"{pad}\tCHANNELS 3 Zrotation Xrotation Yrotation")
        for c in children[i]:
            write(c, depth + 1)
        if not children[i]:
            tail = (pos - bones[p][2]) * 0.3 if p >= 0 else np.array([0.0, 0.1, 0.0])
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {cm(tail)}", f"{pad}\t}}"])
        lines.append(pad + "}")

    write(0, 0)
    joints = [line.split()[1] for line in lines if line.split()[0] in ("ROOT", "JOINT")]
    assert joints == [b[0] for b in bones], "the bones' order is the hierarchy's depth-first order"
    n_channels = 6 + 3 * (len(bones) - 1)
    frame = " ".join(["0.000000"] * n_channels)
    lines += ["MOTION", "Frames: 2", "Frame Time: 0.0333333", frame, frame, ""]
    return "\n".join(lines).encode("ascii")


def cmu_bvh(*, unit: float = 0.01, leg_up: bool = False) -> bytes:
    """A skeleton laid out as the widely used BVH conversion of the CMU mocap database writes it: zero offsets for
    ``LHipJoint``/``RHipJoint``, ``LowerBack``, ``Neck`` and both ``*Shoulder`` bones (so the chest's children all
    start where it does), ``Neck1`` between neck and head, ``LeftFingerBase``, ``LeftHandIndex1`` and ``LThumb``
    on the hand. T-pose, Y up, facing +Z, 1.72 m tall; ``unit`` metres per file unit (0.01: centimetres).
    ``leg_up``: the left leg points up from the hip in the zero pose, as in a rig whose rest is not standing."""
    j: list[tuple[str, str | None, tuple[float, float, float]]] = [("Hips", None, (0.0, 0.95, 0.0))]
    for s, side, x in (("L", "Left", 1.0), ("R", "Right", -1.0)):
        foot = (0.09 * x, 1.80, 0.0) if leg_up and x > 0 else (0.09 * x, 0.08, 0.0)
        knee = (0.09 * x, 1.35, 0.0) if leg_up and x > 0 else (0.09 * x, 0.50, 0.0)
        j += [
            (f"{s}HipJoint", "Hips", (0.0, 0.95, 0.0)),
            (f"{side}UpLeg", f"{s}HipJoint", (0.09 * x, 0.90, 0.0)),
            (f"{side}Leg", f"{side}UpLeg", knee),
            (f"{side}Foot", f"{side}Leg", foot),
            (f"{side}ToeBase", f"{side}Foot", (foot[0], foot[1] - 0.06 * (1 if foot[1] < 1 else -1), 0.12)),
        ]
    j += [
        ("LowerBack", "Hips", (0.0, 0.95, 0.0)),
        ("Spine", "LowerBack", (0.0, 1.10, 0.0)),
        ("Spine1", "Spine", (0.0, 1.40, 0.0)),
        ("Neck", "Spine1", (0.0, 1.40, 0.0)),
        ("Neck1", "Neck", (0.0, 1.47, 0.0)),
        ("Head", "Neck1", (0.0, 1.55, 0.0)),
    ]
    for s, side, x in (("L", "Left", 1.0), ("R", "Right", -1.0)):
        j += [
            (f"{side}Shoulder", "Spine1", (0.0, 1.40, 0.0)),
            (f"{side}Arm", f"{side}Shoulder", (0.18 * x, 1.40, 0.0)),
            (f"{side}ForeArm", f"{side}Arm", (0.47 * x, 1.40, 0.0)),
            (f"{side}Hand", f"{side}ForeArm", (0.72 * x, 1.40, 0.0)),
            (f"{side}FingerBase", f"{side}Hand", (0.80 * x, 1.40, 0.0)),
            (f"{side}HandIndex1", f"{side}FingerBase", (0.86 * x, 1.40, 0.0)),
            (f"{s}Thumb", f"{side}Hand", (0.76 * x, 1.39, 0.03)),
        ]
    index = {name: i for i, (name, _, _) in enumerate(j)}
    pos = {name: np.array(p) for name, _, p in j}
    children: dict[str | None, list[str]] = {}
    for name, parent, _ in j:
        children.setdefault(parent, []).append(name)
    lines = ["HIERARCHY"]
    order: list[str] = []

    def num(v: np.ndarray) -> str:
        return " ".join(f"{c / unit:.6f}" for c in v)

    def write(name: str, depth: int) -> None:
        pad = "\t" * depth
        parent = j[index[name]][1]
        order.append(name)
        lines.append(f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}")
        lines.append(pad + "{")
        lines.append(f"{pad}\tOFFSET {num(pos[name] - (pos[parent] if parent else 0.0))}")
        if parent is None:
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
        else:
            lines.append(f"{pad}\tCHANNELS 3 Zrotation Yrotation Xrotation")
        for c in children.get(name, []):
            write(c, depth + 1)
        if name not in children:
            tail = np.array([0.0, 0.17, 0.0]) if name == "Head" else np.array([0.0, 0.0, 0.02])
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {num(tail)}", f"{pad}\t}}"])
        lines.append(pad + "}")

    write("Hips", 0)
    frame = " ".join(["0.000000"] * (6 + 3 * (len(order) - 1)))
    lines += ["MOTION", "Frames: 2", "Frame Time: 0.0083333", frame, frame, ""]
    return "\n".join(lines).encode("ascii")


# ----------------------------------------------------------------------------- files


def rig_files(spec: RigSpec) -> dict[str, bytes]:
    """The file of ``spec``: ``{"<naming>.<glb|vrm|bvh>": bytes}``."""
    data = _bvh(spec) if spec.suffix == ".bvh" else _gltf(spec)
    return {f"{spec.naming}{spec.suffix}": data}


def write_rig(folder: Path, spec: RigSpec, name: str | None = None) -> Path:
    """Write the file of ``spec`` into ``folder`` (named ``name`` + its extension if given); its path."""
    ((default, data),) = rig_files(spec).items()
    path = Path(folder) / (default if name is None else Path(name).stem + spec.suffix)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    return path


#: The named characters of the acceptance tests.
CASES: dict[str, RigSpec] = {
    "mixamo_t": RigSpec(),
    "mixamo_a_rolled": RigSpec(rest="A", roll_seed=1, armature=True, arm=1.08, forearm=1.08),
    "vrm0_a": RigSpec(naming="vrm0", rest="A", roll_seed=2, shoulder_width=1.15, spine_bones=2),
    "vrm1_t": RigSpec(naming="vrm1", roll_seed=4, height=1.55, texture=True),
    "bvh_zeggs_a": RigSpec(naming="zeggs", fmt="bvh", rest="A", height=1.85),
    "no_fingers": RigSpec(fingers=False),
    "twist": RigSpec(twist_bones=True, roll_seed=3),
    "missing_elbow": RigSpec(drop=("left_elbow",)),
    "custom_names": RigSpec(naming="custom", roll_seed=5),
    "zeggs_glb": RigSpec(naming="zeggs", texture=True, mesh=True),
}
