"""Skinned meshes posed at the render's time code, by usd-core's UsdSkel.

A mesh bound to a ``Skeleton`` under a ``SkelRoot`` (``UsdSkel.BindingAPI``) renders posed:
blend shapes first (``UsdSkel.BlendShapeQuery`` with the animation's weights), then linear
blend skinning (``UsdSkel.SkinningQuery.ComputeSkinnedPoints`` with the skeleton's skinning
transforms) or, for a rigidly deformed mesh, its skinned transform. UsdSkel's skinned points
are in the skeleton's space, so the posed mesh is placed by the skeleton's world transform,
not its own (UsdSkel's rule: the skinned prim's transform is ignored).

A skeleton whose joints cannot be posed (its joints do not resolve, the influences name joints
it does not have, the mesh binds no skeleton) gets one warning naming the mesh, and the mesh
renders in its rest pose (its authored points and transform). A rigidly deformed mesh (one
joint moves it whole) blurs by its posed transform over the shutter
(:meth:`SkelPoser.rigid_motion`); other skinned meshes blur by their deformation, posed at
times across the shutter (:mod:`mipray.usd.deform`).

Inside an instancing prototype a skinned mesh is posed relative to the prototype's root (its
transform there is the skeleton's to that root), so every instance places the one posed mesh;
a native prototype whose SkelRoot is the instance prim (or above it) is posed through its first
instance's proxies. The prototype's meshes show the first instance's pose; an instance that
binds another skeleton or animation outside the prototype (a crowd: one animation per
instance) renders its own, its skinned meshes posed through its proxies. A rigidly deformed
mesh in a prototype blurs by its points, posed over the shutter.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom, UsdSkel, Vt

from .transform import MOTION_SUBSAMPLES, matrix_to_numpy

__all__ = ["Posed", "SkelPoser", "is_skinned"]

_log = logging.getLogger(__name__)


def is_skinned(prim: Usd.Prim) -> bool:
    """Whether ``prim`` is a mesh that UsdSkel may pose: bound with ``UsdSkel.BindingAPI``."""
    return bool(prim.IsA(UsdGeom.Mesh) and prim.HasAPI(UsdSkel.BindingAPI))


@dataclass(frozen=True)
class Posed:
    """A skinned mesh at one time code."""

    #: (N, 3) float32 posed points, in the space ``transform`` places.
    points: NDArray[np.float32]
    #: Object-to-world for ``points``: the skeleton's world transform.
    transform: NDArray[np.float64]
    #: Whether the pose may change with the time (an animated skeleton or blend shapes).
    might_vary: bool
    #: Rigidly deformed (one joint moves the whole mesh): ``points`` are the rest points and
    #: ``transform`` carries the pose, so the pose over a shutter is a transform motion.
    rigid: bool = False


class SkelPoser:
    """Poses skinned meshes of one stage; keeps a ``UsdSkel.Cache`` across calls."""

    def __init__(self) -> None:
        self._cache = UsdSkel.Cache()
        self._populated: set[str] = set()
        self._warned: set[str] = set()
        # Per native prototype: its skinned meshes (paths below it) and the skeleton and
        # animation each is posed by through the prototype's first instance.
        self._skinned: dict[str, dict[str, tuple[str, str]]] = {}

    def clear(self) -> None:
        """Forget what the cache read (the stage's skeletons or bindings changed)."""
        self._cache.Clear()
        self._populated.clear()
        self._skinned.clear()

    def pose(
        self,
        prim: Usd.Prim,
        time: Usd.TimeCode,
        points: NDArray[np.float32],
        root: Usd.Prim | None = None,
    ) -> Posed | None:
        """``prim`` (a mesh whose rest ``points`` are given) posed at ``time``.

        ``root``: an instancing prototype's root ``prim`` is in; the transform is then the
        skeleton's to it, not to the world. A native prototype with no SkelRoot of its own
        (the instance prim is the SkelRoot, as for an instanced character) is posed through
        its first instance's proxy of ``prim``: instances share one prototype mesh, so they
        share that pose (UsdSkel's, as for the instance's own skeleton and animation).

        Returns:
            The posed points and the transform placing them; None when the mesh is not
            skinned (no SkelRoot above it, no joint influences nor blend shapes), or when it
            cannot be posed — then with one warning naming the mesh: it renders at rest.

        """
        if root is not None and root.IsPrototype() and not UsdSkel.Root.Find(prim):
            through = self._first_instance(prim, root)
            if through is None:
                return None
            prim, root = through
        skel_root = UsdSkel.Root.Find(prim)
        if not skel_root:
            return None
        # An instance proxy's skinning is found only walking through instance proxies.
        proxy = prim.IsInstanceProxy()
        key = f"{skel_root.GetPath()}{' (proxies)' if proxy else ''}"
        if key not in self._populated:
            predicate = (
                Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
                if proxy
                else Usd.PrimDefaultPredicate
            )
            self._cache.Populate(skel_root, predicate)
            self._populated.add(key)
        query = self._cache.GetSkinningQuery(prim)
        if not query or not (query.HasJointInfluences() or query.HasBlendShapes()):
            return None
        path = str(prim.GetPath())
        skeleton = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
        if not skeleton:
            return self._rest(path, "its skel:skeleton does not resolve to a Skeleton")
        skel_query = self._cache.GetSkelQuery(skeleton)
        if not skel_query:
            return self._rest(path, f"the joints of {skeleton.GetPath()} do not resolve")
        anim = skel_query.GetAnimQuery()
        varies = bool(anim) and (
            anim.JointTransformsMightBeTimeVarying() or anim.BlendShapeWeightsMightBeTimeVarying()
        )
        posed = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32))
        is_rigid = False
        if query.HasBlendShapes() and anim:
            problem = _blend(prim, query, anim, time, posed)
            if problem:
                return self._rest(path, problem)
        if root is None:
            skel_to_world = UsdGeom.Xformable(skeleton.GetPrim()).ComputeLocalToWorldTransform(time)
        else:
            # To the prototype's root (or the instance standing for it), as its meshes are.
            skel_to_world, _ = UsdGeom.XformCache(time).ComputeRelativeTransform(
                skeleton.GetPrim(), root
            )
        if query.HasJointInfluences():
            xforms = skel_query.ComputeSkinningTransforms(time)
            if xforms is None or len(xforms) != len(skel_query.GetJointOrder()):
                return self._rest(path, f"the joints of {skeleton.GetPath()} cannot be posed")
            if query.IsRigidlyDeformed():
                rigid = query.ComputeSkinnedTransform(xforms, time)
                if rigid is None:
                    return self._rest(path, f"its joints are not in {skeleton.GetPath()}")
                skel_to_world = rigid * skel_to_world
                is_rigid = not query.HasBlendShapes()
            elif not query.ComputeSkinnedPoints(xforms, posed, time):
                return self._rest(
                    path, f"its jointIndices name joints {skeleton.GetPath()} does not have"
                )
        out = np.asarray(posed, dtype=np.float32).reshape(-1, 3)
        if not np.isfinite(out).all():
            return self._rest(path, "skinning gave points that are not finite")
        return Posed(
            np.ascontiguousarray(out), matrix_to_numpy(skel_to_world), bool(varies), is_rigid
        )

    def _first_instance(
        self, prim: Usd.Prim, prototype: Usd.Prim
    ) -> tuple[Usd.Prim, Usd.Prim] | None:
        """The first instance's proxy of prototype mesh ``prim``, and that instance prim.

        The prototype's mesh shows the first instance's pose; an instance binding another
        skeleton or animation (on or above it, outside the prototype) renders its own
        (:meth:`posed_apart`).
        """
        instances = sorted(prototype.GetInstances(), key=lambda i: str(i.GetPath()))
        if not instances:
            return None
        stage = prim.GetStage()
        rel = str(prim.GetPath())[len(str(prototype.GetPath())) :]
        first = instances[0]
        proxy = stage.GetPrimAtPath(f"{first.GetPath()}{rel}")
        if not proxy:
            return None
        return proxy, first

    def posed_apart(self, instance: Usd.Prim, prototype: Usd.Prim) -> list[str]:
        """The skinned meshes of native ``prototype`` that ``instance`` poses otherwise.

        Paths below the prototype of the meshes whose skeleton or animation, seen through
        ``instance``'s proxies, is not the first instance's (whose pose the prototype's
        meshes show): UsdSkel's instanced crowds bind an animation on each instance prim.
        """
        key = str(prototype.GetPath())
        first = self._skinned.get(key)
        if first is None:
            first = {}
            instances = sorted(prototype.GetInstances(), key=lambda i: str(i.GetPath()))
            if instances:
                base = str(instances[0].GetPath())
                stage = prototype.GetStage()
                predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
                for proxy in Usd.PrimRange(instances[0], predicate):
                    if proxy.IsA(UsdGeom.Mesh) and UsdSkel.BindingAPI(proxy).GetInheritedSkeleton():
                        rel = str(proxy.GetPath())[len(base) :]
                        if stage.GetPrimAtPath(key + rel):
                            first[rel] = _skel_binding(proxy, instances[0])
            self._skinned[key] = first
        base = str(instance.GetPath())
        stage = instance.GetStage()
        apart = []
        for rel, want in first.items():
            proxy = stage.GetPrimAtPath(base + rel)
            if proxy and _skel_binding(proxy, instance) != want:
                apart.append(rel)
        return apart

    @staticmethod
    def binding_of(mesh: Usd.Prim, instance: Usd.Prim) -> tuple[str, str]:
        """The skeleton and animation instance proxy ``mesh`` is posed by.

        Paths relative to ``instance`` where they are inside it.
        """
        return _skel_binding(mesh, instance)

    def rigid_motion(
        self,
        prim: Usd.Prim,
        time: Usd.TimeCode,
        shutter: tuple[float, float],
        points: NDArray[np.float32],
    ) -> tuple[NDArray[np.float32], NDArray[np.float64]] | None:
        """A rigidly deformed mesh's posed transform over the shutter.

        As :func:`mipray.usd.transform.motion_samples` gives a moving prim's: (times as
        fractions of the shutter, (N, 4, 4) matrices) at the shutter's ends and evenly spaced
        times between; None when it does not move in it, or is not rigidly posed.
        """
        if time.IsDefault() or shutter[1] <= shutter[0]:
            return None
        t0, t1 = time.GetValue() + shutter[0], time.GetValue() + shutter[1]
        steps = MOTION_SUBSAMPLES + 1
        times = [t0 + (t1 - t0) * k / steps for k in range(steps + 1)]
        mats = []
        for t in times:
            posed = self.pose(prim, Usd.TimeCode(t), points)
            if posed is None or not posed.rigid:
                return None
            mats.append(posed.transform)
        stack = np.stack(mats)
        if np.all(stack == stack[0]):
            return None
        return np.array([(t - t0) / (t1 - t0) for t in times], dtype=np.float32), stack

    def _rest(self, path: str, problem: str) -> Posed | None:
        """Warn once that ``path`` renders at rest because of ``problem``; None (no pose)."""
        if path not in self._warned:
            self._warned.add(path)
            _log.warning(
                "mipray: %s: cannot pose the skinned mesh: %s; rendering its rest pose",
                path,
                problem,
            )
        return None


