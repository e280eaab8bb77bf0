"""A USD stage as Mitsuba 3 sees it: the scene mipray renders, for a reference render.

The stage is read by mipray's own scene delegate into a recording delegate
(:func:`capture`), so Mitsuba gets exactly what mipray's renderer gets: the
same points, transforms, camera, light inputs and UsdPreviewSurface inputs.
:func:`scene_dict` turns that into a Mitsuba scene description and
:func:`render` renders it with the ``scalar_rgb`` variant (no LLVM needed).

What maps how (render space is USD world space in both renderers):

- Meshes must be polygonal (``subdivisionScheme = "none"``) with planar faces:
  mipray renders a planar polygon as itself, Mitsuba as a triangle fan, the
  same surface. A non-planar face (mipray: a bilinear patch) or a subdivision
  surface is refused, naming the prim. Faces are flat-shaded in both.
- Camera: perspective, the window fitted to the image aspect as mipray does
  (Hydra's ``CameraUtilFit``, enlarging), the horizontal field of view from
  it; Mitsuba's camera looks down its +Z with +X to the left, USD's down -Z
  with +X to the right, so its ``to_world`` is USD's times diag(-1, 1, -1).
  Pixel centres are at half-integers in both, and both box-filter over the
  pixel (mipray's first sample sits at the pixel centre, the rest uniform).
- Lights (UsdLux units, as ``mipray.light`` documents them): distant (angle 0)
  → ``directional`` of irradiance intensity·2^exposure·color; sphere → a
  ``sphere`` shape with an ``area`` emitter of that radiance (÷ area with
  ``normalize``) and a black BSDF; rect → ``rectangle``, disk → ``disk``,
  both emitting along the light's -Z, a rect's ``texture:file`` as a ``bitmap``
  radiance (s along +X, t along +Y, clamped); cylinder → ``cylinder`` (along
  the light's X, no caps, emitting outward); dome (no texture) → ``constant``;
  a sphere light with ``ShapingAPI`` → ``spot`` (:func:`_spot`: Mitsuba's hard
  cutoff at the cone angle, UsdLux's smoothstep softness and focus as the spot's
  projected texture; a point, so a small sphere); a polygonal mesh with
  MeshLightAPI → ``area`` emitters on its triangles (front faces, and a
  turned-over copy when ``doubleSided``), black, each face's radiance tinted as
  mipray tints it (its GeomSubset's or the mesh's ``emissiveColor``, a textured
  one as a ``bitmap`` at the mesh's ``st``). Shaping on other lights, IES
  profiles and dome textures are refused. Camera rays see lights in both
  renderers (the dome as the background).
- Materials (UsdPreviewSurface, clamped as mipray clamps them), wrapped in
  ``twosided`` because mipray shades both sides of a surface: no specular
  (F0 = 0, no clearcoat) → ``diffuse`` (exact); a full metal (metallic
  workflow, metallic 1, no clearcoat) → ``principled`` with metallic 1 (GGX,
  α = roughness², Schlick Fresnel to F0 = diffuseColor: the same model up to
  Mitsuba's separable Smith G), and at roughness 0 a delta mirror with that
  Fresnel (a small Python plugin: Mitsuba's ``conductor`` has the
  complex-index Fresnel); opacity 0 with opacityThreshold 0 →
  ``dielectric`` / ``roughdielectric`` of ``ior`` (GGX, α = roughness²);
  anything else → ``principled`` or ``roughplastic``, marked approximate
  (their diffuse-specular coupling differs from UsdPreviewSurface's).
  ``emissiveColor`` → an ``area`` emitter on the mesh, and on a turned-over
  copy a hair behind it (mipray's emission is two-sided, Mitsuba's
  one-sided). A cutout (opacityThreshold > 0) below its threshold removes the
  mesh. A textured ``diffuseColor`` on a lambertian surface → ``diffuse`` with
  a ``bitmap`` of the same file, decoded by Mitsuba (``raw`` off where mipray
  reads the file as sRGB), the mesh's ``st`` as its texture coordinates; a
  normal map (raw, scale 2, bias −1) on a lambertian surface → ``normalmap``
  around ``diffuse``; other textured inputs are refused.

- Implicit gprims map to Mitsuba's analytic shapes: ``Sphere`` → ``sphere``,
  ``Cylinder`` (equal radii) → ``cylinder`` (open) and two ``disk`` caps,
  ``Plane`` → ``rectangle``, ``Cube`` → ``cube``, ``Points`` → a ``sphere``
  per point; each ``to_world`` the prim's transform times the shape's own
  scale and axis. Cones, frustums and capsules (Mitsuba has none) are refused.

- Curves (BasisCurves round tubes, nonperiodic) map to Mitsuba's curves, written to a
  text file of world-space control points and radii: ``linear`` → ``linearcurve``, cubic
  ``bspline`` → ``bsplinecurve``; widths constant, uniform or vertex (half of each, times
  the transform's uniform scale; USD's fallback width 1 when none). Ribbons, other bases,
  periodic and pinned curves, varying widths and non-uniform scales are refused.
  NurbsPatch has no Mitsuba shape and is refused: a comparison scene of one gives
  Mitsuba a stand-in stage (the analytic sphere a NURBS sphere is exactly).

Everything Mitsuba cannot represent the way mipray renders it raises
:class:`~mipray.errors.PrimError` naming the prim, rather than rendering a
different scene.
"""

from __future__ import annotations

import atexit
import math
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd

from ..errors import MiprayError, PrimError
from ..usd.camera import image_height
from ..usd.primvars import INTERPOLATIONS, per_face_vertex
from ..usd.scene_delegate import UsdSceneDelegate

__all__ = [
    "Capture",
    "MaterialMapping",
    "capture",
    "material_mapping",
    "render",
    "scene_dict",
]

#: Mitsuba variant: CPU, RGB, no LLVM.
VARIANT = "scalar_rgb"

#: Roughness below which UsdPreviewSurface's lobes are the delta mirror and glass (mipray's
#: BSDF uses such a threshold; Mitsuba's smooth plugins are the same limit).
SMOOTH_ROUGHNESS = 1e-3


class _Recorder:
    """A render delegate that records what mipray's scene delegate sends it."""

    def __init__(self) -> None:
        self.meshes: dict[str, dict[str, Any]] = {}
        self.cameras: dict[str, dict[str, Any]] = {}
        self.lights: dict[str, dict[str, Any]] = {}

    def set_mesh(self, path: str, **kwargs: Any) -> None:
        self.meshes[path] = kwargs

    def set_transform(self, path: str, transform: NDArray[np.float64]) -> None:
        self.meshes[path]["transform"] = transform

    def set_camera(self, path: str, **kwargs: Any) -> None:
        self.cameras[path] = kwargs

    def set_distant_light(self, path: str, **kwargs: Any) -> None:
        self.lights[path] = {"kind": "distant", **kwargs}

    def set_light(self, path: str, **kwargs: Any) -> None:
        self.lights[path] = kwargs

    def set_instancer(self, path: str, **kwargs: Any) -> None:
        raise PrimError(path, "instancers are not exported to Mitsuba; flatten the scene")

    def set_motion(self, path: str, *args: Any, **kwargs: Any) -> None:
        raise PrimError(path, "motion blur is not exported to Mitsuba")

    def set_instancer_motion(self, path: str, *args: Any, **kwargs: Any) -> None:
        raise PrimError(path, "motion blur is not exported to Mitsuba")

    def set_deformation(self, path: str, *args: Any, **kwargs: Any) -> None:
        raise PrimError(path, "motion blur is not exported to Mitsuba")

    def remove(self, path: str) -> None:
        for table in (self.meshes, self.cameras, self.lights):
            table.pop(path, None)

    def prim_paths(self) -> list[str]:
        return sorted({*self.meshes, *self.cameras, *self.lights})


