"""usdrecord's own test command lines, replayed through mipray-record (issue 20).

The command lines are OpenUSD's (v24.08, ``pxr/usdImaging/bin/usdrecord``'s
``pxr_register_test`` entries), run unchanged but for the program name in the
test environment's folder (copied from the corpus: ``tests/usd_corpus.py``).
Each must run, and frame and cover the stage as OpenUSD's baseline images do:
the coverage (alpha) and its bounding box do not depend on the renderer, the
shading does. The baselines are RGBA, like mipray-record's PNGs.
"""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, UsdRender
from usd_corpus import corpus_path, coverage, coverage_match, read_rgba

from mipray.image import srgb_encode
from mipray.record import (
    COMPLEXITY_REFINEMENT_LEVEL,
    build_parser,
    main,
    render_settings,
)

from stages import add_camera, add_cube, new_stage

TESTENV = ("openusd", "pxr", "usdImaging", "bin", "usdrecord", "testenv")

#: (test name in OpenUSD, test environment, command line, [(our image, baseline)]).
COMMANDS = [
    (
        "testUsdRecordSingleFrame",
        "RecordTest",
        "usdrecord AnimCube.usda AnimCube.1.png",
        [("AnimCube.1.png", "AnimCube.1.png")],
    ),
    (
        "testUsdRecordMultipleFrames",
        "RecordTest",
        "usdrecord AnimCube.usda AnimCube.#.png --frames 1,5,10",
        [(f"AnimCube.{f}.png", f"AnimCube.{f}.png") for f in (1, 5, 10)],
    ),
    (
        "testUsdRecordSingleFrame_NoGpu",
        "RecordTest",
        "usdrecord --disableGpu AnimCube.usda AnimCubeNoGpu.1.png",
        [("AnimCubeNoGpu.1.png", "AnimCubeNoGpu.1.png")],
    ),
    (
        "testUsdRecordSessionLayer",
        "RecordTest",
        (
            "usdrecord --sessionLayer overrideDisplayColor.usda AnimCube.usda "
            "AnimCube_overrides.1.png"
        ),
        [("AnimCube_overrides.1.png", "AnimCube_overrides.1.png")],
    ),
    (
        "testUsdRecordSmallObject",
        "SmallObjectTest",
        "usdrecord --enableDomeLightVisibility test.usda out.png",
        [("out.png", "out.png")],
    ),
]