def _blend(
    prim: Usd.Prim,
    query: UsdSkel.SkinningQuery,
    anim: UsdSkel.AnimQuery,
    time: Usd.TimeCode,
    points: Vt.Vec3fArray,
) -> str | None:
    """Apply the mesh's blend shapes at the animation's weights to ``points`` in place.

    Returns the problem, or None.
    """
    weights = anim.ComputeBlendShapeWeights(time)
    if weights is None:
        return "its blend shape weights cannot be read"
    mapper = query.GetBlendShapeMapper()
    if mapper is not None and not mapper.IsNull():
        weights = mapper.Remap(weights)
        if weights is None:
            return "its blendShapes do not match the animation's"
    shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
    sub_weights, shape_indices, sub_indices = shapes.ComputeSubShapeWeights(weights)
    if not shapes.ComputeDeformedPoints(
        sub_weights,
        shape_indices,
        sub_indices,
        shapes.ComputeBlendShapePointIndices(),
        shapes.ComputeSubShapePointOffsets(),
        points,
    ):
        return "its blend shapes do not fit its points"
    return None


def _skel_binding(mesh: Usd.Prim, instance: Usd.Prim) -> tuple[str, str]:
    """The skeleton and animation ``mesh`` (an instance proxy) is posed by, as paths.

    Relative to ``instance`` where they are inside it, so instances binding their own copies
    inside the prototype compare equal.
    """
    base = str(instance.GetPath())
    skeleton = UsdSkel.BindingAPI(mesh).GetInheritedSkeleton()
    if not skeleton:
        return ("", "")
    anim = UsdSkel.BindingAPI(skeleton.GetPrim()).GetInheritedAnimationSource()

    def inside(path: str) -> str:
        return path.removeprefix(base) if path.startswith(base + "/") else path

    return inside(str(skeleton.GetPath())), inside(str(anim.GetPath()) if anim else "")