@dataclass
class Capture:
    """A stage as mipray's render delegate receives it (``set_*`` keyword arguments)."""

    camera_path: str
    camera: dict[str, Any]
    meshes: dict[str, dict[str, Any]]
    lights: dict[str, dict[str, Any]]
    #: Per mesh path: how its material maps to Mitsuba (filled by :func:`scene_dict`).
    materials: dict[str, MaterialMapping] = field(default_factory=dict)


def capture(
    stage: Usd.Stage, camera: str | None = None, time: Usd.TimeCode | float | None = None
) -> Capture:
    """Read ``stage`` through mipray's scene delegate (the default and render purposes).

    A stage without lights is exported without lights (lit by its emissive
    surfaces alone): render it in mipray with ``camera_light=False`` to compare.

    Raises:
        PrimError: no camera (or not the one asked for), or a prim mipray itself
            refuses.

    """
    recorder = _Recorder()
    delegate = UsdSceneDelegate(
        stage, recorder, time=time if time is not None else stage.GetStartTimeCode()
    )
    delegate.sync()
    errors = delegate.delegate_errors if hasattr(delegate, "delegate_errors") else []
    if errors:
        raise MiprayError(f"the stage did not sync: {errors[0]}")
    if camera is None:
        if not recorder.cameras:
            raise PrimError(str(stage.GetPseudoRoot().GetPath()), "the stage has no camera")
        camera = sorted(recorder.cameras)[0]
    if camera not in recorder.cameras:
        raise PrimError(camera, f"no such camera (cameras: {', '.join(sorted(recorder.cameras))})")
    return Capture(camera, recorder.cameras[camera], recorder.meshes, recorder.lights)


# ----------------------------------------------------------------------------- materials


@dataclass(frozen=True)
class MaterialMapping:
    """A UsdPreviewSurface as a Mitsuba BSDF (and emitter)."""

    #: The Mitsuba BSDF dict; None when the mesh is cut out entirely.
    bsdf: dict[str, Any] | None
    #: Emitted radiance (linear RGB), or None.
    emission: tuple[float, float, float] | None
    #: "diffuse", "mirror", "metal", "glass", "plastic", "principled", "cutout".
    model: str
    #: True when Mitsuba's model is UsdPreviewSurface's (up to Smith G and sampling).
    exact: bool


def _clamp01(x: float) -> float:
    return 0.0 if math.isnan(x) else min(max(x, 0.0), 1.0)


def _rgb(value: Any, default: tuple[float, float, float]) -> tuple[float, float, float]:
    if value is None:
        return default
    r, g, b = (float(c) for c in value)
    return (r, g, b)


def _spectrum(rgb: tuple[float, float, float]) -> dict[str, Any]:
    return {"type": "rgb", "value": list(rgb)}


#: The model name of a lambertian surface with a textured diffuseColor.
TEXTURED_DIFFUSE = "diffuse (textured)"

#: The model name of a lambertian surface with a tangent-space normal map.
NORMAL_MAPPED = "diffuse (normal map)"

#: UsdUVTexture wrap tokens → Mitsuba's bitmap ``wrap_mode`` (``black`` has none).
_WRAP = {"repeat": "repeat", "mirror": "mirror", "clamp": "clamp", None: "repeat"}


def _bitmap(path: str, tex: dict[str, Any], normal: bool = False) -> dict[str, Any]:
    """A UsdUVTexture feeding diffuseColor (or, with ``normal``, normal) as Mitsuba's ``bitmap``.

    The file is Mitsuba's to read and decode: ``raw`` off where mipray decodes sRGB
    (``sourceColorSpace`` sRGB, or auto on an 8-bit file of 3 or 4 channels, Hydra's rule), so
    the two renderers' decodings are independent. Mitsuba interpolates the finest level
    bilinearly (no MIP map); mipray filters by the ray differentials: the same image when the
    texture varies slowly across a pixel. Texture coordinates go as Mitsuba's (v down the
    image): see :func:`_mesh`.

    A normal map goes to Mitsuba's ``normalmap``, which decodes texels as 2·texel − 1 in the
    frame (dP/du made tangent, n × that, n): mipray's frame (dP/ds, ±n × dP/ds, n) wherever st
    is right-handed about the normal, so only UsdUVTexture's usual scale 2 and bias −1 on a
    raw file are exported.
    """
    mi = _mitsuba()
    what = "normal" if normal else "diffuseColor"
    if tex.get("channel", 0) != 0:
        raise PrimError(path, f"a {what} texture read from a single channel is not exported")
    for key, identity in (("scale", 2.0 if normal else 1.0), ("bias", -1.0 if normal else 0.0)):
        if any(abs(float(v) - identity) > 1e-6 for v in list(tex.get(key, [identity] * 4))[:3]):
            raise PrimError(
                path, f"a {what} texture with {key} other than {identity} is not exported"
            )
    wraps = {tex.get("wrapS"), tex.get("wrapT")}
    if len(wraps) != 1 or next(iter(wraps)) not in _WRAP:
        raise PrimError(path, f"texture wrap modes {sorted(map(str, wraps))} are not exported")
    file = str(tex["file"])
    bitmap = mi.Bitmap(file)
    eight_bit = bitmap.component_format() == mi.Struct.Type.UInt8
    space = tex.get("sourceColorSpace", "auto")
    srgb = space == "sRGB" or (space == "auto" and eight_bit and bitmap.channel_count() in (3, 4))
    if srgb and not bitmap.srgb_gamma():
        raise PrimError(path, f"{file}: Mitsuba does not read it as sRGB-encoded")
    if normal and srgb:
        raise PrimError(path, f"{file}: a normal map read as sRGB is not exported (author raw)")
    return {
        "type": "bitmap",
        "filename": file,
        "raw": not srgb,
        "filter_type": "bilinear",
        "wrap_mode": _WRAP[next(iter(wraps))],
    }


