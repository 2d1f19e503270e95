"""Read an FBX file with the ufbx library, in a process of its own: ``python -m gesturekit.character._fbx_read IN OUT``.

:mod:`gesturekit.character._user_fbx` runs this module as a child process with a memory limit and reads what it
writes to ``OUT`` (an ``.npz`` of plain arrays, no pickles): the scene's unit and axes, every node's name, parent
and world matrix at rest (ufbx composes ``Lcl Translation``, ``PreRotation``, ``Lcl Rotation``,
``PostRotation``, pivots and scaling), each mesh's vertices, polygons, UVs, normals, materials by polygon, its
skin clusters (the bone, the matrix from the geometry to the bone at bind) and weights, and each material's
diffuse colour and texture (the embedded bytes, else the file names it gives).

Why a process of its own: ufbx's Python bindings (0.0.5) hand out their cached scene elements without counting
the reference, so an element asked for twice may be freed under the reader; here every element received is
counted once more (kept for the life of the process), the garbage collector is off, and the process ends with
``os._exit`` after writing, so nothing of the scene is ever freed. A file that exhausts the memory limit or
crashes the library ends this process, not the caller's, which then reports it for the file.
"""

from __future__ import annotations

import ctypes
import gc
import os
import sys
from typing import Any

import numpy as np

__all__ = ["main"]

_incref = ctypes.pythonapi.Py_IncRef
_incref.argtypes = [ctypes.py_object]
_incref.restype = None


def _own(x: Any) -> Any:
    """Count one more reference to a scene element the bindings returned without counting it."""
    import ufbx

    if isinstance(x, ufbx.Element):
        _incref(x)
    return x


def _matrix(m: Any) -> np.ndarray:
    out = np.eye(4)
    for k, c in enumerate((m.c0, m.c1, m.c2, m.c3)):
        out[:3, k] = (c.x, c.y, c.z)
    return out


