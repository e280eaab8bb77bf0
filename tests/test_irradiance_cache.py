"""The irradiance cache (``irradianceCache``, ``irradianceCacheError``) end to end from USD.

Ambient occlusion (``integrator = ao``) and one-bounce color bleeding (``colorBleeding``)
rendered with the cache agree with the same renders without it to within what the error
bound allows, from far fewer hemisphere rays; the stats report the cache; the image is the same
with one and two threads; a bad error bound is refused naming the setting; and
``mipray-sweep`` sweeps the two knobs, its reference rendered without the cache. The
closed-form checks (a plane beside a wall, a white furnace, a closed emissive box) are the core's
``rust/tests/irradiance_cache.rs``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

import mipray
from mipray import RenderSettingsError
from mipray.tools import sweep as sw

WIDTH = 64


def _material(stage: Usd.Stage, name: str, color: tuple[float, float, float]) -> UsdShade.Material:
    material = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
    shader = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    shader.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    shader.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.0))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def _box(
    stage: Usd.Stage, path: str, lo: tuple[float, ...], hi: tuple[float, ...], scheme: str
) -> UsdGeom.Mesh:
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(
        [(x, y, z) for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])]
    )
    mesh.CreateFaceVertexCountsAttr([4] * 6)
    mesh.CreateFaceVertexIndicesAttr(
        [0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 1, 3, 7, 5, 3, 2, 6, 7, 2, 0, 4, 6]
    )
    mesh.CreateSubdivisionSchemeAttr(scheme)
    return mesh


def _stage() -> Usd.Stage:
    """A white ground, a red wall and a rounded white blob beside it, under a sun (Z up)."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    ground = UsdGeom.Mesh.Define(stage, "/World/Ground")
    ground.CreatePointsAttr([(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)])
    ground.CreateFaceVertexCountsAttr([4])
    ground.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    ground.CreateSubdivisionSchemeAttr("none")
    white = _material(stage, "White", (0.7, 0.7, 0.7))
    UsdShade.MaterialBindingAPI.Apply(ground.GetPrim()).Bind(white)
    wall = _box(stage, "/World/Wall", (-1.6, -2.0, 0.0), (-1.3, 2.0, 1.5), "none")
    UsdShade.MaterialBindingAPI.Apply(wall.GetPrim()).Bind(_material(stage, "Red", (0.8, 0.1, 0.1)))
    blob = _box(stage, "/World/Blob", (-0.9, -0.5, -0.3), (0.1, 0.5, 1.0), "catmullClark")
    UsdShade.MaterialBindingAPI.Apply(blob.GetPrim()).Bind(white)
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(2.0)
    sun.CreateNormalizeAttr(True)  # intensity = irradiance facing the light (UsdLux)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(40.0, 25.0, 0.0))
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.CreateHorizontalApertureAttr(24.0)
    cam.CreateVerticalApertureAttr(18.0)
    cam.AddTranslateOp().Set(Gf.Vec3d(0.3, -5.0, 3.2))
    cam.AddRotateXOp().Set(60.0)
    return stage


def _render(stage: Usd.Stage, **settings: object) -> mipray.RenderResult:
    return mipray.render(stage, "/World/Cam", width=WIDTH, aovs=("color", "ao"), settings=settings)


def _lit(result: mipray.RenderResult) -> np.ndarray:
    return result.aovs["color"].sum(axis=-1) > 0


def test_cached_ambient_occlusion_agrees_with_uncached_from_fewer_rays(native) -> None:
    stage = _stage()
    base = {"integrator": "ao", "aoSamples": 64, "aoDistance": 2.0}
    plain = _render(stage, **base)
    for error in (0.2, 0.05):
        cached = _render(stage, irradianceCache=1, irradianceCacheError=error, **base)
        ao, ref = cached.aovs["ao"][..., 0], plain.aovs["ao"][..., 0]
        assert np.isfinite(cached.aovs["color"]).all() and np.isfinite(ao).all()
        # Noise of 64 rays (σ ≤ 0.06 a pixel) plus interpolation error bounded by about a.
        assert abs(ao.mean() - ref.mean()) < 0.02, (error, ao.mean(), ref.mean())
        assert np.sqrt(np.mean((ao - ref) ** 2)) < 0.05 + 0.25 * error, error
        ic = cached.stats["irradiance_cache"]["occlusion"]
        assert ic["records"] > 0 and ic["error_bound"] == pytest.approx(error)
        assert ic["interpolated"] > 0.9 * ic["lookups"], ic
        assert cached.stats["render"]["rays"]["ao"] < 0.7 * plain.stats["render"]["rays"]["ao"]
    assert "irradiance_cache" not in plain.stats


