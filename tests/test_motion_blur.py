"""Transform motion blur from USD: the render camera's shutter, time-sampled xforms."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom

import mipray
from mipray.usd import UsdSceneDelegate

from stages import add_cube, new_stage

QUAD = dict(
    points=[(-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0)],
    counts=[4],
    indices=[0, 1, 2, 3],
)


def sliding_stage(shutter: tuple[float, float] | None) -> Usd.Stage:
    """A unit quad whose x goes from −0.5 at frame 1 to 0.5 at frame 2, under an
    orthographic camera 4 units wide looking down −Z, its shutter open for ``shutter``."""
    stage = new_stage()
    quad = add_cube(stage, "/World/Slider", scheme="none", **QUAD)
    op = quad.AddTranslateOp()
    op.Set(Gf.Vec3d(-0.5, 0, 0), 1.0)
    op.Set(Gf.Vec3d(0.5, 0, 0), 2.0)
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, 5))
    cam.CreateProjectionAttr("orthographic")
    cam.CreateHorizontalApertureAttr(40.0)
    cam.CreateVerticalApertureAttr(2.0)
    if shutter is not None:
        cam.CreateShutterOpenAttr(shutter[0])
        cam.CreateShutterCloseAttr(shutter[1])
    return stage


def test_moving_meshes_get_their_transform_over_the_shutter(fake) -> None:
    stage = sliding_stage((0.0, 1.0))
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    assert scene.update_motion("/Cam") == ["/World/Slider"]
    (call,) = [c for c in fake.calls_for("/World/Slider") if c.method == "set_motion"]
    times, mats = call.kwargs["times"], call.kwargs["transforms"]
    assert times[0] == 0.0 and times[-1] == 1.0 and np.all(np.diff(times) > 0)
    # USD interpolates the translate linearly between frames 1 and 2.
    np.testing.assert_allclose(mats[:, 3, 0], -0.5 + times, atol=1e-6)


def test_a_closed_shutter_or_a_still_mesh_sends_no_motion(fake) -> None:
    stage = sliding_stage(None)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    assert scene.update_motion("/Cam") == []
    assert not [c for c in fake.calls if c.method == "set_motion"]


def test_a_mesh_that_stops_moving_has_its_motion_cleared(fake) -> None:
    stage = sliding_stage((0.0, 1.0))
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    UsdGeom.Camera(stage.GetPrimAtPath("/Cam")).GetShutterCloseAttr().Set(0.0)
    scene.sync()
    assert scene.update_motion("/Cam") == []
    last = [c for c in fake.calls_for("/World/Slider") if c.method == "set_motion"][-1]
    assert len(last.kwargs["times"]) == 0


@pytest.mark.usefixtures("native")
def test_a_sliding_quad_is_blurred_by_its_share_of_the_shutter() -> None:
    settings = {"samples": 128}
    blurred = mipray.render(sliding_stage((0.0, 1.0)), "/Cam", 40, settings=settings, time=1.0)
    sharp = mipray.render(sliding_stage(None), "/Cam", 40, settings=settings, time=1.0)
    effects = {e["name"]: e["why"] for e in blurred.stats["effects"]["enabled"]}
    assert "/World/Slider" in effects["motion_blur"]
    assert "motion_blur" not in {e["name"] for e in sharp.stats["effects"]["enabled"]}
    row = blurred.aovs["color"][0, :, 0]
    xs = -2.0 + 0.1 * (np.arange(40) + 0.5)
    # The still quad's inside: what a pixel covered for the whole shutter reads.
    centre = sharp.aovs["color"][0, 15, 0]
    assert centre > 0.0
    # A point at x is covered while the quad's centre (−0.5 → 0.5) is within 0.5 of it.
    expected = np.clip(1.0 - np.abs(xs), 0.0, None)
    np.testing.assert_allclose(row / centre, expected, atol=0.05)
    # Without a shutter the quad is sharp, where it is at frame 1: x in [−1, 0].
    srow = sharp.aovs["color"][0, :, 0]
    assert np.all(srow[(xs > -0.95) & (xs < -0.05)] > 0.0)
    assert np.all(srow[(xs < -1.05) | (xs > 0.05)] == 0.0)
