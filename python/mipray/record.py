"""``mipray-record``: render a USD file to images, with usdrecord's interface.

    mipray-record scene.usda out.exr
    mipray-record --frames 1:24 --imageWidth 640 --aovs color,depth shot.usda out.####.exr

Every option of OpenUSD's usdrecord is accepted, spelled and behaving the same
(positional ``usdFilePath outputImagePath``, ``--camera``, ``--frames`` with
``#`` placeholders, ``--imageWidth``, ``--complexity`` (a refinement level),
``--purposes``, ``--colorCorrectionMode``, ``--mask``, ``--sessionLayer``,
``--renderer`` (mipray only), ``--enableDomeLightVisibility``,
``--renderPassPrimPath``, ``--renderSettingsPrimPath``, ...), so its command
lines run unchanged; renderer options are mipray's own. A
UsdRender.Settings prim (the one named, else the stage's
``renderSettingsPrimPath``) supplies the resolution, camera, purposes and AOVs
that the command line does not give explicitly. With ``--progressive`` the
output image is rewritten (atomically) after each pass of 1, 2, 4, ... samples
per pixel. Output paths go to stdout, one per line; warnings
and one-line errors (``mipray-record: ...``) to stderr. Exit status: 0 when
every image was written (even if prims with bad data were skipped, each named);
2 when every image was written but a prim was dropped after an internal error
(a renderer bug, named on stderr and in the stats' ``prim_errors``); 1 on
failure.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import time as time_module
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NoReturn, TextIO

import numpy as np
from numpy.typing import NDArray
from pxr import Sdf, Usd, UsdRender

from . import distributed
from .errors import MiprayError, RenderSettingsError
from .frames import (
    FrameSpecError,
    format_frame_path,
    frame_placeholder,
    frames_precision,
    parse_frame_spec,
    write_frame,
)
from .image import COLOR_CORRECTION_MODES, check_output, eight_bit_aovs, is_eight_bit
from .session import DEFAULT_WIDTH, RenderSession, open_stage
from .settings import TABLE, parse
from .stats import format_stats_table
from .usd.render_settings import read_render_settings
from .usd.scene_delegate import PURPOSES
from .usd.unsupported import Unsupported, audit_render_settings, warn_unsupported

__all__ = [
    "COMPLEXITY_REFINEMENT_LEVEL",
    "COMPLEXITY_TESS_FACTOR",
    "RENDERER_NAMES",
    "build_parser",
    "main",
    "pass_samples",
    "render_settings",
]

PROG = "mipray-record"

#: usdrecord's ``--complexity`` levels are refinement levels (Storm refines a subdivision
#: surface 0, 1, 2 or 3 times): each level halves the edges of the surface drawn. mipray
#: always traces the limit surface and chooses a rate per ray, so a level halves the tess
#: factor instead (a subpatch edge this many ray beam widths long; smaller is finer):
#: ``tessFactor = 4 / 2**level``. ``high`` (level 2) is the paper's rate, 1.
COMPLEXITY_REFINEMENT_LEVEL = {"low": 0, "medium": 1, "high": 2, "veryhigh": 3}
COMPLEXITY_TESS_FACTOR = {
    name: 4.0 / 2.0**level for name, level in COMPLEXITY_REFINEMENT_LEVEL.items()
}
#: What ``-r/--renderer`` accepts: mipray's one renderer (usdrecord takes a Hydra renderer
#: plugin's display name; mipray's plugin id is the last).
RENDERER_NAMES = ("mipray", "Mipray", "HdMiprayRendererPlugin")
#: Flags that set a renderer setting: flag → setting key. Each flag's type, range,
#: choices and help come from the settings table (:mod:`mipray.settings`), so a flag
#: and ``--setting key=value`` accept and refuse the same values.
SETTING_FLAGS = {
    "--samples": "samples",
    "--tess-factor": "tessFactor",
    "--geometry-cache-mb": "geometryCacheMb",
    "--cache-mode": "cacheMode",
    "--integrator": "integrator",
    "--threads": "threads",
    "--seed": "seed",
}

_log = logging.getLogger("mipray")
#: usdrecord's OpenColorIO mode: mipray has no OpenColorIO; its default display is sRGB.
_OCIO = "openColorIO"


class _UsageError(Exception):
    """A bad command line; reported in one line, exit status 1."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{message} (see --help)")


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _setting_type(key: str) -> Callable[[str], object]:
    """An argparse ``type`` that checks a flag's value as setting ``key``'s."""

    def check(text: str) -> object:
        try:
            return parse(key, text)
        except RenderSettingsError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from exc

    check.__name__ = key
    return check


