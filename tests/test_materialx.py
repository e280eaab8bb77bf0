"""Inline MaterialX networks (``outputs:mtlx:surface``) mapped onto the UsdPreviewSurface BSDF
(docs/materials.md): each checked against the UsdPreviewSurface the mapping says it is."""

from __future__ import annotations

import logging
import shutil
import subprocess

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

import mipray
from mipray.usd import UsdSceneDelegate

from stages import add_camera, add_cube, add_distant_light, add_preview_material, bind

F, C3, F2 = Sdf.ValueTypeNames.Float, Sdf.ValueTypeNames.Color3f, Sdf.ValueTypeNames.Float2


def new_stage() -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    return stage


def node(stage: Usd.Stage, path: str, node_id: str, out=C3) -> UsdShade.Shader:
    shader = UsdShade.Shader.Define(stage, path)
    shader.CreateIdAttr(node_id)
    shader.CreateOutput("out", out)
    return shader


def mtlx_material(stage: Usd.Stage, path: str, surface_id: str, **inputs) -> UsdShade.Shader:
    material = UsdShade.Material.Define(stage, path)
    surface = node(stage, f"{path}/Surface", surface_id, Sdf.ValueTypeNames.Token)
    material.CreateSurfaceOutput("mtlx").ConnectToSource(surface.ConnectableAPI(), "out")
    for name, value in inputs.items():
        kind = C3 if isinstance(value, tuple) else F
        surface.CreateInput(name, kind).Set(Gf.Vec3f(*value) if kind == C3 else value)
    return surface


def quad(stage: Usd.Stage) -> UsdGeom.Mesh:
    points = [(-0.5, -0.5, 0.0), (0.5, -0.5, 0.0), (0.5, 0.5, 0.0), (-0.5, 0.5, 0.0)]
    mesh = add_cube(stage, "/World/Quad", points=points, counts=[4], indices=[0, 1, 2, 3])
    mesh.CreateSubdivisionSchemeAttr("none")
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
        "uv", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    st.Set(Vt.Vec2fArray([Gf.Vec2f(p[0] + 0.5, p[1] + 0.5) for p in points]))
    return mesh


def sent_material(stage: Usd.Stage, fake) -> dict:
    UsdSceneDelegate(stage, fake).sync()
    return fake.meshes()["/World/Quad"]["material"]


def test_standard_surface_maps_onto_the_preview_inputs(fake) -> None:
    stage = new_stage()
    mtlx_material(
        stage, "/Looks/M", "ND_standard_surface_surfaceshader",
        base=0.5, base_color=(0.8, 0.4, 0.2), metalness=0.25, specular_roughness=0.3,
        specular_IOR=1.4, coat=0.5, coat_roughness=0.2, emission=2.0,
        emission_color=(1.0, 0.5, 0.0),
    )  # fmt: skip
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    m = sent_material(stage, fake)
    assert m["diffuseColor"] == pytest.approx((0.4, 0.2, 0.1))
    assert m["emissiveColor"] == pytest.approx((2.0, 1.0, 0.0))
    for key, want in (("metallic", 0.25), ("roughness", 0.3), ("ior", 1.4), ("clearcoat", 0.5)):
        assert m[key] == pytest.approx(want), key
    assert m["clearcoatRoughness"] == pytest.approx(0.2)


def test_open_pbr_maps_onto_the_preview_inputs_with_its_defaults(fake) -> None:
    stage = new_stage()
    mtlx_material(
        stage, "/Looks/M", "ND_open_pbr_surface_surfaceshader",
        base_metalness=1.0, transmission_weight=0.0,
    )  # fmt: skip
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    m = sent_material(stage, fake)
    # OpenPBR's defaults: base 0.8 grey at weight 1, specular roughness 0.3.
    assert m["diffuseColor"] == pytest.approx((0.8, 0.8, 0.8))
    assert m["roughness"] == pytest.approx(0.3) and m["metallic"] == 1.0
    assert "opacity" not in m


