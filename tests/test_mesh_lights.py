"""UsdLux MeshLightAPI: emissive meshes as area lights, rendered from USD against closed forms.

A square mesh light facing a floor from height h lights it with Lambert's exact polygon
irradiance E, so the floor's radiance is albedo · E / π pixel by pixel; the camera sees the
light's emitting side at its radiance and through its back; ``normalize`` divides by the
area; a subdivision mesh light emits from its limit surface; linking and stats as for any light.
"""

from __future__ import annotations

import math

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdLux
from test_lights_shaping_linking import ALBEDO, floor_radius, render, stage_with_camera

import mipray

H = 1.5  # the light's height above the floor
HALF = 0.5  # half its side


def square_light(stage: Usd.Stage, *, down: bool = True, intensity: float = 3.0) -> Usd.Prim:
    """A HALF-sized square at height H with MeshLightAPI, emitting down (or up)."""
    mesh = UsdGeom.Mesh.Define(stage, "/World/Glow")
    a = HALF
    mesh.CreatePointsAttr([(-a, -a, H), (a, -a, H), (a, a, H), (-a, a, H)])
    mesh.CreateFaceVertexCountsAttr([4])
    # Counter-clockwise seen from above: the right-hand normal is +Z (up).
    mesh.CreateFaceVertexIndicesAttr([0, 3, 2, 1] if down else [0, 1, 2, 3])
    mesh.CreateSubdivisionSchemeAttr("none")
    UsdLux.MeshLightAPI.Apply(mesh.GetPrim())
    UsdLux.LightAPI(mesh.GetPrim()).CreateIntensityAttr(intensity)
    return mesh.GetPrim()


