"""Instancing: ``UsdGeom.PointInstancer`` and native instances, prototypes shared.

A prototype's meshes are sent to the render delegate once, with
``prototype=True`` and transforms relative to the prototype's root; an
instancer (``set_instancer``) then places them. The delegate keeps one core
mesh per prototype mesh however many instances there are, so instances share
the prototype's subpatches and its geometry cache entries (DESIGN.md, "Data
flow", step 4).

* **PointInstancer** ``/PI``: an instancer at ``/PI`` whose prototypes are the
  meshes under each prototype root (``prototypes`` targets), each placed at
  ``protoIndices``, ``positions``, ``orientations`` and ``scales`` (the root's
  own transform included, as ``ComputeInstanceTransformsAtTime`` does),
  ``invisibleIds`` and inactive ids masked out. Meshes under a root below the
  PointInstancer keep their paths; a root elsewhere on the stage (it may also
  render in place) is sent under ``/PI.proto<i>`` so the two never collide.
  Children of a PointInstancer never render in place (as in UsdImaging).
* **Native instances**: one instancer per prototype, at the prototype's path
  (``/__Prototype_1``), placing its meshes at every instance prim's world
  transform.
* **Nesting**: a PointInstancer or an instance inside a prototype becomes an
  instancer with ``prototype=True`` inside its parent prototype.

* **Motion**: when the camera's shutter is open, :meth:`Instancing.update_motion`
  sends each instancer whose instances move within it their transforms over the
  shutter (``set_instancer_motion``): a PointInstancer's from usd-core's
  ``ComputeInstanceTransformsAtTimes`` (time-sampled positions, orientations and
  scales; velocities and angular velocities) and its own transform, a native
  instance's from its xform, nested ones relative to their prototype's root.
  Instancers nothing moves in send nothing. A prototype mesh whose points move
  within the shutter (time-sampled, ``velocities``, skinned: :mod:`mipray.usd.deform`)
  is sent them (``set_deformation``), in its object space, so it deforms in every
  instance; a prototype mesh light's are not (listed as unsupported by the scene
  delegate).

Visibility and purpose are applied inside prototypes, starting from the
prototype root. A mesh inside a prototype that cannot be read is reported
(naming it) and left out; the rest of the prototype renders.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom, UsdShade

from ..errors import PrimError
from .deform import deformation_samples
from .gprim import is_renderable_gprim
from .light import link_arguments, material_tints, mesh_light_arguments
from .mesh_sync import read_mesh
from .protocol import RenderDelegateLike
from .shading import bound_material
from .skel import SkelPoser
from .transform import ancestors_might_vary, matrix_to_numpy, shutter_times, world_transform

__all__ = [
    "InstancerState",
    "Instancing",
    "PointInstancerArrays",
    "read_point_instancer",
]

_log = logging.getLogger(__name__)

_EMPTY_XFORMS = np.zeros((0, 4, 4), np.float64)


@dataclass(frozen=True)
class PointInstancerArrays:
    """A PointInstancer's instances at one time code, masked and checked."""

    #: The prototype root prims, in ``prototypes`` order.
    roots: list[Usd.Prim]
    #: (N,) int32 index into ``roots`` per visible instance.
    proto_indices: NDArray[np.int32]
    #: (N, 4, 4) float64 prototype-root-to-instancer transforms (USD row-vector
    #: layout), the root's own transform included.
    transforms: NDArray[np.float64]
    #: Whether any of the instancer's own attributes might change over time.
    might_vary: bool


def _check_per_instance(
    path: str, name: str, value: Any, n: int, *, required: bool
) -> NDArray[np.float64] | None:
    """A per-instance array attribute, checked for size and finiteness."""
    if value is None or len(value) == 0:
        if required and n:
            raise PrimError(path, f"{name} is empty but protoIndices has {n} entries")
        return None
    array = np.asarray(value, dtype=np.float64).reshape(len(value), -1)
    if len(array) != n:
        raise PrimError(path, f"{name} has {len(array)} entries but protoIndices has {n}")
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise PrimError(path, f"{name}[{i}] = {tuple(array[i].tolist())} is not finite")
    return array


#: The prims of a prototype that render: active, loaded and not abstract, but not required to
#: be defined. A PointInstancer's prototypes are often kept under an ``over`` so that they are
#: not drawn where they stand, only through the instancer; UsdImaging populates them with the
#: same predicate (OpenUSD's testUsdImagingGLPointInstancer/pi_sibling_pi_over).
_PROTOTYPE_PREDICATE = Usd.PrimIsActive & Usd.PrimIsLoaded & ~Usd.PrimIsAbstract


