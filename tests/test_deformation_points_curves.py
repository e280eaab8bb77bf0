"""Deformation motion blur of Points and curves from USD (issue 18): their ``points`` (and
``widths``) sampled inside the shutter, or moved by ``velocities``, cross as samples over the
camera's shutter; a point or a curve slid by its points renders as the same prim slid by its
transform, a point whose width grows covers each pixel for the share of the shutter its radius
reaches it, and what cannot be blurred is one warning naming the prim, rendered at the frame's
time."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom
from test_motion_blur import sliding_stage

import mipray
from mipray.errors import PrimDataError
from mipray.usd import UsdSceneDelegate
from mipray.usd.curves import curves_arguments


def _stage(kind: str, how: str) -> Usd.Stage:
    """:func:`sliding_stage`'s camera (40 × 2 pixels of 0.1 units, shutter over frames 1 to 2)
    looking at one prim at /World/Slider, moved from x = −0.5 at frame 1 to 0.5 at frame 2:

    ``kind``: ``points`` (one point of width 1), ``curve`` (a linear BasisCurves along y of
    width 0.4) or ``nurbs`` (a NurbsCurves of order 4 along y, width 0.4);
    ``how``: ``points`` (its points sampled at both frames), ``velocities`` (one points
    sample, 24 units a second at 24 time codes a second) or ``transform`` (a translate op).
    """
    stage = sliding_stage((0.0, 1.0))
    stage.SetTimeCodesPerSecond(24.0)
    stage.RemovePrim("/World/Slider")
    if kind == "points":
        prim = UsdGeom.Points.Define(stage, "/World/Slider")
        rest = np.array([[0.0, 0.0, 0.0]])
        prim.CreateWidthsAttr([1.0])
    elif kind == "curve":
        prim = UsdGeom.BasisCurves.Define(stage, "/World/Slider")
        prim.CreateTypeAttr("linear")
        prim.CreateCurveVertexCountsAttr([2])
        prim.CreateWidthsAttr([0.4])
        prim.SetWidthsInterpolation("constant")
        rest = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    else:
        prim = UsdGeom.NurbsCurves.Define(stage, "/World/Slider")
        prim.CreateCurveVertexCountsAttr([4])
        prim.CreateOrderAttr([4])
        prim.CreateKnotsAttr([0, 0, 0, 0, 1, 1, 1, 1])
        prim.CreateWidthsAttr([0.4])
        prim.SetWidthsInterpolation("constant")
        rest = np.array([[0.0, -1.0, 0.0], [0.0, -0.3, 0.0], [0.0, 0.3, 0.0], [0.0, 1.0, 0.0]])

    def vec3s(dx: float) -> list[Gf.Vec3f]:
        return [Gf.Vec3f(float(p[0] + dx), float(p[1]), float(p[2])) for p in rest]

    points = prim.GetPointsAttr()
    if how == "points":
        points.Set(vec3s(-0.5), 1.0)
        points.Set(vec3s(0.5), 2.0)
    elif how == "velocities":
        points.Set(vec3s(-0.5), 1.0)
        prim.GetVelocitiesAttr().Set([Gf.Vec3f(24.0, 0, 0)] * len(rest), 1.0)
    else:
        points.Set(vec3s(0.0))
        op = prim.AddTranslateOp()
        op.Set(Gf.Vec3d(-0.5, 0, 0), 1.0)
        op.Set(Gf.Vec3d(0.5, 0, 0), 2.0)
    return stage


def deformations(fake, path: str = "/World/Slider") -> list:
    return [c for c in fake.calls_for(path) if c.method == "set_deformation"]


@pytest.mark.parametrize("kind", ["points", "curve", "nurbs"])
@pytest.mark.parametrize("how", ["points", "velocities"])
def test_moving_points_and_curves_cross_over_the_shutter(fake, kind: str, how: str) -> None:
    stage = _stage(kind, how)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    assert scene.update_motion("/Cam") == ["/World/Slider"]
    (call,) = deformations(fake)
    times, points = call.kwargs["times"], call.kwargs["points"]
    np.testing.assert_array_equal(times, [0.0, 1.0])
    (mesh,) = [c for c in fake.calls_for("/World/Slider") if c.method == "set_mesh"]
    sent = mesh.kwargs["points"]  # what the prim sends at frame 1 (x − 0.5)
    np.testing.assert_allclose(points[0], sent, atol=1e-6)
    np.testing.assert_allclose(points[1], sent + np.array([1.0, 0, 0]), atol=1e-6)
    assert "widths" not in call.kwargs  # widths do not change
    assert scene.unsupported == []


def test_a_nurbs_curve_s_samples_are_its_bezier_segments_at_each_time(fake) -> None:
    # The curve bends between the frames: each sample is the conversion of that time's points.
    stage = _stage("nurbs", "points")
    prim = stage.GetPrimAtPath("/World/Slider")
    bent = [(0.0, -1.0, 0.0), (0.8, -0.3, 0.0), (-0.8, 0.3, 0.0), (0.0, 1.0, 0.0)]
    UsdGeom.NurbsCurves(prim).GetPointsAttr().Set([Gf.Vec3f(*p) for p in bent], 2.0)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (call,) = deformations(fake)
    for k, frame in enumerate((1.0, 2.0)):
        want, _ = curves_arguments(prim, Usd.TimeCode(frame))
        np.testing.assert_allclose(call.kwargs["points"][k], want, atol=1e-6)


def test_widths_sampled_in_the_shutter_cross_with_the_points(fake) -> None:
    # Widths alone change: the points are sent at each widths sample too (still).
    stage = _stage("points", "transform")
    widths = UsdGeom.Points(stage.GetPrimAtPath("/World/Slider")).GetWidthsAttr()
    widths.Set([0.2], 1.0)
    widths.Set([1.0], 1.5)
    widths.Set([1.8], 2.0)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (call,) = deformations(fake)
    np.testing.assert_array_equal(call.kwargs["times"], [0.0, 0.5, 1.0])
    np.testing.assert_allclose(call.kwargs["widths"], [[0.2], [1.0], [1.8]], atol=1e-6)
    assert np.all(call.kwargs["points"] == 0.0)


def test_points_or_widths_changing_in_number_are_warned_once_and_not_blurred(fake, caplog) -> None:
    stage = _stage("points", "points")
    prim = UsdGeom.Points(stage.GetPrimAtPath("/World/Slider"))
    prim.GetPointsAttr().Set([Gf.Vec3f(0, 0, 0)] * 3, 2.0)
    stage2 = _stage("points", "points")
    widths = UsdGeom.Points(stage2.GetPrimAtPath("/World/Slider")).GetWidthsAttr()
    widths.Set([1.0], 1.0)
    widths.Set([1.0, 2.0], 2.0)
    for st, what in ((stage, "points change in number"), (stage2, "widths change in number")):
        caplog.clear()
        scene = UsdSceneDelegate(st, fake, time=1.0)
        scene.sync()
        with caplog.at_level(logging.WARNING, logger="mipray"):
            assert scene.update_motion("/Cam") == []
            scene.update_motion("/Cam")
        said = [r.getMessage() for r in caplog.records if "/World/Slider" in r.getMessage()]
        assert len(said) == 1 and what in said[0], said
        assert "rendering it at the frame's time without motion blur" in said[0]
        assert scene.unsupported == []
    assert deformations(fake) == []


def _alpha_and_color(stage: Usd.Stage, samples: int = 256) -> tuple[np.ndarray, np.ndarray]:
    out = mipray.render(
        stage, "/Cam", 40, aovs=["color", "alpha"], settings={"samples": samples}, time=1.0
    )
    return out.aovs["alpha"][..., 0], out.aovs["color"][..., 0]


def _pixel_mean(inside) -> np.ndarray:
    """The mean over each pixel of the 40 × 2 film (0.1 units; row 0 spans y 0 … 0.1) and the
    shutter of ``inside(x, y, t)``, on a 20 × 20 × 200 grid."""
    g = (np.arange(20) + 0.5) / 20
    t = ((np.arange(200) + 0.5) / 200)[:, None, None]
    out = np.zeros((2, 40))
    for row in range(2):
        y = (0.1 - 0.1 * (row + g))[None, :, None]
        for col in range(40):
            x = (-2.0 + 0.1 * (col + g))[None, None, :]
            out[row, col] = np.mean(inside(x, y, t))
    return out


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize("kind", ["points", "curve", "nurbs"])
@pytest.mark.parametrize("how", ["points", "velocities"])
def test_a_prim_moved_by_its_points_renders_as_one_moved_by_its_transform(
    kind: str, how: str
) -> None:
    alpha, color = _alpha_and_color(_stage(kind, how))
    alpha_t, color_t = _alpha_and_color(_stage(kind, "transform"))
    if kind == "points":  # a disc of radius 0.5 about (t − 0.5, 0)
        want = _pixel_mean(lambda x, y, t: (x - (t - 0.5)) ** 2 + y * y < 0.25)
    else:  # a band of half width 0.2 about x = t − 0.5
        want = _pixel_mean(lambda x, y, t: np.abs(x - (t - 0.5)) + 0 * y < 0.2)
    # 256 samples: 3 standard deviations of a half-covered pixel's estimate are 0.09.
    np.testing.assert_allclose(alpha, want, atol=0.06)
    # The same camera samples at the same times see the same surface.
    np.testing.assert_allclose(alpha, alpha_t, atol=2e-3)
    np.testing.assert_allclose(color, color_t, atol=2e-3 * color_t.max())


@pytest.mark.usefixtures("native")
def test_a_point_whose_width_grows_covers_each_pixel_once_its_radius_reaches_it() -> None:
    stage = _stage("points", "transform")
    prim = stage.GetPrimAtPath("/World/Slider")
    UsdGeom.Xformable(prim).ClearXformOpOrder()
    widths = UsdGeom.Points(prim).GetWidthsAttr()
    widths.Set([0.2], 1.0)
    widths.Set([1.8], 2.0)
    alpha, _ = _alpha_and_color(stage)
    want = _pixel_mean(lambda x, y, t: x * x + y * y < (0.1 + 0.8 * t) ** 2)
    np.testing.assert_allclose(alpha, want, atol=0.06)
    assert want.max() - want[want > 0].min() > 0.5  # a blur, not one size held


def test_the_delegate_refuses_bad_widths_in_one_line(native) -> None:
    delegate = native.RenderDelegate()
    empty = np.zeros(0, np.int32)
    common = dict(face_vertex_counts=empty, face_vertex_indices=empty, transform=np.eye(4))
    one = np.zeros((1, 3), np.float32)
    delegate.set_mesh("/P", points=one, gprim={"type": "Points", "widths": [1.0]}, **common)
    delegate.set_mesh(
        "/S", points=np.zeros((0, 3), np.float32), gprim={"type": "Sphere", "radius": 1.0}, **common
    )
    times, two = np.array([0.0, 1.0], np.float32), np.stack([one, one])
    cases = [
        ("/P", two, np.zeros((3, 1), np.float32), "2 deformation times for widths of shape (3, 1)"),
        ("/P", two, np.ones((2, 2), np.float32), "widths has 2 values for 1 points"),
        ("/P", two, np.array([[1.0], [-1.0]], np.float32), "widths[0] = -1"),
        ("/S", np.zeros((2, 0, 3), np.float32), np.ones((2, 1), np.float32), "without widths"),
    ]
    for path, points, widths, reason in cases:
        with pytest.raises(PrimDataError) as caught:
            delegate.set_deformation(path, times, points, widths)
        assert caught.value.prim_path == path
        assert reason in caught.value.reason, caught.value.reason
    delegate.set_deformation("/P", times, two, np.array([[1.0], [2.0]], np.float32))


def _growing_sphere(how: str) -> Usd.Stage:
    """:func:`_stage`'s camera over a sphere at the origin growing from radius 0.1 at frame 1
    to 0.9 at frame 2: an implicit ``Sphere`` (``radius`` sampled) or one point (``widths``
    sampled)."""
    stage = _stage("points", "transform")
    stage.RemovePrim("/World/Slider")
    if how == "sphere":
        radius = UsdGeom.Sphere.Define(stage, "/World/Ball").GetRadiusAttr()
        radius.Set(0.1, 1.0)
        radius.Set(0.9, 2.0)
    else:
        points = UsdGeom.Points.Define(stage, "/World/Ball")
        points.CreatePointsAttr([Gf.Vec3f(0, 0, 0)])
        points.GetWidthsAttr().Set([0.2], 1.0)
        points.GetWidthsAttr().Set([1.8], 2.0)
    return stage


def test_an_implicit_prim_s_sizes_cross_over_the_shutter(fake) -> None:
    stage = _growing_sphere("sphere")
    UsdGeom.Sphere(stage.GetPrimAtPath("/World/Ball")).GetRadiusAttr().Set(0.7, 1.25)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    assert scene.update_motion("/Cam") == ["/World/Ball"]
    (call,) = deformations(fake, "/World/Ball")
    np.testing.assert_array_equal(call.kwargs["times"], [0.0, 0.25, 1.0])
    assert call.kwargs["points"].shape == (3, 0, 3)
    radii = [g["radius"] for g in call.kwargs["gprims"]]
    assert [g["type"] for g in call.kwargs["gprims"]] == ["Sphere"] * 3
    np.testing.assert_allclose(radii, [0.1, 0.7, 0.9], atol=1e-6)
    assert scene.unsupported == []


def test_sizes_an_implicit_prim_cannot_take_within_the_shutter_are_one_warning(
    fake, caplog
) -> None:
    stage = _growing_sphere("sphere")
    UsdGeom.Sphere(stage.GetPrimAtPath("/World/Ball")).GetRadiusAttr().Set(0.0, 1.5)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    with caplog.at_level(logging.WARNING, logger="mipray"):
        assert scene.update_motion("/Cam") == []
        scene.update_motion("/Cam")
    said = [r.getMessage() for r in caplog.records if "/World/Ball" in r.getMessage()]
    assert said == [
        "mipray: /World/Ball: radius = 0 must be a positive number within the shutter; "
        "rendering it at the frame's time without motion blur"
    ], said
    assert deformations(fake, "/World/Ball") == []


@pytest.mark.usefixtures("native")
def test_a_sphere_whose_radius_grows_covers_each_pixel_once_its_radius_reaches_it() -> None:
    alpha, color = _alpha_and_color(_growing_sphere("sphere"))
    want = _pixel_mean(lambda x, y, t: x * x + y * y < (0.1 + 0.8 * t) ** 2)
    np.testing.assert_allclose(alpha, want, atol=0.06)
    # The same growth as a point's widths: the same spheres at the same times.
    alpha_p, color_p = _alpha_and_color(_growing_sphere("point"))
    np.testing.assert_allclose(alpha, alpha_p, atol=2e-3)
    np.testing.assert_allclose(color, color_p, atol=2e-3 * color_p.max())


def test_the_delegate_refuses_bad_implicit_samples_in_one_line(native) -> None:
    delegate = native.RenderDelegate()
    empty = np.zeros(0, np.int32)
    common = dict(face_vertex_counts=empty, face_vertex_indices=empty, transform=np.eye(4))
    none = np.zeros((0, 3), np.float32)
    cyl = {"type": "Cylinder", "radius_bottom": 1.0, "radius_top": 1.0, "height": 2.0}
    delegate.set_mesh("/C", points=none, gprim=cyl, **common)
    times, no_points = np.array([0.0, 1.0], np.float32), np.zeros((2, 0, 3), np.float32)
    cone = {**cyl, "radius_top": 0.0}
    cases = [
        (None, "0 shapes for 2 deformation samples of an implicit prim"),
        ([cyl, cone], "has other pieces than the first sample's"),
        ([cyl, {"type": "Sphere", "radius": 1.0}], "of another type or axis"),
        ([cyl, {**cyl, "height": -1.0}], "height = -1"),
    ]
    for gprims, reason in cases:
        with pytest.raises(PrimDataError) as caught:
            delegate.set_deformation("/C", times, no_points, None, gprims)
        assert caught.value.prim_path == "/C"
        assert reason in caught.value.reason, caught.value.reason
    delegate.set_deformation("/C", times, no_points, None, [cyl, {**cyl, "radius_top": 2.0}])


def _instanced_dust(kind: str) -> Usd.Stage:
    """Two instances, at x = −1 and 1, of a Points prim of one point of width 0.6 sliding
    by its points from −0.5 to 0.5 across the shutter and a sphere growing from radius 0.1 to
    0.3 at y = 0: a PointInstancer's prototype (``kind`` "points"), native instances of a
    class ("native") or (``kind`` "plain") the same prims under Xforms: the truth."""
    stage = _stage("points", "transform")
    stage.RemovePrim("/World/Slider")

    def prims(root: str) -> None:
        UsdGeom.Xform.Define(stage, root)
        dust = UsdGeom.Points.Define(stage, f"{root}/Dust")
        dust.CreateWidthsAttr([0.6])
        dust.GetPointsAttr().Set([Gf.Vec3f(-0.5, 0, 0)], 1.0)
        dust.GetPointsAttr().Set([Gf.Vec3f(0.5, 0, 0)], 2.0)
        ball = UsdGeom.Sphere.Define(stage, f"{root}/Ball").GetRadiusAttr()
        ball.Set(0.1, 1.0)
        ball.Set(0.3, 2.0)

    if kind == "points":
        pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
        prims("/World/PI/Protos/P")
        pi.CreatePrototypesRel().AddTarget("/World/PI/Protos/P")
        pi.CreateProtoIndicesAttr([0, 0])
        pi.CreatePositionsAttr([(-1, 0, 0), (1, 0, 0)])
    elif kind == "native":
        stage.DefinePrim("/Proto", "Xform").SetSpecifier(Sdf.SpecifierClass)
        prims("/Proto/P")
        for name, x in (("A", -1.0), ("B", 1.0)):
            inst = UsdGeom.Xform.Define(stage, f"/World/{name}")
            inst.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
            inst.GetPrim().GetReferences().AddInternalReference("/Proto")
            inst.GetPrim().SetInstanceable(True)
    else:
        for name, x in (("A", -1.0), ("B", 1.0)):
            prims(f"/World/{name}")
            UsdGeom.Xform(stage.GetPrimAtPath(f"/World/{name}")).AddTranslateOp().Set(
                Gf.Vec3d(x, 0, 0)
            )
    return stage


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize("kind", ["points", "native"])
def test_points_and_implicit_prims_deform_in_every_instance_of_a_prototype(kind: str) -> None:
    alpha, color = _alpha_and_color(_instanced_dust(kind))
    alpha_t, color_t = _alpha_and_color(_instanced_dust("plain"))
    want = _pixel_mean(
        lambda x, y, t: sum(
            ((x - c - (t - 0.5)) ** 2 + y * y < 0.09)
            | ((x - c) ** 2 + y * y < (0.1 + 0.2 * t) ** 2)
            for c in (-1.0, 1.0)
        )
    )
    np.testing.assert_allclose(alpha_t, want, atol=0.06)
    np.testing.assert_allclose(alpha, alpha_t, atol=2e-3)
    np.testing.assert_allclose(color, color_t, atol=2e-3 * color_t.max())
