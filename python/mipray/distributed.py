"""Rendering across machines on Dask (``dask.distributed``): frames and tiles as tasks.

A render is cut into pieces, one task each: one per frame (``--frames``), and
each frame into ``tiles`` crop windows (the ``crop`` setting, USD's
``dataWindowNDC``). The client opens nothing but a Dask ``Client``; every
worker keeps a long-lived :class:`~mipray.session.RenderSession` per stage in a
worker plugin (:class:`mipray.dask_plugin.SessionPlugin`), so the stage is opened and synced once
per worker, and its geometry and texture caches stay warm across that worker's
frames and tiles: a later frame re-syncs only the prims that vary in time.

Every pixel depends on (seed, pixel, sample) alone, and a crop window's pixels
are the whole frame's bit for bit, so the assembled image is the one a single
machine renders, whichever worker rendered which piece. A worker that dies has
its tasks retried elsewhere by the scheduler; a piece that fails on bad data is
reported with its frame, and the other frames still land. Images are written
on the client through :meth:`RenderResult.write` with ``atomic=True``: a file is
never half written.

Before any frame is rendered, the client checks what would otherwise fail late:
an unreachable scheduler, a worker running another mipray (or another build of
its settings table), and a stage file (a layer or an asset, resolved on the
client) missing on a worker. Each is one line naming what is missing where.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import time as time_module
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import MiprayError, RenderSettingsError, StageError
from .session import DEFAULT_WIDTH, RenderResult, open_stage
from .usd.scene_delegate import SyncError

__all__ = [
    "PLUGIN_NAME",
    "FrameFailure",
    "Job",
    "Piece",
    "cache_figures",
    "check_workers",
    "connect",
    "crop_setting",
    "merge_stats",
    "render",
    "render_frames",
    "stage_files",
    "tile_windows",
]

_log = logging.getLogger(__name__)

#: The name the worker plugin is registered under (one per worker).
PLUGIN_NAME = "mipray-sessions"
#: Seconds to wait for a scheduler to answer, and for its first worker.
CONNECT_TIMEOUT_S = 20.0


@dataclass(frozen=True)
class Job:
    """What every piece of a render shares: the stage, the view and the settings.

    ``stage_path`` is resolved on the client (absolute); workers must see the
    same path (a shared file system). ``height`` is None until resolved from
    the camera's aspect ratio.
    """

    stage_path: str
    camera: str | None
    width: int
    height: int | None
    aovs: tuple[str, ...]
    settings: tuple[tuple[str, Any], ...]
    purposes: tuple[str, ...] | None = None
    mask: tuple[str, ...] | None = None
    session_layer: str | None = None
    camera_light: bool = True

    def session_key(self) -> tuple[Any, ...]:
        """What makes two jobs share a worker's session: the same stage, opened alike."""
        return (self.stage_path, self.mask, self.session_layer, self.purposes)


@dataclass
class Piece:
    """One task's result: a frame, or one crop window of it, and what it cost where."""

    frame: float
    #: Pixels of the whole frame this piece holds: [x0, y0, x1, y1), row 0 at the top.
    window: tuple[int, int, int, int]
    aovs: dict[str, NDArray[np.float32]]
    stats: dict[str, Any]
    camera: str
    camera_args: dict[str, Any]
    #: Prims skipped for bad data, each naming its path and problem.
    errors: list[SyncError]
    worker: str
    #: Prims (re-)sent to the worker's render delegate for this piece.
    synced: list[str]
    #: Whether this piece opened the stage on its worker (a cold session).
    opened: bool
    busy_s: float
    #: The scene has a dome light (see :attr:`RenderResult.dome_background`).
    dome_background: bool = False


def _resolve_view(job: Job, frame: float) -> tuple[str, int]:
    """On a worker: the camera path and the image height ``job`` renders at ``frame``."""
    from .dask_plugin import worker_plugin as _plugin
    from .usd.camera import image_height

    session, _ = _plugin().session(job)
    session.scene.set_time(_time_code(frame))
    session.scene.sync()
    camera = session.scene.resolve_camera(job.camera)
    height = job.height or image_height(job.width, session.scene.cameras[camera])
    return camera, height


