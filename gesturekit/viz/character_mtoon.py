"""A VRM's toon-shaded (MToon) materials in the MP4: VTK actors whose fragments are shaded by the MToon rule.

The page draws a VRM's MToon materials with three-vrm's ``MToonMaterial``;
the MP4 draws the same rule (:func:`gesturekit.character.mtoon.mtoon_shade`)
per fragment, as three.js does: each material's triangles are one VTK actor
whose fragment shader is replaced by :func:`fragment_code` (the skinned
normal of every vertex passed in as a vertex attribute, interpolated across
the triangle, so the toony step between lit and shade colour stays as sharp
as on the page), with its lit and shade textures sampled in linear light. An
outlined material gets a second actor, its vertices pushed out along their
normals (:func:`outline_points`) and drawn on its back faces only.
The look's lights and the camera are constants of the shader.
"""

from __future__ import annotations

import numpy as np
import pyvista as pv
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

from .._arguments import checks_arguments
from ..character.look import AMBIENT, LIGHTS
from ..character.materials import SkinMaterial
from ..character.mtoon import MToon
from .character_user import UserBody

__all__ = ["NORMALS", "fragment_code", "outline_points", "MToonActors"]

#: The name of the skinned normals' point array that the MToon shader reads.
NORMALS = "mtoon_normal"

_VS_DEC = """//VTK::Normal::Dec
in vec3 mtoonNormal;
out vec3 mtoonNormalVSOutput;
out vec3 mtoonPositionVSOutput;
"""
_VS_IMPL = """//VTK::Normal::Impl
  mtoonNormalVSOutput = mtoonNormal;
  mtoonPositionVSOutput = vertexMC.xyz;
"""
_FS_DEC = """//VTK::Normal::Dec
in vec3 mtoonNormalVSOutput;
in vec3 mtoonPositionVSOutput;
"""


def _vec3(v) -> str:
    return "vec3(" + ", ".join(f"{float(x):.8f}" for x in v) + ")"


