"""``make bench-throughput``: mipray's rays/s by ray type against Embree's, same geometry and rays.

    .venv/bin/python -m mipray.tools.throughput [--width 512] [--runs 3]
        [--baseline-record /work/baseline-4a6d22c/.venv/bin/mipray-record]
        [--embree-bin out/throughput/embree_throughput] [--out docs/throughput.md]

For each scene of :mod:`mipray.tools.throughput_scenes` (*plain*: creased cars; *displaced*:
texture-displaced blobs) it

1. writes the scene (USD) and its export for the Embree harness
   (``scripts/bench/embree_throughput.cpp``), and runs the harness: camera, AO, shadow and
   reflection rays, each timed on its own;
2. renders the scene with ``mipray-record`` in one configuration per ray type, every run a new
   process, configurations interleaved run by run:

   ============  ==========================================================================
   camera        ``--integrator direct``, lights off (a session layer deactivates them):
                 one camera ray per pixel and its shading, nothing else
   ao            ``--integrator ao --setting aoSamples=N``, lights off
   shadow        ``--integrator direct --setting shadowSamples=1`` with the sun (angle 0, a
                 delta light: one shadow ray per lit camera hit)
   reflection    ``--integrator direct --setting maxDepth=1``, lights off, every
                 UsdPreviewSurface made a mirror (metallic 1, roughness 0; session layer)
   ============  ==========================================================================

   Rays of each type are the stats' ``render.rays.<type>``; a configuration's time is the
   stats' ``render.wall_s`` (the render, tessellation included, not the USD reading and scene
   sync). The time of the camera rays is the camera configuration's; the time of another
   type's rays is its configuration's time **minus** the camera configuration's time of the
   same run (median over runs of that difference): it is honest only as long as the camera
   rays and their shading cost the same in both, which the checks below the tables state;
3. with ``--baseline-record``, does 2 again with another build's ``mipray-record`` (the issue's
   starting commit) for a before/after table;
4. profiles the ``ao`` configuration of the current build with ``perf record -g`` and lists the
   functions with the most samples (self time; skipped with a note if ``perf`` is absent);
5. writes ``docs/throughput.md``: the machine, the command, the date, the tables.

Everything goes through the command line of ``mipray-record``, so any build of it can be
measured. Exit status 0 when the report was written, 1 on an error (one line,
``throughput: ...``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import resource
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Sdf, Usd, UsdLux, UsdShade

from .throughput_scenes import (
    SCENES,
    ExportError,
    export_stage,
    write_displaced,
    write_height_texture,
    write_plain,
)

__all__ = ["RAY_TYPES", "Config", "configs", "main", "prepare_scene"]

PROG = "throughput"
#: Ray types in table order; each is also the name of the mipray configuration isolating it.
RAY_TYPES = ("camera", "ao", "shadow", "reflection")
#: Stats ray counters (``render.rays.*``) that no configuration here should make.
OTHER_RAYS = ("refraction", "glossy", "diffuse")
TEXTURE = "throughput_height.tx"


class ThroughputError(Exception):
    """A step that failed; the message is the one-line report."""


@dataclass(frozen=True)
class Config:
    """A ``mipray-record`` configuration isolating one ray type."""

    ray_type: str
    args: tuple[str, ...]
    #: Session layer: ``dark`` (lights off), ``mirror`` (lights off, every surface a mirror),
    #: or None.
    session: str | None


def configs(ao_samples: int, ao_distance: float | None) -> tuple[Config, ...]:
    """The four configurations, in :data:`RAY_TYPES` order."""
    ao = ["--integrator", "ao", "--setting", f"aoSamples={ao_samples}"]
    if ao_distance is not None:
        ao += ["--setting", f"aoDistance={ao_distance}"]
    return (
        # The depth AOV (written after the render, outside render.wall_s) is checked against
        # the harness's: the two trace the same surfaces (depth_agreement).
        Config("camera", ("--integrator", "direct", "--aovs", "color,depth"), "dark"),
        Config("ao", tuple(ao), "dark"),
        Config("shadow", ("--integrator", "direct", "--setting", "shadowSamples=1"), None),
        Config("reflection", ("--integrator", "direct", "--setting", "maxDepth=1"), "mirror"),
    )


# --- scenes ---------------------------------------------------------------------------------


@dataclass
class PreparedScene:
    """A generated scene: its USD, the harness's export and the session layers."""

    name: str
    usd: Path
    export: Path
    sessions: dict[str, Path]
    control_faces: int


def _session_layers(usd: Path) -> dict[str, Path]:
    """Write ``<scene>.dark.usda`` and ``<scene>.mirror.usda`` beside ``usd``."""
    stage = Usd.Stage.Open(str(usd))
    lights = [p.GetPath() for p in stage.Traverse() if p.HasAPI(UsdLux.LightAPI)]
    surfaces = [
        p.GetPath()
        for p in stage.Traverse()
        if p.IsA(UsdShade.Shader) and UsdShade.Shader(p).GetIdAttr().Get() == "UsdPreviewSurface"
    ]
    out: dict[str, Path] = {}
    for name, mirror in (("dark", False), ("mirror", True)):
        path = usd.with_suffix(f".{name}.usda")
        layer = Sdf.Layer.CreateAnonymous()
        for light in lights:
            Sdf.CreatePrimInLayer(layer, light).active = False
        if mirror:
            for surface in surfaces:
                spec = Sdf.CreatePrimInLayer(layer, surface)
                for attr, value in (("inputs:metallic", 1.0), ("inputs:roughness", 0.0)):
                    Sdf.AttributeSpec(spec, attr, Sdf.ValueTypeNames.Float).default = value
        layer.Export(str(path))
        out[name] = path
    return out


