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

import re
from collections.abc import Collection, Mapping, Sequence

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..skeleton import FINGERS, JOINT_NAMES

__all__ = [
    "PELVIS",
    "REQUIRED",
    "MIXAMO",
    "VRM_BONES",
    "FAMILIES",
    "name_maps",
    "match_names",
    "match_families",
    "fingers_by_shape",
    "check_bone_map",
    "missing_message",
]

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


@checks_arguments
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


@checks_arguments
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


@checks_arguments
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


@checks_arguments
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


# ----------------------------------------------------------------------------- common naming families

#: The scheme name of :func:`match_families` in messages and :attr:`Character.matched_by`.
FAMILIES = "common names"

_SIDE_SUFFIX = re.compile(r"[._ -](left|right|l|r)$", re.IGNORECASE)
_SIDE_PREFIX = re.compile(r"^(left|right|l|r)[._ -]", re.IGNORECASE)
_CAMEL_SIDE = re.compile(r"^(Left|Right|L|R)(?=[A-Z][a-z]|[A-Z]$)")
_PREFIXES = ("cc_base_", "def-", "def_", "org-", "bip01 ", "bip01_", "bip001 ", "bip001_", "b_", "j_bip_")
_SKIP = ("twist", "roll", "bend", "share", "ik", "pole", "target", "meta", "carpal", "helper", "adjust")
_LIMBS = {
    "collar": ("shoulder", "clavicle", "collar", "collarbone"),
    "shoulder": ("arm", "upperarm", "uparm", "humerus"),
    "elbow": ("forearm", "lowerarm", "elbow"),
    "wrist": ("hand", "wrist"),
}
_FINGER_WORDS = {"thumb": "thumb", "index": "index", "middle": "middle", "mid": "middle", "ring": "ring"}
_FINGER_WORDS |= {"pinky": "pinky", "little": "pinky", "small": "pinky"}
_FINGER = re.compile(r"^(?:hand)?f?(?P<finger>thumb|index|middle|mid|ring|pinky|little|small)(?P<k>\d{1,2})?$")
_UMA_FINGER = re.compile(r"^(?:hand)?finger(?P<finger>0[1-5])(?P<k>0[1-4])$")


def _side_and_base(name: str) -> tuple[str | None, str]:
    """A bone name's side (``"left"``, ``"right"`` or None) and its base, lower case without separators:
    ``mixamorig:LeftForeArm`` -> (left, forearm), ``upper_arm.L`` -> (left, upperarm), ``CC_Base_L_Index1`` ->
    (left, index1), ``hand_r`` -> (right, hand), ``f_index.01.L`` -> (left, findex01)."""
    text = name.rsplit(":", 1)[-1].strip()
    low = text.lower()
    for prefix in _PREFIXES:
        if low.startswith(prefix) and len(low) > len(prefix):
            text, low = text[len(prefix) :], low[len(prefix) :]
            break
    side = None
    for pattern in (_SIDE_SUFFIX, _SIDE_PREFIX, _CAMEL_SIDE):
        m = pattern.search(text)
        if m:
            side = "left" if m.group(1)[0] in "lL" else "right"
            text = text[: m.start()] + text[m.end() :]
            break
    return side, re.sub(r"[._ -]+", "", text).lower()


def _finger_of(base: str) -> tuple[str, int] | None:
    """Our finger and phalanx (1..4) of a base name (``index1``, ``findex01``, ``handindex2``, ``thumb03``,
    ``handfinger0201`` (UMA: finger 2 is the index)), or None."""
    m = _FINGER.match(base)
    if m:
        finger, k = _FINGER_WORDS[m.group("finger")], int(m.group("k") or 1)  # "LThumb": its first bone
    else:
        m = _UMA_FINGER.match(base)
        if not m:
            return None
        finger, k = FINGERS[int(m.group("finger")) - 1], int(m.group("k"))
    return (finger, k) if 1 <= k <= 4 else None


