"""Mesh lights whose faces emit their own materials' colours, against Lambert's closed form.

Under UsdLux's ``materialGlowTintsLight`` the light's colour is multiplied by "the color feeding
the emission/glow input of the Material": a GeomSubset's faces take their own material's
``emissiveColor`` (the other faces the mesh's), and an ``emissiveColor`` texture tints each
point by its texel at the point's ``st``. So the floor under a square whose two halves emit two
colours is the sum of each half's Lambert irradiance times its colour, channel by channel.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade
from test_lights_shaping_linking import ALBEDO, stage_with_camera
from test_mesh_lights import HALF, H, floor_xy
from test_mesh_lights_tint_instances import bind_emissive, relative_error, render_with_stats

LEFT = (1.0, 0.25, 0.0)
RIGHT = (0.0, 0.5, 1.0)


def lambert_rect(x: np.ndarray, y: np.ndarray, x0: float, x1: float) -> np.ndarray:
    """Irradiance at floor points (x, y, 0), normal +Z, from the unit-radiance rectangle
    [x0, x1] × [−HALF, HALF] at height H: Lambert's E = ½ Σ θᵢ (n · γᵢ) over its edges."""
    corners = [(x0, -HALF), (x1, -HALF), (x1, HALF), (x0, HALF)]
    e = np.zeros_like(x)
    for (ax, ay), (bx, by) in zip(corners, corners[1:] + corners[:1], strict=True):
        a = np.stack([ax - x, ay - y, np.full_like(x, H)], axis=-1)
        b = np.stack([bx - x, by - y, np.full_like(x, H)], axis=-1)
        a /= np.linalg.norm(a, axis=-1, keepdims=True)
        b /= np.linalg.norm(b, axis=-1, keepdims=True)
        theta = np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0))
        g = np.cross(a, b)
        g /= np.linalg.norm(g, axis=-1, keepdims=True)
        e += theta * g[..., 2]
    return np.abs(0.5 * e)


def halved_light(stage: Usd.Stage, intensity: float) -> Usd.Prim:
    """The HALF-sized square at height H facing down, as two quads: x < 0 (face 0), x > 0."""
    mesh = UsdGeom.Mesh.Define(stage, "/World/Glow")
    a = HALF
    mesh.CreatePointsAttr([(-a, -a, H), (0, -a, H), (a, -a, H), (a, a, H), (0, a, H), (-a, a, H)])
    mesh.CreateFaceVertexCountsAttr([4, 4])
    # Clockwise seen from above: the right-hand normal is −Z (down).
    mesh.CreateFaceVertexIndicesAttr([0, 5, 4, 1, 1, 4, 3, 2])
    mesh.CreateSubdivisionSchemeAttr("none")
    UsdLux.MeshLightAPI.Apply(mesh.GetPrim())
    UsdLux.LightAPI(mesh.GetPrim()).CreateIntensityAttr(intensity)
    return mesh.GetPrim()


def check_halves(image: np.ndarray, stage: Usd.Stage, intensity: float, left, right) -> None:
    """Each channel is left × E(left half) + right × E(right half) (within noise)."""
    x, y = floor_xy(image, stage)
    e_left, e_right = lambert_rect(x, y, -HALF, 0.0), lambert_rect(x, y, 0.0, HALF)
    for c in range(3):
        truth = intensity * (left[c] * e_left + right[c] * e_right) * ALBEDO / math.pi
        if truth.max() == 0.0:
            assert float(np.abs(image[..., c]).max()) == 0.0
            continue
        mean, worst = relative_error(image[..., c], truth)
        # A channel only one half emits is noisier than a uniform light's where that half is
        # seen at a grazing angle: each pixel within 20%, the mean within 1%.
        assert abs(mean) < 0.01 and worst < 0.2, (c, mean, worst)
    # The test can tell: one colour (the faces' mean) over the whole square is far off.
    mean_colour = 0.5 * (np.asarray(left) + np.asarray(right))
    wrong = intensity * mean_colour[0] * (e_left + e_right) * ALBEDO / math.pi
    left_side = (x < -HALF / 2) & (wrong > 0.05 * wrong.max())
    off = np.abs(image[..., 0][left_side] / wrong[left_side] - 1.0).mean()
    assert off > 0.2, off