def lambert_square(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Irradiance at floor points (x, y, 0), normal +Z, from the unit-radiance square above.

    Lambert's formula: E = ½ Σ θᵢ (n · γᵢ) over the polygon's edges.
    """
    corners = [(-HALF, -HALF), (HALF, -HALF), (HALF, HALF), (-HALF, HALF)]
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


def floor_xy(image: np.ndarray, stage: Usd.Stage) -> tuple[np.ndarray, np.ndarray]:
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam")).GetCamera()
    height, width = image.shape[:2]
    half = 8.0 * camera.horizontalAperture / (2.0 * camera.focalLength)
    pixel = 2.0 * half / width
    ys, xs = np.mgrid[0:height, 0:width]
    # Image rows run down the screen: +Y up.
    return (xs + 0.5 - width / 2) * pixel, (height / 2 - ys - 0.5) * pixel


def test_a_square_mesh_light_lights_the_floor_with_lamberts_irradiance(native) -> None:
    stage = stage_with_camera()
    intensity = 3.0
    square_light(stage, intensity=intensity)
    # The camera looks down at the light's back: a one-sided light is not seen from behind,
    # so every pixel shows the floor.
    image = render(stage, width=33, samples=64, shadowSamples=4)
    x, y = floor_xy(image, stage)
    truth = intensity * lambert_square(x, y) * ALBEDO / math.pi
    got = image[..., 0]
    lit = truth > 0.05 * truth.max()
    assert lit.sum() > 200
    rel = got[lit] / truth[lit] - 1.0
    # The mean carries no noise to speak of; each pixel a few percent.
    assert abs(float(rel.mean())) < 0.01, float(rel.mean())
    assert float(np.abs(rel).max()) < 0.08, float(np.abs(rel).max())
    # Nothing reaches the floor from the light's back (it faces down: the floor is all in front).
    assert np.isfinite(image).all()


def test_the_camera_sees_the_emitting_side_at_its_radiance_and_normalize_divides_by_area(
    native,
) -> None:
    stage = stage_with_camera(ground=False)
    prim = square_light(stage, down=False, intensity=2.0)
    image = render(stage, width=33)
    r = floor_radius(image, stage)  # distances from the axis, scaled to the floor plane
    # The light's square at height H seen from 8: its half side appears HALF·8/(8−H) wide.
    inside = r < 0.8 * HALF * 8.0 / (8.0 - H)
    assert inside.sum() > 20
    assert np.allclose(image[inside], 2.0, rtol=1e-5)
    UsdLux.LightAPI(prim).CreateNormalizeAttr(True)
    image = render(stage, width=33)
    assert np.allclose(image[inside], 2.0 / (2 * HALF) ** 2, rtol=1e-5)
    # Turned away (emitting down), the camera sees through its back to nothing.
    UsdGeom.Mesh(prim).GetFaceVertexIndicesAttr().Set([0, 3, 2, 1])
    assert float(render(stage, width=33).max()) == 0.0


def test_a_subdivision_mesh_light_emits_from_its_limit_surface(native) -> None:
    # A Catmull-Clark cube's limit surface is a rounded blob inside the cage. Normalized, a
    # closed light's power is π·intensity whatever its shape, so far away (ten sizes) the
    # floor under it sees about the same from the blob as from the cage lit as polygons.
    def floor_value(scheme: str) -> float:
        stage = stage_with_camera()
        cube = UsdGeom.Mesh.Define(stage, "/World/Blob")
        pts = [(x, y, z) for z in (-0.2, 0.2) for y in (-0.2, 0.2) for x in (-0.2, 0.2)]
        cube.CreatePointsAttr(pts)
        cube.CreateFaceVertexCountsAttr([4] * 6)
        cube.CreateFaceVertexIndicesAttr(
            [0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5]
        )
        cube.CreateSubdivisionSchemeAttr(scheme)
        cube.AddTranslateOp().Set(Gf.Vec3d(0, 0, 3.0))
        UsdLux.MeshLightAPI.Apply(cube.GetPrim())
        light = UsdLux.LightAPI(cube.GetPrim())
        light.CreateIntensityAttr(1.0)
        light.CreateNormalizeAttr(True)
        with mipray.RenderSession(stage) as session:
            result = session.render(
                "/World/Cam", width=17, settings={"samples": 32}, camera_light=False
            )
        lights = {entry["name"]: entry for entry in result.stats["scene"]["lights"]}
        entry = lights["/World/Blob"]
        assert entry["kind"] == "mesh" and entry["triangles"] > 0
        image = np.asarray(result.aovs["color"][..., 0], dtype=np.float64)
        # The floor around the blob (the camera sees the blob itself in the middle).
        floor = floor_radius(image, stage) > 1.5
        return float(image[floor].mean()), entry

    polygonal, p_entry = floor_value("none")
    smooth, s_entry = floor_value("catmullClark")
    # The cage: 6 faces, 2 triangles each, area 6 · 0.4²; the limit surface is smaller and
    # finely tessellated (32 triangles a patch; OpenSubdiv isolates the valence-3 corners into
    # more patches than the cage has faces).
    assert p_entry["triangles"] == 12 and math.isclose(p_entry["area"], 6 * 0.16, rel_tol=1e-5)
    assert s_entry["triangles"] % 32 == 0 and s_entry["triangles"] >= 6 * 32
    assert s_entry["area"] < p_entry["area"]
    # Normalized, each emits power π·intensity (a closed surface: radiance / area × area × π)
    # spread over all directions, so the floor three units below sees nearly the same.
    assert polygonal > 0.0 and math.isclose(smooth, polygonal, rel_tol=0.1), (smooth, polygonal)


def test_mesh_lights_are_linked_and_named_in_the_stats(native) -> None:
    stage = stage_with_camera()
    prim = square_light(stage)
    link = UsdLux.LightAPI(prim).GetLightLinkCollectionAPI()
    link.CreateIncludeRootAttr(False)
    link.CreateIncludesRel().AddTarget("/World/Nothing")
    with mipray.RenderSession(stage) as session:
        result = session.render("/World/Cam", width=17, settings={}, camera_light=False)
    # The floor is not in the light's collection: black.
    assert float(np.asarray(result.aovs["color"]).max()) == 0.0
    (entry,) = result.stats["scene"]["lights"]
    assert entry["name"] == "/World/Glow" and entry["kind"] == "mesh"
    assert entry["triangles"] == 2 and math.isclose(entry["area"], 1.0, rel_tol=1e-6)
    assert entry["not_illuminating"] == ["/World/Ground"]
    assert entry["two_sided"] is False


def test_a_geometry_light_makes_its_mesh_a_light_and_letting_go_makes_it_a_surface(
    native,
) -> None:
    stage = stage_with_camera()
    mesh = UsdGeom.Mesh.Define(stage, "/World/Glow")
    a = HALF
    mesh.CreatePointsAttr([(-a, -a, H), (a, -a, H), (a, a, H), (-a, a, H)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 3, 2, 1])  # facing down
    mesh.CreateSubdivisionSchemeAttr("none")
    geometry_light = UsdLux.GeometryLight.Define(stage, "/World/GeoLight")
    geometry_light.CreateIntensityAttr(3.0)
    geometry_light.CreateGeometryRel().AddTarget("/World/Glow")
    with mipray.RenderSession(stage) as session:
        lit = session.render("/World/Cam", width=33, settings={"samples": 64}, camera_light=False)
        (entry,) = lit.stats["scene"]["lights"]
        assert (entry["name"], entry["kind"], entry["triangles"]) == ("/World/Glow", "mesh", 2)
        image = np.asarray(lit.aovs["color"][..., :3], dtype=np.float64)
        x, y = floor_xy(image, stage)
        truth = 3.0 * lambert_square(x, y) * ALBEDO / math.pi
        lit_px = truth > 0.05 * truth.max()
        assert abs(float((image[..., 0][lit_px] / truth[lit_px]).mean()) - 1.0) < 0.01
        # Without the light, the mesh is a grey surface again, lit by nothing: black, and the
        # stage has no light left (no headlight here: camera_light is off).
        stage.RemovePrim("/World/GeoLight")
        dark = session.render("/World/Cam", width=33, settings={}, camera_light=False)
        assert dark.stats["scene"]["lights"] == []
        assert float(np.asarray(dark.aovs["color"]).max()) == 0.0
