"""Rendering on a Dask cluster (mipray.distributed): a LocalCluster of 2 worker processes.

Truth is the single-machine render: every image from the cluster, as frames or as
tiles, on 1 or 2 workers, after a worker was killed mid-frame, must equal it bit for
bit. What each worker synced comes from its scene delegate's sync counts.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdLux

from stages import CUBE_COUNTS, CUBE_INDICES, CUBE_POINTS

distributed = pytest.importorskip("distributed")
mipray = pytest.importorskip("mipray")
cluster_api = pytest.importorskip("mipray.distributed")
record = pytest.importorskip("mipray.record")
pytest.importorskip("mipray._mipray", reason="the compiled module is not built")

WIDTH = 40
AOVS = ("color", "depth", "normal", "primId")
SETTINGS = {"samples": 4, "aoSamples": 2, "seed": 7}
FRAMES = [1.0, 2.0, 3.0, 4.0]
STATIC, ANIMATED = "/World/Static", "/World/Anim"


def write_stage(
    path: Path, *, bad_camera_at: float | None = None, nan_at: float | None = None
) -> str:
    """A static and a time-varying subdivision cube (points move per frame), a camera, a light."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(4)
    UsdGeom.Xform.Define(stage, "/World")
    for prim_path, x in ((STATIC, -0.8), (ANIMATED, 0.8)):
        mesh = UsdGeom.Mesh.Define(stage, prim_path)
        mesh.CreateFaceVertexCountsAttr(CUBE_COUNTS)
        mesh.CreateFaceVertexIndicesAttr(CUBE_INDICES)
        mesh.CreateSubdivisionSchemeAttr("catmullClark")
        mesh.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
        mesh.AddRotateXYZOp().Set(Gf.Vec3f(30, 40, 0))
        points = mesh.CreatePointsAttr()
        if prim_path == STATIC:
            points.Set(CUBE_POINTS)
            continue
        for frame in FRAMES:
            scale = 0.8 + 0.1 * frame
            moved = [Gf.Vec3f(*(scale * c for c in p)) for p in CUBE_POINTS]
            if frame == nan_at:
                moved[0] = Gf.Vec3f(math.nan, 0, 0)
            points.Set(moved, frame)
    camera = UsdGeom.Camera.Define(stage, "/World/Cam")
    camera.AddTranslateOp().Set(Gf.Vec3d(0, 0, 5))
    camera.CreateFocalLengthAttr(35.0)
    if bad_camera_at is not None:
        # Interpolated between whole frames: only that frame's focal length is 0.
        for frame, focal in (
            (bad_camera_at - 1, 35.0),
            (bad_camera_at, 0.0),
            (bad_camera_at + 1, 35.0),
        ):
            camera.GetFocalLengthAttr().Set(focal, frame)
    light = UsdLux.DistantLight.Define(stage, "/World/Sun")
    light.CreateIntensityAttr(2.0)
    light.AddRotateXOp().Set(-45.0)
    stage.GetRootLayer().Save()
    return str(path)


@pytest.fixture(scope="module")
def stage_path(tmp_path_factory: pytest.TempPathFactory) -> str:
    return write_stage(tmp_path_factory.mktemp("dask") / "cubes.usda")


@contextlib.contextmanager
def local_cluster(workers: int) -> Iterator[distributed.Client]:
    """A client of a new LocalCluster of ``workers`` processes, closed after."""
    c = cluster_api.connect(local_cluster=workers)
    try:
        yield c
    finally:
        cluster = c.cluster
        c.close()
        cluster.close()


@pytest.fixture(scope="module")
def client():
    with local_cluster(2) as c:
        yield c


def local(path: str, frame: float) -> mipray.RenderResult:
    """The single-machine render: the truth."""
    return mipray.render(path, "/World/Cam", WIDTH, AOVS, SETTINGS, time=frame)


def assert_same_bits(got: mipray.RenderResult, want: mipray.RenderResult, what: str) -> None:
    assert set(got.aovs) == set(want.aovs), what
    for name, expected in want.aovs.items():
        assert got.aovs[name].shape == expected.shape, f"{what}: {name}"
        same = np.array_equal(got.aovs[name].view(np.uint32), expected.view(np.uint32))
        assert same, f"{what}: AOV {name} differs from the single-machine render"