def _scaled_bitmap(
    path: str, tex: dict[str, Any], scale: tuple[float, float, float]
) -> dict[str, Any]:
    """A texture's colour times ``scale`` as Mitsuba's ``bitmap`` (an emitter's radiance).

    Mitsuba's bitmap has no scale, so Mitsuba decodes the file (:func:`_bitmap`'s rules:
    its own sRGB curve where mipray reads sRGB) and the product is handed over as data.
    """
    mi = _mitsuba()
    spec = _bitmap(path, tex)
    bitmap = mi.Bitmap(spec.pop("filename"))
    if spec["raw"]:
        # A raw file's values as they are (convert would take an sRGB-tagged file's curve off).
        bitmap.set_srgb_gamma(False)
    linear = bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
    data = np.array(linear, dtype=np.float32) * np.asarray(scale, dtype=np.float32)
    return {**spec, "data": mi.TensorXf(data), "raw": True}


def _surface(material: dict[str, Any] | None) -> dict[str, Any]:
    """UsdPreviewSurface's inputs with fallbacks, clamped as the core clamps them."""
    m = material or {}
    if material is None:
        # set_mesh without a material: lambertian grey (specular workflow, no specular).
        m = {"diffuseColor": (0.18,) * 3, "useSpecularWorkflow": True}
    s = {
        "diffuseColor": tuple(_clamp01(c) for c in _rgb(m.get("diffuseColor"), (0.18,) * 3)),
        "emissiveColor": tuple(
            0.0 if math.isnan(c) else max(c, 0.0) for c in _rgb(m.get("emissiveColor"), (0.0,) * 3)
        ),
        "useSpecularWorkflow": bool(m.get("useSpecularWorkflow", False)),
        "specularColor": tuple(_clamp01(c) for c in _rgb(m.get("specularColor"), (0.0,) * 3)),
    }
    for name, default in (
        ("metallic", 0.0),
        ("roughness", 0.5),
        ("clearcoat", 0.0),
        ("clearcoatRoughness", 0.01),
        ("opacity", 1.0),
        ("opacityThreshold", 0.0),
    ):
        s[name] = _clamp01(float(m.get(name, default)))
    ior = float(m.get("ior", 1.5))
    s["ior"] = ior if math.isfinite(ior) and ior > 0.0 else 1.0
    return s


def material_mapping(path: str, material: dict[str, Any] | None) -> MaterialMapping:
    """The Mitsuba BSDF for a mesh's ``material`` argument (None: lambertian 0.18 grey).

    Raises:
        PrimError: a textured input (Mitsuba would need the mesh's st).

    """
    textures = dict((material or {}).get("textures") or {})
    diffuse_texture = textures.pop("diffuseColor", None)
    normal_texture = textures.pop("normal", None)
    if textures:
        inputs = ", ".join(sorted(textures))
        raise PrimError(
            path,
            f"textured inputs ({inputs}) are not exported to Mitsuba (diffuseColor and normal are)",
        )
    s = _surface(material)
    emission = s["emissiveColor"] if max(s["emissiveColor"]) > 0.0 else None
    rough = s["roughness"]
    alpha = rough * rough
    smooth = rough < SMOOTH_ROUGHNESS
    if s["opacityThreshold"] > 0.0:
        if s["opacity"] < s["opacityThreshold"]:
            return MaterialMapping(None, None, "cutout", True)
    elif s["opacity"] < 1.0:
        glass: dict[str, Any] = {"type": "dielectric" if smooth else "roughdielectric"}
        glass.update({"int_ior": s["ior"], "ext_ior": 1.0})
        if not smooth:
            glass.update({"distribution": "ggx", "alpha": alpha})
        if s["opacity"] <= 0.0:
            return MaterialMapping(glass, emission, "glass", True)
        opaque = material_mapping(path, {**(material or {}), "opacity": 1.0})
        blend = {
            "type": "blendbsdf",
            "weight": 1.0 - s["opacity"],
            "opaque": opaque.bsdf,
            "glass": glass,
        }
        return MaterialMapping(blend, emission, "glass", False)
    diffuse = s["diffuseColor"]
    metallic = 0.0 if s["useSpecularWorkflow"] else s["metallic"]
    if s["useSpecularWorkflow"]:
        f0 = max(s["specularColor"])
    else:
        dielectric = ((1.0 - s["ior"]) / (1.0 + s["ior"])) ** 2
        f0 = max((1.0 - metallic) * dielectric + metallic * c for c in diffuse)
    bsdf: dict[str, Any]
    if (diffuse_texture or normal_texture) and (s["clearcoat"] > 0.0 or f0 > 0.0):
        what = "a textured diffuseColor" if diffuse_texture else "a normal map"
        raise PrimError(
            path,
            f"{what} is exported only on a lambertian surface (no specular or clearcoat)",
        )
    if diffuse_texture is not None:
        bsdf = {"type": "diffuse", "reflectance": _bitmap(path, diffuse_texture)}
        model, exact = TEXTURED_DIFFUSE, True
    elif normal_texture is not None:
        bsdf = {
            "type": "normalmap",
            "normalmap": _bitmap(path, normal_texture, normal=True),
            "bsdf": {"type": "diffuse", "reflectance": _spectrum(diffuse)},
        }
        model, exact = NORMAL_MAPPED, True
    elif s["clearcoat"] <= 0.0 and f0 <= 0.0:
        bsdf = {"type": "diffuse", "reflectance": _spectrum(diffuse)}
        model, exact = "diffuse", True
    elif s["clearcoat"] <= 0.0 and metallic >= 1.0 and smooth:
        bsdf = {"type": SCHLICK_MIRROR, "f0_r": diffuse[0], "f0_g": diffuse[1], "f0_b": diffuse[2]}
        model, exact = "mirror", True
    elif s["clearcoat"] <= 0.0 and metallic >= 1.0:
        bsdf = {
            "type": "principled",
            "base_color": _spectrum(diffuse),
            "metallic": 1.0,
            "roughness": max(rough, SMOOTH_ROUGHNESS),
            "spec_tint": 0.0,
        }
        model, exact = "metal", True
    elif s["clearcoat"] <= 0.0 and metallic <= 0.0 and not s["useSpecularWorkflow"]:
        bsdf = {
            "type": "plastic" if smooth else "roughplastic",
            "diffuse_reflectance": _spectrum(diffuse),
            "int_ior": max(s["ior"], 1.0 + 1e-4),
            "ext_ior": 1.0,
            "nonlinear": False,
        }
        if not smooth:
            bsdf.update({"distribution": "ggx", "alpha": alpha})
        model, exact = "plastic", False
    else:
        eta = max(s["ior"], 1.0 + 1e-4)
        bsdf = {
            "type": "principled",
            "base_color": _spectrum(diffuse),
            "metallic": metallic,
            "roughness": max(rough, SMOOTH_ROUGHNESS),
            "specular": ((eta - 1.0) / (eta + 1.0)) ** 2 / 0.08,
            "clearcoat": s["clearcoat"],
            "clearcoat_gloss": 1.0 - s["clearcoatRoughness"],
        }
        model, exact = "principled", False
    return MaterialMapping({"type": "twosided", "bsdf": bsdf}, emission, model, exact)


# ----------------------------------------------------------------------------- geometry


