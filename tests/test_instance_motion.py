"""Motion blur of instances: PointInstancers and native instances that move within the shutter.

A quad placed by a PointInstancer (time-sampled ``positions``, or ``velocities``) or by a
native instance (an animated xform on the instanceable prim) sliding across the shutter is
blurred exactly as the same quad moved by its own xform (the peer, itself held to the analytic
coverage in test_motion_blur.py), and its coverage matches the analytic fraction of the
shutter; an instanced mesh light moving across the shutter lights the floor with Lambert's
irradiance averaged over it; instances that do not move send nothing and render bit for bit
as without a shutter.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom
from test_lights_shaping_linking import ALBEDO, stage_with_camera
from test_mesh_lights import floor_xy, lambert_square
from test_mesh_lights_tint_instances import instanced_squares, relative_error, render_with_stats
from test_motion_blur import QUAD, sliding_stage

import mipray
from mipray.usd import UsdSceneDelegate

from stages import add_cube, new_stage

#: Pixel centres of the 40-pixel row the sliding stages' camera sees (4 units wide).
XS = -2.0 + 0.1 * (np.arange(40) + 0.5)


def camera(stage: Usd.Stage, shutter: tuple[float, float] | None) -> None:
    """sliding_stage's camera: orthographic, 4 units wide, looking down −Z."""
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, 5))
    cam.CreateProjectionAttr("orthographic")
    cam.CreateHorizontalApertureAttr(40.0)
    cam.CreateVerticalApertureAttr(2.0)
    if shutter is not None:
        cam.CreateShutterOpenAttr(shutter[0])
        cam.CreateShutterCloseAttr(shutter[1])


def points_stage(
    shutter: tuple[float, float] | None, how: str = "positions", still: bool = False
) -> Usd.Stage:
    """A unit quad placed by a PointInstancer at x = −0.5 at frame 1 and 0.5 at frame 2, by
    time-sampled ``positions`` or by ``velocities`` (one unit a frame, from one sample), and (``still``) a
    second instance that stays at x = 1.5."""
    stage = new_stage()
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    add_cube(stage, "/World/PI/Protos/Quad", scheme="none", **QUAD)
    pi.CreatePrototypesRel().AddTarget("/World/PI/Protos/Quad")
    extra = [(1.5, 0, 0)] if still else []
    pi.CreateProtoIndicesAttr([0] * (1 + len(extra)))
    positions = pi.CreatePositionsAttr()
    if how == "positions":
        positions.Set([(-0.5, 0, 0), *extra], 1.0)
        positions.Set([(0.5, 0, 0), *extra], 2.0)
    elif how == "velocities":
        # USD applies velocities sampled at the positions' sample time (units per second).
        positions.Set([(-0.5, 0, 0), *extra], 1.0)
        fps = stage.GetTimeCodesPerSecond()
        pi.CreateVelocitiesAttr().Set([(fps, 0, 0), *[(0, 0, 0)] * len(extra)], 1.0)
    else:
        positions.Set([(-0.5, 0, 0), *extra])
    camera(stage, shutter)
    return stage


def native_stage(shutter: tuple[float, float] | None, moving: bool = True) -> Usd.Stage:
    """The unit quad as a native instance's prototype, the instance prim sliding from
    x = −0.5 at frame 1 to 0.5 at frame 2 (or staying at −0.5), and a still instance at
    x = 1.5."""
    stage = new_stage()
    stage.DefinePrim("/Proto", "Xform").SetSpecifier(Sdf.SpecifierClass)
    add_cube(stage, "/Proto/Quad", scheme="none", **QUAD)
    for name, x in (("Slider", None), ("Still", 1.5)):
        inst = UsdGeom.Xform.Define(stage, f"/World/{name}")
        op = inst.AddTranslateOp()
        if x is None:
            op.Set(Gf.Vec3d(-0.5, 0, 0), 1.0)
            op.Set(Gf.Vec3d(0.5 if moving else -0.5, 0, 0), 2.0)
        else:
            op.Set(Gf.Vec3d(x, 0, 0))
        inst.GetPrim().GetReferences().AddInternalReference("/Proto")
        inst.GetPrim().SetInstanceable(True)
    camera(stage, shutter)
    return stage