def prepare_scene(name: str, work: Path, small: bool = False) -> PreparedScene:
    """Write scene ``name`` (``plain`` or ``displaced``) into ``work`` and export it.

    ``small`` writes a tiny version (for tests): 2×1 cars, or 2×1 blobs of 2² quads a side.
    """
    work.mkdir(parents=True, exist_ok=True)
    usd = work / f"{name}.usda"
    if usd.exists():
        usd.unlink()  # Usd.Stage.CreateNew refuses an existing file
    if name == "plain":
        write_plain(usd, grid=(2, 1) if small else (6, 3))
    elif name == "displaced":
        texture = work / TEXTURE
        if not texture.exists():
            write_height_texture(texture, size=64 if small else 1024)
        if small:
            write_displaced(usd, TEXTURE, grid=(2, 1), face_res=2)
        else:
            write_displaced(usd, TEXTURE)
    else:
        raise ThroughputError(f"unknown scene {name!r}; the scenes are {', '.join(SCENES)}")
    export = usd.with_suffix(".bin")
    scene = export_stage(usd, export)
    faces = sum(len(m.counts) for m in scene.meshes)
    return PreparedScene(name, usd, export, _session_layers(usd), faces)


# --- running --------------------------------------------------------------------------------


def _run(cmd: Sequence[str], what: str, env: dict[str, str] | None = None) -> str:
    """Run ``cmd``; its stdout, or ThroughputError naming ``what`` with stderr's last line."""
    proc = subprocess.run(list(cmd), capture_output=True, text=True, env=env, check=False)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise ThroughputError(f"{what} failed (exit {proc.returncode}): {last}")
    return proc.stdout


@dataclass
class Measured:
    """Runs of one configuration: render seconds, ray counts and process CPU seconds per run."""

    wall_s: list[float] = field(default_factory=list)
    rays: list[dict[str, int]] = field(default_factory=list)
    #: User + system CPU seconds of the whole ``mipray-record`` process (USD reading and sync
    #: included: the same in every configuration, so they cancel in a difference).
    cpu_s: list[float] = field(default_factory=list)


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def record_command(
    record: str, scene: PreparedScene, config: Config, width: int, threads: int, out: Path
) -> list[str]:
    """The ``mipray-record`` command line of ``config`` on ``scene``."""
    cmd = [record, "--imageWidth", str(width), "--threads", str(threads), "--disableCameraLight"]
    cmd += ["--stats", str(out.with_suffix(".stats.json"))]
    if config.session:
        cmd += ["--sessionLayer", str(scene.sessions[config.session])]
    cmd += [*config.args, str(scene.usd), str(out)]
    return cmd


def measure_mipray(
    record: str,
    scene: PreparedScene,
    cfgs: Sequence[Config],
    width: int,
    threads: int,
    runs: int,
    work: Path,
    log: Any,
) -> dict[str, Measured]:
    """Render every configuration ``runs`` times, interleaved run by run."""
    measured = {c.ray_type: Measured() for c in cfgs}
    for run in range(runs):
        for config in cfgs:
            out = work / f"{scene.name}.{config.ray_type}.exr"
            cmd = record_command(record, scene, config, width, threads, out)
            cpu_before = _children_cpu_s()
            _run(cmd, f"{record} ({scene.name}, {config.ray_type})")
            measured[config.ray_type].cpu_s.append(_children_cpu_s() - cpu_before)
            stats = json.loads(out.with_suffix(".stats.json").read_text())
            render = stats["render"]
            rays = {k: int(v) for k, v in render["rays"].items()}
            measured[config.ray_type].wall_s.append(float(render["wall_s"]))
            measured[config.ray_type].rays.append(rays)
            log(
                f"  {scene.name} {config.ray_type} run {run + 1}/{runs}: "
                f"{render['wall_s']:.2f} s, {rays.get(config.ray_type, 0):,} rays"
            )
    return measured


@dataclass
class Rate:
    """Rays of one type, the seconds they took, and the checks that held."""

    rays: int
    #: Seconds of these rays: the camera configuration's render, or another configuration's
    #: render minus the camera configuration's (median over runs of the run-by-run difference).
    seconds: float
    notes: list[str] = field(default_factory=list)
    #: The configuration's own render time (median over runs).
    config_s: float | None = None
    #: CPU seconds of these rays (types other than camera): the configuration's process CPU
    #: time minus the camera configuration's, run by run, median. Less sensitive than wall
    #: time to other work on the machine.
    cpu_s: float | None = None

    @property
    def per_s(self) -> float:
        """Rays per second (0 when the time is not positive)."""
        return self.rays / self.seconds if self.seconds > 0 else 0.0

    @property
    def per_cpu_s(self) -> float:
        """Rays per CPU second (0 when unknown or not positive)."""
        return self.rays / self.cpu_s if self.cpu_s is not None and self.cpu_s > 0 else 0.0