def _image_network(stage: Usd.Stage, file: str, tint: tuple[float, float, float]) -> None:
    surface = mtlx_material(stage, "/Looks/M", "ND_standard_surface_surfaceshader", base=1.0)
    coord = node(stage, "/Looks/M/Coord", "ND_geompropvalue_vector2", F2)
    coord.CreateInput("geomprop", Sdf.ValueTypeNames.String).Set("uv")
    image = node(stage, "/Looks/M/Image", "ND_image_color3")
    file_input = image.CreateInput("file", Sdf.ValueTypeNames.Asset)
    file_input.Set(file)
    file_input.GetAttr().SetColorSpace("srgb_texture")
    image.CreateInput("texcoord", F2).ConnectToSource(coord.ConnectableAPI(), "out")
    for axis in ("uaddressmode", "vaddressmode"):
        image.CreateInput(axis, Sdf.ValueTypeNames.String).Set("clamp")
    tinted = node(stage, "/Looks/M/Tint", "ND_multiply_color3")
    tinted.CreateInput("in1", C3).ConnectToSource(image.ConnectableAPI(), "out")
    tinted.CreateInput("in2", C3).Set(Gf.Vec3f(*tint))
    surface.CreateInput("base_color", C3).ConnectToSource(tinted.ConnectableAPI(), "out")


def test_an_image_times_a_constant_is_a_texture_with_that_scale(fake, tmp_path) -> None:
    stage = new_stage()
    _image_network(stage, str(tmp_path / "wood.png"), (0.5, 1.0, 0.25))
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    UsdSceneDelegate(stage, fake).sync()
    args = fake.meshes()["/World/Quad"]
    tex = args["material"]["textures"]["diffuseColor"]
    assert tex["file"] == str(tmp_path / "wood.png")
    assert tex["scale"][:3] == pytest.approx([0.5, 1.0, 0.25])
    assert tex["bias"][:3] == pytest.approx([0.0, 0.0, 0.0])
    assert tex["sourceColorSpace"] == "sRGB" and tex["wrapS"] == "clamp"
    assert args["st_values"].shape == (4, 2)  # the uv primvar the geompropvalue names


def test_texcoord_constant_mix_arithmetic_and_dot_nodes_fold_into_the_textures_affine_map(
    fake, tmp_path, caplog
) -> None:
    # base_color = dot((d + (mix(fg = image(texcoord), bg = constant, mix = constant) − c)) / 2)
    # with MaterialX's mix = bg·(1 − w) + fg·w and dot a pass-through:
    # texel·w/2 + (bg·(1 − w) − c + d)/2, worked out by hand.
    stage = new_stage()
    surface = mtlx_material(stage, "/Looks/M", "ND_standard_surface_surfaceshader", base=1.0)
    coord = node(stage, "/Looks/M/Coord", "ND_texcoord_vector2", F2)
    image = node(stage, "/Looks/M/Image", "ND_image_color3")
    image.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(str(tmp_path / "wood.png"))
    image.CreateInput("texcoord", F2).ConnectToSource(coord.ConnectableAPI(), "out")
    bg = node(stage, "/Looks/M/Bg", "ND_constant_color3")
    bg.CreateInput("value", C3).Set(Gf.Vec3f(0.2, 0.4, 0.6))
    weight = node(stage, "/Looks/M/W", "ND_constant_float", F)
    weight.CreateInput("value", F).Set(0.25)
    mix = node(stage, "/Looks/M/Mix", "ND_mix_color3")
    mix.CreateInput("fg", C3).ConnectToSource(image.ConnectableAPI(), "out")
    mix.CreateInput("bg", C3).ConnectToSource(bg.ConnectableAPI(), "out")
    mix.CreateInput("mix", F).ConnectToSource(weight.ConnectableAPI(), "out")
    less = node(stage, "/Looks/M/Less", "ND_subtract_color3")
    less.CreateInput("in1", C3).ConnectToSource(mix.ConnectableAPI(), "out")
    less.CreateInput("in2", C3).Set(Gf.Vec3f(0.05, 0.1, 0.15))
    more = node(stage, "/Looks/M/More", "ND_add_color3")
    more.CreateInput("in1", C3).Set(Gf.Vec3f(0.01, 0.02, 0.03))
    more.CreateInput("in2", C3).ConnectToSource(less.ConnectableAPI(), "out")
    half = node(stage, "/Looks/M/Half", "ND_divide_color3")
    half.CreateInput("in1", C3).ConnectToSource(more.ConnectableAPI(), "out")
    half.CreateInput("in2", C3).Set(Gf.Vec3f(2.0, 2.0, 2.0))
    passed = node(stage, "/Looks/M/Dot", "ND_dot_color3")
    passed.CreateInput("in", C3).ConnectToSource(half.ConnectableAPI(), "out")
    surface.CreateInput("base_color", C3).ConnectToSource(passed.ConnectableAPI(), "out")
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        UsdSceneDelegate(stage, fake).sync()
    assert not [r for r in caplog.records if "MaterialX" in r.getMessage()], caplog.text
    tex = fake.meshes()["/World/Quad"]["material"]["textures"]["diffuseColor"]
    assert tex["file"] == str(tmp_path / "wood.png")
    # ÷ 2 (ND_divide), passed through by ND_dot.
    assert tex["scale"][:3] == pytest.approx([0.25 / 2] * 3)
    bg, less, more = (0.2, 0.4, 0.6), (0.05, 0.1, 0.15), (0.01, 0.02, 0.03)
    bias = [(b * 0.75 - c + d) / 2 for b, c, d in zip(bg, less, more, strict=True)]
    assert tex["bias"][:3] == pytest.approx(bias)


