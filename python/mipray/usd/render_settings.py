"""``UsdRender.Settings``, ``Product`` and ``Var``: resolution, camera, purposes and AOVs.

A RenderSettings prim says how a stage wants to be rendered: its
``resolution``, the ``camera`` to look through, the ``includedPurposes``, and
its ``products``, each an image whose channels are the ``orderedVars``
(RenderVar prims naming an AOV by ``sourceName``). A product may override
the settings' resolution and camera; mipray writes one image (to the path it
is given, not the products' ``productName``), so it takes the first
product's overrides, and the AOVs of every product in order, each once.

Which settings apply: the prim a user names (``--renderSettingsPrimPath``),
else the stage's ``renderSettingsPrimPath`` metadata, else none. Command-line
flags given explicitly win over the settings (see ``mipray.record``).

A RenderVar's ``sourceName`` is an AOV mipray renders (``color``, ``depth``,
``normal``, ``alpha``, ``primId``, ``instanceId``, ...) or one of the usual
aliases (``Ci``, ``C``, ``rgb`` and LPEs starting with ``C`` for colour;
``a``; ``z``/``Z``; ``N``/``Nworld``; ``id``). Authored ``pixelAspectRatio``
other than 1 and ``dataWindowNDC`` other than the full frame are not
supported: a warning says so and they are ignored. The window is expanded to
the image's aspect ratio, as ``aspectRatioConformPolicy = expandAperture``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from pxr import Gf, Usd, UsdGeom, UsdRender

from ..aovs import TABLE as AOV_TABLE
from ..errors import RenderSettingsError

__all__ = [
    "AOV_ALIASES",
    "KNOWN_AOVS",
    "RenderSettingsSpec",
    "aov_for_source",
    "read_render_settings",
    "stage_render_settings_path",
]

_log = logging.getLogger(__name__)

#: The AOVs the renderer produces (:data:`mipray.aovs.TABLE`).
KNOWN_AOVS = tuple(AOV_TABLE)
#: RenderVar source names other renderers use, and the AOV they mean here.
AOV_ALIASES = {
    "Ci": "color",
    "C": "color",
    "rgb": "color",
    "rgba": "color",
    "a": "alpha",
    "A": "alpha",
    "z": "depth",
    "Z": "depth",
    "N": "normal",
    "Nworld": "normal",
    "id": "primId",
}


@dataclass(frozen=True)
class RenderSettingsSpec:
    """What one RenderSettings prim asks for."""

    #: The RenderSettings prim's path.
    path: str
    #: (width, height) in pixels.
    resolution: tuple[int, int]
    #: The camera prim's path, or None when none is targeted.
    camera: str | None
    #: AOV names in product order, each once (empty when no product names one).
    aovs: list[str] = field(default_factory=list)
    #: ``includedPurposes`` (``default`` always among them).
    purposes: tuple[str, ...] = ("default", "render")
    #: The products' paths.
    products: list[str] = field(default_factory=list)


def aov_for_source(source_name: str, source_type: str = "raw") -> str | None:
    """The AOV a RenderVar's ``sourceName`` (and ``sourceType``) means, or None."""
    if source_name in KNOWN_AOVS:
        return source_name
    if source_name in AOV_ALIASES:
        return AOV_ALIASES[source_name]
    if source_type == "lpe" and source_name.startswith("C"):
        return "color"  # a light path expression from the camera: beauty
    return None


def stage_render_settings_path(stage: Usd.Stage) -> str | None:
    """The stage's default RenderSettings path (``renderSettingsPrimPath`` metadata)."""
    value = stage.GetMetadata("renderSettingsPrimPath")
    return str(value) if value else None


def _single_target(rel: Usd.Relationship) -> str | None:
    targets = rel.GetForwardedTargets() if rel else []
    return str(targets[0]) if targets else None


def _resolution(base: UsdRender.Settings | UsdRender.Product, time: Usd.TimeCode) -> Gf.Vec2i:
    return base.GetResolutionAttr().Get(time)