def _world_points(args: dict[str, Any]) -> NDArray[np.float64]:
    p = np.asarray(args["points"], dtype=np.float64).reshape(-1, 3)
    m = np.asarray(args["transform"], dtype=np.float64).reshape(4, 4)
    # Row-vector USD layout: p_world = [p, 1] @ m.
    h = np.hstack([p, np.ones((len(p), 1))]) @ m
    out: NDArray[np.float64] = h[:, :3] / h[:, 3:4]
    return out


def _axis_matrix(axis: str) -> NDArray[np.float64]:
    """Object from canonical (spine +z) coordinates: mipray's cyclic map (``implicit.rs``)."""
    cols = {"Z": (0, 1, 2), "X": (1, 2, 0), "Y": (2, 0, 1)}[axis]
    m = np.eye(4)
    m[:3, :3] = 0.0
    for canonical, obj in enumerate(cols):
        m[obj, canonical] = 1.0
    return m


_curve_files: list[str] = []


def _curve_file(text: str) -> str:
    """A file holding ``text`` for Mitsuba's curve loaders, removed when Python exits."""
    if not _curve_files:
        directory = tempfile.mkdtemp(prefix="mipray-mitsuba-curves-")
        atexit.register(shutil.rmtree, directory, True)
        _curve_files.append(directory)
    path = Path(_curve_files[0]) / f"curves{len(_curve_files)}.txt"
    _curve_files.append(str(path))
    path.write_text(text)
    return str(path)


def _curves_shape(path: str, args: dict[str, Any]) -> dict[str, Any]:
    """A curves ``gprim`` as Mitsuba's ``linearcurve`` or ``bsplinecurve`` (module doc)."""
    g = args["gprim"]
    if g.get("style", "tube") != "tube" or g.get("normals"):
        raise PrimError(path, "ribbons are not exported to Mitsuba (its curves are round)")
    wrap, basis = g.get("wrap", "nonperiodic"), g.get("basis", "bezier")
    if wrap != "nonperiodic":
        raise PrimError(path, f"{wrap} curves are not exported to Mitsuba")
    if g.get("curve_type", "cubic") == "linear":
        plugin = "linearcurve"
    elif basis == "bspline":
        plugin = "bsplinecurve"
    else:
        raise PrimError(path, f"Mitsuba has no {basis} curves (only linear and bspline)")
    counts = np.asarray(g["curve_vertex_counts"], dtype=np.int64)
    points = _world_points(args)
    linear = _column_matrix(args)[:3, :3]
    scale = abs(np.linalg.det(linear)) ** (1.0 / 3.0)
    if not np.allclose(linear.T @ linear, scale * scale * np.eye(3), rtol=1e-6, atol=1e-9):
        raise PrimError(path, "curves under a non-uniform scale are not exported to Mitsuba")
    widths = np.asarray(g.get("widths", []), dtype=np.float64).reshape(-1)
    interpolation = g.get("widths_interpolation", "vertex")
    if widths.size == 0:
        per_vertex = np.ones(len(points))
    elif interpolation == "constant":
        per_vertex = np.full(len(points), widths[0])
    elif interpolation == "uniform":
        per_vertex = np.repeat(widths, counts)
    elif interpolation == "vertex":
        per_vertex = widths
    else:
        raise PrimError(path, f"{interpolation} widths are not exported to Mitsuba")
    radii = per_vertex * scale / 2.0
    lines, start = [], 0
    for n in counts.tolist():
        lines += [
            " ".join(f"{c:.9g}" for c in (*points[i], radii[i])) for i in range(start, start + n)
        ]
        lines.append("")
        start += n
    return {"type": plugin, "filename": _curve_file("\n".join(lines))}


def _analytic_shapes(path: str, args: dict[str, Any]) -> list[dict[str, Any]]:
    """Mitsuba's analytic shapes (without BSDF) for a ``gprim`` of ``set_mesh`` (module doc)."""
    g = args["gprim"]
    if g["type"] == "Curves":
        return [_curves_shape(path, args)]
    if g["type"] == "Nurbs":
        raise PrimError(path, "Mitsuba has no NURBS surfaces (a scene may give it a stand-in)")
    world = _column_matrix(args)

    def shape(kind: str, local: NDArray[np.float64]) -> dict[str, Any]:
        return {"type": kind, "to_world": _mitsuba().ScalarTransform4f((world @ local).tolist())}

    kind = g["type"]
    if kind == "Points":
        points = np.asarray(args["points"], dtype=np.float64).reshape(-1, 3)
        widths = np.asarray(g.get("widths", []), dtype=np.float64).reshape(-1)
        radii = (
            np.full(len(points), 0.5)
            if widths.size == 0
            else np.broadcast_to(widths / 2, len(points))
        )
        return [
            shape("sphere", np.diag([r, r, r, 1.0]) + np.pad(p[:, None], ((0, 1), (3, 0))))
            for p, r in zip(points, radii, strict=True)
            if r > 0
        ]
    if kind == "Sphere":
        r = g["radius"]
        return [shape("sphere", np.diag([r, r, r, 1.0]))]
    if kind == "Cube":
        h = g["size"] / 2
        return [shape("cube", np.diag([h, h, h, 1.0]))]
    axis = _axis_matrix(g.get("axis", "Z"))
    if kind == "Plane":
        w, length = g["width"], g["length"]
        a, b = (w, length) if g.get("axis", "Z") == "Z" else (length, w)
        return [shape("rectangle", axis @ np.diag([a / 2, b / 2, 1.0, 1.0]))]
    if kind == "Cylinder" and g["radius_bottom"] == g["radius_top"]:
        r, hh = g["radius_bottom"], g["height"] / 2
        body = axis @ np.array([[r, 0, 0, 0], [0, r, 0, 0], [0, 0, 2 * hh, -hh], [0, 0, 0, 1.0]])
        top = axis @ np.array([[r, 0, 0, 0], [0, r, 0, 0], [0, 0, 1, hh], [0, 0, 0, 1.0]])
        # The bottom cap faces −z: the disk turned over about x.
        bottom = axis @ np.array([[r, 0, 0, 0], [0, -r, 0, 0], [0, 0, -1, -hh], [0, 0, 0, 1.0]])
        return [shape("cylinder", body), shape("disk", top), shape("disk", bottom)]
    raise PrimError(
        path, f"Mitsuba has no {kind.lower()} of unequal radii (cone, frustum or capsule)"
    )


