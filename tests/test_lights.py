"""UsdLux sphere, rect, disk and dome lights: read with their shapes, rendered with soft shadows."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdLux

import mipray
from mipray.usd.light import area_light_arguments


def _stage(light_type: type, **inputs: float) -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    ground = UsdGeom.Mesh.Define(stage, "/World/Ground")
    ground.CreatePointsAttr([(-10, -10, 0), (10, -10, 0), (10, 10, 0), (-10, 10, 0)])
    ground.CreateFaceVertexCountsAttr([4])
    ground.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    ground.CreateSubdivisionSchemeAttr("none")
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, 8))
    light = light_type.Define(stage, "/World/Light")
    light.AddTranslateOp().Set(Gf.Vec3d(0, 0, 3))
    for name, value in inputs.items():
        light.GetPrim().GetAttribute(f"inputs:{name}").Set(value)
    return stage


@pytest.mark.parametrize(
    ("light_type", "kind", "inputs"),
    [
        (UsdLux.SphereLight, "sphere", {"radius": 0.7}),
        (UsdLux.RectLight, "rect", {"width": 2.0, "height": 1.0}),
        (UsdLux.DiskLight, "disk", {"radius": 0.4}),
        (UsdLux.DomeLight, "dome", {}),
    ],
)
def test_area_lights_are_read_with_their_shape(light_type, kind, inputs) -> None:
    stage = _stage(light_type, intensity=2.0, **inputs)
    prim = stage.GetPrimAtPath("/World/Light")
    args = area_light_arguments(prim, Usd.TimeCode.Default(), np.eye(4))
    assert args is not None and args["kind"] == kind and args["intensity"] == 2.0
    for name, value in inputs.items():
        assert args[name] == pytest.approx(value)


def test_a_zero_sized_light_is_an_error_naming_the_prim() -> None:
    stage = _stage(UsdLux.DiskLight, radius=0.0)
    with pytest.raises(mipray.MiprayError, match=r"/World/Light.*radius"):
        area_light_arguments(stage.GetPrimAtPath("/World/Light"), Usd.TimeCode.Default(), np.eye(4))


def test_a_rect_light_lights_the_ground_with_soft_shadows(native) -> None:
    stage = _stage(UsdLux.RectLight, intensity=5.0, width=2.0, height=2.0)
    result = mipray.render(stage, width=32, aovs=("color",))
    centre = result.aovs["color"][16, 16]
    assert centre.sum() > 0.0 and np.isfinite(result.aovs["color"]).all()
    names = [e["name"] for e in result.stats["effects"]["enabled"]]
    assert "soft_shadows" in names, names


def test_a_dome_texture_colours_the_light(native, tmp_path) -> None:
    # A latlong map that is red above the horizon: a ground lit by it turns red.
    from mipray import _mipray

    env = np.zeros((32, 64, 3), dtype=np.float32)
    env[:16, :, 0] = 1.0  # top half (+Y up in the light's space): red sky
    path = tmp_path / "sky.exr"
    _mipray.write_image(str(path), {"color": env}, ["color"], {"color": "float"})
    stage = _stage(UsdLux.DomeLight, intensity=1.0)
    light = stage.GetPrimAtPath("/World/Light")
    light.GetAttribute("inputs:texture:file").Set(str(path))
    # The stage is Z-up: turn the dome so its +Y points up the stage's +Z.
    UsdGeom.Xformable(light).AddRotateXOp().Set(90.0)
    result = mipray.render(stage, width=16, aovs=("color",))
    r, g, b = result.aovs["color"][8, 8]
    assert r > 0.05 and g < 0.2 * r and b < 0.2 * r, (r, g, b)
