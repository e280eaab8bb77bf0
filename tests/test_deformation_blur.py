"""Deformation motion blur from USD (issue 18, part 3): time-sampled ``points`` and skinned
meshes cross as their points over the camera's shutter; a quad slid by its points renders as
the same quad slid by its transform; a skinned arm bending across the shutter covers the
pixels it sweeps for the share of the shutter UsdSkel's pose covers them; points that do not
change render bit-identically to a still mesh."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom
from test_motion_blur import QUAD, sliding_stage
from test_usd_nurbs import nurbs_sphere
from test_usd_skel import ELBOW, arm, bent

import mipray
from mipray.errors import PrimDataError
from mipray.usd import UsdSceneDelegate
from mipray.usd.skel import SkelPoser

from stages import CUBE_POINTS, add_camera, add_cube, add_distant_light, new_stage


def deforming_stage(shutter: tuple[float, float] | None, *, still: bool = False) -> Usd.Stage:
    """:func:`sliding_stage`'s quad, its transform fixed and its points moved instead (from
    x − 0.5 at frame 1 to x + 0.5 at frame 2), or with ``still`` its points time-sampled
    but the same at both frames."""
    stage = sliding_stage(shutter)
    stage.RemovePrim("/World/Slider")
    quad = add_cube(stage, "/World/Slider", scheme="none", **QUAD)
    points = quad.GetPointsAttr()
    rest = np.array(QUAD["points"], dtype=np.float32)
    points.Clear()
    for frame, dx in ((1.0, -0.5), (2.0, 0.5)):
        shift = np.array([0.0 if still else dx, 0.0, 0.0], dtype=np.float32)
        points.Set([Gf.Vec3f(*map(float, p)) for p in rest + shift], frame)
    return stage


def deformations(fake, path: str) -> list:
    return [c for c in fake.calls_for(path) if c.method == "set_deformation"]


def test_time_sampled_points_cross_over_the_shutter(fake) -> None:
    scene = UsdSceneDelegate(deforming_stage((0.0, 1.0)), fake, time=1.0)
    scene.sync()
    assert scene.update_motion("/Cam") == ["/World/Slider"]
    (call,) = deformations(fake, "/World/Slider")
    times, points = call.kwargs["times"], call.kwargs["points"]
    np.testing.assert_array_equal(times, [0.0, 1.0])
    rest = np.array(QUAD["points"], dtype=np.float32)
    np.testing.assert_allclose(points[0], rest + np.array([-0.5, 0, 0]), atol=1e-6)
    np.testing.assert_allclose(points[1], rest + np.array([0.5, 0, 0]), atol=1e-6)
    assert scene.unsupported == []


def test_still_points_a_closed_shutter_or_a_stopped_mesh_send_no_samples(fake) -> None:
    scene = UsdSceneDelegate(deforming_stage((0.0, 1.0), still=True), fake, time=1.0)
    scene.sync()
    assert scene.update_motion("/Cam") == []
    assert deformations(fake, "/World/Slider") == []
    stage = deforming_stage((0.0, 1.0))
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    UsdGeom.Camera(stage.GetPrimAtPath("/Cam")).GetShutterCloseAttr().Set(0.0)
    scene.sync()
    assert scene.update_motion("/Cam") == []
    assert len(deformations(fake, "/World/Slider")[-1].kwargs["times"]) == 0


def test_points_changing_in_number_within_the_shutter_are_warned_and_not_blurred(
    fake, caplog
) -> None:
    stage = deforming_stage((0.0, 1.0))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Slider")).GetPointsAttr()
    points.Set([Gf.Vec3f(0, 0, 0)] * 5, 2.0)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    with caplog.at_level(logging.WARNING, logger="mipray"):
        assert scene.update_motion("/Cam") == []
    assert deformations(fake, "/World/Slider") == []
    said = [r.getMessage() for r in caplog.records if "/World/Slider" in r.getMessage()]
    assert said == [
        "mipray: /World/Slider: points change in number within the shutter (another "
        "topology); rendering it at the frame's time without motion blur"
    ]


def test_a_skinned_arm_crosses_posed_across_the_shutter(fake) -> None:
    stage = new_stage()
    mesh = arm(stage)
    cam = add_camera(stage, "/World/Camera")
    cam.CreateShutterOpenAttr(0.0)
    cam.CreateShutterCloseAttr(1.0)
    scene = UsdSceneDelegate(stage, fake, time=1)
    scene.sync()
    assert scene.unsupported == []  # blurred: nothing left out
    assert scene.update_motion("/World/Camera") == ["/World/Arm/Mesh"]
    (call,) = deformations(fake, "/World/Arm/Mesh")
    times, points = call.kwargs["times"], call.kwargs["points"]
    assert times[0] == 0.0 and times[-1] == 1.0 and len(times) > 2
    rest = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    transform = fake.meshes()["/World/Arm/Mesh"]["transform"]
    for f, p in zip(times, points, strict=True):
        world = p.astype(np.float64) @ transform[:3, :3] + transform[3, :3]
        # UsdSkel slerps the elbow: the forearm's points turned 90°·f about it.
        angle = np.radians(90.0 * f)
        c, s = np.cos(angle), np.sin(angle)
        want = rest.copy()
        fore = rest[:, 0] > 1.5
        want[fore] = (rest[fore] - ELBOW) @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) + ELBOW
        np.testing.assert_allclose(world, want, atol=1e-5)
    np.testing.assert_allclose(world, bent(rest), atol=1e-5)


@pytest.mark.usefixtures("native")
def test_a_quad_slid_by_its_points_renders_as_one_slid_by_its_transform() -> None:
    settings = {"samples": 128}
    deformed = mipray.render(deforming_stage((0.0, 1.0)), "/Cam", 40, settings=settings, time=1.0)
    moved = mipray.render(sliding_stage((0.0, 1.0)), "/Cam", 40, settings=settings, time=1.0)
    effects = {e["name"]: e["why"] for e in deformed.stats["effects"]["enabled"]}
    assert "/World/Slider" in effects["motion_blur"]
    row, peer = deformed.aovs["color"][0, :, 0], moved.aovs["color"][0, :, 0]
    x = -2.0 + 0.1 * (np.arange(40) + 0.5)
    coverage = np.maximum(0.0, 1.0 - np.abs(x))
    lit = peer[np.argmax(coverage)] / coverage.max()
    np.testing.assert_allclose(row, coverage * lit, atol=0.05 * lit)
    # The same camera samples at the same times: the two agree far within the noise.
    np.testing.assert_allclose(row, peer, atol=0.01 * lit)


@pytest.mark.usefixtures("native")
def test_points_that_do_not_change_render_bit_identically_to_a_still_mesh() -> None:
    aovs = ["color", "alpha", "depth"]
    still = mipray.render(deforming_stage((0.0, 1.0), still=True), "/Cam", 40, aovs=aovs, time=1.0)
    stage = deforming_stage((0.0, 1.0), still=True)
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Slider")).GetPointsAttr()
    points.Clear()
    points.Set([Gf.Vec3f(*p) for p in QUAD["points"]])
    plain = mipray.render(stage, "/Cam", 40, aovs=aovs, time=1.0)
    for aov in aovs:
        assert np.array_equal(still.aovs[aov], plain.aovs[aov]), aov


def _inside(quad: np.ndarray, p: np.ndarray) -> bool:
    """Whether the 2-D point ``p`` is inside the convex quad ``quad`` (4 × 2, either winding)."""
    edges = np.roll(quad, -1, axis=0) - quad
    cross = edges[:, 0] * (p[1] - quad[:, 1]) - edges[:, 1] * (p[0] - quad[:, 0])
    return bool(np.all(cross >= 0) or np.all(cross <= 0))


@pytest.mark.usefixtures("native")
def test_a_skinned_arm_bending_across_the_shutter_covers_what_it_sweeps() -> None:
    # The camera looks down −z at the arm from above the elbow's neighbourhood; the shutter
    # is open from frame 1 (straight) to frame 2 (the forearm turned 90° about the elbow).
    stage = new_stage()
    mesh = arm(stage)
    cam = add_camera(stage, "/World/Camera", eye=(1.0, 0.5, 10.0))
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)
    cam.CreateShutterOpenAttr(0.0)
    cam.CreateShutterCloseAttr(1.0)
    width = 40
    out = mipray.render(
        stage, "/World/Camera", width, aovs=["alpha"], settings={"samples": 400}, time=1
    )
    alpha = out.aovs["alpha"][..., 0]
    # The truth: UsdSkel's pose at 200 times in the shutter, the forearm's top face (z = 0.1)
    # tested against each pixel centre's point on that plane.
    rest = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float32)
    poser = SkelPoser()
    prim = mesh.GetPrim()
    top = [1, 5, 7, 3, 5, 9, 11, 7]  # the two top quads (x 0→1, 1→2), z = 0.1
    poses = [poser.pose(prim, Usd.TimeCode(1 + t), rest) for t in (np.arange(200) + 0.5) / 200]
    quads = [(p.points[top[:4], :2], p.points[top[4:], :2]) for p in poses]
    scale = width / 4.0 * 10.0 / 9.9  # pixels per unit on the plane z = 0.1

    def coverage(row: int, col: int) -> float:
        p = np.array([1.0 + (col + 0.5 - width / 2) / scale, 0.5 - (row + 0.5 - width / 2) / scale])
        return float(np.mean([_inside(a, p) or _inside(b, p) for a, b in quads]))

    checked = 0
    for row in range(width):
        for col in range(width):
            want = coverage(row, col)
            if 0.15 < want < 0.85:
                # Partly covered: a blur, by the share of the shutter the pose covers it (400
                # samples: 3 standard deviations of the estimate are 0.075 at a half share).
                assert abs(alpha[row, col] - want) < 0.08, (row, col, alpha[row, col], want)
                checked += 1
    assert checked > 20, checked


def test_the_delegate_refuses_bad_deformation_samples_in_one_line(native) -> None:
    delegate = native.RenderDelegate()
    quad = np.array(QUAD["points"], np.float32)
    delegate.set_mesh(
        "/World/Q",
        points=quad,
        face_vertex_counts=np.array(QUAD["counts"], np.int32),
        face_vertex_indices=np.array(QUAD["indices"], np.int32),
        transform=np.eye(4),
        scheme="none",
    )
    nan = np.stack([quad, quad])
    nan[1, 2, 0] = np.nan
    cases = [
        (np.array([0.0], np.float32), quad[None], "1 deformation samples (2 to 16 are traced)"),
        (
            np.array([0.0, 1.0], np.float32),
            quad[None],
            "2 deformation times",
        ),
        (np.array([0.5, 0.5], np.float32), np.stack([quad, quad]), "deformation sample times"),
        (np.array([0.0, 1.0], np.float32), np.stack([quad[:3], quad[:3]]), "the points at"),
        (np.array([0.0, 1.0], np.float32), nan, "points[2] at shutter time 1 is not finite"),
    ]
    for times, points, reason in cases:
        with pytest.raises(PrimDataError) as caught:
            delegate.set_deformation("/World/Q", times, points)
        assert caught.value.prim_path == "/World/Q"
        assert caught.value.reason.startswith(reason), caught.value.reason
    with pytest.raises(PrimDataError, match="no mesh at this path"):
        delegate.set_deformation("/World/None", np.zeros(2, np.float32), np.stack([quad, quad]))
    delegate.set_deformation("/World/Q", np.array([0.0, 1.0], np.float32), np.stack([quad, quad]))


def _sliding_blob(by_points: bool) -> Usd.Stage:
    """A Catmull-Clark cube sliding from x = −0.5 at frame 1 to 0.5 at frame 2, by its points or
    by its transform, under a sun, seen by a camera whose shutter spans the two frames."""
    stage = new_stage()
    cube = add_cube(stage, "/World/Blob", scheme="catmullClark")
    rest = np.array(CUBE_POINTS, dtype=np.float32)
    for frame, dx in ((1.0, -0.5), (2.0, 0.5)):
        if by_points:
            moved = rest + np.array([dx, 0.0, 0.0], dtype=np.float32)
            cube.GetPointsAttr().Set([Gf.Vec3f(*map(float, p)) for p in moved], frame)
        else:
            if frame == 1.0:
                op = cube.AddTranslateOp()
            op.Set(Gf.Vec3d(dx, 0.0, 0.0), frame)
    cam = add_camera(stage, "/World/Camera")
    cam.CreateShutterOpenAttr(0.0)
    cam.CreateShutterCloseAttr(1.0)
    add_distant_light(stage, "/World/Sun")
    return stage


@pytest.mark.usefixtures("native")
def test_a_subdivision_surface_slid_by_its_points_renders_as_one_slid_by_its_transform() -> None:
    # The OpenSubdiv path: one surface per sample, built on first use.
    settings = {"samples": 64}
    deformed = mipray.render(_sliding_blob(True), "/World/Camera", 48, settings=settings, time=1.0)
    moved = mipray.render(_sliding_blob(False), "/World/Camera", 48, settings=settings, time=1.0)
    assert (
        "/World/Blob"
        in {e["name"]: e["why"] for e in deformed.stats["effects"]["enabled"]}["motion_blur"]
    )
    a, b = deformed.aovs["color"][..., :3], moved.aovs["color"][..., :3]
    assert a.max() > 0.01
    # Blurred: some pixels neither background nor fully lit.
    assert np.count_nonzero((a[..., 0] > 0.02 * a.max()) & (a[..., 0] < 0.5 * a.max())) > 20
    # Both see the same camera samples at the same times; they differ by the rates each
    # tessellates at (the deforming mesh's swept boxes ask for finer ones): measured 2.5e-4 of
    # the brightest pixel, against 1.3 for the sharp frame-time render.
    assert np.abs(a - b).max() < 0.005 * a.max(), np.abs(a - b).max()


def velocity_stage(
    velocity: float, acceleration: float | None = None, *, count: int = 4
) -> Usd.Stage:
    """:func:`deforming_stage`'s quad with one points sample, at x − 0.5 on frame 1, moved by
    ``velocities`` (and ``accelerations``) along x in units per second; 24 time codes a second.
    ``count`` velocities (the points are 4)."""
    stage = sliding_stage((0.0, 1.0))
    stage.SetTimeCodesPerSecond(24.0)
    stage.RemovePrim("/World/Slider")
    quad = add_cube(stage, "/World/Slider", scheme="none", **QUAD)
    rest = np.array(QUAD["points"], dtype=np.float32) + np.array([-0.5, 0, 0], np.float32)
    quad.GetPointsAttr().Clear()
    quad.GetPointsAttr().Set([Gf.Vec3f(*map(float, p)) for p in rest], 1.0)
    quad.GetVelocitiesAttr().Set([Gf.Vec3f(velocity, 0, 0)] * count, 1.0)
    if acceleration is not None:
        quad.GetAccelerationsAttr().Set([Gf.Vec3f(acceleration, 0, 0)] * 4, 1.0)
    return stage


def test_velocities_move_the_points_across_the_shutter(fake) -> None:
    # 24 units a second for 1/24 s: the quad moves by one unit, as deforming_stage's does.
    scene = UsdSceneDelegate(velocity_stage(24.0), fake, time=1.0)
    scene.sync()
    assert scene.update_motion("/Cam") == ["/World/Slider"]
    (call,) = deformations(fake, "/World/Slider")
    times, points = call.kwargs["times"], call.kwargs["points"]
    np.testing.assert_array_equal(times, [0.0, 1.0])  # linear: the ends are exact
    rest = np.array(QUAD["points"], dtype=np.float32)
    np.testing.assert_allclose(points[0], rest + np.array([-0.5, 0, 0]), atol=1e-6)
    np.testing.assert_allclose(points[1], rest + np.array([0.5, 0, 0]), atol=1e-6)


def test_accelerations_bend_the_path_into_a_parabola(fake) -> None:
    # x(s) = x0 + v·s + a·s²/2, s in seconds from frame 1 (1/24 s a frame): sampled at enough
    # times that the blend between them follows the curve.
    v, a = 6.0, 1152.0
    scene = UsdSceneDelegate(velocity_stage(v, a), fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (call,) = deformations(fake, "/World/Slider")
    times, points = call.kwargs["times"], call.kwargs["points"]
    assert len(times) >= 3 and times[0] == 0.0 and times[-1] == 1.0
    rest = np.array(QUAD["points"], dtype=np.float64) + np.array([-0.5, 0, 0])
    for f, p in zip(times, points, strict=True):
        s = f / 24.0
        np.testing.assert_allclose(p[:, 0], rest[:, 0] + v * s + 0.5 * a * s * s, atol=1e-5)
        np.testing.assert_allclose(p[:, 1:], rest[:, 1:], atol=1e-6)


def test_velocities_of_the_wrong_count_are_warned_and_not_blurred(fake, caplog) -> None:
    scene = UsdSceneDelegate(velocity_stage(24.0, count=3), fake, time=1.0)
    scene.sync()
    with caplog.at_level(logging.WARNING, logger="mipray"):
        assert scene.update_motion("/Cam") == []
        scene.update_motion("/Cam")
    assert deformations(fake, "/World/Slider") == []
    said = [r.getMessage() for r in caplog.records if "/World/Slider" in r.getMessage()]
    assert said == [
        "mipray: /World/Slider: velocities has 3 entries but points has 4; rendering it at "
        "the frame's time without motion blur"
    ]


@pytest.mark.usefixtures("native")
def test_a_quad_moved_by_velocities_renders_as_one_moved_by_its_points() -> None:
    settings = {"samples": 128}
    by_velocity = mipray.render(velocity_stage(24.0), "/Cam", 40, settings=settings, time=1.0)
    by_points = mipray.render(deforming_stage((0.0, 1.0)), "/Cam", 40, settings=settings, time=1.0)
    row, peer = by_velocity.aovs["color"][0, :, 0], by_points.aovs["color"][0, :, 0]
    x = -2.0 + 0.1 * (np.arange(40) + 0.5)
    coverage = np.maximum(0.0, 1.0 - np.abs(x))
    lit = peer[np.argmax(coverage)] / coverage.max()
    np.testing.assert_allclose(row, coverage * lit, atol=0.05 * lit)
    np.testing.assert_allclose(row, peer, atol=0.01 * lit)


@pytest.mark.usefixtures("native")
def test_an_accelerating_quad_covers_what_its_parabola_sweeps() -> None:
    # From rest at x − 0.5, a = 1152 units/s² over 1/24 s: the centre is at −0.5 + f² at
    # shutter fraction f, so a pixel centre at x is covered while f² is within (x, x + 1).
    out = mipray.render(
        velocity_stage(0.0, 1152.0), "/Cam", 40, settings={"samples": 256}, time=1.0
    )
    row = out.aovs["color"][0, :, 0]
    # Averaged over each pixel's width (0.1), where the square root bends within a pixel.
    x = -2.0 + 0.1 * (np.arange(40)[:, None] + (np.arange(100) + 0.5) / 100)
    lo, hi = np.sqrt(np.clip(x, 0.0, 1.0)), np.sqrt(np.clip(x + 1.0, 0.0, 1.0))
    coverage = np.maximum(0.0, hi - lo).mean(axis=1)
    linear = np.maximum(0.0, 1.0 - np.abs(x)).mean(axis=1)  # the chord from end to end's
    assert np.abs(coverage - linear).max() > 0.2
    lit = row[np.argmax(coverage)] / coverage.max()
    np.testing.assert_allclose(row, coverage * lit, atol=0.05 * lit)


def test_a_nurbs_patch_changing_shape_within_the_shutter_is_named_not_dropped(caplog) -> None:
    # The core blurs the deformation of meshes, Points, curves and implicit prims: curves and
    # points whose points move inside an open shutter, and a sphere whose radius grows, blur,
    # while a NurbsPatch whose points move renders at the frame's time and is named once
    # (warning and stats), not silently. Still ones, a sample only at the frame's time, or a
    # closed shutter are not named.
    def stage_with(shutter_close: float, moving: bool) -> Usd.Stage:
        stage = new_stage()
        c = UsdGeom.BasisCurves.Define(stage, "/World/Hair")
        c.CreateTypeAttr("linear")
        c.CreateCurveVertexCountsAttr([2])
        c.CreateWidthsAttr([0.2])
        c.SetWidthsInterpolation("constant")
        p = UsdGeom.Points.Define(stage, "/World/Dust")
        s = UsdGeom.Sphere.Define(stage, "/World/Ball")
        s.AddTranslateOp().Set(Gf.Vec3d(0, -2, 0))
        sheet = nurbs_sphere(stage, "/World/Sheet", 0.5)
        rest = np.array(sheet.GetPointsAttr().Get(), dtype=np.float64)
        sheet.GetPointsAttr().Clear()
        sheet.AddTranslateOp().Set(Gf.Vec3d(2, 0, 0))
        for t in (0, 1) if moving else (0,):
            c.GetPointsAttr().Set([(t, -1, 0), (t, 1, 0)], t)
            p.GetPointsAttr().Set([(t, 2, 0)], t)
            s.GetRadiusAttr().Set(0.3 + 0.3 * t, t)
            sheet.GetPointsAttr().Set([Gf.Vec3f(*(q * (1 + t))) for q in rest], t)
        cam = add_camera(stage, "/World/Camera", eye=(0.0, 0.0, 8.0))
        cam.CreateShutterOpenAttr(0.0)
        cam.CreateShutterCloseAttr(shutter_close)
        add_distant_light(stage, "/World/Sun")
        return stage

    what = "deformation of a NurbsPatch"

    def named(stage: Usd.Stage) -> tuple[list[str], str]:
        with mipray.RenderSession(stage) as session:
            r = session.render("/World/Camera", width=16, time=0.0)
        blur = {e["name"]: e["why"] for e in r.stats["effects"]["enabled"]}.get("motion_blur", "")
        return sorted(u["prim"] for u in r.stats["unsupported"] if what in u["what"]), blur

    with caplog.at_level(logging.WARNING, logger="mipray"):
        prims, blur = named(stage_with(1.0, moving=True))
    assert prims == ["/World/Sheet"]
    for moving in ("/World/Ball", "/World/Dust", "/World/Hair"):
        assert moving in blur, blur
    lines = [r.getMessage() for r in caplog.records if what in r.getMessage()]
    assert len(lines) == 1 and "/World/Sheet" in lines[0], lines
    assert named(stage_with(1.0, moving=False)) == ([], "")
    assert named(stage_with(0.0, moving=True)) == ([], "")