@checks_arguments
def fragment_code(material: SkinMaterial, *, base: bool, shade: bool, camera: np.ndarray, outline: bool = False) -> str:
    """The fragment shader's body (VTK's ``//VTK::TCoord::Impl``) of an MToon material.

    Parameters
    ----------
    material : SkinMaterial
        With its :attr:`~gesturekit.character.materials.SkinMaterial.mtoon`.
    base, shade : bool
        Whether the base colour texture (sampler ``mtoonBase``) and the shade multiply texture (``mtoonShade``)
        are bound, both sampled in linear light.
    camera : np.ndarray, shape (3,)
        The camera's position, metres (the rim looks towards it).
    outline : bool
        The outline's fragments: its colour times the shading mixed by its lighting mix.

    Returns
    -------
    str
        GLSL writing the fragment's sRGB colour, or discarding it under the material's alpha cutoff.
    """
    m = material.mtoon
    assert m is not None
    lines = ["  vec3 n = normalize(mtoonNormalVSOutput);"]
    if material.double_sided and not outline:
        lines.append("  if (!gl_FrontFacing) n = -n;")  # three.js's DOUBLE_SIDED: the back face's own normal
    lines.append(f"  vec4 base = vec4({_vec3(material.color[:3])}, {float(np.clip(material.color[3], 0, 1)):.8f});")
    if base:
        lines.append("  base *= texture(mtoonBase, tcoordVCVSOutput);")
    # OPAQUE ignores alpha; BLEND is cut at half (the MP4 sorts no transparent layers), as for other materials
    cutoff = {"MASK": material.alpha_cutoff, "BLEND": 0.5}.get(material.alpha_mode)
    if cutoff is not None:
        lines.append(f"  if (base.a < {float(cutoff):.8f}) discard;")
    lines.append(f"  vec3 shadeColor = {_vec3(m.shade_color)};")
    if shade:
        lines.append("  shadeColor *= texture(mtoonShade, tcoordVCVSOutput).rgb;")
    lines.append(f"  vec3 col = {float(AMBIENT):.8f} * base.rgb;")
    lo, hi = -1.0 + m.shading_toony, 1.0 - m.shading_toony
    for direction, strength in LIGHTS:
        d = np.asarray(direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        lines.append(f"  float d{len(lines)} = clamp(dot(n, {_vec3(d)}), -1.0, 1.0) + {m.shading_shift:.8f};")
        name = f"d{len(lines) - 1}"
        if hi > lo:
            t = f"clamp(({name} - {lo:.8f}) / {hi - lo:.8f}, 0.0, 1.0)"
        else:
            t = f"step({lo:.8f}, {name})"
        lines.append(f"  col += {float(strength):.8f} * mix(shadeColor, base.rgb, {t});")
    if any(m.rim_color):
        light = AMBIENT + sum(float(k) for _, k in LIGHTS)
        mix = 1.0 + m.rim_lighting_mix * (light - 1.0)
        lines += [
            f"  vec3 towards = normalize({_vec3(camera)} - mtoonPositionVSOutput);",
            f"  float edge = clamp(1.0 - dot(towards, n) + {m.rim_lift:.8f}, 0.0, 1.0);",
            f"  edge = pow(edge, {m.rim_fresnel_power:.8f});",
            f"  col += {mix:.8f} * edge * {_vec3(m.rim_color)};",
        ]
    lines.append(f"  col += {_vec3(m.emissive)};")
    if outline:
        lines.append(f"  col = {_vec3(m.outline_color)} * mix(vec3(1.0), col, {m.outline_lighting_mix:.8f});")
    lines += [
        "  vec3 lin = clamp(col, 0.0, 1.0);",
        "  gl_FragData[0] = vec4(mix(lin * 12.92, 1.055 * pow(lin, vec3(1.0 / 2.4)) - 0.055, "
        "step(0.0031308, lin)), 1.0);",
    ]
    return "\n" + "\n".join(lines) + "\n"


@checks_arguments
def outline_points(
    vertices: np.ndarray, normals: np.ndarray, mtoon: MToon, camera: dict, *, out: np.ndarray | None = None
) -> np.ndarray:
    """The outline's vertices: each pushed out along its unit normal by the outline's width, as three-vrm does.

    Parameters
    ----------
    vertices, normals : np.ndarray, shape (V, 3)
        The posed skin, metres, and its unit normals.
    mtoon : MToon
        ``"worldCoordinates"``: the width in metres; ``"screenCoordinates"``: a share of half the picture's
        height at the vertex's depth (the width times the depth times ``tan(fov / 2)``).
    camera : dict
        ``position``, ``target`` (metres) and ``fov`` (degrees, vertical).
    out : np.ndarray, optional
        Where to write them.

    Returns
    -------
    np.ndarray, shape (V, 3)
    """
    width = np.full(len(vertices), float(mtoon.outline_width))
    if mtoon.outline_mode == "screenCoordinates":
        eye = np.asarray(camera["position"], dtype=np.float64)
        forward = np.asarray(camera["target"], dtype=np.float64) - eye
        forward /= np.linalg.norm(forward)
        depth = (np.asarray(vertices, dtype=np.float64) - eye) @ forward
        width = width * depth * np.tan(np.radians(float(camera["fov"])) / 2)
    result = np.asarray(vertices) + width[:, None] * np.asarray(normals)
    if out is None:
        return result
    out[:] = result
    return out


def _texture(image: np.ndarray, nearest: bool):
    """A VTK texture of an sRGB image (height, width, 4), uint8, top row first, sampled in linear light."""
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkRenderingCore import vtkTexture

    h, w = image.shape[:2]
    data = vtkImageData()
    data.SetDimensions(w, h, 1)
    data.GetPointData().SetScalars(numpy_to_vtk(np.ascontiguousarray(image[::-1].reshape(-1, 4)), deep=True))
    texture = vtkTexture()
    texture.SetInputData(data)
    texture.SetColorModeToDirectScalars()
    texture.SetUseSRGBColorSpace(True)  # decoded before filtering, as WebGL decodes an sRGB texture
    texture.SetRepeat(True)
    texture.SetInterpolate(not nearest)
    texture.SetMipmap(not nearest)
    return texture


class MToonActors:
    """The MToon materials of one character: a surface actor each, an outline actor for each outlined one.

    Parameters
    ----------
    plotter : pyvista.Plotter
    mesh : pyvista.PolyData
        The character's posed mesh (its points are shared, not copied).
    faces : np.ndarray, shape (F, 3)
        Its triangles (those of ``user``'s skin).
    user : UserBody
        The character: its skin's materials of each triangle and texture coordinates, its materials and images.
    camera : dict
        The picture's camera (``position``, ``target``, ``fov``).
    """

    def __init__(self, plotter: pv.Plotter, mesh: pv.PolyData, faces: np.ndarray, user: UserBody, camera: dict):
        from vtkmodules.vtkCommonDataModel import vtkDataObject
        from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper

        self.camera = camera
        eye = np.asarray(camera["position"], dtype=np.float64)
        n_points = mesh.GetNumberOfPoints()
        self._normals = numpy_to_vtk(np.zeros((n_points, 3), dtype=np.float32), deep=True)
        self._normals.SetName(NORMALS)
        self.normals = vtk_to_numpy(self._normals)
        materials, images = user.materials, user.images
        assert user.skin.uvs is not None and user.skin.face_materials is not None
        uv = np.asarray(user.skin.uvs, dtype=np.float32)
        tcoords = numpy_to_vtk(np.ascontiguousarray(np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)), deep=True)
        textures: dict[tuple[int, bool], object] = {}

        def texture(image: int, nearest: bool):
            if (image, nearest) not in textures:
                textures[(image, nearest)] = _texture(images[image], nearest)
            return textures[(image, nearest)]

        self.actors: list = []
        #: each outline: its material, its points' numpy view, its polydata
        self._outlines: list[tuple[MToon, np.ndarray, pv.PolyData]] = []
        which = np.asarray(user.skin.face_materials)
        for k, mat in enumerate(materials):
            mine = faces[which == k]
            if mat.mtoon is None or not len(mine):
                continue
            cells = np.hstack([np.full((len(mine), 1), 3, dtype=np.int64), mine.astype(np.int64)]).ravel()
            shade_image = mat.shade_image
            for outline in (False, True) if mat.mtoon.outlined else (False,):
                part = pv.PolyData()
                if outline:
                    points = np.zeros((n_points, 3), dtype=np.float64)
                    part.points = points
                else:
                    part.SetPoints(mesh.GetPoints())  # one set of points: posing the mesh poses the part
                part.faces = cells
                part.GetPointData().AddArray(self._normals)
                if mat.image is not None or shade_image is not None:
                    part.GetPointData().SetTCoords(tcoords)
                # a plain polygon mapper: the shader reads the normals as a vertex attribute of its own
                mapper = vtkPolyDataMapper()
                mapper.SetInputData(part)
                mapper.ScalarVisibilityOff()
                actor = vtkActor()
                actor.SetMapper(mapper)
                prop = actor.GetProperty()
                prop.LightingOff()
                prop.SetInterpolationToGouraud()
                if outline:
                    prop.FrontfaceCullingOn()  # the pushed-out hull's back faces: a rim around the body
                    self._outlines.append((mat.mtoon, vtk_to_numpy(part.GetPoints().GetData()), part))
                else:
                    prop.SetBackfaceCulling(not mat.double_sided)
                plotter.renderer.AddActor(actor)
                if mat.image is not None:
                    actor.GetProperty().SetTexture("mtoonBase", texture(mat.image, mat.nearest))
                if shade_image is not None:
                    actor.GetProperty().SetTexture("mtoonShade", texture(shade_image, mat.shade_nearest))
                mapper.MapDataArrayToVertexAttribute("mtoonNormal", NORMALS, vtkDataObject.FIELD_ASSOCIATION_POINTS, -1)
                sp = actor.GetShaderProperty()
                sp.AddVertexShaderReplacement("//VTK::Normal::Dec", True, _VS_DEC, False)
                sp.AddVertexShaderReplacement("//VTK::Normal::Impl", True, _VS_IMPL, False)
                sp.AddFragmentShaderReplacement("//VTK::Normal::Dec", True, _FS_DEC, False)
                code = fragment_code(
                    mat, base=mat.image is not None, shade=shade_image is not None, camera=eye, outline=outline
                )
                sp.AddFragmentShaderReplacement("//VTK::TCoord::Impl", True, code, False)
                self.actors.append(actor)

    def update(self, vertices: np.ndarray, normals: np.ndarray) -> None:
        """Pose the materials: the mesh's points are already ``vertices``; its unit normals and the outlines."""
        self.normals[:] = normals
        self._normals.Modified()
        for mtoon, view, part in self._outlines:
            outline_points(vertices, normals, mtoon, self.camera, out=view)
            part.GetPoints().Modified()
