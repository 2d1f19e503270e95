"""A user's own humanoid character: a glTF/GLB, VRM or FBX file with a skinned body, or a BVH skeleton.

:func:`read_character` reads the file, finds which of its bones is which of
our joints (:mod:`gesturekit.character.humanoid`) and returns a
:class:`Character`: its skeleton in its rest pose (whatever that pose is: a
T-pose, an A-pose, bones with any roll) and, from a glTF or VRM, its skinned
mesh with the colour of its materials.

The character's frame
---------------------
Every array of a :class:`Character` is in *our* frame: metres, Y up, the
character facing +Z with its left at +X, as our motions are. The file's own
frame is found from its rest pose (up: from the pelvis to the head; left:
from the right upper arm to the left one) and :attr:`Character.to_file` takes
points back to it, so a VRM 0.x (facing -Z), a glTF whose armature is turned
and scaled by 0.01 (as exports from FBX are) or a BVH in centimetres all read
the same way.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from pathlib import Path
from typing import Any

from .._arguments import checks_arguments
from .._io import safe_filename
from ..errors import ConfigError, GestureKitError, InputFileError
from ..limits import read_json
from ..paths import is_file
from ._user_bvh import read_bvh_skeleton
from ._user_fbx import read_fbx_skeleton
from ._user_gltf import read_gltf_skeleton
from .humanoid import (
    FAMILIES,
    REQUIRED,
    check_bone_map,
    fingers_by_shape,
    match_families,
    match_names,
    missing_message,
    name_maps,
)
from .shape import SHAPE, match_by_shape, sides_by_rest_pose
from .target import WRIST_SLACK, Character, FileSkeleton, check_wrist_slack

__all__ = ["CHARACTER_SUFFIXES", "read_character", "read_character_upload", "character_record", "bone_tree"]

#: File name suffixes :func:`read_character` reads.
CHARACTER_SUFFIXES: tuple[str, ...] = (".glb", ".gltf", ".vrm", ".fbx", ".bvh")


@checks_arguments
def read_character(
    path: str | os.PathLike, *, bone_map: str | os.PathLike | dict | None = None, wrist_slack: float = WRIST_SLACK
) -> Character:
    """Read a user's humanoid character and match its bones to our joints.

    Parameters
    ----------
    path : str or path-like
        A ``.glb``, ``.gltf``, ``.vrm`` or ``.fbx`` (binary 7.x, ASCII 6.1 to 7.x) with a skinned humanoid, or a
        ``.bvh`` skeleton.
    bone_map : str, path-like or dict, optional
        A JSON bone map (a file, or its content) of the form
        ``{"pelvis": "Hips", "joints": {"spine_mid": "Spine", ...}}``; default: the VRM humanoid of a VRM,
        else bone names (Mixamo's, our BVH presets', the common families), else the hierarchy's shape
        (:func:`~gesturekit.character.shape.match_by_shape`). Left and right are then checked against the rest
        pose (:func:`~gesturekit.character.shape.sides_by_rest_pose`): names that have them the other way round
        are swapped, and a note says so (warned, and in :attr:`Character.notes`).
    wrist_slack : float
        How far its wrists may stay from our reach when it is posed, a fraction of the arm's length in
        [0, 0.2] (:attr:`Character.wrist_slack`): 0 puts the hands exactly where ours reach.

    Returns
    -------
    Character

    Raises
    ------
    InputFileError
        The file is missing, of another kind, or not readable as its kind.
    ConfigError
        A bone needed (:data:`~gesturekit.character.humanoid.REQUIRED`) is not found (the message names it), the
        map names a bone the file lacks, or the rest pose is not a humanoid's.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"read_character takes a file name or path, not {type(path).__name__}")
    if bone_map is not None and not isinstance(bone_map, (str, os.PathLike, dict)):
        raise ConfigError(f"bone_map is a JSON file's name or path, or a dict, not {type(bone_map).__name__}")
    slack = check_wrist_slack(wrist_slack)  # before the file is read: a wrong option costs no reading
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in CHARACTER_SUFFIXES:
        kinds = ", ".join(CHARACTER_SUFFIXES)
        raise InputFileError(f"a character is a {kinds} file, not {suffix or 'a file without suffix'}", path=p)
    if not is_file(p):
        raise InputFileError("no such character file", path=p)
    user_map = _bone_map(bone_map)
    if suffix == ".bvh":
        skeleton = read_bvh_skeleton(p)
    elif suffix == ".fbx":
        skeleton = read_fbx_skeleton(p)
    else:
        skeleton = read_gltf_skeleton(p)
    _check_unique(skeleton)
    found, matched_by, expected = _match(skeleton, user_map, p)
    notes: tuple[str, ...] = ()
    if user_map is None:  # a map the user wrote is taken as written
        found, note = sides_by_rest_pose(found, skeleton.parents.tolist(), skeleton.world[:, :3, 3], skeleton.names)
        if note:
            notes, matched_by = (f"{p.name}: {note}",), f"{matched_by}, left and right from the rest pose"
    character = skeleton.character(found, matched_by, expected, notes=notes)
    return character if slack == character.wrist_slack else dataclasses.replace(character, wrist_slack=slack)


