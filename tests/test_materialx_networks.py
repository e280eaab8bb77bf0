"""MaterialX node networks beyond one affine texture lookup, evaluated per shading point.

Each stage is a flat quad facing the camera with ``st`` over [0, 1]², lambertian
(``ND_UsdPreviewSurface_surfaceshader``, specular workflow without specular) and lit by a
distant light; its ``diffuseColor`` is fed by a network of MaterialX standard-library nodes
reading float EXR files the test writes. The truth is the network worked out in numpy from
the nodes' definitions (MaterialX 1.39 ``stdlib_defs.mtlx`` defaults, the GLSL
implementations' operators, ``stdlib_ng.mtlx`` for place2d and tiledimage) at each pixel's
``st``: the ``albedo`` AOV is that colour, and the ``color`` AOV that colour times the
light's irradiance over π.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade
from test_materials import quad

import mipray
from mipray.usd import UsdSceneDelegate

from stages import add_camera, add_distant_light, bind, new_stage

C3, F, F2 = Sdf.ValueTypeNames.Color3f, Sdf.ValueTypeNames.Float, Sdf.ValueTypeNames.Float2
TYPES = {
    "color3": C3,
    "vector3": Sdf.ValueTypeNames.Float3,
    "float": F,
    "vector2": F2,
    "integer": Sdf.ValueTypeNames.Int,
    "vector4": Sdf.ValueTypeNames.Float4,
}
WIDTH = 64
HALF = 1.6  # the quad's half size; the camera sees ±2 at its distance (10)
#: Radiance of a white lambertian quad facing +Z under stages.add_distant_light (irradiance 2
#: facing the light, tilted 45°).
WHITE = 2.0 * math.cos(math.radians(45.0)) / math.pi
#: Two constant colours, exact in half floats.
A = (0.125, 0.25, 0.5)
B = (0.5, 0.375, 0.25)


def write(native, path, values) -> str:
    values = np.asarray(values, np.float32)
    if values.ndim == 2:
        values = values[..., None]
    native.write_image(
        str(path), {"color": np.ascontiguousarray(values)}, ["color"], {"color": "float"}
    )
    return str(path)


def constant_image(native, path, colour) -> str:
    return write(native, path, np.broadcast_to(np.float32(colour), (8, 8, 3)))


#: Colours of the four quadrants of QUADRANTS, indexed [s ≥ 0.5][t ≥ 0.5].
QUADRANT = np.array(
    [[(0.75, 0.125, 0.125), (0.125, 0.75, 0.125)], [(0.125, 0.125, 0.75), (0.5, 0.5, 0.5)]]
)


def quadrant_image(native, path) -> str:
    n = 64
    rows = np.arange(n)
    t_high = (rows < n // 2)[:, None]  # row 0 is the top: t = 1
    s_high = (rows >= n // 2)[None, :]
    img = QUADRANT[
        s_high.astype(int) * np.ones((n, 1), int), t_high.astype(int) * np.ones((1, n), int)
    ]
    return write(native, path, img)


def quadrant_truth(st: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """QUADRANT at frac(st), and where that is at least 0.1 from a quadrant's edge."""
    f = st - np.floor(st)
    truth = QUADRANT[(f[..., 0] >= 0.5).astype(int), (f[..., 1] >= 0.5).astype(int)]
    edge = np.minimum(np.abs(f - 0.5), np.minimum(f, 1 - f)).min(-1)
    return truth, edge > 0.1


def node(stage: Usd.Stage, name: str, node_id: str, out: str, **inputs) -> UsdShade.Shader:
    """A MaterialX node at /Looks/M/<name>; inputs: a Shader (connected), an asset path
    (``file``), or a (type, value) pair."""
    shader = UsdShade.Shader.Define(stage, f"/Looks/M/{name}")
    shader.CreateIdAttr(node_id)
    shader.CreateOutput("out", TYPES[out])
    for key, value in inputs.items():
        if isinstance(value, UsdShade.Shader):
            kind = value.GetOutput("out").GetTypeName()
            shader.CreateInput(key, kind).ConnectToSource(value.ConnectableAPI(), "out")
        elif key == "file":
            shader.CreateInput(key, Sdf.ValueTypeNames.Asset).Set(value)
        else:
            kind, v = value
            shader.CreateInput(key, TYPES[kind]).Set(
                Gf.Vec3f(*v) if kind == "color3" else Gf.Vec2f(*v) if kind == "vector2" else v
            )
    return shader


def lambertian(
    stage: Usd.Stage, diffuse: UsdShade.Shader, normal: UsdShade.Shader | None = None
) -> None:
    """/Looks/M: a lambertian MaterialX UsdPreviewSurface whose diffuseColor is ``diffuse``,
    bound to the quad, with the camera and the light."""
    material = UsdShade.Material.Define(stage, "/Looks/M")
    surface = UsdShade.Shader.Define(stage, "/Looks/M/Surface")
    surface.CreateIdAttr("ND_UsdPreviewSurface_surfaceshader")
    surface.CreateOutput("out", Sdf.ValueTypeNames.Token)
    material.CreateSurfaceOutput("mtlx").ConnectToSource(surface.ConnectableAPI(), "out")
    surface.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    surface.CreateInput("specularColor", C3).Set(Gf.Vec3f(0.0, 0.0, 0.0))
    surface.CreateInput("diffuseColor", C3).ConnectToSource(diffuse.ConnectableAPI(), "out")
    if normal is not None:
        kind = Sdf.ValueTypeNames.Normal3f
        surface.CreateInput("normal", kind).ConnectToSource(normal.ConnectableAPI(), "out")
    bind(quad(stage, half=HALF).GetPrim(), material)
    add_camera(stage, "/World/Camera")
    add_distant_light(stage, "/World/Sun")


@dataclass
class Render:
    albedo: np.ndarray
    color: np.ndarray
    #: Each pixel's st on the quad (from its mean world position: the quad is z = 0).
    st: np.ndarray
    #: Pixels wholly on the quad.
    on: np.ndarray
    normal: np.ndarray


def render(stage: Usd.Stage) -> Render:
    aovs = ("albedo", "color", "position", "alpha", "normal")
    r = mipray.render(stage, width=WIDTH, aovs=aovs, settings={"samples": 1}).aovs
    st = r["position"][..., :2] / (2 * HALF) + 0.5
    on = r["alpha"][..., 0] == 1.0
    return Render(r["albedo"][..., :3], r["color"][..., :3], st, on, r["normal"][..., :3])


def assert_albedo(albedo: np.ndarray, truth: np.ndarray, where: np.ndarray, atol: float = 2e-3):
    assert where.sum() > WIDTH * WIDTH // 16
    np.testing.assert_allclose(
        albedo[where], np.broadcast_to(truth, albedo.shape)[where], atol=atol
    )


