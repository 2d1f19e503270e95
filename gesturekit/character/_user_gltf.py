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
from .materials import MAX_TEXTURE_PIXELS, materials_glb
from .mesh import vertex_normals
from .target import FileSkeleton, GltfSource, empty_skin, reorder, topological

__all__ = ["read_gltf_skeleton", "MAX_VERTICES", "MAX_TEXTURE_PIXELS", "MAX_NODE_SCALE"]

#: Most vertices a character's body may have (a detailed game character has some 100 000): counted from the
#: accessors' declared counts before any is read.
MAX_VERTICES = 2_000_000


#: Largest and smallest scale a node may carry (a factor of a million either way is no unit conversion).
MAX_NODE_SCALE = 1e6

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
        _check_references(doc, path)
        _check_transforms(doc, path)
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
        if not any("uri" in img for img in doc.get("images", [])):
            return doc, bytes(binary)
        blob = bytearray(binary)
    else:
        doc = dict(read_json(path, what="a glTF file"))  # type: ignore[call-overload]
        blob = bytearray()
        bases = []
        for b in doc.get("buffers", []):
            blob.extend(b"\0" * (-len(blob) % 4))
            bases.append(len(blob))
            blob.extend(_uri_bytes(path, b.get("uri", "")))
        for i, v in enumerate(doc.get("bufferViews", [])):
            _index(v.get("buffer"), len(bases), f"buffer view {i}'s buffer", path)
            v["byteOffset"] = v.get("byteOffset", 0) + bases[v["buffer"]]
            v["buffer"] = 0
    # an image is a buffer view or a URI (a data URI, or a file beside a .gltf) in a GLB and a .gltf alike
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


