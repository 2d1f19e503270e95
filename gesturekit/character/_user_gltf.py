"""A glTF, GLB or VRM file's skeleton and skinned body as a character, in the file's own frame.

The bones are the joints of the file's skins (all nodes when it has none),
with the nodes a VRM humanoid names and a finger tip for each distal finger
bone that has a child node. The body is every skinned mesh, posed at rest by
its skin (each vertex ``sum_k w_k World_{j_k} IBM_{j_k} v``), and every mesh
on a node under a bone, carried rigidly by that bone. Its colour per vertex is
the material's base colour times its texture, sampled at the vertex, times the
vertex colour.
"""

from __future__ import annotations

import base64
import io
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, InputFileError
from ..limits import check_bytes, read_json
from ..skeleton import FINGERS
from .glb import accessor_array, node_matrices, read_glb
from .humanoid import VRM_BONES
from .mesh import vertex_normals
from .target import FileSkeleton, GltfSource, empty_skin, reorder, topological

__all__ = ["read_gltf_skeleton", "MAX_VERTICES"]

#: Most vertices a character's body may have (a detailed game character has some 100 000).
MAX_VERTICES = 2_000_000

_TRIANGLES = 4


def read_gltf_skeleton(path: Path) -> FileSkeleton:
    """The skeleton and body of a ``.glb``, ``.vrm`` or ``.gltf``.

    Raises
    ------
    InputFileError
        Not a readable glTF 2.0 file, or a part of it (an accessor, a buffer, an image) out of its bounds.
    """
    try:
        check_bytes(path.stat().st_size, what="a character file", path=path)
        doc, binary = _load(path)
        return _skeleton(path, doc, binary)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OSError, RecursionError) as e:
        raise InputFileError(f"not a readable glTF character ({type(e).__name__}: {e})", path=path) from None
    except ConfigError as e:
        if e.path is not None:
            raise
        raise InputFileError(e.problem, path=path) from None


def _load(path: Path) -> tuple[dict[str, Any], bytes]:
    """The document and one binary buffer (a .gltf's buffers and images inlined into it)."""
    if path.suffix.lower() != ".gltf":
        doc, binary = read_glb(path.read_bytes())
        if len(doc.get("buffers", [])) > 1 or any("uri" in b for b in doc.get("buffers", [])):
            raise InputFileError("a GLB whose data is outside its binary chunk is not read", path=path)
        return doc, bytes(binary)
    doc = dict(read_json(path, what="a glTF file"))  # type: ignore[call-overload]
    blob = bytearray()
    bases = []
    for b in doc.get("buffers", []):
        blob.extend(b"\0" * (-len(blob) % 4))
        bases.append(len(blob))
        blob.extend(_uri_bytes(path, b.get("uri", "")))
    for v in doc.get("bufferViews", []):
        v["byteOffset"] = v.get("byteOffset", 0) + bases[v["buffer"]]
        v["buffer"] = 0
    for img in doc.get("images", []):
        if "uri" in img:
            data = _uri_bytes(path, img.pop("uri"))
            blob.extend(b"\0" * (-len(blob) % 4))
            doc.setdefault("bufferViews", []).append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
            blob.extend(data)
            img["bufferView"] = len(doc["bufferViews"]) - 1
            img.setdefault("mimeType", "image/jpeg" if data[:2] == b"\xff\xd8" else "image/png")
    doc["buffers"] = [{"byteLength": len(blob)}] if blob else []
    return doc, bytes(blob)


def _uri_bytes(path: Path, uri: str) -> bytes:
    """A buffer's or image's bytes: a data URI, or a file beside the .gltf (no other folder)."""
    if uri.startswith("data:"):
        head, _, data = uri.partition(",")
        if not head.endswith(";base64"):
            raise InputFileError("a data URI that is not base64", path=path)
        return base64.b64decode(data, validate=True)
    name = Path(uri)
    if not uri or name.name != uri or uri in (".", ".."):
        raise InputFileError(f"{uri!r}: a glTF's files must lie beside it (no folders, no URLs)", path=path)
    other = path.parent / uri
    if not other.is_file():
        raise InputFileError(f"the file {uri!r} it names is missing", path=path)
    check_bytes(other.stat().st_size, what="a glTF buffer", path=other)
    return other.read_bytes()


