"""Which bone of a user's humanoid is which of our joints: the VRM humanoid map, Mixamo names, our BVH presets, JSON.

A *bone map* names, for some of our 55 joints (:data:`gesturekit.skeleton.JOINT_NAMES`)
and for ``"pelvis"``, the bone of a user's skeleton that sits at that joint.
The pelvis, the first spine bone, the head and both arms down to the hands
(:data:`REQUIRED`) must be found; the rest is optional: a rig without finger
bones keeps its hands still, a rig without collars hangs its arms from the
chest, an extra spine or twist bone between two matched ones rides along with
the upper of the two.

The maps, tried in this order:

* **a JSON map** given by the user, in the form of the BVH joint maps
  (:func:`gesturekit.datasets.presets.load_joint_map`):
  ``{"pelvis": "Hips", "joints": {"spine_mid": "Spine", ...}}``, here with any
  subset of the joints besides :data:`REQUIRED`;
* **the VRM humanoid** of a VRM file (0.x: ``extensions.VRM.humanoid.humanBones``,
  a list of ``{"bone", "node"}``; 1.0: ``extensions.VRMC_vrm.humanoid.humanBones``,
  ``{bone: {"node"}}``), through :data:`VRM_BONES`;
* **names**: Mixamo's (:data:`MIXAMO`, with any prefix ending in ``:``, as in
  ``mixamorig:LeftArm``) and those of our BVH presets (``zeggs``/``beat``); the
  scheme that finds more bones wins.

A finger's tip (our joint 4) has no humanoid bone in VRM; the first child of the
distal bone stands for it where the file has one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from ..errors import ConfigError
from ..skeleton import FINGERS, JOINT_NAMES

__all__ = ["PELVIS", "REQUIRED", "MIXAMO", "VRM_BONES", "name_maps", "match_names", "check_bone_map", "missing_message"]

#: The key of the pelvis (the hips bone) in a bone map: not one of our 55 joints, but where their skeleton is anchored.
PELVIS = "pelvis"

#: Joints every character must have a bone for.
REQUIRED: tuple[str, ...] = (
    PELVIS,
    "spine_mid",
    "head",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
)

_FINGER_CAP = {f: f.capitalize() for f in FINGERS}


def _mixamo() -> dict[str, str]:
    out = {
        PELVIS: "Hips",
        "spine_mid": "Spine",
        "chest": "Spine1",
        "upper_chest": "Spine2",
        "neck": "Neck",
        "head": "Head",
        "head_top": "HeadTop_End",
    }
    for side, s in (("left", "Left"), ("right", "Right")):
        out |= {
            f"{side}_collar": f"{s}Shoulder",
            f"{side}_shoulder": f"{s}Arm",
            f"{side}_elbow": f"{s}ForeArm",
            f"{side}_wrist": f"{s}Hand",
        }
        for f in FINGERS:
            for k in range(1, 5):
                out[f"{side}_{f}{k}"] = f"{s}Hand{_FINGER_CAP[f]}{k}"
    return out


#: Our joints (and the pelvis) by Mixamo bone name, without the ``mixamorig:`` prefix.
MIXAMO: Mapping[str, str] = _mixamo()


def _vrm(version: int) -> dict[str, str]:
    out = {
        PELVIS: "hips",
        "spine_mid": "spine",
        "chest": "chest",
        "upper_chest": "upperChest",
        "neck": "neck",
        "head": "head",
    }
    finger_bones = {f: ("Proximal", "Intermediate", "Distal") for f in FINGERS}
    if version == 1:
        finger_bones["thumb"] = ("Metacarpal", "Proximal", "Distal")
    for side in ("left", "right"):
        out |= {
            f"{side}_collar": f"{side}Shoulder",
            f"{side}_shoulder": f"{side}UpperArm",
            f"{side}_elbow": f"{side}LowerArm",
            f"{side}_wrist": f"{side}Hand",
        }
        for f in FINGERS:
            vrm_finger = "Little" if f == "pinky" else _FINGER_CAP[f]
            for k, part in enumerate(finger_bones[f], start=1):
                out[f"{side}_{f}{k}"] = f"{side}{vrm_finger}{part}"
    return out


#: Our joints (and the pelvis) by VRM humanoid bone name, for VRM 0.x (key 0) and 1.0 (key 1).
VRM_BONES: Mapping[int, Mapping[str, str]] = {0: _vrm(0), 1: _vrm(1)}


def name_maps() -> dict[str, dict[str, str]]:
    """The bone-name schemes tried on a rig without a VRM humanoid: ``{scheme: {our joint: their bone name}}``.

    ``"mixamo"`` (:data:`MIXAMO`) and one per BVH preset of :mod:`gesturekit.datasets.presets` (their pelvis and
    all their joints).
    """
    from ..datasets.presets import PRESETS

    out = {"mixamo": dict(MIXAMO)}
    for name, preset in PRESETS.items():
        out[name] = {PELVIS: preset.pelvis, **preset.joints}
    return out


def _strip(name: str) -> str:
    """A bone name without a namespace prefix (``mixamorig:LeftArm`` -> ``LeftArm``)."""
    return name.rsplit(":", 1)[-1]


def match_names(bone_names: Sequence[str]) -> tuple[str, dict[str, int]]:
    """The name scheme that finds the most of a rig's bones, and what it finds.

    Parameters
    ----------
    bone_names : sequence of str
        The rig's bones, in its order.

    Returns
    -------
    scheme : str
        A key of :func:`name_maps`.
    found : dict
        Our joint (or :data:`PELVIS`) -> index into ``bone_names``.
    """
    by_name: dict[str, int] = {}
    for i, n in enumerate(bone_names):
        by_name.setdefault(n, i)
        by_name.setdefault(_strip(n), i)
    best: tuple[int, int, str, dict[str, int]] | None = None
    for rank, (scheme, names) in enumerate(name_maps().items()):
        found = {ours: by_name[theirs] for ours, theirs in names.items() if theirs in by_name}
        required = sum(k in found for k in REQUIRED)
        key = (required, len(found))
        if best is None or key > best[:2]:
            best = (*key, scheme, found)
        del rank
    assert best is not None
    return best[2], best[3]


def check_bone_map(content: object, *, source: str) -> dict[str, str]:
    """A user's JSON bone map, checked: ``{"pelvis": name, "joints": {our joint: their bone name}}``.

    Parameters
    ----------
    content : object
        The parsed JSON.
    source : str
        Where it came from, for messages.

    Returns
    -------
    dict
        Our joint (or :data:`PELVIS`) -> their bone name.

    Raises
    ------
    ConfigError
        Not that form, an unknown joint of ours, or a name that is not a non-empty string.
    """
    if not isinstance(content, Mapping) or not isinstance(content.get("joints"), Mapping):
        raise ConfigError(f'{source}: a bone map is {{"pelvis": "Hips", "joints": {{"spine_mid": "Spine", ...}}}}')
    extra = sorted(set(content) - {"pelvis", "joints", "name"})
    if extra:
        raise ConfigError(f"{source}: unknown keys {', '.join(map(repr, extra))} (expected pelvis, joints)")
    joints = dict(content["joints"])
    unknown = sorted(str(k) for k in joints if k not in JOINT_NAMES)
    if unknown:
        raise ConfigError(f"{source}: not joints of gesturekit's skeleton: {', '.join(unknown[:8])}")
    out: dict[str, str] = {}
    if "pelvis" in content:
        joints[PELVIS] = content["pelvis"]
    for ours, theirs in joints.items():
        if not isinstance(theirs, str) or not theirs.strip():
            raise ConfigError(f"{source}: the bone for {ours} must be a non-empty name, got {theirs!r}")
        out[str(ours)] = theirs
    return out


def missing_message(found: Mapping[str, object], scheme: str, expected: Mapping[str, str] | None, *, path: str) -> str:
    """Why a rig is refused: which required joints lack a bone, and the names that were looked for."""
    lack = [k for k in REQUIRED if k not in found]
    parts = []
    for k in lack:
        hint = f" (looked for {expected[k]!r})" if expected and k in expected else ""
        parts.append(f"{k}{hint}")
    return (
        f"{path}: no bone found for {', '.join(parts)} by the {scheme} map; a character needs bones for "
        f"{', '.join(REQUIRED)}. Give a JSON bone map (--character-map) naming them."
    )