def test_tiles_assemble_into_the_single_machine_image_bit_for_bit(client, stage_path) -> None:
    want = local(stage_path, 1.0)
    assert want.aovs["color"].max() > 0.05, "the cubes are in view"
    for tiles in (4, 6):
        got = mipray.render(
            stage_path, "/World/Cam", WIDTH, AOVS, SETTINGS, time=1.0, client=client, tiles=tiles
        )
        assert_same_bits(got, want, f"{tiles} tiles")
        assert got.stats["distributed"]["pieces"] == tiles
        # Merged stats add up: every ray of the frame is counted once, in the tile that shot it.
        assert got.stats["render"]["rays"] == want.stats["render"]["rays"]
        per_worker = got.stats["distributed"]["workers"].values()
        merged = cluster_api.cache_figures(got.stats)
        for key in ("lookups", "misses", "recomputed_vertices"):
            assert sum(w["geometry_cache"][key] for w in per_worker) == merged[key], key
        assert sum(w["pieces"] for w in per_worker) == tiles


def test_frames_are_the_same_on_one_and_two_workers(client, stage_path) -> None:
    want = [local(stage_path, f) for f in FRAMES]
    two = cluster_api.render_frames(client, stage_path, FRAMES, "/World/Cam", WIDTH, AOVS, SETTINGS)
    first = sorted(client.scheduler_info()["workers"])[0]
    one = cluster_api.render_frames(
        client, stage_path, FRAMES, "/World/Cam", WIDTH, AOVS, SETTINGS, tiles=2, workers=[first]
    )
    assert {w for r in one for w in r.stats["distributed"]["workers"]} == {first}
    assert len({w for r in two for w in r.stats["distributed"]["workers"]}) == 2
    for frame, w, a, b in zip(FRAMES, want, two, one, strict=True):
        assert_same_bits(a, w, f"frame {frame:g} on 2 workers")
        assert_same_bits(b, w, f"frame {frame:g} on 1 worker, 2 tiles")
        assert a.time == frame
    # The frames really differ (the animated cube grows).
    assert not np.array_equal(want[0].aovs["color"], want[-1].aovs["color"])


def test_a_warm_worker_resyncs_only_what_varies_in_time(client, tmp_path) -> None:
    # A stage of its own: every worker opens a new session for it.
    path = write_stage(tmp_path / "warm.usda")
    pieces: list[cluster_api.Piece] = []
    cluster_api.render_frames(
        client,
        path,
        FRAMES * 2,
        "/World/Cam",
        WIDTH,
        AOVS,
        SETTINGS,
        on_done=lambda done, total, piece: pieces.append(piece),
    )
    assert len(pieces) == 8
    by_worker: dict[str, list[cluster_api.Piece]] = {}
    for piece in pieces:
        by_worker.setdefault(piece.worker, []).append(piece)
    for worker, mine in by_worker.items():
        # The stage is opened once per worker, and the first piece synced everything.
        assert sum(p.opened for p in mine) == 1, worker
        first = next(p for p in mine if p.opened)
        assert {STATIC, ANIMATED} <= set(first.synced), first.synced
        for piece in mine:
            if piece.opened:
                continue
            # A later frame re-sends the time-varying mesh, never the static one.
            assert STATIC not in piece.synced, (worker, piece.frame, piece.synced)
    later = [p for p in pieces if not p.opened]
    assert later and any(ANIMATED in p.synced for p in later)
    # The static cube's tessellations stay in a warm worker's cache: fewer misses.
    # Cold pieces tessellate every subpatch they meet for the first time; a warm worker keeps
    # the static cube's, so it builds fewer.
    cold = min(cluster_api.cache_figures(p.stats)["cold_vertices"] for p in pieces if p.opened)
    warm = max(cluster_api.cache_figures(p.stats)["cold_vertices"] for p in later)
    assert warm < cold, (warm, cold)


