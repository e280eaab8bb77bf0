"""Mesh lights tinted by their material, instanced, and moving, against closed forms.

UsdLux's ``materialGlowTintsLight`` (``MeshLightAPI``'s fallback) multiplies the light's colour
by the bound UsdPreviewSurface's ``emissiveColor``, so the floor under a tinted square is the
tint times Lambert's figure for the untinted one; a mesh light in a PointInstancer's or a
native instance's prototype emits from each instance (two squares light their midpoint twice as
one does); a moving square lights the floor with Lambert's irradiance averaged over the
camera's shutter.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade
from test_lights_shaping_linking import ALBEDO, stage_with_camera
from test_mesh_lights import HALF, H, floor_xy, lambert_square, square_light

import mipray


def render_with_stats(stage: Usd.Stage, width: int = 33, time: float | None = None, **settings):
    with mipray.RenderSession(stage) as session:
        kwargs = {} if time is None else {"time": time}
        result = session.render(
            "/World/Cam",
            width=width,
            settings={"samples": 64, "shadowSamples": 4, **settings},
            camera_light=False,
            **kwargs,
        )
    return np.asarray(result.aovs["color"][..., :3], dtype=np.float64), result.stats


def bind_emissive(
    stage: Usd.Stage,
    prim: Usd.Prim,
    emissive: tuple[float, float, float] | None,
    name: str = "Glow",
):
    material = UsdShade.Material.Define(stage, f"/Looks/{name}")
    shader = UsdShade.Shader.Define(stage, f"/Looks/{name}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    if emissive is not None:
        shader.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*emissive))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def relative_error(image: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Mean and largest relative error of channel values where the truth is lit."""
    lit = truth > 0.05 * truth.max()
    assert lit.sum() > 200
    rel = image[lit] / truth[lit] - 1.0
    return float(rel.mean()), float(np.abs(rel).max())


def test_the_bound_materials_emission_tints_the_light(native, caplog) -> None:
    intensity, tint = 3.0, (0.5, 1.0, 0.25)
    stage = stage_with_camera()
    prim = square_light(stage, intensity=intensity)
    plain, _ = render_with_stats(stage)
    bind_emissive(stage, prim, tint)
    tinted, stats = render_with_stats(stage)
    x, y = floor_xy(tinted, stage)
    truth = intensity * lambert_square(x, y) * ALBEDO / math.pi
    for c in range(3):
        mean, worst = relative_error(tinted[..., c], tint[c] * truth)
        assert abs(mean) < 0.01 and worst < 0.08, (c, mean, worst)
    # The same samples as the untinted light: tint × that image, channel by channel.
    lit = truth > 0.05 * truth.max()
    for c in range(3):
        np.testing.assert_allclose(tinted[..., c][lit], tint[c] * plain[..., c][lit], rtol=1e-4)
    (entry,) = stats["scene"]["lights"]
    assert entry["name"] == "/World/Glow" and entry["kind"] == "mesh"
    np.testing.assert_allclose(entry["radiance"], [intensity * c for c in tint], rtol=1e-6)
    # independent: the light's own colour alone, whatever the material.
    prim.CreateAttribute("light:materialSyncMode", Sdf.ValueTypeNames.Token).Set("independent")
    independent, _ = render_with_stats(stage)
    np.testing.assert_allclose(independent[lit], plain[lit], rtol=1e-5)
    # materialGlowTintsLight with a material that emits nothing (emissiveColor's fallback is
    # black): the light emits nothing, and says so once.
    prim.GetAttribute("light:materialSyncMode").Set("materialGlowTintsLight")
    bind_emissive(stage, prim, None, "Dull")
    with caplog.at_level(logging.WARNING):
        dark, _ = render_with_stats(stage)
    assert float(dark.max()) == 0.0
    assert any("/World/Glow" in r.message and "emits nothing" in r.message for r in caplog.records)


def test_a_geometry_light_is_not_tinted_by_its_meshs_material(native) -> None:
    # GeometryLight's materialSyncMode falls back to noMaterialResponse.
    stage = stage_with_camera()
    mesh = UsdGeom.Mesh.Define(stage, "/World/Glow")
    a = HALF
    mesh.CreatePointsAttr([(-a, -a, H), (a, -a, H), (a, a, H), (-a, a, H)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 3, 2, 1])
    mesh.CreateSubdivisionSchemeAttr("none")
    bind_emissive(stage, mesh.GetPrim(), (0.0, 0.0, 1.0))
    light = UsdLux.GeometryLight.Define(stage, "/World/GeoLight")
    light.CreateIntensityAttr(3.0)
    light.CreateGeometryRel().AddTarget("/World/Glow")
    image, _ = render_with_stats(stage)
    x, y = floor_xy(image, stage)
    truth = 3.0 * lambert_square(x, y) * ALBEDO / math.pi
    mean, _ = relative_error(image[..., 0], truth)
    assert abs(mean) < 0.01


