"""UsdUVTexture ``sourceColorSpace`` end to end.

An 8-bit sRGB file must render as the linear values it encodes: the truth is the
same texture written as float linear values (the sRGB curve applied in numpy),
compared through the ``albedo`` AOV, which is the textured diffuseColor itself.
``auto`` (the fallback) reads 8-bit RGB as sRGB, as Hydra's Storm does; ``raw``
reads the codes as they are; an unknown token warns once, naming the shader,
and renders as ``auto``.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Sdf, UsdShade
from test_materials import quad, surface, texture

import mipray
from mipray.usd.scene_delegate import UsdSceneDelegate

from stages import add_camera, bind, new_stage

#: 16 × 16 texels: 8-bit codes, red rising to the right, green falling, blue rising upward.
_X = np.arange(16)
CODES = np.zeros((16, 16, 3), np.uint8)
CODES[..., 0] = (16 + 15 * _X)[None, :]
CODES[..., 1] = (255 - 15 * _X)[None, :]
CODES[..., 2] = (20 + 12 * _X)[::-1, None]


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1, encoded [0, 1] → linear."""
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def write(native, path, values: np.ndarray, fmt: str) -> str:
    native.write_image(
        str(path),
        {"color": np.ascontiguousarray(values, np.float32)},
        ["color"],
        {"color": fmt},
    )
    return str(path)


@pytest.fixture
def files(native, tmp_path) -> dict[str, str]:
    encoded = CODES.astype(np.float32) / 255.0
    return {
        "png": write(native, tmp_path / "ramp.png", encoded, "uint8"),
        "linear": write(native, tmp_path / "ramp_linear.exr", srgb_to_linear(encoded), "float"),
        "codes": write(native, tmp_path / "ramp_codes.exr", encoded, "float"),
    }


def _stage(file: str, color_space: str | None):
    stage = new_stage()
    mesh = quad(stage, half=1.6)
    material, shader = surface(stage, "/World/Looks/M", useSpecularWorkflow=1)
    bind(mesh.GetPrim(), material)
    tex = texture(
        stage,
        "/World/Looks/M",
        shader,
        "diffuseColor",
        file,
        wrapS="clamp",
        wrapT="clamp",
    )
    if color_space is not None:
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
    add_camera(stage, "/World/Camera")
    return stage


def albedo(file: str, color_space: str | None) -> np.ndarray:
    # 64 px over ±2.1 units: 16 texels over about 49 px, magnified, so every lookup reads the
    # finest level and the two files' MIP maps (maketx's, automip's) do not enter.
    result = mipray.render(
        _stage(file, color_space), width=64, aovs=("albedo",), settings={"samples": 4}
    )
    return result.aovs["albedo"][..., :3]


def test_an_8bit_texture_renders_as_the_linear_values_it_encodes(files) -> None:
    truth = albedo(files["linear"], None)
    assert truth.max() > 0.5 and np.ptp(truth[..., 0][truth[..., 0] > 0]) > 0.5
    for space in (None, "auto", "sRGB"):
        got = albedo(files["png"], space)
        np.testing.assert_allclose(got, truth, atol=2e-3, rtol=2e-3, err_msg=f"{space}")
    # raw reads the codes as they are: the float file of the codes, and much brighter.
    raw = albedo(files["png"], "raw")
    np.testing.assert_allclose(raw, albedo(files["codes"], None), atol=2e-3, rtol=2e-3)
    assert (raw - truth).max() > 0.15


def test_auto_leaves_float_files_as_they_are(files) -> None:
    # The float file of the codes under auto is raw (not decoded a second time).
    codes = albedo(files["codes"], "auto")
    np.testing.assert_allclose(codes, albedo(files["codes"], "raw"), atol=1e-6)


def test_the_stats_name_the_file_each_linear_copy_was_decoded_from(files) -> None:
    result = mipray.render(_stage(files["png"], None), width=16, aovs=("color",))
    decoded = [
        f for f in result.stats["texture_cache"]["files"] if f["source_color_space"] == "sRGB"
    ]
    assert [f["decoded_from"] for f in decoded] == [files["png"]], result.stats["texture_cache"]


def test_an_unknown_source_color_space_warns_naming_the_shader_and_renders_as_auto(
    files, caplog
) -> None:
    with caplog.at_level(logging.WARNING):
        got = albedo(files["png"], "linear-ish")
    messages = [r.getMessage() for r in caplog.records if "sourceColorSpace" in r.getMessage()]
    assert messages and "/World/Looks/M/diffuseColorTexture" in messages[0], messages
    np.testing.assert_allclose(got, albedo(files["png"], "auto"), atol=1e-6)


def test_source_color_space_reaches_set_mesh(fake) -> None:
    stage = _stage("ramp.png", "raw")
    UsdSceneDelegate(stage, fake).sync()
    tex = fake.meshes()["/World/Quad"]["material"]["textures"]["diffuseColor"]
    assert tex["sourceColorSpace"] == "raw"
    # Unauthored: left out, so the renderer's fallback (auto) applies.
    UsdShade.Shader(
        stage.GetPrimAtPath("/World/Looks/M/diffuseColorTexture")
    ).GetPrim().RemoveProperty("inputs:sourceColorSpace")
    UsdSceneDelegate(stage, fake).sync()
    assert (
        "sourceColorSpace"
        not in fake.meshes()["/World/Quad"]["material"]["textures"]["diffuseColor"]
    )


def test_auto_decoding_a_file_that_feeds_data_warns_once_naming_prim_input_and_file(
    files, caplog
) -> None:
    def stage_with(color_space: str | None):
        stage = new_stage()
        mesh = quad(stage, half=1.6)
        material, shader = surface(stage, "/World/Looks/M", useSpecularWorkflow=1)
        bind(mesh.GetPrim(), material)
        tex = texture(stage, "/World/Looks/M", shader, "roughness", files["png"], "r")
        if color_space is not None:
            tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
        add_camera(stage, "/World/Camera")
        return stage

    def warnings(color_space: str | None) -> list[str]:
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            mipray.render(stage_with(color_space), width=16, aovs=("color",))
        return [r.getMessage() for r in caplog.records if "as sRGB" in r.getMessage()]

    # An 8-bit RGB file on roughness: Hydra's auto decodes it, which only its author can say
    # is wrong, so the renderer says what it did and how to change it.
    got = warnings(None)
    assert len(got) == 1, got
    assert all(w in got[0] for w in ("/World/Quad", "roughness", "ramp.png", "raw")), got
    assert warnings("raw") == [] and warnings("sRGB") == []
