"""mipray.render and RenderSession over the fake module (no Rust needed)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, UsdGeom

import mipray
from mipray.errors import OutputError, PrimError, RenderSettingsError, StageError

from stages import add_camera, add_cube, add_distant_light, new_stage


def scene():
    stage = new_stage()
    add_cube(stage, "/World/Cube")
    add_camera(stage, "/World/Cam")
    add_distant_light(stage, "/World/Sun")
    return stage


def test_render_a_live_stage(fake_native) -> None:
    stage = scene()
    result = mipray.render(stage, width=40, aovs=("color", "depth"), settings={"samples": 2})
    assert result.camera == "/World/Cam"
    assert (result.width, result.height) == (40, 29)  # 40 * 15.2908 / 20.955 = 29.2
    assert result.aovs["depth"].shape == (29, 40, 1)
    assert result.stats["render"]["rays"]["camera"] == 40 * 29
    assert result.errors == []
    assert result.time == 0.0  # the stage's start time code


def test_render_a_file_and_write(fake_native, tmp_path: Path) -> None:
    path = tmp_path / "s.usda"
    stage = scene()  # keep the stage alive: it owns its in-memory root layer
    stage.GetRootLayer().Export(str(path))
    result = mipray.render(str(path), width=8)
    result.write(tmp_path / "o.exr", metadata={"shot": "sq010"})
    written = fake_native.written[str(tmp_path / "o.exr")]
    assert written["metadata"]["shot"] == "sq010"
    assert written["metadata"]["mipray:camera"] == "/World/Cam"
    with pytest.raises(OutputError, match="no AOV named 'depth'"):
        result.write(tmp_path / "o2.exr", aovs=["depth"])


def test_api_errors_are_mipray_errors(fake_native, tmp_path: Path) -> None:
    with pytest.raises(StageError, match="no such file"):
        mipray.render(tmp_path / "missing.usda")
    with pytest.raises(PrimError) as info:
        mipray.render(scene(), camera="/World/Nope")
    assert info.value.prim_path == "/World/Nope"
    with pytest.raises(RenderSettingsError, match="at least 1 pixel"):
        mipray.render(scene(), width=0)
    with pytest.raises(RenderSettingsError, match="unknown AOV"):
        mipray.render(scene(), width=8, aovs=("beauty",))
    with pytest.raises(RenderSettingsError, match="unknown purpose"):
        mipray.render(scene(), width=8, purposes=("beauty",))
    assert issubclass(StageError, mipray.MiprayError)


def test_session_resyncs_only_what_changed(fake_native) -> None:
    stage = scene()
    with mipray.RenderSession(stage) as session:
        session.render(width=8)
        cube = UsdGeom.Xformable(stage.GetPrimAtPath("/World/Cube"))
        cube.AddTranslateOp().Set(Gf.Vec3d(1, 0, 0))
        session.render(width=8)
        assert session.scene.sync_counts == {"/World/Cube": 2, "/World/Cam": 1, "/World/Sun": 1}
        moved = session.delegate.prims["/World/Cube"].kwargs["transform"]
        np.testing.assert_allclose(moved[3, :3], [1, 0, 0])


def test_progress_callback_reaches_the_renderer(fake_native) -> None:
    seen: list[tuple[int, int]] = []
    with mipray.RenderSession(scene()) as session:
        session.render(width=8, progress=lambda done, total: seen.append((done, total)))
    assert seen and seen[-1][0] == seen[-1][1]


def test_a_stage_with_nothing_to_render_says_so_once_a_session(native, caplog) -> None:
    stage = new_stage()
    add_camera(stage, "/World/Cam")
    add_distant_light(stage, "/World/Sun")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        with mipray.RenderSession(stage) as session:
            first = session.render(width=16)
            session.render(width=16)
    said = [r.getMessage() for r in caplog.records if "nothing to render" in r.getMessage()]
    assert said == [
        "mipray: nothing to render: no gprim of the included purposes (default, render) on the "
        "stage; the image holds only what its lights show"
    ]
    assert first.stats["scene"]["instances"] == 0
    caplog.clear()
    add_cube(stage, "/World/Cube")
    with caplog.at_level(logging.WARNING, logger="mipray"):
        with mipray.RenderSession(stage) as session:
            assert session.render(width=16).stats["scene"]["instances"] == 1
    assert not [r for r in caplog.records if "nothing to render" in r.getMessage()]
