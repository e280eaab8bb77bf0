"""UsdPreviewSurface inputs from USD to the renderer: constants, textures, bad input.

Reading (on the recording fake delegate): every input reaches ``set_mesh``'s
``material`` dict, constant or textured (with the connected output's channel);
unsupported nodes fall back to the input's fallback with one warning naming the
material and the node. Rendering (the compiled module): a textured input renders
exactly as the same value given as a constant, on the part of the surface where
the texture has that value; out-of-range inputs are clamped with one warning
naming the material; extreme inputs never make a NaN.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

import mipray
from mipray.usd.scene_delegate import UsdSceneDelegate
from mipray.usd.shading import COLOR_INPUTS, FLOAT_INPUTS

from fake_delegate import display_color
from stages import add_camera, bind, new_stage

# ----------------------------------------------------------------------------- helpers


def quad(
    stage: Usd.Stage, path: str = "/World/Quad", half: float = 1.0, z: float = 0.0
) -> UsdGeom.Mesh:
    """A square facing +Z (toward the default camera) with st over [0, 1]²."""
    mesh = UsdGeom.Mesh.Define(stage, path)
    h = half
    mesh.CreatePointsAttr([(-h, -h, z), (h, -h, z), (h, h, z), (-h, h, z)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    mesh.CreateSubdivisionSchemeAttr("none")
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
    )
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    return mesh


def surface(
    stage: Usd.Stage, path: str, **inputs: object
) -> tuple[UsdShade.Material, UsdShade.Shader]:
    """A material at ``path`` whose surface is a UsdPreviewSurface with constant ``inputs``."""
    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    for name, value in inputs.items():
        set_input(shader, name, value)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material, shader


def set_input(shader: UsdShade.Shader, name: str, value: object) -> None:
    if name in COLOR_INPUTS:
        shader.CreateInput(name, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*value))  # type: ignore[misc]
    elif name == "useSpecularWorkflow":
        shader.CreateInput(name, Sdf.ValueTypeNames.Int).Set(int(value))  # type: ignore[call-overload]
    else:
        shader.CreateInput(name, Sdf.ValueTypeNames.Float).Set(float(value))  # type: ignore[arg-type]


def texture(
    stage: Usd.Stage,
    material_path: str,
    shader: UsdShade.Shader,
    name: str,
    file: str | None,
    output: str = "rgb",
    varname: str = "st",
    **inputs: object,
) -> UsdShade.Shader:
    """A UsdUVTexture (reading primvar ``varname``) feeding ``shader``'s input ``name``."""
    tex = UsdShade.Shader.Define(stage, f"{material_path}/{name}Texture")
    tex.CreateIdAttr("UsdUVTexture")
    if file is not None:
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(file)
    for key, value in inputs.items():
        if key in ("wrapS", "wrapT"):
            tex.CreateInput(key, Sdf.ValueTypeNames.Token).Set(value)
        else:
            tex.CreateInput(key, Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*value))  # type: ignore[misc]
    reader = UsdShade.Shader.Define(stage, f"{material_path}/{name}Reader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set(varname)
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    )
    kind = Sdf.ValueTypeNames.Float3 if output == "rgb" else Sdf.ValueTypeNames.Float
    out = tex.CreateOutput(output, kind)
    in_type = (
        Sdf.ValueTypeNames.Color3f
        if name in COLOR_INPUTS
        else Sdf.ValueTypeNames.Normal3f
        if name == "normal"
        else Sdf.ValueTypeNames.Float
    )
    shader.CreateInput(name, in_type).ConnectToSource(out)
    return tex


def read(stage: Usd.Stage, fake, path: str = "/World/Quad") -> dict:
    UsdSceneDelegate(stage, fake).sync()
    return fake.meshes()[path]


def scene(half: float = 1.0, **inputs: object) -> tuple[Usd.Stage, UsdShade.Shader]:
    """A quad of half-size ``half`` bound to a material with ``inputs``, a camera at z = 10."""
    stage = new_stage()
    mesh = quad(stage, half=half)
    material, shader = surface(stage, "/World/Looks/M", **inputs)
    bind(mesh.GetPrim(), material)
    add_camera(stage, "/World/Camera")
    return stage, shader