def _render(stage: Usd.Stage) -> np.ndarray:
    add_camera(stage, "/World/Cam", eye=(0, 0, 2))
    add_distant_light(stage, "/World/Sun")
    return mipray.render(stage, width=32, aovs=("color",)).aovs["color"]


def test_a_mtlx_image_network_renders_as_the_same_usd_uv_texture(native, tmp_path) -> None:
    tool = shutil.which("oiiotool")
    if tool is None:
        pytest.skip("oiiotool (openimageio-tools) is not installed")
    file = tmp_path / "checker.png"
    subprocess.run(
        [tool, "--pattern", "checker:width=4:height=4", "16x16", "3", "-d", "uint8", "-o",
         str(file)],
        check=True, capture_output=True,
    )  # fmt: skip
    stage = new_stage()
    _image_network(stage, str(file), (0.5, 1.0, 0.25))
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    got = _render(stage)
    # The same as UsdPreviewSurface: a UsdUVTexture with scale = the tint, MaterialX's
    # standard_surface defaults for the rest (specular roughness 0.2, coat roughness 0.1).
    stage = new_stage()
    preview = add_preview_material(stage, "/Looks/P", None)
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/P/PreviewSurface"))
    surface.CreateInput("roughness", F).Set(0.2)
    surface.CreateInput("clearcoatRoughness", F).Set(0.1)
    reader = node(stage, "/Looks/P/St", "UsdPrimvarReader_float2", F2)
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("uv")
    tex = node(stage, "/Looks/P/Tex", "UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(str(file))
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
    tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(0.5, 1.0, 0.25, 1.0))
    for wrap in ("wrapS", "wrapT"):
        tex.CreateInput(wrap, Sdf.ValueTypeNames.Token).Set("clamp")
    tex.CreateInput("st", F2).ConnectToSource(reader.ConnectableAPI(), "out")
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    surface.CreateInput("diffuseColor", C3).ConnectToSource(tex.ConnectableAPI(), "rgb")
    bind(quad(stage).GetPrim(), preview)
    want = _render(stage)
    assert got[..., 0].std() > 0.01  # the checker shows
    np.testing.assert_array_equal(got, want)


def test_a_preview_surface_node_renders_as_the_usd_preview_surface(native) -> None:
    stage = new_stage()
    mtlx_material(
        stage, "/Looks/M", "ND_UsdPreviewSurface_surfaceshader",
        diffuseColor=(0.2, 0.5, 0.7), metallic=0.3, roughness=0.4, clearcoat=0.2,
    )  # fmt: skip
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    got = _render(stage)
    stage = new_stage()
    preview = add_preview_material(stage, "/Looks/P", (0.2, 0.5, 0.7))
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/P/PreviewSurface"))
    for name, value in (("metallic", 0.3), ("roughness", 0.4), ("clearcoat", 0.2)):
        surface.CreateInput(name, F).Set(value)
    bind(quad(stage).GetPrim(), preview)
    assert got.max() > 0.05
    np.testing.assert_array_equal(got, _render(stage))