def _read(path: str) -> dict[str, np.ndarray]:
    import ufbx

    scene = ufbx.load_file(path, load_external_files=False, ignore_animation=True, generate_missing_normals=True)
    settings = scene.settings
    axes = settings.axes
    out: dict[str, np.ndarray] = {
        "version": np.array(int(scene.metadata.version)),
        "ascii": np.array(bool(scene.metadata.ascii)),
        "unit_meters": np.array(float(settings.unit_meters)),
        "axes": np.array([int(axes.right), int(axes.up), int(axes.front)]),
    }
    nodes_list = scene.nodes
    nodes = [_own(nodes_list[i]) for i in range(len(nodes_list))]
    ids = {int(n.element_id): i for i, n in enumerate(nodes)}
    names, parents, world, bones, roots = [], [], [], [], []
    for n in nodes:
        names.append(str(n.name))
        parent = _own(n.parent)
        parents.append(-1 if parent is None else ids[int(parent.element_id)])
        world.append(_matrix(n.node_to_world))
        bones.append(_own(n.bone) is not None)
        roots.append(bool(n.is_root))
    out |= {
        "node_names": np.array(names, dtype=str),
        "node_parents": np.array(parents, dtype=np.int64),
        "node_world": np.array(world, dtype=np.float64).reshape(-1, 4, 4),
        "node_is_bone": np.array(bones, dtype=bool),
        "node_is_root": np.array(roots, dtype=bool),
    }
    materials_list = scene.materials
    materials = [_own(materials_list[i]) for i in range(len(materials_list))]
    mat_ids = {int(m.element_id): i for i, m in enumerate(materials)}
    mat_names: list[str] = []
    colors: list[tuple[float, float, float]] = []
    texture_of: list[int] = []
    textures: list[tuple[str, str]] = []
    for m in materials:
        mat_names.append(str(m.name))
        diffuse = m.fbx.diffuse_color
        v = diffuse.value_vec4
        factor = float(m.fbx.diffuse_factor.value_vec4.x) if m.fbx.diffuse_factor.has_value else 1.0
        colors.append((v.x * factor, v.y * factor, v.z * factor))
        tex = _own(diffuse.texture)
        if tex is None:
            texture_of.append(-1)
            continue
        texture_of.append(len(textures))
        content = bytes(tex.content)
        if not content:
            video = _own(tex.video)
            content = bytes(video.content) if video is not None else b""
        out[f"texture{len(textures)}_content"] = np.frombuffer(content, dtype=np.uint8)
        textures.append((str(tex.relative_filename), str(tex.filename)))
    out |= {
        "material_names": np.array(mat_names, dtype=str),
        "material_colors": np.array(colors, dtype=np.float64).reshape(-1, 3),
        "material_texture": np.array(texture_of, dtype=np.int64),
        "texture_names": np.array(textures, dtype=str).reshape(-1, 2),
    }
    k = 0
    for i, n in enumerate(nodes):
        mesh = _own(n.mesh)
        if mesh is None:
            continue
        pre = f"mesh{k}_"
        out[pre + "node"] = np.array(i)
        out[pre + "geometry_to_world"] = _matrix(n.geometry_to_world)
        out[pre + "positions"] = np.array(mesh.vertices, dtype=np.float64).reshape(-1, 3)
        out[pre + "corner_position"] = np.array(mesh.vertex_indices, dtype=np.int64)
        out[pre + "faces"] = np.array(mesh.faces, dtype=np.int64).reshape(-1, 2)
        uv = mesh.vertex_uv
        if uv.exists:
            out[pre + "uv_values"] = np.array(uv.values, dtype=np.float64).reshape(-1, 2)
            out[pre + "uv_index"] = np.array(uv.indices, dtype=np.int64)
        normal = mesh.vertex_normal
        if normal.exists:
            out[pre + "normal_values"] = np.array(normal.values, dtype=np.float64).reshape(-1, 3)
            out[pre + "normal_index"] = np.array(normal.indices, dtype=np.int64)
        mesh_materials = mesh.materials
        out[pre + "materials"] = np.array(
            [mat_ids[int(_own(mesh_materials[j]).element_id)] for j in range(len(mesh_materials))], dtype=np.int64
        )
        out[pre + "face_material"] = np.array(mesh.face_material, dtype=np.int64)
        skins = mesh.skin_deformers
        if len(skins):
            skin = _own(skins[0])
            clusters = skin.clusters
            bone_of, to_bone, bind = [], [], []
            for j in range(len(clusters)):
                cluster = _own(clusters[j])
                bone = _own(cluster.bone_node)
                bone_of.append(-1 if bone is None else ids[int(bone.element_id)])
                to_bone.append(_matrix(cluster.geometry_to_bone))
                bind.append(_matrix(cluster.bind_to_world))
            out[pre + "cluster_bone"] = np.array(bone_of, dtype=np.int64)
            out[pre + "cluster_geometry_to_bone"] = np.array(to_bone, dtype=np.float64).reshape(-1, 4, 4)
            out[pre + "cluster_bind_to_world"] = np.array(bind, dtype=np.float64).reshape(-1, 4, 4)
            vertices, weights = skin.vertices, skin.weights
            out[pre + "skin_vertices"] = np.array(
                [(v.weight_begin, v.num_weights) for v in (vertices[j] for j in range(len(vertices)))], dtype=np.int64
            ).reshape(-1, 2)
            w = [weights[j] for j in range(len(weights))]
            out[pre + "skin_cluster"] = np.array([x.cluster_index for x in w], dtype=np.int64)
            out[pre + "skin_weight"] = np.array([x.weight for x in w], dtype=np.float64)
        k += 1
    out["meshes"] = np.array(k)
    return out


def main(argv: list[str] | None = None) -> None:
    """Read ``argv[0]`` (an FBX), write its arrays to ``argv[1]`` (an ``.npz``); exit 0, or 3 with the library's
    message on stderr for a file it refuses."""
    args = sys.argv[1:] if argv is None else argv
    gc.disable()
    try:
        data = _read(args[0])
    except Exception as e:  # the library's refusal of the file, in its words
        sys.stderr.write(f"{type(e).__name__}: {e}\n")
        sys.stderr.flush()
        os._exit(3)
    with open(args[1], "wb") as f:
        np.savez(f, **data)  # type: ignore[arg-type]
    sys.stdout.flush()
    os._exit(0)  # the scene is never freed (see the module's docstring)


if __name__ == "__main__":
    main()
