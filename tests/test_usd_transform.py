"""World transforms: composed xform ops, nesting, time samples, row-vector layout."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, UsdGeom

from mipray.usd import UsdSceneDelegate

from stages import add_cube, new_stage


def translate(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[3, :3] = (x, y, z)
    return m


def rotate_z(degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    m = np.eye(4)
    # Row-vector convention: p' = p @ m rotates p counter-clockwise about +Z.
    m[0, :2] = (c, s)
    m[1, :2] = (-s, c)
    return m


def scale(sx: float, sy: float, sz: float) -> np.ndarray:
    return np.diag([sx, sy, sz, 1.0])


def test_nested_ops_compose_in_usd_order(fake) -> None:
    stage = new_stage()
    parent = UsdGeom.Xform.Define(stage, "/P")
    parent.AddTranslateOp().Set(Gf.Vec3d(10, 0, 0))
    parent.AddRotateZOp().Set(90.0)
    cube = add_cube(stage, "/P/Cube")
    cube.AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    cube.AddScaleOp().Set(Gf.Vec3f(2, 2, 2))

    UsdSceneDelegate(stage, fake).sync()

    m = fake.meshes()["/P/Cube"]["transform"]
    assert m.dtype == np.float64 and m.shape == (4, 4)
    # xformOpOrder [translate, rotate] means p' = p @ R @ T (last op first, row vectors).
    local = scale(2, 2, 2) @ translate(1, 2, 3)
    parent_m = rotate_z(90) @ translate(10, 0, 0)
    np.testing.assert_allclose(m, local @ parent_m, atol=1e-12)
    # The cube's local origin lands where USD says it does.
    origin = np.array([0.0, 0.0, 0.0, 1.0]) @ m
    np.testing.assert_allclose(origin[:3], [10 - 2, 1, 3], atol=1e-12)
    expected = cube.ComputeLocalToWorldTransform(0.0)
    np.testing.assert_allclose(m, np.array(expected), atol=1e-12)


def test_time_samples_are_interpolated_at_the_time_code(fake) -> None:
    stage = new_stage()
    cube = add_cube(stage, "/Cube")
    op = cube.AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1.0)
    op.Set(Gf.Vec3d(4, 0, 0), 5.0)

    UsdSceneDelegate(stage, fake, time=2.0).sync()
    assert fake.meshes()["/Cube"]["transform"][3, 0] == pytest.approx(1.0)

    fake2 = type(fake)()
    UsdSceneDelegate(stage, fake2, time=5.0).sync()
    assert fake2.meshes()["/Cube"]["transform"][3, 0] == pytest.approx(4.0)


def test_reset_xform_stack_ignores_the_parent(fake) -> None:
    stage = new_stage()
    parent = UsdGeom.Xform.Define(stage, "/P")
    parent.AddTranslateOp().Set(Gf.Vec3d(100, 0, 0))
    cube = add_cube(stage, "/P/Cube")
    cube.SetResetXformStack(True)
    cube.AddTranslateOp().Set(Gf.Vec3d(1, 0, 0))
    UsdSceneDelegate(stage, fake).sync()
    np.testing.assert_allclose(fake.meshes()["/P/Cube"]["transform"], translate(1, 0, 0))