def test_cached_color_bleeding_agrees_with_uncached_from_fewer_rays(native) -> None:
    stage = _stage()
    base = {"integrator": "colorBleeding", "indirectSamples": 64, "shadowSamples": 1}
    aovs = ("color", "indirectDiffuse")
    plain = mipray.render(stage, "/World/Cam", width=WIDTH, aovs=aovs, settings=base)
    cached = mipray.render(
        stage,
        "/World/Cam",
        width=WIDTH,
        aovs=aovs,
        settings={**base, "irradianceCache": 1, "irradianceCacheError": 0.1},
    )
    assert np.isfinite(cached.aovs["color"]).all()
    on = _lit(plain)
    # The bounce alone: the red wall bleeds red onto the white ground and blob.
    ind, ref = cached.aovs["indirectDiffuse"][on], plain.aovs["indirectDiffuse"][on]
    bleed = ref[:, 0].mean() - ref[:, 1].mean()
    assert bleed > 0.2 * ref[:, 1].mean(), "the scene must show color bleeding"
    for channel in range(3):
        assert abs(ind[:, channel].mean() - ref[:, channel].mean()) < 0.05 * ref[:, channel].mean()
    assert abs((ind[:, 0].mean() - ind[:, 1].mean()) - bleed) < 0.1 * bleed
    # The rest (direct light, the same random numbers) is untouched by the cache.
    direct = cached.aovs["color"] - cached.aovs["indirectDiffuse"]
    assert np.allclose(direct, plain.aovs["color"] - plain.aovs["indirectDiffuse"], atol=1e-5)
    ic = cached.stats["irradiance_cache"]["irradiance"]
    assert ic["records"] > 0 and ic["interpolated"] > 0.9 * ic["lookups"]
    rays = cached.stats["render"]["rays"]["diffuse"], plain.stats["render"]["rays"]["diffuse"]
    assert rays[0] < 0.7 * rays[1], rays
    assert any(e["name"] == "indirect_diffuse" for e in cached.stats["effects"]["enabled"])


@pytest.mark.parametrize("integrator", ["ao", "colorBleeding", "auto"])
def test_cached_renders_are_a_function_of_the_seed_alone(native, integrator) -> None:
    stage = _stage()
    base = {
        "integrator": integrator,
        "aoSamples": 8,
        "indirectSamples": 8,
        "samples": 2,
        "irradianceCache": 1,
        "irradianceCacheError": 0.2,
    }
    one = _render(stage, threads=1, **base)
    two = _render(stage, threads=2, **base)
    for aov in ("color", "ao"):
        assert one.aovs[aov].tobytes() == two.aovs[aov].tobytes(), (integrator, aov)
    records = {q: v["records"] for q, v in one.stats["irradiance_cache"].items()}
    assert records == {q: v["records"] for q, v in two.stats["irradiance_cache"].items()}


@pytest.mark.parametrize("bad", [0, -0.1, 11])
def test_an_error_bound_out_of_range_is_refused(native, bad: float) -> None:
    with pytest.raises(RenderSettingsError, match="irradianceCacheError"):
        _render(_stage(), integrator="ao", aoSamples=4, irradianceCache=1, irradianceCacheError=bad)


def test_the_sweep_varies_the_error_bound_against_an_uncached_reference(
    native, tmp_path: Path
) -> None:
    path = tmp_path / "wall.usda"
    stage = _stage()  # kept alive while its layer is exported
    stage.GetRootLayer().Export(str(path))
    settings = {"integrator": "ao", "aoSamples": 8, "irradianceCache": 1}
    assert (
        sw.auto_reference_settings({"irradianceCacheError": [0.4, 0.1]}, settings)[
            "irradianceCache"
        ]
        == 0
    )
    rows = sw.sweep(
        path,
        {"irradianceCacheError": [0.4, 0.1]},
        settings=settings,
        width=32,
        camera="/World/Cam",
        reference_samples=2,
        out=None,
        plot=False,
    )
    assert [r["setting"]["irradianceCacheError"] for r in rows] == [0.4, 0.1]
    for r in rows:
        assert r["settings"]["irradianceCache"] == 1
        assert np.isfinite(r["color_rmse"]) and r["color_rmse"] > 0