def _skeleton(path: Path, doc: dict[str, Any], binary: bytes) -> FileSkeleton:
    nodes = doc.get("nodes", [])
    if not nodes:
        raise InputFileError("a glTF without nodes has no skeleton", path=path)
    parent = [-1] * len(nodes)
    for i, node in enumerate(nodes):
        for c in node.get("children", ()):
            if parent[c] != -1 or c == i:
                raise InputFileError(f"node {c} has two parents", path=path)
            parent[c] = i
    for i in range(len(nodes)):  # a cycle of nodes would send forward kinematics round for ever
        a, steps = parent[i], 0
        while a >= 0:
            a, steps = parent[a], steps + 1
            if steps > len(nodes):
                raise InputFileError(f"node {i}'s ancestors form a cycle", path=path)
    skins = doc.get("skins", [])
    candidates = sorted({int(j) for s in skins for j in s["joints"]}) if skins else list(range(len(nodes)))
    kind, humanoid = _humanoid(doc)
    chosen = set(candidates) | set(humanoid.values())
    for key, tip in _tips(nodes, humanoid).items():
        humanoid[key] = tip
        chosen.add(tip)
    bone_nodes = sorted(chosen)
    in_set = set(bone_nodes)

    def up(i: int) -> int:
        p = parent[i]
        while p >= 0 and p not in in_set:
            p = parent[p]
        return p

    index = {n: k for k, n in enumerate(bone_nodes)}
    names = [str(nodes[n].get("name", f"node{n}")) for n in bone_nodes]
    parents = [index[up(n)] if up(n) >= 0 else -1 for n in bone_nodes]
    order = topological(parents)
    names_t, parents_t, new = reorder(names, parents, order)
    node_of = np.array([bone_nodes[o] for o in order], dtype=np.int64)
    world_all = node_matrices(nodes, {}, 1)[0]
    found = None
    if humanoid:
        label = "VRM 1.0 humanoid" if kind == "vrm1" else "VRM 0.x humanoid"
        found = {k: int(new[index[n]]) for k, n in humanoid.items()}
        expected = dict(VRM_BONES[1 if kind == "vrm1" else 0])
    skin = _skin(doc, binary, world_all, parent, {int(n): int(new[index[n]]) for n in bone_nodes}, path)
    return FileSkeleton(
        path=path,
        kind=kind,
        names=names_t,
        parents=parents_t,
        world=world_all[node_of],
        humanoid=None if found is None else (label, found, expected),
        skin=skin,
        gltf=GltfSource(document=doc, binary=binary, nodes=node_of),
    )


def _tips(nodes: list[dict[str, Any]], humanoid: dict[str, int]) -> dict[str, int]:
    """The nodes that stand for the finger tips and the head top, which a VRM humanoid does not name: of a distal
    finger bone, the child named like an end (``..._end``), else its only child; of the head, the child named so."""
    out = {}
    for key, node in humanoid.items():
        kids = [int(c) for c in nodes[node].get("children", [])]
        ends = [c for c in kids if str(nodes[c].get("name", "")).lower().endswith("end")]
        if key.endswith("3") and key[:-1].split("_")[-1] in FINGERS:
            pick = ends[0] if ends else kids[0] if len(kids) == 1 else -1
            if pick >= 0:
                out[key[:-1] + "4"] = pick
        elif key == "head" and len(ends) == 1:
            out["head_top"] = ends[0]
    return out


