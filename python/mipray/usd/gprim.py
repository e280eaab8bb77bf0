"""Read implicit gprims, ``UsdGeom.Points`` and curves into ``set_mesh`` arguments.

``Sphere``, ``Cube``, ``Cylinder``, ``Cylinder_1``, ``Cone``, ``Capsule``,
``Capsule_1`` and ``Plane`` cross as their schema attributes (the ``gprim``
argument), ``Points`` as its ``points`` and ``widths``; the core intersects
them exactly (``rust/src/implicit.rs``, which also documents their ``st``).
``BasisCurves`` and ``NurbsCurves`` are read by :mod:`mipray.usd.curves`.
``NurbsPatch`` crosses as its control points, orders, knots, ranges and weights;
the core cuts it into rational Bézier patches tessellated on demand
(``rust/src/nurbs.rs``); counts, orders, knots or weights that do not fit are
refused by the delegate with one line naming the prim and attribute. Its trim
curves (``trimCurve:*``) cross as ``gprim["trim"]`` and cut the surface
(``rust/src/trim.rs``: a point is kept inside an odd number of loops); trim
curves that do not fit are one warning naming the prim and attribute, and the
surface renders untrimmed.
``extent`` plays no part in the shape. A size that leaves nothing to render
(a zero radius, say) is refused with one line naming the prim and attribute.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom

from ..errors import PrimError
from .attributes import read_array
from .curves import CURVE_TYPES, curves_arguments
from .material import lambertian
from .warn import warn_once

__all__ = [
    "GPRIM_TYPES",
    "curve_colors",
    "gprim_arguments",
    "implicit_shape",
    "is_renderable_gprim",
    "point_colors",
]

_warn_once = warn_once(__name__)


#: The implicit gprims, by schema class.
_IMPLICIT_TYPES: tuple[type, ...] = (
    UsdGeom.Sphere,
    UsdGeom.Cube,
    UsdGeom.Cylinder,
    UsdGeom.Cone,
    UsdGeom.Capsule,
    UsdGeom.Plane,
    *(t for t in (getattr(UsdGeom, "Cylinder_1", None), getattr(UsdGeom, "Capsule_1", None)) if t),
)

#: The gprims besides ``Mesh`` that render, by schema class.
GPRIM_TYPES: tuple[type, ...] = (
    *_IMPLICIT_TYPES,
    UsdGeom.Points,
    UsdGeom.NurbsPatch,
    *CURVE_TYPES,
)


def is_renderable_gprim(prim: Usd.Prim) -> bool:
    """Whether ``prim`` is a mesh or another gprim the delegate renders."""
    return prim.IsA(UsdGeom.Mesh) or any(prim.IsA(t) for t in GPRIM_TYPES)


def _size(prim: Usd.Prim, name: str, time: Usd.TimeCode, *, zero_ok: bool = False) -> float:
    """A size attribute's value (its schema fallback when unauthored), checked."""
    value = prim.GetAttribute(name).Get(time)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise PrimError(str(prim.GetPath()), f"{name} = {value!r} is not a number") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not zero_ok):
        need = "a non-negative" if zero_ok else "a positive"
        raise PrimError(str(prim.GetPath()), f"{name} = {v:g} must be {need} number")
    return v


def _axis(prim: Usd.Prim, time: Usd.TimeCode) -> str:
    axis = str(prim.GetAttribute("axis").Get(time) or "Z")
    if axis not in ("X", "Y", "Z"):
        raise PrimError(str(prim.GetPath()), f"axis '{axis}' is not X, Y or Z")
    return axis


def _radii(prim: Usd.Prim, time: Usd.TimeCode) -> tuple[float, float]:
    """``(radius_bottom, radius_top)`` of a ``_1`` form; one of them may be 0, not both."""
    bottom = _size(prim, "radiusBottom", time, zero_ok=True)
    top = _size(prim, "radiusTop", time, zero_ok=True)
    if bottom == 0 and top == 0:
        raise PrimError(str(prim.GetPath()), "radiusBottom = radiusTop = 0: nothing to render")
    return bottom, top


