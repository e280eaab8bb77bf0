"""A recording stand-in for ``mipray._mipray`` so the Python side tests without Rust.

``FakeRenderDelegate`` has exactly the methods and signatures of
``mipray._mipray.RenderDelegate`` (``test_protocol.py`` checks it against the
stubs); it validates the basics the real one does (array dtypes and shapes),
has the real one check each mesh's geometry, and records every call. ``fake_module()`` builds a module object with the
delegate, ``write_image``, ``read_image`` and ``version``, to stand in for
``mipray._mipray`` in tests of ``mipray.render`` and ``mipray-record``.
"""

from __future__ import annotations

import json
import os
import types
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass
class Call:
    """One recorded delegate call."""

    method: str
    path: str
    kwargs: dict[str, Any] = field(default_factory=dict)


def _check_array(path: str, name: str, value: Any, dtype: type, ndim: int) -> None:
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{path}: {name} must be a numpy array, got {type(value).__name__}")
    if value.dtype != dtype:
        raise TypeError(f"{path}: {name} must be {np.dtype(dtype).name}, got {value.dtype}")
    if value.ndim != ndim:
        raise ValueError(f"{path}: {name} must have {ndim} dimension(s), got {value.ndim}")


# The compiled delegate's class, taken now: tests stand the fake module in for
# ``mipray._mipray`` (the ``fake_native`` fixture), and the fake must not ask itself.
try:
    from mipray._mipray import RenderDelegate as _CompiledDelegate
except ImportError:  # a build-less run: meshes go unchecked
    _CompiledDelegate = None

#: The compiled delegate that checks the fake's meshes (see :func:`_check_geometry`).
_CHECKER: list[Any] = []

#: The ``set_mesh`` arguments about shading, not geometry: tests give the fake what they like.
_SHADING = frozenset(
    (
        "material face_materials face_material_indices displacement_texture gprim primvars "
        "st_values st_indices st_interpolation double_sided prototype light"
    ).split()
)


def _check_geometry(path: str, kwargs: dict[str, Any]) -> None:
    """Refuse a mesh as the real delegate does: mesh data is checked in one place, the
    compiled delegate's ``set_mesh`` (``PrimDataError`` naming the prim), so the fake asks it
    rather than keeping a copy of its rules."""
    if _CompiledDelegate is None:
        return
    if not _CHECKER:
        _CHECKER.append(_CompiledDelegate())
    checker = _CHECKER[0]
    checker.set_mesh(path, **{k: v for k, v in kwargs.items() if k not in _SHADING})
    checker.remove(path)


