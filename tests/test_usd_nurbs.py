"""NurbsPatch from USD: what crosses to the delegate, what is refused (one line naming the
prim and attribute, the rest renders), trim curves warned about, and a rational NURBS sphere
rendered against the closed-form sphere."""

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


def test_a_nurbs_patch_crosses_as_its_attributes(fake, caplog) -> None:
    stage = new_stage()
    patch = nurbs_sphere(stage, "/Ball")
    patch.CreateURangeAttr(Gf.Vec2d(0.0, 0.75))
    patch.CreateTrimCurveCountsAttr([1])
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
    # The prim type is rendered; its trim curves are listed and warned about once.
    assert [(u.prim, u.what) for u in scene.unsupported] == [
        ("/Ball", "NurbsPatch trim curves 1 loop(s)")
    ]
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [
        "mipray: /Ball: trimCurve:* (trim curves) are not applied; rendering the untrimmed surface"
    ]


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