def nested_stage(shutter: tuple[float, float] | None, kind: str) -> Usd.Stage:
    """The sliding quad one level down: placed by a PointInstancer (``kind`` "points") or a
    native instance ("native") inside a prototype that a still outer instancer places once,
    at x = 0 (an outer PointInstancer, or a native instance)."""
    stage = new_stage()
    if kind == "points":
        outer = UsdGeom.PointInstancer.Define(stage, "/World/Outer")
        group = "/World/Outer/Protos/Group"
        UsdGeom.Xform.Define(stage, group)
        inner = UsdGeom.PointInstancer.Define(stage, f"{group}/Inner")
        add_cube(stage, f"{group}/Inner/Protos/Quad", scheme="none", **QUAD)
        inner.CreatePrototypesRel().AddTarget(f"{group}/Inner/Protos/Quad")
        inner.CreateProtoIndicesAttr([0])
        inner.CreatePositionsAttr().Set([(-0.5, 0, 0)], 1.0)
        inner.GetPositionsAttr().Set([(0.5, 0, 0)], 2.0)
        outer.CreatePrototypesRel().AddTarget(group)
        outer.CreateProtoIndicesAttr([0])
        outer.CreatePositionsAttr([(0, 0, 0)])
    else:
        stage.DefinePrim("/Proto", "Xform").SetSpecifier(Sdf.SpecifierClass)
        add_cube(stage, "/Proto/Quad", scheme="none", **QUAD)
        stage.DefinePrim("/Group", "Xform").SetSpecifier(Sdf.SpecifierClass)
        slider = UsdGeom.Xform.Define(stage, "/Group/Slider")
        op = slider.AddTranslateOp()
        op.Set(Gf.Vec3d(-0.5, 0, 0), 1.0)
        op.Set(Gf.Vec3d(0.5, 0, 0), 2.0)
        slider.GetPrim().GetReferences().AddInternalReference("/Proto")
        slider.GetPrim().SetInstanceable(True)
        holder = UsdGeom.Xform.Define(stage, "/World/Holder")
        holder.GetPrim().GetReferences().AddInternalReference("/Group")
        holder.GetPrim().SetInstanceable(True)
    camera(stage, shutter)
    return stage


def member_stage(shutter: tuple[float, float] | None, kind: str) -> Usd.Stage:
    """The quad sliding by its own xform inside a prototype that a still PointInstancer
    (``kind`` "points") or native instance ("native") places once at the origin."""
    stage = new_stage()
    root = "/World/PI/Protos/Group" if kind == "points" else "/Proto"
    if kind == "points":
        pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
        UsdGeom.Xform.Define(stage, root)
        pi.CreatePrototypesRel().AddTarget(root)
        pi.CreateProtoIndicesAttr([0])
        pi.CreatePositionsAttr([(0, 0, 0)])
    else:
        stage.DefinePrim(root, "Xform").SetSpecifier(Sdf.SpecifierClass)
        holder = UsdGeom.Xform.Define(stage, "/World/Holder")
        holder.GetPrim().GetReferences().AddInternalReference(root)
        holder.GetPrim().SetInstanceable(True)
    op = add_cube(stage, f"{root}/Quad", scheme="none", **QUAD).AddTranslateOp()
    op.Set(Gf.Vec3d(-0.5, 0, 0), 1.0)
    op.Set(Gf.Vec3d(0.5, 0, 0), 2.0)
    camera(stage, shutter)
    return stage


# ------------------------------------------------------------------ what is sent