def _add_setting_flag(group: Any, flag: str, metavar: str, extra: str = "") -> None:
    """A flag for setting ``SETTING_FLAGS[flag]``: type, choices and help from its row."""
    key = SETTING_FLAGS[flag]
    row = TABLE.get(key)
    if row is None:  # no compiled module: the renderer checks the value when it renders
        group.add_argument(flag, metavar=metavar, help=f"the {key} setting")
        return
    default = extra or f"default: {row['default']}"
    group.add_argument(
        flag,
        type=None if row["choices"] else _setting_type(key),
        choices=row["choices"] or None,
        metavar=None if row["choices"] else metavar,
        help=f"{row['help']}; {row['range']} ({default}; the {key} setting)".replace("%", "%%"),
    )


_positive_int.__name__ = "integer >= 1"


def _renderer(text: str) -> str:
    """``-r/--renderer``: mipray's name; any other renderer is a usage error, not a guess."""
    if text not in RENDERER_NAMES:
        raise argparse.ArgumentTypeError(
            f"'{text}' is not a renderer mipray-record has; it renders with mipray only "
            f"(-r {RENDERER_NAMES[0]}, or leave -r out)"
        )
    return text


_renderer.__name__ = "renderer"


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser of ``mipray-record`` (documented by ``--help``)."""
    parser = _Parser(
        prog=PROG,
        description=(
            "Render a USD file to images with mipray, a ray tracer with\n"
            "multiresolution geometry caching. Options follow usdrecord's where they apply."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  mipray-record scene.usda out.exr\n"
            "  mipray-record --camera /World/cam -w 640 --aovs color,depth scene.usda out.exr\n"
            "  mipray-record --frames 1:24 scene.usda out.####.exr\n"
            "  mipray-record --stats - --cache-mode unbounded scene.usda out.png\n"
            "  mipray-record --progressive --samples 64 scene.usda out.exr  # refines in place\n"
            "\n"
            "Prints each output image path on stdout. Exit status 0 when every image\n"
            "was written, even if some prims were skipped (each is reported on\n"
            "stderr); 1 on failure."
        ),
    )
    parser.add_argument("usdFilePath", help="USD file to render")
    parser.add_argument(
        "outputImagePath",
        help=(
            "output image; the extension chooses the type (.exr keeps every AOV "
            "linear; .png/.jpg hold the color AOV in 8 bits; .tif float). With "
            "--frames it needs one frame placeholder such as out.####.exr or "
            "out.###.##.exr (the number of # is the zero-padded width)"
        ),
    )
    usd = parser.add_argument_group("usdrecord options")
    usd.add_argument(
        "--camera",
        "-cam",
        metavar="CAMERA",
        help=(
            "camera prim path, or the name of a camera prim (default: the camera "
            "named main_cam, else the first camera on the stage, else one framing "
            "the stage's bounds from the front)"
        ),
    )
    time = usd.add_mutually_exclusive_group()
    time.add_argument(
        "--frames",
        "-f",
        metavar="FRAMESPEC[,FRAMESPEC...]",
        help=(
            "time codes to render: F, F:L or F:LxS (start, end, stride), several "
            "joined by commas, e.g. 101:109x2,120; one image per time code "
            "(default: the stage's startTimeCode)"
        ),
    )
    time.add_argument(
        "--defaultTime",
        "-d",
        action="store_true",
        help="render at the Default time code instead of the stage's startTimeCode",
    )
    usd.add_argument(
        "--imageWidth",
        "-w",
        type=_positive_int,
        metavar="PIXELS",
        help=(
            "image width; the height follows the render settings' aspect ratio, else "
            "the camera's aperture's, truncated as usdrecord does (default: "
            f"{DEFAULT_WIDTH}, or the render settings' resolution)"
        ),
    )
    usd.add_argument(
        "--complexity",
        "-c",
        choices=tuple(COMPLEXITY_TESS_FACTOR),
        default="high",
        help=(
            "refinement level, as usdrecord's (low 0, medium 1, high 2, veryhigh 3); each "
            "level halves the tess factor: low 4, medium 2, high 1, veryhigh 0.5 (default: "
            "%(default)s, the paper's rate; usdrecord's is low; --tess-factor overrides it)"
        ),
    )
    usd.add_argument(
        "--renderer",
        "-r",
        type=_renderer,
        metavar="RENDERER",
        help=f"the Hydra renderer: only {RENDERER_NAMES[0]} (for usdrecord's command lines)",
    )
    usd.add_argument(
        "--enableDomeLightVisibility",
        action="store_true",
        help=(
            "show dome lights as the background; without it a dome lights the scene and "
            "shows in reflections, and the background is transparent, as usdrecord's "
            "(the domeLightCameraVisibility setting)"
        ),
    )
    usd.add_argument(
        "--purposes",
        metavar="PURPOSE[,PURPOSE...]",
        help=(
            "purposes to render besides 'default' (always rendered): render, proxy, "
            "guide (default: the render settings' includedPurposes, else render; "
            "usdrecord's is proxy)"
        ),
    )
    usd.add_argument(
        "--colorCorrectionMode",
        "-color",
        choices=(*COLOR_CORRECTION_MODES, _OCIO),
        default="sRGB",
        help=(
            "sRGB encodes 8-bit outputs (PNG, JPEG) with the sRGB curve; EXR and "
            f"TIFF stay linear either way; {_OCIO} is taken as sRGB, with a warning "
            "(default: %(default)s)"
        ),
    )
    usd.add_argument(
        "--renderPassPrimPath",
        "-rp",
        metavar="PRIMPATH",
        help=(
            "UsdRender.Pass prim whose renderSource names the render settings to use, as "
            "--renderSettingsPrimPath (not both)"
        ),
    )
    usd.add_argument(
        "--renderSettingsPrimPath",
        "-rs",
        metavar="PRIMPATH",
        help=(
            "UsdRender.Settings prim for the resolution, camera, purposes and AOVs "
            "(its products' orderedVars); flags given explicitly win (default: the "
            "stage's renderSettingsPrimPath metadata, if any)"
        ),
    )
    usd.add_argument(
        "--mask",
        metavar="PRIMPATH[,PRIMPATH...]",
        help="limit the stage to these prims, their ancestors and descendants",
    )
    usd.add_argument(
        "--sessionLayer",
        metavar="SESSIONLAYER",
        help="open the stage with this layer as its session layer",
    )
    usd.add_argument(
        "--disableCameraLight",
        action="store_true",
        help="do not light a stage that has no lights from the camera",
    )
    usd.add_argument(
        "--disableGpu",
        action="store_true",
        help="accepted for usdrecord compatibility; mipray never uses a GPU",
    )
    ren = parser.add_argument_group("mipray options")
    ren.add_argument(
        "--aovs",
        metavar="AOV[,AOV...]",
        help=(
            "AOVs to render and write: color, depth, normal, or another the renderer "
            "offers (default: the render settings' RenderVars, else color)"
        ),
    )
    _add_setting_flag(ren, "--samples", "N")
    ren.add_argument(
        "--progressive",
        action="store_true",
        help=(
            "render in passes of 1, 2, 4, ... samples per pixel up to --samples and "
            "rewrite the output image after each pass, so a viewer watching the file "
            "sees it refine (each write goes to a hidden temporary file in the same "
            "directory, renamed over the output: never a half-written image). The "
            "final image is the same as without --progressive; the same as "
            "--setting progressive=1"
        ),
    )
    _add_setting_flag(ren, "--tess-factor", "F", "default: from --complexity")
    _add_setting_flag(ren, "--geometry-cache-mb", "MB")
    _add_setting_flag(ren, "--cache-mode", "MODE")
    _add_setting_flag(ren, "--integrator", "NAME")
    ren.add_argument(
        "--setting",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=(
            "any renderer setting, e.g. aoSamples=16 or irradianceCache=1 (repeatable; "
            "an unknown key is an error listing the valid ones); wins over the flags above"
        ),
    )
    _add_setting_flag(ren, "--threads", "N")
    _add_setting_flag(ren, "--seed", "N")
    ren.add_argument(
        "--stats",
        metavar="FILE",
        help=(
            "write render statistics: JSON to FILE (with --frames, FILE needs a "
            "# placeholder), or a table to stdout with -"
        ),
    )
    ren.add_argument("--verbose", "-v", action="store_true", help="log every prim synced")
    ren.add_argument(
        "--list-settings",
        action=_ListSettings,
        help="print every renderer setting --setting takes, with its default, and exit",
    )
    ren.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    distributed.add_arguments(parser)
    return parser


class _ListSettings(argparse.Action):
    """``--list-settings``: the renderer's settings table, then exit (like ``--version``)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *_args: Any) -> None:
        from . import _mipray

        rows = _mipray.render_settings()
        width = max(len(key) for key, _, _ in rows)
        shown = {key: default if default else "(unset)" for key, default, _ in rows}
        dwidth = max(len(d) for d in shown.values())
        takes = max(len(row["range"]) for row in TABLE.values())
        for key, _, description in rows:
            values = TABLE[key]["range"]
            line = f"{key:<{width}}  {shown[key]:<{dwidth}}  {values:<{takes}}  {description}"
            sys.stdout.write(line + "\n")
        parser.exit(0)