def _shape(prim: Usd.Prim, time: Usd.TimeCode) -> dict[str, Any]:
    """The ``gprim`` argument of an implicit prim."""
    type_name = prim.GetTypeName()
    if prim.IsA(UsdGeom.Sphere):
        return {"type": "Sphere", "radius": _size(prim, "radius", time)}
    if prim.IsA(UsdGeom.Cube):
        return {"type": "Cube", "size": _size(prim, "size", time)}
    if prim.IsA(UsdGeom.Plane):
        return {
            "type": "Plane",
            "width": _size(prim, "width", time),
            "length": _size(prim, "length", time),
            "axis": _axis(prim, time),
        }
    if prim.IsA(UsdGeom.Cone):
        bottom, top = _size(prim, "radius", time), 0.0
    elif type_name in ("Cylinder_1", "Capsule_1"):
        bottom, top = _radii(prim, time)
    else:  # Cylinder, Capsule
        bottom = top = _size(prim, "radius", time)
    capsule = type_name.startswith("Capsule")
    return {
        "type": "Capsule" if capsule else "Cylinder",
        "radius_bottom": bottom,
        "radius_top": top,
        # A capsule of height 0 is still a sphere: only cylinders and cones need height.
        "height": _size(prim, "height", time, zero_ok=capsule),
        "axis": _axis(prim, time),
    }


def implicit_shape(prim: Usd.Prim, time: Usd.TimeCode) -> dict[str, Any] | None:
    """The ``gprim`` argument of an implicit prim at ``time``; None for any other prim.

    Raises:
        PrimError: a size that is not a positive number, or an ``axis`` not X, Y or Z.

    """
    if not any(prim.IsA(t) for t in _IMPLICIT_TYPES):
        return None
    return _shape(prim, time)


def _points(prim: Usd.Prim, time: Usd.TimeCode) -> tuple[NDArray[np.float32], dict[str, Any]]:
    """A Points prim's positions and its ``gprim`` argument (widths checked by the delegate)."""
    points = UsdGeom.Points(prim)
    positions = read_array(points.GetPointsAttr(), time, np.float32, 3)
    widths = read_array(points.GetWidthsAttr(), time, np.float32)
    return positions, {"type": "Points", "widths": widths}


def _count(prim: Usd.Prim, name: str, time: Usd.TimeCode) -> int:
    value = prim.GetAttribute(name).Get(time)
    if value is None:
        raise PrimError(str(prim.GetPath()), f"{name} is not authored")
    return int(value)


def _nurbs_patch(prim: Usd.Prim, time: Usd.TimeCode) -> tuple[NDArray[np.float32], dict[str, Any]]:
    """A NurbsPatch's control points and its ``gprim`` argument (checked by the delegate)."""
    patch = UsdGeom.NurbsPatch(prim)
    path = str(prim.GetPath())
    positions = read_array(patch.GetPointsAttr(), time, np.float32, 3)
    gprim: dict[str, Any] = {
        "type": "Nurbs",
        "u_vertex_count": _count(prim, "uVertexCount", time),
        "v_vertex_count": _count(prim, "vVertexCount", time),
        "u_order": _count(prim, "uOrder", time),
        "v_order": _count(prim, "vOrder", time),
        "u_knots": [float(k) for k in patch.GetUKnotsAttr().Get(time) or []],
        "v_knots": [float(k) for k in patch.GetVKnotsAttr().Get(time) or []],
    }
    for key, attr in (("u_range", patch.GetURangeAttr()), ("v_range", patch.GetVRangeAttr())):
        value = attr.Get(time)
        if value is not None:
            gprim[key] = (float(value[0]), float(value[1]))
    weights = patch.GetPointWeightsAttr().Get(time)
    if weights is not None and len(weights):
        gprim["weights"] = [float(w) for w in weights]
    trim = _trim_curves(patch, time)
    if trim is not None:
        # Imported here: the USD front end imports without the extension (a recording fake
        # delegate), and then the trim crosses unchecked.
        try:
            from .._mipray import check_trim_curves
        except ImportError:
            problem = None
        else:
            problem = check_trim_curves(trim)
        if problem is None:
            gprim["trim"] = trim
        else:
            _warn_once(f"{path}: {problem}; rendering the untrimmed surface")
    return positions, gprim


def _trim_curves(patch: UsdGeom.NurbsPatch, time: Usd.TimeCode) -> dict[str, Any] | None:
    """A NurbsPatch's ``trimCurve:*`` as ``gprim["trim"]``; None when it has no loops."""
    counts = patch.GetTrimCurveCountsAttr().Get(time)
    if counts is None or not len(counts):
        return None

    def values(attr: Usd.Attribute, kind: type) -> list[Any]:
        value = attr.Get(time)
        if value is None:
            return []
        if kind is tuple:
            return [tuple(float(c) for c in v) for v in value]
        return [kind(v) for v in value]

    return {
        "counts": [int(c) for c in counts],
        "orders": values(patch.GetTrimCurveOrdersAttr(), int),
        "vertex_counts": values(patch.GetTrimCurveVertexCountsAttr(), int),
        "knots": values(patch.GetTrimCurveKnotsAttr(), float),
        "ranges": values(patch.GetTrimCurveRangesAttr(), tuple),
        "points": values(patch.GetTrimCurvePointsAttr(), tuple),
    }


