"""Read ``UsdGeom.BasisCurves`` and ``UsdGeom.NurbsCurves`` into ``set_mesh`` arguments.

BasisCurves cross as authored (points, ``curveVertexCounts``, ``type``, ``basis``,
``wrap``, ``widths`` and ``normals`` with their interpolations); the core converts them
to Bézier segments and ray traces them as curves (``rust/src/curves.rs``). NurbsCurves are
converted here to cubic Bézier segments, one per knot span, and cross as a bezier
BasisCurves: each span's polynomial is evaluated at four parameters by de Boor's algorithm
and interpolated (exact for degree up to 3). A curve of higher degree or unusable knots is
drawn as its control polygon, as Storm draws every NurbsCurves, with one warning. Rational
curves (``pointWeights`` not all 1) are evaluated without their weights, with one warning.

What a curve looks like across: authored ``normals`` make it a ribbon facing them;
otherwise the constant token primvar ``primvars:mipray:curveStyle`` says ``tube`` (the
default) or ``ribbon`` (flat, facing each ray, as Storm draws ribbons without normals). A
renderer's own setting on a gprim is a primvar in its namespace, as Arnold's
``primvars:arnold:mode`` and RenderMan's ``primvars:ri:attributes:*`` are, so it inherits
and instances as primvars do. The attribute ``mipray:curveStyle`` that earlier versions read
is still accepted, with one deprecation warning naming the prim.

Bad input gets one line naming the prim and the attribute:

* ``curveVertexCounts`` that do not add up to the points: the prim is skipped (the
  delegate refuses it). One curve whose count the type, basis and wrap cannot make segments
  of is drawn as its control polygon (or left out below two vertices) by the core, warned.
* ``widths`` of the wrong length for their interpolation: the curves render at USD's
  fallback width 1 (warned); one value for vertex or varying interpolation is the constant
  width, as Storm reads it.
* ``normals`` of the wrong length: the curves render as tubes (warned).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom

from ..errors import PrimError
from .attributes import check_vertex_counts, read_array
from .warn import warn_once

__all__ = ["CURVE_STYLE", "CURVE_TYPES", "curves_arguments", "segment_end_count"]

_warn_once = warn_once(__name__)

#: The curve schemas that render.
CURVE_TYPES: tuple[type, ...] = (UsdGeom.BasisCurves, UsdGeom.NurbsCurves)


def segment_end_count(n: int, curve_type: str, basis: str, wrap: str) -> int:
    """How many ``varying`` values a curve of ``n`` vertices has (UsdGeomBasisCurves)."""
    if curve_type == "linear":
        return n
    if basis == "bezier":
        return n // 3 if wrap == "periodic" else (n - 4) // 3 + 2
    return n - 2 if wrap == "nonperiodic" else n


def _expected(interpolation: str, counts: NDArray[np.int32], kind: tuple[str, str, str]) -> int:
    if interpolation == "constant":
        return 1
    if interpolation == "uniform":
        return len(counts)
    if interpolation in ("varying", "faceVarying"):
        return sum(segment_end_count(int(n), *kind) for n in counts)
    return int(counts.sum())


def _put_checked(
    gprim: dict[str, Any],
    path: str,
    name: str,
    values: NDArray[Any],
    interpolation: str,
    counts: NDArray[np.int32],
    kind: tuple[str, str, str],
    fallback: str,
) -> bool:
    """Puts ``values`` in ``gprim`` (``name`` and ``name_interpolation``) if they fit.

    When they do not, warns (naming the fallback) and returns False.
    """
    want = _expected(interpolation, counts, kind)
    if len(values) == want:
        gprim[name] = values.tolist()
        gprim[f"{name}_interpolation"] = interpolation
        return True
    _warn_once(
        f"{path}: {name} has {len(values)} values but {interpolation} interpolation wants "
        f"{want}; {fallback}"
    )
    return False


def _basis_curves(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    points: NDArray[np.float32] | None,
    widths: NDArray[np.float32] | None,
) -> tuple[NDArray[np.float32], dict[str, Any]]:
    curves = UsdGeom.BasisCurves(prim)
    path = str(prim.GetPath())
    if points is None:
        points = read_array(curves.GetPointsAttr(), time, np.float32, 3)
    counts = read_array(curves.GetCurveVertexCountsAttr(), time, np.int32)
    curve_type = str(curves.GetTypeAttr().Get(time) or "cubic")
    basis = str(curves.GetBasisAttr().Get(time) or "bezier")
    wrap = str(curves.GetWrapAttr().Get(time) or "nonperiodic")
    kind = (curve_type, basis, wrap)
    gprim: dict[str, Any] = {
        "type": "Curves",
        "curve_vertex_counts": counts.tolist(),
        "curve_type": curve_type,
        "basis": basis,
        "wrap": wrap,
    }
    check_vertex_counts(path, counts, len(points))
    if widths is None:
        widths = read_array(curves.GetWidthsAttr(), time, np.float32)
    if len(widths):
        interpolation = str(curves.GetWidthsInterpolation())
        if len(widths) == 1 and interpolation in ("vertex", "varying"):
            # Storm's rule (HdSt_BasisCurvesPrimvarInterpolaterComputation): one value of a
            # vertex or varying primvar is the constant.
            interpolation = "constant"
        fallback = "using the fallback width 1"
        _put_checked(gprim, path, "widths", widths, interpolation, counts, kind, fallback)
    normals = read_array(curves.GetNormalsAttr(), time, np.float32, 3)
    style = _curve_style(prim, time)
    if len(normals):
        interpolation = str(curves.GetNormalsInterpolation())
        fallback = "rendering tubes instead"
        if _put_checked(gprim, path, "normals", normals, interpolation, counts, kind, fallback):
            style = "ribbon"
    gprim["style"] = style
    return points, gprim


#: The primvar that says how curves without normals look across, and the attribute it replaced.
CURVE_STYLE = "primvars:mipray:curveStyle"
_OLD_CURVE_STYLE = "mipray:curveStyle"


def _curve_style(prim: Usd.Prim, time: Usd.TimeCode) -> str:
    """``tube`` or ``ribbon``: :data:`CURVE_STYLE`, else the deprecated attribute (warned)."""
    path = str(prim.GetPath())
    name, value = CURVE_STYLE, None
    primvar = UsdGeom.PrimvarsAPI(prim).FindPrimvarWithInheritance("mipray:curveStyle")
    if primvar and primvar.HasValue():
        value = primvar.Get(time)
    else:
        old = prim.GetAttribute(_OLD_CURVE_STYLE)
        if old and old.HasValue():
            name, value = _OLD_CURVE_STYLE, old.Get(time)
            _warn_once(
                f"{path}: {_OLD_CURVE_STYLE} is deprecated: author the constant token primvar "
                f"{CURVE_STYLE} instead"
            )
    if value is None:
        return "tube"
    if not isinstance(value, str) and hasattr(value, "__len__"):
        # A token[] primvar: one value for the prim.
        value = value[0] if len(value) else "tube"
    style = str(value)
    if style not in ("tube", "ribbon"):
        _warn_once(f"{path}: {name} '{style}' is not tube or ribbon; using tube")
        return "tube"
    return style


def _de_boor(
    knots: NDArray[np.float64], cps: NDArray[np.float64], p: int, k: int, u: float
) -> NDArray[np.float64]:
    """The B-spline of degree ``p`` at ``u`` in knot span ``k`` (de Boor's algorithm)."""
    d: list[NDArray[np.float64]] = [
        np.array(cps[j + k - p], dtype=np.float64) for j in range(p + 1)
    ]
    for r in range(1, p + 1):
        for j in range(p, r - 1, -1):
            den = knots[j + 1 + k - r] - knots[j + k - p]
            alpha = 0.0 if den == 0 else (u - knots[j + k - p]) / den
            d[j] = (1.0 - alpha) * d[j - 1] + alpha * d[j]
    return d[p]


#: Bézier control points from a cubic's values at t = 0, 1/3, 2/3, 1 (the inverse of the
#: Bernstein matrix at those parameters).
_FROM_SAMPLES = np.linalg.inv(
    np.array(
        [
            [(1 - t) ** 3, 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t**2, t**3]
            for t in (0, 1 / 3, 2 / 3, 1)
        ]
    )
)


def _nurbs_to_bezier(
    path: str, cps: NDArray[np.float64], order: int, knots: NDArray[np.float64]
) -> NDArray[np.float64]:
    """One NURBS curve's cubic Bézier control points (3k + 1 for k spans)."""
    p = order - 1
    n = len(cps)
    if not 1 <= p <= 3:
        raise PrimError(path, f"order = {order}: curves of degree above 3 are not rendered")
    if len(knots) != n + order:
        raise PrimError(
            path,
            f"knots has {len(knots)} values for {n} points of order {order} (want {n + order})",
        )
    if np.any(np.diff(knots) < 0):
        raise PrimError(path, "knots decrease")
    out: list[NDArray[np.float64]] = []
    for k in range(p, n):
        a, b = knots[k], knots[k + 1]
        if not a < b:
            continue
        samples = np.array(
            [_de_boor(knots, cps, p, k, a + (b - a) * s) for s in (0, 1 / 3, 2 / 3, 1)]
        )
        bez = _FROM_SAMPLES @ samples
        out.extend(bez if not out else bez[1:])
    if not out:
        raise PrimError(path, "knots span no parameter range: nothing to render")
    return np.array(out)


def _polygon_to_bezier(cps: NDArray[np.float64]) -> NDArray[np.float64]:
    """A control polygon as cubic Bézier control points (3k + 1 for k edges).

    None for fewer than two points. How Storm draws every NurbsCurves
    (UsdImagingNurbsCurvesAdapter's linear basis curves), and how these curves are drawn when
    their knots cannot be used.
    """
    if len(cps) < 2:
        return np.zeros((0, cps.shape[1]))
    a, b = cps[:-1], cps[1:]
    thirds = np.stack([a, (2 * a + b) / 3, (a + 2 * b) / 3], axis=1).reshape(-1, cps.shape[1])
    return np.concatenate([thirds, cps[-1:]])


def _nurbs_curves(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    given_points: NDArray[np.float32] | None,
    given_widths: NDArray[np.float32] | None,
) -> tuple[NDArray[np.float32], dict[str, Any]]:
    curves = UsdGeom.NurbsCurves(prim)
    path = str(prim.GetPath())
    if given_points is None:
        points = read_array(curves.GetPointsAttr(), time, np.float64, 3)
    else:
        points = np.asarray(given_points, dtype=np.float64).reshape(-1, 3)
    counts = read_array(curves.GetCurveVertexCountsAttr(), time, np.int64)
    orders = read_array(curves.GetOrderAttr(), time, np.int64)
    knots = read_array(curves.GetKnotsAttr(), time, np.float64)
    check_vertex_counts(path, counts, len(points))
    if len(orders) != len(counts):
        raise PrimError(path, f"order has {len(orders)} values for {len(counts)} curves")
    weights = curves.GetPointWeightsAttr().Get(time)
    if weights is not None and len(weights) and not np.allclose(np.asarray(weights), 1.0):
        _warn_once(f"{path}: pointWeights (a rational curve) are not applied")
    if given_widths is None:
        widths = read_array(curves.GetWidthsAttr(), time, np.float64)
    else:
        widths = np.asarray(given_widths, dtype=np.float64)
    w_interp = str(curves.GetWidthsInterpolation()) if len(widths) else "constant"
    if len(widths) == 1 and w_interp in ("vertex", "varying"):
        w_interp = "constant"  # Storm's rule, as for BasisCurves
    if len(widths) and not (
        (w_interp == "constant" and len(widths) == 1)
        or (w_interp == "uniform" and len(widths) == len(counts))
        or (w_interp == "vertex" and len(widths) == len(points))
    ):
        _warn_once(
            f"{path}: widths has {len(widths)} values for {w_interp} interpolation "
            "(NurbsCurves: constant, uniform or vertex widths); using the fallback width 1"
        )
        widths = np.zeros(0)
    out_points: list[NDArray[np.float64]] = []
    out_widths: list[NDArray[np.float64]] = []
    out_counts: list[int] = []
    # A curve whose knots or order cannot be used is drawn as its control polygon, as Storm
    # draws every NurbsCurves, and named; one of fewer than two points is left out. The other
    # curves of the prim render as authored.
    want_knots = int(np.sum(counts + orders)) if len(counts) else 0
    all_polygons = len(knots) != want_knots
    as_polygon: list[str] = []
    left_out: list[int] = []
    if all_polygons:
        as_polygon.append(f"knots has {len(knots)} values (want {want_knots}): every curve")
    start, kstart = 0, 0
    for c, (count, order) in enumerate(zip(counts.tolist(), orders.tolist(), strict=True)):
        cps = points[start : start + count]
        w = widths[start : start + count].reshape(-1, 1) if w_interp == "vertex" else None
        bez = w_bez = None
        if not all_polygons:
            curve_knots = knots[kstart : kstart + count + order]
            try:
                bez = _nurbs_to_bezier(path, cps, order, curve_knots)
                if w is not None and len(widths):
                    w_bez = _nurbs_to_bezier(path, w, order, curve_knots).reshape(-1)
            except PrimError as e:
                if count >= 2:
                    as_polygon.append(f"curve {c}: {e.reason}")
        if bez is None:
            bez = _polygon_to_bezier(cps)
            if w is not None and len(widths):
                w_bez = _polygon_to_bezier(w).reshape(-1)
        if len(bez) == 0:
            left_out.append(c)
        else:
            out_points.append(bez)
            out_counts.append(len(bez))
            if w_bez is not None:
                out_widths.append(w_bez)
        start += count
        kstart += count + order
    if as_polygon:
        more = len(as_polygon) - 3
        shown = "; ".join(as_polygon[:3]) + (f"; and {more} more" if more > 0 else "")
        _warn_once(f"{path}: drawn as control polygons (as Storm draws NurbsCurves): {shown}")
    if left_out:
        _warn_once(
            f"{path}: {len(left_out)} curve(s) of fewer than 2 points left out: {left_out[:5]}"
        )
    if not out_points:
        raise PrimError(path, "no curve has two points: nothing to render")
    if w_interp == "uniform" and len(widths) and left_out:
        widths = np.delete(widths, left_out)
    gprim: dict[str, Any] = {
        "type": "Curves",
        "curve_vertex_counts": out_counts,
        "curve_type": "cubic",
        "basis": "bezier",
        "wrap": "nonperiodic",
        "style": "tube",
    }
    if len(widths):
        if w_interp == "vertex":
            gprim["widths"] = np.concatenate(out_widths).tolist()
        else:
            gprim["widths"] = widths.tolist()
        gprim["widths_interpolation"] = w_interp
    return np.concatenate(out_points).astype(np.float32), gprim


def curves_arguments(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    points: NDArray[np.float32] | None = None,
    widths: NDArray[np.float32] | None = None,
) -> tuple[NDArray[np.float32], dict[str, Any]]:
    """A curves prim's vertices and its ``gprim`` argument for ``set_mesh``.

    ``points`` and ``widths``: the prim's ``points`` and ``widths`` values to use instead of
    those at ``time`` (its samples across a shutter, :mod:`mipray.usd.deform`); every other
    attribute is read at ``time``.

    Raises:
        PrimError: the prim cannot be rendered (the message names the attribute).

    """
    if prim.IsA(UsdGeom.NurbsCurves):
        return _nurbs_curves(prim, time, points, widths)
    return _basis_curves(prim, time, points, widths)