def test_a_warm_worker_reads_each_texture_tile_once(client) -> None:
    # The textured example: two textures (color and displacement height), a static stage.
    # Its texture statistics are the worker session's, cumulative: a warm worker's later
    # pieces look up texels again (lookups grow) without opening a file again or reading a
    # tile it has (a cold session per piece would reopen both files and read the tiles anew,
    # and its lookups would not add up).
    path = str(Path(__file__).resolve().parent.parent / "examples" / "textured.usda")
    pieces: list[cluster_api.Piece] = []
    cluster_api.render_frames(
        client,
        path,
        [1.0] * 6,
        None,
        24,
        ("color",),
        {"seed": 3},
        on_done=lambda done, total, piece: pieces.append(piece),
    )
    by_worker: dict[str, list[dict]] = {}
    for piece in pieces:
        by_worker.setdefault(piece.worker, []).append(piece.stats["texture_cache"])
    warm = 0
    for worker, stats in by_worker.items():
        stats.sort(key=lambda t: t["lookups"])
        first = stats[0]
        assert first["files"], worker
        for later in stats[1:]:
            warm += 1
            assert later["lookups"] > first["lookups"], worker
            assert later["tiles_read"] == first["tiles_read"], (worker, later, first)
            assert [f["times_opened"] for f in later["files"]] == [1] * len(later["files"]), worker
    assert warm >= 4, "fewer than four pieces rendered by a warm worker"


def test_record_reports_a_failed_frame_and_writes_the_others(client, tmp_path, capsys) -> None:
    path = write_stage(tmp_path / "bad.usda", bad_camera_at=3.0, nan_at=2.0)
    out = tmp_path / "out"
    status = record.main(
        [
            "--scheduler",
            client.scheduler.address,
            "--frames",
            "1:4",
            "--camera",
            "/World/Cam",
            "-w",
            "24",
            "--stats",
            str(out / "s.#.json"),
            path,
            str(out / "img.#.exr"),
        ]
    )
    captured = capsys.readouterr()
    assert status == 1, captured.err
    written = sorted(p.name for p in out.iterdir())
    assert written == ["img.1.exr", "img.2.exr", "img.4.exr", "s.1.json", "s.2.json", "s.4.json"]
    # Each frame's path as it lands (in any order).
    assert sorted(captured.out.split()) == [str(out / f"img.{f}.exr") for f in (1, 2, 4)]
    lines = captured.err.splitlines()
    # The broken camera fails frame 3 alone, named with its prim.
    assert any("error: frame 3: /World/Cam" in line and "focalLength" in line for line in lines), (
        lines
    )
    # The NaN point skips the animated cube in frame 2 alone, named with the frame.
    assert any("warning: frame 2: /World/Anim" in line for line in lines), lines
    assert not any("frame 1:" in line or "frame 4:" in line for line in lines), lines
    assert any("pieces done; per worker:" in line for line in lines), lines
    # No temporary file left beside the images.
    assert not any(p.name.startswith(".") for p in out.iterdir())


def test_bad_clusters_are_refused_before_any_frame(client, stage_path, tmp_path) -> None:
    with pytest.raises(mipray.MiprayError, match=r"scheduler tcp://127.0.0.1:9: unreachable"):
        cluster_api.connect("tcp://127.0.0.1:9", timeout=2)
    missing = str(tmp_path / "gone" / "texture.png")
    worker = sorted(client.scheduler_info()["workers"])[0]
    with pytest.raises(mipray.MiprayError, match=rf"worker {worker}: {missing} does not exist"):
        cluster_api.check_workers(client, [stage_path, missing])

    def other_version() -> None:
        import mipray as m

        m.__version__ = "0.0.0+other"

    def restore(version: str) -> None:
        import mipray as m

        m.__version__ = version

    client.run(other_version)
    try:
        with pytest.raises(mipray.MiprayError, match=r"runs mipray 0.0.0\+other, the client"):
            cluster_api.render_frames(client, stage_path, [1.0], "/World/Cam", WIDTH)
    finally:
        client.run(restore, mipray.__version__)
    cluster_api.check_workers(client, cluster_api.stage_files(stage_path))


def _render_in_thread(client, path, frames, out):
    try:
        out["results"] = cluster_api.render_frames(
            client, path, frames, "/World/Cam", 64, AOVS, {**SETTINGS, "samples": 24}
        )
    except BaseException as exc:
        out["error"] = exc


