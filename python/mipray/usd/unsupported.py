"""What the USD front end does not consume: one table, and the audit that applies it.

Every authored thing on a stage that changes the picture in USD but that mipray
ignores is listed, so a user can see what the image lacks: the stats'
``unsupported`` list holds one ``{"prim", "what"}`` per prim and thing, and one
warning per thing names its prims (the first few, and how many).

:data:`RENDERED_TYPES` says which prim types the scene delegate syncs (it reads
this tuple): any other gprim or light is a ``prim type`` entry. :data:`TABLE`
has one row per other thing the front end does not use (an applied API
schema, an input, a relationship, a material output, a render var). Adding
support for one means removing its row (or adding the type to
:data:`RENDERED_TYPES`); the test that authors one of each
(``tests/test_unsupported.py``) then names the row gone.

A row whose thing is already warned about where it is read (the reader says
what it falls back to) has ``warned_by``: the audit lists it in the stats but
does not warn a second time.

Two entries depend on the render's camera, not on what a prim authors, and are made by the
scene delegate with the same :class:`Unsupported` form and warning: :data:`HEADLIGHT` and
:data:`GPRIM_DEFORMATION` (a NurbsPatch whose points move within the camera's shutter).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

from pxr import Usd, UsdGeom, UsdLux, UsdRender, UsdShade

from .gprim import GPRIM_TYPES
from .light import AREA_LIGHT_TYPES, SHAPED_KINDS, SHAPING_INPUTS, authored_properties
from .materialx import mtlx_surface, unsupported_nodes
from .mtlx_files import LOADED
from .shading import COLOR_INPUTS, FLOAT_INPUTS, bound_material

__all__ = [
    "GPRIM_DEFORMATION",
    "HEADLIGHT",
    "RENDERED_TYPES",
    "TABLE",
    "Row",
    "Unsupported",
    "audit_render_settings",
    "audit_stage",
    "composition_errors",
    "is_rendered_type",
    "warn_unsupported",
]

_log = logging.getLogger(__name__)

#: Prim types the scene delegate syncs (``UsdSceneDelegate`` asks :func:`is_rendered_type`).
RENDERED_TYPES: tuple[type, ...] = (
    UsdGeom.Mesh,
    *GPRIM_TYPES,
    UsdGeom.PointInstancer,
    UsdGeom.Camera,
    UsdLux.DistantLight,
    *(t for t, _ in AREA_LIGHT_TYPES),
    UsdLux.GeometryLight,
    UsdLux.PortalLight,
)

#: The UsdPreviewSurface inputs :mod:`mipray.usd.shading` reads (displacement only from a
#: texture: see the ``constant displacement`` row).
PREVIEW_SURFACE_INPUTS = frozenset(
    (*COLOR_INPUTS, *FLOAT_INPUTS, "useSpecularWorkflow", "normal", "displacement")
)
#: The light inputs :mod:`mipray.usd.light` reads, on every light type it renders
#: (``treatAsPoint`` is a hint area-light renderers may disregard, per UsdLux).
LIGHT_INPUTS = frozenset(
    {
        "intensity",
        "exposure",
        "color",
        "normalize",
        "enableColorTemperature",
        "colorTemperature",
        "shadow:enable",
        "angle",
        "radius",
        "width",
        "height",
        "length",
        "texture:file",
        "texture:format",
    }
)
#: How many prims a warning names before "and N more".
_NAMED = 3


@dataclass(frozen=True, order=True)
class Unsupported:
    """One authored thing mipray does not render, on one prim."""

    #: The prim's path (for what is inside a native instance: the first instance's proxy).
    prim: str
    #: What is ignored, as the table's row names it (details in parentheses).
    what: str

    def as_dict(self) -> dict[str, str]:
        """The stats' form: ``{"prim": ..., "what": ...}``."""
        return {"prim": self.prim, "what": self.what}


# ------------------------------------------------------------------- the checks
# Each takes a prim (and the time) and returns the details of what it authors that the
# row names (empty: nothing), so a row's ``what`` can say which input or output it is.


def _is_light(prim: Usd.Prim) -> bool:
    return bool(prim.HasAPI(UsdLux.LightAPI))