def _version() -> str:
    from . import __version__

    return __version__


def _split(text: str) -> list[str]:
    return [t for t in text.replace(",", " ").split() if t]


def render_settings(args: argparse.Namespace) -> dict[str, object]:
    """The renderer settings a parsed command line asks for."""
    settings: dict[str, object] = {
        "tessFactor": args.tess_factor
        if args.tess_factor is not None
        else COMPLEXITY_TESS_FACTOR[args.complexity]
    }
    for key, value in (
        ("samples", args.samples),
        ("seed", args.seed),
        ("threads", args.threads),
        ("geometryCacheMb", args.geometry_cache_mb),
        ("cacheMode", args.cache_mode),
        ("integrator", args.integrator),
        ("progressive", 1 if args.progressive else None),
        # usdrecord hides domes from the camera unless asked; so does mipray-record.
        ("domeLightCameraVisibility", int(args.enableDomeLightVisibility)),
    ):
        if value is not None:
            settings[key] = value
    for item in args.setting:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise RenderSettingsError(f"--setting {item!r} is not KEY=VALUE")
        settings[key.strip()] = parse(key.strip(), value.strip())
    return settings


class _Formatter(logging.Formatter):
    """``mipray-record: warning: ...`` without the library's own ``mipray:`` prefix."""

    def format(self, record: logging.LogRecord) -> str:
        message = record.getMessage()
        message = message.removeprefix("mipray: ")
        return f"{PROG}: {record.levelname.lower()}: {message}"


