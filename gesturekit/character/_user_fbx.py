"""An FBX file's skeleton and skinned body as a character: read by the ufbx library, turned into a glTF document.

FBX (binary 7.x and ASCII 6.1 through 7.x, as Mixamo, Unity and Unreal stores, UMA, Maya, 3ds Max and
Blender write it) is read by `ufbx <https://ufbx.github.io/>`_ in a child process
(:mod:`gesturekit.character._fbx_read`, under a memory limit), which composes each node's transform
(``Lcl Translation``, ``PreRotation``, ``Lcl Rotation``, ``PostRotation``, pivots, scaling) into its world matrix
at rest and gives each mesh's polygons, UVs, normals, materials, skin clusters and weights.

The scene is then written as the glTF document :mod:`gesturekit.character._user_gltf` reads, so the skeleton,
the body and its colours, the GLB written from a motion and everything downstream are those of a glTF character:

- every point and matrix goes from the file's axes and unit to glTF's (metres, Y up, +Z front): ``C = s A``
  with ``s`` the file's ``UnitScaleFactor`` in metres and ``A`` the rotation (or reflection) from its
  ``UpAxis``/``FrontAxis``/``CoordAxis`` to glTF's; a world matrix ``W`` becomes ``C W C^-1``;
- one glTF node per FBX node, its local matrix ``inv(W'_parent) W'``;
- one skin per skinned mesh whose joints are every skeleton node (``LimbNode``) and every bone of a cluster; a
  cluster's inverse bind matrix is ``C G inv(B) inv(C)`` (``G`` its geometry-to-bone matrix, ``B`` the mesh's
  geometry-to-world at bind), the mesh's vertices ``C B v``;
- polygons cut into triangles as fans from their first corner (what FBX characters hold are triangles and
  convex quads); one primitive per material, with a vertex per distinct (position, UV, normal) of its corners;
  the 4 largest weights of each vertex;
- a material's base colour is its texture when it has one (embedded in the file, or a file of the name it gives
  beside the FBX or in its ``NAME.fbm`` folder), else its ``DiffuseColor`` times ``DiffuseFactor`` (read as sRGB).
"""

from __future__ import annotations

import importlib.util
import io
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, InputFileError, MissingDependencyError, warn
from ..limits import check_bytes, check_npz, max_input_bytes
from ._user_gltf import MAX_TEXTURE_PIXELS, MAX_VERTICES, _check_linear, _check_references, _check_transforms, _skeleton
from .glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, UINT, GlbBuffer
from .target import FileSkeleton

__all__ = ["read_fbx_skeleton", "fans", "FBX_PACKAGE", "READ_TIMEOUT_S"]

#: The package that reads FBX (``pip install ufbx``).
FBX_PACKAGE = "ufbx"

#: Longest an FBX may take to read, seconds (a character of a million polygons takes a few).
READ_TIMEOUT_S = 600.0

_USHORT = 5123
# ufbx's CoordinateAxis: +X, -X, +Y, -Y, +Z, -Z
_AXIS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)


def read_fbx_skeleton(path: Path) -> FileSkeleton:
    """The skeleton and body of a ``.fbx``, as a glTF character (:class:`~.target.FileSkeleton` of kind ``"fbx"``).

    Raises
    ------
    InputFileError
        Not an FBX file the library reads (its words), a scene without a skeleton, a node, matrix or weight that
        is not finite or is out of bounds, or more than the memory, vertices or texture pixels allowed.
    MissingDependencyError
        The ``ufbx`` package is not installed.
    """
    check_bytes(path.stat().st_size, what="an FBX character file", path=path)
    data = _run_reader(path)
    try:
        doc, binary = _document(path, data)
        _check_references(doc, path)
        _check_transforms(doc, path)
        skeleton = _skeleton(path, doc, binary)
    except (KeyError, IndexError, TypeError, ValueError, OverflowError, np.linalg.LinAlgError) as e:
        raise InputFileError(f"not a readable FBX character ({type(e).__name__}: {e})", path=path) from None
    except ConfigError as e:
        if e.path is not None:
            raise
        raise InputFileError(e.problem, path=path) from None
    skeleton.kind = "fbx"
    return skeleton