@checks_arguments
def read_character_upload(name: str, data: bytes, *, bone_map: tuple[str, bytes] | None = None) -> Character:
    """Read an uploaded character file (and bone map) via a temporary folder, as :func:`read_character` reads one.

    Parameters
    ----------
    name : str
        The file name the user gave (only its sanitised form is used on disk; the suffix tells the kind).
    data : bytes
        The file's content.
    bone_map : (str, bytes), optional
        An uploaded JSON bone map: its name and content.

    Returns
    -------
    Character
        With :attr:`Character.path` the upload's name (the temporary copy is gone).

    Raises
    ------
    GestureKitError
        As :func:`read_character`; the message names the uploads, not their temporary copies.
    """
    import dataclasses
    import tempfile

    with tempfile.TemporaryDirectory(prefix="gesturekit-character-") as tmp:
        path = Path(tmp) / safe_filename(Path(str(name)).name, default="character")
        path.write_bytes(bytes(data))
        map_path = None
        if bone_map is not None:
            (Path(tmp) / "map").mkdir()
            map_path = Path(tmp) / "map" / safe_filename(Path(str(bone_map[0])).name, default="bones")
            map_path.write_bytes(bytes(bone_map[1]))
        try:
            character = read_character(path, bone_map=map_path)
        except GestureKitError as exc:
            problem = exc.problem.replace(str(path), str(name))
            if map_path is not None:
                problem = problem.replace(str(map_path), str(bone_map[0] if bone_map else ""))
            problem = problem.replace(tmp + os.sep, "")
            shown = None if exc.path is None else bone_map[0] if bone_map and exc.path == str(map_path) else name
            error = type(exc)(problem, path=shown)
            if hasattr(exc, "bone_tree"):
                error.bone_tree = exc.bone_tree  # type: ignore[attr-defined]
            raise error from None
    return dataclasses.replace(character, path=Path(str(name)))


@checks_arguments
def character_record(character: Character, *, bone_map: str | os.PathLike | dict | None = None) -> dict[str, Any]:
    """What names a character's files, for a record of what made an output (a study's ``study.json``).

    Returns
    -------
    dict
        ``file`` (the file's name, no folder), ``sha256`` (hex, None where the file is gone), ``matched_by``,
        ``wrist_slack`` (how far its wrists may stay from our reach);
        with a bone map file also ``bone_map``: its ``file`` and ``sha256``.
    """
    out: dict[str, Any] = {"file": character.path.name, "sha256": _sha256(character.path)}
    out["matched_by"] = character.matched_by
    out["wrist_slack"] = character.wrist_slack
    if isinstance(bone_map, (str, os.PathLike)):
        out["bone_map"] = {"file": Path(bone_map).name, "sha256": _sha256(Path(bone_map))}
    return out


def _sha256(path: Path) -> str | None:
    if not path.is_file():
        return None
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _check_unique(skeleton: FileSkeleton) -> None:
    """Refuse two bones of one name: a map or a name scheme could not say which is meant, nor a BVH of it."""
    seen: dict[str, int] = {}
    for i, name in enumerate(skeleton.names):
        if name in seen:
            raise InputFileError(
                f"two bones are named {name!r}; rename one in the modelling tool (bone names must be unique)",
                path=skeleton.path,
            )
        seen[name] = i


