"""Everything ``set_mesh`` needs for one ``UsdGeom.Mesh`` (or other gprim), read in one place.

The topology and subdivision tags (:func:`mipray.usd.mesh.mesh_arguments`),
then the per-face diffuse colours (:func:`mipray.usd.face_albedo.compute_surface_albedo`).
Implicit gprims and points cross as their shape (:func:`mipray.usd.gprim.gprim_arguments`)
with one colour.
Both the scene delegate (meshes rendered in place) and the instancing code
(prototype meshes) read meshes through :func:`read_mesh`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom

from ..errors import PrimError
from .curves import CURVE_TYPES
from .deform import moves_by_velocities
from .face_albedo import compute_surface_albedo, material_subsets
from .gprim import curve_colors, gprim_arguments, point_colors
from .material import compute_albedo, display_opacity, lambertian
from .mesh import mesh_arguments
from .primvars import primvar_argument, read_normals
from .shading import material_might_vary, shading_arguments
from .skel import Posed, SkelPoser, is_skinned
from .warn import warn_once

__all__ = ["MeshRead", "read_mesh"]

_warn_once = warn_once(__name__)


@dataclass(frozen=True)
class MeshRead:
    """One mesh read at one time code."""

    #: ``set_mesh`` keyword arguments (without the path), or None for a mesh
    #: without faces (valid USD that renders nothing).
    args: dict[str, Any] | None
    #: Materials bound to the mesh and its GeomSubsets.
    material_paths: tuple[str, ...]
    #: Whether the mesh's data (not its transform) might change over time.
    might_vary: bool
    #: A skinned mesh's posed world bounds (min and max corners), which its rest extent
    #: does not give; None for other meshes.
    posed_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    #: A rigidly deformed skinned mesh: its pose is its transform (see :mod:`mipray.usd.skel`).
    rigid: bool = False


def read_mesh(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    transform: NDArray[np.float64],
    *,
    prototype: bool = False,
    poser: SkelPoser | None = None,
    root: Usd.Prim | None = None,
) -> MeshRead:
    """Read the mesh ``prim`` at ``time``.

    ``transform`` is object-to-world, or for a prototype object-to-prototype-root (``root``,
    the prototype's root prim). A skinned mesh is posed at ``time`` by ``poser``
    (:mod:`mipray.usd.skel`; one is made if None): its points posed, its transform the
    skeleton's (in a prototype: the skeleton's to ``root``).

    Raises:
        PrimError: the mesh's data is inconsistent (the message names the
            prim, or the GeomSubset at fault).

    """
    # A mesh moving by velocities from one points sample is re-read and blurred like one whose
    # points are sampled twice (ValueMightBeTimeVarying is False for one sample).
    data_varies = moves_by_velocities(prim) or any(
        a.ValueMightBeTimeVarying()
        for a in prim.GetAuthoredAttributes()
        if not a.GetName().startswith("xformOp")
    )
    if not prim.IsA(UsdGeom.Mesh):
        return _read_gprim(prim, time, transform, data_varies, prototype=prototype)
    mesh = UsdGeom.Mesh(prim)
    args = mesh_arguments(mesh, time, transform)
    if args is None:
        return MeshRead(None, (), data_varies)
    posed = _pose(prim, time, args["points"], root if prototype else None, poser)
    if posed is not None:
        args["points"], args["transform"] = posed.points, posed.transform
    counts, n_points = args["face_vertex_counts"], len(args["points"])
    surface = compute_surface_albedo(mesh, time, counts, args["face_vertex_indices"], n_points)
    path = str(prim.GetPath())
    args["material"] = surface.material(path)
    primvars: dict[str, Any] = dict(surface.primvars)
    n_faces = len(counts)
    subsets = material_subsets(mesh, time, n_faces)
    shading = shading_arguments(prim, time, subsets=subsets, face_count=n_faces)
    primvars.update(shading.pop("primvars", {}))
    args.update(shading)
    if args.get("material") != surface.material(path) and primvars.get(
        "opacity"
    ) is surface.primvars.get("opacity"):
        # A material of the mesh's own took over: displayOpacity stands in for one only.
        primvars.pop("opacity", None)
    surface.face_arguments(path, args, primvars)
    normals, normals_vary = _normals(mesh, time, args["scheme"], counts, n_points)
    if normals is not None:
        primvars["normals"] = normals
    if primvars:
        args["primvars"] = primvars
    if prototype:
        args["prototype"] = True
    varies = data_varies or surface.might_vary or normals_vary or material_might_vary(prim, subsets)
    if posed is None:
        return MeshRead(args, surface.material_paths, varies)
    world = posed.points.astype(np.float64) @ posed.transform[:3, :3] + posed.transform[3, :3]
    bounds = (world.min(axis=0), world.max(axis=0)) if len(world) else None
    return MeshRead(args, surface.material_paths, varies or posed.might_vary, bounds, posed.rigid)


def _pose(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    points: NDArray[np.float32],
    root: Usd.Prim | None,
    poser: SkelPoser | None,
) -> Posed | None:
    """A skinned mesh posed at ``time``, or None (not skinned, or at rest with a warning).

    ``root``: the root of the instancing prototype the mesh is in (None: not in one).
    """
    if not is_skinned(prim):
        return None
    return (poser or SkelPoser()).pose(prim, time, points, root)


def _normals(
    mesh: UsdGeom.Mesh, time: Usd.TimeCode, scheme: str, counts: NDArray[np.int32], n_points: int
) -> tuple[dict[str, Any] | None, bool]:
    """A polygonal mesh's authored normals as a ``primvars`` entry, and whether they may vary.

    Subdivision surfaces ignore authored normals, as UsdGeom.Mesh says (they have their own);
    bad normals are warned about once, naming the prim and attribute, and the mesh shades with
    its own faceted normals.
    """
    if scheme != "none":
        return None, False
    try:
        normals = read_normals(mesh, time, counts, n_points)
    except PrimError as exc:
        _warn_once(f"{exc}; shading the mesh with its faces' own normals")
        return None, False
    if normals is None:
        return None, False
    return primvar_argument(normals), normals.might_vary


def _read_gprim(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    transform: NDArray[np.float64],
    data_varies: bool,
    *,
    prototype: bool,
) -> MeshRead:
    """:func:`read_mesh` for an implicit gprim, a Points or a curves prim: no subsets."""
    args = gprim_arguments(prim, time, transform)
    if args is None:
        return MeshRead(None, (), data_varies)
    own = compute_albedo(prim, time)
    alpha = display_opacity(prim, time) if own.source != "material" else 1.0
    args["material"] = lambertian(str(prim.GetPath()), own.rgb, alpha)
    if prim.IsA(UsdGeom.Points) and own.source != "material":
        args.update(point_colors(prim, time, len(args["points"]), alpha))
    elif any(prim.IsA(t) for t in CURVE_TYPES) and own.source != "material":
        args.update(curve_colors(prim, time, len(args["gprim"]["curve_vertex_counts"]), alpha))
    args.update(shading_arguments(prim, time, surface_st=True))
    if prototype:
        args["prototype"] = True
    paths = (own.material_path,) if own.material_path else ()
    return MeshRead(args, paths, data_varies or own.might_vary or material_might_vary(prim))
