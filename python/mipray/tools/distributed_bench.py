"""``make bench-distributed``: rendering on a Dask cluster, measured (``docs/distributed.md``).

    .venv/bin/python -m mipray.tools.distributed_bench [--scene examples/subdiv_showcase.usda]
        [--frames 1:8] [--width 160] [--tile-width 320] [--samples 4] [--runs 1]
        [--out docs/distributed.md]

On ``LocalCluster`` s of this machine (processes, one Dask thread each, loopback):

1. **frames**: ``--frames`` rendered one task per frame on 1 worker (render threads =
   all cores) and on 2 workers (cores shared), against the same frames rendered here in
   one :class:`~mipray.RenderSession` (no Dask at all);
2. **tiles**: one frame at ``--tile-width`` as 4 tiles, on 1 and on 2 workers, against the
   whole frame rendered here;
3. **warm against cold workers**: the frames twice on one 2-worker cluster; the first pass
   opens, syncs and tessellates cold, the second finds every worker's session and geometry
   cache warm (the geometry cache's hit rate, cold tessellations and recomputed vertices,
   summed over the pieces of each pass);
4. **tile size and the geometry cache**: one frame cut into 1, 4, 16 and 64 tiles, each tile
   rendered in a new session (a cold cache, as when every tile lands on another machine):
   the vertices tessellated (cold and recomputed) over all tiles against the whole frame's.

Every cluster image is checked bit for bit against the one rendered here (a mismatch is an
error, not a row). Timings are wall-clock medians over ``--runs``, on a shared machine:
read them as ratios. Exit status 0 when the report was written, 1 on an error (one line).
"""

from __future__ import annotations

import argparse
import datetime
import functools
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

PROG = "distributed_bench"


class BenchError(Exception):
    """A run that cannot be reported; one line."""


def _frames(spec: str) -> list[float]:
    from ..frames import parse_frame_spec

    return [float(f) for f in parse_frame_spec(spec)]


def build_parser() -> argparse.ArgumentParser:
    """The benchmark's command line."""
    parser = argparse.ArgumentParser(prog=f"python -m mipray.tools.{PROG}", description=__doc__)
    parser.add_argument("--scene", default="examples/subdiv_showcase.usda")
    parser.add_argument("--frames", default="1:8", help="frames of the frame runs (default 1:8)")
    parser.add_argument("--width", type=int, default=160, help="frame runs' width (default 160)")
    parser.add_argument(
        "--tile-width", type=int, default=320, help="tile runs' width (default 320)"
    )
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--runs", type=int, default=1, help="runs per timing, median (default 1)")
    parser.add_argument("--out", type=Path, default=Path("docs/distributed.md"))
    return parser


def _same(a: Any, b: Any, what: str) -> None:
    for name, pixels in b.aovs.items():
        if not np.array_equal(a.aovs[name].view(np.uint32), pixels.view(np.uint32)):
            raise BenchError(f"{what}: AOV {name} differs from the single-machine render")


def _timed(fn: Callable[[], Any], runs: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(runs):
        started = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - started)
    return statistics.median(times), out


def _local_cluster(workers: int) -> Any:
    from .. import distributed

    return distributed.connect(local_cluster=workers)


def _close(client: Any) -> None:
    cluster = client.cluster
    client.close()
    cluster.close()


def _cache_sum(stats_list: Sequence[dict[str, Any]]) -> dict[str, float]:
    from ..distributed import cache_figures

    total: dict[str, float] = {}
    for stats in stats_list:
        for key, value in cache_figures(stats).items():
            total[key] = total.get(key, 0) + value
    looked = total["hits"] + total["misses"]
    total["hit_rate"] = total["hits"] / looked if looked else 1.0
    return total


def _on_clusters(
    render: Callable[[Any], Any], runs: int, log: Callable[[str], None], what: str
) -> Iterator[tuple[int, tuple[float, Any]]]:
    """``render(client)`` timed on a new LocalCluster of 1, then 2 workers."""
    for workers in (1, 2):
        log(f"{what}: {workers} worker(s)")
        client = _local_cluster(workers)
        try:
            # Render threads: every core, shared among the workers (the default).
            timed = _timed(functools.partial(render, client), runs)
        finally:
            _close(client)
        yield workers, timed


def _keep(pieces: list[Any], done: int, total: int, piece: Any) -> None:
    pieces.append(piece)