def _install_logging(verbose: bool, stream: TextIO) -> tuple[logging.Handler, int]:
    """Send the library's log to ``stream``; return the handler and the old level."""
    handler = logging.StreamHandler(stream)
    handler.setFormatter(_Formatter())
    old_level = _log.level
    _log.addHandler(handler)
    _log.setLevel(logging.DEBUG if verbose else logging.WARNING)
    return handler, old_level


def _validate(args: argparse.Namespace) -> list[Any]:
    """Check the command line against itself; return the frames to render.

    Returns a list of time-code values, or ``[None]`` when the stage's start
    time code is to be used (known only once the stage is open).
    """
    if args.renderPassPrimPath and args.renderSettingsPrimPath:
        raise _UsageError("give --renderSettingsPrimPath or --renderPassPrimPath, not both")
    args.aov_list = None if args.aovs is None else list(dict.fromkeys(_split(args.aovs)))
    if args.aov_list is not None and not args.aov_list:
        raise _UsageError("--aovs needs at least one AOV, e.g. color")
    args.purpose_list = None if args.purposes is None else _split(args.purposes)
    unknown = [p for p in args.purpose_list or () if p not in PURPOSES]
    if unknown:
        raise _UsageError(
            f"unknown purpose '{unknown[0]}' in --purposes; use {', '.join(PURPOSES)}"
        )
    if args.aov_list is not None and is_eight_bit(args.outputImagePath):
        if "color" not in args.aov_list:
            raise _UsageError(
                f"{args.outputImagePath}: an 8-bit image needs the color AOV in --aovs"
            )
    try:
        placeholder = frame_placeholder(args.outputImagePath)
        stats_placeholder = frame_placeholder(args.stats) if args.stats else None
        frames: list[Any] = parse_frame_spec(args.frames) if args.frames else []
    except FrameSpecError as exc:
        raise _UsageError(str(exc)) from exc
    if not args.frames:
        if placeholder or stats_placeholder:
            raise _UsageError(
                f"'{args.outputImagePath if placeholder else args.stats}' has a frame "
                "placeholder; give --frames to render a frame range"
            )
        return [Usd.TimeCode.Default()] if args.defaultTime else [None]
    if len(frames) > 1 and not placeholder:
        raise _UsageError(
            f"outputImagePath '{args.outputImagePath}' needs one frame placeholder such as "
            "out.####.exr to render several frames"
        )
    precision = frames_precision(frames)
    for path, mark in ((args.outputImagePath, placeholder), (args.stats, stats_placeholder)):
        if mark is not None:
            written = len(mark.split(".")[1]) if "." in mark else 0
            if written < precision:
                raise _UsageError(
                    f"the frames need {precision} decimal place(s) but '{path}' has "
                    f"placeholder '{mark}'; use e.g. ####.{'#' * precision}"
                )
    if args.stats and args.stats != "-" and len(frames) > 1 and not stats_placeholder:
        raise _UsageError(
            f"--stats '{args.stats}' needs a frame placeholder (e.g. stats.####.json) "
            "to hold several frames"
        )
    return frames


