"""Implicit gprims and Points from USD: what crosses to the delegate, what is refused, and
renders of them (silhouettes against the closed form, instancing, the record command)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom

import mipray
from mipray import record
from mipray.usd import UsdSceneDelegate

from stages import add_camera, add_cube, add_distant_light, new_stage, pinhole_directions


def test_every_schema_attribute_crosses_to_the_delegate(fake) -> None:
    stage = new_stage()
    UsdGeom.Sphere.Define(stage, "/Sphere").CreateRadiusAttr(2.5)
    UsdGeom.Cube.Define(stage, "/Cube")  # schema fallback: size 2
    cyl = UsdGeom.Cylinder.Define(stage, "/Cyl")
    cyl.CreateRadiusAttr(0.5)
    cyl.CreateHeightAttr(3.0)
    cyl.CreateAxisAttr("X")
    UsdGeom.Cone.Define(stage, "/Cone").CreateAxisAttr("Y")
    UsdGeom.Capsule.Define(stage, "/Capsule")
    c1 = UsdGeom.Cylinder_1.Define(stage, "/Cyl1")
    c1.CreateRadiusTopAttr(0.25)
    c1.CreateRadiusBottomAttr(0.75)
    cap1 = UsdGeom.Capsule_1.Define(stage, "/Cap1")
    cap1.CreateRadiusTopAttr(0.1)
    plane = UsdGeom.Plane.Define(stage, "/Plane")
    plane.CreateWidthAttr(4.0)
    plane.CreateLengthAttr(6.0)
    plane.CreateAxisAttr("Y")
    UsdGeom.Gprim(plane).CreateOrientationAttr("leftHanded")
    pts = UsdGeom.Points.Define(stage, "/Points")
    pts.CreatePointsAttr([(0, 0, 0), (1, 2, 3)])
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert scene.delegate_errors == []
    got = {path: kw["gprim"] for path, kw in fake.meshes().items()}
    assert got["/Sphere"] == {"type": "Sphere", "radius": 2.5}
    assert got["/Cube"] == {"type": "Cube", "size": 2.0}
    assert got["/Cyl"] == {
        "type": "Cylinder",
        "radius_bottom": 0.5,
        "radius_top": 0.5,
        "height": 3.0,
        "axis": "X",
    }
    # USD's cone: radius 1 at the base, the apex along +axis.
    assert got["/Cone"] == {
        "type": "Cylinder",
        "radius_bottom": 1.0,
        "radius_top": 0.0,
        "height": 2.0,
        "axis": "Y",
    }
    assert got["/Capsule"] == {
        "type": "Capsule",
        "radius_bottom": 0.5,
        "radius_top": 0.5,
        "height": 1.0,
        "axis": "Z",
    }
    assert got["/Cyl1"]["radius_bottom"] == 0.75 and got["/Cyl1"]["radius_top"] == 0.25
    assert got["/Cap1"]["type"] == "Capsule" and got["/Cap1"]["radius_top"] == pytest.approx(0.1)
    assert got["/Plane"] == {"type": "Plane", "width": 4.0, "length": 6.0, "axis": "Y"}
    # Plane's doubleSided fallback is true in the schema; orientation crosses as for meshes.
    assert fake.meshes()["/Plane"]["double_sided"] is True
    assert fake.meshes()["/Plane"]["left_handed"] is True
    assert got["/Points"]["type"] == "Points"
    assert len(got["/Points"]["widths"]) == 0  # USD's default width 1, applied in the core
    np.testing.assert_array_equal(fake.meshes()["/Points"]["points"], [[0, 0, 0], [1, 2, 3]])


@pytest.mark.parametrize(
    "make, message",
    [
        (
            lambda s: UsdGeom.Sphere.Define(s, "/Bad").CreateRadiusAttr(0.0),
            "radius = 0 must be a positive number",
        ),
        (
            lambda s: UsdGeom.Cube.Define(s, "/Bad").CreateSizeAttr(-1.0),
            "size = -1 must be a positive number",
        ),
        (
            lambda s: UsdGeom.Cylinder.Define(s, "/Bad").CreateHeightAttr(0.0),
            "height = 0 must be a positive number",
        ),
        (
            lambda s: UsdGeom.Plane.Define(s, "/Bad").CreateLengthAttr(float("nan")),
            "length = nan must be a positive number",
        ),
        (
            lambda s: UsdGeom.Cone.Define(s, "/Bad").CreateRadiusAttr(float("inf")),
            "radius = inf must be a positive number",
        ),
    ],
)
def test_a_size_that_leaves_nothing_is_refused_by_name_and_the_rest_renders(
    fake, caplog, make, message
) -> None:
    stage = new_stage()
    make(stage)
    UsdGeom.Sphere.Define(stage, "/Good")
    with caplog.at_level(logging.ERROR, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    assert [str(e) for e in scene.delegate_errors] == [f"/Bad: {message}"]
    assert set(fake.meshes()) == {"/Good"}
    # One line, naming the prim.
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert errors == [f"mipray: skipping /Bad: {message}"]


def _render(stage, width: int, aovs: list[str], **settings) -> dict[str, np.ndarray]:
    """The AOVs of a render, one-channel ones as (h, w) arrays."""
    with mipray.RenderSession(stage) as session:
        r = session.render(
            "/World/Camera", width=width, aovs=aovs, settings=settings, camera_light=False
        )
    return {k: v[..., 0] if v.shape[-1] == 1 else v for k, v in r.aovs.items()}


def _camera(stage, eye=(0.0, 0.0, 8.0)) -> None:
    cam = add_camera(stage, "/World/Camera", eye=eye)
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)


def test_a_sphere_renders_its_closed_form_silhouette_and_depth(native) -> None:
    stage = new_stage()
    sphere = UsdGeom.Sphere.Define(stage, "/World/Ball")
    sphere.CreateRadiusAttr(1.5)
    sphere.AddTranslateOp().Set(Gf.Vec3d(0.4, -0.3, 0.0))
    _camera(stage)
    add_distant_light(stage, "/World/Sun")
    width = 48
    r = _render(stage, width, ["color", "depth", "alpha"])
    # The default-style camera: 50 mm lens, a 20 mm square film back at (0, 0, 8) looking
    # down -z; pixel centres at half-integers.
    d = pinhole_directions(width)
    o = np.array([0.0, 0.0, 8.0]) - np.array([0.4, -0.3, 0.0])
    b = d @ o
    disc = b * b - (o @ o - 1.5**2)
    clear = np.abs(disc) > 1e-3  # away from the silhouette through a pixel centre
    hit = disc > 0
    assert hit.sum() > 200
    np.testing.assert_array_equal(r["alpha"][clear] > 0.5, hit[clear])
    t = -b - np.sqrt(np.where(hit, disc, 0))
    depth = t * -d[..., 2]
    np.testing.assert_allclose(r["depth"][hit & clear], depth[hit & clear], rtol=1e-5)
    assert np.isfinite(r["color"]).all() and r["color"][hit].min() >= 0.0


def test_a_point_instancer_places_an_implicit_prototype_and_points_take_their_widths(
    native,
) -> None:
    stage = new_stage()
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    proto = UsdGeom.Sphere.Define(stage, "/World/PI/Protos/Ball")
    proto.CreateRadiusAttr(0.5)
    pi.CreatePrototypesRel().SetTargets([proto.GetPath()])
    pi.CreateProtoIndicesAttr([0, 0, 0])
    pi.CreatePositionsAttr([(-2.0, 0, 0), (0, 0, 0), (2.0, 0, 0)])
    pts = UsdGeom.Points.Define(stage, "/World/Dust")
    pts.CreatePointsAttr([(0.0, 2.0, 0.0), (0.0, -2.0, 0.0)])
    pts.CreateWidthsAttr([0.5, 1.5])
    pts.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    _camera(stage, eye=(0.0, 0.0, 20.0))
    add_distant_light(stage, "/World/Sun")
    width = 100
    r = _render(stage, width, ["alpha", "instanceId"])
    # Orthographic-ish check at this distance: coverage of each ball's centre pixel and of
    # the gaps between them; each width as the pixel span along its row.
    scale = width / (2 * 20.0 * 10.0 / 50.0)  # pixels per unit at the focal plane (z = 0)
    col = lambda x: int(width / 2 + x * scale)  # noqa: E731
    row = lambda y: int(width / 2 - y * scale)  # noqa: E731
    for x in (-2.0, 0.0, 2.0):
        assert r["alpha"][row(0), col(x)] == 1.0
    assert r["alpha"][row(0), col(1.0)] == 0.0
    ids = {float(v) for v in np.unique(r["instanceId"]) if v >= 0}
    assert len(ids) >= 4  # three instances and the points
    for y, w in ((2.0, 0.5), (-2.0, 1.5)):
        span = (r["alpha"][row(y)] > 0.5).sum() / scale
        assert abs(span - w) < 2.5 / scale, (y, span, w)


def test_a_stage_of_implicits_rendered_by_mipray_record_is_lit_and_skips_nothing(
    native, tmp_path: Path, capsys
) -> None:
    stage = new_stage()
    for k, (kind, t) in enumerate(
        [
            (UsdGeom.Sphere, (-3, 0, 0)),
            (UsdGeom.Cube, (-1, 0, 0)),
            (UsdGeom.Cylinder, (1, 0, 0)),
            (UsdGeom.Cone, (3, 0, 0)),
            (UsdGeom.Capsule, (-2, 2, 0)),
            (UsdGeom.Cylinder_1, (0, 2, 0)),
            (UsdGeom.Capsule_1, (2, 2, 0)),
        ]
    ):
        kind.Define(stage, f"/World/G{k}").AddTranslateOp().Set(Gf.Vec3d(*t))
    floor = UsdGeom.Plane.Define(stage, "/World/Floor")
    floor.CreateWidthAttr(10.0)
    floor.CreateLengthAttr(10.0)
    floor.AddTranslateOp().Set(Gf.Vec3d(0, 0, -1.5))
    pts = UsdGeom.Points.Define(stage, "/World/Dust")
    pts.CreatePointsAttr([(x * 0.5, -2.5, 0.0) for x in range(-6, 7)])
    _camera(stage, eye=(0.0, 0.0, 20.0))
    sun = add_distant_light(stage, "/World/Sun")
    sun.CreateAngleAttr(0.0)
    path = tmp_path / "implicits.usda"
    stage.GetRootLayer().Export(str(path))
    stats = tmp_path / "stats.json"
    code = record.main([str(path), str(tmp_path / "o.exr"), "-w", "64", "--stats", str(stats)])
    _, err = capsys.readouterr()
    assert code == 0
    assert "unsupported" not in err and "skipping" not in err, err
    s = json.loads(stats.read_text())
    assert s["prim_errors"] == [] and s["dropped_prims"] == []
    # 7 implicits, the plane and the points, every piece a patch intersected exactly: sphere
    # 1, cube 6, cylinder 3 (side, caps), cone 2, capsule 3, Cylinder_1 3, Capsule_1 3,
    # plane 1, 13 points; none tessellated.
    assert s["scene"]["instances"] == 9
    assert s["scene"]["subpatches"] == s["scene"]["exact_patches"] == 35
    assert s["scene"]["full_tessellation_vertices"] == 0
    r = _render(stage, 64, ["color", "alpha"])
    lit = r["color"][r["alpha"] > 0]
    assert lit.mean() > 0.05, "the implicits render lit, not black"


def test_points_widths_of_the_wrong_length_name_the_prim(native) -> None:
    stage = new_stage()
    pts = UsdGeom.Points.Define(stage, "/World/Dust")
    pts.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0)])
    pts.CreateWidthsAttr([0.1, 0.2])
    UsdGeom.Sphere.Define(stage, "/World/Good")
    scene = UsdSceneDelegate(stage, native.RenderDelegate())
    scene.sync()
    assert [str(e) for e in scene.delegate_errors] == [
        "/World/Dust: widths has 2 values for 3 points (want 1 or one per point)"
    ]


def test_per_point_display_colors_colour_each_point(native) -> None:
    stage = new_stage()
    pts = UsdGeom.Points.Define(stage, "/World/Dust")
    pts.CreatePointsAttr([(-1.5, 0, 0), (1.5, 0, 0)])
    pts.CreateWidthsAttr([2.0])
    primvar = UsdGeom.PrimvarsAPI(pts).CreatePrimvar(
        "displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex
    )
    primvar.Set([(1, 0, 0), (0, 0, 1)])
    _camera(stage)
    sun = add_distant_light(stage, "/World/Sun")
    sun.CreateAngleAttr(0.0)
    r = _render(stage, 40, ["color"])
    c = r["color"]
    left, right = c[20, 20 - 8], c[20, 20 + 8]
    assert left[0] > 10 * left[2] and right[2] > 10 * right[0], (left, right)


def test_native_instances_of_an_implicit_prototype_render(native) -> None:
    stage = new_stage()
    proto = stage.CreateClassPrim("/Proto")  # abstract: renders only through the instances
    UsdGeom.Sphere.Define(stage, "/Proto/Ball").CreateRadiusAttr(0.75)
    for k, x in enumerate((-2.0, 2.0)):
        inst = UsdGeom.Xform.Define(stage, f"/World/I{k}")
        inst.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
        inst.GetPrim().GetReferences().AddInternalReference(proto.GetPath())
        inst.GetPrim().SetInstanceable(True)
    add_cube(stage, "/World/Marker").AddTranslateOp().Set(Gf.Vec3d(0, 3, 0))
    _camera(stage, eye=(0.0, 0.0, 12.0))
    add_distant_light(stage, "/World/Sun")
    r = _render(stage, 60, ["alpha", "instanceId"])
    scale = 60 / (2 * 12.0 * 10.0 / 50.0)
    for x in (-2.0, 2.0):
        assert r["alpha"][30, int(30 + x * scale)] == 1.0
    assert r["alpha"][30, 30] == 0.0