def _triangles(path: str, args: dict[str, Any], points: NDArray[np.float64]) -> NDArray[np.int64]:
    """Fan triangles of every planar face, as an (F', 7) array.

    Columns: three point indices, the face each came from, and its corners' face-vertex
    positions (for face-varying st).
    """
    scheme = args.get("scheme", "catmullClark")
    if scheme != "none":
        raise PrimError(
            path,
            f"subdivisionScheme '{scheme}': only polygonal meshes (none) are exported, "
            "so both renderers see the same surface",
        )
    counts = np.asarray(args["face_vertex_counts"], dtype=np.int64)
    indices = np.asarray(args["face_vertex_indices"], dtype=np.int64)
    holes = set(np.asarray(args.get("hole_indices") or [], dtype=np.int64).tolist())
    left = bool(args.get("left_handed", False))
    out: list[tuple[int, int, int, int, int, int, int]] = []
    start = 0
    for face, n in enumerate(counts.tolist()):
        idx = indices[start : start + n]
        fv = np.arange(start, start + n)
        start += n
        if face in holes or n < 3:
            continue
        if left:
            idx, fv = idx[::-1], fv[::-1]
        poly = points[idx]
        if n > 3:
            # Newell's normal; every corner must lie on the plane through the centroid.
            nrm = np.zeros(3)
            for i in range(n):
                a, b = poly[i], poly[(i + 1) % n]
                nrm += np.array([(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]), 0.0])
                nrm[2] += (a[0] - b[0]) * (a[1] + b[1])
            size = float(np.ptp(poly, axis=0).max())
            length = float(np.linalg.norm(nrm))
            if length > 0.0 and size > 0.0:
                off = np.abs((poly - poly.mean(axis=0)) @ (nrm / length)).max()
                if off > 1e-5 * size:
                    raise PrimError(
                        path,
                        f"face {face} is not planar ({off:.3g} off its plane): mipray renders "
                        "it as a bilinear patch, Mitsuba would render triangles",
                    )
        for i in range(1, n - 1):
            corners = (int(idx[0]), int(idx[i]), int(idx[i + 1]))
            out.append((*corners, face, int(fv[0]), int(fv[i]), int(fv[i + 1])))
    return np.asarray(out, dtype=np.int64).reshape(-1, 7)


def _face_vertex_st(path: str, args: dict[str, Any]) -> NDArray[np.float64] | None:
    """The mesh's ``st`` at every face-vertex (F_v, 2), or None without one."""
    if args.get("st_values") is None:
        return None
    values = np.asarray(args["st_values"], dtype=np.float64).reshape(-1, 2)
    if args.get("st_indices") is not None:
        values = values[np.asarray(args["st_indices"], dtype=np.int64)]
    counts = np.asarray(args["face_vertex_counts"], dtype=np.int64)
    indices = np.asarray(args["face_vertex_indices"], dtype=np.int64)
    how = args.get("st_interpolation", "faceVarying")
    if how not in INTERPOLATIONS:
        raise PrimError(path, f"st interpolation '{how}' is not exported to Mitsuba")
    per = per_face_vertex(values, how, counts, indices)
    if len(per) != len(indices):
        raise PrimError(path, f"st has {len(per)} values for {len(indices)} face-vertices")
    return per


def _mesh(
    mi: Any,
    name: str,
    points: NDArray[np.float64],
    tris: NDArray[np.int64],
    props: Any,
    st: NDArray[np.float64] | None = None,
) -> Any:
    """A Mitsuba mesh of the triangles, without vertex normals (flat-shaded, as mipray).

    With ``st`` (per face-vertex), every triangle corner is its own vertex carrying its
    texture coordinate, v = 1 - t: Mitsuba's v runs down the image (its mesh loaders flip
    t on reading), USD's t up.
    """
    if st is None:
        used, inverse = np.unique(tris[:, :3].reshape(-1), return_inverse=True)
        positions, faces, uv = points[used], inverse, None
    else:
        positions = points[tris[:, :3].reshape(-1)]
        faces = np.arange(3 * len(tris))
        uv = st[tris[:, 4:7].reshape(-1)].copy()
        uv[:, 1] = 1.0 - uv[:, 1]
    mesh = mi.Mesh(
        name,
        len(positions),
        len(tris),
        props=props,
        has_vertex_normals=False,
        has_vertex_texcoords=uv is not None,
    )
    params = mi.traverse(mesh)
    params["vertex_positions"] = positions.astype(np.float32).reshape(-1)
    params["faces"] = faces.astype(np.uint32).reshape(-1)
    if uv is not None:
        params["vertex_texcoords"] = uv.astype(np.float32).reshape(-1)
    params.update()
    return mesh


# ----------------------------------------------------------------------------- lights


def _light_radiance(args: dict[str, Any]) -> tuple[float, float, float]:
    scale = float(args.get("intensity", 1.0)) * 2.0 ** float(args.get("exposure", 0.0))
    r, g, b = (float(c) * scale for c in args.get("color", (1.0, 1.0, 1.0)))
    return (r, g, b)


def _column_matrix(args: dict[str, Any]) -> NDArray[np.float64]:
    """A light's or camera's transform in column-vector layout (p' = M p)."""
    return np.asarray(args["transform"], dtype=np.float64).reshape(4, 4).T