def _render_piece(job: Job, frame: float, window: tuple[int, int, int, int]) -> Piece:
    """On a worker: render ``window`` of ``frame`` in the worker's session for the stage."""
    from distributed import get_worker

    from .dask_plugin import worker_plugin as _plugin

    plugin = _plugin()
    session, _ = plugin.session(job)
    started = time_module.perf_counter()
    width, height = job.width, job.height
    assert height is not None, "the client resolves the height before any piece"
    settings = dict(job.settings)
    if window != (0, 0, width, height):
        settings["crop"] = crop_setting(window, width, height)
    result = session.render(
        job.camera,
        width,
        job.aovs,
        settings,
        time=_time_code(frame),
        camera_light=job.camera_light,
        height=height,
    )
    synced, opened = plugin.report(job)
    return Piece(
        frame=frame,
        window=window,
        aovs=result.aovs,
        stats=result.stats,
        camera=result.camera,
        camera_args=result._camera_args,
        errors=list(result.errors),
        worker=get_worker().address,
        synced=synced,
        opened=opened,
        busy_s=time_module.perf_counter() - started,
        dome_background=result.dome_background,
    )


def _time_code(frame: float) -> Any:
    """A frame as a time code: NaN is the Default time (a ``Usd.TimeCode`` does not pickle)."""
    from pxr import Usd

    return Usd.TimeCode.Default() if math.isnan(frame) else Usd.TimeCode(frame)


def _worker_facts(paths: Sequence[str]) -> dict[str, Any]:
    """On a worker: its mipray version, its settings table, and which of ``paths`` it lacks."""
    from . import __version__
    from .settings import TABLE

    return {
        "version": __version__,
        "settings": sorted(TABLE),
        "missing": [p for p in paths if not os.path.exists(p)],
    }


def crop_setting(window: tuple[int, int, int, int], width: int, height: int) -> str:
    """The ``crop`` setting rendering pixels [x0, x1) × [y0, y1) (row 0 at the top) of a frame.

    Its edges lie on pixel edges, half a pixel from every pixel centre, so the
    renderer's rounding takes exactly those pixels.
    """
    x0, y0, x1, y1 = window
    return f"{x0 / width},{1 - y1 / height},{x1 / width},{1 - y0 / height}"


def tile_windows(width: int, height: int, tiles: int) -> list[tuple[int, int, int, int]]:
    """``tiles`` windows covering a ``width``×``height`` frame: a grid of c×r = ``tiles``.

    The grid is as square as ``tiles`` allows (4: 2×2, 6: 3×2, 7: 7×1), cut at
    whole pixels; each window is [x0, y0, x1, y1) in pixels, row 0 at the top,
    in image order.
    """
    if tiles < 1:
        raise RenderSettingsError(f"tiles must be at least 1, got {tiles}")
    rows = max(r for r in range(1, math.isqrt(tiles) + 1) if tiles % r == 0)
    columns = tiles // rows
    if columns > width or rows > height:
        raise RenderSettingsError(
            f"{tiles} tiles ({columns}×{rows}) do not fit a {width}×{height} image"
        )
    xs = [round(i * width / columns) for i in range(columns + 1)]
    ys = [round(j * height / rows) for j in range(rows + 1)]
    return [(xs[i], ys[j], xs[i + 1], ys[j + 1]) for j in range(rows) for i in range(columns)]


# ---------------------------------------------------------------- the client side


def connect(
    scheduler: str | None = None,
    local_cluster: int | None = None,
    *,
    timeout: float = CONNECT_TIMEOUT_S,
    **cluster_options: Any,
) -> Any:
    """A Dask ``Client``: to the scheduler at ``scheduler``, or a new local cluster.

    ``local_cluster`` starts that many worker processes on this machine (one
    thread each, loopback only; ``cluster_options`` go to ``LocalCluster``).
    The session plugin is registered on every worker, present and future.

    Raises:
        MiprayError: dask.distributed is not installed, or the scheduler does
            not answer within ``timeout`` seconds.

    """
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise MiprayError(
            f"rendering on a cluster needs dask.distributed ({exc}); "
            "pip install -r scripts/requirements.txt"
        ) from exc
    if scheduler:
        try:
            client = Client(scheduler, timeout=f"{timeout}s")  # type: ignore[no-untyped-call]
        except (OSError, TimeoutError) as exc:
            raise MiprayError(
                f"scheduler {scheduler}: unreachable ({str(exc).splitlines()[0]})"
            ) from exc
    else:
        cluster = LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=local_cluster or 1,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=":0",  # any free port: several clusters may run at once
            **cluster_options,
        )
        client = Client(cluster)  # type: ignore[no-untyped-call]
    from .dask_plugin import SessionPlugin

    client.register_plugin(SessionPlugin(), name=PLUGIN_NAME)
    return client