# ----------------------------------------------------------------------------- the reader's process


def _memory_limit() -> int:
    """Bytes of address space the reader's process may take: the input limit and room for Python and numpy."""
    return int(max_input_bytes() + 2e9)


def _limit_memory() -> None:  # pragma: no cover - runs in the child before it starts
    import resource

    limit = _memory_limit()
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def _run_reader(path: Path) -> dict[str, np.ndarray]:
    """The arrays :mod:`._fbx_read` writes for ``path``."""
    if importlib.util.find_spec(FBX_PACKAGE) is None:
        raise MissingDependencyError(
            f"reading an FBX character needs the {FBX_PACKAGE} package: pip install {FBX_PACKAGE}", path=path
        )
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    # this very gesturekit in the child, run in a temporary folder (so no other checkout's is found first)
    home = os.fspath(Path(__file__).resolve().parents[2])
    start = f"import sys; sys.path.insert(0, {home!r}); from gesturekit.character._fbx_read import main; main()"
    with tempfile.TemporaryDirectory(prefix="gesturekit-fbx-") as tmp:
        out = Path(tmp) / "scene.npz"
        try:
            run = subprocess.run(
                [sys.executable, "-c", start, os.fspath(path.resolve()), os.fspath(out)],
                capture_output=True,
                env=env,
                timeout=READ_TIMEOUT_S,
                preexec_fn=_limit_memory if os.name == "posix" else None,
                cwd=tmp,
                check=False,
            )
        except subprocess.TimeoutExpired:
            raise InputFileError(f"reading it took more than {READ_TIMEOUT_S:.0f} s", path=path) from None
        message = run.stderr.decode("utf-8", "replace").strip().splitlines()
        if run.returncode == 3:
            said = message[-1][:300] if message else "no reason given"
            if "OutOfMemory" in said or "MemoryLimit" in said:
                raise InputFileError(
                    f"reading it needs more than the {_memory_limit() / 1e9:.1f} GB of memory allowed "
                    f"({FBX_PACKAGE}: {said}); GESTUREKIT_MAX_INPUT_GB raises the limit",
                    path=path,
                )
            raise InputFileError(f"not an FBX file the FBX reader ({FBX_PACKAGE}) can read: {said}", path=path)
        if run.returncode != 0 or not out.is_file():
            why = (
                f"signal {signal.Signals(-run.returncode).name}"
                if run.returncode < 0 and -run.returncode in signal.valid_signals()
                else f"exit status {run.returncode}"
            )
            if any("memory" in m.lower() for m in message):
                why = f"it needs more than the {_memory_limit() / 1e9:.1f} GB of memory allowed"
            elif message:
                why += f": {message[-1][:200]}"
            raise InputFileError(f"the FBX reader ({FBX_PACKAGE}) stopped on it ({why})", path=path)
        check_npz(out, max_bytes=max_input_bytes(), what="the FBX reader's arrays", owner=path)
        with np.load(out, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}


# ----------------------------------------------------------------------------- the glTF document


