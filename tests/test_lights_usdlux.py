"""UsdLux parity, rendered: normalize and angle of distant lights, color temperature, the dome
texture's orientation and importance sampling, and bad lights that never stop the others."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdLux

import mipray
from mipray.usd.light import (
    area_light_arguments,
    blackbody_rgb,
    distant_light_arguments,
)

#: The default material's diffuse reflectance (UsdPreviewSurface's fallback).
ALBEDO = 0.18


def ground_stage() -> Usd.Stage:
    """A Z-up stage: a 40 × 40 ground at z = 0 (default material) seen from 8 units above."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    ground = UsdGeom.Mesh.Define(stage, "/World/Ground")
    ground.CreatePointsAttr([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)])
    ground.CreateFaceVertexCountsAttr([4])
    ground.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    ground.CreateSubdivisionSchemeAttr("none")
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, 8))
    return stage


def render(stage: Usd.Stage, width: int = 16, **settings: object) -> mipray.RenderResult:
    with mipray.RenderSession(stage) as session:
        return session.render("/World/Cam", width=width, settings=settings, camera_light=False)


def mean_color(result: mipray.RenderResult) -> np.ndarray:
    return result.aovs["color"][..., :3].reshape(-1, 3).mean(axis=0)


# ------------------------------------------------------------------ distant: normalize, angle


@pytest.mark.parametrize("normalize", [True, False])
def test_distant_light_normalize_follows_usdlux(native, normalize: bool) -> None:
    # Straight down, angular diameter 10°. Normalized, intensity is the irradiance on a surface
    # facing the light; not normalized, it is the radiance of the sun's disk: E = L π sin²(5°).
    stage = ground_stage()
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(2.0)
    sun.CreateAngleAttr(10.0)
    sun.CreateNormalizeAttr(normalize)
    irradiance = 2.0 if normalize else 2.0 * math.pi * math.sin(math.radians(5.0)) ** 2
    got = mean_color(render(stage, samples=4))
    np.testing.assert_allclose(got, ALBEDO / math.pi * irradiance, rtol=5e-3)


def test_a_distant_point_light_delivers_its_intensity_normalized_or_not(native) -> None:
    for normalize in (True, False):
        stage = ground_stage()
        sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
        sun.CreateIntensityAttr(3.0)
        sun.CreateExposureAttr(-1.0)
        sun.CreateAngleAttr(0.0)
        sun.CreateNormalizeAttr(normalize)
        color = render(stage).aovs["color"][..., :3]
        np.testing.assert_allclose(color, ALBEDO / math.pi * 1.5, rtol=1e-5)


def test_distant_angle_outside_usdlux_range_is_clipped_with_one_warning(caplog) -> None:
    stage = ground_stage()
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateAngleAttr(-3.0)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        args = distant_light_arguments(sun, Usd.TimeCode.Default(), np.eye(4))
        distant_light_arguments(sun, Usd.TimeCode.Default(), np.eye(4))
    assert args["angle"] == 0.0
    warnings = [r.getMessage() for r in caplog.records if "inputs:angle" in r.getMessage()]
    assert len(warnings) == 1 and "/World/Sun" in warnings[0] and "\n" not in warnings[0]


# ------------------------------------------------------------------------ color temperature


def test_blackbody_colors_are_usdlux_s_and_6500k_is_white() -> None:
    for kelvin in (1500.0, 3000.0, 6500.0, 9000.0):
        r, g, b = blackbody_rgb(kelvin)
        assert 0.2126 * r + 0.7152 * g + 0.0722 * b == pytest.approx(1.0, abs=1e-4)
    # D65 is close to, not exactly on, the Planckian locus: white within 5 %.
    np.testing.assert_allclose(blackbody_rgb(6500.0), (1.0, 1.0, 1.0), atol=0.05)
    r, g, b = blackbody_rgb(3000.0)
    assert r > g > b, "warm"
    r, g, b = blackbody_rgb(9000.0)
    assert b > g > r, "cool"


