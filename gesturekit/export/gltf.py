"""Motion as a binary glTF file (``.glb``): the character, its skeleton, skin and animation, with the speech beside it.

One file that 3D tools and the web (Blender, three.js, model viewers) open as
an animated, skinned character:

* **Skeleton.** One node per joint of the rig (:func:`gesturekit.character.rig.rig_for`),
  named by :data:`gesturekit.skeleton.JOINT_NAMES` as in the BVH, in the
  motion's coordinates (metres, Y up, the character faces +Z). A node's rest
  translation is its bone's offset in the rig's T-pose; the root rests at the
  origin. Of a partial skeleton only the drawn joints become nodes, each under
  its nearest drawn ancestor, as in the BVH.
* **Animation.** The rotations of the shared solve
  (:func:`gesturekit.character.rig.solve_pose`, the BVH's) as quaternions,
  one key per frame at the motion's frame rate (key ``i`` at ``i / fps``
  seconds), interpolated linearly; each joint's quaternions keep one sign
  from frame to frame, so the interpolation takes the short way. The root
  also carries its position.
* **Skin and body.** The body of :func:`gesturekit.character.mesh.build_mesh`
  bound to the skeleton: inverse bind matrices (a translation by minus the
  joint's rest position; rest rotations are the identity), ``JOINTS_0`` and
  ``WEIGHTS_0`` per vertex, one primitive per part (:data:`~gesturekit.character.mesh.PARTS`)
  with a plain PBR material (metallic 0, roughness :data:`ROUGHNESS`) of the
  part's colour in the chosen scheme (:func:`gesturekit.character.look.part_colors`,
  converted to linear light as glTF's ``baseColorFactor`` is).
* **Legs.** Our motions hold the upper body only; the still hips, legs and shoes of
  :func:`gesturekit.character.stand.stand_mesh` are a second mesh (``legs``, not skinned) on a node of
  their own, in the motion's frame: the pelvis at the origin (as in the BVH), the soles on the floor at
  ``extras.floor`` metres (negative: below the pelvis).
* **Speech.** glTF has no audio; the speech is written as a 16-bit WAV beside
  the file (the same name with ``.wav``) and named in the extras of the
  ``asset`` and of the scene: ``{"audio": "take.wav", "fps": 15.0, "frames": ..}``.

The file is written by gesturekit itself (numpy, ``struct``, ``json``): the
GLB container, one binary buffer, every buffer view starting at a multiple of
4 bytes.

Error report
------------
:func:`export_gltf` reads the written bytes back by another path than the one
that wrote them (:func:`read_glb`, :func:`accessor_array`, and forward
kinematics of the nodes' transforms and animation, :func:`node_matrices`)
and compares every joint with the motion: a :class:`GltfReport`. The file
holds the rig's bones, each of one length (the median over the motion), in
32-bit floats: a motion whose bones keep their lengths is reproduced to well
under a micrometre (0.09 um on 82 s of the demo database). Over
:data:`WARN_ABOVE` (1 mm) it warns.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from .._io import Target, target_path
from .._version import __version__
from ..character.glb import ARRAY_BUFFER as _ARRAY_BUFFER
from ..character.glb import ELEMENT_ARRAY_BUFFER as _ELEMENT_ARRAY_BUFFER
from ..character.glb import FLOAT as _FLOAT
from ..character.glb import UBYTE as _UBYTE
from ..character.glb import UINT as _UINT
from ..character.glb import USHORT as _USHORT
from ..character.glb import GlbBuffer, accessor_array, glb_bytes, node_matrices, read_glb
from ..character.look import part_colors
from ..character.mesh import PARTS, build_mesh
from ..character.rig import Rig, rig_for, rotation_to_quaternion, solve_pose
from ..character.solve import bvh_parents
from ..character.stand import stand_mesh, standing_root
from ..errors import ConfigError, OutputError
from ..motion import AUDIO_SR, Motion
from ..outputs import MP4_TAG, check_output
from ..skeleton import DERIVED, JOINT_NAMES, N_JOINTS, PARENTS
from ._files import write_export
from .bvh import error_warning, summary_parts

__all__ = [
    "WARN_ABOVE",
    "ROUGHNESS",
    "GENERATOR",
    "WAV_TAG",
    "GltfReport",
    "export_gltf",
    "audio_path_for",
    "speech_targets",
    "continuous_quaternions",
    "glb_bytes",
    "read_glb",
    "accessor_array",
    "node_matrices",
]

#: Largest position error of a written file (metres) that passes without a warning: the BVH's, since both files
#: hold the same solve and miss the motion for the same reason (bones whose length changes over the motion).
WARN_ABOVE = 0.01

#: Roughness of every material (a matte body).
ROUGHNESS = 0.9

#: The ``asset.generator`` of every file written.
GENERATOR = f"gesturekit {__version__}"

#: Marker in the WAV files gesturekit writes (a RIFF ``LIST/INFO`` ``ISFT`` entry), by which
#: :func:`gesturekit.outputs.check_output` recognises them.
WAV_TAG = MP4_TAG.encode("ascii")


@dataclass(frozen=True, eq=False)
class GltfReport:
    """What a written glTF file holds, and how well it reproduces the motion.

    The errors are measured on the bytes as written: parsed again, forward
    kinematics of their nodes and animation, every joint of every frame
    against the motion's positions.

    Attributes
    ----------
    path : Path
        The ``.glb`` file written.
    audio : Path or None
        The speech's WAV beside it (None without speech).
    frames : int
        Animation keys, one per frame of the motion.
    fps : float
        Keys per second.
    joints : tuple of str
        The joints written (the skeleton's nodes), in the skin's order.
    max_error, mean_error : float
        Largest and mean distance of a joint from its position in the motion, metres.
    worst_joint : str
        The joint of the largest error.
    worst_frame : int
        Its frame.
    root : str
        The root joint.
    left_out : tuple of str
        Joints not written (absent from the motion).
    derived : tuple of str
        Joints written that the data does not hold (placed from others).
    vertices, triangles : int
        Size of the body.
    size : int
        Bytes of the file.
    remedy : str or None
        What the warning says would bring the file closer to the motion, as
        :attr:`gesturekit.export.bvh.BvhReport.remedy`.
    """

    path: Path
    audio: Path | None
    frames: int
    fps: float
    joints: tuple[str, ...]
    max_error: float
    mean_error: float
    worst_joint: str
    worst_frame: int
    root: str
    left_out: tuple[str, ...]
    derived: tuple[str, ...]
    vertices: int
    triangles: int
    size: int
    remedy: str | None = None

    @property
    def exceeds(self) -> bool:
        """The largest error is over :data:`WARN_ABOVE`."""
        return self.max_error > WARN_ABOVE

    def warning(self) -> str | None:
        """What the warning over :data:`WARN_ABOVE` says (without the file's path); None below it."""
        if not self.exceeds:
            return None
        return error_warning(f"the glTF file is up to {self.max_error * 1000:.1f} mm off the motion", self)

    def summary(self) -> str:
        """One line, e.g. ``"take.glb: position error max 0.00 mm ..., 55 joints, 200 frames at 15 fps; ..."``."""
        error, root, left_out = summary_parts(self)
        parts = [
            error,
            f"{len(self.joints)} joints, {self.frames} frames at {self.fps:g} fps, root at {root}",
            f"body of {self.vertices} vertices; {self.size / 1e6:.1f} MB",
            *left_out,
        ]
        if self.audio is not None:
            parts.append(f"speech in {self.audio.name}")
        return "; ".join(parts)


@checks_arguments
def audio_path_for(path: str | os.PathLike[str]) -> Path:
    """Where :func:`export_gltf` writes the speech of ``path``: the same name with ``.wav``."""
    return Path(path).with_suffix(".wav")


@checks_arguments
def speech_targets(
    path: Path, audio: np.ndarray | None, sr: int, *, overwrite: bool
) -> tuple[Path | None, np.ndarray | None]:
    """Check the speech of a glTF file about to be written and whether it and its WAV may be written.

    Parameters
    ----------
    path : Path
        The glTF file.
    audio : np.ndarray, shape (samples,), or None
        The speech, float samples.
    sr : int
        Its sample rate, Hz.
    overwrite : bool
        Whether existing files (that gesturekit wrote) may be replaced.

    Returns
    -------
    wav_path : Path or None
        :func:`audio_path_for` ``(path)``; None without speech.
    samples : np.ndarray or None
        The speech as float64.

    Raises
    ------
    ConfigError
        Speech that is not one channel of finite samples, a bad sample rate, a glTF named ``.wav``, or a file
        that exists and may not be replaced (:class:`~gesturekit.errors.OutputError`).
    """
    wav_path = None
    samples = None
    if audio is not None:
        samples = np.asarray(audio, dtype=np.float64)
        if samples.ndim != 1 or samples.size == 0 or not np.isfinite(samples).all():
            raise ConfigError("the speech must be one channel of finite samples", path=path)
        if not isinstance(sr, (int, np.integer)) or sr <= 0:
            raise ConfigError(f"the speech's sample rate must be a positive integer, got {sr!r}", path=path)
        wav_path = audio_path_for(path)
        if wav_path == path:
            raise ConfigError("the glTF file cannot have the suffix .wav of its speech; name it .glb", path=path)
    for p in (path, wav_path):
        if p is None:
            continue
        if not overwrite and (p.exists() or p.is_symlink()):
            raise OutputError("already exists; pass overwrite=True (--force on the command line) to replace it", path=p)
        if overwrite:
            check_output(p, "file", overwrite=True)  # only a file gesturekit wrote is replaced
    return wav_path, samples


@checks_arguments
def export_gltf(
    path: Target,
    motion: Motion,
    *,
    audio: np.ndarray | None = None,
    sr: int = AUDIO_SR,
    scheme: str = "blue",
    overwrite: bool = False,
    rest: np.ndarray | None = None,
    remedy: str | None = None,
) -> GltfReport:
    """Write a motion as a binary glTF file (and its speech as a WAV beside it), atomically, and report
    how well the file reproduces the motion.

    Warns (:class:`~gesturekit.errors.GestureKitWarning`) when a joint of the
    file is more than :data:`WARN_ABOVE` from its position in the motion.

    Parameters
    ----------
    path : str, os.PathLike or binary file object
        The file to create (written exactly there, atomically; ``.glb`` is the usual suffix), or a
        binary file object to write it into (then without ``audio``, which has no place beside it:
        write that with :func:`gesturekit.datasets.audio.write_wav`).
    motion : Motion
        Positions (frames, 55, 3) in metres and fps. At least one frame; every
        value finite. Only its drawn joints are written.
    audio : np.ndarray, shape (samples,), optional
        The speech, float samples in [-1, 1] (clipped beyond), written as 16-bit
        PCM to :func:`audio_path_for` ``(path)`` and named in the file.
    sr : int
        Its sample rate, Hz.
    scheme : str
        Colour scheme of the body, a key of :data:`gesturekit.character.look.SCHEMES`.
    overwrite : bool
        Replace an existing file (and WAV) that gesturekit wrote.
    rest : np.ndarray, shape (55, 3), optional
        Joint positions whose bone directions make the rest pose, as for
        :func:`gesturekit.character.rig.rig_for`; default the T-pose.
    remedy : str, optional
        What the warning names as the way to a closer file, as for
        :func:`gesturekit.export.bvh.export_bvh`.

    Returns
    -------
    GltfReport

    Raises
    ------
    ConfigError
        Invalid motion, speech, scheme or rest pose, drawn joints that do not
        form one tree, or a file to write exists and ``overwrite`` is False
        (:class:`~gesturekit.errors.OutputError`).
    """
    target, path = path, target_path(path, "motion.glb")
    if not isinstance(motion, Motion):
        raise ConfigError(f"motion must be a gesturekit Motion, got {type(motion).__name__}", path=path)
    try:
        colors = part_colors(scheme)
    except ConfigError as exc:
        raise ConfigError(exc.problem, path=path) from None
    if motion.n_frames == 0:
        raise ConfigError("cannot write a motion without frames", path=path)
    positions = motion.positions.astype(np.float64)
    bad = ~np.isfinite(positions).all(axis=(1, 2))
    if bad.any():
        raise ConfigError(f"positions are not finite (NaN or infinite) from frame {int(np.argmax(bad))} on", path=path)
    bvh_parents(motion.presence, path=path)  # a skeleton no tree can hold, named with the file
    if isinstance(target, (str, os.PathLike)):
        wav_path, samples = speech_targets(path, audio, sr, overwrite=overwrite)
    elif audio is not None:
        raise ConfigError("a glTF written into a file object has no folder for its speech's WAV; pass no audio")
    else:
        wav_path, samples = None, None

    try:
        rig = rig_for(motion, rest=rest)
    except ConfigError as exc:
        raise ConfigError(exc.problem, path=exc.path or path) from None
    written = [j for j in range(N_JOINTS) if rig.parents[j] >= -1]
    extras: dict[str, Any] = {"fps": float(motion.fps), "frames": int(motion.n_frames), "units": "m"}
    if wav_path is not None:
        extras["audio"] = wav_path.name
    doc, binary, n_vertices, n_triangles = _document(motion, rig, written, colors, extras)
    data = glb_bytes(doc, binary)
    measured = _measure(data, positions, path=path, written=written)
    derived = motion.presence.names(DERIVED)
    report = GltfReport(
        path=path,
        audio=wav_path,
        frames=measured.frames,
        fps=measured.fps,
        joints=measured.joints,
        max_error=measured.max_error,
        mean_error=measured.mean_error,
        worst_joint=measured.worst_joint,
        worst_frame=measured.worst_frame,
        root=JOINT_NAMES[rig.root],
        left_out=tuple(JOINT_NAMES[j] for j in range(N_JOINTS) if rig.parents[j] < -1),
        derived=tuple(n for n in derived if n in measured.joints),
        vertices=n_vertices,
        triangles=n_triangles,
        size=len(data),
        remedy=remedy,
    )
    write_export(
        target,
        data,
        overwrite=overwrite,
        wav_path=wav_path,
        samples=samples,
        sr=sr,
        warning=report.warning(),
        stacklevel=2,
    )
    return report


# ----------------------------------------------------------------------------- the document


def _linear(srgb: np.ndarray) -> np.ndarray:
    """sRGB colour components in [0, 1] in linear light (the sRGB transfer function)."""
    c = np.asarray(srgb, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _material(name: str, srgb: np.ndarray) -> dict[str, Any]:
    """A plain PBR material of one part's sRGB colour (glTF's ``baseColorFactor`` is in linear light)."""
    return {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [*(float(c) for c in _linear(srgb)), 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": ROUGHNESS,
        },
    }


def _unit_normals(normals: np.ndarray) -> np.ndarray:
    """Normals of unit length (glTF requires it); a zero normal becomes +Y."""
    n = np.asarray(normals, dtype=np.float64)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-12, n / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])


@checks_arguments
def continuous_quaternions(q: np.ndarray) -> np.ndarray:
    """Quaternions (frames, ..., 4) with each one's sign chosen to be nearest the previous frame's."""
    q = q.copy()
    for t in range(1, len(q)):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t][flip] *= -1
    return q