D = 0.9  # the instances' offsets along x


def instanced_squares(stage: Usd.Stage, native: bool) -> None:
    """Two copies of the down-facing square at x = ±D, height H: a PointInstancer's or native
    instances of one prototype."""
    # A PointInstancer's prototypes live under it (rendered only through it).
    proto_root = "/World/Lamps/Protos/Lamp" if not native else "/Lamp"
    if native:
        stage.DefinePrim(proto_root, "Xform").SetSpecifier(Sdf.SpecifierClass)
    else:
        UsdGeom.PointInstancer.Define(stage, "/World/Lamps")
        UsdGeom.Xform.Define(stage, proto_root)
    mesh = UsdGeom.Mesh.Define(stage, f"{proto_root}/Glow")
    a = HALF
    mesh.CreatePointsAttr([(-a, -a, H), (a, -a, H), (a, a, H), (-a, a, H)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 3, 2, 1])  # facing down
    mesh.CreateSubdivisionSchemeAttr("none")
    UsdLux.MeshLightAPI.Apply(mesh.GetPrim())
    UsdLux.LightAPI(mesh.GetPrim()).CreateIntensityAttr(3.0)
    if native:
        for k, x in enumerate((-D, D)):
            inst = UsdGeom.Xform.Define(stage, f"/World/Lamp{k}")
            inst.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
            inst.GetPrim().GetReferences().AddInternalReference(proto_root)
            inst.GetPrim().SetInstanceable(True)
    else:
        pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Lamps"))
        pi.CreatePrototypesRel().AddTarget(proto_root)
        pi.CreateProtoIndicesAttr([0, 0])
        pi.CreatePositionsAttr([(-D, 0, 0), (D, 0, 0)])


def test_each_instance_of_a_mesh_light_emits(native) -> None:
    for native_instances in (False, True):
        stage = stage_with_camera()
        instanced_squares(stage, native_instances)
        image, stats = render_with_stats(stage)
        x, y = floor_xy(image, stage)
        one = 3.0 * lambert_square(x - D, y) * ALBEDO / math.pi
        truth = one + 3.0 * lambert_square(x + D, y) * ALBEDO / math.pi
        mean, worst = relative_error(image[..., 0], truth)
        assert abs(mean) < 0.01 and worst < 0.08, (native_instances, mean, worst)
        # At the symmetric point (the axis: the centre pixel) twice one instance's figure.
        c = image.shape[0] // 2
        assert math.isclose(truth[c, c], 2.0 * one[c, c], rel_tol=1e-9)
        # The 3 × 3 pixels about it, against twice one instance's figure there.
        block = np.s_[c - 1 : c + 2, c - 1 : c + 2]
        ratio = image[block][..., 0].mean() / (2.0 * one[block]).mean()
        assert abs(ratio - 1.0) < 0.02, ratio
        lights = stats["scene"]["lights"]
        assert len(lights) == 2 and all(e["kind"] == "mesh" for e in lights), lights
        names = sorted(e["name"] for e in lights)
        assert names[0].endswith("[0]") and names[1].endswith("[1]"), names


def test_a_moving_mesh_light_gives_lamberts_irradiance_averaged_over_the_shutter(native) -> None:
    # The square slides from x = −X0 at frame 1 to +X0 at frame 2; the shutter spans the frame.
    x0 = 0.6
    stage = stage_with_camera()
    prim = square_light(stage, intensity=3.0)
    op = UsdGeom.Xformable(prim).AddTranslateOp()
    op.Set(Gf.Vec3d(-x0, 0, 0), 1.0)
    op.Set(Gf.Vec3d(x0, 0, 0), 2.0)
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
    cam.CreateShutterOpenAttr(0.0)
    cam.CreateShutterCloseAttr(1.0)
    image, stats = render_with_stats(stage, time=1.0, samples=256)
    x, y = floor_xy(image, stage)
    steps = 200
    shift = -x0 + 2.0 * x0 * (np.arange(steps) + 0.5) / steps
    truth = sum(lambert_square(x - s, y) for s in shift) / steps * 3.0 * ALBEDO / math.pi
    mean, worst = relative_error(image[..., 0], truth)
    assert abs(mean) < 0.01 and worst < 0.1, (mean, worst)
    # Not the square frozen at the shutter's open: the test can tell.
    frozen = 3.0 * lambert_square(x + x0, y) * ALBEDO / math.pi
    lit = truth > 0.05 * truth.max()
    assert float(np.abs(frozen[lit] / truth[lit] - 1.0).max()) > 0.3
    (entry,) = stats["scene"]["lights"]
    assert entry["moving"] is True


