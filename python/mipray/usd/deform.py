"""A mesh's points across the camera's shutter, for deformation motion blur.

A ``UsdGeom.Mesh`` whose ``points`` are time-sampled inside the shutter, or a skinned mesh
(:mod:`mipray.usd.skel`) whose skeleton or blend shapes move in it, crosses as its points at
the shutter's ends and at its authored samples between (a skinned mesh at the ends and
:data:`~mipray.usd.transform.MOTION_SUBSAMPLES` evenly spaced times between, so a bending
joint sweeps close to its arc rather than along the chord), each in the object space of the
transform the mesh was sent with at the frame's time. The renderer builds the mesh at each
sample over its one topology and blends between them at each ray's time (``mipray.deform``
in the core).

What cannot be blurred is warned about once, naming the prim, and the mesh renders at the
frame's time: a point count that changes within the shutter (another topology), or more
samples than :data:`MAX_SAMPLES`.

A mesh whose ``points`` have no sample inside the shutter (other than at the frame's time) but
``velocities`` (and maybe ``accelerations``) authored moves by them: its points at shutter
time code ``t`` are usd-core's ``UsdGeom.PointBased.ComputePointsAtTimes`` (p + v·s + ½·a·s²,
s the seconds from the points' sample at or before the frame's time, by the stage's
timeCodesPerSecond), not the rule written again. As in USD, velocities apply only where their
sample's time code is the points' (points authored only as a default value do not move).
Velocities or accelerations of a count other than the points': one warning naming the prim and
attribute, and the mesh renders at the frame's time without motion blur.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pxr import Gf, Usd, UsdGeom

from .skel import SkelPoser, is_skinned
from .transform import MOTION_SUBSAMPLES
from .warn import warn_once

__all__ = ["MAX_SAMPLES", "changes_shape_in_shutter", "deformation_samples", "moves_by_velocities"]

#: Most samples the renderer takes across one shutter (``mipray::deform::MAX_SAMPLES``).
MAX_SAMPLES = 16

_warn_once = warn_once(__name__)


def deformation_samples(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    shutter: tuple[float, float],
    poser: SkelPoser,
    root: Usd.Prim | None = None,
) -> tuple[NDArray[np.float32], NDArray[np.float32]] | None:
    """``prim``'s points across the shutter, or None when they do not change in it.

    ``root``: the root of the instancing prototype ``prim`` is in (a skinned mesh there is
    posed relative to it, :meth:`~mipray.usd.skel.SkelPoser.pose`); None outside one.

    Returns (times as fractions of the shutter, 0 = open, 1 = close; (N, P, 3) float32
    points in the object space the mesh was sent in at ``time``). ``shutter`` is relative to
    ``time`` (frames). None too, with one warning naming the prim, when the deformation
    cannot be blurred (see the module's note).
    """
    if time.IsDefault() or shutter[1] <= shutter[0] or not prim.IsA(UsdGeom.Mesh):
        return None
    t0, t1 = time.GetValue() + shutter[0], time.GetValue() + shutter[1]
    path = prim.GetPath()
    attr = UsdGeom.Mesh(prim).GetPointsAttr()
    rest = np.asarray(attr.Get(time) or [], dtype=np.float32).reshape(-1, 3)
    if is_skinned(prim):
        steps = MOTION_SUBSAMPLES + 1
        codes = [t0 + (t1 - t0) * k / steps for k in range(steps + 1)]
        samples = _skinned(prim, time, codes, rest, poser, root)
        if samples is None:
            return None
        frame = samples.pop()
    else:
        inside = [t for t in attr.GetTimeSamplesInInterval(Gf.Interval(t0, t1)) if t0 < t < t1]
        if not [t for t in inside if t != time.GetValue()] and moves_by_velocities(prim):
            return _by_velocities(UsdGeom.Mesh(prim), time, (t0, t1), rest)
        if not attr.ValueMightBeTimeVarying():
            return None
        codes = [t0, *inside, t1]
        if len(codes) > MAX_SAMPLES:
            _warn_once(
                f"{path}: points has {len(codes)} samples within the shutter, more than the "
                f"{MAX_SAMPLES} traced; rendering it at the frame's time without motion blur"
            )
            return None
        samples = [np.asarray(attr.Get(Usd.TimeCode(t)) or [], dtype=np.float32) for t in codes]
        frame = rest
    if any(s.size != frame.size for s in samples):
        _warn_once(
            f"{path}: points change in number within the shutter (another topology); "
            "rendering it at the frame's time without motion blur"
        )
        return None
    stack = np.stack([s.reshape(-1, 3) for s in samples]).astype(np.float32)
    if np.all(stack == frame.reshape(1, -1, 3)):
        return None
    times = np.array([(t - t0) / (t1 - t0) for t in codes], dtype=np.float32)
    return times, np.ascontiguousarray(stack)


def _skinned(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    codes: list[float],
    rest: NDArray[np.float32],
    poser: SkelPoser,
    root: Usd.Prim | None,
) -> list[NDArray[np.float32]] | None:
    """A skinned mesh posed at each of ``codes``, then at ``time`` (last).

    Each in the object space of its pose at ``time``; None when it cannot be posed or is
    rigidly deformed (its pose is then a transform motion).
    """
    frame = poser.pose(prim, time, rest, root)
    if frame is None or frame.rigid:
        return None
    to_object = np.linalg.inv(frame.transform)
    out = []
    for t in codes:
        posed = poser.pose(prim, Usd.TimeCode(t), rest, root)
        if posed is None:
            return None
        points = posed.points
        if not np.array_equal(posed.transform, frame.transform):
            # Row vectors: object space at t, to world, back to the frame's object space.
            m = posed.transform @ to_object
            points = (points.astype(np.float64) @ m[:3, :3] + m[3, :3]).astype(np.float32)
        out.append(points)
    out.append(frame.points)
    return out


#: The attributes that shape each implicit prim (UsdGeom's schemas; ``axis`` is uniform).
_IMPLICIT_SHAPE = ("radius", "radiusTop", "radiusBottom", "height", "size", "width", "length")


def changes_shape_in_shutter(
    prim: Usd.Prim, time: Usd.TimeCode, shutter: tuple[float, float]
) -> bool:
    """Whether ``prim``, a gprim other than a mesh, changes shape within the shutter.

    Point-based prims (curves, points, NURBS patches): ``points`` sampled strictly inside the
    shutter at a time other than the frame's, or moving by ``velocities``; implicit prims:
    a shaping attribute (radius, height, size, ...) sampled there. Meshes: False (they blur,
    :func:`deformation_samples`).
    """
    if time.IsDefault() or shutter[1] <= shutter[0] or prim.IsA(UsdGeom.Mesh):
        return False
    t0, t1 = time.GetValue() + shutter[0], time.GetValue() + shutter[1]
    if prim.IsA(UsdGeom.PointBased):
        attrs = [UsdGeom.PointBased(prim).GetPointsAttr()]
        if moves_by_velocities(prim):
            return True
    else:
        attrs = [a for a in (prim.GetAttribute(n) for n in _IMPLICIT_SHAPE) if a]

    def sampled_inside(attr: Usd.Attribute) -> bool:
        inside = attr.GetTimeSamplesInInterval(Gf.Interval(t0, t1))
        if [t for t in inside if t0 < t < t1 and t != time.GetValue()]:
            return True
        # Samples only beyond the shutter's ends still interpolate across it.
        return bool(attr.ValueMightBeTimeVarying()) and attr.Get(t0) != attr.Get(t1)

    return any(sampled_inside(a) for a in attrs)


def moves_by_velocities(prim: Usd.Prim) -> bool:
    """Whether ``prim``'s points may move by its ``velocities`` within a shutter.

    Time-sampled ``points`` (one sample is enough) and time-sampled ``velocities``: USD
    applies velocities only from a points sample at the velocities' own time code.
    """
    based = UsdGeom.PointBased(prim)
    if not based:
        return False
    return bool(
        based.GetPointsAttr().GetNumTimeSamples() and based.GetVelocitiesAttr().GetNumTimeSamples()
    )


def _by_velocities(
    mesh: UsdGeom.Mesh,
    time: Usd.TimeCode,
    shutter: tuple[float, float],
    rest: NDArray[np.float32],
) -> tuple[NDArray[np.float32], NDArray[np.float32]] | None:
    """``mesh``'s points over the shutter (time codes ``shutter``) moved by its velocities.

    The shutter's ends only when the motion is linear; with accelerations, the ends and
    :data:`~mipray.usd.transform.MOTION_SUBSAMPLES` evenly spaced times between, so the
    blend between samples follows the parabola (off it by a·h²/8 at most, h the step).
    None, with one warning, for velocities or accelerations whose count is not the points'.
    """
    path = mesh.GetPath()
    n = len(rest)
    accelerations = mesh.GetAccelerationsAttr()
    curved = False
    for attr in (mesh.GetVelocitiesAttr(), accelerations):
        if not attr.HasAuthoredValue():
            continue
        count = len(attr.Get(time) or ())
        if count == 0:
            continue  # none at this sample: nothing moves the points (or bends their path)
        if count != n:
            _warn_once(
                f"{path}: {attr.GetName()} has {count} entries but points has {n}; "
                "rendering it at the frame's time without motion blur"
            )
            return None
        curved = attr is accelerations
    t0, t1 = shutter
    steps = MOTION_SUBSAMPLES + 1 if curved else 1
    codes = [t0 + (t1 - t0) * k / steps for k in range(steps + 1)]
    # baseTime = the frame's time: every time is computed from the one points sample at or
    # before it (as Hydra's motion blur does), so the count cannot change within the shutter.
    computed = mesh.ComputePointsAtTimes([Usd.TimeCode(t) for t in codes], time)
    stack = np.stack([np.asarray(p, dtype=np.float32).reshape(-1, 3) for p in computed])
    if stack.shape[1] != n or np.all(stack == rest.reshape(1, -1, 3)):
        return None
    times = np.array([(t - t0) / (t1 - t0) for t in codes], dtype=np.float32)
    return times, np.ascontiguousarray(stack)
