"""Authored normals and primvars interpolated as authored (issue 18, part 4): what crosses to
the delegate, what bad data gets, and renders against the closed form — a faceted sphere
with vertex normals shades as the smooth sphere, a gradient along a faceVarying primvar
matches its analytic value at each pixel (on polygonal and OpenSubdiv surfaces)."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from pxr import Sdf, UsdGeom, UsdShade, Vt

import mipray
from mipray.usd import UsdSceneDelegate

from fake_delegate import face_colors
from stages import add_camera, add_distant_light, new_stage

# ------------------------------------------------------------------------ stages


def uv_sphere(stage, path: str, segments: int = 24, rings: int = 12) -> UsdGeom.Mesh:
    """A polygonal (subdivisionScheme none) unit sphere of quads, triangles at the poles."""
    points = [(0.0, 1.0, 0.0)]
    for r in range(1, rings):
        theta = math.pi * r / rings
        for s in range(segments):
            phi = 2 * math.pi * s / segments
            points.append(
                (math.sin(theta) * math.cos(phi), math.cos(theta), -math.sin(theta) * math.sin(phi))
            )
    points.append((0.0, -1.0, 0.0))
    south = len(points) - 1

    def ring(r: int, s: int) -> int:
        return 1 + (r - 1) * segments + s % segments

    counts, indices = [], []
    for s in range(segments):
        counts.append(3)
        indices += [0, ring(1, s), ring(1, s + 1)]
    for r in range(1, rings - 1):
        for s in range(segments):
            counts.append(4)
            indices += [ring(r, s), ring(r + 1, s), ring(r + 1, s + 1), ring(r, s + 1)]
    for s in range(segments):
        counts.append(3)
        indices += [ring(rings - 1, s), south, ring(rings - 1, s + 1)]
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(points)
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(indices)
    mesh.CreateSubdivisionSchemeAttr("none")
    return mesh


def grid(stage, path: str, n: int, scheme: str) -> UsdGeom.Mesh:
    """n × n quads over [-1, 1]² in z = 0, facing +z; face k = row · n + column."""
    xs = np.linspace(-1.0, 1.0, n + 1)
    points = [(float(x), float(y), 0.0) for y in xs for x in xs]
    counts, indices = [], []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            counts.append(4)
            indices += [a, a + 1, a + n + 2, a + n + 1]
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(points)
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(indices)
    mesh.CreateSubdivisionSchemeAttr(scheme)
    return mesh


def _camera(stage, eye=(0.0, 0.0, 8.0)) -> None:
    cam = add_camera(stage, "/World/Camera", eye=eye)
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)


def _render(stage, width: int, aovs: list[str]) -> dict[str, np.ndarray]:
    with mipray.RenderSession(stage) as session:
        r = session.render("/World/Camera", width=width, aovs=aovs, camera_light=False)
    return {k: v[..., 0] if v.shape[-1] == 1 else v for k, v in r.aovs.items()}


def _synced(stage, fake) -> UsdSceneDelegate:
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    return scene


# ------------------------------------------------------- normals: what crosses


def test_primvars_normals_win_over_normals_and_cross_with_their_interpolation(fake) -> None:
    stage = new_stage()
    mesh = grid(stage, "/World/G", 2, "none")
    mesh.CreateNormalsAttr([(0, 0, 1)] * 9)  # per point
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "normals", Sdf.ValueTypeNames.Normal3fArray, UsdGeom.Tokens.uniform
    )
    pv.Set([(1, 0, 0), (0, 1, 0)])
    pv.SetIndices(Vt.IntArray([0, 1, 1, 0]))
    assert _synced(stage, fake).delegate_errors == []
    normals = fake.meshes()["/World/G"]["primvars"]["normals"]
    assert normals["interpolation"] == "uniform"
    # Indexed values arrive flattened: one per face.
    np.testing.assert_array_equal(normals["values"], [(1, 0, 0), (0, 1, 0), (0, 1, 0), (1, 0, 0)])


@pytest.mark.parametrize("interpolation, count", [("vertex", 9), ("faceVarying", 16)])
def test_normals_cross_for_polygonal_meshes_only(fake, interpolation, count) -> None:
    stage = new_stage()
    for scheme in ("none", "catmullClark"):
        mesh = grid(stage, f"/World/{scheme}", 2, scheme)
        mesh.CreateNormalsAttr([(0, 0, 1)] * count)
        mesh.SetNormalsInterpolation(interpolation)
    assert _synced(stage, fake).delegate_errors == []
    got = fake.meshes()["/World/none"]["primvars"]["normals"]
    assert got["interpolation"] == interpolation and got["values"].shape == (count, 3)
    # Subdivision surfaces have their own normals (UsdGeom.Mesh: authored ones are ignored).
    assert fake.meshes()["/World/catmullClark"].get("primvars") is None


@pytest.mark.parametrize(
    "author, fragment",
    [
        (
            lambda m: m.CreateNormalsAttr([(0, 0, 1)] * 5),
            "normals (vertex) has 5 values for 9 points",
        ),
        (
            lambda m: (
                UsdGeom.PrimvarsAPI(m)
                .CreatePrimvar("normals", Sdf.ValueTypeNames.Normal3fArray, "faceVarying")
                .Set([(0, 0, 1)] * 15)
            ),
            "primvars:normals (faceVarying) has 15 values for 16 face-vertices",
        ),
        (
            lambda m: m.CreateNormalsAttr([(0, 0, float("nan"))] * 9),
            "normals[0] = (0.0, 0.0, nan) is not finite",
        ),
    ],
)
def test_bad_normals_warn_once_by_prim_and_attribute_and_the_mesh_shades_faceted(
    fake, caplog, author, fragment
) -> None:
    stage = new_stage()
    author(grid(stage, "/World/Bad", 2, "none"))
    grid(stage, "/World/Good", 2, "none")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = _synced(stage, fake)
    assert scene.delegate_errors == []
    assert set(fake.meshes()) == {"/World/Bad", "/World/Good"}
    assert fake.meshes()["/World/Bad"].get("primvars") is None
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [
        f"mipray: /World/Bad: {fragment}; shading the mesh with its faces' own normals"
    ]


# ------------------------------------------------------------ normals: renders


def _sphere_stage(normals: str | None):
    stage = new_stage()
    mesh = uv_sphere(stage, "/World/Ball")
    if normals is not None:
        points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
        if normals == "vertex":
            mesh.CreateNormalsAttr([tuple(p) for p in points])
            mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        else:  # faceVarying through primvars:normals, indexed by point
            pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
                "normals", Sdf.ValueTypeNames.Normal3fArray, UsdGeom.Tokens.faceVarying
            )
            pv.Set([tuple(p) for p in points])
            pv.SetIndices(Vt.IntArray(list(mesh.GetFaceVertexIndicesAttr().Get())))
    _camera(stage)
    add_distant_light(stage, "/World/Sun")
    return stage


def _normal_error_degrees(r: dict[str, np.ndarray]) -> np.ndarray:
    """Per hit pixel, the angle between the shading normal and the unit sphere's normal
    at the hit (its position, normalized), for pixels away from the silhouette."""
    hit = r["alpha"] == 1.0
    p = r["position"][hit]
    want = p / np.linalg.norm(p, axis=-1, keepdims=True)
    view = np.array([0.0, 0.0, 8.0]) - p
    view /= np.linalg.norm(view, axis=-1, keepdims=True)
    inner = (want * view).sum(-1) > 0.3
    cos = np.clip((r["normal"][hit] * want).sum(-1), -1, 1)
    return np.degrees(np.arccos(cos))[inner]


@pytest.mark.parametrize("normals", ["vertex", "faceVarying"])
def test_a_faceted_sphere_with_authored_normals_shades_as_the_smooth_sphere(
    native, normals
) -> None:
    width = 48
    aovs = ["color", "normal", "position", "alpha"]
    smooth = _render(_sphere_stage(normals), width, aovs)
    faceted = _render(_sphere_stage(None), width, aovs)
    err_smooth = _normal_error_degrees(smooth)
    err_faceted = _normal_error_degrees(faceted)
    assert len(err_smooth) > 300
    # 15° facets: their own normals are up to ~9° off; interpolated ones (measured 0.04°)
    # follow the sphere.
    assert err_faceted.max() > 4.0, err_faceted.max()
    assert err_smooth.max() < 0.25, err_smooth.max()
    # The colour at a pixel: as the exact sphere's (an implicit Sphere under the same light).
    exact = new_stage()
    UsdGeom.Sphere.Define(exact, "/World/Ball").CreateRadiusAttr(1.0)
    _camera(exact)
    add_distant_light(exact, "/World/Sun")
    truth = _render(exact, width, aovs)
    both = (smooth["alpha"] == 1.0) & (truth["alpha"] == 1.0)
    lit = both & (truth["color"][..., 0] > 0.05)
    rel = np.abs(smooth["color"][lit] - truth["color"][lit]) / truth["color"][lit]
    rel_faceted = np.abs(faceted["color"][lit] - truth["color"][lit]) / truth["color"][lit]
    assert np.median(rel) < 0.01 and rel_faceted.max() > 0.05, (np.median(rel), rel.max())


# ------------------------------------------------------------------ primvars


def _gradient(mesh: UsdGeom.Mesh, interpolation: str) -> None:
    """displayColor r = (x + 1) / 2, g = 0.25, and — face-varying — b = 0 on faces left of
    x = 0, 1 right of it (a seam); vertex and varying: b = (y + 1) / 2."""
    points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    fvi = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
    if interpolation == "faceVarying":
        face = np.repeat(np.arange(len(counts)), counts)
        centre_x = np.array([points[fvi[face == f]][:, 0].mean() for f in range(len(counts))])
        p = points[fvi]
        colours = np.stack(
            [(p[:, 0] + 1) / 2, np.full(len(p), 0.25), (centre_x[face] > 0).astype(float)], -1
        )
        # Indexed: the distinct corner colours once each.
        unique, inverse = np.unique(np.round(colours, 6), axis=0, return_inverse=True)
        pv = mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.faceVarying)
        pv.Set([tuple(c) for c in unique])
        pv.SetIndices(Vt.IntArray([int(i) for i in inverse.reshape(-1)]))
    else:
        colours = np.stack(
            [(points[:, 0] + 1) / 2, np.full(len(points), 0.25), (points[:, 1] + 1) / 2], -1
        )
        mesh.CreateDisplayColorPrimvar(interpolation).Set([tuple(c) for c in colours])


def _expected(position: np.ndarray, interpolation: str) -> np.ndarray:
    x, y = position[..., 0], position[..., 1]
    b = (x > 0).astype(float) if interpolation == "faceVarying" else (y + 1) / 2
    return np.stack([(x + 1) / 2, np.full_like(x, 0.25), b], -1)


@pytest.mark.parametrize(
    "scheme, interpolation",
    [
        ("none", "faceVarying"),
        ("none", "vertex"),
        ("none", "varying"),
        ("catmullClark", "faceVarying"),
        ("catmullClark", "vertex"),
    ],
)
def test_a_display_color_gradient_matches_its_analytic_value_at_each_pixel(
    native, scheme, interpolation
) -> None:
    stage = new_stage()
    mesh = grid(stage, "/World/Grid", 4, scheme)
    _gradient(mesh, interpolation)
    _camera(stage, eye=(0.0, 0.0, 4.0))
    add_distant_light(stage, "/World/Sun")
    r = _render(stage, 40, ["albedo", "position", "alpha"])
    hit = r["alpha"] == 1.0
    pos = r["position"][hit]
    # Away from the seam at x = 0, where a pixel's samples straddle two colours.
    clear = np.abs(pos[:, 0]) > 0.06
    assert clear.sum() > 300
    np.testing.assert_allclose(
        r["albedo"][hit][clear], _expected(pos, interpolation)[clear], atol=1e-4
    )


def test_a_primvar_reader_feeding_diffuse_color_is_interpolated(native) -> None:
    stage = new_stage()
    mesh = grid(stage, "/World/Grid", 2, "catmullClark")
    points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "tint", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex
    )
    pv.Set([((x + 1) / 2, 0.5, 0.5) for x, _, _ in points])
    material = UsdShade.Material.Define(stage, "/World/Looks/M")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/M/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    # Specular workflow without specular: the albedo AOV is diffuseColor itself.
    shader.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    shader.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set((0, 0, 0))
    reader = UsdShade.Shader.Define(stage, "/World/Looks/M/Tint")
    reader.CreateIdAttr("UsdPrimvarReader_float3")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("tint")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        reader.ConnectableAPI(), "result"
    )
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    _camera(stage, eye=(0.0, 0.0, 4.0))
    add_distant_light(stage, "/World/Sun")
    r = _render(stage, 32, ["albedo", "position", "alpha"])
    hit = r["alpha"] == 1.0
    x = r["position"][hit][:, 0]
    np.testing.assert_allclose(r["albedo"][hit][:, 0], (x + 1) / 2, atol=3e-3)


def test_a_subset_material_keeps_its_faces_and_the_primvar_shades_the_rest(fake) -> None:
    stage = new_stage()
    mesh = grid(stage, "/World/Grid", 2, "none")
    _gradient(mesh, "vertex")
    material = UsdShade.Material.Define(stage, "/World/Looks/Red")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/Red/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set((1, 0, 0))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    sub = binding.CreateMaterialBindSubset("red", Vt.IntArray([1]))
    UsdShade.MaterialBindingAPI.Apply(sub.GetPrim()).Bind(material)
    assert _synced(stage, fake).delegate_errors == []
    args = fake.meshes()["/World/Grid"]
    # The primvar shades the faces of the mesh's own material.
    np.testing.assert_array_equal(np.flatnonzero(args["face_material_indices"] < 0), [0, 2, 3])
    assert tuple(face_colors(args)[1]) == (1, 0, 0)
