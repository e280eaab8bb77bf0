"""UsdLux.PortalLight, rendered: a portal over a room's only opening guides the dome's light
sampling; the image keeps its expectation (the dome contributes what it did) with less noise."""

from __future__ import annotations

import logging

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdLux

import mipray
from mipray.usd.light import portal_arguments

#: The room: x, y in [-2, 2], z in [0, 3]; a 1 × 1 window in the middle of the ceiling.
HALF, TOP, WINDOW = 2.0, 3.0, 0.5


def _quad(stage: Usd.Stage, path: str, corners: list[tuple[float, float, float]]) -> None:
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(corners)
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    mesh.CreateSubdivisionSchemeAttr("none")
    mesh.CreateDoubleSidedAttr(True)


def room(portal: bool, portals_rel: list[str] | None = None) -> Usd.Stage:
    """A closed box room whose only opening is the ceiling window; a uniform dome outside.

    The camera hangs under the ceiling looking down at the floor, so every pixel is lit by
    light through the window (directly, or after bounces off the walls).
    """
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.Xform.Define(stage, "/World")
    h, w, t = HALF, WINDOW, TOP
    _quad(stage, "/World/Floor", [(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)])
    for name, corners in {
        "WallXN": [(-h, -h, 0), (-h, h, 0), (-h, h, t), (-h, -h, t)],
        "WallXP": [(h, -h, 0), (h, -h, t), (h, h, t), (h, h, 0)],
        "WallYN": [(-h, -h, 0), (-h, -h, t), (h, -h, t), (h, -h, 0)],
        "WallYP": [(-h, h, 0), (h, h, 0), (h, h, t), (-h, h, t)],
        # The ceiling as four slabs around the window.
        "CeilN": [(-h, -h, t), (-h, -w, t), (h, -w, t), (h, -h, t)],
        "CeilP": [(-h, w, t), (-h, h, t), (h, h, t), (h, w, t)],
        "CeilW": [(-h, -w, t), (-h, w, t), (-w, w, t), (-w, -w, t)],
        "CeilE": [(w, -w, t), (w, w, t), (h, w, t), (h, -w, t)],
    }.items():
        _quad(stage, f"/World/{name}", corners)
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0.3, -0.2, 2.6))
    cam.CreateFocalLengthAttr(12.0)
    dome = UsdLux.DomeLight.Define(stage, "/World/Sky")
    dome.CreateIntensityAttr(2.0)
    if portal:
        # Its local -Z (down, into the room) is the way light passes; it spans the window.
        window = UsdLux.PortalLight.Define(stage, "/World/Window")
        window.AddTranslateOp().Set(Gf.Vec3d(0, 0, t))
        window.CreateWidthAttr(2 * w)
        window.CreateHeightAttr(2 * w)
    if portals_rel is not None:
        dome.GetPortalsRel().SetTargets(portals_rel)
    return stage


def render(stage: Usd.Stage, samples: int, seed: int = 0) -> mipray.RenderResult:
    with mipray.RenderSession(stage) as session:
        return session.render(
            "/World/Cam",
            width=16,
            settings={"samples": samples, "seed": seed},
            camera_light=False,
        )


def luminance(result: mipray.RenderResult) -> np.ndarray:
    return result.aovs["color"][..., :3].mean(axis=-1)


def test_a_portal_keeps_the_image_and_lowers_its_noise(native) -> None:
    reference = luminance(render(room(portal=False), samples=1024))
    guided = luminance(render(room(portal=True), samples=1024))
    assert np.isfinite(guided).all() and reference.mean() > 0.0
    # Same expectation: the portal changes how the dome is sampled, not what it contributes.
    np.testing.assert_allclose(guided.mean(), reference.mean(), rtol=0.03)
    # Equal (low) sample counts, several seeds: error against the 1024-sample reference.
    errors = {}
    for portal in (False, True):
        errors[portal] = np.mean(
            [
                np.mean((luminance(render(room(portal), samples=4, seed=s)) - reference) ** 2)
                for s in range(1, 4)
            ]
        )
    assert errors[True] < 0.5 * errors[False], errors


def test_stats_name_each_portal_and_a_dome_takes_only_the_portals_it_names(native, caplog) -> None:
    result = render(room(portal=True), samples=1)
    lights = {entry["name"]: entry for entry in result.stats["scene"]["lights"]}
    # A portal is no light of its own: it is listed under the dome it guides.
    assert set(lights) == {"/World/Sky"}
    assert [p["name"] for p in lights["/World/Sky"]["portals"]] == ["/World/Window"]
    assert abs(lights["/World/Sky"]["portals"][0]["area"] - 1.0) < 1e-5
    with caplog.at_level(logging.WARNING):
        result = render(room(portal=True, portals_rel=["/World/Nothing"]), samples=1)
    (sky,) = result.stats["scene"]["lights"]
    assert "portals" not in sky
    text = " ".join(r.getMessage() for r in caplog.records)
    assert "/World/Nothing" in text and "/World/Window" in text, text


def test_portal_sizes_are_checked() -> None:
    stage = room(portal=True)
    prim = stage.GetPrimAtPath("/World/Window")
    args = portal_arguments(prim, Usd.TimeCode.Default(), np.eye(4))
    assert (args["kind"], args["width"], args["height"]) == ("portal", 1.0, 1.0)
    UsdLux.PortalLight(prim).GetWidthAttr().Set(0.0)
    try:
        portal_arguments(prim, Usd.TimeCode.Default(), np.eye(4))
    except mipray.PrimError as exc:
        assert "/World/Window" in str(exc) and "width" in str(exc)
    else:
        raise AssertionError("a zero width was accepted")


def test_a_portals_light_inputs_are_listed_unsupported_and_a_domes_portals_are_read() -> None:
    from mipray.usd.unsupported import audit_stage

    stage = room(portal=True, portals_rel=["/World/Window"])
    UsdLux.PortalLight(stage.GetPrimAtPath("/World/Window")).CreateIntensityAttr(3.0)
    found = audit_stage(stage, Usd.TimeCode.Default(), ("default", "render"))
    assert [(u.prim, u.what) for u in found] == [
        ("/World/Window", "light input inputs:intensity")
    ], found


def test_the_scene_delegate_sends_portals_and_a_domes_portal_targets(fake) -> None:
    from mipray.usd import UsdSceneDelegate

    stage = room(portal=True, portals_rel=["/World/Window"])
    scene = UsdSceneDelegate(stage, fake)
    scene.sync()
    window = fake.prims["/World/Window"].kwargs
    assert (window["kind"], window["width"], window["height"]) == ("portal", 1.0, 1.0)
    np.testing.assert_allclose(np.asarray(window["transform"])[3, :3], (0.0, 0.0, TOP))
    assert fake.prims["/World/Sky"].kwargs["portals"] == ["/World/Window"]
    # A portal is not a light: a stage with portals only is lit from the camera.
    assert "/World/Window" not in scene.light_paths
    # Without the relationship, the dome takes every portal (``portals`` left unset).
    scene = UsdSceneDelegate(room(portal=True), type(fake)())
    scene.sync()
    assert scene.delegate.prims["/World/Sky"].kwargs.get("portals") is None