def _conversion(data: dict[str, np.ndarray], path: Path) -> np.ndarray:
    """``C`` (4, 4): the file's axes and unit to glTF's."""
    unit = float(data["unit_meters"])
    if not (np.isfinite(unit) and 1e-6 <= unit <= 1e6):
        raise InputFileError(f"its unit is {unit:g} m (UnitScaleFactor), not a length from 1e-6 to 1e6 m", path=path)
    axes = [int(a) for a in data["axes"]]
    if any(not 0 <= a < 6 for a in axes) or len({a // 2 for a in axes}) != 3:
        raise InputFileError(f"its axis system {axes} does not name three different axes", path=path)
    c = np.eye(4)
    c[:3, :3] = unit * np.stack([_AXIS[a] for a in axes])  # rows: the file's right, up and front
    return c


def _finite(a: np.ndarray, what: str, path: Path) -> np.ndarray:
    if not np.isfinite(a).all():
        raise InputFileError(f"{what} is not finite", path=path)
    return a


def _document(path: Path, data: dict[str, np.ndarray]) -> tuple[dict[str, Any], bytes]:
    """The glTF document and binary chunk of the scene."""
    c = _conversion(data, path)
    c_inv = np.linalg.inv(c)
    names = [str(n) for n in data["node_names"]]
    parents = data["node_parents"].astype(np.int64)
    is_root = data["node_is_root"].astype(bool)
    world = data["node_world"]
    for i, name in enumerate(names):
        _finite(world[i], f"the rest pose of node {name!r}", path)
    keep = [i for i in range(len(names)) if not is_root[i]]
    if not keep:
        raise InputFileError("it holds no nodes (no skeleton, no mesh)", path=path)
    gl = {i: k for k, i in enumerate(keep)}  # FBX node -> glTF node
    world_gl = np.einsum("ab,nbc,cd->nad", c, world, c_inv)
    for i in keep:  # a node scaled to nothing (or mirrored, or absurdly) before any matrix of it is inverted
        _check_linear(world_gl[i, :3, :3], f"node {names[i]!r}", path)
    nodes: list[dict[str, Any]] = []
    for i in keep:
        p = int(parents[i])
        local = world_gl[i] if p < 0 or is_root[p] else np.linalg.solve(world_gl[p], world_gl[i])
        nodes.append({"name": names[i], "matrix": [float(x) for x in local.T.reshape(-1)]})
        if p >= 0 and not is_root[p]:
            nodes[gl[p]].setdefault("children", []).append(gl[i])
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": f"gesturekit from FBX {int(data['version'])} ({FBX_PACKAGE})"},
        "scene": 0,
        "nodes": nodes,
    }
    buf = GlbBuffer()
    bones = sorted({gl[i] for i in keep if data["node_is_bone"][i]})
    for k in range(int(data["meshes"])):
        bones += [gl[int(b)] for b in data.get(f"mesh{k}_cluster_bone", ()) if int(b) in gl and gl[int(b)] not in bones]
    bones = sorted(set(bones))
    declared = sum(len(data[f"mesh{k}_corner_position"]) for k in range(int(data["meshes"])))
    if declared > 2 * MAX_VERTICES:
        raise InputFileError(
            f"a body of {declared} polygon corners, more than a character of {MAX_VERTICES} vertices has; "
            "decimate it in the modelling tool",
            path=path,
        )
    materials, images = _materials(path, data, doc, buf)
    meshes, skins = [], []
    for k in range(int(data["meshes"])):
        mesh = _mesh(path, data, k, c, c_inv, world_gl, gl, bones, len(materials))
        if mesh is None:
            continue
        primitives = []
        for material, faces in mesh["parts"]:
            # each material's own vertices (a glTF reader reads every primitive's attributes in full)
            used, local = np.unique(faces.reshape(-1), return_inverse=True)
            attributes = {
                "POSITION": buf.add(_f32(mesh["vertices"][used]), "VEC3", FLOAT, target=ARRAY_BUFFER, bounds=True),
                "NORMAL": buf.add(_f32(mesh["normals"][used]), "VEC3", FLOAT, target=ARRAY_BUFFER),
            }
            if "uv" in mesh:
                attributes["TEXCOORD_0"] = buf.add(_f32(mesh["uv"][used]), "VEC2", FLOAT, target=ARRAY_BUFFER)
            if "joints" in mesh:
                joints = mesh["joints"][used].astype(np.uint16)
                attributes["JOINTS_0"] = buf.add(joints, "VEC4", _USHORT, target=ARRAY_BUFFER)
                attributes["WEIGHTS_0"] = buf.add(_f32(mesh["weights"][used]), "VEC4", FLOAT, target=ARRAY_BUFFER)
            index = buf.add(local.astype(np.uint32), "SCALAR", UINT, target=ELEMENT_ARRAY_BUFFER)
            prim: dict[str, Any] = {"attributes": attributes, "indices": index}
            if material >= 0:
                prim["material"] = material
            primitives.append(prim)
        meshes.append({"name": names[int(data[f"mesh{k}_node"])], "primitives": primitives})
        node: dict[str, Any] = {"name": f"{names[int(data[f'mesh{k}_node'])]} (skinned)", "mesh": len(meshes) - 1}
        if "joints" in mesh:
            ibm = buf.add(np.transpose(mesh["ibm"], (0, 2, 1)).reshape(-1, 16).astype(np.float32), "MAT4", FLOAT)
            skins.append({"joints": bones, "inverseBindMatrices": ibm})
            node["skin"] = len(skins) - 1
            nodes.append(node)
        else:  # carried rigidly by its node (a prop under a bone): its vertices in that node's frame
            nodes[gl[int(data[f"mesh{k}_node"])]]["mesh"] = len(meshes) - 1
    if not skins and bones:  # a skeleton without a skinned body: its bones, for the reader of glTF skins
        ibm = buf.add(
            np.linalg.inv(world_gl[[keep[b] for b in bones]]).transpose(0, 2, 1).reshape(-1, 16), "MAT4", FLOAT
        )
        skins.append({"joints": bones, "inverseBindMatrices": ibm})
    roots = [gl[i] for i in keep if parents[i] < 0 or is_root[parents[i]]] + [
        len(nodes) - 1 - j for j in range(len(nodes) - len(keep))
    ]
    doc["scenes"] = [{"nodes": sorted(roots)}]
    if meshes:
        doc["meshes"] = meshes
    if skins:
        doc["skins"] = skins
    if materials:
        doc["materials"] = materials
    if images:
        doc["images"] = images
        doc["textures"] = [{"source": j} for j in range(len(images))]
    doc["bufferViews"] = buf.views
    doc["accessors"] = buf.accessors
    doc["buffers"] = [{"byteLength": len(buf.data)}] if buf.data else []
    return doc, bytes(buf.data)


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


def _linear(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _materials(
    path: Path, data: dict[str, np.ndarray], doc: dict[str, Any], buf: GlbBuffer
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """glTF materials of the scene's materials, and the images of their textures (in ``buf``)."""
    materials, images = [], []
    names = data["texture_names"]
    for j, name in enumerate(data["material_names"]):
        color = _finite(data["material_colors"][j], f"the colour of material {str(name)!r}", path)
        pbr: dict[str, Any] = {"baseColorFactor": [*map(float, _linear(color)), 1.0], "metallicFactor": 0.0}
        t = int(data["material_texture"][j])
        if t >= 0:
            image = _texture(path, data.get(f"texture{t}_content"), str(names[t][0]), str(names[t][1]))
            if image is not None:
                buf.data.extend(b"\0" * (-len(buf.data) % 4))
                buf.views.append({"buffer": 0, "byteOffset": len(buf.data), "byteLength": len(image)})
                buf.data.extend(image)
                images.append({"bufferView": len(buf.views) - 1, "mimeType": "image/png"})
                pbr["baseColorFactor"] = [1.0, 1.0, 1.0, 1.0]  # an FBX texture replaces the diffuse colour
                pbr["baseColorTexture"] = {"index": len(images) - 1}
        materials.append({"name": str(name), "pbrMetallicRoughness": pbr})
    return materials, images


def _texture(path: Path, content: np.ndarray | None, relative: str, absolute: str) -> bytes | None:
    """A texture's image as PNG bytes: embedded, else the file it names beside the FBX or in ``NAME.fbm``;
    ``None`` (with a warning) when it is not there."""
    from PIL import Image

    data = bytes(content.tobytes()) if content is not None and len(content) else None
    shown = relative or absolute
    if data is None:
        base = Path(relative.replace("\\", "/")).name or Path(absolute.replace("\\", "/")).name
        for folder in (path.parent, path.parent / f"{path.stem}.fbm"):
            other = folder / base
            if base and base not in (".", "..") and other.is_file():
                if other.is_symlink() or other.resolve().parent != folder.resolve():
                    raise InputFileError(
                        f"its texture {base!r} is a link to a file elsewhere; copy the file there", path=path
                    )
                check_bytes(other.stat().st_size, what="a texture file", path=other)
                data = other.read_bytes()
                break
    if data is None:
        warn(f"{path.name}: its texture {shown!r} is neither embedded nor beside it; drawn in its plain colour")
        return None
    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.width * im.height > MAX_TEXTURE_PIXELS:
                side = int(MAX_TEXTURE_PIXELS**0.5)
                raise InputFileError(
                    f"its texture {shown!r} is {im.width} x {im.height} pixels, more than a character's texture may "
                    f"have ({side} x {side}); scale it down",
                    path=path,
                )
            out = io.BytesIO()
            im.convert("RGB").save(out, format="PNG")
            return out.getvalue()
    except InputFileError:
        raise
    except Exception as e:  # Pillow's own errors (an unknown format, a truncated file, a decompression bomb)
        raise InputFileError(f"its texture {shown!r} is not a readable image ({type(e).__name__})", path=path) from None


def _mesh(
    path: Path,
    data: dict[str, np.ndarray],
    k: int,
    c: np.ndarray,
    c_inv: np.ndarray,
    world_gl: np.ndarray,
    gl: dict[int, int],
    bones: list[int],
    n_materials: int,
) -> dict[str, Any] | None:
    """One mesh's vertices (glTF world at bind, or its node's frame when not skinned), triangles by material,
    UVs, normals, and its skin: joints (indices into ``bones``), weights and inverse bind matrices."""
    pre = f"mesh{k}_"
    node = int(data[pre + "node"])
    positions = _finite(data[pre + "positions"], f"a vertex of mesh {k}", path)
    corner_pos = data[pre + "corner_position"]
    faces = data[pre + "faces"]
    n_corners = len(corner_pos)
    if len(faces) == 0 or n_corners == 0:
        return None
    if corner_pos.min() < 0 or corner_pos.max() >= len(positions):
        raise InputFileError(f"a polygon of mesh {k} names a vertex it lacks", path=path)
    begin, count = faces[:, 0], faces[:, 1]
    if begin.min() < 0 or (begin + count).max() > n_corners:
        raise InputFileError(f"a polygon of mesh {k} runs past its corners", path=path)
    keys = [corner_pos]
    uv = normal = None
    if pre + "uv_values" in data:
        uv, uv_index = data[pre + "uv_values"], data[pre + "uv_index"]
        if len(uv_index) != n_corners or (len(uv_index) and (uv_index.min() < 0 or uv_index.max() >= len(uv))):
            raise InputFileError(f"the UVs of mesh {k} do not match its polygons", path=path)
        keys.append(uv_index)
    if pre + "normal_values" in data:
        normal, normal_index = data[pre + "normal_values"], data[pre + "normal_index"]
        if len(normal_index) != n_corners or (
            len(normal_index) and (normal_index.min() < 0 or normal_index.max() >= len(normal))
        ):
            raise InputFileError(f"the normals of mesh {k} do not match its polygons", path=path)
        keys.append(normal_index)
    # one vertex per distinct (position, UV, normal) of a corner
    unique, corner_vertex = np.unique(np.stack(keys, axis=1), axis=0, return_inverse=True)
    corner_vertex = corner_vertex.reshape(-1)
    if len(unique) > MAX_VERTICES:
        raise InputFileError(
            f"a body of more than {MAX_VERTICES} vertices; decimate it in the modelling tool", path=path
        )
    tri_face, tri_corners = fans(begin, count)
    triangles = corner_vertex[tri_corners]
    out: dict[str, Any] = {}
    source = unique[:, 0]
    v = np.c_[positions[source], np.ones(len(source))]
    if uv is not None:
        out["uv"] = np.c_[uv[unique[:, 1], 0], 1.0 - uv[unique[:, 1], 1]]  # FBX's V runs up, glTF's down
    n = normal[unique[:, -1]] if normal is not None else None
    if pre + "cluster_bone" in data and len(data[pre + "cluster_bone"]):
        cluster_bone = data[pre + "cluster_bone"]
        g = _finite(data[pre + "cluster_geometry_to_bone"], f"a skin cluster's matrix of mesh {k}", path)
        b = _finite(data[pre + "cluster_bind_to_world"], f"a skin cluster's bind matrix of mesh {k}", path)
        bind = b[0] @ g[0]  # the geometry's world at bind (the same for every cluster of a consistent file)
        to_world = c @ bind
        weights, joints = _weights(path, data, k, len(positions), cluster_bone, gl, bones)
        out["joints"], out["weights"] = joints[source], weights[source]
        ibm = np.linalg.inv(world_gl[[_fbx(gl, j) for j in bones]])  # a bone without a cluster: bound at rest
        for j, bone in enumerate(cluster_bone):
            if int(bone) in gl:
                ibm[bones.index(gl[int(bone)])] = c @ g[j] @ np.linalg.inv(bind) @ c_inv
        out["ibm"] = _finite(ibm, f"an inverse bind matrix of mesh {k}", path)
    else:
        to_world = c @ data[pre + "geometry_to_world"]
        to_world = np.linalg.solve(world_gl[node], to_world)  # into its node's frame
    out["vertices"] = (v @ to_world.T)[:, :3]
    if n is not None:
        normals = n @ np.linalg.inv(to_world[:3, :3])  # normals go by the inverse transpose
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        out["normals"] = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    else:
        out["normals"] = np.zeros_like(out["vertices"])
    mesh_materials = data[pre + "materials"]
    face_material = data[pre + "face_material"]
    if len(face_material) != len(faces):
        face_material = np.zeros(len(faces), dtype=np.int64)
    tri_material = face_material[tri_face] if len(mesh_materials) else np.full(len(tri_face), -1)
    parts = []
    for m in np.unique(tri_material):
        material = int(mesh_materials[m]) if 0 <= m < len(mesh_materials) else -1
        if material >= n_materials:
            material = -1
        parts.append((material, triangles[tri_material == m]))
    out["parts"] = parts
    return out


def fans(begin: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polygons cut into triangle fans from their first corner.

    Parameters
    ----------
    begin, count : np.ndarray, shape (F,), int
        Each polygon's first corner and number of corners (a polygon of fewer than 3 gives no triangle).

    Returns
    -------
    face : np.ndarray, shape (T,), int64
        The polygon of each triangle, in order.
    corners : np.ndarray, shape (T, 3), int64
        Its corners: ``begin, begin + i + 1, begin + i + 2`` for its ``i``-th triangle.
    """
    n = np.maximum(np.asarray(count, dtype=np.int64) - 2, 0)
    face = np.repeat(np.arange(len(n)), n)
    step = np.arange(len(face)) - np.repeat(np.cumsum(n) - n, n)
    first = np.asarray(begin, dtype=np.int64)[face]
    return face, np.stack([first, first + step + 1, first + step + 2], axis=1)


def _fbx(gl: dict[int, int], node: int) -> int:
    """The FBX node of a glTF node."""
    return next(i for i, g in gl.items() if g == node)


def _weights(
    path: Path,
    data: dict[str, np.ndarray],
    k: int,
    n_positions: int,
    cluster_bone: np.ndarray,
    gl: dict[int, int],
    bones: list[int],
) -> tuple[np.ndarray, np.ndarray]:
    """Each position's 4 largest weights (summing to 1; a vertex of no weight follows the first bone) and joints."""
    pre = f"mesh{k}_"
    vert, cluster, weight = data[pre + "skin_vertices"], data[pre + "skin_cluster"], data[pre + "skin_weight"]
    _finite(weight, f"a skin weight of mesh {k}", path)
    if len(vert) != n_positions or (len(cluster) and (cluster.min() < 0 or cluster.max() >= len(cluster_bone))):
        raise InputFileError(f"the skin of mesh {k} does not match its vertices", path=path)
    joint_of_cluster = np.array([bones.index(gl[int(b)]) if int(b) in gl else 0 for b in cluster_bone], dtype=np.int64)
    joints = np.zeros((n_positions, 4), dtype=np.int64)
    weights = np.zeros((n_positions, 4))
    for slot in range(4):  # ufbx lists each vertex's weights largest first
        has = vert[:, 1] > slot
        at = vert[has, 0] + slot
        if len(at) and at.max() >= len(weight):
            raise InputFileError(f"the skin of mesh {k} names more weights than it has", path=path)
        joints[has, slot] = joint_of_cluster[cluster[at]]
        weights[has, slot] = np.maximum(weight[at], 0.0)
    total = weights.sum(axis=1, keepdims=True)
    weights = np.divide(weights, total, out=np.zeros_like(weights), where=total > 0)
    weights[total[:, 0] <= 0, 0] = 1.0
    return weights, joints
