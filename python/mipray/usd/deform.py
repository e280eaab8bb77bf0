"""Points of meshes, Points and curves across the camera's shutter: deformation blur.

A ``UsdGeom.Mesh`` whose ``points`` are time-sampled inside the shutter, or a skinned mesh
(:mod:`mipray.usd.skel`) whose skeleton or blend shapes move in it, crosses as its points at
the shutter's ends and at its authored samples between (a skinned mesh at the ends and
:data:`~mipray.usd.transform.MOTION_SUBSAMPLES` evenly spaced times between, so a bending
joint sweeps close to its arc rather than along the chord), each in the object space of the
transform the mesh was sent with at the frame's time. The renderer builds the mesh at each
sample over its one topology and blends between them at each ray's time (``mipray.deform``
in the core).

``UsdGeom.Points`` (particles) and curves (``BasisCurves``, ``NurbsCurves``) cross the same
way: their points at the shutter's ends and at the authored samples between (or moved by
``velocities``), and, when their ``widths`` change within the shutter, their widths at those
times too (the times are then those of both attributes' samples). The renderer blends each
sphere's centre and radius, and each curve's control points and widths, at each ray's time
(``PointsSurface`` and ``CurvesSurface`` in the core). A NurbsCurves prim's samples are its
points converted to Bézier segments as at the frame's time (the conversion is linear in the
points). A curve's ``normals`` stay the frame's.

What cannot be blurred is warned about once, naming the prim, and the prim renders at the
frame's time: a point count that changes within the shutter (another topology), widths whose
count changes within it, or more samples than :data:`MAX_SAMPLES`.

Implicit prims whose sizes (``radius``, ``height``, ``size``, ...) are sampled inside the
shutter cross as their ``gprim`` argument at the shutter's ends and at those samples; the
renderer intersects the shape of sizes blended at each ray's time exactly. Sizes a shape
cannot take at one of the samples: one warning, rendered at the frame's time. A NurbsPatch
whose points move within the shutter is named by :func:`changes_shape_in_shutter` and
renders at the frame's time.

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

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from pxr import Gf, Usd, UsdGeom

from ..errors import PrimError
from .curves import CURVE_TYPES, curves_arguments
from .gprim import implicit_shape
from .skel import SkelPoser, is_skinned
from .transform import MOTION_SUBSAMPLES
from .warn import warn_once

__all__ = [
    "MAX_SAMPLES",
    "Deformation",
    "changes_shape_in_shutter",
    "deformation_samples",
    "moves_by_velocities",
]

#: Most samples the renderer takes across one shutter (``mipray::deform::MAX_SAMPLES``).
MAX_SAMPLES = 16

_warn_once = warn_once(__name__)


class Deformation(NamedTuple):
    """A prim's shape over the shutter: ``set_deformation``'s arguments."""

    #: (N,) float32 shutter fractions, 0 = open, 1 = close, strictly increasing.
    times: NDArray[np.float32]
    #: (N, P, 3) float32 points in the object space the prim was sent in.
    points: NDArray[np.float32]
    #: (N, W) float32 widths of a Points or curves prim whose widths change within the
    #: shutter (as many as the prim sent); None keeps the prim's own.
    widths: NDArray[np.float32] | None = None
    #: An implicit prim's ``gprim`` argument at each sample (its points are then (N, 0, 3));
    #: None for other prims.
    gprims: list[dict[str, Any]] | None = None


def deformation_samples(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    shutter: tuple[float, float],
    poser: SkelPoser,
    root: Usd.Prim | None = None,
) -> Deformation | None:
    """``prim``'s points (and widths) across the shutter, or None when they do not change in it.

    ``prim``: a mesh, a Points or a curves prim (other prims give None). ``root``: the root of
    the instancing prototype ``prim`` is in (a skinned mesh there is posed relative to it,
    :meth:`~mipray.usd.skel.SkelPoser.pose`); None outside one.

    Returns the samples in the object space the prim was sent in at ``time`` (its
    :class:`Deformation`). ``shutter`` is relative to ``time`` (frames). None too, with one
    warning naming the prim, when the deformation cannot be blurred (see the module's note).
    """
    if time.IsDefault() or shutter[1] <= shutter[0]:
        return None
    t0, t1 = time.GetValue() + shutter[0], time.GetValue() + shutter[1]
    if prim.IsA(UsdGeom.Mesh):
        return _mesh_samples(prim, time, (t0, t1), poser, root)
    if prim.IsA(UsdGeom.Points) or any(prim.IsA(t) for t in CURVE_TYPES):
        return _points_or_curves(prim, time, (t0, t1))
    return _implicit(prim, time, (t0, t1))


def _implicit(
    prim: Usd.Prim, time: Usd.TimeCode, shutter: tuple[float, float]
) -> Deformation | None:
    """An implicit prim's shape at ``shutter``'s ends (time codes) and its sizes' samples.

    When a size (radius, height, size, ...) changes within the shutter; None for other prims,
    or (with one warning naming the prim) sizes the prim cannot take there.
    """
    if implicit_shape(prim, time) is None:
        return None
    attrs = [a for a in (prim.GetAttribute(n) for n in _IMPLICIT_SHAPE) if a]
    varying = [a for a in attrs if _varies_in(a, time, shutter)]
    if not varying:
        return None
    path = prim.GetPath()
    codes = sorted({*shutter, *(t for a in varying for t in _inside(a, time, shutter))})
    if len(codes) > MAX_SAMPLES:
        _too_many(path, "its sizes", len(codes))
        return None
    try:
        shapes = [implicit_shape(prim, Usd.TimeCode(t)) for t in codes]
    except PrimError as e:
        _warn_once(
            f"{path}: {e.reason} within the shutter; rendering it at the frame's time without "
            "motion blur"
        )
        return None
    points = np.zeros((len(codes), 0, 3), dtype=np.float32)
    return Deformation(_fractions(codes, shutter), points, None, [s for s in shapes if s])


def _inside(attr: Usd.Attribute, time: Usd.TimeCode, shutter: tuple[float, float]) -> list[float]:
    """``attr``'s sample times strictly inside ``shutter`` (time codes)."""
    t0, t1 = shutter
    return [t for t in attr.GetTimeSamplesInInterval(Gf.Interval(t0, t1)) if t0 < t < t1]


def _varies_in(attr: Usd.Attribute, time: Usd.TimeCode, shutter: tuple[float, float]) -> bool:
    """Whether ``attr``'s value changes within ``shutter`` (time codes).

    A sample inside it at another time than the frame's, or samples beyond its ends that
    interpolate across it.
    """
    if not attr or not attr.ValueMightBeTimeVarying():
        return False
    if [t for t in _inside(attr, time, shutter) if t != time.GetValue()]:
        return True
    return bool(attr.Get(shutter[0]) != attr.Get(shutter[1]))


def _mesh_samples(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    shutter: tuple[float, float],
    poser: SkelPoser,
    root: Usd.Prim | None,
) -> Deformation | None:
    """A mesh's points across ``shutter`` (time codes), posed when it is skinned."""
    t0, t1 = shutter
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
        inside = _inside(attr, time, shutter)
        if not [t for t in inside if t != time.GetValue()] and moves_by_velocities(prim):
            moved = _by_velocities(UsdGeom.PointBased(prim), time, shutter, rest)
            return None if moved is None else Deformation(*moved)
        if not attr.ValueMightBeTimeVarying():
            return None
        codes = [t0, *inside, t1]
        if len(codes) > MAX_SAMPLES:
            _too_many(path, "points", len(codes))
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
    return Deformation(_fractions(codes, shutter), np.ascontiguousarray(stack))


def _too_many(path: Usd.Path, what: str, count: int) -> None:
    _warn_once(
        f"{path}: {what} has {count} samples within the shutter, more than the "
        f"{MAX_SAMPLES} traced; rendering it at the frame's time without motion blur"
    )


def _fractions(codes: list[float], shutter: tuple[float, float]) -> NDArray[np.float32]:
    t0, t1 = shutter
    return np.array([(t - t0) / (t1 - t0) for t in codes], dtype=np.float32)


def _points_or_curves(
    prim: Usd.Prim, time: Usd.TimeCode, shutter: tuple[float, float]
) -> Deformation | None:
    """A Points or curves prim's points, and widths when they change, across ``shutter``.

    The points and widths of each sample are what the prim sends at the frame's time
    (:func:`mipray.usd.gprim.gprim_arguments`) made of that sample's attribute values: a
    Points prim's as authored, a curves prim's through :func:`curves_arguments` (a
    NurbsCurves prim's converted to Bézier segments).
    """
    t0, t1 = shutter
    path = prim.GetPath()
    based = UsdGeom.PointBased(prim)
    points_attr = based.GetPointsAttr()
    widths_attr = prim.GetAttribute("widths")
    rest = np.asarray(points_attr.Get(time) or [], dtype=np.float32).reshape(-1, 3)
    widths_vary = _varies_in(widths_attr, time, shutter)
    inside = [t for t in _inside(points_attr, time, shutter) if t != time.GetValue()]
    if not inside and moves_by_velocities(prim):
        moved = _by_velocities(based, time, shutter, rest)
        if moved is None:
            return None
        codes = [t0 + (t1 - t0) * float(f) for f in moved[0]]
        raw = list(moved[1])
    elif _varies_in(points_attr, time, shutter) or widths_vary:
        codes = sorted({t0, t1, *_inside(points_attr, time, shutter)})
        if widths_vary:
            codes = sorted({*codes, *_inside(widths_attr, time, shutter)})
        if len(codes) > MAX_SAMPLES:
            _too_many(path, "points and widths" if widths_vary else "points", len(codes))
            return None
        raw = [
            np.asarray(points_attr.Get(Usd.TimeCode(t)) or [], dtype=np.float32).reshape(-1, 3)
            for t in codes
        ]
    else:
        return None
    if any(len(p) != len(rest) for p in raw):
        _warn_once(
            f"{path}: points change in number within the shutter; rendering it at the "
            "frame's time without motion blur"
        )
        return None
    raw_widths = (
        [np.asarray(widths_attr.Get(Usd.TimeCode(t)) or [], dtype=np.float32) for t in codes]
        if widths_vary
        else None
    )
    if raw_widths is not None and any(len(w) != len(raw_widths[0]) for w in raw_widths):
        _warn_once(
            f"{path}: widths change in number within the shutter; rendering it at the "
            "frame's time without motion blur"
        )
        return None
    if prim.IsA(UsdGeom.Points):
        points, widths = raw, raw_widths
    else:
        try:
            converted = [
                curves_arguments(prim, time, p, None if raw_widths is None else raw_widths[k])
                for k, p in enumerate(raw)
            ]
        except PrimError:
            return None  # the prim is refused at the frame's time too, and said so there
        points = [c[0] for c in converted]
        widths = None
        if raw_widths is not None:
            sent = [np.asarray(c[1].get("widths", []), dtype=np.float32) for c in converted]
            # Widths the frame's interpolation cannot use were warned about: kept as sent.
            widths = sent if all(len(w) == len(sent[0]) and len(w) for w in sent) else None
    stack = np.ascontiguousarray(np.stack(points).astype(np.float32))
    width_stack = None if widths is None else np.ascontiguousarray(np.stack(widths), np.float32)
    if np.all(stack == stack[:1]) and (
        width_stack is None or np.all(width_stack == width_stack[:1])
    ):
        return None
    return Deformation(_fractions(codes, shutter), stack, width_stack)


def _skinned(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    codes: list[float],
    rest: NDArray[np.float32],
    poser: SkelPoser,
    root: Usd.Prim | None,
) -> list[NDArray[np.float32]] | None:
    """A skinned mesh posed at each of ``codes``, then at ``time`` (last).

    Each in the object space of its pose at ``time``; None when it cannot be posed, or is
    rigidly deformed outside a prototype (its pose is then a transform motion). Inside one
    (``root``) a rigid pose moves the points too: the prototype mesh's transform is its own,
    not the skeleton's over the shutter, so the motion travels as points.
    """
    frame = poser.pose(prim, time, rest, root)
    if frame is None or (frame.rigid and root is None):
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
    """Whether ``prim``, a gprim whose deformation is not blurred, changes shape in the shutter.

    NurbsPatch: ``points`` sampled strictly inside the shutter at a time other than the
    frame's, or moving by ``velocities``. Meshes, Points, curves and implicit prims: False
    (they blur, :func:`deformation_samples`).
    """
    if time.IsDefault() or shutter[1] <= shutter[0] or not prim.IsA(UsdGeom.NurbsPatch):
        return False
    window = (time.GetValue() + shutter[0], time.GetValue() + shutter[1])
    if moves_by_velocities(prim):
        return True
    return _varies_in(UsdGeom.PointBased(prim).GetPointsAttr(), time, window)


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
    based: UsdGeom.PointBased,
    time: Usd.TimeCode,
    shutter: tuple[float, float],
    rest: NDArray[np.float32],
) -> tuple[NDArray[np.float32], NDArray[np.float32]] | None:
    """``based``'s points over the shutter (time codes ``shutter``) moved by its velocities.

    The shutter's ends only when the motion is linear; with accelerations, the ends and
    :data:`~mipray.usd.transform.MOTION_SUBSAMPLES` evenly spaced times between, so the
    blend between samples follows the parabola (off it by a·h²/8 at most, h the step).
    None, with one warning, for velocities or accelerations whose count is not the points'.
    """
    path = based.GetPath()
    n = len(rest)
    accelerations = based.GetAccelerationsAttr()
    curved = False
    for attr in (based.GetVelocitiesAttr(), accelerations):
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
    computed = based.ComputePointsAtTimes([Usd.TimeCode(t) for t in codes], time)
    stack = np.stack([np.asarray(p, dtype=np.float32).reshape(-1, 3) for p in computed])
    if stack.shape[1] != n or np.all(stack == rest.reshape(1, -1, 3)):
        return None
    return _fractions(codes, shutter), np.ascontiguousarray(stack)
