"""The character in the MP4: the skinned body, lit, coloured and framed as the page draws it.

:class:`CharacterStage` holds what a render of side-by-side motions needs
besides VTK: each motion's rig, pose and mesh (:mod:`gesturekit.character`),
where each character stands and the box the camera frames
(:func:`gesturekit.character.look.stage_layout`), and per frame the skinned
vertices and their colours. The colours carry the shading: the page's
Lambert rule ``albedo * (AMBIENT + KEY * max(0, n . l))`` is evaluated here in
linear light, per vertex, and converted to sRGB (:func:`shade`), so VTK draws
them unlit (:class:`CharacterDrawing`) and its own light model cannot make the
MP4 differ from the page. With a user's character (``character=``), each motion
is retargeted onto it and its own skin and colours are drawn by the same rules
(:mod:`gesturekit.viz.character_user`); its toon-shaded (MToon) materials, whose
step between lit and shade colour is too sharp for colours per vertex, are shaded
per fragment by the same rule as the page's (:mod:`gesturekit.viz.character_mtoon`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyvista as pv
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

from ..character.look import (
    FIELD_OF_VIEW,
    FRAMINGS,
    UPPER_BODY,
    camera_for,
    linear_to_srgb,
    part_colors,
    scheme_for,
    shade,
    srgb_to_linear,
    stage_layout,
    stage_meshes,
)
from ..character.mesh import PARTS, CharacterMesh, build_mesh
from ..character.paint import EMPTY_BODY, paint
from ..character.rig import Pose, Rig, rig_for, solve_pose
from ..character.skin import skin_normals, skin_vertices
from ..character.stand import StandMesh, stand_mesh, standing_root
from ..character.target import Character
from ..errors import ConfigError
from ..motion import Motion
from .character_mtoon import MToonActors
from .character_user import UserBody

__all__ = ["srgb_to_linear", "linear_to_srgb", "shade", "visible_faces", "CharacterStage", "CharacterDrawing"]


def visible_faces(mesh: CharacterMesh, rig: Rig) -> np.ndarray:
    """The faces drawn for a rig, shape (F', 3), int32: those with no vertex bound mostly (weight
    above a half) to a joint the rig lacks (an absent part follows its nearest ancestor and would
    hang there; it is hidden instead)."""
    absent = ~rig.in_rig
    on_absent = (mesh.weights * absent[mesh.joints]).sum(axis=1) > 0.5
    return mesh.faces[~on_absent[mesh.faces].any(axis=1)]


def _body(rig: Rig) -> CharacterMesh:
    """The rig's body; none (no vertex) when no bone has a length (every joint at one point), as on the page."""
    return build_mesh(rig) if (rig.lengths[rig.parents >= 0] > 1e-6).any() else EMPTY_BODY


