"""The throughput benchmark's scenes and export (``make bench-throughput``), without Embree.

The export is what the Embree harness traces, so it must be the USD stage mipray renders:
points, face counts and indices, creases, st and the displacement texture are compared here
with the stage read directly through ``pxr``. The cages are checked to be closed and
consistently wound (each directed edge once), the crease tags to sit on the box edges. The
driver's arithmetic (subtraction of the camera-only time, checks of the ray counts) and its
reading of ``perf report`` are checked on made-up inputs.
"""

from __future__ import annotations

import math
import random
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade

from mipray.tools.shapes import blob_cage, box_cage, wheel_cage
from mipray.tools.throughput import (
    Measured,
    depth_agreement,
    mipray_rates,
    parse_dso_symbols,
    parse_perf_report,
    prepare_scene,
    read_pfm,
)
from mipray.tools.throughput_scenes import ExportError, crease_edges, read_export


def _directed_edges(counts: list[int], indices: list[int]) -> Counter[tuple[int, int]]:
    edges: Counter[tuple[int, int]] = Counter()
    at = 0
    for n in counts:
        face = indices[at : at + n]
        for k in range(n):
            edges[(face[k], face[(k + 1) % n])] += 1
        at += n
    return edges


def _assert_closed_and_oriented(counts: list[int], indices: list[int]) -> None:
    edges = _directed_edges(counts, indices)
    assert max(edges.values()) == 1, "a directed edge twice: faces wound inconsistently"
    for a, b in edges:
        assert (b, a) in edges, f"edge {a}-{b} has one face: the cage is open"


def _signed_volume(points: list[tuple[float, float, float]], counts: list[int], idx: list[int]):
    """Volume by the divergence theorem over fan triangles: positive when wound outward."""
    p = np.asarray(points, np.float64)
    volume, at = 0.0, 0
    for n in counts:
        face = idx[at : at + n]
        for k in range(1, n - 1):
            volume += np.dot(p[face[0]], np.cross(p[face[k]], p[face[k + 1]])) / 6.0
        at += n
    return volume


