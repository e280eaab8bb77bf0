"""The Blender add-on (``mipray.blender``) inside Blender's own Python module, ``bpy``, headless.

Each test starts from Blender's factory scene (camera, 2×2×2 cube, light) at a few dozen pixels
wide, renders with ``bpy.ops.render.render`` and reads what Blender wrote: Cycles is the peer
for light and geometry, mipray's own API on the same exported stage the truth for the passes.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent

if sys.version_info[:2] != (3, 11) and not os.environ.get("CI"):
    # bpy 5.0 is built for CPython 3.11 alone; scripts/requirements.txt installs it there.
    pytest.skip("bpy needs CPython 3.11", allow_module_level=True)

import bpy  # noqa: E402
from pxr import Usd, UsdGeom  # noqa: E402

import mipray  # noqa: E402
from mipray import _mipray  # noqa: E402
from mipray import blender as mipray_blender  # noqa: E402
from mipray.blender import engine, export  # noqa: E402
from mipray.blender.passes import blender_passes  # noqa: E402
from mipray.blender.properties import ENGINE_SETTINGS, render_settings  # noqa: E402
from mipray.settings import TABLE  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def registered():
    mipray_blender.register()
    yield
    mipray_blender.unregister()


@pytest.fixture
def scene():
    """Blender's default scene, rendered by mipray at 48×27."""
    bpy.ops.wm.read_factory_settings(use_empty=False)
    sc = bpy.context.scene
    sc.render.engine = "MIPRAY"
    sc.render.resolution_x, sc.render.resolution_y = 48, 27
    sc.render.resolution_percentage = 100
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.view_settings.view_transform = "Standard"
    # Cycles' alpha is the coverage only with a transparent film (mipray's always is).
    sc.render.film_transparent = True
    sc.mipray.samples = 4
    return sc


def _render(sc, path: Path) -> np.ndarray:
    """Render ``sc`` to the EXR ``path``; its RGBA pixels, top row first."""
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return _mipray.read_image(str(path))[0]


def _render_layers(sc, path: Path) -> dict[str, np.ndarray]:
    """Render ``sc`` to a multilayer EXR; pass name → H×W×C pixels, as Blender wrote them."""
    sc.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    info = subprocess.run(
        ["oiiotool", "--info", "-v", str(path)], capture_output=True, text=True, check=True
    ).stdout
    count = int(m.group(1)) if (m := re.search(r"(\d+) subimages", info)) else 1
    parts = [path.with_suffix(f".part{index}.exr") for index in range(count)]
    # One oiiotool for all parts: its start-up is most of its time.
    command = ["oiiotool"]
    for index, part in enumerate(parts):
        command += [str(path), "--subimage", str(index), "-o", str(part)]
    subprocess.run(command, check=True)
    layers = {}
    for part in parts:
        pixels, channels = _mipray.read_image(str(part))
        names = {c.split(".")[1] for c in channels}
        assert len(names) == 1, channels
        layers[names.pop()] = pixels
    return layers


def _exported_render(sc, aovs, tmp_path: Path) -> mipray.RenderResult:
    """mipray's own render of what the add-on exports of ``sc``, with the panel's settings."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    stage = mipray.open_stage(export.export_usd(depsgraph, str(tmp_path)))
    export.match_blender_lights(stage, depsgraph)
    with mipray.RenderSession(stage) as session:
        return session.render(
            export.camera_prim(stage, sc.camera),
            sc.render.resolution_x,
            aovs,
            render_settings(sc.mipray),
            height=sc.render.resolution_y,
            camera_light=False,
        )


def test_settings_are_the_tables_and_saved_in_the_blend(scene, tmp_path):
    props = scene.mipray.bl_rna.properties
    for key, row in TABLE.items():
        if key in ENGINE_SETTINGS:
            assert key not in props, key
            continue
        prop = props[key]
        if row["type"] == "choice":
            assert [item.identifier for item in prop.enum_items] == row["choices"]
        if row["default"] is not None and row["type"] in ("int", "choice"):
            assert prop.default == row["default"], key
        if row["type"] in ("int", "float") and row["max"] is not None and row["max"] < 2**31:
            assert prop.hard_max == pytest.approx(row["max"]), key
        if row["default"] is None:
            assert f"use_{key}" in props, key
    # Every value the panel holds is one the renderer takes.
    for key, value in render_settings(scene.mipray).items():
        _mipray.parse_setting(key, value)
    scene.mipray.samples = 7
    scene.mipray.cacheMode = "single"
    scene.mipray.tessFactor = 2.5
    scene.mipray.use_geometryCacheFineMb = True
    scene.mipray.geometryCacheFineMb = 3.0
    blend = tmp_path / "saved.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.read_factory_settings(use_empty=False)
    assert bpy.context.scene.mipray.samples == TABLE["samples"]["default"]
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    saved = render_settings(bpy.context.scene.mipray)
    assert saved["samples"] == 7 and saved["cacheMode"] == "single"
    assert saved["tessFactor"] == pytest.approx(2.5) and saved["geometryCacheFineMb"] == 3.0
    assert "geometryCacheCoarseMb" not in saved


class _Layout:
    """Records what a panel's ``draw`` lays out (Blender draws no UI headless)."""

    def __init__(self, shown: list[str]):
        self.shown = shown
        self.use_property_split = False
        self.active = True

    def prop(self, data, name, **kwargs):
        assert hasattr(data, name), name
        self.shown.append(name)

    def box(self):
        return self

    def row(self, **kwargs):
        return self

    def label(self, **kwargs):
        pass


