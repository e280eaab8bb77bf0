"""Rendering one setting of a sweep, in this process or in a new one.

:func:`render_in_subprocess` (the default runner of :func:`mipray.tools.sweep.sweep`)
starts ``python -m mipray.tools.sweep --one REQUEST.json`` so each setting's peak
memory is its own; that worker calls :func:`run_worker`, which renders with
:func:`render_in_process`. :func:`image_size` and :func:`read_reference` let a
sweep check a reference image before anything renders.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .sweep_knobs import SweepError

__all__ = [
    "AOVS",
    "Rendered",
    "RowRequest",
    "Runner",
    "check_size",
    "extension_identity",
    "image_size",
    "read_reference",
    "render_in_process",
    "render_in_subprocess",
    "run_worker",
]

PROG = "mipray-sweep"
#: The AOVs each row renders: color for the error, alpha and tessError for the geometry.
AOVS = ("color", "alpha", "tessError")


@dataclass(frozen=True)
class RowRequest:
    """One configuration to render: what the worker process is given."""

    scene: str
    settings: dict[str, object]
    width: int
    camera: str | None = None
    runs: int = 1
    aovs: tuple[str, ...] = AOVS


@dataclass
class Rendered:
    """What rendering one configuration gave back."""

    #: AOV name → H×W×C float32 (of the last run; every run gives the same pixels).
    aovs: dict[str, NDArray[np.float32]]
    #: ``render.wall_s`` of each run.
    wall_s_runs: list[float]
    #: The last run's stats (``memory.peak_rss_bytes`` is the process's peak over all runs).
    stats: dict[str, Any]
    #: The camera rendered through.
    camera: str = ""
    #: Which build of ``mipray._mipray`` rendered it (:func:`extension_identity`).
    extension: str = ""
    #: CPU seconds of this process (every thread) during each run's render call.
    cpu_s_runs: list[float] = field(default_factory=list)


#: Renders one configuration; called with a percent callback ``(run, done, total)`` or None.
Runner = Callable[[RowRequest, Callable[[int, int, int], None] | None], Rendered]


def extension_identity() -> str:
    """Path, size and modification time of the compiled ``mipray._mipray`` in use.

    A sweep checks that every row was rendered by the same build: on a machine
    where the extension is rebuilt while a sweep runs, rows from two builds
    would not be comparable.
    """
    try:
        from .. import _mipray
    except ImportError:
        return ""
    path = getattr(_mipray, "__file__", None) or ""
    try:
        st = os.stat(path)
    except OSError:
        return path
    return f"{path}:{st.st_size}:{st.st_mtime_ns}"


def render_in_process(
    request: RowRequest, progress: Callable[[int, int, int], None] | None = None
) -> Rendered:
    """Render ``request.runs`` times in this process (what ``--one`` does).

    Each run gets a new render delegate, so each starts cold: a delegate kept
    between renders carries cache statistics over (``recomputed_vertices``
    grows run after run), and a sweep wants every run to measure the same.
    """
    from ..session import RenderSession, open_stage

    stage = open_stage(request.scene)
    walls: list[float] = []
    cpus: list[float] = []
    result = None
    for run in range(1, request.runs + 1):

        def step(done: int, total: int, run: int = run) -> None:
            if progress is not None:
                progress(run, done, total)

        with RenderSession(stage) as session:
            session.scene.sync()  # reading the stage is not the render's cost
            cpu0 = time.process_time()
            result = session.render(
                request.camera,
                request.width,
                list(request.aovs),
                request.settings,
                progress=step if progress is not None else None,
            )
            cpus.append(time.process_time() - cpu0)
        walls.append(float(result.stats.get("render", {}).get("wall_s", math.nan)))
    assert result is not None  # runs >= 1
    return Rendered(
        dict(result.aovs), walls, result.stats, result.camera, extension_identity(), cpus
    )


def render_in_subprocess(
    request: RowRequest, progress: Callable[[int, int, int], None] | None = None
) -> Rendered:
    """Render ``request`` in a new process (``python -m mipray.tools.sweep --one``).

    Its ``memory.peak_rss_bytes`` is then this configuration's own. A
    ``KeyboardInterrupt`` here stops the worker and is raised again.

    Raises:
        SweepError: the worker failed; the message is its error line.

    """
    with tempfile.TemporaryDirectory(prefix="mipray-sweep-") as tmp:
        req_path = os.path.join(tmp, "request.json")
        with open(req_path, "w", encoding="utf-8") as handle:
            json.dump(
                {
                    **request.__dict__,
                    "aovs": list(request.aovs),
                    "out": tmp,
                    "progress": progress is not None,
                },
                handle,
            )
        package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, env.get("PYTHONPATH")]))
        with subprocess.Popen(
            [sys.executable, "-m", "mipray.tools.sweep", "--one", req_path],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
            env=env,
        ) as proc:
            try:
                assert proc.stdout is not None and proc.stderr is not None
                for line in proc.stdout:
                    parts = line.split()
                    if progress is not None and len(parts) == 4 and parts[0] == "progress":
                        progress(int(parts[1]), int(parts[2]), int(parts[3]))
                err = proc.stderr.read()
                code = proc.wait()
            except BaseException:
                proc.kill()
                proc.wait()
                raise
        if code != 0:
            lines = [ln for ln in err.splitlines() if ln.strip()]
            reason = lines[-1].removeprefix(f"{PROG}: ") if lines else f"exit status {code}"
            if code < 0 or code == 130:
                reason = f"worker stopped by signal ({reason})"
            raise SweepError(reason)
        with np.load(os.path.join(tmp, "aovs.npz")) as data:
            aovs = {k: np.asarray(data[k], dtype=np.float32) for k in data.files}
        with open(os.path.join(tmp, "result.json"), encoding="utf-8") as handle:
            meta = json.load(handle)
    return Rendered(
        aovs,
        meta["wall_s_runs"],
        meta["stats"],
        meta["camera"],
        meta.get("extension", ""),
        meta.get("cpu_s_runs", []),
    )


def run_worker(request_path: str) -> int:
    """``--one REQUEST.json``: render one configuration; results into the request's dir."""
    with open(request_path, encoding="utf-8") as handle:
        req = json.load(handle)
    request = RowRequest(
        scene=req["scene"],
        settings=req["settings"],
        width=int(req["width"]),
        camera=req.get("camera"),
        runs=int(req.get("runs", 1)),
        aovs=tuple(req.get("aovs", AOVS)),
    )

    def report(run: int, done: int, total: int) -> None:
        sys.stdout.write(f"progress {run} {done} {total}\n")
        sys.stdout.flush()

    rendered = render_in_process(request, report if req.get("progress") else None)
    arrays: dict[str, Any] = dict(rendered.aovs)
    np.savez(os.path.join(req["out"], "aovs.npz"), **arrays)
    with open(os.path.join(req["out"], "result.json"), "w", encoding="utf-8") as handle:
        json.dump(
            {
                "wall_s_runs": rendered.wall_s_runs,
                "cpu_s_runs": rendered.cpu_s_runs,
                "stats": rendered.stats,
                "camera": rendered.camera,
                "extension": rendered.extension,
            },
            handle,
        )
    return 0


