"""A VRM's toon shading (MToon): its parameters read from the file, and the rule that shades with them.

A VRM 1.0 material carries its MToon in the ``VRMC_materials_mtoon`` extension;
a VRM 0.x keeps it beside the materials, in the ``VRM`` extension's
``materialProperties`` (the shader ``VRM/MToon``, or ``VRM/Unlit*``), in Unity's
property names and sRGB colours. :func:`from_vrm0` turns a 0.x material into
the 1.0 form as three-vrm reads it (its colours to linear light by a 2.2 power,
its shading shift and toony remapped, its outline width from centimetres to
metres), so that the page (three-vrm's ``MToonMaterial``) and the MP4 read the
same parameters (:func:`read_mtoon`).

The rule (:func:`mtoon_shade`), in linear light, for a surface of lit colour
``c`` (the base colour factor times its texture) and shade colour ``s`` (the
shade factor times its texture), unit normal ``n``, under the look's lights
(:data:`gesturekit.character.look.LIGHTS`, each a direction ``l_i`` and a
strength ``k_i``) and ambient light ``a``::

    t_i = clamp((n . l_i + shift + 1 - toony) / (2 - 2 toony), 0, 1)
    colour = sum_i k_i (s + t_i (c - s)) + a c + emissive

that is, each light mixes the shade colour into the lit one by a step ``toony``
sharp, centred where ``n . l_i = -shift``: a light behind the surface leaves it
in its shade colour, not black. Where the material has an outline, the surface
is drawn once more on its back faces with its vertices pushed out along their
normals by the outline's width (in metres, or with ``"screenCoordinates"`` as a
share of half the picture's height at the vertex's depth), in the outline colour
times ``1 + m (colour - 1)`` for the lighting mix ``m``.

What is drawn: the lit and shade colours and textures, shading shift and toony,
the parametric rim, emission (factor) and outlines. The page draws the rest of
MToon too (matcap, the shading shift texture, UV animation); the MP4 leaves
them out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .._arguments import checks_arguments
from ..errors import ConfigError

__all__ = ["EXTENSION", "OUTLINE_MODES", "MToon", "from_vrm0", "read_mtoon", "mtoon_shade", "outline_color"]

#: The glTF extension of a VRM 1.0 material's MToon.
EXTENSION = "VRMC_materials_mtoon"

#: How an outline's width is measured: none, metres, or a share of half the picture's height at the vertex.
OUTLINE_MODES = ("none", "worldCoordinates", "screenCoordinates")

_SPEC_VERSIONS = ("1.0", "1.0-beta")


@dataclass(frozen=True)
class MToon:
    """One material's MToon parameters, as the MP4 draws them (colours linear, in [0, 1]).

    Attributes
    ----------
    shade_color : tuple of 3 float
        The shade colour factor.
    shade_texture : int or None
        The shade multiply texture (an index into the file's ``textures``), or None.
    shading_shift, shading_toony : float
        Where the lit colour turns into the shade colour (``n . l = -shading_shift``) and how sharply (1: a
        hard edge, 0: across the whole sphere).
    rim_color : tuple of 3 float
        The parametric rim's colour (black: no rim).
    rim_fresnel_power, rim_lift, rim_lighting_mix : float
    emissive : tuple of 3 float
        The material's emissive factor.
    outline_mode : str
        One of :data:`OUTLINE_MODES`.
    outline_width : float
        Metres (``"worldCoordinates"``) or a share of half the picture's height (``"screenCoordinates"``).
    outline_color : tuple of 3 float
    outline_lighting_mix : float
        0: the outline in its colour alone; 1: its colour times the surface's shading.
    """

    shade_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shade_texture: int | None = None
    shading_shift: float = 0.0
    shading_toony: float = 0.9
    rim_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rim_fresnel_power: float = 5.0
    rim_lift: float = 0.0
    rim_lighting_mix: float = 1.0
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)
    outline_mode: str = "none"
    outline_width: float = 0.0
    outline_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    outline_lighting_mix: float = 1.0

    @property
    def outlined(self) -> bool:
        """Whether the material has an outline (a mode other than ``"none"`` and a width over 0)."""
        return self.outline_mode != "none" and self.outline_width > 0


def _numbers(value: Any, n: int, where: str) -> list[float]:
    """The first ``n`` of a list of finite numbers, or a ConfigError naming ``where``."""
    try:
        v = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"{where} is not a list of numbers: {value!r}") from None
    if v.size < n or not np.isfinite(v[:n]).all():
        raise ConfigError(f"{where} is not {n} finite numbers: {value!r}")
    return [float(x) for x in v[:n]]


def _gamma(value: Any, n: int, where: str) -> list[float]:
    """A VRM 0.x colour (Unity's gamma space) in linear light, as three-vrm reads it: each value ``** 2.2``."""
    return [max(x, 0.0) ** 2.2 for x in _numbers(value, n, where)]


def _number_of(table: dict[str, Any], key: str, label: str) -> float:
    """``table[key]`` as a finite number, or a ConfigError naming ``label``'s ``key``."""
    return _numbers(table[key], 1, f"{label}'s {key}")[0]


@checks_arguments
def from_vrm0(properties: dict[str, Any], material: dict[str, Any]) -> dict[str, Any]:
    """A VRM 0.x material as three-vrm reads it: the glTF material with its MToon as :data:`EXTENSION`.

    Parameters
    ----------
    properties : dict
        The material's entry of the ``VRM`` extension's ``materialProperties`` (``shader``, ``floatProperties``,
        ``vectorProperties``, ``textureProperties``, ``keywordMap``).
    material : dict
        The glTF material of the same index.

    Returns
    -------
    dict
        A glTF material: for ``VRM/MToon`` and ``VRM/Unlit*``, the base colour, textures, alpha mode and sides
        of the properties and their MToon; for any other shader (``VRM_USE_GLTFSHADER``), ``material`` itself.
    """
    shader = str(properties.get("shader", ""))
    label = f"the VRM 0.x material {properties.get('name', material.get('name', ''))!r}"
    floats = properties.get("floatProperties") or {}
    vectors = properties.get("vectorProperties") or {}
    textures = properties.get("textureProperties") or {}
    keywords = properties.get("keywordMap") or {}
    if not all(isinstance(x, dict) for x in (floats, vectors, textures, keywords)):
        raise ConfigError(f"{label}'s properties are not tables of names")

    def number(key: str, default: float) -> float:
        return _numbers(floats.get(key, default), 1, f"{label}'s {key}")[0]

    def colour(key: str, default: Sequence[float], n: int = 3) -> list[float]:
        return _gamma(vectors.get(key, default), n, f"{label}'s {key}")

    if shader == "VRM/MToon":
        transparent = bool(keywords.get("_ALPHABLEND_ON", False))
        cutout = bool(keywords.get("_ALPHATEST_ON", False))
        alpha = _numbers(vectors.get("_Color", (1.0, 1.0, 1.0, 1.0)), 4, f"{label}'s _Color")[3]
        shift, toony = number("_ShadeShift", 0.0), number("_ShadeToony", 0.9)
        toony = toony + (1.0 - toony) * (0.5 + 0.5 * shift)  # three-vrm's remapping of the 0.x pair
        shift = -shift - (1.0 - toony)
        k = int(number("_OutlineWidthMode", 0.0))
        mode = OUTLINE_MODES[k] if 0 <= k < len(OUTLINE_MODES) else "none"
        mixed = int(number("_OutlineColorMode", 0.0)) == 1
        ext: dict[str, Any] = {
            "specVersion": "1.0",
            "shadeColorFactor": colour("_ShadeColor", (0.97, 0.81, 0.86, 1.0)),
            "shadingShiftFactor": shift,
            "shadingToonyFactor": toony,
            "parametricRimColorFactor": colour("_RimColor", (0.0, 0.0, 0.0, 1.0)),
            "parametricRimFresnelPowerFactor": number("_RimFresnelPower", 1.0),
            "parametricRimLiftFactor": number("_RimLift", 0.0),
            "rimLightingMixFactor": number("_RimLightingMix", 0.0),
            "outlineWidthMode": mode,
            "outlineWidthFactor": 0.01 * number("_OutlineWidth", 0.0),
            "outlineColorFactor": colour("_OutlineColor", (0.0, 0.0, 0.0)),
            "outlineLightingMixFactor": number("_OutlineLightingMix", 1.0) if mixed else 0.0,
        }
        if "_ShadeTexture" in textures:
            ext["shadeMultiplyTexture"] = {"index": int(_number_of(textures, "_ShadeTexture", label))}
        out: dict[str, Any] = {
            "pbrMetallicRoughness": {"baseColorFactor": [*colour("_Color", (1.0, 1.0, 1.0, 1.0)), alpha]},
            "emissiveFactor": colour("_EmissionColor", (0.0, 0.0, 0.0, 1.0)),
            "alphaMode": "BLEND" if transparent else "MASK" if cutout else "OPAQUE",
            "doubleSided": int(number("_CullMode", 2.0)) == 0,
            "extensions": {EXTENSION: ext},
        }
        if cutout:
            out["alphaCutoff"] = number("_Cutoff", 0.5)
    elif shader.startswith("VRM/Unlit"):
        color = colour("_Color", (1.0, 1.0, 1.0, 1.0), 4)
        ext = {"specVersion": "1.0", "shadeColorFactor": color[:3]}
        out = {
            "pbrMetallicRoughness": {"baseColorFactor": color},
            "alphaMode": "BLEND" if "Transparent" in shader else "MASK" if shader == "VRM/UnlitCutout" else "OPAQUE",
            "extensions": {EXTENSION: ext},
        }
        if shader == "VRM/UnlitCutout":
            out["alphaCutoff"] = number("_Cutoff", 0.5)
    else:
        return material
    if "_MainTex" in textures:
        main = int(_number_of(textures, "_MainTex", label))
        out["pbrMetallicRoughness"]["baseColorTexture"] = {"index": main}
        if shader.startswith("VRM/Unlit"):
            out["extensions"][EXTENSION]["shadeMultiplyTexture"] = {"index": main}
    if "name" in material:
        out["name"] = material["name"]
    return out


@checks_arguments
def file_materials(document: dict[str, Any]) -> list[dict[str, Any]]:
    """The glTF materials of a document as a VRM viewer reads them: a VRM 0.x's turned into the 1.0 form by
    :func:`from_vrm0` where its ``VRM`` extension has material properties for them, every other one as it is."""
    vrm = (document.get("extensions") or {}).get("VRM")
    v0 = vrm.get("materialProperties") if isinstance(vrm, dict) else None
    v0 = v0 if isinstance(v0, list) else []
    return [
        from_vrm0(v0[i], m) if i < len(v0) and isinstance(v0[i], dict) else m
        for i, m in enumerate(document.get("materials", []))
    ]


def _color(value: Any, default: tuple[float, float, float], where: str) -> tuple[float, float, float]:
    if value is None:
        return default
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.size < 3 or not np.isfinite(v[:3]).all():
        raise ConfigError(f"{where} is not a colour of three finite numbers: {value!r}")
    return (float(v[0]), float(v[1]), float(v[2]))


def _number(value: Any, default: float, where: str) -> float:
    if value is None:
        return default
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{where} is not a number: {value!r}") from None
    if not np.isfinite(x):
        raise ConfigError(f"{where} is not finite: {value!r}")
    return x


@checks_arguments
def read_mtoon(material: dict[str, Any], n_textures: int = 0) -> MToon | None:
    """A glTF material's MToon (:data:`EXTENSION`), or None where it has none (or one of an unknown version).

    Parameters
    ----------
    material : dict
        A glTF material (a VRM 0.x one through :func:`from_vrm0` first).
    n_textures : int
        How many textures the file has: a texture index outside them is left out, as three.js leaves it.

    Raises
    ------
    ConfigError
        A colour or number that is not finite, or an unknown outline mode.
    """
    ext = (material.get("extensions") or {}).get(EXTENSION)
    if not isinstance(ext, dict) or str(ext.get("specVersion")) not in _SPEC_VERSIONS:
        return None
    name = material.get("name", "a material")
    mode = str(ext.get("outlineWidthMode", "none"))
    if mode not in OUTLINE_MODES:
        raise ConfigError(f"{name}'s outline width mode is {mode!r}, not one of {', '.join(OUTLINE_MODES)}")
    shade_texture = None
    ref = ext.get("shadeMultiplyTexture")
    if isinstance(ref, dict) and "index" in ref:
        index = _numbers(ref["index"], 1, f"{name}'s shade multiply texture")[0]
        shade_texture = int(index) if 0 <= index < n_textures else None
    return MToon(
        shade_color=_color(ext.get("shadeColorFactor"), (0.0, 0.0, 0.0), f"{name}'s shade colour"),
        shade_texture=shade_texture,
        shading_shift=_number(ext.get("shadingShiftFactor"), 0.0, f"{name}'s shading shift"),
        shading_toony=_number(ext.get("shadingToonyFactor"), 0.9, f"{name}'s shading toony"),
        rim_color=_color(ext.get("parametricRimColorFactor"), (0.0, 0.0, 0.0), f"{name}'s rim colour"),
        rim_fresnel_power=_number(ext.get("parametricRimFresnelPowerFactor"), 5.0, f"{name}'s rim power"),
        rim_lift=_number(ext.get("parametricRimLiftFactor"), 0.0, f"{name}'s rim lift"),
        rim_lighting_mix=_number(ext.get("rimLightingMixFactor"), 1.0, f"{name}'s rim lighting mix"),
        emissive=_color(material.get("emissiveFactor"), (0.0, 0.0, 0.0), f"{name}'s emissive factor"),
        outline_mode=mode,
        outline_width=_number(ext.get("outlineWidthFactor"), 0.0, f"{name}'s outline width"),
        outline_color=_color(ext.get("outlineColorFactor"), (0.0, 0.0, 0.0), f"{name}'s outline colour"),
        outline_lighting_mix=_number(ext.get("outlineLightingMixFactor"), 1.0, f"{name}'s outline lighting mix"),
    )


@checks_arguments
def mtoon_shade(
    normals: npt.ArrayLike,
    lit: npt.ArrayLike,
    shade: npt.ArrayLike,
    mtoon: MToon,
    *,
    view: npt.ArrayLike | None = None,
    lights: Sequence[tuple[Sequence[float], float]] | None = None,
    ambient: float | None = None,
) -> np.ndarray:
    """The MToon rule (the module's formula) at each point: the plain reference the MP4's shader is tested on.

    Parameters
    ----------
    normals : array_like, shape (N, 3)
        Unit normals, in the world.
    lit, shade : array_like, shape (N, 3)
        The lit and shade colours, linear light (factor times texel).
    mtoon : MToon
    view : array_like, shape (N, 3), optional
        Unit directions from each point towards the camera (for the rim); without them, no rim.
    lights : sequence of (direction, strength), optional
        Default :data:`gesturekit.character.look.LIGHTS`.
    ambient : float, optional
        Default :data:`gesturekit.character.look.AMBIENT`.

    Returns
    -------
    np.ndarray, shape (N, 3), float64
        Linear light, not clipped.
    """
    from .look import AMBIENT, LIGHTS

    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(lit, dtype=np.float64).reshape(-1, 3)
    s = np.asarray(shade, dtype=np.float64).reshape(-1, 3)
    lights = LIGHTS if lights is None else lights
    a = AMBIENT if ambient is None else float(ambient)
    toony = mtoon.shading_toony
    out = a * c
    for direction, strength in lights:
        d = np.asarray(direction, dtype=np.float64)
        dot = np.clip(n @ (d / np.linalg.norm(d)), -1.0, 1.0) + mtoon.shading_shift
        lo, hi = -1.0 + toony, 1.0 - toony
        t = np.clip((dot - lo) / (hi - lo), 0.0, 1.0) if hi != lo else (dot >= lo).astype(np.float64)
        out = out + float(strength) * (s + t[:, None] * (c - s))
    if view is not None and any(mtoon.rim_color):
        v = np.asarray(view, dtype=np.float64).reshape(-1, 3)
        light = a + sum(float(k) for _, k in lights)
        rim_mix = 1.0 + mtoon.rim_lighting_mix * (light - 1.0)
        edge = np.clip(1.0 - np.einsum("ij,ij->i", v, n) + mtoon.rim_lift, 0.0, 1.0) ** mtoon.rim_fresnel_power
        out = out + rim_mix * edge[:, None] * np.asarray(mtoon.rim_color)
    return out + np.asarray(mtoon.emissive)


@checks_arguments
def outline_color(surface: npt.ArrayLike, mtoon: MToon) -> np.ndarray:
    """The outline's colour over a surface shaded ``surface`` (linear, shape (N, 3)): the outline colour times
    ``1 + mix (surface - 1)``, linear light, shape (N, 3)."""
    col = np.asarray(surface, dtype=np.float64).reshape(-1, 3)
    return np.asarray(mtoon.outline_color) * (1.0 + mtoon.outline_lighting_mix * (col - 1.0))
