"""The GLB container: reading and writing its chunks, accessors as arrays, forward kinematics of nodes.

Shared by the glTF gesturekit writes (:mod:`gesturekit.export.gltf`) and the
characters it reads (:mod:`gesturekit.character.user`). Plain numpy, ``struct``
and ``json``; every buffer view starts at a multiple of 4 bytes.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError

__all__ = [
    "FLOAT",
    "UBYTE",
    "USHORT",
    "UINT",
    "ARRAY_BUFFER",
    "ELEMENT_ARRAY_BUFFER",
    "GlbBuffer",
    "glb_bytes",
    "read_glb",
    "accessor_array",
    "quaternion_matrix",
    "node_matrices",
]

FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_DTYPE = {FLOAT: "<f4", UBYTE: "u1", USHORT: "<u2", UINT: "<u4", 5120: "i1", 5122: "<i2"}


class GlbBuffer:
    """The binary chunk, its buffer views and accessors, grown one array at a time."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def add(
        self, array: np.ndarray, kind: str, component: int, *, target: int | None = None, bounds: bool = False
    ) -> int:
        """Append ``array`` (rows of ``kind``) as one buffer view and accessor; its index."""
        a = np.ascontiguousarray(array, dtype=_DTYPE[component])
        self.data.extend(b"\0" * (-len(self.data) % 4))  # every view starts on a 4-byte boundary
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": a.nbytes}
        if target is not None:
            view["target"] = target
        self.data.extend(a.tobytes())
        self.views.append(view)
        accessor: dict[str, Any] = {
            "bufferView": len(self.views) - 1,
            "componentType": component,
            "count": int(a.shape[0]),
            "type": kind,
        }
        if bounds:
            rows = a.reshape(a.shape[0], -1)
            cast = float if component == FLOAT else int
            accessor["min"] = [cast(x) for x in rows.min(axis=0)]
            accessor["max"] = [cast(x) for x in rows.max(axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1


@checks_arguments
def glb_bytes(doc: Mapping[str, Any], binary: bytes) -> bytes:
    """A GLB container: 12-byte header, the JSON chunk (padded with spaces) and the binary chunk
    (padded with zeros), each a multiple of 4 bytes."""
    text = json.dumps(doc, separators=(",", ":"), ensure_ascii=True).encode("ascii")
    text += b" " * (-len(text) % 4)
    binary = binary + b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return b"".join(
        [
            struct.pack("<4sII", b"glTF", 2, total),
            struct.pack("<I4s", len(text), b"JSON"),
            text,
            struct.pack("<I4s", len(binary), b"BIN\0"),
            binary,
        ]
    )


@checks_arguments
def read_glb(data: bytes) -> tuple[dict[str, Any], bytes]:
    """The JSON and the binary chunk of a GLB file's bytes.

    Raises
    ------
    ConfigError
        Not a GLB 2.0 container, or a chunk that does not fit in it.
    """
    if len(data) < 20 or data[:4] != b"glTF":
        raise ConfigError("not a binary glTF file (no glTF header)")
    _magic, version, total = struct.unpack_from("<4sII", data, 0)
    if version != 2 or total != len(data):
        raise ConfigError(f"not a GLB 2.0 file of its length (version {version}, {total} of {len(data)} bytes)")
    doc: dict[str, Any] | None = None
    binary = b""
    at = 12
    while at + 8 <= total:
        length, kind = struct.unpack_from("<I4s", data, at)
        chunk = data[at + 8 : at + 8 + length]
        if len(chunk) != length:
            raise ConfigError(f"a GLB chunk of {length} bytes runs past the end of the file")
        if kind == b"JSON":
            doc = json.loads(chunk.decode("utf-8"))
        elif kind == b"BIN\0":
            binary = chunk
        at += 8 + length
    if doc is None:
        raise ConfigError("a GLB file without its JSON chunk")
    return doc, binary


@checks_arguments
def accessor_array(doc: Mapping[str, Any], binary: bytes, index: int) -> np.ndarray:
    """Accessor ``index`` of a glTF document as an array (count, components) (``(count,)`` for scalars).

    Raises
    ------
    ConfigError
        The accessor runs past its buffer view, or the view past the binary data.
    """
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = np.dtype(_DTYPE[acc["componentType"]])
    width = _WIDTH[acc["type"]]
    at, length = int(view.get("byteOffset", 0)), int(view["byteLength"])
    if at < 0 or length < 0 or at + length > len(binary):
        raise ConfigError(
            f"buffer view {acc['bufferView']} (bytes {at} to {at + length}) runs past the {len(binary)} bytes of data"
        )
    offset, count = int(acc.get("byteOffset", 0)), int(acc["count"])
    stride = int(view.get("byteStride", width * dtype.itemsize))
    end = offset + (count - 1) * stride + width * dtype.itemsize if count > 0 else offset
    if offset < 0 or count < 0 or stride < width * dtype.itemsize or end > length:
        raise ConfigError(
            f"accessor {index} ({count} x {acc['type']} from byte {offset}, stride {stride}) runs past its buffer "
            f"view of {length} bytes"
        )
    start = at + offset
    rows = np.ndarray(
        (acc["count"], width), dtype=dtype, buffer=binary, offset=start, strides=(stride, dtype.itemsize)
    ).copy()
    return rows[:, 0] if acc["type"] == "SCALAR" else rows


@checks_arguments
def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) ``(x, y, z, w)``, normalised first."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


@checks_arguments
def node_matrices(
    nodes: Sequence[Mapping[str, Any]], tracks: Mapping[tuple[int, str], np.ndarray], n_frames: int
) -> np.ndarray:
    """Forward kinematics of glTF nodes: every node's world transform at every key.

    Parameters
    ----------
    nodes : sequence of mapping
        glTF nodes (``children``, ``translation``, ``rotation``, ``scale`` or ``matrix``).
    tracks : mapping
        ``(node, path) -> values`` of the animation, ``path`` one of ``"translation"`` (n_frames, 3),
        ``"rotation"`` (n_frames, 4) ``(x, y, z, w)`` and ``"scale"`` (n_frames, 3), one row per key;
        a node's own value holds where there is no track.
    n_frames : int

    Returns
    -------
    np.ndarray, shape (n_frames, len(nodes), 4, 4)
        ``world[t, i] @ [p; 1]`` takes a point ``p`` of node ``i``'s frame to the world (the file's units).
    """
    parent = [-1] * len(nodes)
    for i, node in enumerate(nodes):
        for c in node.get("children", ()):
            parent[c] = i
    world = np.zeros((n_frames, len(nodes), 4, 4))
    done = [False] * len(nodes)

    def local(i: int) -> np.ndarray:
        node = nodes[i]
        m = np.tile(np.eye(4), (n_frames, 1, 1))
        if "matrix" in node:
            m[:] = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major
            return m
        t = tracks.get((i, "translation"), np.asarray(node.get("translation", (0, 0, 0)), dtype=np.float64))
        r = tracks.get((i, "rotation"), np.asarray(node.get("rotation", (0, 0, 0, 1)), dtype=np.float64))
        s = tracks.get((i, "scale"), np.asarray(node.get("scale", (1, 1, 1)), dtype=np.float64))
        m[:, :3, :3] = quaternion_matrix(r) * np.asarray(s, dtype=np.float64)[..., None, :]
        m[:, :3, 3] = t
        return m

    def place(i: int) -> None:
        if done[i]:
            return
        if parent[i] >= 0:
            place(parent[i])
            world[:, i] = world[:, parent[i]] @ local(i)
        else:
            world[:, i] = local(i)
        done[i] = True

    for i in range(len(nodes)):
        place(i)
    return world