def warnings_naming(caplog, *words: str) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.levelno >= logging.WARNING and all(w in r.getMessage() for w in words)
    ]


# ----------------------------------------------------------------------------- reading


ALL_CONSTANTS: dict[str, object] = {
    "diffuseColor": (0.1, 0.2, 0.3),
    "emissiveColor": (0.4, 0.5, 0.6),
    "useSpecularWorkflow": 1,
    "specularColor": (0.7, 0.8, 0.9),
    "metallic": 0.25,
    "roughness": 0.35,
    "clearcoat": 0.45,
    "clearcoatRoughness": 0.55,
    "opacity": 0.65,
    "opacityThreshold": 0.15,
    "ior": 1.33,
}


def test_every_constant_input_reaches_set_mesh(fake) -> None:
    stage, _ = scene(**ALL_CONSTANTS)
    material = read(stage, fake)["material"]
    assert material["name"] == "/World/Looks/M"
    for name, value in ALL_CONSTANTS.items():
        if name == "useSpecularWorkflow":
            assert material[name] is True
        else:
            assert material[name] == pytest.approx(value, abs=1e-6), name
    assert "textures" not in material


def test_unauthored_inputs_are_left_to_the_fallbacks(fake) -> None:
    stage, _ = scene(roughness=0.2)
    material = read(stage, fake)["material"]
    assert set(material) == {"name", "roughness"}


def test_a_constant_through_a_material_interface_input(fake) -> None:
    stage, shader = scene()
    material = UsdShade.Material(stage.GetPrimAtPath("/World/Looks/M"))
    knob = material.CreateInput("shine", Sdf.ValueTypeNames.Float)
    knob.Set(0.8)
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).ConnectToSource(knob)
    assert read(stage, fake)["material"]["metallic"] == pytest.approx(0.8)


def test_metal_is_sent_as_it_is_not_as_a_mirror(fake, caplog) -> None:
    stage, _ = scene(metallic=1.0, roughness=0.0, diffuseColor=(0.9, 0.6, 0.2))
    with caplog.at_level(logging.WARNING):
        args = read(stage, fake)
    assert "mirror" not in args  # no mirror shortcut: set_mesh has one material model
    assert args["material"]["metallic"] == 1.0 and args["material"]["roughness"] == 0.0
    assert not warnings_naming(caplog, "rough")


@pytest.mark.parametrize(
    ("name", "output", "channel"),
    [(n, "rgb", 0) for n in COLOR_INPUTS]
    + [
        (n, out, c)
        for n, (out, c) in zip(
            [n for n in FLOAT_INPUTS if n != "opacityThreshold"],
            [("r", 0), ("g", 1), ("b", 2), ("a", 3), ("r", 0), ("g", 1)],
            strict=True,
        )
    ]
    + [("normal", "rgb", 0)],
)
def test_each_textured_input_reaches_set_mesh_with_its_channel(fake, name, output, channel) -> None:
    stage, shader = scene()
    texture(
        stage,
        "/World/Looks/M",
        shader,
        name,
        "maps/x.exr",
        output,
        scale=(2.0, 3.0, 4.0, 5.0),
        bias=(-1.0, -0.5, 0.0, 0.5),
        fallback=(0.1, 0.2, 0.3, 0.4),
    )
    args = read(stage, fake)
    tex = args["material"]["textures"][name]
    assert tex["file"].endswith("x.exr")
    assert tex["channel"] == channel
    assert tex["scale"] == [2.0, 3.0, 4.0, 5.0] and tex["bias"] == [-1.0, -0.5, 0.0, 0.5]
    assert tex["fallback"] == pytest.approx([0.1, 0.2, 0.3, 0.4])
    assert name not in args["material"]  # a textured input has no constant
    assert args["st_values"].shape == (4, 2)


def test_a_texture_without_a_file_is_its_fallback(fake, caplog) -> None:
    stage, shader = scene()
    texture(stage, "/World/Looks/M", shader, "roughness", None, "g", fallback=(0.1, 0.7, 0.3, 1.0))
    with caplog.at_level(logging.WARNING):
        material = read(stage, fake)["material"]
    assert material["roughness"] == pytest.approx(0.7)
    assert "textures" not in material
    assert warnings_naming(caplog, "/World/Looks/M", "no file")


