"""Read a ``UsdGeom.Mesh`` into the arguments of ``RenderDelegate.set_mesh``.

Everything the subdivision surface needs crosses as numpy arrays: points,
topology, the subdivision tags (creases, corners, holes) and the boundary and
face-varying rules, as OpenSubdiv takes them (DESIGN.md, "Mesh sync"). The data
is checked here, in Python, before it reaches the delegate: a bad mesh costs
one logged error naming its path, never the render.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom

from ..errors import PrimError

__all__ = [
    "FACE_VARYING_LINEAR_INTERPOLATIONS",
    "INTERPOLATE_BOUNDARIES",
    "SCHEMES",
    "TRIANGLE_SUBDIVISION_RULES",
    "check_mesh",
    "mesh_arguments",
]

#: USD ``subdivisionScheme`` tokens the delegate knows.
SCHEMES = frozenset({"catmullClark", "loop", "bilinear", "none"})
#: USD ``interpolateBoundary`` tokens.
INTERPOLATE_BOUNDARIES = frozenset({"none", "edgeOnly", "edgeAndCorner"})
#: USD ``faceVaryingLinearInterpolation`` tokens.
FACE_VARYING_LINEAR_INTERPOLATIONS = frozenset(
    {"none", "cornersOnly", "cornersPlus1", "cornersPlus2", "boundaries", "all"}
)
#: USD ``triangleSubdivisionRule`` tokens.
TRIANGLE_SUBDIVISION_RULES = frozenset({"catmullClark", "smooth"})


def _array(attr: Usd.Attribute, time: Usd.TimeCode, dtype: type) -> NDArray[Any]:
    """An attribute's value at ``time`` as a 1-D or 2-D numpy array (empty if unset)."""
    value = attr.Get(time) if attr else None
    if value is None:
        return np.zeros(0, dtype=dtype)
    return np.ascontiguousarray(np.asarray(value, dtype=dtype))


def _token(attr: Usd.Attribute, time: Usd.TimeCode, default: str) -> str:
    value = attr.Get(time) if attr else None
    return str(value) if value else default


def _first_bad(mask: NDArray[np.bool_]) -> int:
    """Index of the first True in ``mask``."""
    return int(np.flatnonzero(mask)[0])


def _check_indices(name: str, indices: NDArray[np.int32], limit: int, what: str) -> str | None:
    """A problem with ``indices`` (each must be in [0, limit)), or None."""
    if indices.size == 0:
        return None
    bad = (indices < 0) | (indices >= limit)
    if bad.any():
        i = _first_bad(bad)
        return f"{name}[{i}] = {int(indices[i])} is out of range for {limit} {what}"
    return None