def test_a_worker_killed_mid_frame_has_its_frame_rendered_elsewhere(client, tmp_path) -> None:
    # Last of the tests on the shared cluster: its nanny restarts the killed worker.
    path = write_stage(tmp_path / "fault.usda")
    # Three frames of about a second each on one render thread: the kill lands inside one.
    frames = FRAMES[:3]
    want = [
        mipray.render(path, "/World/Cam", 64, AOVS, {**SETTINGS, "samples": 24}, time=f)
        for f in frames
    ]
    pids = client.run(os.getpid)
    out: dict[str, object] = {}
    thread = threading.Thread(target=_render_in_thread, args=(client, path, frames, out))
    thread.start()
    victim = None
    deadline = time.monotonic() + 60
    while victim is None and time.monotonic() < deadline:
        busy = [
            w
            for w, keys in client.processing().items()
            if any("_render_piece" in k for k in map(str, keys))
        ]
        if busy:
            time.sleep(0.1)  # into the frame
            victim = busy[0]
        else:
            time.sleep(0.02)
    assert victim is not None, "no frame was ever rendering"
    os.kill(pids[victim], signal.SIGKILL)
    thread.join(timeout=120)
    assert "error" not in out, out.get("error")
    results = out["results"]
    assert len(results) == len(frames)
    for frame, got, expected in zip(frames, results, want, strict=True):
        assert isinstance(got, mipray.RenderResult), got
        assert_same_bits(got, expected, f"frame {frame:g} after a worker died")


def test_tile_windows_cover_the_frame_once() -> None:
    for w, h, n in ((40, 30, 4), (41, 29, 6), (10, 7, 7), (5, 5, 1)):
        covered = np.zeros((h, w), dtype=int)
        for x0, y0, x1, y1 in cluster_api.tile_windows(w, h, n):
            covered[y0:y1, x0:x1] += 1
        assert (covered == 1).all(), (w, h, n)
        assert len(cluster_api.tile_windows(w, h, n)) == n
    with pytest.raises(mipray.RenderSettingsError, match="do not fit"):
        cluster_api.tile_windows(4, 4, 5)


def test_record_refuses_cluster_flags_that_do_not_go_together(stage_path, tmp_path, capsys) -> None:
    out = str(tmp_path / "x.exr")
    for argv, message in (
        (["--tiles", "2"], "--tiles needs a cluster"),
        (["--local-cluster", "0"], "--local-cluster needs at least 1 worker"),
        (["--local-cluster", "2", "--progressive"], "--progressive is not supported on a cluster"),
    ):
        assert record.main([*argv, stage_path, out]) == 1
        err = capsys.readouterr().err
        assert message in err and len(err.splitlines()) == 1, err
    assert not os.path.exists(out)


def test_a_cluster_frame_is_written_as_a_local_one(client, tmp_path) -> None:
    # Frames written on a cluster lacked what the local path adds: the render settings'
    # unsupported things in the stats, and usdrecord's opaque alpha over a visible dome.
    import json

    from test_unsupported import _settings

    path = tmp_path / "dome.usda"
    write_stage(path)
    stage = Usd.Stage.Open(str(path))
    UsdLux.DomeLight.Define(stage, "/World/Sky").CreateIntensityAttr(0.5)
    _settings(stage, "C<RD>.*L")
    stage.GetRootLayer().Save()
    common = ["--camera", "/World/Cam", "-w", "16", "-rs", "/Render/Settings"]
    common += ["--enableDomeLightVisibility", str(path)]
    written = {}
    for where, flags in (("local", []), ("cluster", ["--scheduler", client.scheduler.address])):
        image, stats = tmp_path / f"{where}.png", tmp_path / f"{where}.json"
        status = record.main([*flags, "--stats", str(stats), *common, str(image)])
        assert status == 0, where
        pixels, names = mipray._mipray.read_image(str(image))
        written[where] = (pixels, names, json.loads(stats.read_text())["unsupported"])
    local, cluster = written["local"], written["cluster"]
    assert any("light-path expression" in u["what"] for u in local[2]), local[2]
    assert cluster[2] == local[2]
    assert local[1] == cluster[1] and "A" in local[1]
    alpha = cluster[0][..., cluster[1].index("A")]
    assert (alpha == 1.0).all(), "the dome fills every pixel: the PNG is opaque"
    assert np.array_equal(cluster[0], local[0])