def _light(mi: Any, path: str, args: dict[str, Any]) -> dict[str, Any]:
    kind = args["kind"]
    if not args.get("shadow_enable", True):
        raise PrimError(path, "inputs:shadow:enable is off: Mitsuba's lights always cast shadows")
    m = _column_matrix(args)
    radiance = _light_radiance(args)
    black = {"type": "diffuse", "reflectance": _spectrum((0.0, 0.0, 0.0))}
    if kind == "distant":
        if float(args.get("angle", 0.0)) > 0.0:
            raise PrimError(
                path,
                f"inputs:angle {args['angle']}: Mitsuba's directional light is a point at "
                "infinity; author angle 0",
            )
        d = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
        d /= np.linalg.norm(d)
        return {"type": "directional", "direction": d.tolist(), "irradiance": _spectrum(radiance)}
    if kind == "dome":
        if args.get("texture"):
            raise PrimError(path, "dome textures are not exported to Mitsuba")
        return {"type": "constant", "radiance": _spectrum(radiance)}
    if args.get("ies_file"):
        raise PrimError(path, "IES profiles are not exported to Mitsuba")
    shaped = "cone_angle" in args
    if shaped and kind != "sphere":
        raise PrimError(
            path,
            f"ShapingAPI on a {kind} light is not exported to Mitsuba (only on a sphere light, "
            "as a spot)",
        )
    center = m[:3, 3]
    if kind == "sphere":
        scale = float(np.mean(np.linalg.norm(m[:3, :3], axis=0)))
        radius = float(args.get("radius", 0.5)) * scale
        area = 4.0 * math.pi * radius * radius
        if args.get("normalize"):
            radiance = (radiance[0] / area, radiance[1] / area, radiance[2] / area)
        if shaped:
            return _spot(mi, path, args, m, radiance, radius)
        return {
            "type": "sphere",
            "center": center.tolist(),
            "radius": radius,
            "bsdf": black,
            "emitter": {"type": "area", "radiance": _spectrum(radiance)},
        }
    if kind in ("rect", "disk"):
        if kind == "rect":
            # Mitsuba's rectangle reads its texture at uv = ((x + 1)/2, (y + 1)/2) of its
            # local square, v down the image; UsdLux's s runs along +X, t along +Y up the
            # image: local y is the light's -Y.
            u = m[:3, :3] @ np.array([float(args.get("width", 1.0)) * 0.5, 0.0, 0.0])
            v = m[:3, :3] @ np.array([0.0, -float(args.get("height", 1.0)) * 0.5, 0.0])
            area = 4.0 * float(np.linalg.norm(np.cross(u, v)))
        else:
            r = float(args.get("radius", 0.5))
            u = m[:3, :3] @ np.array([r, 0.0, 0.0])
            v = m[:3, :3] @ np.array([0.0, r, 0.0])
            area = math.pi * float(np.linalg.norm(np.cross(u, v)))
        if args.get("normalize") and area > 0.0:
            radiance = (radiance[0] / area, radiance[1] / area, radiance[2] / area)
        # UsdLux rect and disk lights emit along their -Z; Mitsuba's shapes along their
        # normal, which its to_world maps from +Z (by the inverse transpose).
        n = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
        n /= np.linalg.norm(n)
        to_world = np.eye(4)
        to_world[:3, 0], to_world[:3, 1], to_world[:3, 2], to_world[:3, 3] = u, v, n, center
        emitted: dict[str, Any] = _spectrum(radiance)
        if kind == "rect" and args.get("texture"):
            # The light's colour times the texture (hdEmbree's rect texture), read with
            # Hydra's sourceColorSpace auto and clamped at the rect's edges, as mipray does.
            texture = {"file": args["texture"], "wrapS": "clamp", "wrapT": "clamp"}
            emitted = _scaled_bitmap(path, texture, radiance)
        return {
            "type": "rectangle" if kind == "rect" else "disk",
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "bsdf": black,
            "emitter": {"type": "area", "radiance": emitted},
        }
    if kind == "cylinder":
        # UsdLux: a tube along the light's X, no end caps, emitting outward; round under the
        # mean of its Y and Z scales (as mipray). Mitsuba's cylinder: radius 1 about its +Z
        # from z = 0 to 1, emitting outward; a right-handed frame keeps its normals so.
        axis = m[:3, :3] @ np.array([float(args.get("length", 1.0)), 0.0, 0.0])
        scale = float(np.mean(np.linalg.norm(m[:3, 1:3], axis=0)))
        radius = float(args.get("radius", 0.5)) * scale
        length = float(np.linalg.norm(axis))
        if args.get("normalize"):
            area = 2.0 * math.pi * radius * length
            radiance = (radiance[0] / area, radiance[1] / area, radiance[2] / area)
        a = axis / length
        x = np.cross(a, [0.0, 1.0, 0.0] if abs(a[1]) < 0.9 else [1.0, 0.0, 0.0])
        x /= np.linalg.norm(x)
        to_world = np.eye(4)
        to_world[:3, 0], to_world[:3, 1] = radius * x, radius * np.cross(a, x)
        to_world[:3, 2], to_world[:3, 3] = axis, center - 0.5 * axis
        return {
            "type": "cylinder",
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "bsdf": black,
            "emitter": {"type": "area", "radiance": _spectrum(radiance)},
        }
    raise PrimError(path, f"light kind '{kind}' is not exported to Mitsuba")


#: Texels a side of the bitmap carrying UsdLux's cone softness and focus on a Mitsuba spot.
SPOT_TEXELS = 512


def shaping_factor(
    theta: NDArray[np.float64],
    cone_deg: float,
    softness: float,
    focus: float,
    focus_tint: tuple[float, float, float],
) -> NDArray[np.float64]:
    """UsdLux ShapingAPI's factor at angles ``theta`` (radians) off the light's axis, (..., 3).

    As Hydra's hdEmbree applies it (and ``mipray::light::Shaping`` documents it):
    ``lerp(|cos θ|^focus, focusTint, 1)`` when focus > 0, times
    ``1 − smoothstep(θ; θsoft, θcone)`` with θcone = cone angle and θsoft = θcone·(1 − softness)
    (softness 0: a hard edge at θcone). Written here from the schema, apart from the core's.
    """
    theta = np.asarray(theta, dtype=np.float64)
    out = np.ones((*theta.shape, 3))
    if focus > 0.0:
        ff = np.abs(np.cos(theta)) ** focus
        tint = np.asarray(focus_tint, dtype=np.float64)
        out = tint + (1.0 - tint) * ff[..., None]
    cone = math.radians(min(max(cone_deg, 0.0), 180.0))
    if cone < math.pi:
        soft = cone * (1.0 - min(max(softness, 0.0), 1.0))
        t = np.clip((theta - soft) / max(cone - soft, 1e-30), 0.0, 1.0)
        step = np.where(theta >= cone, 1.0, np.where(theta <= soft, 0.0, t * t * (3.0 - 2.0 * t)))
        out = out * (1.0 - step)[..., None]
    return out