def measure(args: argparse.Namespace, log: Callable[[str], None]) -> dict[str, Any]:
    """Every figure of the report."""
    import mipray
    from mipray import distributed

    scene = str(Path(args.scene).resolve())
    frames = _frames(args.frames)
    cores = os.cpu_count() or 1
    settings = {"samples": args.samples}
    stage = mipray.open_stage(scene)
    out: dict[str, Any] = {"cores": cores, "frames": frames}

    log("frames: here, one session")

    def here_frames() -> list[Any]:
        with mipray.RenderSession(mipray.open_stage(scene)) as session:
            return [session.render(None, args.width, settings=settings, time=f) for f in frames]

    out["frames_here_s"], truth = _timed(here_frames, args.runs)
    for workers, (seconds, results) in _on_clusters(
        lambda client: distributed.render_frames(
            client, scene, frames, None, args.width, ("color",), settings
        ),
        args.runs,
        log,
        "frames",
    ):
        for f, got, want in zip(frames, results, truth, strict=True):
            if not isinstance(got, mipray.RenderResult):
                raise BenchError(f"frame {f:g} failed on {workers} worker(s): {got.message}")
            _same(got, want, f"frame {f:g} on {workers} worker(s)")
        out[f"frames_{workers}w_s"] = seconds

    log("tiles: here, whole frame")
    start = stage.GetStartTimeCode()
    out["tiles_here_s"], whole = _timed(
        lambda: mipray.render(scene, None, args.tile_width, settings=settings, time=start),
        args.runs,
    )
    for workers, (seconds, got) in _on_clusters(
        lambda client: distributed.render(
            client, scene, None, args.tile_width, ("color",), settings, start, tiles=4
        ),
        args.runs,
        log,
        "tiles",
    ):
        _same(got, whole, f"4 tiles on {workers} worker(s)")
        out[f"tiles_{workers}w_s"] = seconds

    log("warm against cold workers")
    client = _local_cluster(2)
    passes = []
    try:
        for _ in range(2):
            pieces: list[Any] = []
            started = time.perf_counter()
            distributed.render_frames(
                client,
                scene,
                frames,
                None,
                args.width,
                ("color",),
                settings,
                on_done=functools.partial(_keep, pieces),
            )
            passes.append(
                {
                    "wall_s": time.perf_counter() - started,
                    "cache": _cache_sum([p.stats for p in pieces]),
                    "synced": sum(len(p.synced) for p in pieces),
                    "opened": sum(p.opened for p in pieces),
                }
            )
    finally:
        _close(client)
    out["warm"] = passes

    log("tile size and the geometry cache")
    rows = []
    for tiles in (1, 4, 16, 64):
        windows = distributed.tile_windows(args.tile_width, whole.height, tiles)
        stats = []
        for window in windows:
            crop = distributed.crop_setting(window, args.tile_width, whole.height)
            tile = mipray.render(
                scene, None, args.tile_width, settings={**settings, "crop": crop}, time=start
            )
            stats.append(tile.stats)
        cache = _cache_sum(stats)
        rows.append(
            {
                "tiles": tiles,
                "tile_px": f"{windows[0][2] - windows[0][0]}×{windows[0][3] - windows[0][1]}",
                "cold_vertices": cache["cold_vertices"],
                "recomputed_vertices": cache["recomputed_vertices"],
                "lookups": cache["lookups"],
            }
        )
    out["tile_sizes"] = rows
    out["resolution"] = (args.tile_width, whole.height)
    return out