def stage_files(stage_path: str) -> list[str]:
    """Every file the stage reads, resolved here: its layers and assets (textures, ...)."""
    from pxr import UsdUtils

    layers, assets, _unresolved = UsdUtils.ComputeAllDependencies(stage_path)
    files = {os.path.abspath(stage_path)}
    files.update(layer.realPath for layer in layers if layer.realPath)
    files.update(a for a in assets if a)
    return sorted(files)


def check_workers(client: Any, files: Sequence[str]) -> list[str]:
    """Check every worker before rendering; return their addresses.

    Raises:
        MiprayError: no worker joined within :data:`CONNECT_TIMEOUT_S`
            seconds; a worker runs another mipray version (or a build with
            other settings); a worker lacks one of ``files``. One line, naming
            the worker and what is missing.

    """
    from . import __version__
    from .settings import TABLE

    try:
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise MiprayError(
            f"scheduler {client.scheduler.address}: no worker joined within {CONNECT_TIMEOUT_S:g} s"
        ) from exc
    facts = client.run(_worker_facts, list(files))
    for address, fact in sorted(facts.items()):
        if fact["version"] != __version__:
            raise MiprayError(
                f"worker {address} runs mipray {fact['version']}, the client {__version__}; "
                "install the same mipray on every worker"
            )
        if fact["settings"] != sorted(TABLE):
            theirs, ours = set(fact["settings"]), set(TABLE)
            differ = sorted(theirs ^ ours)
            raise MiprayError(
                f"worker {address} runs another build of mipray {__version__} "
                f"(settings differ: {', '.join(differ)}); install the same build everywhere"
            )
        if fact["missing"]:
            more = len(fact["missing"]) - 1
            raise MiprayError(
                f"worker {address}: {fact['missing'][0]} does not exist there"
                + (f" (and {more} more of the stage's files)" if more else "")
                + "; the stage's files must be at the same paths on every worker"
            )
    return sorted(facts)