def is_rendered_type(prim: Usd.Prim) -> bool:
    """Whether the scene delegate syncs prims of ``prim``'s type."""
    return any(prim.IsA(t) for t in RENDERED_TYPES)


def _prim_type(prim: Usd.Prim, _: Usd.TimeCode) -> list[str]:
    if (prim.IsA(UsdGeom.Gprim) or _is_light(prim)) and not is_rendered_type(prim):
        return [prim.GetTypeName() or "untyped"]
    return []


def _api_properties(api: str, unread: Callable[[str], bool] = lambda _: True) -> list[str]:
    definition = Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(api)
    return [n for n in (definition.GetPropertyNames() if definition else ()) if unread(n)]


def _applied(
    api: str, read: frozenset[str] = frozenset(), *, presence: bool = False
) -> Callable[..., list[str]]:
    """An applied API schema: its authored properties mipray does not read.

    With ``presence``, the API itself when nothing is authored: applying it changes the
    picture (MeshLightAPI makes a mesh a light); otherwise its fallbacks change nothing.
    """

    def check(prim: Usd.Prim, _: Usd.TimeCode) -> list[str]:
        if api not in prim.GetAppliedSchemas():
            return []
        unread = _api_properties(api, lambda n: n.removeprefix("inputs:") not in read)
        names = authored_properties(prim, unread)
        return names or ([api] if presence else [])

    return check


