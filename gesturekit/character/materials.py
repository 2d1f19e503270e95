"""A user's character's own materials: the file's materials, textures and images, for the page and the MP4.

The page and the MP4 draw a glTF or VRM character with the materials of its
file, not one colour per vertex. What they need travels as a *materials GLB*
(:func:`materials_glb`): a glTF binary holding only the file's ``materials``,
``textures``, ``samplers`` and ``images`` (and the extensions that describe
them, such as a VRM's MToon), with one more, empty material at the end for
the primitives that name none (glTF's default material). The page reads it
with three.js's ``GLTFLoader``, so every material is what a glTF viewer makes
of it; the MP4 reads the same bytes with :func:`read_materials`.

The mesh refers to it through :attr:`~gesturekit.character.target.CharacterSkin.face_materials`
(each triangle's material) and :attr:`~gesturekit.character.target.CharacterSkin.uvs`
(``TEXCOORD_0``, glTF's convention: the image's top left at (0, 0)).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from .glb import glb_bytes, read_glb
from .mtoon import MToon, file_materials, read_mtoon

__all__ = ["SkinMaterial", "materials_glb", "read_materials", "MAX_TEXTURE_PIXELS"]

#: Most pixels of one texture (4096 x 4096), read from the image's header before it is decoded.
MAX_TEXTURE_PIXELS = 4096 * 4096

#: Extensions a materials GLB keeps from the file: those of materials and textures (the rest describe nodes).
_KEPT_EXTENSIONS = ("VRM", "VRMC_materials_mtoon")

_NEAREST = 9728


@dataclass(frozen=True)
class SkinMaterial:
    """One material as the MP4 draws it.

    Attributes
    ----------
    name : str
    color : tuple of 4 float
        The base colour factor, linear RGBA in [0, 1].
    image : int or None
        The base colour texture's image (an index into :func:`read_materials`' images), or None.
    nearest : bool
        The texture is magnified without interpolation (its sampler's ``magFilter`` is NEAREST).
    alpha_mode : str
        ``"OPAQUE"``, ``"MASK"`` or ``"BLEND"``.
    alpha_cutoff : float
        Under ``"MASK"``, texels of a smaller alpha (times the factor's) are not drawn.
    double_sided : bool
    mtoon : MToon or None
        The material's toon shading (a VRM's MToon, :mod:`gesturekit.character.mtoon`), or None: Lambert.
    shade_image : int or None
        The MToon's shade multiply texture's image, or None.
    shade_nearest : bool
        That texture is magnified without interpolation.
    """

    name: str
    color: tuple[float, float, float, float]
    image: int | None
    nearest: bool
    alpha_mode: str
    alpha_cutoff: float
    double_sided: bool
    mtoon: MToon | None = None
    shade_image: int | None = None
    shade_nearest: bool = False


def _image_header(data: bytes, index: int) -> tuple[int, int]:
    """An image's width and height from its header (not decoded); refused past :data:`MAX_TEXTURE_PIXELS`."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as im:
            size = im.size
    except Exception as e:  # Pillow's own errors: an unknown format, a truncated file
        raise ConfigError(f"image {index} is not a readable PNG or JPEG ({type(e).__name__})") from None
    if size[0] * size[1] > MAX_TEXTURE_PIXELS:
        side = int(MAX_TEXTURE_PIXELS**0.5)
        raise ConfigError(
            f"image {index} is {size[0]} x {size[1]} pixels, more than a character's texture may have "
            f"({side} x {side}); scale it down"
        )
    return size


@checks_arguments
def materials_glb(document: dict[str, Any], binary: bytes) -> bytes:
    """The materials GLB of a glTF document whose images are buffer views of ``binary``.

    Parameters
    ----------
    document : dict
        The file's glTF JSON (images as buffer views of ``binary``, as the reader leaves them).
    binary : bytes
        Its one buffer.

    Returns
    -------
    bytes
        A GLB with the document's materials (and an empty one appended: glTF's default material), textures,
        samplers and images, its images' bytes in its binary chunk, and a scene without nodes.

    Raises
    ------
    ConfigError
        An image past its buffer, unreadable, or larger than :data:`MAX_TEXTURE_PIXELS`; an MToon (VRM 1.0's
        extension, VRM 0.x's material properties) with a colour or number that is not finite.
    """
    # a VRM's MToon is checked here, where the file is read, not first where the MP4 draws it
    for m in file_materials(document):
        read_mtoon(m, len(document.get("textures", [])))
    out = bytearray()
    views: list[dict[str, Any]] = []
    images = []
    for k, img in enumerate(document.get("images", [])):
        view = document["bufferViews"][img["bufferView"]]
        start, length = int(view.get("byteOffset", 0)), int(view["byteLength"])
        if start < 0 or length < 0 or start + length > len(binary):
            raise ConfigError(f"image {k}'s buffer view runs past the {len(binary)} bytes of data")
        data = binary[start : start + length]
        _image_header(data, k)
        out.extend(b"\0" * (-len(out) % 4))
        views.append({"buffer": 0, "byteOffset": len(out), "byteLength": length})
        out.extend(data)
        kept = {key: v for key, v in img.items() if key in ("name", "mimeType")}
        images.append({**kept, "bufferView": len(views) - 1})
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "gesturekit materials"},
        "scene": 0,
        "scenes": [{"nodes": []}],
        "materials": [*document.get("materials", []), {}],
    }
    for key in ("textures", "samplers"):
        if document.get(key):
            doc[key] = document[key]
    if images:
        doc["images"] = images
        doc["bufferViews"] = views
        doc["buffers"] = [{"byteLength": len(out) + (-len(out) % 4)}]
    used = [e for e in document.get("extensionsUsed", []) if e.startswith("KHR_") or e in _KEPT_EXTENSIONS]
    if used:
        doc["extensionsUsed"] = used
    ext = document.get("extensions", {})
    if "VRM" in ext and "materialProperties" in ext["VRM"]:
        # a VRM 0.x keeps its MToon parameters beside the materials, in the document's own extension
        doc["extensions"] = {"VRM": {"materialProperties": ext["VRM"]["materialProperties"]}}
    return glb_bytes(doc, bytes(out))


