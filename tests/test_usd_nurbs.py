"""NurbsPatch from USD: what crosses to the delegate, what is refused (one line naming the
prim and attribute, the rest renders), trim curves crossing and cutting a hole (bad ones
warned about once, the surface untrimmed), and a rational NURBS sphere rendered against the
closed-form sphere."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from pxr import Gf, UsdGeom

import mipray
from mipray.usd import UsdSceneDelegate

from stages import HALF_TAN, add_camera, add_distant_light, new_stage, pinhole_directions

_H = math.sqrt(0.5)
_CIRCLE = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)]
_PROFILE = [(0, -1), (1, -1), (1, 0), (1, 1), (0, 1)]


def nurbs_sphere(stage, path: str, radius: float = 1.0) -> UsdGeom.NurbsPatch:
    """The sphere as a rational biquadratic NURBS: the nine-point circle swept pole to pole."""
    patch = UsdGeom.NurbsPatch.Define(stage, path)
    points, weights = [], []
    for j, (r, z) in enumerate(_PROFILE):
        for i, (x, y) in enumerate(_CIRCLE):
            points.append(Gf.Vec3f(radius * x * r, radius * y * r, radius * z))
            weights.append((_H if i % 2 else 1.0) * (_H if j % 2 else 1.0))
    patch.CreatePointsAttr(points)
    patch.CreatePointWeightsAttr(weights)
    patch.CreateUVertexCountAttr(9)
    patch.CreateVVertexCountAttr(5)
    patch.CreateUOrderAttr(3)
    patch.CreateVOrderAttr(3)
    patch.CreateUKnotsAttr([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])
    patch.CreateVKnotsAttr([0, 0, 0, 0.5, 0.5, 1, 1, 1])
    return patch


def add_trim(patch: UsdGeom.NurbsPatch, centre=(0.5, 0.5), radius=0.25, box=(0.0, 1.0)) -> None:
    """Trims ``patch`` to the square ``box``² of its parameters less the circle of ``radius``
    about ``centre``: the square's outline (order 2) and the exact rational circle (order 3,
    homogeneous points) as two loops."""
    lo, hi = box
    square = [(lo, lo), (hi, lo), (hi, hi), (lo, hi), (lo, lo)]
    points = [Gf.Vec3d(u, v, 1.0) for u, v in square]
    for i, (x, y) in enumerate(_CIRCLE):
        w = _H if i % 2 else 1.0
        points.append(Gf.Vec3d((centre[0] + radius * x) * w, (centre[1] + radius * y) * w, w))
    patch.CreateTrimCurveCountsAttr([1, 1])
    patch.CreateTrimCurveOrdersAttr([2, 3])
    patch.CreateTrimCurveVertexCountsAttr([5, 9])
    patch.CreateTrimCurveKnotsAttr(
        [0, 0, 1, 2, 3, 4, 4, *[0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]]
    )
    patch.CreateTrimCurveRangesAttr([Gf.Vec2d(0, 4), Gf.Vec2d(0, 1)])
    patch.CreateTrimCurvePointsAttr(points)


def test_a_nurbs_patch_crosses_as_its_attributes(fake, caplog) -> None:
    stage = new_stage()
    patch = nurbs_sphere(stage, "/Ball")
    patch.CreateURangeAttr(Gf.Vec2d(0.0, 0.75))
    add_trim(patch)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    assert scene.delegate_errors == []
    kw = fake.meshes()["/Ball"]
    g = kw["gprim"]
    assert g["type"] == "Nurbs"
    assert (g["u_vertex_count"], g["v_vertex_count"], g["u_order"], g["v_order"]) == (
        9,
        5,
        3,
        3,
    )
    assert g["u_knots"][3] == 0.25 and len(g["v_knots"]) == 8
    assert g["u_range"] == (0.0, 0.75) and "v_range" not in g
    assert g["weights"][1] == pytest.approx(_H)
    assert kw["points"].shape == (45, 3)
    # The trim curves cross as they are authored; nothing is unsupported or warned about.
    t = g["trim"]
    assert (t["counts"], t["orders"], t["vertex_counts"]) == ([1, 1], [2, 3], [5, 9])
    assert len(t["knots"]) == 19 and t["ranges"] == [(0.0, 4.0), (0.0, 1.0)]
    assert len(t["points"]) == 14 and t["points"][6] == pytest.approx((0.75 * _H, 0.75 * _H, _H))
    assert scene.unsupported == []
    assert [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING] == []


@pytest.mark.parametrize(
    ("spoil", "attribute"),
    [
        (lambda p: p.GetTrimCurveCountsAttr().Set([2, 1]), "trimCurve:orders has 2 values"),
        (
            lambda p: p.GetTrimCurveOrdersAttr().Set([2, 10]),
            "trimCurve:orders[1] = 10 is more than trimCurve:vertexCounts[1] = 9",
        ),
        (
            lambda p: p.GetTrimCurvePointsAttr().Set(
                [Gf.Vec3d(math.nan, 0, 1), *list(p.GetTrimCurvePointsAttr().Get())[1:]]
            ),
            "trimCurve:points[0] is not finite",
        ),
        (lambda p: p.GetTrimCurveKnotsAttr().Set([0, 1]), "trimCurve:knots has 2 values"),
    ],
)
def test_bad_trim_curves_are_one_warning_and_the_patch_renders_untrimmed(
    fake, caplog, spoil, attribute
) -> None:
    stage = new_stage()
    patch = nurbs_sphere(stage, "/World/Ball")
    add_trim(patch)
    spoil(patch)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
        scene.mark_all_dirty()
        scene.sync()  # warned once
    assert scene.delegate_errors == []
    assert "trim" not in fake.meshes()["/World/Ball"]["gprim"]
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1, warnings
    assert warnings[0].startswith(f"mipray: /World/Ball: {attribute}"), warnings
    assert warnings[0].endswith("; rendering the untrimmed surface"), warnings


def test_a_trimmed_square_renders_with_its_hole(native) -> None:
    """A bilinear NURBS square (u = x, v = y over [-1, 1]²) trimmed to its outline less a
    circle: seen from above, the pixels whose ray meets z = 0 inside the circle (or past the
    square) are empty and the rest covered, the circle's edge within a pixel's footprint."""
    stage = new_stage()
    patch = UsdGeom.NurbsPatch.Define(stage, "/World/Sheet")
    patch.CreatePointsAttr([(-1, -1, 0), (1, -1, 0), (-1, 1, 0), (1, 1, 0)])
    for attr in (patch.CreateUVertexCountAttr, patch.CreateVVertexCountAttr):
        attr(2)
    for attr in (patch.CreateUOrderAttr, patch.CreateVOrderAttr):
        attr(2)
    for attr in (patch.CreateUKnotsAttr, patch.CreateVKnotsAttr):
        attr([-1.0, -1.0, 1.0, 1.0])
    centre, radius = (0.2, -0.1), 0.55
    add_trim(patch, centre=centre, radius=radius, box=(-1.0, 1.0))
    cam = add_camera(stage, "/World/Camera", eye=(0.0, 0.0, 4.0))
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)
    add_distant_light(stage, "/World/Sun")
    width = 64
    with mipray.RenderSession(stage) as session:
        r = session.render("/World/Camera", width=width, aovs=["alpha"], camera_light=False)
    alpha = r.aovs["alpha"][..., 0]
    d = pinhole_directions(width)
    t = 4.0 / -d[..., 2]
    x, y = d[..., 0] * t, d[..., 1] * t
    footprint = 4.0 * 2 * HALF_TAN / width
    ring = np.hypot(x - centre[0], y - centre[1]) - radius
    edge = np.minimum(1 - np.abs(x), 1 - np.abs(y))
    clear = (np.abs(ring) > footprint) & (np.abs(edge) > footprint)
    kept = (ring > 0) & (edge > 0)
    assert (kept & clear).sum() > 1000 and (~kept & clear & (edge > 0)).sum() > 300
    np.testing.assert_array_equal(alpha[clear] > 0.5, kept[clear])


@pytest.mark.parametrize(
    ("spoil", "message"),
    [
        (
            lambda p: p.GetUKnotsAttr().Set([0, 0, 0, 1, 1, 1]),
            "uKnots has 6 values for uVertexCount 9 and uOrder 3 (want 12)",
        ),
        (
            lambda p: p.GetVVertexCountAttr().Set(6),
            "points has 45 values but uVertexCount × vVertexCount = 9 × 6",
        ),
        (
            lambda p: p.GetPointWeightsAttr().Set([0.0] * 45),
            "pointWeights[0] = 0 must be a positive number",
        ),
        (lambda p: p.GetUOrderAttr().Clear(), "uOrder is not authored"),
    ],
)
def test_bad_nurbs_are_refused_by_name_and_the_rest_renders(native, caplog, spoil, message) -> None:
    stage = new_stage()
    spoil(nurbs_sphere(stage, "/World/Bad"))
    good = nurbs_sphere(stage, "/World/Good")
    del good
    with caplog.at_level(logging.ERROR, logger="mipray"):
        scene = UsdSceneDelegate(stage, native.RenderDelegate())
        scene.sync()
    assert [str(e) for e in scene.delegate_errors] == [f"/World/Bad: {message}"]
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert errors == [f"mipray: skipping /World/Bad: {message}"]


def test_a_nurbs_sphere_renders_the_spheres_silhouette_and_depth(native) -> None:
    stage = new_stage()
    ball = nurbs_sphere(stage, "/World/Ball", radius=1.5)
    ball.AddTranslateOp().Set(Gf.Vec3d(0.4, -0.3, 0.0))
    cam = add_camera(stage, "/World/Camera", eye=(0.0, 0.0, 8.0))
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)
    add_distant_light(stage, "/World/Sun")
    width = 48
    with mipray.RenderSession(stage) as session:
        r = session.render(
            "/World/Camera",
            width=width,
            aovs=["color", "depth", "alpha"],
            camera_light=False,
        )
    alpha, depth = r.aovs["alpha"][..., 0], r.aovs["depth"][..., 0]
    # 50 mm lens, 20 mm film back at (0, 0, 8) looking down -z; pixel centres at half-integers.
    d = pinhole_directions(width)
    o = np.array([0.0, 0.0, 8.0]) - np.array([0.4, -0.3, 0.0])
    b = d @ o
    closest = np.sqrt(np.maximum(o @ o - b * b, 0.0))
    # A pixel's footprint at the sphere: the beam width the tessellation's chord error stays
    # within; pixels whose centre ray passes nearer the silhouette than that are left out.
    footprint = 8.0 * 2 * HALF_TAN / width
    clear = np.abs(closest - 1.5) > footprint
    hit = closest < 1.5
    assert (hit & clear).sum() > 200
    np.testing.assert_array_equal(alpha[clear] > 0.5, hit[clear])
    disc = np.where(hit, b * b - (o @ o - 1.5**2), 0.0)
    want = (-b - np.sqrt(disc)) * -d[..., 2]
    inside = hit & clear
    assert np.abs(depth[inside] - want[inside]).max() <= footprint
    assert np.isfinite(r.aovs["color"]).all()
    assert r.aovs["color"][inside].mean() > 0.05, "lit, not black"