def test_an_unsupported_node_is_named_once_and_its_input_takes_the_default(fake, caplog) -> None:
    stage = new_stage()
    surface = mtlx_material(stage, "/Looks/M", "ND_standard_surface_surfaceshader")
    noise = node(stage, "/Looks/M/Noise", "ND_fractal3d_color3")
    surface.CreateInput("base_color", C3).ConnectToSource(noise.ConnectableAPI(), "out")
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    m = fake.meshes()["/World/Quad"]["material"]
    assert m["diffuseColor"] == pytest.approx((0.8, 0.8, 0.8))  # standard_surface's default
    named = [r.getMessage() for r in caplog.records if "ND_fractal3d_color3" in r.getMessage()]
    assert len(named) == 1 and "/Looks/M" in named[0] and "/Looks/M/Noise" in named[0]
    assert any(u.what.startswith("MaterialX node") for u in scene.unsupported)


def test_a_node_input_of_the_wrong_type_is_named_and_the_input_takes_its_default(
    fake, caplog, tmp_path
) -> None:
    stage = new_stage()
    surface = mtlx_material(stage, "/Looks/M", "ND_standard_surface_surfaceshader")
    rough = node(stage, "/Looks/M/Rough", "ND_constant_float", F)
    rough.CreateInput("value", Sdf.ValueTypeNames.String).Set("0.7")
    surface.CreateInput("specular_roughness", F).ConnectToSource(rough.ConnectableAPI(), "out")
    image = node(stage, "/Looks/M/Image", "ND_image_color3")
    image.CreateInput("file", Sdf.ValueTypeNames.String).Set(str(tmp_path / "wood.png"))
    surface.CreateInput("base_color", C3).ConnectToSource(image.ConnectableAPI(), "out")
    bind(quad(stage).GetPrim(), UsdShade.Material.Get(stage, "/Looks/M"))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    m = fake.meshes()["/World/Quad"]["material"]
    # standard_surface's defaults: roughness 0.2; base_color the image's default (black).
    assert m["roughness"] == pytest.approx(0.2) and "textures" not in m
    # One warning each, naming the node, the input and (after "on") the material.
    for where, what in (
        ("/Looks/M/Rough", "input value of type string"),
        ("/Looks/M/Image", "input file of type string"),
    ):
        named = [r.getMessage() for r in caplog.records if what in r.getMessage()]
        assert len(named) == 1 and where in named[0], caplog.text
        assert named[0].endswith("on /Looks/M"), named[0]


# ------------------------------------------------------------ .mtlx files referenced


def _mtlx_file(path, *, with_graph: bool) -> None:
    mx = pytest.importorskip("MaterialX")
    doc = mx.createDocument()
    surface = doc.addNode("standard_surface", "Surf", "surfaceshader")
    surface.setInputValue("base", 1.0)
    surface.setInputValue("metalness", 0.3)
    surface.setInputValue("specular_roughness", 0.4)
    if with_graph:
        graph = doc.addNodeGraph("Graph")
        const = graph.addNode("constant", "Paint", "color3")
        const.setInputValue("value", mx.Color3(0.2, 0.5, 0.7))
        out = graph.addOutput("out", "color3")
        out.setConnectedNode(const)
        base = surface.addInput("base_color", "color3")
        base.setNodeGraphString("Graph")
        base.setOutputString("out")
    else:
        surface.setInputValue("base_color", mx.Color3(0.2, 0.5, 0.7))
    material = doc.addMaterialNode("Paint")
    material.setConnectedNode("surfaceshader", surface)
    mx.writeToXmlFile(doc, str(path))