def gprim_arguments(
    prim: Usd.Prim, time: Usd.TimeCode, transform: NDArray[np.float64]
) -> dict[str, Any] | None:
    """``set_mesh`` keyword arguments (without path and shading) of a non-mesh gprim.

    Returns None for a Points, curves or NurbsPatch prim without points (valid USD
    that renders nothing).

    Raises:
        PrimError: a size that is not a positive number (the message names the
            attribute), an ``axis`` that is not X, Y or Z, or a NurbsPatch's unauthored
            vertex count or order.

    """
    empty_i = np.zeros(0, dtype=np.int32)
    if prim.IsA(UsdGeom.Points):
        positions, gprim = _points(prim, time)
        if len(positions) == 0:
            return None
    elif any(prim.IsA(t) for t in CURVE_TYPES):
        if not prim.GetAttribute("points").Get(time):
            return None
        positions, gprim = curves_arguments(prim, time)
    elif prim.IsA(UsdGeom.NurbsPatch):
        if not prim.GetAttribute("points").Get(time):
            return None
        positions, gprim = _nurbs_patch(prim, time)
    else:
        positions, gprim = np.zeros((0, 3), dtype=np.float32), _shape(prim, time)
    gprim_schema = UsdGeom.Gprim(prim)
    return {
        "points": positions,
        "face_vertex_counts": empty_i,
        "face_vertex_indices": empty_i,
        "transform": transform,
        "scheme": "none",
        "left_handed": (gprim_schema.GetOrientationAttr().Get(time) or "rightHanded")
        == "leftHanded",
        "double_sided": bool(gprim_schema.GetDoubleSidedAttr().Get(time) or False),
        "gprim": gprim,
    }


def point_colors(
    prim: Usd.Prim, time: Usd.TimeCode, n_points: int, opacity: float = 1.0
) -> dict[str, Any]:
    """Per-point ``displayColor`` of a Points prim as ``set_mesh``'s face material table.

    Each point is a "face" of its own; ``{}`` when the prim has one colour
    (constant, or a single value). ``opacity`` is the prim's ``displayOpacity``.

    Raises:
        PrimError: a per-point ``displayColor`` whose length is not the point count.

    """
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
    if not primvar or not primvar.HasValue():
        return {}
    interpolation = primvar.GetInterpolation()
    if interpolation in (UsdGeom.Tokens.constant, UsdGeom.Tokens.uniform):
        return {}
    return _color_table(prim, primvar, time, n_points, "points", opacity)


def curve_colors(
    prim: Usd.Prim, time: Usd.TimeCode, n_curves: int, opacity: float = 1.0
) -> dict[str, Any]:
    """Per-curve (``uniform``) ``displayColor`` as ``set_mesh``'s face material table.

    Each curve is a "face" of its own; ``{}`` for any other interpolation (the prim's one
    colour, :func:`mipray.usd.material.compute_albedo`'s). ``opacity`` is the prim's
    ``displayOpacity``.
    """
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
    if not primvar or not primvar.HasValue():
        return {}
    if primvar.GetInterpolation() != UsdGeom.Tokens.uniform:
        return {}
    return _color_table(prim, primvar, time, n_curves, "curves", opacity)


def _color_table(
    prim: Usd.Prim,
    primvar: UsdGeom.Primvar,
    time: Usd.TimeCode,
    count: int,
    what: str,
    opacity: float,
) -> dict[str, Any]:
    """``set_mesh``'s face material table of ``primvar``'s colours, one per "face".

    The faces are the prim's ``count`` ``what`` (points or curves); ``{}`` for a single colour.

    Raises:
        PrimError: the colours are not ``count``.

    """
    values = np.asarray(primvar.ComputeFlattened(time) or [], dtype=np.float64).reshape(-1, 3)
    if len(values) <= 1:
        return {}
    if len(values) != count:
        raise PrimError(
            str(prim.GetPath()),
            f"primvars:displayColor ({primvar.GetInterpolation()}) has {len(values)} values "
            f"for {count} {what}",
        )
    unique, inverse = np.unique(np.clip(values, 0.0, 1.0), axis=0, return_inverse=True)
    path = str(prim.GetPath())
    # Rounded to float32 as the colours were when they crossed as an array.
    colours = np.ascontiguousarray(unique, dtype=np.float32)
    return {
        "face_materials": [lambertian(f"{path}[{k}]", c, opacity) for k, c in enumerate(colours)],
        "face_material_indices": np.ascontiguousarray(inverse.reshape(-1), dtype=np.int32),
    }
