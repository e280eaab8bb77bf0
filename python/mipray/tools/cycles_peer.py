"""mipray against Cycles on the same USD stage, camera, resolution, samples and threads.

Issue 14's end-to-end target: the 16 spp cars render within 3x of Cycles. Run::

    python -m mipray.tools.cycles_peer out/throughput/plain.usda --samples 16 --width 512

(``make bench-cycles``; the scene is ``make bench-throughput``'s *plain* scene, written by
:mod:`mipray.tools.throughput_scenes`). It writes a layer beside the stage holding a camera
framing the stage the way mipray frames a stage without one, renders that layer with
``mipray-record`` and with Cycles through ``bpy`` (Blender's USD importer, subdivision kept as a
Subdivision Surface modifier with Cycles' adaptive subdivision at ``--dicing-rate`` pixels, so
both renderers tessellate the limit surface to about a pixel), each in its own process, runs
interleaved, and writes ``docs/cycles-comparison.md`` with medians.

Times: mipray's ``render.wall_s`` (its stats: tessellation is on demand, inside it) and the whole
process; Cycles' ``bpy.ops.render.render`` call (scene sync, subdivision, BVH and path tracing)
and the whole process. The process times include reading the stage (and for Cycles starting
Blender), the render times are what a user waits for after loading.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pxr import Gf, Sdf, Usd, UsdGeom

from mipray.usd.camera import framing_camera_arguments

CAMERA = "/CyclesPeerCamera"

#: Run inside the Blender Python process: import the layer, set Cycles up, render, print JSON.
_BLENDER_SCRIPT = r"""
import json, sys, time
import bpy
usd, out, width, samples, threads, dicing, camera = sys.argv[1:8]
width, samples, threads, dicing = int(width), int(samples), int(threads), float(dicing)
bpy.ops.wm.read_factory_settings(use_empty=True)
t0 = time.perf_counter()
bpy.ops.wm.usd_import(
    filepath=usd, import_subdivision=True, import_cameras=True, import_lights=True
)
import_s = time.perf_counter() - t0
scene = bpy.context.scene
cams = [o for o in scene.objects if o.type == "CAMERA"]
scene.camera = next((o for o in cams if o.name == camera), cams[0])
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = 1
scene.cycles.dicing_rate = dicing
scene.render.threads_mode = "FIXED"
scene.render.threads = threads
scene.render.resolution_x = width
scene.render.resolution_y = width
scene.render.resolution_percentage = 100
scene.render.filepath = out
scene.render.image_settings.file_format = "PNG"
subdivided = 0
for o in scene.objects:
    for m in getattr(o, "modifiers", []):
        if m.type == "SUBSURF":
            m.use_adaptive_subdivision = True
            m.adaptive_space = "PIXEL"
            m.adaptive_pixel_size = dicing
            subdivided += 1
t0 = time.perf_counter()
bpy.ops.render.render(write_still=True)
render_s = time.perf_counter() - t0
print("CYCLES_PEER " + json.dumps({"import_s": import_s, "render_s": render_s,
      "subdivided_objects": subdivided, "objects": len(scene.objects),
      "version": bpy.app.version_string}))
