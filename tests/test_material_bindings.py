"""Material bindings as USD resolves them: GeomSubsets with whole (textured) networks, native
instances and instance proxies, binding strength, collections and material purpose."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

import mipray
from mipray.usd import UsdSceneDelegate
from mipray.usd.material import lambertian

from fake_delegate import display_color
from stages import (
    add_camera,
    add_cube,
    add_distant_light,
    add_preview_material,
    add_textured_material,
    bind,
    new_stage,
)

# A 3 × 1 strip of unit quads in z = 0 facing +Z: faces 0, 1, 2 from left to right, with an
# st primvar per point (s along x over the whole strip).
STRIP_POINTS = [(x - 1.5, y - 0.5, 0.0) for y in (0, 1) for x in range(4)]
STRIP_INDICES = [0, 1, 5, 4, 1, 2, 6, 5, 2, 3, 7, 6]


def strip(stage: Usd.Stage, path: str = "/World/Strip") -> UsdGeom.Mesh:
    mesh = add_cube(
        stage, path, points=STRIP_POINTS, counts=[4, 4, 4], indices=STRIP_INDICES, scheme="none"
    )
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    st.Set(Vt.Vec2fArray([Gf.Vec2f(x / 3, y) for y in (0, 1) for x in range(4)]))
    return mesh


def subset(mesh: UsdGeom.Mesh, name: str, faces: list[int], material) -> UsdGeom.Subset:
    sub = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).CreateMaterialBindSubset(
        name, Vt.IntArray(faces)
    )
    if material is not None:
        bind(sub.GetPrim(), material)
    return sub


def textured_material(stage: Usd.Stage, path: str, file: str) -> UsdShade.Material:
    """diffuseColor from ``file`` at the mesh's ``st``, repeating: no black border blended in
    at the strip's edges."""
    return add_textured_material(stage, path, file, wrap="repeat")


def make_texture(path: Path, color: tuple[float, ...], fmt: str = "uint8", size: int = 8) -> Path:
    """A constant-colour image written by OpenImageIO's oiiotool (skip without it)."""
    tool = shutil.which("oiiotool")
    if tool is None:
        pytest.skip("oiiotool (openimageio-tools) is not installed")
    values = ",".join(f"{c:g}" for c in color)
    subprocess.run(
        [
            tool,
            "--pattern",
            f"constant:color={values}",
            f"{size}x{size}",
            str(len(color)),
            "-d",
            fmt,
            "-o",
            str(path),
        ],
        check=True,
        capture_output=True,
    )
    return path


def synced(stage: Usd.Stage, fake) -> UsdSceneDelegate:
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    return scene


def prototype_mesh(fake, path: str) -> dict:
    call = fake.prims[path]
    assert call.method == "set_mesh" and call.kwargs["prototype"], path
    return call.kwargs


def material_name(args: dict) -> str | None:
    """The bound material's name; None for a display colour (a lambertian named after the prim)."""
    material = args.get("material")
    diffuse = material.get("diffuseColor", (0.18,) * 3) if material else None
    if material is None or material == lambertian(material["name"], diffuse):
        return None
    return str(material["name"])


# ------------------------------------------------------------------- GeomSubsets


def test_a_textured_subset_sends_its_whole_network_on_its_faces(fake, tmp_path) -> None:
    stage = new_stage()
    mesh = strip(stage)
    bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5)))
    subset(mesh, "Tex", [1], textured_material(stage, "/Looks/Tex", str(tmp_path / "blue.png")))
    scene = synced(stage, fake)
    assert scene.delegate_errors == []
    args = fake.meshes()["/World/Strip"]
    materials, indices = args["face_materials"], args["face_material_indices"]
    names = [m["name"] for m in materials]
    assert [names[i] for i in indices] == ["/Looks/Grey", "/Looks/Tex", "/Looks/Grey"]
    tex = materials[indices[1]]["textures"]["diffuseColor"]
    assert tex["file"] == str(tmp_path / "blue.png")
    # The subset's texture reads the mesh's st.
    assert args["st_values"].shape == (8, 2)


def test_subsets_all_on_the_mesh_material_add_no_face_table(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    grey = add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5))
    bind(mesh.GetPrim(), grey)
    subset(mesh, "Same", [0], grey)
    subset(mesh, "Unbound", [2], None)
    synced(stage, fake)
    assert fake.meshes()["/World/Strip"]["face_materials"] is None