def read_point_instancer(pi: UsdGeom.PointInstancer, time: Usd.TimeCode) -> PointInstancerArrays:
    """Read and check a PointInstancer's instances at ``time``.

    Raises:
        PrimError: a prototype target that is not a prim, a protoIndex out of
            range, per-instance arrays whose sizes disagree, or values that
            are not finite; the message names the PointInstancer.

    """
    path = str(pi.GetPath())
    stage = pi.GetPrim().GetStage()
    targets = pi.GetPrototypesRel().GetForwardedTargets()
    roots = []
    for i, target in enumerate(targets):
        root = stage.GetPrimAtPath(target)
        if not root:
            raise PrimError(path, f"prototypes[{i}] <{target}> is not a prim on the stage")
        roots.append(root)
    indices = np.asarray(pi.GetProtoIndicesAttr().Get(time) or [], dtype=np.int64)
    n = len(indices)
    bad = (indices < 0) | (indices >= len(roots))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise PrimError(
            path,
            f"protoIndices[{i}] = {int(indices[i])} is out of range for {len(roots)} prototypes",
        )
    _check_per_instance(path, "positions", pi.GetPositionsAttr().Get(time), n, required=True)
    _check_per_instance(path, "orientations", pi.GetOrientationsAttr().Get(time), n, required=False)
    _check_per_instance(
        path, "orientationsf", pi.GetOrientationsfAttr().Get(time), n, required=False
    )
    _check_per_instance(path, "scales", pi.GetScalesAttr().Get(time), n, required=False)
    might_vary = any(a.ValueMightBeTimeVarying() for a in pi.GetPrim().GetAuthoredAttributes())
    if n == 0:
        return PointInstancerArrays(roots, np.zeros(0, np.int32), _EMPTY_XFORMS, might_vary)
    xforms = pi.ComputeInstanceTransformsAtTime(time, time)
    mask = pi.ComputeMaskAtTime(time)
    if mask:
        indices = indices[np.asarray(mask, dtype=bool)]
    if len(xforms) != len(indices):
        raise PrimError(path, "the instance transforms cannot be computed (see USD's warning)")
    transforms = np.asarray(xforms, dtype=np.float64).reshape(-1, 4, 4)
    return PointInstancerArrays(roots, indices.astype(np.int32), transforms, might_vary)


@dataclass
class InstancerState:
    """What the scene delegate keeps about one synced PointInstancer."""

    #: Prototype root paths (USD), to route edits below them to this instancer.
    roots: tuple[str, ...] = ()
    #: Per root, the delegate paths of its members (meshes, nested instancers).
    groups: list[list[str]] = field(default_factory=list)
    #: Every delegate path this instancer registered, its own included.
    owned: set[str] = field(default_factory=set)
    #: Materials bound to member meshes.
    material_paths: tuple[str, ...] = ()
    #: Whether member meshes might change over time (then a time change
    #: re-sends them, not only the instances).
    members_might_vary: bool = False
    #: USD paths of member prims that were read (for the scene delegate's books).
    member_prims: set[str] = field(default_factory=set)


@dataclass
class _Walk:
    """What collecting one instancer's prototypes gathers."""

    owner: str
    time: Usd.TimeCode
    xform_cache: UsdGeom.XformCache
    unsupported: Counter[str]
    owned: set[str] = field(default_factory=set)
    material_paths: set[str] = field(default_factory=set)
    might_vary: bool = False
    member_prims: set[str] = field(default_factory=set)
    #: (delegate path, USD path) of each gprim member sent.
    gprims: list[tuple[str, str]] = field(default_factory=list)
    #: The PointInstancers being expanded, outermost first: one met again is a cycle.
    expanding: set[str] = field(default_factory=set)


#: The materials bound to a gprim and to each of its materialBind GeomSubsets.
_Bindings = tuple[str, ...]
#: (path below the prototype, material bindings, skeleton and animation) of the gprims an
#: instance sees bound differently: other materials, or (a skinned mesh) another skeleton or
#: animation than the prototype's pose, which is its first instance's (``("", "")`` if same).
_Variant = tuple[tuple[str, _Bindings, tuple[str, str]], ...]


def _bindings(prim: Usd.Prim) -> _Bindings:
    """The paths of the materials bound to ``prim`` and its materialBind subsets ("" for none)."""
    owners = [
        prim,
        *(s.GetPrim() for s in UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()),
    ]
    out = []
    for owner in owners:
        material = bound_material(owner)
        out.append(str(material.GetPath()) if material is not None else "")
    return tuple(out)


def _expand(
    groups: list[list[str]], proto_indices: NDArray[np.int32], transforms: NDArray[np.float64]
) -> tuple[list[str], NDArray[np.int32], NDArray[np.float64]]:
    """Per-root instances → per-member instances: root r with k members becomes k placements."""
    flat: list[str] = []
    first: list[int] = []
    for members in groups:
        first.append(len(flat))
        flat.extend(members)
    sizes = np.array([len(m) for m in groups], dtype=np.int64)
    if not flat or len(proto_indices) == 0:
        return flat, np.zeros(0, np.int32), _EMPTY_XFORMS
    per_instance = sizes[proto_indices]
    keep = per_instance > 0
    proto_indices, transforms, per_instance = (
        proto_indices[keep],
        transforms[keep],
        per_instance[keep],
    )
    starts = np.asarray(first, dtype=np.int64)[proto_indices]
    # Instance i contributes members starts[i], starts[i] + 1, ..., starts[i] + per_instance[i] - 1.
    offsets = np.arange(int(per_instance.sum())) - np.repeat(
        np.cumsum(per_instance) - per_instance, per_instance
    )
    indices = np.repeat(starts, per_instance) + offsets
    return flat, indices.astype(np.int32), np.repeat(transforms, per_instance, axis=0)


