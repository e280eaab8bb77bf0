"""``primvars:displayColor`` and ``primvars:displayOpacity`` of a mesh, checked and per face.

A primvar's interpolation says how many values it holds: ``constant`` one,
``uniform`` one per face, ``vertex`` and ``varying`` one per point,
``faceVarying`` one per face-vertex. Indexed primvars are flattened through
their indices first. A size that does not match, an index out of range or a
value that is not finite is an error naming the prim (the mesh is skipped,
the rest of the stage renders).

Vertex, varying and faceVarying colours cross to the renderer as they are
(:func:`primvar_argument`) and are interpolated over the surface; where one
colour per face is wanted (a GeomSubset's fallback) they are averaged over
each face's corners (:func:`per_face`). ``displayOpacity`` is read and checked
the same way; it does not change the picture yet. Authored normals of polygonal meshes
(``primvars:normals``, else ``normals``) are read by :func:`read_normals`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom

from ..errors import PrimError

__all__ = [
    "INTERPOLATIONS",
    "DisplayPrimvar",
    "per_face",
    "per_face_vertex",
    "primvar_argument",
    "read_display_primvar",
    "read_normals",
]

#: The interpolation tokens UsdGeom defines for primvars.
INTERPOLATIONS = ("constant", "uniform", "vertex", "varying", "faceVarying")


@dataclass(frozen=True)
class DisplayPrimvar:
    """A display primvar's flattened values and how they map onto the mesh."""

    #: The primvar's name, e.g. ``"displayColor"``.
    name: str
    #: Flattened values: (N, 3) float32 for colours, (N, 1) for opacities.
    values: NDArray[np.float32]
    #: One of :data:`INTERPOLATIONS`.
    interpolation: str
    #: Whether the value might change over time.
    might_vary: bool


def _expected_size(
    interpolation: str, counts: NDArray[np.int32], n_points: int, n_face_vertices: int
) -> int | None:
    return {
        "constant": None,  # one or more; the first is used
        "uniform": len(counts),
        "vertex": n_points,
        "varying": n_points,
        "faceVarying": n_face_vertices,
    }[interpolation]


def read_display_primvar(
    mesh: UsdGeom.Mesh,
    name: str,
    time: Usd.TimeCode,
    counts: NDArray[np.int32],
    n_points: int,
    width: int | None = None,
) -> DisplayPrimvar | None:
    """Read ``primvars:<name>`` (``displayColor`` or ``displayOpacity``) of ``mesh``.

    Args:
        mesh: the mesh.
        name: ``"displayColor"`` (three components) or ``"displayOpacity"`` (one).
        time: the time code.
        counts: the mesh's faceVertexCounts (already checked).
        n_points: the number of points.
        width: the component count wanted; None: 3 for ``displayColor``, else 1.

    Returns:
        The values, or None when the primvar is unauthored or empty.

    Raises:
        PrimError: an unknown interpolation, an index out of range, a size
            that does not match the interpolation, or a value that is not
            finite. The message names the mesh and the primvar.

    """
    path = str(mesh.GetPath())
    primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar(name)
    if not primvar or not primvar.HasValue():
        return None
    return _checked(path, primvar, f"primvars:{name}", name, time, counts, n_points, width)


