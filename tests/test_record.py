"""mipray-record's command line: frames, complexity, errors and output, with the
fake module standing in for the renderer (no Rust needed)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, UsdGeom

from mipray import record
from mipray.errors import RenderSettingsError
from mipray.image import srgb_encode

from stages import add_camera, add_cube, add_distant_light, new_stage


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    stage = new_stage()
    cube = add_cube(stage, "/World/Cube")
    op = cube.AddRotateYOp()
    op.Set(0.0, 1.0)
    op.Set(90.0, 10.0)
    cam = add_camera(stage, "/World/main_cam", eye=(0, 0, 8))
    cam.CreateHorizontalApertureAttr(36.0)
    cam.CreateVerticalApertureAttr(24.0)
    add_distant_light(stage, "/World/Sun")
    stage.SetStartTimeCode(1.0)
    stage.SetEndTimeCode(10.0)
    path = tmp_path / "scene.usda"
    stage.GetRootLayer().Export(str(path))
    return path


def run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = record.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    "level, factor", [("low", 4.0), ("medium", 2.0), ("high", 1.0), ("veryhigh", 0.5)]
)
def test_complexity_maps_to_tess_factor(level: str, factor: float) -> None:
    args = record.build_parser().parse_args(["in.usda", "out.exr", "--complexity", level])
    # mipray-record hides domes from the camera unless asked, as usdrecord.
    assert record.render_settings(args) == {"tessFactor": factor, "domeLightCameraVisibility": 0}


def test_tess_factor_overrides_complexity_and_flags_become_settings() -> None:
    args = record.build_parser().parse_args(
        [
            "in.usda",
            "out.exr",
            "-c",
            "low",
            "--tess-factor",
            "0.25",
            "--samples",
            "4",
            "--seed",
            "7",
            "--threads",
            "2",
            "--geometry-cache-mb",
            "30",
            "--cache-mode",
            "single",
        ]
    )
    assert record.render_settings(args) == {
        "tessFactor": 0.25,
        "samples": 4,
        "seed": 7,
        "threads": 2,
        "geometryCacheMb": 30.0,
        "cacheMode": "single",
        "domeLightCameraVisibility": 0,
    }


def test_integrator_and_free_settings_become_settings() -> None:
    args = record.build_parser().parse_args(
        [
            "in.usda",
            "out.exr",
            "--integrator",
            "path",
            "--setting",
            "aoSamples=16",
            "--setting",
            "irradianceCacheError = 0.1",
            "--setting",
            "textureFilter=finest",
        ]
    )
    settings = record.render_settings(args)
    assert settings["integrator"] == "path"
    assert settings["aoSamples"] == 16 and isinstance(settings["aoSamples"], int)
    assert settings["irradianceCacheError"] == 0.1
    assert settings["textureFilter"] == "finest"


def test_a_malformed_setting_is_refused() -> None:
    args = record.build_parser().parse_args(["in.usda", "out.exr", "--setting", "aoSamples"])
    with pytest.raises(RenderSettingsError, match="KEY=VALUE"):
        record.render_settings(args)


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["only_one_arg.usda"], "required"),
        (["a.usda", "b.exr", "--imageWidth", "0"], "must be at least 1"),
        (["a.usda", "b.exr", "--imageWidth", "wide"], "invalid"),
        (["a.usda", "b.exr", "--complexity", "ultra"], "invalid choice"),
        (["a.usda", "b.exr", "--frames", "1:x"], "invalid frame spec"),
        (["a.usda", "b.exr", "--frames", "1:10"], "needs one frame placeholder"),
        (["a.usda", "b.####.exr"], "give --frames"),
        (["a.usda", "b.####.exr", "--frames", "1:2x0.5"], "decimal place"),
        (["a.usda", "b.exr", "--purposes", "render,beauty"], "unknown purpose 'beauty'"),
        (["a.usda", "b.png", "--aovs", "depth"], "needs the color AOV"),
        (["a.usda", "b.####.exr", "--frames", "1:3", "--stats", "s.json"], "frame placeholder"),
        (["a.usda", "b.exr", "--frames", "1", "--defaultTime"], "not allowed with"),
        (["a.usda", "b.exr", "--no-such-flag"], "unrecognized arguments"),
    ],
)
def test_bad_arguments_exit_1_with_one_line(capsys, argv: list[str], fragment: str) -> None:
    code, out, err = run(argv, capsys)
    assert code == 1
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("mipray-record: ")
    assert fragment in err


def test_missing_usd_file_is_one_line_error(capsys, tmp_path: Path, fake_native) -> None:
    code, out, err = run([tmp_path / "nope.usda", tmp_path / "o.exr"], capsys)
    assert code == 1
    assert err == f"mipray-record: {tmp_path / 'nope.usda'}: no such file\n"


def test_unparsable_usd_file_is_one_line_error(capsys, tmp_path: Path, fake_native) -> None:
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef Mesh "x" {{{\n')
    code, _, err = run([bad, tmp_path / "o.exr"], capsys)
    assert code == 1
    assert err.startswith(f"mipray-record: {bad}: ") and err.count("\n") == 1


def test_missing_camera_is_an_error(capsys, scene_file: Path, tmp_path: Path, fake_native) -> None:
    code, _, err = run([scene_file, tmp_path / "o.exr", "--camera", "/World/NoCam"], capsys)
    assert code == 1
    assert err == "mipray-record: /World/NoCam: no such camera prim on the stage\n"


def test_help_lists_defaults(capsys) -> None:
    code, out, _ = run(["--help"], capsys)
    assert code == 0
    for text in (
        "--frames",
        "--imageWidth",
        "default: 960",
        "--complexity",
        "default: high",
        "--aovs",
        "--samples",
        "--cache-mode",
        "--stats",
        "--colorCorrectionMode",
    ):
        assert text in out, text


def test_single_frame_render_writes_and_prints_the_path(
    capsys, scene_file: Path, tmp_path: Path, fake_native
) -> None:
    out_path = tmp_path / "img" / "beauty.exr"
    code, out, err = run(
        [scene_file, out_path, "-w", "96", "--aovs", "color,depth,normal", "--samples", "2"],
        capsys,
    )
    assert (code, err) == (0, "")
    assert out == f"{out_path}\n"
    written = fake_native.written[str(out_path)]
    assert written["order"] == ["color", "depth", "normal"]
    assert written["formats"] == {"color": "half", "depth": "float", "normal": "half"}
    assert written["aovs"]["color"].shape == (64, 96, 3)  # 96 wide, 36:24 aperture
    meta = written["metadata"]
    assert json.loads(meta["mipray:stats"])["render"]["rays"]["camera"] == 96 * 64
    assert meta["mipray:camera"] == "/World/main_cam"
    assert meta["mipray:timeCode"] == 1.0  # the stage's startTimeCode
    assert len(meta["worldtocamera"]) == 16 and len(meta["worldtoscreen"]) == 16
    assert meta["software"].startswith("mipray ")
    # EXR stays linear: the fake renderer's 0..2 ramp is written unchanged.
    np.testing.assert_allclose(written["aovs"]["color"][0, -1], [2.0, 2.0, 2.0])


def test_frames_render_one_image_per_time_code(
    capsys, scene_file: Path, tmp_path: Path, fake_native
) -> None:
    pattern = tmp_path / "seq.####.exr"
    stats = tmp_path / "stats.####.json"
    code, out, err = run(
        [scene_file, pattern, "--frames", "1:5x2", "-w", "32", "--stats", stats], capsys
    )
    assert code == 0, err
    expected = [tmp_path / f"seq.{f:04d}.exr" for f in (1, 3, 5)]
    assert out.splitlines() == [str(p) for p in expected]
    assert all(p.exists() for p in expected)
    times = [fake_native.written[str(p)]["metadata"]["mipray:timeCode"] for p in expected]
    assert times == [1.0, 3.0, 5.0]
    assert json.loads((tmp_path / "stats.0003.json").read_text())["render"]["wall_s"] == 0.01


def test_png_gets_srgb_color_only(
    capsys, scene_file: Path, tmp_path: Path, fake_native, caplog
) -> None:
    png = tmp_path / "beauty.png"
    code, _, err = run([scene_file, png, "-w", "16", "--aovs", "color,depth"], capsys)
    assert code == 0
    assert "holds only the color AOV" in err
    written = fake_native.written[str(png)]
    assert written["order"] == ["color"] and written["formats"] == {"color": "uint8"}
    ramp = np.linspace(0.0, 2.0, 16, dtype=np.float32)
    np.testing.assert_allclose(written["aovs"]["color"][0, :, 0], srgb_encode(ramp), rtol=1e-6)

    raw = tmp_path / "raw.png"
    assert run([scene_file, raw, "-w", "16", "--colorCorrectionMode", "disabled"], capsys)[0] == 0
    np.testing.assert_allclose(fake_native.written[str(raw)]["aovs"]["color"][0, :, 0], ramp)


def test_stats_dash_prints_a_table(capsys, scene_file: Path, tmp_path: Path, fake_native) -> None:
    code, out, _ = run([scene_file, tmp_path / "o.exr", "-w", "8", "--stats", "-"], capsys)
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == str(tmp_path / "o.exr")
    assert any(line.split() == ["render.wall_s", "0.01"] for line in lines)


def test_skipped_prims_still_exit_0(capsys, tmp_path: Path, fake_native) -> None:
    stage = new_stage()
    add_cube(stage, "/Good")
    add_cube(stage, "/Bad", counts=[4, 4, 4])
    add_camera(stage, "/Cam")
    UsdGeom.TetMesh.Define(stage, "/Patch")
    path = tmp_path / "s.usda"
    stage.GetRootLayer().Export(str(path))
    code, out, err = run([path, tmp_path / "o.exr", "-w", "8"], capsys)
    assert code == 0
    assert out == f"{tmp_path / 'o.exr'}\n"
    assert "mipray-record: error: skipping /Bad: faceVertexCounts add up to 12" in err
    assert "mipray-record: warning: skipping 1 prim of unsupported type TetMesh" in err


def test_no_camera_uses_framing_camera_and_camera_light(
    capsys, tmp_path: Path, fake_native
) -> None:
    stage = new_stage()
    add_cube(stage, "/Cube").AddTranslateOp().Set(Gf.Vec3d(0, 1, 0))
    path = tmp_path / "nocam.usda"
    stage.GetRootLayer().Export(str(path))
    code, _, err = run([path, tmp_path / "o.exr", "-w", "8"], capsys)
    assert code == 0
    assert "no camera" in err
    meta = fake_native.written[str(tmp_path / "o.exr")]["metadata"]
    assert meta["mipray:camera"] == "/__mipray_default_camera"


def test_python_dash_m_entry_point(scene_file: Path, tmp_path: Path) -> None:
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-m", "mipray.record", "--imageWidth", "-3", "a.usda", "b.exr"],
        capture_output=True,
        text=True,
        check=False,
        env={**__import__("os").environ, "PYTHONPATH": str(Path(record.__file__).parent.parent)},
    )
    assert result.returncode == 1
    assert result.stderr.startswith("mipray-record: ")


class _Terminal:
    """A stream that says it is a terminal and remembers what was written."""

    def __init__(self) -> None:
        self.text = ""

    def isatty(self) -> bool:
        return True

    def write(self, text: str) -> None:
        self.text += text

    def flush(self) -> None:
        pass


def test_progress_is_drawn_on_a_terminal_only() -> None:
    from pxr import Usd

    term = _Terminal()
    progress = record._Progress(term, total=2)  # type: ignore[arg-type]
    progress.start(1, Usd.TimeCode(101.0))
    progress.update(50, 100)
    progress.clear()
    assert "frame 1/2 (time 101)" in term.text and " 50%" in term.text
    assert "[############............]" in term.text and "ETA" in term.text
    assert term.text.endswith("\r\033[K")

    class _Pipe(_Terminal):
        def isatty(self) -> bool:
            return False

    pipe = _Pipe()
    quiet = record._Progress(pipe, total=1)  # type: ignore[arg-type]
    quiet.start(1, Usd.TimeCode(1.0))
    quiet.update(1, 2)
    quiet.clear()
    assert pipe.text == ""


def test_list_settings_prints_every_renderer_setting(native, capsys) -> None:
    # No scene or output needed, as with --help: one line per setting the renderer takes.
    code, out, err = run(["--list-settings"], capsys)
    assert code == 0 and err == ""
    lines = out.splitlines()
    rows = native.render_settings()
    assert len(lines) == len(rows)
    for line, (key, default, description) in zip(lines, rows, strict=True):
        words = line.split()
        assert words[0] == key and words[1] == (default or "(unset)"), line
        assert line.endswith(description), line
    assert any(line.split()[0] == "irradianceCache" for line in lines)


def test_infinite_settings_and_the_geometry_budget_reach_the_renderer(
    native, capsys, scene_file: Path, tmp_path: Path
) -> None:
    # `inf` is a value of the settings whose range is unbounded above; the geometry budget
    # takes it (no bound) and refuses, in one line with the minimum, a budget below the
    # geometry cache's own.
    base = [scene_file, "--imageWidth", "16", "--camera", "/World/main_cam", "--frames", "1"]
    inf = ["--setting", "aoDistance=inf", "--setting", "geometryMemoryMb=inf"]
    code, _, err = run([*base[:1], tmp_path / "a.exr", *base[1:], *inf], capsys)
    assert code == 0, err
    small = ["--setting", "geometryMemoryMb=5"]
    code, _, err = run([*base[:1], tmp_path / "b.exr", *base[1:], *small], capsys)
    assert code != 0
    lines = [line for line in err.splitlines() if "geometryMemoryMb" in line]
    assert len(lines) == 1 and "it needs at least 30" in lines[0], err


@pytest.mark.parametrize("unboundable", ["inf_point", "skel_root"])
def test_a_prim_usd_cannot_bound_is_left_out_of_the_framing(unboundable: str) -> None:
    # OpenUSD's testUsdviewInfGeom (a point at infinity) and testUsdSkelCache (a SkelRoot
    # whose skeleton has no rest pose, bounded by ±FLT_MAX) framed a camera at infinity: the
    # render stopped on "clippingRange (NaN, NaN)". The framing is the good prims' alone.
    from pxr import Usd, UsdSkel, Vt

    from mipray.usd.camera import framing_camera_arguments

    def framing(with_bad: bool) -> dict:
        stage = new_stage()
        add_cube(stage, "/Cube").AddTranslateOp().Set(Gf.Vec3d(2, 1, 0))
        if with_bad and unboundable == "inf_point":
            mesh = UsdGeom.Mesh.Define(stage, "/Inf")
            inf = float("inf")
            mesh.CreatePointsAttr(Vt.Vec3fArray([(0, 0, 0), (1, 0, 0), (inf, inf, inf)]))
            mesh.CreateFaceVertexCountsAttr([3])
            mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
        elif with_bad:
            UsdSkel.Root.Define(stage, "/Rig")
            UsdSkel.Skeleton.Define(stage, "/Rig/Skel")
        return framing_camera_arguments(stage, Usd.TimeCode.Default(), ("default", "render"))

    good, bad = framing(False), framing(True)
    near, far = bad["clipping_range"]
    assert 0.0 < near < far < 1e3
    np.testing.assert_allclose(bad["transform"], good["transform"])
    assert bad["clipping_range"] == pytest.approx(good["clipping_range"])


def test_a_package_whose_first_file_is_not_usd_says_so(capsys, tmp_path: Path) -> None:
    # OpenUSD's usdMtlx tests ship .usdz packages of .mtlx documents only; usd-core cannot
    # open them, and the error says which file it took for the root layer.
    import zipfile

    package = tmp_path / "looks.usdz"
    with zipfile.ZipFile(package, "w", zipfile.ZIP_STORED) as z:
        z.writestr("Include.mtlx", '<?xml version="1.0"?>\n<materialx version="1.38"/>\n')
    code, _, err = run([package, tmp_path / "o.exr", "-w", "8"], capsys)
    assert code == 1
    assert err == (
        f"mipray-record: {package}: cannot open as a USD layer: its first file, Include.mtlx, "
        "is not a USD layer (a package's first file is its root layer)\n"
    )