def test_an_unsupported_node_falls_back_with_one_warning(fake, caplog) -> None:
    stage, shader = scene(roughness=0.9)
    node = UsdShade.Shader.Define(stage, "/World/Looks/M/Noise")
    node.CreateIdAttr("ND_noise3d_float")
    shader.GetInput("roughness").ConnectToSource(node.CreateOutput("out", Sdf.ValueTypeNames.Float))
    with caplog.at_level(logging.WARNING):
        material = read(stage, fake)["material"]
        read(stage, fake)  # a second sync does not warn again
    assert material["roughness"] == 0.5  # UsdPreviewSurface's fallback, not the disconnected 0.9
    said = warnings_naming(caplog, "/World/Looks/M", "/World/Looks/M/Noise", "roughness")
    assert len(said) == 1, said


def test_an_unsupported_node_feeding_st_reads_st_with_one_warning(fake, caplog) -> None:
    stage, shader = scene()
    tex = texture(stage, "/World/Looks/M", shader, "roughness", "r.exr", "r")
    node = UsdShade.Shader.Define(stage, "/World/Looks/M/Swizzle")
    node.CreateIdAttr("ND_swizzle_vector2")
    tex.GetInput("st").ConnectToSource(node.CreateOutput("out", Sdf.ValueTypeNames.Float2))
    with caplog.at_level(logging.WARNING):
        args = read(stage, fake)
    assert "roughness" in args["material"]["textures"]
    assert args["st_values"][2] == pytest.approx((1, 1))
    assert len(warnings_naming(caplog, "/World/Looks/M", "/World/Looks/M/Swizzle", "st")) == 1


def test_a_primvar_reader_reads_the_mesh(fake, caplog) -> None:
    stage, shader = scene()
    mesh = stage.GetPrimAtPath("/World/Quad")
    pv = UsdGeom.PrimvarsAPI(mesh)
    pv.CreatePrimvar("wet", Sdf.ValueTypeNames.Float, UsdGeom.Tokens.constant).Set(0.3)
    pv.CreatePrimvar("tint", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex).Set(
        [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    )
    for name, varname, kind, node in (
        ("roughness", "wet", Sdf.ValueTypeNames.Float, "UsdPrimvarReader_float"),
        ("emissiveColor", "tint", Sdf.ValueTypeNames.Color3f, "UsdPrimvarReader_float3"),
    ):
        reader = UsdShade.Shader.Define(stage, f"/World/Looks/M/{varname}")
        reader.CreateIdAttr(node)
        reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set(varname)
        shader.CreateInput(name, kind).ConnectToSource(reader.CreateOutput("result", kind))
    with caplog.at_level(logging.WARNING):
        args = read(stage, fake)
    material = args["material"]
    assert material["roughness"] == pytest.approx(0.3)
    # The mean stands where the primvar cannot be evaluated; the primvar itself crosses to be
    # interpolated as authored (issue 18: it used to be the mean everywhere, with a warning).
    assert material["emissiveColor"] == pytest.approx((0.5, 0.5, 0.0))
    tint = args["primvars"]["emissiveColor"]
    assert tint["interpolation"] == "vertex"
    np.testing.assert_array_equal(tint["values"], [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])
    assert "roughness" not in args["primvars"]  # a constant primvar is its value
    assert warnings_naming(caplog, "/World/Looks/M", "primvars:tint") == []


def test_textures_reading_different_primvars_use_the_first_with_one_warning(fake, caplog) -> None:
    stage, shader = scene()
    mesh = stage.GetPrimAtPath("/World/Quad")
    UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "uv2", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
    ).Set([(5, 5), (6, 5), (6, 6), (5, 6)])
    texture(stage, "/World/Looks/M", shader, "diffuseColor", "a.exr")
    texture(stage, "/World/Looks/M", shader, "roughness", "b.exr", "r", varname="uv2")
    with caplog.at_level(logging.WARNING):
        args = read(stage, fake)
        read(stage, fake)
    assert set(args["material"]["textures"]) == {"diffuseColor", "roughness"}
    assert args["st_values"][0] == pytest.approx((0, 0))  # diffuseColor's st, not uv2
    said = warnings_naming(caplog, "/World/Quad", "primvars:uv2", "primvars:st")
    assert len(said) == 1, said