def pass_samples(samples: int) -> list[int]:
    """Samples per pixel at the end of each progressive pass: 1, 2, 4, ..., ``samples``."""
    ends = []
    done = 0
    while done < samples:
        done = min(max(1, 2 * done), samples)
        ends.append(done)
    return ends


class _Progress:
    """A progress bar on stderr, only when stderr is a terminal: frame, pass, bar, percent, ETA.

    The bar and ETA cover the whole frame (every pass); with passes, the pass
    being rendered is shown as ``pass k/P (S spp)``, S its samples per pixel.
    """

    WIDTH = 24

    def __init__(self, stream: TextIO, total: int) -> None:
        self.stream = stream
        self.total = total
        self.enabled = stream.isatty()
        self.prefix = ""
        self.passes: list[int] = []
        self.passes_done = 0
        self.last = (0, 0)
        self.started = time_module.monotonic()

    def start(self, index: int, time: Usd.TimeCode, passes: Sequence[int] = ()) -> None:
        self.passes = list(passes)
        self.passes_done = 0
        self.last = (0, 0)
        if self.enabled:
            when = "default time" if time.IsDefault() else f"time {time.GetValue():g}"
            self.prefix = f"{PROG}: frame {index}/{self.total} ({when})"
            self.started = time_module.monotonic()
            self.stream.write(f"\r\033[K{self.label()}...")
            self.stream.flush()

    def label(self) -> str:
        """The frame, and the pass now rendering when there are several."""
        if len(self.passes) < 2:
            return self.prefix
        k = min(self.passes_done, len(self.passes) - 1)
        return f"{self.prefix} pass {k + 1}/{len(self.passes)} ({self.passes[k]} spp)"

    def pass_finished(self, samples: int) -> None:
        """A pass ending at ``samples`` samples per pixel is done."""
        self.passes_done = sum(1 for s in self.passes if s <= samples)
        if self.last[1]:
            self.update(*self.last)

    def update(self, done: int, total: int) -> None:
        """The renderer's callback: ``done`` of ``total`` units of work."""
        self.last = (done, total)
        if self.enabled and total > 0:
            filled = self.WIDTH * done // total
            bar = "#" * filled + "." * (self.WIDTH - filled)
            elapsed = time_module.monotonic() - self.started
            eta = ""
            if 0 < done < total:
                left = int(elapsed * (total - done) / done)
                eta = f" ETA {left // 60}:{left % 60:02d}"
            self.stream.write(f"\r\033[K{self.label()} [{bar}] {100 * done // total:3d}%{eta}")
            self.stream.flush()

    def clear(self) -> None:
        if self.enabled:
            self.stream.write("\r\033[K")
            self.stream.flush()


