"""The diffuse albedo of a gprim, from its bound material or its display color.

A mesh bound to a UsdPreviewSurface sends all of that surface's inputs to the
renderer (:mod:`mipray.usd.shading`); the albedo resolved here is what faces
without such a material render with — meshes with only a display color, and
faces of GeomSubsets bound to materials that are not UsdPreviewSurfaces
(:mod:`mipray.usd.face_albedo`). It comes from, in order:

1. the ``diffuseColor`` of the ``UsdPreviewSurface`` that the prim's bound
   material (purpose ``full``, falling back to all-purpose, as Hydra resolves
   it) uses as its surface, when that input is a constant — authored, or
   inherited through a material interface input; unauthored it is the
   shader's own default, 0.18 grey;
2. else ``primvars:displayColor`` when it is constant or has one value;
3. else 0.18 grey.

A ``diffuseColor`` connected to a texture is not a constant: such a subset
falls through to its display color here, and renders its texture through
``face_materials`` (:mod:`mipray.usd.shading`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

from pxr import Usd, UsdGeom, UsdShade

from .shading import bound_material
from .warn import warn_once

__all__ = ["DEFAULT_ALBEDO", "Albedo", "compute_albedo", "display_opacity", "lambertian"]

_log = logging.getLogger(__name__)
_warn_once = warn_once(__name__)


#: Albedo of a prim with neither a usable material nor a display color.
DEFAULT_ALBEDO: tuple[float, float, float] = (0.18, 0.18, 0.18)


def lambertian(
    name: str, rgb: Any, opacity: float = 1.0, *, see_through: bool = False
) -> dict[str, Any]:
    """``set_mesh``'s ``material`` for a diffuse colour alone (a display colour, a face's colour).

    UsdPreviewSurface's specular workflow with no specular: a lambertian surface of linear
    RGB ``rgb``, the one material model expressing what has no material of its own.
    ``name`` names it in messages (the prim's path, ``path[k]`` for a face colour).

    ``opacity`` below 1 (a ``displayOpacity``), or ``see_through`` (an opacity primvar
    shades it), makes it partly transparent as UsdPreviewSurface's ``opacity`` does with
    ``opacityThreshold`` 0: the diffuse weighs ``opacity`` and a pass-through lobe ``1 −
    opacity``, of ``ior`` 1 so that nothing bends or reflects (Storm's blend).
    """
    r, g, b = (float(c) for c in rgb)
    out: dict[str, Any] = {
        "name": name,
        "diffuseColor": (r, g, b),
        "useSpecularWorkflow": True,
        "specularColor": (0.0, 0.0, 0.0),
    }
    if opacity < 1.0 or see_through:
        out["opacity"] = float(opacity)
        out["ior"] = 1.0
    return out


@dataclass(frozen=True)
class Albedo:
    """A resolved albedo and where it came from."""

    #: Linear RGB, each clamped to [0, 1].
    rgb: tuple[float, float, float]
    #: Path of the bound material, if any (the scene delegate re-syncs the
    #: prim when something under this path changes).
    material_path: str | None
    #: Whether the value might change over time (time-sampled input).
    might_vary: bool
    #: "material", "displayColor" or "default".
    source: str


def _rgb(value: object) -> tuple[float, float, float] | None:
    try:
        r, g, b = (float(c) for c in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        return None
    if not all(math.isfinite(c) for c in (r, g, b)):
        return None
    return (min(max(r, 0.0), 1.0), min(max(g, 0.0), 1.0), min(max(b, 0.0), 1.0))


def _preview_surface_diffuse(
    material: UsdShade.Material, time: Usd.TimeCode
) -> tuple[tuple[float, float, float] | None, bool]:
    """``(rgb or None, might_vary)`` of a material's constant PreviewSurface diffuseColor."""
    shader, _, _ = material.ComputeSurfaceSource()
    if not shader or shader.GetShaderId() != "UsdPreviewSurface":
        return None, False
    diffuse = shader.GetInput("diffuseColor")
    if not diffuse:
        return DEFAULT_ALBEDO, False
    producers = diffuse.GetValueProducingAttributes()
    if not producers:
        return DEFAULT_ALBEDO, False
    attr = producers[0]
    if UsdShade.Utils.GetType(attr.GetName()) == UsdShade.AttributeType.Output:
        return None, False  # connected to a texture or another node: not a constant
    value = attr.Get(time)
    if value is None:
        return DEFAULT_ALBEDO, False
    rgb = _rgb(value)
    if rgb is None:
        _log.warning(
            "mipray: %s: diffuseColor %r is not a finite color; using 0.18 grey",
            attr.GetPath(),
            value,
        )
        return DEFAULT_ALBEDO, False
    return rgb, bool(attr.ValueMightBeTimeVarying())


def _display_color(prim: Usd.Prim, time: Usd.TimeCode) -> tuple[float, float, float] | None:
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
    if not primvar or not primvar.HasValue():
        return None
    values = primvar.ComputeFlattened(time)
    if not values:
        return None
    if primvar.GetInterpolation() != UsdGeom.Tokens.constant and len(values) != 1:
        return None
    return _rgb(values[0])


def display_opacity(prim: Usd.Prim, time: Usd.TimeCode) -> float:
    """A gprim's one ``displayOpacity`` (constant, or a single value), clamped; 1 without one.

    A value that is not a finite number is warned about, naming the prim, and read as 1.
    """
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayOpacity")
    if not primvar or not primvar.HasValue():
        return 1.0
    values = primvar.ComputeFlattened(time)
    if not values:
        return 1.0
    if primvar.GetInterpolation() != UsdGeom.Tokens.constant and len(values) != 1:
        _warn_once(
            f"{prim.GetPath()}: primvars:displayOpacity ({primvar.GetInterpolation()}) varies "
            "over the prim, which only meshes apply; rendering it opaque"
        )
        return 1.0
    try:
        value = float(values[0])
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        _warn_once(
            f"{prim.GetPath()}: primvars:displayOpacity {values[0]!r} is not a number; "
            "rendering it opaque"
        )
        return 1.0
    return min(max(value, 0.0), 1.0)


def compute_albedo(prim: Usd.Prim, time: Usd.TimeCode) -> Albedo:
    """Resolve the albedo of ``prim`` at ``time`` (see the module doc for the order)."""
    material = bound_material(prim)
    material_path = str(material.GetPath()) if material else None
    if material:
        rgb, might_vary = _preview_surface_diffuse(material, time)
        if rgb is not None:
            return Albedo(rgb, material_path, might_vary, "material")
    display = _display_color(prim, time)
    if display is not None:
        return Albedo(display, material_path, False, "displayColor")
    return Albedo(DEFAULT_ALBEDO, material_path, False, "default")