class _NullDelegate:
    """Accepts every render-delegate call and keeps nothing: for finding the image size."""

    def __getattr__(self, name: str) -> Callable[..., None]:
        return lambda *args, **kwargs: None


def image_size(scene: str, width: int, camera: str | None = None) -> tuple[str, int, int]:
    """``(camera path, width, height)`` a render of ``scene`` at ``width`` would have.

    Reads the stage only (no geometry is built), so a reference of the wrong
    size is refused before anything renders.

    Raises:
        StageError, PrimError: the stage or the camera is unusable.

    """
    from ..session import RenderSession, open_stage
    from ..usd.camera import image_height

    stage = open_stage(scene)
    with RenderSession(stage, delegate=_NullDelegate()) as session:
        session.scene.sync()
        path = session.scene.resolve_camera(camera)
        return path, width, image_height(width, session.scene.cameras[path])


def read_reference(path: str) -> NDArray[np.float32]:
    """The color (R, G, B) of a reference image, H×W×3 float32.

    Raises:
        SweepError: the file cannot be read or has no color channels.

    """
    from .. import _mipray

    if not os.path.exists(path):
        raise SweepError(f"reference {path}: no such file")
    try:
        pixels, channels = _mipray.read_image(path)
    except (OSError, ValueError, RuntimeError) as exc:
        raise SweepError(f"reference {path}: {str(exc).splitlines()[0]}") from exc
    names = [c.upper() for c in channels]
    if all(c in names for c in "RGB"):
        idx = [names.index(c) for c in "RGB"]
    elif pixels.shape[2] >= 3:
        idx = [0, 1, 2]
    else:
        raise SweepError(f"reference {path}: no R, G, B channels (has {', '.join(channels)})")
    return np.ascontiguousarray(pixels[..., idx], dtype=np.float32)


def check_size(reference: NDArray[np.float32], source: str, width: int, height: int) -> None:
    """Refuse a reference that is not ``width``×``height``; the message names both sizes.

    Raises:
        SweepError: the sizes differ.

    """
    h, w = reference.shape[:2]
    if (w, h) != (width, height):
        raise SweepError(
            f"reference {source} is {w}×{h} pixels but the sweep renders {width}×{height}; "
            f"render the reference at --width {width} or use --reference auto"
        )
