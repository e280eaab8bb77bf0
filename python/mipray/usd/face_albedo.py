"""A mesh's diffuse colour per face: its material, its GeomSubsets' materials, displayColor.

Each control face gets, in order:

1. the constant ``diffuseColor`` of the material bound to a GeomSubset
   (``familyName = "materialBind"``) that holds the face, resolved as USD
   resolves bindings (the subset's own binding, else its ancestors');
2. else that of the mesh's bound material (see :mod:`mipray.usd.material`);
3. else ``primvars:displayColor`` — uniform per face, constant everywhere;
   vertex, varying and faceVarying (indexed or not) interpolated over the
   surface as authored: the face's entry is its corners' mean (its colour at
   the centre for bilinear interpolation) and the primvar crosses as
   ``set_mesh``'s ``primvars["diffuseColor"]``, which the renderer
   interpolates over the faces of the mesh's own material (OpenSubdiv's
   face-varying and vertex evaluation on subdivision surfaces, linear over
   each face on polygonal ones);
4. else 0.18 grey.

Faces coloured by steps 3 and 4 take ``primvars:displayOpacity`` as their
opacity: partly transparent as UsdPreviewSurface's ``opacity`` is
(:func:`mipray.usd.material.lambertian`). A constant one is the faces'
materials' opacity; any other interpolation crosses as ``primvars["opacity"]``
(and a uniform ``displayColor`` with it as ``primvars["diffuseColor"]``), read by
the mesh's own material. A material's faces keep the material's own opacity: in
USD the display primvars stand in for a material.

A material whose diffuse colour is not a constant (a texture) falls through to
step 3 for its faces here; a subset bound to a UsdPreviewSurface also sends its
whole network (textures and every lobe) for its faces
(:func:`mipray.usd.shading.shading_arguments`, ``face_materials``), which the
renderer uses over this colour. The colours cross in the one material model
(:func:`mipray.usd.material.lambertian`): when every face ends up with the same
colour the mesh's ``material`` is that colour; otherwise the distinct colours
join the subsets' networks in ``face_materials`` / ``face_material_indices``
(:meth:`SurfaceAlbedo.face_arguments`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdGeom, UsdShade

from ..errors import PrimError
from .material import DEFAULT_ALBEDO, compute_albedo, lambertian
from .primvars import per_face, primvar_argument, read_display_primvar

__all__ = ["SurfaceAlbedo", "compute_surface_albedo", "material_subsets"]


@dataclass(frozen=True)
class SurfaceAlbedo:
    """A mesh's resolved diffuse colours, as ``set_mesh`` takes them."""

    #: Linear RGB for faces without an entry of their own (all faces when the
    #: table is None).
    albedo: tuple[float, float, float]
    #: (M, 4) float32 distinct per-face colours and opacities (``displayOpacity``), or None.
    face_albedos: NDArray[np.float32] | None
    #: (F,) int32 per face: an index into ``face_albedos``; None with it.
    face_albedo_indices: NDArray[np.int32] | None
    #: Paths of every material involved (the mesh's and its subsets'); the
    #: scene delegate re-syncs the mesh when one of them changes.
    material_paths: tuple[str, ...]
    #: Whether anything read might change over time.
    might_vary: bool
    #: ``set_mesh``'s ``primvars`` entries: ``diffuseColor`` from an interpolated
    #: ``displayColor``, ``opacity`` from an interpolated ``displayOpacity``, or empty.
    primvars: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: The faces ``primvars`` shades when a subset's constant colour takes others; None: all.
    primvar_faces: NDArray[np.int32] | None = None
    #: The opacity of faces without an entry of their own (``displayOpacity``; 1 without).
    opacity: float = 1.0

    def material(self, path: str) -> dict[str, Any]:
        """``set_mesh``'s ``material`` for the mesh without a UsdPreviewSurface of its own."""
        return lambertian(path, self.albedo, self.opacity, see_through="opacity" in self.primvars)

    def face_arguments(self, path: str, args: dict[str, Any], primvars: dict[str, Any]) -> None:
        """Puts the face colours into ``args``'s face material table.

        ``args`` holds the shading's ``face_materials`` (subsets' whole networks) if any;
        ``primvars`` is every ``set_mesh`` primvar of the mesh. In order, a face takes: a
        subset's network; else the mesh's own material where an input primvar shades it
        (:attr:`primvar_faces`, all faces when None), since only that material reads the
        primvar; else its colour; ``-1`` is the mesh's material. A colour no face keeps, or
        the mesh's own (its material being that colour), is not sent: the table lists only
        materials some face renders.
        """
        if self.face_albedos is None or self.face_albedo_indices is None:
            return
        table = self.face_albedo_indices.copy()
        if args.get("material") == self.material(path):
            own = np.asarray((*self.albedo, self.opacity), np.float32)
            table[(self.face_albedos[table] == own).all(axis=1)] = -1
        if any(role != "normals" for role in primvars):
            if self.primvar_faces is None or primvars.get("diffuseColor") is not self.primvars.get(
                "diffuseColor"
            ):
                table[:] = -1
            else:
                table[self.primvar_faces] = -1
        subsets = args.get("face_materials")
        if subsets is not None:
            subset_table = args["face_material_indices"]
            table = np.where(subset_table >= 0, subset_table + len(self.face_albedos), table)
        kept = np.unique(table[table >= 0])
        if len(kept) == 0:
            args.pop("face_materials", None)
            args.pop("face_material_indices", None)
            return
        colours = [
            lambertian(f"{path}[{k}]", c[:3], float(c[3])) for k, c in enumerate(self.face_albedos)
        ]
        materials = colours + list(subsets or [])
        remap = np.full(len(materials), -1, np.int32)
        remap[kept] = np.arange(len(kept), dtype=np.int32)
        args["face_materials"] = [materials[k] for k in kept]
        args["face_material_indices"] = np.ascontiguousarray(
            np.where(table >= 0, remap[np.maximum(table, 0)], -1), dtype=np.int32
        )