def _index(value: Any, n: int, what: str, path: Path) -> int:
    """``value`` as an index into a list of ``n``, or our error naming ``what`` (a negative index is no "last")."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < n:
        raise InputFileError(f"{what} is {value!r}, not an index from 0 to {n - 1}", path=path)
    return value


def _node_label(doc: dict[str, Any], i: int) -> str:
    name = doc["nodes"][i].get("name")
    return f"node {i} ({name!r})" if isinstance(name, str) else f"node {i} (node{i})"


def _check_references(doc: dict[str, Any], path: Path) -> None:
    """Every index the reader follows is within its list (a negative one too is refused, not read as "the last")."""
    count = {k: len(doc.get(k, [])) for k in ("nodes", "meshes", "skins", "accessors", "bufferViews", "materials")}
    count |= {k: len(doc.get(k, [])) for k in ("textures", "images")}
    for i, node in enumerate(doc.get("nodes", [])):
        label = _node_label(doc, i)
        for c in node.get("children", ()):
            _index(c, count["nodes"], f"a child of {label}", path)
        if "mesh" in node:
            _index(node["mesh"], count["meshes"], f"the mesh of {label}", path)
        if "skin" in node:
            _index(node["skin"], count["skins"], f"the skin of {label}", path)
    for k, skin in enumerate(doc.get("skins", [])):
        for j in skin.get("joints", ()):
            _index(j, count["nodes"], f"a joint of skin {k}", path)
        if "inverseBindMatrices" in skin:
            _index(skin["inverseBindMatrices"], count["accessors"], f"skin {k}'s inverse bind matrices", path)
    for k, mesh in enumerate(doc.get("meshes", [])):
        for prim in mesh.get("primitives", ()):
            for attr, a in prim.get("attributes", {}).items():
                _index(a, count["accessors"], f"mesh {k}'s {attr}", path)
            if "indices" in prim:
                _index(prim["indices"], count["accessors"], f"mesh {k}'s indices", path)
            if "material" in prim:
                _index(prim["material"], count["materials"], f"mesh {k}'s material", path)
    for k, acc in enumerate(doc.get("accessors", [])):
        if "bufferView" in acc:
            _index(acc["bufferView"], count["bufferViews"], f"accessor {k}'s buffer view", path)
    for k, material in enumerate(doc.get("materials", [])):
        texture = material.get("pbrMetallicRoughness", {}).get("baseColorTexture")
        if texture is not None:
            _index(texture.get("index"), count["textures"], f"material {k}'s base colour texture", path)
    for k, texture in enumerate(doc.get("textures", [])):
        if "source" in texture:
            _index(texture["source"], count["images"], f"texture {k}'s image", path)
    for k, img in enumerate(doc.get("images", [])):
        _index(img.get("bufferView"), count["bufferViews"], f"image {k}'s buffer view", path)


def _check_transforms(doc: dict[str, Any], path: Path) -> None:
    """Each node's transform is finite, a rotation a quaternion of non-zero length, a scale neither mirrored nor
    beyond :data:`MAX_NODE_SCALE` either way (checked before any is used: a NaN would reach the rest pose)."""
    for i, node in enumerate(doc.get("nodes", [])):
        label = _node_label(doc, i)
        if "matrix" in node:
            m = _numbers(node["matrix"], 16, f"the matrix of {label}", path).reshape(4, 4).T
            linear = m[:3, :3]
        else:
            _numbers(node.get("translation", (0, 0, 0)), 3, f"the translation of {label}", path)
            q = _numbers(node.get("rotation", (0, 0, 0, 1)), 4, f"the rotation of {label}", path)
            if not np.linalg.norm(q) > 1e-6:
                raise InputFileError(f"the rotation of {label} is a quaternion of zero length", path=path)
            linear = np.diag(_numbers(node.get("scale", (1, 1, 1)), 3, f"the scale of {label}", path))
        _check_linear(linear, label, path)


def _check_linear(linear: np.ndarray, label: str, path: Path) -> None:
    sizes = np.linalg.svd(linear, compute_uv=False)
    if not (sizes.max() <= MAX_NODE_SCALE and sizes.min() >= 1.0 / MAX_NODE_SCALE):
        raise InputFileError(
            f"{label} is scaled by {sizes.min():.3g} to {sizes.max():.3g}, beyond a factor of {MAX_NODE_SCALE:.0e} "
            "either way; export the character at its own size",
            path=path,
        )
    if np.linalg.det(linear) < 0:
        raise InputFileError(
            f"{label} is mirrored (a negative scale); a mirrored rig turns its left into its right: apply the "
            "mirror in the modelling tool and export again",
            path=path,
        )


def _numbers(value: Any, n: int, what: str, path: Path) -> np.ndarray:
    """``value`` as ``n`` finite floats, or our error naming ``what``."""
    try:
        out = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputFileError(f"{what} is not {n} numbers", path=path) from None
    if out.shape != (n,):
        raise InputFileError(f"{what} has {out.size} numbers, not {n}", path=path)
    if not np.isfinite(out).all():
        raise InputFileError(f"{what} is not finite ({out.tolist()})", path=path)
    return out


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
    if other.is_symlink() or other.resolve().parent != path.parent.resolve():
        # a link beside it may point anywhere: its bytes would end up in the GLB written from it
        raise InputFileError(f"{uri!r} is a link to a file outside the glTF's folder; copy the file there", path=path)
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
    for n in bone_nodes:  # scales that are each allowed may still compose to one that is not
        if not np.isfinite(world_all[n]).all():
            raise InputFileError(f"the rest pose of {_node_label(doc, n)} is not finite", path=path)
        _check_linear(world_all[n, :3, :3], _node_label(doc, n), path)
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
    declared = 0
    for node in doc.get("nodes", []):  # the vertices the accessors declare, counted before any is read
        if "mesh" in node:
            for prim in doc["meshes"][node["mesh"]]["primitives"]:
                if prim.get("mode", _TRIANGLES) == _TRIANGLES:
                    declared += int(doc["accessors"][prim["attributes"]["POSITION"]]["count"])
    if declared > MAX_VERTICES:
        raise InputFileError(
            f"a body of {declared} vertices, more than the {MAX_VERTICES} a character may have; "
            "decimate it in the modelling tool",
            path=path,
        )
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
            if len(ibm) < len(joints):
                raise InputFileError(f"skin {node['skin']} has fewer inverse bind matrices than joints", path=path)
            for k, j in enumerate(joints):
                if not np.isfinite(ibm[k]).all():
                    label = _node_label(doc, j)
                    raise InputFileError(f"the inverse bind matrix of {label} is not finite", path=path)
                _check_linear(ibm[k, :3, :3], f"the inverse bind matrix of {_node_label(doc, j)}", path)
            mats = world[joints] @ ibm[: len(joints)]
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
    out = {key: np.concatenate([p[key] for p in parts]) for key in parts[0] if key not in ("faces", "material")}
    starts = np.cumsum([0] + [len(p["vertices"]) for p in parts[:-1]])
    out["faces"] = np.concatenate([p["faces"] + s for p, s in zip(parts, starts)])
    # each triangle's material: the file's, or the default one the materials GLB appends after them
    n_materials = len(doc.get("materials", []))
    out["face_materials"] = np.concatenate(
        [np.full(len(p["faces"]), n_materials if p["material"][0] < 0 else p["material"][0]) for p in parts]
    ).astype(np.int64)
    out["materials"] = np.frombuffer(materials_glb(doc, binary), dtype=np.uint8)
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
    uvs = (
        np.nan_to_num(accessor_array(doc, binary, attrs["TEXCOORD_0"]).astype(np.float64)[:, :2])
        if "TEXCOORD_0" in attrs
        else np.zeros((n, 2))
    )
    if "TEXCOORD_0" in attrs:
        acc = doc["accessors"][attrs["TEXCOORD_0"]]
        if acc.get("normalized"):  # quantised UVs (KHR_mesh_quantization) are normalised integers
            uvs /= {5121: 255.0, 5123: 65535.0}.get(acc["componentType"], 1.0)
    return {
        "vertices": pos,
        "normals": normals,
        "faces": faces,
        "joints": to_bone[joints],
        "weights": weights,
        "colors": _colors(doc, binary, prim, n, images),
        "uvs": uvs,
        "material": np.array([int(prim.get("material", -1))]),
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
            uv = np.where(np.isfinite(uv), uv, 0.0)
            h, w = img.shape[:2]
            x = np.floor(np.mod(uv[:, 0], 1.0) * w).astype(np.int64).clip(0, w - 1)
            y = np.floor(np.mod(uv[:, 1], 1.0) * h).astype(np.int64).clip(0, h - 1)
            color *= _linear(img[y, x] / 255.0)  # only the texels sampled become floats
    if "COLOR_0" in attrs:
        c = accessor_array(doc, binary, attrs["COLOR_0"]).astype(np.float64)[:, :3]
        acc = doc["accessors"][attrs["COLOR_0"]]
        c /= {5121: 255.0, 5123: 65535.0}.get(acc["componentType"], 1.0)
        color *= c
    return _srgb(color)


def _image(doc: dict[str, Any], binary: bytes, index: int) -> np.ndarray:
    """An image of the file as sRGB bytes (height, width, 3), uint8; refused past :data:`MAX_TEXTURE_PIXELS`
    from its header, before it is decoded."""
    from PIL import Image

    img = doc["images"][index]
    view = doc["bufferViews"][img["bufferView"]]
    start, length = int(view.get("byteOffset", 0)), int(view["byteLength"])
    if start < 0 or length < 0 or start + length > len(binary):
        raise ValueError(f"image {index}'s buffer view runs past the {len(binary)} bytes of data")
    data = binary[start : start + length]
    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.width * im.height > MAX_TEXTURE_PIXELS:
                side = int(MAX_TEXTURE_PIXELS**0.5)
                raise ConfigError(
                    f"image {index} is {im.width} x {im.height} pixels, more than a character's texture may have "
                    f"({side} x {side}); scale it down"
                )
            return np.asarray(im.convert("RGB"), dtype=np.uint8)
    except ConfigError:
        raise
    except ValueError:
        raise
    except Exception as e:  # Pillow's own errors (an unknown format, a truncated file, a decompression bomb)
        raise ValueError(f"image {index} is not a readable PNG or JPEG ({type(e).__name__})") from None
