"""Integrators chosen by the ``integrator`` render setting, end to end from USD.

White furnaces against their closed forms (a convex subdivision surface of albedo ρ in a
uniform dome of radiance 1 reflects ρ; with ρ = 1 an open box is 1 everywhere only when
path traced), the effects each integrator reports, and determinism: the image is a function
of the seed alone, byte-identical with 1 and 2 threads and with or without ``progressive``.
"""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

import mipray
from mipray import RenderSettingsError

INTEGRATORS = ("auto", "direct", "ao", "colorBleeding", "path")


def _white_material(stage: Usd.Stage, albedo: float) -> UsdShade.Material:
    material = UsdShade.Material.Define(stage, "/World/Looks/White")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/White/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(albedo))
    # A lambertian surface: no specular layer (the specular workflow with a black specular).
    shader.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    shader.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.0))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def _furnace(albedo: float, *, concave: bool) -> Usd.Stage:
    """A white object in a uniform dome of radiance 1, seen by /World/Cam (Z up)."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Object")
    points = [(x, y, z) for z in (0.0, 2.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)]
    mesh.CreatePointsAttr(points)
    if concave:
        # An open box (no top): polygons, so its inside is a cavity the dome half sees.
        mesh.CreateFaceVertexCountsAttr([4] * 5)
        mesh.CreateFaceVertexIndicesAttr(
            [0, 2, 3, 1, 0, 1, 5, 4, 1, 3, 7, 5, 3, 2, 6, 7, 2, 0, 4, 6]
        )
        mesh.CreateSubdivisionSchemeAttr("none")
    else:
        # A cube's Catmull-Clark limit surface: smooth and convex.
        mesh.CreateFaceVertexCountsAttr([4] * 6)
        mesh.CreateFaceVertexIndicesAttr(
            [0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 1, 3, 7, 5, 3, 2, 6, 7, 2, 0, 4, 6]
        )
        mesh.CreateSubdivisionSchemeAttr("catmullClark")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(_white_material(stage, albedo))
    dome = UsdLux.DomeLight.Define(stage, "/World/Dome")
    dome.CreateIntensityAttr(1.0)
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    # Above and in front, looking down into the box (or at the blob).
    cam.AddTranslateOp().Set(Gf.Vec3d(0.0, -1.5, 7.0))
    cam.AddRotateXOp().Set(12.0)
    return stage


def _render(stage: Usd.Stage, **settings: object) -> mipray.RenderResult:
    return mipray.render(stage, "/World/Cam", width=24, aovs=("color", "alpha"), settings=settings)


@pytest.mark.parametrize("albedo", [1.0, 0.5])
@pytest.mark.parametrize("integrator", ["auto", "path", "colorBleeding"])
def test_a_convex_white_object_in_a_furnace_reflects_its_albedo(native, integrator, albedo) -> None:
    result = _render(_furnace(albedo, concave=False), integrator=integrator, samples=4)
    color, alpha = result.aovs["color"], result.aovs["alpha"][..., 0]
    on = alpha == 1.0
    assert on.sum() > 100, "the object must fill part of the view"
    assert np.isfinite(color).all()
    assert abs(color[on].mean() - albedo) < 0.015, (integrator, color[on].mean())
    # Shadow rays near the tessellation's horizon: a few percent at most, anywhere.
    assert np.abs(color[on] - albedo).max() < 0.08


def test_a_concave_white_box_in_a_furnace_is_white_only_when_path_traced(native) -> None:
    stage = _furnace(1.0, concave=True)
    path = _render(stage, integrator="path", samples=16, maxDepth=40)
    c = path.aovs["color"]
    assert abs(c.mean() - 1.0) < 0.02, c.mean()
    direct = _render(stage, integrator="auto", samples=4)
    assert direct.aovs["color"][direct.aovs["alpha"][..., 0] == 1.0].mean() < 0.9


def test_each_integrator_reports_the_effects_it_traces(native) -> None:
    stage = _furnace(0.5, concave=True)

    def effects(**settings: object) -> dict[str, str]:
        result = _render(stage, samples=1, **settings)
        return {e["name"]: e["why"] for e in result.stats["effects"]["enabled"]}

    assert "indirect_diffuse" not in effects(integrator="auto")
    assert "integrator = path" in effects(integrator="path")["indirect_diffuse"]
    assert "integrator = colorBleeding" in effects(integrator="colorBleeding")["indirect_diffuse"]
    ao = effects(integrator="ao", aoSamples=4)
    assert set(ao) == {"camera", "ao"}, ao
    assert "ao" not in effects(integrator="direct", aoSamples=4)
    rays = _render(stage, samples=1).stats["render"]["rays"]
    assert rays["diffuse"] == 0 and rays["ao"] == 0 and rays["camera"] > 0


def test_unknown_integrators_and_unusable_settings_are_refused(native) -> None:
    stage = _furnace(0.5, concave=False)
    with pytest.raises(
        RenderSettingsError, match=r"integrator.*auto, direct, ao, colorBleeding, path"
    ):
        _render(stage, integrator="photonMap")
    with pytest.raises(RenderSettingsError, match=r"aoSamples"):
        _render(stage, integrator="ao")


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_the_image_is_a_function_of_the_seed_alone(native, integrator) -> None:
    # A soft light, a dome and a cavity: every integrator draws many random numbers here.
    stage = _furnace(0.6, concave=True)
    light = UsdLux.RectLight.Define(stage, "/World/Rect")
    light.CreateIntensityAttr(4.0)
    light.AddTranslateOp().Set(Gf.Vec3d(0.5, 0.0, 4.0))
    base = {"integrator": integrator, "samples": 4, "seed": 3, "aoSamples": 4, "indirectSamples": 8}
    one = _render(stage, threads=1, **base).aovs["color"]
    two = _render(stage, threads=2, **base).aovs["color"]
    progressive = _render(stage, threads=2, progressive=1, **base).aovs["color"]
    assert one.tobytes() == two.tobytes(), f"{integrator}: 1 and 2 threads differ"
    assert one.tobytes() == progressive.tobytes(), f"{integrator}: progressive differs"
    reseeded = _render(stage, threads=2, **{**base, "seed": 4}).aovs["color"]
    assert reseeded.tobytes() != one.tobytes(), f"{integrator}: the seed must matter"


def test_progressive_rendering_reports_all_its_work(native) -> None:
    seen: list[tuple[int, int]] = []
    stage = _furnace(0.5, concave=True)
    with mipray.RenderSession(stage) as session:
        session.render(
            "/World/Cam",
            24,
            settings={"integrator": "path", "samples": 8, "progressive": 1},
            progress=lambda done, total: seen.append((done, total)),
        )
    assert seen and seen[-1][0] == seen[-1][1], seen[-3:]