def _checked(
    path: str,
    primvar: UsdGeom.Primvar,
    attr: str,
    name: str,
    time: Usd.TimeCode,
    counts: NDArray[np.int32],
    n_points: int,
    width: int | None,
    interpolation: str | None = None,
) -> DisplayPrimvar | None:
    """A primvar's flattened values checked against the mesh.

    As :func:`read_display_primvar`; ``interpolation`` overrides the primvar's own.
    """
    raw = primvar.Get(time)
    if raw is None or len(raw) == 0:
        return None
    if width is None:
        width = 3 if name == "displayColor" else 1
    values = np.asarray(raw, dtype=np.float32).reshape(len(raw), -1)
    if values.shape[1] != width:
        raise PrimError(path, f"{attr} has {values.shape[1]} components, expected {width}")
    interpolation = interpolation or str(primvar.GetInterpolation())
    if interpolation not in INTERPOLATIONS:
        raise PrimError(path, f"{attr} has unknown interpolation '{interpolation}'")
    if primvar.IsIndexed():
        indices = np.asarray(primvar.GetIndices(time), dtype=np.int64)
        bad = (indices < 0) | (indices >= len(values))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise PrimError(
                path,
                f"{attr}:indices[{i}] = {int(indices[i])} is out of range for {len(values)} values",
            )
        values = values[indices]
    expected = _expected_size(interpolation, counts, n_points, int(counts.sum(dtype=np.int64)))
    if expected is not None and len(values) != expected:
        what = {"uniform": "faces", "faceVarying": "face-vertices"}.get(interpolation, "points")
        raise PrimError(
            path,
            f"{attr} ({interpolation}) has {len(values)} values for {expected} {what}",
        )
    finite = np.isfinite(values).all(axis=1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise PrimError(path, f"{attr}[{i}] = {tuple(values[i].tolist())} is not finite")
    might_vary = bool(primvar.ValueMightBeTimeVarying()) or bool(
        primvar.IsIndexed() and primvar.GetIndicesAttr().ValueMightBeTimeVarying()
    )
    return DisplayPrimvar(name, values, interpolation, might_vary)


def per_face_vertex(
    values: NDArray[Any],
    interpolation: str,
    counts: NDArray[Any],
    face_vertex_indices: NDArray[Any],
) -> NDArray[Any]:
    """One value per face-vertex of flattened (not indexed) ``values``.

    A constant repeated, a face's value at each of its corners, a point's at each corner on
    it, face-varying values as they are. Sizes are the caller's to have checked.
    """
    if interpolation == "constant":
        return np.repeat(values[:1], len(face_vertex_indices), axis=0)
    if interpolation == "uniform":
        return np.repeat(values, counts, axis=0)
    if interpolation in ("vertex", "varying"):
        corners: NDArray[Any] = values[face_vertex_indices]
        return corners
    return values


def per_face(
    primvar: DisplayPrimvar, counts: NDArray[np.int32], face_vertex_indices: NDArray[np.int32]
) -> NDArray[np.float32]:
    """One value per face.

    Uniform values as they are; per-point and per-face-vertex values averaged
    over each face's corners; a constant repeated.

    Returns:
        (F, C) float32, C the primvar's component count.

    """
    values = primvar.values
    n_faces = len(counts)
    if primvar.interpolation == "constant":
        return np.repeat(values[:1], n_faces, axis=0)
    if primvar.interpolation == "uniform":
        return values
    corners = per_face_vertex(values, primvar.interpolation, counts, face_vertex_indices)
    if n_faces == 0:
        return np.zeros((0, values.shape[1]), np.float32)
    starts = np.concatenate(([0], np.cumsum(counts[:-1], dtype=np.int64)))
    sums = np.add.reduceat(corners.astype(np.float64), starts, axis=0)
    return np.asarray(sums / counts[:, None], dtype=np.float32)


def read_normals(
    mesh: UsdGeom.Mesh, time: Usd.TimeCode, counts: NDArray[np.int32], n_points: int
) -> DisplayPrimvar | None:
    """A polygonal mesh's authored normals, flattened and checked.

    ``primvars:normals`` if authored (it wins, as UsdGeom says), else ``normals`` with its
    ``interpolation`` metadata.

    Returns:
        The normals (name ``"normals"``), or None when neither is authored.

    Raises:
        PrimError: as :func:`read_display_primvar`, naming the attribute read.

    """
    path = str(mesh.GetPath())
    primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("normals")
    if primvar and primvar.HasValue():
        return _checked(path, primvar, "primvars:normals", "normals", time, counts, n_points, 3)
    attr = mesh.GetNormalsAttr()
    if not attr or not attr.HasValue():
        return None
    # A plain attribute read as a primvar: its values and indices (none), with the
    # interpolation UsdGeomPointBased gives it (vertex unless authored).
    interpolation = str(mesh.GetNormalsInterpolation())
    return _checked(
        path, UsdGeom.Primvar(attr), "normals", "normals", time, counts, n_points, 3, interpolation
    )


def primvar_argument(primvar: DisplayPrimvar) -> dict[str, Any]:
    """A checked primvar as ``set_mesh``'s ``primvars`` entry.

    Its flattened values (a constant's first only), no indices, its interpolation.
    """
    values = primvar.values[:1] if primvar.interpolation == "constant" else primvar.values
    return {
        "values": np.ascontiguousarray(values, dtype=np.float32),
        "indices": None,
        "interpolation": primvar.interpolation,
    }
