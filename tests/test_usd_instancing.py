"""PointInstancers and native instances share their prototypes (fake and real delegate)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

import mipray
from mipray.usd import UsdSceneDelegate

from stages import add_camera, add_cube, add_distant_light, new_stage


def grid_positions(n: int, spacing: float = 0.1) -> np.ndarray:
    """``n`` points on a square grid in z = 0, centred on the origin."""
    side = int(np.ceil(np.sqrt(n)))
    ij = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n]
    pos = np.zeros((n, 3), np.float32)
    pos[:, :2] = (ij - (side - 1) / 2.0) * spacing
    return pos


def point_instancer(
    stage: Usd.Stage,
    path: str,
    positions: np.ndarray,
    *,
    prototypes: tuple[str, ...] = ("Cube",),
    indices: np.ndarray | None = None,
    scale: float = 0.08,
) -> UsdGeom.PointInstancer:
    """A PointInstancer with subdivided-cube prototypes under ``path/Protos``."""
    pi = UsdGeom.PointInstancer.Define(stage, path)
    targets = []
    for name in prototypes:
        mesh = add_cube(stage, f"{path}/Protos/{name}", scheme="catmullClark")
        mesh.AddScaleOp().Set(Gf.Vec3f(scale))
        targets.append(mesh.GetPath())
    pi.CreatePrototypesRel().SetTargets(targets)
    n = len(positions)
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(positions, np.float32)))
    if indices is None:
        indices = np.zeros(n, np.int32)
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(indices, np.int32)))
    return pi


def native_instances(stage: Usd.Stage, n: int, spacing: float = 0.1) -> list[str]:
    """``n`` instanceable prims inheriting a class holding one small subdivided cube."""
    UsdGeom.Xform.Define(stage, "/Classes/Thing")
    stage.GetPrimAtPath("/Classes").SetSpecifier(Sdf.SpecifierClass)
    add_cube(stage, "/Classes/Thing/Body", scheme="catmullClark").AddScaleOp().Set(Gf.Vec3f(0.08))
    UsdGeom.Xform.Define(stage, "/World/Things")
    layer = stage.GetEditTarget().GetLayer()
    paths = []
    with Sdf.ChangeBlock():  # Sdf specs in one change: 10,000 prims in a blink
        for i, p in enumerate(grid_positions(n, spacing)):
            path = f"/World/Things/T{i}"
            spec = Sdf.CreatePrimInLayer(layer, path)
            spec.specifier = Sdf.SpecifierDef
            spec.typeName = "Xform"
            spec.instanceable = True
            spec.inheritPathList.Prepend(Sdf.Path("/Classes/Thing"))
            translate = Sdf.AttributeSpec(spec, "xformOp:translate", Sdf.ValueTypeNames.Double3)
            translate.default = Gf.Vec3d(*map(float, p))
            order = Sdf.AttributeSpec(
                spec, "xformOpOrder", Sdf.ValueTypeNames.TokenArray, Sdf.VariabilityUniform
            )
            order.default = ["xformOp:translate"]
            paths.append(path)
    return paths


def lit(stage: Usd.Stage, eye: tuple[float, float, float] = (0, 0, 20)) -> Usd.Stage:
    add_camera(stage, "/World/Cam", eye=eye)
    add_distant_light(stage, "/World/Sun")
    return stage


# ----------------------------------------------------------------- scene delegate


def test_point_instancer_sends_each_prototype_once(fake) -> None:
    stage = new_stage()
    positions = grid_positions(5, spacing=1.0)
    pi = point_instancer(
        stage, "/World/PI", positions, prototypes=("A", "B"), indices=[0, 1, 0, 1, 0]
    )
    pi.AddTranslateOp().Set(Gf.Vec3d(100, 0, 0))
    pi.CreateInvisibleIdsAttr([2])  # no ids authored: ids are indices
    UsdSceneDelegate(stage, fake).sync()

    assert fake.meshes() == {}  # prototypes under the PointInstancer never render in place
    assert set(fake.prototypes()) == {"/World/PI/Protos/A", "/World/PI/Protos/B"}
    inst = fake.instancers()["/World/PI"]
    assert inst["prototype"] is False
    assert list(inst["proto_indices"]) == [0, 1, 1, 0]  # instance 2 is invisible
    # Prototype root transforms (the meshes' own scale) are in the instances, so the
    # prototype meshes sit at identity in their roots' space.
    np.testing.assert_allclose(fake.prototypes()["/World/PI/Protos/A"]["transform"], np.eye(4))
    placed = fake.placements()
    xs = sorted(m[3, 0] for _, m in placed)
    expected = sorted(positions[[0, 1, 3, 4], 0] + 100.0)
    np.testing.assert_allclose(xs, expected, atol=1e-5)
    assert all(m[0, 0] == pytest.approx(0.08) for _, m in placed)


def test_prototype_with_several_meshes_and_a_nested_instancer(fake) -> None:
    stage = new_stage()
    # A tree prototype: trunk + crown, placed by an inner PointInstancer (a grove) that
    # an outer PointInstancer places three times: 3 groves × 2 trees × 2 meshes.
    outer = UsdGeom.PointInstancer.Define(stage, "/World/Forest")
    grove = UsdGeom.PointInstancer.Define(stage, "/World/Forest/Protos/Grove")
    tree = UsdGeom.Xform.Define(stage, "/World/Forest/Protos/Grove/Protos/Tree")
    add_cube(stage, "/World/Forest/Protos/Grove/Protos/Tree/Trunk")
    add_cube(stage, "/World/Forest/Protos/Grove/Protos/Tree/Crown", translate=(0, 2, 0))
    grove.CreatePrototypesRel().SetTargets([tree.GetPath()])
    grove.CreatePositionsAttr([(0, 0, 0), (5, 0, 0)])
    grove.CreateProtoIndicesAttr([0, 0])
    outer.CreatePrototypesRel().SetTargets([grove.GetPath()])
    outer.CreatePositionsAttr([(0, 0, 0), (0, 0, 100), (0, 0, 200)])
    outer.CreateProtoIndicesAttr([0, 0, 0])
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert scene.delegate_errors == []
    trunk = "/World/Forest/Protos/Grove/Protos/Tree/Trunk"
    crown = "/World/Forest/Protos/Grove/Protos/Tree/Crown"
    assert set(fake.prototypes()) == {trunk, crown}
    assert fake.instancers()["/World/Forest/Protos/Grove"]["prototype"] is True
    placed = fake.placements()
    assert len(placed) == 12
    crowns = sorted(tuple(round(float(c), 6) for c in m[3, :3]) for p, m in placed if p == crown)
    assert crowns == sorted((x, 2.0, z) for x in (0.0, 5.0) for z in (0.0, 100.0, 200.0))


def test_prototype_outside_the_instancer_also_renders_in_place(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/World/Library/Rock")
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    pi.CreatePrototypesRel().SetTargets(["/World/Library/Rock"])
    pi.CreatePositionsAttr([(10, 0, 0)])
    pi.CreateProtoIndicesAttr([0])
    UsdSceneDelegate(stage, fake).sync()
    # As UsdImaging: the rock renders where it is, and once more through the instancer,
    # under a path of the instancer's so the two never collide.
    assert set(fake.meshes()) == {"/World/Library/Rock"}
    assert set(fake.prototypes()) == {"/World/PI.proto0"}
    assert sorted(m[3, 0] for _, m in fake.placements()) == [0.0, 10.0]


def test_prototypes_kept_under_an_over_render_only_through_the_instancer(fake) -> None:
    # OpenUSD's testUsdImagingGLPointInstancer/pi_sibling_pi_over: prototypes under an `over`
    # (so they are not drawn where they stand) render through the instancer, as UsdImaging
    # populates them; nothing renders in place.
    stage = new_stage()
    rock = UsdGeom.Xform.Define(stage, "/World/Library/Rock")
    add_cube(stage, "/World/Library/Rock/Body")
    stage.OverridePrim("/World/Library/Rock/Ghost")  # an over inside: nothing to draw
    # Defining a prim defines its ancestors: make the library an `over` afterwards.
    stage.GetPrimAtPath("/World/Library").SetSpecifier(Sdf.SpecifierOver)
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    pi.CreatePrototypesRel().SetTargets([rock.GetPath()])
    pi.CreatePositionsAttr([(10, 0, 0), (20, 0, 0)])
    pi.CreateProtoIndicesAttr([0, 0])
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert scene.delegate_errors == []
    assert set(fake.meshes()) == set()
    assert set(fake.prototypes()) == {"/World/PI.proto0/Body"}
    assert sorted(m[3, 0] for _, m in fake.placements()) == [10.0, 20.0]


def test_invisible_and_proxy_prims_inside_prototypes_are_left_out(fake) -> None:
    stage = new_stage()
    pi = point_instancer(stage, "/World/PI", grid_positions(2), prototypes=("Shown",))
    root = "/World/PI/Protos/Shown"
    add_cube(stage, f"{root}/Hidden").CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    add_cube(stage, f"{root}/Proxy").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    assert pi
    UsdSceneDelegate(stage, fake).sync()
    assert set(fake.prototypes()) == {root}


@pytest.mark.parametrize(
    "edit, fragment",
    [
        (lambda pi: pi.GetProtoIndicesAttr().Set([0, 3]), "protoIndices[1] = 3 is out of range"),
        (lambda pi: pi.GetProtoIndicesAttr().Set([0, -1]), "protoIndices[1] = -1"),
        (lambda pi: pi.GetPositionsAttr().Set([(0, 0, 0)]), "positions has 1 entries"),
        (
            lambda pi: pi.GetPositionsAttr().Set([(0, 0, 0), (float("nan"), 0, 0)]),
            "positions[1] = (nan, 0.0, 0.0) is not finite",
        ),
        (lambda pi: pi.CreateScalesAttr([(1, 1, 1)] * 3), "scales has 3 entries"),
        (
            lambda pi: pi.GetPrototypesRel().AddTarget("/World/Nowhere"),
            "prototypes[1] </World/Nowhere> is not a prim",
        ),
    ],
)
def test_broken_point_instancer_is_reported_and_others_render(fake, caplog, edit, fragment) -> None:
    stage = new_stage()
    bad = point_instancer(stage, "/World/Bad", grid_positions(2))
    point_instancer(stage, "/World/Good", grid_positions(2))
    add_cube(stage, "/World/Cube")
    edit(bad)
    with caplog.at_level(logging.ERROR, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    assert [e.prim_path for e in scene.delegate_errors] == ["/World/Bad"]
    assert fragment in scene.delegate_errors[0].message, scene.delegate_errors[0].message
    assert "/World/Bad" not in fake.instancers()
    assert set(fake.instancers()) == {"/World/Good"}
    assert set(fake.meshes()) == {"/World/Cube"}
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "/World/Bad" in errors[0] and "\n" not in errors[0]


def test_broken_prototype_mesh_names_itself_and_the_rest_renders(fake) -> None:
    stage = new_stage()
    point_instancer(
        stage, "/World/PI", grid_positions(2), prototypes=("Good", "Bad"), indices=[0, 1]
    )
    UsdGeom.Mesh(stage.GetPrimAtPath("/World/PI/Protos/Bad")).GetFaceVertexIndicesAttr().Set(
        [0] * 23 + [99]
    )
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    assert [e.prim_path for e in scene.delegate_errors] == ["/World/PI/Protos/Bad"]
    assert "faceVertexIndices[23] = 99" in str(scene.delegate_errors[0])
    assert [p for p, _ in fake.placements()] == ["/World/PI/Protos/Good"]


def test_moving_an_instance_resends_only_the_instancer(fake) -> None:
    stage = new_stage()
    paths = native_instances(stage, 3, spacing=1.0)
    point_instancer(stage, "/World/PI", grid_positions(4))
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    set_mesh_calls = len([c for c in fake.calls if c.method == "set_mesh"])
    UsdGeom.Xformable(stage.GetPrimAtPath(paths[1])).GetOrderedXformOps()[0].Set(Gf.Vec3d(0, 9, 0))
    before = dict(scene.sync_counts)
    scene.sync()
    changed = {p for p in scene.sync_counts if scene.sync_counts[p] != before.get(p)}
    prototype = str(stage.GetPrimAtPath(paths[1]).GetPrototype().GetPath())
    assert changed == {paths[1], prototype}  # the instance prim read, its instancer sent
    assert len([c for c in fake.calls if c.method == "set_mesh"]) == set_mesh_calls
    assert 9.0 in [m[3, 1] for _, m in fake.placements()]

    # New positions on the PointInstancer: its instancer only, no mesh.
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/PI"))
    pi.GetPositionsAttr().Set(Vt.Vec3fArray.FromNumpy(grid_positions(4) + 50.0))
    before = dict(scene.sync_counts)
    scene.sync()
    changed = {p for p in scene.sync_counts if scene.sync_counts[p] != before.get(p)}
    assert changed == {"/World/PI"}
    assert len([c for c in fake.calls if c.method == "set_mesh"]) == set_mesh_calls

    # New points on a prototype mesh: that mesh and its instancer.
    cube = UsdGeom.Mesh(stage.GetPrimAtPath("/World/PI/Protos/Cube"))
    cube.GetPointsAttr().Set([(2 * x, y, z) for x, y, z in cube.GetPointsAttr().Get()])
    before = dict(scene.sync_counts)
    scene.sync()
    changed = {p for p in scene.sync_counts if scene.sync_counts[p] != before.get(p)}
    assert changed == {"/World/PI", "/World/PI/Protos/Cube"}


def test_edit_inside_a_native_prototype_resends_that_prototype(fake) -> None:
    stage = new_stage()
    paths = native_instances(stage, 2)
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    body = stage.GetPrimAtPath("/Classes/Thing/Body")
    points = UsdGeom.Mesh(body).GetPointsAttr()
    points.Set([(x, 3 * y, z) for x, y, z in points.Get()])
    scene.sync()
    prototype = str(stage.GetPrimAtPath(paths[0]).GetPrototype().GetPath())
    sent = fake.prototypes()[f"{prototype}/Body"]["points"]
    assert sent[:, 1].max() == pytest.approx(1.5)


def test_point_instancer_time_samples(fake) -> None:
    stage = new_stage()
    pi = point_instancer(stage, "/World/PI", grid_positions(2, spacing=1.0))
    pi.GetPositionsAttr().Set([(0, 0, 0), (1, 0, 0)], 1.0)
    pi.GetPositionsAttr().Set([(0, 10, 0), (1, 10, 0)], 11.0)
    scene = UsdSceneDelegate(stage, fake, time=1.0)
    scene.sync()
    scene.set_time(6.0)
    scene.sync()
    assert scene.sync_counts["/World/PI"] == 2
    assert scene.sync_counts["/World/PI/Protos/Cube"] == 1  # the prototype is not re-sent
    assert sorted(m[3, 1] for _, m in fake.placements()) == pytest.approx([5.0, 5.0])


def test_removing_a_point_instancer_removes_its_prototypes(fake) -> None:
    stage = new_stage()
    point_instancer(stage, "/World/PI", grid_positions(2))
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    stage.RemovePrim("/World/PI")
    scene.sync()
    assert fake.prims.keys() <= {"/World/Cam"}  # nothing of the instancer is left


# ------------------------------------------------------------ the real renderer


def test_ten_thousand_point_instances_cost_one_prototype(native) -> None:
    single = lit(new_stage())
    add_cube(single, "/World/Cube", scheme="catmullClark")
    one = mipray.render(single, width=32, aovs=("alpha",))

    stage = lit(new_stage())
    point_instancer(stage, "/World/PI", grid_positions(10_000))
    result = mipray.render(stage, width=96, aovs=("alpha", "color", "instanceId"))
    assert result.errors == []
    assert result.stats["scene"]["instances"] == 10_000
    assert result.stats["scene"]["subpatches"] == one.stats["scene"]["subpatches"]
    assert result.stats["scene"]["control_faces"] == 6
    covered = result.aovs["alpha"][..., 0] > 0.5
    assert covered.mean() > 0.2, "the 100 × 100 grid of instances fills the middle of the view"
    assert len(np.unique(result.aovs["instanceId"][covered])) > 100
    assert result.aovs["color"][covered].max() > 0.0


def test_ten_thousand_native_instances_cost_one_prototype(native) -> None:
    stage = lit(new_stage())
    native_instances(stage, 10_000)
    result = mipray.render(stage, width=64, aovs=("alpha",))
    assert result.errors == []
    assert result.stats["scene"]["instances"] == 10_000
    assert result.stats["scene"]["control_faces"] == 6
    assert (result.aovs["alpha"][..., 0] > 0.5).mean() > 0.2


def test_moving_an_instance_rebuilds_no_mesh(native) -> None:
    stage = lit(new_stage(), eye=(0, 0, 4))
    paths = native_instances(stage, 2, spacing=1.0)
    with mipray.RenderSession(stage) as session:
        first = session.render(width=48, aovs=("alpha",))
        prototype = str(stage.GetPrimAtPath(paths[0]).GetPrototype().GetPath())
        body = f"{prototype}/Body"
        assert session.delegate.mesh_sync_count(body) == 1
        for path in paths:
            UsdGeom.Xformable(stage.GetPrimAtPath(path)).GetOrderedXformOps()[0].Set(
                Gf.Vec3d(100, 0, 0)
            )
        second = session.render(width=48, aovs=("alpha",))
        assert session.delegate.mesh_sync_count(body) == 1
        assert session.delegate.instancer_update_count(prototype) == 2
    assert first.aovs["alpha"].max() == 1.0
    assert second.aovs["alpha"].max() == 0.0


def test_prims_added_inside_prototypes_render_only_through_instancers(fake) -> None:
    stage = new_stage()
    point_instancer(stage, "/World/PI", grid_positions(3, spacing=1.0))
    paths = native_instances(stage, 2, spacing=1.0)
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    add_cube(stage, "/World/PI/Protos/Cube/Extra")  # a new mesh in the PI's prototype
    add_cube(stage, "/Classes/Thing/Extra")  # and in the native instances' class
    scene.sync()
    assert fake.meshes() == {}  # nothing in place
    prototype = str(stage.GetPrimAtPath(paths[0]).GetPrototype().GetPath())
    placed = [p for p, _ in fake.placements()]
    assert placed.count("/World/PI/Protos/Cube/Extra") == 3
    assert placed.count(f"{prototype}/Extra") == 2


def test_prototype_mesh_removed_from_the_stage_leaves_the_delegate(fake) -> None:
    stage = new_stage()
    point_instancer(stage, "/World/PI", grid_positions(2, spacing=1.0))
    add_cube(stage, "/World/PI/Protos/Cube/Extra")
    scene = UsdSceneDelegate(stage, fake)
    scene.watch()
    scene.sync()
    assert "/World/PI/Protos/Cube/Extra" in fake.prototypes()
    stage.RemovePrim("/World/PI/Protos/Cube/Extra")
    scene.sync()
    assert "/World/PI/Protos/Cube/Extra" not in fake.prims
    assert [p for p, _ in fake.placements()] == ["/World/PI/Protos/Cube"] * 2
