"""``primvars:displayOpacity`` on a prim without a material: partly transparent as
UsdPreviewSurface's ``opacity`` is, each interpolation as authored, against the analytic blend
of the lit front surface and the emissive one seen through it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdShade

import mipray
from mipray.usd import UsdSceneDelegate

from stages import HALF_TAN, add_camera, add_distant_light, add_preview_material, bind, new_stage

#: The emissive backdrop's radiance and the front quad's colour and light.
EMIT = 0.6
COLOR = (0.8, 0.4, 0.2)
SUN = 2.0


def _quad(stage, path: str, half: float, z: float) -> UsdGeom.Mesh:
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([(-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    mesh.CreateSubdivisionSchemeAttr("none")
    return mesh


def _stage(opacity, interpolation: str = "constant", front=None):
    """A lit quad of ``COLOR`` with ``displayOpacity`` before an emissive, unlit backdrop."""
    stage = new_stage()
    back = _quad(stage, "/World/Back", 20.0, 0.0)
    glow = add_preview_material(stage, "/Looks/Glow", (0.0, 0.0, 0.0))
    shader = UsdShade.Shader(stage.GetPrimAtPath("/Looks/Glow/PreviewSurface"))
    shader.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(EMIT))
    # No specular either: the backdrop's radiance is its emission alone.
    shader.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    shader.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.0))
    bind(back.GetPrim(), glow)
    mesh = front(stage) if front else _quad(stage, "/World/Front", 1.0, 2.0)
    api = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    api.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, "constant").Set([COLOR])
    if opacity is not None:
        api.CreatePrimvar("displayOpacity", Sdf.ValueTypeNames.FloatArray, interpolation).Set(
            opacity
        )
    cam = add_camera(stage, "/World/Camera", eye=(0.0, 0.0, 8.0))
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)
    # A point-like sun (angle 0): its light is one direction, so the pixel is exact.
    add_distant_light(stage, "/World/Sun", intensity=SUN).CreateAngleAttr(0.0)
    return stage


def _render(stage, width: int = 32) -> np.ndarray:
    with mipray.RenderSession(stage) as session:
        r = session.render("/World/Camera", width=width, aovs=["color"], camera_light=False)
    return np.asarray(r.aovs["color"][..., :3], dtype=np.float64)


def _blend(alpha):
    """The analytic pixel: ``alpha`` of the lambertian front lit at 45° by a normalized
    distant light (irradiance SUN facing it), the rest the backdrop's emission."""
    front = np.asarray(COLOR) / math.pi * SUN * math.cos(math.radians(45.0))
    return alpha * front + (1.0 - alpha) * EMIT


def _front_pixels(width: int = 32) -> tuple[slice, slice]:
    # The front quad (±1 at z = 2, 6 from the eye) spans ±1/6 · 50/10 = ±0.83 of the half
    # frame: pixels well inside it.
    c = width // 2
    return slice(c - 8, c + 8), slice(c - 8, c + 8)


def test_constant_display_opacity_blends_front_and_back(native) -> None:
    ys, xs = _front_pixels()
    for alpha in (1.0, 0.5, 0.0):
        img = _render(_stage([alpha]))
        np.testing.assert_allclose(
            img[ys, xs], np.broadcast_to(_blend(alpha), img[ys, xs].shape), rtol=1e-4, atol=1e-5
        )
    # Without displayOpacity: opaque, as before.
    img = _render(_stage(None))
    np.testing.assert_allclose(
        img[ys, xs], np.broadcast_to(_blend(1.0), img[ys, xs].shape), rtol=1e-4
    )
    # Outside the front quad: the backdrop.
    np.testing.assert_allclose(img[0, 0], [EMIT] * 3, rtol=1e-4)


def test_vertex_display_opacity_is_interpolated_across_the_quad(native) -> None:
    # Opacity 0 on the left edge, 1 on the right: linear in x over the quad.
    width = 48
    img = _render(_stage([0.0, 1.0, 1.0, 0.0], "vertex"), width)
    xs = (np.arange(width) + 0.5) / width * 2 * HALF_TAN - HALF_TAN
    x_on_quad = xs * 6.0  # the quad lies 6 from the eye
    row = width // 2
    inside = np.abs(x_on_quad) < 0.95
    want = np.stack([_blend((x + 1.0) / 2.0) for x in x_on_quad[inside]])
    np.testing.assert_allclose(img[row, inside], want, rtol=1e-4, atol=1e-5)


def test_uniform_display_opacity_gives_each_face_its_own(native) -> None:
    def two_faces(stage):
        mesh = UsdGeom.Mesh.Define(stage, "/World/Front")
        pts = [(-1, -1, 2), (0, -1, 2), (1, -1, 2), (1, 1, 2), (0, 1, 2), (-1, 1, 2)]
        mesh.CreatePointsAttr(pts)
        mesh.CreateFaceVertexCountsAttr([4, 4])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 4, 5, 1, 2, 3, 4])
        mesh.CreateSubdivisionSchemeAttr("none")
        return mesh

    width = 48
    img = _render(_stage([0.25, 0.75], "uniform", two_faces), width)
    row, c = width // 2, width // 2
    np.testing.assert_allclose(
        img[row, c - 6 : c - 2], np.broadcast_to(_blend(0.25), (4, 3)), rtol=1e-4
    )
    np.testing.assert_allclose(
        img[row, c + 2 : c + 6], np.broadcast_to(_blend(0.75), (4, 3)), rtol=1e-4
    )


def test_a_material_keeps_its_own_opacity(fake) -> None:
    stage = _stage([0.5])
    bind(stage.GetPrimAtPath("/World/Front"), add_preview_material(stage, "/Looks/Red", (1, 0, 0)))
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    material = fake.meshes()["/World/Front"]["material"]
    assert "opacity" not in material or material["opacity"] == 1.0


@pytest.mark.parametrize("interpolation", ["vertex", "faceVarying"])
def test_an_interpolated_display_opacity_crosses_as_a_primvar(fake, interpolation) -> None:
    values = [0.0, 1.0, 1.0, 0.0]
    scene = UsdSceneDelegate(_stage(values, interpolation), fake)
    scene.sync()
    kw = fake.meshes()["/World/Front"]
    assert kw["primvars"]["opacity"]["interpolation"] == interpolation
    np.testing.assert_array_equal(kw["primvars"]["opacity"]["values"].reshape(-1), values)
    assert kw["material"]["ior"] == 1.0
