"""Lights: ``UsdLux`` distant, sphere, rect, disk, cylinder, dome, mesh and portal lights.

``UsdLux.DistantLight`` goes into ``RenderDelegate.set_distant_light``; the
others into ``RenderDelegate.set_light`` with their shape; a stage with no
light at all is lit from the camera, as usdrecord does by default.

Every ``LightAPI`` input the core needs is read here: ``intensity``,
``exposure``, ``color``, ``normalize``, ``shadow:enable`` and, when
``enableColorTemperature`` is on, ``colorTemperature``, whose blackbody colour
(UsdLux's own ``UsdLuxBlackbodyTemperatureAsRgb``: linear Rec. 709, luminance 1)
multiplies ``color`` before it reaches the core. What the core does with them
(UsdLux's units, ``normalize`` per light family) is documented in
``mipray::light``. A value UsdLux clips (a distant light's ``angle`` outside
[0, 360), a ``colorTemperature`` outside [1000, 10000] K) is clipped with one
warning naming the light; a value nothing sensible can be made of (non-finite,
negative intensity or colour, zero size) is a ``PrimError`` naming the light,
which skips that light only.

``ShapingAPI`` on sphere, rect, disk and cylinder lights (``shaping:cone:angle``,
``cone:softness``, ``focus``, ``focusTint``, and the IES profile ``ies:file``,
``ies:angleScale``, ``ies:normalize``, with the schema's fallbacks once the API is
applied) goes to the core, which applies it as Hydra's hdEmbree does
(``mipray::light::Shaping``, ``mipray::light::IesProfile``); an IES file that cannot be
read or parsed is named in one warning and the light renders without it. Shaping on
distant and dome lights is listed as unsupported. Light and shadow linking
(``collection:lightLink``, ``collection:shadowLink``) are resolved here with usd-core's
``ComputeMembershipQuery`` into the mesh prims each collection leaves out
(``unlit``, ``no_shadow``); the scene delegate re-resolves them whenever the
stage changes. Meshes inside native-instance prototypes are matched by their
prototype path (``/__Prototype_1/...``), which only ``includeRoot`` reaches.

A ``PortalLight`` (:func:`portal_arguments`) is no light: a ``width`` × ``height`` rect that
guides the light sampling of the dome lights (``mipray::light::Portal``: it changes how a dome
is sampled, never what it contributes). A dome whose ``portals`` relationship is authored is
guided by the portals it names; one without, by every portal of the stage.

A Mesh with ``MeshLightAPI``, or named by a ``GeometryLight``'s ``geometry``, is a mesh
light: ``RenderDelegate.set_mesh`` gets ``light`` (:func:`mesh_light_arguments`,
:func:`emitter_arguments`) and the core samples its tessellated limit surface by area. Under
``light:materialSyncMode = materialGlowTintsLight`` (``MeshLightAPI``'s fallback) the bound
material's emission tints the light, each GeomSubset's on its own faces
(:func:`material_tints`); a mesh light inside a prototype
(PointInstancer or native instance) emits from every instance.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade

from ..errors import PrimError
from .warn import warn_once

__all__ = [
    "AREA_LIGHT_TYPES",
    "CAMERA_LIGHT_PATH",
    "LINK_COLLECTIONS",
    "SHAPED_KINDS",
    "SHAPING_INPUTS",
    "area_light_arguments",
    "authored_properties",
    "camera_light_arguments",
    "distant_light_arguments",
    "emitter_arguments",
    "geometry_light_targets",
    "link_arguments",
    "linking_authored",
    "material_tint",
    "material_tints",
    "mesh_light_arguments",
    "portal_arguments",
]

#: The non-distant UsdLux light types mipray renders, and their ``set_light`` kind.
AREA_LIGHT_TYPES: tuple[tuple[type, str], ...] = (
    (UsdLux.SphereLight, "sphere"),
    (UsdLux.RectLight, "rect"),
    (UsdLux.DiskLight, "disk"),
    (UsdLux.CylinderLight, "cylinder"),
    (UsdLux.DomeLight, "dome"),
)
_warn_once = warn_once(__name__)

#: The light kinds ``ShapingAPI`` shapes (as Hydra's hdEmbree: area lights with a position).
SHAPED_KINDS = frozenset({"sphere", "rect", "disk", "cylinder"})
#: The ``ShapingAPI`` inputs mipray reads on those (IES profiles included).
SHAPING_INPUTS = frozenset(
    {
        "shaping:cone:angle",
        "shaping:cone:softness",
        "shaping:focus",
        "shaping:focusTint",
        "shaping:ies:file",
        "shaping:ies:angleScale",
        "shaping:ies:normalize",
    }
)
#: UsdLux's linking collections and the ``set_light`` argument each resolves to: the mesh prims
#: the light does not illuminate, and those that do not block its shadow rays.
LINK_COLLECTIONS = (("lightLink", "unlit"), ("shadowLink", "no_shadow"))

#: Path of the light mipray adds at the camera when a stage has no light.
CAMERA_LIGHT_PATH = "/__mipray_camera_light"


def _color(prim: Usd.Prim, time: Usd.TimeCode) -> tuple[float, float, float]:
    """``inputs:color`` times the blackbody colour of ``inputs:colorTemperature`` when enabled.

    Raises:
        PrimError: a colour or temperature that is not finite, or a negative colour.

    """
    path = str(prim.GetPath())

    def get(name: str, default: Any) -> Any:
        attr = prim.GetAttribute(f"inputs:{name}")
        value = attr.Get(time) if attr else None
        return default if value is None else value

    color = tuple(float(c) for c in get("color", (1.0, 1.0, 1.0)))
    if len(color) != 3 or not all(math.isfinite(c) and c >= 0.0 for c in color):
        raise PrimError(path, f"inputs:color {color} is not a finite non-negative color")
    if not bool(get("enableColorTemperature", False)):
        return (color[0], color[1], color[2])
    kelvin = float(get("colorTemperature", 6500.0))
    if not math.isfinite(kelvin):
        raise PrimError(path, "inputs:colorTemperature is not finite")
    if not 1000.0 <= kelvin <= 10000.0:
        clipped = min(max(kelvin, 1000.0), 10000.0)
        _warn_once(
            f"{path}: inputs:colorTemperature {kelvin:g} K is outside UsdLux's range "
            f"[1000, 10000]; using {clipped:g} K"
        )
        kelvin = clipped
    rgb = blackbody_rgb(kelvin)
    return (color[0] * rgb[0], color[1] * rgb[1], color[2] * rgb[2])


def blackbody_rgb(kelvin: float) -> tuple[float, float, float]:
    """The colour of a blackbody at ``kelvin`` as UsdLux defines it: linear Rec. 709, luminance 1.

    This is ``UsdLux.BlackbodyTemperatureAsRgb``, USD's own definition, so
    every renderer reading the stage gets the same colour.
    """
    rgb = UsdLux.BlackbodyTemperatureAsRgb(float(kelvin))
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))


def distant_light_arguments(
    light: UsdLux.DistantLight, time: Usd.TimeCode, transform: NDArray[np.float64]
) -> dict[str, Any]:
    """The keyword arguments of ``RenderDelegate.set_distant_light`` for ``light``.

    ``inputs:shadow:enable`` is read whether or not ``ShadowAPI`` is applied;
    unauthored, shadows are on (the API's fallback). ``inputs:angle`` is clipped
    to [0, 360) with a warning, as UsdLux says.

    Raises:
        PrimError: a non-finite or negative value, or a non-finite transform.

    """
    path = str(light.GetPath())

    def get(attr: Usd.Attribute, default: Any) -> Any:
        value = attr.Get(time) if attr else None
        return default if value is None else value

    shadow_attr = light.GetPrim().GetAttribute("inputs:shadow:enable")
    color = _color(light.GetPrim(), time)
    args: dict[str, Any] = {
        "transform": transform,
        "intensity": float(get(light.GetIntensityAttr(), 50000.0)),
        "exposure": float(get(light.GetExposureAttr(), 0.0)),
        "color": color,
        "angle": float(get(light.GetAngleAttr(), 0.53)),
        "normalize": bool(get(light.GetNormalizeAttr(), False)),
        "shadow_enable": bool(get(shadow_attr, True)),
    }
    for key in ("intensity", "exposure", "angle"):
        if not math.isfinite(args[key]):
            raise PrimError(path, f"inputs:{key} is not finite")
    if args["intensity"] < 0.0:
        raise PrimError(path, f"inputs:intensity is {args['intensity']}; it must be >= 0")
    if not (0.0 <= args["angle"] < 360.0):
        clipped = min(max(args["angle"], 0.0), 359.999)
        _warn_once(
            f"{path}: inputs:angle {args['angle']:g} is outside UsdLux's [0, 360) degrees; "
            f"using {clipped:g}"
        )
        args["angle"] = clipped
    if not np.isfinite(transform).all():
        raise PrimError(path, "the world transform is not finite")
    return args


def camera_light_arguments(camera_transform: NDArray[np.float64]) -> dict[str, Any]:
    """A shadowless distant light shining along the camera's view direction.

    A distant light at the camera's transform shines down the camera's -Z
    axis. Normalized, its intensity is the irradiance it delivers: π, so that,
    with a Lambertian BRDF (albedo / π), a surface facing the camera has
    radiance equal to its albedo, as the fixed-function headlight of
    usdrecord's default renderer shows it.
    """
    return {
        "transform": camera_transform,
        "intensity": math.pi,
        "exposure": 0.0,
        "color": (1.0, 1.0, 1.0),
        "angle": 0.53,
        "normalize": True,
        "shadow_enable": False,
    }


def area_light_arguments(
    prim: Usd.Prim, time: Usd.TimeCode, transform: NDArray[np.float64]
) -> dict[str, Any] | None:
    """``RenderDelegate.set_light`` keyword arguments for an area or dome light.

    Returns None when ``prim`` is none of those. Sizes are UsdLux's (``radius``,
    ``width``, ``height``, ``length``, in the light's units; a cylinder lies along
    its local X and has no end caps). A dome light's texture is
    read through OpenImageIO as a latlong environment (``texture`` argument;
    a ``texture:format`` other than ``automatic`` or ``latlong`` is read as a
    latlong, with one warning). A rect light's texture multiplies its colour
    over the rect (``s`` along its +X, ``t`` along its +Y). A sphere's
    ``treatAsPoint`` is a hint that renderers of area lights may disregard
    (UsdLux): it stays a sphere.

    Raises:
        PrimError: a non-finite, negative or zero value, or a non-finite transform.

    """
    kind = next((k for t, k in AREA_LIGHT_TYPES if prim.IsA(t)), None)
    if kind is None:
        return None
    path = str(prim.GetPath())

    def get(name: str, default: Any) -> Any:
        attr = prim.GetAttribute(f"inputs:{name}")
        value = attr.Get(time) if attr else None
        return default if value is None else value

    color = _color(prim, time)
    args: dict[str, Any] = {
        "kind": kind,
        "transform": transform,
        "intensity": float(get("intensity", 1.0)),
        "exposure": float(get("exposure", 0.0)),
        "color": color,
        "normalize": bool(get("normalize", False)),
        "shadow_enable": bool(get("shadow:enable", True)),
    }
    if kind in SHAPED_KINDS and prim.HasAPI(UsdLux.ShapingAPI):
        # The schema's fallbacks (a 90° cone) apply once the API is applied.
        shaping = UsdLux.ShapingAPI(prim)
        args["cone_angle"] = float(shaping.GetShapingConeAngleAttr().Get(time))
        args["cone_softness"] = float(shaping.GetShapingConeSoftnessAttr().Get(time))
        args["focus"] = float(shaping.GetShapingFocusAttr().Get(time))
        tint = tuple(float(c) for c in shaping.GetShapingFocusTintAttr().Get(time))
        args["focus_tint"] = (tint[0], tint[1], tint[2])
        for key in ("cone_angle", "cone_softness", "focus", "focus_tint"):
            if not np.isfinite(args[key]).all():
                raise PrimError(path, f"inputs:shaping {key} {args[key]} is not finite")
        ies = shaping.GetShapingIesFileAttr()
        ies_file = ies.Get(time) if ies else None
        if isinstance(ies_file, Sdf.AssetPath) and ies_file.path:
            from .shading import _resolve

            args["ies_file"] = _resolve(ies, ies_file)
            args["ies_angle_scale"] = float(shaping.GetShapingIesAngleScaleAttr().Get(time))
            args["ies_normalize"] = bool(shaping.GetShapingIesNormalizeAttr().Get(time))
            # A tilt table is read at the light's aim's angle from the stage's down.
            z_up = UsdGeom.GetStageUpAxis(prim.GetStage()) == UsdGeom.Tokens.z
            args["ies_down"] = (0.0, 0.0, -1.0) if z_up else (0.0, -1.0, 0.0)
            # Opt-in: directions drawn by the profile (less noise a sample, more time).
            sampling = prim.GetAttribute("mipray:iesProfileSampling")
            if sampling and sampling.HasAuthoredValue() and sampling.Get(time):
                args["ies_profile_sampling"] = True
            if not math.isfinite(args["ies_angle_scale"]):
                raise PrimError(path, "inputs:shaping:ies:angleScale is not finite")
        if not 0.0 <= args["cone_softness"] <= 1.0 or args["focus"] < 0.0:
            _warn_once(
                f"{path}: inputs:shaping:cone:softness {args['cone_softness']:g} is clipped to "
                f"[0, 1] and inputs:shaping:focus {args['focus']:g} to >= 0"
            )
    if kind in ("sphere", "disk", "cylinder"):
        args["radius"] = float(get("radius", 0.5))
    if kind == "cylinder":
        args["length"] = float(get("length", 1.0))
    if kind == "rect":
        args["width"] = float(get("width", 1.0))
        args["height"] = float(get("height", 1.0))
    if kind in ("rect", "dome"):
        from .shading import _resolve

        attr = prim.GetAttribute("inputs:texture:file")
        value: object = attr.Get(time) if attr else None
        if isinstance(value, Sdf.AssetPath) and value.path:
            args["texture"] = _resolve(attr, value)
        elif isinstance(value, str) and value:
            args["texture"] = value
        if kind == "dome":
            rel = prim.GetRelationship("portals")
            if rel and rel.HasAuthoredTargets():
                args["portals"] = [str(t) for t in rel.GetForwardedTargets()]
        if "texture" in args and kind == "dome":
            layout = str(get("texture:format", "automatic"))
            if layout not in ("automatic", "latlong"):
                _warn_once(
                    f"{path}: dome texture:format '{layout}' is not supported; "
                    "reading the texture as a latlong map"
                )
    for key in ("intensity", "exposure", "radius", "width", "height", "length"):
        if key in args and not math.isfinite(args[key]):
            raise PrimError(path, f"inputs:{key} is not finite")
    for key in ("radius", "width", "height", "length"):
        if key in args and args[key] <= 0.0:
            raise PrimError(path, f"inputs:{key} is {args[key]}; it must be > 0")
    if args["intensity"] < 0.0:
        raise PrimError(path, f"inputs:intensity is {args['intensity']}; it must be >= 0")
    if not np.isfinite(transform).all():
        raise PrimError(path, "the world transform is not finite")
    return args


def portal_arguments(
    prim: Usd.Prim, time: Usd.TimeCode, transform: NDArray[np.float64]
) -> dict[str, Any]:
    """``RenderDelegate.set_light`` keyword arguments for a ``UsdLux.PortalLight``.

    Its ``width`` and ``height`` (fallback 1) in the light's units, passing light along its
    local -Z; its ``LightAPI`` inputs are not read (:mod:`mipray.usd.unsupported` lists them).

    Raises:
        PrimError: a non-finite or non-positive size, or a non-finite transform.

    """
    path = str(prim.GetPath())
    args: dict[str, Any] = {"kind": "portal", "transform": transform}
    for key in ("width", "height"):
        attr = prim.GetAttribute(f"inputs:{key}")
        value = attr.Get(time) if attr else None
        args[key] = 1.0 if value is None else float(value)
        if not (math.isfinite(args[key]) and args[key] > 0.0):
            raise PrimError(path, f"inputs:{key} is {args[key]}; it must be finite and > 0")
    if not np.isfinite(transform).all():
        raise PrimError(path, "the world transform is not finite")
    return args


def mesh_light_arguments(prim: Usd.Prim, time: Usd.TimeCode) -> dict[str, Any] | None:
    """``RenderDelegate.set_mesh``'s ``light`` for a Mesh with ``MeshLightAPI``; None otherwise.

    The mesh then is a light, not a surface: its limit surface, tessellated for lighting,
    emits ``color * intensity * 2**exposure`` as radiance from its front faces (both sides
    when ``doubleSided``), divided by its area with ``normalize`` (UsdLux's ``LightAPI``
    inputs and fallbacks; ``colorTemperature`` as for every light). Its bound material is not
    rendered as a surface; whether its emission tints the light is :func:`material_tint`'s.

    Raises:
        PrimError: a non-finite or negative value.

    """
    if not (prim.IsA(UsdGeom.Mesh) and prim.HasAPI(UsdLux.MeshLightAPI)):
        return None
    return emitter_arguments(prim, time)


def geometry_light_targets(light: Usd.Prim) -> list[str]:
    """The Mesh prims a ``UsdLux.GeometryLight``'s ``geometry`` relationship names.

    Each becomes a mesh light with the GeometryLight's inputs
    (:func:`emitter_arguments` of the light prim), as with ``MeshLightAPI``; its own
    transform places it (the GeometryLight's is not read). A target that is not a Mesh is
    skipped with one warning naming both.
    """
    rel = UsdLux.GeometryLight(light).GetGeometryRel()
    out = []
    for target in rel.GetForwardedTargets() if rel else []:
        prim = light.GetStage().GetPrimAtPath(target)
        if prim and prim.IsA(UsdGeom.Mesh):
            out.append(str(target))
        else:
            _warn_once(
                f"{light.GetPath()}: geometry target {target} is not a Mesh; it does not emit"
            )
    return out


def emitter_arguments(prim: Usd.Prim, time: Usd.TimeCode) -> dict[str, Any]:
    """The ``LightAPI`` inputs of a mesh light as ``set_mesh``'s ``light`` takes them.

    ``prim`` is the Mesh with ``MeshLightAPI`` or the ``GeometryLight`` naming it.

    Raises:
        PrimError: a non-finite or negative value.

    """
    path = str(prim.GetPath())
    light = UsdLux.LightAPI(prim)

    def get(attr: Usd.Attribute, default: Any) -> Any:
        value = attr.Get(time) if attr else None
        return default if value is None else value

    args: dict[str, Any] = {
        "intensity": float(get(light.GetIntensityAttr(), 1.0)),
        "exposure": float(get(light.GetExposureAttr(), 0.0)),
        "color": _color(prim, time),
        "normalize": bool(get(light.GetNormalizeAttr(), False)),
        "shadow_enable": bool(get(prim.GetAttribute("inputs:shadow:enable"), True)),
    }
    for key in ("intensity", "exposure"):
        if not math.isfinite(args[key]):
            raise PrimError(path, f"inputs:{key} is not finite")
    if args["intensity"] < 0.0:
        raise PrimError(path, f"inputs:intensity is {args['intensity']}; it must be >= 0")
    return args


def material_tint(
    prim: Usd.Prim, light_prim: Usd.Prim, material: dict[str, Any] | None, time: Usd.TimeCode
) -> bool:
    """Whether mesh light ``prim``'s bound material tints its light (``set_mesh``'s ``tint``).

    UsdLux's ``light:materialSyncMode`` (read on ``light_prim``: the mesh itself with
    ``MeshLightAPI``, whose fallback is ``materialGlowTintsLight``; a ``GeometryLight``, whose
    fallback is ``noMaterialResponse``): with ``materialGlowTintsLight`` the light's colour is
    multiplied by "the color feeding the emission/glow input of the Material", which for a
    UsdPreviewSurface (or a MaterialX surface mapped onto one) is ``emissiveColor`` — black
    when unauthored, so such a light emits nothing (the core warns). With ``independent`` or
    ``noMaterialResponse``, or no bound material ("as if there is no Material bound"), the
    light's own inputs alone. ``material`` is the ``set_mesh`` ``material`` argument read for
    the mesh: a bound material mipray does not read (no UsdPreviewSurface) cannot tint, with
    one warning naming both. The mesh's own material tints the faces no GeomSubset binds
    (:func:`material_tints` for the subsets'); a textured ``emissiveColor`` tints each point
    by its texture at the point's ``st``.
    """
    attr = UsdLux.LightAPI(light_prim).GetMaterialSyncModeAttr()
    mode = attr.Get(time) if attr else None
    if str(mode) != "materialGlowTintsLight":
        return False
    from .shading import bound_material

    bound = bound_material(prim)
    if bound is None:
        return False
    path, bound_path = str(prim.GetPath()), str(bound.GetPath())
    if material is None or material.get("name") != bound_path:
        _warn_once(
            f"{path}: mesh light's material {bound_path} has no surface mipray reads; "
            "its emission does not tint the light"
        )
        return False
    return True


def material_tints(
    prim: Usd.Prim, light_prim: Usd.Prim, args: dict[str, Any], time: Usd.TimeCode
) -> dict[str, Any]:
    """``set_mesh``'s ``light`` keys ``tint`` and ``tint_materials`` for mesh light ``prim``.

    ``tint`` is :func:`material_tint`'s (the mesh's own material tints the faces no
    GeomSubset binds). Under ``materialGlowTintsLight`` each materialBind GeomSubset's
    material tints its own faces by its ``emissiveColor`` (constant or textured, read per
    point): ``tint_materials`` names those among ``args["face_materials"]`` (the subsets'
    networks mipray reads). A subset's material mipray cannot read does not tint its faces,
    with one warning naming both. ``args`` is the ``set_mesh`` keyword arguments read for
    the mesh.
    """
    out: dict[str, Any] = {"tint": material_tint(prim, light_prim, args.get("material"), time)}
    attr = UsdLux.LightAPI(light_prim).GetMaterialSyncModeAttr()
    mode = attr.Get(time) if attr else None
    if str(mode) != "materialGlowTintsLight":
        return out
    from .shading import bound_material

    read = {m.get("name") for m in args.get("face_materials") or []}
    own = (args.get("material") or {}).get("name")
    names: list[str] = []
    for subset in UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets():
        material = bound_material(subset.GetPrim())
        if material is None:
            continue
        key = str(material.GetPath())
        if key == own:
            continue  # the mesh's own material: its faces take it (``tint``)
        if key in read:
            if key not in names:
                names.append(key)
        else:
            _warn_once(
                f"{prim.GetPath()}: GeomSubset {subset.GetPath()}'s material {key} has no "
                "surface mipray reads; its emission does not tint the mesh light's faces"
            )
    if names:
        out["tint_materials"] = names
    return out


def authored_properties(prim: Usd.Prim, names: Iterable[str]) -> list[str]:
    """The names among ``names`` whose attribute or relationship ``prim`` authors."""
    found = []
    for name in names:
        prop = prim.GetProperty(name)
        if isinstance(prop, Usd.Attribute) and prop.HasAuthoredValue():
            found.append(name)
        elif isinstance(prop, Usd.Relationship) and prop.HasAuthoredTargets():
            found.append(name)
    return found


def linking_authored(prim: Usd.Prim, collection: str, time: Usd.TimeCode) -> list[str]:
    """What a light's ``collection:<collection>`` authors that limits it (empty: it holds all).

    UsdLux's linking collections default to ``includeRoot`` true: a light reaches everything.
    """
    names = [f"collection:{collection}:{n}" for n in ("includes", "excludes")]
    names.append(f"collection:{collection}:membershipExpression")
    found = authored_properties(prim, names)
    root = prim.GetAttribute(f"collection:{collection}:includeRoot")
    if root and root.HasAuthoredValue() and not root.Get(time):
        found.append(root.GetName())
    return found


def link_arguments(
    prim: Usd.Prim, time: Usd.TimeCode, mesh_paths: Callable[[], Iterable[str]]
) -> dict[str, list[str]]:
    """``set_light``'s ``unlit`` and ``no_shadow``: the mesh prims a light's linking leaves out.

    Membership is usd-core's (``Usd.CollectionAPI.ComputeMembershipQuery``: includes,
    excludes, ``includeRoot``, expansion rules and membership expressions), asked of every
    path ``mesh_paths()`` gives (called only when the light links anything).
    """
    args: dict[str, list[str]] = {}
    paths: list[str] | None = None
    for collection, key in LINK_COLLECTIONS:
        if not linking_authored(prim, collection, time):
            continue
        if paths is None:
            paths = list(mesh_paths())
        query = Usd.CollectionAPI(prim, collection).ComputeMembershipQuery()
        args[key] = [p for p in paths if not query.IsPathIncluded(Sdf.Path(p))]
    return args