def test_panels_show_every_setting_and_pass(scene):
    context = SimpleNamespace(scene=scene, view_layer=bpy.context.view_layer, engine="MIPRAY")
    for panel, expected in (
        (mipray_blender.RENDER_PT_mipray, [k for k in TABLE if k not in ENGINE_SETTINGS]),
        (mipray_blender.VIEWLAYER_PT_mipray_passes, [p.aov for p in blender_passes()]),
    ):
        shown: list[str] = []
        assert panel.poll(context)
        panel.draw(SimpleNamespace(layout=_Layout(shown)), context)
        assert sorted(n for n in shown if not n.startswith("use_")) == sorted(expected)


def test_passes_hold_mipray_aovs_with_their_shapes(scene, tmp_path):
    for p in blender_passes():
        setattr(bpy.context.view_layer.mipray, p.aov, True)
    scene.mipray.aoSamples = 2
    layers = _render_layers(scene, tmp_path / "passes.exr")
    h, w = scene.render.resolution_y, scene.render.resolution_x
    assert layers["Combined"].shape == (h, w, 4)
    for p in blender_passes():
        assert layers[p.name].shape == (h, w, p.channels), p.name
    # The same stage through mipray's API: the pixels Blender holds are mipray's, rows in place.
    truth = _exported_render(scene, ["color", "alpha", "depth", "normal", "tessError"], tmp_path)
    np.testing.assert_allclose(layers["Combined"][..., :3], truth.aovs["color"], atol=1e-6)
    np.testing.assert_allclose(layers["Combined"][..., 3:], truth.aovs["alpha"], atol=1e-6)
    hit = truth.aovs["alpha"][..., 0] > 0
    assert hit.any() and not hit.all()
    np.testing.assert_allclose(layers["Depth"][hit], truth.aovs["depth"][hit], rtol=1e-6)
    np.testing.assert_allclose(layers["Normal"], truth.aovs["normal"], atol=1e-6)
    np.testing.assert_allclose(layers["tessError"], truth.aovs["tessError"], atol=1e-6)
    assert np.isfinite(layers["Depth"]).all()


def test_progressive_passes_and_stats_line(scene, tmp_path):
    lines: list[str] = []

    def on_stats(*args):
        lines.append(" ".join(str(a) for a in args))

    bpy.app.handlers.render_stats.append(on_stats)
    try:
        scene.mipray.samples = 4
        _render(scene, tmp_path / "progressive.exr")
    finally:
        bpy.app.handlers.render_stats.remove(on_stats)
    text = "\n".join(lines)
    # Passes of 1, 2 and 4 samples per pixel, each shown as it came.
    for n, spp in ((1, 1), (2, 2), (3, 4)):
        assert f"pass {n}/3 ({spp} spp)" in text, text
    assert re.search(r"cache hits .*recomputed vertices .*Mrays/s", text), text