def _write_stats(target: str, frame: float, stats: dict[str, Any], title: str, out: TextIO) -> None:
    if target == "-":
        out.write(format_stats_table(stats, title) + "\n")
        return
    path = format_frame_path(target, frame)
    directory = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(directory, exist_ok=True)
        with open(path, "w", encoding="utf-8") as handle:
            json.dump(stats, handle, indent=2, sort_keys=True)
            handle.write("\n")
    except OSError as exc:
        raise MiprayError(f"cannot write stats {path}: {exc.strerror}") from exc


@dataclass
class _Plan:
    """What to render, once flags and render settings are merged."""

    camera: str | None
    width: int
    height: int | None
    aovs: list[str]
    purposes: list[str]
    settings_path: str | None
    #: What the render settings author that mipray does not render (for the stats).
    unsupported: list[Unsupported]


def _render_pass_settings(stage: Usd.Stage, pass_path: str | None) -> str | None:
    """The RenderSettings path a UsdRender.Pass's ``renderSource`` names.

    As usdrecord: the first target, with a warning when there are several.

    Raises:
        RenderSettingsError: no such pass, or it names no render source.

    """
    if not pass_path:
        return None
    prim = stage.GetPrimAtPath(pass_path) if Sdf.Path.IsValidPathString(pass_path) else None
    if not prim or not prim.IsA(UsdRender.Pass):
        what = "no prim" if not prim else f"a {prim.GetTypeName() or 'typeless'} prim"
        raise RenderSettingsError(f"{pass_path}: {what}, not a RenderPass prim")
    targets = UsdRender.Pass(prim).GetRenderSourceRel().GetForwardedTargets()
    if not targets:
        raise RenderSettingsError(f"{pass_path}: the render pass has no renderSource")
    if len(targets) > 1:
        _log.warning(
            "mipray: %s: the render pass has %d render sources; using <%s>",
            pass_path,
            len(targets),
            targets[0],
        )
    return str(targets[0])