class FakeRenderDelegate:
    """Records ``set_*``/``remove`` calls; ``render`` returns flat AOVs."""

    def __init__(self) -> None:
        self.calls: list[Call] = []
        self.prims: dict[str, Call] = {}
        #: Paths whose ``set_mesh`` should raise ValueError, as the real one does on bad data.
        self.reject: set[str] = set()
        self.renders: list[dict[str, Any]] = []
        #: ``(samples, pass_output)`` of every pass the real delegate would have written.
        self.pass_writes: list[tuple[int, dict[str, Any]]] = []

    def _set(self, method: str, path: str, kwargs: dict[str, Any]) -> None:
        transform = kwargs["transform"]
        _check_array(path, "transform", transform, np.float64, 2)
        if transform.shape != (4, 4):
            raise ValueError(f"{path}: transform must be 4x4")
        call = Call(method, path, kwargs)
        self.calls.append(call)
        self.prims[path] = call

    def set_mesh(
        self,
        path: str,
        *,
        points: NDArray[np.float32],
        face_vertex_counts: NDArray[np.int32],
        face_vertex_indices: NDArray[np.int32],
        transform: NDArray[np.float64],
        scheme: str = "catmullClark",
        interpolate_boundary: str = "edgeAndCorner",
        face_varying_linear_interpolation: str = "cornersPlus1",
        triangle_subdivision_rule: str = "catmullClark",
        crease_indices: NDArray[np.int32] | None = None,
        crease_lengths: NDArray[np.int32] | None = None,
        crease_sharpnesses: NDArray[np.float32] | None = None,
        corner_indices: NDArray[np.int32] | None = None,
        corner_sharpnesses: NDArray[np.float32] | None = None,
        hole_indices: NDArray[np.int32] | None = None,
        left_handed: bool = False,
        double_sided: bool = False,
        prototype: bool = False,
        displacement_bound: float | None = None,
        displacement: tuple[float, float, int, float] | None = None,
        st_values: NDArray[np.float32] | None = None,
        st_indices: NDArray[np.int32] | None = None,
        st_interpolation: str = "faceVarying",
        displacement_texture: dict[str, object] | None = None,
        material: dict[str, object] | None = None,
        gprim: dict[str, object] | None = None,
        primvars: dict[str, dict[str, object]] | None = None,
        face_materials: list[dict[str, object]] | None = None,
        face_material_indices: NDArray[np.int32] | None = None,
        light: dict[str, object] | None = None,
    ) -> None:
        kwargs = locals_without_self(locals())
        for role, pv in (primvars or {}).items():
            _check_array(path, f"primvars['{role}']", pv["values"], np.float32, 2)
        textures = material.get("textures", {}) if material is not None else {}
        for tex in textures.values():  # type: ignore[attr-defined]
            if "file" not in tex:
                raise ValueError(f"{path}: a texture needs a file")
        if st_values is not None:
            _check_array(path, "st_values", st_values, np.float32, 2)
        if displacement_texture is not None and "file" not in displacement_texture:
            raise ValueError(f"{path}: a texture needs a file")
        if path in self.reject:
            raise ValueError(f"{path}: rejected by the fake delegate")
        if (face_materials is None) != (face_material_indices is None):
            raise ValueError(f"{path}: face_materials and face_material_indices go together")
        if face_materials is not None:
            _check_array(path, "face_material_indices", face_material_indices, np.int32, 1)
            # Points: one entry per point (each point's sphere is a face of its own);
            # curves: one per curve.
            kind = gprim.get("type") if gprim is not None else None
            if kind == "Points":
                faces = len(points)
            elif kind == "Curves":
                faces = len(gprim["curve_vertex_counts"])  # type: ignore[index, arg-type]
            else:
                faces = len(face_vertex_counts)
            if len(face_material_indices) != faces:
                raise ValueError(f"{path}: face_material_indices has the wrong length")
            if int(face_material_indices.max(initial=-1)) >= len(face_materials):
                raise ValueError(f"{path}: face_material_indices out of range")
            for m in face_materials:
                for tex in m.get("textures", {}).values():  # type: ignore[attr-defined]
                    if "file" not in tex:
                        raise ValueError(f"{path}: a texture needs a file")
        _check_array(path, "points", points, np.float32, 2)
        _check_array(path, "face_vertex_counts", face_vertex_counts, np.int32, 1)
        _check_array(path, "face_vertex_indices", face_vertex_indices, np.int32, 1)
        for name, value, dtype in (
            ("crease_indices", crease_indices, np.int32),
            ("crease_lengths", crease_lengths, np.int32),
            ("crease_sharpnesses", crease_sharpnesses, np.float32),
            ("corner_indices", corner_indices, np.int32),
            ("corner_sharpnesses", corner_sharpnesses, np.float32),
            ("hole_indices", hole_indices, np.int32),
        ):
            if value is not None:
                _check_array(path, name, value, dtype, 1)
        _check_geometry(path, kwargs)
        self._set("set_mesh", path, kwargs)

    def set_camera(
        self,
        path: str,
        *,
        transform: NDArray[np.float64],
        projection: str = "perspective",
        focal_length: float = 50.0,
        horizontal_aperture: float = 20.955,
        vertical_aperture: float = 15.2908,
        horizontal_aperture_offset: float = 0.0,
        vertical_aperture_offset: float = 0.0,
        clipping_range: tuple[float, float] = (1.0, 1e6),
        f_stop: float = 0.0,
        focus_distance: float = 0.0,
    ) -> None:
        self._set("set_camera", path, dict(locals_without_self(locals())))

    def set_distant_light(
        self,
        path: str,
        *,
        transform: NDArray[np.float64],
        intensity: float = 1.0,
        exposure: float = 0.0,
        color: tuple[float, float, float] = (1.0, 1.0, 1.0),
        angle: float = 0.53,
        normalize: bool = False,
        shadow_enable: bool = True,
        unlit: list[str] | None = None,
        no_shadow: list[str] | None = None,
    ) -> None:
        self._set("set_distant_light", path, dict(locals_without_self(locals())))

    def set_light(
        self,
        path: str,
        *,
        kind: str,
        transform: NDArray[np.float64],
        intensity: float = 1.0,
        exposure: float = 0.0,
        color: tuple[float, float, float] = (1.0, 1.0, 1.0),
        normalize: bool = False,
        shadow_enable: bool = True,
        angle: float = 0.53,
        radius: float = 0.5,
        width: float = 1.0,
        height: float = 1.0,
        texture: str | None = None,
        length: float = 1.0,
        cone_angle: float = 180.0,
        cone_softness: float = 0.0,
        focus: float = 0.0,
        focus_tint: tuple[float, float, float] = (0.0, 0.0, 0.0),
        unlit: list[str] | None = None,
        no_shadow: list[str] | None = None,
        ies_file: str | None = None,
        ies_angle_scale: float = 0.0,
        ies_normalize: bool = False,
        ies_down: tuple[float, float, float] = (0.0, -1.0, 0.0),
        ies_profile_sampling: bool = False,
        portals: list[str] | None = None,
    ) -> None:
        self._set("set_light", path, dict(locals_without_self(locals())))

    def set_motion(
        self, path: str, times: NDArray[np.float32], transforms: NDArray[np.float64]
    ) -> None:
        call = self.prims.get(path)
        if call is None or call.method != "set_mesh":
            raise ValueError(f"{path}: set_motion: no mesh at this path")
        _check_array(path, "times", times, np.float32, 1)
        _check_array(path, "transforms", transforms, np.float64, 3)
        if len(times) != len(transforms):
            raise ValueError(f"{path}: {len(times)} motion times for {len(transforms)} transforms")
        self.calls.append(Call("set_motion", path, {"times": times, "transforms": transforms}))

    def set_deformation(
        self,
        path: str,
        times: NDArray[np.float32],
        points: NDArray[np.float32],
        widths: NDArray[np.float32] | None = None,
        gprims: list[dict[str, Any]] | None = None,
    ) -> None:
        call = self.prims.get(path)
        if call is None or call.method != "set_mesh":
            raise ValueError(f"{path}: set_deformation: no mesh at this path")
        _check_array(path, "times", times, np.float32, 1)
        _check_array(path, "points", points, np.float32, 3)
        if len(times) != len(points):
            raise ValueError(f"{path}: {len(times)} deformation times for {len(points)} samples")
        args: dict[str, Any] = {"times": times, "points": points}
        if widths is not None:
            _check_array(path, "widths", widths, np.float32, 2)
            if len(widths) != len(times):
                raise ValueError(f"{path}: {len(times)} deformation times for {len(widths)} widths")
            args["widths"] = widths
        if gprims is not None:
            if len(gprims) != len(times):
                raise ValueError(f"{path}: {len(times)} deformation times for {len(gprims)} gprims")
            args["gprims"] = gprims
        self.calls.append(Call("set_deformation", path, args))

    def set_transform(self, path: str, transform: NDArray[np.float64]) -> None:
        call = self.prims.get(path)
        if call is None or call.method != "set_mesh":
            raise ValueError(f"{path}: set_transform: no mesh at this path")
        _check_array(path, "transform", transform, np.float64, 2)
        self.calls.append(Call("set_transform", path, {"transform": transform}))
        call.kwargs = {**call.kwargs, "transform": transform}

    def set_instancer(
        self,
        path: str,
        *,
        prototypes: list[str],
        proto_indices: NDArray[np.int32],
        transforms: NDArray[np.float64],
        prototype: bool = False,
    ) -> None:
        _check_array(path, "proto_indices", proto_indices, np.int32, 1)
        _check_array(path, "transforms", transforms, np.float64, 3)
        if transforms.shape[1:] != (4, 4) or len(transforms) != len(proto_indices):
            raise ValueError(f"{path}: transforms must be N×4×4 with N = len(proto_indices)")
        if len(proto_indices) and (
            proto_indices.min() < 0 or proto_indices.max() >= len(prototypes)
        ):
            raise ValueError(f"{path}: proto_indices out of range")
        kwargs = dict(locals_without_self(locals()))
        call = Call("set_instancer", path, kwargs)
        self.calls.append(call)
        self.prims[path] = call

    def set_instancer_motion(
        self, path: str, times: NDArray[np.float32], transforms: NDArray[np.float64]
    ) -> None:
        call = self.prims.get(path)
        if call is None or call.method != "set_instancer":
            raise ValueError(f"{path}: set_instancer_motion: no instancer at this path")
        _check_array(path, "times", times, np.float32, 1)
        _check_array(path, "transforms", transforms, np.float64, 4)
        n = len(call.kwargs["proto_indices"])
        if len(times) and transforms.shape != (len(times), n, 4, 4):
            raise ValueError(f"{path}: motion transforms {transforms.shape} for {len(times)} times")
        self.calls.append(
            Call("set_instancer_motion", path, {"times": times, "transforms": transforms})
        )

    def remove(self, path: str) -> None:
        self.calls.append(Call("remove", path))
        self.prims.pop(path, None)

    def prim_paths(self) -> list[str]:
        return sorted(self.prims)

    def render(
        self,
        camera: str,
        width: int,
        height: int,
        aovs: list[str],
        settings: dict[str, object] | None = None,
        progress: Callable[[int, int], object] | None = None,
        *,
        on_update: Callable[[int, bool, dict[str, NDArray[np.float32]]], object] | None = None,
        pass_output: dict[str, Any] | None = None,
    ) -> tuple[dict[str, NDArray[np.float32]], str]:
        if camera not in self.prims or self.prims[camera].method != "set_camera":
            raise ValueError(f"unknown camera {camera}")
        settings = settings or {}
        channels = {"color": 3, "alpha": 1, "depth": 1, "normal": 3}
        out: dict[str, NDArray[np.float32]] = {}
        for aov in aovs:
            if aov not in channels:
                raise ValueError(f"unknown AOV {aov}")
            # A horizontal ramp 0..2 so tone curves and clamping show in tests.
            ramp = np.linspace(0.0, 2.0, width, dtype=np.float32)
            out[aov] = np.broadcast_to(ramp[None, :, None], (height, width, channels[aov])).copy()
        if progress is not None:
            for done in (0, height // 2, height):
                progress(done, height)
        if on_update is not None or pass_output is not None:
            # The real delegate's passes: 1, 2, 4, ... samples, or one pass; each pass's
            # arrays the ramp scaled by its share of the samples, so passes differ.
            samples = int(settings.get("samples", 1))  # type: ignore[call-overload]
            done = 0
            while done < samples:
                done = (
                    samples if not settings.get("progressive") else min(max(1, 2 * done), samples)
                )
                pixels = {k: v * (done / samples) for k, v in out.items()}
                if pass_output is not None and done < samples:
                    self.pass_writes.append((done, dict(pass_output)))
                if on_update is not None:
                    on_update(done, done == samples, pixels)
        self.renders.append(
            {
                "camera": camera,
                "width": width,
                "height": height,
                "aovs": list(aovs),
                "settings": dict(settings),
            }
        )
        stats = {
            "render": {"wall_s": 0.01, "rays": {"camera": width * height}},
            "geometry_cache": {"mode": settings.get("cacheMode", "multires")},
        }
        return out, json.dumps(stats)

    # Helpers for tests ---------------------------------------------------

    def calls_for(self, path: str) -> list[Call]:
        """Every recorded call about ``path``."""
        return [c for c in self.calls if c.path == path]

    def meshes(self) -> dict[str, dict[str, Any]]:
        """Current meshes rendered in place (not prototypes), path → set_mesh kwargs."""
        return {
            p: c.kwargs
            for p, c in self.prims.items()
            if c.method == "set_mesh" and not c.kwargs.get("prototype")
        }

    def prototypes(self) -> dict[str, dict[str, Any]]:
        """Current prototype meshes, path → set_mesh kwargs."""
        return {
            p: c.kwargs
            for p, c in self.prims.items()
            if c.method == "set_mesh" and c.kwargs.get("prototype")
        }

    def instancers(self) -> dict[str, dict[str, Any]]:
        """Current instancers, path → set_instancer kwargs."""
        return {p: c.kwargs for p, c in self.prims.items() if c.method == "set_instancer"}

    def placements(self) -> list[tuple[str, NDArray[np.float64]]]:
        """Every mesh placement the scene makes, as the render delegate flattens it:
        (mesh path, USD row-layout object-to-world matrix), nested instancers followed."""
        out: list[tuple[str, NDArray[np.float64]]] = [
            (p, kw["transform"]) for p, kw in self.meshes().items()
        ]
        instancers = self.instancers()

        def expand(kw: dict[str, Any], parent: NDArray[np.float64], depth: int) -> None:
            for index, matrix in zip(kw["proto_indices"], kw["transforms"], strict=True):
                proto = kw["prototypes"][index]
                world = matrix @ parent
                if proto in instancers and depth < 8:
                    expand(instancers[proto], world, depth + 1)
                elif proto in self.prims and self.prims[proto].method == "set_mesh":
                    out.append((proto, self.prims[proto].kwargs["transform"] @ world))

        for kw in instancers.values():
            if not kw["prototype"]:
                expand(kw, np.eye(4), 0)
        return out


def display_color(args: dict[str, Any], path: str) -> tuple[float, float, float] | None:
    """The colour ``set_mesh`` got for the prim at ``path`` without a UsdPreviewSurface.

    That is the lambertian ``material`` named after the prim
    (:func:`mipray.usd.material.lambertian`); None when the material is another (a bound
    network, named after its material prim) or absent.
    """
    from mipray.usd.material import lambertian

    material = args.get("material")
    if material is None or material.get("name") != path:
        return None
    # A displayOpacity makes it partly transparent (opacity, ior 1): still the display colour.
    see_through = "ior" in material
    assert material == lambertian(
        path, material["diffuseColor"], material.get("opacity", 1.0), see_through=see_through
    ), material
    return material["diffuseColor"]


def face_colors(args: dict[str, Any]) -> NDArray[np.float32]:
    """(F, 3) diffuse colour per face as the delegate will shade it.

    A face of the mesh's own material with a ``diffuseColor`` primvar takes the mean of its
    corners' values (its colour at the centre under bilinear interpolation).
    """

    def colour(material: dict[str, Any] | None) -> NDArray[np.float32]:
        return np.asarray((material or {}).get("diffuseColor", (0.18,) * 3), np.float32)

    counts = np.asarray(args["face_vertex_counts"])
    n = len(counts)
    own = np.tile(colour(args.get("material")), (n, 1))
    primvar = (args.get("primvars") or {}).get("diffuseColor")
    if primvar is not None:
        values = np.asarray(primvar["values"], np.float32)
        if primvar.get("indices") is not None:
            values = values[primvar["indices"]]
        interpolation = primvar["interpolation"]
        if interpolation == "constant":
            own = np.tile(values[0], (n, 1))
        elif interpolation == "uniform":
            own = values[:n]
        else:
            corners = (
                values[args["face_vertex_indices"]] if interpolation != "faceVarying" else values
            )
            starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
            own = np.add.reduceat(corners, starts, axis=0) / counts[:, None]
    if args.get("face_materials") is None:
        return own
    table = np.asarray([colour(m) for m in args["face_materials"]], np.float32).reshape(-1, 3)
    indices = args["face_material_indices"]
    return np.where(indices[:, None] < 0, own, table[np.maximum(indices, 0)])


def locals_without_self(values: dict[str, Any]) -> dict[str, Any]:
    """A method's ``locals()`` as the kwargs it was called with (no self, no path)."""
    return {k: v for k, v in values.items() if k not in ("self", "path")}


def fake_module() -> types.ModuleType:
    """A module object standing in for ``mipray._mipray``.

    ``write_image`` records what the real writer would write in
    ``module.written`` (path → dict: the AOVs in the file's order, their pixel
    types, the pixels as they go into the file, sRGB-encoded for 8-bit types,
    and the metadata) and writes a small JSON file at the path so tests can
    see it exists. What goes into the file is the real module's plan
    (``output_plan``, ``srgb_encode``: the compiled writer's rules), so the
    fake stands in for OpenImageIO only.
    """
    from mipray import _mipray as native

    module = types.ModuleType("mipray._mipray")
    written: dict[str, dict[str, Any]] = {}

    def write_image(
        path: str,
        aovs: dict[str, NDArray[np.float32]],
        order: list[str] | None = None,
        formats: dict[str, str] | None = None,
        metadata: dict[str, object] | None = None,
        *,
        color_correction: str = "disabled",
        atomic: bool = False,
    ) -> None:
        names = list(order) if order is not None else list(aovs)
        for name in names:
            if name not in aovs:
                raise OSError(f"{path}: no AOV named '{name}' was rendered")
        plan_order, plan_formats, encode = native.output_plan(path, names, color_correction)
        plan_formats.update(formats or {})
        pixels = {name: aovs[name] for name in plan_order}
        if encode:
            pixels["color"] = native.srgb_encode(pixels["color"])
        written[path] = {
            "aovs": pixels,
            "order": plan_order,
            "formats": plan_formats,
            # The writer's own attribute (OpenImageIO's ``Software``), as every file has it.
            "metadata": {**(metadata or {}), "software": f"mipray {native.version()}"},
            "atomic": atomic,
        }
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        with open(path, "w", encoding="utf-8") as handle:
            json.dump({"order": plan_order, "formats": plan_formats}, handle)

    def read_image(path: str) -> tuple[NDArray[np.float32], list[str]]:
        raise OSError(f"{path}: the fake module cannot read images")

    module.RenderDelegate = FakeRenderDelegate  # type: ignore[attr-defined]
    module.write_image = write_image  # type: ignore[attr-defined]
    module.read_image = read_image  # type: ignore[attr-defined]

    def read_metadata(path: str) -> dict[str, str]:
        raise OSError(f"{path}: the fake module cannot read images")

    module.read_metadata = read_metadata  # type: ignore[attr-defined]
    # The writer's rules are the compiled module's own.
    module.eight_bit_aovs = native.eight_bit_aovs  # type: ignore[attr-defined]
    module.output_plan = native.output_plan  # type: ignore[attr-defined]
    module.srgb_encode = native.srgb_encode  # type: ignore[attr-defined]
    # So are the trim curves' checks (the USD front end asks them before sending a trim).
    module.check_trim_curves = native.check_trim_curves  # type: ignore[attr-defined]
    module.version = lambda: "0.0.0-fake"  # type: ignore[attr-defined]
    module.written = written  # type: ignore[attr-defined]
    return module