def test_a_surface_that_is_not_a_preview_surface_renders_display_color(fake, caplog) -> None:
    stage = new_stage()
    mesh = quad(stage)
    mesh.CreateDisplayColorAttr([(0.2, 0.4, 0.6)])
    material = UsdShade.Material.Define(stage, "/World/Looks/X")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/X/Std")
    shader.CreateIdAttr("ND_standard_surface_surfaceshader")
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    bind(mesh.GetPrim(), material)
    with caplog.at_level(logging.WARNING):
        args = read(stage, fake)
    assert display_color(args, "/World/Quad") == pytest.approx((0.2, 0.4, 0.6))
    assert warnings_naming(caplog, "/World/Looks/X", "not a UsdPreviewSurface")


def test_an_animated_input_is_read_at_each_time(fake) -> None:
    stage, shader = scene()
    rough = shader.CreateInput("roughness", Sdf.ValueTypeNames.Float)
    rough.Set(0.1, 1.0)
    rough.Set(0.9, 2.0)
    delegate = UsdSceneDelegate(stage, fake, time=1.0)
    delegate.sync()
    assert fake.meshes()["/World/Quad"]["material"]["roughness"] == pytest.approx(0.1)
    delegate.set_time(2.0)
    delegate.sync()
    assert fake.meshes()["/World/Quad"]["material"]["roughness"] == pytest.approx(0.9)


def test_a_bad_material_dict_is_an_error_naming_the_prim(native) -> None:
    delegate = native.RenderDelegate()
    quad_args = {
        "points": np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32),
        "face_vertex_counts": np.array([4], np.int32),
        "face_vertex_indices": np.array([0, 1, 2, 3], np.int32),
        "transform": np.eye(4),
        "scheme": "none",
    }
    for material, words in (
        ({"rougness": 0.5}, "rougness"),
        ({"roughness": "shiny"}, "roughness"),
        ({"diffuseColor": (1.0, 0.5)}, "diffuseColor"),
        ({"textures": {"displacement": {"file": "x.exr"}}}, "displacement"),
        ({"textures": {"roughness": {"file": "x.exr", "channel": 7}}}, "channel"),
    ):
        with pytest.raises(ValueError, match=rf"/World/Bad: .*{words}"):
            delegate.set_mesh("/World/Bad", material=material, **quad_args)
    delegate.set_mesh(
        "/World/Good", material={"roughness": 0.5, "useSpecularWorkflow": 1}, **quad_args
    )


# ----------------------------------------------------------------------------- rendering


def render(stage: Usd.Stage, width: int = 24, **settings: object) -> np.ndarray:
    with mipray.RenderSession(stage) as session:
        result = session.render("/World/Camera", width=width, settings=settings, camera_light=False)
    return result.aovs["color"][..., :3]


def light(stage: Usd.Stage, intensity: float = 3.0) -> None:
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(intensity)
    sun.CreateAngleAttr(0.0)
    sun.AddRotateXOp().Set(-20.0)
    sun.AddRotateYOp().Set(15.0)


def write_map(native, path, values: np.ndarray) -> str:
    """An H×W×3 float EXR (scanline; OpenImageIO's TextureSystem reads it untiled)."""
    native.write_image(
        str(path),
        {"color": np.ascontiguousarray(values, dtype=np.float32)},
        ["color"],
        {"color": "float"},
    )
    return str(path)


