"""Nothing dropped silently: every authored thing mipray ignores is listed once (issue 20).

One stage authors one of each thing in ``mipray.usd.unsupported.TABLE``; the
list the scene delegate makes, the stats ``mipray-record --stats`` writes and
the warnings are checked against it exactly. Supporting a thing means removing
its row there and its line here.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade
from test_usd_skel import arm

from mipray.record import main
from mipray.usd.scene_delegate import UsdSceneDelegate
from mipray.usd.unsupported import HEADLIGHT, TABLE, Unsupported, audit_render_settings

from stages import (
    add_camera,
    add_cube,
    add_distant_light,
    add_preview_material,
    bind,
    new_stage,
)


def _shader(stage: Usd.Stage, path: str, shader_id: str) -> UsdShade.Shader:
    shader = UsdShade.Shader.Define(stage, path)
    shader.CreateIdAttr(shader_id)
    return shader


def one_of_each(stage: Usd.Stage) -> list[Unsupported]:
    """Author one of each unsupported thing on ``stage``; return what must be listed."""
    add_cube(stage, "/World/Cube")
    add_camera(stage, "/World/Cam")
    UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam")).CreateClippingPlanesAttr(
        [(0.0, 1.0, 0.0, 0.0)]
    )
    UsdGeom.TetMesh.Define(stage, "/World/Ball")
    UsdGeom.TetMesh.Define(stage, "/World/Hidden").CreateVisibilityAttr("invisible")
    UsdLux.PluginLight.Define(stage, "/World/Tube")

    key = add_distant_light(stage, "/World/Key").GetPrim()
    shaping = UsdLux.ShapingAPI.Apply(key)
    shaping.CreateShapingConeAngleAttr(30.0)
    shadow = UsdLux.ShadowAPI.Apply(key)
    shadow.CreateShadowEnableAttr(True)  # read: not listed
    shadow.CreateShadowColorAttr((1.0, 0.0, 0.0))
    light = UsdLux.LightAPI(key)
    light.CreateDiffuseAttr(0.5)
    light.GetLightLinkCollectionAPI().CreateIncludesRel().AddTarget("/World/Cube")
    light.GetShadowLinkCollectionAPI().CreateIncludeRootAttr(False)

    emitter = add_cube(stage, "/World/Emitter").GetPrim()
    UsdLux.MeshLightAPI.Apply(emitter)  # rendered: a light
    emitter.CreateAttribute("light:materialSyncMode", Sdf.ValueTypeNames.Token).Set(
        "independent"
    )  # read: not listed
    ball = UsdGeom.Sphere.Define(stage, "/World/GlowBall").GetPrim()
    UsdLux.MeshLightAPI.Apply(ball)  # only a Mesh becomes a light: listed

    # An instanceable Mesh: USD instances its descendants, not its own geometry.
    add_cube(stage, "/Protos/Box")
    stage.GetPrimAtPath("/Protos").SetSpecifier(Sdf.SpecifierClass)
    inst_mesh = UsdGeom.Mesh.Define(stage, "/World/InstMesh").GetPrim()
    inst_mesh.GetReferences().AddInternalReference("/Protos/Box")
    inst_mesh.SetInstanceable(True)
    # A native instance with its own material binding (rendered: not listed).
    group = UsdGeom.Xform.Define(stage, "/Protos/Group").GetPrim()
    add_cube(stage, "/Protos/Group/Part")
    inst = UsdGeom.Xform.Define(stage, "/World/Inst").GetPrim()
    inst.GetReferences().AddInternalReference(group.GetPath())
    inst.SetInstanceable(True)
    red = add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0))
    bind(inst, red)

    # Materials: MaterialX with a node mipray does not evaluate, a non-PreviewSurface surface
    # (with a render-context output), ignored inputs, constant
    # displacement, and a GeomSubset bound to a textured material (rendered: not listed).
    mtlx = UsdShade.Material.Define(stage, "/Looks/Mtlx")
    std = _shader(stage, "/Looks/Mtlx/Std", "ND_standard_surface_surfaceshader")
    mtlx.CreateSurfaceOutput("mtlx").ConnectToSource(std.ConnectableAPI(), "out")
    noise = _shader(stage, "/Looks/Mtlx/Noise", "ND_noise3d_color3")
    noise.CreateOutput("out", Sdf.ValueTypeNames.Color3f)
    std.CreateInput("base_color", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        noise.ConnectableAPI(), "out"
    )
    bind(add_cube(stage, "/World/MtlxCube").GetPrim(), mtlx)
    other = UsdShade.Material.Define(stage, "/Looks/Other")
    osl = _shader(stage, "/Looks/Other/Osl", "PxrSurface")
    other.CreateSurfaceOutput().ConnectToSource(osl.ConnectableAPI(), "out")
    other.CreateSurfaceOutput("ri").ConnectToSource(osl.ConnectableAPI(), "out")
    bind(add_cube(stage, "/World/OtherCube").GetPrim(), other)
    plain = add_preview_material(stage, "/Looks/Plain", (0.5, 0.5, 0.5))
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/Plain/PreviewSurface"))
    surface.CreateInput("occlusion", Sdf.ValueTypeNames.Float).Set(0.5)
    surface.CreateInput("displacement", Sdf.ValueTypeNames.Float).Set(0.1)
    plain.CreateDisplacementOutput().ConnectToSource(surface.ConnectableAPI(), "displacement")
    bind(add_cube(stage, "/World/PlainCube").GetPrim(), plain)
    subset_cube = add_cube(stage, "/World/SubsetCube")
    subset = UsdGeom.Subset.CreateGeomSubset(
        subset_cube, "Top", UsdGeom.Tokens.face, [0], "materialBind"
    )
    tex = add_preview_material(stage, "/Looks/Tex", (1.0, 1.0, 1.0))
    reader = _shader(stage, "/Looks/Tex/Image", "UsdUVTexture")
    reader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("grid.png")
    reader.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    UsdShade.Shader(stage.GetPrimAtPath("/Looks/Tex/PreviewSurface")).GetInput(
        "diffuseColor"
    ).ConnectToSource(reader.ConnectableAPI(), "rgb")
    bind(subset.GetPrim(), tex)

    arm(stage)  # a skinned mesh with an animated skeleton: blurred, so not listed

    lost = add_cube(stage, "/World/Lost").GetPrim()
    UsdShade.MaterialBindingAPI.Apply(lost).GetDirectBindingRel().SetTargets(["/Looks/Nope"])

    cube, cam, key_path = "/World/Cube", "/World/Cam", "/World/Key"
    del cube
    return sorted(
        [
            Unsupported(cam, "camera clippingPlanes 1 plane(s)"),
            Unsupported("/World/Ball", "prim type TetMesh"),
            Unsupported("/World/Tube", "prim type PluginLight"),
            Unsupported(key_path, "ShapingAPI inputs:shaping:cone:angle"),
            Unsupported(key_path, "ShadowAPI inputs:shadow:color"),
            Unsupported(key_path, "light input inputs:diffuse"),
            Unsupported("/World/GlowBall", "MeshLightAPI"),
            Unsupported(
                "/World/InstMesh",
                "instanceable gprim (its own geometry is not instanced) Mesh",
            ),
            Unsupported("/World/Lost", "material binding to no Material </Looks/Nope>"),
            Unsupported("/Looks/Mtlx", "MaterialX node ND_noise3d_color3 at /Looks/Mtlx/Noise"),
            Unsupported(
                "/Looks/Other",
                "material output (only the universal outputs:surface is read) outputs:ri:surface",
            ),
            Unsupported("/Looks/Other", "surface shader PxrSurface at /Looks/Other/Osl"),
            Unsupported("/Looks/Plain", "UsdPreviewSurface input inputs:occlusion"),
            Unsupported(
                "/Looks/Plain",
                "UsdPreviewSurface constant displacement displacement = 0.1",
            ),
        ]
    )


def test_one_of_each_is_listed_exactly(fake, caplog) -> None:
    stage = new_stage()
    expected = one_of_each(stage)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
        scene.mark_all_dirty()
        scene.sync()  # nothing is warned twice
    assert scene.unsupported == expected
    # Every row of the table is exercised but the render settings' (tested below).
    rows = {r.what for r in TABLE if r.scope not in ("render var", "render settings")}
    assert {r for r in rows if not any(u.what.startswith(r) for u in expected)} == set()
    warnings = [r.getMessage() for r in caplog.records if "not rendered" in r.getMessage()]
    # One warning per thing, except what its reader warns about itself (types, shaders).
    readers = ("prim type", "surface shader")
    listed = {u.what for u in expected if not u.what.startswith(readers)}
    assert len(warnings) == len(listed)
    for what in listed:
        assert sum(f"not rendered: {what} on " in w for w in warnings) == 1, what


def test_invisible_and_excluded_prims_are_not_listed(fake) -> None:
    stage = new_stage()
    UsdGeom.TetMesh.Define(stage, "/Hidden").CreateVisibilityAttr("invisible")
    UsdGeom.TetMesh.Define(stage, "/Guide").CreatePurposeAttr("guide")
    add_cube(stage, "/Cube")
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert scene.unsupported == []


def test_prims_under_an_untyped_root_are_audited(fake) -> None:
    # A production stage's /World is often a bare `def` (no type, so no purpose of its own):
    # what lies under it is rendered, and what is not supported there must be listed too.
    stage = new_stage()
    stage.DefinePrim("/World")
    UsdGeom.TetMesh.Define(stage, "/World/Patch")
    UsdGeom.TetMesh.Define(stage, "/World/Guide").CreatePurposeAttr("guide")
    add_cube(stage, "/World/Cube")
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert [u.prim for u in scene.unsupported] == ["/World/Patch"]


def test_headlight_standing_in_for_unsupported_lights_is_listed(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Cube")
    UsdLux.PluginLight.Define(stage, "/Tube")
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    camera = scene.resolve_camera()
    assert scene.update_camera_light(camera)
    assert scene.unsupported == [
        Unsupported("/Tube", HEADLIGHT),
        Unsupported("/Tube", "prim type PluginLight"),
    ]
    add_distant_light(stage, "/Key")
    scene.sync()
    assert not scene.update_camera_light(camera)
    assert scene.unsupported == [Unsupported("/Tube", "prim type PluginLight")]


def _settings(stage: Usd.Stage, lpe: str) -> None:
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreatePixelAspectRatioAttr(2.0)
    product = UsdRender.Product.Define(stage, "/Render/Product")
    settings.CreateProductsRel().AddTarget(product.GetPath())
    for name, source, kind in (
        ("Beauty", "C.*", "lpe"),
        ("Diffuse", lpe, "lpe"),
        ("Z", "z", "raw"),
    ):
        var = UsdRender.Var.Define(stage, f"/Render/Vars/{name}")
        var.CreateSourceNameAttr(source)
        var.CreateSourceTypeAttr(kind)
        product.CreateOrderedVarsRel().AddTarget(var.GetPath())


def test_render_settings_lpe_and_window_are_listed() -> None:
    stage = new_stage()
    _settings(stage, "C<RD>.*L")
    found = audit_render_settings(stage, "/Render/Settings", Usd.TimeCode.Default())
    assert found == [
        Unsupported("/Render/Settings", "render settings window pixelAspectRatio 2.0"),
        Unsupported(
            "/Render/Vars/Diffuse",
            "render var light-path expression 'C<RD>.*L', rendered as the beauty",
        ),
    ]


def test_record_stats_list_them(capsys, tmp_path: Path, fake_native) -> None:
    stage = new_stage()
    expected = one_of_each(stage)
    _settings(stage, "C<RD>.*L")
    path = tmp_path / "s.usda"
    stage.GetRootLayer().Export(str(path))
    stats = tmp_path / "stats.json"
    code = main(
        [
            str(path),
            str(tmp_path / "o.exr"),
            "-w",
            "8",
            "-rs",
            "/Render/Settings",
            "--stats",
            str(stats),
        ]
    )
    _, err = capsys.readouterr()
    assert code == 0, err
    listed = json.loads(stats.read_text())["unsupported"]
    settings_items = [
        Unsupported("/Render/Settings", "render settings window pixelAspectRatio 2.0"),
        Unsupported(
            "/Render/Vars/Diffuse",
            "render var light-path expression 'C<RD>.*L', rendered as the beauty",
        ),
    ]
    assert listed == [u.as_dict() for u in sorted(expected + settings_items)]
    assert "mipray-record: warning: not rendered: render var light-path expression" in err


def test_composition_errors_are_listed_with_usds_reason(fake, tmp_path: Path) -> None:
    stage = new_stage()
    add_cube(stage, "/World/Cube")
    stage.DefinePrim("/World/Ref").GetReferences().AddReference(str(tmp_path / "missing.usda"))
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    [item] = scene.unsupported
    assert item.prim == "/World/Ref"
    assert item.what.startswith(
        f"composition error: Could not open asset @{tmp_path / 'missing.usda'}@"
    )
    assert "\n" not in item.what