def _render_threads(client: Any) -> int:
    """Render threads per worker: the host's cores shared among the workers on it."""
    workers = client.scheduler_info()["workers"]
    hosts: dict[str, int] = {}
    for info in workers.values():
        hosts[info["host"]] = hosts.get(info["host"], 0) + 1
    per_host = max(hosts.values()) if hosts else 1
    return max(1, (os.cpu_count() or 1) // per_host)


def _job(
    client: Any,
    path_or_stage: Any,
    camera: str | None,
    width: int | None,
    aovs: Sequence[str],
    settings: Mapping[str, object] | None,
    purposes: Sequence[str] | None,
    **more: Any,
) -> Job:
    from pxr import Usd

    if isinstance(path_or_stage, Usd.Stage):
        root = path_or_stage.GetRootLayer()
        if root.anonymous or not root.realPath:
            raise StageError("a stage rendered on a cluster must be a file the workers can open")
        if any(layer.dirty for layer in path_or_stage.GetUsedLayers()):
            raise StageError(
                f"{root.realPath}: has unsaved edits; save it before rendering on a cluster"
            )
        stage_path = root.realPath
    else:
        stage_path = os.path.abspath(os.fspath(path_or_stage))
        if not os.path.exists(stage_path):
            raise StageError(f"{stage_path}: no such file", path=stage_path)
    chosen = dict(settings or {})
    if chosen.get("progressive"):
        raise RenderSettingsError("progressive rendering is not supported on a cluster")
    if "crop" in chosen:
        raise RenderSettingsError("crop is set per tile on a cluster; leave it unset")
    chosen.setdefault("threads", _render_threads(client))
    aov_list = tuple(dict.fromkeys(aovs))
    if not aov_list:
        raise RenderSettingsError("no AOV to render; ask for at least 'color'")
    return Job(
        stage_path=stage_path,
        camera=camera,
        width=DEFAULT_WIDTH if width is None else int(width),
        height=more.pop("height", None),
        aovs=aov_list,
        settings=tuple(sorted(chosen.items())),
        purposes=tuple(purposes) if purposes is not None else None,
        **more,
    )


@dataclass
class FrameFailure:
    """A frame that could not be rendered: which, and the one-line reason."""

    frame: float
    message: str


@dataclass
class _Frame:
    pieces: list[Piece] = field(default_factory=list)
    failure: str | None = None


#: ``on_done(done, total, piece)`` after each piece lands on the client.
PieceCallback = Callable[[int, int, Piece], object]


def render_frames(
    client: Any,
    path_or_stage: Any,
    frames: Sequence[float],
    camera: str | None = None,
    width: int | None = None,
    aovs: Sequence[str] = ("color",),
    settings: Mapping[str, object] | None = None,
    purposes: Sequence[str] | None = None,
    *,
    tiles: int = 1,
    workers: Sequence[str] | None = None,
    on_done: PieceCallback | None = None,
    on_frame: Callable[[RenderResult | FrameFailure], object] | None = None,
    check: bool = True,
    **job_options: Any,
) -> list[RenderResult | FrameFailure]:
    """Render ``frames`` of a USD file on a Dask cluster, each as ``tiles`` tasks.

    Args:
        client: a ``distributed.Client`` (see :func:`connect`).
        path_or_stage: the USD file (resolved here; every worker must see it
            at the same path), or a stage opened from a saved file.
        frames: time codes, one image each.
        camera: as :func:`mipray.render`.
        width: as :func:`mipray.render`.
        aovs: as :func:`mipray.render`.
        settings: as :func:`mipray.render`; ``threads`` defaults to the
            machine's cores shared among the workers on it.
        purposes: as :func:`mipray.render`.
        tiles: crop windows per frame (:func:`tile_windows`), one task each.
        workers: render on these workers only (addresses); default any.
        on_done: called as ``on_done(done, total, piece)`` as each piece lands.
        on_frame: called with each frame's result as soon as its last piece
            lands (or with its :class:`FrameFailure`), in completion order.
        check: check the workers first (:func:`check_workers`).
        job_options: ``height``, ``mask``, ``session_layer``, ``camera_light``.

    Returns:
        One entry per frame, in the order of ``frames``: a
        :class:`RenderResult` (its stats merged over its tiles, with a
        ``distributed`` section per worker), or a :class:`FrameFailure`.

    Raises:
        MiprayError: the cluster cannot render this stage at all (see
            :func:`check_workers`), or the camera or settings are unusable.

    """
    from distributed import as_completed

    job = _job(client, path_or_stage, camera, width, aovs, settings, purposes, **job_options)
    if check:
        check_workers(client, stage_files(job.stage_path))
    started = time_module.perf_counter()
    # The camera and the height once, on a worker (which warms its session too).
    try:
        camera_path, height = client.submit(
            _resolve_view, job, frames[0], pure=False, workers=workers
        ).result()
    except MiprayError:
        raise
    except Exception as exc:  # a worker-side failure arrives as itself; keep it one line
        raise MiprayError(str(exc).splitlines()[0] if str(exc) else type(exc).__name__) from exc
    job = dataclasses.replace(job, camera=camera_path, height=height)
    windows = tile_windows(job.width, height, tiles)
    futures = {}
    for index, frame in enumerate(frames):
        for window in windows:
            future = client.submit(_render_piece, job, frame, window, pure=False, workers=workers)
            futures[future] = index
    state = [_Frame() for _ in frames]
    results: list[RenderResult | FrameFailure | None] = [None] * len(frames)
    done = 0
    for future in as_completed(futures):  # type: ignore[no-untyped-call]
        index = futures[future]
        frame_state = state[index]
        done += 1
        try:
            piece = future.result()
        except Exception as exc:
            message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            if frame_state.failure is None:
                frame_state.failure = message
                results[index] = FrameFailure(frames[index], f"frame {frames[index]:g}: {message}")
                if on_frame is not None:
                    on_frame(results[index])  # type: ignore[arg-type]
            continue
        frame_state.pieces.append(piece)
        if on_done is not None:
            on_done(done, len(futures), piece)
        if frame_state.failure is None and len(frame_state.pieces) == len(windows):
            results[index] = _assemble(
                job, frame_state.pieces, time_module.perf_counter() - started
            )
            frame_state.pieces = []  # the pixels are in the result now
            if on_frame is not None:
                on_frame(results[index])  # type: ignore[arg-type]
    return [r for r in results if r is not None]


def render(
    client: Any,
    path_or_stage: Any,
    camera: str | None = None,
    width: int | None = None,
    aovs: Sequence[str] = ("color",),
    settings: Mapping[str, object] | None = None,
    time: float | None = None,
    purposes: Sequence[str] | None = None,
    *,
    tiles: int | None = None,
    **options: Any,
) -> RenderResult:
    """Render one image on a Dask cluster as ``tiles`` tasks (default: one per worker).

    The image is bit-identical to :func:`mipray.render`'s with the same seed and
    settings. ``time`` defaults to the stage's start time code.

    Raises:
        MiprayError: as :func:`render_frames`; the frame's failure too.

    """
    if time is None:
        stage = path_or_stage if not isinstance(path_or_stage, (str, os.PathLike)) else None
        stage = stage or open_stage(path_or_stage)
        time = stage.GetStartTimeCode()
    if tiles is None:
        tiles = max(1, len(client.scheduler_info()["workers"]))
    (result,) = render_frames(
        client,
        path_or_stage,
        [float(time)],
        camera,
        width,
        aovs,
        settings,
        purposes,
        tiles=tiles,
        **options,
    )
    if isinstance(result, FrameFailure):
        raise MiprayError(result.message)
    return result


def _assemble(job: Job, pieces: list[Piece], wall_s: float) -> RenderResult:
    """One frame from its pieces: the pixels in place, the stats merged."""
    assert job.height is not None
    pieces = sorted(pieces, key=lambda p: (p.window[1], p.window[0]))
    aovs: dict[str, NDArray[np.float32]] = {}
    for name in job.aovs:
        channels = pieces[0].aovs[name].shape[2]
        image = np.empty((job.height, job.width, channels), dtype=np.float32)
        for piece in pieces:
            x0, y0, x1, y1 = piece.window
            image[y0:y1, x0:x1] = piece.aovs[name]
        aovs[name] = image
    stats = merge_stats([p.stats for p in pieces])
    stats.setdefault("render", {})["wall_s"] = wall_s
    stats["render"]["data_window"] = [0, 0, job.width, job.height]
    stats["distributed"] = _worker_stats(pieces)
    # Every piece syncs the whole stage, so each reports the same bad prims: once each.
    errors = list(dict.fromkeys(e for p in pieces for e in p.errors))
    return RenderResult(
        aovs=aovs,
        stats=stats,
        camera=pieces[0].camera,
        time=pieces[0].frame,
        errors=errors,
        _camera_args=pieces[0].camera_args,
        dome_background=pieces[0].dome_background,
    )


#: Stats that are the frame's, the same in every piece: taken from the first, not summed.
_SHARED_PATHS = frozenset(
    {
        "render.threads",
        "render.resolution",
        "render.samples",
        "scene",
        "effects",
        "prim_errors",
        "dropped_prims",
        "internal_errors",
    }
)
#: Keys, wherever they are, that describe a configuration rather than count work.
_SHARED_KEYS = frozenset({"verts_per_side", "capacity_entries", "budget_bytes", "mode", "name"})


def merge_stats(stats: Sequence[Mapping[str, Any]], prefix: str = "") -> dict[str, Any]:
    """The stats of the pieces of one frame as one frame's.

    A count (rays, tests, cache lookups, hits, misses, recomputed vertices,
    ...) is the sum of the pieces'; a peak (``*peak*``) their largest; a hit
    rate is recomputed from the summed hits and misses; what describes the
    frame (resolution, scene, effects, the prims left out) or a configuration
    (a tier's size, a budget) is the first piece's. Lists of objects (the cache
    tiers) merge element by element.
    """
    first = stats[0]
    merged: dict[str, Any] = {}
    for key, value in first.items():
        path = f"{prefix}{key}"
        values = [s[key] for s in stats if key in s]
        if path in _SHARED_PATHS or key in _SHARED_KEYS:
            merged[key] = value
        elif isinstance(value, dict):
            merged[key] = merge_stats([v for v in values if isinstance(v, dict)], f"{path}.")
        elif (
            isinstance(value, list)
            and value
            and all(isinstance(v, dict) for v in value)
            and all(isinstance(v, list) and len(v) == len(value) for v in values)
        ):
            merged[key] = [
                merge_stats([v[i] for v in values], f"{path}.") for i in range(len(value))
            ]
        elif "peak" in key and all(_number(v) for v in values):
            merged[key] = max(values)
        elif all(_number(v) for v in values):
            merged[key] = sum(values)
        else:
            merged[key] = value
    if "hit_rate" in merged and _number(merged.get("hits")) and _number(merged.get("misses")):
        looked = merged["hits"] + merged["misses"]
        merged["hit_rate"] = merged["hits"] / looked if looked else float(merged["lookups"] > 0)
    return merged


def _number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def cache_figures(stats: Mapping[str, Any]) -> dict[str, float]:
    """A render's geometry cache over all tiers: lookups, hits, misses, hit rate, vertices."""
    cache = stats.get("geometry_cache") or {}
    tiers = cache.get("tiers") or []
    out = {k: sum(t.get(k, 0) for t in tiers) for k in ("lookups", "hits", "misses")}
    looked = out["hits"] + out["misses"]
    out["hit_rate"] = out["hits"] / looked if looked else float(out["lookups"] > 0)
    out["recomputed_vertices"] = cache.get("recomputed_vertices", 0)
    out["cold_vertices"] = cache.get("cold_vertices", 0)
    return out


def _worker_stats(pieces: Sequence[Piece]) -> dict[str, Any]:
    """Per worker: pieces rendered, busy time, prims synced, geometry cache figures."""
    workers: dict[str, dict[str, Any]] = {}
    for piece in pieces:
        w = workers.setdefault(
            piece.worker,
            {"pieces": 0, "busy_s": 0.0, "stage_opened": 0, "synced": [], "geometry_cache": {}},
        )
        w["pieces"] += 1
        w["busy_s"] += piece.busy_s
        w["stage_opened"] += int(piece.opened)
        w["synced"] = sorted(set(w["synced"]) | set(piece.synced))
        bucket = w["geometry_cache"]
        for key, value in cache_figures(piece.stats).items():
            if key != "hit_rate":
                bucket[key] = bucket.get(key, 0) + value
    for w in workers.values():
        bucket = w["geometry_cache"]
        looked = bucket["hits"] + bucket["misses"]
        bucket["hit_rate"] = bucket["hits"] / looked if looked else float(bucket["lookups"] > 0)
    return {
        "pieces": len(pieces),
        "windows": [list(p.window) for p in sorted(pieces, key=lambda p: p.window[1::-1])],
        "workers": workers,
    }


# ------------------------------------------------------------- mipray-record's side


def add_arguments(parser: Any) -> None:
    """``mipray-record``'s cluster flags."""
    group = parser.add_argument_group("cluster options (mipray.distributed, on Dask)")
    where = group.add_mutually_exclusive_group()
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=(
            "render on the Dask cluster whose scheduler is at ADDRESS (e.g. "
            "tcp://head:8786): one task per frame (and per tile); every worker "
            "needs the stage's files at the same paths and the same mipray"
        ),
    )
    where.add_argument(
        "--local-cluster",
        type=int,
        metavar="N",
        help="render on a Dask cluster of N worker processes started on this machine",
    )
    group.add_argument(
        "--tiles",
        type=int,
        metavar="N",
        help=(
            "split each image into N tiles, one task each, assembled on the client "
            "into the same image (needs --scheduler or --local-cluster; default 1)"
        ),
    )