def _copy_env(env: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of test environment ``env`` (without its baselines), made the working folder."""
    work = tmp_path / env
    shutil.copytree(corpus_path(*TESTENV, env), work, ignore=shutil.ignore_patterns("baseline"))
    monkeypatch.chdir(work)
    return work


def _replay(env: str, command: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Run ``command`` (usdrecord's) as mipray-record in a copy of test environment ``env``."""
    work = _copy_env(env, tmp_path, monkeypatch)
    argv = shlex.split(command)
    assert argv[0] == "usdrecord"
    code = main(argv[1:])
    assert code == 0, f"{command} exited {code}"
    return work


@pytest.mark.parametrize(
    ("name", "env", "command", "images"), COMMANDS, ids=[c[0] for c in COMMANDS]
)
def test_usdrecord_command_lines_frame_and_cover_as_the_baselines(
    name: str, env: str, command: str, images: list, tmp_path: Path, monkeypatch, native
) -> None:
    work = _replay(env, command, tmp_path, monkeypatch)
    for ours_name, baseline_name in images:
        ours = read_rgba(work / ours_name)
        theirs = read_rgba(corpus_path(*TESTENV, env, "baseline", baseline_name))
        assert ours.shape == theirs.shape, f"{name}: {ours_name} is {ours.shape}"
        iou, offset = coverage_match(ours, theirs)
        if coverage(theirs).all():
            # The dome is the background: the whole frame is covered in both.
            assert coverage(ours).all(), f"{name}: {ours_name} has uncovered pixels"
        else:
            assert iou > 0.97 and offset <= 2, f"{name}: {ours_name}: IoU {iou:.3f}, {offset} px"


def test_session_layer_override_shows(tmp_path: Path, monkeypatch, native) -> None:
    """overrideDisplayColor.usda makes the cube (1, 0.5, 0.5): redder than green, as Storm's."""
    work = _replay("RecordTest", COMMANDS[3][2], tmp_path, monkeypatch)
    ours = read_rgba(work / "AnimCube_overrides.1.png")
    theirs = read_rgba(corpus_path(*TESTENV, "RecordTest", "baseline", "AnimCube_overrides.1.png"))
    for image in (ours, theirs):
        inside = image[coverage(image)]
        assert inside[:, 0].mean() > 1.3 * inside[:, 1].mean()


def test_dome_background_matches_the_baseline_and_is_hidden_by_default(
    tmp_path: Path, monkeypatch, native
) -> None:
    """The dome's latlong orientation (rotateX:Zup 90) is renderer-independent: its
    background agrees with Storm's; without --enableDomeLightVisibility it is transparent."""
    work = _replay("SmallObjectTest", COMMANDS[4][2], tmp_path, monkeypatch)
    ours = read_rgba(work / "out.png")
    theirs = read_rgba(corpus_path(*TESTENV, "SmallObjectTest", "baseline", "out.png"))
    # Mean colour of each of 4x4 blocks: the sky above, the ground below, where the sun is.
    h, w = ours.shape[:2]
    blocks = [
        (slice(i * h // 4, (i + 1) * h // 4), slice(j * w // 4, (j + 1) * w // 4))
        for i in range(4)
        for j in range(4)
    ]
    diffs = [
        np.abs(ours[b][..., :3].mean(axis=(0, 1)) - theirs[b][..., :3].mean(axis=(0, 1))).max()
        for b in blocks
    ]
    assert max(diffs) < 0.1, diffs
    assert main(["test.usda", "hidden.png"]) == 0
    hidden = read_rgba(work / "hidden.png")
    assert hidden.shape == ours.shape
    assert coverage(hidden).mean() < 0.05  # the small object only


@pytest.mark.parametrize(("renderer", "code"), [("Prman", 1), ("Storm", 1), ("mipray", 0)])
def test_renderer_flag_accepts_mipray_only(
    renderer: str, code: int, tmp_path: Path, monkeypatch, native, capsys
) -> None:
    """OpenUSD's (disabled) motion-blur command line asks for Prman: a one-line error, not
    a render with another meaning (``-r`` was taken for ``-rs``)."""
    work = _copy_env("MotionBlurTest", tmp_path, monkeypatch)
    command = f"usdrecord motionBlur.usda motionBlur.exr -cam /first_cam -r {renderer} -w 32"
    assert main(shlex.split(command)[1:]) == code
    err = capsys.readouterr().err
    if code:
        assert err.count("\n") == 1 and f"'{renderer}' is not a renderer" in err, err
    else:
        assert (work / "motionBlur.exr").exists()


# ---------------------------------------------------------------- every flag, no corpus


def _stage_file(tmp_path: Path) -> Path:
    stage = new_stage()
    add_cube(stage, "/World/Cube")
    add_camera(stage, "/World/main_cam", eye=(0, 0, 8))
    settings = UsdRender.Settings.Define(stage, "/Render/Wide")
    settings.CreateResolutionAttr(Gf.Vec2i(40, 10))
    UsdRender.Settings.Define(stage, "/Render/Tall").CreateResolutionAttr(Gf.Vec2i(10, 40))
    render_pass = UsdRender.Pass.Define(stage, "/Render/Pass")
    render_pass.CreateRenderSourceRel().AddTarget("/Render/Tall")
    UsdRender.Pass.Define(stage, "/Render/Empty")
    path = tmp_path / "scene.usda"
    stage.GetRootLayer().Export(str(path))
    return path


def _run(argv: list, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_every_usdrecord_flag_is_accepted() -> None:
    """OpenUSD's usdrecord.py and usdAppUtils' flags, each with a value it takes."""
    argv = [
        "in.usda",
        "out.png",
        "--mask",
        "/World",
        "--purposes",
        "proxy",
        "--sessionLayer",
        "s.usda",
        "--disableGpu",
        "--disableCameraLight",
        "-cam",
        "main_cam",
        "-f",
        "1:3",
        "-c",
        "veryhigh",
        "-color",
        "openColorIO",
        "-r",
        "mipray",
        "-w",
        "64",
        "--enableDomeLightVisibility",
        "-rp",
        "/Render/Pass",
    ]
    args = build_parser().parse_args(argv)
    assert (args.renderer, args.renderPassPrimPath, args.enableDomeLightVisibility) == (
        "mipray",
        "/Render/Pass",
        True,
    )
    for flag in ("--defaultTime", "-d", "-rs"):
        extra = [flag, "/Render/Wide"] if flag == "-rs" else [flag]
        build_parser().parse_args(["in.usda", "out.png", *extra])


@pytest.mark.parametrize(
    ("level", "refinement"), [("low", 0), ("medium", 1), ("high", 2), ("veryhigh", 3)]
)
def test_complexity_is_a_refinement_level_halving_the_tess_factor(
    level: str, refinement: int
) -> None:
    args = build_parser().parse_args(["in.usda", "out.exr", "--complexity", level])
    assert COMPLEXITY_REFINEMENT_LEVEL[level] == refinement
    # One more refinement level halves every edge: half the subpatch edge per beam width.
    assert render_settings(args)["tessFactor"] == 4.0 * 0.5**refinement


def test_dome_visibility_is_off_unless_asked() -> None:
    parse = build_parser().parse_args
    assert render_settings(parse(["in.usda", "o.png"]))["domeLightCameraVisibility"] == 0
    on = parse(["in.usda", "o.png", "--enableDomeLightVisibility"])
    assert render_settings(on)["domeLightCameraVisibility"] == 1


def test_other_renderers_are_a_one_line_error(capsys, tmp_path: Path, fake_native) -> None:
    code, _, err = _run([_stage_file(tmp_path), tmp_path / "o.png", "-r", "Storm"], capsys)
    assert code == 1
    assert err.count("\n") == 1 and "'Storm' is not a renderer" in err
    assert not (tmp_path / "o.png").exists()


def test_render_pass_names_the_settings(capsys, tmp_path: Path, fake_native) -> None:
    scene = _stage_file(tmp_path)
    code, _, err = _run([scene, tmp_path / "o.exr", "-rp", "/Render/Pass"], capsys)
    assert code == 0, err
    assert fake_native.written[str(tmp_path / "o.exr")]["aovs"]["color"].shape[:2] == (
        40,
        10,
    )
    assert (
        fake_native.written[str(tmp_path / "o.exr")]["metadata"]["mipray:renderSettings"]
        == "/Render/Tall"
    )
    for argv, message in (
        (
            ["-rp", "/Render/Empty"],
            "/Render/Empty: the render pass has no renderSource",
        ),
        (["-rp", "/Nope"], "/Nope: no prim, not a RenderPass prim"),
        (["-rp", "/Render/Pass", "-rs", "/Render/Wide"], "not both"),
    ):
        code, _, err = _run([scene, tmp_path / "x.exr", *argv], capsys)
        assert code == 1 and err.count("\n") == 1 and message in err, err


def test_png_is_rgba_as_usdrecord_writes(capsys, tmp_path: Path, fake_native) -> None:
    png = tmp_path / "o.png"
    code, _, err = _run([_stage_file(tmp_path), png, "-w", "8"], capsys)
    assert code == 0, err
    written = fake_native.written[str(png)]
    assert written["order"] == ["color", "alpha"]
    assert written["formats"] == {"color": "uint8", "alpha": "uint8"}
    # Alpha is coverage: written as it is, never sRGB-encoded.
    np.testing.assert_array_equal(
        written["aovs"]["alpha"][0, :, 0], np.linspace(0.0, 2.0, 8, dtype=np.float32)
    )
    jpg = tmp_path / "o.jpg"
    assert _run([_stage_file(tmp_path), jpg, "-w", "8"], capsys)[0] == 0
    assert fake_native.written[str(jpg)]["order"] == ["color"]


def test_a_broken_session_layer_is_named_with_usds_reason(
    capsys, tmp_path: Path, fake_native
) -> None:
    session = tmp_path / "session.usda"
    session.write_text('#usda 1.0\ndef Xform "A" {\n  float x = \n}\n')
    code, _, err = _run(
        [_stage_file(tmp_path), tmp_path / "o.exr", "--sessionLayer", session], capsys
    )
    assert code == 1
    assert err.count("\n") == 1, err
    assert err.startswith(f"mipray-record: {session}: cannot open session layer as a USD layer: ")
    assert "Expected }" in err and "pxrInternal" not in err and "Error in" not in err


def test_open_color_io_is_taken_as_srgb_with_a_warning(capsys, tmp_path: Path, fake_native) -> None:
    png = tmp_path / "o.png"
    code, _, err = _run([_stage_file(tmp_path), png, "-w", "8", "-color", "openColorIO"], capsys)
    assert code == 0
    assert "mipray-record: warning: --colorCorrectionMode openColorIO is not supported" in err
    ramp = np.linspace(0.0, 2.0, 8, dtype=np.float32)
    np.testing.assert_allclose(
        fake_native.written[str(png)]["aovs"]["color"][0, :, 0], srgb_encode(ramp)
    )
