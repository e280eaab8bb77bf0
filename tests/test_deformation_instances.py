"""Deformation motion blur inside instancing prototypes (issue 18): a quad whose points are
time-sampled (or move by velocities) inside a native instance's or a PointInstancer's
prototype deforms in every instance, each instance rendering as the same mesh, not instanced,
at its position (itself held to the analytic coverage of a slide)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel
from test_instance_motion import XS, camera
from test_motion_blur import QUAD
from test_usd_skel import arm, bent

import mipray
from mipray.usd import UsdSceneDelegate

from stages import add_camera, add_cube, new_stage

#: The two instances' x; the quad slides from x − 0.5 to x + 0.5 across the shutter.
PLACES = (-1.0, 1.0)


def _deforming_quad(stage: Usd.Stage, path: str, how: str) -> None:
    """The unit quad at ``path``, its points sliding from x = −0.5 at frame 1 to 0.5 at
    frame 2: time-sampled (``how`` "points") or one sample moved by ``velocities``."""
    points = add_cube(stage, path, scheme="none", **QUAD).GetPointsAttr()
    rest = np.array(QUAD["points"], dtype=np.float32)
    points.Clear()
    if how == "velocities":
        points.Set([Gf.Vec3f(*map(float, p)) for p in rest - np.array([0.5, 0, 0])], 1.0)
        fps = stage.GetTimeCodesPerSecond()
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(path))
        mesh.GetVelocitiesAttr().Set([Gf.Vec3f(fps, 0, 0)] * 4, 1.0)
        return
    for frame, dx in ((1.0, -0.5), (2.0, 0.5)):
        points.Set(
            [Gf.Vec3f(*map(float, p)) for p in rest + np.array([dx, 0, 0], np.float32)], frame
        )


def instanced_stage(kind: str, how: str = "points") -> Usd.Stage:
    """Two instances of the deforming quad at :data:`PLACES`: native instances of a class
    prototype (``kind`` "native"), a PointInstancer's ("points"), or (``kind`` "plain") two
    such meshes under Xforms, not instanced: the truth."""
    stage = new_stage()
    if kind == "native":
        stage.DefinePrim("/Proto", "Xform").SetSpecifier(Sdf.SpecifierClass)
        _deforming_quad(stage, "/Proto/Quad", how)
        for name, x in zip("AB", PLACES, strict=True):
            inst = UsdGeom.Xform.Define(stage, f"/World/{name}")
            inst.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
            inst.GetPrim().GetReferences().AddInternalReference("/Proto")
            inst.GetPrim().SetInstanceable(True)
    elif kind == "points":
        pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
        _deforming_quad(stage, "/World/PI/Protos/Quad", how)
        pi.CreatePrototypesRel().AddTarget("/World/PI/Protos/Quad")
        pi.CreateProtoIndicesAttr([0, 0])
        pi.CreatePositionsAttr([(x, 0, 0) for x in PLACES])
    else:
        for name, x in zip("AB", PLACES, strict=True):
            UsdGeom.Xform.Define(stage, f"/World/{name}").AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
            _deforming_quad(stage, f"/World/{name}/Quad", how)
    camera(stage, (0.0, 1.0))
    return stage


@pytest.mark.parametrize(("kind", "mesh"), [("native", "/__Prototype_1/Quad"), ("points", None)])
def test_a_prototype_mesh_whose_points_move_sends_them_over_the_shutter(fake, kind, mesh) -> None:
    scene = UsdSceneDelegate(instanced_stage(kind), fake, time=1.0)
    scene.sync()
    scene.update_motion("/Cam")
    (path,) = fake.prototypes()
    assert mesh is None or path == mesh
    (call,) = [c for c in fake.calls_for(path) if c.method == "set_deformation"]
    np.testing.assert_array_equal(call.kwargs["times"], [0.0, 1.0])
    rest = np.array(QUAD["points"], dtype=np.float32)
    np.testing.assert_allclose(call.kwargs["points"][0], rest - np.array([0.5, 0, 0]), atol=1e-6)
    np.testing.assert_allclose(call.kwargs["points"][1], rest + np.array([0.5, 0, 0]), atol=1e-6)
    # A shut shutter clears them.
    UsdGeom.Camera(scene.stage.GetPrimAtPath("/Cam")).GetShutterCloseAttr().Set(0.0)
    scene.update_motion("/Cam")
    assert (
        len([c for c in fake.calls_for(path) if c.method == "set_deformation"][-1].kwargs["times"])
        == 0
    )


def _row(stage: Usd.Stage) -> np.ndarray:
    image = mipray.render(stage, "/Cam", 40, settings={"samples": 128}, time=1.0)
    return np.asarray(image.aovs["color"][0, :, 0], dtype=np.float64)


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize("how", ["points", "velocities"])
@pytest.mark.parametrize("kind", ["native", "points"])
def test_each_instance_of_a_deforming_prototype_renders_as_the_mesh_not_instanced(
    kind, how
) -> None:
    got = _row(instanced_stage(kind, how))
    truth = _row(instanced_stage("plain", how))
    # Each instance's quad slides from x − 0.5 to x + 0.5: a pixel at X is covered for
    # 1 − |X − x| of the shutter.
    coverage = sum(np.clip(1.0 - np.abs(XS - x), 0.0, None) for x in PLACES)
    lit = truth[np.argmax(coverage)] / coverage.max()
    assert lit > 0.0
    np.testing.assert_allclose(truth, coverage * lit, atol=0.05 * lit)
    # The same camera samples at the same times: the instances agree far within the noise.
    np.testing.assert_allclose(got, truth, atol=0.01 * lit)


def _alpha(stage: Usd.Stage, width: int = 48, samples: int = 64, time: float = 1.0) -> np.ndarray:
    """The alpha AOV of ``stage`` from /World/Camera."""
    out = mipray.render(
        stage, "/World/Camera", width, aovs=["alpha"], settings={"samples": samples}, time=time
    )
    return np.asarray(out.aovs["alpha"][..., 0], dtype=np.float64)


def skinned_stage(kind: str) -> Usd.Stage:
    """Two instances of test_usd_skel's arm (the elbow straight at frame 1, bent 90° at
    frame 2) at y = −2 and y = 1: native instances whose instance prim is the SkelRoot
    (``kind`` "native", the usual instanced character), a PointInstancer whose prototype root
    is the SkelRoot ("points"), or (``kind`` "plain") the same references not instanced."""
    stage = new_stage()
    arm(stage)
    stage.GetPrimAtPath("/World/Arm").SetSpecifier(Sdf.SpecifierClass)
    places = ((0.0, -2.0, 0.0), (0.0, 1.0, 0.0))
    if kind == "points":
        pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
        stage.DefinePrim("/World/PI/Protos/Arm").GetReferences().AddInternalReference("/World/Arm")
        pi.CreatePrototypesRel().AddTarget("/World/PI/Protos/Arm")
        pi.CreateProtoIndicesAttr([0, 0])
        pi.CreatePositionsAttr(list(places))
    else:
        for name, place in zip("AB", places, strict=True):
            prim = stage.DefinePrim(f"/World/{name}")
            prim.GetReferences().AddInternalReference("/World/Arm")
            UsdGeom.Xformable(prim).AddTranslateOp().Set(Gf.Vec3d(*place))
            prim.SetInstanceable(kind == "native")
    cam = add_camera(stage, "/World/Camera", eye=(1.0, -0.5, 12.0))
    cam.CreateHorizontalApertureAttr(40.0)
    cam.CreateVerticalApertureAttr(40.0)
    cam.CreateShutterOpenAttr(0.0)
    cam.CreateShutterCloseAttr(1.0)
    return stage


@pytest.mark.parametrize("kind", ["native", "points"])
def test_a_skinned_prototype_mesh_is_posed_and_sent_its_pose_over_the_shutter(fake, kind) -> None:
    # At frame 2 the forearm is bent; the prototype mesh carries that pose, relative to its
    # prototype's root (each instance places it), and its deformation over the shutter.
    scene = UsdSceneDelegate(skinned_stage(kind), fake, time=2.0)
    scene.sync()
    (path,) = fake.prototypes()
    args = fake.prototypes()[path]
    rest = np.asarray(
        UsdGeom.Mesh(scene.stage.GetPrimAtPath("/World/Arm/Mesh")).GetPointsAttr().Get()
    )
    posed = args["points"].astype(np.float64) @ args["transform"][:3, :3] + args["transform"][3, :3]
    np.testing.assert_allclose(posed, bent(rest.astype(np.float64)), atol=1e-5)
    scene = UsdSceneDelegate(skinned_stage(kind), fake, time=1.0)
    scene.sync()
    scene.update_motion("/World/Camera")
    (call,) = [c for c in fake.calls_for(path) if c.method == "set_deformation"]
    times, points = call.kwargs["times"], call.kwargs["points"]
    assert times[0] == 0.0 and times[-1] == 1.0 and len(times) > 2
    np.testing.assert_allclose(points[0], rest, atol=1e-5)
    np.testing.assert_allclose(points[-1], bent(rest.astype(np.float64)), atol=1e-5)


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize("kind", ["native", "points"])
def test_each_instance_of_a_skinned_prototype_renders_as_the_arm_not_instanced(kind) -> None:
    got, truth = _alpha(skinned_stage(kind)), _alpha(skinned_stage("plain"))
    # Blurred: the forearms sweep pixels for part of the shutter (the truth itself is held
    # to UsdSkel's swept coverage in test_deformation_blur.py).
    assert np.count_nonzero((truth > 0.15) & (truth < 0.85)) > 20
    # The same camera samples at the same times: equal far within the noise.
    assert np.abs(got - truth).max() < 0.02, np.abs(got - truth).max()


def _crowd(kind: str) -> Usd.Stage:
    """:func:`skinned_stage` as a crowd: the arm's skeleton binds no animation itself; each
    instance prim binds one, A the bending one inside it, B a still one outside."""
    stage = skinned_stage(kind)
    stage.GetPrimAtPath("/World/Arm/Skel").RemoveProperty("skel:animationSource")
    still = UsdSkel.Animation.Define(stage, "/World/Still")
    still.CreateJointsAttr(["shoulder", "shoulder/elbow"])
    still.CreateTranslationsAttr([Gf.Vec3f(0, 0, 0), Gf.Vec3f(1, 0, 0)])
    still.CreateRotationsAttr([Gf.Quatf(1, 0, 0, 0)] * 2)
    still.CreateScalesAttr([Gf.Vec3h(1, 1, 1)] * 2)
    for name, anim in (("A", "/World/A/Skel/Anim"), ("B", "/World/Still")):
        binding = UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(f"/World/{name}"))
        binding.CreateAnimationSourceRel().SetTargets([anim])
    return stage


def test_instances_binding_other_animations_outside_the_prototype_are_posed_apart(
    fake, caplog
) -> None:
    # UsdSkel's instanced crowd: one prototype, an animation bound on each instance prim. The
    # prototype's mesh shows the first instance's pose (A, bent at frame 2); B, binding
    # another animation, is a variant of its own posed through its proxies (still: at rest).
    # It rendered A's pose, with a warning.
    stage = _crowd("native")
    scene = UsdSceneDelegate(stage, fake, time=2.0)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene.sync()
        scene.update_motion("/World/Camera")
    assert not [r for r in caplog.records if "/World/" in r.getMessage()]
    rest = np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Arm/Mesh")).GetPointsAttr().Get())
    poses = []
    for args in fake.prototypes().values():
        p = args["points"].astype(np.float64) @ args["transform"][:3, :3]
        poses.append(p + args["transform"][3, :3])
    assert len(poses) == 2
    bent_pose, rest_pose = bent(rest.astype(np.float64)), rest.astype(np.float64)
    assert sum(np.allclose(p, bent_pose, atol=1e-5) for p in poses) == 1  # A's
    assert sum(np.allclose(p, rest_pose, atol=1e-5) for p in poses) == 1  # B's


@pytest.mark.usefixtures("native")
def test_a_crowd_of_instances_each_binding_its_animation_renders_as_the_plain_references() -> None:
    got, truth = _alpha(_crowd("native"), 96, 16, 2.0), _alpha(_crowd("plain"), 96, 16, 2.0)
    assert np.count_nonzero(truth > 0.5) > 20
    assert np.abs(got - truth).max() < 0.02, np.abs(got - truth).max()


def _rigid(stage: Usd.Stage) -> Usd.Stage:
    """:func:`skinned_stage`'s arm bound whole to the elbow (constant joint influences:
    UsdSkel's rigid deformation), so it turns about the elbow over the shutter."""
    binding = UsdSkel.BindingAPI(stage.GetPrimAtPath("/World/Arm/Mesh"))
    binding.CreateJointIndicesPrimvar(True, 1).Set([1])
    binding.CreateJointWeightsPrimvar(True, 1).Set([1.0])
    return stage


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize("kind", ["native", "points"])
def test_a_rigidly_skinned_prototype_mesh_blurs_in_every_instance(kind) -> None:
    # Outside a prototype a rigid pose is a transform motion; inside one the prototype holds
    # no transform motion of the mesh, and it rendered sharp at the frame's pose. Its points
    # now carry the pose over the shutter: each instance sweeps as the plain arm does.
    got, truth = _alpha(_rigid(skinned_stage(kind))), _alpha(_rigid(skinned_stage("plain")))
    assert np.count_nonzero((truth > 0.15) & (truth < 0.85)) > 20  # the truth is blurred
    assert np.abs(got - truth).max() < 0.02, np.abs(got - truth).max()
