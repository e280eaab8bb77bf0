"""What a prim's attributes decide, checked in the rendered image (the real renderer)."""

from __future__ import annotations

import numpy as np
from pxr import Gf, Usd, UsdGeom

import mipray

from stages import add_camera, add_cube, add_distant_light, new_stage

PLACES = {"Left": -1.2, "Middle": 0.0, "Right": 1.2}


def three_cubes() -> Usd.Stage:
    """Three unit cubes in a row in front of a camera at z = 10 (the default 50 mm lens)."""
    stage = new_stage()
    for name, x in PLACES.items():
        add_cube(stage, f"/World/{name}", translate=(x, 0, 0))
    add_camera(stage, "/World/Cam", eye=(0, 0, 10))
    add_distant_light(stage, "/World/Sun")
    return stage


def alpha_at(result: mipray.RenderResult, name: str) -> float:
    """Alpha where the centre of cube ``name``'s front face (z = 0.5) projects."""
    half_width = 9.5 * 20.955 / 2 / 50.0  # scene units visible at the front faces
    col = int((PLACES[name] / half_width + 1.0) * 0.5 * result.width)
    return float(result.aovs["alpha"][result.height // 2, col, 0])


def test_invisible_and_proxy_prims_do_not_render_by_default(native) -> None:
    stage = three_cubes()
    baseline = mipray.render(stage, width=64, aovs=("alpha",))
    assert [alpha_at(baseline, n) for n in PLACES] == [1.0, 1.0, 1.0]

    UsdGeom.Imageable(stage.GetPrimAtPath("/World/Left")).CreateVisibilityAttr("invisible")
    UsdGeom.Imageable(stage.GetPrimAtPath("/World/Right")).CreatePurposeAttr("proxy")
    hidden = mipray.render(stage, width=64, aovs=("alpha",))
    assert [alpha_at(hidden, n) for n in PLACES] == [0.0, 1.0, 0.0]

    with_proxy = mipray.render(stage, width=64, aovs=("alpha",), purposes=("proxy",))
    assert [alpha_at(with_proxy, n) for n in PLACES] == [0.0, 1.0, 1.0]


def test_moving_one_mesh_rebuilds_and_resends_nothing_else(native) -> None:
    stage = three_cubes()
    with mipray.RenderSession(stage) as session:
        first = session.render(width=64, aovs=("alpha",))
        before = dict(session.scene.sync_counts)
        UsdGeom.Xformable(stage.GetPrimAtPath("/World/Right")).GetOrderedXformOps()[0].Set(
            Gf.Vec3d(100, 0, 0)
        )
        second = session.render(width=64, aovs=("alpha",))
        changed = {p for p, n in session.scene.sync_counts.items() if n != before.get(p)}
        assert changed == {"/World/Right"}
        # No mesh was rebuilt, the moved one included: only its transform was sent.
        for name in PLACES:
            assert session.delegate.mesh_sync_count(f"/World/{name}") == 1
    assert alpha_at(first, "Right") == 1.0
    assert alpha_at(second, "Right") == 0.0
    left_half = slice(0, first.width // 2)
    np.testing.assert_array_equal(
        first.aovs["alpha"][:, left_half], second.aovs["alpha"][:, left_half]
    )


def test_broken_prims_are_named_and_the_rest_renders(native) -> None:
    stage = three_cubes()
    # Left: a NaN point. Right: a displayColor of the wrong size. Plus a PointInstancer
    # whose protoIndices point past its prototypes. Only the middle cube is sound.
    left = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Left"))
    left.GetPointsAttr().Set([(float("nan"), 0, 0), *left.GetPointsAttr().Get()[1:]])
    right = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Right"))
    right.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set([(1, 0, 0)] * 5)
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    add_cube(stage, "/World/PI/Protos/Cube")
    pi.CreatePrototypesRel().SetTargets(["/World/PI/Protos/Cube"])
    pi.CreatePositionsAttr([(0, 2, 0), (0, -2, 0)])
    pi.CreateProtoIndicesAttr([0, 1])
    result = mipray.render(stage, width=64, aovs=("alpha",))
    messages = sorted(str(e) for e in result.errors)
    assert messages == [
        "/World/Left: points[0] = (nan, 0.0, 0.0) is not finite",
        "/World/PI: protoIndices[1] = 1 is out of range for 1 prototypes",
        "/World/Right: primvars:displayColor (uniform) has 5 values for 6 faces",
    ]
    assert [alpha_at(result, n) for n in PLACES] == [0.0, 1.0, 0.0]