def _shaping(prim: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    """ShapingAPI inputs not read: IES profiles, and any shaping on lights it does not shape."""
    shaped = any(prim.IsA(t) for t, k in AREA_LIGHT_TYPES if k in SHAPED_KINDS)
    return _applied("ShapingAPI", SHAPING_INPUTS if shaped else frozenset())(prim, time)


def _mesh_light(prim: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    """``MeshLightAPI`` on anything but a Mesh (no other gprim becomes a light).

    On a Mesh every input is read, ``light:materialSyncMode`` included
    (``mipray.usd.light.material_tint``).
    """
    if "MeshLightAPI" not in prim.GetAppliedSchemas():
        return []
    return [] if prim.IsA(UsdGeom.Mesh) else ["MeshLightAPI"]


def _light_inputs(prim: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    """Inputs of a rendered light that mipray does not read (diffuse, specular, filters, ...)."""
    if not _is_light(prim) or not is_rendered_type(prim):
        return []
    schema_owned = ("inputs:shaping:", "inputs:shadow:", "collection:")
    unread = [
        p.GetName()
        for p in prim.GetAuthoredProperties()
        if p.GetName().startswith("inputs:")
        and not p.GetName().startswith(schema_owned)
        and p.GetName().removeprefix("inputs:") not in LIGHT_INPUTS
    ]
    fmt = prim.GetAttribute("inputs:texture:format")
    if prim.IsA(UsdLux.DomeLight) and fmt and fmt.HasAuthoredValue():
        if str(fmt.Get(time)) not in ("automatic", "latlong"):
            unread.append(f"inputs:texture:format = {fmt.Get(time)}")
    if prim.IsA(UsdLux.PortalLight):
        # A portal only guides domes: none of its light inputs but its size is read.
        unread = [
            p.GetName()
            for p in prim.GetAuthoredProperties()
            if p.GetName().startswith("inputs:")
            and p.GetName() not in ("inputs:width", "inputs:height")
        ]
    return unread + authored_properties(prim, ["light:filters"])


def _clipping_planes(prim: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    if not prim.IsA(UsdGeom.Camera):
        return []
    planes = UsdGeom.Camera(prim).GetClippingPlanesAttr().Get(time)
    return [f"{len(planes)} plane(s)"] if planes else []


def _instanceable_gprim(prim: Usd.Prim, _: Usd.TimeCode) -> list[str]:
    # USD instances a prim's descendants; the instance prim's own geometry is in no prototype.
    return [prim.GetTypeName()] if prim.IsInstance() and prim.IsA(UsdGeom.Gprim) else []


def _missing_material(prim: Usd.Prim, _: Usd.TimeCode) -> list[str]:
    """A gprim's (or its GeomSubsets') binding to a prim that is no Material.

    USD binds nothing then, so the mesh renders its display colour.
    """
    if not prim.IsA(UsdGeom.Gprim):
        return []
    found = []
    subsets = UsdGeom.Subset.GetAllGeomSubsets(UsdGeom.Imageable(prim))
    for owner in (prim, *(s.GetPrim() for s in subsets)):
        binding = UsdShade.MaterialBindingAPI(owner).GetDirectBinding()
        target = binding.GetMaterialPath()
        if target.isEmpty:
            continue
        material = prim.GetStage().GetPrimAtPath(target)
        if not material or not material.IsA(UsdShade.Material):
            where = "" if owner == prim else f" (GeomSubset {owner.GetName()})"
            found.append(f"<{target}>{where}")
    return found


# A material's checks take the Material prim (bound to something rendered).


def _surface(material: Usd.Prim) -> UsdShade.Shader | None:
    shader, _, _ = UsdShade.Material(material).ComputeSurfaceSource()
    return shader if shader else None


def _context_only_outputs(material: Usd.Prim, _: Usd.TimeCode) -> list[str]:
    """Render-context surface outputs of a material without a universal UsdPreviewSurface.

    ``outputs:mtlx:surface``, ``outputs:ri:surface``: mipray reads only the universal one.
    """
    if _preview_surface(material) is not None:
        return []
    read = {"mtlx:surface"} if mtlx_surface(UsdShade.Material(material)) else set()
    outputs = UsdShade.Material(material).GetSurfaceOutputs()
    return [
        o.GetFullName()
        for o in outputs
        if o.GetBaseName() != "surface" and o.HasConnectedSource() and o.GetBaseName() not in read
    ]


def _mtlx_nodes(material: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    """MaterialX nodes (and surface inputs) of the material's mtlx surface mipray cannot map."""
    return unsupported_nodes(UsdShade.Material(material), time)


def _preview_surface(material: Usd.Prim) -> UsdShade.Shader | None:
    shader = _surface(material)
    return shader if shader is not None and shader.GetShaderId() == "UsdPreviewSurface" else None


def _surface_shader(material: Usd.Prim, _: Usd.TimeCode) -> list[str]:
    shader = _surface(material)
    if shader is None or shader.GetShaderId() == "UsdPreviewSurface":
        return []
    return [f"{shader.GetShaderId() or 'no id'} at {shader.GetPath()}"]


def _preview_inputs(material: Usd.Prim, _: Usd.TimeCode) -> list[str]:
    shader = _preview_surface(material)
    if shader is None:
        return []
    return [
        f"inputs:{i.GetBaseName()}"
        for i in shader.GetInputs()
        if i.GetBaseName() not in PREVIEW_SURFACE_INPUTS
        and (i.GetAttr().HasAuthoredValue() or i.HasConnectedSource())
    ]


def _constant_displacement(material: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    shader, _, _ = UsdShade.Material(material).ComputeDisplacementSource()
    if not shader or shader.GetShaderId() != "UsdPreviewSurface":
        return []
    displacement = shader.GetInput("displacement")
    if not displacement or displacement.HasConnectedSource():
        return []
    value = displacement.Get(time)
    return [f"displacement = {value:g}"] if value else []


#: RenderVar light-path expressions that are the whole beauty image (what mipray renders).
BEAUTY_LPES = frozenset({"C.*", "C.*[LO]", "C.*L", "C[DS]*[LO]"})


def _render_var_lpe(var: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    if not var.IsA(UsdRender.Var):
        return []
    render_var = UsdRender.Var(var)
    if str(render_var.GetSourceTypeAttr().Get(time)) != "lpe":
        return []
    expression = str(render_var.GetSourceNameAttr().Get(time) or "")
    return [] if expression in BEAUTY_LPES else [f"'{expression}', rendered as the beauty"]


def _render_settings_window(prim: Usd.Prim, time: Usd.TimeCode) -> list[str]:
    base = UsdRender.SettingsBase(prim)
    found = []
    ratio = base.GetPixelAspectRatioAttr()
    if ratio.HasAuthoredValue() and ratio.Get(time) != 1.0:
        found.append(f"pixelAspectRatio {ratio.Get(time)}")
    window = base.GetDataWindowNDCAttr()
    if window.HasAuthoredValue() and tuple(window.Get(time)) != (0.0, 0.0, 1.0, 1.0):
        found.append(f"dataWindowNDC {tuple(window.Get(time))}")
    return found


@dataclass(frozen=True)
class Row:
    """One thing the front end does not consume."""

    #: How the warning and the stats name it.
    what: str
    #: What it is checked on: ``prim`` (every rendered prim), ``material`` (every material
    #: bound to a rendered mesh or its GeomSubsets), ``render var`` and ``render settings``
    #: (those of the render).
    scope: str
    #: ``check(prim, time)``: the details authored (empty: none).
    check: Callable[[Usd.Prim, Usd.TimeCode], list[str]]
    #: The module that already warns where it reads it (the audit then only lists it).
    warned_by: str | None = None


#: Everything authored that the front end does not consume: one row each.
TABLE: tuple[Row, ...] = (
    Row("prim type", "prim", _prim_type, warned_by="mipray.usd.scene_delegate"),
    Row("instanceable gprim (its own geometry is not instanced)", "prim", _instanceable_gprim),
    Row("material binding to no Material", "prim", _missing_material),
    Row("ShapingAPI", "prim", _shaping),
    Row("ShadowAPI", "prim", _applied("ShadowAPI", frozenset({"shadow:enable"}))),
    Row("MeshLightAPI", "prim", _mesh_light),
    Row("light input", "prim", _light_inputs),
    Row("camera clippingPlanes", "prim", _clipping_planes),
    Row(
        "material output (only the universal outputs:surface is read)",
        "material",
        _context_only_outputs,
    ),
    Row("surface shader", "material", _surface_shader, warned_by="mipray.usd.shading"),
    Row("MaterialX node", "material", _mtlx_nodes),
    Row("UsdPreviewSurface input", "material", _preview_inputs),
    Row("UsdPreviewSurface constant displacement", "material", _constant_displacement),
    Row("render var light-path expression", "render var", _render_var_lpe),
    Row(
        "render settings window",
        "render settings",
        _render_settings_window,
        warned_by="mipray.usd.render_settings",
    ),
)

#: The camera light (``UsdSceneDelegate.update_camera_light``) lights a stage whose only
#: lights are of unsupported types: those lights are named with this.
HEADLIGHT = "headlight added: no light on the stage is of a rendered type"
#: A NurbsPatch whose shape changes within the shutter (its ``points`` sampled inside it or
#: moving by ``velocities``): the core blurs the deformation of meshes, Points, curves and
#: implicit prims only, so it renders at the frame's time (its transform still blurs).
GPRIM_DEFORMATION = "deformation of a NurbsPatch (rendered at the frame's time, without blur)"


def _apply(scope: str, prim: Usd.Prim, time: Usd.TimeCode, shown: str) -> Iterator[Unsupported]:
    for row in TABLE:
        if row.scope == scope:
            for detail in row.check(prim, time):
                yield Unsupported(shown, f"{row.what} {detail}" if detail != row.what else detail)


def _rendered_prims(
    stage: Usd.Stage, time: Usd.TimeCode, purposes: tuple[str, ...]
) -> Iterator[tuple[Usd.Prim, str]]:
    """Every prim the render walks (visible, of an included purpose), and its path to show.

    A native prototype's prims come once, under the first instance that uses it.
    """
    seen_prototypes: set[str] = set()
    stack: list[tuple[Usd.Prim, UsdGeom.Imageable.PurposeInfo, str | None]] = [
        (c, UsdGeom.Imageable.PurposeInfo(), None)
        for c in reversed(stage.GetPseudoRoot().GetFilteredChildren(Usd.PrimDefaultPredicate))
    ]
    while stack:
        prim, parent_info, shown_root = stack.pop()
        info = parent_info
        imageable = UsdGeom.Imageable(prim)
        if imageable:
            if imageable.GetVisibilityAttr().Get(time) == UsdGeom.Tokens.invisible:
                continue
            info = imageable.ComputePurposeInfo(parent_info)
        # Above every imageable prim (an untyped /World) the purpose is not yet computed: an
        # empty token, which is the default purpose, not one the render leaves out.
        if (info.purpose or UsdGeom.Tokens.default_) not in purposes:
            continue
        path = str(prim.GetPath())
        # Inside a prototype (/__Prototype_1/A/B): named under the instance (/inst/A/B).
        shown = path if shown_root is None else shown_root + path[path.index("/", 1) :]
        yield prim, shown
        children = list(prim.GetFilteredChildren(Usd.PrimDefaultPredicate))
        if prim.IsInstance():
            prototype = prim.GetPrototype()
            if str(prototype.GetPath()) in seen_prototypes:
                continue
            seen_prototypes.add(str(prototype.GetPath()))
            children = list(prototype.GetFilteredChildren(Usd.PrimDefaultPredicate))
            stack.extend((c, UsdGeom.Imageable.PurposeInfo(), shown) for c in reversed(children))
            continue
        stack.extend((c, info, shown_root) for c in reversed(children))


def _bound_materials(prim: Usd.Prim) -> list[Usd.Prim]:
    """The materials bound to ``prim`` and to its materialBind GeomSubsets, for rendering."""
    found = []
    subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
    for owner in (prim, *(s.GetPrim() for s in subsets)):
        material = bound_material(owner)
        if material is not None and material.GetPrim() not in found:
            found.append(material.GetPrim())
    return found


def audit_stage(
    stage: Usd.Stage, time: Usd.TimeCode, purposes: tuple[str, ...]
) -> list[Unsupported]:
    """Everything rendered prims author that mipray does not consume, sorted, each once.

    The ``prim`` and ``material`` rows of :data:`TABLE`.
    """
    found: set[Unsupported] = set()
    materials: dict[str, Usd.Prim] = {}
    for prim, shown in _rendered_prims(stage, time, purposes):
        found.update(_apply("prim", prim, time, shown))
        if prim.IsA(UsdGeom.Gprim):
            for material in _bound_materials(prim):
                materials.setdefault(str(material.GetPath()), material)
    found.update(composition_errors(stage))
    for path, material in materials.items():
        found.update(_apply("material", material, time, path))
    return sorted(found)


def composition_errors(stage: Usd.Stage) -> list[Unsupported]:
    """What USD could not compose, each with the prim that introduced it and USD's reason.

    A reference or payload to a missing or unreadable layer, ...; the reason in one line.
    """
    found = []
    for error in stage.GetCompositionErrors():
        text = " ".join(str(error).split())
        if any(os.path.basename(f) in text for f in LOADED):
            continue  # a .mtlx reference mipray composed itself (mipray.usd.mtlx_files)
        site = getattr(error, "rootSite", None)
        prim = str(site.path) if site is not None and hasattr(site, "path") else "/"
        found.append(Unsupported(prim, f"composition error: {text}"))
    return found


def audit_render_settings(stage: Usd.Stage, path: str, time: Usd.TimeCode) -> list[Unsupported]:
    """What the RenderSettings at ``path``, its products and vars author but mipray ignores.

    The ``render settings`` and ``render var`` rows of :data:`TABLE`.
    """
    found: list[Unsupported] = []
    settings = stage.GetPrimAtPath(path)
    if not settings:
        return found
    found += _apply("render settings", settings, time, path)
    for product_path in UsdRender.Settings(settings).GetProductsRel().GetForwardedTargets():
        product = stage.GetPrimAtPath(product_path)
        if not product:
            continue
        found += _apply("render settings", product, time, str(product_path))
        for var_path in UsdRender.Product(product).GetOrderedVarsRel().GetForwardedTargets():
            var = stage.GetPrimAtPath(var_path)
            if var:
                found += _apply("render var", var, time, str(var_path))
    return found


def _warned_elsewhere(item: Unsupported) -> bool:
    return any(r.warned_by and item.what.startswith(r.what) for r in TABLE)


def warn_unsupported(items: Iterable[Unsupported], already: set[Unsupported]) -> None:
    """One warning per thing, naming its first few prims, for those not in ``already``.

    ``already`` is updated. What the reader that ignores it warns about itself is skipped.
    """
    fresh = [i for i in items if i not in already and not _warned_elsewhere(i)]
    already.update(items)
    by_what: dict[str, list[str]] = {}
    for item in fresh:
        by_what.setdefault(item.what, []).append(item.prim)
    for what, prims in sorted(by_what.items()):
        named = ", ".join(prims[:_NAMED])
        more = f" and {len(prims) - _NAMED} more" if len(prims) > _NAMED else ""
        _log.warning("mipray: not rendered: %s on %s%s", what, named, more)
