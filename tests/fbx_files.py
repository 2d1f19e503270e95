"""FBX characters written here, as Mixamo and other exporters write them, for the tests of reading FBX.

No third-party asset: the skeleton and body are the generated rigs of :mod:`tests.character_rigs` (a
:class:`~tests.character_rigs.RigSpec`), written as

- **FBX 6.1 ASCII** (:func:`fbx_ascii_61`): the text format of FBX 2006-2009 (``Properties60``, geometry
  inside its ``Model``, names in ``Connect`` lines), as Mixamo's older downloads and Blender 2.4x-2.7x wrote it;
- **FBX 7.x binary** (:func:`fbx_binary`): the node-record format (a 27-byte header, records of end offset,
  property count, property bytes and name, typed properties, arrays optionally deflated, a null record after
  every list of children; 64-bit record headers from version 7500), as the FBX SDK writes it.

Both have what a real character file has: ``mixamorig:`` bone names on ``LimbNode`` models whose rest rotation
is split into a ``PreRotation``, a ``Lcl Rotation`` and a ``PostRotation`` (so a reader that drops any of them
puts the children elsewhere), lengths in centimetres (``UnitScaleFactor`` 1) or another unit, an up axis
(Y, or Z as 3ds Max writes), one skinned mesh of quads (a reader must triangulate them) with two materials by
polygon, UVs by polygon vertex, normals, skin clusters (``Indexes``, ``Weights``, ``Transform``: the mesh's world
matrix at bind in the bone's frame, and ``TransformLink``: the bone's world matrix at bind) and a diffuse
texture: a PNG named beside the file, or embedded in the ``Video``'s ``Content``.
What a reader should find is :func:`tests.character_rigs.truth` of the rig, in metres.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tests.character_rigs import RigSpec, _bones, _png, _tubes

__all__ = [
    "RawProperty",
    "ObjectId",
    "FbxSpec",
    "fbx_ascii_61",
    "fbx_binary",
    "fbx_texture",
    "fbx_scene",
    "FbxScene",
    "node_bytes",
]

# the sub-rotations the writers give some bones (degrees, X then Y then Z): PreRotation, Lcl Rotation, PostRotation
_TURNS = {
    "Hips": ((-90.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "Spine": ((90.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "LeftArm": ((0.0, 0.0, -30.0), (10.0, 5.0, 0.0), (0.0, 20.0, 0.0)),
    "RightForeArm": ((0.0, 45.0, 0.0), (0.0, 0.0, 15.0), (0.0, 0.0, 0.0)),
    "Head": ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (30.0, 0.0, 0.0)),
}

#: The FBX axis systems the writers use: ``(UpAxis, UpAxisSign, FrontAxis, FrontAxisSign, CoordAxis, CoordAxisSign)``
#: and the rotation from our frame (Y up) to the file's.
AXES = {
    "y": ((1, 1, 2, 1, 0, 1), np.eye(3)),
    "z": ((2, 1, 1, -1, 0, 1), np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])),
}


@dataclass(frozen=True)
class FbxSpec:
    """What FBX character to write.

    Attributes
    ----------
    rig : RigSpec
        The skeleton and body (its names, rest pose, height); ``mesh`` must be True.
    unit : float
        Metres per unit of the file's numbers; ``UnitScaleFactor`` says ``unit * 100`` (centimetres per unit).
    declared : float or None
        The ``UnitScaleFactor`` written when not the true one (an exporter that wrote metres but said centimetres).
    up : str
        ``"y"`` or ``"z"`` (see :data:`AXES`).
    turns : bool
        Split some bones' rest rotations into PreRotation, Lcl Rotation and PostRotation (:data:`_TURNS`).
    texture : str
        ``"file"`` (a PNG beside the FBX, named by ``RelativeFilename``), ``"embedded"`` (the PNG in the Video's
        ``Content``; binary only) or ``"none"``.
    armature : bool
        Binary only: the bones and the mesh under a null ``Armature`` (:data:`ARMATURE`), as Blender exports.
    """

    rig: RigSpec = field(default_factory=RigSpec)
    unit: float = 0.01
    declared: float | None = None
    up: str = "y"
    turns: bool = True
    texture: str = "file"
    armature: bool = False


#: The ``Armature`` null of a Blender export (``FbxSpec.armature``): turned -90 degrees about X, scaled 100;
#: the root bone undoes both, the mesh is its child.
ARMATURE = ((-90.0, 0.0, 0.0), 100.0)


@dataclass
class FbxScene:
    """The character in the file's frame and units: bones, their transforms, the mesh and its skin."""

    names: list[str]
    parents: list[int]
    translation: np.ndarray  # (M, 3) Lcl Translation
    turns: list[tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]]  # pre, lcl, post (degrees)
    world: np.ndarray  # (M, 4, 4) each bone's world matrix at rest
    vertices: np.ndarray  # (V, 3)
    normals: np.ndarray  # (V, 3)
    uv: np.ndarray  # (V, 2) FBX's convention: v up from the image's bottom
    polygons: list[list[int]]
    polygon_material: list[int]
    clusters: dict[int, tuple[np.ndarray, np.ndarray]]  # bone -> (vertex indexes, weights)
    png: bytes
    texel: np.ndarray  # (8, 8, 3) uint8, the PNG's pixels, top row first
    settings: tuple[int, ...]
    unit_scale_factor: float
    scaling: np.ndarray  # (M,) each bone's Lcl Scaling (uniform)
    armature: np.ndarray | None  # (4, 4) the Armature null's world matrix; the mesh's world at bind