def test_esc_stops_after_the_pass_in_flight_and_keeps_it(scene, tmp_path, monkeypatch):
    lines: list[str] = []

    def on_stats(*args):
        lines.append(" ".join(str(a) for a in args))

    # Esc pressed from the start: Blender's test_break answers True (no keyboard headless).
    monkeypatch.setattr(engine, "esc_pressed", lambda _engine: True)
    bpy.app.handlers.render_stats.append(on_stats)
    try:
        scene.mipray.samples = 16
        stopped = _render(scene, tmp_path / "stopped.exr")
    finally:
        bpy.app.handlers.render_stats.remove(on_stats)
    monkeypatch.undo()
    assert any("cancelled after pass 1/5" in line for line in lines), lines
    # The image kept is the first pass: one sample per pixel, as a one-sample render has it.
    scene.mipray.samples = 1
    one = _render(scene, tmp_path / "one.exr")
    np.testing.assert_allclose(stopped, one, atol=1e-6)
    scene.mipray.samples = 16
    assert np.abs(_render(scene, tmp_path / "all.exr") - one).max() > 1e-3


def _lambertian_cube_under_sun(sc):
    """The default cube, white-ish lambertian, lit by one sun in a black world."""
    bpy.data.objects.remove(bpy.data.objects["Light"])
    sun_data = bpy.data.lights.new("Sun", "SUN")
    sun_data.energy = 3.0
    sun_data.angle = 0.0
    sun = bpy.data.objects.new("Sun", sun_data)
    sc.collection.objects.link(sun)
    sun.rotation_euler = (0.6, 0.2, 0.9)
    sc.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    bsdf = bpy.data.materials["Material"].node_tree.nodes["Principled BSDF"]
    # IOR 1: no Fresnel reflection in Cycles' Principled BSDF nor in UsdPreviewSurface
    # (F0 = 0 and F90 = 0 in mipray's), leaving each a pure lambertian of the base colour.
    bsdf.inputs["IOR"].default_value = 1.0
    sc.cycles.samples = 64
    sc.cycles.device = "CPU"
    sc.cycles.use_denoising = False
    sc.cycles.pixel_filter_type = "BOX"
    sc.cycles.max_bounces = 0