def mipray_rates(measured: dict[str, Measured]) -> dict[str, Rate]:
    """Rays/s per type: camera from its own configuration, the others by subtraction."""
    camera = measured["camera"]
    camera_rays = camera.rays[0].get("camera", 0)
    camera_s = statistics.median(camera.wall_s)
    rates = {"camera": Rate(camera_rays, camera_s, config_s=camera_s)}
    for ray_type, m in measured.items():
        notes: list[str] = []
        counts = {r.get(ray_type, 0) for r in m.rays}
        if len(counts) > 1:
            notes.append(f"{ray_type} rays differ between runs: {sorted(counts)}")
        for r in m.rays[:1]:
            if r.get("camera", 0) != camera_rays:
                notes.append(f"{r.get('camera', 0):,} camera rays, not {camera_rays:,}")
            others = {
                k: v for k, v in r.items() if v and k not in ("camera", ray_type) and k != "total"
            }
            if others:
                notes.append("also traced " + ", ".join(f"{v:,} {k}" for k, v in others.items()))
        if ray_type == "camera":
            rates["camera"].notes = notes
            continue
        diffs = [w - c for w, c in zip(m.wall_s, camera.wall_s, strict=True)]
        # CPU times are missing when the figures come from an older saved run.
        cpu_diffs = (
            [w - c for w, c in zip(m.cpu_s, camera.cpu_s, strict=True)]
            if len(m.cpu_s) == len(camera.cpu_s)
            else []
        )
        rates[ray_type] = Rate(
            m.rays[0].get(ray_type, 0),
            statistics.median(diffs),
            notes,
            config_s=statistics.median(m.wall_s),
            cpu_s=statistics.median(cpu_diffs) if cpu_diffs else None,
        )
    return rates


def run_embree(
    binary: Path,
    scene: PreparedScene,
    width: int,
    ao_samples: int,
    ao_distance: float | None,
    threads: int,
    runs: int,
    edge_level: int,
) -> dict[str, Any]:
    """The harness's JSON for ``scene``."""
    cmd = [str(binary), str(scene.export), "--width", str(width), "--height", str(width)]
    cmd += ["--ao-samples", str(ao_samples), "--threads", str(threads), "--runs", str(runs)]
    cmd += ["--edge-level", str(edge_level)]
    if ao_distance is not None:
        cmd += ["--ao-distance", str(ao_distance)]
    cmd += ["--image", str(scene.usd.with_suffix(".embree_ao.pgm"))]
    cmd += ["--depth", str(scene.usd.with_suffix(".embree_depth.pfm"))]
    return dict(json.loads(_run(cmd, f"{binary} ({scene.name})")))


def read_pfm(path: Path) -> NDArray[np.float32]:
    """A one-channel PFM (``Pf``) as an H×W array, first row at the top."""
    data = Path(path).read_bytes()
    magic, size, scale, pixels = data.split(b"\n", 3)
    if magic != b"Pf":
        raise ThroughputError(f"{path}: not a one-channel PFM")
    width, height = (int(v) for v in size.split())
    order = "<f4" if float(scale) < 0 else ">f4"
    image = np.frombuffer(pixels, order, width * height).reshape(height, width)
    return np.ascontiguousarray(image[::-1], dtype=np.float32)


def depth_agreement(embree: NDArray[np.float32], mipray: NDArray[np.float32]) -> dict[str, Any]:
    """How far the two renderers' camera-hit depths (0 = no hit) agree, pixel by pixel."""
    if embree.shape != mipray.shape:
        raise ThroughputError(f"depth images of {embree.shape} and {mipray.shape} pixels")
    e_hit, m_hit = embree > 0, mipray > 0
    both = e_hit & m_hit
    rel = np.abs(embree[both] - mipray[both]) / mipray[both]
    return {
        "both": int(both.sum()),
        "only_embree": int((e_hit & ~m_hit).sum()),
        "only_mipray": int((m_hit & ~e_hit).sum()),
        "median_rel": float(np.median(rel)) if rel.size else 0.0,
        "p99_rel": float(np.percentile(rel, 99)) if rel.size else 0.0,
        "over_1pct": int((rel > 0.01).sum()),
    }


def _mipray_depth(path: Path) -> NDArray[np.float32]:
    from .. import _mipray

    pixels, channels = _mipray.read_image(str(path))
    for name in ("Z", "depth", "depth.Z"):
        if name in channels:
            return np.ascontiguousarray(pixels[..., channels.index(name)], dtype=np.float32)
    raise ThroughputError(f"{path}: no depth channel among {channels}")


# --- profile --------------------------------------------------------------------------------

_PERF_LINE = re.compile(r"^\s*([0-9.]+)%\s+(.*\S)\s*$")
#: A ``--sort dso,symbol`` line: percentage, shared object, ``[.]`` or ``[k]``, symbol (which
#: ends at the first wide gap: call-graph columns may follow).
_PERF_DSO_SYMBOL = re.compile(r"^\s*([0-9.]+)%\s+(\S+)\s+\[[.kgu]\]\s+(.*?)(?:\s{2,}|\s*$)")


