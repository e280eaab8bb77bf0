"""End to end through the compiled renderer: mipray-record and mipray.render.

Every test here needs ``mipray._mipray`` (the ``native`` fixture skips without
it; ``make test`` builds it first, and under CI a missing module fails).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom

import mipray
from mipray.image import srgb_encode
from mipray.usd import UsdSceneDelegate
from mipray.usd.camera import camera_matrices

from fake_delegate import FakeRenderDelegate
from stages import add_camera, add_cube, add_distant_light, new_stage

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "subdiv_showcase.usda"


def subprocess_env() -> dict[str, str]:
    """The environment for child Pythons: they import the same mipray as this one."""
    package_parent = str(Path(mipray.__file__).resolve().parent.parent)
    path = os.environ.get("PYTHONPATH")
    return {**os.environ, "PYTHONPATH": package_parent + (os.pathsep + path if path else "")}


def record_command() -> list[str]:
    """``mipray-record`` installed beside this Python, else ``python -m mipray.record``."""
    script = Path(sys.executable).with_name("mipray-record")
    return [str(script)] if script.exists() else [sys.executable, "-m", "mipray.record"]


def pixel_of(
    stage: Usd.Stage, prim_path: str, width: int, height: int, time: float
) -> tuple[int, int]:
    """The pixel (row, column) where the center of a prim's world bounds projects."""
    scene = UsdSceneDelegate(stage, FakeRenderDelegate(), time=time)
    camera = scene.resolve_camera()
    _, world_to_screen = camera_matrices(scene.cameras[camera])
    box = (
        UsdGeom.BBoxCache(time, ["default", "render"])
        .ComputeWorldBound(stage.GetPrimAtPath(prim_path))
        .ComputeAlignedRange()
    )
    c = box.GetMidpoint()
    s = np.array([c[0], c[1], c[2], 1.0]) @ world_to_screen
    x, y = s[0] / s[3], s[1] / s[3]
    return int((1.0 - y) * 0.5 * height), int((x + 1.0) * 0.5 * width)


def channel(pixels: np.ndarray, names: list[str], name: str) -> np.ndarray:
    return pixels[..., names.index(name)]


