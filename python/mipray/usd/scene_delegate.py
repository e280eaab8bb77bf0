"""The USD scene delegate: walks a ``Usd.Stage`` and syncs it into a render delegate.

This is Hydra's scene-delegate role (DESIGN.md, "Data flow", steps 1–2), done
with usd-core's Python API because usd-core ships no Hydra: the stage is read
here, prims cross into the render delegate as numpy arrays through ``set_*``
calls, and later edits re-sync only what they touched.

* Rprims: ``UsdGeom.Mesh`` (GeomSubset materials and display primvars per
  face, :mod:`mipray.usd.face_albedo`), the implicit gprims (``Sphere``,
  ``Cube``, ``Cylinder``, ``Cone``, ``Capsule``, ``Plane`` and the ``_1``
  forms) and ``Points``, intersected exactly (:mod:`mipray.usd.gprim`). Sprims: ``UsdGeom.Camera``,
  ``UsdLux.DistantLight``. Other gprims and lights are skipped with one
  warning per type.
* Instancing shares prototypes (:mod:`mipray.usd.instancing`): a
  ``UsdGeom.PointInstancer`` becomes an instancer of its prototypes' meshes,
  and every native prototype one instancer placing its meshes at each
  instance prim. Prototype meshes are sent once, however many instances.
* Visibility and purpose are inherited down the walk exactly as
  ``ComputeVisibility`` / ``ComputePurpose`` compute them; invisible subtrees
  are pruned, prims whose purpose is not included are skipped.
* A bad prim is logged (one line naming its path), skipped and listed in
  :attr:`UsdSceneDelegate.delegate_errors`; the rest of the stage syncs.
* :meth:`UsdSceneDelegate.watch` listens to ``Usd.Notice.ObjectsChanged``;
  the next :meth:`~UsdSceneDelegate.sync` re-walks resynced subtrees and
  re-sends only prims whose data, transform or material changed. A mesh whose
  transform alone changed is moved with ``set_transform`` (its points are not
  sent again); a moved instance or a PointInstancer whose instances changed
  re-sends only its instancer.
"""

from __future__ import annotations

import logging
import weakref
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom, UsdLux

from ..errors import PrimError, RenderSettingsError
from .camera import (
    DEFAULT_CAMERA_PATH,
    camera_arguments,
    find_camera_prim,
    framing_camera_arguments,
)
from .deform import changes_shape_in_shutter, deformation_samples
from .gprim import is_renderable_gprim
from .instancing import InstancerState, Instancing
from .light import (
    AREA_LIGHT_TYPES,
    CAMERA_LIGHT_PATH,
    area_light_arguments,
    camera_light_arguments,
    distant_light_arguments,
    emitter_arguments,
    geometry_light_targets,
    link_arguments,
    material_tints,
    mesh_light_arguments,
    portal_arguments,
)
from .mesh_sync import read_mesh
from .mtlx_files import load_mtlx_references
from .protocol import RenderDelegateLike
from .skel import SkelPoser
from .transform import ancestors_might_vary, camera_shutter, motion_samples, world_transform
from .unsupported import (
    GPRIM_DEFORMATION,
    HEADLIGHT,
    Unsupported,
    audit_stage,
    is_rendered_type,
    warn_unsupported,
)

__all__ = ["PURPOSES", "SyncError", "UsdSceneDelegate"]

_log = logging.getLogger(__name__)

#: Every purpose token UsdGeom defines.
PURPOSES = ("default", "render", "proxy", "guide")

# Property names whose change affects the prim and everything below it (xform
# ops too, tracked apart: they only move things).
_SUBTREE_DATA_PREFIXES = ("material:binding",)
# Property names whose change can add or remove prims from the render (a
# PointInstancer's prototypes: its members).
_TRAVERSAL_PROPERTIES = frozenset({"visibility", "purpose", "prototypes"})
# Where USD puts native-instance prototypes.
_PROTOTYPE_PREFIX = "/__Prototype"


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

    # "mesh", "camera", "light", "portal" (a PortalLight: guides domes, lights nothing),
    # "instancer" (PointInstancer) or "instance"
    kind: str
    order: int  # traversal order, to pick "the first camera"
    in_delegate: bool = True  # False for a mesh with no faces, and for instance prims
    might_vary: bool = False  # re-sync when the time changes
    xform_varies: bool = False  # its world transform might change with the time
    material_paths: tuple[str, ...] = ()
    args: dict[str, Any] = field(default_factory=dict)  # kept for cameras only
    instancer: InstancerState | None = None  # a PointInstancer's prototypes
    # A skinned mesh's posed world bounds (min, max); skinned meshes are re-read, not moved.
    posed_bounds: tuple[Any, Any] | None = None
    rigid: bool = False  # a rigidly deformed skinned mesh: its pose is a transform
    light: bool = False  # a mesh that is a light (MeshLightAPI)


