"""UsdRender.Settings / Product / Var: resolution, camera, purposes and AOVs."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdRender

from mipray import RenderSettingsError, record
from mipray.usd.render_settings import aov_for_source, read_render_settings

from stages import add_camera, add_cube, add_distant_light, new_stage


def add_settings(
    stage: Usd.Stage,
    path: str = "/Render/Settings",
    *,
    resolution: tuple[int, int] = (64, 32),
    camera: str | None = "/World/Side",
    products: dict[str, list[str]] | None = None,
    purposes: list[str] | None = None,
) -> UsdRender.Settings:
    """RenderSettings with products (name → RenderVar source names) under ``/Render``."""
    settings = UsdRender.Settings.Define(stage, path)
    settings.CreateResolutionAttr(Gf.Vec2i(*resolution))
    if camera:
        settings.CreateCameraRel().SetTargets([camera])
    if purposes is not None:
        settings.CreateIncludedPurposesAttr(purposes)
    for name, sources in (products or {"Beauty": ["color", "z"]}).items():
        product = UsdRender.Product.Define(stage, f"/Render/{name}")
        product.CreateProductNameAttr(f"{name}.exr")
        vars_ = []
        for source in sources:
            var = UsdRender.Var.Define(stage, f"/Render/Vars/{source.replace('.', '_')}")
            var.CreateSourceNameAttr(source)
            vars_.append(var.GetPath())
        product.CreateOrderedVarsRel().SetTargets(vars_)
        settings.GetProductsRel().AddTarget(product.GetPath())
    return settings


def two_camera_stage() -> Usd.Stage:
    stage = new_stage()
    add_cube(stage, "/World/Cube")
    add_camera(stage, "/World/main_cam", eye=(0, 0, 8))
    add_camera(stage, "/World/Side", eye=(0, 0, 12))
    add_distant_light(stage, "/World/Sun")
    return stage


def test_settings_read_resolution_camera_purposes_and_aovs() -> None:
    stage = two_camera_stage()
    add_settings(
        stage,
        products={"Beauty": ["Ci", "a"], "Data": ["depth", "N", "Ci"]},
        purposes=["default", "proxy"],
    )
    spec = read_render_settings(stage, "/Render/Settings")
    assert spec is not None
    assert spec.resolution == (64, 32)
    assert spec.camera == "/World/Side"
    assert spec.aovs == ["color", "alpha", "depth", "normal"]  # product order, each once
    assert spec.purposes == ("default", "proxy")
    assert spec.products == ["/Render/Beauty", "/Render/Data"]


def test_the_stages_default_settings_and_product_overrides() -> None:
    stage = two_camera_stage()
    assert read_render_settings(stage) is None  # no metadata: no settings
    add_settings(stage, "/Render/Main")
    product = UsdRender.Product(stage.GetPrimAtPath("/Render/Beauty"))
    product.CreateResolutionAttr(Gf.Vec2i(20, 10))
    product.CreateCameraRel().SetTargets(["/World/main_cam"])
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Main")
    spec = read_render_settings(stage)
    assert spec is not None and spec.path == "/Render/Main"
    assert (spec.resolution, spec.camera) == ((20, 10), "/World/main_cam")


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda s: None, None),
        (
            lambda s: s.GetPrimAtPath("/Render/Settings").SetTypeName("Scope"),
            "/Render/Settings: a Scope prim, not a RenderSettings prim",
        ),
        (
            lambda s: (
                UsdRender.Var(s.GetPrimAtPath("/Render/Vars/z"))
                .GetSourceNameAttr()
                .Set("subsurface")
            ),
            "/Render/Vars/z: sourceName 'subsurface' is not an AOV mipray renders",
        ),
        (
            lambda s: (
                UsdRender.Settings(s.GetPrimAtPath("/Render/Settings"))
                .GetCameraRel()
                .SetTargets(["/World/Cube"])
            ),
            "/Render/Settings: camera target </World/Cube> is not a Camera prim",
        ),
        (
            lambda s: (
                UsdRender.Settings(s.GetPrimAtPath("/Render/Settings"))
                .GetResolutionAttr()
                .Set(Gf.Vec2i(0, 10))
            ),
            "/Render/Settings: resolution 0x10 must be positive",
        ),
        (
            lambda s: (
                UsdRender.Settings(s.GetPrimAtPath("/Render/Settings"))
                .GetProductsRel()
                .AddTarget("/World/Cube")
            ),
            "/Render/Settings: products target </World/Cube> is not a RenderProduct",
        ),
    ],
)
def test_bad_settings_are_one_line_errors_naming_the_prim(edit, message) -> None:
    stage = two_camera_stage()
    add_settings(stage)
    edit(stage)
    if message is None:
        assert read_render_settings(stage, "/Render/Settings") is not None
        return
    with pytest.raises(RenderSettingsError) as info:
        read_render_settings(stage, "/Render/Settings")
    assert str(info.value).startswith(message), str(info.value)
    assert "\n" not in str(info.value)


def test_missing_settings_prim() -> None:
    with pytest.raises(RenderSettingsError, match="/Nope: no prim, not a RenderSettings prim"):
        read_render_settings(two_camera_stage(), "/Nope")


def test_aov_aliases() -> None:
    assert aov_for_source("Ci") == "color"
    assert aov_for_source("C.*", "lpe") == "color"
    assert aov_for_source("Z") == "depth"
    assert aov_for_source("instanceId") == "instanceId"
    assert aov_for_source("subsurface") is None


# ------------------------------------------------------------------ mipray-record


def write(stage: Usd.Stage, tmp_path: Path) -> Path:
    path = tmp_path / "scene.usda"
    stage.GetRootLayer().Export(str(path))
    return path


def test_record_uses_the_stages_render_settings(capsys, tmp_path: Path, fake_native) -> None:
    stage = two_camera_stage()
    add_settings(stage, products={"Beauty": ["color", "depth", "normal"]})
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    out = tmp_path / "out.exr"
    code = record.main([str(write(stage, tmp_path)), str(out)])
    _, err = capsys.readouterr()
    assert (code, err) == (0, "")
    written = fake_native.written[str(out)]
    assert written["order"] == ["color", "depth", "normal"]
    assert written["aovs"]["color"].shape == (32, 64, 3)
    assert written["metadata"]["mipray:camera"] == "/World/Side"
    assert written["metadata"]["mipray:renderSettings"] == "/Render/Settings"


def test_explicit_flags_win_over_render_settings(capsys, tmp_path: Path, fake_native) -> None:
    stage = two_camera_stage()
    add_settings(stage, products={"Beauty": ["color", "depth"]})
    out = tmp_path / "out.exr"
    argv = [write(stage, tmp_path), out, "--renderSettingsPrimPath", "/Render/Settings"]
    code = record.main(
        [str(a) for a in [*argv, "-w", "32", "--aovs", "normal", "--camera", "main_cam"]]
    )
    assert code == 0, capsys.readouterr().err
    written = fake_native.written[str(out)]
    assert written["order"] == ["normal"]
    assert written["aovs"]["normal"].shape == (16, 32, 3)  # the settings' 2:1 aspect kept
    assert written["metadata"]["mipray:camera"] == "/World/main_cam"


def test_bad_render_settings_flag_fails_in_one_line(capsys, tmp_path: Path, fake_native) -> None:
    stage = two_camera_stage()
    path = write(stage, tmp_path)
    code = record.main([str(path), str(tmp_path / "o.exr"), "-rs", "/World/Cube"])
    out, err = capsys.readouterr()
    assert code == 1 and out == ""
    assert err == "mipray-record: /World/Cube: a Mesh prim, not a RenderSettings prim\n"


def test_broken_stage_default_settings_only_warn(capsys, tmp_path: Path, fake_native) -> None:
    stage = two_camera_stage()
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Gone")
    out = tmp_path / "o.exr"
    code = record.main([str(write(stage, tmp_path)), str(out), "-w", "16"])
    _, err = capsys.readouterr()
    assert code == 0
    assert "warning: ignoring the stage's render settings: /Render/Gone" in err
    assert fake_native.written[str(out)]["order"] == ["color"]


def test_included_purposes_decide_what_renders(native, tmp_path: Path, caplog) -> None:
    stage = new_stage()
    add_cube(stage, "/World/Proxy").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    add_camera(stage, "/World/Side", eye=(0, 0, 8))
    add_distant_light(stage, "/World/Sun")
    settings = add_settings(stage, products={"Beauty": ["color", "alpha"]})
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    path = write(stage, tmp_path)
    default_out, proxy_out = tmp_path / "default.exr", tmp_path / "proxy.exr"
    assert record.main([str(path), str(default_out)]) == 0
    settings.CreateIncludedPurposesAttr(["default", "proxy"])
    path = write(stage, tmp_path)
    assert record.main([str(path), str(proxy_out)]) == 0
    default_px, names = native.read_image(str(default_out))
    proxy_px, _ = native.read_image(str(proxy_out))
    assert names == ["R", "G", "B", "A"] and default_px.shape == (32, 64, 4)
    assert default_px[..., 3].max() == 0.0  # proxy purpose: not rendered by default
    assert proxy_px[16, 32, 3] == 1.0  # included by the settings
    assert np.isfinite(proxy_px).all()


def test_metadata_naming_a_missing_prim_says_where_the_path_came_from() -> None:
    layer = Sdf.Layer.CreateAnonymous()
    layer.pseudoRoot.SetInfo("renderSettingsPrimPath", "/Render/Settings")
    stage = Usd.Stage.Open(layer)
    with pytest.raises(RenderSettingsError, match="the stage's renderSettingsPrimPath"):
        read_render_settings(stage)


def test_warns_about_unsupported_pixel_aspect(caplog) -> None:
    stage = two_camera_stage()
    settings = add_settings(stage)
    settings.CreatePixelAspectRatioAttr(2.0)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        read_render_settings(stage, "/Render/Settings")
    assert any("pixelAspectRatio 2.0 is not supported" in r.getMessage() for r in caplog.records)


def test_a_dropped_scene_delegate_frees_its_stage_at_once(fake) -> None:
    """No reference cycle keeps a synced delegate (and so its stage and layers) alive until
    the collector runs: usd-core would hand the next ``Usd.Stage.Open`` of the file the stale
    layer, and a re-render of an edited file would render the old stage."""
    import gc
    import weakref

    from mipray.usd import UsdSceneDelegate

    stage = new_stage()
    add_cube(stage, "/World/Cube")
    add_distant_light(stage, "/World/Sun")
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    dropped = weakref.ref(scene)
    gc.disable()
    try:
        del scene
        assert dropped() is None, "something still refers to the delegate"
    finally:
        gc.enable()
