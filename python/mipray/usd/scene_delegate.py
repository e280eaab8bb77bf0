"""The USD scene delegate: walks a ``Usd.Stage`` and syncs it into a render delegate.

This is Hydra's scene-delegate role (DESIGN.md, "Data flow", steps 1–2), done
with usd-core's Python API because usd-core ships no Hydra: the stage is read
here, prims cross into the render delegate as numpy arrays through ``set_*``
calls, and later edits re-sync only what they touched.

* Rprims: ``UsdGeom.Mesh``. Sprims: ``UsdGeom.Camera``, ``UsdLux.DistantLight``.
  Other gprims and lights are skipped with one warning per type.
* Native instances render: the walk follows instance proxies, so each
  instance is synced as its own prims (sharing prototypes comes later).
* Visibility and purpose are inherited down the walk exactly as
  ``ComputeVisibility`` / ``ComputePurpose`` compute them; invisible subtrees
  are pruned, prims whose purpose is not included are skipped.
* A bad prim is logged (one line naming its path), skipped and listed in
  :attr:`UsdSceneDelegate.delegate_errors`; the rest of the stage syncs.
* :meth:`UsdSceneDelegate.watch` listens to ``Usd.Notice.ObjectsChanged``;
  the next :meth:`~UsdSceneDelegate.sync` re-walks resynced subtrees and
  re-sends only prims whose data, transform or material changed.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from pxr import Sdf, Tf, Usd, UsdGeom, UsdLux

from ..errors import PrimError, RenderSettingsError
from .camera import (
    DEFAULT_CAMERA_PATH,
    camera_arguments,
    find_camera_prim,
    framing_camera_arguments,
)
from .light import CAMERA_LIGHT_PATH, camera_light_arguments, distant_light_arguments
from .material import compute_albedo
from .mesh import mesh_arguments
from .protocol import RenderDelegateLike
from .transform import ancestors_might_vary, world_transform

__all__ = ["PURPOSES", "SyncError", "UsdSceneDelegate"]

_log = logging.getLogger(__name__)

#: Every purpose token UsdGeom defines.
PURPOSES = ("default", "render", "proxy", "guide")

# Property names whose change affects the prim and everything below it.
_SUBTREE_DATA_PREFIXES = ("xformOp", "material:binding")
# Property names whose change can add or remove prims from the render.
_TRAVERSAL_PROPERTIES = frozenset({"visibility", "purpose"})


@dataclass(frozen=True)
class SyncError:
    """A prim that could not be synced, and why."""

    #: The prim's path.
    prim_path: str
    #: The problem, one line.
    message: str

    def __str__(self) -> str:
        if self.prim_path in self.message:
            return self.message
        return f"{self.prim_path}: {self.message}"


@dataclass
class _Record:
    """What the scene delegate remembers about one synced (or failed) prim."""

    kind: str  # "mesh", "camera" or "light"
    order: int  # traversal order, to pick "the first camera"
    in_delegate: bool = True  # False for a mesh with no faces
    might_vary: bool = False  # re-sync when the time changes
    material_path: str | None = None
    args: dict[str, Any] = field(default_factory=dict)  # kept for cameras only


def _under(path: str, root: str) -> bool:
    """Whether prim path ``path`` is ``root`` or below it."""
    return root == "/" or path == root or path.startswith(root + "/")


def _ancestors_visible(prim: Usd.Prim, time: Usd.TimeCode) -> bool:
    """Whether no strict ancestor of ``prim`` is invisible at ``time``."""
    parent = prim.GetParent()
    while parent and not parent.IsPseudoRoot():
        imageable = UsdGeom.Imageable(parent)
        if imageable and imageable.GetVisibilityAttr().Get(time) == UsdGeom.Tokens.invisible:
            return False
        parent = parent.GetParent()
    return True


def _inherited_purpose_info(prim: Usd.Prim) -> UsdGeom.Imageable.PurposeInfo:
    """The purpose ``prim`` inherits: that of its nearest imageable ancestor."""
    parent = prim.GetParent()
    while parent and not parent.IsPseudoRoot():
        imageable = UsdGeom.Imageable(parent)
        if imageable:
            return imageable.ComputePurposeInfo()
        parent = parent.GetParent()
    return UsdGeom.Imageable.PurposeInfo()


def _to_time(time: Usd.TimeCode | float | None) -> Usd.TimeCode:
    if time is None:
        return Usd.TimeCode.Default()
    if isinstance(time, Usd.TimeCode):
        return time
    return Usd.TimeCode(float(time))


class UsdSceneDelegate:
    """Syncs a ``Usd.Stage`` into a render delegate, fully or incrementally.

    Args:
        stage: the stage to read; it stays owned by the caller.
        delegate: a ``mipray._mipray.RenderDelegate``, or anything with the
            same ``set_*``/``remove`` methods.
        time: the time code to read values at.
        purposes: the purposes to render; ``"default"`` is always included.

    Attributes:
        sync_counts: path → number of times that prim was sent to the
            delegate; tests and tools read it to see what a sync touched.

    Raises:
        RenderSettingsError: an unknown purpose.

    """

    def __init__(
        self,
        stage: Usd.Stage,
        delegate: RenderDelegateLike,
        time: Usd.TimeCode | float | None = None,
        purposes: tuple[str, ...] | list[str] = ("default", "render"),
    ) -> None:
        unknown = [p for p in purposes if p not in PURPOSES]
        if unknown:
            raise RenderSettingsError(
                f"unknown purpose '{unknown[0]}'; purposes are {', '.join(PURPOSES)}"
            )
        self.stage = stage
        self.delegate = delegate
        self.time = _to_time(time)
        self.purposes: tuple[str, ...] = (
            "default",
            *(p for p in dict.fromkeys(purposes) if p != "default"),
        )
        self.sync_counts: dict[str, int] = {}
        self._records: dict[str, _Record] = {}
        self._errors: dict[str, SyncError] = {}
        self._order = 0
        self._full = True
        self._resync: set[str] = set()
        self._subtree_dirty: set[str] = set()
        self._prim_dirty: set[str] = set()
        self._animated_visibility = False
        self._listener: Tf.Notice.Listener | None = None
        self._warned_types: set[str] = set()
        self._default_camera: dict[str, Any] | None = None
        self._camera_light = False

    # ------------------------------------------------------------------ state

    @property
    def delegate_errors(self) -> list[SyncError]:
        """The prims that currently fail to sync, in the order they failed."""
        return list(self._errors.values())

    @property
    def synced_paths(self) -> list[str]:
        """Paths of the stage prims currently held by the delegate."""
        return list(self._records)

    @property
    def cameras(self) -> dict[str, dict[str, Any]]:
        """Synced cameras, path → the ``set_camera`` arguments they were sent with.

        Includes the framing camera once :meth:`default_camera` made it.
        """
        result = {p: r.args for p, r in self._records.items() if r.kind == "camera"}
        if self._default_camera is not None:
            result[DEFAULT_CAMERA_PATH] = self._default_camera
        return result

    @property
    def light_paths(self) -> list[str]:
        """Paths of the synced stage lights (not the camera light)."""
        return [p for p, r in self._records.items() if r.kind == "light"]

    @property
    def is_dirty(self) -> bool:
        """Whether the next :meth:`sync` has anything to do."""
        return bool(self._full or self._resync or self._subtree_dirty or self._prim_dirty)

    # ---------------------------------------------------------- change tracking

    def watch(self) -> None:
        """Listen to ``Usd.Notice.ObjectsChanged`` on the stage (idempotent).

        Changes are only recorded; the next :meth:`sync` applies them.
        """
        if self._listener is None:
            self._listener = Tf.Notice.Register(
                Usd.Notice.ObjectsChanged, self._on_objects_changed, self.stage
            )

    def unwatch(self) -> None:
        """Stop listening to stage changes."""
        if self._listener is not None:
            self._listener.Revoke()
            self._listener = None

    def close(self) -> None:
        """Stop listening; the delegate keeps what was synced."""
        self.unwatch()

    def __enter__(self) -> UsdSceneDelegate:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _on_objects_changed(self, notice: Usd.Notice.ObjectsChanged, sender: Usd.Stage) -> None:
        for path in notice.GetResyncedPaths():
            self._mark(path, resynced=True)
        for path in notice.GetChangedInfoOnlyPaths():
            self._mark(path, resynced=False)

    def _mark(self, path: Sdf.Path, *, resynced: bool) -> None:
        """Record one changed path from a notice."""
        prim_path = str(path.GetPrimPath())
        if prim_path.startswith("/__Prototype"):
            # An edit inside a native-instance prototype: every instance of it
            # may change. Rare enough to just walk the stage again.
            self._full = True
            return
        if path.IsPropertyPath():
            name = path.name
            if name in _TRAVERSAL_PROPERTIES:
                self._resync.add(prim_path)
            elif name.startswith(_SUBTREE_DATA_PREFIXES):
                self._subtree_dirty.add(prim_path)
            else:
                self._prim_dirty.add(prim_path)
        elif resynced:
            self._resync.add(prim_path)
        else:
            self._prim_dirty.add(prim_path)

    def mark_all_dirty(self) -> None:
        """Make the next :meth:`sync` walk the whole stage again."""
        self._full = True

    def set_time(self, time: Usd.TimeCode | float) -> None:
        """Read values at another time code from the next :meth:`sync` on.

        Only prims whose values or world transform might vary over time are
        re-sent; if some visibility is animated the stage is walked again.
        """
        new_time = _to_time(time)
        if new_time == self.time:
            return
        self.time = new_time
        if self._animated_visibility:
            self._full = True
            return
        for path, record in self._records.items():
            if record.might_vary:
                self._prim_dirty.add(path)
        for path in self._errors:
            self._prim_dirty.add(path)

    # --------------------------------------------------------------------- sync

    def sync(self) -> None:
        """Bring the render delegate up to date with the stage.

        The first call walks the whole stage; later calls apply only the
        changes recorded since (see :meth:`watch`, :meth:`set_time`).
        Problems with single prims are logged and listed in
        :attr:`delegate_errors`; nothing is raised for them.
        """
        xform_cache = UsdGeom.XformCache(self.time)
        unsupported: Counter[str] = Counter()
        synced_now: set[str] = set()
        changed = self._full or bool(self._resync or self._subtree_dirty or self._prim_dirty)

        if self._full:
            self._order = 0
            roots = ["/"]
        else:
            roots = sorted(self._resync)
            roots = [r for i, r in enumerate(roots) if not any(_under(r, q) for q in roots[:i])]
        self._full = False
        self._resync.clear()

        for root in roots:
            self._resync_subtree(root, xform_cache, unsupported, synced_now)

        dirty: set[str] = set()
        for root in self._subtree_dirty:
            dirty.update(p for p in (*self._records, *self._errors) if _under(p, root))
        elsewhere: list[str] = []  # changed prims that are not synced ones
        for path in self._prim_dirty:
            if path in self._records or path in self._errors:
                dirty.add(path)
            else:
                elsewhere.append(path)
        if elsewhere:
            # A changed material (or a shader under it) re-syncs the meshes bound to it.
            dirty.update(
                p
                for p, r in self._records.items()
                if r.material_path is not None
                and any(_under(r.material_path, q) or _under(q, r.material_path) for q in elsewhere)
            )
        self._subtree_dirty.clear()
        self._prim_dirty.clear()
        memo: dict[str, bool] = {}
        for path in sorted(dirty - synced_now):
            prim = self.stage.GetPrimAtPath(path)
            if not prim:
                self._forget(path)
                continue
            record = self._records.get(path)
            order = record.order if record else self._next_order()
            self._sync_prim(prim, xform_cache, memo, order, unsupported)

        self._warn_unsupported(unsupported)
        if changed and self._default_camera is not None:
            self._sync_default_camera()

    def _next_order(self) -> int:
        self._order += 1
        return self._order

    def _resync_subtree(
        self,
        root: str,
        xform_cache: UsdGeom.XformCache,
        unsupported: Counter[str],
        synced_now: set[str],
    ) -> None:
        """Walk the subtree at ``root`` and sync it; drop what is no longer there."""
        seen: set[str] = set()
        prim = self.stage.GetPrimAtPath(root)
        if prim and (prim.IsActive() or prim.IsPseudoRoot()):
            self._walk(prim, xform_cache, seen, unsupported)
        for path in [p for p in (*self._records, *self._errors) if _under(p, root)]:
            if path not in seen:
                self._forget(path)
        # Materials under the resynced root may have changed: their meshes too.
        for path, record in list(self._records.items()):
            if path not in seen and record.material_path and _under(record.material_path, root):
                self._prim_dirty.add(path)
        synced_now.update(seen)

    def _walk(
        self,
        root: Usd.Prim,
        xform_cache: UsdGeom.XformCache,
        seen: set[str],
        unsupported: Counter[str],
    ) -> None:
        """Depth-first walk from ``root``, inheriting visibility and purpose."""
        predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        memo: dict[str, bool] = {}
        time = self.time
        if root.IsPseudoRoot():
            no_purpose = UsdGeom.Imageable.PurposeInfo()
            stack = [(c, no_purpose) for c in reversed(root.GetFilteredChildren(predicate))]
        else:
            if not _ancestors_visible(root, time):
                return
            stack = [(root, _inherited_purpose_info(root))]
        while stack:
            prim, parent_info = stack.pop()
            info = parent_info
            imageable = UsdGeom.Imageable(prim)
            if imageable:
                visibility = imageable.GetVisibilityAttr()
                if visibility.ValueMightBeTimeVarying():
                    self._animated_visibility = True
                if visibility.Get(time) == UsdGeom.Tokens.invisible:
                    continue  # invisibility is inherited: prune the subtree
                info = imageable.ComputePurposeInfo(parent_info)
                if info.purpose in self.purposes:
                    path = str(prim.GetPath())
                    if self._is_supported(prim, unsupported):
                        seen.add(path)
                        self._sync_prim(prim, xform_cache, memo, self._next_order(), unsupported)
            children = prim.GetFilteredChildren(predicate)
            stack.extend((c, info) for c in reversed(children))

    def _is_supported(self, prim: Usd.Prim, unsupported: Counter[str]) -> bool:
        """Whether ``prim`` is synced; counts renderable prims of unsupported types."""
        if prim.IsA(UsdGeom.Mesh) or prim.IsA(UsdGeom.Camera) or prim.IsA(UsdLux.DistantLight):
            return True
        if (
            prim.IsA(UsdGeom.Gprim)
            or prim.IsA(UsdGeom.PointInstancer)
            or prim.HasAPI(UsdLux.LightAPI)
        ):
            unsupported[prim.GetTypeName() or "untyped"] += 1
        return False

    def _sync_prim(
        self,
        prim: Usd.Prim,
        xform_cache: UsdGeom.XformCache,
        memo: dict[str, bool],
        order: int,
        unsupported: Counter[str],
    ) -> None:
        """Read one prim and send it to the delegate; record a failure instead of raising."""
        path = str(prim.GetPath())
        time = self.time
        try:
            transform = world_transform(xform_cache, prim)
            might_vary = ancestors_might_vary(prim, memo) or any(
                a.ValueMightBeTimeVarying() for a in prim.GetAuthoredAttributes()
            )
            if prim.IsA(UsdGeom.Mesh):
                albedo = compute_albedo(prim, time)
                args = mesh_arguments(UsdGeom.Mesh(prim), time, transform, albedo.rgb)
                record = _Record(
                    "mesh",
                    order,
                    might_vary=might_vary or albedo.might_vary,
                    material_path=albedo.material_path,
                )
                if args is None:  # no faces: valid USD that renders nothing
                    self._forget(path)
                    record.in_delegate = False
                    self._records[path] = record
                    return
                self.delegate.set_mesh(path, **args)
            elif prim.IsA(UsdGeom.Camera):
                args = camera_arguments(UsdGeom.Camera(prim), time, transform)
                record = _Record("camera", order, might_vary=might_vary, args=args)
                self.delegate.set_camera(path, **args)
            elif prim.IsA(UsdLux.DistantLight):
                args = distant_light_arguments(UsdLux.DistantLight(prim), time, transform)
                record = _Record("light", order, might_vary=might_vary)
                self.delegate.set_distant_light(path, **args)
            else:
                # Its type changed to one we do not render.
                self._is_supported(prim, unsupported)
                self._forget(path)
                return
        except PrimError as exc:
            self._fail(path, exc.reason)
            return
        except (ValueError, TypeError, OverflowError) as exc:
            # The delegate refused the data (its message names the path).
            self._fail(path, str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
            return
        self._records[path] = record
        self._errors.pop(path, None)
        self.sync_counts[path] = self.sync_counts.get(path, 0) + 1
        _log.debug("mipray: synced %s %s", record.kind, path)

    def _fail(self, path: str, message: str) -> None:
        error = SyncError(path, message)
        _log.error("mipray: skipping %s", error)
        self._forget(path)
        self._errors[path] = error

    def _forget(self, path: str) -> None:
        """Remove a prim from the delegate and from the books."""
        record = self._records.pop(path, None)
        if record is not None and record.in_delegate:
            self.delegate.remove(path)
        self._errors.pop(path, None)

    def _warn_unsupported(self, unsupported: Counter[str]) -> None:
        for type_name, count in sorted(unsupported.items()):
            if type_name in self._warned_types:
                continue
            self._warned_types.add(type_name)
            noun = "prim" if count == 1 else "prims"
            _log.warning("mipray: skipping %d %s of unsupported type %s", count, noun, type_name)

    # ------------------------------------------------------- camera and lights

    def resolve_camera(self, requested: str | None = None) -> str:
        """The path of the camera to render through, syncing first if needed.

        ``requested`` is a camera prim path or a bare camera name (as
        usdrecord's ``--camera``). Without one: the camera named ``main_cam``
        (usdrecord's primary camera name), else the first camera in traversal
        order, else a camera framing the stage (:meth:`default_camera`).

        A requested camera is used even if it is invisible or its purpose is
        not rendered: visibility hides what a camera is, not what it sees.

        Raises:
            PrimError: the requested camera is missing, not a camera, or its
                data is unusable.

        """
        if self.is_dirty:
            self.sync()
        cameras = {p: r for p, r in self._records.items() if r.kind == "camera"}
        if requested:
            prim = find_camera_prim(self.stage, requested)
            path = str(prim.GetPath())
            if path not in cameras and path not in self._errors:
                # A camera hidden by visibility or purpose still sees: sync it on demand.
                xform_cache = UsdGeom.XformCache(self.time)
                self._sync_prim(prim, xform_cache, {}, self._next_order(), Counter())
            if path in self._errors:
                raise PrimError(path, self._errors[path].message)
            return path
        named = [p for p in cameras if Sdf.Path(p).name == "main_cam"]
        if named:
            return min(named, key=lambda p: cameras[p].order)
        if cameras:
            return min(cameras, key=lambda p: cameras[p].order)
        return self.default_camera()

    def default_camera(self) -> str:
        """Sync the camera framing the stage's bounds, and return its path.

        Logs a warning the first time, as the stage has no camera of its own.
        The camera is re-framed after each :meth:`sync` that changed anything.
        """
        if self._default_camera is None:
            _log.warning(
                "mipray: the stage has no camera; framing its bounds with %s",
                DEFAULT_CAMERA_PATH,
            )
        self._sync_default_camera()
        return DEFAULT_CAMERA_PATH

    def _sync_default_camera(self) -> None:
        args = framing_camera_arguments(self.stage, self.time, self.purposes)
        self._default_camera = args
        self.delegate.set_camera(DEFAULT_CAMERA_PATH, **args)
        self.sync_counts[DEFAULT_CAMERA_PATH] = self.sync_counts.get(DEFAULT_CAMERA_PATH, 0) + 1

    def update_camera_light(self, camera_path: str, enabled: bool = True) -> bool:
        """Add a headlight at ``camera_path`` if the stage has no light, else remove it.

        usdrecord lights a stage without lights from the camera; so does
        mipray unless ``enabled`` is False (``--disableCameraLight``).

        Returns:
            Whether the camera light is in the scene now.

        """
        want = enabled and not self.light_paths
        if want:
            transform = self.cameras[camera_path]["transform"]
            self.delegate.set_distant_light(CAMERA_LIGHT_PATH, **camera_light_arguments(transform))
            if not self._camera_light:
                _log.info("mipray: the stage has no light; lighting it from the camera")
        elif self._camera_light:
            self.delegate.remove(CAMERA_LIGHT_PATH)
        self._camera_light = want
        return want