@pytest.mark.parametrize(
    ("op", "truth"),
    [
        ("add", np.add(A, B)),
        ("multiply", np.multiply(A, B)),
        ("subtract", np.clip(np.subtract(B, A), 0, 1)),  # in1 − in2, clamped as a colour is
        ("max", np.maximum(A, B)),
    ],
)
def test_two_images_combine_as_the_node_says(native, tmp_path, op, truth) -> None:
    stage = new_stage()
    a = node(
        stage, "A", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "a.exr", A)
    )
    b = node(
        stage, "B", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "b.exr", B)
    )
    first, second = (b, a) if op == "subtract" else (a, b)
    lambertian(stage, node(stage, "Op", f"ND_{op}_color3", "color3", in1=first, in2=second))
    r = render(stage)
    assert_albedo(r.albedo, truth, r.on, atol=1e-5)
    # The light's response: lambertian, colour × irradiance / π (UsdLux's distant light is a
    # 0.53° disc, sampled: 0.5 % noise at one sample a pixel).
    np.testing.assert_allclose(
        r.color[r.on], np.broadcast_to(truth * WHITE, r.color.shape)[r.on], rtol=5e-3, atol=1e-5
    )


def test_a_textured_mask_mixes_a_constant_and_an_image(native, tmp_path) -> None:
    mask = np.where(np.arange(64)[None, :] < 32, 0.25, 0.75) * np.ones((64, 1))
    stage = new_stage()
    m = node(
        stage, "Mask", "ND_image_float", "float", file=write(native, tmp_path / "mask.exr", mask)
    )
    m.CreateInput("uaddressmode", Sdf.ValueTypeNames.String).Set("clamp")
    bg = node(
        stage, "Bg", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "b.exr", B)
    )
    fg = node(stage, "Fg", "ND_constant_color3", "color3", value=("color3", A))
    lambertian(stage, node(stage, "Mix", "ND_mix_color3", "color3", fg=fg, bg=bg, mix=m))
    r = render(stage)
    s = r.st[..., 0]
    w = np.where(s < 0.5, 0.25, 0.75)[..., None]
    truth = np.multiply(B, 1 - w) + np.multiply(A, w)  # GLSL mix(bg, fg, mask)
    assert_albedo(r.albedo, truth, r.on & (np.abs(s - 0.5) > 0.1), atol=1e-5)


def test_power_of_a_ramp(native, tmp_path) -> None:
    # A ramp in s: texel centres hold s, and bilinear and MIP filtering keep a linear ramp.
    ramp = (np.arange(64) + 0.5)[None, :] / 64 * np.ones((8, 1))
    stage = new_stage()
    image = node(
        stage, "Ramp", "ND_image_float", "float", file=write(native, tmp_path / "ramp.exr", ramp)
    )
    image.CreateInput("uaddressmode", Sdf.ValueTypeNames.String).Set("clamp")
    grey = node(stage, "Grey", "ND_convert_float_color3", "color3", **{"in": image})
    lambertian(
        stage, node(stage, "Pow", "ND_power_color3FA", "color3", in1=grey, in2=("float", 2.2))
    )
    r = render(stage)
    s = r.st[..., 0]
    truth = (s**2.2)[..., None] * np.ones(3)
    inside = r.on & (s > 0.05) & (s < 0.95)
    assert_albedo(r.albedo, truth, inside)
    np.testing.assert_allclose(r.color[inside], truth[inside] * WHITE, atol=2e-3 * WHITE, rtol=5e-3)


def _place2d(st: np.ndarray, scale, rotate: float, offset, pivot) -> np.ndarray:
    """NG_place2d_vector2, operationorder 0 (SRT), mx_rotate_vector2's rotation, in numpy."""
    v = (st - pivot) / scale
    a = math.radians(rotate)
    ca, sa = math.cos(a), math.sin(a)
    v = np.stack([ca * v[..., 0] + sa * v[..., 1], -sa * v[..., 0] + ca * v[..., 1]], -1)
    return v - offset + pivot


@pytest.mark.parametrize(
    ("scale", "rotate", "offset", "pivot"),
    [((0.5, 0.5), 0.0, (0.25, 0.0), (0.0, 0.0)), ((1.0, 0.5), 90.0, (0.0, 0.125), (0.5, 0.5))],
)
def test_place2d_moves_scales_and_turns_the_lookup(
    native, tmp_path, scale, rotate, offset, pivot
) -> None:
    stage = new_stage()
    uv = node(stage, "Uv", "ND_texcoord_vector2", "vector2")
    place = node(
        stage, "Place", "ND_place2d_vector2", "vector2", texcoord=uv,
        scale=("vector2", scale), rotate=("float", rotate), offset=("vector2", offset),
        pivot=("vector2", pivot),
    )  # fmt: skip
    file = quadrant_image(native, tmp_path / "quadrants.exr")
    lambertian(stage, node(stage, "Image", "ND_image_color3", "color3", file=file, texcoord=place))
    r = render(stage)
    truth, inside = quadrant_truth(_place2d(r.st, np.array(scale), rotate, offset, pivot))
    assert_albedo(r.albedo, truth, r.on & inside)


def test_tiledimage_repeats_the_image_uvtiling_times(native, tmp_path) -> None:
    stage = new_stage()
    file = quadrant_image(native, tmp_path / "quadrants.exr")
    lambertian(
        stage,
        node(
            stage,
            "Tiled",
            "ND_tiledimage_color3",
            "color3",
            file=file,
            uvtiling=("vector2", (2.0, 2.0)),
        ),
    )
    r = render(stage)
    truth, inside = quadrant_truth(2.0 * r.st)  # NG_tiledimage: uv · uvtiling − uvoffset
    assert_albedo(r.albedo, truth, r.on & inside)


def test_checkerboard_cells_follow_uvtiling_and_uvoffset(native, tmp_path) -> None:
    stage = new_stage()
    board = node(
        stage, "Board", "ND_checkerboard_color3", "color3",
        color1=("color3", A), color2=("color3", B), uvtiling=("vector2", (4.0, 2.0)),
        uvoffset=("vector2", (0.5, 0.0)),
    )  # fmt: skip
    lambertian(stage, board)
    r = render(stage)
    # NG_checkerboard_color3: mix(color2, color1, mod(floor(u') + floor(v'), 2)).
    cell = r.st * (4.0, 2.0) - (0.5, 0.0)
    odd = (np.floor(cell).sum(-1) % 2)[..., None]
    truth = np.multiply(B, 1 - odd) + np.multiply(A, odd)
    inside = r.on & (np.abs(cell - np.round(cell)).min(-1) > 0.05)
    assert_albedo(r.albedo, truth, inside, atol=1e-5)


@pytest.mark.parametrize("normalmap", ["ND_normalmap_float", "ND_normalmap"])  # 1.39, 1.38
def test_a_normal_map_chain_tilts_the_shading_normal(native, tmp_path, normalmap) -> None:
    # normalize(normalmap(image, scale 0.5)): n = normalize((2t − 1) · (0.5, 0.5, 1)) in the
    # quad's (dP/ds, dP/dt, N) = (+X, +Y, +Z) frame.
    texel = (0.75, 0.375, 0.875)
    stage = new_stage()
    file = constant_image(native, tmp_path / "n.exr", texel)
    image = node(stage, "NormalImage", "ND_image_vector3", "vector3", file=file)
    mapped = node(stage, "Map", normalmap, "vector3", scale=("float", 0.5), **{"in": image})
    unit = node(stage, "Unit", "ND_normalize_vector3", "vector3", **{"in": mapped})
    lambertian(
        stage, node(stage, "Grey", "ND_constant_color3", "color3", value=("color3", A)), unit
    )
    r = render(stage)
    n = (2 * np.array(texel) - 1) * (0.5, 0.5, 1.0)
    truth = n / np.linalg.norm(n)
    assert abs(truth[0]) > 0.2 and abs(truth[1]) > 0.1
    assert r.on.sum() > WIDTH * WIDTH // 4
    np.testing.assert_allclose(
        r.normal[r.on], np.broadcast_to(truth, r.normal.shape)[r.on], atol=2e-3
    )