def test_each_geomsubsets_faces_emit_their_own_materials_colour(native) -> None:
    intensity = 3.0
    stage = stage_with_camera()
    prim = halved_light(stage, intensity)
    # The mesh's own material tints the faces no subset binds (the right half).
    bind_emissive(stage, prim, RIGHT, "Base")
    subset = UsdGeom.Subset.CreateGeomSubset(
        UsdGeom.Mesh(prim), "Left", UsdGeom.Tokens.face, [0], "materialBind"
    )
    bind_emissive(stage, subset.GetPrim(), LEFT, "Warm")
    image, stats = render_with_stats(stage, samples=256)
    check_halves(image, stage, intensity, LEFT, RIGHT)
    (entry,) = stats["scene"]["lights"]
    assert entry["per_face_emission"] is True
    # The power-weighted mean: both halves have the same area.
    np.testing.assert_allclose(
        entry["radiance"], [intensity * 0.5 * (a + b) for a, b in zip(LEFT, RIGHT, strict=True)]
    )
    # Two subsets, the mesh without a material of its own: both halves their subset's colour.
    UsdShade.MaterialBindingAPI(prim).UnbindAllBindings()
    right = UsdGeom.Subset.CreateGeomSubset(
        UsdGeom.Mesh(prim), "Right", UsdGeom.Tokens.face, [1], "materialBind"
    )
    bind_emissive(stage, right.GetPrim(), RIGHT, "Cool")
    image, _ = render_with_stats(stage, samples=256)
    check_halves(image, stage, intensity, LEFT, RIGHT)
    # independent: the light's own colour everywhere.
    prim.CreateAttribute("light:materialSyncMode", Sdf.ValueTypeNames.Token).Set("independent")
    image, stats = render_with_stats(stage)
    x, y = floor_xy(image, stage)
    truth = intensity * (lambert_rect(x, y, -HALF, 0.0) + lambert_rect(x, y, 0.0, HALF))
    mean, worst = relative_error(image[..., 2], truth * ALBEDO / math.pi)
    assert abs(mean) < 0.01 and worst < 0.08
    assert stats["scene"]["lights"][0]["per_face_emission"] is False


def test_a_textured_emissive_colour_tints_each_point_by_its_texel(native, tmp_path) -> None:
    # LEFT where s < 0.5, RIGHT elsewhere (fine enough that filtering across the middle is
    # negligible), times scale 2; st runs 0..1 along x over the square, one quad whose two
    # triangles the texture's edge crosses: the colour changes inside a triangle.
    texels = np.zeros((8, 64, 3), dtype=np.float32)
    texels[:, :32] = LEFT
    texels[:, 32:] = RIGHT
    path = tmp_path / "glow.exr"
    native.write_image(str(path), {"color": texels}, ["color"], {"color": "float"})
    intensity = 2.0
    stage = stage_with_camera()
    mesh = UsdGeom.Mesh.Define(stage, "/World/Glow")
    a = HALF
    mesh.CreatePointsAttr([(-a, -a, H), (a, -a, H), (a, a, H), (-a, a, H)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 3, 2, 1])
    mesh.CreateSubdivisionSchemeAttr("none")
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    UsdLux.MeshLightAPI.Apply(mesh.GetPrim())
    UsdLux.LightAPI(mesh.GetPrim()).CreateIntensityAttr(intensity)
    material = UsdShade.Material.Define(stage, "/Looks/Glow")
    shader = UsdShade.Shader.Define(stage, "/Looks/Glow/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(stage, "/Looks/Glow/St")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
    tex = UsdShade.Shader.Define(stage, "/Looks/Glow/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(str(path))
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.ConnectableAPI(), "result"
    )
    tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(2, 2, 2, 1))
    # Clamped: the file names no wrap mode, and a black border would darken the rim texels.
    for wrap in ("wrapS", "wrapT"):
        tex.CreateInput(wrap, Sdf.ValueTypeNames.Token).Set("clamp")
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    shader.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        tex.ConnectableAPI(), "rgb"
    )
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    image, stats = render_with_stats(stage, samples=256)
    scaled = (tuple(2 * c for c in LEFT), tuple(2 * c for c in RIGHT))
    check_halves(image, stage, intensity, *scaled)
    assert stats["scene"]["lights"][0]["per_face_emission"] is True


def test_a_subset_on_the_meshs_own_material_tints_as_the_mesh_without_a_warning(
    native, caplog
) -> None:
    intensity = 3.0
    stage = stage_with_camera()
    prim = halved_light(stage, intensity)
    bind_emissive(stage, prim, RIGHT, "Base")
    subset = UsdGeom.Subset.CreateGeomSubset(
        UsdGeom.Mesh(prim), "Left", UsdGeom.Tokens.face, [0], "materialBind"
    )
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(
        UsdShade.Material(stage.GetPrimAtPath("/Looks/Base"))
    )
    with caplog.at_level(logging.WARNING):
        image, stats = render_with_stats(stage)
    assert not [r for r in caplog.records if "GeomSubset" in r.message]
    x, y = floor_xy(image, stage)
    truth = intensity * (lambert_rect(x, y, -HALF, 0.0) + lambert_rect(x, y, 0.0, HALF))
    for c in range(3):
        if RIGHT[c] == 0.0:
            assert float(np.abs(image[..., c]).max()) == 0.0
            continue
        mean, worst = relative_error(image[..., c], RIGHT[c] * truth * ALBEDO / math.pi)
        assert abs(mean) < 0.01 and worst < 0.08, (c, mean, worst)
    assert stats["scene"]["lights"][0]["per_face_emission"] is False