def _plan(args: argparse.Namespace, stage: Usd.Stage, time: Usd.TimeCode) -> _Plan:
    """Merge the command line with the stage's render settings; explicit flags win.

    Raises:
        RenderSettingsError: the named render settings are unusable, or the
            resulting AOVs cannot go to the output file.

    """
    named = args.renderSettingsPrimPath or _render_pass_settings(stage, args.renderPassPrimPath)
    try:
        spec = read_render_settings(stage, named, time)
    except RenderSettingsError as exc:
        if named:
            raise
        # Settings the user did not ask for are not worth failing over.
        _log.warning("mipray: ignoring the stage's render settings: %s", exc)
        spec = None
    width, height = DEFAULT_WIDTH, None
    if spec is not None:
        width, height = spec.resolution
        if args.imageWidth is not None:
            height = max(1, round(args.imageWidth * spec.resolution[1] / spec.resolution[0]))
    if args.imageWidth is not None:
        width = args.imageWidth
    aovs = args.aov_list or (spec.aovs if spec is not None and spec.aovs else ["color"])
    if args.aov_list is None and is_eight_bit(args.outputImagePath) and "color" in aovs:
        # An 8-bit image with an alpha channel holds the alpha AOV too (RGBA, as usdrecord's);
        # explicit --aovs say what it holds.
        aovs = list(dict.fromkeys([*aovs, *eight_bit_aovs(args.outputImagePath)]))
    if args.purpose_list is not None:
        purposes = args.purpose_list
    elif spec is not None:
        unknown = [p for p in spec.purposes if p not in PURPOSES]
        if unknown:
            raise RenderSettingsError(f"{spec.path}: unknown includedPurposes '{unknown[0]}'")
        purposes = [p for p in spec.purposes if p != "default"]
    else:
        purposes = ["render"]
    if is_eight_bit(args.outputImagePath) and "color" not in aovs:
        raise RenderSettingsError(
            f"{args.outputImagePath}: an 8-bit image needs the color AOV, but "
            f"{spec.path if spec else '--aovs'} asks for {', '.join(aovs)}"
        )
    camera = args.camera or (spec.camera if spec is not None else None)
    if spec is not None:
        _log.info(
            "mipray: render settings %s: %dx%d, camera %s, AOVs %s",
            spec.path,
            width,
            height,
            camera or "(default)",
            ", ".join(aovs),
        )
    unsupported = audit_render_settings(stage, spec.path, time) if spec is not None else []
    warn_unsupported(unsupported, set())
    return _Plan(camera, width, height, aovs, purposes, spec.path if spec else None, unsupported)


def _run(args: argparse.Namespace, frames: list[Any], out: TextIO, err: TextIO) -> int:
    if args.colorCorrectionMode == _OCIO:
        _log.warning("mipray: --colorCorrectionMode %s is not supported; encoding sRGB", _OCIO)
        args.colorCorrectionMode = "sRGB"
    stage = open_stage(
        args.usdFilePath,
        population_mask=_split(args.mask) if args.mask else None,
        session_layer=args.sessionLayer,
    )
    times = [
        Usd.TimeCode(stage.GetStartTimeCode())
        if f is None
        else f
        if isinstance(f, Usd.TimeCode)
        else Usd.TimeCode(f)
        for f in frames
    ]
    settings = render_settings(args)
    plan = _plan(args, stage, times[0])
    extra = {"mipray:renderSettings": plan.settings_path} if plan.settings_path else None
    progress = _Progress(err, len(times))
    progressive = bool(settings.get("progressive"))
    passes = pass_samples(_samples(settings)) if progressive else []
    # Every frame's output is checked before the first render, not found unwritable after it.
    for time in times:
        check_output(
            format_frame_path(args.outputImagePath, 0.0 if time.IsDefault() else time.GetValue()),
            plan.aovs,
            args.colorCorrectionMode,
        )
    if distributed.wanted(args):
        return distributed.record(args, times, settings, plan, extra, out, err, _write_stats)
    internal_errors = 0
    with RenderSession(stage, purposes=plan.purposes, time=times[0]) as session:
        for index, time in enumerate(times, start=1):
            progress.start(index, time, passes)
            value = 0.0 if time.IsDefault() else time.GetValue()
            path = format_frame_path(args.outputImagePath, value)
            # Each pass but the last is written by the renderer itself, atomically.
            pass_output = (
                {
                    "path": path,
                    "aovs": plan.aovs,
                    "color_correction": args.colorCorrectionMode,
                    "metadata": extra or {},
                }
                if progressive
                else None
            )
            try:
                result = session.render(
                    plan.camera,
                    plan.width,
                    plan.aovs,
                    settings,
                    time=time,
                    camera_light=not args.disableCameraLight,
                    height=plan.height,
                    progress=progress.update if progress.enabled else None,
                    on_update=_pass_counter(progress) if progressive else None,
                    pass_output=pass_output,
                )
                write_frame(
                    result,
                    path,
                    plan.aovs,
                    color_correction=args.colorCorrectionMode,
                    metadata=extra,
                    unsupported=plan.unsupported,
                    dome_opaque=args.enableDomeLightVisibility,
                    atomic=progressive,
                )
            finally:
                progress.clear()
            out.write(path + "\n")
            out.flush()
            if args.stats:
                title = f"mipray stats: {path}"
                _write_stats(args.stats, value, result.stats, title, out)
            internal_errors += int(result.stats.get("internal_errors", 0))
    if internal_errors:
        err.write(
            f"{PROG}: images written, but {internal_errors} prim(s) were dropped after internal "
            "errors (named above)\n"
        )
        return 2
    return 0


