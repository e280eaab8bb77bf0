"""UsdSkel (issue 18, part 3): skinned meshes posed at the render's time code through
usd-core's UsdSkel — a two-joint arm bending between two frames against the analytic
rotation, blend shapes, the framing camera from the posed bounds, and a skeleton whose
joints do not resolve (one warning naming the mesh; its rest pose)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

import mipray
from mipray.usd import UsdSceneDelegate
from mipray.usd.camera import DEFAULT_CAMERA_PATH

from stages import add_camera, add_distant_light, new_stage

ELBOW = np.array([1.0, 0.0, 0.0])
#: The elbow's rotation at frame 2: 90° about +z.
BEND = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # row-vector form


def arm(stage: Usd.Stage, joints=("shoulder", "shoulder/elbow")) -> UsdGeom.Mesh:
    """A 2 × 0.2 × 0.2 box along +x from the shoulder (origin) through the elbow (x = 1),
    under a SkelRoot; points with x > 1.5 follow the elbow, the rest the shoulder. The elbow
    is straight at frame 1 and bent 90° about +z at frame 2."""
    UsdSkel.Root.Define(stage, "/World/Arm")
    skel = UsdSkel.Skeleton.Define(stage, "/World/Arm/Skel")
    skel.CreateJointsAttr(list(joints))
    elbow = Gf.Matrix4d().SetTranslate(Gf.Vec3d(*ELBOW))
    skel.CreateRestTransformsAttr([Gf.Matrix4d(1), elbow])
    skel.CreateBindTransformsAttr([Gf.Matrix4d(1), elbow])
    anim = UsdSkel.Animation.Define(stage, "/World/Arm/Skel/Anim")
    anim.CreateJointsAttr(list(joints))
    anim.CreateTranslationsAttr([Gf.Vec3f(0, 0, 0), Gf.Vec3f(*ELBOW)])
    anim.CreateScalesAttr([Gf.Vec3h(1, 1, 1)] * 2)
    rotations = anim.CreateRotationsAttr()
    rotations.Set([Gf.Quatf(1, 0, 0, 0)] * 2, 1)
    bend = Gf.Quatf(Gf.Rotation(Gf.Vec3d(0, 0, 1), 90).GetQuat())
    rotations.Set([Gf.Quatf(1, 0, 0, 0), bend], 2)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    mesh = UsdGeom.Mesh.Define(stage, "/World/Arm/Mesh")
    points = [(x, y, z) for x in (0.0, 1.0, 2.0) for y in (-0.1, 0.1) for z in (-0.1, 0.1)]
    mesh.CreatePointsAttr(points)
    mesh.CreateExtentAttr([(0, -0.1, -0.1), (2, 0.1, 0.1)])
    counts, indices = [], []
    for s in range(2):
        a, b = 4 * s, 4 * s + 4
        for quad in (
            (a, b, b + 1, a + 1),
            (a + 1, b + 1, b + 3, a + 3),
            (a + 3, b + 3, b + 2, a + 2),
            (a + 2, b + 2, b, a),
        ):
            counts.append(4)
            indices += list(quad)
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(indices)
    mesh.CreateSubdivisionSchemeAttr("none")
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(False, 1).Set([0 if p[0] < 1.5 else 1 for p in points])
    binding.CreateJointWeightsPrimvar(False, 1).Set([1.0] * len(points))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1))
    return mesh


def world_points(args: dict) -> np.ndarray:
    p = args["points"].astype(np.float64)
    return p @ args["transform"][:3, :3] + args["transform"][3, :3]


def bent(rest: np.ndarray) -> np.ndarray:
    """The analytic pose at frame 2: the forearm (x > 1.5) turned 90° about the elbow."""
    out = rest.copy()
    fore = rest[:, 0] > 1.5
    out[fore] = (rest[fore] - ELBOW) @ BEND + ELBOW
    return out


def test_a_skinned_arm_bends_between_two_frames(fake) -> None:
    stage = new_stage()
    mesh = arm(stage)
    rest = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    scene = UsdSceneDelegate(stage, fake, time=1)
    scene.sync()
    assert scene.delegate_errors == []
    np.testing.assert_allclose(world_points(fake.meshes()["/World/Arm/Mesh"]), rest, atol=1e-6)
    scene.set_time(2)
    scene.sync()
    posed = world_points(fake.meshes()["/World/Arm/Mesh"])
    np.testing.assert_allclose(posed, bent(rest), atol=1e-5)
    # The tip's corner (2, 0.1, 0.1) is now above the elbow, at (0.9, 1, 0.1).
    np.testing.assert_allclose(posed[-1], (0.9, 1.0, 0.1), atol=1e-5)
    assert scene.sync_counts["/World/Arm/Mesh"] == 2


def test_the_skeleton_places_the_skinned_points(fake) -> None:
    # UsdSkel's skinned points are in the skeleton's space: the skeleton's transform places
    # them, the mesh's own is ignored.
    stage = new_stage()
    mesh = arm(stage)
    UsdGeom.Xformable(stage.GetPrimAtPath("/World/Arm")).AddTranslateOp().Set((0, 0, 5))
    mesh.AddTranslateOp().Set((100, 0, 0))
    rest = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    UsdSceneDelegate(stage, fake, time=2).sync()
    want = bent(rest) + np.array([0.0, 0.0, 5.0])
    np.testing.assert_allclose(world_points(fake.meshes()["/World/Arm/Mesh"]), want, atol=1e-5)


def test_blend_shapes_apply_before_skinning(fake) -> None:
    stage = new_stage()
    mesh = arm(stage)
    shape = UsdSkel.BlendShape.Define(stage, "/World/Arm/Mesh/Fist")
    tip = [8, 9, 10, 11]  # the four points at x = 2
    shape.CreateOffsetsAttr([Gf.Vec3f(0.5, 0, 0)] * 4)
    shape.CreatePointIndicesAttr(Vt.IntArray(tip))
    binding = UsdSkel.BindingAPI(mesh.GetPrim())
    binding.CreateBlendShapesAttr(["fist"])
    binding.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/World/Arm/Skel/Anim"))
    anim.CreateBlendShapesAttr(["fist"])
    weights = anim.CreateBlendShapeWeightsAttr()
    weights.Set(Vt.FloatArray([0.0]), 1)
    weights.Set(Vt.FloatArray([1.0]), 2)
    rest = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    UsdSceneDelegate(stage, fake, time=2).sync()
    shaped = rest.copy()
    shaped[tip, 0] += 0.5
    # The forearm, half a unit longer, then bent: the tip reaches y = 1.5.
    got = world_points(fake.meshes()["/World/Arm/Mesh"])
    np.testing.assert_allclose(got, bent(shaped), atol=1e-5)
    assert got[:, 1].max() > 1.49


def _misordered(stage: Usd.Stage, mesh: UsdGeom.Mesh) -> None:
    # The elbow before its parent: UsdSkel's topology is invalid.
    order = ["shoulder/elbow", "shoulder"]
    UsdSkel.Skeleton(stage.GetPrimAtPath("/World/Arm/Skel")).GetJointsAttr().Set(order)


def _missing(stage: Usd.Stage, mesh: UsdGeom.Mesh) -> None:
    UsdSkel.BindingAPI(mesh.GetPrim()).GetSkeletonRel().SetTargets(["/World/Arm/Nothing"])


def _out_of_range(stage: Usd.Stage, mesh: UsdGeom.Mesh) -> None:
    UsdSkel.BindingAPI(mesh.GetPrim()).GetJointIndicesPrimvar().Set([5] * 12)


@pytest.mark.parametrize(
    "break_it, problem",
    [
        (_misordered, "the joints of /World/Arm/Skel do not resolve"),
        (_missing, "its skel:skeleton does not resolve to a Skeleton"),
        (_out_of_range, "its jointIndices name joints /World/Arm/Skel does not have"),
    ],
)
def test_a_skeleton_whose_joints_do_not_resolve_warns_once_and_renders_at_rest(
    fake, caplog, break_it, problem
) -> None:
    stage = new_stage()
    mesh = arm(stage)
    break_it(stage, mesh)
    rest = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    UsdGeom.Mesh.Define(stage, "/World/Other").CreatePointsAttr([(0, 0, 0)] * 3)
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake, time=2)
        scene.sync()
        scene.set_time(1)
        scene.sync()
    assert scene.delegate_errors == []
    np.testing.assert_allclose(world_points(fake.meshes()["/World/Arm/Mesh"]), rest, atol=1e-6)
    # The stage audit's own line (deformation blur is not rendered, whatever the pose) is
    # another fact about the prim; the posing problem is said once.
    said = [
        r.getMessage()
        for r in caplog.records
        if "/World/Arm/Mesh" in r.getMessage()
        and not r.getMessage().startswith("mipray: not rendered:")
    ]
    assert said == [
        f"mipray: /World/Arm/Mesh: cannot pose the skinned mesh: {problem}; rendering its rest pose"
    ]


def test_the_framing_camera_frames_the_posed_arm(fake) -> None:
    stage = new_stage()
    arm(stage)
    scene = UsdSceneDelegate(stage, fake, time=2)
    scene.sync()
    scene.default_camera()
    eye = fake.prims[DEFAULT_CAMERA_PATH].kwargs["transform"][3, :3]
    # Posed: the upper arm's x in [0, 1], the tip's corners at x = 1 ∓ 0.1, y = 1: the box
    # x in [0, 1.1], y in [-0.1, 1]; the rest extent's centre would be (1, 0).
    np.testing.assert_allclose(eye[:2], (0.55, 0.45), atol=1e-5)


def test_a_render_shows_the_arm_where_the_pose_puts_it(native) -> None:
    stage = new_stage()
    arm(stage)
    cam = add_camera(stage, "/World/Camera", eye=(1.0, 0.5, 10.0))
    cam.CreateHorizontalApertureAttr(20.0)
    cam.CreateVerticalApertureAttr(20.0)
    add_distant_light(stage, "/World/Sun")
    width = 40

    def pixel(x: float, y: float) -> tuple[int, int]:
        # 50 mm lens, 20 mm film, the arm's plane 10 units away: 4 units across.
        scale = width / 4.0
        return int(width / 2 - (y - 0.5) * scale), int(width / 2 + (x - 1.0) * scale)

    with mipray.RenderSession(stage) as session:
        alpha = {
            t: session.render("/World/Camera", width=width, aovs=["alpha"], time=t).aovs["alpha"][
                ..., 0
            ]
            for t in (1, 2)
        }
    straight, up = pixel(1.8, 0.0), pixel(1.0, 0.8)
    assert alpha[1][straight] == 1.0 and alpha[1][up] == 0.0
    assert alpha[2][straight] == 0.0 and alpha[2][up] == 1.0


def test_a_rigidly_skinned_mesh_blurs_by_its_pose_over_the_shutter(fake) -> None:
    # The whole mesh bound to the elbow (constant joint influences: UsdSkel's rigid
    # deformation), the shutter open from frame 1 to 2: the elbow turns 0° to 90°.
    stage = new_stage()
    mesh = arm(stage)
    binding = UsdSkel.BindingAPI(mesh.GetPrim())
    binding.CreateJointIndicesPrimvar(True, 1).Set([1])
    binding.CreateJointWeightsPrimvar(True, 1).Set([1.0])
    cam = add_camera(stage, "/World/Camera")
    cam.CreateShutterOpenAttr(-0.5)
    cam.CreateShutterCloseAttr(0.5)
    scene = UsdSceneDelegate(stage, fake, time=1.5)
    scene.sync()
    assert scene.unsupported == []  # a rigid pose blurs: nothing left out
    assert scene.update_motion("/World/Camera") == ["/World/Arm/Mesh"]
    call = fake.calls_for("/World/Arm/Mesh")[-1]
    assert call.method == "set_motion"
    times, mats = call.kwargs["times"], call.kwargs["transforms"]
    tip = np.array([2.0, 0.1, 0.1, 1.0])
    for f, m in zip(times, mats, strict=True):
        angle = np.radians(90.0 * f)  # UsdSkel slerps the joint's rotation
        c, s = np.cos(angle), np.sin(angle)
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # row-vector form
        want = (tip[:3] - ELBOW) @ rot + ELBOW
        np.testing.assert_allclose((tip @ m)[:3], want, atol=1e-5)
    assert times[0] == 0.0 and times[-1] == 1.0 and len(times) > 2