def test_remap_luminance_sqrt_and_ifgreater_on_a_textured_mask(native, tmp_path) -> None:
    mask = np.where(np.arange(64)[None, :] < 32, 0.25, 0.75) * np.ones((64, 1))
    stage = new_stage()
    m = node(stage, "Mask", "ND_image_float", "float", file=write(native, tmp_path / "m.exr", mask))
    m.CreateInput("uaddressmode", Sdf.ValueTypeNames.String).Set("clamp")
    a = node(
        stage, "A", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "a.exr", A)
    )
    b = node(
        stage, "B", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "b.exr", B)
    )
    grey = node(stage, "Grey", "ND_luminance_color3", "color3", **{"in": b})
    root = node(stage, "Root", "ND_sqrt_color3", "color3", **{"in": grey})
    remapped = node(
        stage, "Remap", "ND_remap_color3FA", "color3", inlow=("float", 0.1), inhigh=("float", 0.6),
        outlow=("float", 0.2), outhigh=("float", 0.4), **{"in": a},
    )  # fmt: skip
    pick = node(
        stage,
        "Pick",
        "ND_ifgreater_color3",
        "color3",
        value1=m,
        value2=("float", 0.5),
        in1=root,
        in2=remapped,
    )
    lambertian(stage, pick)
    r = render(stage)
    s = r.st[..., 0]
    # Right (mask 0.75 > 0.5): sqrt of B's luminance (ACEScg coefficients, stdlib_defs.mtlx);
    # left: remap(A) = 0.2 + (A − 0.1) · 0.2 / 0.5.
    lum = np.dot(B, (0.2722287, 0.6740818, 0.0536895))
    right = np.full(3, math.sqrt(lum))
    left = 0.2 + (np.array(A) - 0.1) * (0.4 - 0.2) / (0.6 - 0.1)
    truth = np.where((s > 0.5)[..., None], right, left)
    assert_albedo(r.albedo, truth, r.on & (np.abs(s - 0.5) > 0.1), atol=1e-4)


def test_channels_extracted_combined_converted_and_clamped(native, tmp_path) -> None:
    stage = new_stage()
    a = node(
        stage, "A", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "a.exr", A)
    )
    b = node(
        stage, "B", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "b.exr", B)
    )
    a_red = node(stage, "ARed", "ND_image_float", "float", file=str(tmp_path / "a.exr"))
    blue = node(stage, "Blue", "ND_extract_color3", "float", index=("integer", 2), **{"in": a})
    green = node(stage, "Green", "ND_extract_color3", "float", index=("integer", 1), **{"in": b})
    rgb = node(
        stage, "Rgb", "ND_combine3_color3", "color3", in1=blue, in2=green, in3=("float", 0.125)
    )
    clamped = node(
        stage,
        "Clamp",
        "ND_clamp_color3FA",
        "color3",
        low=("float", 0.2),
        high=("float", 0.45),
        **{"in": rgb},
    )
    grey = node(stage, "Grey", "ND_convert_float_color3", "color3", **{"in": a_red})
    lambertian(stage, node(stage, "Times", "ND_multiply_color3", "color3", in1=clamped, in2=grey))
    r = render(stage)
    # combine3(A.b, B.g, 0.125) = (0.5, 0.375, 0.125), clamped into [0.2, 0.45], × A.r.
    truth = np.clip((A[2], B[1], 0.125), 0.2, 0.45) * A[0]
    assert_albedo(r.albedo, truth, r.on, atol=1e-5)


def test_separate3_outputs_feed_a_combine3(native, tmp_path) -> None:
    stage = new_stage()
    a = node(
        stage, "A", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "a.exr", A)
    )
    split = UsdShade.Shader.Define(stage, "/Looks/M/Split")
    split.CreateIdAttr("ND_separate3_color3")
    split.CreateInput("in", C3).ConnectToSource(a.ConnectableAPI(), "out")
    rgb = node(stage, "Rgb", "ND_combine3_color3", "color3")
    for name, channel in (("in1", "outb"), ("in2", "outr"), ("in3", "outg")):
        split.CreateOutput(channel, F)
        rgb.CreateInput(name, F).ConnectToSource(split.ConnectableAPI(), channel)
    lambertian(stage, rgb)
    r = render(stage)
    assert_albedo(r.albedo, (A[2], A[0], A[1]), r.on, atol=1e-5)


def test_one_lookup_through_the_network_renders_as_the_affine_fast_path(native, tmp_path) -> None:
    # max(image, −1) is the image itself, through the core's network instead of TexturedColor:
    # the same lookup, filtered over the same footprint, so the same bits.
    ramp = np.stack([(np.arange(64) + 0.5)[None, :] / 64 * np.ones((64, 1))] * 3, -1)
    ramp[..., 1] = ramp[..., 1].T[::-1]
    file = write(native, tmp_path / "ramp.exr", ramp)
    images = []
    for through_network in (False, True):
        stage = new_stage()
        image = node(stage, "Image", "ND_image_color3", "color3", file=file)
        if through_network:
            image = node(stage, "Max", "ND_max_color3FA", "color3", in1=image, in2=("float", -1.0))
        lambertian(stage, image)
        images.append(render(stage))
    fast, network = images
    assert fast.albedo[fast.on].std() > 0.1
    np.testing.assert_array_equal(network.albedo, fast.albedo)
    np.testing.assert_array_equal(network.color, fast.color)


def test_a_network_is_sent_as_ops_over_lookups(fake, tmp_path, caplog) -> None:
    stage = new_stage()
    a = node(stage, "A", "ND_image_color3", "color3", file=str(tmp_path / "a.exr"))
    b = node(
        stage,
        "B",
        "ND_tiledimage_color3",
        "color3",
        file=str(tmp_path / "b.exr"),
        uvtiling=("vector2", (2.0, 3.0)),
    )
    lambertian(stage, node(stage, "Add", "ND_add_color3", "color3", in1=a, in2=b))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        UsdSceneDelegate(stage, fake).sync()
    assert not caplog.records, caplog.text
    material = fake.meshes()["/World/Quad"]["material"]
    assert "textures" not in material
    net = material["networks"]["diffuseColor"]
    assert net["ops"] == [("texture", 0), ("texture", 1), ("add",)]
    first, second = net["lookups"]
    assert first["file"] == str(tmp_path / "a.exr") and first["channels"] == 3
    assert first["st_transform"] == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    assert second["st_transform"] == [2.0, 0.0, 0.0, 0.0, 3.0, 0.0]
    assert second["wrapS"] == second["wrapT"] == "repeat"  # NG_tiledimage reads periodic


