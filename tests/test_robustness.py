"""Hostile but realistic input never takes a render down (issue 16).

Each stage here once crashed the whole render (a Rust panic surfacing in Python as
``PanicException``, or OpenImageIO aborting the process). Now the bad prim is named in one
line and left out (or, for a flattened object, drawn as the flat shape it is), the other prims
render, and the stats list what was dropped.
"""

from __future__ import annotations

import logging
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom
from test_end_to_end import pixel_of, record_command, subprocess_env
from test_materials import scene, texture

import mipray

from stages import CUBE_INDICES, add_camera, add_cube, add_distant_light, new_stage


def _render(stage: Usd.Stage, width: int = 24, **settings: object) -> mipray.RenderResult:
    return mipray.render(stage, width=width, settings={"samples": 1, "seed": 1, **settings})


def _record(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """``mipray-record args`` in a new process; its exit status and text (never raises)."""
    return subprocess.run(
        [*record_command(), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        env=subprocess_env(),
    )


def _stage_with(build) -> Usd.Stage:
    """A lit stage with a camera at z = 10, a cube /World/Ok down and left of the centre, and
    whatever ``build(stage)`` adds."""
    stage = new_stage()
    add_cube(stage, "/World/Ok", translate=(-1.4, -0.9, 0.0))
    add_camera(stage, "/World/Cam", eye=(0.0, 0.0, 10.0))
    add_distant_light(stage, "/World/Sun")
    build(stage)
    return stage


def _ok_is_drawn(stage: Usd.Stage, result: mipray.RenderResult) -> None:
    color = result.aovs["color"]
    assert np.isfinite(color).all()
    row, col = pixel_of(stage, "/World/Ok", result.width, result.height, Usd.TimeCode.Default())
    assert color[row, col].sum() > 0.0, "the good prim is missing"


def _scaled_parent(scale: tuple[float, float, float]):
    def build(stage: Usd.Stage) -> None:
        parent = UsdGeom.Xform.Define(stage, "/World/Parent")
        parent.AddScaleOp().Set(Gf.Vec3f(*scale))
        add_cube(stage, "/World/Parent/Bad")

    return build


@pytest.mark.parametrize(
    "scale", [(0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1e-30, 1e-30, 1e-30), (1e20, 1e20, 1e20)]
)
def test_degenerate_scales_drop_the_prim_by_name(native, caplog, scale) -> None:
    stage = _stage_with(_scaled_parent(scale))
    with caplog.at_level(logging.WARNING):
        result = _render(stage)
    _ok_is_drawn(stage, result)
    dropped = result.stats["dropped_prims"]
    assert len(dropped) == 1 and dropped[0].startswith("/World/Parent/Bad: transform "), dropped
    assert any("/World/Parent/Bad: transform" in r.getMessage() for r in caplog.records)
    assert result.stats["internal_errors"] == 0


def test_an_object_scaled_flat_renders_as_the_flat_shape_it_is(native) -> None:
    # Scaled to zero along the view axis: the cube is a square facing the camera.
    stage = _stage_with(_scaled_parent((2.0, 2.0, 0.0)))
    result = _render(stage, width=32)
    assert result.stats["dropped_prims"] == []
    depth = result.aovs["depth"] if "depth" in result.aovs else None
    color = result.aovs["color"]
    h, w = color.shape[:2]
    assert color[h // 2, w // 2].sum() > 0.0
    assert depth is None or depth[h // 2, w // 2, 0] == pytest.approx(10.0, abs=1e-3)


def test_a_point_instancer_with_scale_zero_names_the_prototype(native) -> None:
    def build(stage: Usd.Stage) -> None:
        inst = UsdGeom.PointInstancer.Define(stage, "/World/Forest")
        add_cube(stage, "/World/Forest/Protos/Tree")
        inst.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Forest/Protos/Tree")])
        inst.CreateProtoIndicesAttr([0, 0, 0])
        inst.CreatePositionsAttr([(-2, 0, 0), (0, 0, 0), (2, 0, 0)])
        inst.CreateScalesAttr([(0, 0, 0), (1, 1, 1), (0, 0, 0)])
        UsdGeom.Imageable(stage.GetPrimAtPath("/World/Forest/Protos")).MakeInvisible()

    stage = _stage_with(build)
    result = _render(stage)
    _ok_is_drawn(stage, result)
    dropped = result.stats["dropped_prims"]
    assert len(dropped) == 1 and "/World/Forest/Protos/Tree" in dropped[0], dropped
    assert "(2 instances)" in dropped[0]
    color = result.aovs["color"]
    h, w = color.shape[:2]
    assert color[h // 2, w // 2].sum() > 0.0, "the instance of scale 1 is drawn"


@pytest.mark.parametrize("far", [1e30, 3e38])
def test_points_beyond_the_traceable_range_drop_the_mesh_by_name(native, far) -> None:
    def build(stage: Usd.Stage) -> None:
        points = [(x, y, z) for x, y, z in [(-0.5, -0.5, 0.5), (far, -0.5, 0.5)]]
        points += [(-0.5, 0.5, 0.5), (0.5, 0.5, 0.5), (-0.5, 0.5, -0.5), (0.5, 0.5, -0.5)]
        points += [(-0.5, -0.5, -0.5), (0.5, -0.5, -0.5)]
        add_cube(stage, "/World/Far", points=points, scheme="none")

    stage = _stage_with(build)
    result = _render(stage)
    _ok_is_drawn(stage, result)
    dropped = result.stats["dropped_prims"]
    assert len(dropped) == 1 and dropped[0].startswith("/World/Far: "), dropped


def test_a_face_whose_indices_are_all_one_vertex(native) -> None:
    def build(stage: Usd.Stage) -> None:
        mesh = add_cube(stage, "/World/Bad")
        mesh.CreateFaceVertexIndicesAttr([0, 0, 0, 0, *CUBE_INDICES[4:]])

    stage = _stage_with(build)
    result = _render(stage)
    _ok_is_drawn(stage, result)


def test_a_huge_displacement_scale_drops_the_mesh_by_name(native) -> None:
    def build(stage: Usd.Stage) -> None:
        mesh = add_cube(stage, "/World/Bumpy")
        prim = mesh.GetPrim()
        prim.CreateAttribute("mipray:displacement:amplitude", Sdf.ValueTypeNames.Float).Set(1e30)

    stage = _stage_with(build)
    result = _render(stage)
    _ok_is_drawn(stage, result)
    dropped = result.stats["dropped_prims"]
    assert len(dropped) == 1 and dropped[0].startswith("/World/Bumpy: "), dropped


def test_many_coincident_faces_render(native) -> None:
    # A production mesh with duplicated points: thousands of quads on the same four points
    # (obvhs built a BVH deeper than its traversal stack).
    def build(stage: Usd.Stage) -> None:
        n = 40_000
        mesh = UsdGeom.Mesh.Define(stage, "/World/Dup")
        mesh.CreatePointsAttr([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)])
        mesh.CreateFaceVertexCountsAttr([4] * n)
        mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3] * n)
        mesh.CreateSubdivisionSchemeAttr("none")

    result = _render(_stage_with(build))
    color = result.aovs["color"]
    h, w = color.shape[:2]
    assert color[h // 2, w // 2].sum() > 0.0
    assert result.stats["dropped_prims"] == []


def test_a_projective_transform_drops_the_prim_by_name(native) -> None:
    def build(stage: Usd.Stage) -> None:
        mesh = add_cube(stage, "/World/Proj")
        m = Gf.Matrix4d(1.0)
        m.SetColumn(3, Gf.Vec4d(0.0, 0.0, 0.3, 1.0))
        mesh.AddTransformOp().Set(m)

    stage = _stage_with(build)
    result = _render(stage)
    _ok_is_drawn(stage, result)
    dropped = result.stats["dropped_prims"]
    assert len(dropped) == 1 and dropped[0].startswith("/World/Proj: transform is projective"), (
        dropped
    )


def _texture_file(native, path: Path, texel: tuple[float, ...]) -> str:
    """An 8×8 float EXR whose every texel is ``texel`` (as many channels as values)."""
    values = np.ascontiguousarray(np.broadcast_to(np.array(texel, np.float32), (8, 8, len(texel))))
    native.write_image(str(path), {"map": values}, ["map"], {"map": "float"})
    return str(path)


@pytest.mark.parametrize(
    ("texel", "expected"),
    [
        ((0.25,), (0.25, 0.25, 0.25)),  # grey: r = g = b
        ((0.25, 0.5), (0.25, 0.25, 0.25)),  # grey and alpha: the grey in r, g and b
        ((0.1, 0.2, 0.3), (0.1, 0.2, 0.3)),
    ],
)
def test_rgb_of_files_with_fewer_channels_follows_usd_uv_texture(native, tmp_path, texel, expected):
    stage, shader = scene(diffuseColor=(0.0, 0.0, 0.0), useSpecularWorkflow=1)
    file = _texture_file(native, tmp_path / "map.exr", texel)
    texture(stage, "/World/Looks/M", shader, "emissiveColor", file)
    with mipray.RenderSession(stage) as session:
        result = session.render(
            "/World/Camera", width=16, settings={"samples": 1}, camera_light=False
        )
    color = result.aovs["color"]
    h, w = color.shape[:2]
    np.testing.assert_allclose(color[h // 2, w // 2, :3], expected, atol=1e-4)


@pytest.mark.parametrize(
    ("texel", "alpha"),
    [((0.25,), 1.0), ((0.1, 0.2, 0.3), 1.0), ((0.25, 0.5), 0.0), ((0.1, 0.2, 0.3, 0.75), 1.0)],
)
def test_outputs_a_of_a_file_without_alpha_is_one(native, tmp_path, texel, alpha):
    # OpenImageIO aborted the process (sample_bilinear: offset < tile_bytes) when asked for a
    # channel the file lacks. A cut-out at 0.6 shows the alpha read: 1 for a file without
    # alpha, the second channel (0.5: cut) of a grey-and-alpha file, the fourth of an RGBA one.
    stage, shader = scene(
        diffuseColor=(0.0, 0.0, 0.0),
        emissiveColor=(1.0, 1.0, 1.0),
        useSpecularWorkflow=1,
        opacityThreshold=0.6,
    )
    file = _texture_file(native, tmp_path / "map.exr", texel)
    texture(stage, "/World/Looks/M", shader, "opacity", file, output="a")
    with mipray.RenderSession(stage) as session:
        result = session.render(
            "/World/Camera",
            width=16,
            aovs=["color", "alpha"],
            settings={"samples": 1},
            camera_light=False,
        )
    a = result.aovs["alpha"]
    h, w = a.shape[:2]
    assert a[h // 2, w // 2, 0] == pytest.approx(alpha, abs=1e-4)


def test_colour_beyond_half_float_is_clamped_in_the_exr_with_a_warning(native, tmp_path) -> None:
    # An emissive 1e5: half float's largest value is 65504, so the EXR held Inf.
    stage, _ = scene(
        diffuseColor=(0.0, 0.0, 0.0), emissiveColor=(1e5, 1e5, 1e5), useSpecularWorkflow=1
    )
    usd = tmp_path / "bright.usda"
    stage.GetRootLayer().Export(str(usd))
    out = tmp_path / "bright.exr"
    done = _record(str(usd), str(out), "--imageWidth", "16", "--camera", "/World/Camera")
    assert done.returncode == 0, done.stderr
    pixels, names = native.read_image(str(out))
    assert np.isfinite(pixels).all()
    h, w = pixels.shape[:2]
    assert pixels[h // 2, w // 2, names.index("R")] == 65504.0
    warned = [line for line in done.stderr.splitlines() if "clamped" in line]
    assert len(warned) == 1 and str(out) in warned[0], done.stderr


def test_a_point_instancer_whose_prototype_holds_it_is_reported_in_one_line(native) -> None:
    # Its prototype is its own parent: expanding it met itself again, without end (a 2,663-line
    # RecursionError).
    def build(stage: Usd.Stage) -> None:
        inst = UsdGeom.PointInstancer.Define(stage, "/World/Group/Forest")
        add_cube(stage, "/World/Group/Tree")
        inst.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Group")])
        inst.CreateProtoIndicesAttr([0])
        inst.CreatePositionsAttr([(3.0, 0.0, 0.0)])

    stage = _stage_with(build)
    result = _render(stage)
    _ok_is_drawn(stage, result)
    said = [str(e) for e in result.errors]
    assert said == [
        "/World/Group/Forest: its prototypes hold this PointInstancer itself (a cycle)"
    ], said


def test_an_unusable_stage_camera_is_reported_not_replaced(native, tmp_path) -> None:
    # It was silently replaced by a camera framing the stage (exit status 0).
    stage = new_stage()
    add_cube(stage, "/World/Cube")
    add_camera(stage, "/World/Cam").CreateFocalLengthAttr(-5.0)
    with pytest.raises(
        mipray.PrimError, match=r"^/World/Cam: cannot render through it: focalLength"
    ):
        _render(stage)
    usd = tmp_path / "bad_camera.usda"
    stage.GetRootLayer().Export(str(usd))
    done = _record(str(usd), str(tmp_path / "out.exr"), "--imageWidth", "16")
    assert done.returncode == 1
    assert (
        done.stderr.strip().splitlines()[-1].startswith("mipray-record: /World/Cam: cannot render")
    )
    assert not (tmp_path / "out.exr").exists()


def test_an_aperture_giving_no_possible_image_height_is_one_line(native, tmp_path) -> None:
    # Found by tests/test_fuzz.py (seed 354351): a verticalAperture of 3e38 made the height
    # overflow the renderer's integer, an OverflowError instead of a MiprayError.
    stage = new_stage()
    add_cube(stage, "/World/Cube")
    add_camera(stage, "/World/Cam").CreateVerticalApertureAttr(3e38)
    with pytest.raises(mipray.RenderSettingsError, match=r"^/World/Cam: an image 24 pixels wide"):
        _render(stage)
    usd = tmp_path / "tall.usda"
    stage.GetRootLayer().Export(str(usd))
    done = _record(str(usd), str(tmp_path / "out.exr"), "--imageWidth", "16")
    assert done.returncode == 1, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("mipray-record: /World/Cam: an image 16 pixels wide"), done.stderr
    assert not (tmp_path / "out.exr").exists()


@pytest.mark.parametrize("problem", ["directory", "device", "file as folder"])
def test_an_unwritable_output_is_refused_before_any_frame_renders(native, tmp_path, problem):
    # Frame 2's output cannot be written: nothing renders (frame 1's image was written, and
    # only frame 2's write failed, after its render).
    stage = _stage_with(lambda stage: None)
    usd = tmp_path / "shot.usda"
    stage.GetRootLayer().Export(str(usd))
    if problem == "directory":
        (tmp_path / "out.2.exr").mkdir()
        pattern = str(tmp_path / "out.#.exr")
    elif problem == "device":
        os.symlink("/dev/full", tmp_path / "out.2.exr")
        pattern = str(tmp_path / "out.#.exr")
    else:
        pattern = str(tmp_path / "frame#" / "out.exr")
        (tmp_path / "frame2").write_text("a file where frame 2's folder would be made")
    done = _record(str(usd), pattern, "--frames", "1:2", "--imageWidth", "8")
    assert done.returncode == 1
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("mipray-record: ") and "2" in last, last
    assert done.stdout == "", "a frame was rendered and written first"


def _texture_stage(tmp_path: Path, file: str) -> Path:
    stage, shader = scene()
    texture(stage, "/World/Looks/M", shader, "diffuseColor", file)
    add_distant_light(stage, "/World/Sun")
    usd = tmp_path / "textured.usda"
    stage.GetRootLayer().Export(str(usd))
    return usd


@pytest.mark.parametrize("kind", ["device", "FIFO", "directory"])
def test_a_texture_that_is_not_a_regular_file_is_refused_in_one_line(native, tmp_path, kind):
    # /dev/zero and a FIFO hung the render for ever, past SIGTERM (OpenImageIO's format
    # probes read them); now the file is named and its input takes its fallback.
    file = {"device": "/dev/zero", "FIFO": str(tmp_path / "pipe.png"), "directory": str(tmp_path)}
    if kind == "FIFO":
        os.mkfifo(file[kind])
    usd = _texture_stage(tmp_path, file[kind])
    done = _record(str(usd), str(tmp_path / "out.exr"), "--imageWidth", "8", timeout=120)
    assert done.returncode == 0, done.stderr
    said = [line for line in done.stderr.splitlines() if file[kind] in line]
    assert said and all(line.startswith("mipray-record: ") for line in said), done.stderr
    if kind != "directory":
        assert f"not a regular file (a {kind})" in said[0], said


def test_a_usd_layer_that_is_a_fifo_is_refused_in_one_line(native, tmp_path) -> None:
    # USD read it for ever.
    fifo = tmp_path / "shot.usda"
    os.mkfifo(fifo)
    done = _record(str(fifo), str(tmp_path / "out.exr"), timeout=120)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [
        f"mipray-record: {fifo}: not a regular file (a FIFO); a USD layer must be a file"
    ]


def _available_gb() -> float:
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024 / 1e9
    except OSError:
        pass
    return math.inf


@pytest.mark.skipif(_available_gb() > 200, reason="this machine could hold a 65536-wide film")
def test_an_image_too_large_for_the_memory_is_refused_before_the_sync(native, tmp_path) -> None:
    # -w 65536 aborted the process on a 37 GB allocation, after the sync.
    stage = _stage_with(lambda stage: None)
    with pytest.raises(mipray.RenderSettingsError, match=r"memory available") as caught:
        _render(stage, width=65536)
    assert "65536x" in str(caught.value) and "\n" not in str(caught.value)
    usd = tmp_path / "big.usda"
    stage.GetRootLayer().Export(str(usd))
    done = _record(str(usd), str(tmp_path / "big.exr"), "--imageWidth", "65536")
    assert done.returncode == 1
    last = done.stderr.strip().splitlines()
    assert len(last) == 1 and "memory available" in last[0], done.stderr
    assert not (tmp_path / "big.exr").exists()


def test_prims_skipped_for_bad_data_are_listed_in_the_stats(native) -> None:
    # Only prims the renderer dropped were listed; those the scene delegate could not send
    # (caught in Python) were in result.errors but not in the stats.
    def build(stage: Usd.Stage) -> None:
        bad = UsdGeom.Mesh.Define(stage, "/World/Bad")
        bad.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (1, 1, 0)])
        bad.CreateFaceVertexCountsAttr([3])
        bad.CreateFaceVertexIndicesAttr([0, 1, 7])
        _scaled_parent((0.0, 0.0, 0.0))(stage)

    stage = _stage_with(build)
    result = _render(stage)
    _ok_is_drawn(stage, result)
    listed = result.stats["prim_errors"]
    assert [e for e in listed if e.startswith("/World/Bad:")] == [str(result.errors[0])]
    assert any(e.startswith("/World/Parent/Bad:") for e in listed), listed
    assert len(listed) == 2, listed


def test_a_native_instance_with_a_non_finite_transform_is_left_out_by_name(native) -> None:
    # Found by test_fuzz.py: a NaN rotation of one instance raised a ValueError out of
    # mipray.render (the whole frame lost) instead of dropping that instance.
    def build(stage: Usd.Stage) -> None:
        add_cube(stage, "/Proto/Cube")
        for name, x in (("Good", 1.4), ("Bad", 0.0)):
            prim = stage.DefinePrim(f"/World/{name}", "Xform")
            prim.GetReferences().AddInternalReference("/Proto")
            prim.SetInstanceable(True)
            UsdGeom.Xformable(prim).AddTranslateOp().Set(Gf.Vec3d(x, 0.9, 0.0))
        UsdGeom.Xformable(stage.GetPrimAtPath("/World/Bad")).AddRotateYOp().Set(float("nan"))

    stage = _stage_with(build)
    stage.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)
    result = _render(stage)
    _ok_is_drawn(stage, result)
    assert [str(e) for e in result.errors] == ["/World/Bad: its transform is not finite"]
    row, col = pixel_of(stage, "/World/Good", result.width, result.height, Usd.TimeCode.Default())
    assert result.aovs["color"][row, col].sum() > 0.0, "the good instance is missing"


def test_an_image_librarys_own_messages_never_reach_stderr_unprefixed(native, tmp_path) -> None:
    # A PNG cut short: libpng printed "libpng error: IHDR: ..." on stderr by itself, beside
    # mipray's own warning.
    cut = tmp_path / "cut.png"
    cut.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x04\x00\x00\x00\x04")
    usd = _texture_stage(tmp_path, str(cut))
    done = _record(str(usd), str(tmp_path / "out.exr"), "--imageWidth", "8", timeout=120)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert lines and all(line.startswith("mipray-record: ") for line in lines), done.stderr
    assert any(str(cut) in line for line in lines), done.stderr


@pytest.mark.parametrize("arc", ["sublayer", "reference", "payload", "variant reference"])
def test_a_layer_brought_in_that_is_a_fifo_is_refused_in_one_line(native, tmp_path, arc) -> None:
    # USD read it for ever while composing (only the root and session layers were checked).
    fifo = tmp_path / "part.usda"
    os.mkfifo(fifo)
    stage = _stage_with(lambda stage: None)
    root = stage.GetRootLayer()
    prim = stage.DefinePrim("/World/Part")
    if arc == "sublayer":
        root.subLayerPaths.append("./part.usda")
    elif arc == "reference":
        prim.GetReferences().AddReference("./part.usda")
    elif arc == "payload":
        prim.GetPayloads().AddPayload("./part.usda")
    else:
        variants = prim.GetVariantSets().AddVariantSet("look")
        variants.AddVariant("a")
        variants.SetVariantSelection("a")
        with variants.GetVariantEditContext():
            prim.GetReferences().AddReference("./part.usda")
    usd = tmp_path / "shot.usda"
    root.Export(str(usd))
    try:
        done = _record(str(usd), str(tmp_path / "out.exr"), "--imageWidth", "8", timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"a {arc} that is a FIFO hung the render")
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [
        f"mipray-record: {fifo}: not a regular file (a FIFO); a USD layer must be a file"
        f" (brought in by {usd})"
    ]
    with pytest.raises(mipray.StageError, match="not a regular file"):
        mipray.open_stage(usd)


def test_a_1024_gon_renders_with_bilinear_end_caps_named_in_the_stats(native) -> None:
    # Its Gregory end caps cost the square of its side count (a 16384-gon took over 24 GB).
    def build(stage: Usd.Stage) -> None:
        n = 1024
        mesh = UsdGeom.Mesh.Define(stage, "/World/NGon")
        angles = [2.0 * math.pi * i / n for i in range(n)]
        mesh.CreatePointsAttr([Gf.Vec3f(2 * math.cos(a), 2 * math.sin(a), 0.0) for a in angles])
        mesh.CreateFaceVertexCountsAttr([n])
        mesh.CreateFaceVertexIndicesAttr(list(range(n)))
        mesh.CreateSubdivisionSchemeAttr("catmullClark")

    result = _render(_stage_with(build))
    simplified = result.stats["scene"]["simplified"]
    assert len(simplified) == 1 and simplified[0].startswith(
        "/World/NGon: a vertex of valence 1024"
    )
    assert result.stats["prim_errors"] == []
    color = np.asarray(result.aovs["color"])
    h, w = color.shape[:2]
    assert np.isfinite(color).all() and color[h // 2, w // 2].sum() > 0.0, "the n-gon is missing"
