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

from .face_albedo import compute_surface_albedo, material_subsets
from .gprim import gprim_arguments, point_colors
from .material import compute_albedo
from .mesh import mesh_arguments
from .shading import material_might_vary, shading_arguments

__all__ = ["MeshRead", "read_mesh"]


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


def read_mesh(
    prim: Usd.Prim, time: Usd.TimeCode, transform: NDArray[np.float64], *, prototype: bool = False
) -> MeshRead:
    """Read the mesh ``prim`` at ``time``.

    ``transform`` is object-to-world, or for a prototype object-to-prototype-root.

    Raises:
        PrimError: the mesh's data is inconsistent (the message names the
            prim, or the GeomSubset at fault).

    """
    data_varies = any(
        a.ValueMightBeTimeVarying()
        for a in prim.GetAuthoredAttributes()
        if not a.GetName().startswith("xformOp")
    )
    if not prim.IsA(UsdGeom.Mesh):
        return _read_gprim(prim, time, transform, data_varies, prototype=prototype)
    mesh = UsdGeom.Mesh(prim)
    args = mesh_arguments(mesh, time, transform, (0.18, 0.18, 0.18))
    if args is None:
        return MeshRead(None, (), data_varies)
    surface = compute_surface_albedo(
        mesh, time, args["face_vertex_counts"], args["face_vertex_indices"], len(args["points"])
    )
    args.update(surface.arguments())
    n_faces = len(args["face_vertex_counts"])
    subsets = material_subsets(mesh, time, n_faces)
    args.update(shading_arguments(prim, time, subsets=subsets, face_count=n_faces))
    if prototype:
        args["prototype"] = True
    varies = data_varies or surface.might_vary or material_might_vary(prim, subsets)
    return MeshRead(args, surface.material_paths, varies)


def _read_gprim(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    transform: NDArray[np.float64],
    data_varies: bool,
    *,
    prototype: bool,
) -> MeshRead:
    """:func:`read_mesh` for an implicit gprim or a Points prim: one colour, no subsets."""
    args = gprim_arguments(prim, time, transform)
    if args is None:
        return MeshRead(None, (), data_varies)
    own = compute_albedo(prim, time)
    args["albedo"] = own.rgb
    if prim.IsA(UsdGeom.Points) and own.source != "material":
        args.update(point_colors(prim, time, len(args["points"])))
    args.update(shading_arguments(prim, time, surface_st=True))
    if prototype:
        args["prototype"] = True
    paths = (own.material_path,) if own.material_path else ()
    return MeshRead(args, paths, data_varies or own.might_vary or material_might_vary(prim))