def test_cages_are_closed_and_wound_outward():
    wheel = wheel_cage(0.5, 0.3, segments=12, sharpness=2.0)
    box = box_cage((2.0, 1.0, 1.0), (3, 2, 2), sharpness=1.0)
    points, indices = blob_cage(3, random.Random(1))
    cages = [
        (wheel.points, wheel.counts, wheel.indices),
        (box.points, box.counts, box.indices),
        (points, [4] * (len(indices) // 4), indices),
    ]
    for pts, counts, idx in cages:
        _assert_closed_and_oriented(counts, idx)
        assert _signed_volume(pts, counts, idx) > 0
    # The box is exactly its extents; the wheel a 12-gon prism (bulge aside) of its size.
    assert _signed_volume(box.points, box.counts, box.indices) == pytest.approx(2.0)
    prism = 0.5 * 12 * 0.5**2 * math.sin(2 * math.pi / 12) * 0.3
    assert _signed_volume(wheel.points, wheel.counts, wheel.indices) == pytest.approx(
        prism, rel=0.05
    )


def test_box_creases_are_its_edges():
    box = box_cage((2.0, 4.0, 6.0), (2, 1, 3), sharpness=2.5)
    # 4 edges along each axis, split into that axis's divisions.
    assert len(box.creases) == 4 * (2 + 1 + 3)
    half = np.array([1.0, 2.0, 3.0])
    for a, b, s in box.creases:
        assert s == 2.5
        pa, pb = np.array(box.points[a]), np.array(box.points[b])
        # On a box edge: the same +-half in two coordinates at both ends.
        shared = np.isclose(np.abs(pa), half) & np.isclose(pa, pb)
        assert shared.sum() == 2, (box.points[a], box.points[b])


def test_wheel_creases_are_its_rims():
    wheel = wheel_cage(0.4, 0.2, segments=8, sharpness=3.0)
    assert len(wheel.creases) == 16
    for a, b, s in wheel.creases:
        assert s == 3.0
        za, zb = wheel.points[a][2], wheel.points[b][2]
        assert za == zb and abs(za) == pytest.approx(0.1)


def test_crease_edges_expand_chains():
    indices = np.array([0, 1, 2, 5, 6])
    # One sharpness per crease: the chain 0-1-2 gets 1.5 on both edges.
    pairs, weights = crease_edges(indices, np.array([3, 2]), np.array([1.5, 4.0]))
    assert pairs.tolist() == [[0, 1], [1, 2], [5, 6]]
    assert weights.tolist() == [1.5, 1.5, 4.0]
    # One sharpness per crease edge.
    pairs, weights = crease_edges(indices, np.array([3, 2]), np.array([1.0, 2.0, 3.0]))
    assert weights.tolist() == [1.0, 2.0, 3.0]
    pairs, weights = crease_edges(None, None, None)
    assert pairs.shape == (0, 2) and weights.size == 0


def _usd_creases(mesh: UsdGeom.Mesh) -> list[tuple[int, int, float]]:
    """Crease edges straight from the USD attributes (one sharpness per crease here)."""
    idx = list(mesh.GetCreaseIndicesAttr().Get() or [])
    lengths = list(mesh.GetCreaseLengthsAttr().Get() or [])
    sharp = list(mesh.GetCreaseSharpnessesAttr().Get() or [])
    out, at = [], 0
    for c, n in enumerate(lengths):
        out += [(idx[at + e], idx[at + e + 1], sharp[c]) for e in range(n - 1)]
        at += n
    return out


def _check_export(scene_name: str, tmp_path: Path) -> None:
    scene = prepare_scene(scene_name, tmp_path, small=True)
    exported = read_export(scene.export)
    stage = Usd.Stage.Open(str(scene.usd))
    xforms = UsdGeom.XformCache(Usd.TimeCode.Default())
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    assert [m.path for m in exported.meshes] == [str(p.GetPath()) for p in meshes]
    assert scene.control_faces == sum(
        len(UsdGeom.Mesh(p).GetFaceVertexCountsAttr().Get()) for p in meshes
    )
    for prim, out in zip(meshes, exported.meshes, strict=True):
        mesh = UsdGeom.Mesh(prim)
        m = np.array(xforms.GetLocalToWorldTransform(prim))
        local = np.asarray(mesh.GetPointsAttr().Get(), np.float64)
        world = local @ m[:3, :3] + m[3, :3]
        np.testing.assert_allclose(out.points, world, rtol=0, atol=1e-5)
        assert out.counts.tolist() == list(mesh.GetFaceVertexCountsAttr().Get())
        assert out.indices.tolist() == list(mesh.GetFaceVertexIndicesAttr().Get())
        assert out.scheme == mesh.GetSubdivisionSchemeAttr().Get()
        got = [
            (int(a), int(b), float(w))
            for (a, b), w in zip(out.crease_pairs, out.crease_weights, strict=True)
        ]
        assert got == _usd_creases(mesh)
        primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
        if primvar and primvar.HasValue():
            np.testing.assert_array_equal(out.st, np.asarray(primvar.Get(), np.float32))
        else:
            assert out.st is None
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if material and material.GetDisplacementOutput().HasConnectedSource():
            texture = UsdShade.Shader(
                stage.GetPrimAtPath(material.GetPath().AppendChild("HeightTexture"))
            )
            assert out.displacement is not None
            path, scale, bias, channel, wrap_s, wrap_t = out.displacement
            assert Path(path) == Path(texture.GetInput("file").Get().resolvedPath)
            assert Path(path).is_file()
            assert scale == pytest.approx(texture.GetInput("scale").Get()[0])
            assert bias == pytest.approx(texture.GetInput("bias").Get()[0])
            assert (channel, wrap_s, wrap_t) == (0, 2, 2)  # r, repeat, repeat
        else:
            assert out.displacement is None
    # Camera and sun: the eye is the camera's position, forward its -Z axis, the sun its +Z.
    camera = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Camera))
    cam = np.array(xforms.GetLocalToWorldTransform(camera))
    np.testing.assert_allclose(exported.eye, cam[3, :3], atol=1e-5)
    np.testing.assert_allclose(
        exported.forward, -cam[2, :3] / np.linalg.norm(cam[2, :3]), atol=1e-6
    )
    focal = UsdGeom.Camera(camera).GetFocalLengthAttr().Get()
    aperture = UsdGeom.Camera(camera).GetHorizontalApertureAttr().Get()
    assert np.linalg.norm(exported.right) == pytest.approx(0.5 * aperture / focal, rel=1e-6)
    sun = next(p for p in stage.Traverse() if p.IsA(UsdLux.DistantLight))
    z = np.array(xforms.GetLocalToWorldTransform(sun))[2, :3]
    np.testing.assert_allclose(exported.to_sun, z / np.linalg.norm(z), atol=1e-6)