def _humanoid(doc: dict[str, Any]) -> tuple[str, dict[str, int]]:
    """The file's kind and its VRM humanoid (our joint -> node), empty when not a VRM."""
    ext = doc.get("extensions", {})
    if "VRMC_vrm" in ext:
        bones = {k: int(v["node"]) for k, v in ext["VRMC_vrm"]["humanoid"]["humanBones"].items()}
        table = VRM_BONES[1]
        kind = "vrm1"
    elif "VRM" in ext:
        listed = ext["VRM"]["humanoid"]["humanBones"]
        bones = {str(b["bone"]): int(b["node"]) for b in listed if int(b.get("node", -1)) >= 0}
        table = VRM_BONES[0]
        kind = "vrm0"
    else:
        return "gltf", {}
    ours = {theirs: mine for mine, theirs in table.items()}
    return kind, {ours[b]: n for b, n in bones.items() if b in ours}


def _skin(
    doc: dict[str, Any], binary: bytes, world: np.ndarray, parent: list[int], bone_of_node: dict[int, int], path: Path
) -> dict[str, np.ndarray]:
    """Every mesh on a skinned node or under a bone, at rest, in the file's world frame."""
    parts: list[dict[str, np.ndarray]] = []
    total = 0
    images: dict[int, np.ndarray] = {}
    for i, node in enumerate(doc.get("nodes", [])):
        if "mesh" not in node:
            continue
        if "skin" in node:
            skin = doc["skins"][node["skin"]]
            joints = [int(j) for j in skin["joints"]]
            ibm = (
                accessor_array(doc, binary, skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
                if "inverseBindMatrices" in skin
                else np.tile(np.eye(4), (len(joints), 1, 1))
            )
            mats = world[joints] @ ibm
            to_bone = np.array([bone_of_node[j] for j in joints], dtype=np.int64)
        else:
            a = parent[i]
            while a >= 0 and a not in bone_of_node:
                a = parent[a]
            if a < 0:
                continue  # a mesh beside the character (a floor, a prop): not part of it
            mats, to_bone = world[i][None], np.array([bone_of_node[a]], dtype=np.int64)
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            if prim.get("mode", _TRIANGLES) != _TRIANGLES:
                continue
            part = _primitive(doc, binary, prim, mats, to_bone, "skin" in node, images)
            total += len(part["vertices"])
            if total > MAX_VERTICES:
                raise InputFileError(f"a body of more than {MAX_VERTICES} vertices", path=path)
            parts.append(part)
    if not parts:
        return empty_skin()
    out = {key: np.concatenate([p[key] for p in parts]) for key in parts[0] if key != "faces"}
    starts = np.cumsum([0] + [len(p["vertices"]) for p in parts[:-1]])
    out["faces"] = np.concatenate([p["faces"] + s for p, s in zip(parts, starts)])
    return out


def _primitive(
    doc: dict[str, Any],
    binary: bytes,
    prim: dict[str, Any],
    mats: np.ndarray,
    to_bone: np.ndarray,
    skinned: bool,
    images: dict[int, np.ndarray],
) -> dict[str, np.ndarray]:
    attrs = prim["attributes"]
    v = accessor_array(doc, binary, attrs["POSITION"]).astype(np.float64)
    n = len(v)
    faces = (
        accessor_array(doc, binary, prim["indices"]).astype(np.int64).reshape(-1, 3)
        if "indices" in prim
        else np.arange(n - n % 3, dtype=np.int64).reshape(-1, 3)
    )
    if faces.size and (faces.min() < 0 or faces.max() >= n):
        raise ValueError("a primitive's indices point past its vertices")
    if skinned:
        joints = accessor_array(doc, binary, attrs["JOINTS_0"]).astype(np.int64)
        weights = _weights(doc, binary, attrs["WEIGHTS_0"])
        if joints.max(initial=0) >= len(mats):
            raise ValueError("a vertex is bound to a joint its skin lacks")
    else:
        joints = np.zeros((n, 4), dtype=np.int64)
        weights = np.zeros((n, 4))
        weights[:, 0] = 1.0
    m = np.einsum("vk,vkab->vab", weights, mats[joints])  # (n, 4, 4): each vertex's blended rest transform
    pos = np.einsum("vab,vb->va", m[:, :3, :3], v) + m[:, :3, 3]
    if "NORMAL" in attrs:
        normals = np.einsum("vab,vb->va", m[:, :3, :3], accessor_array(doc, binary, attrs["NORMAL"]).astype(np.float64))
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    else:
        normals = vertex_normals(pos.astype(np.float32), faces.astype(np.int32)).astype(np.float64)
    return {
        "vertices": pos,
        "normals": normals,
        "faces": faces,
        "joints": to_bone[joints],
        "weights": weights,
        "colors": _colors(doc, binary, prim, n, images),
    }


def _weights(doc: dict[str, Any], binary: bytes, accessor: int) -> np.ndarray:
    """``WEIGHTS_0`` as floats summing to 1 (normalised integers divided by their maximum)."""
    acc = doc["accessors"][accessor]
    w = accessor_array(doc, binary, accessor).astype(np.float64)
    if acc["componentType"] == 5121:
        w /= 255.0
    elif acc["componentType"] == 5123:
        w /= 65535.0
    total = w.sum(axis=1, keepdims=True)
    w = np.divide(w, total, out=np.zeros_like(w), where=total > 0)
    w[total[:, 0] <= 0, 0] = 1.0
    return w


def _linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


def _colors(
    doc: dict[str, Any], binary: bytes, prim: dict[str, Any], n: int, images: dict[int, np.ndarray]
) -> np.ndarray:
    """Each vertex's sRGB base colour: factor x texture at its UV x vertex colour, in linear light, shown as sRGB."""
    color = np.ones((n, 3))
    material = doc["materials"][prim["material"]] if "material" in prim else {}
    pbr = material.get("pbrMetallicRoughness", {})
    color *= np.asarray(pbr.get("baseColorFactor", (1, 1, 1, 1)), dtype=np.float64)[:3]
    texture = pbr.get("baseColorTexture")
    attrs = prim["attributes"]
    key = f"TEXCOORD_{texture.get('texCoord', 0)}" if texture else ""
    if texture is not None and key in attrs:
        source = doc["textures"][texture["index"]].get("source")
        if source is not None:
            if source not in images:
                images[source] = _image(doc, binary, source)
            img = images[source]
            uv = accessor_array(doc, binary, attrs[key]).astype(np.float64)
            h, w = img.shape[:2]
            x = np.floor(np.mod(uv[:, 0], 1.0) * w).astype(np.int64).clip(0, w - 1)
            y = np.floor(np.mod(uv[:, 1], 1.0) * h).astype(np.int64).clip(0, h - 1)
            color *= _linear(img[y, x])
    if "COLOR_0" in attrs:
        c = accessor_array(doc, binary, attrs["COLOR_0"]).astype(np.float64)[:, :3]
        acc = doc["accessors"][attrs["COLOR_0"]]
        c /= {5121: 255.0, 5123: 65535.0}.get(acc["componentType"], 1.0)
        color *= c
    return _srgb(color)


def _image(doc: dict[str, Any], binary: bytes, index: int) -> np.ndarray:
    """An image of the file as sRGB floats (height, width, 3)."""
    from PIL import Image

    img = doc["images"][index]
    view = doc["bufferViews"][img["bufferView"]]
    start, length = int(view.get("byteOffset", 0)), int(view["byteLength"])
    if start < 0 or length < 0 or start + length > len(binary):
        raise ValueError(f"image {index}'s buffer view runs past the {len(binary)} bytes of data")
    data = binary[start : start + length]
    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.width * im.height > 8192 * 8192:
                raise ValueError("a texture larger than 8192 x 8192")
            return np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    except ValueError:
        raise
    except Exception as e:  # Pillow's own errors (an unknown format, a truncated file, a decompression bomb)
        raise ValueError(f"image {index} is not a readable PNG or JPEG ({type(e).__name__})") from None