def _document(
    motion: Motion, rig: Rig, written: list[int], colors: np.ndarray, extras: dict[str, Any]
) -> tuple[dict[str, Any], bytes, int, int]:
    """The glTF JSON and its binary chunk; the body's vertex and triangle counts."""
    pose = solve_pose(motion, rig)
    mesh = build_mesh(rig)
    buf = GlbBuffer()
    node_of = {j: k for k, j in enumerate(written)}
    nodes: list[dict[str, Any]] = []
    for j in written:
        node: dict[str, Any] = {"name": JOINT_NAMES[j]}
        if rig.parents[j] >= 0:
            node["translation"] = [float(x) for x in np.float32(rig.offsets[j])]
        children = [node_of[c] for c in written if rig.parents[c] == j]
        if children:
            node["children"] = children
        nodes.append(node)
    root = node_of[rig.root]

    # skin: the rest pose has identity rotations, so B_j is a translation to the joint's rest position
    ibm = np.tile(np.eye(4), (len(written), 1, 1))
    ibm[:, :3, 3] = -rig.rest[written]
    ibm_acc = buf.add(ibm.transpose(0, 2, 1).reshape(len(written), 16), "MAT4", _FLOAT)  # column-major
    skin = {"name": "skeleton", "inverseBindMatrices": ibm_acc, "joints": list(range(len(written))), "skeleton": root}

    # a vertex bound to a joint outside the rig moves with its nearest ancestor in it, as Pose.world places it
    slot = np.zeros(N_JOINTS, np.int64)
    for j in range(N_JOINTS):
        a = j
        while rig.parents[a] < -1:
            a = int(PARENTS[a]) if PARENTS[a] >= 0 else rig.root
        slot[j] = node_of[a]
    weights = mesh.weights.astype(np.float64)
    weights /= weights.sum(axis=1, keepdims=True)
    joints = np.where(weights > 0, slot[mesh.joints.astype(np.int64)], 0)
    normals = mesh.normals.astype(np.float64)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])
    attributes = {
        "POSITION": buf.add(mesh.vertices, "VEC3", _FLOAT, target=_ARRAY_BUFFER, bounds=True),
        "NORMAL": buf.add(normals, "VEC3", _FLOAT, target=_ARRAY_BUFFER),
        "JOINTS_0": buf.add(joints, "VEC4", _UBYTE if len(written) <= 256 else _USHORT, target=_ARRAY_BUFFER),
        "WEIGHTS_0": buf.add(weights, "VEC4", _FLOAT, target=_ARRAY_BUFFER),
    }
    face_part = mesh.parts[mesh.faces[:, 0]]
    index_type = _USHORT if mesh.n_vertices <= 65535 else _UINT
    primitives: list[dict[str, Any]] = []
    materials: list[dict[str, Any]] = []
    for p, name in enumerate(PARTS):
        faces = mesh.faces[face_part == p]
        if not len(faces):
            continue
        indices = buf.add(faces.reshape(-1), "SCALAR", index_type, target=_ELEMENT_ARRAY_BUFFER)
        primitives.append({"attributes": attributes, "indices": indices, "material": len(materials), "mode": 4})
        materials.append(_material(name, colors[p]))
    nodes.append({"name": "character", "mesh": 0, "skin": 0})
    scene_nodes = [root, len(nodes) - 1]
    meshes: list[dict[str, Any]] = [{"name": "body", "primitives": primitives}]
    # the still legs (our motions have no legs to move them): a plain mesh in the motion's frame, on the floor
    stand = stand_mesh(rig, standing_root(pose.root))
    if stand is not None:
        legs = {
            "POSITION": buf.add(stand.vertices, "VEC3", _FLOAT, target=_ARRAY_BUFFER, bounds=True),
            "NORMAL": buf.add(_unit_normals(stand.normals), "VEC3", _FLOAT, target=_ARRAY_BUFFER),
        }
        leg_primitives = []
        leg_part = stand.parts[stand.faces[:, 0]]
        for p, name in enumerate(PARTS):
            faces = stand.faces[leg_part == p]
            if not len(faces):
                continue
            index = buf.add(
                faces.reshape(-1),
                "SCALAR",
                _USHORT if stand.n_vertices <= 65535 else _UINT,
                target=_ELEMENT_ARRAY_BUFFER,
            )
            leg_primitives.append({"attributes": legs, "indices": index, "material": len(materials), "mode": 4})
            materials.append(_material(name, colors[p]))
        meshes.append({"name": "legs", "primitives": leg_primitives})
        nodes.append({"name": "legs", "mesh": 1})
        scene_nodes.append(len(nodes) - 1)
        extras = {**extras, "floor": float(stand.floor)}

    n = pose.n_frames
    times = buf.add(np.arange(n) / float(motion.fps), "SCALAR", _FLOAT, bounds=True)
    quats = continuous_quaternions(rotation_to_quaternion(pose.local[:, written]))
    samplers = [{"input": times, "output": buf.add(pose.root, "VEC3", _FLOAT), "interpolation": "LINEAR"}]
    channels = [{"sampler": 0, "target": {"node": root, "path": "translation"}}]
    for k in range(len(written)):
        samplers.append({"input": times, "output": buf.add(quats[:, k], "VEC4", _FLOAT), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": k, "path": "rotation"}})

    doc = {
        "asset": {"version": "2.0", "generator": GENERATOR, "extras": extras},
        "scene": 0,
        "scenes": [{"name": "gesturekit", "nodes": scene_nodes, "extras": extras}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "skins": [skin],
        "animations": [{"name": "motion", "samplers": samplers, "channels": channels}],
        "accessors": buf.accessors,
        "bufferViews": buf.views,
        "buffers": [{"byteLength": len(buf.data) + (-len(buf.data) % 4)}],
    }
    return doc, bytes(buf.data), mesh.n_vertices, int(len(mesh.faces))


# ----------------------------------------------------------------------------- reading back


@dataclass(frozen=True)
class _Measured:
    frames: int
    fps: float
    joints: tuple[str, ...]
    max_error: float
    mean_error: float
    worst_joint: str
    worst_frame: int


def _measure(data: bytes, positions: np.ndarray, *, path: Path, written: list[int]) -> _Measured:
    """The errors of the GLB ``data`` against ``positions``, read back from its bytes."""
    doc, binary = read_glb(data)
    animation = doc["animations"][0]
    tracks: dict[tuple[int, str], np.ndarray] = {}
    times = None
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        times = accessor_array(doc, binary, sampler["input"])
        tracks[(channel["target"]["node"], channel["target"]["path"])] = accessor_array(doc, binary, sampler["output"])
    assert times is not None
    fps = float(doc["asset"]["extras"]["fps"])
    if len(times) != len(positions) or not np.allclose(times, np.arange(len(positions)) / fps, rtol=1e-6, atol=1e-6):
        raise ConfigError(f"the written animation's keys are not the motion's {len(positions)} frames", path=path)
    world = node_matrices(doc["nodes"], tracks, len(times))[..., :3, 3]
    by_name = {node.get("name"): i for i, node in enumerate(doc["nodes"])}
    names = tuple(JOINT_NAMES[j] for j in written)
    err = np.linalg.norm(world[:, [by_name[n] for n in names]] - positions[:, written], axis=-1)
    frame, k = np.unravel_index(int(np.argmax(err)), err.shape)
    return _Measured(
        frames=len(times),
        fps=fps,
        joints=names,
        max_error=float(err.max()),
        mean_error=float(err.mean()),
        worst_joint=names[int(k)],
        worst_frame=int(frame),
    )
