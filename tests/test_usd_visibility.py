"""Visibility, purpose and native instances decide what is synced."""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, UsdGeom

from mipray.usd import UsdSceneDelegate

from stages import add_cube, new_stage


def test_invisible_prims_and_their_subtrees_are_skipped(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Shown")
    add_cube(stage, "/Hidden").CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    add_cube(stage, "/HiddenGroup/Child")
    UsdGeom.Imageable(stage.GetPrimAtPath("/HiddenGroup")).CreateVisibilityAttr("invisible")
    UsdSceneDelegate(stage, fake).sync()
    assert set(fake.meshes()) == {"/Shown"}


def test_proxy_and_guide_purposes_are_skipped_by_default(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Render").CreatePurposeAttr(UsdGeom.Tokens.render)
    add_cube(stage, "/Proxy").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    add_cube(stage, "/Guide").CreatePurposeAttr(UsdGeom.Tokens.guide)
    add_cube(stage, "/Default")
    # Purpose is inherited from an ancestor, also through an untyped prim.
    UsdGeom.Xform.Define(stage, "/ProxyGroup").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    stage.DefinePrim("/ProxyGroup/Untyped")
    add_cube(stage, "/ProxyGroup/Untyped/Cube")
    UsdSceneDelegate(stage, fake).sync()
    assert set(fake.meshes()) == {"/Render", "/Default"}


def test_purposes_include_proxy_when_asked(fake) -> None:
    stage = new_stage()
    add_cube(stage, "/Render").CreatePurposeAttr(UsdGeom.Tokens.render)
    add_cube(stage, "/Proxy").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    UsdGeom.Xform.Define(stage, "/ProxyGroup").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    add_cube(stage, "/ProxyGroup/Cube")
    UsdSceneDelegate(stage, fake, purposes=("default", "proxy")).sync()
    assert set(fake.meshes()) == {"/Proxy", "/ProxyGroup/Cube"}


def test_walk_agrees_with_compute_visibility_and_purpose(fake) -> None:
    stage = new_stage()
    for path, purpose, vis in [
        ("/A", "render", None),
        ("/A/B", None, None),
        ("/A/B/C", "proxy", None),
        ("/A/B/C/D", "render", None),
        ("/E", None, "invisible"),
        ("/E/F", "render", None),
        ("/G", "guide", None),
        ("/G/H", "default", None),
    ]:
        UsdGeom.Xform.Define(stage, path)
        img = UsdGeom.Imageable(stage.GetPrimAtPath(path))
        if purpose:
            img.CreatePurposeAttr(purpose)
        if vis:
            img.CreateVisibilityAttr(vis)
        add_cube(stage, path + "/Mesh")
    UsdSceneDelegate(stage, fake).sync()
    expected = set()
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            img = UsdGeom.Imageable(prim)
            if img.ComputeVisibility() != "invisible" and img.ComputePurpose() in (
                "default",
                "render",
            ):
                expected.add(str(prim.GetPath()))
    assert set(fake.meshes()) == expected
    assert "/A/B/C/D/Mesh" in expected and "/A/B/C/Mesh" not in expected


def test_native_instances_share_their_prototype(fake) -> None:
    stage = new_stage()
    proto = UsdGeom.Xform.Define(stage, "/Prototypes/Thing")
    stage.GetPrimAtPath("/Prototypes").SetSpecifier(Sdf.SpecifierClass)
    add_cube(stage, "/Prototypes/Thing/Body")
    for i in range(3):
        inst = UsdGeom.Xform.Define(stage, f"/World/Thing{i}")
        inst.GetPrim().GetInherits().AddInherit(proto.GetPath())
        inst.AddTranslateOp().Set(Gf.Vec3d(3.0 * i, 0, 0))
        inst.GetPrim().SetInstanceable(True)
    assert stage.GetPrimAtPath("/World/Thing0").IsInstance()
    UsdSceneDelegate(stage, fake).sync()
    assert fake.meshes() == {}  # nothing renders in place
    prototype = str(stage.GetPrimAtPath("/World/Thing0").GetPrototype().GetPath())
    assert set(fake.prototypes()) == {f"{prototype}/Body"}  # one mesh for three instances
    placements = fake.placements()
    assert {p for p, _ in placements} == {f"{prototype}/Body"}
    xs = sorted(m[3, 0] for _, m in placements)
    np.testing.assert_allclose(xs, [0.0, 3.0, 6.0])
