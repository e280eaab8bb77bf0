"""World transforms as the render delegate takes them.

USD matrices are row-vector (``p_world = p @ m``, translation in the last row);
``numpy.array(Gf.Matrix4d)`` keeps that layout, and so does the delegate, so no
transpose happens anywhere.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pxr import Gf, Usd, UsdGeom

__all__ = [
    "ancestors_might_vary",
    "camera_shutter",
    "matrix_to_numpy",
    "motion_samples",
    "shutter_times",
    "world_transform",
]

#: Extra evenly spaced samples inside the shutter besides the authored ones: keeps a fast spin
#: between two authored samples (which USD interpolates angle by angle) close to the renderer's
#: per-key slerp, which takes the short way round.
MOTION_SUBSAMPLES = 4


def matrix_to_numpy(m: Gf.Matrix4d) -> NDArray[np.float64]:
    """A ``Gf.Matrix4d`` as a (4, 4) float64 array in the same row-vector layout."""
    return np.array(m, dtype=np.float64).reshape(4, 4)


def world_transform(cache: UsdGeom.XformCache, prim: Usd.Prim) -> NDArray[np.float64]:
    """``prim``'s local-to-world matrix at the cache's time code."""
    return matrix_to_numpy(cache.GetLocalToWorldTransform(prim))


def ancestors_might_vary(prim: Usd.Prim, memo: dict[str, bool]) -> bool:
    """Whether ``prim``'s world transform might change over time.

    True when ``prim`` or any ancestor has time-sampled (or otherwise varying)
    xform ops. ``memo`` caches the answer per path across one traversal, so a
    walk over N prims costs O(N), not O(N × depth).
    """
    chain: list[Usd.Prim] = []
    p = prim
    result = False
    while p and not p.IsPseudoRoot():
        key = str(p.GetPath())
        if key in memo:
            result = memo[key]
            break
        chain.append(p)
        p = p.GetParent()
    # Resolve from the topmost unknown ancestor downward.
    for q in reversed(chain):
        xf = UsdGeom.Xformable(q)
        if not result and xf:
            result = bool(xf.TransformMightBeTimeVarying())
        memo[str(q.GetPath())] = result
    return result


def camera_shutter(stage: Usd.Stage, camera_path: str, time: Usd.TimeCode) -> tuple[float, float]:
    """The camera's ``shutter:open`` and ``shutter:close`` (frames, relative to ``time``).

    (0, 0) — no motion blur — for a camera without a prim (the framing camera),
    an unauthored shutter, or a non-finite or reversed interval.
    """
    prim = stage.GetPrimAtPath(camera_path) if camera_path.startswith("/") else None
    if not prim or not prim.IsA(UsdGeom.Camera):
        return (0.0, 0.0)
    cam = UsdGeom.Camera(prim)
    o = cam.GetShutterOpenAttr().Get(time)
    c = cam.GetShutterCloseAttr().Get(time)
    o, c = float(o or 0.0), float(c or 0.0)
    if not (np.isfinite(o) and np.isfinite(c)) or c <= o:
        return (0.0, 0.0)
    return (o, c)


def shutter_times(
    prims: list[Usd.Prim],
    time: Usd.TimeCode,
    shutter: tuple[float, float],
    attributes: tuple[Usd.Attribute, ...] = (),
) -> list[float] | None:
    """The time codes a motion over the shutter is sampled at, in order; None when it is shut.

    The shutter's ends, :data:`MOTION_SUBSAMPLES` evenly spaced times between them, and
    every authored time sample inside it of the xform ops of ``prims`` and their ancestors
    and of ``attributes``. ``time`` must be numeric (the default time has no motion).
    """
    if time.IsDefault() or shutter[1] <= shutter[0]:
        return None
    t0 = time.GetValue() + shutter[0]
    t1 = time.GetValue() + shutter[1]
    times = {t0, t1}
    times.update(
        t0 + (t1 - t0) * k / (MOTION_SUBSAMPLES + 1) for k in range(1, MOTION_SUBSAMPLES + 1)
    )
    interval = Gf.Interval(t0, t1)
    seen: set[str] = set()
    for prim in prims:
        p = prim
        while p and not p.IsPseudoRoot() and str(p.GetPath()) not in seen:
            seen.add(str(p.GetPath()))
            xf = UsdGeom.Xformable(p)
            if xf:
                times.update(t for t in xf.GetTimeSamplesInInterval(interval) if t0 < t < t1)
            p = p.GetParent()
    for attribute in attributes:
        times.update(t for t in attribute.GetTimeSamplesInInterval(interval) if t0 < t < t1)
    return sorted(times)


def motion_samples(
    prim: Usd.Prim, time: Usd.TimeCode, shutter: tuple[float, float]
) -> tuple[NDArray[np.float32], NDArray[np.float64]] | None:
    """``prim``'s world transform over the shutter, or None when it does not move in it.

    Returns (times as fractions of the shutter, 0 = open, 1 = close; (N, 4, 4)
    matrices) at the shutter's ends, every authored xform time sample of the prim
    and its ancestors inside it, and :data:`MOTION_SUBSAMPLES` evenly spaced
    times. ``time`` must be numeric (the default time has no motion).
    """
    ordered = shutter_times([prim], time, shutter)
    if ordered is None:
        return None
    t0, t1 = ordered[0], ordered[-1]
    mats = np.stack([world_transform(UsdGeom.XformCache(Usd.TimeCode(t)), prim) for t in ordered])
    if np.all(mats == mats[0]):
        return None
    fractions = np.array([(t - t0) / (t1 - t0) for t in ordered], dtype=np.float32)
    return fractions, mats