def report(m: dict[str, Any], command: str, started: str, args: argparse.Namespace) -> str:
    """``docs/distributed.md`` from the figures of :func:`measure`."""

    def speed(key: str, base: str) -> str:
        return f"{m[base] / m[key]:.2f}×"

    n = len(m["frames"])
    whole = m["tile_sizes"][0]
    lines = [
        "# Rendering on a Dask cluster: measured",
        "",
        f"Written by `{command}` (`make bench-distributed`) on {started}: "
        f"{platform.node() or 'this machine'}, {m['cores']} cores, Python "
        f"{platform.python_version()}, `{args.scene}`, {args.samples} samples per pixel, "
        "the extension `make setup` builds (dev profile: the core at opt-level 2). "
        "Timings are wall-clock seconds (medians of "
        f"{args.runs} run{'s' if args.runs > 1 else ''}) on a machine shared with other "
        "work: read them as ratios. Every image rendered on a cluster below was checked bit "
        "for bit against the same image rendered here.",
        "",
        "## Frames: one task per frame",
        "",
        f"{n} frames at {args.width} px. *Here* is one `RenderSession` in this process (no "
        "Dask); the clusters are `LocalCluster(processes=True, threads_per_worker=1)`, each "
        "worker rendering with the cores shared among the workers (1 worker: "
        f"{m['cores']} render threads; 2 workers: {max(1, m['cores'] // 2)} each). Cluster "
        "times include starting each worker's session (opening and syncing the stage).",
        "",
        "| where | wall s | frames/s | against here |",
        "|---|---:|---:|---:|",
        f"| here | {m['frames_here_s']:.2f} | {n / m['frames_here_s']:.2f} | 1.00× |",
        f"| 1 worker | {m['frames_1w_s']:.2f} | {n / m['frames_1w_s']:.2f} | "
        f"{speed('frames_1w_s', 'frames_here_s')} |",
        f"| 2 workers | {m['frames_2w_s']:.2f} | {n / m['frames_2w_s']:.2f} | "
        f"{speed('frames_2w_s', 'frames_here_s')} |",
        "",
        "## Tiles: one frame as 4 tiles",
        "",
        f"One frame at {m['resolution'][0]}×{m['resolution'][1]} px cut into 4 tiles "
        "(2×2, crop windows), assembled on the client.",
        "",
        "| where | wall s | against here |",
        "|---|---:|---:|",
        f"| here, whole frame | {m['tiles_here_s']:.2f} | 1.00× |",
        f"| 1 worker, 4 tiles | {m['tiles_1w_s']:.2f} | {speed('tiles_1w_s', 'tiles_here_s')} |",
        f"| 2 workers, 4 tiles | {m['tiles_2w_s']:.2f} | {speed('tiles_2w_s', 'tiles_here_s')} |",
        "",
        "On 2 cores the two workers share the cores one render on one worker would use, so "
        "no speed-up is possible here beyond what one process fails to use (the Python side "
        "of each frame: reading and syncing the stage); the rows show what Dask costs. Across "
        "machines each worker brings its own cores.",
        "",
        "## Warm against cold workers",
        "",
        f"The {n} frames twice on one 2-worker cluster. Figures are summed over the pieces of "
        "each pass. *Served from the cache* is hits / lookups: a lookup that is not a hit is a "
        "cold tessellation (the first of a subpatch at a rate) or a miss (built again after an "
        "eviction); the *hit rate* is the paper's, hits / (hits + misses), cold tessellations "
        "apart, so it is 1 whenever the budget holds the scene.",
        "",
        "| pass | wall s | sessions opened | prims synced | cache lookups | "
        "served from the cache | hit rate | cold-tessellated vertices | recomputed vertices |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, p in zip(("cold (first)", "warm (second)"), m["warm"], strict=True):
        c = p["cache"]
        served = c["hits"] / c["lookups"] if c["lookups"] else 0.0
        lines.append(
            f"| {name} | {p['wall_s']:.2f} | {p['opened']} | {p['synced']} | "
            f"{c['lookups']:,.0f} | {served:.4f} | {c['hit_rate']:.4f} | "
            f"{c['cold_vertices']:,.0f} | {c['recomputed_vertices']:,.0f} |"
        )
    lines += [
        "",
        "A warm worker re-syncs only the prims that vary in time (here the spinning torus, "
        "by its transform alone: `set_transform`) and keeps every mesh's tessellations, "
        "which are in object space; what it still tessellates cold are subpatches seen at a "
        "rate no earlier frame on that worker asked for.",
        "",
        "## Tile size and the geometry cache",
        "",
        f"One frame at {m['resolution'][0]}×{m['resolution'][1]} px cut into N tiles, every "
        "tile rendered with a new (cold) geometry cache, as when each tile lands on a "
        "different machine. A subpatch seen by several tiles is tessellated once per tile, "
        "so the vertices built grow as tiles shrink:",
        "",
        "| tiles | tile px | vertices tessellated cold | against the whole frame | "
        "recomputed vertices | cache lookups |",
        "|---:|---|---:|---:|---:|---:|",
    ]
    for row in m["tile_sizes"]:
        ratio = row["cold_vertices"] / whole["cold_vertices"] if whole["cold_vertices"] else 0
        lines.append(
            f"| {row['tiles']} | {row['tile_px']} | {row['cold_vertices']:,.0f} | "
            f"{ratio:.2f}× | {row['recomputed_vertices']:,.0f} | {row['lookups']:,.0f} |"
        )
    lines += [
        "",
        "On a real cluster tiles share a worker's cache when they land on the same worker "
        "(the scheduler gives a worker several tiles of a frame), so the cost lies between "
        "the whole frame's row and this table's. Fewer, larger tiles, or tiles of one frame "
        "kept on few workers, keep it near the whole frame's.",
        "",
    ]
    return "\n".join(lines) + "\n" + GUIDE


GUIDE = """## Pointing it at a real cluster

`mipray-record --scheduler tcp://HOST:8786 ...` (or `mipray.render(..., client=Client(...))`,
`mipray.distributed.render_frames`) renders on any running `dask.distributed` scheduler.
Every worker needs:

- the same Python environment: `pip install -r scripts/requirements.txt` and the mipray build
  (`scripts/setup.sh`), so `dask`, `distributed` and `mipray` are the same versions as the
  client's;
- the stage's files at the same absolute paths (a shared file system): the client resolves the
  stage's layers and assets (`UsdUtils.ComputeAllDependencies`) and sends those paths.

Before any frame is rendered, the client checks every worker (`mipray.distributed.check_workers`)
and stops with one line naming what is wrong where: `scheduler ADDRESS: unreachable (...)`,
`worker ADDRESS runs mipray X, the client Y`, `worker ADDRESS runs another build of mipray X
(settings differ: ...)`, `worker ADDRESS: PATH does not exist there`.

**SSH** (machines you can log in to, `pip install asyncssh`):

```python
from dask.distributed import Client, SSHCluster
cluster = SSHCluster(["head", "node1", "node2"],
                     remote_python="/shared/mipray/.venv/bin/python",
                     worker_options={"nthreads": 1})
client = Client(cluster)   # then mipray.render(..., client=client)
```

or by hand: `dask scheduler` on one machine, `dask worker tcp://head:8786 --nthreads 1` on each
of the others, and `mipray-record --scheduler tcp://head:8786 ...`.

**SLURM / PBS** (`pip install dask-jobqueue`): one job per worker.

```python
from dask_jobqueue import SLURMCluster
cluster = SLURMCluster(cores=32, processes=1, memory="64GB", walltime="04:00:00",
                       python="/shared/mipray/.venv/bin/python")
cluster.scale(jobs=20)
client = Client(cluster)
```

(`PBSCluster` takes the same arguments.) Give each worker one Dask thread and all its cores:
mipray renders a piece with every core of the worker's machine shared among the workers on it
(the `threads` setting, unless given).

**Kubernetes** (`pip install dask-kubernetes`, an image with mipray installed and the assets
mounted at the same path):

```python
from dask_kubernetes.operator import KubeCluster
cluster = KubeCluster(name="mipray", image="registry/mipray:TAG", n_workers=10,
                      resources={"requests": {"cpu": "8", "memory": "16Gi"}})
client = Client(cluster)
```

Each worker keeps one render session per stage for its life (the `mipray-sessions` worker
plugin), so a long-lived cluster serving several shots keeps their geometry caches warm; the
`distributed` section of each frame's stats says per worker what it synced, how many pieces it
rendered and its geometry cache's figures.
"""


def main(argv: Sequence[str] | None = None) -> int:
    """Measure and write the report; the exit status."""
    args = build_parser().parse_args(argv)
    shown = " ".join(
        ["python -m mipray.tools.distributed_bench", *(sys.argv[1:] if argv is None else argv)]
    )
    started = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")

    def log(message: str) -> None:
        print(f"{PROG}: {message}", file=sys.stderr, flush=True)

    try:
        measured = measure(args, log)
        args.out.write_text(report(measured, shown, started, args))
        # The figures, so the report can be read again or compared (--report-only).
        args.out.with_suffix(".json").write_text(json.dumps(measured, indent=1) + "\n")
    except (BenchError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # a MiprayError, a Dask failure: one line
        from ..errors import MiprayError

        if not isinstance(exc, MiprayError):
            raise
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 1
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