def test_an_instanced_mesh_lights_links_are_resolved(native) -> None:
    stage = stage_with_camera()
    instanced_squares(stage, native=False)
    glow = stage.GetPrimAtPath("/World/Lamps/Protos/Lamp/Glow")
    link = UsdLux.LightAPI(glow).GetLightLinkCollectionAPI()
    link.CreateIncludeRootAttr(False)
    link.CreateIncludesRel().AddTarget("/World/Nothing")
    image, stats = render_with_stats(stage, width=17, samples=4)
    # The floor is in neither instance's collection: black.
    assert float(image.max()) == 0.0
    lights = stats["scene"]["lights"]
    assert len(lights) == 2 and all(e["not_illuminating"] == ["/World/Ground"] for e in lights)


def _deform_square(stage: Usd.Stage, path: str, x0: float) -> None:
    """Time-sample the square at ``path``'s points: shifted by −x0 at frame 1, +x0 at frame 2."""
    points = UsdGeom.Mesh(stage.GetPrimAtPath(path)).GetPointsAttr()
    rest = np.array(points.Get(), dtype=np.float64)
    for frame, dx in ((1.0, -x0), (2.0, x0)):
        points.Set([Gf.Vec3f(*(p + np.array([dx, 0.0, 0.0]))) for p in rest], frame)


def test_a_deforming_mesh_light_lights_the_floor_as_its_blend_over_the_shutter(
    native, caplog
) -> None:
    # The square's points slide from x = −x0 (frame 1, shutter open) to +x0 (frame 2, close):
    # the floor's irradiance is Lambert's over the slide, averaged over the shutter. It was
    # built from the frame's points (lit at −x0), with a warning.
    x0 = 0.6
    stage = stage_with_camera()
    square_light(stage, intensity=3.0)
    _deform_square(stage, "/World/Glow", x0)
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
    cam.CreateShutterOpenAttr(0.0)
    cam.CreateShutterCloseAttr(1.0)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        image, stats = render_with_stats(stage, time=1.0, samples=256)
    assert not [r for r in caplog.records if "/World/Glow" in r.getMessage()]
    assert not [u for u in stats["unsupported"] if u["prim"] == "/World/Glow"]
    (entry,) = [e for e in stats["scene"]["lights"] if e["name"] == "/World/Glow"]
    assert entry["moving"] is True
    x, y = floor_xy(image, stage)
    shifts = (np.arange(64) + 0.5) / 64 * 2 * x0 - x0  # the square's x over the shutter
    truth = np.mean([lambert_square(x - dx, y) for dx in shifts], axis=0) * 3.0 * ALBEDO / math.pi
    mean, worst = relative_error(image[..., 0], truth)
    assert abs(mean) < 0.02 and worst < 0.15, (mean, worst)
    still = 3.0 * lambert_square(x + x0, y) * ALBEDO / math.pi  # the frame's square alone
    assert relative_error(image[..., 0], still)[1] > 0.5  # the measurement sees the blur


def test_a_deforming_instanced_mesh_light_is_sent_its_points_over_the_shutter(fake) -> None:
    from mipray.usd import UsdSceneDelegate

    for native_instances in (False, True):
        stage = stage_with_camera()
        instanced_squares(stage, native_instances)
        glow = "/Lamp/Glow" if native_instances else "/World/Lamps/Protos/Lamp/Glow"
        _deform_square(stage, glow, 0.6)
        cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
        cam.CreateShutterOpenAttr(0.0)
        cam.CreateShutterCloseAttr(1.0)
        before = len(fake.calls)
        scene = UsdSceneDelegate(stage, fake, time=1.0)
        scene.sync()
        scene.update_motion("/World/Cam")
        (call,) = [c for c in fake.calls[before:] if c.method == "set_deformation"]
        points = call.kwargs["points"]
        np.testing.assert_allclose(points[-1][:, 0] - points[0][:, 0], 1.2, atol=1e-6)
        assert scene.unsupported == []