def test_plain_export_is_the_usd_stage(tmp_path):
    _check_export("plain", tmp_path)
    exported = read_export(tmp_path / "plain.bin")
    cars = [m for m in exported.meshes if m.scheme == "catmullClark"]
    assert len(cars) == 2 and all(len(m.crease_weights) > 0 for m in cars)


def test_displaced_export_is_the_usd_stage(tmp_path, native):
    if shutil.which("maketx") is None:
        pytest.skip("maketx (openimageio-tools) is not installed")
    _check_export("displaced", tmp_path)
    exported = read_export(tmp_path / "displaced.bin")
    blobs = [m for m in exported.meshes if m.displacement is not None]
    assert len(blobs) == 2 and all(len(m.counts) == 6 * 2 * 2 for m in blobs)


def test_session_layers_turn_lights_off_and_surfaces_into_mirrors(tmp_path):
    scene = prepare_scene("plain", tmp_path, small=True)
    root = Sdf.Layer.FindOrOpen(str(scene.usd))

    def with_session(name: str) -> Usd.Stage:
        return Usd.Stage.Open(root, Sdf.Layer.FindOrOpen(str(scene.sessions[name])))

    plain = Usd.Stage.Open(root)
    assert any(p.HasAPI(UsdLux.LightAPI) for p in plain.Traverse())
    for name in ("dark", "mirror"):
        stage = with_session(name)
        assert not any(p.HasAPI(UsdLux.LightAPI) for p in stage.Traverse())
    mirror = with_session("mirror")
    surfaces = [
        UsdShade.Shader(p)
        for p in mirror.Traverse()
        if p.IsA(UsdShade.Shader) and UsdShade.Shader(p).GetIdAttr().Get() == "UsdPreviewSurface"
    ]
    assert surfaces
    for s in surfaces:
        assert s.GetInput("metallic").Get() == 1.0 and s.GetInput("roughness").Get() == 0.0


def test_read_export_rejects_other_files(tmp_path):
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"NOTMINE!" + bytes(8))
    with pytest.raises(ExportError, match=r"bad\.bin"):
        read_export(bad)
    scene = prepare_scene("plain", tmp_path, small=True)
    cut = tmp_path / "cut.bin"
    cut.write_bytes(scene.export.read_bytes()[:200])
    with pytest.raises(ExportError, match=r"cut\.bin"):
        read_export(cut)