def parse_perf_report(text: str, limit: int) -> list[tuple[float, str]]:
    """``(percent, name)`` of the first ``limit`` entries of ``perf report --stdio`` output."""
    rows: list[tuple[float, str]] = []
    for line in text.splitlines():
        if line.startswith("#") or not line.strip():
            continue
        match = _PERF_LINE.match(line)
        if not match:
            continue
        # "[.] name   <padding and call-graph rules>": the name ends at the first wide gap.
        name = re.split(r"\s{2,}", re.sub(r"^\[[.kgu]\]\s+", "", match.group(2)))[0]
        rows.append((float(match.group(1)), name))
        if len(rows) >= limit:
            break
    return rows


def _render_threads(perf: str, data: Path, threads: int) -> list[str]:
    """The ``threads`` busiest thread ids of ``data`` other than the process's main thread.

    The main thread reads the USD stage and syncs the scene (outside ``render.wall_s``) and
    then waits while the render's worker pool traces, so the pool's threads are the render.
    """
    # The first sample's "pid/tid" names the process; read one line, not the whole script.
    with subprocess.Popen(
        [perf, "script", "-i", str(data), "-F", "pid,tid"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    ) as proc:
        first = proc.stdout.readline() if proc.stdout else ""
        proc.kill()
    pid = first.split("/", 1)[0].strip()
    text = _run(
        [
            perf,
            "report",
            "-i",
            str(data),
            "--no-children",
            "--stdio",
            "-g",
            "none",
            "--sort",
            "pid",
        ],
        "perf report --sort pid",
    )
    tids = [name.split(":", 1)[0] for _, name in parse_perf_report(text, 64)]
    return [t for t in tids if t != pid][:threads]


def profile(
    record: str, scene: PreparedScene, config: Config, width: int, threads: int, work: Path
) -> dict[str, Any]:
    """``perf record -g`` of one render: the render threads' top symbols and shared objects."""
    perf = shutil.which("perf")
    if perf is None:
        return {"skipped": "perf is not installed (apt-get install linux-perf)"}
    data = work / f"{scene.name}.{config.ray_type}.perf.data"
    out = work / f"{scene.name}.{config.ray_type}.perf.exr"
    cmd = [perf, "record", "-g", "-q", "-o", str(data), "--"]
    cmd += record_command(record, scene, config, width, threads, out)
    try:
        _run(cmd, f"perf record ({scene.name})")
        return summarize_perf(perf, data, threads)
    except ThroughputError as e:
        return {"skipped": str(e)}


def summarize_perf(perf: str, data: Path, threads: int) -> dict[str, Any]:
    """The render threads' top symbols (self time, at least 0.5 %) and shared objects.

    One ``perf report --sort dso,symbol`` restricted to the render threads, shares relative to
    their samples; the shared objects' shares are sums over their symbols (perf's own
    ``--sort dso`` miscounts once ``--tid`` filters).
    """
    tids = _render_threads(perf, data, threads)
    report = [perf, "report", "-i", str(data), "--no-children", "--stdio", "-g", "none"]
    report += ["--sort", "dso,symbol", "--percent-limit", "0", "--percentage", "relative"]
    if tids:
        report += ["--tid", ",".join(tids)]
    symbols, objects = parse_dso_symbols(_run(report, "perf report"))
    return {"threads": len(tids), "symbols": symbols[:20], "objects": objects[:8]}


def parse_dso_symbols(text: str) -> tuple[list[tuple[float, str]], list[tuple[float, str]]]:
    """``perf report --sort dso,symbol`` output as (symbols, shared objects).

    Symbols with at least 0.5 %, in the report's order; shared objects with at least 0.5 %,
    their symbols' shares summed, largest first.
    """
    symbols: list[tuple[float, str]] = []
    objects: dict[str, float] = {}
    for line in text.splitlines():
        match = _PERF_DSO_SYMBOL.match(line)
        if not match:
            continue
        pct, dso, symbol = float(match.group(1)), match.group(2), match.group(3)
        objects[dso] = objects.get(dso, 0.0) + pct
        if pct >= 0.5:
            symbols.append((pct, symbol))
    ranked = sorted(((round(p, 2), o) for o, p in objects.items() if p >= 0.5), reverse=True)
    return symbols, ranked


# --- the report -----------------------------------------------------------------------------


def _git_label(record: str) -> str:
    """``<commit>`` (``+dirty``) of the worktree whose ``.venv`` holds ``record``, else ''."""
    path = Path(record).resolve()
    for parent in path.parents:
        if parent.name == ".venv":
            root = parent.parent

            def git(*args: str, root: Path = root) -> str:
                return subprocess.run(
                    ["git", "-C", str(root), *args], capture_output=True, text=True, check=True
                ).stdout.strip()

            try:
                commit = git("rev-parse", "--short", "HEAD")
                dirty = git("status", "--porcelain", "-uno")
            except (OSError, subprocess.CalledProcessError):
                return ""
            return commit + ("+dirty" if dirty else "")
    return ""


def _machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    system = f"{platform.system()} {platform.release()}"
    return f"{model}, {os.cpu_count()} logical CPUs, {system}; load average at start {load}"


def _embree_rate(em: dict[str, Any], ray_type: str) -> float:
    """Embree's rays/s of ``ray_type`` (median time), 0 if the time is not positive."""
    e = em["types"][ray_type]
    return float(e["rays"] / e["median_s"]) if e["median_s"] > 0 else 0.0


def _m(rate: float) -> str:
    return f"{rate / 1e6:.3g}" if rate > 0 else "—"


def _ratio(a: float, b: float) -> str:
    return f"{a / b:.3g}×" if a > 0 and b > 0 else "—"


@dataclass
class Results:
    """Everything the report needs."""

    args: argparse.Namespace
    command: str
    started: str
    machine: str
    #: Control faces per scene, in run order.
    faces: dict[str, int] = field(default_factory=dict)
    embree: dict[str, dict[str, Any]] = field(default_factory=dict)
    current: dict[str, dict[str, Rate]] = field(default_factory=dict)
    baseline: dict[str, dict[str, Rate]] = field(default_factory=dict)
    profiles: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Per scene, :func:`depth_agreement` of the harness's and mipray's camera hits.
    depth: dict[str, dict[str, Any]] = field(default_factory=dict)
    labels: dict[str, str] = field(default_factory=dict)
    elapsed_s: float = 0.0


def report(r: Results) -> str:
    """``docs/throughput.md``."""
    a = r.args
    cur, base = r.labels["current"], r.labels.get("baseline", "")
    lines = [
        "# Ray throughput: mipray against Embree on the same geometry and rays",
        "",
        "Written by `make bench-throughput` (`python -m mipray.tools.throughput`, issue 14 part "
        "3): rays per second by ray type for mipray and, in the same run on the same geometry "
        "and rays, for Embree through the project's harness `scripts/bench/embree_throughput.cpp`.",
        "",
        f"- Date: {r.started} (took {r.elapsed_s / 60:.1f} min)",
        f"- Machine: {r.machine}",
        f"- Command: `{r.command}`",
        f"- mipray: {cur}" + (f"; baseline: {base}" if base else ""),
        f"- Image {a.width}×{a.width}, {a.threads} threads for both renderers, "
        f"{a.ao_samples} AO rays per camera hit, AO distance "
        f"{'infinite' if a.ao_distance is None else a.ao_distance}; "
        f"mipray: median of {a.runs} runs per configuration, each a new process, "
        f"configurations interleaved; Embree: median of {a.embree_runs} runs per ray type.",
        "",
        "## Scenes",
        "",
        "Generated by `mipray/tools/throughput_scenes.py` into the work directory "
        f"(`{a.work}`), deterministic:",
        "",
    ]
    for name, faces in r.faces.items():
        what = {
            "plain": "creased Catmull-Clark cars (box body and cabin with creased edges, four "
            "wheels with creased rims and 16-gon caps) on a one-quad ground, a sun of angle 0",
            "displaced": "lumpy Catmull-Clark blobs, UsdPreviewSurface displacement from a "
            "1024² height texture (maketx MIP map) on vertex st, on a one-quad ground, a sun "
            "of angle 0",
        }[name]
        lines.append(f"- **{name}**: {faces:,} control faces; {what}.")
    lines += [
        "",
        "## Rays per second by ray type",
        "",
        "*config. render s* is the median `render.wall_s` of the configuration isolating the "
        "ray type; *mipray s* is the rays' share of it: the configuration's time minus the "
        "camera-only configuration's, run by run (see *How* below). Where that difference is "
        "not positive the type's rays cost less than the run-to-run noise of the renders (on "
        "a machine shared with other work) and no rate is given (—). Embree's times exclude "
        "its BVH build (all geometry tessellated and displaced up front: *build s*); mipray's "
        "include its lazy tessellation, which is how it renders.",
        "",
    ]
    for name in r.faces:
        em = r.embree.get(name)
        lines += [f"### {name}", ""]
        header = "| ray type | mipray rays | config. render s | mipray s | mipray M rays/s |"
        rule = "|---|---:|---:|---:|---:|"
        if em:
            header += " Embree rays | Embree s | Embree M rays/s | mipray / Embree |"
            rule += "---:|---:|---:|---:|"
        lines += [header, rule]
        for t in RAY_TYPES:
            m = r.current[name][t]
            config_s = "—" if m.config_s is None else f"{m.config_s:.2f}"
            row = f"| {t} | {m.rays:,} | {config_s} | {m.seconds:.2f} | {_m(m.per_s)} |"
            if em:
                e, e_rate = em["types"][t], _embree_rate(em, t)
                row += f" {e['rays']:,} | {e['median_s']:.3f} | {_m(e_rate)} |"
                row += f" {_ratio(m.per_s, e_rate)} |"
            lines.append(row)
        if em:
            lines += [
                "",
                f"Embree {em['embree_version']}: build {em['build_s']:.2f} s "
                f"(edge level {em['edge_level']}), {em['hits']:,} camera hits of "
                f"{em['pixels']:,} pixels, mean unoccluded AO fraction "
                f"{em['ao_unoccluded_mean']:.3f}.",
            ]
        cpu_rows = [t for t in RAY_TYPES if r.current[name][t].cpu_s is not None]
        if cpu_rows:
            lines += [
                "",
                "Per CPU second (the load of a shared machine moves these least; on an idle "
                "machine with perfect scaling wall rays/s would be "
                f"{a.threads} × rays per CPU second):",
                "",
                "| ray type | mipray CPU s | mipray M rays/CPU-s | Embree CPU s "
                "| Embree M rays/CPU-s | mipray / Embree |",
                "|---|---:|---:|---:|---:|---:|",
            ]
            for t in cpu_rows:
                m_cpu = r.current[name][t].cpu_s or 0.0
                m_rate = r.current[name][t].per_cpu_s
                e_cpu = float(em["types"][t].get("median_cpu_s", 0.0)) if em else 0.0
                e_rate = em["types"][t]["rays"] / e_cpu if em and e_cpu > 0 else 0.0
                e_cell = f"{e_cpu:.3f}" if em else "—"
                lines.append(
                    f"| {t} | {m_cpu:.2f} | {_m(m_rate)} | {e_cell} | {_m(e_rate)} | "
                    f"{_ratio(m_rate, e_rate)} |"
                )
        dep = r.depth.get(name)
        if dep:
            lines += [
                "",
                f"Same surfaces: the camera hits' depth (mipray's `depth` AOV against the "
                f"harness's) differs by a median {100 * dep['median_rel']:.2g} % and at the 99th "
                f"percentile {100 * dep['p99_rel']:.2g} % over the {dep['both']:,} pixels both "
                f"hit ({dep['over_1pct']:,} by more than 1 %); pixels only Embree hit: "
                f"{dep['only_embree']:,}, only mipray: {dep['only_mipray']:,}.",
            ]
        notes = [f"{t}: {n}" for t in RAY_TYPES for n in r.current[name][t].notes]
        lines += [
            "",
            "Checks: "
            + (
                "; ".join(notes)
                if notes
                else "every configuration traced "
                "only its own ray type besides the same camera rays, the same counts in every "
                "run."
            ),
            "",
        ]
    if r.baseline:
        lines += [
            "## Before and after",
            "",
            f"M rays/s (wall); before: {base}, after: {cur}. *after / before (CPU)*: the same "
            "speed-up in rays per CPU second, which the machine's other work moves least (not "
            "for camera rays, whose process CPU time includes reading the scene). Embree's "
            "rays/s from the same run, and the after/Embree ratio against the issue's target "
            "of 0.5.",
            "",
            "| scene | ray type | before | after | after / before | after / before (CPU) "
            "| Embree | after / Embree |",
            "|---|---|---:|---:|---:|---:|---:|---:|",
        ]
        for name in r.baseline:
            em = r.embree.get(name)
            for t in RAY_TYPES:
                b, c = r.baseline[name][t], r.current[name][t]
                e_rate = _embree_rate(em, t) if em else 0.0
                cpu_ratio = _ratio(c.per_cpu_s, b.per_cpu_s)
                lines.append(
                    f"| {name} | {t} | {_m(b.per_s)} | {_m(c.per_s)} | {_ratio(c.per_s, b.per_s)} "
                    f"| {cpu_ratio} | {_m(e_rate)} | {_ratio(c.per_s, e_rate)} |"
                )
        missing = [n for n in r.faces if n not in r.baseline]
        if missing:
            lines += [
                "",
                f"Not measured with the baseline (the run was stopped before): "
                f"{', '.join(missing)}.",
            ]
        notes = [
            f"{n}: {t}: {x}" for n in r.baseline for t in RAY_TYPES for x in r.baseline[n][t].notes
        ]
        if notes:
            lines += ["", "Checks (before): " + "; ".join(notes)]
        lines.append("")
    lines += [
        "## Profile",
        "",
        "Instruction counts (callgrind) per configuration, before and after each optimisation "
        "step, are in [throughput-callgrind.md](throughput-callgrind.md): repeatable on a loaded "
        "machine, where these wall times are not.",
        "",
    ]
    for name, p in r.profiles.items():
        lines += [f"### {name}, `ao` configuration", ""]
        if "skipped" in p:
            lines += [f"Skipped: {p['skipped']}", ""]
            continue
        lines += [
            f"`perf record -g` of one render; self time (`perf report --no-children --sort "
            f"dso,symbol`) in its {p['threads']} render threads (the main thread, which reads the "
            "stage and syncs the scene before `render.wall_s` starts, left out), as a share of "
            "their samples; functions with at least 0.5 %.",
            "",
            "| % | function |",
            "|---:|---|",
        ]
        lines += [f"| {pct:.1f} | `{sym[:120]}` |" for pct, sym in p["symbols"]]
        lines += [
            "",
            "By shared object: " + ", ".join(f"{o} {pct:.1f} %" for pct, o in p["objects"]),
            "",
        ]
    lines += [
        "## How",
        "",
        "- **Same geometry**: the harness reads an export of the very USD stage mipray renders "
        "(points, face counts and indices, crease edges and sharpness, vertex st, the "
        "displacement texture with its scale and bias), builds `RTC_GEOMETRY_TYPE_SUBDIVISION` "
        "at edge level 16 (mipray's finest rate is 16 quads per subpatch side) with corners "
        "pinned (USD's `edgeAndCorner`), and for the displaced scene a displacement callback "
        "that reads the same texture through OpenImageIO at the vertex's st with a filter of "
        "one grid step, as mipray does.",
        "- **Same rays**: the camera (one ray per pixel centre), then from each camera hit "
        f"{a.ao_samples} cosine-distributed AO rays, one shadow ray toward the sun where the "
        "surface faces it, one mirror reflection ray. Single rays (`rtcIntersect1`, "
        f"`rtcOccluded1`) on {a.threads} `std::thread`s taking chunks of 64 hits; Embree's "
        "TBB threads (limited to the same count) only build.",
        "- **mipray's configurations** (each `mipray-record --threads "
        f"{a.threads} --disableCameraLight --stats`): camera = `--integrator direct` with the "
        "lights off (a session layer); ao = `--integrator ao --setting aoSamples=N`, lights "
        "off; shadow = `--integrator direct --setting shadowSamples=1` with the sun; reflection "
        "= `--integrator direct --setting maxDepth=1`, lights off, every UsdPreviewSurface "
        "metallic 1 and roughness 0 (a mirror; session layer). Rays from the stats' "
        "`render.rays`, time from `render.wall_s`.",
        "- **The subtraction**: a type's time is its configuration's `render.wall_s` minus the "
        "camera configuration's, run by run, median over runs. It counts the camera rays and "
        "their shading once, so it is honest only if they cost the same in both "
        "configurations: the checks above confirm the camera ray counts match, but the "
        "tessellation the camera rays leave in the cache serves the secondary rays too, so "
        "secondary rays get the cache warm. Noise of either time lands in the difference: a "
        "type whose rays take little time (shadow, reflection) has a large relative error.",
        "- **CPU seconds**: mipray's are the `mipray-record` process's user + system time "
        "(`getrusage` of the child), so a type's CPU seconds are its configuration's minus the "
        "camera configuration's, run by run, which also cancels reading and syncing the "
        "scene; Embree's are the harness process's around each pass.",
        "- **Before/after**: the baseline is another build's `mipray-record`, run with the "
        "same command lines (`--baseline-record`); built once in its own worktree: "
        "`git worktree add --detach /work/baseline-4a6d22c 4a6d22c && cd /work/baseline-4a6d22c "
        "&& MIPRAY_SKIP_APT=1 MIPRAY_SKIP_BUILD=1 bash scripts/setup.sh && VIRTUAL_ENV=$PWD/.venv "
        "PATH=$PWD/.venv/bin:$PATH .venv/bin/maturin develop --release -m python/Cargo.toml`.",
        "",
    ]
    return "\n".join(lines)


# --- command line ---------------------------------------------------------------------------


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The command line (documented by ``--help``)."""
    venv_bin = Path(sys.executable).parent
    p = argparse.ArgumentParser(
        prog="python -m mipray.tools.throughput",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    p.add_argument("--width", type=_positive, default=512, help="image width and height (512)")
    p.add_argument("--runs", type=_positive, default=3, help="mipray runs per configuration (3)")
    p.add_argument("--embree-runs", type=_positive, default=5, help="Embree runs per ray type (5)")
    p.add_argument("--threads", type=_positive, default=2, help="render threads, both (2)")
    p.add_argument("--ao-samples", type=_positive, default=64, help="AO rays per hit (64)")
    p.add_argument(
        "--ao-distance",
        type=float,
        default=None,
        help="AO ray length in world units (default: infinite, mipray's default aoDistance)",
    )
    p.add_argument("--edge-level", type=_positive, default=16, help="Embree's edge level (16)")
    p.add_argument("--scenes", default=",".join(SCENES), help="scenes to run (plain,displaced)")
    p.add_argument(
        "--record",
        default=str(venv_bin / "mipray-record"),
        help="the mipray-record to measure (default: this venv's)",
    )
    p.add_argument("--baseline-record", help="another build's mipray-record: before/after table")
    p.add_argument(
        "--embree-bin",
        type=Path,
        help="the compiled harness (make bench-throughput builds it); without it no Embree column",
    )
    p.add_argument("--no-profile", action="store_true", help="skip the perf profile")
    p.add_argument("--work", type=Path, default=Path("out/throughput"), help="scratch directory")
    p.add_argument("--out", type=Path, default=Path("docs/throughput.md"), help="the report")
    p.add_argument(
        "--report-only",
        type=Path,
        metavar="JSON",
        help="write the report from a run's throughput.json (in --work) without measuring",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and write the report; the exit status."""
    args = build_parser().parse_args(argv)
    if args.report_only is not None:
        try:
            args.out.write_text(report(load(args.report_only)))
        except (OSError, KeyError, ValueError, TypeError) as e:
            print(f"{PROG}: {args.report_only}: {e}", file=sys.stderr)
            return 1
        print(args.out)
        return 0
    started = time.monotonic()

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    shown = ["python -m mipray.tools.throughput", *(sys.argv[1:] if argv is None else argv)]
    results = Results(
        args=args,
        command=" ".join(shown),
        started=datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        machine=_machine(),
    )
    try:
        for record in filter(None, (args.record, args.baseline_record)):
            if not (Path(record).is_file() and os.access(record, os.X_OK)):
                raise ThroughputError(f"{record}: not an executable mipray-record")
        if args.embree_bin is not None and not args.embree_bin.is_file():
            raise ThroughputError(
                f"{args.embree_bin}: no such harness (make bench-throughput builds it)"
            )
        version = _run([args.record, "--version"], "mipray-record --version").strip()
        results.labels["current"] = (
            f"`{args.record}` ({version}, {_git_label(args.record) or 'commit unknown'})"
        )
        if args.baseline_record:
            bversion = _run([args.baseline_record, "--version"], "baseline --version").strip()
            results.labels["baseline"] = (
                f"`{args.baseline_record}` ({bversion}, "
                f"{_git_label(args.baseline_record) or 'commit unknown'})"
            )
        cfgs = configs(args.ao_samples, args.ao_distance)
        names = [n.strip() for n in args.scenes.split(",") if n.strip()]

        def checkpoint() -> None:
            # After every step, so a failure or an interruption keeps the figures so far
            # (--report-only writes the report from them).
            results.elapsed_s = time.monotonic() - started
            save(results, args.work / "throughput.json")

        # The current build on every scene first, then the profiles, then the baseline: the
        # figures that matter most are in before a long run is cut short.
        scenes: dict[str, PreparedScene] = {}
        for name in names:
            log(f"{PROG}: writing the {name} scene")
            scene = scenes[name] = prepare_scene(name, args.work)
            results.faces[name] = scene.control_faces
            if args.embree_bin is not None:
                log(f"{PROG}: Embree on {name}")
                results.embree[name] = run_embree(
                    args.embree_bin,
                    scene,
                    args.width,
                    args.ao_samples,
                    args.ao_distance,
                    args.threads,
                    args.embree_runs,
                    args.edge_level,
                )
            log(f"{PROG}: mipray on {name}")
            results.current[name] = mipray_rates(
                measure_mipray(
                    args.record, scene, cfgs, args.width, args.threads, args.runs, args.work, log
                )
            )
            if args.embree_bin is not None:
                results.depth[name] = depth_agreement(
                    read_pfm(scene.usd.with_suffix(".embree_depth.pfm")),
                    _mipray_depth(args.work / f"{name}.camera.exr"),
                )
            checkpoint()
        for name, scene in scenes.items():
            if not args.no_profile:
                log(f"{PROG}: profiling {name}")
                results.profiles[name] = profile(
                    args.record, scene, cfgs[1], args.width, args.threads, args.work
                )
                checkpoint()
        for name, scene in scenes.items():
            if args.baseline_record:
                log(f"{PROG}: baseline on {name}")
                results.baseline[name] = mipray_rates(
                    measure_mipray(
                        args.baseline_record,
                        scene,
                        cfgs,
                        args.width,
                        args.threads,
                        args.runs,
                        args.work,
                        log,
                    )
                )
                checkpoint()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(report(results))
    except (ThroughputError, ExportError, OSError, KeyError, ValueError) as e:
        print(f"{PROG}: {e}", file=sys.stderr)
        return 1
    print(args.out)
    return 0


def save(r: Results, path: Path) -> None:
    """Write ``r`` as JSON (the work directory's ``throughput.json``; :func:`load` reads it)."""

    def rates(d: dict[str, dict[str, Rate]]) -> dict[str, Any]:
        return {
            n: {
                t: {
                    "rays": x.rays,
                    "seconds": x.seconds,
                    "notes": x.notes,
                    "config_s": x.config_s,
                    "cpu_s": x.cpu_s,
                }
                for t, x in v.items()
            }
            for n, v in d.items()
        }

    data = {
        "args": {k: str(v) if isinstance(v, Path) else v for k, v in vars(r.args).items()},
        "command": r.command,
        "started": r.started,
        "machine": r.machine,
        "elapsed_s": r.elapsed_s,
        "faces": r.faces,
        "labels": r.labels,
        "embree": r.embree,
        "current": rates(r.current),
        "baseline": rates(r.baseline),
        "profiles": r.profiles,
        "depth": r.depth,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1))


def load(path: Path) -> Results:
    """Results :func:`save` wrote."""
    data = json.loads(Path(path).read_text())

    def rates(d: dict[str, Any]) -> dict[str, dict[str, Rate]]:
        return {n: {t: Rate(**x) for t, x in v.items()} for n, v in d.items()}

    return Results(
        args=argparse.Namespace(**data["args"]),
        command=data["command"],
        started=data["started"],
        machine=data["machine"],
        faces=data["faces"],
        embree=data["embree"],
        current=rates(data["current"]),
        baseline=rates(data["baseline"]),
        profiles=data["profiles"],
        depth=data.get("depth", {}),
        labels=data["labels"],
        elapsed_s=data["elapsed_s"],
    )


if __name__ == "__main__":
    sys.exit(main())
