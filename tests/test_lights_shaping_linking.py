"""UsdLux ShapingAPI and light and shadow linking, rendered from USD against closed forms.

A spot pointing down from height h lights the floor inside r = h·tan(cone angle) and
nothing outside; a light linked to one of two spheres leaves the other black; an occluder left
out of a light's shadow-linking collection casts no shadow, and the lit floor has the closed-form
radiance albedo · E / π.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdLux

import mipray
from mipray.usd.light import area_light_arguments

#: The default material's diffuse reflectance (UsdPreviewSurface's fallback).
ALBEDO = 0.18
#: The camera's height above the floor, looking straight down.
EYE = 8.0


def stage_with_camera(ground: bool = True) -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    if ground:
        mesh = UsdGeom.Mesh.Define(stage, "/World/Ground")
        mesh.CreatePointsAttr([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)])
        mesh.CreateFaceVertexCountsAttr([4])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
        mesh.CreateSubdivisionSchemeAttr("none")
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, EYE))
    # Square: an odd width puts a pixel's centre on the axis both ways.
    cam.CreateVerticalApertureAttr(cam.GetHorizontalApertureAttr().Get())
    return stage


def render(stage: Usd.Stage, width: int = 48, **settings: object) -> np.ndarray:
    with mipray.RenderSession(stage) as session:
        result = session.render("/World/Cam", width=width, settings=settings, camera_light=False)
    return np.asarray(result.aovs["color"][..., :3], dtype=np.float64)


def floor_radius(image: np.ndarray, stage: Usd.Stage) -> np.ndarray:
    """Per pixel, the distance from the point below the camera of the floor point it sees."""
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam")).GetCamera()
    height, width = image.shape[:2]
    half = EYE * camera.horizontalAperture / (2.0 * camera.focalLength)
    pixel = 2.0 * half / width
    ys, xs = np.mgrid[0:height, 0:width]
    return np.hypot((xs + 0.5 - width / 2) * pixel, (ys + 0.5 - height / 2) * pixel)


def test_a_spot_lights_the_floor_inside_h_tan_angle_only(native) -> None:
    stage = stage_with_camera()
    h, cone, radius, intensity = 2.0, 30.0, 0.01, 1.0e4
    spot = UsdLux.DiskLight.Define(stage, "/World/Spot")
    spot.AddTranslateOp().Set(Gf.Vec3d(0, 0, h))
    spot.CreateRadiusAttr(radius)
    spot.CreateIntensityAttr(intensity)
    UsdLux.ShapingAPI.Apply(spot.GetPrim()).CreateShapingConeAngleAttr(cone)
    image = render(stage, samples=4)
    r = floor_radius(image, stage)
    edge = h * math.tan(math.radians(cone))
    inside, outside = r < 0.9 * edge, r > 1.1 * edge
    assert inside.sum() > 50 and outside.sum() > 50
    assert float(image[outside].max()) == 0.0, "light outside the cone"
    # Inside: L · A · cos θ · cos θ / d² · albedo / π (a small disk facing down), whatever r.
    d2 = r[inside] ** 2 + h * h
    truth = intensity * math.pi * radius**2 * (h * h / d2) / d2 * ALBEDO / math.pi
    got = image[inside][:, 0]
    assert np.allclose(got, truth, rtol=0.03), float(np.abs(got / truth - 1).max())


def test_shaping_inputs_are_read_with_the_schema_s_fallbacks() -> None:
    stage = stage_with_camera()
    sphere = UsdLux.SphereLight.Define(stage, "/World/Bulb").GetPrim()
    identity = np.eye(4)
    assert "cone_angle" not in area_light_arguments(sphere, Usd.TimeCode.Default(), identity)
    shaping = UsdLux.ShapingAPI.Apply(sphere)
    shaping.CreateShapingFocusAttr(2.0)
    shaping.CreateShapingFocusTintAttr((0.5, 0.25, 0.0))
    args = area_light_arguments(sphere, Usd.TimeCode.Default(), identity)
    assert args is not None
    # Applied, the cone falls back to UsdLux's 90°: a sphere then lights only its −Z half.
    assert (args["cone_angle"], args["cone_softness"], args["focus"]) == (90.0, 0.0, 2.0)
    assert args["focus_tint"] == (0.5, 0.25, 0.0)


def two_spheres() -> Usd.Stage:
    stage = stage_with_camera(ground=False)
    for name, x in (("A", -0.8), ("B", 0.8)):
        sphere = UsdGeom.Sphere.Define(stage, f"/World/{name}")
        sphere.CreateRadiusAttr(0.5)
        sphere.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0.5))
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateAngleAttr(0.0)
    sun.CreateIntensityAttr(1.0)
    return stage


def test_a_light_linked_to_one_sphere_leaves_the_other_dark(native) -> None:
    stage = two_spheres()
    width = 48
    left, right = slice(0, width // 2), slice(width // 2, width)
    both = render(stage, width)
    assert both[:, left].max() > 0.0 and both[:, right].max() > 0.0
    # The sphere's top faces the light: albedo · E / π, E = 1 (a point at infinity).
    assert math.isclose(float(both.max()), ALBEDO / math.pi, rel_tol=0.02)
    link = UsdLux.LightAPI(stage.GetPrimAtPath("/World/Sun")).GetLightLinkCollectionAPI()
    link.CreateIncludeRootAttr(False)
    link.CreateIncludesRel().AddTarget("/World/A")
    only_a = render(stage, width)
    # The screen's left half holds A at x < 0 or B: whichever is lit, one half stays black.
    halves = sorted([float(only_a[:, left].max()), float(only_a[:, right].max())])
    assert halves[0] == 0.0 and math.isclose(halves[1], ALBEDO / math.pi, rel_tol=0.02)
    # Excluding A instead (includeRoot back to its fallback) swaps them.
    link.GetIncludeRootAttr().Clear()
    link.GetIncludesRel().ClearTargets(True)
    link.CreateExcludesRel().AddTarget("/World/A")
    only_b = render(stage, width)
    assert np.array_equal(only_b > 0, (only_a == 0) & (both > 0))


def test_an_occluder_left_out_of_shadow_linking_casts_no_shadow(native) -> None:
    stage = stage_with_camera()
    occluder = UsdGeom.Mesh.Define(stage, "/World/Occluder")
    occluder.CreatePointsAttr([(-0.5, -0.5, 1), (0.5, -0.5, 1), (0.5, 0.5, 1), (-0.5, 0.5, 1)])
    occluder.CreateFaceVertexCountsAttr([4])
    occluder.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    occluder.CreateSubdivisionSchemeAttr("none")
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateAngleAttr(0.0)
    sun.CreateIntensityAttr(1.0)
    # Travelling along (1, 0, −1)/√2: the occluder's shadow falls on x ∈ [0.5, 1.5].
    sun.AddRotateYOp().Set(-45.0)
    image = render(stage, 64)
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam")).GetCamera()
    half = EYE * camera.horizontalAperture / (2.0 * camera.focalLength)
    column = int((1.0 + half) / (2 * half) * image.shape[1])
    row = image.shape[0] // 2
    lit = ALBEDO * math.cos(math.radians(45.0)) / math.pi
    assert image[row, column, 0] == 0.0, "in the occluder's shadow"
    assert math.isclose(float(image[row, 5, 0]), lit, rel_tol=0.01)
    shadow = UsdLux.LightAPI(sun.GetPrim()).GetShadowLinkCollectionAPI()
    shadow.CreateExcludesRel().AddTarget("/World/Occluder")
    unshadowed = render(stage, 64)
    assert math.isclose(float(unshadowed[row, column, 0]), lit, rel_tol=0.01)
    # The light still lights the occluder itself (linking is not shadow linking).
    assert float(unshadowed.max()) > 0.0


def test_the_stats_name_each_light_and_what_it_did(native) -> None:
    stage = two_spheres()
    link = UsdLux.LightAPI(stage.GetPrimAtPath("/World/Sun")).GetLightLinkCollectionAPI()
    link.CreateExcludesRel().AddTarget("/World/B")
    shadow = UsdLux.LightAPI(stage.GetPrimAtPath("/World/Sun")).GetShadowLinkCollectionAPI()
    shadow.CreateIncludeRootAttr(False)
    bulb = UsdLux.SphereLight.Define(stage, "/World/Bulb")
    UsdLux.ShapingAPI.Apply(bulb.GetPrim()).CreateShapingConeSoftnessAttr(0.25)
    with mipray.RenderSession(stage) as session:
        result = session.render("/World/Cam", width=8, camera_light=False)
    lights = {light["name"]: light for light in result.stats["scene"]["lights"]}
    sun, spot = lights["/World/Sun"], lights["/World/Bulb"]
    assert sun["kind"] == "distant" and sun["not_illuminating"] == ["/World/B"]
    assert sorted(sun["not_shadowed_by"]) == ["/World/A", "/World/B"]
    assert "shaping" not in sun and "not_illuminating" not in spot
    assert spot["kind"] == "sphere" and spot["casts_shadows"]
    assert math.isclose(spot["shaping"]["cone_angle_deg"], 90.0, rel_tol=1e-6)
    assert spot["shaping"]["cone_softness"] == 0.25


def test_shaping_on_a_distant_light_stays_listed_as_unsupported_ies_profiles_do_not() -> None:
    from mipray.usd.unsupported import audit_stage

    stage = stage_with_camera()
    UsdGeom.Xform.Define(stage, "/World")
    bulb = UsdLux.SphereLight.Define(stage, "/World/Bulb").GetPrim()
    shaping = UsdLux.ShapingAPI.Apply(bulb)
    shaping.CreateShapingConeAngleAttr(40.0)
    shaping.CreateShapingIesFileAttr("profile.ies")
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun").GetPrim()
    UsdLux.ShapingAPI.Apply(sun).CreateShapingFocusAttr(2.0)
    UsdLux.LightAPI(sun).GetLightLinkCollectionAPI().CreateExcludesRel().AddTarget("/World/G")
    found = {(u.prim, u.what) for u in audit_stage(stage, Usd.TimeCode.Default(), ("default",))}
    # The bulb's IES profile is read (tests/test_ies.py); the sun's shaping is not.
    assert found == {("/World/Sun", "ShapingAPI inputs:shaping:focus")}


def test_a_cylinder_light_lights_the_floor_as_the_quadrature_of_its_wall(native) -> None:
    # A tube along X (its local axis) of radius 0.2 and length 1.5, 2 units above the floor and
    # 1 unit aside, out of the view of the floor point the image's centre shows.
    stage = stage_with_camera()
    radius, length, h, side, intensity = 0.2, 1.5, 2.0, 1.0, 5.0
    tube = UsdLux.CylinderLight.Define(stage, "/World/Tube")
    tube.AddTranslateOp().Set(Gf.Vec3d(0, side, h))
    tube.CreateRadiusAttr(radius)
    tube.CreateLengthAttr(length)
    tube.CreateIntensityAttr(intensity)
    # E at the origin = ∫ L cos θ_light cos θ_floor / d² dA over the wall facing the point.
    x, phi = np.meshgrid(
        (np.arange(1500) + 0.5) / 1500 * length - length / 2,
        (np.arange(1500) + 0.5) / 1500 * 2 * math.pi,
    )
    normal = np.stack([np.zeros_like(x), np.cos(phi), np.sin(phi)], -1)
    point = np.stack([x, side + radius * np.cos(phi), h + radius * np.sin(phi)], -1)
    d2 = (point**2).sum(-1)
    w = point / np.sqrt(d2)[..., None]
    cos_light = np.clip(-(normal * w).sum(-1), 0.0, None)
    area = 2 * math.pi * radius * length / x.size
    irradiance = float((intensity * cos_light * w[..., 2] / d2).sum() * area)
    image = render(stage, 33, samples=16)
    row = image.shape[0] // 2
    centre = image[row, 16, 0]
    assert math.isclose(float(centre), ALBEDO * irradiance / math.pi, rel_tol=0.03)
    # Normalized, the same light's radiance is divided by its wall's area.
    tube.CreateNormalizeAttr(True)
    normalized = render(stage, 33, samples=16)[row, 16, 0]
    wall = 2 * math.pi * radius * length
    assert math.isclose(float(normalized), float(centre) / wall, rel_tol=0.03)


def _rect_irradiance(
    p: tuple[float, float], h: float, x0: float, x1: float, y0: float, y1: float
) -> float:
    """E at floor point ``p`` from the part [x0, x1] × [y0, y1] of a rect of radiance 1 at
    height ``h`` facing down: ∫ cos θ_light cos θ_floor / d² dA by quadrature."""
    n = 400
    xs = x0 + (np.arange(n) + 0.5) / n * (x1 - x0)
    ys = y0 + (np.arange(n) + 0.5) / n * (y1 - y0)
    x, y = np.meshgrid(xs, ys)
    d2 = (x - p[0]) ** 2 + (y - p[1]) ** 2 + h * h
    return float((h * h / d2**2).sum() * (x1 - x0) * (y1 - y0) / (n * n))


def test_a_rect_light_texture_colours_its_light_as_laid_over_the_rect(native, tmp_path) -> None:
    # Red on its left half (s < 0.5: the light's −X half), green on its right: fine enough
    # that filtering across the middle is negligible.
    texels = np.zeros((8, 64, 3), dtype=np.float32)
    texels[:, :32] = (1.0, 0.0, 0.0)
    texels[:, 32:] = (0.0, 1.0, 0.0)
    path = tmp_path / "card.exr"
    native.write_image(str(path), {"color": texels}, ["color"], {"color": "float"})
    stage = stage_with_camera()
    h, width, height, intensity = 1.0, 2.0, 1.0, 4.0
    card = UsdLux.RectLight.Define(stage, "/World/Card")
    card.AddTranslateOp().Set(Gf.Vec3d(0, 0, h))
    card.CreateWidthAttr(width)
    card.CreateHeightAttr(height)
    card.CreateIntensityAttr(intensity)
    card.CreateTextureFileAttr(str(path))
    image = render(stage, 33, samples=256)
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam")).GetCamera()
    half = EYE * camera.horizontalAperture / (2.0 * camera.focalLength)
    pixel = 2 * half / 33
    got, want = [], []
    for column in range(8, 25, 2):  # along the rect's X axis, under its middle
        x = (column + 0.5) * pixel - half
        red = _rect_irradiance((x, 0.0), h, -1.0, 0.0, -0.5, 0.5)
        green = _rect_irradiance((x, 0.0), h, 0.0, 1.0, -0.5, 0.5)
        want.append(np.array([red, green, 0.0]) * intensity * ALBEDO / math.pi)
        got.append(image[image.shape[0] // 2, column])
    # Each pixel within its noise (a texel's colour per light sample), the row's sums closely;
    # mirrored, red and green would swap (about 4.5× on either end).
    assert np.allclose(got, want, rtol=0.1, atol=1e-6), (got, want)
    assert np.allclose(np.sum(got, axis=0), np.sum(want, axis=0), rtol=0.02, atol=1e-6)


@pytest.mark.parametrize("kind", ["rect", "dome"])
def test_a_light_texture_that_cannot_be_read_is_named_once_and_lights_with_its_colour(
    native, tmp_path, caplog, kind
) -> None:
    missing = tmp_path / "no-such-card.exr"
    stage = stage_with_camera()
    if kind == "rect":
        light = UsdLux.RectLight.Define(stage, "/World/Light")
        light.AddTranslateOp().Set(Gf.Vec3d(0, 0, 1.0))
    else:
        light = UsdLux.DomeLight.Define(stage, "/World/Light")
    light.CreateIntensityAttr(2.0)
    light.CreateTextureFileAttr(str(missing))
    with caplog.at_level(logging.WARNING):
        with mipray.RenderSession(stage) as session:
            for _ in range(2):
                got = session.render(
                    "/World/Cam", width=24, settings={"samples": 2}, camera_light=False
                )
    named = [r.getMessage() for r in caplog.records if "no-such-card.exr" in r.getMessage()]
    assert len(named) == 1 and "/World/Light" in named[0], named
    # The frame renders as the same light without a texture.
    light.GetPrim().RemoveProperty("inputs:texture:file")
    plain = render(stage, 24, samples=2)
    image = np.asarray(got.aovs["color"][..., :3], dtype=np.float64)
    assert image.max() > 0.0
    np.testing.assert_array_equal(image, plain)