def test_rates_subtract_the_camera_pass_run_by_run():
    camera = {"camera": 100}
    measured = {
        "camera": Measured([2.0, 3.0, 2.5], [camera] * 3, [6.0, 7.0, 5.0]),
        "ao": Measured([10.0, 12.0, 10.5], [{**camera, "ao": 6400}] * 3, [30.0, 31.0, 33.0]),
        "shadow": Measured([2.5, 3.5, 3.0], [{**camera, "shadow": 90}] * 3),
        # A reflection pass that also traced shadow rays, and counts that moved: both noted.
        "reflection": Measured(
            [3.0, 4.0, 3.0],
            [
                {**camera, "reflection": 100, "shadow": 5},
                {**camera, "reflection": 99},
                {**camera, "reflection": 100},
            ],
        ),
    }
    rates = mipray_rates(measured)
    assert rates["camera"].rays == 100 and rates["camera"].seconds == 2.5
    assert rates["ao"].seconds == pytest.approx(8.0)  # median of 8, 9, 8
    assert rates["ao"].per_s == pytest.approx(800.0)
    # CPU seconds by the same run-by-run difference: median of 24, 24, 28.
    assert rates["ao"].cpu_s == pytest.approx(24.0)
    assert rates["ao"].per_cpu_s == pytest.approx(6400 / 24.0)
    assert rates["camera"].cpu_s is None and rates["shadow"].cpu_s is None
    assert rates["shadow"].seconds == pytest.approx(0.5)
    assert rates["ao"].notes == [] and rates["shadow"].notes == []
    notes = " ".join(rates["reflection"].notes)
    assert "differ between runs" in notes and "5 shadow" in notes


def test_parse_perf_report():
    text = (
        "# Samples: 10K of event 'cpu-clock'\n"
        "#\n"
        "    21.20%  [.] mipray_bridge::OsdMesh::Impl::eval          -      -  \n"
        "     9.11%  [.] mipray::geometry_cache::tier_cache::TierCache<E>::get_or_build   \n"
        "\n"
        "     0.90%  [k] clear_page_erms\n"
        "    56.27%    22858:mipray-record\n"
    )
    rows = parse_perf_report(text, 10)
    assert rows == [
        (21.2, "mipray_bridge::OsdMesh::Impl::eval"),
        (9.11, "mipray::geometry_cache::tier_cache::TierCache<E>::get_or_build"),
        (0.9, "clear_page_erms"),
        (56.27, "22858:mipray-record"),
    ]
    assert parse_perf_report(text, 1) == rows[:1]


def test_depth_agreement_reads_pfm_and_compares_hits(tmp_path):
    # A 3×2 PFM, rows stored bottom-up: the top row of the image is the file's last.
    top, bottom = [1.0, 2.0, 0.0], [4.0, 0.0, 6.0]
    pfm = tmp_path / "d.pfm"
    pfm.write_bytes(b"Pf\n3 2\n-1.0\n" + np.asarray(bottom + top, "<f4").tobytes())
    embree = read_pfm(pfm)
    assert embree.tolist() == [top, bottom]
    mipray = np.array([[1.0, 2.02, 3.0], [4.0, 5.0, 0.0]], np.float32)
    got = depth_agreement(embree, mipray)
    assert (got["both"], got["only_embree"], got["only_mipray"]) == (3, 1, 2)
    assert got["over_1pct"] == 0 and got["median_rel"] == 0.0
    assert got["p99_rel"] == pytest.approx(0.02 / 2.02 * 0.98, rel=1e-3)


def test_parse_dso_symbols_sums_objects():
    pad = " " * 40 + "-      -  "
    text = (
        "# Overhead  Shared Object  Symbol\n"
        f"    60.00%  _mipray.so   [.] mipray::seam::intersect_seams{pad}\n"
        f"    20.00%  libosdCPU.so [.] OpenSubdiv::Far::EvalBasisBSpline<double>{pad}\n"
        f"    19.70%  _mipray.so   [.] mipray::trace::Tracer::trace{pad}\n"
        "     0.30%  libc.so.6    [.] memcpy\n"
    )
    symbols, objects = parse_dso_symbols(text)
    assert symbols == [
        (60.0, "mipray::seam::intersect_seams"),
        (20.0, "OpenSubdiv::Far::EvalBasisBSpline<double>"),
        (19.7, "mipray::trace::Tracer::trace"),
    ]
    assert objects == [(79.7, "_mipray.so"), (20.0, "libosdCPU.so")]
