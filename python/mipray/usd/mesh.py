"""Read a ``UsdGeom.Mesh`` into the arguments of ``RenderDelegate.set_mesh``.

Everything the subdivision surface needs crosses as numpy arrays: points,
topology, the subdivision tags (creases, corners, holes) and the boundary and
face-varying rules, as OpenSubdiv takes them (DESIGN.md, "Mesh sync"). The data
is checked once, by the delegate's ``set_mesh`` (in Rust), which refuses a bad
mesh with a :class:`~mipray.errors.PrimDataError` naming its path: one logged
error, never the render.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom

from .warn import warn_once

__all__ = ["mesh_arguments"]

_warn = warn_once(__name__)


def _array(attr: Usd.Attribute, time: Usd.TimeCode, dtype: type) -> NDArray[Any]:
    """An attribute's value at ``time`` as a 1-D or 2-D numpy array (empty if unset)."""
    value = attr.Get(time) if attr else None
    if value is None:
        return np.zeros(0, dtype=dtype)
    return np.ascontiguousarray(np.asarray(value, dtype=dtype))


def _token(attr: Usd.Attribute, time: Usd.TimeCode, default: str) -> str:
    value = attr.Get(time) if attr else None
    return str(value) if value else default


def mesh_arguments(
    mesh: UsdGeom.Mesh,
    time: Usd.TimeCode,
    transform: NDArray[np.float64],
) -> dict[str, Any] | None:
    """The geometry keyword arguments of ``RenderDelegate.set_mesh`` for ``mesh`` at ``time``.

    Shading is not among them (:mod:`mipray.usd.face_albedo`, :mod:`mipray.usd.shading`).

    Optional subdivision tags that are unauthored or empty are passed as
    ``None``.

    Returns:
        The arguments (without the path), or None if the mesh has no faces
        (an empty mesh is valid USD and simply renders nothing).

    The data is not checked here: the delegate's ``set_mesh`` checks it, once.

    """
    points = _array(mesh.GetPointsAttr(), time, np.float32)
    counts = _array(mesh.GetFaceVertexCountsAttr(), time, np.int32)
    indices = _array(mesh.GetFaceVertexIndicesAttr(), time, np.int32)
    if counts.size == 0 and indices.size == 0:
        return None
    if points.ndim == 1 and points.size == 0:
        points = points.reshape(0, 3)

    def optional(attr: Usd.Attribute, dtype: type) -> NDArray[Any] | None:
        value = _array(attr, time, dtype)
        return value if value.size else None

    args: dict[str, Any] = {
        "points": points,
        "face_vertex_counts": counts,
        "face_vertex_indices": indices,
        "transform": transform,
        "scheme": _token(mesh.GetSubdivisionSchemeAttr(), time, "catmullClark"),
        "interpolate_boundary": _token(mesh.GetInterpolateBoundaryAttr(), time, "edgeAndCorner"),
        "face_varying_linear_interpolation": _token(
            mesh.GetFaceVaryingLinearInterpolationAttr(), time, "cornersPlus1"
        ),
        "triangle_subdivision_rule": _token(
            mesh.GetTriangleSubdivisionRuleAttr(), time, "catmullClark"
        ),
        "crease_indices": optional(mesh.GetCreaseIndicesAttr(), np.int32),
        "crease_lengths": optional(mesh.GetCreaseLengthsAttr(), np.int32),
        "crease_sharpnesses": optional(mesh.GetCreaseSharpnessesAttr(), np.float32),
        "corner_indices": optional(mesh.GetCornerIndicesAttr(), np.int32),
        "corner_sharpnesses": optional(mesh.GetCornerSharpnessesAttr(), np.float32),
        "hole_indices": optional(mesh.GetHoleIndicesAttr(), np.int32),
        "left_handed": _token(mesh.GetOrientationAttr(), time, "rightHanded") == "leftHanded",
        "double_sided": bool(mesh.GetDoubleSidedAttr().Get(time) or False),
    }
    if args["scheme"] == "loop" and counts.size and (counts != 3).any():
        # OpenSubdiv's Loop scheme takes triangles only. Storm (usdrecord) draws such a mesh
        # unrefined, and so does this, rather than leave it out.
        face = int(np.flatnonzero(counts != 3)[0])
        _warn(
            f"{mesh.GetPath()}: subdivisionScheme loop needs triangles, but face {face} has "
            f"{int(counts[face])} vertices; rendered unsubdivided (as subdivisionScheme none), "
            "as Storm draws it"
        )
        args["scheme"] = "none"
    return args
