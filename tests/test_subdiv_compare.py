"""mipray-subdiv-compare from Python: the --json schema, OBJ and USD inputs, refusals,
the heatmap, and the console script. Needs the compiled module (``native``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest
from pxr import UsdGeom

from mipray.tools import subdiv_compare

from stages import add_cube, new_stage

SHAPES = Path(__file__).resolve().parent.parent.parent / "shared" / "osd-shapes"

#: Fields the issue asks for, and their types.
REQUIRED = {
    "shape": str,
    "scheme": str,
    "faces": int,
    "max_rel_position_error": float,
    "rms_rel_position_error": float,
    "max_normal_angle_deg": float,
    "max_rel_tessellation_error": dict,
    "max_rel_tessellation_error_by_rate": dict,
    "max_rel_tessellation_error_after_split": dict,
    "watertight": bool,
    "watertight_detail": dict,
    "uniform": dict,
}


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = subdiv_compare.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def check_schema(report: dict) -> None:
    for key, kind in REQUIRED.items():
        assert key in report, key
        value = report[key]
        assert isinstance(value, kind) or (kind is float and isinstance(value, int)), (key, value)
    assert set(report["max_rel_tessellation_error"]) == {"coarse", "medium", "fine"}
    assert set(report["max_rel_tessellation_error_by_rate"]) == {"1", "2", "4", "8", "16"}
    rates = report["max_rel_tessellation_error_by_rate"]
    assert rates["16"] < rates["4"] < rates["1"], rates


@pytest.fixture
def cube_obj() -> Path:
    path = SHAPES / "catmark_cube_creases1.obj"
    if not path.exists():
        pytest.skip(f"{SHAPES} is absent")
    return path


def test_json_from_an_obj_shape_has_the_issue_s_fields(
    native: types.ModuleType, cube_obj: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(["--json", "--quick", cube_obj], capsys)
    assert code == 0, err
    report = json.loads(out)
    check_schema(report)
    assert report["shape"] == "catmark_cube_creases1"
    assert report["scheme"] == "catmullClark" and report["faces"] == 6
    assert report["max_rel_position_error"] <= 1e-5
    assert report["watertight"] is True


def test_a_usd_mesh_is_read_by_prim_path(
    native: types.ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    stage = new_stage()
    cube = add_cube(stage, "/World/Body")
    mesh = UsdGeom.Mesh(cube.GetPrim())
    mesh.CreateCreaseIndicesAttr([0, 1])
    mesh.CreateCreaseLengthsAttr([2])
    mesh.CreateCreaseSharpnessesAttr([3.0])
    path = tmp_path / "scene.usda"
    stage.GetRootLayer().Export(str(path))
    code, out, err = run(["--json", "--quick", f"{path}:/World/Body"], capsys)
    assert code == 0, err
    report = json.loads(out)
    check_schema(report)
    assert report["shape"] == "/World/Body"
    assert report["faces"] == len(mesh.GetFaceVertexCountsAttr().Get())
    assert report["max_rel_position_error"] <= 1e-5 and report["watertight"] is True
    # The table names the prim too.
    code, out, _ = run(["--quick", f"{path}:/World/Body"], capsys)
    assert code == 0 and "/World/Body" in out and "watertight" in out


def test_missing_prims_and_hierarchical_edits_fail_in_one_line(
    native: types.ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    stage = new_stage()
    add_cube(stage, "/World/Body")
    path = tmp_path / "scene.usda"
    stage.GetRootLayer().Export(str(path))
    code, out, err = run(["--json", f"{path}:/World/Nope"], capsys)
    assert code == 1 and out == ""
    assert err.startswith("mipray-subdiv-compare: /World/Nope") and err.count("\n") == 1, err
    hedit = SHAPES / "catmark_square_hedit0.obj"
    if hedit.exists():
        code, out, err = run(["--json", hedit], capsys)
        assert code == 1 and "not supported" in err and "catmark_square_hedit0" in err, err


def test_heatmap_is_written(
    native: types.ModuleType, cube_obj: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    png = tmp_path / "err.png"
    code, _, err = run(["--quick", "--heatmap", png, "--heatmap-rate", "2", cube_obj], capsys)
    assert code == 0, err
    pixels, channels = native.read_image(str(png))
    assert channels[:3] == ["R", "G", "B"] and pixels.shape[0] > 100
    assert pixels.std() > 0.05, "the picture shows something"


def test_usd_input_split_keeps_colons_in_file_paths() -> None:
    assert subdiv_compare.split_usd_input("C:/scenes/a.usda:/World/M") == (
        "C:/scenes/a.usda",
        "/World/M",
    )
    assert subdiv_compare.split_usd_input("shape.obj") is None


def test_console_script_runs(native: types.ModuleType, cube_obj: Path) -> None:
    exe = Path(sys.executable).parent / "mipray-subdiv-compare"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "mipray.tools.subdiv_compare"]
    done = subprocess.run(
        [*cmd, "--json", "--quick", str(cube_obj)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"},
    )
    assert done.returncode == 0, done.stderr
    check_schema(json.loads(done.stdout))