@pytest.mark.parametrize("with_graph", [False, True])
def test_a_referenced_mtlx_file_renders_as_the_same_network_inline(
    native, tmp_path, with_graph
) -> None:
    _mtlx_file(tmp_path / "looks.mtlx", with_graph=with_graph)
    layer = tmp_path / "scene.usda"
    stage = Usd.Stage.CreateNew(str(layer))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    material = UsdShade.Material.Define(stage, "/Looks/Paint")
    material.GetPrim().GetReferences().AddReference("./looks.mtlx", "/MaterialX/Materials/Paint")
    bind(quad(stage).GetPrim(), material)
    stage.Save()
    scene = UsdSceneDelegate(stage, _FakeHolder.make())
    scene.sync()
    assert not [u for u in scene.unsupported if "mtlx" in u.what], scene.unsupported
    got = _render(stage)
    inline = new_stage()
    mtlx_material(
        inline, "/Looks/Paint", "ND_standard_surface_surfaceshader",
        base=1.0, metalness=0.3, specular_roughness=0.4, base_color=(0.2, 0.5, 0.7),
    )  # fmt: skip
    bind(quad(inline).GetPrim(), UsdShade.Material.Get(inline, "/Looks/Paint"))
    want = _render(inline)
    assert want.max() > 0.05
    np.testing.assert_array_equal(got, want)


def test_a_whole_mtlx_document_composes_under_materials_as_usd_mtlx_lays_it_out(
    fake, tmp_path
) -> None:
    """``references = @looks.mtlx@</MaterialX>``: its materials at <prim>/Materials/<name>."""
    _mtlx_file(tmp_path / "looks.mtlx", with_graph=True)
    stage = Usd.Stage.CreateNew(str(tmp_path / "scene.usda"))
    scope = stage.DefinePrim("/MaterialX", "Scope")
    scope.GetReferences().AddReference("./looks.mtlx", "/MaterialX")
    UsdShade.MaterialBindingAPI.Apply(quad(stage).GetPrim()).GetDirectBindingRel().SetTargets(
        ["/MaterialX/Materials/Paint"]
    )
    stage.Save()
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    m = fake.meshes()["/World/Quad"]["material"]
    assert m["name"] == "/MaterialX/Materials/Paint"
    assert m["diffuseColor"] == pytest.approx((0.2, 0.5, 0.7))
    assert m["metallic"] == pytest.approx(0.3)
    assert scene.unsupported == []


def test_a_documents_materials_compose_as_the_referencing_prims_children(fake, tmp_path) -> None:
    """``references = @looks.mtlx@</MaterialX/Materials>`` (usd-wg's OpenChessSet): the
    materials at <prim>/<name>."""
    _mtlx_file(tmp_path / "looks.mtlx", with_graph=True)
    stage = Usd.Stage.CreateNew(str(tmp_path / "scene.usda"))
    scope = stage.DefinePrim("/Asset/Materials", "Scope")
    scope.GetReferences().AddReference("./looks.mtlx", "/MaterialX/Materials")
    UsdShade.MaterialBindingAPI.Apply(quad(stage).GetPrim()).GetDirectBindingRel().SetTargets(
        ["/Asset/Materials/Paint"]
    )
    stage.Save()
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    m = fake.meshes()["/World/Quad"]["material"]
    assert m["name"] == "/Asset/Materials/Paint"
    assert m["diffuseColor"] == pytest.approx((0.2, 0.5, 0.7))
    assert scene.unsupported == []


def test_an_unreadable_mtlx_file_is_named_and_the_frame_renders(native, tmp_path, caplog) -> None:
    pytest.importorskip("MaterialX")
    (tmp_path / "broken.mtlx").write_text("<materialx><not closed")
    layer = tmp_path / "scene.usda"
    stage = Usd.Stage.CreateNew(str(layer))
    material = UsdShade.Material.Define(stage, "/Looks/Paint")
    material.GetPrim().GetReferences().AddReference("./broken.mtlx", "/MaterialX/Materials/Paint")
    bind(quad(stage).GetPrim(), material)
    stage.Save()
    with caplog.at_level(logging.WARNING, logger="mipray"):
        image = _render(stage)
    assert np.isfinite(image).all() and image.max() > 0
    assert any(
        "/Looks/Paint" in r.getMessage() and "broken.mtlx" in r.getMessage() for r in caplog.records
    )


class _FakeHolder:
    @staticmethod
    def make():
        from fake_delegate import FakeRenderDelegate

        return FakeRenderDelegate()