def _euler(deg: tuple[float, ...]) -> np.ndarray:
    """FBX's XYZ order: ``Rz @ Ry @ Rx``."""
    a, b, c = np.radians(deg)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


def fbx_texture(seed: int = 0) -> tuple[bytes, np.ndarray]:
    """The 8 x 8 checker PNG of the textured material and its pixels (top row first)."""
    rng = np.random.default_rng(seed)
    checker = ((np.arange(8)[:, None] + np.arange(8)[None, :]) % 2).astype(np.uint8)
    tint = rng.integers(96, 256, size=3, dtype=np.uint8)
    rgb = np.where(checker[..., None] == 1, tint, 255 - tint // 2).astype(np.uint8)
    rgb[0, 0] = (255, 0, 0)  # one texel unlike the others: a flipped V would find another colour
    return _png(8, 8, rgb), rgb


def fbx_scene(spec: FbxSpec) -> FbxScene:
    """The character of ``spec`` in the file's frame and units."""
    bones = _bones(spec.rig)
    settings, axes = AXES[spec.up]
    scale = 1.0 / spec.unit
    names = [b[0] for b in bones]
    parents = [b[1] for b in bones]
    pos = np.array([axes @ b[2] * scale for b in bones])
    turns = []
    world = np.tile(np.eye(4), (len(bones), 1, 1))
    translation = np.zeros((len(bones), 3))
    for i, name in enumerate(names):
        plain = name.split(":")[-1]
        t = _TURNS.get(plain) if spec.turns else None
        pre, lcl, post = t if t else ((0.0, 0.0, 0.0),) * 3
        turns.append((pre, lcl, post))
        p = parents[i]
        above = world[p] if p >= 0 else np.eye(4)
        # FBX: local = T @ Rpre @ R @ inv(Rpost) (no pivots)
        local_rot = _euler(pre) @ _euler(lcl) @ _euler(post).T
        translation[i] = above[:3, :3].T @ (pos[i] - above[:3, 3])
        world[i, :3, :3] = above[:3, :3] @ local_rot
        world[i, :3, 3] = pos[i]
    v, n, uv, jnt, wgt, skin_faces, cloth_faces, _ = _tubes(bones, spec.rig)  # no third (textured) part
    vertices = (v.astype(np.float64) @ axes.T) * scale
    normals = n.astype(np.float64) @ axes.T
    polygons, material = [], []
    for m, faces in enumerate((skin_faces, cloth_faces)):
        tri = faces.reshape(-1, 3)
        for a, b in zip(tri[0::2], tri[1::2]):  # the tube's quads, as two triangles (i0, i1, j1), (i0, j1, j0)
            polygons.append([int(a[0]), int(a[1]), int(a[2]), int(b[2])])
            material.append(m)
    clusters = {}
    for b in range(len(bones)):
        rows, cols = np.nonzero((jnt == b) & (wgt > 0))
        if len(rows):
            order = np.argsort(rows, kind="stable")
            idx, w = rows[order], wgt[rows[order], cols[order]].astype(np.float64)
            uniq, inv = np.unique(idx, return_inverse=True)
            clusters[b] = (uniq, np.bincount(inv, weights=w))
    png, texel = fbx_texture(spec.rig.seed)
    fbx_uv = uv.astype(np.float64).copy()
    fbx_uv[:, 1] = 1.0 - fbx_uv[:, 1]  # glTF's V runs down from the top, FBX's up from the bottom
    declared = spec.unit * 100.0 if spec.declared is None else spec.declared
    scaling = np.ones(len(bones))
    armature = None
    if spec.armature:
        from scipy.spatial.transform import Rotation

        turn, size = ARMATURE
        armature = np.eye(4)
        armature[:3, :3] = _euler(turn) * size
        inv = np.linalg.inv(armature)
        for i in range(len(bones)):
            if parents[i] < 0:  # the root bone undoes the armature's turn and scale: its world stays as it was
                local = inv @ world[i]
                translation[i] = local[:3, 3]
                scaling[i] = 1.0 / size
                pre = Rotation.from_matrix(local[:3, :3] * size).as_euler("xyz", degrees=True)
                turns[i] = (tuple(pre), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        vertices = vertices @ inv[:3, :3].T + inv[:3, 3]
        normals = normals @ _euler(turn)
    return FbxScene(
        names, parents, translation, turns, world, vertices, normals, fbx_uv, polygons, material, clusters, png,
        texel, settings, declared, scaling, armature,
    )  # fmt: skip


def _polygon_index(polygons: list[list[int]]) -> list[int]:
    out = []
    for poly in polygons:
        out.extend(poly[:-1])
        out.append(-poly[-1] - 1)
    return out


def _matrix(m: np.ndarray) -> list[float]:
    """FBX's 16 numbers of a 4 x 4 matrix: column by column (the translation last but one row)."""
    return [float(x) for x in m.T.reshape(-1)]


def _num(x: float) -> str:
    return repr(float(x)) if x != int(x) else str(int(x))


def _join(values: Any) -> str:
    return ",".join(_num(x) for x in np.asarray(values, dtype=np.float64).reshape(-1))


# ----------------------------------------------------------------------------- FBX 6.1 ASCII


def fbx_ascii_61(spec: FbxSpec, texture_name: str = "skin.png") -> str:
    """The character as an FBX 6.1 ASCII file (its text); the texture, when ``"file"``, is ``texture_name``."""
    s = fbx_scene(spec)
    out = [
        "; FBX 6.1.0 project file",
        "; ----------------------------------------------------",
        "",
        "FBXHeaderExtension:  {",
        "\tFBXHeaderVersion: 1003",
        "\tFBXVersion: 6100",
        '\tCreator: "FBX SDK/FBX Plugins version 2009.3"',
        "}",
        'Creator: "gesturekit tests"',
        "",
        "Objects:  {",
    ]
    for i, name in enumerate(s.names):
        pre, lcl, post = s.turns[i]
        out += [
            f'\tModel: "Model::{name}", "LimbNode" {{',
            "\t\tVersion: 232",
            "\t\tProperties60:  {",
            '\t\t\tProperty: "RotationActive", "bool", "",1',
            f'\t\t\tProperty: "PreRotation", "Vector3D", "",{_join(pre)}',
            f'\t\t\tProperty: "PostRotation", "Vector3D", "",{_join(post)}',
            f'\t\t\tProperty: "Lcl Translation", "Lcl Translation", "A+",{_join(s.translation[i])}',
            f'\t\t\tProperty: "Lcl Rotation", "Lcl Rotation", "A+",{_join(lcl)}',
            '\t\t\tProperty: "Lcl Scaling", "Lcl Scaling", "A+",1,1,1',
            "\t\t}",
            "\t\tMultiLayer: 0",
            "\t\tMultiTake: 1",
            '\t\tTypeFlags: "Skeleton"',
            "\t}",
        ]
    corners = _polygon_index(s.polygons)
    uv_index = [abs(c) if c >= 0 else -c - 1 for c in corners]
    out += [
        '\tModel: "Model::Body", "Mesh" {',
        "\t\tVersion: 232",
        "\t\tProperties60:  {",
        '\t\t\tProperty: "Lcl Translation", "Lcl Translation", "A+",0,0,0',
        '\t\t\tProperty: "Lcl Rotation", "Lcl Rotation", "A+",0,0,0',
        '\t\t\tProperty: "Lcl Scaling", "Lcl Scaling", "A+",1,1,1',
        "\t\t}",
        "\t\tMultiLayer: 0",
        "\t\tMultiTake: 1",
        f"\t\tVertices: {_join(s.vertices)}",
        f"\t\tPolygonVertexIndex: {','.join(map(str, corners))}",
        "\t\tGeometryVersion: 124",
        "\t\tLayerElementNormal: 0 {",
        "\t\t\tVersion: 101",
        '\t\t\tName: ""',
        '\t\t\tMappingInformationType: "ByVertice"',
        '\t\t\tReferenceInformationType: "Direct"',
        f"\t\t\tNormals: {_join(s.normals)}",
        "\t\t}",
        "\t\tLayerElementUV: 0 {",
        "\t\t\tVersion: 101",
        '\t\t\tName: "UVChannel_1"',
        '\t\t\tMappingInformationType: "ByPolygonVertex"',
        '\t\t\tReferenceInformationType: "IndexToDirect"',
        f"\t\t\tUV: {_join(s.uv)}",
        f"\t\t\tUVIndex: {','.join(map(str, uv_index))}",
        "\t\t}",
        "\t\tLayerElementMaterial: 0 {",
        "\t\t\tVersion: 101",
        '\t\t\tName: ""',
        '\t\t\tMappingInformationType: "ByPolygon"',
        '\t\t\tReferenceInformationType: "IndexToDirect"',
        f"\t\t\tMaterials: {','.join(map(str, s.polygon_material))}",
        "\t\t}",
        "\t\tLayer: 0 {",
        "\t\t\tVersion: 100",
        '\t\t\tLayerElement:  {\n\t\t\t\tType: "LayerElementNormal"\n\t\t\t\tTypedIndex: 0\n\t\t\t}',
        '\t\t\tLayerElement:  {\n\t\t\t\tType: "LayerElementMaterial"\n\t\t\t\tTypedIndex: 0\n\t\t\t}',
        '\t\t\tLayerElement:  {\n\t\t\t\tType: "LayerElementUV"\n\t\t\t\tTypedIndex: 0\n\t\t\t}',
        "\t\t}",
        "\t}",
    ]
    for name, color in (("skin", (0.87, 0.68, 0.57)), ("cloth", (0.25, 0.35, 0.6))):
        out += [
            f'\tMaterial: "Material::{name}", "" {{',
            "\t\tVersion: 102",
            '\t\tShadingModel: "lambert"',
            "\t\tMultiLayer: 0",
            "\t\tProperties60:  {",
            f'\t\t\tProperty: "DiffuseColor", "ColorRGB", "",{_join(color)}',
            '\t\t\tProperty: "DiffuseFactor", "double", "",1',
            "\t\t}",
            "\t}",
        ]
    if spec.texture == "file":
        out += [
            '\tTexture: "Texture::checker", "TextureVideoClip" {',
            '\t\tType: "TextureVideoClip"',
            "\t\tVersion: 202",
            '\t\tTextureName: "Texture::checker"',
            '\t\tMedia: "Video::checker"',
            f'\t\tFileName: "C:/Users/artist/textures/{texture_name}"',
            f'\t\tRelativeFilename: "{texture_name}"',
            "\t}",
        ]
    for i, (idx, w) in s.clusters.items():
        out += [
            f'\tDeformer: "SubDeformer::Cluster Body {s.names[i]}", "Cluster" {{',
            "\t\tVersion: 100",
            "\t\tMultiLayer: 0",
            '\t\tType: "Cluster"',
            '\t\tUserData: "", ""',
            f"\t\tIndexes: {','.join(map(str, idx))}",
            f"\t\tWeights: {_join(w)}",
            f"\t\tTransform: {_join(_matrix(np.linalg.inv(s.world[i])))}",
            f"\t\tTransformLink: {_join(_matrix(s.world[i]))}",
            "\t}",
        ]
    out += [
        '\tDeformer: "Deformer::Skin Body", "Skin" {',
        "\t\tVersion: 100",
        "\t\tMultiLayer: 0",
        '\t\tType: "Skin"',
        "\t\tLink_DeformAcuracy: 50",
        "\t}",
        "\tGlobalSettings:  {",
        "\t\tVersion: 1000",
        "\t\tProperties60:  {",
    ]
    for key, value in zip(
        ("UpAxis", "UpAxisSign", "FrontAxis", "FrontAxisSign", "CoordAxis", "CoordAxisSign"), s.settings
    ):
        out.append(f'\t\t\tProperty: "{key}", "int", "",{value}')
    out += [
        f'\t\t\tProperty: "UnitScaleFactor", "double", "",{_num(s.unit_scale_factor)}',
        "\t\t}",
        "\t}",
        "}",
        "",
        "Connections:  {",
    ]
    for i, name in enumerate(s.names):
        parent = "Model::Scene" if s.parents[i] < 0 else f"Model::{s.names[s.parents[i]]}"
        out.append(f'\tConnect: "OO", "Model::{name}", "{parent}"')
    out.append('\tConnect: "OO", "Model::Body", "Model::Scene"')
    out.append('\tConnect: "OO", "Material::skin", "Model::Body"')
    out.append('\tConnect: "OO", "Material::cloth", "Model::Body"')
    if spec.texture == "file":
        out.append('\tConnect: "OP", "Texture::checker", "Material::cloth", "DiffuseColor"')
    out.append('\tConnect: "OO", "Deformer::Skin Body", "Model::Body"')
    for i in s.clusters:
        out.append(f'\tConnect: "OO", "SubDeformer::Cluster Body {s.names[i]}", "Deformer::Skin Body"')
        out.append(f'\tConnect: "OO", "Model::{s.names[i]}", "SubDeformer::Cluster Body {s.names[i]}"')
    out.append("}")
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- FBX 7.x binary


class _L(int):
    """An FBX 64-bit integer property (object ids)."""


ObjectId = _L


class RawProperty(bytes):
    """A property written as these bytes, type code included (for a header that lies about its data)."""


Node = tuple[str, list[Any], list[Any]]


def _property(v: Any, compress: bool) -> bytes:
    if isinstance(v, RawProperty):
        return bytes(v)
    if isinstance(v, _L):
        return b"L" + struct.pack("<q", int(v))
    if isinstance(v, bool):
        return b"C" + struct.pack("<?", v)
    if isinstance(v, int):
        return b"I" + struct.pack("<i", v)
    if isinstance(v, float):
        return b"D" + struct.pack("<d", v)
    if isinstance(v, str):
        data = v.encode("utf-8")
        return b"S" + struct.pack("<I", len(data)) + data
    if isinstance(v, bytes):
        return b"R" + struct.pack("<I", len(v)) + v
    a = np.asarray(v)
    code, dtype = {"f": (b"d", "<f8"), "i": (b"i", "<i4")}[a.dtype.kind if a.dtype.kind != "u" else "i"]
    if a.dtype.kind == "i" and a.dtype.itemsize == 8:
        code, dtype = b"l", "<i8"
    raw = np.ascontiguousarray(a.reshape(-1), dtype=dtype).tobytes()
    body = zlib.compress(raw) if compress else raw
    return code + struct.pack("<III", a.size, 1 if compress else 0, len(body)) + body


def node_bytes(out: bytearray, node: Node, *, wide: bool, compress: bool = True) -> None:
    """Append one node record (and its children, then a null record) to ``out``."""
    name, props, children = node
    start = len(out)
    data = b"".join(_property(p, compress) for p in props)
    head = struct.Struct("<QQQ" if wide else "<III")
    out += b"\0" * head.size
    out += bytes([len(name)]) + name.encode("ascii") + data
    for child in children:
        node_bytes(out, child, wide=wide, compress=compress)
    if children or not props:
        out += b"\0" * (head.size + 1)
    head.pack_into(out, start, len(out), len(props), len(data))


def _p70(*entries: tuple) -> Node:
    return ("Properties70", [], [("P", list(e), []) for e in entries])


def fbx_binary(spec: FbxSpec, *, version: int = 7400, compress: bool = True, texture_name: str = "skin.png") -> bytes:
    """The character as a binary FBX of ``version`` (7100..7700); arrays deflated when ``compress``."""
    s = fbx_scene(spec)
    keys = ("UpAxis", "UpAxisSign", "FrontAxis", "FrontAxisSign", "CoordAxis", "CoordAxisSign")
    settings = [(k, "int", "Integer", "", int(v)) for k, v in zip(keys, s.settings)]
    settings.append(("UnitScaleFactor", "double", "Number", "", float(s.unit_scale_factor)))
    objects: list[Node] = []
    links: list[Node] = []
    ids = {name: _L(1000 + i) for i, name in enumerate(s.names)}
    top_id = _L(0)
    if s.armature is not None:
        top_id = _L(10)
        turn, size = ARMATURE
        null = _p70(
            ("Lcl Rotation", "Lcl Rotation", "", "A", *map(float, turn)),
            ("Lcl Scaling", "Lcl Scaling", "", "A", *[float(size)] * 3),
        )
        objects.append(("Model", [top_id, "Armature\x00\x01Model", "Null"], [("Version", [232], []), null]))
        links.append(("C", ["OO", top_id, _L(0)], []))
    for i, name in enumerate(s.names):
        pre, lcl, post = s.turns[i]
        attr = _L(5000 + i)
        objects.append(
            ("NodeAttribute", [attr, f"{name}\x00\x01NodeAttribute", "LimbNode"], [("TypeFlags", ["Skeleton"], [])])
        )
        objects.append(
            (
                "Model",
                [ids[name], f"{name}\x00\x01Model", "LimbNode"],
                [
                    ("Version", [232], []),
                    _p70(
                        ("RotationActive", "bool", "", "", 1),
                        ("PreRotation", "Vector3D", "Vector", "", *map(float, pre)),
                        ("PostRotation", "Vector3D", "Vector", "", *map(float, post)),
                        ("Lcl Translation", "Lcl Translation", "", "A", *map(float, s.translation[i])),
                        ("Lcl Rotation", "Lcl Rotation", "", "A", *map(float, lcl)),
                        ("Lcl Scaling", "Lcl Scaling", "", "A", *[float(s.scaling[i])] * 3),
                    ),
                ],
            )
        )
        links.append(("C", ["OO", attr, ids[name]], []))
        parent = top_id if s.parents[i] < 0 else ids[s.names[s.parents[i]]]
        links.append(("C", ["OO", ids[name], parent], []))
    corners = np.array(_polygon_index(s.polygons), dtype=np.int32)
    uv_index = np.where(corners >= 0, corners, -corners - 1).astype(np.int32)
    mesh, geom, skin = _L(20), _L(21), _L(22)
    layer = [
        ("LayerElement", [], [("Type", [t], []), ("TypedIndex", [0], [])])
        for t in ("LayerElementNormal", "LayerElementUV", "LayerElementMaterial")
    ]
    objects.append(
        (
            "Geometry",
            [geom, "Body\x00\x01Geometry", "Mesh"],
            [
                ("Vertices", [s.vertices], []),
                ("PolygonVertexIndex", [corners], []),
                ("GeometryVersion", [124], []),
                (
                    "LayerElementNormal",
                    [0],
                    [
                        ("Version", [101], []),
                        ("Name", [""], []),
                        ("MappingInformationType", ["ByVertice"], []),
                        ("ReferenceInformationType", ["Direct"], []),
                        ("Normals", [s.normals], []),
                    ],
                ),
                (
                    "LayerElementUV",
                    [0],
                    [
                        ("Version", [101], []),
                        ("Name", ["UVMap"], []),
                        ("MappingInformationType", ["ByPolygonVertex"], []),
                        ("ReferenceInformationType", ["IndexToDirect"], []),
                        ("UV", [s.uv], []),
                        ("UVIndex", [uv_index], []),
                    ],
                ),
                (
                    "LayerElementMaterial",
                    [0],
                    [
                        ("Version", [101], []),
                        ("Name", [""], []),
                        ("MappingInformationType", ["ByPolygon"], []),
                        ("ReferenceInformationType", ["IndexToDirect"], []),
                        ("Materials", [np.array(s.polygon_material, dtype=np.int32)], []),
                    ],
                ),
                ("Layer", [0], [("Version", [100], []), *layer]),
            ],
        )
    )
    objects.append(("Model", [mesh, "Body\x00\x01Model", "Mesh"], [("Version", [232], [])]))
    links += [("C", ["OO", mesh, top_id], []), ("C", ["OO", geom, mesh], [])]
    for k, (name, color) in enumerate((("skin", (0.87, 0.68, 0.57)), ("cloth", (0.25, 0.35, 0.6)))):
        material = _L(30 + k)
        objects.append(
            (
                "Material",
                [material, f"{name}\x00\x01Material", ""],
                [
                    ("Version", [102], []),
                    ("ShadingModel", ["phong"], []),
                    _p70(
                        ("DiffuseColor", "Color", "", "A", *map(float, color)),
                        ("DiffuseFactor", "Number", "", "A", 1.0),
                    ),
                ],
            )
        )
        links.append(("C", ["OO", material, mesh], []))
    if spec.texture != "none":
        texture, video = _L(40), _L(41)
        video_children = [
            ("Type", ["Clip"], []),
            ("FileName", [f"C:/Users/artist/textures/{texture_name}"], []),
            ("RelativeFilename", [texture_name], []),
        ]
        if spec.texture == "embedded":
            video_children.append(("Content", [s.png], []))
        objects.append(("Video", [video, "checker\x00\x01Video", "Clip"], video_children))
        objects.append(
            (
                "Texture",
                [texture, "checker\x00\x01Texture", ""],
                [
                    ("Type", ["TextureVideoClip"], []),
                    ("Version", [202], []),
                    ("TextureName", ["checker\x00\x01Texture"], []),
                    ("Media", ["checker\x00\x01Video"], []),
                    ("FileName", [f"C:/Users/artist/textures/{texture_name}"], []),
                    ("RelativeFilename", [texture_name], []),
                ],
            )
        )
        links += [("C", ["OP", texture, _L(31), "DiffuseColor"], []), ("C", ["OO", video, texture], [])]
    objects.append(
        (
            "Deformer",
            [skin, "Body\x00\x01Deformer", "Skin"],
            [("Version", [101], []), ("Link_DeformAcuracy", [50.0], [])],
        )
    )
    links.append(("C", ["OO", skin, geom], []))
    mesh_world = np.eye(4) if s.armature is None else s.armature
    for b, (idx, w) in s.clusters.items():
        cluster = _L(3000 + b)
        objects.append(
            (
                "Deformer",
                [cluster, f"{s.names[b]}\x00\x01SubDeformer", "Cluster"],
                [
                    ("Version", [100], []),
                    ("UserData", ["", ""], []),
                    ("Indexes", [idx.astype(np.int32)], []),
                    ("Weights", [w], []),
                    ("Transform", [np.array(_matrix(np.linalg.inv(s.world[b]) @ mesh_world))], []),
                    ("TransformLink", [np.array(_matrix(s.world[b]))], []),
                ],
            )
        )
        links += [("C", ["OO", cluster, skin], []), ("C", ["OO", ids[s.names[b]], cluster], [])]
    top: list[Node] = [
        (
            "FBXHeaderExtension",
            [],
            [("FBXHeaderVersion", [1003], []), ("FBXVersion", [version], []), ("Creator", ["gesturekit tests"], [])],
        ),
        ("GlobalSettings", [], [("Version", [1000], []), _p70(*settings)]),
        ("Objects", [], objects),
        ("Connections", [], links),
    ]
    out = bytearray(b"Kaydara FBX Binary  \x00\x1a\x00" + struct.pack("<I", version))
    wide = version >= 7500
    for node in top:
        node_bytes(out, node, wide=wide, compress=compress)
    out += b"\0" * (25 if wide else 13)
    out += bytes.fromhex("fabcab09d0c8d466b176fb831cf7267e") + b"\0" * (-len(out) % 16 + 4)
    out += struct.pack("<I", version) + b"\0" * 120 + bytes.fromhex("f85a8c6adef5d97eece90ce3758f290b")
    return bytes(out)
