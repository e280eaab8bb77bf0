"""Texture files as real assets hold them: inside ``.usdz`` packages, ``<UDIM>`` tile sets, and
files of 1-4 channels at 8 bits, 16 bits and float (UsdUVTexture's rules for missing channels).

Each is checked against a render whose answer is known: the same texture unpacked, or a
constant ``diffuseColor`` of the value the file holds."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdUtils, Vt

import mipray
from mipray.usd import UsdSceneDelegate
from mipray.usd.assets import local_file, udim_tiles

from stages import (
    add_camera,
    add_cube,
    add_distant_light,
    add_preview_material,
    add_textured_material,
    bind,
)


def oiiotool(*args: str) -> None:
    tool = shutil.which("oiiotool")
    if tool is None:
        pytest.skip("oiiotool (openimageio-tools) is not installed")
    subprocess.run([tool, *args], check=True, capture_output=True)


def constant_image(path: Path, values: tuple[float, ...], fmt: str = "uint8") -> Path:
    """An image of one colour; with alpha, the colour is stored as given (unassociated), as
    an artist's PNG holds it (OpenImageIO would otherwise divide it by alpha on writing)."""
    values_text = ",".join(f"{v:g}" for v in values)
    oiiotool(
        "--pattern", f"constant:color={values_text}", "8x8", str(len(values)), "-d", fmt,
        "--attrib", "oiio:UnassociatedAlpha", "1", "-o", str(path),
    )  # fmt: skip
    return path


def quads(stage: Usd.Stage, n: int = 1, path: str = "/World/Quads") -> UsdGeom.Mesh:
    """``n`` unit quads side by side in z = 0 facing +Z, centred; st = (x + n/2, y + 1/2)."""
    points = [(x - n / 2, y - 0.5, 0.0) for y in (0, 1) for x in range(n + 1)]
    indices = [i for f in range(n) for i in (f, f + 1, f + n + 2, f + n + 1)]
    mesh = add_cube(stage, path, points=points, counts=[4] * n, indices=indices, scheme="none")
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    st.Set(Vt.Vec2fArray([Gf.Vec2f(x, y) for y in (0, 1) for x in range(n + 1)]))
    return mesh


def textured(
    stage: Usd.Stage, path: str, file: str, *, output: str = "rgb", space: str = "raw"
) -> UsdShade.Material:
    """A textured material (see ``stages.add_textured_material``): the edge texel continues,
    so no border is blended in; colour read as ``space`` (raw unless told)."""
    return add_textured_material(stage, path, file, output=output, space=space, wrap="clamp")


def lit(stage: Usd.Stage, n: int = 1) -> None:
    camera = add_camera(stage, "/World/Cam", eye=(0, 0, 4))
    camera.CreateHorizontalApertureAttr(10.0 * n)
    camera.CreateVerticalApertureAttr(10.0)
    camera.CreateFocalLengthAttr(18.0)
    add_distant_light(stage, "/World/Sun")


def new_stage(path: Path | None = None) -> Usd.Stage:
    stage = Usd.Stage.CreateNew(str(path)) if path else Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    return stage


def render(stage: Usd.Stage, aov: str = "color", width: int = 32) -> np.ndarray:
    return mipray.render(stage, width=width, aovs=(aov,)).aovs[aov]


def constant_render(rgb: tuple[float, float, float]) -> np.ndarray:
    stage = new_stage()
    bind(quads(stage).GetPrim(), add_preview_material(stage, "/Looks/M", rgb))
    lit(stage)
    return render(stage)


# ---------------------------------------------------------------------- usdz packages


def _packaged_scene(folder: Path) -> Path:
    (folder / "tex").mkdir()
    oiiotool(
        "--pattern", "checker:width=2:height=2:color1=0.8,0.2,0.1:color2=0.1,0.3,0.9",
        "16x16", "3", "-d", "uint8", "-o", str(folder / "tex" / "checker.png"),
    )  # fmt: skip
    stage = new_stage(folder / "scene.usda")
    bind(quads(stage).GetPrim(), textured(stage, "/Looks/Tex", "./tex/checker.png", space="auto"))
    lit(stage)
    stage.Save()
    return folder / "scene.usda"