def _spot(
    mi: Any,
    path: str,
    args: dict[str, Any],
    m: NDArray[np.float64],
    radiance: tuple[float, float, float],
    radius: float,
) -> dict[str, Any]:
    """A sphere light with ``ShapingAPI`` as Mitsuba's ``spot`` at its centre.

    Its intensity is the sphere's seen from afar, radiance · πr² (``normalize`` already
    applied to ``radiance``): a uniform sphere above a point's horizon lights it exactly as that
    point source does, and its radius r only blurs the cone's edge (and the shadows) by about
    r/d radians at distance d. The spot points
    along the light's -Z. Mitsuba's own falloff ramps *linearly* in θ from ``beam_width`` to
    ``cutoff_angle``; UsdLux's is a smoothstep over the same interval (they agree at both ends
    and halfway, and differ by up to 0.096 at a fifth of the way in from either end). So the
    spot's edge is Mitsuba's hard ``cutoff_angle`` = cone angle (``beam_width`` the same), and
    softness and focus ride on the spot's projected ``texture``: a bitmap over its tangent
    plane (uv = ½ + ½·(x/z, y/z)/tan(cutoff)) holding :func:`shaping_factor`, SPOT_TEXELS a
    side, read bilinearly. That needs a cone under 89°; a hard cone alone needs no texture.
    """
    cone = float(args["cone_angle"])
    softness = min(max(float(args.get("cone_softness", 0.0)), 0.0), 1.0)
    focus = max(float(args.get("focus", 0.0)), 0.0)
    tint = tuple(float(c) for c in args.get("focus_tint", (0.0, 0.0, 0.0)))
    axis = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
    axis /= np.linalg.norm(axis)
    side = np.cross(axis, [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    to_world = np.eye(4)
    to_world[:3, 0], to_world[:3, 1] = side, np.cross(axis, side)
    to_world[:3, 2], to_world[:3, 3] = axis, m[:3, 3]
    area = math.pi * radius * radius
    spot: dict[str, Any] = {
        "type": "spot",
        "to_world": mi.ScalarTransform4f(to_world.tolist()),
        "intensity": _spectrum((radiance[0] * area, radiance[1] * area, radiance[2] * area)),
        "cutoff_angle": min(cone, 180.0),
        "beam_width": min(cone, 180.0),
    }
    if softness > 0.0 or focus > 0.0:
        if not 0.0 < cone < 89.0:
            raise PrimError(
                path,
                f"a shaped light of cone angle {cone:g} with softness or focus is not exported "
                "to Mitsuba (its spot's texture needs a cone under 89 degrees)",
            )
        n = SPOT_TEXELS
        c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
        x, y = np.meshgrid(c, c)
        theta = np.arctan(np.hypot(x, y) * math.tan(math.radians(cone)))
        factor = shaping_factor(theta, cone, softness, focus, (tint[0], tint[1], tint[2]))
        spot["texture"] = {
            "type": "bitmap",
            "data": mi.TensorXf(factor.astype(np.float32)),
            "raw": True,
            "filter_type": "bilinear",
            "wrap_mode": "clamp",
        }
    return spot


# ----------------------------------------------------------------------------- camera


def _camera(mi: Any, path: str, args: dict[str, Any], width: int, height: int) -> dict[str, Any]:
    if args.get("projection", "perspective") != "perspective":
        raise PrimError(path, "only perspective cameras are exported to Mitsuba")
    if args.get("horizontal_aperture_offset", 0.0) or args.get("vertical_aperture_offset", 0.0):
        raise PrimError(path, "aperture offsets are not exported to Mitsuba")
    if args.get("f_stop", 0.0) > 0.0 and args.get("focus_distance", 0.0) > 0.0:
        raise PrimError(path, "depth of field is not exported to Mitsuba")
    ha, va = float(args["horizontal_aperture"]), float(args["vertical_aperture"])
    # The window fitted to the image as mipray's camera fits it (enlarged to the image aspect).
    aspect = width / height
    if aspect > ha / va:
        ha = va * aspect
    fov = math.degrees(2.0 * math.atan(0.5 * ha / float(args["focal_length"])))
    m = _column_matrix(args) @ np.diag([-1.0, 1.0, -1.0, 1.0])
    near, far = args.get("clipping_range", (1.0, 1e6))
    return {
        "type": "perspective",
        "fov": fov,
        "fov_axis": "x",
        "near_clip": float(near),
        "far_clip": float(far),
        "to_world": mi.ScalarTransform4f(m.tolist()),
        "film": {
            "type": "hdrfilm",
            "width": width,
            "height": height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
            "component_format": "float32",
            "sample_border": False,
        },
        "sampler": {"type": "independent", "sample_count": 1},
    }


# ----------------------------------------------------------------------------- scene


#: Mitsuba plugin name of the smooth Schlick conductor registered by :func:`_mitsuba`.
SCHLICK_MIRROR = "mipray_schlick_mirror"


def _register_schlick_mirror(mi: Any) -> None:
    """Registers a delta mirror whose Fresnel is Schlick's from ``f0_r/g/b`` to white.

    That is UsdPreviewSurface's metal at roughness 0. Mitsuba's ``conductor`` uses the
    complex-index Fresnel instead, and its ``principled`` at a tiny roughness is a near-delta
    GGX whose light samples make fireflies.
    """
    import drjit as dr

    class SchlickMirror(mi.BSDF):  # type: ignore[misc]
        def __init__(self, props: Any) -> None:
            mi.BSDF.__init__(self, props)
            self.f0 = mi.Color3f(*(float(props.get(f"f0_{c}", 1.0)) for c in "rgb"))
            self.m_flags = mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def sample(self, ctx: Any, si: Any, sample1: Any, sample2: Any, active: Any = True) -> Any:
            cos = mi.Frame3f.cos_theta(si.wi)
            bs = mi.BSDFSample3f()
            bs.wo = mi.reflect(si.wi)
            bs.pdf = 1.0
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DeltaReflection)
            bs.sampled_component = 0
            f = self.f0 + (1.0 - self.f0) * (1.0 - dr.clip(cos, 0.0, 1.0)) ** 5
            return bs, dr.select(cos > 0, f, mi.Color3f(0.0))

        def eval(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            return mi.Color3f(0.0)

        def pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            return 0.0

        def eval_pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            return mi.Color3f(0.0), 0.0

        def to_string(self) -> str:
            return f"SchlickMirror[f0 = {self.f0}]"

    mi.register_bsdf(SCHLICK_MIRROR, lambda props: SchlickMirror(props))


_registered: set[str] = set()


def _mitsuba() -> Any:
    try:
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MiprayError(
            f"Mitsuba 3 is not installed ({exc}); pip install mitsuba (scripts/requirements.txt)"
        ) from exc
    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    if VARIANT not in _registered:
        _register_schlick_mirror(mi)
        _registered.add(VARIANT)
    return mi


def scene_dict(
    cap: Capture, width: int, height: int | None = None, integrator: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The Mitsuba scene description of a :class:`Capture`; fills ``cap.materials``.

    ``integrator`` is Mitsuba's dict; by default ``path`` with max_depth 2 (direct light).

    Raises:
        PrimError: something Mitsuba cannot render the way mipray does (see the module doc).

    """
    mi = _mitsuba()
    height = image_height(width, cap.camera) if height is None else height
    scene: dict[str, Any] = {
        "type": "scene",
        "integrator": integrator or {"type": "path", "max_depth": 2},
        "sensor": _camera(mi, cap.camera_path, cap.camera, width, height),
    }
    for k, (path, args) in enumerate(sorted(cap.lights.items())):
        scene[f"light_{k}"] = _light(mi, path, args)
    for k, (path, args) in enumerate(sorted(cap.meshes.items())):
        if args.get("prototype"):
            raise PrimError(path, "instance prototypes are not exported to Mitsuba")
        if args.get("gprim") is not None:
            own = material_mapping(path, args.get("material"))
            cap.materials[path] = own
            if own.emission is not None or own.model in (TEXTURED_DIFFUSE, NORMAL_MAPPED):
                raise PrimError(path, "an emissive or textured implicit prim is not exported")
            for j, shape in enumerate(_analytic_shapes(path, args)):
                scene[f"mesh_{k}_{j}"] = {**shape, "bsdf": own.bsdf}
            continue
        points = _world_points(args)
        tris = _triangles(path, args, points)
        if len(tris) == 0:
            continue
        if args.get("light") is not None:
            scene.update(_mesh_light(mi, path, args, points, tris, f"mesh_{k}"))
            continue
        own = material_mapping(path, args.get("material"))
        cap.materials[path] = own
        # Per-face materials (GeomSubsets, per-face displayColor as lambertian ones).
        table = args.get("face_material_indices")
        groups: dict[int, MaterialMapping] = {-1: own}
        face_group = np.full(len(tris), -1, dtype=np.int64)
        if table is not None:
            face_group = np.asarray(table, dtype=np.int64)[tris[:, 3]]
            for g in np.unique(face_group).tolist():
                if g >= 0:
                    groups[g] = material_mapping(path, args["face_materials"][g])
        for g, mapping in groups.items():
            sel = tris[face_group == g]
            if len(sel) == 0 or mapping.bsdf is None:
                continue
            props = mi.Properties()
            props["bsdf"] = mi.load_dict(mapping.bsdf)
            if mapping.emission is not None:
                props["emitter"] = mi.load_dict(
                    {"type": "area", "radiance": _spectrum(mapping.emission)}
                )
                back = _back_faces(points, sel)
                back_props = mi.Properties()
                back_props["bsdf"] = mi.load_dict(mapping.bsdf)
                back_props["emitter"] = mi.load_dict(
                    {"type": "area", "radiance": _spectrum(mapping.emission)}
                )
                scene[f"mesh_{k}_{g + 1}_back"] = _mesh(mi, f"{path}[{g}] back", *back, back_props)
            st = None
            if mapping.model in (TEXTURED_DIFFUSE, NORMAL_MAPPED):
                st = _face_vertex_st(path, args)
                if st is None:
                    raise PrimError(path, "a texture on a mesh without st")
            scene[f"mesh_{k}_{g + 1}"] = _mesh(mi, f"{path}[{g}]", points, sel, props, st)
    return scene


def _mesh_light(
    mi: Any, path: str, args: dict[str, Any], points: NDArray[np.float64], tris: Any, key: str
) -> dict[str, Any]:
    """A mesh light (``set_mesh``'s ``light``) as Mitsuba area emitters on its triangles.

    Black (mipray's mesh lights reflect nothing), emitting from the front faces, and from
    the turned-over copy too when ``double_sided``. Under ``tint`` / ``tint_materials``
    (UsdLux ``materialGlowTintsLight``) each face's radiance is multiplied by what mipray's
    render delegate gives it: a GeomSubset's faces whose material is in ``tint_materials``
    that material's ``emissiveColor``, the other faces the mesh's own material's under
    ``tint`` (else the light's colour alone); a textured ``emissiveColor`` is a ``bitmap``
    radiance read at the mesh's ``st``. Only polygonal meshes: a subdivision surface's
    lighting tessellation is mipray's own.

    Raises:
        PrimError: a subdivision mesh light, one that casts no shadows, or a textured tint
            on a mesh without ``st``.

    """
    light = args["light"]
    if args.get("scheme", "catmullClark") != "none":
        raise PrimError(path, "a subdivision mesh light is not exported to Mitsuba")
    if not light.get("shadow_enable", True):
        raise PrimError(path, "inputs:shadow:enable is off: Mitsuba's lights always cast shadows")
    radiance = _light_radiance(light)
    if light.get("normalize"):
        corners = points[tris[:, :3]]
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        area = 0.5 * float(np.linalg.norm(cross, axis=1).sum())
        radiance = (radiance[0] / area, radiance[1] / area, radiance[2] / area)
    black = {"type": "diffuse", "reflectance": _spectrum((0.0, 0.0, 0.0))}

    def emission(material: dict[str, Any] | None) -> tuple[str, Any]:
        """A face group's tint: ("rgb", colour) or ("texture", the emissiveColor texture)."""
        if material is None:
            return ("rgb", (1.0, 1.0, 1.0))
        tex = (material.get("textures") or {}).get("emissiveColor")
        if tex is not None:
            return ("texture", tex)
        tint = _rgb(material.get("emissiveColor"), (0.0, 0.0, 0.0))
        return ("rgb", tuple(0.0 if math.isnan(c) else max(c, 0.0) for c in tint))

    own = emission(args.get("material") if light.get("tint") else None)
    own_name = (args.get("material") or {}).get("name") if light.get("tint") else None
    tinting = set(light.get("tint_materials") or [])
    # Per triangle: an index into `kinds` (0 the mesh's own emission).
    kinds: list[tuple[str, Any]] = [own]
    slot = np.zeros(len(tris), dtype=np.int64)
    table = args.get("face_material_indices")
    if table is not None and tinting:
        face_group = np.asarray(table, dtype=np.int64)[tris[:, 3]]
        for g in np.unique(face_group).tolist():
            if g < 0:
                continue
            material = args["face_materials"][g]
            if material.get("name") in tinting:
                kinds.append(emission(material))
                slot[face_group == g] = len(kinds) - 1
            elif material.get("name") != own_name:
                kinds.append(("rgb", (1.0, 1.0, 1.0)))
                slot[face_group == g] = len(kinds) - 1
    out: dict[str, Any] = {}
    for j, (what, value) in enumerate(kinds):
        sel = tris[slot == j]
        if len(sel) == 0:
            continue
        st = None
        if what == "texture":
            st = _face_vertex_st(path, args)
            if st is None:
                raise PrimError(path, "a mesh light tinted by a texture on a mesh without st")
            emitted = _scaled_bitmap(path, value, radiance)
        else:
            emitted = _spectrum(tuple(r * c for r, c in zip(radiance, value, strict=True)))

        def props(emitter: dict[str, Any] = emitted) -> Any:
            p = mi.Properties()
            p["bsdf"] = mi.load_dict(black)
            p["emitter"] = mi.load_dict({"type": "area", "radiance": emitter})
            return p

        name = f"{key}_{j}"
        out[name] = _mesh(mi, f"{path}[{j}]", points, sel, props(), st)
        if args.get("double_sided"):
            back_points, back_tris = _back_faces(points, sel)
            out[f"{name}_back"] = _mesh(
                mi, f"{path}[{j}] back", back_points, back_tris, props(), st
            )
    return out


def _back_faces(
    points: NDArray[np.float64], tris: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The triangles turned over and moved a hair behind themselves.

    mipray's ``emissiveColor`` emits from both sides of a surface, Mitsuba's area emitter
    along the face normal only: the turned-over copy emits the other way. Each triangle moves
    1e-5 of the mesh's size along its own back normal, so a ray from either side meets the copy
    that faces it first; nothing else can tell the two apart.
    """
    corners = points[tris[:, :3]]  # (T, 3, 3)
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    size = float(np.ptp(corners.reshape(-1, 3), axis=0).max())
    moved = corners[:, ::-1] - (1e-5 * size) * n[:, None, :]
    idx = np.arange(3 * len(tris), dtype=np.int64).reshape(-1, 3)
    # The face, and its corners' face-vertex positions in the turned-over order.
    faces = np.hstack([idx, tris[:, 3:4], tris[:, 6:3:-1]])
    return moved.reshape(-1, 3), faces


def render(
    stage: Usd.Stage,
    *,
    width: int,
    spp: int,
    seed: int = 0,
    integrator: dict[str, Any] | None = None,
    camera: str | None = None,
    height: int | None = None,
) -> NDArray[np.float32]:
    """Render ``stage`` with Mitsuba 3: an (H, W, 3) float32 linear RGB image, row 0 on top.

    Raises:
        PrimError: see :func:`scene_dict`.

    """
    mi = _mitsuba()
    cap = capture(stage, camera)
    scene = mi.load_dict(scene_dict(cap, width, height, integrator))
    image = mi.render(scene, spp=spp, seed=seed)
    out: NDArray[np.float32] = np.array(image, dtype=np.float32)[..., :3]
    return out