def test_color_temperature_multiplies_the_color_only_when_enabled(native, caplog) -> None:
    stage = ground_stage()
    light = UsdLux.RectLight.Define(stage, "/World/Key")
    light.AddTranslateOp().Set(Gf.Vec3d(0, 0, 3))
    light.CreateWidthAttr(4.0)
    light.CreateHeightAttr(4.0)
    light.CreateColorAttr(Gf.Vec3f(1.0, 0.5, 1.0))
    light.CreateColorTemperatureAttr(3000.0)
    prim = light.GetPrim()
    args = area_light_arguments(prim, Usd.TimeCode.Default(), np.eye(4))
    assert args is not None and args["color"] == pytest.approx((1.0, 0.5, 1.0))
    light.CreateEnableColorTemperatureAttr(True)
    args = area_light_arguments(prim, Usd.TimeCode.Default(), np.eye(4))
    want = np.array(blackbody_rgb(3000.0)) * (1.0, 0.5, 1.0)
    assert args is not None
    np.testing.assert_allclose(args["color"], want, rtol=1e-6)
    # Rendered: every channel sees the same samples, so the pixel's colour ratios are the
    # light's exactly.
    rgb = mean_color(render(stage, samples=2))
    np.testing.assert_allclose(rgb / rgb[0], want / want[0], rtol=1e-4)
    # Outside UsdLux's range: clipped to 10 000 K with one warning naming the light.
    light.CreateColorTemperatureAttr(20000.0)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        args = area_light_arguments(prim, Usd.TimeCode.Default(), np.eye(4))
    assert args is not None
    np.testing.assert_allclose(args["color"], np.array(blackbody_rgb(10000.0)) * (1.0, 0.5, 1.0))
    warnings = [r.getMessage() for r in caplog.records if "colorTemperature" in r.getMessage()]
    assert len(warnings) == 1 and "/World/Key" in warnings[0]


# --------------------------------------------------------------------------------- area lights


def test_each_area_light_lights_the_ground_as_its_closed_form_says(native) -> None:
    # The ground point under the light's centre, seen from the side through a narrow camera (so
    # the light itself is out of view): a disk of radius r at height h facing down gives
    # E = π L r² / (h² + r²); a sphere of radius r at height h, E = π L r² / h².
    for kind, inputs, irradiance in [
        (UsdLux.DiskLight, {"radius": 1.0}, math.pi * 5.0 / (9.0 + 1.0)),
        (UsdLux.SphereLight, {"radius": 0.5}, math.pi * 5.0 * 0.25 / 9.0),
    ]:
        stage = ground_stage()
        cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
        cam.ClearXformOpOrder()
        look = Gf.Matrix4d().SetLookAt(Gf.Vec3d(6, 0, 1), Gf.Vec3d(0, 0, 0), Gf.Vec3d(0, 0, 1))
        cam.AddTransformOp().Set(look.GetInverse())
        cam.CreateHorizontalApertureAttr(0.1)
        cam.CreateVerticalApertureAttr(0.1)
        light = kind.Define(stage, "/World/Light")
        light.AddTranslateOp().Set(Gf.Vec3d(0, 0, 3))
        light.CreateIntensityAttr(5.0)
        for name, value in inputs.items():
            light.GetPrim().GetAttribute(f"inputs:{name}").Set(value)
        got = mean_color(render(stage, width=8, samples=64))
        np.testing.assert_allclose(
            got, ALBEDO / math.pi * irradiance, rtol=0.01, err_msg=kind.__name__
        )


def test_treat_as_point_is_a_hint_the_sphere_keeps_its_radius() -> None:
    stage = ground_stage()
    light = UsdLux.SphereLight.Define(stage, "/World/Bulb")
    light.CreateRadiusAttr(0.3)
    light.CreateTreatAsPointAttr(True)
    args = area_light_arguments(light.GetPrim(), Usd.TimeCode.Default(), np.eye(4))
    assert args is not None and args["kind"] == "sphere" and args["radius"] == pytest.approx(0.3)


def test_a_broken_light_is_skipped_naming_it_and_the_others_still_light(native, caplog) -> None:
    stage = ground_stage()
    good = UsdLux.DistantLight.Define(stage, "/World/Sun")
    good.CreateAngleAttr(0.0)
    good.CreateIntensityAttr(1.0)
    bad = UsdLux.SphereLight.Define(stage, "/World/Broken")
    bad.CreateIntensityAttr(-4.0)
    nan = UsdLux.RectLight.Define(stage, "/World/NaN")
    nan.CreateColorAttr(Gf.Vec3f(1.0, float("nan"), 1.0))
    with caplog.at_level(logging.ERROR, logger="mipray"):
        result = render(stage)
    assert sorted(e.prim_path for e in result.errors) == ["/World/Broken", "/World/NaN"]
    messages = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert any("/World/Broken" in m and "intensity" in m for m in messages)
    assert all("\n" not in m for m in messages)
    np.testing.assert_allclose(result.aovs["color"][..., :3], ALBEDO / math.pi, rtol=1e-5)


# --------------------------------------------------------------------------------------- dome


def _latlong(native, tmp_path, texels: np.ndarray) -> str:
    path = tmp_path / "env.exr"
    native.write_image(
        str(path),
        {"color": np.ascontiguousarray(texels, dtype=np.float32)},
        ["color"],
        {"color": "float"},
    )
    return str(path)