class CharacterStage:
    """Side-by-side characters on one stage: their bodies frame by frame and the camera's box.

    Parameters
    ----------
    motions : sequence of Motion
        One character each, left to right; a motion shorter than the longest holds its last pose.
    neutral : bool
        Every character in the neutral scheme (study stimuli) instead of the side-by-side schemes.
    view_box : array_like, shape (3, 2), optional
        ``(min, max)`` of x, y, z, metres: a fixed box for the camera instead of the stage's
        (:func:`~gesturekit.character.look.stage_layout`), so that clips of different systems are
        framed alike. With a ``character``, the box is relative to its pelvis's rest position.
    character : Character, optional
        A user's character (:func:`gesturekit.character.user.read_character`) that every motion is retargeted
        onto (:class:`~gesturekit.viz.character_user.UserBody`): its own skin and colours instead of our
        character, framed on its bones that follow the motion.
    framing : str
        :func:`~gesturekit.character.look.stage_layout`'s framing (:data:`~gesturekit.character.look.FRAMINGS`).
    schemes : sequence of str, optional
        Each character's colour scheme (default by place, :func:`~gesturekit.character.look.scheme_for`).

    Attributes
    ----------
    offsets : np.ndarray, shape (characters,)
        Each character's shift along X, metres.
    box : np.ndarray, shape (2, 3)
        Lower and upper corner of the framed box, metres.
    schemes : list of str
        Each character's colour scheme.
    users : list of UserBody or None
        With a ``character``: each motion on it (:class:`~gesturekit.viz.character_user.UserBody`); then
        the attributes of our body (``rigs``, ``poses``, ``meshes``, ``stands``) are not set.
    stands : list of StandMesh or None
        Each character's still legs (:func:`gesturekit.character.stand.stand_mesh`), in its motion's frame.
    ground : float or None
        The floor's height, metres (the lowest soles), None without legs.
    """

    def __init__(
        self,
        motions: Sequence[Motion],
        *,
        neutral: bool = False,
        view_box: object = None,
        character: Character | None = None,
        framing: str = UPPER_BODY,
        schemes: Sequence[str] | None = None,
    ):
        self.motions = list(motions)
        if not self.motions:
            raise ConfigError("a stage needs at least one motion")
        if framing not in FRAMINGS:
            raise ConfigError(f"unknown framing {framing!r}; choose one of {', '.join(FRAMINGS)}")
        if schemes is not None and len(schemes) != len(self.motions):
            raise ConfigError(f"{len(self.motions)} motions need as many colour schemes, got {len(schemes)}")
        self.framing = framing
        self.schemes = (
            list(schemes) if schemes is not None else [scheme_for(i, neutral=neutral) for i in range(len(self.motions))]
        )
        self.users: list[UserBody] | None = None
        self.ground: float | None = None
        self.stands: list[StandMesh | None] = [None] * len(self.motions)
        if character is not None:
            self.users = [UserBody(m, character, s) for m, s in zip(self.motions, self.schemes)]
            self.faces = [u.faces for u in self.users]
            self.offsets, self.box = stage_layout([u.framing_points() for u in self.users], framing=framing)
            if view_box is not None:
                pelvis = np.asarray(character.rest_position[character.pelvis], dtype=np.float64)
                self.box = np.asarray(view_box, dtype=np.float64).T + pelvis
            return
        self.rigs = [rig_for(m) for m in self.motions]
        self.poses = [solve_pose(m, r) for m, r in zip(self.motions, self.rigs)]
        # the page's colours on the page's mesh: split where colours meet, each vertex one palette entry
        painted = [paint(_body(r), m.presence, s) for r, m, s in zip(self.rigs, self.motions, self.schemes)]
        self.meshes = [mesh for mesh, _ in painted]
        self.faces = [visible_faces(mesh, r) for mesh, r in zip(self.meshes, self.rigs)]
        self.stands = [
            stand_mesh(r, standing_root(p.root)) if mesh.n_vertices else None
            for r, p, mesh in zip(self.rigs, self.poses, self.meshes)
        ]
        floors = [st.floor for st in self.stands if st is not None]
        self.ground = min(floors) if floors else None
        # the page's layout rule on the page's input: every drawn joint over the clip
        drawn = [m.positions[:, m.presence.drawn] for m in self.motions]
        waist = min(st.pelvis for st in self.stands if st is not None) if floors else None
        self.offsets, self.box = stage_layout(drawn, framing=framing, ground=self.ground, waist=waist)
        if view_box is not None:
            self.box = np.asarray(view_box, dtype=np.float64).T.copy()
        self._albedo = [srgb_to_linear(palette[mesh.parts]) for mesh, palette in painted]  # (V, 3), linear light
        self._palettes = [palette for _, palette in painted]

    @property
    def n_frames(self) -> int:
        """Frames of the longest motion."""
        return max(m.n_frames for m in self.motions)

    def camera(self, aspect: float) -> dict:
        """The page's camera for a picture of width over height ``aspect``
        (:func:`~gesturekit.character.look.camera_for` of :attr:`box`)."""
        top = self.framing == UPPER_BODY
        return camera_for(self.box[0], self.box[1], aspect, fov=FIELD_OF_VIEW, top=top, floor=self.ground)

    def stand(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Character ``index``'s still legs in its place: vertices (V, 3) float32 metres, faces (F, 3) and shaded
        sRGB colours (V, 3) uint8, lit by the same rule as the body; None without legs."""
        st = self.stands[index]
        if st is None:
            return None
        v = st.vertices.copy()
        v[:, 0] += np.float32(self.offsets[index])
        colours = shade(st.normals, srgb_to_linear(self._palettes[index][st.parts]))
        return v, st.faces, colours

    def stage(self) -> list[dict]:
        """The floor and each character's contact shadow (:func:`~gesturekit.character.look.stage_meshes`),
        as the page draws them; none without legs."""
        if self.ground is None:
            return []
        full = stage_layout(
            [m.positions[:, m.presence.drawn] for m in self.motions], framing="full body", ground=self.ground
        )[1]
        feet = [
            np.array([dx, 0.0, 0.0]) + st.vertices.mean(axis=0)
            for st, dx in zip(self.stands, self.offsets)
            if st is not None
        ]
        return stage_meshes(full, self.ground, feet)

    def vertices(self, index: int, frame: int) -> np.ndarray:
        """Character ``index``'s skinned vertices at ``frame`` (its last past its end), shifted to its
        place, shape (V, 3), float32, metres."""
        if self.users is not None:
            v = self.users[index].vertices(frame)
            v[:, 0] += np.float32(self.offsets[index])
            return v
        pose = self.poses[index]
        f = min(int(frame), pose.n_frames - 1)
        # one frame's pose at a time: a frame's vertices do not depend on which others are skinned with it
        one = Pose(local=pose.local[f : f + 1], root=pose.root[f : f + 1])
        v = skin_vertices(self.meshes[index], self.rigs[index], one)[0]
        v[:, 0] += np.float32(self.offsets[index])
        return v

    def colors(self, index: int, frame: int) -> np.ndarray:
        """Shaded sRGB colours, shape (V, 3), uint8, of character ``index`` at ``frame`` (its last past its end).

        The normals are the rest normals skinned as three.js skins them
        (:func:`~gesturekit.character.skin.skin_normals`), so the MP4 shades each vertex as the page does.
        A user's character: its own colours, shaded by its skinned normals.
        """
        if self.users is not None:
            return self.users[index].colors(frame)
        if not self.meshes[index].n_vertices:  # no body
            return np.zeros((0, 3), np.uint8)
        pose = self.poses[index]
        f = min(int(frame), pose.n_frames - 1)
        one = Pose(local=pose.local[f : f + 1], root=pose.root[f : f + 1])
        return shade(skin_normals(self.meshes[index], self.rigs[index], one)[0], self._albedo[index])

    def label_anchor(self, index: int) -> np.ndarray:
        """Where character ``index``'s label stands, shape (3,), metres: as on the page, at the top of
        the framed box, at the character's place across, halfway in depth (the label's foot is
        :data:`LABEL_RAISE` pixels above it)."""
        centre = (self.box[0] + self.box[1]) / 2
        return np.array([centre[0] + self.offsets[index], self.box[1, 1], centre[2]])


#: The fragment shader's texturing of a user's material (VTK's ``//VTK::TCoord::Impl``): the vertex colour
#: (the material's factor, shaded, sRGB) times the texel, in linear light, shown as sRGB; a texel whose alpha
#: (times the factor's) is under the cutoff is not drawn. ``{cutoff}`` and ``{alpha}`` are filled in per material.
_TEXTURED = """
  vec4 texel = texture(actortexture, tcoordVCVSOutput);
  if (texel.a * {alpha} < {cutoff}) discard;
  vec3 shaded = gl_FragData[0].rgb;
  vec3 a = mix(shaded / 12.92, pow((shaded + 0.055) / 1.055, vec3(2.4)), step(0.04045, shaded));
  vec3 b = mix(texel.rgb / 12.92, pow((texel.rgb + 0.055) / 1.055, vec3(2.4)), step(0.04045, texel.rgb));
  vec3 lin = clamp(a * b, 0.0, 1.0);
  gl_FragData[0] = vec4(mix(lin * 12.92, 1.055 * pow(lin, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, lin)), 1.0);
