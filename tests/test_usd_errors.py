"""Bad prims are reported with their path and skipped; the rest of the stage syncs."""

from __future__ import annotations

import logging
import math

import pytest
from pxr import UsdGeom

from mipray.usd import UsdSceneDelegate

from stages import CUBE_POINTS, add_cube, new_stage

BROKEN = {
    "index_out_of_range": (dict(indices=[0, 1, 3, 2] * 5 + [0, 1, 99, 2]), "out of range"),
    "nan_point": (
        dict(points=[*CUBE_POINTS[:5], (math.nan, 0.0, 0.0), *CUBE_POINTS[6:]]),
        "points[5]",
    ),
    "inf_point": (dict(points=[(math.inf, 0, 0), *CUBE_POINTS[1:]]), "not finite"),
    "counts_mismatch": (dict(counts=[4, 4, 4, 4, 4, 3]), "add up to 23"),
    "negative_count": (dict(counts=[4, 4, 4, 4, 4, -4, 8]), "at least 3"),
}
# A Loop mesh with quads is not broken data: it renders unsubdivided with a warning, as Storm
# draws it (test_usd_mesh.test_a_loop_mesh_with_quads_renders_unsubdivided_with_a_warning); the
# delegate itself still refuses such a mesh sent to it (test_mesh_check).


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_mesh_is_reported_and_others_still_sync(fake, caplog, case: str) -> None:
    overrides, fragment = BROKEN[case]
    stage = new_stage()
    add_cube(stage, "/World/Good")
    add_cube(stage, "/World/Broken", **overrides)
    add_cube(stage, "/World/AlsoGood")

    with caplog.at_level(logging.ERROR, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()  # must not raise

    assert set(fake.meshes()) == {"/World/Good", "/World/AlsoGood"}
    assert [e.prim_path for e in scene.delegate_errors] == ["/World/Broken"]
    assert fragment in scene.delegate_errors[0].message
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1
    assert "/World/Broken" in errors[0] and "\n" not in errors[0]


@pytest.mark.parametrize(
    "attrs, fragment",
    [
        (dict(creaseIndices=[0, 1, 2], creaseLengths=[2], creaseSharpnesses=[1.0]), "add up to 2"),
        (
            dict(creaseIndices=[0, 42], creaseLengths=[2], creaseSharpnesses=[1.0]),
            "creaseIndices[1] = 42",
        ),
        (
            dict(creaseIndices=[0, 1], creaseLengths=[2], creaseSharpnesses=[1.0, 2.0, 3.0]),
            "creaseSharpnesses has 3",
        ),
        (dict(cornerIndices=[0, 1], cornerSharpnesses=[1.0]), "cornerSharpnesses has 1"),
        (dict(cornerIndices=[8], cornerSharpnesses=[1.0]), "cornerIndices[0] = 8"),
        (dict(holeIndices=[6]), "holeIndices[0] = 6 is out of range for 6 faces"),
    ],
)
def test_bad_subdivision_tags_are_reported(fake, attrs: dict, fragment: str) -> None:
    stage = new_stage()
    mesh = add_cube(stage, "/Cube")
    for name, value in attrs.items():
        getattr(mesh, f"Create{name[0].upper()}{name[1:]}Attr")(value)
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert fake.meshes() == {}
    assert len(scene.delegate_errors) == 1
    assert fragment in str(scene.delegate_errors[0])
    assert str(scene.delegate_errors[0]).startswith("/Cube: ")


def test_delegate_value_error_is_recorded_not_raised(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/A")
    add_cube(stage, "/B")
    fake.reject.add("/A")
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert set(fake.meshes()) == {"/B"}
    assert [str(e) for e in scene.delegate_errors] == ["/A: rejected by the fake delegate"]


def test_fixing_a_broken_mesh_clears_its_error(fake) -> None:
    stage = new_stage()
    mesh = add_cube(stage, "/Cube", counts=[4, 4, 4, 4, 4, 3])
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    assert len(scene.delegate_errors) == 1
    mesh.GetFaceVertexCountsAttr().Set([4, 4, 4, 4, 4, 4])
    scene.sync()
    assert scene.delegate_errors == []
    assert "/Cube" in fake.meshes()


def test_breaking_a_synced_mesh_removes_it(fake) -> None:
    stage = new_stage()
    mesh = add_cube(stage, "/Cube")
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    mesh.GetFaceVertexIndicesAttr().Set([0] * 23 + [1000])
    scene.sync()
    assert "/Cube" not in fake.prims
    assert [c.method for c in fake.calls_for("/Cube")] == ["set_mesh", "remove"]
    assert scene.delegate_errors[0].prim_path == "/Cube"


def test_unsupported_types_warn_once_per_type(fake, caplog) -> None:
    stage = new_stage()
    # (Implicit gprims, curves and NurbsPatch render now: TetMesh and HermiteCurves do not.)
    for i in range(3):
        UsdGeom.TetMesh.Define(stage, f"/S{i}")
    for i in range(2):
        UsdGeom.HermiteCurves.Define(stage, f"/C{i}")
    UsdGeom.TetMesh.Define(stage, "/Hidden").CreateVisibilityAttr("invisible")
    UsdGeom.Xform.Define(stage, "/JustAGroup")
    stage.DefinePrim("/Untyped")
    add_cube(stage, "/Cube")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
        scene.mark_all_dirty()
        scene.sync()  # a second sync does not repeat the warnings
    warnings = sorted(r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)
    assert warnings == [
        "mipray: skipping 2 prims of unsupported type HermiteCurves",
        "mipray: skipping 3 prims of unsupported type TetMesh",
    ]
    assert set(fake.meshes()) == {"/Cube"}
    assert scene.delegate_errors == []