def test_record_example_writes_a_readable_exr(native, tmp_path: Path) -> None:
    out = tmp_path / "showcase.exr"
    result = subprocess.run(
        [
            *record_command(),
            str(EXAMPLE),
            str(out),
            "--imageWidth",
            "160",
            "--aovs",
            "color,depth,normal",
            "--stats",
            str(tmp_path / "stats.json"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        env=subprocess_env(),
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == str(out)
    pixels, names = native.read_image(str(out))
    assert pixels.dtype == np.float32
    assert pixels.shape[:2] == (106, 160)  # 36:24 aperture: 106.67, truncated as usdrecord does
    assert names[:3] == ["R", "G", "B"] and "Z" in names and "N.x" in names
    color = pixels[..., :3]
    assert not np.isnan(pixels).any()
    assert np.isfinite(color).all() and color.max() > 0.0

    stage = Usd.Stage.Open(str(EXAMPLE))
    depth = channel(pixels, names, "Z")
    for prim in ("/World/Geo/CreasedCube", "/World/Geo/Torus", "/World/Geo/OpenBall"):
        row, col = pixel_of(stage, prim, 160, 106, 1.0)
        assert color[row, col].sum() > 0.0, f"{prim} is black at pixel {(row, col)}"
        assert np.isfinite(depth[row, col]) and depth[row, col] > 0.0, prim
    assert (tmp_path / "stats.json").exists()


def simple_stage(scheme: str = "none") -> Usd.Stage:
    stage = new_stage()
    add_cube(stage, "/World/Cube", scheme=scheme)
    add_camera(stage, "/World/Cam", eye=(0, 0, 10))
    add_distant_light(stage, "/World/Sun")
    return stage


def test_render_live_stage_depth_and_normal(native) -> None:
    stage = simple_stage()
    result = mipray.render(
        stage, width=64, aovs=("color", "depth", "normal"), settings={"samples": 1, "seed": 1}
    )
    assert result.camera == "/World/Cam"
    h, w = result.height, result.width
    assert (w, h) == (64, int(64 * 15.2908 / 20.955))  # truncated, as usdrecord does
    color, depth, normal = (result.aovs[k] for k in ("color", "depth", "normal"))
    assert color.shape == (h, w, 3) and depth.shape == (h, w, 1) and normal.shape == (h, w, 3)
    assert color.dtype == np.float32
    cy, cx = h // 2, w // 2
    # The polygonal cube's front face is at z = 0.5: 9.5 along the view axis.
    assert depth[cy, cx, 0] == pytest.approx(9.5, abs=1e-3)
    np.testing.assert_allclose(normal[cy, cx], [0, 0, 1], atol=1e-3)
    assert color[cy, cx].sum() > 0.0
    # A miss holds the far clipping distance (USD's default 1e6): no Inf ever reaches the film.
    assert depth[0, 0, 0] == pytest.approx(1.0e6)
    assert not np.isnan(color).any()
    assert isinstance(result.stats, dict) and result.stats


def test_hydra_camera_space_aovs_hold_the_hit_in_camera_space(native) -> None:
    # The cube's front face is the camera-space plane z = -9.5; the camera sits on the world's
    # z axis looking down -z, so Peye = (x, y, -9.5) with x, y the world's, and cameraDepth
    # = -Peye.z = depth. Where nothing is hit: depth the far clip, cameraDepth and Peye 0.
    result = mipray.render(
        simple_stage(), width=64, aovs=("depth", "cameraDepth", "Peye", "position")
    )
    h, w = result.height, result.width
    depth, camera_depth, peye, position = (
        result.aovs[k] for k in ("depth", "cameraDepth", "Peye", "position")
    )
    assert camera_depth.shape == (h, w, 1) and peye.shape == (h, w, 3)
    hit = np.abs(position[..., 2] - 0.5) < 1e-4
    assert hit.sum() > 100
    np.testing.assert_allclose(peye[hit][:, 2], -9.5, atol=1e-3)
    np.testing.assert_allclose(camera_depth[hit][:, 0], 9.5, atol=1e-3)
    np.testing.assert_allclose(peye[hit][:, :2], position[hit][:, :2], atol=1e-4)
    np.testing.assert_array_equal(camera_depth[..., 0], -peye[..., 2])
    assert depth[0, 0, 0] == pytest.approx(1.0e6)
    assert camera_depth[0, 0, 0] == 0.0 and not peye[0, 0].any()


def test_depth_of_field_names_the_camera_prim_that_asked(native) -> None:
    stage = simple_stage()
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
    camera.CreateFStopAttr(2.8)
    camera.CreateFocusDistanceAttr(9.5)
    result = mipray.render(stage, width=16, aovs=("color",))
    why = {e["name"]: e["why"] for e in result.stats["effects"]["enabled"]}
    assert "/World/Cam" in why["depth_of_field"] and "2.8" in why["depth_of_field"], why


def test_session_follows_live_edits(native) -> None:
    stage = simple_stage(scheme="catmullClark")
    with mipray.RenderSession(stage) as session:
        first = session.render(width=48, aovs=("depth",))
        cy, cx = first.height // 2, first.width // 2
        assert np.isfinite(first.aovs["depth"][cy, cx, 0])
        UsdGeom.Xformable(stage.GetPrimAtPath("/World/Cube")).AddTranslateOp().Set(
            Gf.Vec3d(100, 0, 0)
        )
        second = session.render(width=48, aovs=("depth",))
        assert second.aovs["depth"][cy, cx, 0] == pytest.approx(1.0e6)  # a miss: far clip
        assert session.scene.sync_counts["/World/Cube"] == 2
        assert session.scene.sync_counts["/World/Cam"] == 1


def test_broken_prim_is_skipped_and_the_rest_renders(native) -> None:
    stage = simple_stage()
    add_cube(stage, "/World/Broken", counts=[4, 4])
    result = mipray.render(stage, width=32, aovs=("depth",))
    assert [e.prim_path for e in result.errors] == ["/World/Broken"]
    assert np.isfinite(result.aovs["depth"][result.height // 2, result.width // 2, 0])


def test_write_and_read_back(native, tmp_path: Path) -> None:
    result = mipray.render(simple_stage(), width=32, aovs=("color", "depth"))
    exr = tmp_path / "a.exr"
    result.write(exr)
    pixels, names = native.read_image(str(exr))
    assert names == ["R", "G", "B", "Z"]
    np.testing.assert_allclose(pixels[..., :3], result.aovs["color"], rtol=1e-3, atol=1e-3)
    hit = np.isfinite(result.aovs["depth"][..., 0])
    np.testing.assert_allclose(pixels[..., 3][hit], result.aovs["depth"][..., 0][hit], rtol=1e-6)

    png = tmp_path / "a.png"
    result.write(png)
    pixels8, names8 = native.read_image(str(png))
    assert names8 == ["R", "G", "B"]
    expected = srgb_encode(result.aovs["color"])
    np.testing.assert_allclose(pixels8, expected, atol=1.0 / 255 + 1e-6)


def test_missing_native_module_message_is_one_line(monkeypatch) -> None:
    """Without the compiled module, mipray.render fails with a clear one-line error."""
    monkeypatch.setitem(sys.modules, "mipray._mipray", None)
    monkeypatch.delattr(mipray, "_mipray", raising=False)
    with pytest.raises(mipray.MiprayError, match="not installed") as info:
        mipray.render(simple_stage(), width=8)
    assert "\n" not in str(info.value)


def test_record_module_runs_without_console_script(native, tmp_path: Path) -> None:
    out = tmp_path / "m.exr"
    result = subprocess.run(
        [sys.executable, "-m", "mipray.record", str(EXAMPLE), str(out), "-w", "32"],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        env=subprocess_env(),
    )
    assert result.returncode == 0, result.stderr
    assert out.exists()


def test_python_example_script_runs(native, tmp_path: Path) -> None:
    script = EXAMPLE.with_name("render_from_python.py")
    result = subprocess.run(
        [sys.executable, str(script), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        env=subprocess_env(),
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 3
    assert "torus synced 2x, cube 1x" in lines[1]  # the edit re-synced the torus only
    for stem in ("python_first", "python_edited", "python_frame24"):
        assert (tmp_path / f"{stem}.exr").exists() and (tmp_path / f"{stem}.png").exists()
