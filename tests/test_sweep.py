"""mipray-sweep: knobs and their errors, the table's schema, a real sweep on a tiny
scene, a reference of the wrong size, and rows kept when a sweep is interrupted."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from mipray.tools import sweep as sw
from mipray.tools.sweep_report import (
    ROW_FIELDS,
    SCHEMA,
    image_errors,
    pareto_front,
    tess_error_figures,
    write_tables,
)

from stages import add_camera, add_cube, add_distant_light, new_stage

WIDTH = 8  # a few pixels: the whole sweep renders in about a second per row


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    """A subdivision cube (a rounded blob) in front of a camera, under a light."""
    stage = new_stage()
    add_cube(stage, "/World/Blob")
    cam = add_camera(stage, "/World/main_cam", eye=(0, 0, 3))
    cam.CreateHorizontalApertureAttr(24.0)
    cam.CreateVerticalApertureAttr(16.0)
    add_distant_light(stage, "/World/Sun")
    path = tmp_path / "blob.usda"
    stage.GetRootLayer().Export(str(path))
    return path


def run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = sw.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def fake_rendered(height: int, width: int, value: float = 0.5, wall: float = 1.0) -> sw.Rendered:
    aovs = {
        "color": np.full((height, width, 3), value, np.float32),
        "alpha": np.ones((height, width, 1), np.float32),
        "tessError": np.zeros((height, width, 2), np.float32),
    }
    stats = {
        "render": {"wall_s": wall, "ray_subpatch_tests": 10},
        "memory": {"peak_rss_bytes": 123},
        "geometry_cache": {"recomputed_vertices": 7},
    }
    return sw.Rendered(aovs, [wall], stats, "/World/main_cam")


# --- knobs ----------------------------------------------------------------------------


def test_parse_knob_values_and_types() -> None:
    assert sw.parse_knob("tessFactor=0.25, 0.5,1") == ("tessFactor", [0.25, 0.5, 1.0])
    assert sw.parse_knob("samples=4,16,4") == ("samples", [4, 16])
    assert sw.parse_knob("cacheMode=multires,none") == ("cacheMode", ["multires", "none"])
    assert sw.parse_knob("samples=8.0") == ("samples", [8])


@pytest.mark.parametrize(
    "spec, expect",
    [
        ("tessFactr=1,2", "unknown knob 'tessFactr'"),
        ("tessFactor=0", "tessFactor=0: out of range; tessFactor takes number, 0 < x ≤ 1000"),
        ("tessFactor=abc", "tessFactor=abc: not a finite number"),
        ("tessFactor=nan", "not a finite number"),
        ("samples=0", "samples=0: out of range; samples takes integer, 1 ≤ x ≤ 1e+06"),
        ("samples=2.5", "samples=2.5: not an integer"),
        ("aoSamples=-1", "aoSamples=-1: out of range"),
        ("maxDepth=65", "maxDepth=65: out of range"),
        ("cacheMode=fast", "cacheMode=fast: not one of multires, single, unbounded, none"),
        ("tessFactor", "is not NAME=V1,V2"),
        ("tessFactor=", "has no values"),
    ],
)
def test_bad_knob_or_value_lists_the_valid_knobs(scene_file: Path, capsys, spec, expect) -> None:
    code, out, err = run([scene_file, "--knob", spec, "--out", scene_file.parent / "s"], capsys)
    assert code == 1
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("mipray-sweep: ")
    assert expect in err
    if "NAME=V1" not in expect and "no values" not in expect:
        for knob in sw.KNOBS.values():
            assert f"{knob.name} ({knob.describe()})" in err
    assert not (scene_file.parent / "s.json").exists()


def test_irradiance_cache_knobs_follow_the_renderer(monkeypatch) -> None:
    from mipray.tools import sweep_knobs

    monkeypatch.setattr(
        sweep_knobs, "_renderer_settings", lambda: ("irradianceCache", "irradianceCacheError")
    )
    assert sw.parse_knob("irradianceCache=0,1") == ("irradianceCache", [0, 1])
    assert sw.parse_knob("irradianceCacheError=0.4,0.05") == ("irradianceCacheError", [0.4, 0.05])
    with pytest.raises(sw.SweepError, match="out of range"):
        sw.parse_knob("irradianceCacheError=0")
    with pytest.raises(sw.SweepError, match="out of range"):
        sw.parse_knob("irradianceCache=2")
    # The reference samples every hemisphere integral: the cache off.
    ref = sw.auto_reference_settings({"irradianceCacheError": [0.4, 0.1]}, {"irradianceCache": 1})
    assert ref["irradianceCache"] == 0 and "irradianceCacheError" not in ref
    monkeypatch.setattr(sweep_knobs, "_renderer_settings", lambda: ())
    with pytest.raises(sw.SweepError, match=r"'irradianceCache' .* not yet available"):
        sw.parse_knob("irradianceCache=0,1")


def test_optional_knobs_follow_the_renderer(monkeypatch) -> None:
    from mipray.tools import sweep_knobs

    monkeypatch.setattr(sweep_knobs, "_renderer_settings", lambda: ("textureFilter",))
    assert sw.parse_knob("textureFilter=finest,differentials") == (
        "textureFilter",
        ["finest", "differentials"],
    )
    with pytest.raises(sw.SweepError, match="not one of differentials, finest"):
        sw.parse_knob("textureFilter=bilinear")
    with pytest.raises(sw.SweepError, match=r"'shadowSamples' .* not yet available in this build"):
        sw.parse_knob("shadowSamples=1,4")
    assert "shadowSamples" in sw.unavailable_knobs()
    monkeypatch.setattr(sweep_knobs, "_renderer_settings", lambda: ())
    with pytest.raises(sw.SweepError, match=r"'textureFilter' .* not yet available"):
        sw.parse_knob("textureFilter=finest")


def test_knob_given_twice_or_also_fixed_is_refused(scene_file: Path) -> None:
    with pytest.raises(sw.SweepError, match="given twice"):
        sw.sweep(scene_file, ["tessFactor=1", "tessFactor=2"], out=None)
    with pytest.raises(sw.SweepError, match=r"both swept .* and fixed"):
        sw.sweep(scene_file, {"tessFactor": [1, 2]}, settings={"tessFactor": 1}, out=None)


def test_plan_rows_product_and_zip() -> None:
    knobs = {"tessFactor": [1.0, 2.0], "samples": [1, 4, 16]}
    rows = sw.plan_rows(knobs)
    assert len(rows) == 6
    assert rows[0] == {"tessFactor": 1.0, "samples": 1}
    assert rows[3] == {"tessFactor": 2.0, "samples": 1}
    zipped = sw.plan_rows(
        {"tessFactor": [1.0, 2.0, 4.0], "tessFactorIncoherent": [1, 0.5, 0.25], "aoSamples": [8]},
        zip_knobs=True,
    )
    assert zipped == [
        {"tessFactor": 1.0, "tessFactorIncoherent": 1, "aoSamples": 8},
        {"tessFactor": 2.0, "tessFactorIncoherent": 0.5, "aoSamples": 8},
        {"tessFactor": 4.0, "tessFactorIncoherent": 0.25, "aoSamples": 8},
    ]
    with pytest.raises(sw.SweepError, match="same number of values"):
        sw.plan_rows({"tessFactor": [1.0, 2.0], "samples": [1, 4, 16]}, zip_knobs=True)


def test_auto_reference_is_the_most_accurate_setting() -> None:
    ref = sw.auto_reference_settings(
        {
            "tessFactor": [0.5, 4.0],
            "samples": [4, 128],
            "aoSamples": [2, 8],
            "cacheMode": ["none"],
            "geometryCacheMb": [1.0],
        },
        {"maxDepth": 2, "seed": 5},
    )
    assert ref == {
        "maxDepth": 2,
        "seed": 6,
        "tessFactor": 0.25,
        "tessFactorIncoherent": 1.0,
        "cacheMode": "unbounded",
        "samples": 128,
        "aoSamples": 8,
    }
    assert sw.auto_reference_settings({"tessFactor": [0.1]}, {})["tessFactor"] == 0.1


# --- figures --------------------------------------------------------------------------


def test_image_errors_and_tess_error_figures_known_values() -> None:
    ref = np.zeros((2, 2, 3), np.float32)
    img = ref.copy()
    img[0, 0, 0] = 2.0  # one of 12 values off by 2: RMSE = sqrt(4/12)
    errs = image_errors(img, ref)
    assert errs["color_rmse"] == pytest.approx((4 / 12) ** 0.5)
    assert errs["color_max_abs"] == pytest.approx(2.0)
    assert errs["color_mean_diff"] == pytest.approx(2 / 12)
    img[1, 1, 1] = np.nan
    assert image_errors(img, ref)["color_max_abs"] > 1e30  # a NaN is never a small error
    te = np.zeros((2, 2, 2), np.float32)
    te[0, 0] = (0.3, 3.0)
    te[1, 1] = (9.0, 90.0)  # a miss: left out by alpha
    alpha = np.ones((2, 2, 1), np.float32)
    alpha[1, 1] = 0.0
    figs = tess_error_figures(te, alpha)
    assert figs["tess_error_mean"] == pytest.approx(0.1)
    assert figs["tess_error_max"] == pytest.approx(0.3)
    assert figs["tess_error_rel_mean"] == pytest.approx(1.0)
    assert figs["tess_error_rel_max"] == pytest.approx(3.0)


def test_pareto_front() -> None:
    rows = [
        {"wall_s": 1.0, "color_rmse": 0.5},
        {"wall_s": 2.0, "color_rmse": 0.6},  # slower and worse than row 0
        {"wall_s": 3.0, "color_rmse": 0.1},
        {"wall_s": 0.5, "color_rmse": 0.9},
        {"wall_s": 4.0, "color_rmse": 0.1},  # as good as row 2, but slower
    ]
    assert pareto_front(rows) == [3, 0, 2]


# --- a real sweep ---------------------------------------------------------------------


def test_sweep_one_knob_on_a_tiny_scene(native, scene_file: Path, tmp_path: Path, capsys) -> None:
    prefix = tmp_path / "out" / "tess"
    code, out, err = run(
        [
            scene_file,
            "--knob",
            "tessFactor=0.25,8",
            "--width",
            WIDTH,
            "--reference-samples",
            2,
            "--out",
            prefix,
            "--runs",
            2,
            "--no-plot",
        ],
        capsys,
    )
    assert code == 0, err
    assert err == ""  # progress only on a terminal
    table = json.loads(Path(f"{prefix}.json").read_text())
    # The schema: header fields, and every row field documented (and only those).
    assert table["schema"] == SCHEMA
    assert table["complete"] is True and table["stopped"] is None
    assert table["image_size"][0] == WIDTH and table["image_size"][1] >= 1
    assert table["knobs"] == {"tessFactor": [0.25, 8.0]}
    assert table["reference"]["source"] == "auto"
    assert table["reference"]["settings"]["cacheMode"] == "unbounded"
    assert table["reference"]["settings"]["samples"] == 2
    assert Path(table["reference"]["written"]).exists()
    assert table["planned_rows"] == 2
    rows = table["rows"]
    assert [r["setting"] for r in rows] == [{"tessFactor": 0.25}, {"tessFactor": 8.0}]
    for row in rows:
        assert set(row) == set(ROW_FIELDS)
        assert len(row["wall_s_runs"]) == 2 and row["wall_s"] > 0
        assert len(row["cpu_s_runs"]) == 2 and row["cpu_s"] > 0
        assert row["peak_rss_bytes"] > 10_000_000
        assert row["recomputed_vertices"] >= 0
        assert 0 <= row["color_rmse"] <= row["color_max_abs"]
        assert row["tess_error_mean"] <= row["tess_error_max"]
    # Coarser tessellation: the hit is farther from the limit surface, in beam widths too.
    fine, coarse = rows
    assert coarse["tess_error_rel_mean"] > fine["tess_error_rel_mean"]
    assert coarse["tess_error_max"] > fine["tess_error_max"]
    # The Markdown table and the command's output list the same rows.
    md = Path(f"{prefix}.md").read_text()
    assert "| tessFactor=0.25 |" in md and "| tessFactor=8 |" in md
    assert "| tessFactor=0.25 |" in out
    assert out.strip().splitlines()[-1] == f"{prefix}.reference.exr"
    assert not Path(f"{prefix}.png").exists()


def test_python_api_with_a_file_reference(native, scene_file: Path, tmp_path: Path) -> None:
    first = tmp_path / "a"
    sw.sweep(scene_file, {"samples": [1]}, width=WIDTH, reference_samples=2, out=first, plot=False)
    ref = f"{first}.reference.exr"
    rows = sw.sweep(
        scene_file, {"cacheMode": ["none", "multires"]}, width=WIDTH, reference=ref, out=None
    )
    assert [r["label"] for r in rows] == ["cacheMode=none", "cacheMode=multires"]
    # The cache never changes pixels: both rows have the same error.
    assert rows[0]["color_rmse"] == pytest.approx(rows[1]["color_rmse"], abs=1e-7)


def test_reference_of_the_wrong_size_is_refused(
    native, scene_file: Path, tmp_path: Path, capsys
) -> None:
    ref = tmp_path / "small.exr"
    native.write_image(str(ref), {"color": np.zeros((5, 5, 3), np.float32)}, ["color"])
    _, _, height = sw.image_size(str(scene_file), WIDTH)

    def never(request, progress):
        raise AssertionError("nothing should render before the reference is checked")

    with pytest.raises(sw.SweepError) as info:
        sw.sweep(scene_file, {"tessFactor": [1]}, width=WIDTH, reference=ref, runner=never)
    assert f"is 5×5 pixels but the sweep renders {WIDTH}×{height}" in str(info.value)
    code, _, err = run(
        [
            scene_file,
            "-k",
            "tessFactor=1",
            "-w",
            WIDTH,
            "--reference",
            ref,
            "--out",
            tmp_path / "s",
        ],
        capsys,
    )
    assert code == 1
    assert err == (
        f"mipray-sweep: reference {ref} is 5×5 pixels but the sweep renders {WIDTH}×{height}; "
        f"render the reference at --width {WIDTH} or use --reference auto\n"
    )


def test_a_failing_worker_is_one_line_naming_the_row(
    native, scene_file: Path, tmp_path: Path, capsys
) -> None:
    code, _, err = run(
        [
            scene_file,
            "-k",
            "tessFactor=1",
            "-w",
            WIDTH,
            "--set",
            "aoDistance=-1",
            "--out",
            tmp_path / "s",
        ],
        capsys,
    )
    assert code == 1
    assert err.count("\n") == 1
    assert err.startswith("mipray-sweep: reference (") and "failed: " in err
    assert "aoDistance" in err


# --- interruption ---------------------------------------------------------------------


@pytest.mark.parametrize("failure", [sw.SweepError("worker died"), KeyboardInterrupt()])
def test_rows_finished_before_a_failure_are_kept(
    scene_file: Path, tmp_path: Path, failure: BaseException
) -> None:
    _, width, height = sw.image_size(str(scene_file), WIDTH)
    calls: list[dict[str, object]] = []

    def runner(request: sw.RowRequest, progress) -> sw.Rendered:
        calls.append(request.settings)
        if len(calls) == 4:  # the reference, rows 1 and 2, then row 3 fails
            raise failure
        return fake_rendered(
            height, width, value=0.5 if len(calls) > 1 else 0.25, wall=float(len(calls))
        )

    prefix = tmp_path / "stop"
    expected = sw.SweepError if isinstance(failure, Exception) else KeyboardInterrupt
    with pytest.raises(expected) as info:
        sw.sweep(
            scene_file,
            {"tessFactor": [1, 2, 4, 8]},
            width=WIDTH,
            out=prefix,
            runner=runner,
            plot=False,
        )
    table = json.loads(Path(f"{prefix}.json").read_text())
    assert [r["label"] for r in table["rows"]] == ["tessFactor=1", "tessFactor=2"]
    assert table["complete"] is False and table["planned_rows"] == 4
    if expected is sw.SweepError:
        assert "row 3 (tessFactor=4) failed: worker died" in str(info.value)
        assert table["stopped"] == str(info.value)
    else:
        assert table["stopped"] == "interrupted after 2 of 4 rows"
    assert table["rows"][0]["color_rmse"] == pytest.approx(0.25)
    assert "**incomplete**: 2 of 4 rows" in Path(f"{prefix}.md").read_text()


def test_tables_are_written_after_every_row(scene_file: Path, tmp_path: Path) -> None:
    _, width, height = sw.image_size(str(scene_file), WIDTH)
    prefix = tmp_path / "live"
    seen: list[int] = []

    def runner(request: sw.RowRequest, progress) -> sw.Rendered:
        path = Path(f"{prefix}.json")
        seen.append(len(json.loads(path.read_text())["rows"]) if path.exists() else -1)
        return fake_rendered(height, width)

    sw.sweep(scene_file, {"samples": [1, 2, 3]}, width=WIDTH, out=prefix, runner=runner, plot=False)
    assert seen == [-1, 0, 1, 2]  # reference first, then each row sees the ones before it


def test_plot_is_optional(scene_file: Path, tmp_path: Path, monkeypatch, caplog) -> None:
    table = {
        "scene": str(scene_file),
        "rows": [{"label": "a", "wall_s": 1.0, "color_rmse": 0.1, "tess_error_rel_mean": 0.01}],
    }
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import fails as if not installed
    with caplog.at_level("WARNING", logger="mipray"):
        assert sw._try_plot(table, str(tmp_path / "p.png")) is False
    assert "matplotlib is not installed" in caplog.text
    assert "pip install" in caplog.text
    assert not (tmp_path / "p.png").exists()
    paths = write_tables({**table, "runs": 1, "complete": True}, str(tmp_path / "t"))
    assert all(Path(p).exists() for p in paths)


def test_list_knobs(capsys) -> None:
    code, out, _ = run(["--list-knobs"], capsys)
    assert code == 0
    for name in (*sw.KNOBS, *sw.OPTIONAL_KNOBS, *sw.RESERVED_KNOBS):
        assert name in out
    assert ("not yet available" in out) == bool(sw.unavailable_knobs())


def test_every_run_starts_cold(native) -> None:
    # A delegate kept between renders carries the cache's recomputed-vertex count over;
    # the sweep renders each run with a new one, so the last run's stats are one run's.
    scene = str(Path(__file__).resolve().parent.parent / "examples" / "subdiv_showcase.usda")
    # tessFactor 0.1: at 8 pixels the default rates stay in the coarse tier, which 10 kB holds
    # whole; quads a tenth of the beam reach the fine tier, whose working set outgrows it.
    settings = {"geometryCacheMb": 0.01, "tessFactor": 0.1}
    one = sw.render_in_process(sw.RowRequest(scene, settings, WIDTH, runs=1))
    two = sw.render_in_process(sw.RowRequest(scene, settings, WIDTH, runs=2))
    recomputed = one.stats["geometry_cache"]["recomputed_vertices"]
    assert recomputed > 0
    assert two.stats["geometry_cache"]["recomputed_vertices"] == recomputed
    assert len(two.wall_s_runs) == 2


def test_rows_from_another_build_of_the_extension_are_refused(scene_file: Path, tmp_path: Path):
    _, width, height = sw.image_size(str(scene_file), WIDTH)
    builds = iter(["so:1:100", "so:1:100", "so:1:200"])  # rebuilt before the second row

    def runner(request: sw.RowRequest, progress) -> sw.Rendered:
        rendered = fake_rendered(height, width)
        rendered.extension = next(builds)
        return rendered

    prefix = tmp_path / "rebuilt"
    with pytest.raises(sw.SweepError, match=r"row 2 \(samples=2\): mipray._mipray changed"):
        sw.sweep(
            scene_file, {"samples": [1, 2]}, width=WIDTH, out=prefix, runner=runner, plot=False
        )
    table = json.loads(Path(f"{prefix}.json").read_text())
    assert [r["label"] for r in table["rows"]] == ["samples=1"]
    assert table["extension"] == "so:1:100"


def test_committed_cache_scene_is_what_its_generator_writes(tmp_path: Path) -> None:
    import importlib.util

    examples = Path(__file__).resolve().parent.parent / "examples"
    spec = importlib.util.spec_from_file_location(
        "make_cache_scene", examples / "make_cache_scene.py"
    )
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    module.main([str(tmp_path)])
    fresh = (tmp_path / "cache_scene.usda").read_text()
    assert fresh == (examples / "cache_scene.usda").read_text(), (
        "examples/cache_scene.usda is stale: run `python examples/make_cache_scene.py`"
    )


def test_progress_names_the_reference_then_each_row_and_run(
    scene_file: Path, tmp_path: Path
) -> None:
    # What mipray-sweep draws on a terminal: one status line per step, in order, with the
    # renderer's own completion for the run under way.
    _, width, height = sw.image_size(str(scene_file), WIDTH)
    lines: list[str] = []

    def runner(request: sw.RowRequest, progress) -> sw.Rendered:
        for run in range(1, request.runs + 1):
            if progress is not None:
                progress(run, 1, 2)
                progress(run, 2, 2)
        return fake_rendered(height, width)

    sw.sweep(
        scene_file,
        {"tessFactor": [1, 4]},
        width=WIDTH,
        runs=2,
        out=tmp_path / "p",
        runner=runner,
        plot=False,
        progress=lines.append,
    )
    starts = [line for line in lines if line.endswith(" ...")]
    assert starts[0].startswith("reference (") and starts[1:] == [
        "[1/2] tessFactor=1 ...",
        "[2/2] tessFactor=4 ...",
    ]
    row2 = lines[lines.index("[2/2] tessFactor=4 ...") + 1 :]
    assert row2 == [
        "[2/2] tessFactor=4 run 1/2  50%",
        "[2/2] tessFactor=4 run 1/2 100%",
        "[2/2] tessFactor=4 run 2/2  50%",
        "[2/2] tessFactor=4 run 2/2 100%",
    ]