"""


@dataclass
class Run:
    """One render: seconds in the render call, the whole process, and its CPU seconds."""

    render_s: float
    process_s: float
    cpu_s: float


def peer_layer(usd: Path) -> tuple[Path, str]:
    """The layer both renderers render, and the path of its camera.

    The stage's first camera if it has one (the layer is then the stage itself); otherwise a
    layer sublayering ``usd`` with a camera at :data:`CAMERA` that frames the stage as mipray
    frames a stage without a camera, with a square aperture for the square image.
    """
    stage = Usd.Stage.Open(str(usd))
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Camera):
            return usd, str(prim.GetPath())
    args = framing_camera_arguments(stage, Usd.TimeCode.Default(), ("default", "render"))
    path = usd.with_suffix(".peer.usda")
    layer = Sdf.Layer.CreateNew(str(path))
    layer.subLayerPaths.append(usd.name)
    peer = Usd.Stage.Open(layer)
    UsdGeom.SetStageUpAxis(peer, UsdGeom.GetStageUpAxis(stage))
    cam = UsdGeom.Camera.Define(peer, CAMERA)
    cam.AddTransformOp().Set(Gf.Matrix4d(*[float(x) for x in args["transform"].reshape(-1)]))
    aperture = min(args["horizontal_aperture"], args["vertical_aperture"])
    cam.GetFocalLengthAttr().Set(args["focal_length"])
    cam.GetHorizontalApertureAttr().Set(aperture)
    cam.GetVerticalApertureAttr().Set(aperture)
    cam.GetClippingRangeAttr().Set(Gf.Vec2f(*args["clipping_range"]))
    layer.Save()
    return path, CAMERA


def _child_cpu() -> float:
    """CPU seconds (user + system) of every child process waited for so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_mipray(
    record: str, layer: Path, camera: str, out: Path, width: int, samples: int, threads: int
) -> Run:
    """One ``mipray-record`` render of ``layer`` through ``camera`` into ``out``."""
    stats = out.with_suffix(".stats.json")
    cmd = [record, "--imageWidth", str(width), "--camera", camera, "--threads", str(threads)]
    cmd += ["--setting", f"samples={samples}", "--stats", str(stats), str(layer), str(out)]
    cpu0, t0 = _child_cpu(), time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    process_s, cpu = time.perf_counter() - t0, _child_cpu() - cpu0
    render = json.loads(stats.read_text())["render"]
    return Run(float(render["wall_s"]), process_s, cpu)


def run_cycles(
    python: str,
    layer: Path,
    camera: str,
    out: Path,
    width: int,
    samples: int,
    threads: int,
    dicing: float,
) -> tuple[Run, dict[str, Any]]:
    """One Cycles render in a new ``python`` process with bpy; its times and what it rendered."""
    args = [
        str(layer),
        str(out),
        str(width),
        str(samples),
        str(threads),
        str(dicing),
        camera.rsplit("/", 1)[-1],
    ]
    cmd = [python, "-c", _BLENDER_SCRIPT, *args]
    cpu0, t0 = _child_cpu(), time.perf_counter()
    p = subprocess.run(cmd, check=True, capture_output=True, text=True)
    process_s, cpu = time.perf_counter() - t0, _child_cpu() - cpu0
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("CYCLES_PEER ")), None)
    if line is None:
        raise RuntimeError(f"Cycles printed no result:\n{p.stdout[-2000:]}\n{p.stderr[-2000:]}")
    info = json.loads(line.split(" ", 1)[1])
    return Run(float(info["render_s"]), process_s, cpu), info