"""


def _texture(image: np.ndarray, nearest: bool):
    """A VTK texture of an RGBA image (height, width, 4), uint8, top row first, repeated as glTF's default
    sampler repeats; interpolated and mipmapped unless ``nearest``."""
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkRenderingCore import vtkTexture

    h, w = image.shape[:2]
    data = vtkImageData()
    data.SetDimensions(w, h, 1)
    # VTK's rows run from the bottom: the texture coordinate t = 1 - v reaches the image's top row at v = 0
    texels = numpy_to_vtk(np.ascontiguousarray(image[::-1].reshape(-1, 4)), deep=True)
    data.GetPointData().SetScalars(texels)
    texture = vtkTexture()
    texture.SetInputData(data)
    texture.SetColorModeToDirectScalars()
    texture.SetRepeat(True)
    texture.SetInterpolate(not nearest)
    texture.SetMipmap(not nearest)
    return texture


def _material_actors(plotter: pv.Plotter, mesh: pv.PolyData, user: UserBody, faces: np.ndarray) -> list:
    """One unlit actor per material of a user's character, its triangles of ``mesh`` (sharing its points and
    colours), textured on the file's UVs where the material has a base colour texture; a single-sided material's
    back faces are not drawn, as a glTF viewer draws them."""
    skin = user.skin
    uvs = np.asarray(skin.uvs, dtype=np.float32)
    tcoords = numpy_to_vtk(np.ascontiguousarray(np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], axis=1)), deep=True)
    which = np.asarray(skin.face_materials)
    textures = {}
    actors = []
    for k, mat in enumerate(user.materials):
        mine = faces[which == k]
        if not len(mine) or mat.mtoon is not None:  # toon-shaded: gesturekit.viz.character_mtoon
            continue
        part = pv.PolyData()
        part.SetPoints(mesh.GetPoints())  # one set of points: posing the mesh poses every part
        cells = np.hstack([np.full((len(mine), 1), 3, dtype=np.int64), mine.astype(np.int64)])
        part.faces = cells.ravel()
        part.GetPointData().SetScalars(mesh.GetPointData().GetScalars())
        actor = plotter.add_mesh(part, scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False)
        actor.prop.interpolation = "gouraud"
        actor.prop.backface_culling = not mat.double_sided
        if mat.image is not None:
            part.GetPointData().SetTCoords(tcoords)
            key = (mat.image, mat.nearest)
            if key not in textures:
                textures[key] = _texture(user.images[mat.image], mat.nearest)
            actor.SetTexture(textures[key])
            # OPAQUE ignores alpha; BLEND is cut at half (the MP4 sorts no transparent layers)
            cutoff = {"MASK": mat.alpha_cutoff, "BLEND": 0.5}.get(mat.alpha_mode, -1.0)
            code = _TEXTURED.format(alpha=f"{float(np.clip(mat.color[3], 0, 1)):.6f}", cutoff=f"{cutoff:.6f}")
            actor.GetShaderProperty().AddFragmentShaderReplacement("//VTK::TCoord::Impl", True, code, False)
        actors.append(actor)
    return actors


#: Pixels from a label's anchor (:meth:`CharacterStage.label_anchor`) up to the label's top, as on the page.
LABEL_RAISE = 16
#: Pixels kept free between a label's top and the picture's top edge.
LABEL_MARGIN = 4


class CharacterDrawing:
    """A stage's characters as VTK meshes in one renderer, unlit, updated frame by frame.

    Parameters
    ----------
    stage : CharacterStage
    plotter : pyvista.Plotter
        An offscreen plotter of one renderer.
    resolution : (int, int)
        Width and height of the picture, pixels.
    labels : sequence of str, optional
        One label per character, drawn above it in its scheme's shirt colour.
    font_size : int
        Points.
    """

    def __init__(
        self,
        stage: CharacterStage,
        plotter: pv.Plotter,
        resolution: tuple[int, int],
        labels: Sequence[str] | None = None,
        font_size: int = 14,
    ):
        self.stage = stage
        self._meshes: list[pv.PolyData] = []
        self._colors = []
        # numpy views of the VTK arrays: a frame is written into them in place
        self._point_views: list[np.ndarray] = []
        self._color_views: list[np.ndarray] = []
        self._shown: list[int] = []  # the characters that have a body
        self._actors: list = []  # the characters' actors: their bodies and legs
        self._mtoon: list[MToonActors | None] = []  # each shown character's toon-shaded materials
        w, h = resolution
        camera = stage.camera(w / h)
        # the stage and the still legs: drawn once, unlit, their colours already shaded
        for flat in stage.stage():
            self._add_still(plotter, flat["vertices"], flat["faces"], flat["colors"])
        for i in range(len(stage.motions)):
            legs = stage.stand(i)
            if legs is not None:
                self._actors.append(self._add_still(plotter, *legs))
        for i, faces in enumerate(stage.faces):
            if not len(faces):
                continue
            self._shown.append(i)
            v = stage.vertices(i, 0)
            cells = np.hstack([np.full((len(faces), 1), 3, dtype=np.int64), faces.astype(np.int64)])
            mesh = pv.PolyData(v.astype(np.float64), cells.ravel())
            rgb = numpy_to_vtk(stage.colors(i, 0), deep=True)
            rgb.SetName("rgb")
            mesh.GetPointData().SetScalars(rgb)
            user = stage.users[i] if stage.users is not None else None
            toon = None
            if user is not None and user.materials:
                self._actors.extend(_material_actors(plotter, mesh, user, faces))
                if any(mat.mtoon is not None for mat in user.materials):
                    toon = MToonActors(plotter, mesh, faces, user, camera)
                    toon.update(v, user.normals(0))
                    self._actors.extend(toon.actors)
            else:
                actor = plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False)
                actor.prop.interpolation = "gouraud"  # colours blend across each triangle, as on the page
                self._actors.append(actor)
            self._mtoon.append(toon)
            self._meshes.append(mesh)
            self._colors.append(rgb)
            self._point_views.append(vtk_to_numpy(mesh.GetPoints().GetData()))
            self._color_views.append(vtk_to_numpy(rgb))
        cam = plotter.renderer.GetActiveCamera()
        cam.SetPosition(*camera["position"])
        cam.SetFocalPoint(*camera["target"])
        cam.SetViewUp(*camera["up"])
        cam.SetViewAngle(camera["fov"])  # VTK's view angle is vertical, like three.js's fov
        distance = float(np.linalg.norm(np.subtract(camera["position"], camera["target"])))
        reach = float(np.linalg.norm(stage.box[1] - stage.box[0]))
        # the floor reaches from under the camera far behind the characters
        cam.SetClippingRange(max(1e-2, 0.02 * distance), distance + 2 * reach + 12.0)
        plotter.renderer.camera_set = True
        self._frame = 0
        if labels is not None:
            self._labels(plotter, labels, resolution, font_size)

    @staticmethod
    def _add_still(plotter: pv.Plotter, vertices: np.ndarray, faces: np.ndarray, colours: np.ndarray) -> object:
        """A mesh that does not move, drawn unlit in its per-vertex sRGB colours."""
        cells = np.hstack([np.full((len(faces), 1), 3, dtype=np.int64), np.asarray(faces, dtype=np.int64)])
        mesh = pv.PolyData(np.asarray(vertices, dtype=np.float64), cells.ravel())
        rgb = numpy_to_vtk(np.ascontiguousarray(colours, dtype=np.uint8), deep=True)
        rgb.SetName("rgb")
        mesh.GetPointData().SetScalars(rgb)
        actor = plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False)
        actor.prop.interpolation = "gouraud"
        return actor

    def set_characters_visible(self, visible: bool) -> None:
        """Show or hide every character (their bodies and legs), leaving the stage."""
        for actor in self._actors:
            actor.SetVisibility(bool(visible))

    def _labels(self, plotter: pv.Plotter, labels: Sequence[str], resolution: tuple[int, int], size: int) -> None:
        w, h = resolution
        renderer = plotter.renderer
        # a picture smaller than 640 x 480 gets smaller labels, so that each fits above its body
        size = max(6, round(size * min(1.0, w / 640, h / 480)))
        for i, text in enumerate(labels):
            if not str(text):
                continue
            renderer.SetWorldPoint(*self.stage.label_anchor(i), 1.0)
            renderer.WorldToDisplay()
            x, y, _ = renderer.GetDisplayPoint()  # pixels from the bottom left
            # the label's top LABEL_RAISE pixels above the anchor, and inside the picture: the text hangs from
            # its position (its glyphs are taller than ``size`` pixels, so placing its foot cut them off)
            top = min(y + LABEL_RAISE, h - LABEL_MARGIN)
            colour = part_colors(self.stage.schemes[i])[PARTS.index("shirt")]
            actor = plotter.add_text(str(text), position=(float(np.clip(x, 0, w)), float(top)), font_size=size)
            actor.GetTextProperty().SetColor(*colour)
            actor.GetTextProperty().SetJustificationToCentered()
            actor.GetTextProperty().SetVerticalJustificationToTop()

    def update(self, frame: int) -> None:
        """Pose every character at ``frame``."""
        if frame == self._frame:
            return
        for k, (i, mesh, rgb) in enumerate(zip(self._shown, self._meshes, self._colors)):
            v = self.stage.vertices(i, frame)
            self._point_views[k][:] = v
            mesh.GetPoints().Modified()
            self._color_views[k][:] = self.stage.colors(i, frame)
            rgb.Modified()
            toon = self._mtoon[k]
            if toon is not None and self.stage.users is not None:
                toon.update(v, self.stage.users[i].normals(frame))
        self._frame = frame