def test_a_texture_inside_a_usdz_renders_as_the_same_texture_unpacked(native, tmp_path) -> None:
    scene = _packaged_scene(tmp_path)
    package = tmp_path / "scene.usdz"
    assert UsdUtils.CreateNewUsdzPackage(str(scene), str(package))
    unpacked = render(Usd.Stage.Open(str(scene)))
    packed = render(Usd.Stage.Open(str(package)))
    assert unpacked[..., 2].max() > 0.1 and unpacked[..., 0].max() > 0.1  # both checker colours
    np.testing.assert_array_equal(packed, unpacked)


def test_a_packaged_texture_is_extracted_once_privately(native, tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("MIPRAY_TEXTURE_CACHE", str(tmp_path / "cache"))
    scene = _packaged_scene(tmp_path)
    package = tmp_path / "scene.usdz"
    assert UsdUtils.CreateNewUsdzPackage(str(scene), str(package))
    resolved = f"{package}[tex/checker.png]"
    first = Path(local_file(resolved))
    assert first.parent == tmp_path / "cache" / "packaged"
    assert first.read_bytes() == (tmp_path / "tex" / "checker.png").read_bytes()
    assert (first.parent.stat().st_mode & 0o077) == 0
    assert local_file(resolved) == str(first)
    # A file outside any package is used where it is.
    assert local_file(str(tmp_path / "tex" / "checker.png")) == str(tmp_path / "tex/checker.png")


def test_a_missing_file_in_a_package_warns_and_renders_the_fallback(native, tmp_path, caplog):
    scene = _packaged_scene(tmp_path)
    stage = Usd.Stage.Open(str(scene))
    image = UsdShade.Shader(stage.GetPrimAtPath("/Looks/Tex/Image"))
    image.GetInput("file").Set("./tex/missing.png")
    image.CreateInput("fallback", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(0.2, 0.4, 0.6, 1.0))
    stage.Save()
    package = tmp_path / "scene.usdz"
    writer = Sdf.ZipFileWriter.CreateNew(str(package))  # a package without the file
    writer.AddFile(str(scene), "scene.usda")
    writer.Save()
    got = render(Usd.Stage.Open(str(package)))
    np.testing.assert_allclose(got, constant_render((0.2, 0.4, 0.6)), atol=1e-5)
    assert any("missing.png" in r.getMessage() for r in caplog.records)


# ------------------------------------------------------------------------------ UDIM

UDIM_COLOURS = {1001: (0.8, 0.2, 0.2), 1002: (0.2, 0.8, 0.2), 1003: (0.2, 0.2, 0.8)}


def test_udim_tiles_are_listed_from_the_pattern(tmp_path) -> None:
    for tile in (1001, 1002, 1011):
        (tmp_path / f"t.{tile}.png").write_bytes(b"")
    (tmp_path / "t.0999.png").write_bytes(b"")
    (tmp_path / "other.1001.png").write_bytes(b"")
    got = udim_tiles(str(tmp_path / "t.<UDIM>.png"))
    assert got == [(t, str(tmp_path / f"t.{t}.png")) for t in (1001, 1002, 1011)]


def test_a_udim_set_renders_each_tile_on_its_faces(native, tmp_path) -> None:
    """Three quads over st ∈ [0, 3) × [0, 1): tiles 1001, 1002, 1003, one colour each; the
    truth is the same quads with each face's constant colour (GeomSubsets)."""
    for tile, rgb in UDIM_COLOURS.items():
        constant_image(tmp_path / f"paint.{tile}.png", rgb)

    def scene(udim: bool) -> np.ndarray:
        stage = new_stage()
        mesh = quads(stage, 3)
        if udim:
            bind(mesh.GetPrim(), textured(stage, "/Looks/U", str(tmp_path / "paint.<UDIM>.png")))
        else:
            api = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
            for face, rgb in enumerate(UDIM_COLOURS.values()):
                sub = api.CreateMaterialBindSubset(f"F{face}", Vt.IntArray([face]))
                bind(sub.GetPrim(), add_preview_material(stage, f"/Looks/C{face}", rgb))
        lit(stage, 3)
        return render(stage, width=96)

    got, want = scene(True), scene(False)
    row = got.shape[0] // 2
    for face in range(3):
        middle = slice(face * 32 + 6, face * 32 + 26)  # inside each face, off the tile edges
        np.testing.assert_allclose(got[row, middle], want[row, middle], atol=1e-3)


def test_a_udim_set_reaches_set_mesh_with_its_tiles(fake, tmp_path) -> None:
    for tile in (1001, 1002):
        constant_image(tmp_path / f"paint.{tile}.png", (0.5, 0.5, 0.5))
    stage = new_stage()
    bind(quads(stage).GetPrim(), textured(stage, "/Looks/U", str(tmp_path / "paint.<UDIM>.png")))
    UsdSceneDelegate(stage, fake).sync()
    tex = fake.meshes()["/World/Quads"]["material"]["textures"]["diffuseColor"]
    assert tex["file"] == str(tmp_path / "paint.<UDIM>.png")
    assert tex["udim_tiles"] == [(t, str(tmp_path / f"paint.{t}.png")) for t in (1001, 1002)]


# ------------------------------------------------------- channels and bit depths

# Multiples of 0.2 are exact at 8 bits (k · 51/255) and 16 bits (k · 13107/65535).
COLOURS = {1: (0.4,), 2: (0.4,), 3: (0.2, 0.4, 0.6), 4: (0.2, 0.4, 0.6)}
ALPHA = {1: 1.0, 2: 0.2, 3: 1.0, 4: 0.2}
#: UsdUVTexture's rule: a grey file is r = g = b; grey and alpha gives a its second channel;
#: a file without alpha has a = 1.
RGB = {1: (0.4, 0.4, 0.4), 2: (0.4, 0.4, 0.4), 3: (0.2, 0.4, 0.6), 4: (0.2, 0.4, 0.6)}


def _file_values(channels: int) -> tuple[float, ...]:
    return COLOURS[channels] + ((ALPHA[channels],) if channels in (2, 4) else ())


FORMATS = [("uint8", "png"), ("uint16", "png"), ("uint16", "tif"), ("float", "exr")]


@pytest.mark.parametrize("fmt, ext", FORMATS)
@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_files_of_every_channel_count_and_depth_give_usd_uv_texture_values(
    native, tmp_path, fmt, ext, channels
) -> None:
    file = constant_image(tmp_path / f"c{channels}.{ext}", _file_values(channels), fmt)
    stage = new_stage()
    bind(quads(stage).GetPrim(), textured(stage, "/Looks/T", str(file)))
    lit(stage)
    want = constant_render(RGB[channels])
    np.testing.assert_allclose(render(stage), want, atol=2e-3)
    # Alpha as a cut-out mask (threshold 0.5): a = 1 shows the quad, a = 0.2 cuts it out.
    stage = new_stage()
    bind(quads(stage).GetPrim(), textured(stage, "/Looks/T", str(file), output="a"))
    lit(stage)
    alpha = render(stage, "alpha")[..., 0]
    middle = alpha[alpha.shape[0] // 2, alpha.shape[1] // 2]
    assert middle == (1.0 if ALPHA[channels] > 0.5 else 0.0)


@pytest.mark.parametrize("output, channel", [("r", 0), ("g", 1), ("b", 2)])
def test_single_channel_outputs_of_a_grey_file_all_read_its_grey(
    native, tmp_path, output, channel
) -> None:
    """``outputs:g`` of a one-channel file is its grey, not the black of a missing channel."""
    file = constant_image(tmp_path / "grey.png", (0.6,))
    stage = new_stage()
    material = textured(stage, "/Looks/T", str(file))
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/T/PreviewSurface"))
    image = UsdShade.Shader(stage.GetPrimAtPath("/Looks/T/Image"))
    image.CreateOutput(output, Sdf.ValueTypeNames.Float)
    surface.GetInput("diffuseColor").ClearSources()
    surface.GetInput("diffuseColor").Set(Gf.Vec3f(0.5, 0.5, 0.5))
    surface.CreateInput("metallic", Sdf.ValueTypeNames.Float).ConnectToSource(
        image.ConnectableAPI(), output
    )
    bind(quads(stage).GetPrim(), material)
    lit(stage)
    got = render(stage)
    truth_stage = new_stage()
    truth = add_preview_material(truth_stage, "/Looks/T", (0.5, 0.5, 0.5))
    UsdShade.Shader(truth_stage.GetPrimAtPath("/Looks/T/PreviewSurface")).CreateInput(
        "metallic", Sdf.ValueTypeNames.Float
    ).Set(0.6)
    bind(quads(truth_stage).GetPrim(), truth)
    lit(truth_stage)
    np.testing.assert_allclose(got, render(truth_stage), atol=2e-3)
    del channel