def test_subset_faces_without_a_mesh_material_keep_their_display_colour(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    mesh.CreateDisplayColorAttr([(1.0, 0.0, 0.0)])
    subset(mesh, "Green", [2], add_preview_material(stage, "/Looks/Green", (0.0, 1.0, 0.0)))
    synced(stage, fake)
    args = fake.meshes()["/World/Strip"]
    assert list(args["face_material_indices"]) == [-1, -1, 0]
    assert display_color(args, "/World/Strip") == pytest.approx((1, 0, 0))


def _strip_scene(stage: Usd.Stage) -> None:
    camera = add_camera(stage, "/World/Cam", eye=(0, 0, 4))
    camera.CreateHorizontalApertureAttr(30.0)
    camera.CreateVerticalApertureAttr(10.0)
    camera.CreateFocalLengthAttr(18.0)
    add_distant_light(stage, "/World/Sun").GetPrim().GetAttribute("xformOp:rotateX").Set(0.0)


def test_a_textured_subset_renders_its_texture_as_the_same_constant_colour(
    native, tmp_path
) -> None:
    """Truth: the subset bound to a constant diffuseColor equal to the texture's one colour."""
    file = make_texture(tmp_path / "blue.png", (0.0, 0.0, 1.0))

    def render(textured: bool) -> np.ndarray:
        stage = new_stage()
        mesh = strip(stage)
        mesh.CreateDisplayColorAttr([(1.0, 0.0, 0.0)])  # what a subset fell back to before
        bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5)))
        looks = (
            textured_material(stage, "/Looks/Tex", str(file))
            if textured
            else add_preview_material(stage, "/Looks/Tex", (0.0, 0.0, 1.0))
        )
        subset(mesh, "Tex", [1], looks)
        _strip_scene(stage)
        return mipray.render(stage, width=90, aovs=("color",)).aovs["color"]

    textured, constant = render(True), render(False)
    row, middle = textured.shape[0] // 2, textured.shape[1] // 2
    face = textured[row, middle - 5 : middle + 5]
    assert (face[:, 2] > 2 * face[:, 0]).all(), face  # blue, not the red display colour
    np.testing.assert_allclose(textured, constant, atol=2e-3)


def test_a_subset_renders_its_whole_lobes_as_the_same_material_on_the_whole_mesh(native) -> None:
    """A metallic subset face matches the same face of the mesh bound wholly to that material."""

    def render(on_subset: bool) -> np.ndarray:
        stage = new_stage()
        mesh = strip(stage)
        metal = add_preview_material(stage, "/Looks/Gold", (1.0, 0.8, 0.3))
        surface = UsdShade.Shader(stage.GetPrimAtPath("/Looks/Gold/PreviewSurface"))
        surface.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(1.0)
        surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.3)
        if on_subset:
            bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5)))
            subset(mesh, "Gold", [1], metal)
        else:
            bind(mesh.GetPrim(), metal)
        _strip_scene(stage)
        return mipray.render(stage, width=90, aovs=("color",)).aovs["color"]

    sub, whole = render(True), render(False)
    row, middle = sub.shape[0] // 2, sub.shape[1] // 2
    # The middle face spans ±6.75 pixels about the middle column.
    np.testing.assert_allclose(
        sub[row - 3 : row + 3, middle - 5 : middle + 5],
        whole[row - 3 : row + 3, middle - 5 : middle + 5],
        atol=1e-5,
    )


# --------------------------------------------------------- strength, collections, purpose


def test_a_stronger_than_descendants_binding_wins_over_the_mesh_own(fake) -> None:
    stage = new_stage()
    mesh = strip(stage)
    red = add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0))
    bind(mesh.GetPrim(), add_preview_material(stage, "/Looks/Blue", (0.0, 0.0, 1.0)))
    UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath("/World")).Bind(
        red, UsdShade.Tokens.strongerThanDescendants
    )
    synced(stage, fake)
    assert material_name(fake.meshes()["/World/Strip"]) == "/Looks/Red"


def test_a_collection_binding_reaches_the_meshes_it_names(fake) -> None:
    stage = new_stage()
    strip(stage, "/World/A")
    strip(stage, "/World/B")
    red = add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0))
    world = stage.GetPrimAtPath("/World")
    collection = Usd.CollectionAPI.Apply(world, "reds")
    collection.CreateIncludesRel().AddTarget("/World/B")
    UsdShade.MaterialBindingAPI.Apply(world).Bind(collection, red, "reds")
    synced(stage, fake)
    meshes = fake.meshes()
    assert material_name(meshes["/World/A"]) is None
    assert material_name(meshes["/World/B"]) == "/Looks/Red"


@pytest.mark.parametrize(
    "bindings, expected",
    [
        # (purpose, material) pairs bound to the mesh; Hydra's full-purpose resolution.
        ([("allPurpose", "Red"), ("full", "Blue")], "/Looks/Blue"),
        ([("allPurpose", "Red"), ("preview", "Blue")], "/Looks/Red"),
        ([("preview", "Blue")], None),
    ],
)
def test_material_purpose_full_then_all_purpose(fake, bindings, expected) -> None:
    stage = new_stage()
    mesh = strip(stage)
    looks = {
        "Red": add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0)),
        "Blue": add_preview_material(stage, "/Looks/Blue", (0.0, 0.0, 1.0)),
    }
    api = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    for purpose, name in bindings:
        token = UsdShade.Tokens.allPurpose if purpose == "allPurpose" else purpose
        api.Bind(looks[name], UsdShade.Tokens.fallbackStrength, token)
    synced(stage, fake)
    assert material_name(fake.meshes()["/World/Strip"]) == expected


# ------------------------------------------------------------------ native instances