def test_the_dome_texture_is_oriented_as_usdlux_says(native, tmp_path) -> None:
    # UsdLux's latlong (OpenEXR's): the map's centre column looks down the light's +Z, a quarter
    # of the way across is +X. A band at s ∈ [0.2, 0.3] lights a wall facing +X, not one facing −X.
    env = np.zeros((32, 64, 3), dtype=np.float32)
    env[:, 13:19, :] = 5.0
    texture = _latlong(native, tmp_path, env)
    values = {}
    for facing in (+1, -1):
        stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        wall = UsdGeom.Mesh.Define(stage, "/World/Wall")
        # Either side: shading faces the normals toward the viewer.
        wall.CreatePointsAttr([(0, -5, -5), (0, -5, 5), (0, 5, 5), (0, 5, -5)])
        wall.CreateFaceVertexCountsAttr([4])
        wall.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
        wall.CreateSubdivisionSchemeAttr("none")
        cam = UsdGeom.Camera.Define(stage, "/World/Cam")
        cam.AddTranslateOp().Set(Gf.Vec3d(8.0 * facing, 0, 0))
        cam.AddRotateYOp().Set(90.0 * facing)
        dome = UsdLux.DomeLight.Define(stage, "/World/Dome")
        dome.CreateTextureFileAttr(texture)
        values[facing] = mean_color(render(stage, width=8, samples=4))
    assert values[+1][0] > 0.1, values
    assert values[-1][0] < 0.01 * values[+1][0], values


def test_an_unsupported_dome_layout_is_read_as_latlong_with_one_warning(caplog) -> None:
    stage = ground_stage()
    dome = UsdLux.DomeLight.Define(stage, "/World/Probe")
    dome.CreateTextureFileAttr("probe.exr")
    dome.CreateTextureFormatAttr("mirroredBall")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        for _ in range(2):
            args = area_light_arguments(dome.GetPrim(), Usd.TimeCode.Default(), np.eye(4))
    assert args is not None and args["texture"].endswith("probe.exr")
    warnings = [r.getMessage() for r in caplog.records if "texture:format" in r.getMessage()]
    assert len(warnings) == 1 and "/World/Probe" in warnings[0] and "mirroredBall" in warnings[0]


def test_a_small_sun_in_the_dome_is_importance_sampled(native, tmp_path) -> None:
    # A dim sky (0.05) with a sun of radius 3° and radiance 2000 at 60° elevation: the ground's
    # irradiance is about π L_sky + (L_sun − L_sky) π sin²(3°) cos 30° (integrated from the texels
    # below). Cosine sampling would find the sun with a pixel's 16 light samples in about 4 % of
    # the pixels; importance sampling finds it in every one.
    h, w = 128, 256
    theta = (np.arange(h) + 0.5) / h * math.pi  # from the light's +Y
    lon = (0.5 - (np.arange(w) + 0.5) / w) * 2.0 * math.pi
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    d = np.stack(
        [
            st * np.sin(lon)[None, :],
            np.broadcast_to(ct, (h, w)),
            st * np.cos(lon)[None, :],
        ],
        -1,
    )
    # The sun at 30° from the pole, toward the light's +Z.
    sun_dir = np.array([0.0, math.cos(math.radians(30)), math.sin(math.radians(30))])
    inside = d @ sun_dir >= math.cos(math.radians(3.0))
    env = np.where(inside[..., None], 2000.0, 0.05).astype(np.float32)
    texture = _latlong(native, tmp_path, env)
    stage = ground_stage()
    dome = UsdLux.DomeLight.Define(stage, "/World/Dome")
    dome.CreateTextureFileAttr(texture)
    # Z-up stage: the light's +Y to +Z.
    UsdGeom.Xformable(dome).AddRotateXOp().Set(90.0)
    # What the texture really holds (the sun is a few texels wide): integrate it.
    solid = (2 * math.pi / w) * (
        np.cos(theta - math.pi / (2 * h)) - np.cos(theta + math.pi / (2 * h))
    )
    up = d[..., 1]  # the light's +Y is the stage's +Z, the ground's normal
    irradiance = float((env[..., 0] * np.clip(up, 0, None) * solid[:, None]).sum())
    result = render(stage, width=16, samples=4)
    color = result.aovs["color"][..., 0]
    assert np.isfinite(color).all()
    np.testing.assert_allclose(color.mean(), ALBEDO / math.pi * irradiance, rtol=0.02)
    # Per pixel (16 light and 16 BSDF samples): measured 0.145 of the mean. Cosine sampling would
    # find the sun in about 4 % of the pixels, a relative deviation near 5.
    assert color.std() < 0.25 * color.mean(), (color.std(), color.mean())