def _warnings(caplog, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


def test_an_unsupported_node_in_a_network_is_named_once_and_the_input_keeps_its_default(
    fake, tmp_path, caplog
) -> None:
    stage = new_stage()
    image = node(stage, "Image", "ND_image_color3", "color3", file=str(tmp_path / "a.exr"))
    # (ND_position_vector3 was the example here until it was evaluated.)
    position = node(stage, "Position", "ND_tangent_vector3", "color3")
    tint = node(stage, "Tint", "ND_multiply_color3", "color3", in1=image, in2=position)
    lambertian(stage, tint)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    material = fake.meshes()["/World/Quad"]["material"]
    assert "networks" not in material and "textures" not in material
    assert "diffuseColor" not in material  # UsdPreviewSurface's fallback
    named = _warnings(caplog, "ND_tangent_vector3")
    assert (
        len(named) == 1 and "/Looks/M/Position" in named[0] and named[0].endswith("on /Looks/M")
    ), caplog.text
    assert any(u.what.startswith("MaterialX node ND_tangent_vector3") for u in scene.unsupported)


def test_an_input_of_the_wrong_type_in_a_network_is_named_once(fake, tmp_path, caplog) -> None:
    stage = new_stage()
    image = node(stage, "Image", "ND_image_color3", "color3", file=str(tmp_path / "a.exr"))
    power = node(stage, "Pow", "ND_power_color3FA", "color3", in1=image)
    power.CreateInput("in2", Sdf.ValueTypeNames.String).Set("2.2")
    lambertian(stage, power)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        UsdSceneDelegate(stage, fake).sync()
    material = fake.meshes()["/World/Quad"]["material"]
    assert "networks" not in material and "textures" not in material
    named = _warnings(caplog, "input in2 of type string")
    assert len(named) == 1 and "/Looks/M/Pow" in named[0] and named[0].endswith("on /Looks/M"), (
        caplog.text
    )


def test_an_unreadable_lookup_takes_its_default_and_the_rest_of_the_network_still_runs(
    native, tmp_path, caplog
) -> None:
    stage = new_stage()
    a = node(
        stage, "A", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "a.exr", A)
    )
    missing = str(tmp_path / "missing.exr")
    gone = node(stage, "Gone", "ND_image_color3", "color3", file=missing, default=("color3", B))
    lambertian(stage, node(stage, "Add", "ND_add_color3", "color3", in1=a, in2=gone))
    with caplog.at_level(logging.WARNING):
        r = render(stage)
    assert_albedo(r.albedo, np.add(A, B), r.on, atol=1e-5)  # ND_image's default where unread
    assert np.isfinite(r.color).all()
    named = _warnings(caplog, missing)
    assert len(named) == 1 and "/World/Quad" in named[0], caplog.text


def test_a_malformed_network_is_an_error_naming_the_prim(native) -> None:
    delegate = native.RenderDelegate()
    quad_args = {
        "points": np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32),
        "face_vertex_counts": np.array([4], np.int32),
        "face_vertex_indices": np.array([0, 1, 2, 3], np.int32),
        "transform": np.eye(4),
        "scheme": "none",
    }
    one = [{"file": "x.exr"}]
    for network, words in (
        ({"ops": [("texture", 0), ("add",)], "lookups": one}, "needs 2 value"),
        ({"ops": [("texture", 1)], "lookups": one}, "reads lookup 1 of 1"),
        # (noise3d was the example of an unknown op until it was evaluated.)
        ({"ops": [("worleynoise3d",)], "lookups": []}, "worleynoise3d"),
        ({"ops": [("const", math.nan, 0, 0, 0)], "lookups": []}, "non-finite"),
        ({"ops": [("texture", 0)], "lookups": [{"file": "x.exr", "channels": 5}]}, "channels"),
    ):
        material = {"networks": {"diffuseColor": network}}
        with pytest.raises(ValueError, match=rf"/World/Bad: .*{words}"):
            delegate.set_mesh("/World/Bad", material=material, **quad_args)
    both = {
        "textures": {"roughness": one[0]},
        "networks": {"roughness": {"ops": [("const", 1, 1, 1, 1)]}},
    }
    with pytest.raises(ValueError, match="both a texture and a network"):
        delegate.set_mesh("/World/Bad", material=both, **quad_args)
    ok = {
        "networks": {
            "roughness": {
                "ops": [("texture", 0), ("const", 2, 2, 2, 2), ("power",)],
                "lookups": one,
            }
        }
    }
    delegate.set_mesh("/World/Good", material=ok, **quad_args)


def assert_same_bits_across_threads_and_cache_modes(stage) -> None:
    """The stage's colour at 32 px is not flat and the same bits with one thread and the
    multires cache, and with two threads and the `none` and `unbounded` caches."""
    images = [
        mipray.render(stage, width=32, aovs=("color",), settings=settings).aovs["color"]
        for settings in (
            {"threads": 1, "cacheMode": "multires"},
            {"threads": 2, "cacheMode": "none"},
            {"threads": 2, "cacheMode": "unbounded"},
        )
    ]
    assert images[0].std() > 0.01
    for other in images[1:]:
        np.testing.assert_array_equal(other, images[0])


def test_a_network_renders_the_same_bits_with_any_thread_count_and_cache_mode(
    native, tmp_path
) -> None:
    stage = new_stage()
    uv = node(stage, "Uv", "ND_texcoord_vector2", "vector2")
    place = node(
        stage, "Place", "ND_place2d_vector2", "vector2", texcoord=uv, rotate=("float", 30.0)
    )
    file = quadrant_image(native, tmp_path / "quadrants.exr")
    image = node(stage, "Image", "ND_image_color3", "color3", file=file, texcoord=place)
    lambertian(
        stage, node(stage, "Pow", "ND_power_color3FA", "color3", in1=image, in2=("float", 0.5))
    )
    assert_same_bits_across_threads_and_cache_modes(stage)


def test_a_cycle_of_connections_is_named_once_and_the_frame_renders(
    native, tmp_path, caplog
) -> None:
    stage = new_stage()
    a = node(
        stage, "A", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "a.exr", A)
    )
    first = node(stage, "First", "ND_add_color3", "color3", in1=a)
    second = node(stage, "Second", "ND_multiply_color3", "color3", in1=first, in2=a)
    first.CreateInput("in2", C3).ConnectToSource(second.ConnectableAPI(), "out")
    lambertian(stage, first)
    with caplog.at_level(logging.WARNING):
        r = render(stage)
    named = _warnings(caplog, "in a cycle")
    assert len(named) == 1 and "/Looks/M" in named[0], caplog.text
    assert_albedo(r.albedo, np.full(3, 0.18), r.on, atol=1e-3)  # UsdPreviewSurface's fallback


