"""GeomSubset materials and display primvars colour exactly their faces."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

import mipray
from mipray.usd import UsdSceneDelegate

from fake_delegate import face_colors
from stages import add_camera, add_cube, add_distant_light, add_preview_material, bind, new_stage

# A 3 × 1 strip of unit quads in z = 0 facing +Z: faces 0, 1, 2 from left to right.
STRIP_POINTS = [(x - 1.5, y - 0.5, 0.0) for y in (0, 1) for x in range(4)]
STRIP_COUNTS = [4, 4, 4]
STRIP_INDICES = [0, 1, 5, 4, 1, 2, 6, 5, 2, 3, 7, 6]


def strip(stage, path: str = "/World/Strip") -> UsdGeom.Mesh:
    return add_cube(
        stage,
        path,
        points=STRIP_POINTS,
        counts=STRIP_COUNTS,
        indices=STRIP_INDICES,
        scheme="none",
    )


def subset(mesh: UsdGeom.Mesh, name: str, faces: list[int], material) -> UsdGeom.Subset:
    binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    sub = binding.CreateMaterialBindSubset(name, Vt.IntArray(faces))
    if material is not None:
        UsdShade.MaterialBindingAPI.Apply(sub.GetPrim()).Bind(material)
    return sub


def synced(stage, fake) -> UsdSceneDelegate:
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    return scene


# ---------------------------------------------------------------- GeomSubsets


def test_subset_material_covers_exactly_its_faces(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5)))
    subset(mesh, "Red", [1], add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0)))
    scene = synced(stage, fake)
    assert scene.delegate_errors == []
    colors = face_colors(fake.meshes()["/World/Strip"])
    np.testing.assert_allclose(colors, [(0.5, 0.5, 0.5), (1, 0, 0), (0.5, 0.5, 0.5)])


def test_subset_without_own_binding_uses_the_mesh_material(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Blue", (0.0, 0.0, 1.0)))
    subset(mesh, "Plain", [0, 2], None)
    synced(stage, fake)
    args = fake.meshes()["/World/Strip"]
    assert args["face_materials"] is None and args["material"]["diffuseColor"] == pytest.approx(
        (0, 0, 1)
    )


def test_subset_edit_resyncs_its_mesh(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    green = add_preview_material(stage, "/Looks/Green", (0.0, 1.0, 0.0))
    sub = subset(mesh, "Green", [0], green)
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    sub.GetIndicesAttr().Set(Vt.IntArray([2]))
    scene.sync()
    colors = face_colors(fake.meshes()["/World/Strip"])
    np.testing.assert_allclose(colors[:, 1], [0.18, 0.18, 1.0], atol=1e-6)
    green.GetSurfaceOutput().GetConnectedSource()[0].GetInput("diffuseColor").Set(
        Gf.Vec3f(0, 0.5, 0)
    )
    scene.sync()
    assert face_colors(fake.meshes()["/World/Strip"])[2, 1] == pytest.approx(0.5)
    assert scene.sync_counts["/World/Strip"] == 3


def test_subset_indices_out_of_range_name_the_subset(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    subset(mesh, "Bad", [1, 7], add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0)))
    add_cube(stage, "/World/Other")
    scene = synced(stage, fake)
    assert set(fake.meshes()) == {"/World/Other"}
    assert [e.prim_path for e in scene.delegate_errors] == ["/World/Strip"]
    assert str(scene.delegate_errors[0]) == (
        "/World/Strip/Bad: indices[1] = 7 is out of range for 3 faces"
    )


def test_subset_colour_shows_on_exactly_its_faces_in_the_render(native) -> None:
    stage = new_stage()
    mesh = strip(stage)
    bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5)))
    red = add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0))
    # A subset renders its material's whole network: no specular lobe, so the face is pure red.
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/Red/PreviewSurface"))
    surface.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    surface.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0, 0, 0))
    subset(mesh, "Red", [1], red)
    camera = add_camera(stage, "/World/Cam", eye=(0, 0, 4))
    camera.CreateHorizontalApertureAttr(30.0)
    camera.CreateVerticalApertureAttr(10.0)
    camera.CreateFocalLengthAttr(18.0)
    light = add_distant_light(stage, "/World/Sun")
    light.GetPrim().GetAttribute("xformOp:rotateX").Set(0.0)  # straight down -Z
    result = mipray.render(stage, width=120, aovs=("color", "alpha"))
    color, alpha = result.aovs["color"], result.aovs["alpha"][..., 0]
    row = result.height // 2
    # Project the face boundaries x = -0.5 and 0.5 at distance 4: 18 mm lens, 30 mm back.
    half = 120 / 2
    edge = 0.5 / 4 * 18 / 15 * half
    left, right = int(np.floor(half - edge)), int(np.ceil(half + edge))
    inside = color[row, left + 2 : right - 2]
    outside = np.concatenate([color[row, : left - 2], color[row, right + 2 :]])
    hit_outside = np.concatenate([alpha[row, : left - 2], alpha[row, right + 2 :]]) > 0.5
    assert (inside[:, 0] > 0).all() and (inside[:, 1:] == 0).all(), "the red subset face"
    assert hit_outside.sum() > 20
    grey = outside[hit_outside]
    assert (grey[:, 0] > 0).all() and np.allclose(grey[:, 0], grey[:, 1]), "grey elsewhere"


# ------------------------------------------------------------ display primvars


@pytest.mark.parametrize(
    "interpolation, values, expected",
    [
        ("constant", [(0.2, 0.4, 0.6)], [(0.2, 0.4, 0.6)] * 3),
        ("uniform", [(1, 0, 0), (0, 1, 0), (0, 0, 1)], [(1, 0, 0), (0, 1, 0), (0, 0, 1)]),
        # Per point: each face averages its four corners.
        (
            "vertex",
            [(x / 3, 0, 0) for _ in (0, 1) for x in range(4)],
            [(1 / 6, 0, 0), (0.5, 0, 0), (5 / 6, 0, 0)],
        ),
        ("varying", [(0, y, 0) for y in (0, 1) for _ in range(4)], [(0, 0.5, 0)] * 3),
        # Per face-vertex: face 2's corners are 0, 0, 1, 1 in blue.
        (
            "faceVarying",
            [(0, 0, 0)] * 8 + [(0, 0, 0), (0, 0, 0), (0, 0, 1), (0, 0, 1)],
            [(0, 0, 0), (0, 0, 0), (0, 0, 0.5)],
        ),
    ],
)
def test_display_color_interpolations(fake, interpolation, values, expected) -> None:
    stage = new_stage()
    mesh = strip(stage)
    mesh.CreateDisplayColorPrimvar(interpolation).Set(values)
    scene = synced(stage, fake)
    assert scene.delegate_errors == []
    np.testing.assert_allclose(face_colors(fake.meshes()["/World/Strip"]), expected, atol=1e-6)


def test_indexed_display_color(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    primvar = mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform)
    primvar.Set([(1, 0, 0), (0, 1, 0)])
    primvar.SetIndices(Vt.IntArray([1, 0, 1]))
    synced(stage, fake)
    np.testing.assert_allclose(
        face_colors(fake.meshes()["/World/Strip"]), [(0, 1, 0), (1, 0, 0), (0, 1, 0)]
    )


def test_material_wins_over_display_color(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set([(1, 0, 0), (0, 1, 0), (0, 0, 1)])
    bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5)))
    synced(stage, fake)
    assert fake.meshes()["/World/Strip"]["face_materials"] is None


@pytest.mark.parametrize(
    "name, interpolation, values, fragment",
    [
        (
            "displayColor",
            "uniform",
            [(1, 0, 0)] * 2,
            "primvars:displayColor (uniform) has 2 values for 3 faces",
        ),
        ("displayColor", "vertex", [(1, 0, 0)] * 3, "has 3 values for 8 points"),
        ("displayColor", "faceVarying", [(1, 0, 0)] * 11, "has 11 values for 12 face-vertices"),
        (
            "displayColor",
            "uniform",
            [(1, 0, 0), (float("nan"), 0, 0), (1, 0, 0)],
            "primvars:displayColor[1] = (nan, 0.0, 0.0) is not finite",
        ),
        (
            "displayOpacity",
            "vertex",
            [0.5] * 7,
            "primvars:displayOpacity (vertex) has 7 values for 8 points",
        ),
    ],
)
def test_mismatched_display_primvars_name_the_prim(
    fake, name, interpolation, values, fragment
) -> None:
    stage = new_stage()
    mesh = strip(stage)
    add_cube(stage, "/World/Fine")
    api = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    type_name = (
        Sdf.ValueTypeNames.Color3fArray if name == "displayColor" else Sdf.ValueTypeNames.FloatArray
    )
    api.CreatePrimvar(name, type_name, interpolation).Set(values)
    scene = synced(stage, fake)
    assert set(fake.meshes()) == {"/World/Fine"}
    assert [e.prim_path for e in scene.delegate_errors] == ["/World/Strip"]
    assert fragment in str(scene.delegate_errors[0])
    assert str(scene.delegate_errors[0]).startswith("/World/Strip: ")


def test_display_color_index_out_of_range(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    primvar = mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform)
    primvar.Set([(1, 0, 0)])
    primvar.SetIndices(Vt.IntArray([0, 0, 4]))
    scene = synced(stage, fake)
    assert "primvars:displayColor:indices[2] = 4 is out of range for 1 values" in str(
        scene.delegate_errors[0]
    )


def test_uniform_display_color_renders_per_face(native) -> None:
    stage = new_stage()
    mesh = strip(stage)
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set([(1, 0, 0), (0, 1, 0), (0, 0, 1)])
    add_camera(stage, "/World/Cam", eye=(0, 0, 6))
    add_distant_light(stage, "/World/Sun").GetPrim().GetAttribute("xformOp:rotateX").Set(0.0)
    result = mipray.render(stage, width=90, aovs=("color",))
    row = result.aovs["color"][result.height // 2]
    dominant = [int(np.argmax(px)) for px in row if px.max() > 0]
    # Left to right: red, green, blue, each on a run of pixels.
    runs = [c for i, c in enumerate(dominant) if i == 0 or dominant[i - 1] != c]
    assert runs == [0, 1, 2]