@checks_arguments
def read_materials(glb: bytes) -> tuple[list[SkinMaterial], list[np.ndarray]]:
    """The materials of a materials GLB (:func:`materials_glb`) and their images.

    Returns
    -------
    materials : list of SkinMaterial
        One per material, the default one last.
    images : list of np.ndarray, shape (height, width, 4), uint8
        Each image's sRGB colour and alpha, its top row first.

    Raises
    ------
    ConfigError
        Not a materials GLB, or an image unreadable or too large.
    """
    from PIL import Image

    doc, binary = read_glb(glb)
    images = []
    for k, img in enumerate(doc.get("images", [])):
        view = doc["bufferViews"][img["bufferView"]]
        start, length = int(view.get("byteOffset", 0)), int(view["byteLength"])
        data = binary[start : start + length]
        _image_header(data, k)
        with Image.open(io.BytesIO(data)) as im:
            images.append(np.asarray(im.convert("RGBA"), dtype=np.uint8))
    textures, samplers = doc.get("textures", []), doc.get("samplers", [])

    def image_of(ref: Any) -> tuple[int | None, bool]:
        """A texture reference's image and whether it is magnified without interpolation."""
        if not isinstance(ref, dict) or not 0 <= int(ref.get("index", -1)) < len(textures):
            return None, False
        texture = textures[int(ref["index"])]
        source = texture.get("source")
        if source is None or not 0 <= int(source) < len(images):
            return None, False
        nearest = False
        if "sampler" in texture and 0 <= int(texture["sampler"]) < len(samplers):
            nearest = samplers[int(texture["sampler"])].get("magFilter") == _NEAREST
        return int(source), nearest

    out = []
    # a VRM 0.x keeps its MToon beside the materials: read as a VRM viewer reads it, as a 1.0 material
    for i, m in enumerate(file_materials(doc)):
        pbr = m.get("pbrMetallicRoughness", {})
        factor = [float(x) for x in pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0))]
        image, nearest = image_of(pbr.get("baseColorTexture"))
        mtoon = read_mtoon(m, len(textures))
        shade_image, shade_nearest = (None, False)
        if mtoon is not None and mtoon.shade_texture is not None:
            shade_image, shade_nearest = image_of({"index": mtoon.shade_texture})
        out.append(
            SkinMaterial(
                name=str(m.get("name", f"material {i}")),
                color=(factor[0], factor[1], factor[2], factor[3]),
                image=image,
                nearest=nearest,
                alpha_mode=str(m.get("alphaMode", "OPAQUE")),
                alpha_cutoff=float(m.get("alphaCutoff", 0.5)),
                double_sided=bool(m.get("doubleSided", False)),
                mtoon=mtoon,
                shade_image=shade_image,
                shade_nearest=shade_nearest,
            )
        )
    return out, images
