"""Joint maps: which joint of a source skeleton is each of our 55 joints.

A :class:`JointMap` names the source joint of every joint of
:data:`gesturekit.skeleton.JOINT_NAMES` and the source joint that is the
pelvis (its world position is subtracted to make the motion pelvis-relative).
Each of our bones must join two joints that are parent and child in the
source skeleton (or at least move rigidly together), so that bone lengths stay
constant over time.

Presets
-------
``"zeggs"``
    The ZeroEGGS BVH skeleton (75 joints, centimetres): ``Hips``,
    ``Spine``..``Spine3``, ``Neck``, ``Neck1``, ``Head``, ``HeadEnd`` (a joint
    with channels), ``{Left,Right}{Shoulder,Arm,ForeArm,Hand}`` and
    ``{Left,Right}Hand{Thumb,Index,Middle,Ring,Pinky}{1..4}``, where ``4`` is
    the finger tip. Our root ``spine_mid`` is ``Spine1``; ``Spine`` lies between
    it and the pelvis and is not needed. Every one of our bones is a
    parent-child pair in this skeleton.
``"beat"``
    The BEAT (v0.2.x) BVH skeleton. Based on the BEAT authors' public code
    (PantoMatrix: the ``beat_joints`` table of 75 joints and 228 channels) and
    published listings of BEAT BVH joint names: ``Hips``,
    ``Spine``..``Spine3``, ``Neck``, ``Neck1``, ``Head``, ``HeadEnd``, per side
    ``Shoulder, Arm, ForeArm, Hand``, ``HandMiddle1..4``,
    ``HandRing, HandRing1..4``, ``HandPinky, HandPinky1..4``,
    ``HandIndex, HandIndex1..4``, ``HandThumb1..4``, then the legs. The
    finger tips ``...4`` are joints there (their End Sites come after them),
    so the names are the same as ZEGGS's. Unlike ZEGGS, BEAT puts a metacarpal
    joint (``RightHandIndex``, ``RightHandRing``, ``RightHandPinky``) between
    the wrist and the first joint of the index, ring and little fingers: the
    wrist-to-``1`` distance of those fingers stays constant only as far as that
    metacarpal joint does not rotate.

Custom maps are JSON files (or dicts) of the form
``{"pelvis": "Hips", "joints": {"spine_mid": "Spine1", ...}}`` naming all 55
joints; see :func:`load_joint_map`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from .._arguments import checks_arguments
from .._config import config_to_dict
from ..errors import ConfigError, InputFileError
from ..limits import read_json
from ..paths import is_file
from ..skeleton import FINGERS, JOINT_NAMES

__all__ = ["JointMap", "PRESETS", "load_joint_map", "missing_and_unknown", "mapping_problems"]


@dataclass(frozen=True)
class JointMap:
    """Where each of our 55 joints comes from in a source skeleton.

    Parameters
    ----------
    name : str
        Name of the map (a preset name or the JSON file it was read from),
        used in error messages.
    pelvis : str
        Source joint whose world position is subtracted from every joint.
    joints : Mapping[str, str]
        Our joint name (all 55 of :data:`gesturekit.skeleton.JOINT_NAMES`) ->
        source joint name.
    """

    name: str
    pelvis: str
    joints: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self):
        # read-only, so a preset cannot be changed by a caller by accident
        object.__setattr__(self, "joints", MappingProxyType(dict(self.joints)))

    def source_names(self) -> list[str]:
        """Source joint names in the order of :data:`gesturekit.skeleton.JOINT_NAMES`."""
        return [self.joints[n] for n in JOINT_NAMES]

    def to_dict(self) -> dict:
        """The JSON form: ``{"pelvis": ..., "joints": {...}}``."""
        return config_to_dict(self, exclude=("name",))


@checks_arguments
def missing_and_unknown(names: Iterable[str]) -> tuple[list[str], list[str]]:
    """Compare joint names with our 55.

    Returns
    -------
    missing : list of str
        Our joints not in ``names``, in skeleton order.
    unknown : list of str
        Names that are not joints of our skeleton, sorted.
    """
    names = set(names)
    missing = [n for n in JOINT_NAMES if n not in names]
    unknown = sorted(str(n) for n in names - set(JOINT_NAMES))
    return missing, unknown


@checks_arguments
def mapping_problems(joints: Mapping, *, value_ok: Callable[[object], bool], values_must_be: str) -> list[str]:
    """What is wrong with a map from our joint names to source joints, one phrase per problem.

    Parameters
    ----------
    joints : mapping
        Our joint name -> the source joint it comes from.
    value_ok : callable(value) -> bool
        Whether a value names a source joint the way this kind of map must.
    values_must_be : str
        The start of the phrase for values that are not, e.g. ``"values must be joint indices or names"``.

    Returns
    -------
    list of str
        Our joints not mapped, keys that are not our joints, our joints with
        a bad value; empty when the map is sound.
    """
    missing, unknown = missing_and_unknown(joints)
    problems = []
    if missing:
        problems.append(f"{len(missing)} of our joints not mapped: {', '.join(missing)}")
    if unknown:
        problems.append(f"not joints of our skeleton: {', '.join(unknown)}")
    bad = sorted(k for k, v in joints.items() if k in JOINT_NAMES and not value_ok(v))
    if bad:
        problems.append(f"{values_must_be}: {', '.join(bad)}")
    return problems


def _mixamo_like(name: str) -> JointMap:
    """The map shared by skeletons named like ZEGGS's and BEAT's."""
    joints = {
        "spine_mid": "Spine1",
        "chest": "Spine2",
        "upper_chest": "Spine3",
        "neck": "Neck",
        "neck_upper": "Neck1",
        "head": "Head",
        "head_top": "HeadEnd",
    }
    for side, Side in (("left", "Left"), ("right", "Right")):
        joints[f"{side}_collar"] = f"{Side}Shoulder"
        joints[f"{side}_shoulder"] = f"{Side}Arm"
        joints[f"{side}_elbow"] = f"{Side}ForeArm"
        joints[f"{side}_wrist"] = f"{Side}Hand"
        for finger in FINGERS:
            for i in range(1, 5):
                joints[f"{side}_{finger}{i}"] = f"{Side}Hand{finger.capitalize()}{i}"
    return JointMap(name=name, pelvis="Hips", joints=joints)


#: The built-in joint maps by name.
PRESETS: Mapping[str, JointMap] = MappingProxyType({"zeggs": _mixamo_like("zeggs"), "beat": _mixamo_like("beat")})


@checks_arguments
def load_joint_map(spec: str | os.PathLike | Mapping | JointMap) -> JointMap:
    """A complete joint map from a preset name, a JSON file or a dict.

    Parameters
    ----------
    spec : str, os.PathLike, Mapping or JointMap
        A preset name (see :data:`PRESETS`), a path to a JSON file
        ``{"pelvis": str, "joints": {our_name: source_name}}``, such a dict,
        or a :class:`JointMap` (checked and returned).

    Returns
    -------
    JointMap

    Raises
    ------
    InputFileError
        The JSON file is missing, not JSON or not a complete map (the message
        names the file and lists missing or unknown joints).
    ConfigError
        An unknown preset name, or a dict that is not a complete map.
    """
    if isinstance(spec, JointMap):
        _validate(spec.to_dict(), name=spec.name, path=None)
        return spec
    if isinstance(spec, Mapping):
        return _validate(spec, name="joint map", path=None)
    if isinstance(spec, str) and spec.lower() in PRESETS:
        return PRESETS[spec.lower()]
    if not isinstance(spec, (str, os.PathLike)):
        raise ConfigError(f"a joint map must be a preset name, a JSON file or a dict, got {type(spec).__name__}")
    path = Path(spec)
    if not is_file(path):
        if path.suffix.lower() == ".json" or os.sep in str(spec):
            raise InputFileError("joint map file not found", path=path)
        raise ConfigError(f"unknown joint map {str(spec)!r}: not a preset ({', '.join(PRESETS)}) nor a JSON file")
    content = read_json(path, what="joint map ", encoding="utf-8-sig")
    return _validate(content, name=os.fspath(path), path=path)


def _validate(content, *, name: str, path) -> JointMap:
    """Check a ``{"pelvis", "joints"}`` mapping and build the :class:`JointMap`."""

    def fail(message: str):
        if path is not None:
            raise InputFileError(message, path=path)
        raise ConfigError(f"{name}: {message}")

    if not isinstance(content, Mapping):
        fail("a joint map must be a JSON object with keys 'pelvis' and 'joints'")
    extra = sorted(str(k) for k in set(content) - {"pelvis", "joints"})
    if extra:
        fail(f"unexpected keys {extra}; a joint map has 'pelvis' and 'joints'")
    pelvis = content.get("pelvis")
    if not isinstance(pelvis, str) or not pelvis:
        fail("'pelvis' must name the source joint of the pelvis")
    joints = content.get("joints")
    if not isinstance(joints, Mapping):
        fail("'joints' must map each of our joint names to a source joint name")
    problems = mapping_problems(
        joints,
        value_ok=lambda v: isinstance(v, str) and bool(v),
        values_must_be="source joint names must be non-empty strings",
    )
    if problems:
        fail("; ".join(problems))
    return JointMap(name=name, pelvis=pelvis, joints=dict(joints))
