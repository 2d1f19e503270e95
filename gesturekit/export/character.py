"""A user's character animated by our motion: their GLB or VRM with one more animation, or a BVH of their skeleton.

Both writers take a :class:`~gesturekit.character.retarget.Retargeted` (our
motion on their character) and write in the file's own frame and units, so
the result opens where the character came from (Blender, a game engine, a VRM
viewer) in the place and size it had.

GLB (:func:`export_character_glb`)
    Their document and binary chunk as read (meshes, materials, textures,
    skins, extensions such as VRM's, their animations), with one animation
    more, named :data:`ANIMATION`, first of the animations (a viewer that plays
    one plays the first; theirs follow as they were, or are left out with
    ``their_clips="drop"``): one key per frame at ``i / fps`` seconds,
    interpolated linearly, a rotation channel for each bone whose local
    rotation moves and a translation channel for the hips when they move. A
    bone's world rotation in the file is ``S = R_F @ W`` (``W`` the retargeted
    world rotation in our frame, ``R_F`` the rotation of
    :attr:`~gesturekit.character.target.Character.to_file`); its local
    rotation is its parent node's world rotation transposed times ``S``. A
    node written as a ``matrix`` that is animated is written as translation,
    rotation and scale (glTF animates no matrix). The speech goes beside it
    as a WAV, named in the extras of the asset and the scene, as
    :func:`gesturekit.export.gltf.export_gltf` does.

BVH (:func:`export_character_bvh`, in :mod:`gesturekit.export._character_bvh`)
    Their bones as joints; see that function.

Both read what they wrote back by another path (the GLB: its bytes parsed and
the nodes' forward kinematics with the animation; the BVH: its text parsed
and its forward kinematics) and compare every bone with the retargeted
positions: the report's ``max_error`` and ``mean_error`` in metres.
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..character.glb import FLOAT, GlbBuffer, accessor_array, glb_bytes, node_matrices, read_glb
from ..character.retarget import Retargeted
from ..character.rig import rotation_to_quaternion
from ..errors import ConfigError
from ..motion import AUDIO_SR
from ..outputs import check_not_input
from ._character_bvh import (
    CharacterBvhReport,
    _check_arguments,
    character_bvh_joints,
    check_character_bvh,
    export_character_bvh,
    rotation_of,
    worst,
)
from ._files import write_export
from .gltf import GENERATOR, WARN_ABOVE, continuous_quaternions, speech_targets

__all__ = [
    "ANIMATION",
    "THEIR_CLIPS",
    "CHARACTER_GLB_SUFFIXES",
    "CharacterGltfReport",
    "CharacterBvhReport",
    "export_character_glb",
    "export_character_bvh",
    "character_bvh_joints",
    "check_character_bvh",
]

#: The name of the animation :func:`export_character_glb` adds.
ANIMATION = "gesturekit"

#: What :func:`export_character_glb` does with the character's own animations: ``"keep"`` them after ours (the
#: default: viewers and engines that play one animation play the first, ours, and the file keeps what it had) or
#: ``"drop"`` them (ours is the only one; their keys stay in the binary chunk, referenced by nothing).
THEIR_CLIPS: tuple[str, ...] = ("keep", "drop")

#: Suffixes a character's GLB may be written with (a VRM keeps its own).
CHARACTER_GLB_SUFFIXES = (".glb", ".vrm")

# a local rotation (or translation, relative to its size) that moves less than this is left as it rests
_STILL = 1e-6


@dataclass(frozen=True, eq=False)
class CharacterGltfReport:
    """What a character's written GLB holds, and how well it reproduces the retargeted motion.

    Attributes
    ----------
    path : Path
        The file written.
    audio : Path or None
        The speech's WAV beside it.
    frames : int
        Animation keys, one per frame.
    fps : float
    bones : tuple of str
        The character's bones, all measured.
    animated : tuple of str
        The bones with a channel in the animation.
    max_error, mean_error : float
        Largest and mean distance, metres, of a bone read back from the file (converted to our frame) from its
        retargeted position.
    worst_bone : str
    worst_frame : int
    size : int
        Bytes of the file.
    their_clips : tuple of str
        The character's own animations kept in the file, after ours.
    dropped_clips : tuple of str
        The character's own animations left out (``their_clips="drop"``).
    """

    path: Path
    audio: Path | None
    frames: int
    fps: float
    bones: tuple[str, ...]
    animated: tuple[str, ...]
    max_error: float
    mean_error: float
    worst_bone: str
    worst_frame: int
    size: int
    their_clips: tuple[str, ...] = ()
    dropped_clips: tuple[str, ...] = ()

    def summary(self) -> str:
        """One line: the file, its error, what is animated, its size."""
        parts = [
            f"{self.path.name}: position error max {self.max_error * 1000:.2f} mm "
            f"({self.worst_bone}, frame {self.worst_frame}), mean {self.mean_error * 1000:.2f} mm",
            f"{len(self.animated)} of {len(self.bones)} bones animated, {self.frames} frames at {self.fps:g} fps",
            f"{self.size / 1e6:.1f} MB",
        ]
        if self.audio is not None:
            parts.append(f"speech in {self.audio.name}")
        if self.their_clips:
            parts.append(f"its own clips after ours: {', '.join(self.their_clips)}")
        if self.dropped_clips:
            parts.append(f"its own clips left out: {', '.join(self.dropped_clips)}")
        return "; ".join(parts)


@checks_arguments
def export_character_glb(
    path: str | os.PathLike[str],
    retargeted: Retargeted,
    *,
    audio: np.ndarray | None = None,
    sr: int = AUDIO_SR,
    overwrite: bool = False,
    their_clips: str = "keep",
) -> CharacterGltfReport:
    """Write the user's glTF or VRM character with our motion as its animation :data:`ANIMATION`, atomically.

    Warns (:class:`~gesturekit.errors.GestureKitWarning`) when a bone read back is more than
    :data:`gesturekit.export.gltf.WARN_ABOVE` from its retargeted position.

    Parameters
    ----------
    path : str or os.PathLike
        The file to create, ``.glb`` or ``.vrm`` (:data:`CHARACTER_GLB_SUFFIXES`; a VRM's extension is kept
        either way).
    retargeted : Retargeted
        The motion on a character read from a glTF, GLB or VRM (:func:`gesturekit.character.retarget.retarget`).
    audio : np.ndarray, shape (samples,), optional
        The speech, float samples in [-1, 1], written as a WAV beside the file
        (:func:`gesturekit.export.gltf.audio_path_for`) and named in it.
    sr : int
        Its sample rate, Hz.
    overwrite : bool
        Replace existing files that gesturekit wrote (never the character's own file).
    their_clips : {"keep", "drop"}
        The character's own animations: kept after ours, or left out (:data:`THEIR_CLIPS`).

    Returns
    -------
    CharacterGltfReport

    Raises
    ------
    ConfigError
        A character without a glTF (a BVH), another suffix, an animated bone with a non-uniform or mirroring
        scale, bad speech, or a file that exists and may not be replaced
        (:class:`~gesturekit.errors.OutputError`).
    """
    _check_arguments(path, retargeted, "export_character_glb")
    if their_clips not in THEIR_CLIPS:
        raise ConfigError(f"their_clips is one of {', '.join(THEIR_CLIPS)}, not {their_clips!r}")
    path = Path(path)
    ch = retargeted.character
    if ch.gltf is None:
        raise ConfigError(f"{ch.path.name} is a skeleton without a body; write its motion as a BVH", path=path)
    if path.suffix.lower() not in CHARACTER_GLB_SUFFIXES:
        raise ConfigError(f"a character's GLB is named .glb or .vrm, not {path.suffix or 'without suffix'}", path=path)
    check_not_input(path, [ch.path])  # never over the character's own file
    wav_path, samples = speech_targets(path, audio, sr, overwrite=overwrite)
    extras: dict[str, Any] = {"fps": float(retargeted.fps), "frames": int(retargeted.n_frames), "units": "m"}
    if wav_path is not None:
        extras["audio"] = wav_path.name
    doc, binary, animated, dropped = _document(retargeted, extras, keep=their_clips == "keep")
    data = glb_bytes(doc, binary)
    err, frames = _measure(data, retargeted, path)
    frame, bone = worst(err)
    report = CharacterGltfReport(
        path=path,
        audio=wav_path,
        frames=frames,
        fps=float(retargeted.fps),
        bones=ch.names,
        animated=tuple(ch.names[b] for b in animated),
        max_error=float(err.max()),
        mean_error=float(err.mean()),
        worst_bone=ch.names[bone],
        worst_frame=frame,
        size=len(data),
        their_clips=tuple(str(a.get("name", "")) for a in doc.get("animations", []) if a.get("name") != ANIMATION),
        dropped_clips=dropped,
    )
    warning = None
    if report.max_error > WARN_ABOVE:
        warning = (
            f"the character's GLB is up to {report.max_error * 1000:.1f} mm off the retargeted motion "
            f"({report.worst_bone}, frame {report.worst_frame})"
        )
    write_export(
        path, data, overwrite=overwrite, wav_path=wav_path, samples=samples, sr=sr, warning=warning, stacklevel=2
    )
    return report


# ----------------------------------------------------------------------------- the document


def _trs(node: dict[str, Any], name: str, path: Path) -> None:
    """Give an animated node translation, rotation and scale (from its matrix); refuse a non-uniform scale."""
    if "matrix" in node:
        m = np.asarray(node.pop("matrix"), dtype=np.float64).reshape(4, 4).T  # column-major
        scale = np.linalg.norm(m[:3, :3], axis=0)
        if np.linalg.det(m[:3, :3]) <= 0:
            raise ConfigError(f"the bone {name!r} is mirrored (a matrix of negative determinant)", path=path)
        node["translation"] = [float(x) for x in m[:3, 3]]
        node["rotation"] = [float(x) for x in rotation_to_quaternion(rotation_of(m[:3, :3]))]
        node["scale"] = [float(x) for x in scale]
    scale = np.asarray(node.get("scale", (1.0, 1.0, 1.0)), dtype=np.float64)
    if scale.min() <= 0 or scale.max() > scale.min() * (1 + 1e-5):
        shown = ", ".join(f"{s:g}" for s in scale)
        raise ConfigError(
            f"the bone {name!r} has the scale ({shown}); an animated bone needs one positive scale on all axes",
            path=path,
        )


def _document(
    r: Retargeted, extras: dict[str, Any], *, keep: bool = True
) -> tuple[dict[str, Any], bytes, list[int], tuple[str, ...]]:
    """Their document with the animation added, the binary chunk, and the bones animated."""
    ch = r.character
    assert ch.gltf is not None
    doc = copy.deepcopy(ch.gltf.document)
    nodes = doc["nodes"]
    bone_node = [int(n) for n in ch.gltf.nodes]
    bone_at = {n: b for b, n in enumerate(bone_node)}
    parent = [-1] * len(nodes)
    for i, node in enumerate(nodes):
        for c in node.get("children", ()):
            parent[c] = i
    rest = node_matrices(nodes, {}, 1)[0]
    r_f = rotation_of(ch.to_file[:3, :3])
    world_s = np.einsum("ab,tmbc->tmac", r_f, r.rotation)  # (T, M, 3, 3): each bone's rotation in the file
    memo: dict[int, np.ndarray] = {}

    def world_rotation(i: int) -> np.ndarray:
        """Node ``i``'s world rotation, (T, 3, 3) below a bone, else (3, 3)."""
        if i not in memo:
            if i in bone_at:
                memo[i] = world_s[:, bone_at[i]]
            elif _below_bone(i, parent, bone_at):
                own = rotation_of(np.linalg.solve(rest[parent[i]], rest[i])[:3, :3])
                memo[i] = world_rotation(parent[i]) @ own
            else:
                memo[i] = rotation_of(rest[i, :3, :3])
        return memo[i]

    n_frames = r.n_frames
    buf = GlbBuffer()
    times = buf.add(np.arange(n_frames) / float(r.fps), "SCALAR", FLOAT, bounds=True)
    samplers: list[dict[str, Any]] = []
    channels: list[dict[str, Any]] = []
    tracks: dict[tuple[int, str], np.ndarray] = {}
    animated = []
    for b, n in enumerate(bone_node):
        above = np.eye(3) if parent[n] < 0 else world_rotation(parent[n])
        local = np.swapaxes(above, -1, -2) @ world_s[:, b]
        at_rest = rotation_of(rest[n, :3, :3] if parent[n] < 0 else np.linalg.solve(rest[parent[n]], rest[n])[:3, :3])
        if np.abs(local - at_rest).max() <= _STILL:
            continue
        _trs(nodes[n], ch.names[b], ch.path)
        quats = continuous_quaternions(rotation_to_quaternion(local))
        tracks[(n, "rotation")] = quats
        animated.append(b)
        samplers.append({"input": times, "output": buf.add(quats, "VEC4", FLOAT), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": n, "path": "rotation"}})

    # the hips: their position when it leaves the rest position (our motions keep the pelvis still)
    hips = bone_node[ch.pelvis]
    target = r.position[:, ch.pelvis] @ ch.to_file[:3, :3].T + ch.to_file[:3, 3]
    if parent[hips] >= 0:
        above_m = node_matrices(nodes, tracks, n_frames)[:, parent[hips]]
        target = np.einsum("tab,tb->ta", np.linalg.inv(above_m), np.c_[target, np.ones(n_frames)])[:, :3]
    rest_t = (rest[hips] if parent[hips] < 0 else np.linalg.solve(rest[parent[hips]], rest[hips]))[:3, 3]
    if np.abs(target - rest_t).max() > _STILL * max(1.0, float(np.abs(rest_t).max())):
        _trs(nodes[hips], ch.names[ch.pelvis], ch.path)
        samplers.append({"input": times, "output": buf.add(target, "VEC3", FLOAT), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": hips, "path": "translation"}})
        if ch.pelvis not in animated:
            animated.append(ch.pelvis)

    binary = _append(doc, ch.gltf.binary, buf, samplers)
    animations = [a for a in doc.get("animations", []) if a.get("name") != ANIMATION]
    dropped: tuple[str, ...] = ()
    if not keep:
        dropped, animations = tuple(str(a.get("name", f"animation {i}")) for i, a in enumerate(animations)), []
    if channels:  # first: the clip a viewer plays when it plays one (theirs follow, as they were)
        animations.insert(0, {"name": ANIMATION, "samplers": samplers, "channels": channels})
    if animations:
        doc["animations"] = animations
    else:
        doc.pop("animations", None)
    asset = dict(doc.get("asset", {"version": "2.0"}))
    theirs = asset.get("generator")
    asset["generator"] = GENERATOR + (f", animating a character from {theirs}" if theirs else "")
    asset["extras"] = _merged(asset.get("extras"), extras)
    scenes = doc.get("scenes", [])
    if scenes:
        scene = scenes[int(doc.get("scene", 0))]
        scene["extras"] = _merged(scene.get("extras"), extras)
    # the asset first: gesturekit.outputs recognises its files by the generator at the head of the JSON
    out = {"asset": asset, **{k: v for k, v in doc.items() if k != "asset"}}
    return out, binary, sorted(animated), dropped


def _merged(theirs: object, ours: dict[str, Any]) -> dict[str, Any]:
    """Their extras (when an object) with ours over them."""
    return {**(theirs if isinstance(theirs, dict) else {}), **ours}


def _below_bone(i: int, parent: list[int], bone_at: dict[int, int]) -> bool:
    p = parent[i]
    while p >= 0:
        if p in bone_at:
            return True
        p = parent[p]
    return False


def _append(doc: dict[str, Any], binary: bytes, buf: GlbBuffer, samplers: list[dict[str, Any]]) -> bytes:
    """Add ``buf``'s views and accessors to ``doc`` after its binary chunk; the new chunk. Renumbers ``samplers``."""
    base = len(binary) + (-len(binary) % 4)
    views = doc.setdefault("bufferViews", [])
    accessors = doc.setdefault("accessors", [])
    first_view, first_accessor = len(views), len(accessors)
    for v in buf.views:
        views.append({**v, "byteOffset": v["byteOffset"] + base})
    for a in buf.accessors:
        accessors.append({**a, "bufferView": a["bufferView"] + first_view})
    for s in samplers:
        s["input"] += first_accessor
        s["output"] += first_accessor
    data = binary + b"\0" * (base - len(binary)) + bytes(buf.data)
    buffers = doc.setdefault("buffers", [])
    if buffers:
        buffers[0]["byteLength"] = len(data)
    else:
        buffers.append({"byteLength": len(data)})
    return data


# ----------------------------------------------------------------------------- reading back


def _measure(data: bytes, r: Retargeted, path: Path) -> tuple[np.ndarray, int]:
    """Each bone's distance (frames, M), metres, read back from the GLB ``data``, from its retargeted position."""
    doc, binary = read_glb(data)
    ch = r.character
    assert ch.gltf is not None
    tracks: dict[tuple[int, str], np.ndarray] = {}
    n = r.n_frames
    for animation in doc.get("animations", []):
        if animation.get("name") != ANIMATION:
            continue
        for channel in animation["channels"]:
            sampler = animation["samplers"][channel["sampler"]]
            times = accessor_array(doc, binary, sampler["input"])
            if len(times) != n or not np.allclose(times, np.arange(n) / r.fps, rtol=1e-6, atol=1e-6):
                raise ConfigError(f"the written animation's keys are not the motion's {n} frames", path=path)
            key = (channel["target"]["node"], channel["target"]["path"])
            tracks[key] = accessor_array(doc, binary, sampler["output"]).astype(np.float64)
    world = node_matrices(doc["nodes"], tracks, n)[:, ch.gltf.nodes][..., :3, 3]
    # back to our frame: to_file is a rotation times a uniform scale
    to_ours = np.linalg.inv(ch.to_file)
    ours = world @ to_ours[:3, :3].T + to_ours[:3, 3]
    return np.linalg.norm(ours - r.position, axis=-1), n
