"""BasisCurves and NurbsCurves from USD: what crosses to the delegate, NURBS converted to
Bézier segments against a direct B-spline evaluation, bad input (one line naming the prim
and the attribute, the prim skipped or falling back), and renders (a tube's width on screen
against the pinhole camera, per-curve colours)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

import mipray
from mipray.usd import UsdSceneDelegate
from mipray.usd.curves import _nurbs_to_bezier, curves_arguments

from stages import add_camera, add_distant_light, new_stage


def _bezier(c: np.ndarray, t: float) -> np.ndarray:
    s = 1 - t
    return s**3 * c[0] + 3 * s * s * t * c[1] + 3 * s * t * t * c[2] + t**3 * c[3]


def _cox_de_boor(knots: np.ndarray, i: int, p: int, u: float) -> float:
    """The B-spline basis function N_{i,p}(u), by its recursive definition (half-open spans)."""
    if p == 0:
        return 1.0 if knots[i] <= u < knots[i + 1] else 0.0
    out = 0.0
    if knots[i + p] > knots[i]:
        out += (u - knots[i]) / (knots[i + p] - knots[i]) * _cox_de_boor(knots, i, p - 1, u)
    if knots[i + p + 1] > knots[i + 1]:
        out += (
            (knots[i + p + 1] - u)
            / (knots[i + p + 1] - knots[i + 1])
            * _cox_de_boor(knots, i + 1, p - 1, u)
        )
    return out


@pytest.mark.parametrize(
    ("order", "knots"),
    [
        (4, [0, 0, 0, 0, 1, 2, 3, 3, 3, 3]),  # clamped cubic, 3 spans
        (4, [0, 1, 2, 3, 4, 5, 6, 7, 8, 9]),  # uniform unclamped cubic
        (3, [0, 0, 0, 1, 1.5, 3, 4, 4, 4]),  # quadratic, uneven knots
        (2, [0, 0, 1, 2, 3, 4, 5, 5]),  # linear
    ],
)
def test_nurbs_become_bezier_segments_on_the_same_curve(order, knots) -> None:
    rng = np.random.default_rng(3)
    knots = np.asarray(knots, dtype=np.float64)
    n = len(knots) - order
    cps = rng.uniform(-2, 2, (n, 3))
    bez = _nurbs_to_bezier("/N", cps, order, knots)
    assert (len(bez) - 1) % 3 == 0
    p = order - 1
    spans = [(knots[k], knots[k + 1]) for k in range(p, n) if knots[k] < knots[k + 1]]
    assert (len(bez) - 1) // 3 == len(spans)
    for s, (a, b) in enumerate(spans):
        seg = bez[3 * s : 3 * s + 4]
        for t in (0.0, 0.2, 0.5, 0.9):
            u = a + (b - a) * t
            want = sum(_cox_de_boor(knots, i, p, u) * cps[i] for i in range(n))
            np.testing.assert_allclose(_bezier(seg, t), want, atol=1e-9)


def test_basis_curves_attributes_cross_to_the_delegate(fake) -> None:
    stage = new_stage()
    c = UsdGeom.BasisCurves.Define(stage, "/Hair")
    c.CreatePointsAttr([(0, 0, 0), (0, 1, 0), (1, 2, 0), (1, 3, 0), (5, 0, 0), (5, 1, 0)])
    c.CreateCurveVertexCountsAttr([4, 2])
    c.CreateTypeAttr("linear")
    c.CreateWidthsAttr([0.1, 0.2])
    c.SetWidthsInterpolation("uniform")
    r = UsdGeom.BasisCurves.Define(stage, "/Ribbon")
    r.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)])
    r.CreateCurveVertexCountsAttr([4])
    r.CreateBasisAttr("catmullRom")
    r.CreateWrapAttr("pinned")
    r.CreateNormalsAttr([(0, 0, 1)] * 4)
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert scene.delegate_errors == []
    hair = fake.meshes()["/Hair"]["gprim"]
    assert hair["type"] == "Curves" and hair["curve_type"] == "linear"
    assert hair["curve_vertex_counts"] == [4, 2]
    assert hair["widths"] == pytest.approx([0.1, 0.2])
    assert hair["widths_interpolation"] == "uniform"
    assert hair["style"] == "tube"
    ribbon = fake.meshes()["/Ribbon"]["gprim"]
    assert (ribbon["basis"], ribbon["wrap"], ribbon["style"]) == ("catmullRom", "pinned", "ribbon")
    assert ribbon["normals_interpolation"] == "vertex"


def _line(stage, path: str) -> UsdGeom.BasisCurves:
    c = UsdGeom.BasisCurves.Define(stage, path)
    c.CreatePointsAttr([(0, 0, 0), (1, 0, 0)])
    c.CreateCurveVertexCountsAttr([2])
    c.CreateTypeAttr("linear")
    return c


def test_curve_style_is_a_primvar_and_the_old_attribute_is_deprecated(fake, caplog) -> None:
    stage = new_stage()
    api = UsdGeom.PrimvarsAPI
    new = _line(stage, "/New").GetPrim()
    api(new).CreatePrimvar("mipray:curveStyle", Sdf.ValueTypeNames.Token, "constant").Set("ribbon")
    old = _line(stage, "/Old").GetPrim()
    old.CreateAttribute("mipray:curveStyle", Sdf.ValueTypeNames.Token).Set("ribbon")
    both = _line(stage, "/Both").GetPrim()
    both.CreateAttribute("mipray:curveStyle", Sdf.ValueTypeNames.Token).Set("ribbon")
    api(both).CreatePrimvar("mipray:curveStyle", Sdf.ValueTypeNames.Token, "constant").Set("tube")
    bad = _line(stage, "/Bad").GetPrim()
    api(bad).CreatePrimvar("mipray:curveStyle", Sdf.ValueTypeNames.Token, "constant").Set("flat")
    # The primvar inherits as primvars do: from an ancestor.
    group = UsdGeom.Xform.Define(stage, "/Group").GetPrim()
    api(group).CreatePrimvar("mipray:curveStyle", Sdf.ValueTypeNames.Token, "constant").Set(
        "ribbon"
    )
    _line(stage, "/Group/Child")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
        scene.mark_all_dirty()
        scene.sync()  # warned once
    style = {p: kw["gprim"]["style"] for p, kw in fake.meshes().items()}
    assert style == {
        "/New": "ribbon",
        "/Old": "ribbon",
        "/Both": "tube",
        "/Bad": "tube",
        "/Group/Child": "ribbon",
    }
    warnings = sorted(r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)
    assert warnings == [
        "mipray: /Bad: primvars:mipray:curveStyle 'flat' is not tube or ribbon; using tube",
        "mipray: /Old: mipray:curveStyle is deprecated: author the constant token primvar "
        "primvars:mipray:curveStyle instead",
    ]


def test_wrong_counts_skip_the_prim_and_wrong_widths_fall_back_by_name(native, caplog) -> None:
    stage = new_stage()
    bad = UsdGeom.BasisCurves.Define(stage, "/World/BadCounts")
    bad.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (4, 0, 0)])
    bad.CreateCurveVertexCountsAttr([6])  # 6 vertices of 5 points
    wide = UsdGeom.BasisCurves.Define(stage, "/World/BadWidths")
    wide.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)])
    wide.CreateCurveVertexCountsAttr([4])
    wide.CreateWidthsAttr([0.1, 0.2, 0.3])  # vertex wants 4
    UsdGeom.Sphere.Define(stage, "/World/Good")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, native.RenderDelegate())
        scene.sync()
    assert [str(e) for e in scene.delegate_errors] == [
        "/World/BadCounts: curveVertexCounts add up to 6 vertices but points has 5"
    ]
    lines = [r.getMessage() for r in caplog.records if "BadWidths" in r.getMessage()]
    assert lines == [
        "mipray: /World/BadWidths: widths has 3 values but vertex interpolation wants 4; "
        "using the fallback width 1"
    ]


def _two_curve_prims(fallback: bool):
    stage = new_stage()
    poly = UsdGeom.BasisCurves.Define(stage, "/World/Polygon")
    poly.CreateTypeAttr("cubic" if fallback else "linear")
    poly.CreateBasisAttr("bezier")
    poly.CreatePointsAttr([(-3, -2, 0), (-3, 2, 0), (-1, 2, 0), (-1, -2, 0), (1, -2, 0)])
    poly.CreateCurveVertexCountsAttr([5])
    pinned = UsdGeom.BasisCurves.Define(stage, "/World/Pinned")
    pinned.CreateTypeAttr("cubic")
    pinned.CreateBasisAttr("bspline")
    pinned.CreateWrapAttr("pinned")
    good = [(2, -2, 0), (2, 2, 0), (3, 2, 0)]
    pinned.CreatePointsAttr([*good, (3, -2, 0)] if fallback else good)
    pinned.CreateCurveVertexCountsAttr([3, 1] if fallback else [3])
    for c in (poly, pinned):
        c.CreateWidthsAttr([0.3])
        c.SetWidthsInterpolation("constant")
    add_camera(stage, "/World/Camera", eye=(0.0, 0.0, 12.0))
    add_distant_light(stage, "/World/Sun")
    return stage


def test_one_curve_its_basis_cannot_use_does_not_take_the_others_with_it(native, caplog) -> None:
    # As Storm draws OpenUSD's testUsdImagingGLBasisCurvesVaryingTopology (bezier curves of
    # 8 and 13 vertices) and testUsdImagingGLCurves/pinnedCurves (a pinned curve of one vertex
    # beside good ones): the bezier curve of 5 vertices is its control polygon, the pinned
    # curve of 1 is left out, the rest render, and each prim is named once (and in the stats).
    # The image is the one of the same curves authored as a linear curve and without the
    # pinned curve of one vertex.
    with caplog.at_level(logging.WARNING, logger="mipray"):
        with mipray.RenderSession(_two_curve_prims(True)) as session:
            r = session.render(
                "/World/Camera", width=64, aovs=["color", "alpha"], camera_light=False
            )
    warned = sorted(m.getMessage() for m in caplog.records if "curve(s)" in m.getMessage())
    assert len(warned) == 2, warned
    assert (
        warned[0].startswith("/World/Pinned: 1 curve(s) left out")
        and "curve 1 has 1 vertices" in warned[0]
    )
    assert warned[1].startswith("/World/Polygon: 1 curve(s) drawn as their control polygons")
    assert "curve 0 has 5 vertices; a bezier curve needs 4 + 3k" in warned[1]
    assert sorted(r.stats["scene"]["simplified"]) == warned
    with mipray.RenderSession(_two_curve_prims(False)) as session:
        want = session.render(
            "/World/Camera", width=64, aovs=["color", "alpha"], camera_light=False
        )
    assert want.stats["scene"]["simplified"] == []
    assert r.aovs["alpha"].sum() > 50
    np.testing.assert_array_equal(r.aovs["alpha"], want.aovs["alpha"])
    np.testing.assert_array_equal(r.aovs["color"], want.aovs["color"])


def _render(stage, width: int, aovs: list[str]) -> dict[str, np.ndarray]:
    with mipray.RenderSession(stage) as session:
        r = session.render("/World/Camera", width=width, aovs=aovs, camera_light=False)
    return {k: v[..., 0] if v.shape[-1] == 1 else v for k, v in r.aovs.items()}


def test_a_tube_covers_the_pixels_a_pinhole_camera_predicts(native) -> None:
    # A vertical tube of width w, 8 units in front of a 50 mm lens with a 20 mm film back:
    # its silhouette is the tangents at asin(r / 8), so it covers 2·50·tan(asin(r / 8)) mm
    # of the film's 20 mm.
    stage = new_stage()
    w = 0.4
    c = UsdGeom.BasisCurves.Define(stage, "/World/Tube")
    c.CreatePointsAttr([(0, -3, 0), (0, -1, 0), (0, 1, 0), (0, 3, 0)])
    c.CreateCurveVertexCountsAttr([4])
    c.CreateWidthsAttr([w])
    c.SetWidthsInterpolation("constant")
    cam = add_camera(stage, "/World/Camera", eye=(0.0, 0.0, 8.0))
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)
    add_distant_light(stage, "/World/Sun")
    width = 200
    r = _render(stage, width, ["color", "alpha"])
    span = 2 * 50 * np.tan(np.arcsin(w / 2 / 8)) / 20 * width  # pixels
    # One sample a pixel, at its centre: the centres within the span are covered.
    centres = np.arange(width) + 0.5 - width / 2
    predicted = np.abs(centres) < span / 2
    for row in range(width // 2 - 20, width // 2 + 20):
        np.testing.assert_array_equal(r["alpha"][row] > 0.5, predicted)
    assert predicted.sum() == 26  # 25.008 pixels wide, centred on a pixel boundary
    lit = r["color"][r["alpha"] > 0.99]
    assert np.isfinite(r["color"]).all() and lit.mean() > 0.01


def test_nurbs_curves_and_uniform_colours_render(native) -> None:
    stage = new_stage()
    n = UsdGeom.NurbsCurves.Define(stage, "/World/Nurbs")
    n.CreatePointsAttr([(-3, -1, 0), (-1, 1, 0), (1, -1, 0), (3, 1, 0), (-3, 1, 0), (3, 1.5, 0)])
    n.CreateCurveVertexCountsAttr([4, 2])
    n.CreateOrderAttr([4, 2])
    n.CreateKnotsAttr([0, 0, 0, 0, 1, 1, 1, 1, 0, 0, 1, 1])
    n.CreateWidthsAttr([0.3])
    n.SetWidthsInterpolation("constant")
    primvar = UsdGeom.PrimvarsAPI(n).CreatePrimvar(
        "displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.uniform
    )
    primvar.Set([(1, 0, 0), (0, 0, 1)])
    cam = add_camera(stage, "/World/Camera", eye=(0.0, 0.0, 8.0))
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)
    sun = add_distant_light(stage, "/World/Sun")
    sun.CreateAngleAttr(0.0)
    width = 100
    r = _render(stage, width, ["color", "alpha"])
    assert r["alpha"].sum() > 100
    # The cubic through (0, 0) is red at the image centre; the straight one at y ≈ 1.25 blue.
    centre = r["color"][width // 2, width // 2]
    assert centre[0] > 10 * centre[2], centre
    row = round(width / 2 - 1.25 / (8 * 10 / 50) * width / 2)
    blue = r["color"][row - 1 : row + 2, width // 2 + 20].max(axis=0)
    assert blue[2] > 10 * blue[0], blue


def test_nurbs_curves_whose_knots_cannot_be_used_are_drawn_as_their_control_polygons(
    caplog,
) -> None:
    # OpenUSD's testUsdImagingGLNurbsCurves/testCurves.usda authors curves without knots; Storm
    # draws every NurbsCurves as its control polygon. Here: no knots at all (every curve a
    # polygon), then one curve of two with decreasing knots (only it a polygon), and a curve of
    # one point (left out).
    stage = new_stage()
    pts = [(-3, -1, 0), (-1, 1, 0), (1, -1, 0), (3, 1, 0), (-3, 1, 0), (3, 1.5, 0), (9, 9, 9)]
    n = UsdGeom.NurbsCurves.Define(stage, "/World/NoKnots")
    n.CreatePointsAttr(pts[:6])
    n.CreateCurveVertexCountsAttr([4, 2])
    n.CreateOrderAttr([4, 2])
    with caplog.at_level(logging.WARNING, logger="mipray"):
        points, gprim = curves_arguments(n.GetPrim(), Usd.TimeCode.Default())
    assert gprim["curve_vertex_counts"] == [10, 4]
    a, b = np.array(pts[0]), np.array(pts[1])
    np.testing.assert_allclose(points[:4], [a, (2 * a + b) / 3, (a + 2 * b) / 3, b], atol=1e-6)
    np.testing.assert_allclose(points[9], pts[3])
    np.testing.assert_allclose(points[[10, 13]], [pts[4], pts[5]])
    assert any(
        "/World/NoKnots: drawn as control polygons" in r.getMessage()
        and "knots has 0 values (want 12)" in r.getMessage()
        for r in caplog.records
    )

    m = UsdGeom.NurbsCurves.Define(stage, "/World/OneBad")
    m.CreatePointsAttr(pts)
    m.CreateCurveVertexCountsAttr([4, 2, 1])
    m.CreateOrderAttr([4, 2, 1])
    m.CreateKnotsAttr([0, 0, 0, 0, 1, 1, 1, 1, 1, 0, 0, 0, 0, 1])  # the second curve's decrease
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="mipray"):
        points, gprim = curves_arguments(m.GetPrim(), Usd.TimeCode.Default())
    exact = _nurbs_to_bezier(
        "/N", np.array(pts[:4], float), 4, np.array([0, 0, 0, 0, 1, 1, 1, 1.0])
    )
    assert gprim["curve_vertex_counts"] == [4, 4]
    np.testing.assert_allclose(points[:4], exact, atol=1e-6)
    messages = [r.getMessage() for r in caplog.records]
    assert any("curve 1: knots decrease" in t for t in messages), messages
    assert any("1 curve(s) of fewer than 2 points left out: [2]" in t for t in messages), messages


@pytest.mark.parametrize("interpolation", ["vertex", "varying"])
def test_one_width_for_vertex_or_varying_interpolation_is_the_constant_width(
    native, caplog, interpolation: str
) -> None:
    # Storm reads one value of a vertex or varying primvar as the constant (OpenUSD's imaging
    # test stages author widths = [w] with the schema's vertex interpolation).
    stage = new_stage()
    curve = UsdGeom.BasisCurves.Define(stage, "/World/Curve")
    curve.CreateTypeAttr("linear")
    curve.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)])
    curve.CreateCurveVertexCountsAttr([4])
    curve.CreateWidthsAttr([0.25])
    curve.SetWidthsInterpolation(interpolation)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        _, gprim = curves_arguments(stage.GetPrimAtPath("/World/Curve"), Usd.TimeCode.Default())
    assert (gprim["widths"], gprim["widths_interpolation"]) == ([0.25], "constant")
    assert not [r for r in caplog.records if "Curve" in r.getMessage()]