def _samples(settings: dict[str, object]) -> int:
    """The samples per pixel ``settings`` ask for (the renderer's default 1; it checks them)."""
    try:
        return max(1, int(float(settings.get("samples", 1))))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return 1


def _pass_counter(
    progress: _Progress,
) -> Callable[[int, bool, dict[str, NDArray[np.float32]]], None]:
    """The ``on_update`` of a progressive render: the bar's pass label follows the passes.

    The passes' images are written by the renderer (``pass_output``); the last
    pass's image is the result, written once the render returns with the full
    metadata (the stats).
    """

    def on_update(samples: int, converged: bool, pixels: dict[str, NDArray[np.float32]]) -> None:
        progress.pass_finished(samples)

    return on_update


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``mipray-record`` with ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    out, err = sys.stdout, sys.stderr
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        frames = _validate(args)
    except _UsageError as exc:
        err.write(f"{PROG}: {exc}\n")
        return 1
    except SystemExit as exc:  # --help, --version
        return int(exc.code or 0) if not isinstance(exc.code, str) else 1
    handler, old_level = _install_logging(args.verbose, err)
    old_sigterm = _stop_on_sigterm()
    try:
        return _run(args, frames, out, err)
    except MiprayError as exc:
        err.write(f"{PROG}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}\n")
        return 1
    except KeyboardInterrupt:
        err.write(f"{PROG}: interrupted\n")
        return 130
    except _Terminated:
        err.write(f"{PROG}: terminated\n")
        return 128 + signal.SIGTERM
    finally:
        if old_sigterm is not None:
            signal.signal(signal.SIGTERM, old_sigterm)
        _log.removeHandler(handler)
        _log.setLevel(old_level)


class _Terminated(BaseException):
    """SIGTERM arrived (a render farm's stop, ``kill``): stop as Ctrl-C does.

    A BaseException, as KeyboardInterrupt is, so that no ``except Exception`` on the way
    swallows it; raised by the handler on the main thread, where the render's watcher runs
    Python's signal handlers while the render threads work, so the render stops at its next
    check and no output is left half written.
    """


def _stop_on_sigterm() -> Any:
    """Make SIGTERM raise :class:`_Terminated`; return the handler it replaced.

    None (nothing installed) off the main thread, where Python cannot set handlers.
    """

    def stop(signum: int, frame: object) -> None:
        raise _Terminated

    try:
        return signal.signal(signal.SIGTERM, stop)
    except ValueError:
        return None


if __name__ == "__main__":
    sys.exit(main())