def _instanced(stage: Usd.Stage, names: list[str]) -> None:
    """``/World/<name>`` instances of ``/Protos/Group`` (a Part cube), 2 apart along x."""
    UsdGeom.Xform.Define(stage, "/Protos/Group")
    add_cube(stage, "/Protos/Group/Part")
    stage.GetPrimAtPath("/Protos").SetSpecifier(Sdf.SpecifierClass)
    for i, name in enumerate(names):
        inst = UsdGeom.Xform.Define(stage, f"/World/{name}")
        inst.AddTranslateOp().Set(Gf.Vec3d(2.0 * i - (len(names) - 1), 0, 0))
        inst.GetPrim().GetReferences().AddInternalReference("/Protos/Group")
        inst.GetPrim().SetInstanceable(True)


def test_a_binding_on_an_instance_reaches_its_prototype_meshes(fake) -> None:
    stage = new_stage()
    _instanced(stage, ["Plain", "Red"])
    bind(stage.GetPrimAtPath("/World/Red"), add_preview_material(stage, "/Looks/Red", (1, 0, 0)))
    scene = synced(stage, fake)
    assert scene.delegate_errors == []
    instancers = fake.instancers()
    proto = str(stage.GetPrimAtPath("/World/Plain").GetPrototype().GetPath())
    plain, red = instancers[proto], instancers[proto + ".variant0"]
    assert len(plain["transforms"]) == 1 and len(red["transforms"]) == 1
    assert material_name(prototype_mesh(fake, plain["prototypes"][0])) is None
    assert material_name(prototype_mesh(fake, red["prototypes"][0])) == "/Looks/Red"
    # The red one is placed where /World/Red is (x = +1).
    assert red["transforms"][0][3, 0] == pytest.approx(1.0)


def test_a_collection_naming_an_instance_proxy_binds_that_instance_only(fake) -> None:
    stage = new_stage()
    _instanced(stage, ["A", "B", "C"])
    red = add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0))
    world = stage.GetPrimAtPath("/World")
    collection = Usd.CollectionAPI.Apply(world, "picked")
    collection.CreateIncludesRel().AddTarget("/World/B/Part")
    UsdShade.MaterialBindingAPI.Apply(world).Bind(collection, red, "picked")
    synced(stage, fake)
    instancers = fake.instancers()
    proto = str(stage.GetPrimAtPath("/World/A").GetPrototype().GetPath())
    assert len(instancers[proto]["transforms"]) == 2
    variant = instancers[proto + ".variant0"]
    assert variant["transforms"][0][3, 0] == pytest.approx(0.0)  # /World/B, the middle one
    assert material_name(prototype_mesh(fake, variant["prototypes"][0])) == "/Looks/Red"


def test_editing_an_instance_binding_moves_it_between_variants(fake) -> None:
    stage = new_stage()
    _instanced(stage, ["A", "B"])
    red = add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0))
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    proto = str(stage.GetPrimAtPath("/World/A").GetPrototype().GetPath())
    assert proto + ".variant0" not in fake.instancers()
    bind(stage.GetPrimAtPath("/World/B"), red)
    scene.sync()
    assert len(fake.instancers()[proto]["transforms"]) == 1
    assert proto + ".variant0" in fake.instancers()
    UsdShade.MaterialBindingAPI(stage.GetPrimAtPath("/World/B")).UnbindAllBindings()
    scene.sync()
    assert len(fake.instancers()[proto]["transforms"]) == 2
    assert proto + ".variant0" not in fake.instancers()


def test_instances_render_as_the_same_scene_without_instancing(native) -> None:
    """Truth: the stage with instanceable turned off, where USD composes plain prims."""

    def render(instanceable: bool) -> np.ndarray:
        stage = new_stage()
        _instanced(stage, ["A", "B", "C"])
        bind(stage.GetPrimAtPath("/World/B"), add_preview_material(stage, "/Looks/Red", (1, 0, 0)))
        bind(
            stage.GetPrimAtPath("/Protos/Group/Part"),
            add_preview_material(stage, "/Looks/Grey", (0.5, 0.5, 0.5)),
        )
        UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath("/World/C")).Bind(
            add_preview_material(stage, "/Looks/Blue", (0, 0, 1)),
            UsdShade.Tokens.strongerThanDescendants,
        )
        for name in "ABC":
            stage.GetPrimAtPath(f"/World/{name}").SetInstanceable(instanceable)
        add_camera(stage, "/World/Cam", eye=(0, 0, 8))
        add_distant_light(stage, "/World/Sun")
        return mipray.render(stage, width=96, aovs=("color",)).aovs["color"]

    instanced, flat = render(True), render(False)
    np.testing.assert_allclose(instanced, flat, atol=1e-4)
    # B's own binding is weaker than Part's direct grey: no red anywhere. C's
    # strongerThanDescendants blue wins over Part's grey.
    lit = instanced[instanced.max(axis=2) > 0.05]
    assert not (lit[:, 0] > 1.5 * lit[:, 1]).any()
    assert (lit[:, 2] > 2 * lit[:, 0]).sum() > 20