def main(argv: list[str] | None = None) -> int:
    """Run both renderers ``--runs`` times, interleaved, and write the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("usd", type=Path)
    ap.add_argument("--width", type=int, default=512)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument(
        "--dicing-rate", type=float, default=1.0, help="Cycles' adaptive subdivision, pixels"
    )
    ap.add_argument("--record", default=str(Path(sys.executable).with_name("mipray-record")))
    ap.add_argument("--blender-python", default=sys.executable, help="a Python with bpy")
    ap.add_argument("--doc", type=Path, default=Path("docs/cycles-comparison.md"))
    a = ap.parse_args(argv)
    layer, camera = peer_layer(a.usd.resolve())
    work = layer.parent
    mipray_runs: list[Run] = []
    cycles_runs: list[Run] = []
    info: dict[str, Any] = {}
    load = os.getloadavg()
    for i in range(a.runs):
        mipray_runs.append(
            run_mipray(
                a.record, layer, camera, work / "peer.mipray.png", a.width, a.samples, a.threads
            )
        )
        run, info = run_cycles(
            a.blender_python,
            layer,
            camera,
            work / "peer.cycles.png",
            a.width,
            a.samples,
            a.threads,
            a.dicing_rate,
        )
        cycles_runs.append(run)
        print(f"run {i + 1}: mipray {mipray_runs[-1]}, cycles {cycles_runs[-1]}", file=sys.stderr)

    def med(runs: list[Run], f: str) -> float:
        return float(statistics.median(getattr(r, f) for r in runs))

    rows = [
        (f, med(mipray_runs, f), med(cycles_runs, f)) for f in ("render_s", "process_s", "cpu_s")
    ]
    names = {
        "render_s": "render (s)",
        "process_s": "whole process (s)",
        "cpu_s": "CPU of the process (s)",
    }
    version = subprocess.run([a.record, "--version"], capture_output=True, text=True).stdout.strip()
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    command = (
        f"python -m mipray.tools.cycles_peer {a.usd} --width {a.width} --samples {a.samples} "
        f"--threads {a.threads} --runs {a.runs}"
    )
    subdivided = f"{info.get('subdivided_objects', '?')} of {info.get('objects', '?')} objects"
    lines = [
        "# mipray against Cycles, end to end",
        "",
        f"Written by `{command}` (`make bench-cycles`), {when}; load average at start "
        f"{load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} on {os.cpu_count()} CPUs.",
        "",
        f"The same stage and camera (`{camera}` of `{layer.name}`), {a.width}×{a.width}, "
        f"{a.samples} samples per pixel, {a.threads} threads. mipray: `{version}`, default "
        "settings (direct light, the paper's multiresolution cache). Cycles "
        f"{info.get('version', '?')} through bpy: Blender's USD importer ({subdivided} with a "
        f"Subdivision Surface modifier, set to adaptive subdivision at {a.dicing_rate} px), CPU, "
        "no adaptive sampling or denoising, at most 1 bounce. Medians of the runs, each "
        "renderer in a new process, runs interleaved. Light units differ between the two "
        "(Blender's importer scales them), so the images differ in brightness, not in what is "
        "traced.",
        "",
        "| time | mipray | Cycles | mipray / Cycles |",
        "|---|---:|---:|---:|",
    ]
    for f, m, c in rows:
        lines.append(f"| {names[f]} | {m:.2f} | {c:.2f} | {m / c:.2f}× |")
    lines += [
        "",
        "*render*: mipray's `render.wall_s` (on-demand tessellation included); Cycles' "
        "`bpy.ops.render.render` (scene sync, subdivision, BVH build and sampling). *whole "
        "process*: from launch to exit, reading the stage included (and starting Blender).",
        "",
        "Each run's figures:",
        "",
    ]
    for i, (mr, cr) in enumerate(zip(mipray_runs, cycles_runs, strict=True)):
        lines.append(
            f"- run {i + 1}: mipray {mr.render_s:.2f} / {mr.process_s:.2f} / {mr.cpu_s:.2f} s; "
            f"Cycles {cr.render_s:.2f} / {cr.process_s:.2f} / {cr.cpu_s:.2f} s "
            "(render / process / CPU)"
        )
    # The last run's images, halved, beside the doc.
    images = a.doc.parent / "images"
    images.mkdir(parents=True, exist_ok=True)
    for name in ("mipray", "cycles"):
        src, dst = work / f"peer.{name}.png", images / f"cycles-peer-{name}.png"
        half = f"{a.width // 2}x{a.width // 2}"
        subprocess.run(
            ["oiiotool", str(src), "--ch", "R,G,B", "--resize", half, "-o", str(dst)], check=False
        )
    lines += [
        "",
        "The last run's images (halved; mipray left, Cycles right):",
        "",
        "![mipray](images/cycles-peer-mipray.png) ![Cycles](images/cycles-peer-cycles.png)",
    ]
    a.doc.parent.mkdir(parents=True, exist_ok=True)
    a.doc.write_text("\n".join(lines) + "\n")
    print(a.doc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