def test_lambertian_cube_under_sun_matches_cycles(scene, tmp_path):
    _lambertian_cube_under_sun(scene)
    scene.render.resolution_x, scene.render.resolution_y = 96, 54
    scene.mipray.samples = 16
    mine = _render(scene, tmp_path / "mipray.exr")
    scene.render.engine = "CYCLES"
    cycles = _render(scene, tmp_path / "cycles.exr")
    assert cycles[..., :3].mean() > 0.03  # lit, so the comparison says something
    # One convex cube under a delta sun: direct light only, no noise inside a face, so the
    # means agree to the 0.2% the edges' sampling leaves (Cycles 64 box-filtered random samples,
    # mipray 16 stratified ones); a 4x error in the sun's units would be 75%.
    np.testing.assert_allclose(mine[..., :3].mean(), cycles[..., :3].mean(), rtol=0.01)
    diff = np.abs(mine[..., :3] - cycles[..., :3]).max(axis=2)
    # Inside a face (a pixel whose 3×3 neighbourhood in Cycles' image is one flat colour and
    # fully covered) each pixel's shading is exact in both renderers.
    luma = np.where(cycles[..., 3] > 0.999, cycles[..., 0], np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(
        np.pad(luma, 1, constant_values=np.nan), (3, 3)
    )
    inside = np.ptp(windows, axis=(2, 3)) < 1e-4
    # The figures of README's Blender section (`pytest -s -k cycles` prints them).
    print(
        f"\nmean: mipray {mine[..., :3].mean():.5f}, Cycles {cycles[..., :3].mean():.5f}; "
        f"face interiors: {inside.sum()} px, max |diff| {diff[inside].max():.2e}; "
        f"all pixels: max |diff| {diff.max():.3f}, {100 * (diff > 0.05).mean():.2f}% beyond 0.05"
    )
    assert inside.sum() > 300
    assert diff[inside].max() < 0.01
    # Pixels the cube's edges cross are covered by differing sample positions; they are ~1% of
    # the image and differ by at most ~0.17 (measured 0.7% beyond 0.05).
    assert (diff > 0.05).mean() < 0.02


def _subdivided_cube(sc, crease: float | None = None):
    cube = bpy.data.objects["Cube"]
    if crease is not None:
        attr = cube.data.attributes.new("crease_edge", "FLOAT", "EDGE")
        attr.data.foreach_set("value", [crease] * len(cube.data.edges))
    modifier = cube.modifiers.new("Subdivision", "SUBSURF")
    modifier.levels = modifier.render_levels = 1
    return cube, modifier


def _coverage(pixels: np.ndarray) -> float:
    return float(pixels[..., 3].sum())


def test_subdivision_surface_renders_the_limit_surface_with_creases(scene, tmp_path):
    scene.render.resolution_x, scene.render.resolution_y = 96, 54
    scene.cycles.samples = 16
    scene.cycles.pixel_filter_type = "BOX"
    cube_area = _coverage(_render(scene, tmp_path / "cube.exr"))
    cube, modifier = _subdivided_cube(scene)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    stage = mipray.open_stage(export.export_usd(depsgraph, str(tmp_path)))
    mesh = next(p for p in stage.Traverse() if p.GetTypeName() == "Mesh")
    # The control cage and its scheme are exported, not the modifier's mesh.
    assert mesh.GetAttribute("subdivisionScheme").Get() == "catmullClark"
    assert len(mesh.GetAttribute("faceVertexCounts").Get()) == 6
    limit = _coverage(_render(scene, tmp_path / "limit.exr"))
    # Cycles renders the modifier's mesh: level 1 is coarser than the limit surface, level 5 is
    # within a fraction of a pixel of it.
    scene.render.engine = "CYCLES"
    level1 = _coverage(_render(scene, tmp_path / "level1.exr"))
    modifier.render_levels = 5
    level5 = _coverage(_render(scene, tmp_path / "level5.exr"))
    print(
        f"\ncoverage in pixels: cube {cube_area:.1f}, mipray limit {limit:.1f}, "
        f"Cycles level 1 {level1:.1f}, level 5 {level5:.1f}"
    )
    assert abs(level1 - level5) > 0.03 * level5
    assert abs(limit - level5) < 0.005 * level5
    assert limit < 0.9 * cube_area
    # Creases of 1 (infinitely sharp) on every edge keep the cube a cube.
    scene.render.engine = "MIPRAY"
    cube.modifiers.remove(modifier)
    _subdivided_cube(scene, crease=1.0)
    creased = _coverage(_render(scene, tmp_path / "creased.exr"))
    print(f"all edges creased: {creased:.1f}")
    assert abs(creased - cube_area) < 0.005 * cube_area


def test_base_colour_texture_arrives(scene, tmp_path):
    # A 4×4 texture of one sRGB colour, and the same colour as a constant base colour: the
    # renders agree only if the texture is exported, bound and decoded from sRGB.
    srgb = np.array([200, 60, 30]) / 255.0
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    image = bpy.data.images.new("swatch", 4, 4)
    image.pixels.foreach_set(np.tile([*srgb, 1.0], 16).astype(np.float32))
    image.filepath_raw = str(tmp_path / "swatch.png")
    image.file_format = "PNG"
    image.save()
    tree = bpy.data.materials["Material"].node_tree
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*linear, 1.0)
    constant = _render(scene, tmp_path / "constant.exr")
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    textured = _render(scene, tmp_path / "textured.exr")
    hit = constant[..., 3] > 0.999
    assert textured[hit, 0].mean() > 2 * textured[hit, 1].mean()
    np.testing.assert_allclose(
        textured[hit, :3].mean(axis=0), constant[hit, :3].mean(axis=0), rtol=0.02
    )


def test_failed_export_is_a_blender_report(scene, tmp_path, monkeypatch):
    # An option value this Blender's exporter does not take: the exporter refuses to run.
    monkeypatch.setitem(export.EXPORT_OPTIONS, "export_subdivision", "NO_SUCH_MODE")
    with pytest.raises(RuntimeError, match=r"mipray: USD export to .* failed"):
        bpy.ops.render.render(write_still=False)
    monkeypatch.undo()
    # Blender and the add-on go on working.
    assert _render(scene, tmp_path / "after.exr")[..., 3].max() > 0.99


def test_object_the_export_drops_is_named_and_the_rest_renders(scene, tmp_path, capfd):
    volume = bpy.data.objects.new("Smoke", bpy.data.volumes.new("Smoke"))
    scene.collection.objects.link(volume)
    pixels = _render(scene, tmp_path / "volume.exr")
    out = capfd.readouterr()
    lines = [line for line in (out.out + out.err).splitlines() if "Smoke" in line]
    assert lines == [
        "Warning: mipray: object 'Smoke' (volume): no mesh in the USD export; rendered without it"
    ], out
    assert pixels[..., 3].max() > 0.99


