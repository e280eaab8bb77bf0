"""``mipray-sweep``: what accuracy costs in time, measured on your own scene.

    mipray-sweep scene.usda --knob tessFactor=0.25,0.5,1,2,4
    mipray-sweep scene.usda --knob tessFactor=1,4 --knob samples=4,16 --runs 3 --out out/s
    mipray-sweep scene.usda --knob tessFactor=1,2,4 --knob tessFactorIncoherent=1,0.5,0.25 --zip

Renders the scene once per setting — the cartesian product of the knobs'
values, or with ``--zip`` the knobs stepped together — and compares each
image with a reference: ``auto`` renders the most accurate settings (tess
factor 0.25, so subpatches split wherever a ray needs it; the unbounded
geometry cache; many samples) and writes it to ``PREFIX.reference.exr`` for
reuse; or give an EXR of the same size. It writes ``PREFIX.json`` and
``PREFIX.md`` (one row per setting: median wall and CPU time, peak memory,
recomputed vertices, color RMSE, max and mean error against the reference,
and the ``tessError`` AOV's geometric error in world units and in beam
widths; see :data:`mipray.tools.sweep_report.ROW_FIELDS`) after every row, so an
interrupted sweep keeps the rows it finished, and ``PREFIX.png``, error
against time with the Pareto front marked (needs matplotlib).

``--set KEY=VALUE`` fixes a setting for every row; ``--reference-set`` changes
one of the ``auto`` reference's (``samples=4 seed=0`` gives it the rows' own
noise, so the error left is the knobs' bias). Each setting renders in its own
process (``python -m mipray.tools.sweep --one REQUEST.json``), so its peak memory is
its own, and every run of it with a new render delegate, so each starts cold;
a row rendered by another build of the extension than the rows before it (a
rebuild during the sweep) stops the sweep. From Python::

    from mipray.tools.sweep import sweep
    rows = sweep("scene.usda", {"tessFactor": [0.5, 1, 2]}, width=160, out="out/tess")
    rows[0]["wall_s"], rows[0]["color_rmse"]

Errors are one line, ``mipray-sweep: ...``; exit status 0 when every row was
rendered, 1 on an error (the table keeps the rows finished before it), 130
when interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import signal
import statistics
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NoReturn, TextIO

import numpy as np
from numpy.typing import NDArray

from ..errors import MiprayError
from .sweep_knobs import (
    DEFAULT_REFERENCE_SAMPLES,
    KNOBS,
    OPTIONAL_KNOBS,
    REFERENCE_TESS_FACTOR,
    RESERVED_KNOBS,
    Knob,
    SweepError,
    auto_reference_settings,
    available_knobs,
    check_base,
    check_knobs,
    parse_knob,
    plan_rows,
    unavailable_knobs,
)
from .sweep_report import (
    SCHEMA,
    format_markdown,
    image_errors,
    setting_label,
    tess_error_figures,
    write_plot,
    write_tables,
)
from .sweep_worker import (
    Rendered,
    RowRequest,
    Runner,
    check_size,
    extension_identity,
    image_size,
    read_reference,
    render_in_process,
    render_in_subprocess,
    run_worker,
)

__all__ = [
    "DEFAULT_REFERENCE_SAMPLES",
    "DEFAULT_WIDTH",
    "KNOBS",
    "OPTIONAL_KNOBS",
    "PROG",
    "REFERENCE_TESS_FACTOR",
    "RESERVED_KNOBS",
    "Knob",
    "Rendered",
    "RowRequest",
    "Runner",
    "SweepError",
    "auto_reference_settings",
    "available_knobs",
    "extension_identity",
    "image_size",
    "main",
    "parse_knob",
    "plan_rows",
    "read_reference",
    "render_in_process",
    "render_in_subprocess",
    "sweep",
    "unavailable_knobs",
]

PROG = "mipray-sweep"
#: Image width of a sweep when none is given: small, since a sweep renders many times.
DEFAULT_WIDTH = 160
_MATPLOTLIB_HINT = "pip install 'matplotlib>=3.7'"

_log = logging.getLogger("mipray")


@dataclass
class _Status:
    """Status lines for a progress callback: which row, which run, how far."""

    emit: Callable[[str], None] | None
    prefix: str = ""
    runs: int = 1
    lines: list[str] = field(default_factory=list)

    def start(self, prefix: str) -> None:
        self.prefix = prefix
        if self.emit is not None:
            self.emit(f"{prefix} ...")

    def percent(self, run: int, done: int, total: int) -> None:
        if self.emit is not None and total > 0:
            runs = f" run {run}/{self.runs}" if self.runs > 1 else ""
            self.emit(f"{self.prefix}{runs} {100 * done // total:3d}%")


def _check_same_build(
    table: dict[str, Any], rendered: Rendered, index: int, setting: Mapping[str, object]
) -> None:
    """Refuse a row rendered by another build of the extension than the rows before it."""
    first = table.setdefault("extension", rendered.extension)
    if first and rendered.extension and rendered.extension != first:
        raise SweepError(
            f"row {index} ({setting_label(setting)}): mipray._mipray changed during the sweep "
            "(rebuilt?), so its rows are not comparable; run the sweep again"
        )


def _hemisphere_rays(stats: Mapping[str, Any]) -> int | None:
    """render.rays.ao + render.rays.diffuse: what irradiance caching saves."""
    rays = (stats.get("render") or {}).get("rays") or {}
    if "ao" not in rays and "diffuse" not in rays:
        return None
    return int(rays.get("ao", 0)) + int(rays.get("diffuse", 0))


def _row(
    setting: dict[str, object],
    settings: dict[str, object],
    rendered: Rendered,
    reference: NDArray[np.float32],
) -> dict[str, Any]:
    stats = rendered.stats
    cache = stats.get("geometry_cache", {})
    row: dict[str, Any] = {
        "label": setting_label(setting),
        "setting": setting,
        "settings": settings,
        "wall_s": statistics.median(rendered.wall_s_runs),
        "wall_s_runs": rendered.wall_s_runs,
        "cpu_s": statistics.median(rendered.cpu_s_runs) if rendered.cpu_s_runs else None,
        "cpu_s_runs": rendered.cpu_s_runs,
        "peak_rss_bytes": stats.get("memory", {}).get("peak_rss_bytes"),
        "recomputed_vertices": cache.get("recomputed_vertices"),
        "ray_subpatch_tests": stats.get("render", {}).get("ray_subpatch_tests"),
        "hemisphere_rays": _hemisphere_rays(stats),
        "texture_tiles_read": (stats.get("texture_cache") or {}).get("tiles_read"),
    }
    row.update(image_errors(rendered.aovs["color"], reference))
    if "tessError" in rendered.aovs:
        row.update(tess_error_figures(rendered.aovs["tessError"], rendered.aovs.get("alpha")))
    return row


def sweep(
    scene: str | os.PathLike[str],
    knobs: Mapping[str, Sequence[object]] | Sequence[str],
    *,
    reference: str | os.PathLike[str] = "auto",
    runs: int = 1,
    out: str | os.PathLike[str] | None = None,
    width: int = DEFAULT_WIDTH,
    camera: str | None = None,
    settings: Mapping[str, object] | Sequence[str] | None = None,
    zip_knobs: bool = False,
    reference_samples: int = DEFAULT_REFERENCE_SAMPLES,
    reference_settings: Mapping[str, object] | Sequence[str] | None = None,
    plot: bool = True,
    progress: Callable[[str], None] | None = None,
    runner: Runner | None = None,
) -> list[dict[str, Any]]:
    """Render ``scene`` at every setting of ``knobs`` and measure error against time.

    Args:
        scene: the USD file.
        knobs: knob name → values (``{"tessFactor": [0.5, 1, 2]}``), or
            ``"NAME=V1,V2"`` strings as on the command line. Valid knobs and
            their ranges: :func:`available_knobs`.
        reference: ``"auto"`` (render :func:`auto_reference_settings`; kept in
            ``OUT.reference.exr`` when ``out`` is given) or an image file of
            the sweep's size.
        runs: renders per setting; ``wall_s`` is their median.
        out: prefix of the files written: ``OUT.json``, ``OUT.md`` (after
            every row), ``OUT.png`` (if ``plot`` and matplotlib is installed).
            None writes nothing.
        width: image width; the height follows the camera.
        camera: camera prim path or name (default as ``mipray-record``'s).
        settings: settings fixed for every row and the reference (e.g.
            ``{"aoSamples": 8}``).
        zip_knobs: step the knobs together instead of over their product.
        reference_samples: camera samples of the ``auto`` reference (at least).
        reference_settings: settings of the ``auto`` reference to override
            (``{"samples": 4, "seed": 0}``, or ``"KEY=VALUE"`` strings). With
            the rows' own samples and seed the reference has the same noise
            as the rows, so their difference is the bias of the knobs alone.
        plot: write ``OUT.png``.
        progress: called with a one-line status as rows render.
        runner: renders one configuration (default: a new process each).

    Returns:
        The rows, one dict per setting (fields in
        :data:`mipray.tools.sweep_report.ROW_FIELDS`).

    Raises:
        SweepError: bad knobs, values, settings or reference; or a row that
            failed — the files then hold the rows finished before it.
        KeyboardInterrupt: interrupted; the files hold the finished rows.
        StageError, PrimError: the scene or camera is unusable.

    """
    scene_path = os.fspath(scene)
    if not os.path.exists(scene_path):
        raise SweepError(f"{scene_path}: no such file")
    if runs < 1:
        raise SweepError(f"--runs must be at least 1, got {runs}")
    if width < 1:
        raise SweepError(f"--width must be at least 1, got {width}")
    checked = check_knobs(knobs)
    base = check_base(settings)
    clash = sorted(set(base) & set(checked))
    if clash:
        raise SweepError(f"{clash[0]} is both swept (--knob) and fixed (--set); give it once")
    ref_overrides = check_base(reference_settings)
    planned = plan_rows(checked, zip_knobs)
    run = runner or render_in_subprocess
    prefix = os.fspath(out) if out is not None else None
    camera_path, width, height = image_size(scene_path, width, camera)
    ref_source = os.fspath(reference)
    ref_image: NDArray[np.float32] | None = None
    if ref_source != "auto":
        if ref_overrides:
            raise SweepError("--reference-set applies to --reference auto only")
        ref_image = read_reference(ref_source)
        check_size(ref_image, ref_source, width, height)

    table: dict[str, Any] = {
        "schema": SCHEMA,
        "scene": scene_path,
        "camera": camera_path,
        "image_size": [width, height],
        "runs": runs,
        "knobs": checked,
        "zip": zip_knobs,
        "base_settings": base,
        "reference": {"source": ref_source},
        "planned_rows": len(planned),
        "rows": [],
        "complete": False,
        "stopped": None,
    }
    rows: list[dict[str, Any]] = table["rows"]
    status = _Status(progress, runs=runs)
    percent = status.percent if progress is not None else None
    try:
        if ref_image is None:
            ref_settings = {
                **auto_reference_settings(checked, base, reference_samples),
                **ref_overrides,
            }
            status.runs = 1
            status.start(f"reference ({setting_label(ref_settings)})")
            try:
                rendered = run(RowRequest(scene_path, ref_settings, width, camera_path, 1), percent)
            except SweepError as exc:
                raise SweepError(
                    f"reference ({setting_label(ref_settings)}) failed: {exc}"
                ) from exc
            ref_image = rendered.aovs["color"]
            table["reference"].update(
                settings=ref_settings,
                wall_s=rendered.wall_s_runs[0],
                peak_rss_bytes=rendered.stats.get("memory", {}).get("peak_rss_bytes"),
            )
            table["reference"]["rays"] = rendered.stats.get("render", {}).get("rays", {})
            table["scene_stats"] = rendered.stats.get("scene", {})
            table["extension"] = rendered.extension
            if prefix is not None:
                from ..image import write_aovs

                ref_path = f"{prefix}.reference.exr"
                write_aovs(ref_path, {"color": ref_image}, ["color"], formats={"color": "float"})
                table["reference"]["written"] = ref_path
            status.runs = runs
        check_size(ref_image, ref_source, width, height)
        if prefix is not None:
            write_tables(table, prefix)
        for index, setting in enumerate(planned, start=1):
            row_settings = {**base, **setting}
            status.start(f"[{index}/{len(planned)}] {setting_label(setting)}")
            try:
                rendered = run(
                    RowRequest(scene_path, row_settings, width, camera_path, runs), percent
                )
            except SweepError as exc:
                raise SweepError(f"row {index} ({setting_label(setting)}) failed: {exc}") from exc
            _check_same_build(table, rendered, index, setting)
            rows.append(_row(setting, row_settings, rendered, ref_image))
            if prefix is not None:
                write_tables(table, prefix)
        table["complete"] = True
    except KeyboardInterrupt:
        table["stopped"] = f"interrupted after {len(rows)} of {len(planned)} rows"
        raise
    except Exception as exc:
        table["stopped"] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise
    finally:
        if prefix is not None:
            write_tables(table, prefix)
            if plot and rows:
                _try_plot(table, f"{prefix}.png")
    return rows


def _try_plot(table: Mapping[str, Any], path: str) -> bool:
    try:
        write_plot(table, path)
    except ImportError:
        _log.warning(
            "mipray: matplotlib is not installed, so %s was not drawn (the tables are "
            "written); %s, or pass --no-plot",
            path,
            _MATPLOTLIB_HINT,
        )
        return False
    return True


# --- the command ---------------------------------------------------------------------


class _UsageError(Exception):
    """A bad command line; reported in one line, exit status 1."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{message} (see --help)")


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser of ``mipray-sweep`` (documented by ``--help``)."""
    knob_lines = "\n".join(
        f"  {k.name:<22} {k.describe()}: {k.help}" for k in available_knobs().values()
    )
    refused = ", ".join(unavailable_knobs())
    missing = f"  not yet available: {refused}\n" if refused else ""
    parser = _Parser(
        prog=PROG,
        description="Measure what accuracy costs in time: render a USD scene at each setting\n"
        "of some knobs and compare each image with a reference.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            f"knobs:\n{knob_lines}\n" + missing + "\n"
            "examples:\n"
            "  mipray-sweep scene.usda --knob tessFactor=0.25,0.5,1,2,4\n"
            "  mipray-sweep scene.usda --knob tessFactor=1,4 --knob samples=4,16 --runs 3\n"
            "  mipray-sweep scene.usda --set aoSamples=8 --knob tessFactorIncoherent=1,4,16\n"
            "  mipray-sweep scene.usda --zip --knob tessFactor=1,2,4 "
            "--knob tessFactorIncoherent=1,0.5,0.25\n\n"
            "Writes PREFIX.json and PREFIX.md after every row (an interrupted sweep keeps\n"
            "its rows), PREFIX.png (matplotlib) and, with --reference auto,\n"
            "PREFIX.reference.exr; prints the table and the paths. Exit status 0 when\n"
            "every row rendered, 1 on an error, 130 when interrupted."
        ),
    )
    parser.add_argument("usdFilePath", nargs="?", help="USD file to render")
    parser.add_argument(
        "--knob",
        "-k",
        action="append",
        default=[],
        metavar="NAME=V1,V2,...",
        help="a setting to vary and its values; repeat for more knobs (their product is swept)",
    )
    parser.add_argument(
        "--zip",
        action="store_true",
        help="step the knobs together (i-th value of each) instead of over their product",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a render setting fixed for every row and the reference, e.g. aoSamples=8",
    )
    parser.add_argument(
        "--reference",
        default="auto",
        metavar="auto|FILE.exr",
        help="the image to compare with: auto renders the most accurate settings "
        "(default: %(default)s)",
    )
    parser.add_argument(
        "--reference-samples",
        type=int,
        default=DEFAULT_REFERENCE_SAMPLES,
        metavar="N",
        help="camera samples of the auto reference (default: %(default)s)",
    )
    parser.add_argument(
        "--reference-set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a setting of the auto reference, e.g. samples=4 and seed=0 to give it "
        "the rows' noise, so the error is the knobs' bias alone",
    )
    parser.add_argument(
        "--runs",
        type=int,
        default=1,
        metavar="N",
        help="renders per setting; the time is their median (default: %(default)s)",
    )
    parser.add_argument(
        "--out",
        metavar="PREFIX",
        help="prefix of the files written (default: the scene's name + '.sweep', here)",
    )
    parser.add_argument(
        "--width",
        "-w",
        type=int,
        default=DEFAULT_WIDTH,
        metavar="PIXELS",
        help="image width; the height follows the camera (default: %(default)s)",
    )
    parser.add_argument(
        "--camera",
        "-cam",
        metavar="CAMERA",
        help="camera prim path or name (default: main_cam, else the first camera)",
    )
    parser.add_argument("--no-plot", action="store_true", help="do not draw PREFIX.png")
    parser.add_argument(
        "--list-knobs", action="store_true", help="print the knobs and their ranges, and exit"
    )
    parser.add_argument("--one", metavar="REQUEST", help=argparse.SUPPRESS)
    return parser


class _Progress:
    """One status line on stderr, redrawn in place; only when stderr is a terminal."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.enabled = stream.isatty()

    def __call__(self, message: str) -> None:
        if self.enabled:
            self.stream.write(f"\r\033[K{PROG}: {message}")
            self.stream.flush()

    def clear(self) -> None:
        if self.enabled:
            self.stream.write("\r\033[K")
            self.stream.flush()


