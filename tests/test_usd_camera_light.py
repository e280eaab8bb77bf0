"""Cameras and distant lights are read as USD defines them; a stage without a
camera gets a framing camera, as usdrecord does."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from pxr import Gf, UsdGeom, UsdLux

from mipray.errors import PrimError
from mipray.usd import CAMERA_LIGHT_PATH, DEFAULT_CAMERA_PATH, UsdSceneDelegate, image_height
from mipray.usd.camera import camera_matrices

from stages import add_camera, add_cube, add_distant_light, new_stage


def test_camera_attributes_are_read(fake) -> None:
    stage = new_stage()
    cam = add_camera(stage, "/Cam", eye=(1, 2, 3))
    cam.CreateFocalLengthAttr(35.0)
    cam.CreateHorizontalApertureAttr(36.0)
    cam.CreateVerticalApertureAttr(24.0)
    cam.CreateHorizontalApertureOffsetAttr(1.5)
    cam.CreateVerticalApertureOffsetAttr(-0.5)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.1, 500.0))
    cam.CreateFStopAttr(2.8)
    cam.CreateFocusDistanceAttr(7.0)
    cam.CreateProjectionAttr("orthographic")
    UsdSceneDelegate(stage, fake).sync()
    args = fake.prims["/Cam"].kwargs
    assert args["focal_length"] == 35.0
    assert (args["horizontal_aperture"], args["vertical_aperture"]) == (36.0, 24.0)
    assert (args["horizontal_aperture_offset"], args["vertical_aperture_offset"]) == (1.5, -0.5)
    assert args["clipping_range"] == pytest.approx((0.1, 500.0))
    assert args["f_stop"] == pytest.approx(2.8)
    assert args["focus_distance"] == 7.0
    assert args["projection"] == "orthographic"
    np.testing.assert_allclose(args["transform"][3, :3], [1, 2, 3])


def test_bad_camera_is_an_error_naming_it(fake) -> None:
    stage = new_stage()
    add_camera(stage, "/Cam").CreateFocalLengthAttr(0.0)
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert [str(e) for e in scene.delegate_errors] == [
        "/Cam: focalLength is 0.0; it must be positive"
    ]
    with pytest.raises(PrimError, match="/Cam"):
        scene.resolve_camera("/Cam")


def test_camera_choice_follows_usdrecord(fake) -> None:
    stage = new_stage()
    add_camera(stage, "/A/first")
    add_camera(stage, "/B/main_cam")
    scene = UsdSceneDelegate(stage, fake)
    assert scene.resolve_camera() == "/B/main_cam"
    assert scene.resolve_camera("first") == "/A/first"
    assert scene.resolve_camera("/A/first") == "/A/first"
    with pytest.raises(PrimError, match="/Nope"):
        scene.resolve_camera("/Nope")
    with pytest.raises(PrimError, match="nope"):
        scene.resolve_camera("nope")
    add_cube(stage, "/Cube")
    with pytest.raises(PrimError, match="not a Camera"):
        scene.resolve_camera("/Cube")


def test_first_camera_in_traversal_order_without_main_cam(fake) -> None:
    stage = new_stage()
    add_camera(stage, "/Z/cam")
    add_camera(stage, "/A/cam")
    scene = UsdSceneDelegate(stage, fake)
    assert scene.resolve_camera() == "/Z/cam"


def test_stage_without_camera_gets_a_framing_camera(fake, caplog) -> None:
    stage = new_stage()
    add_cube(stage, "/Cube", translate=(5, 1, -2))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        path = scene.resolve_camera()
    assert path == DEFAULT_CAMERA_PATH
    assert any("no camera" in r.getMessage() for r in caplog.records)
    args = fake.prims[DEFAULT_CAMERA_PATH].kwargs
    m = args["transform"]
    # Looks down -Z at the cube's center from in front of it (stage is Y up).
    center = np.array([5.0, 1.0, -2.0])
    eye = m[3, :3]
    forward = -m[2, :3]
    np.testing.assert_allclose(eye[:2], center[:2], atol=1e-9)
    assert eye[2] > center[2] + 0.87  # outside the bounding sphere
    np.testing.assert_allclose(forward / np.linalg.norm(forward), [0, 0, -1], atol=1e-9)
    # The whole bounding sphere fits in the narrower field of view.
    half_v = math.atan(0.5 * args["vertical_aperture"] / args["focal_length"])
    radius = 0.5 * math.sqrt(3.0)
    assert math.asin(radius / np.linalg.norm(eye - center)) <= half_v + 1e-9
    near, far = args["clipping_range"]
    assert 0 < near < np.linalg.norm(eye - center) - radius
    assert far > np.linalg.norm(eye - center) + radius


def test_framing_camera_for_z_up_stage_looks_along_plus_y(fake) -> None:
    stage = new_stage()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    add_cube(stage, "/Cube")
    scene = UsdSceneDelegate(stage, fake)
    scene.resolve_camera()
    m = fake.prims[DEFAULT_CAMERA_PATH].kwargs["transform"]
    np.testing.assert_allclose(-m[2, :3], [0, 1, 0], atol=1e-9)  # view direction
    np.testing.assert_allclose(m[1, :3], [0, 0, 1], atol=1e-9)  # camera up


def test_image_height_follows_aperture_aspect() -> None:
    # 700.51, truncated as usdrecord's frame recorder does (its SmallObjectTest baseline is
    # 960x700).
    assert image_height(960, {"horizontal_aperture": 20.955, "vertical_aperture": 15.2908}) == 700
    assert image_height(960, {"horizontal_aperture": 36.0, "vertical_aperture": 24.0}) == 640
    assert image_height(320, {"horizontal_aperture": 36.0, "vertical_aperture": 24.0}) == 213
    assert image_height(1, {"horizontal_aperture": 100.0, "vertical_aperture": 1.0}) == 1


def test_camera_matrices_project_the_view_center_to_the_screen_center(fake) -> None:
    stage = new_stage()
    add_camera(stage, "/Cam", eye=(0, 0, 10))
    scene = UsdSceneDelegate(stage, fake)
    path = scene.resolve_camera()
    args = scene.cameras[path]
    world_to_camera, world_to_screen = camera_matrices(args)
    p = np.array([0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose((p @ world_to_camera)[:3], [0, 0, -10])
    s = p @ world_to_screen
    np.testing.assert_allclose(s[:2] / s[3], [0, 0], atol=1e-12)


def test_distant_light_attributes_are_read(fake) -> None:
    stage = new_stage()
    light = add_distant_light(stage, "/Sun", intensity=3.0)
    light.CreateExposureAttr(1.5)
    light.CreateColorAttr(Gf.Vec3f(1.0, 0.9, 0.8))
    light.CreateAngleAttr(2.0)
    light.CreateNormalizeAttr(True)
    shadow = UsdLux.ShadowAPI.Apply(light.GetPrim())
    shadow.CreateShadowEnableAttr(False)
    default = UsdLux.DistantLight.Define(stage, "/Default")
    UsdSceneDelegate(stage, fake).sync()
    args = fake.prims["/Sun"].kwargs
    assert args["intensity"] == 3.0 and args["exposure"] == 1.5
    assert args["color"] == pytest.approx((1.0, 0.9, 0.8))
    assert args["angle"] == 2.0 and args["normalize"] is True
    assert args["shadow_enable"] is False
    # The light shines down its -Z axis, tilted 45° down by its rotateX op.
    direction = -args["transform"][2, :3]
    np.testing.assert_allclose(direction, [0, -math.sqrt(0.5), -math.sqrt(0.5)], atol=1e-9)
    d = fake.prims[str(default.GetPath())].kwargs
    assert d["shadow_enable"] is True and d["intensity"] == 50000.0
    assert d["angle"] == pytest.approx(0.53)


def test_camera_light_only_when_the_stage_has_no_light(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Cube")
    add_camera(stage, "/Cam")
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    cam = scene.resolve_camera()
    assert scene.update_camera_light(cam) is True
    assert fake.prims[CAMERA_LIGHT_PATH].kwargs["shadow_enable"] is False
    np.testing.assert_allclose(
        fake.prims[CAMERA_LIGHT_PATH].kwargs["transform"], fake.prims["/Cam"].kwargs["transform"]
    )
    add_distant_light(stage, "/Sun")
    scene.sync()
    assert scene.update_camera_light(cam) is False
    assert CAMERA_LIGHT_PATH not in fake.prims
    assert scene.update_camera_light(cam, enabled=False) is False


def test_requested_camera_renders_even_if_invisible(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Cube")
    UsdGeom.Xform.Define(stage, "/Hidden").CreateVisibilityAttr("invisible")
    add_camera(stage, "/Hidden/shotcam", eye=(0, 0, 5))
    scene = UsdSceneDelegate(stage, fake)
    assert scene.resolve_camera() == DEFAULT_CAMERA_PATH  # not chosen by default
    assert scene.resolve_camera("shotcam") == "/Hidden/shotcam"
    assert fake.prims["/Hidden/shotcam"].method == "set_camera"