def _face_indices(subset: UsdGeom.Subset, time: Usd.TimeCode, n_faces: int) -> NDArray[np.int64]:
    """A materialBind subset's face indices, checked; errors name the subset."""
    path = str(subset.GetPath())
    element = subset.GetElementTypeAttr().Get(time) or UsdGeom.Tokens.face
    if element != UsdGeom.Tokens.face:
        raise PrimError(path, f"elementType '{element}' cannot carry a material; use 'face'")
    indices = np.asarray(subset.GetIndicesAttr().Get(time) or [], dtype=np.int64)
    bad = (indices < 0) | (indices >= n_faces)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise PrimError(
            path, f"indices[{i}] = {int(indices[i])} is out of range for {n_faces} faces"
        )
    return indices


def material_subsets(
    mesh: UsdGeom.Mesh, time: Usd.TimeCode, n_faces: int
) -> list[tuple[Usd.Prim, NDArray[np.int64]]]:
    """The mesh's materialBind GeomSubsets and their checked face indices, in USD's order.

    Raises:
        PrimError: a subset of the wrong element type or with face indices out of range
            (the message names the subset).

    """
    return [
        (subset.GetPrim(), _face_indices(subset, time, n_faces))
        for subset in UsdShade.MaterialBindingAPI(mesh.GetPrim()).GetMaterialBindSubsets()
    ]