def test_a_network_deeper_than_the_evaluator_is_named_and_the_input_keeps_its_default(
    native, tmp_path, caplog
) -> None:
    # add(image, add(image, …)) twenty deep: each level holds one more value on the stack.
    stage = new_stage()
    file = constant_image(native, tmp_path / "a.exr", (0.01, 0.01, 0.01))
    inner = node(stage, "Image0", "ND_image_color3", "color3", file=file)
    for k in range(1, 20):
        image = node(stage, f"Image{k}", "ND_image_color3", "color3", file=file)
        inner = node(stage, f"Add{k}", "ND_add_color3", "color3", in1=image, in2=inner)
    lambertian(stage, inner)
    with caplog.at_level(logging.WARNING):
        r = render(stage)
    named = _warnings(caplog, "more than 16 values")
    assert len(named) == 1 and "/Looks/M" in named[0], caplog.text
    assert_albedo(r.albedo, np.full(3, 0.18), r.on, atol=1e-3)


def test_a_mesh_lights_network_emission_is_named_once_as_not_tinting(native, tmp_path, caplog):
    from pxr import UsdLux

    stage = new_stage()
    a = node(
        stage, "A", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "a.exr", A)
    )
    b = node(
        stage, "B", "ND_image_color3", "color3", file=constant_image(native, tmp_path / "b.exr", B)
    )
    glow = node(stage, "Glow", "ND_add_color3", "color3", in1=a, in2=b)
    lambertian(stage, node(stage, "Grey", "ND_constant_color3", "color3", value=("color3", A)))
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/M/Surface"))
    surface.CreateInput("emissiveColor", C3).ConnectToSource(glow.ConnectableAPI(), "out")
    UsdLux.MeshLightAPI.Apply(stage.GetPrimAtPath("/World/Quad"))
    with caplog.at_level(logging.WARNING):
        image = mipray.render(stage, width=16, aovs=("color",)).aovs["color"]
    assert np.isfinite(image).all()
    named = _warnings(caplog, "node network, which a mesh light's tint does not evaluate")
    assert len(named) == 1 and "/World/Quad" in named[0] and "/Looks/M" in named[0], caplog.text