def check_mesh(args: dict[str, Any]) -> str | None:
    """Check ``set_mesh`` arguments; return the first problem found, or None.

    Checks, in this order: points are finite and (N, 3); face counts are at
    least 3 and add up to the number of face-vertex indices; indices are in
    range; ``loop`` meshes are all triangles; creases, corners and holes are
    consistent and in range; subdivision tokens are known; the transform is
    finite.
    """
    points: NDArray[np.float32] = args["points"]
    counts: NDArray[np.int32] = args["face_vertex_counts"]
    indices: NDArray[np.int32] = args["face_vertex_indices"]
    n_points = len(points)

    if points.ndim != 2 or points.shape[1] != 3:
        return f"points has shape {points.shape}, expected (N, 3)"
    finite: NDArray[np.bool_] = np.asarray(np.isfinite(points).all(axis=1), dtype=np.bool_)
    if not finite.all():
        i = _first_bad(~finite)
        return f"points[{i}] = {tuple(float(c) for c in points[i])} is not finite"
    if counts.size and (counts < 3).any():
        i = _first_bad(counts < 3)
        return f"faceVertexCounts[{i}] = {int(counts[i])}; a face needs at least 3 vertices"
    total = int(counts.sum(dtype=np.int64))
    if total != len(indices):
        return (
            f"faceVertexCounts add up to {total} but faceVertexIndices has {len(indices)} entries"
        )
    problem = _check_indices("faceVertexIndices", indices, n_points, "points")
    if problem:
        return problem

    scheme = args["scheme"]
    if scheme not in SCHEMES:
        return f"unknown subdivisionScheme '{scheme}'"
    if scheme == "loop" and (counts != 3).any():
        i = _first_bad(counts != 3)
        return f"subdivisionScheme loop needs triangles, but face {i} has {int(counts[i])} vertices"
    for key, attr_name, allowed in (
        ("interpolate_boundary", "interpolateBoundary", INTERPOLATE_BOUNDARIES),
        (
            "face_varying_linear_interpolation",
            "faceVaryingLinearInterpolation",
            FACE_VARYING_LINEAR_INTERPOLATIONS,
        ),
        ("triangle_subdivision_rule", "triangleSubdivisionRule", TRIANGLE_SUBDIVISION_RULES),
    ):
        if args[key] not in allowed:
            return f"unknown {attr_name} '{args[key]}'"

    problem = _check_creases(args, n_points)
    if problem:
        return problem

    corner_indices = args["corner_indices"]
    corner_sharpnesses = args["corner_sharpnesses"]
    if corner_indices is not None or corner_sharpnesses is not None:
        ci = corner_indices if corner_indices is not None else np.zeros(0, np.int32)
        cs = corner_sharpnesses if corner_sharpnesses is not None else np.zeros(0, np.float32)
        if len(ci) != len(cs):
            return f"cornerIndices has {len(ci)} entries but cornerSharpnesses has {len(cs)}"
        problem = _check_indices("cornerIndices", ci, n_points, "points")
        if problem:
            return problem
        if not np.isfinite(cs).all():
            return f"cornerSharpnesses[{_first_bad(~np.isfinite(cs))}] is not finite"

    holes = args["hole_indices"]
    if holes is not None:
        problem = _check_indices("holeIndices", holes, len(counts), "faces")
        if problem:
            return problem

    if not np.isfinite(args["transform"]).all():
        return "the world transform is not finite"
    return None


def _check_creases(args: dict[str, Any], n_points: int) -> str | None:
    indices = args["crease_indices"]
    lengths = args["crease_lengths"]
    sharpnesses = args["crease_sharpnesses"]
    if indices is None and lengths is None and sharpnesses is None:
        return None
    indices = indices if indices is not None else np.zeros(0, np.int32)
    lengths = lengths if lengths is not None else np.zeros(0, np.int32)
    sharpnesses = sharpnesses if sharpnesses is not None else np.zeros(0, np.float32)
    if lengths.size and (lengths < 2).any():
        i = _first_bad(lengths < 2)
        return f"creaseLengths[{i}] = {int(lengths[i])}; a crease needs at least 2 vertices"
    total = int(lengths.sum(dtype=np.int64))
    if total != len(indices):
        return f"creaseLengths add up to {total} but creaseIndices has {len(indices)} entries"
    # USD allows one sharpness per crease or one per crease edge.
    per_edge = total - len(lengths)
    if len(sharpnesses) not in (len(lengths), per_edge):
        return (
            f"creaseSharpnesses has {len(sharpnesses)} entries; expected {len(lengths)} "
            f"(one per crease) or {per_edge} (one per crease edge)"
        )
    if not np.isfinite(sharpnesses).all():
        return f"creaseSharpnesses[{_first_bad(~np.isfinite(sharpnesses))}] is not finite"
    return _check_indices("creaseIndices", indices, n_points, "points")


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

    Raises:
        PrimError: the data is inconsistent (see :func:`check_mesh`).

    """
    path = str(mesh.GetPath())
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
    problem = check_mesh(args)
    if problem:
        raise PrimError(path, problem)
    return args