@pytest.mark.parametrize("how", ["positions", "velocities"])
def test_a_moving_point_instancer_sends_its_instances_over_the_shutter(fake, how) -> None:
    scene = UsdSceneDelegate(points_stage((0.0, 1.0), how, still=True), fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (call,) = [c for c in fake.calls_for("/World/PI") if c.method == "set_instancer_motion"]
    times, mats = call.kwargs["times"], call.kwargs["transforms"]
    assert times[0] == 0.0 and times[-1] == 1.0 and np.all(np.diff(times) > 0)
    assert mats.shape == (len(times), 2, 4, 4)
    # The moving instance goes from −0.5 to 0.5 linearly; the still one stays at 1.5.
    np.testing.assert_allclose(mats[:, 0, 3, 0], -0.5 + times, atol=1e-6)
    np.testing.assert_array_equal(mats[:, 1, 3, 0], 1.5)


def test_still_instances_or_a_shut_shutter_send_no_motion(fake) -> None:
    stages = [points_stage((0.0, 1.0), "still"), points_stage(None), native_stage(None)]
    stages += [nested_stage(None, "points"), nested_stage(None, "native")]
    stages += [member_stage(None, "points"), member_stage(None, "native")]
    for stage in stages:
        scene = UsdSceneDelegate(stage, fake, time=1.0)
        scene.sync()
        scene.update_motion("/Cam")
    assert not [c for c in fake.calls if c.method == "set_instancer_motion"]


def test_a_moving_native_instance_sends_its_prototypes_instancer_motion(fake) -> None:
    stage = native_stage((0.0, 1.0))
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (call,) = [c for c in fake.calls if c.method == "set_instancer_motion"]
    assert call.path == str(stage.GetPrimAtPath("/World/Slider").GetPrototype().GetPath())
    times, mats = call.kwargs["times"], call.kwargs["transforms"]
    placed = fake.instancers()[call.path]["transforms"]
    slider = int(np.flatnonzero(placed[:, 3, 0] != 1.5)[0])
    np.testing.assert_allclose(mats[:, slider, 3, 0], -0.5 + times, atol=1e-6)
    # The still instance keeps its transform at every key.
    still = 1 - slider
    assert np.all(mats[:, still] == placed[still])
    # Shut the shutter: the motion is cleared.
    UsdGeom.Camera(stage.GetPrimAtPath("/Cam")).GetShutterCloseAttr().Set(0.0)
    scene.sync()
    scene.update_motion("/Cam")
    last = [c for c in fake.calls if c.method == "set_instancer_motion"][-1]
    assert len(last.kwargs["times"]) == 0


@pytest.mark.parametrize("kind", ["points", "native"])
def test_an_instance_moving_inside_a_prototype_sends_its_motion_there(fake, kind) -> None:
    scene = UsdSceneDelegate(nested_stage((0.0, 1.0), kind), fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (call,) = [c for c in fake.calls if c.method == "set_instancer_motion"]
    assert fake.instancers()[call.path]["prototype"] is True
    times, mats = call.kwargs["times"], call.kwargs["transforms"]
    # Relative to the prototype's root, which the outer instancer places at the origin.
    np.testing.assert_allclose(mats[:, 0, 3, 0], -0.5 + times, atol=1e-6)


@pytest.mark.parametrize("kind", ["points", "native"])
def test_a_mesh_moving_inside_its_prototype_sends_its_motion_there(fake, kind) -> None:
    stage = member_stage((0.0, 1.0), kind)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (call,) = [c for c in fake.calls if c.method == "set_motion"]
    assert fake.prims[call.path].kwargs["prototype"] is True
    times, mats = call.kwargs["times"], call.kwargs["transforms"]
    np.testing.assert_allclose(mats[:, 3, 0], -0.5 + times, atol=1e-6)
    # Shut the shutter: the motion is cleared.
    UsdGeom.Camera(stage.GetPrimAtPath("/Cam")).GetShutterCloseAttr().Set(0.0)
    scene.sync()
    scene.update_motion("/Cam")
    last = [c for c in fake.calls if c.method == "set_motion"][-1]
    assert last.path == call.path and len(last.kwargs["times"]) == 0


# ------------------------------------------------------------------------ renders


def row(stage: Usd.Stage, samples: int = 128) -> np.ndarray:
    image = mipray.render(stage, "/Cam", 40, settings={"samples": samples}, time=1.0)
    return np.asarray(image.aovs["color"][0, :, 0], dtype=np.float64)


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize(
    "how",
    [
        "positions",
        "velocities",
        "native",
        "nested points",
        "nested native",
        "member points",
        "member native",
    ],
)
def test_a_sliding_instance_blurs_as_the_same_quad_moved_by_its_xform(how) -> None:
    if how.startswith("nested"):
        stage = nested_stage((0.0, 1.0), how.split()[1])
    elif how.startswith("member"):
        stage = member_stage((0.0, 1.0), how.split()[1])
    elif how == "native":
        stage = native_stage((0.0, 1.0))
    else:
        stage = points_stage((0.0, 1.0), how)
    got = row(stage)
    peer = row(sliding_stage((0.0, 1.0)))
    centre = row(sliding_stage(None))[15]  # the still quad's inside
    assert centre > 0.0
    # A point at x is covered while the quad's centre (−0.5 → 0.5) is within 0.5 of it.
    near = np.abs(XS) < 1.0
    expected = np.clip(1.0 - np.abs(XS), 0.0, None)
    np.testing.assert_allclose(got[near] / centre, expected[near], atol=0.05)
    np.testing.assert_allclose(got[near], peer[near], atol=0.01 * centre)
    # Not the quad frozen at the frame's time (x in [−1, 0]): the test can tell.
    assert got[XS > 0.05].max() > 0.3 * centre
    if how == "native":
        # The still instance at x = 1.5 covers [1, 2] fully, and nothing between.
        np.testing.assert_allclose(got[XS > 1.05] / centre, 1.0, atol=1e-6)


@pytest.mark.usefixtures("native")
def test_a_spinning_point_instance_blurs_as_the_same_quad_spun_by_its_xform() -> None:
    # orientations from none to 45° about Z across the shutter, against a rotateZ op
    # animated alike (USD slerps the one and interpolates the other's angle: the same turn).
    def spinning(instanced: bool) -> Usd.Stage:
        stage = new_stage()
        if instanced:
            pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
            add_cube(stage, "/World/PI/Protos/Quad", scheme="none", **QUAD)
            pi.CreatePrototypesRel().AddTarget("/World/PI/Protos/Quad")
            pi.CreateProtoIndicesAttr([0])
            pi.CreatePositionsAttr([(0, 0, 0)])
            turn = Gf.Rotation(Gf.Vec3d(0, 0, 1), 45.0).GetQuat()
            pi.CreateOrientationsAttr().Set([Gf.Quath(1, 0, 0, 0)], 1.0)
            pi.GetOrientationsAttr().Set([Gf.Quath(turn)], 2.0)
        else:
            op = add_cube(stage, "/World/Quad", scheme="none", **QUAD).AddRotateZOp()
            op.Set(0.0, 1.0)
            op.Set(45.0, 2.0)
        camera(stage, (0.0, 1.0))
        return stage

    got, peer = row(spinning(True), 256), row(spinning(False), 256)
    centre = row(sliding_stage(None))[15]
    # The quad's half-width along y = 0 grows from 0.5 to 0.5·√2 as it turns.
    assert got[np.abs(XS) < 0.45].min() > 0.99 * centre
    assert 0.0 < got[(XS > 0.55) & (XS < 0.65)].max() < 0.9 * centre
    np.testing.assert_allclose(got, peer, atol=0.02 * centre)


@pytest.mark.usefixtures("native")
def test_still_instances_render_bit_for_bit_as_without_a_shutter() -> None:
    # Time-sampled but still (the native slider's two samples are equal): nothing is sent,
    # and the shutter changes no bit.
    pairs = [
        (points_stage((0.0, 1.0), "still"), points_stage(None, "still")),
        (native_stage((0.0, 1.0), moving=False), native_stage(None, moving=False)),
    ]
    for opened, shut in pairs:
        for aov in ("color", "depth"):
            a = mipray.render(opened, "/Cam", 40, aovs=[aov], settings={"samples": 16}, time=1.0)
            b = mipray.render(shut, "/Cam", 40, aovs=[aov], settings={"samples": 16}, time=1.0)
            assert np.array_equal(np.asarray(a.aovs[aov]), np.asarray(b.aovs[aov]))
            assert np.asarray(a.aovs[aov]).max() > 0.0


@pytest.mark.parametrize("native_instances", [False, True])
def test_a_moving_instanced_mesh_light_gives_lamberts_irradiance_averaged_over_the_shutter(
    native, native_instances
) -> None:
    # Two instances of the down-facing square at x = ±D; the whole instancer (or each
    # instance) slides by −X0 → +X0 from frame 1 to frame 2, the shutter spanning the frame.
    from test_mesh_lights_tint_instances import D

    x0 = 0.6
    stage = stage_with_camera()
    instanced_squares(stage, native_instances)
    movers = ["/World/Lamp0", "/World/Lamp1"] if native_instances else ["/World/Lamps"]
    for path in movers:
        xf = UsdGeom.Xformable(stage.GetPrimAtPath(path))
        ops = xf.GetOrderedXformOps()
        base = ops[0].Get() if ops else Gf.Vec3d(0, 0, 0)
        op = ops[0] if ops else xf.AddTranslateOp()
        op.GetAttr().Clear()
        op.Set(base + Gf.Vec3d(-x0, 0, 0), 1.0)
        op.Set(base + Gf.Vec3d(x0, 0, 0), 2.0)
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
    cam.CreateShutterOpenAttr(0.0)
    cam.CreateShutterCloseAttr(1.0)
    image, stats = render_with_stats(stage, time=1.0, samples=256)
    x, y = floor_xy(image, stage)
    steps = 200
    shift = -x0 + 2.0 * x0 * (np.arange(steps) + 0.5) / steps
    one = sum(lambert_square(x - s - D, y) + lambert_square(x - s + D, y) for s in shift)
    truth = one / steps * 3.0 * ALBEDO / math.pi
    mean, worst = relative_error(image[..., 0], truth)
    assert abs(mean) < 0.01 and worst < 0.1, (native_instances, mean, worst)
    # Not the squares frozen at the shutter's open: the test can tell.
    frozen = (lambert_square(x + x0 - D, y) + lambert_square(x + x0 + D, y)) * 3.0
    frozen *= ALBEDO / math.pi
    lit = truth > 0.05 * truth.max()
    assert float(np.abs(frozen[lit] / truth[lit] - 1.0).max()) > 0.3
    lights = stats["scene"]["lights"]
    assert len(lights) == 2 and all(e["moving"] is True for e in lights), lights