class Instancing:
    """Sends instancers and their prototypes to a render delegate, and keeps the books.

    Owned by :class:`~mipray.usd.scene_delegate.UsdSceneDelegate`, which calls
    it for every PointInstancer and instance prim it walks.

    Args:
        delegate: the render delegate.
        purposes: the purposes rendered.
        sync_counts: the scene delegate's counts, path → sends.
        poser: poses skinned meshes inside prototypes (one is made if None).

    """

    def __init__(
        self,
        delegate: RenderDelegateLike,
        purposes: tuple[str, ...],
        sync_counts: dict[str, int],
        mesh_paths: Callable[[], Iterable[str]] | None = None,
        poser: SkelPoser | None = None,
    ) -> None:
        self.delegate = delegate
        self.purposes = purposes
        self.sync_counts = sync_counts
        #: Every gprim path of the stage, for a prototype mesh light's linking collections.
        self.mesh_paths = mesh_paths
        #: Member prims that could not be read: USD path → message.
        self.errors: dict[str, str] = {}
        self._holders: dict[str, set[str]] = {}  # delegate path → owners holding it
        self._native_members: dict[str, list[str]] = {}  # prototype path → member paths
        self._native_owned: dict[str, set[str]] = {}
        self._native_vary: set[str] = set()  # prototypes whose members might change in time
        self._groups: dict[str, dict[str, NDArray[np.float64]]] = {}  # prototype → instances
        self._instance_of: dict[str, str] = {}  # instance prim path → prototype path
        self._dirty_groups: set[str] = set()
        # Per native prototype: (path below the prototype, bindings there) per gprim member.
        self._native_bindings: dict[str, list[tuple[str, _Bindings]]] = {}
        # Per instance prim: the members whose bindings differ through it (its variant).
        self._variant_of: dict[str, _Variant] = {}
        self._variant_owned: dict[str, set[str]] = {}  # prototype → variant paths held
        self._referenced: set[str] = set()
        self._stage: Usd.Stage | None = None
        self._binding_memo: dict[str, bool] = {}  # prim path → binds (see _binds_above)
        self._context: tuple[Usd.TimeCode, UsdGeom.XformCache, Counter[str]] | None = None
        # What each instancer last sent places, by delegate path, for its motion over the
        # shutter: a PointInstancer's USD path, the prototype root it is placed relative to
        # (None at the top level: world) and its member groups; a native (or variant)
        # instancer's instance prims, their transforms at the frame's time and its member
        # count; an instance inside a prototype: its USD path, the root's and member count.
        self._sent_points: dict[str, tuple[str, str | None, list[list[str]]]] = {}
        self._sent_native: dict[str, tuple[list[str], NDArray[np.float64], int]] = {}
        self._sent_nested: dict[str, tuple[str, str, int]] = {}
        # Each prototype mesh sent: its USD path and its prototype root's (its own motion there).
        self._sent_members: dict[str, tuple[str, str]] = {}
        self._moving_members: set[str] = set()  # prototype meshes last sent motion
        # Prototype meshes whose points might move within a shutter (time-sampled points,
        # velocities, skinning, a rigidly skinned mesh's pose), and
        # those last sent points over the shutter (set_deformation); mesh lights too.
        self._might_deform: set[str] = set()
        self._deforming: set[str] = set()
        # Poses prototypes' skinned meshes (the scene delegate's, cleared with its own).
        self._poser = poser or SkelPoser()
        self._moving: set[str] = set()  # instancers last sent motion
        self._might_move: set[str] = set()  # native instance prims whose transform might vary

    # ------------------------------------------------------------ bookkeeping

    def _hold(self, owner: str, path: str, owned: set[str]) -> None:
        self._holders.setdefault(path, set()).add(owner)
        owned.add(path)

    def _release(self, owner: str, paths: set[str]) -> None:
        for path in paths:
            holders = self._holders.get(path)
            if holders is None:
                continue
            holders.discard(owner)
            if not holders:
                del self._holders[path]
                self.delegate.remove(path)

    def _count(self, path: str) -> None:
        self.sync_counts[path] = self.sync_counts.get(path, 0) + 1

    def _fail(self, prim_path: str, exc: Exception) -> None:
        """Record why a prim inside a prototype was left out (one line, naming it)."""
        if isinstance(exc, PrimError) and exc.prim_path == prim_path:
            message = exc.reason
        else:
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            message = text.removeprefix(f"{prim_path}: ")
        self.errors[prim_path] = message
        _log.error("mipray: skipping %s: %s", prim_path, message)

    # ------------------------------------------------------------- prototypes

    def _collect(self, root: Usd.Prim, prefix: str, walk: _Walk) -> list[str]:
        """Send the renderable prims of the prototype at ``root``; return their delegate paths."""
        root_path = str(root.GetPath())
        members: list[str] = []
        time = walk.time
        # The purpose the root inherits: its nearest imageable ancestor's.
        start = UsdGeom.Imageable.PurposeInfo()
        parent = root.GetParent()
        while parent and not parent.IsPseudoRoot():
            if UsdGeom.Imageable(parent):
                start = UsdGeom.Imageable(parent).ComputePurposeInfo()
                break
            parent = parent.GetParent()
        stack: list[tuple[Usd.Prim, Any]] = [(root, start)]
        while stack:
            prim, info = stack.pop()
            path = str(prim.GetPath())
            dpath = prefix + path[len(root_path) :]
            imageable = UsdGeom.Imageable(prim)
            if imageable:
                if imageable.GetVisibilityAttr().Get(time) == UsdGeom.Tokens.invisible:
                    continue  # invisibility is inherited: prune the subtree
                info = imageable.ComputePurposeInfo(info)
            # Purpose is not pruning: a descendant may author one that is rendered.
            included = info.purpose in self.purposes
            if prim.IsInstance():
                if included and self._nested_native(prim, root, dpath, walk):
                    members.append(dpath)
                continue
            if prim.IsA(UsdGeom.PointInstancer):
                if included and self._nested_point_instancer(prim, root, dpath, walk):
                    members.append(dpath)
                continue  # its children render only through it
            if included and is_renderable_gprim(prim):
                if self._prototype_mesh(prim, root, dpath, walk):
                    members.append(dpath)
            elif included and prim.IsA(UsdGeom.Gprim):
                walk.unsupported[prim.GetTypeName() or "untyped"] += 1
            children = prim.GetFilteredChildren(_PROTOTYPE_PREDICATE)
            stack.extend((c, info) for c in reversed(children))
        return members

    def _relative(self, prim: Usd.Prim, root: Usd.Prim, walk: _Walk) -> NDArray[np.float64]:
        matrix, _ = walk.xform_cache.ComputeRelativeTransform(prim, root)
        return matrix_to_numpy(matrix)

    def _prototype_mesh(self, prim: Usd.Prim, root: Usd.Prim, dpath: str, walk: _Walk) -> bool:
        path = str(prim.GetPath())
        walk.member_prims.add(path)
        try:
            read = read_mesh(
                prim,
                walk.time,
                self._relative(prim, root, walk),
                prototype=True,
                poser=self._poser,
                root=root,
            )
            if read.args is None:
                return False
            # A mesh light in a prototype emits from every instance, linked as resolved now.
            light = mesh_light_arguments(prim, walk.time)
            if light is not None:
                tints = material_tints(prim, prim, read.args, walk.time)
                links = link_arguments(prim, walk.time, self.mesh_paths or (lambda: []))
                read.args["light"] = {**light, **links, **tints}
            self.delegate.set_mesh(dpath, **read.args)
            self._sent_members[dpath] = (path, str(root.GetPath()))
            if read.might_vary:
                # A rigidly skinned prototype mesh too: its pose over the shutter moves its
                # points (deform._skinned), as the prototype holds no transform motion of it.
                self._might_deform.add(dpath)
            else:
                self._might_deform.discard(dpath)
        except (PrimError, ValueError, TypeError, OverflowError) as exc:
            self._fail(path, exc)
            return False
        self.errors.pop(path, None)
        walk.material_paths.update(read.material_paths)
        walk.might_vary = walk.might_vary or read.might_vary
        walk.gprims.append((dpath, path))
        self._hold(walk.owner, dpath, walk.owned)
        self._count(dpath)
        return True

    def _nested_point_instancer(
        self, prim: Usd.Prim, root: Usd.Prim, dpath: str, walk: _Walk
    ) -> bool:
        path = str(prim.GetPath())
        walk.member_prims.add(path)
        try:
            if path in walk.expanding:
                raise PrimError(path, "its prototypes hold this PointInstancer itself (a cycle)")
            arrays = read_point_instancer(UsdGeom.PointInstancer(prim), walk.time)
            walk.expanding.add(path)
            try:
                groups = [
                    self._collect(r, self._root_prefix(path, dpath, i, r), walk)
                    for i, r in enumerate(arrays.roots)
                ]
            finally:
                walk.expanding.discard(path)
            flat, indices, transforms = _expand(
                groups, arrays.proto_indices, arrays.transforms @ self._relative(prim, root, walk)
            )
            self.delegate.set_instancer(
                dpath, prototypes=flat, proto_indices=indices, transforms=transforms, prototype=True
            )
            self._sent_points[dpath] = (path, str(root.GetPath()), groups)
        except (PrimError, ValueError, TypeError, OverflowError) as exc:
            self._fail(path, exc)
            return False
        self.errors.pop(path, None)
        walk.might_vary = walk.might_vary or arrays.might_vary
        self._hold(walk.owner, dpath, walk.owned)
        self._count(dpath)
        return True

    def _nested_native(self, prim: Usd.Prim, root: Usd.Prim, dpath: str, walk: _Walk) -> bool:
        members = self._native(prim.GetPrototype())
        if not members:
            return False
        k = len(members)
        placement = self._relative(prim, root, walk)
        self.delegate.set_instancer(
            dpath,
            prototypes=members,
            proto_indices=np.arange(k, dtype=np.int32),
            transforms=np.repeat(placement[None], k, axis=0),
            prototype=True,
        )
        self._sent_nested[dpath] = (str(prim.GetPath()), str(root.GetPath()), k)
        self._hold(walk.owner, dpath, walk.owned)
        self._count(dpath)
        return True

    @staticmethod
    def _root_prefix(pi_path: str, pi_dpath: str, index: int, root: Usd.Prim) -> str:
        """Delegate path prefix of prototype root ``root`` of the PointInstancer at ``pi_path``."""
        root_path = str(root.GetPath())
        if root_path.startswith(pi_path + "/"):
            return pi_dpath + root_path[len(pi_path) :]
        return f"{pi_dpath}.proto{index}"

    def _native(self, prototype: Usd.Prim) -> list[str]:
        """The members of native prototype ``prototype``, sent on first use."""
        path = str(prototype.GetPath())
        self._stage = prototype.GetStage()
        self._referenced.add(path)
        if path not in self._native_members:
            self._resend_native(prototype)
        return self._native_members[path]

    def _resend_native(self, prototype: Usd.Prim) -> None:
        assert self._context is not None, "begin_sync() first"
        time, xform_cache, unsupported = self._context
        path = str(prototype.GetPath())
        walk = _Walk(path, time, xform_cache, unsupported)
        self._native_members[path] = []  # guards against re-entry
        members = self._collect(prototype, path, walk)
        old = self._native_owned.get(path, set())
        if path in old:  # the instancer itself stays held
            self._hold(path, path, walk.owned)
        self._release(path, old - walk.owned)
        self._native_members[path] = members
        self._native_owned[path] = walk.owned
        self._native_bindings[path] = [
            (usd_path[len(path) :], _bindings(prototype.GetStage().GetPrimAtPath(usd_path)))
            for _, usd_path in walk.gprims
        ]
        stage = prototype.GetStage()
        for instance_path in self._groups.get(path, {}):
            instance = stage.GetPrimAtPath(instance_path)
            if instance:
                self._variant_of[instance_path] = self._variant(instance, path)
        if walk.might_vary:
            self._native_vary.add(path)
        else:
            self._native_vary.discard(path)
        self._dirty_groups.add(path)

    # ------------------------------------------------------------ entry points

    def begin_sync(
        self,
        time: Usd.TimeCode,
        xform_cache: UsdGeom.XformCache,
        unsupported: Counter[str],
        *,
        full: bool,
    ) -> None:
        """Start a sync.

        ``full`` when the whole stage is walked again: prototype paths may
        have changed, so native prototypes are collected anew.
        """
        self._context = (time, xform_cache, unsupported)
        self._binding_memo.clear()
        if full:
            self._native_members.clear()
            self._referenced = set()
            self._dirty_groups.update(self._groups)

    def end_sync(self, *, full: bool) -> None:
        """Finish a sync: send the native instancers whose instances changed.

        After a full walk, drop the prototypes nothing uses any more.
        """
        for proto in sorted(self._dirty_groups):
            every = self._groups.get(proto, {})
            plain = self._send_variants(proto, every)
            instances = {p: every[p] for p in plain}
            members = self._native_members.get(proto, [])
            owned = self._native_owned.setdefault(proto, set())
            # An instance whose transform is not finite is left out by name; the others stay.
            placed = {}
            for instance, transform in instances.items():
                if np.isfinite(transform).all():
                    self.errors.pop(instance, None)
                    placed[instance] = transform
                else:
                    self._fail(instance, ValueError("its transform is not finite"))
            if placed and members:
                k, n = len(members), len(placed)
                transforms = np.stack(list(placed.values()))
                try:
                    self.delegate.set_instancer(
                        proto,
                        prototypes=members,
                        proto_indices=np.tile(np.arange(k, dtype=np.int32), n),
                        transforms=np.repeat(transforms, k, axis=0),
                    )
                except (PrimError, ValueError, TypeError, OverflowError) as exc:
                    self._fail(proto, exc)
                    continue
                self._hold(proto, proto, owned)
                self._count(proto)
                self._sent_native[proto] = (list(placed), transforms, k)
            elif proto in owned:
                owned.discard(proto)
                self._release(proto, {proto})
        self._dirty_groups.clear()
        if full:
            for proto in [p for p in self._native_owned if p not in self._referenced]:
                self._release(proto, self._native_owned.pop(proto))
                self._release(proto + ".variants", self._variant_owned.pop(proto, set()))
                self._native_bindings.pop(proto, None)
                self._groups.pop(proto, None)
                self._native_vary.discard(proto)
        self._context = None

    def varying_prototypes(self) -> set[str]:
        """Native prototypes whose meshes might change over time.

        The scene delegate re-sends them when the time changes.
        """
        return set(self._native_vary)

    def resend_native_prototype(self, stage: Usd.Stage, path: str) -> bool:
        """Re-send the members of native prototype ``path`` after an edit inside it.

        Returns False when there is no such prototype any more (walk the stage again).
        """
        prototype = stage.GetPrimAtPath(path)
        if not prototype or not prototype.IsPrototype():
            return False
        if path in self._native_members:
            self._resend_native(prototype)
        return True

    def _variant(self, instance: Usd.Prim, proto: str) -> _Variant:
        """The prototype's gprims whose materials or pose differ seen through ``instance``.

        A binding on the instance prim (or an ancestor, or a collection naming instance
        proxies) reaches the prototype's prims only through the instance proxies, so the
        bindings are resolved there (usd-core's ComputeBoundMaterial) and compared with the
        prototype's own. A skinned mesh whose skeleton or animation, bound on or above the
        instance (UsdSkel's instanced crowd: one prototype, an animation per instance),
        differs from the first instance's (whose pose the prototype shows) is another
        variant too, posed through this instance's proxies. Empty: the instance renders the
        shared prototype.
        """
        root = str(instance.GetPath())
        stage = instance.GetStage()
        found: dict[str, tuple[_Bindings, tuple[str, str]]] = {}
        if self._binds_above(instance):  # else nothing outside the prototype binds materials
            for rel, own in self._native_bindings.get(proto, []):
                proxy = stage.GetPrimAtPath(root + rel)
                if proxy and (seen := _bindings(proxy)) != own:
                    found[rel] = (seen, ("", ""))
        prototype = stage.GetPrimAtPath(proto)
        if prototype:
            for rel in self._poser.posed_apart(instance, prototype):
                proxy = stage.GetPrimAtPath(root + rel)
                seen, _ = found.get(rel, (_bindings(proxy), ("", "")))
                found[rel] = (seen, self._poser.binding_of(proxy, instance))
        return tuple((rel, b, k) for rel, (b, k) in sorted(found.items()))

    def _binds_above(self, prim: Usd.Prim) -> bool:
        """Whether ``prim`` or an ancestor has MaterialBindingAPI (memoized for the sync).

        A binding reaching an instance proxy, direct or through a collection, is authored
        on the proxy's ancestors; those outside the prototype are the instance and above.
        usd-core ignores bindings on prims without the API applied.
        """
        path = str(prim.GetPath())
        known = self._binding_memo.get(path)
        if known is None:
            parent = prim.GetParent()
            known = prim.HasAPI(UsdShade.MaterialBindingAPI) or bool(
                parent and not parent.IsPseudoRoot() and self._binds_above(parent)
            )
            self._binding_memo[path] = known
        return known

    def add_instance(
        self,
        instance_path: str,
        prototype: Usd.Prim,
        world: NDArray[np.float64],
        *,
        might_move: bool = False,
    ) -> tuple[str, ...]:
        """Place native prototype ``prototype`` at ``world`` for instance prim ``instance_path``.

        ``might_move``: its world transform might vary in time (only such instances are
        sampled over the shutter, :meth:`update_motion`).

        Returns the materials bound through the instance to its prototype's prims where they
        differ from the prototype's own (the scene delegate re-syncs the instance when one of
        them changes).
        """
        proto = str(prototype.GetPath())
        self._native(prototype)
        old = self._instance_of.get(instance_path)
        if old is not None and old != proto:
            self.remove_instance(instance_path)
        self._groups.setdefault(proto, {})[instance_path] = world
        self._instance_of[instance_path] = proto
        if might_move:
            self._might_move.add(instance_path)
        else:
            self._might_move.discard(instance_path)
        instance = prototype.GetStage().GetPrimAtPath(instance_path)
        variant = self._variant(instance, proto) if instance else ()
        self._variant_of[instance_path] = variant
        self._dirty_groups.add(proto)
        return tuple(sorted({m for _, b, _ in variant for m in b if m}))

    def _send_variants(self, proto: str, instances: dict[str, NDArray[np.float64]]) -> list[str]:
        """Send one instancer per distinct variant of ``proto``'s instances; hold its meshes.

        A variant's meshes are read through its first instance's proxies (so each gets the
        materials bound there) under ``<prototype>.variant<k>``. Returns the instances
        rendering the shared prototype.
        """
        assert self._context is not None, "begin_sync() first"
        time, xform_cache, unsupported = self._context
        owner = proto + ".variants"
        groups: dict[_Variant, list[str]] = {}
        plain: list[str] = []
        for instance_path in instances:
            variant = self._variant_of.get(instance_path, ())
            (groups.setdefault(variant, []) if variant else plain).append(instance_path)
        owned: set[str] = set()
        members = self._native_members.get(proto, [])
        for k, (variant, paths) in enumerate(sorted(groups.items())):
            first = self._stage_prim(paths[0])
            if first is None:
                continue
            root = f"{proto}.variant{k}"
            walk = _Walk(owner, time, xform_cache, unsupported)
            replaced: dict[str, str] = {}
            for rel, _, _ in variant:
                proxy = self._stage_prim(paths[0] + rel)
                if proxy is not None and self._prototype_mesh(proxy, first, root + rel, walk):
                    replaced[proto + rel] = root + rel
            placed = [replaced.get(m, m) for m in members]
            if not placed:
                continue
            transforms = np.stack([instances[p] for p in paths])
            n = len(placed)
            self.delegate.set_instancer(
                root,
                prototypes=placed,
                proto_indices=np.tile(np.arange(n, dtype=np.int32), len(paths)),
                transforms=np.repeat(transforms, n, axis=0),
            )
            self._hold(owner, root, walk.owned)
            self._count(root)
            self._sent_native[root] = (paths, transforms, n)
            owned |= walk.owned
        self._release(owner, self._variant_owned.get(proto, set()) - owned)
        self._variant_owned[proto] = owned
        return plain

    def _stage_prim(self, path: str) -> Usd.Prim | None:
        prim = self._stage.GetPrimAtPath(path) if self._stage is not None else None
        return prim if prim else None

    def remove_instance(self, instance_path: str) -> None:
        """Take instance prim ``instance_path`` out of its prototype's instancer."""
        proto = self._instance_of.pop(instance_path, None)
        self._variant_of.pop(instance_path, None)
        self._might_move.discard(instance_path)
        if proto is not None:
            self._groups.get(proto, {}).pop(instance_path, None)
            self._dirty_groups.add(proto)

    def sync_point_instancer(
        self,
        prim: Usd.Prim,
        world: NDArray[np.float64],
        previous: InstancerState | None,
        *,
        members: bool,
    ) -> tuple[InstancerState, bool]:
        """Send the PointInstancer ``prim``, and its prototypes when ``members`` is set.

        ``previous`` is its state from the last sync, if any: without
        ``members`` only the instances are re-sent (the prototypes are those of
        ``previous``); with it, prototype meshes that are gone are removed.

        Returns:
            The new state, and whether the instancer's own data might vary in time.

        Raises:
            PrimError: the PointInstancer's data is inconsistent.

        """
        assert self._context is not None, "begin_sync() first"
        time, xform_cache, unsupported = self._context
        path = str(prim.GetPath())
        arrays = read_point_instancer(UsdGeom.PointInstancer(prim), time)
        roots = tuple(str(r.GetPath()) for r in arrays.roots)
        state = previous
        if members or state is None or roots != state.roots:
            walk = _Walk(path, time, xform_cache, unsupported, expanding={path})
            groups = [
                self._collect(r, self._root_prefix(path, path, i, r), walk)
                for i, r in enumerate(arrays.roots)
            ]
            old = previous.owned if previous is not None else set()
            if path in old:
                self._hold(path, path, walk.owned)
            self._release(path, old - walk.owned)
            state = InstancerState(
                roots=roots,
                groups=groups,
                owned=walk.owned,
                material_paths=tuple(sorted(walk.material_paths)),
                members_might_vary=walk.might_vary,
                member_prims=walk.member_prims,
            )
        flat, indices, transforms = _expand(
            state.groups, arrays.proto_indices, arrays.transforms @ world
        )
        self.delegate.set_instancer(
            path, prototypes=flat, proto_indices=indices, transforms=transforms
        )
        self._hold(path, path, state.owned)
        self._stage = prim.GetStage()
        self._sent_points[path] = (path, None, state.groups)
        return state, arrays.might_vary

    def forget_point_instancer(self, path: str, state: InstancerState) -> None:
        """Remove the PointInstancer at ``path`` and whatever only it held."""
        self._release(path, state.owned | {path})
        self._sent_points.pop(path, None)
        self._moving.discard(path)
        for prim_path in state.member_prims:
            self.errors.pop(prim_path, None)

    # ----------------------------------------------------------------- motion

    def update_motion(self, time: Usd.TimeCode, shutter: tuple[float, float]) -> list[str]:
        """Send each top-level instancer's instance transforms over the shutter where they move.

        Transform motion blur of instances: a PointInstancer's by usd-core's
        ``ComputeInstanceTransformsAtTimes`` (time-sampled positions, orientations and
        scales, and ``velocities``/``angularVelocities``) and its own world transform; a
        native prototype's instances by their world transforms. Only instancers that
        might move are sampled; one that no longer moves has its motion cleared.
        Returns the paths of the moving instancers.
        """
        moving: list[str] = []
        if shutter[1] > shutter[0] and not time.IsDefault() and self._stage is not None:
            memo: dict[str, bool] = {}
            found: list[tuple[str, tuple[NDArray[np.float32], NDArray[np.float64]] | None]] = [
                (path, self._points_motion(*sent, time, shutter, memo))
                for path, sent in sorted(self._sent_points.items())
                if path in self._holders
            ]
            found += [
                (path, self._nested_motion(*sent, time, shutter, memo))
                for path, sent in sorted(self._sent_nested.items())
                if path in self._holders
            ]
            # Native instances are sampled only when some might move: a still scene pays nothing.
            found += [
                (path, self._native_motion(*sent, time, shutter))
                for path, sent in sorted(self._sent_native.items())
                if self._might_move and path in self._holders
            ]
            for path, samples in found:
                if samples is None:
                    continue
                try:
                    self.delegate.set_instancer_motion(path, samples[0], samples[1])
                except (PrimError, ValueError) as exc:
                    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                    _log.warning("mipray: %s; its instances render without motion blur", text)
                    continue
                moving.append(path)
        for path in sorted(self._moving - set(moving)):
            if path in self._holders:
                self.delegate.set_instancer_motion(
                    path, np.zeros(0, np.float32), np.zeros((0, 0, 4, 4), np.float64)
                )
        self._moving = set(moving)
        self._update_member_motion(time, shutter)
        return moving

    def _update_member_motion(self, time: Usd.TimeCode, shutter: tuple[float, float]) -> None:
        """Send the prototype meshes that move within their prototype their motion there.

        Their transform to the prototype's root over the shutter (``set_motion``); those
        that stopped moving have it cleared.
        """
        moving: set[str] = set()
        if shutter[1] > shutter[0] and not time.IsDefault() and self._stage is not None:
            memo: dict[str, bool] = {}
            for dpath, (path, root) in sorted(self._sent_members.items()):
                if dpath not in self._holders:
                    continue
                samples = self._nested_motion(path, root, 1, time, shutter, memo)
                if samples is None:
                    continue
                try:
                    self.delegate.set_motion(dpath, samples[0], samples[1][:, 0])
                except (PrimError, ValueError) as exc:
                    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                    _log.warning("mipray: %s; rendering it without motion blur", text)
                    continue
                moving.add(dpath)
        for dpath in sorted(self._moving_members - moving):
            if dpath in self._holders:
                self.delegate.set_motion(
                    dpath, np.zeros(0, np.float32), np.zeros((0, 4, 4), np.float64)
                )
        self._moving_members = moving
        self._update_member_deformation(time, shutter)

    def _update_member_deformation(self, time: Usd.TimeCode, shutter: tuple[float, float]) -> None:
        """Send the prototype meshes whose points move within the shutter those points.

        Deformation motion blur inside prototypes (:mod:`mipray.usd.deform`): the points are
        in the mesh's object space, which its transform to the prototype's root and then each
        instance's placement carry, so the one deforming prototype mesh deforms in every
        instance. Those that stopped deforming have their samples cleared.
        """
        deforming: set[str] = set()
        if shutter[1] > shutter[0] and not time.IsDefault() and self._stage is not None:
            for dpath in sorted(self._might_deform & set(self._holders)):
                path, root_path = self._sent_members[dpath]
                prim, root = self._stage.GetPrimAtPath(path), self._stage.GetPrimAtPath(root_path)
                samples = (
                    deformation_samples(prim, time, shutter, self._poser, root)
                    if prim and root
                    else None
                )
                if samples is None:
                    continue
                try:
                    self.delegate.set_deformation(dpath, *samples)
                except (PrimError, ValueError) as exc:
                    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                    _log.warning(
                        "mipray: %s; rendering it at the frame's time without motion blur", text
                    )
                    continue
                deforming.add(dpath)
        for dpath in sorted(self._deforming - deforming):
            if dpath in self._holders:
                self.delegate.set_deformation(
                    dpath, np.zeros(0, np.float32), np.zeros((0, 0, 3), np.float32)
                )
        self._deforming = deforming

    @staticmethod
    def _fractions(times: list[float]) -> NDArray[np.float32]:
        t0, t1 = times[0], times[-1]
        return np.array([(t - t0) / (t1 - t0) for t in times], dtype=np.float32)

    def _frame(
        self, cache: UsdGeom.XformCache, prim: Usd.Prim, root: str | None
    ) -> NDArray[np.float64]:
        """``prim``'s transform to the world (``root`` None) or to prototype root ``root``."""
        if root is None:
            return world_transform(cache, prim)
        assert self._stage is not None
        matrix, _ = cache.ComputeRelativeTransform(prim, self._stage.GetPrimAtPath(root))
        return matrix_to_numpy(matrix)

    def _points_motion(
        self,
        path: str,
        root: str | None,
        groups: list[list[str]],
        time: Usd.TimeCode,
        shutter: tuple[float, float],
        memo: dict[str, bool],
    ) -> tuple[NDArray[np.float32], NDArray[np.float64]] | None:
        """The PointInstancer at ``path``'s placements over the shutter, or None if still.

        Relative to prototype root ``root`` for one inside a prototype (None: the world).
        """
        assert self._stage is not None
        prim = self._stage.GetPrimAtPath(path)
        if not prim or not prim.IsA(UsdGeom.PointInstancer):
            return None
        pi = UsdGeom.PointInstancer(prim)
        attributes = tuple(
            a
            for a in (
                pi.GetPositionsAttr(),
                pi.GetOrientationsAttr(),
                pi.GetOrientationsfAttr(),
                pi.GetScalesAttr(),
                pi.GetVelocitiesAttr(),
                pi.GetAngularVelocitiesAttr(),
                pi.GetAccelerationsAttr(),
            )
            if a.HasAuthoredValue()
        )
        velocities = any(
            a.GetName() in ("velocities", "angularVelocities", "accelerations")
            and len(a.Get(time) or ()) > 0
            for a in attributes
        )
        varies = any(a.ValueMightBeTimeVarying() for a in attributes)
        if not (velocities or varies or ancestors_might_vary(prim, memo)):
            return None
        times = shutter_times([prim], time, shutter, attributes)
        if times is None:
            return None
        try:
            arrays = read_point_instancer(pi, time)
        except PrimError:
            return None  # reported by its sync
        codes = [Usd.TimeCode(t) for t in times]
        xforms = pi.ComputeInstanceTransformsAtTimes(codes, time)
        n = len(arrays.proto_indices)
        if len(xforms) != len(times) or any(len(x) != n for x in xforms):
            _log.warning(
                "mipray: %s: the instance transforms over the shutter cannot be computed "
                "(see USD's warning); its instances render without motion blur",
                path,
            )
            return None
        per_time = []
        for t, x in zip(times, xforms, strict=True):
            frame = self._frame(UsdGeom.XformCache(Usd.TimeCode(t)), prim, root)
            local = np.asarray(x, dtype=np.float64).reshape(-1, 4, 4)
            per_time.append(_expand(groups, arrays.proto_indices, local @ frame)[2])
        mats = np.stack(per_time)
        if mats.shape[1] == 0 or np.all(mats == mats[0]):
            return None
        return self._fractions(times), mats

    def _nested_motion(
        self,
        path: str,
        root: str,
        k: int,
        time: Usd.TimeCode,
        shutter: tuple[float, float],
        memo: dict[str, bool],
    ) -> tuple[NDArray[np.float32], NDArray[np.float64]] | None:
        """A prim inside a prototype over the shutter, or None when it does not move there.

        Its transform to the prototype's root, repeated for its ``k`` members (an instance's;
        1 for a mesh).
        """
        assert self._stage is not None
        prim = self._stage.GetPrimAtPath(path)
        if not prim or not ancestors_might_vary(prim, memo):
            return None
        times = shutter_times([prim], time, shutter)
        if times is None:
            return None
        mats = np.stack(
            [self._frame(UsdGeom.XformCache(Usd.TimeCode(t)), prim, root) for t in times]
        )
        if np.all(mats == mats[0]):
            return None
        return self._fractions(times), np.repeat(mats[:, None], k, axis=1)

    def _native_motion(
        self,
        instances: list[str],
        transforms: NDArray[np.float64],
        k: int,
        time: Usd.TimeCode,
        shutter: tuple[float, float],
    ) -> tuple[NDArray[np.float32], NDArray[np.float64]] | None:
        """A native instancer's placements over the shutter, or None when no instance moves.

        Each instance's world transform, repeated for its ``k`` members.
        """
        assert self._stage is not None
        moving = [i for i, p in enumerate(instances) if p in self._might_move]
        prims = {i: self._stage.GetPrimAtPath(instances[i]) for i in moving}
        moving = [i for i in moving if prims[i]]
        if not moving:
            return None
        times = shutter_times([prims[i] for i in moving], time, shutter)
        if times is None:
            return None
        # Still instances keep their frame-time transform at every key (placed as without motion).
        mats = np.repeat(transforms[None], len(times), axis=0)
        for j, t in enumerate(times):
            cache = UsdGeom.XformCache(Usd.TimeCode(t))
            for i in moving:
                mats[j, i] = world_transform(cache, prims[i])
        if np.all(mats == mats[0]):
            return None
        return self._fractions(times), np.repeat(mats, k, axis=1)

    def owner_of(self, changed: str, states: dict[str, InstancerState]) -> list[str]:
        """PointInstancers (path → state) whose prototypes hold the prim path ``changed``."""
        return [
            p
            for p, s in states.items()
            if any(changed == r or changed.startswith(r + "/") for r in s.roots)
        ]