_NO_RECORD = _Record("none", -1, in_delegate=False)


def _kind(prim: Usd.Prim) -> str:
    """The :class:`_Record` kind ``prim`` is synced as."""
    if prim.IsInstance():
        return "instance"
    if is_renderable_gprim(prim):
        return "mesh"
    if prim.IsA(UsdGeom.PointInstancer):
        return "instancer"
    if prim.IsA(UsdGeom.Camera):
        return "camera"
    if prim.IsA(UsdLux.PortalLight):
        return "portal"
    return "light"


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
        self._unsupported: list[Unsupported] = []
        self._headlight: list[Unsupported] = []  # lights the camera light stands in for
        # Mesh lights whose points move within the shutter (lit at the frame's time).
        self._in_shutter: list[Unsupported] = []
        self._warned_unsupported: set[Unsupported] = set()
        self._default_camera: dict[str, Any] | None = None
        # Meshes last sent a moving transform (set_motion), so one that stops moving is reset.
        self._moving: set[str] = set()
        # Meshes last sent points over the shutter (set_deformation), reset when they stop.
        self._deforming: set[str] = set()
        self._camera_light = False
        self._xform_roots: set[str] = set()  # where xform ops changed
        self._xform_only: set[str] = set()  # records whose transform alone changed in time
        self._instancer_full: set[str] = set()  # PointInstancers whose prototypes changed
        self._prototype_edits: set[str] = set()  # native prototypes edited inside
        # A weak reference: a bound method would make a cycle (self -> instancing -> self) that
        # keeps this delegate, its stage and the stage's layers alive until the collector runs,
        # so usd-core would hand the next Usd.Stage.Open of the same file the stale layer.
        gprim_paths = weakref.WeakMethod(self._gprim_paths)
        self._poser = SkelPoser()
        self._instancing = Instancing(
            delegate,
            self.purposes,
            self.sync_counts,
            mesh_paths=lambda: (gprim_paths() or list)(),
            poser=self._poser,
        )
        # Before anything is read: .mtlx references usd-core cannot compose.
        load_mtlx_references(stage)
        self._linked: set[str] = set()  # lights whose linking leaves some meshes out
        # GeometryLights and the meshes their ``geometry`` names (those meshes are lights).
        self._geometry_lights: dict[str, list[str]] = {}
        self._gprims: list[str] | None = None  # the stage's gprim paths, this sync

    # ------------------------------------------------------------------ state

    @property
    def delegate_errors(self) -> list[SyncError]:
        """The prims that currently fail to sync, in the order they failed.

        Prims inside instancing prototypes come last.
        """
        inside = [SyncError(p, m) for p, m in self._instancing.errors.items()]
        return [*self._errors.values(), *inside]

    @property
    def unsupported(self) -> list[Unsupported]:
        """What the rendered prims author that mipray does not render, as of the last sync.

        See :mod:`mipray.usd.unsupported`; the camera light standing in for unsupported
        lights is listed too.
        """
        return sorted((*self._unsupported, *self._headlight, *self._in_shutter))

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
        return [p for p, r in self._records.items() if r.kind == "light" or r.light]

    @property
    def is_dirty(self) -> bool:
        """Whether the next :meth:`sync` has anything to do."""
        return bool(
            self._full
            or self._resync
            or self._subtree_dirty
            or self._prim_dirty
            or self._xform_roots
            or self._xform_only
            or self._prototype_edits
        )

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
        if prim_path.startswith(_PROTOTYPE_PREFIX):
            if resynced:
                # Prototypes may be renumbered: walk the stage again.
                self._full = True
            else:
                # A value inside a native prototype: re-send that prototype's meshes.
                self._prototype_edits.add("/" + prim_path.split("/")[1])
            return
        parent = str(path.GetPrimPath().GetParentPath())
        if self._records.get(parent, _NO_RECORD).kind == "mesh":
            # A GeomSubset (its indices or its material binding) belongs to its mesh.
            self._prim_dirty.add(parent)
        if path.IsPropertyPath():
            name = path.name
            if name in _TRAVERSAL_PROPERTIES:
                self._resync.add(prim_path)
            elif name.startswith("xformOp"):
                self._xform_roots.add(prim_path)
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
            elif record.xform_varies:
                self._xform_only.add(path)
            if record.instancer is not None and record.instancer.members_might_vary:
                self._prim_dirty.add(path)
                self._instancer_full.add(path)
        for path in self._errors:
            self._prim_dirty.add(path)
        self._prototype_edits.update(self._instancing.varying_prototypes())
        for path, record in self._records.items():
            # Prototype meshes that failed may read fine at another time.
            if record.instancer is not None and record.instancer.member_prims & set(
                self._instancing.errors
            ):
                self._prim_dirty.add(path)
                self._instancer_full.add(path)

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
        changed = self.is_dirty
        self._gprims = None
        if any(not self.stage.GetPrimAtPath(p) for p in self._prototype_edits):
            self._full = True
        full = self._full
        self._instancing.begin_sync(self.time, xform_cache, unsupported, full=full)
        if not full:
            for prototype in sorted(self._prototype_edits):
                self._instancing.resend_native_prototype(self.stage, prototype)
        self._prototype_edits.clear()

        if full or self._resync:
            self._poser.clear()  # skeletons and bindings may have changed
        if full:
            self._order = 0
            roots = ["/"]
        else:
            roots = sorted(self._resync)
            roots = [r for i, r in enumerate(roots) if not any(_under(r, q) for q in roots[:i])]
        self._full = False
        self._resync.clear()

        for root in roots:
            self._resync_subtree(root, xform_cache, unsupported, synced_now)

        dirty, transform_only = self._dirty_records()
        memo: dict[str, bool] = {}
        for path in sorted(dirty - synced_now):
            prim = self.stage.GetPrimAtPath(path)
            if not prim:
                self._forget(path)
                continue
            record = self._records.get(path)
            order = record.order if record else self._next_order()
            members = path in self._instancer_full or record is None
            self._sync_prim(prim, xform_cache, memo, order, unsupported, members=members)
        for path in sorted(transform_only - dirty - synced_now):
            self._sync_transform(path, xform_cache)
        self._instancer_full.clear()
        self._instancing.end_sync(full=full)
        if changed:
            # Linking is resolved against the stage's meshes: those may have changed.
            for path in sorted(self._linked):
                prim, record = self.stage.GetPrimAtPath(path), self._records.get(path)
                if prim and record is not None:
                    self._sync_prim(prim, xform_cache, memo, record.order, unsupported)

        self._warn_unsupported(unsupported)
        if changed:
            self._unsupported = audit_stage(self.stage, self.time, self.purposes)
            warn_unsupported(self._unsupported, self._warned_unsupported)
        if changed and self._default_camera is not None:
            self._sync_default_camera()

    def _dirty_records(self) -> tuple[set[str], set[str]]:
        """Consume the recorded changes: (paths to re-read, paths whose transform alone changed).

        PointInstancers whose prototypes hold a changed prim (or use a changed
        material) are re-read with their prototypes (``_instancer_full``).
        """
        known = (*self._records, *self._errors)
        dirty: set[str] = set()
        moved: set[str] = set()
        for root in self._subtree_dirty:
            dirty.update(p for p in known if _under(p, root))
        for root in self._xform_roots:
            moved.update(p for p in known if _under(p, root))
        elsewhere: list[str] = []  # changed prims that are not synced ones
        for path in self._prim_dirty:
            if path in self._records or path in self._errors:
                dirty.add(path)
            else:
                elsewhere.append(path)
        instancers = {p: r.instancer for p, r in self._records.items() if r.instancer is not None}
        for path in (*elsewhere, *self._subtree_dirty, *self._xform_roots):
            # An edit inside a PointInstancer's prototype: re-send it, prototypes too.
            owners = self._instancing.owner_of(path, instancers)
            dirty.update(owners)
            self._instancer_full.update(owners)
        if elsewhere:
            # A changed skeleton or animation re-poses the skinned meshes.
            dirty.update(p for p, r in self._records.items() if r.posed_bounds is not None)
            # A changed material (or a shader under it) re-syncs the meshes bound to it.
            for p, r in self._records.items():
                if any(_under(m, q) or _under(q, m) for m in r.material_paths for q in elsewhere):
                    dirty.add(p)
                    if r.instancer is not None:
                        self._instancer_full.add(p)
        # Meshes only moved: set_transform; other moved prims are cheap to re-read.
        transform_only = {p for p in moved | self._xform_only if self._is_mesh_record(p)}
        dirty.update((moved | self._xform_only) - transform_only)
        self._subtree_dirty.clear()
        self._prim_dirty.clear()
        self._xform_roots.clear()
        self._xform_only.clear()
        return dirty, transform_only

    def _is_mesh_record(self, path: str) -> bool:
        record = self._records.get(path)
        return (
            record is not None
            and record.kind == "mesh"
            and record.in_delegate
            and record.posed_bounds is None  # a skinned mesh is placed by its skeleton
        )

    def _sync_transform(self, path: str, xform_cache: UsdGeom.XformCache) -> None:
        """Move a synced mesh: only its world transform is sent (``set_transform``)."""
        prim = self.stage.GetPrimAtPath(path)
        if not prim:
            self._forget(path)
            return
        try:
            self.delegate.set_transform(path, world_transform(xform_cache, prim))
        except (ValueError, TypeError, OverflowError) as exc:
            self._fail(path, str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
            return
        self.sync_counts[path] = self.sync_counts.get(path, 0) + 1
        _log.debug("mipray: moved mesh %s", path)

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
        owner = self._point_instancer_above(root)
        if owner is not None:
            # Inside a PointInstancer: its prims render only through it.
            if owner in self._records or owner in self._errors:
                self._prim_dirty.add(owner)
                self._instancer_full.add(owner)
            return
        if prim and (prim.IsPseudoRoot() or Usd.PrimDefaultPredicate(prim)):
            # Not below a class, an over or an inactive prim, nor inside an instance.
            if not prim.IsInstanceProxy():
                self._walk(prim, xform_cache, seen, unsupported)
        for path in [p for p in (*self._records, *self._errors) if _under(p, root)]:
            if path not in seen:
                self._forget(path)
        # Materials under the resynced root may have changed: their meshes too.
        for path, record in list(self._records.items()):
            if path not in seen and any(_under(m, root) for m in record.material_paths):
                self._prim_dirty.add(path)
                if record.instancer is not None:
                    self._instancer_full.add(path)
        synced_now.update(seen)

    def _point_instancer_above(self, path: str) -> str | None:
        """The nearest PointInstancer strictly above prim path ``path``, if any.

        ``path`` itself may be gone from the stage (a removed prim).
        """
        parent = Sdf.Path(path).GetParentPath()
        while not parent.isEmpty and parent != Sdf.Path.absoluteRootPath:
            prim = self.stage.GetPrimAtPath(parent)
            if prim and prim.IsA(UsdGeom.PointInstancer):
                return str(parent)
            parent = parent.GetParentPath()
        return None

    def _walk(
        self,
        root: Usd.Prim,
        xform_cache: UsdGeom.XformCache,
        seen: set[str],
        unsupported: Counter[str],
    ) -> None:
        """Depth-first walk from ``root``, inheriting visibility and purpose.

        Instance prims and PointInstancers are synced as instancers; the walk
        does not go below them (their prototypes render through them).
        """
        predicate = Usd.PrimDefaultPredicate
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
            included = info.purpose in self.purposes
            if prim.IsInstance():
                # Its prototype's purposes start from the default: an instance whose
                # own purpose is not rendered is left out whole.
                if included:
                    seen.add(str(prim.GetPath()))
                    self._sync_prim(prim, xform_cache, memo, self._next_order(), unsupported)
                continue
            if imageable and included and self._is_supported(prim, unsupported):
                seen.add(str(prim.GetPath()))
                self._sync_prim(prim, xform_cache, memo, self._next_order(), unsupported)
            if prim.IsA(UsdGeom.PointInstancer):
                continue  # its children render only through it
            children = prim.GetFilteredChildren(predicate)
            stack.extend((c, info) for c in reversed(children))

    def _is_supported(self, prim: Usd.Prim, unsupported: Counter[str]) -> bool:
        """Whether ``prim`` is synced; counts renderable prims of unsupported types."""
        if is_rendered_type(prim):
            return True
        if prim.IsA(UsdGeom.Gprim) or prim.HasAPI(UsdLux.LightAPI):
            unsupported[prim.GetTypeName() or "untyped"] += 1
        return False

    def _sync_prim(
        self,
        prim: Usd.Prim,
        xform_cache: UsdGeom.XformCache,
        memo: dict[str, bool],
        order: int,
        unsupported: Counter[str],
        *,
        members: bool = True,
    ) -> None:
        """Read one prim and send it to the delegate; record a failure instead of raising.

        For a PointInstancer synced before, ``members=False`` re-sends only its
        instances, not its prototypes.
        """
        path = str(prim.GetPath())
        time = self.time
        try:
            transform = world_transform(xform_cache, prim)
            xform_varies = ancestors_might_vary(prim, memo)
            data_varies = any(
                a.ValueMightBeTimeVarying()
                for a in prim.GetAuthoredAttributes()
                if not a.GetName().startswith("xformOp")
            )
            might_vary = xform_varies or data_varies
            previous = self._records.get(path)
            if previous is not None and previous.kind != _kind(prim):
                self._forget(path)  # its type changed: drop what the old kind sent
                previous = None
            if prim.IsInstance():
                bound = self._instancing.add_instance(
                    path, prim.GetPrototype(), transform, might_move=xform_varies
                )
                record = _Record(
                    "instance",
                    order,
                    in_delegate=False,
                    xform_varies=xform_varies,
                    material_paths=bound,
                )
            elif is_renderable_gprim(prim):
                read = read_mesh(prim, time, transform, poser=self._poser)
                record = _Record(
                    "mesh",
                    order,
                    might_vary=read.might_vary,
                    xform_varies=xform_varies,
                    material_paths=read.material_paths,
                    posed_bounds=read.posed_bounds,
                    rigid=read.rigid,
                )
                if read.args is None:  # no faces: valid USD that renders nothing
                    self._forget(path)
                    record.in_delegate = False
                    self._records[path] = record
                    return
                light, light_prim = mesh_light_arguments(prim, time), prim
                owner = self._geometry_light_of(path)
                if light is None and owner is not None:
                    light_prim = self.stage.GetPrimAtPath(owner)
                    light = emitter_arguments(light_prim, time)
                if light is not None:
                    links = link_arguments(light_prim, time, self._gprim_paths)
                    tints = material_tints(prim, light_prim, read.args, time)
                    read.args["light"] = {**light, **links, **tints}
                    record.light = True
                    record.might_vary = might_vary or record.might_vary
                self.delegate.set_mesh(path, **read.args)
                self._track_links(path, links if light is not None else {})
            elif prim.IsA(UsdGeom.PointInstancer):
                state, own_varies = self._instancing.sync_point_instancer(
                    prim,
                    transform,
                    previous.instancer if previous is not None else None,
                    members=members,
                )
                record = _Record(
                    "instancer",
                    order,
                    might_vary=own_varies,
                    xform_varies=xform_varies,
                    material_paths=state.material_paths,
                    instancer=state,
                )
            elif prim.IsA(UsdGeom.Camera):
                args = camera_arguments(UsdGeom.Camera(prim), time, transform)
                record = _Record("camera", order, might_vary=might_vary, args=args)
                self.delegate.set_camera(path, **args)
            elif prim.IsA(UsdLux.DistantLight):
                args = distant_light_arguments(UsdLux.DistantLight(prim), time, transform)
                links = link_arguments(prim, time, self._gprim_paths)
                record = _Record("light", order, might_vary=might_vary)
                self.delegate.set_distant_light(path, **{**args, **links})
                self._track_links(path, links)
            elif prim.IsA(UsdLux.GeometryLight):
                # No prim of its own in the delegate: its meshes are the light. Re-synced
                # whenever the stage changes (with the linked lights), it re-sends the meshes
                # it names now and those it named before.
                before = self._geometry_lights.get(path, [])
                self._geometry_lights[path] = geometry_light_targets(prim)
                record = _Record("light", order, might_vary=might_vary, in_delegate=False)
                self._linked.add(path)
                self._resync_meshes([*before, *self._geometry_lights[path]], xform_cache, memo)
            elif prim.IsA(UsdLux.PortalLight):
                args = portal_arguments(prim, time, transform)
                record = _Record("portal", order, might_vary=might_vary)
                self.delegate.set_light(path, **args)
            elif any(prim.IsA(t) for t, _ in AREA_LIGHT_TYPES):
                args = area_light_arguments(prim, time, transform) or {}
                links = link_arguments(prim, time, self._gprim_paths)
                record = _Record("light", order, might_vary=might_vary)
                self.delegate.set_light(path, **{**args, **links})
                self._track_links(path, links)
            else:
                # Its type changed to one we do not render.
                self._is_supported(prim, unsupported)
                self._forget(path)
                return
        except PrimError as exc:
            # A GeomSubset's problem names the subset, not the mesh.
            self._fail(path, exc.reason if exc.prim_path == path else str(exc))
            return
        except (ValueError, TypeError, OverflowError) as exc:
            # The delegate refused the data (its message names the path).
            self._fail(path, str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
            return
        self._records[path] = record
        self._errors.pop(path, None)
        self.sync_counts[path] = self.sync_counts.get(path, 0) + 1
        _log.debug("mipray: synced %s %s", record.kind, path)

    def _geometry_light_of(self, mesh: str) -> str | None:
        """The GeometryLight whose ``geometry`` names ``mesh`` (the first by path), if any."""
        owners = sorted(light for light, meshes in self._geometry_lights.items() if mesh in meshes)
        return owners[0] if owners else None

    def _resync_meshes(
        self,
        paths: Iterable[str],
        xform_cache: UsdGeom.XformCache | None = None,
        memo: dict[str, bool] | None = None,
    ) -> None:
        """Send the synced meshes among ``paths`` again (a GeometryLight's, as it changes)."""
        xform_cache = xform_cache or UsdGeom.XformCache(self.time)
        for mesh in sorted(set(paths)):
            prim, record = self.stage.GetPrimAtPath(mesh), self._records.get(mesh)
            if prim and record is not None and record.kind == "mesh":
                self._sync_prim(
                    prim, xform_cache, {} if memo is None else memo, record.order, Counter()
                )

    def _gprim_paths(self) -> list[str]:
        """Every gprim on the stage (PointInstancer prototypes' included), once per sync."""
        if self._gprims is None:
            self._gprims = [
                str(p.GetPath())
                for p in Usd.PrimRange(self.stage.GetPseudoRoot())
                if p.IsA(UsdGeom.Gprim)
            ]
        return self._gprims

    def _track_links(self, path: str, links: dict[str, list[str]]) -> None:
        if links:
            self._linked.add(path)
        else:
            self._linked.discard(path)

    def _fail(self, path: str, message: str) -> None:
        error = SyncError(path, message)
        _log.error("mipray: skipping %s", error)
        self._forget(path)
        self._errors[path] = error

    def _forget(self, path: str) -> None:
        """Remove a prim from the delegate and from the books."""
        record = self._records.pop(path, None)
        self._moving.discard(path)
        self._linked.discard(path)
        if path in self._geometry_lights:
            # Its meshes are surfaces again.
            self._resync_meshes(self._geometry_lights.pop(path))
        if record is not None and record.kind == "instance":
            self._instancing.remove_instance(path)
        elif record is not None and record.instancer is not None:
            self._instancing.forget_point_instancer(path, record.instancer)
        elif record is not None and record.in_delegate:
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

    def update_motion(self, camera_path: str) -> list[str]:
        """Send the world transform over ``camera_path``'s shutter of every mesh that moves in it.

        Transform motion blur: only meshes whose transform (or an ancestor's) is
        time-varying are sampled, and only when the camera's shutter is open for
        a while; a mesh that no longer moves gets its motion cleared. Returns the
        paths of the moving meshes. A rigidly deformed skinned mesh moves by its posed
        transform (:meth:`mipray.usd.skel.SkelPoser.rigid_motion`); a mesh whose points move
        (time-sampled, or skinned) gets its points over the shutter too, and counts as moving
        (:mod:`mipray.usd.deform`). PointInstancers and native instances that move get
        their instances' transforms over the shutter too
        (:meth:`mipray.usd.instancing.Instancing.update_motion`; their paths are not in
        the list).
        """
        shutter = camera_shutter(self.stage, camera_path, self.time)
        moving: list[str] = []
        self._in_shutter = []
        for path, record in self._records.items():
            if record.kind != "mesh" or not record.in_delegate:
                continue
            samples = None
            if record.rigid and shutter[1] > shutter[0]:
                prim = self.stage.GetPrimAtPath(path)
                if prim:
                    rest = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(self.time) or [])
                    points = rest.astype(np.float32).reshape(-1, 3)
                    samples = self._poser.rigid_motion(prim, self.time, shutter, points)
            elif record.xform_varies and shutter[1] > shutter[0]:
                prim = self.stage.GetPrimAtPath(path)
                if prim:
                    samples = motion_samples(prim, self.time, shutter)
            if samples is not None:
                self.delegate.set_motion(path, samples[0], samples[1])
                moving.append(path)
            elif path in self._moving:
                self.delegate.set_motion(
                    path, np.zeros(0, dtype=np.float32), np.zeros((0, 4, 4), dtype=np.float64)
                )
            if self._update_deformation(path, record, shutter) and path not in moving[-1:]:
                moving.append(path)
        self._moving = set(moving)
        self._instancing.update_motion(self.time, shutter)
        warn_unsupported(self._in_shutter, self._warned_unsupported)
        return moving

    def _update_deformation(self, path: str, record: _Record, shutter: tuple[float, float]) -> bool:
        """Send the mesh at ``path``'s points over the shutter when they move in it.

        Deformation motion blur (:mod:`mipray.usd.deform`): point-animated and skinned
        meshes (mesh lights too: their light is blended at each ray's time as their surface is),
        moving Points and curves (their widths too). A prim whose points stop moving gets its
        samples cleared. Returns whether the mesh deforms.
        """
        samples = None
        if record.might_vary and not record.rigid and shutter[1] > shutter[0]:
            prim = self.stage.GetPrimAtPath(path)
            if prim:
                samples = deformation_samples(prim, self.time, shutter, self._poser)
                if samples is None and changes_shape_in_shutter(prim, self.time, shutter):
                    self._in_shutter.append(Unsupported(path, GPRIM_DEFORMATION))
        if samples is not None:
            try:
                self.delegate.set_deformation(path, *samples)
            except PrimError as exc:
                _log.warning(
                    "mipray: %s; rendering it at the frame's time without motion blur", exc
                )
                samples = None
        if samples is None and path in self._deforming:
            self.delegate.set_deformation(
                path, np.zeros(0, dtype=np.float32), np.zeros((0, 0, 3), dtype=np.float32)
            )
        if samples is None:
            self._deforming.discard(path)
            return False
        self._deforming.add(path)
        return True

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
                data is unusable; or, with none requested, the camera that
                would be chosen (``main_cam``, else the stage's only ones)
                is unusable.

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
        # A stage camera that could not be read is the one meant, not a reason to frame the
        # stage with a camera of our own: say what is wrong with it.
        broken = sorted(p for p in self._errors if self.stage.GetPrimAtPath(p).IsA(UsdGeom.Camera))
        broken_main = [p for p in broken if Sdf.Path(p).name == "main_cam"]
        if (broken_main and not named) or (broken and not cameras):
            path = (broken_main or broken)[0]
            raise PrimError(path, f"cannot render through it: {self._errors[path].message}")
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
        posed = {p: r.posed_bounds for p, r in self._records.items() if r.posed_bounds is not None}
        args = framing_camera_arguments(self.stage, self.time, self.purposes, posed)
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
        self._headlight = []
        if want:
            # Lights of types mipray does not render leave the stage lit by the headlight.
            self._headlight = [
                Unsupported(u.prim, HEADLIGHT)
                for u in self._unsupported
                if u.what.startswith("prim type")
                and self.stage.GetPrimAtPath(u.prim).HasAPI(UsdLux.LightAPI)
            ]
            warn_unsupported(self._headlight, self._warned_unsupported)
            transform = self.cameras[camera_path]["transform"]
            self.delegate.set_distant_light(CAMERA_LIGHT_PATH, **camera_light_arguments(transform))
            if not self._camera_light:
                _log.info("mipray: the stage has no light; lighting it from the camera")
        elif self._camera_light:
            self.delegate.remove(CAMERA_LIGHT_PATH)
        self._camera_light = want
        return want
