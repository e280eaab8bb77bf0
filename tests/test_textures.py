"""Textures end to end: UsdUVTexture on diffuseColor (filtered by the ray differentials) and on
displacement (at tessellation time), unreadable files, and the paper's §6.3.3 experiment."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdShade

import mipray

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "textured.usda"
TEXTURES = EXAMPLE.parent / "textures"


@pytest.fixture
def stage(native) -> Usd.Stage:
    if not (TEXTURES / "bricks_color.tx").exists():
        pytest.skip("textures not made (make examples)")
    return Usd.Stage.Open(str(EXAMPLE))


def _wall_box(result: mipray.RenderResult) -> tuple[slice, slice]:
    h, w = result.height, result.width
    return slice(h // 6, h // 2), slice(w // 3, w // 2)


def test_diffuse_texture_shows_and_is_read_through_the_texture_cache(stage) -> None:
    result = mipray.render(stage, width=96, aovs=("color",))
    ys, xs = _wall_box(result)
    wall = result.aovs["color"][ys, xs]
    # Bricks and mortar: the red channel varies a lot across the wall.
    assert wall[..., 0].std() > 0.02, wall[..., 0].std()
    tc = result.stats["texture_cache"]
    assert tc["bytes_read"] > 0 and tc["failed_lookups"] == 0


def test_displacement_texture_moves_the_surface(stage) -> None:
    displaced = mipray.render(stage, width=96, aovs=("depth",))
    height = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/BrickWall/HeightTexture"))
    height.GetInput("scale").Set((0.0, 0.0, 0.0, 0.0))
    height.GetInput("bias").Set((0.0, 0.0, 0.0, 0.0))
    flat = mipray.render(stage, width=96, aovs=("depth",))
    ys, xs = _wall_box(displaced)
    diff = np.abs(displaced.aovs["depth"][ys, xs] - flat.aovs["depth"][ys, xs])
    assert diff.max() > 0.01, diff.max()


def test_an_unreadable_texture_names_prim_and_file_and_renders_the_fallback(stage, caplog) -> None:
    color = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/BrickWall/ColorTexture"))
    color.GetInput("file").Set(Sdf.AssetPath("textures/no_such_file.tx"))
    with caplog.at_level(logging.WARNING):
        result = mipray.render(stage, width=64, aovs=("color",))
    ys, xs = _wall_box(result)
    wall = result.aovs["color"][ys, xs]
    # The fallback (0.5, 0.2, 0.15) is one colour: the wall is flat-shaded apart from the
    # grooves of its displacement.
    assert np.isfinite(wall).all() and wall[..., 0].mean() > 0.05
    assert wall[..., 0].std() < 0.05
    warnings = [r.getMessage() for r in caplog.records if r.name == "mipray"]
    assert any("/World/Geo/Wall" in w and "no_such_file.tx" in w for w in warnings), warnings
    # A live session says it once, not once per render.
    caplog.clear()
    with mipray.RenderSession(stage) as session:
        session.render(width=32, aovs=("color",))
        session.render(width=32, aovs=("color",))
    assert sum("no_such_file" in r.getMessage() for r in caplog.records) == 1


def test_forcing_the_finest_mip_level_reads_many_times_more_texture_tiles(stage) -> None:
    # The paper's §6.3.3: with differentials ignored, every lookup reads the finest level.
    # Colour lookups only: displacement reads fine levels for fine tiers either way. Tiles
    # are OpenImageIO's ImageCache tiles brought in (`stat:tiles_created`), bytes the pixel
    # bytes read from the file (`stat:bytes_read`).
    surface = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/BrickWall/PreviewSurface"))
    surface.GetInput("displacement").ClearSources()
    normal = mipray.render(stage, width=48, aovs=("color",))
    finest = mipray.render(stage, width=48, aovs=("color",), settings={"textureFilter": "finest"})
    proper_tc, finest_tc = normal.stats["texture_cache"], finest.stats["texture_cache"]
    assert (proper_tc["filter_mode"], finest_tc["filter_mode"]) == ("differentials", "finest")
    assert proper_tc["tiles_read"] > 0 and proper_tc["bytes_read"] > 0, proper_tc
    tiles = finest_tc["tiles_read"] / proper_tc["tiles_read"]
    data = finest_tc["bytes_read"] / proper_tc["bytes_read"]
    print(f"§6.3.3: finest/differentials = {tiles:.0f}x the tiles, {data:.0f}x the bytes")
    assert tiles >= 10, (finest_tc["tiles_read"], proper_tc["tiles_read"])
    assert data >= 10, (finest_tc["bytes_read"], proper_tc["bytes_read"])


def test_a_transform2d_scales_and_moves_st() -> None:
    from mipray.usd.shading import apply_transform2d

    st = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], dtype=np.float32)
    out = apply_transform2d(st, ((2.0, 3.0), 90.0, (0.5, 0.25)))
    # Scale, rotate 90° counter-clockwise, translate: (1,0)→(2,0)→(0,2)→(0.5,2.25).
    np.testing.assert_allclose(out, [[0.5, 0.25], [0.5, 2.25], [-2.5, 0.25]], atol=1e-6)


def test_the_scene_delegate_applies_a_transform2d_between_reader_and_texture(stage) -> None:
    from pxr import Sdf

    from mipray.usd.shading import shading_arguments

    root = "/World/Looks/BrickWall"
    xf = UsdShade.Shader.Define(stage, f"{root}/Tiling")
    xf.CreateIdAttr("UsdTransform2d")
    reader = UsdShade.Shader(stage.GetPrimAtPath(f"{root}/StReader"))
    xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.GetOutput("result"))
    xf.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set((4.0, 4.0))
    out = xf.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    for name in ("ColorTexture", "HeightTexture"):
        UsdShade.Shader(stage.GetPrimAtPath(f"{root}/{name}")).GetInput("st").ConnectToSource(out)
    wall = stage.GetPrimAtPath("/World/Geo/Wall")
    args = shading_arguments(wall, Usd.TimeCode.Default())
    authored = np.asarray(wall.GetAttribute("primvars:st").Get(), dtype=np.float32)
    np.testing.assert_allclose(args["st_values"], authored * 4.0, atol=1e-6)
