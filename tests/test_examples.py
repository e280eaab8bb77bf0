"""The committed examples are what make_examples.py writes, and sync cleanly."""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

import pytest
from pxr import Usd, UsdGeom, UsdLux

from mipray.usd import UsdSceneDelegate

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
    assert len({m["albedo"] for m in meshes.values()}) == 4
    lights = {p: c.kwargs for p, c in fake.prims.items() if c.method == "set_distant_light"}
    assert lights["/World/Lights/Sun"]["shadow_enable"] is True
    direction = -lights["/World/Lights/Sun"]["transform"][2, :3]
    assert direction[1] < -0.5 and abs(direction[0]) > 0.1  # down, at an angle
    assert UsdLux.DistantLight(stage.GetPrimAtPath("/World/Lights/Sun"))
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