class _Formatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return f"{PROG}: {record.levelname.lower()}: {record.getMessage().removeprefix('mipray: ')}"


@contextlib.contextmanager
def _logging_to(stream: TextIO) -> Iterator[None]:
    handler = logging.StreamHandler(stream)
    handler.setFormatter(_Formatter())
    old = _log.level
    _log.addHandler(handler)
    _log.setLevel(logging.WARNING)
    try:
        yield
    finally:
        _log.removeHandler(handler)
        _log.setLevel(old)


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """Treat SIGTERM as Ctrl-C while a sweep runs: the worker is stopped, the rows kept."""

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, interrupt)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _one_line(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return text.removeprefix(f"{PROG}: ")


def _mtime(path: str) -> float | None:
    try:
        return os.stat(path).st_mtime_ns / 1e9
    except OSError:
        return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``mipray-sweep`` with ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    out, err = sys.stdout, sys.stderr
    try:
        args = build_parser().parse_args(argv)
    except _UsageError as exc:
        err.write(f"{PROG}: {exc}\n")
        return 1
    except SystemExit as exc:  # --help
        return int(exc.code or 0) if not isinstance(exc.code, str) else 1
    if args.one:
        try:
            return run_worker(args.one)
        except KeyboardInterrupt:
            err.write(f"{PROG}: interrupted\n")
            return 130
        except Exception as exc:  # one line for the parent to report
            err.write(f"{PROG}: {_one_line(exc)}\n")
            return 1
    if args.list_knobs:
        for knob in available_knobs().values():
            out.write(f"{knob.name:<22} {knob.describe():<34} {knob.help}\n")
        for name, what in unavailable_knobs().items():
            out.write(f"{name:<22} {'not yet available':<34} {what}\n")
        return 0
    if not args.usdFilePath:
        err.write(f"{PROG}: the following arguments are required: usdFilePath (see --help)\n")
        return 1
    prefix = args.out or os.path.splitext(os.path.basename(args.usdFilePath))[0] + ".sweep"
    before = _mtime(f"{prefix}.json")
    progress = _Progress(err)
    with _logging_to(err), _terminate_as_interrupt():
        try:
            if args.reference_samples < 1:
                raise SweepError(
                    f"--reference-samples must be at least 1, got {args.reference_samples}"
                )
            sweep(
                args.usdFilePath,
                args.knob,
                reference=args.reference,
                runs=args.runs,
                out=prefix,
                width=args.width,
                camera=args.camera,
                settings=args.set,
                zip_knobs=args.zip,
                reference_samples=args.reference_samples,
                reference_settings=args.reference_set,
                plot=not args.no_plot,
                progress=progress if progress.enabled else None,
            )
        except KeyboardInterrupt:
            progress.clear()
            err.write(f"{PROG}: interrupted; the finished rows are in {prefix}.json\n")
            return 130
        except MiprayError as exc:
            progress.clear()
            written = _mtime(f"{prefix}.json") not in (None, before)
            kept = f" (the rows finished are in {prefix}.json)" if written else ""
            err.write(f"{PROG}: {_one_line(exc)}{kept}\n")
            return 1
        progress.clear()
    with open(f"{prefix}.json", encoding="utf-8") as handle:
        out.write(format_markdown(json.load(handle)))
    for suffix in (".json", ".md", ".png", ".reference.exr"):
        if os.path.exists(prefix + suffix):
            out.write(prefix + suffix + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