def wanted(args: Any) -> bool:
    """Whether the command line asks for a cluster; a bad combination is refused."""
    on_cluster = bool(args.scheduler or args.local_cluster)
    if args.local_cluster is not None and args.local_cluster < 1:
        raise RenderSettingsError(
            f"--local-cluster needs at least 1 worker, got {args.local_cluster}"
        )
    if args.tiles is not None and (args.tiles < 1 or not on_cluster):
        raise RenderSettingsError(
            "--tiles needs a cluster (--scheduler or --local-cluster) and at least 1 tile"
        )
    if on_cluster and args.progressive:
        raise RenderSettingsError("--progressive is not supported on a cluster")
    return on_cluster


def record(
    args: Any,
    times: Sequence[Any],
    settings: Mapping[str, object],
    plan: Any,
    extra: Mapping[str, Any] | None,
    out: Any,
    err: Any,
    write_stats: Callable[[str, float, dict[str, Any], str, Any], None],
) -> int:
    """``mipray-record --scheduler/--local-cluster``: render ``times`` on the cluster.

    Writes each frame (atomically) as soon as its last piece lands, prints its
    path, and progress lines on ``err`` (pieces done; per worker, pieces and
    throughput). A frame that fails is one line on ``err``; the others are
    written. Returns the exit status: 0, 2 (a prim dropped after an internal
    error) or 1 (a frame failed).
    """
    from .frames import format_frame_path, write_frame

    prog = "mipray-record"
    frames = [math.nan if t.IsDefault() else float(t.GetValue()) for t in times]
    client = connect(args.scheduler, args.local_cluster)
    status = {"failed": 0, "internal": 0}
    per_worker: dict[str, list[float]] = {}
    started = time_module.perf_counter()

    def on_done(done: int, total: int, piece: Piece) -> None:
        busy = per_worker.setdefault(piece.worker, [])
        busy.append(piece.busy_s)
        elapsed = max(time_module.perf_counter() - started, 1e-9)
        rates = ", ".join(
            f"{w} {len(b)} ({len(b) / elapsed:.2f}/s)" for w, b in sorted(per_worker.items())
        )
        err.write(f"{prog}: {done}/{total} pieces done; per worker: {rates}\n")
        err.flush()

    def on_frame(result: RenderResult | FrameFailure) -> None:
        if isinstance(result, FrameFailure):
            status["failed"] += 1
            err.write(f"{prog}: error: {result.message}\n")
            return
        value = 0.0 if math.isnan(result.time) else result.time
        for problem in result.errors:
            err.write(f"{prog}: warning: frame {value:g}: {problem}\n")
        path = format_frame_path(args.outputImagePath, value)
        write_frame(
            result,
            path,
            plan.aovs,
            color_correction=args.colorCorrectionMode,
            metadata=extra,
            unsupported=plan.unsupported,
            dome_opaque=args.enableDomeLightVisibility,
            atomic=True,
        )
        out.write(path + "\n")
        out.flush()
        if args.stats:
            write_stats(args.stats, value, result.stats, f"mipray stats: {path}", out)
        status["internal"] += int(result.stats.get("internal_errors", 0))

    try:
        render_frames(
            client,
            args.usdFilePath,
            frames,
            plan.camera,
            plan.width,
            plan.aovs,
            settings,
            plan.purposes,
            tiles=args.tiles or 1,
            on_done=on_done,
            on_frame=on_frame,
            height=plan.height,
            mask=tuple(args.mask.replace(",", " ").split()) if args.mask else None,
            session_layer=args.sessionLayer,
            camera_light=not args.disableCameraLight,
        )
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if args.local_cluster and cluster is not None:
            cluster.close()
    if status["failed"]:
        err.write(f"{prog}: {status['failed']} of {len(frames)} frame(s) failed (named above)\n")
        return 1
    if status["internal"]:
        err.write(
            f"{prog}: images written, but {status['internal']} prim(s) were dropped after "
            "internal errors (named above)\n"
        )
        return 2
    return 0
