"""The scene delegate reads UsdGeom.Mesh data exactly (fake delegate, no Rust)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdShade

from mipray.usd import UsdSceneDelegate

from fake_delegate import display_color, face_colors
from stages import (
    CUBE_COUNTS,
    CUBE_INDICES,
    CUBE_POINTS,
    add_cube,
    add_preview_material,
    bind,
    new_stage,
)


def sync(stage, fake, **kwargs) -> UsdSceneDelegate:
    scene = UsdSceneDelegate(stage, fake, **kwargs)
    scene.sync()
    return scene


def test_topology_and_subdivision_tags_are_read_exactly(fake) -> None:
    stage = new_stage()
    mesh = add_cube(stage, "/World/Cube")
    mesh.CreateSubdivisionSchemeAttr("catmullClark")
    mesh.CreateInterpolateBoundaryAttr("edgeOnly")
    mesh.CreateFaceVaryingLinearInterpolationAttr("all")
    mesh.CreateTriangleSubdivisionRuleAttr("smooth")
    mesh.CreateCreaseIndicesAttr([0, 1, 3, 2, 3])
    mesh.CreateCreaseLengthsAttr([3, 2])
    mesh.CreateCreaseSharpnessesAttr([10.0, 2.5])
    mesh.CreateCornerIndicesAttr([4, 7])
    mesh.CreateCornerSharpnessesAttr([3.0, 10.0])
    mesh.CreateHoleIndicesAttr([5])
    mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    mesh.CreateDoubleSidedAttr(True)

    sync(stage, fake)

    args = fake.meshes()["/World/Cube"]
    np.testing.assert_array_equal(args["points"], np.array(CUBE_POINTS, np.float32))
    assert args["points"].dtype == np.float32 and args["points"].shape == (8, 3)
    np.testing.assert_array_equal(args["face_vertex_counts"], CUBE_COUNTS)
    np.testing.assert_array_equal(args["face_vertex_indices"], CUBE_INDICES)
    assert args["face_vertex_indices"].dtype == np.int32
    assert args["scheme"] == "catmullClark"
    assert args["interpolate_boundary"] == "edgeOnly"
    assert args["face_varying_linear_interpolation"] == "all"
    assert args["triangle_subdivision_rule"] == "smooth"
    np.testing.assert_array_equal(args["crease_indices"], [0, 1, 3, 2, 3])
    np.testing.assert_array_equal(args["crease_lengths"], [3, 2])
    np.testing.assert_array_equal(args["crease_sharpnesses"], np.array([10.0, 2.5], np.float32))
    assert args["crease_sharpnesses"].dtype == np.float32
    np.testing.assert_array_equal(args["corner_indices"], [4, 7])
    np.testing.assert_array_equal(args["corner_sharpnesses"], [3.0, 10.0])
    np.testing.assert_array_equal(args["hole_indices"], [5])
    assert args["left_handed"] is True
    assert args["double_sided"] is True


def test_unauthored_tags_use_usd_fallbacks_and_none(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Cube")
    sync(stage, fake)
    args = fake.meshes()["/Cube"]
    assert args["scheme"] == "catmullClark"
    assert args["interpolate_boundary"] == "edgeAndCorner"
    assert args["face_varying_linear_interpolation"] == "cornersPlus1"
    assert args["triangle_subdivision_rule"] == "catmullClark"
    for key in (
        "crease_indices",
        "crease_lengths",
        "crease_sharpnesses",
        "corner_indices",
        "corner_sharpnesses",
        "hole_indices",
    ):
        assert args[key] is None, key
    assert args["left_handed"] is False
    assert args["double_sided"] is False
    assert display_color(args, "/Cube") == (0.18, 0.18, 0.18)


@pytest.mark.parametrize("scheme", ["none", "bilinear", "loop"])
def test_scheme_is_passed_through(fake, scheme: str) -> None:
    stage = new_stage()
    if scheme == "loop":
        add_cube(
            stage,
            "/M",
            points=[(0, 0, 0), (1, 0, 0), (0, 1, 0)],
            counts=[3],
            indices=[0, 1, 2],
            scheme=scheme,
        )
    else:
        add_cube(stage, "/M", scheme=scheme)
    sync(stage, fake)
    assert fake.meshes()["/M"]["scheme"] == scheme


def test_a_loop_mesh_with_quads_renders_unsubdivided_with_a_warning(fake, caplog) -> None:
    # usd-wg's subdiv_loop_quads: OpenSubdiv's Loop takes triangles only; usdrecord (Storm)
    # draws the cube unrefined, and so does mipray, saying so.
    stage = new_stage()
    add_cube(stage, "/LoopCube", scheme="loop")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = sync(stage, fake)
    assert scene.delegate_errors == []
    assert fake.meshes()["/LoopCube"]["scheme"] == "none"
    said = [r.getMessage() for r in caplog.records if "/LoopCube" in r.getMessage()]
    assert len(said) == 1 and "loop needs triangles" in said[0] and "unsubdivided" in said[0]


def test_per_edge_crease_sharpness_is_accepted(fake) -> None:
    stage = new_stage()
    mesh = add_cube(stage, "/Cube")
    mesh.CreateCreaseIndicesAttr([0, 1, 3])
    mesh.CreateCreaseLengthsAttr([3])
    mesh.CreateCreaseSharpnessesAttr([1.0, 4.0])  # one per edge of the crease
    scene = sync(stage, fake)
    assert scene.delegate_errors == []
    np.testing.assert_array_equal(fake.meshes()["/Cube"]["crease_sharpnesses"], [1.0, 4.0])


def test_mesh_without_faces_is_skipped_silently(fake, caplog) -> None:
    stage = new_stage()
    UsdGeom.Mesh.Define(stage, "/Empty")
    scene = sync(stage, fake)
    assert "/Empty" not in fake.prims
    assert scene.delegate_errors == []
    assert not [r for r in caplog.records if r.levelname in ("WARNING", "ERROR")]


def test_albedo_from_bound_preview_surface(fake) -> None:
    stage = new_stage()
    cube = add_cube(stage, "/Cube")
    cube.CreateDisplayColorAttr([(0.0, 0.0, 1.0)])
    bind(cube.GetPrim(), add_preview_material(stage, "/Looks/Red", (0.8, 0.1, 0.05)))
    sync(stage, fake)
    assert fake.meshes()["/Cube"]["material"]["diffuseColor"] == pytest.approx((0.8, 0.1, 0.05))


def test_albedo_binding_is_inherited_from_an_ancestor(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Group/Cube")
    bind(stage.GetPrimAtPath("/Group"), add_preview_material(stage, "/Looks/G", (0.2, 0.7, 0.2)))
    sync(stage, fake)
    assert fake.meshes()["/Group/Cube"]["material"]["diffuseColor"] == pytest.approx(
        (0.2, 0.7, 0.2)
    )


def test_unauthored_diffuse_is_the_preview_surface_default(fake) -> None:
    stage = new_stage()
    cube = add_cube(stage, "/Cube")
    cube.CreateDisplayColorAttr([(0.0, 0.0, 1.0)])
    bind(cube.GetPrim(), add_preview_material(stage, "/Looks/Plain", None))
    sync(stage, fake)
    assert tuple(face_colors(fake.meshes()["/Cube"])[0]) == pytest.approx((0.18, 0.18, 0.18))


def test_textured_diffuse_falls_back_to_display_color(fake) -> None:
    stage = new_stage()
    cube = add_cube(stage, "/Cube")
    cube.CreateDisplayColorAttr([(0.1, 0.2, 0.3)])
    material = add_preview_material(stage, "/Looks/Tex", None)
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/Tex/PreviewSurface"))
    texture = UsdShade.Shader.Define(stage, "/Looks/Tex/Texture")
    texture.CreateIdAttr("UsdUVTexture")
    texture.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("wood.png")
    out = texture.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(out)
    bind(cube.GetPrim(), material)
    sync(stage, fake)
    mesh = fake.meshes()["/Cube"]
    # The network shades it, not displayColor; the renderer uses the texture's own fallback
    # if the file cannot be read.
    assert display_color(mesh, "/Cube") is None
    assert mesh["material"]["textures"]["diffuseColor"]["file"].endswith("wood.png")
    assert mesh["material"]["textures"]["diffuseColor"]["channel"] == 0


def test_diffuse_through_a_material_interface_input_is_constant(fake) -> None:
    stage = new_stage()
    cube = add_cube(stage, "/Cube")
    material = add_preview_material(stage, "/Looks/Iface", None)
    knob = material.CreateInput("tint", Sdf.ValueTypeNames.Color3f)
    knob.Set(Gf.Vec3f(0.3, 0.4, 0.5))
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/Iface/PreviewSurface"))
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(knob)
    bind(cube.GetPrim(), material)
    sync(stage, fake)
    assert fake.meshes()["/Cube"]["material"]["diffuseColor"] == pytest.approx((0.3, 0.4, 0.5))


def test_albedo_from_display_color_else_grey(fake) -> None:
    stage = new_stage()
    one = add_cube(stage, "/One")
    one.CreateDisplayColorAttr([(0.9, 0.5, 0.1)])
    many = add_cube(stage, "/Many")
    many.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set([(1, 0, 0)] * 6)
    add_cube(stage, "/None")
    sync(stage, fake)
    assert display_color(fake.meshes()["/One"], "/One") == pytest.approx((0.9, 0.5, 0.1))
    # The same colour on every face is one albedo, no per-face table.
    assert display_color(fake.meshes()["/Many"], "/Many") == pytest.approx((1.0, 0.0, 0.0))
    assert fake.meshes()["/Many"]["face_materials"] is None
    assert display_color(fake.meshes()["/None"], "/None") == pytest.approx((0.18, 0.18, 0.18))


def test_time_sampled_points_are_read_at_the_time_code(fake) -> None:
    stage = new_stage()
    mesh = add_cube(stage, "/Cube")
    moved = [(x + 1.0, y, z) for x, y, z in CUBE_POINTS]
    mesh.GetPointsAttr().Set(CUBE_POINTS, 1.0)
    mesh.GetPointsAttr().Set(moved, 3.0)
    sync(stage, fake, time=2.0)
    pts = fake.meshes()["/Cube"]["points"]
    np.testing.assert_allclose(pts[:, 0], np.array(CUBE_POINTS)[:, 0] + 0.5)