def test_an_emissive_quad_shows_its_emissive_color(native) -> None:
    # No light: the quad's radiance is its emission alone.
    stage, _ = scene(
        diffuseColor=(0.0, 0.0, 0.0), emissiveColor=(0.2, 0.5, 0.8), useSpecularWorkflow=1
    )
    image = render(stage)
    h, w = image.shape[:2]
    assert image[h // 2, w // 2] == pytest.approx((0.2, 0.5, 0.8), abs=1e-5)


def test_clamping_warns_once_naming_the_material(native, caplog) -> None:
    # One material on two meshes, rendered three times: one warning, naming every bad input.
    stage, _ = scene(diffuseColor=(-1.0, 2.0, 0.5), roughness=1.5, ior=-1.0)
    other = quad(stage, "/World/Other", half=0.5, z=0.5)
    bind(other.GetPrim(), UsdShade.Material(stage.GetPrimAtPath("/World/Looks/M")))
    light(stage)
    with caplog.at_level(logging.WARNING), mipray.RenderSession(stage) as session:
        images = [
            session.render("/World/Camera", width=16, camera_light=False).aovs["color"]
            for _ in range(3)
        ]
    said = warnings_naming(caplog, "/World/Looks/M", "clamped")
    assert len(said) == 1, said
    for name in ("diffuseColor", "roughness", "ior"):
        assert name in said[0], said[0]
    assert not warnings_naming(caplog, "metallic")
    assert np.isfinite(images[0]).all() and np.array_equal(images[0], images[2])


def test_clamped_inputs_render_as_their_clamped_values(native) -> None:
    bad, _ = scene(diffuseColor=(-1.0, 2.0, 0.5), useSpecularWorkflow=1)
    good, _ = scene(diffuseColor=(0.0, 1.0, 0.5), useSpecularWorkflow=1)
    light(bad)
    light(good)
    assert np.array_equal(render(bad), render(good))


HALF = 1.6  # the textured quad's half-size

HALVES = {
    # input: (value on the left half, value on the right half, constants that make it show)
    "diffuseColor": ((0.8, 0.2, 0.1), (0.1, 0.3, 0.9), {"useSpecularWorkflow": 1}),
    "emissiveColor": (
        (0.5, 0.1, 0.0),
        (0.0, 0.2, 0.6),
        {"diffuseColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 1},
    ),
    "specularColor": (
        (0.9, 0.9, 0.9),
        (0.05, 0.05, 0.05),
        {"useSpecularWorkflow": 1, "roughness": 0.3, "diffuseColor": (0.1, 0.1, 0.1)},
    ),
    "metallic": (1.0, 0.0, {"roughness": 0.3, "diffuseColor": (0.9, 0.6, 0.2)}),
    "roughness": (0.15, 0.8, {"metallic": 1.0, "diffuseColor": (0.9, 0.9, 0.9)}),
    "clearcoat": (1.0, 0.0, {"clearcoatRoughness": 0.5, "diffuseColor": (0.0, 0.0, 0.0)}),
    "opacity": (1.0, 0.0, {"diffuseColor": (0.8, 0.8, 0.8)}),
}


@pytest.mark.parametrize("name", list(HALVES))
def test_a_textured_input_renders_as_the_constant_where_the_texture_has_that_value(
    native, tmp_path, name
) -> None:
    left, right, others = HALVES[name]
    # A 16×16 texel map: left half `left`, right half `right` (rows are all the same).
    color = name in COLOR_INPUTS
    lv = np.array(left if color else [left, 0.0, 0.0], dtype=np.float32)
    rv = np.array(right if color else [right, 0.0, 0.0], dtype=np.float32)
    texels = np.zeros((16, 16, 3), np.float32)
    texels[:, :8], texels[:, 8:] = lv, rv
    file = write_map(native, tmp_path / f"{name}.exr", texels)

    def stage_with(value: object | None) -> Usd.Stage:
        stage, shader = scene(half=HALF, **others)
        backdrop = quad(stage, "/World/Backdrop", half=3.0, z=-1.0)
        bmat, _ = surface(
            stage, "/World/Looks/Backdrop", diffuseColor=(0.9, 0.9, 0.9), useSpecularWorkflow=1
        )
        bind(backdrop.GetPrim(), bmat)
        light(stage)
        if value is None:
            texture(
                stage,
                "/World/Looks/M",
                shader,
                name,
                file,
                "rgb" if color else "r",
                wrapS="clamp",
                wrapT="clamp",
            )
        else:
            set_input(shader, name, value)
        return stage

    width = 32
    textured = render(stage_with(None), width=width, samples=4)
    lo, hi = (
        render(stage_with(left), width=width, samples=4),
        render(stage_with(right), width=width, samples=4),
    )
    h, w = textured.shape[:2]
    # Where s is in [0.05, 0.2] every texel a (bicubic, clamped) lookup reads is the left value,
    # in [0.8, 0.95] the right one (the halves meet at s = 0.5). The default camera sees
    # ±2.0955 units at the quad's distance (aperture 20.955 mm, focal length 50 mm, 10 units).
    half_px = HALF / 2.0955 * (w / 2)

    def columns(s0: float, s1: float) -> slice:
        px = lambda s: w / 2 - half_px + s * 2 * half_px  # noqa: E731
        return slice(math.ceil(px(s0)), math.floor(px(s1)))

    rows = slice(h // 2 - 3, h // 2 + 3)
    left_cols, right_cols = columns(0.05, 0.2), columns(0.8, 0.95)
    assert left_cols.stop > left_cols.start and right_cols.stop > right_cols.start
    np.testing.assert_allclose(textured[rows, left_cols], lo[rows, left_cols], atol=1e-3, rtol=1e-3)
    np.testing.assert_allclose(
        textured[rows, right_cols], hi[rows, right_cols], atol=1e-3, rtol=1e-3
    )
    # And the two constants do look different there: the input matters.
    assert np.abs(lo[rows, left_cols] - hi[rows, left_cols]).max() > 0.02


def test_an_unreadable_texture_renders_its_fallback_with_one_warning(native, caplog) -> None:
    stage, shader = scene(useSpecularWorkflow=1)
    light(stage)
    texture(
        stage,
        "/World/Looks/M",
        shader,
        "diffuseColor",
        "/no/such/map.exr",
        fallback=(0.3, 0.6, 0.1, 1.0),
    )
    with caplog.at_level(logging.WARNING):
        image = render(stage)
    said = warnings_naming(caplog, "/World/Quad", "/no/such/map.exr")
    assert len(said) == 1, said
    ref, _ = scene(useSpecularWorkflow=1, diffuseColor=(0.3, 0.6, 0.1))
    light(ref)
    np.testing.assert_allclose(image, render(ref), atol=1e-6)


EXTREMES: list[dict[str, object]] = [
    {"roughness": 0.0, "metallic": 1.0},
    {"roughness": 1.0, "metallic": 1.0, "clearcoat": 1.0, "clearcoatRoughness": 0.0},
    {"opacity": 0.0, "ior": 1.0, "roughness": 0.0},
    {"opacity": 0.0, "ior": 1e-6, "roughness": 0.0},
    {"opacity": 0.0, "ior": 100.0, "roughness": 1.0},
    {"opacity": 0.3, "opacityThreshold": 0.5},
    {"opacity": 0.5, "roughness": 1e-7},
    {"emissiveColor": (1e30, 1e30, 1e30)},
    {"diffuseColor": (math.nan, 1.0, math.inf), "roughness": math.nan, "ior": math.nan},
    {
        "useSpecularWorkflow": 1,
        "specularColor": (1.0, 1.0, 1.0),
        "roughness": 0.0,
        "diffuseColor": (1, 1, 1),
    },
    {"ior": 0.0, "roughness": -3.0, "metallic": 7.0, "clearcoat": -1.0},
]


@pytest.mark.parametrize("integrator", ["auto", "path"])
def test_extreme_inputs_never_make_a_nan(native, integrator) -> None:
    stage = new_stage()
    add_camera(stage, "/World/Camera", eye=(0, 0, 12))
    light(stage)
    UsdLux.SphereLight.Define(stage, "/World/Bulb").AddTranslateOp().Set(Gf.Vec3d(0, 3, 4))
    for i, inputs in enumerate(EXTREMES):
        # Overlapping quads at different depths, so rays cross several of them.
        x, y = (i % 4) - 1.5, (i // 4) - 1.0
        mesh = quad(stage, f"/World/Q{i}", half=0.9, z=-0.3 * (i % 3))
        mesh.AddTranslateOp().Set(Gf.Vec3d(x * 1.2, y * 1.2, 0))
        material, _ = surface(stage, f"/World/Looks/X{i}", **inputs)
        bind(mesh.GetPrim(), material)
    back = quad(stage, "/World/Back", half=6.0, z=-2.0)
    bind(back.GetPrim(), surface(stage, "/World/Looks/Back", diffuseColor=(0.5, 0.5, 0.5))[0])
    image = render(stage, width=32, samples=4, integrator=integrator, maxDepth=6)
    assert np.isfinite(image).all()
    assert image.max() > 0.0


@pytest.mark.parametrize("degrees", [0.0, 60.0])
def test_a_normal_map_tilts_the_shading_normal_by_its_angle(native, tmp_path, degrees) -> None:
    # A lambertian quad facing a distant light of irradiance π along its normal: radiance
    # ρ E cos θ / π = ρ cos θ, where θ is the angle the normal map tilts the normal by. The map
    # holds the tangent-space normal (sin θ, 0, cos θ) encoded as n / 2 + 1 / 2, decoded by
    # UsdUVTexture's scale 2 and bias -1 (the (dP/du, dP/dv, N) frame: dP/du is +X here).
    t = math.radians(degrees)
    n = np.array([math.sin(t), 0.0, math.cos(t)], np.float32)
    file = write_map(native, tmp_path / "normal.exr", np.tile(n * 0.5 + 0.5, (8, 8, 1)))
    stage, shader = scene(half=1.6, diffuseColor=(0.5, 0.5, 0.5), useSpecularWorkflow=1)
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(math.pi)
    sun.CreateAngleAttr(0.0)
    texture(
        stage, "/World/Looks/M", shader, "normal", file, scale=(2, 2, 2, 1), bias=(-1, -1, -1, 0)
    )
    image = render(stage, width=16)
    h, w = image.shape[:2]
    centre = image[h // 2 - 2 : h // 2 + 2, w // 2 - 2 : w // 2 + 2]
    np.testing.assert_allclose(centre, 0.5 * math.cos(t), atol=2e-3)


def test_a_cut_out_card_casts_a_shadow_only_where_its_opacity_mask_leaves_a_leaf(
    native, tmp_path
) -> None:
    # A UsdUVTexture opacity mask under opacityThreshold 0.5: the card's left half (s < 0.5,
    # opacity 0.2) is cut out, its right half (0.9) a surface. A sun of irradiance π travelling
    # along (-1, 0, -1)/√2 casts the card (x in [3, 5], 2 above the ground) onto x in [1, 3]:
    # under the cut-out half (x < 2) the lambertian ground (ρ = 0.5) has its unshadowed
    # radiance ρ/π · π · cos 45°, under the leaf (x > 2) none. A long lens at x = 2 frames the
    # ground x in [0.95, 3.05] and never sees the card.
    texels = np.zeros((16, 16, 3), np.float32)
    texels[:, :8, 0], texels[:, 8:, 0] = 0.2, 0.9
    mask = write_map(native, tmp_path / "leaf_mask.exr", texels)
    stage = new_stage()
    camera = add_camera(stage, "/World/Camera", eye=(2, 0, 10))
    camera.CreateFocalLengthAttr(100.0)
    ground = quad(stage, "/World/Ground", half=6.0)
    bind(
        ground.GetPrim(),
        surface(stage, "/World/Looks/Ground", diffuseColor=(0.5,) * 3, useSpecularWorkflow=1)[0],
    )
    card = quad(stage, "/World/Card", half=1.0, z=2.0)
    card.AddTranslateOp().Set(Gf.Vec3d(4, 0, 0))
    leaf, shader = surface(stage, "/World/Looks/Leaf", useSpecularWorkflow=1, opacityThreshold=0.5)
    texture(stage, "/World/Looks/Leaf", shader, "opacity", mask, "r", wrapS="clamp", wrapT="clamp")
    bind(card.GetPrim(), leaf)
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(math.pi)
    sun.CreateAngleAttr(0.0)
    sun.AddRotateYOp().Set(45.0)
    image = render(stage, width=32)[..., 0]
    h = image.shape[0]
    rows = slice(h // 4, 3 * h // 4)
    lit = 0.5 * math.cos(math.radians(45.0))
    np.testing.assert_allclose(image[rows, 2:15], lit, atol=1e-3)
    np.testing.assert_array_equal(image[rows, 17:30], 0.0)
    # The same card with no threshold: opacity 0.2–0.9 is glass there, which shadow rays do not
    # pass (a classic ray tracer's glass), so all of x in [1, 3] is in shadow.
    shader.GetInput("opacityThreshold").Set(0.0)
    np.testing.assert_array_equal(render(stage, width=32)[..., 0][rows, 2:30], 0.0)