def _bone_map(spec: str | os.PathLike | dict | None) -> tuple[str, dict[str, str]] | None:
    if spec is None:
        return None
    if isinstance(spec, dict):
        return "JSON map", check_bone_map(spec, source="the bone map")
    p = Path(spec)
    if not is_file(p):
        raise InputFileError("no such bone map file", path=p)
    return f"JSON map {p.name}", check_bone_map(read_json(p), source=str(p))


def _match(
    skeleton: FileSkeleton, user_map: tuple[str, dict[str, str]] | None, path: Path
) -> tuple[dict[str, int], str, dict[str, str] | None]:
    """Our joint -> bone of the skeleton, how they were matched, and the names looked for."""
    names: tuple[str, ...] = skeleton.names
    if user_map is not None:
        label, wanted = user_map
        index = {n: i for i, n in enumerate(names)}
        absent = sorted(f"{k} -> {v!r}" for k, v in wanted.items() if v not in index)
        if absent:
            raise _with_tree(f"{path}: the bone map names bones the file lacks: {', '.join(absent[:8])}", skeleton)
        found = {k: index[v] for k, v in wanted.items()}
        if any(k not in found for k in REQUIRED):
            raise _with_tree(missing_message(found, label, wanted, path=str(path)), skeleton)
        return found, label, wanted
    if skeleton.humanoid is not None:
        label, found, expected = skeleton.humanoid
        if any(k not in found for k in REQUIRED):
            raise ConfigError(missing_message(found, label, expected, path=str(path)))
        return found, label, expected
    scheme, found = match_names(names)
    label = f"{scheme} names"
    expected = name_maps()[scheme]
    families = match_families(names, [int(p) for p in skeleton.parents])
    if (sum(k in families for k in REQUIRED), len(families)) > (sum(k in found for k in REQUIRED), len(found)):
        found, label, expected = families, FAMILIES, {}
    parents, rest, ends = [int(p) for p in skeleton.parents], skeleton.world[:, :3, 3], _end_sites(skeleton)
    if any(k not in found for k in REQUIRED):  # names fail: the hierarchy's shape, sides from the rest pose
        shaped = match_by_shape(parents, rest, ends)
        if all(k in shaped for k in REQUIRED):
            found, label, expected = shaped, SHAPE, {}
    found, sides = fingers_by_shape(found, parents, rest, ends)
    if sides:
        label += f", the fingers of the {' and '.join(sides)} hand{'s' if len(sides) > 1 else ''} by their shape"
    if any(k not in found for k in REQUIRED):
        raise _with_tree(missing_message(found, label, expected, path=str(path)), skeleton)
    return found, label, expected


def _end_sites(skeleton: FileSkeleton) -> set[int]:
    """A BVH's End Sites: the leaves its reader named after their parent (``NAME_End`` below ``NAME``)."""
    if skeleton.kind != "bvh":
        return set()
    names, parents = skeleton.names, skeleton.parents
    has_child = set(int(p) for p in parents)
    return {b for b, p in enumerate(parents) if p >= 0 and b not in has_child and names[b] == f"{names[p]}_End"}


def _with_tree(message: str, skeleton: FileSkeleton) -> ConfigError:
    error = ConfigError(message)
    error.bone_tree = bone_tree(skeleton)  # type: ignore[attr-defined]
    return error


@checks_arguments
def bone_tree(skeleton: FileSkeleton, most: int = 200) -> str:
    """The file's bones as an indented tree with their rest positions (metres, the file's axes), for writing a
    bone map: a glTF node without a name is ``node{index}`` (its index among the file's nodes).

    A :class:`ConfigError` of :func:`read_character` for bones it could not find carries this as ``bone_tree``.
    """
    depth = [0] * len(skeleton.names)
    lines = []
    for b, name in enumerate(skeleton.names[:most]):
        p = int(skeleton.parents[b])
        depth[b] = depth[p] + 1 if p >= 0 else 0
        x, y, z = skeleton.world[b, :3, 3] * skeleton.units
        lines.append(f"{'  ' * depth[b]}{name} ({x:.2f}, {y:.2f}, {z:.2f})")
    more = len(skeleton.names) - most
    tail = f"\n... and {more} more" if more > 0 else ""
    return "\n".join(lines) + tail
