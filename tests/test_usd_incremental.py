"""ObjectsChanged and time changes re-sync only the prims they touch (sync_counts)."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom

from mipray.usd import UsdSceneDelegate

from stages import add_camera, add_cube, add_distant_light, add_preview_material, bind, new_stage


def scene_with_three_cubes(fake):
    stage = new_stage()
    cubes = {
        name: add_cube(stage, f"/World/{name}", translate=(i, 0, 0))
        for i, name in enumerate(("A", "B", "C"))
    }
    add_camera(stage, "/World/Cam")
    add_distant_light(stage, "/World/Sun")
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    assert set(scene.sync_counts.values()) == {1}
    return stage, cubes, scene


def test_transform_edit_resyncs_only_that_prim(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    before = dict(scene.sync_counts)
    cubes["B"].GetOrderedXformOps()[0].Set(Gf.Vec3d(7, 0, 0))
    assert scene.is_dirty
    scene.sync()
    changed = {p for p in scene.sync_counts if scene.sync_counts[p] != before.get(p)}
    assert changed == {"/World/B"}
    np.testing.assert_allclose(fake.meshes()["/World/B"]["transform"][3, :3], [7, 0, 0])
    scene.sync()  # nothing dirty: nothing re-sent
    assert scene.sync_counts["/World/B"] == 2


def test_first_xform_op_on_a_prim_counts_as_a_transform_edit(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    before = dict(scene.sync_counts)
    cubes["C"].AddRotateYOp().Set(30.0)  # a new property: a resync notice
    scene.sync()
    assert {p for p in scene.sync_counts if scene.sync_counts[p] != before[p]} == {"/World/C"}


def test_parent_transform_resyncs_its_subtree_only(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    add_cube(stage, "/Other/D")
    scene.sync()
    before = dict(scene.sync_counts)
    UsdGeom.Xformable(stage.GetPrimAtPath("/World")).AddTranslateOp().Set(Gf.Vec3d(0, 5, 0))
    scene.sync()
    changed = {p for p in scene.sync_counts if scene.sync_counts[p] != before[p]}
    assert changed == {"/World/A", "/World/B", "/World/C", "/World/Cam", "/World/Sun"}
    assert fake.meshes()["/World/A"]["transform"][3, 1] == 5.0


def test_points_edit_resyncs_only_that_mesh(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    before = dict(scene.sync_counts)
    points = np.array(cubes["A"].GetPointsAttr().Get()) * 2.0
    cubes["A"].GetPointsAttr().Set(points.tolist())
    scene.sync()
    assert {p for p in scene.sync_counts if scene.sync_counts[p] != before[p]} == {"/World/A"}
    np.testing.assert_allclose(fake.meshes()["/World/A"]["points"], points)


def test_material_edit_resyncs_the_meshes_bound_to_it(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    material = add_preview_material(stage, "/Looks/Red", (1.0, 0.0, 0.0))
    bind(cubes["A"].GetPrim(), material)
    bind(cubes["C"].GetPrim(), material)
    scene.sync()
    assert tuple(fake.meshes()["/World/A"]["material"]["diffuseColor"]) == (1.0, 0.0, 0.0)
    before = dict(scene.sync_counts)
    shader = stage.GetPrimAtPath("/Looks/Red/PreviewSurface")
    shader.GetAttribute("inputs:diffuseColor").Set(Gf.Vec3f(0.0, 0.5, 0.0))
    scene.sync()
    assert {p for p in scene.sync_counts if scene.sync_counts[p] != before[p]} == {
        "/World/A",
        "/World/C",
    }
    assert tuple(fake.meshes()["/World/C"]["material"]["diffuseColor"]) == (0.0, 0.5, 0.0)


def test_added_removed_and_hidden_prims(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    add_cube(stage, "/World/New")
    scene.sync()
    assert "/World/New" in fake.meshes()
    assert scene.sync_counts["/World/A"] == 1

    stage.RemovePrim("/World/New")
    scene.sync()
    assert "/World/New" not in fake.prims
    assert fake.calls[-1].method == "remove" and fake.calls[-1].path == "/World/New"

    cubes["B"].CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    scene.sync()
    assert "/World/B" not in fake.prims
    cubes["B"].GetVisibilityAttr().Set(UsdGeom.Tokens.inherited)
    scene.sync()
    assert "/World/B" in fake.prims

    stage.GetPrimAtPath("/World/C").SetActive(False)
    scene.sync()
    assert "/World/C" not in fake.prims
    assert scene.sync_counts["/World/A"] == 1  # untouched all along


def test_set_time_resyncs_only_time_varying_prims(fake) -> None:
    stage = new_stage()
    still = add_cube(stage, "/Still")
    moving = add_cube(stage, "/Group/Moving")
    group_op = UsdGeom.Xformable(stage.GetPrimAtPath("/Group")).AddTranslateOp()
    group_op.Set(Gf.Vec3d(0, 0, 0), 1.0)
    group_op.Set(Gf.Vec3d(10, 0, 0), 11.0)
    deforming = add_cube(stage, "/Deforming")
    deforming.GetPointsAttr().Set(still.GetPointsAttr().Get(), 1.0)
    deforming.GetPointsAttr().Set([(x, y + 1, z) for x, y, z in still.GetPointsAttr().Get()], 11.0)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.set_time(6.0)
    scene.sync()
    assert scene.sync_counts == {"/Still": 1, "/Group/Moving": 2, "/Deforming": 2}
    assert fake.meshes()["/Group/Moving"]["transform"][3, 0] == 5.0
    assert moving.GetPath() == Sdf.Path("/Group/Moving")


def test_unwatch_stops_tracking(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    scene.unwatch()
    cubes["A"].GetOrderedXformOps()[0].Set(Gf.Vec3d(9, 9, 9))
    scene.sync()
    assert scene.sync_counts["/World/A"] == 1


def test_transform_edit_sends_only_the_transform(fake) -> None:
    stage, cubes, scene = scene_with_three_cubes(fake)
    cubes["B"].GetOrderedXformOps()[0].Set(Gf.Vec3d(7, 0, 0))
    UsdGeom.Xformable(stage.GetPrimAtPath("/World")).AddRotateYOp().Set(10.0)
    scene.sync()
    # Points and topology are not read or sent again for a move.
    for name in ("A", "B", "C"):
        assert [c.method for c in fake.calls_for(f"/World/{name}")] == ["set_mesh", "set_transform"]
    # A move and a data edit together: the data wins, with the new transform.
    cubes["A"].GetOrderedXformOps()[0].Set(Gf.Vec3d(0, 3, 0))
    cubes["A"].GetPointsAttr().Set([(2 * x, y, z) for x, y, z in cubes["A"].GetPointsAttr().Get()])
    scene.sync()
    assert fake.calls_for("/World/A")[-1].method == "set_mesh"
    assert fake.meshes()["/World/A"]["transform"][3, 1] == pytest.approx(3.0)


def test_animated_transform_sends_only_the_transform(fake) -> None:
    stage = new_stage()
    moving = add_cube(stage, "/Moving")
    op = moving.AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1.0)
    op.Set(Gf.Vec3d(10, 0, 0), 11.0)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.set_time(6.0)
    scene.sync()
    assert [c.method for c in fake.calls_for("/Moving")] == ["set_mesh", "set_transform"]
    assert fake.meshes()["/Moving"]["transform"][3, 0] == pytest.approx(5.0)