def compute_surface_albedo(
    mesh: UsdGeom.Mesh,
    time: Usd.TimeCode,
    counts: NDArray[np.int32],
    face_vertex_indices: NDArray[np.int32],
    n_points: int,
) -> SurfaceAlbedo:
    """Resolve the per-face diffuse colour of ``mesh`` at ``time`` (see the module doc).

    ``counts``, ``face_vertex_indices`` and ``n_points`` are the mesh's
    checked topology (:func:`mipray.usd.mesh.mesh_arguments`).

    Raises:
        PrimError: a display primvar of the wrong size or with bad values, or
            a materialBind subset with face indices out of range (the message
            names the subset).

    """
    prim = mesh.GetPrim()
    n_faces = len(counts)
    own = compute_albedo(prim, time)
    paths = [own.material_path] if own.material_path else []
    might_vary = own.might_vary

    color = read_display_primvar(mesh, "displayColor", time, counts, n_points)
    opacity = read_display_primvar(mesh, "displayOpacity", time, counts, n_points)
    might_vary = might_vary or any(p.might_vary for p in (color, opacity) if p is not None)
    display: NDArray[np.float64] | None = None
    if color is not None:
        display = np.clip(per_face(color, counts, face_vertex_indices).astype(np.float64), 0, 1)
    # The display primvars' faces' opacity (1 where a material colours the face).
    alpha = np.ones((n_faces, 1), np.float64)
    if opacity is not None:
        alpha = np.clip(per_face(opacity, counts, face_vertex_indices).astype(np.float64), 0, 1)
    # A displayOpacity that varies crosses as a primvar of its own interpolation (uniform
    # too), read by the mesh's own material, and then so does a uniform displayColor: the
    # faces it shades all take that one material.
    interpolated_alpha = (
        opacity is not None and own.source != "material" and opacity.interpolation != "constant"
    )
    constant_alpha = 1.0
    if opacity is not None and own.source != "material" and not interpolated_alpha and n_faces:
        constant_alpha = float(np.float32(alpha[0, 0]))
    # A colour per point or face-vertex is interpolated over the faces by the renderer.
    interpolated = (
        color is not None
        and own.source != "material"
        and (
            color.interpolation in ("vertex", "varying", "faceVarying")
            or (interpolated_alpha and color.interpolation == "uniform")
        )
    )
    # Faces a subset's constant-colour material colours; the primvar colours the rest.
    constant = np.zeros(n_faces, dtype=bool)

    # Per face: linear RGB and opacity.
    if own.source == "material":
        faces = np.tile(np.asarray((*own.rgb, 1.0), np.float64), (n_faces, 1))
    elif display is not None:
        faces = np.concatenate([display, alpha], axis=1)
    else:
        faces = np.concatenate(
            [np.tile(np.asarray(DEFAULT_ALBEDO, np.float64), (n_faces, 1)), alpha], axis=1
        )
    fallback = np.concatenate(
        [
            display
            if display is not None
            else np.tile(np.asarray(DEFAULT_ALBEDO, np.float64), (n_faces, 1)),
            alpha,
        ],
        axis=1,
    )

    for subset in UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets():
        indices = _face_indices(subset, time, n_faces)
        bound = compute_albedo(subset.GetPrim(), time)
        if bound.material_path and bound.material_path not in paths:
            paths.append(bound.material_path)
        might_vary = (
            might_vary or bound.might_vary or subset.GetIndicesAttr().ValueMightBeTimeVarying()
        )
        if bound.source == "material":
            faces[indices] = (*bound.rgb, 1.0)
            constant[indices] = True
        else:  # a textured (or no) material: the display colour, as for the mesh
            faces[indices] = fallback[indices]

    primvars: dict[str, dict[str, Any]] = {}
    primvar_faces: NDArray[np.int32] | None = None
    if (interpolated or interpolated_alpha) and not constant.all():
        if interpolated:
            assert color is not None
            primvars["diffuseColor"] = primvar_argument(color)
        if interpolated_alpha:
            assert opacity is not None
            primvars["opacity"] = primvar_argument(opacity)
        if constant.any():
            primvar_faces = np.flatnonzero(~constant).astype(np.int32)
    if n_faces == 0 or (faces == faces[0]).all():
        rgb = (
            own.rgb
            if n_faces == 0
            else (float(faces[0, 0]), float(faces[0, 1]), float(faces[0, 2]))
        )
        return SurfaceAlbedo(
            rgb,
            None,
            None,
            tuple(paths),
            might_vary,
            primvars,
            primvar_faces,
            opacity=constant_alpha,
        )
    unique, inverse = np.unique(faces, axis=0, return_inverse=True)
    return SurfaceAlbedo(
        own.rgb,
        np.ascontiguousarray(unique, dtype=np.float32),
        np.ascontiguousarray(inverse.reshape(-1), dtype=np.int32),
        tuple(paths),
        might_vary,
        primvars,
        primvar_faces,
        opacity=constant_alpha,
    )
