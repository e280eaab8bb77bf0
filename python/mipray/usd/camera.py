"""Cameras: reading ``UsdGeom.Camera``, choosing one, and framing a stage without one.

``UsdGeom.Camera`` goes into ``RenderDelegate.set_camera``; when a stage has no
camera, a camera framing its bounds is made, as usdrecord does.

Units are USD's: focal length and apertures in tenths of a scene unit,
clipping range in scene units, the camera looking down its local -Z axis.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Gf, Usd, UsdGeom, UsdSkel

from ..errors import PrimError, RenderSettingsError
from .transform import matrix_to_numpy

__all__ = [
    "DEFAULT_CAMERA_PATH",
    "camera_arguments",
    "camera_matrices",
    "find_camera_prim",
    "framing_camera_arguments",
    "image_height",
]

#: Path of the camera mipray makes when a stage has none (as usdrecord does).
DEFAULT_CAMERA_PATH = "/__mipray_default_camera"

# UsdGeom.Camera's fallback values, used for the framing camera.
_FOCAL_LENGTH = 50.0
_H_APERTURE = 20.955
_V_APERTURE = 15.2908


def camera_arguments(
    camera: UsdGeom.Camera, time: Usd.TimeCode, transform: NDArray[np.float64]
) -> dict[str, Any]:
    """The keyword arguments of ``RenderDelegate.set_camera`` for ``camera``.

    Raises:
        PrimError: a value the camera model cannot use (non-positive focal
            length or aperture, an empty clipping range, a non-finite
            transform).

    """
    path = str(camera.GetPath())

    def get(attr: Usd.Attribute, default: Any) -> Any:
        value = attr.Get(time)
        return default if value is None else value

    near, far = get(camera.GetClippingRangeAttr(), (1.0, 1e6))
    args: dict[str, Any] = {
        "transform": transform,
        "projection": str(get(camera.GetProjectionAttr(), "perspective")),
        "focal_length": float(get(camera.GetFocalLengthAttr(), _FOCAL_LENGTH)),
        "horizontal_aperture": float(get(camera.GetHorizontalApertureAttr(), _H_APERTURE)),
        "vertical_aperture": float(get(camera.GetVerticalApertureAttr(), _V_APERTURE)),
        "horizontal_aperture_offset": float(get(camera.GetHorizontalApertureOffsetAttr(), 0.0)),
        "vertical_aperture_offset": float(get(camera.GetVerticalApertureOffsetAttr(), 0.0)),
        "clipping_range": (float(near), float(far)),
        "f_stop": float(get(camera.GetFStopAttr(), 0.0)),
        "focus_distance": float(get(camera.GetFocusDistanceAttr(), 0.0)),
    }
    problem = _check_camera(args)
    if problem:
        raise PrimError(path, problem)
    return args


def _check_camera(args: dict[str, Any]) -> str | None:
    if args["projection"] not in ("perspective", "orthographic"):
        return f"unknown projection '{args['projection']}'"
    for key, name in (
        ("focal_length", "focalLength"),
        ("horizontal_aperture", "horizontalAperture"),
        ("vertical_aperture", "verticalAperture"),
    ):
        value = args[key]
        if not (math.isfinite(value) and value > 0.0):
            return f"{name} is {value}; it must be positive"
    near, far = args["clipping_range"]
    if not (math.isfinite(near) and near >= 0.0 and far > near):
        return f"clippingRange ({near}, {far}) is empty or negative"
    if not (math.isfinite(args["f_stop"]) and args["f_stop"] >= 0.0):
        return f"fStop is {args['f_stop']}; it must be 0 (no depth of field) or positive"
    if not np.isfinite(args["transform"]).all():
        return "the world transform is not finite"
    return None


def find_camera_prim(stage: Usd.Stage, requested: str) -> Usd.Prim:
    """The camera prim a user named, as usdrecord's ``--camera`` resolves it.

    ``requested`` is a prim path, or a bare name matched against the names of
    the stage's camera prims (the first in traversal order wins).

    Raises:
        PrimError: there is no such prim, or it is not a ``UsdGeom.Camera``.

    """
    if requested.startswith("/"):
        prim = stage.GetPrimAtPath(requested)
        if not prim:
            raise PrimError(requested, "no such camera prim on the stage")
        if not prim.IsA(UsdGeom.Camera):
            raise PrimError(
                requested, f"is a {prim.GetTypeName() or 'typeless prim'}, not a Camera"
            )
        return prim
    predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
    for prim in Usd.PrimRange.Stage(stage, predicate):
        if prim.GetName() == requested and prim.IsA(UsdGeom.Camera):
            return prim
    raise PrimError(requested, "no camera prim of that name on the stage")


def _bounds_without(
    cache: UsdGeom.BBoxCache, root: Usd.Prim, skip: Mapping[str, Any]
) -> Gf.Range3d:
    """The world bounds of everything under ``root`` but the prims in ``skip``.

    Each boundable (or instance) outside them, as ``cache`` bounds it; skeletons, which
    render nothing, are left out.
    """
    box = Gf.Range3d()
    prims = iter(Usd.PrimRange(root))
    for prim in prims:
        if str(prim.GetPath()) in skip or prim.IsA(UsdSkel.Skeleton):
            prims.PruneChildren()
        elif prim.IsInstance() or (prim.IsA(UsdGeom.Boundable) and not prim.IsA(UsdSkel.Root)):
            one = cache.ComputeWorldBound(prim).ComputeAlignedRange()
            if _finite(one):
                box.UnionWith(one)
            prims.PruneChildren()
    return box


def _finite(box: Gf.Range3d) -> bool:
    """Whether ``box`` is empty or a real box.

    usd-core bounds a prim it cannot bound (a SkelRoot whose skeletons have no rest pose, a
    mesh with an infinite point) by ±FLT_MAX or by non-finite corners; framing such a box
    gives a camera at infinity and a clipping range the renderer refuses.
    """
    if box.IsEmpty():
        return True
    corners = (*box.GetMin(), *box.GetMax())
    return all(math.isfinite(x) and abs(x) < 1e30 for x in corners)


def framing_camera_arguments(
    stage: Usd.Stage,
    time: Usd.TimeCode,
    purposes: tuple[str, ...],
    posed: Mapping[str, tuple[Any, Any]] | None = None,
) -> dict[str, Any]:
    """A perspective camera that frames the stage's world bounds from the front.

    "Front" looks down -Z when the stage's up axis is Y and down +Y when it
    is Z. The bounds are computed with ``UsdGeom.BBoxCache`` for the included
    purposes, except for the prims in ``posed`` (skinned meshes: path → posed
    world (min, max) corners), whose rest extents are replaced by their posed
    bounds; prims usd-core bounds by infinite or ±FLT_MAX boxes are left out, and an empty
    stage frames the unit cube at the origin.
    """
    cache = UsdGeom.BBoxCache(time, list(purposes), useExtentsHint=True)
    root = stage.GetPseudoRoot()
    if posed:
        box = _bounds_without(cache, root, posed)
        for lo, hi in posed.values():
            box.UnionWith(Gf.Range3d(Gf.Vec3d(*map(float, lo)), Gf.Vec3d(*map(float, hi))))
    else:
        box = cache.ComputeWorldBound(root).ComputeAlignedRange()
        if not _finite(box):
            # One prim usd-core cannot bound makes the whole stage's box unbounded: frame the
            # prims it can bound instead.
            box = _bounds_without(cache, root, {})
    if box.IsEmpty():
        box = Gf.Range3d(Gf.Vec3d(-1, -1, -1), Gf.Vec3d(1, 1, 1))
    center = box.GetMidpoint()
    radius = 0.5 * box.GetSize().GetLength() or 1.0

    half_fov = min(
        math.atan(0.5 * _H_APERTURE / _FOCAL_LENGTH), math.atan(0.5 * _V_APERTURE / _FOCAL_LENGTH)
    )
    distance = radius / math.sin(half_fov)
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        up = Gf.Vec3d(0, 0, 1)
        eye = center - Gf.Vec3d(0, distance, 0)
    else:
        up = Gf.Vec3d(0, 1, 0)
        eye = center + Gf.Vec3d(0, 0, distance)
    camera_to_world = Gf.Matrix4d().SetLookAt(eye, center, up).GetInverse()
    near = max(distance - radius, 0.0) * 0.5 or distance * 1e-4
    far = (distance + radius) * 2.0
    return {
        "transform": matrix_to_numpy(camera_to_world),
        "projection": "perspective",
        "focal_length": _FOCAL_LENGTH,
        "horizontal_aperture": _H_APERTURE,
        "vertical_aperture": _V_APERTURE,
        "horizontal_aperture_offset": 0.0,
        "vertical_aperture_offset": 0.0,
        "clipping_range": (max(near, distance * 1e-4), far),
        "f_stop": 0.0,
        "focus_distance": 0.0,
    }


def image_height(width: int, camera_args: dict[str, Any], camera: str = "the camera") -> int:
    """Image height for ``width`` pixels from the camera's aperture aspect ratio.

    Truncated to whole pixels in single precision, at least 1, as usdrecord's frame
    recorder computes it (so its command lines give its image sizes).

    Raises:
        RenderSettingsError: the aperture's aspect gives no height an image can have
            (``camera`` names the camera in the message).

    """
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        aspect = np.float32(camera_args["horizontal_aperture"]) / np.float32(
            camera_args["vertical_aperture"]
        )
        height = np.float32(width) / aspect
    if not np.isfinite(height) or height >= 2.0**32:
        # Past what any image side can be; the renderer's own check states the bound.
        raise RenderSettingsError(
            f"{camera}: an image {width} pixels wide through its aperture of "
            f"{camera_args['horizontal_aperture']:g} x {camera_args['vertical_aperture']:g} "
            "would be too tall to render; give the camera a sane aperture or the image a height"
        )
    return max(1, int(height))


def camera_matrices(
    camera_args: dict[str, Any],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(world_to_camera, world_to_screen)`` of a camera, row-vector convention.

    Both follow USD/OpenGL conventions (the camera looks down -Z; the screen
    is the projection's normalized device coordinates, -1..1 across the
    aperture), as ``Gf.Frustum`` computes them. They go into image metadata
    as OpenImageIO's ``worldtocamera`` and ``worldtoscreen``.
    """
    gf_camera = Gf.Camera(
        Gf.Matrix4d(camera_args["transform"].tolist()),
        Gf.Camera.Perspective
        if camera_args["projection"] == "perspective"
        else Gf.Camera.Orthographic,
        camera_args["horizontal_aperture"],
        camera_args["vertical_aperture"],
        camera_args["horizontal_aperture_offset"],
        camera_args["vertical_aperture_offset"],
        camera_args["focal_length"],
        Gf.Range1f(*camera_args["clipping_range"]),
    )
    frustum = gf_camera.frustum
    view = frustum.ComputeViewMatrix()
    projection = frustum.ComputeProjectionMatrix()
    return matrix_to_numpy(view), matrix_to_numpy(view * projection)