@pytest.mark.parametrize("gprim", ["mesh", "mesh without st", "implicit sphere"])
def test_a_geompropvalue_of_a_primvar_the_gprim_lacks_is_its_default(
    native, tmp_path, caplog, gprim
) -> None:
    # MaterialX (and Storm): geompropvalue's `default` where the geometry has no such
    # property. Here a texcoord reading primvars:uv, which no gprim here has, defaults to a
    # constant (0.25, 0.75): the whole surface is the quadrant there, with st or without; a
    # colour reading primvars:tint defaults to B and tints it.
    stage = new_stage()
    uv = node(stage, "Uv", "ND_geompropvalue_vector2", "vector2", default=("vector2", (0.25, 0.75)))
    uv.CreateInput("geomprop", Sdf.ValueTypeNames.String).Set("uv")
    tint = node(stage, "Tint", "ND_geompropvalue_color3", "color3", default=("color3", B))
    tint.CreateInput("geomprop", Sdf.ValueTypeNames.String).Set("tint")
    file = quadrant_image(native, tmp_path / "quadrants.exr")
    image = node(stage, "Image", "ND_image_color3", "color3", file=file, texcoord=uv)
    lambertian(stage, node(stage, "Mul", "ND_multiply_color3", "color3", in1=image, in2=tint))
    if gprim == "mesh without st":
        # The constant texcoord is looked up where the surface has no st channel at all.
        UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Quad")).RemovePrimvar("st")
    elif gprim != "mesh":
        stage.RemovePrim("/World/Quad")
        sphere = UsdGeom.Sphere.Define(stage, "/World/Ball")
        sphere.CreateRadiusAttr(HALF)
        bind(sphere.GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    with caplog.at_level(logging.WARNING):
        r = render(stage)
    assert not _warnings(caplog, "primvars"), caplog.text
    assert_albedo(r.albedo, QUADRANT[0][1] * np.array(B), r.on, atol=1e-5)


def _geomprop(stage: Usd.Stage, name: str, out: str, primvar: str) -> UsdShade.Shader:
    shader = node(stage, name, f"ND_geompropvalue_{out}", out)
    shader.CreateInput("geomprop", Sdf.ValueTypeNames.String).Set(primvar)
    return shader


def test_geompropvalue_reads_a_primvar_of_any_type_into_the_nodes_lanes(native, caplog) -> None:
    # tint (color3f, constant) · gain (float, uniform over the one face) · the first three
    # lanes of dir (float4 read as a vector3, constant), through geompropvalue of color3, float
    # and vector3: MaterialX's geompropvalue is the primvar's value, whatever its type.
    stage = new_stage()
    tint, gain, direction = (0.25, 0.5, 1.0), 0.75, (1.0, 0.5, 0.25, 9.0)
    a = _geomprop(stage, "Tint", "color3", "tint")
    b = _geomprop(stage, "Gain", "float", "gain")
    c = _geomprop(stage, "Dir", "vector3", "dir")
    c3 = node(stage, "AsColor", "ND_convert_vector3_color3", "color3", **{"in": c})
    ab = node(stage, "Ab", "ND_multiply_color3FA", "color3", in1=a, in2=b)
    lambertian(stage, node(stage, "Abc", "ND_multiply_color3", "color3", in1=ab, in2=c3))
    primvars = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Quad"))
    primvars.CreatePrimvar("tint", Sdf.ValueTypeNames.Color3fArray, "constant").Set([tint])
    primvars.CreatePrimvar("gain", Sdf.ValueTypeNames.FloatArray, "uniform").Set([gain])
    primvars.CreatePrimvar("dir", Sdf.ValueTypeNames.Float4, "constant").Set(Gf.Vec4f(*direction))
    with caplog.at_level(logging.WARNING):
        r = render(stage)
    assert not caplog.records, caplog.text
    assert_albedo(r.albedo, np.multiply(tint, direction[:3]) * gain, r.on, atol=1e-5)


def test_a_geompropvalue_of_a_primvar_varying_over_a_mesh_is_interpolated_as_authored(
    native, caplog
) -> None:
    # tint (color3f, vertex) · the fourth component of dir (float4, vertex, read as a vector4
    # and extracted): each bilinear over the quad's corners, as a subdivisionScheme none quad
    # interpolates a vertex primvar, and so their product per pixel.
    stage = new_stage()
    tint = _geomprop(stage, "Tint", "color3", "tint")
    w = node(stage, "W", "ND_extract_vector4", "float", index=("integer", 3))
    w.CreateInput("in", Sdf.ValueTypeNames.Float4).ConnectToSource(
        _geomprop(stage, "Dir", "vector4", "dir").ConnectableAPI(), "out"
    )
    lambertian(stage, node(stage, "Mul", "ND_multiply_color3FA", "color3", in1=tint, in2=w))
    corners = np.array([(0.0, 0.25, 1.0), (0.5, 0.25, 1.0), (1.0, 0.25, 0.0), (0.5, 0.75, 0.0)])
    weights = np.array([0.25, 0.5, 1.0, 0.75])
    primvars = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Quad"))
    primvars.CreatePrimvar("tint", Sdf.ValueTypeNames.Color3fArray, "vertex").Set(
        [Gf.Vec3f(*c) for c in corners]
    )
    primvars.CreatePrimvar("dir", Sdf.ValueTypeNames.Float4Array, "vertex").Set(
        [Gf.Vec4f(9.0, 9.0, 9.0, x) for x in weights]
    )
    with caplog.at_level(logging.WARNING):
        r = render(stage)
    assert not caplog.records, caplog.text
    s, t = r.st[..., :1], r.st[..., 1:]
    # Corners (0, 0), (1, 0), (1, 1), (0, 1), in the quad's point order.
    bilinear = [(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t]
    want_tint = sum(b * c for b, c in zip(bilinear, corners, strict=True))
    want_w = sum(b * x for b, x in zip(bilinear, weights, strict=True))
    assert_albedo(r.albedo, want_tint * want_w, r.on, atol=2e-3)


def test_a_geompropvalue_of_a_primvar_varying_over_an_implicit_prim_is_its_mean_named_once(
    fake, caplog
) -> None:
    stage = new_stage()
    lambertian(stage, _geomprop(stage, "Tint", "color3", "tint"))
    stage.RemovePrim("/World/Quad")
    ball = UsdGeom.Sphere.Define(stage, "/World/Ball")
    bind(ball.GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    colours = [(0.0, 0.25, 1.0), (0.5, 0.25, 1.0), (1.0, 0.25, 0.0), (0.5, 0.25, 0.0)]
    primvars = UsdGeom.PrimvarsAPI(ball.GetPrim())
    primvars.CreatePrimvar("tint", Sdf.ValueTypeNames.Color3fArray, "vertex").Set(colours)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        UsdSceneDelegate(stage, fake).sync()
    material = fake.meshes()["/World/Ball"]["material"]
    np.testing.assert_allclose(material["diffuseColor"], np.mean(colours, axis=0))
    named = _warnings(caplog, "primvars:tint, which varies over /World/Ball")
    assert len(named) == 1 and "/Looks/M/Tint" in named[0], caplog.text


_PI = math.pi


@pytest.mark.parametrize(
    ("op", "pre", "post", "truth"),
    [
        ("sin_float", (6.0, 0.0), (0.5, 0.5), np.sin),
        ("cos_float", (6.0, 0.0), (0.5, 0.5), np.cos),
        ("tan_float", (1.2, -0.6), (0.5, 0.5), np.tan),
        ("asin_float", (2.0, -1.0), (1 / _PI, 0.5), np.arcsin),
        ("acos_float", (2.0, -1.0), (1 / _PI, 0.0), np.arccos),
        ("exp_float", (-2.0, 0.0), (1.0, 0.0), np.exp),
        ("ln_float", (2.0, 0.1), (0.3, 0.7), np.log),
        ("sign_float", (1.0, -0.5), (0.25, 0.5), np.sign),
        ("atan2_float", (1.0, -0.5), (1 / _PI, 0.5), lambda y: np.arctan2(y, 0.25)),
        ("sin_vector3", (6.0, 0.0), (0.5, 0.5), np.sin),
        ("atan2_vector3", (1.0, -0.5), (1 / _PI, 0.5), lambda y: np.arctan2(y, 0.25)),
    ],
)
def test_math_nodes_of_a_ramp_are_glsls(native, tmp_path, op, pre, post, truth) -> None:
    # post · op(pre · s) per pixel, s from a ramp image: genglsl's mx_sin(in) … log(in),
    # sign(in), mx_atan(iny, inx) (inx 0.25), float and vector variants.
    ramp = (np.arange(64) + 0.5)[None, :] / 64 * np.ones((8, 1))
    stage = new_stage()
    image = node(
        stage, "Ramp", "ND_image_float", "float", file=write(native, tmp_path / "ramp.exr", ramp)
    )
    image.CreateInput("uaddressmode", Sdf.ValueTypeNames.String).Set("clamp")
    scaled = node(stage, "Pre", "ND_multiply_float", "float", in1=image, in2=("float", pre[0]))
    x = node(stage, "Pre2", "ND_add_float", "float", in1=scaled, in2=("float", pre[1]))
    name, kind = op.split("_")
    if kind == "vector3":
        x = node(stage, "AsVector", "ND_convert_float_vector3", "vector3", **{"in": x})
    if name == "atan2":
        inx = ("vector3", (0.25,) * 3) if kind == "vector3" else ("float", 0.25)
        y = node(stage, "Op", f"ND_{op}", kind, iny=x, inx=inx)
    else:
        y = node(stage, "Op", f"ND_{op}", kind, **{"in": x})
    colour = node(stage, "Colour", f"ND_convert_{kind}_color3", "color3", **{"in": y})
    k = node(stage, "Post", "ND_multiply_color3FA", "color3", in1=colour, in2=("float", post[0]))
    lambertian(
        stage, node(stage, "Post2", "ND_add_color3FA", "color3", in1=k, in2=("float", post[1]))
    )
    r = render(stage)
    s = r.st[..., 0]
    want = (post[0] * truth(pre[0] * s + pre[1]) + post[1])[..., None] * np.ones(3)
    inside = r.on & (s > 0.05) & (s < 0.95) & (np.abs(pre[0] * s + pre[1]) > 0.03)
    assert_albedo(r.albedo, np.clip(want, 0, 1), inside, atol=4e-3)


def test_math_nodes_of_constants_fold_as_glsl_computes_them(fake) -> None:
    # (sin 0.5, 0.25 · atan2(1, −1), sign(0)), folded to the constant diffuseColor.
    stage = new_stage()
    half = node(stage, "Half", "ND_constant_float", "float", value=("float", 0.5))
    sin = node(stage, "Sin", "ND_sin_float", "float", **{"in": half})
    at = node(stage, "At", "ND_atan2_float", "float", iny=("float", 1.0), inx=("float", -1.0))
    quarter = node(stage, "Quarter", "ND_multiply_float", "float", in1=at, in2=("float", 0.25))
    zero = node(stage, "Sign", "ND_sign_float", "float", **{"in": ("float", 0.0)})
    parts = {"in1": sin, "in2": quarter, "in3": zero}
    lambertian(stage, node(stage, "Rgb", "ND_combine3_color3", "color3", **parts))
    UsdSceneDelegate(stage, fake).sync()
    material = fake.meshes()["/World/Quad"]["material"]
    assert "networks" not in material
    np.testing.assert_allclose(
        material["diffuseColor"], (math.sin(0.5), 0.25 * math.atan2(1, -1), 0.0), rtol=1e-6
    )


_CUSTOM_DEFS = """<?xml version="1.0"?>
<materialx version="1.39" namespace="Test">
  <nodedef name="ND_tinted_image" node="tinted_image">
    <input name="file" type="filename" value="" />
    <input name="tint" type="color3" value="1, 1, 1" />
    <input name="scale" type="vector2" value="2, 2" />
    <output name="out" type="color3" />
  </nodedef>
  <nodegraph name="NG_tinted_image" nodedef="ND_tinted_image">
    <texcoord name="uv" type="vector2" />
    <multiply name="scaled" type="vector2">
      <input name="in1" type="vector2" nodename="uv" />
      <input name="in2" type="vector2" interfacename="scale" />
    </multiply>
    <image name="img" type="color3">
      <input name="file" type="filename" interfacename="file" />
      <input name="texcoord" type="vector2" nodename="scaled" />
    </image>
    <multiply name="tinted" type="color3">
      <input name="in1" type="color3" nodename="img" />
      <input name="in2" type="color3" interfacename="tint" />
    </multiply>
    <output name="out" type="color3" nodename="tinted" />
  </nodegraph>
</materialx>
"""

_CUSTOM_LOOKS = """<?xml version="1.0"?>
<materialx version="1.39">
  {include}
  <nodegraph name="G">
    <constant name="tint" type="color3">
      <input name="value" type="color3" value="0.5, 1, 0.75" />
    </constant>
    <tinted_image name="tex" type="color3" namespace="Test">
      <input name="file" type="filename" value="quadrants.exr" />
      <input name="tint" type="color3" nodename="tint" />
    </tinted_image>
    <multiply name="half" type="color3">
      <input name="in1" type="color3" nodename="tex" />
      <input name="in2" type="float" value="0.5" />
    </multiply>
    <output name="out" type="color3" nodename="half" />
  </nodegraph>
  <UsdPreviewSurface name="S" type="surfaceshader">
    <input name="diffuseColor" type="color3" nodegraph="G" output="out" />
    <input name="useSpecularWorkflow" type="integer" value="1" />
    <input name="specularColor" type="color3" value="0, 0, 0" />
  </UsdPreviewSurface>
  <surfacematerial name="M" type="material">
    <input name="surfaceshader" type="surfaceshader" nodename="S" />
  </surfacematerial>
</materialx>
"""


@pytest.mark.parametrize("found", ["included", "PXR_MTLX_PLUGIN_SEARCH_PATHS"])
def test_a_custom_nodedef_built_as_a_nodegraph_renders_as_its_graph(
    native, tmp_path, monkeypatch, caplog, found
) -> None:
    # A namespaced custom node (Test:ND_tinted_image: image(file, texcoord · scale) · tint) in
    # a referenced .mtlx, its nodedef included by the document or found where usdMtlx looks:
    # its file from the node, its tint from a node of the outer graph, its scale the
    # nodedef's default (2, 2); then halved downstream.
    pytest.importorskip("MaterialX")
    quadrant_image(native, tmp_path / "quadrants.exr")
    defs = tmp_path / "defs"
    defs.mkdir()
    (defs / "tinted.mtlx").write_text(_CUSTOM_DEFS)
    include = '<xi:include href="defs/tinted.mtlx" />' if found == "included" else ""
    if found != "included":
        monkeypatch.setenv("PXR_MTLX_PLUGIN_SEARCH_PATHS", str(defs))
    (tmp_path / "looks.mtlx").write_text(_CUSTOM_LOOKS.format(include=include))
    stage = new_stage()
    material = UsdShade.Material.Define(stage, "/Looks/M")
    material.GetPrim().GetReferences().AddReference(
        str(tmp_path / "looks.mtlx"), "/MaterialX/Materials/M"
    )
    bind(quad(stage, half=HALF).GetPrim(), material)
    add_camera(stage, "/World/Camera")
    add_distant_light(stage, "/World/Sun")
    with caplog.at_level(logging.WARNING):
        r = render(stage)
    assert not caplog.records, caplog.text
    truth, inside = quadrant_truth(2.0 * r.st)
    assert_albedo(r.albedo, truth * (0.5, 1.0, 0.75) * 0.5, r.on & inside)


def test_a_custom_nodedef_implemented_by_itself_is_named_once_and_the_frame_renders(
    fake, tmp_path, caplog
) -> None:
    pytest.importorskip("MaterialX")
    defs = _CUSTOM_DEFS.replace(
        '<texcoord name="uv" type="vector2" />',
        '<tinted_image name="again" type="color3" />\n    <texcoord name="uv" type="vector2" />',
    ).replace('interfacename="tint"', 'nodename="again"')
    (tmp_path / "defs.mtlx").write_text(defs)
    looks = _CUSTOM_LOOKS.format(include='<xi:include href="defs.mtlx" />')
    (tmp_path / "looks.mtlx").write_text(looks)
    stage = new_stage()
    material = UsdShade.Material.Define(stage, "/Looks/M")
    material.GetPrim().GetReferences().AddReference(
        str(tmp_path / "looks.mtlx"), "/MaterialX/Materials/M"
    )
    bind(quad(stage, half=HALF).GetPrim(), material)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        UsdSceneDelegate(stage, fake).sync()
    assert "diffuseColor" not in fake.meshes()["/World/Quad"]["material"]
    named = _warnings(caplog, "MaterialX node Test:ND_tinted_image")
    assert len(named) == 1, caplog.text


# --- position, normal and the stdlib's Perlin noise ---------------------------------------


def _moved_quad(stage: Usd.Stage) -> Gf.Matrix4d:
    """Moves the quad (translated, tilted, turned and shrunk) and returns its object-to-world
    matrix (USD's row vectors: p_world = p_object · M)."""
    prim = stage.GetPrimAtPath("/World/Quad")
    xf = UsdGeom.Xformable(prim)
    xf.AddTranslateOp().Set(Gf.Vec3d(0.3, -0.2, 0.4))
    xf.AddRotateXYZOp().Set(Gf.Vec3f(20.0, 0.0, 30.0))
    xf.AddScaleOp().Set(Gf.Vec3f(0.8, 0.8, 0.8))
    return xf.ComputeLocalToWorldTransform(Usd.TimeCode.Default())


def _positions(r: dict, m: Gf.Matrix4d) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's world and object-space hit point (from the ``position`` AOV)."""
    world = r["position"][..., :3].astype(np.float64)
    inv = np.array(m.GetInverse(), np.float64)
    obj = world @ inv[:3, :3] + inv[3, :3]
    return world, obj


def _as_colour(stage: Usd.Stage, v: UsdShade.Shader, kind: str) -> UsdShade.Shader:
    return node(stage, "Colour", f"ND_convert_{kind}_color3", "color3", **{"in": v})


@pytest.mark.parametrize("space", ["object", "world", "model", None])
def test_position_and_normal_are_the_hit_points_in_their_space(native, space) -> None:
    """``position · 0.25 + 0.5`` is the albedo, and ``normal · 0.5 + 0.5`` the albedo of a
    second render: the quad's own point and +Z in object space (the stdlib's default and
    ``model``), moved by its transform in world space."""
    for what in ("position", "normal"):
        stage = new_stage()
        kw = {} if space is None else {"space": space}
        geo = UsdShade.Shader.Define(stage, "/Looks/M/Geo")
        geo.CreateIdAttr(f"ND_{what}_vector3")
        geo.CreateOutput("out", TYPES["vector3"])
        for key, value in kw.items():
            geo.CreateInput(key, Sdf.ValueTypeNames.String).Set(value)
        k = 0.25 if what == "position" else 0.5
        scaled = node(stage, "Scale", "ND_multiply_vector3FA", "vector3", in1=geo, in2=("float", k))
        biased = node(stage, "Bias", "ND_add_vector3FA", "vector3", in1=scaled, in2=("float", 0.5))
        lambertian(stage, _as_colour(stage, biased, "vector3"))
        m = _moved_quad(stage)
        r = mipray.render(
            stage, width=WIDTH, aovs=("albedo", "position", "alpha"), settings={"samples": 1}
        ).aovs
        on = r["alpha"][..., 0] == 1.0
        world, obj = _positions(r, m)
        if what == "position":
            p = world if space == "world" else obj
        else:
            n_obj = np.array([0.0, 0.0, 1.0])
            n = n_obj @ np.array(m, np.float64)[:3, :3] if space == "world" else n_obj
            p = np.broadcast_to(n / np.linalg.norm(n), world.shape)
        truth = np.clip(p * k + 0.5, 0.0, 1.0)
        assert_albedo(r["albedo"][..., :3], truth, on, atol=1e-4)
        # Object and world space differ enough here for the test to tell them apart.
        other = obj if what == "position" else np.array([0.0, 0.0, 1.0])
        differ = np.abs(truth - np.clip(other * k + 0.5, 0.0, 1.0))[on]
        assert (differ.mean() > 0.05) == (space == "world")


def _bjfinal(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """mx_noise.glsl's mx_bjfinal, in uint32 (wrapping) arithmetic."""

    def rot(x, k):
        return (x << np.uint32(k)) | (x >> np.uint32(32 - k))

    with np.errstate(over="ignore"):
        for x, y, k in ((2, 1, 14), (0, 2, 11), (1, 0, 25), (2, 1, 16), (0, 2, 4), (1, 0, 14)):
            w = [a, b, c]
            w[x] = (w[x] ^ w[y]) - rot(w[y], k)
            a, b, c = w
        c = (c ^ b) - rot(b, 24)
    return c


def perlin3(p: np.ndarray) -> np.ndarray:
    """mx_perlin_noise_float(vec3) of mx_noise.glsl, written out again in numpy (float32)."""
    p = np.asarray(p, np.float32)
    i = np.floor(p).astype(np.int32)
    f = (p - i.astype(np.float32)).astype(np.float32)
    fade = f * f * f * (f * (f * np.float32(6) - np.float32(15)) + np.float32(10))
    seed = np.uint32(0xDEADBEEF + (3 << 2) + 13)
    corners = []
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                d = np.array([dx, dy, dz], np.int32)
                with np.errstate(over="ignore"):
                    h = (i + d).astype(np.uint32) + seed
                h = _bjfinal(h[..., 0], h[..., 1], h[..., 2]) & np.uint32(15)
                x, y, z = np.moveaxis(f - d.astype(np.float32), -1, 0)
                u = np.where(h < 8, x, y)
                v = np.where(h < 4, y, np.where((h == 12) | (h == 14), x, z))
                corners.append(np.where(h & 1, -u, u) + np.where(h & 2, -v, v))
    s, t, r = np.moveaxis(fade, -1, 0)
    one = np.float32(1)

    def lerp(a, b, w):
        return a * (one - w) + b * w

    g = corners
    x0 = (one - t) * lerp(g[0], g[1], s) + t * lerp(g[2], g[3], s)
    x1 = (one - t) * lerp(g[4], g[5], s) + t * lerp(g[6], g[7], s)
    return np.float32(0.982) * ((one - r) * x0 + r * x1)


def fractal3(p: np.ndarray, octaves: int, lacunarity: float, diminish: float) -> np.ndarray:
    """mx_fractal3d_noise_float in numpy."""
    p = np.asarray(p, np.float32)
    out, amp = np.zeros(p.shape[:-1], np.float32), np.float32(1)
    for _ in range(octaves):
        out += amp * perlin3(p)
        amp *= np.float32(diminish)
        p = p * np.float32(lacunarity)
    return out


def test_the_numpy_noise_is_zero_on_the_lattice_and_spans_about_minus_one_to_one() -> None:
    lattice = np.array([[0, 0, 0], [3, -2, 7], [-5, 11, -1]], np.float32)
    assert np.all(perlin3(lattice) == 0)
    rng = np.random.default_rng(1)
    v = perlin3(rng.uniform(-20, 20, (20000, 3)))
    assert -1.05 < v.min() < -0.6 and 0.6 < v.max() < 1.05 and abs(v.mean()) < 0.02


@pytest.mark.parametrize("kind", ["noise3d", "fractal3d"])
def test_noise3d_and_fractal3d_of_the_object_position_are_the_stdlibs(native, kind) -> None:
    """``noise3d`` (amplitude 0.5, pivot 0.5) and ``fractal3d`` (amplitude 0.4, 3 octaves,
    lacunarity 2.5, diminish 0.6; + 0.5 after) of ``position · 3`` match mx_noise.glsl's
    formulas evaluated again in numpy at each pixel's object-space point."""
    stage = new_stage()
    pos = node(stage, "Pos", "ND_position_vector3", "vector3")
    scaled = node(stage, "Scale", "ND_multiply_vector3FA", "vector3", in1=pos, in2=("float", 3.0))
    if kind == "noise3d":
        noise = node(
            stage, "Noise", "ND_noise3d_float", "float", position=scaled,
            amplitude=("float", 0.5), pivot=("float", 0.5),
        )  # fmt: skip
    else:
        fractal = node(
            stage, "Noise", "ND_fractal3d_float", "float", position=scaled,
            amplitude=("float", 0.4), octaves=("integer", 3), lacunarity=("float", 2.5),
            diminish=("float", 0.6),
        )  # fmt: skip
        noise = node(stage, "Bias", "ND_add_float", "float", in1=fractal, in2=("float", 0.5))
    lambertian(stage, _as_colour(stage, noise, "float"))
    m = _moved_quad(stage)
    r = mipray.render(
        stage, width=WIDTH, aovs=("albedo", "position", "alpha"), settings={"samples": 1}
    ).aovs
    on = r["alpha"][..., 0] == 1.0
    _, obj = _positions(r, m)
    p = (obj * 3.0).astype(np.float32)
    v = perlin3(p) * 0.5 + 0.5 if kind == "noise3d" else fractal3(p, 3, 2.5, 0.6) * 0.4 + 0.5
    truth = np.clip(v, 0, 1)[..., None] * np.ones(3)
    assert truth[on].std() > 0.05  # the noise varies over the quad
    assert_albedo(r["albedo"][..., :3], truth, on, atol=2e-3)


def test_noise_renders_the_same_bits_with_any_thread_count_and_cache_mode(native) -> None:
    stage = new_stage()
    pos = node(stage, "Pos", "ND_position_vector3", "vector3")
    scaled = node(stage, "Scale", "ND_multiply_vector3FA", "vector3", in1=pos, in2=("float", 4.0))
    noise = node(stage, "Noise", "ND_fractal3d_float", "float", position=scaled)
    lambertian(stage, _as_colour(stage, noise, "float"))
    assert_same_bits_across_threads_and_cache_modes(stage)


def test_a_vector_noise_is_named_once_and_the_input_keeps_its_default(fake, caplog) -> None:
    """The color3/vector noises hash per lane (mx_hash_vec3), which is not ported: named."""
    stage = new_stage()
    noise = node(stage, "Noise", "ND_noise3d_color3", "color3")
    lambertian(stage, noise)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    material = fake.meshes()["/World/Quad"]["material"]
    assert "networks" not in material and "diffuseColor" not in material
    named = _warnings(caplog, "ND_noise3d_color3")
    assert len(named) == 1 and "/Looks/M/Noise" in named[0], caplog.text
