"""Rendering a USD stage from Python: one call, or a session that follows edits.

``render()`` is the one-shot form; :class:`RenderSession` keeps the render
delegate and the scene delegate alive between renders, so edits to a live
stage (``Usd.Notice.ObjectsChanged``) and time changes re-sync only the prims
they touch. ``mipray-record`` renders its frames through one session.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import re
import stat
import sys
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from pxr import Sdf, Tf, Usd

from .errors import InternalError, MiprayError, OutputError, RenderSettingsError, StageError
from .image import write_aovs
from .settings import TABLE, describe
from .usd.camera import camera_matrices, image_height
from .usd.scene_delegate import SyncError, UsdSceneDelegate

if TYPE_CHECKING:
    from .usd.protocol import RenderDelegateLike

__all__ = [
    "DEFAULT_WIDTH",
    "SETTINGS",
    "RenderResult",
    "RenderSession",
    "UpdateCallback",
    "open_stage",
    "render",
]

_log = logging.getLogger(__name__)

#: ``on_update(samples, converged, aovs)``: one progressive pass's image (see
#: :meth:`RenderSession.render`).
UpdateCallback = Callable[[int, bool, dict[str, NDArray[np.float32]]], object]

#: Image width when none is given (usdrecord's default).
DEFAULT_WIDTH = 960
#: Every render setting, key → what it does, the values it takes and its default:
#: the renderer's settings table (:data:`mipray.settings.TABLE`), empty without the
#: compiled module.
SETTINGS: dict[str, str] = {key: describe(key) for key in TABLE}


def open_stage(
    path: str | os.PathLike[str],
    *,
    population_mask: Iterable[str] | None = None,
    session_layer: str | None = None,
) -> Usd.Stage:
    """Open a USD file as usdrecord does, with one-line errors.

    Args:
        path: the USD file.
        population_mask: prim paths to limit the stage to (with their
            ancestors and descendants), as ``--mask``.
        session_layer: a layer to use as the session layer.

    Raises:
        StageError: the file or the session layer is missing or unreadable.

    """
    file_path = os.fspath(path)
    root = _open_layer(file_path, "")
    session = _open_layer(session_layer, "session layer ") if session_layer else None
    for layer in (root, session):
        if layer is not None:
            _refuse_special_dependencies(layer)
    try:
        session = session or Sdf.Layer.CreateAnonymous()
        with _usd_diagnostics():
            if population_mask:
                mask = Usd.StagePopulationMask()
                for prim_path in population_mask:
                    mask.Add(Sdf.Path(prim_path))
                stage = Usd.Stage.OpenMasked(root, session, mask)
            else:
                stage = Usd.Stage.Open(root, session)
    except Tf.ErrorException as exc:
        # A layer the root brings in (a sublayer) failed: USD's reason names it.
        raise StageError(f"{file_path}: {_tf_reason(exc)}", path=file_path) from exc
    if not stage:
        raise StageError(f"{file_path}: cannot open USD stage", path=file_path)
    return stage


def _open_layer(path: str, what: str) -> Sdf.Layer:
    """Open one layer; a failure is a one-line error naming it (``what``: its role)."""
    if not os.path.exists(path):
        raise StageError(f"{path}: no such {what.strip() or 'file'}", path=path)
    if not os.path.isfile(path):
        # A FIFO or a device would have USD read it for ever, a directory fail obscurely.
        kind, role = _kind_of(path), what or "layer "
        raise StageError(
            f"{path}: not a regular file ({kind}); a USD {role}must be a file", path=path
        )
    try:
        layer = Sdf.Layer.FindOrOpen(path)
    except Tf.ErrorException as exc:
        raise StageError(
            f"{path}: cannot open {what}as a USD layer: {_tf_reason(exc)}", path=path
        ) from exc
    if not layer:
        raise StageError(
            f"{path}: cannot open {what}as a USD layer{_package_reason(path)}", path=path
        )
    return layer


def _package_reason(path: str) -> str:
    """Why a ``.usdz`` package did not open, when its first file says (else "")."""
    if not path.lower().endswith(".usdz"):
        return ""
    try:
        with zipfile.ZipFile(path) as package:
            names = package.namelist()
    except (OSError, zipfile.BadZipFile) as exc:
        return f": not a zip archive ({exc})"
    if not names:
        return ": the package is empty"
    first = names[0]
    if os.path.splitext(first)[1].lower() not in (".usd", ".usda", ".usdc"):
        # usdz's rule: the first file is the root layer. MaterialX-only packages (OpenUSD's
        # usdMtlx tests) need usdMtlx's file format, which usd-core's wheel does not register.
        return (
            f": its first file, {first}, is not a USD layer"
            " (a package's first file is its root layer)"
        )
    return ""


def _refuse_special_dependencies(top: Sdf.Layer) -> None:
    """Refuse every layer ``top`` brings in that is a FIFO, a device or a directory.

    Sublayers, references and payloads (in variants too, and theirs in turn) are checked; the
    error names the file and the layer that asks for it. Composing would have USD read a FIFO
    or a device for ever.

    Layers that are not local files (inside a package, through a custom resolver) or that fail
    to open are left to USD, whose composition errors are reported as before.
    """
    seen = {top.identifier}
    pending = [top]
    while pending:
        layer = pending.pop()
        for asset in layer.GetCompositionAssetDependencies():
            path = _local_path(layer, asset)
            if path is None:
                continue
            if not os.path.isfile(path):
                raise StageError(
                    f"{path}: not a regular file ({_kind_of(path)}); a USD layer must be a "
                    f"file (brought in by {layer.identifier})",
                    path=path,
                )
            try:
                dependency = Sdf.Layer.FindOrOpen(path)
            except Tf.ErrorException:
                continue  # USD reports it when composing
            if dependency and dependency.identifier not in seen:
                seen.add(dependency.identifier)
                pending.append(dependency)


def _local_path(layer: Sdf.Layer, asset: str) -> str | None:
    """The local file an asset path of ``layer`` names, when it names an existing one."""
    if not asset or "[" in asset:  # a package's inner file: read through its package
        return None
    try:
        resolved = Sdf.ComputeAssetPathRelativeToLayer(layer, asset)
    except Tf.ErrorException:
        return None
    path = resolved or asset
    return path if os.path.exists(path) else None


def _kind_of(path: str) -> str:
    """What a path that is not a regular file is, for a message."""
    mode = os.stat(path).st_mode
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a socket" if stat.S_ISSOCK(mode) else "not a plain file"


#: The prefix of a warning USD prints itself: where in its source it was issued.
_TF_WARNING = re.compile(r"^Warning: in \S+ at line \d+ of \S+ -- ")


@contextlib.contextmanager
def _usd_diagnostics() -> Iterator[None]:
    """Catch what USD's C++ prints on the standard error while opening a stage.

    Its composition errors (a reference to a missing layer, ...) are listed in the stats'
    ``unsupported`` with USD's reason (:func:`mipray.usd.unsupported.composition_errors`);
    each other warning is logged in one line, without USD's source location.
    """
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):
        yield  # no file descriptor 2 to catch (an embedding host): USD prints as it likes
        return
    with tempfile.TemporaryFile(mode="w+b") as caught:
        os.dup2(caught.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            text = caught.read().decode("utf-8", "replace")
    for line in text.splitlines():
        message = _TF_WARNING.sub("", line).strip()
        if not message or (message.startswith("In <") and "Could not open asset" in message):
            continue  # a composition error: listed in the stats, warned once there
        _log.warning("mipray: USD: %s", message)


#: The prefix USD puts on each error: where in its source it was raised, no use to a user.
_TF_NOISE = re.compile(r"^Error in '[^']*' at line \d+ in file [^:]*:?\s*:\s*")


def _tf_reason(exc: Exception) -> str:
    """The first reason of a ``Tf.ErrorException``, in one line.

    Its message is multi-line, each line with USD's ``Error in 'pxrInternal_...' at
    line N in file ...`` prefix, which says nothing to a user.
    """
    for line in str(exc).splitlines():
        reason = _TF_NOISE.sub("", line.strip()).strip().strip("'").strip()
        if reason:
            return reason
    return type(exc).__name__


@dataclass
class RenderResult:
    """What one render produced."""

    #: AOV name → H×W×C float32 array, linear. A render's arrays are read-only views of the
    #: renderer's own buffers (no pixel copied); ``numpy.array(a)`` is a copy to change.
    aovs: dict[str, NDArray[np.float32]]
    #: Render statistics (names as in DESIGN.md, "Statistics and stats JSON").
    stats: dict[str, Any]
    #: Path of the camera rendered through.
    camera: str
    #: Time code rendered (``nan`` for the default time).
    time: float
    #: Prims skipped because their data was bad, each naming its path.
    errors: list[SyncError] = field(default_factory=list)
    _camera_args: dict[str, Any] = field(default_factory=dict, repr=False)
    #: The scene has a dome light: seen from the camera, it is the background of every pixel.
    dome_background: bool = False

    @property
    def width(self) -> int:
        """Image width in pixels."""
        return int(next(iter(self.aovs.values())).shape[1]) if self.aovs else 0

    @property
    def height(self) -> int:
        """Image height in pixels."""
        return int(next(iter(self.aovs.values())).shape[0]) if self.aovs else 0

    def metadata(self) -> dict[str, Any]:
        """Image attributes written with the pixels (the writer adds ``Software``).

        ``mipray:stats`` (the stats as JSON), ``mipray:camera``, and the
        camera's ``worldtocamera`` / ``worldtoscreen`` matrices (USD
        conventions, 16 floats each, row by row).
        """
        data: dict[str, Any] = {
            "mipray:stats": json.dumps(self.stats, sort_keys=True),
            "mipray:camera": self.camera,
        }
        if not math.isnan(self.time):
            data["mipray:timeCode"] = float(self.time)
        if self._camera_args:
            world_to_camera, world_to_screen = camera_matrices(self._camera_args)
            data["worldtocamera"] = [float(v) for v in world_to_camera.ravel()]
            data["worldtoscreen"] = [float(v) for v in world_to_screen.ravel()]
        return data

    def write(
        self,
        path: str | os.PathLike[str],
        aovs: Sequence[str] | None = None,
        *,
        formats: Mapping[str, str] | None = None,
        color_correction: str = "sRGB",
        metadata: Mapping[str, Any] | None = None,
        atomic: bool = False,
    ) -> None:
        """Write AOVs to an image file through the renderer's image writer.

        The pixels go from the render's buffers to the file without a copy
        through Python.

        Args:
            path: output file; ``.exr`` keeps every AOV linear (color and
                normal half, depth float); 8-bit types (``.png``, ``.jpg``)
                hold the color AOV only, sRGB-encoded unless
                ``color_correction="disabled"``.
            aovs: which AOVs, in channel order (default: all rendered).
            formats: per-AOV pixel format overrides.
            color_correction: ``"sRGB"`` or ``"disabled"``.
            metadata: extra attributes, added to :meth:`metadata`.
            atomic: write a temporary file beside ``path`` and rename it
                over ``path`` (readers never see a half-written image).

        Raises:
            OutputError: the file cannot be written.

        """
        data = self.metadata()
        data.update(metadata or {})
        write_aovs(
            os.fspath(path),
            self.aovs,
            aovs,
            formats=formats,
            color_correction=color_correction,
            metadata=data,
            atomic=atomic,
        )


def _new_delegate() -> RenderDelegateLike:
    try:
        from . import _mipray
    except ImportError as exc:
        raise MiprayError(
            f"the compiled module mipray._mipray is not installed ({exc}); "
            "build it with `make build` or `maturin develop -m python/Cargo.toml`"
        ) from exc
    return _mipray.RenderDelegate()


class RenderSession:
    """A render delegate kept in step with a live ``Usd.Stage``.

    Args:
        stage: the stage to render; edits to it are followed.
        purposes: purposes to render besides ``"default"`` (default:
            ``("render",)``).
        time: initial time code (default: the stage's start time code).
        delegate: a render delegate to sync into (default: a new
            ``mipray._mipray.RenderDelegate``).

    Use as a context manager, or call :meth:`close`, to stop listening.

    """

    def __init__(
        self,
        stage: Usd.Stage,
        *,
        purposes: Sequence[str] | None = None,
        time: Usd.TimeCode | float | None = None,
        delegate: RenderDelegateLike | None = None,
    ) -> None:
        if not isinstance(stage, Usd.Stage):
            raise StageError(f"expected a Usd.Stage, got {type(stage).__name__}")
        self.delegate: Any = delegate if delegate is not None else _new_delegate()
        chosen = ("default", *(purposes if purposes is not None else ("render",)))
        self.scene = UsdSceneDelegate(
            stage,
            self.delegate,
            time=time if time is not None else stage.GetStartTimeCode(),
            purposes=chosen,
        )
        self.scene.watch()
        # Said once a session: a stage with nothing to render (see `render`).
        self._said_empty = False

    def close(self) -> None:
        """Stop following edits to the stage."""
        self.scene.close()

    def __enter__(self) -> RenderSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def render(
        self,
        camera: str | None = None,
        width: int | None = None,
        aovs: Sequence[str] = ("color",),
        settings: Mapping[str, object] | None = None,
        time: Usd.TimeCode | float | None = None,
        *,
        camera_light: bool = True,
        height: int | None = None,
        progress: Callable[[int, int], object] | None = None,
        progressive: bool | None = None,
        on_update: UpdateCallback | None = None,
        pass_output: Mapping[str, Any] | None = None,
    ) -> RenderResult:
        """Sync what changed and render one image.

        Args:
            camera: camera prim path or name; default: ``main_cam``, else the
                first camera, else one framing the stage.
            width: image width (default 960); the height follows the camera's
                aperture aspect ratio unless ``height`` is given.
            aovs: AOV names: ``"color"``, ``"depth"``, ``"normal"``.
            settings: render settings (see :data:`SETTINGS`); checked by the
                renderer, which rejects unknown keys.
            time: time code to render at (default: the session's current one).
            camera_light: light the stage from the camera if it has no light.
            height: image height, overriding the aspect ratio.
            progress: called as ``progress(done, total)`` while rendering,
                in pixel samples (pixels × samples per pixel, all passes).
            progressive: render in passes of 1, 2, 4, ... samples per pixel
                up to ``settings["samples"]`` (the ``"progressive"`` setting;
                None leaves it as ``settings`` has it, default off). The
                final image is bit-identical to a one-pass render with the
                same seed and sample count.
            on_update: called as ``on_update(samples, converged, aovs)`` after
                each pass, in order: ``samples`` is the samples per pixel so
                far (int), ``converged`` is True for the last pass only (its
                arrays equal the result's), and ``aovs`` maps each AOV asked
                for to a read-only H×W×C float32 array, linear, averaged over
                the samples so far, viewing that pass's own buffers (yours to
                keep: later passes do not touch them). A render without
                ``progressive`` has one pass, so one call. It runs on a
                render thread with the GIL held, while no pixel is being
                rendered; the GIL is released in between. An exception it
                raises stops the render before the next pass and is raised
                here unchanged; the session stays usable.
            pass_output: with ``progressive``, write each pass but the last
                to an image file as the renderer finishes it, atomically (a
                reader sees one whole pass or the next), before ``on_update``
                hears of it: ``{"path": str, "aovs": [names],
                "color_correction": "sRGB" or "disabled", "metadata": {...}}``
                (as :meth:`RenderResult.write`; each file also says
                ``mipray:progressiveSamples``). The last pass is the result,
                for the caller to write with its stats.

        Ctrl-C (SIGINT on the main thread) stops the render within a fraction
        of a second, whether it is syncing or rendering: ``KeyboardInterrupt``
        is raised and no further pass is written.

        Raises:
            PrimError: the camera is missing or unusable.
            RenderSettingsError: a bad size, AOV list or setting.
            InternalError: the renderer failed outside any one prim's work.
            OutputError: a pass could not be written to ``pass_output``.
            KeyboardInterrupt: Ctrl-C stopped the sync or the render.
            BaseException: whatever ``on_update`` raised.

        """
        width = DEFAULT_WIDTH if width is None else int(width)
        if width < 1 or (height is not None and int(height) < 1):
            raise RenderSettingsError(f"image size must be at least 1 pixel, got width {width}")
        aov_list = list(dict.fromkeys(aovs))
        if not aov_list:
            raise RenderSettingsError("no AOV to render; ask for at least 'color'")
        if time is not None:
            self.scene.set_time(time)
        self.scene.sync()
        camera_path = self.scene.resolve_camera(camera)
        camera_args = self.scene.cameras[camera_path]
        self.scene.update_camera_light(camera_path, camera_light)
        self.scene.update_motion(camera_path)
        h = int(height) if height is not None else image_height(width, camera_args, camera_path)
        chosen = dict(settings or {})
        if progressive is not None:
            chosen["progressive"] = int(bool(progressive))
        kwargs: dict[str, Any] = {}
        if progress is not None:
            kwargs["progress"] = progress
        # The callback's own exceptions pass through as they are, not as setting errors.
        raised: list[BaseException] = []
        if on_update is not None:
            callback = on_update

            def forward(samples: int, converged: bool, aovs: dict[str, Any]) -> None:
                try:
                    callback(samples, converged, aovs)
                except BaseException as exc:
                    raised.append(exc)
                    raise

            kwargs["on_update"] = forward
        if pass_output is not None:
            kwargs["pass_output"] = dict(pass_output)
        try:
            pixels, stats_json = self.delegate.render(
                camera_path, width, h, aov_list, chosen, **kwargs
            )
        except (ValueError, RuntimeError, OSError) as exc:
            if raised and exc is raised[0]:
                raise
            if isinstance(exc, OSError):
                raise OutputError(f"cannot write image {str(exc).splitlines()[0]}") from exc
            if isinstance(exc, RuntimeError):
                raise InternalError(str(exc).splitlines()[0]) from exc
            raise RenderSettingsError(str(exc).splitlines()[0]) from exc
        try:
            stats = json.loads(stats_json) if stats_json else {}
        except json.JSONDecodeError:
            _log.warning("mipray: the renderer returned stats that are not JSON")
            stats = {}
        if stats.get("scene", {}).get("instances") == 0 and not self._said_empty:
            # A layer of cameras or looks alone, a mask or purposes that leave nothing: say so,
            # rather than hand back an empty image as if it were the render.
            self._said_empty = True
            _log.warning(
                "mipray: nothing to render: no gprim of the included purposes (%s) on the stage; "
                "the image holds only what its lights show",
                ", ".join(self.scene.purposes),
            )
        # Everything authored that the image lacks (mipray.usd.unsupported), listed in the stats.
        stats["unsupported"] = [u.as_dict() for u in self.scene.unsupported]
        # Every prim left out, one line each: those the scene delegate could not send (bad
        # data caught in Python) and those the renderer dropped.
        skipped = [str(e) for e in self.scene.delegate_errors]
        stats["prim_errors"] = list(dict.fromkeys([*skipped, *stats.get("prim_errors", [])]))
        scene_time = self.scene.time
        return RenderResult(
            aovs=dict(pixels),
            stats=stats,
            camera=camera_path,
            time=math.nan if scene_time.IsDefault() else float(scene_time.GetValue()),
            errors=self.scene.delegate_errors,
            _camera_args=camera_args,
            dome_background=_has_dome_light(self.scene),
        )


def _has_dome_light(scene: Any) -> bool:
    """Whether a synced stage light of ``scene`` is a dome."""
    from pxr import UsdLux

    return any(scene.stage.GetPrimAtPath(p).IsA(UsdLux.DomeLight) for p in scene.light_paths)


def render(
    path_or_stage: str | os.PathLike[str] | Usd.Stage,
    camera: str | None = None,
    width: int | None = None,
    aovs: Sequence[str] = ("color",),
    settings: Mapping[str, object] | None = None,
    time: Usd.TimeCode | float | None = None,
    purposes: Sequence[str] | None = None,
    *,
    progressive: bool | None = None,
    on_update: UpdateCallback | None = None,
    client: Any = None,
    tiles: int | None = None,
) -> RenderResult:
    """Render a USD file or a live ``Usd.Stage`` once.

    Args:
        path_or_stage: a USD file path, or an open stage (left as it is).
        camera: camera prim path or name; default: ``main_cam``, else the
            first camera on the stage, else a camera framing the stage.
        width: image width in pixels (default 960); the height follows the
            camera's aperture aspect ratio.
        aovs: AOVs to render: ``"color"`` (linear RGB), ``"depth"`` (distance
            along the view axis, scene units, ``inf`` on misses), ``"normal"``
            (world space).
        settings: render settings, e.g. ``{"samples": 4, "tessFactor": 1.0}``
            (keys in :data:`SETTINGS`).
        time: time code (default: the stage's start time code).
        purposes: purposes to render besides ``"default"`` (default
            ``("render",)``).
        progressive: render in passes of 1, 2, 4, ... samples per pixel up
            to ``settings["samples"]``, ending bit-identical to a one-pass
            render (see :meth:`RenderSession.render`).
        on_update: called as ``on_update(samples, converged, aovs)`` after
            each pass: samples per pixel so far, whether it is the last pass,
            and AOV name → new H×W×C float32 array (linear); see
            :meth:`RenderSession.render`.
        client: a ``distributed.Client``: render on that Dask cluster
            (:func:`mipray.distributed.render`; the stage must be a saved file
            every worker sees at the same path), bit-identical to rendering
            here. Not with ``progressive`` or ``on_update``.
        tiles: with ``client``, the image is cut into this many tiles, one
            task each (default: one per worker).

    Returns:
        A :class:`RenderResult` with ``.aovs`` (name → H×W×C float32),
        ``.stats`` (dict) and ``.write(path)``.

    Raises:
        StageError, PrimError, RenderSettingsError, InternalError: see
        :mod:`mipray.errors`.

    Example::

        import mipray
        result = mipray.render("shot.usda", width=320, aovs=("color", "depth"))
        result.write("shot.exr")

        def show(samples, converged, aovs):
            print(samples, "samples per pixel:", aovs["color"].mean())

        mipray.render("shot.usda", settings={"samples": 16}, progressive=True, on_update=show)

    """
    if client is not None:
        if on_update is not None or progressive:
            raise RenderSettingsError("progressive rendering is not supported on a cluster")
        from .distributed import render as render_on_cluster

        return render_on_cluster(
            client, path_or_stage, camera, width, aovs, settings, time, purposes, tiles=tiles
        )
    if isinstance(path_or_stage, Usd.Stage):
        stage = path_or_stage
    else:
        stage = open_stage(path_or_stage)
    with RenderSession(stage, purposes=purposes, time=time) as session:
        return session.render(
            camera, width, aovs, settings, progressive=progressive, on_update=on_update
        )
