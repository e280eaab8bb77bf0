"""The render-delegate interface the scene delegate writes to.

``mipray._mipray.RenderDelegate`` implements it; so does the recording fake in
``tests/fake_delegate.py``. Spelled out as a :class:`typing.Protocol` so the
scene delegate is typed without importing the compiled module (it must import
without it, for tests and for tools that only read USD).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["RenderDelegateLike"]


class RenderDelegateLike(Protocol):
    """The ``set_*``/``remove`` half of ``mipray._mipray.RenderDelegate``."""

    def set_mesh(
        self,
        path: str,
        *,
        points: NDArray[np.float32],
        face_vertex_counts: NDArray[np.int32],
        face_vertex_indices: NDArray[np.int32],
        transform: NDArray[np.float64],
        scheme: str = ...,
        interpolate_boundary: str = ...,
        face_varying_linear_interpolation: str = ...,
        triangle_subdivision_rule: str = ...,
        crease_indices: NDArray[np.int32] | None = ...,
        crease_lengths: NDArray[np.int32] | None = ...,
        crease_sharpnesses: NDArray[np.float32] | None = ...,
        corner_indices: NDArray[np.int32] | None = ...,
        corner_sharpnesses: NDArray[np.float32] | None = ...,
        hole_indices: NDArray[np.int32] | None = ...,
        left_handed: bool = ...,
        double_sided: bool = ...,
        prototype: bool = ...,
        displacement_bound: float | None = ...,
        displacement: tuple[float, float, int, float] | None = ...,
        st_values: NDArray[np.float32] | None = ...,
        st_indices: NDArray[np.int32] | None = ...,
        st_interpolation: str = ...,
        displacement_texture: dict[str, object] | None = ...,
        material: dict[str, object] | None = ...,
        gprim: dict[str, object] | None = ...,
        primvars: dict[str, dict[str, object]] | None = ...,
        face_materials: list[dict[str, object]] | None = ...,
        face_material_indices: NDArray[np.int32] | None = ...,
        light: dict[str, object] | None = ...,
    ) -> None:
        """Add or replace a mesh."""

    def set_transform(self, path: str, transform: NDArray[np.float64]) -> None:
        """Move a mesh without resending its data."""

    def set_motion(
        self, path: str, times: NDArray[np.float32], transforms: NDArray[np.float64]
    ) -> None:
        """Set a mesh's world transform over the camera's shutter (none: it is still)."""

    def set_deformation(
        self,
        path: str,
        times: NDArray[np.float32],
        points: NDArray[np.float32],
        widths: NDArray[np.float32] | None = None,
        gprims: list[dict[str, Any]] | None = None,
    ) -> None:
        """Set a mesh's points (and widths) across the camera's shutter (none: still)."""

    def set_instancer(
        self,
        path: str,
        *,
        prototypes: list[str],
        proto_indices: NDArray[np.int32],
        transforms: NDArray[np.float64],
        prototype: bool = ...,
    ) -> None:
        """Add or replace an instancer."""

    def set_instancer_motion(
        self, path: str, times: NDArray[np.float32], transforms: NDArray[np.float64]
    ) -> None:
        """Set an instancer's per-instance transforms over the camera's shutter (none: still)."""

    def set_camera(
        self,
        path: str,
        *,
        transform: NDArray[np.float64],
        projection: str = ...,
        focal_length: float = ...,
        horizontal_aperture: float = ...,
        vertical_aperture: float = ...,
        horizontal_aperture_offset: float = ...,
        vertical_aperture_offset: float = ...,
        clipping_range: tuple[float, float] = ...,
        f_stop: float = ...,
        focus_distance: float = ...,
    ) -> None:
        """Add or replace a camera."""

    def set_distant_light(
        self,
        path: str,
        *,
        transform: NDArray[np.float64],
        intensity: float = ...,
        exposure: float = ...,
        color: tuple[float, float, float] = ...,
        angle: float = ...,
        normalize: bool = ...,
        shadow_enable: bool = ...,
        unlit: list[str] = ...,
        no_shadow: list[str] = ...,
    ) -> None:
        """Add or replace a distant light."""

    def set_light(
        self,
        path: str,
        *,
        kind: str,
        transform: NDArray[np.float64],
        intensity: float = ...,
        exposure: float = ...,
        color: tuple[float, float, float] = ...,
        normalize: bool = ...,
        shadow_enable: bool = ...,
        angle: float = ...,
        radius: float = ...,
        width: float = ...,
        height: float = ...,
        texture: str | None = ...,
        length: float = ...,
        cone_angle: float = ...,
        cone_softness: float = ...,
        focus: float = ...,
        focus_tint: tuple[float, float, float] = ...,
        unlit: list[str] = ...,
        no_shadow: list[str] = ...,
        ies_file: str | None = ...,
        ies_angle_scale: float = ...,
        ies_normalize: bool = ...,
        ies_down: tuple[float, float, float] = ...,
        ies_profile_sampling: bool = ...,
        portals: list[str] | None = ...,
    ) -> None:
        """Add or replace a UsdLux light of any kind (``kind``), portals included."""

    def remove(self, path: str) -> None:
        """Remove a prim."""