def _instance_on_points(grid: object, prototype: object, as_instance: bool) -> None:
    """Geometry nodes on ``grid``: ``prototype`` instanced on each of its points."""
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    group_in = tree.nodes.new("NodeGroupInput")
    group_out = tree.nodes.new("NodeGroupOutput")
    scatter = tree.nodes.new("GeometryNodeInstanceOnPoints")
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = prototype
    info.inputs["As Instance"].default_value = as_instance
    tree.links.new(group_in.outputs[0], scatter.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], scatter.inputs["Instance"])
    tree.links.new(scatter.outputs[0], group_out.inputs[0])
    grid.modifiers.new("Scatter", "NODES").node_group = tree


@pytest.mark.parametrize("as_instance", [True, False])
def test_geometry_node_instances_render_or_are_named(scene, tmp_path, capfd, as_instance):
    # A 2×2 grid of points below the cube, each carrying a small ico sphere.
    bpy.ops.mesh.primitive_grid_add(
        x_subdivisions=1, y_subdivisions=1, size=3, location=(0, 0, -1.3)
    )
    grid = bpy.context.active_object
    grid.name = "Scatter"
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.3, location=(50, 0, 0))
    prototype = bpy.context.active_object
    prototype.hide_render = True
    _instance_on_points(grid, prototype, as_instance)
    stage = Usd.Stage.Open(export.export_usd(bpy.context.evaluated_depsgraph_get(), str(tmp_path)))
    placed = [
        prim
        for prim in stage.Traverse()
        if prim.IsA(UsdGeom.Mesh)
        and len(UsdGeom.Mesh(prim).GetFaceVertexCountsAttr().Get()) > 0
        and "Scatter" in str(prim.GetPath())
    ]
    _render(scene, tmp_path / "scatter.exr")
    out = capfd.readouterr()
    lines = [line for line in (out.out + out.err).splitlines() if "Scatter" in line]
    if as_instance:
        # The four spheres arrive as meshes, and nothing is reported.
        assert len(placed) >= 4 and lines == [], (placed, lines)
    else:
        # The exporter wrote them empty: the report says so, by object and count.
        assert placed == []
        assert lines == [
            "Warning: mipray: object 'Scatter': 4 geometry-node instances came out of the USD "
            "export empty (an Object Info node without 'As Instance', or geometry the exporter "
            "cannot write); rendered without it"
        ], out


def test_addon_zip_installs_and_renders(tmp_path):
    """The zip ``make blender-addon`` writes, installed by Blender's add-on installer.

    In a fresh process, so the add-on imports the mipray it ships, not this test's.
    """
    archive = tmp_path / "mipray_blender.zip"
    subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "make_blender_addon.py"), str(archive)],
        check=True,
        capture_output=True,
    )
    names = zipfile.ZipFile(archive).namelist()
    assert "mipray_blender/__init__.py" in names
    assert any(re.match(r"mipray_blender/lib/mipray/_mipray.*\.so$", n) for n in names)
    script = f"""
import bpy, sys
bpy.ops.wm.read_factory_settings(use_empty=False)
bpy.ops.preferences.addon_install(filepath={str(archive)!r}, target="DEFAULT")
bpy.ops.preferences.addon_enable(module="mipray_blender")
import mipray
assert "mipray_blender" in mipray.__file__, mipray.__file__
sc = bpy.context.scene
sc.render.engine = "MIPRAY"
sc.render.resolution_x, sc.render.resolution_y = 32, 18
sc.render.image_settings.file_format = "OPEN_EXR"
sc.render.filepath = {str(tmp_path / "zip.exr")!r}
bpy.ops.render.render(write_still=True)
"""
    env = dict(
        os.environ,
        BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"),
        BLENDER_USER_CONFIG=str(tmp_path / "config"),
        BLENDER_USER_RESOURCES=str(tmp_path / "resources"),
    )
    done = subprocess.run(
        [sys.executable, "-c", script], env=env, cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-2000:]
    pixels = _mipray.read_image(str(tmp_path / "zip.exr"))[0]
    assert pixels.shape == (18, 32, 4) and pixels[..., 3].max() > 0.99
