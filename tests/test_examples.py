"""The committed examples are what make_examples.py writes, and sync cleanly."""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdLux

import mipray
from mipray.usd import UsdSceneDelegate, read_render_settings

from fake_delegate import face_colors

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def load_generator():
    spec = importlib.util.spec_from_file_location("make_examples", EXAMPLES / "make_examples.py")
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return module


def stage_contents(stage: Usd.Stage) -> dict[str, object]:
    """Every authored attribute value and time sample, by path, to compare stages."""
    root = stage.GetRootLayer().pseudoRoot
    data: dict[str, object] = {"layer": {k: str(root.GetInfo(k)) for k in root.ListInfoKeys()}}
    for prim in stage.Traverse():
        data[str(prim.GetPath())] = prim.GetTypeName()
        for attr in prim.GetAuthoredAttributes():
            samples = attr.GetTimeSamples()
            value = [(t, str(attr.Get(t))) for t in samples] if samples else str(attr.Get())
            data[str(attr.GetPath())] = value
        for rel in prim.GetAuthoredRelationships():
            data[str(rel.GetPath())] = [str(t) for t in rel.GetTargets()]
    return data


@pytest.mark.parametrize("name", sorted(load_generator().EXAMPLES))
def test_committed_example_matches_generator(tmp_path: Path, name: str) -> None:
    load_generator().main([str(tmp_path)])
    committed = Usd.Stage.Open(str(EXAMPLES / name))
    fresh = Usd.Stage.Open(str(tmp_path / name))
    assert stage_contents(committed) == stage_contents(fresh), (
        f"examples/{name} is stale: run `python examples/make_examples.py`"
    )


def test_subdiv_showcase_has_what_it_promises(fake, caplog) -> None:
    stage = Usd.Stage.Open(str(EXAMPLES / "subdiv_showcase.usda"))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake, time=1.0)
        scene.sync()
        camera = scene.resolve_camera()
    assert scene.delegate_errors == []
    assert not caplog.records
    assert camera == "/World/main_cam"
    meshes = fake.meshes()
    assert meshes["/World/Geo/Ground"]["scheme"] == "none"
    cube = meshes["/World/Geo/CreasedCube"]
    assert cube["scheme"] == "catmullClark"
    assert 10.0 in cube["crease_sharpnesses"] and 2.0 in cube["crease_sharpnesses"]
    assert cube["corner_indices"] is not None
    assert meshes["/World/Geo/OpenBall"]["hole_indices"] is not None
    assert len({tuple(face_colors(m)[0]) for m in meshes.values()}) == 4
    lights = {p: c.kwargs for p, c in fake.prims.items() if c.method == "set_distant_light"}
    assert lights["/World/Lights/Sun"]["shadow_enable"] is True
    direction = -lights["/World/Lights/Sun"]["transform"][2, :3]
    assert direction[1] < -0.5 and abs(direction[0]) > 0.1  # down, at an angle
    assert UsdLux.DistantLight(stage.GetPrimAtPath("/World/Lights/Sun"))
    assert UsdGeom.GetStageUpAxis(stage) == "Y"


def test_forest_is_thousands_of_instances_of_a_few_prototypes(fake, caplog) -> None:
    stage = Usd.Stage.Open(str(EXAMPLES / "forest.usda"))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    assert scene.delegate_errors == []
    assert not caplog.records
    assert set(fake.meshes()) == {"/World/Geo/Ground"}
    assert len(fake.prototypes()) == 5  # two trees of two meshes, and a rock
    grove = fake.instancers()["/World/Geo/Forest/Prototypes/Grove"]
    forest = fake.instancers()["/World/Geo/Forest"]
    assert grove["prototype"] and not forest["prototype"]
    trees_and_rocks = 50 * 60
    assert len(forest["proto_indices"]) == 50
    placements = fake.placements()
    assert len(placements) > trees_and_rocks  # a tree is two mesh placements
    assert {p for p, _ in placements} == {"/World/Geo/Ground", *fake.prototypes()}


def test_forest_renders_with_shared_prototypes(native) -> None:
    result = mipray.render(EXAMPLES / "forest.usda", width=64, aovs=("alpha",))
    assert result.errors == []
    scene = result.stats["scene"]
    assert scene["instances"] > 5000
    assert scene["control_faces"] == 5 * 6 + 1  # five prototype cages and the ground
    assert result.aovs["alpha"].mean() > 0.5


def test_render_settings_example_says_how_to_render_itself(fake, caplog) -> None:
    stage = Usd.Stage.Open(str(EXAMPLES / "render_settings.usda"))
    spec = read_render_settings(stage)
    assert spec is not None and spec.path == "/Render/Settings"
    assert spec.resolution == (480, 270)
    assert spec.camera == "/World/Cameras/Closeup"
    assert spec.aovs == ["color", "alpha", "depth", "normal", "primId", "instanceId"]
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    assert scene.delegate_errors == [] and not caplog.records
    block = fake.meshes()["/World/Geo/Block"]
    assert len(np.unique(face_colors(block), axis=0)) == 2  # blue sides, a red top (a GeomSubset)
    torus = fake.meshes()["/World/Geo/Torus"]
    assert len(np.unique(face_colors(torus), axis=0)) == 4  # uniform displayColor
    assert len([p for p, _ in fake.placements() if "Gem" in p or "Prototype" in p]) == 5


def test_render_settings_example_renders_its_aovs(native, tmp_path: Path) -> None:
    from mipray import record

    out = tmp_path / "rs.exr"
    assert record.main([str(EXAMPLES / "render_settings.usda"), str(out), "-w", "120"]) == 0
    pixels, names = native.read_image(str(out))
    assert pixels.shape[:2] == (68, 120)  # the settings' 16:9, 120 wide
    assert {"R", "A", "Z", "N.x", "primId", "instanceId"} <= set(names)
    assert np.isfinite(pixels).all()


def test_curves_example_syncs_every_curve_without_a_warning(fake, caplog) -> None:
    stage = Usd.Stage.Open(str(EXAMPLES / "curves.usda"))
    with caplog.at_level(logging.WARNING, logger="mipray"):
        scene = UsdSceneDelegate(stage, fake)
        scene.sync()
    assert scene.delegate_errors == []
    assert [r.getMessage() for r in caplog.records] == []
    curves = {p: kw["gprim"] for p, kw in fake.meshes().items() if kw["gprim"]["type"] == "Curves"}
    assert set(curves) == {
        "/World/Hair",
        "/World/Tube",
        "/World/Ribbon",
        "/World/Facing",
        "/World/Ring",
        "/World/Spiral",
    }
    assert len(curves["/World/Hair"]["curve_vertex_counts"]) == 2000
    assert curves["/World/Ribbon"]["style"] == curves["/World/Facing"]["style"] == "ribbon"
    assert "normals" in curves["/World/Ribbon"] and "normals" not in curves["/World/Facing"]
    # The spiral's 9 knot spans are 9 Bézier segments.
    assert curves["/World/Spiral"]["curve_vertex_counts"] == [28]