@checks_arguments
def match_families(names: Sequence[str], parents: Sequence[int]) -> dict[str, int]:
    """Our joints found by the common naming families and the hierarchy, where no one scheme names them.

    The side is a prefix or suffix (``Left``/``Right``, ``L_``/``R_``, ``.L``/``.R``, ``_l``/``_r``), namespace
    and tool prefixes are dropped (``mixamorig:``, ``CC_Base_``, ``DEF-``, ``Bip01``), and the rest is looked up
    among the words for each limb (collar: shoulder, clavicle; upper arm: arm, upperarm; forearm: forearm,
    lowerarm; hand: hand, wrist) and fingers (``thumb``, ``index``, ``middle``/``mid``, ``ring``,
    ``pinky``/``little`` with a phalanx number; UMA's ``HandFinger02_01`` is the index's first). Twist, roll,
    IK and helper bones are left out. The pelvis is the highest bone named hips, hip or pelvis above the head;
    the spine is the bones between it and the neck (the first bone named neck above the head): the last three
    are our spine_mid, chest and upper_chest (as many as there are). A finger's tip (our 4) is the only child of
    its third bone, the head's top a child of the head named as an end.

    Parameters
    ----------
    names : sequence of str
    parents : sequence of int
        Each bone's parent (``-1`` for a root), parents before children.

    Returns
    -------
    dict
        Our joint (or :data:`PELVIS`) -> bone index.
    """
    n = len(names)
    children: list[list[int]] = [[] for _ in range(n)]
    for b, p in enumerate(parents):
        if p >= 0:
            children[p].append(b)

    def chain_up(b: int) -> list[int]:
        out = []
        while b >= 0:
            out.append(b)
            b = int(parents[b])
        return out

    depth = [len(chain_up(b)) for b in range(n)]
    parsed = [_side_and_base(x) for x in names]
    found: dict[str, int] = {}

    def take(key: str, bones: list[int]) -> None:
        if bones and key not in found:
            found[key] = min(bones, key=lambda b: (depth[b], b))

    heads = [b for b, (side, base) in enumerate(parsed) if side is None and base == "head"]
    take("head", heads)
    if "head" not in found:
        return found
    above_head = chain_up(found["head"])[1:]
    take(PELVIS, [b for b in above_head if parsed[b][0] is None and parsed[b][1] in ("hips", "hip", "pelvis")])
    necks = [b for b in above_head if parsed[b][1].startswith("neck")]
    if necks:
        found["neck"] = max(necks, key=lambda b: -depth[b])  # the lowest neck bone, nearest the chest
    if PELVIS in found:
        top = found["neck"] if "neck" in found else found["head"]
        path = [b for b in reversed(chain_up(top)[1:]) if depth[b] > depth[found[PELVIS]]]
        path = [b for b in path if not any(s in parsed[b][1] for s in _SKIP)]
        keys = ("spine_mid", "chest", "upper_chest")[: min(3, len(path))]
        for key, b in zip(keys, path[len(path) - len(keys) :]):  # of four or more, the lowest are none of ours
            found[key] = b
    for b in children[found["head"]]:
        if re.search(r"(end|top|tip|nub)$", parsed[b][1]):
            found.setdefault("head_top", b)
    for side in ("left", "right"):
        for ours, words in _LIMBS.items():
            take(f"{side}_{ours}", [b for b, (s, base) in enumerate(parsed) if s == side and base in words])
        if f"{side}_wrist" not in found:
            continue
        hand = found[f"{side}_wrist"]
        below = _descendants(children, hand)
        for b in below:
            s, base = parsed[b]
            f = _finger_of(base)
            if f is not None and s in (side, None) and not any(x in base for x in _SKIP):
                take(f"{side}_{f[0]}{f[1]}", [b])
        for finger in FINGERS:
            third = found.get(f"{side}_{finger}3")
            if third is not None and f"{side}_{finger}4" not in found and len(children[third]) == 1:
                found[f"{side}_{finger}4"] = children[third][0]
    return found


def _descendants(children: list[list[int]], b: int) -> list[int]:
    out: list[int] = []
    stack = list(children[b])
    while stack:
        c = stack.pop()
        out.append(c)
        stack.extend(children[c])
    return out


@checks_arguments
def fingers_by_shape(
    found: dict[str, int], parents: Sequence[int], positions: np.ndarray, ends: Collection[int] = ()
) -> tuple[dict[str, int], list[str]]:
    """Fingers found from the hand's shape where names did not find them: five chains under a hand.

    A hand (our wrist) none of whose fingers is matched, with exactly five children each starting a chain of
    two to four bones (one child each), has its fingers there: the thumb is the chain whose first bone is
    nearest the wrist, and the other four go index, middle, ring, pinky by their first bone's distance from the
    thumb's side of the hand.

    Parameters
    ----------
    found : dict
        Our joint -> bone, as matched so far (not changed).
    parents : sequence of int
    positions : np.ndarray, shape (M, 3)
        Rest positions (any frame and unit).
    ends : collection of int
        A BVH's End Sites, left out of the chains.

    Returns
    -------
    found : dict
        With the fingers added.
    sides : list of str
        The sides (``"left"``, ``"right"``) whose fingers were found so.
    """
    children: list[list[int]] = [[] for _ in parents]
    for b, p in enumerate(parents):
        if p >= 0 and b not in ends:
            children[p].append(b)
    out, sides = dict(found), []
    for side in ("left", "right"):
        hand, elbow = found.get(f"{side}_wrist"), found.get(f"{side}_elbow")
        if hand is None or elbow is None or any(k.startswith(f"{side}_") and k[-1].isdigit() for k in found):
            continue
        chains = []
        for c in children[hand]:
            chain = [c]
            while len(children[chain[-1]]) == 1 and len(chain) < 4:
                chain.append(children[chain[-1]][0])
            if children[chain[-1]] or len(chain) < 2:
                break
            chains.append(chain)
        if len(chains) != 5 or len(children[hand]) != 5:
            continue
        wrist = positions[hand]
        axis = wrist - positions[elbow]
        axis = axis / max(float(np.linalg.norm(axis)), 1e-12)
        thumb = min(chains, key=lambda ch: float(np.linalg.norm(positions[ch[0]] - wrist)))
        rest = [ch for ch in chains if ch is not thumb]
        lateral = positions[thumb[0]] - wrist
        lateral = lateral - axis * float(lateral @ axis)
        rest.sort(key=lambda ch: -float((positions[ch[0]] - wrist) @ lateral))
        for finger, chain in zip(FINGERS, [thumb, *rest]):
            for k, b in enumerate(chain, start=1):
                out[f"{side}_{finger}{k}"] = b
        sides.append(side)
    return out, sides