def _warn_unsupported(prim: Usd.Prim, time: Usd.TimeCode) -> None:
    base = UsdRender.SettingsBase(prim)
    ratio = base.GetPixelAspectRatioAttr()
    if ratio.HasAuthoredValue() and ratio.Get(time) != 1.0:
        _log.warning(
            "mipray: %s: pixelAspectRatio %s is not supported; rendering square pixels",
            prim.GetPath(),
            ratio.Get(time),
        )
    window = base.GetDataWindowNDCAttr()
    if window.HasAuthoredValue() and tuple(window.Get(time)) != (0.0, 0.0, 1.0, 1.0):
        _log.warning(
            "mipray: %s: dataWindowNDC %s is not supported; rendering the full frame",
            prim.GetPath(),
            tuple(window.Get(time)),
        )


def read_render_settings(
    stage: Usd.Stage,
    path: str | None = None,
    time: Usd.TimeCode | None = None,
) -> RenderSettingsSpec | None:
    """Read the RenderSettings at ``path`` (default: the stage's metadata).

    Returns:
        The settings, or None when no path is given and the stage names none.

    Raises:
        RenderSettingsError: the prim is missing or not a RenderSettings, a
            resolution is not positive, the camera target is not a camera, a
            product target is not a RenderProduct, or a RenderVar names no AOV
            mipray renders. Each message names the prim.

    """
    time = Usd.TimeCode.Default() if time is None else time
    explicit = path is not None
    path = path if explicit else stage_render_settings_path(stage)
    if path is None:
        return None
    prim = stage.GetPrimAtPath(path)
    if not prim or not prim.IsA(UsdRender.Settings):
        what = "no prim" if not prim else f"a {prim.GetTypeName() or 'typeless'} prim"
        source = "" if explicit else " (the stage's renderSettingsPrimPath)"
        raise RenderSettingsError(f"{path}{source}: {what}, not a RenderSettings prim")
    settings = UsdRender.Settings(prim)
    _warn_unsupported(prim, time)
    resolution = _resolution(settings, time)
    camera = _single_target(settings.GetCameraRel())
    aovs: list[str] = []
    products: list[str] = []
    for target in settings.GetProductsRel().GetForwardedTargets():
        product_prim = stage.GetPrimAtPath(target)
        if not product_prim or not product_prim.IsA(UsdRender.Product):
            raise RenderSettingsError(f"{path}: products target <{target}> is not a RenderProduct")
        product = UsdRender.Product(product_prim)
        products.append(str(target))
        _warn_unsupported(product_prim, time)
        if len(products) == 1:  # the image written: the first product's overrides
            if product.GetResolutionAttr().HasAuthoredValue():
                resolution = _resolution(product, time)
            camera = _single_target(product.GetCameraRel()) or camera
        for var_path in product.GetOrderedVarsRel().GetForwardedTargets():
            var_prim = stage.GetPrimAtPath(var_path)
            if not var_prim or not var_prim.IsA(UsdRender.Var):
                raise RenderSettingsError(
                    f"{target}: orderedVars target <{var_path}> is not a RenderVar"
                )
            var = UsdRender.Var(var_prim)
            source = str(var.GetSourceNameAttr().Get(time) or var_prim.GetName())
            source_type = str(var.GetSourceTypeAttr().Get(time) or "raw")
            aov = aov_for_source(source, source_type)
            if aov is None:
                raise RenderSettingsError(
                    f"{var_path}: sourceName '{source}' is not an AOV mipray renders "
                    f"({', '.join(KNOWN_AOVS)})"
                )
            if aov not in aovs:
                aovs.append(aov)
    width, height = int(resolution[0]), int(resolution[1])
    if width < 1 or height < 1:
        raise RenderSettingsError(f"{path}: resolution {width}x{height} must be positive")
    if camera is not None:
        camera_prim = stage.GetPrimAtPath(camera)
        if not camera_prim or not camera_prim.IsA(UsdGeom.Camera):
            raise RenderSettingsError(f"{path}: camera target <{camera}> is not a Camera prim")
    purposes = tuple(str(p) for p in settings.GetIncludedPurposesAttr().Get(time) or ())
    return RenderSettingsSpec(
        path=str(path),
        resolution=(width, height),
        camera=camera,
        aovs=aovs,
        purposes=("default", *(p for p in purposes if p != "default")),
        products=products,
    )
