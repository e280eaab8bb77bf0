"""A mesh's shading: its UsdPreviewSurface's inputs, textures, ``st`` and displacement.

Read from the ``UsdPreviewSurface`` of the bound material (``full`` purpose, as
:mod:`mipray.usd.material` resolves it) and from the mesh itself, as
``set_mesh`` keyword arguments:

- ``material``: every UsdPreviewSurface input mipray renders — ``diffuseColor``,
  ``emissiveColor``, ``useSpecularWorkflow``, ``specularColor``, ``metallic``,
  ``roughness``, ``clearcoat``, ``clearcoatRoughness``, ``opacity``,
  ``opacityThreshold``, ``ior`` — each a constant (authored, or through a
  material interface input; unauthored inputs are left out and keep the
  specification's fallbacks), and under ``"textures"`` a ``UsdUVTexture`` per
  textured input (``normal`` included), with ``"name"`` the material's path.
  Values go as authored: the renderer clamps out-of-range ones with one warning
  naming the material.
- What feeds an input: a ``UsdUVTexture`` (``file``, ``scale``, ``bias``,
  ``fallback``, ``wrapS``, ``wrapT``, ``sourceColorSpace`` and the connected
  output's channel), its
  ``st`` read by a ``UsdPrimvarReader_float2`` (``varname``, default ``st``),
  optionally through a ``UsdTransform2d``; or a ``UsdPrimvarReader_*`` reading
  a primvar of the mesh (its value if constant; one that varies over a mesh is
  interpolated as authored: ``primvars``; on other gprims its mean, with one
  warning). Any other node falls back to the input's fallback value, with one
  warning naming the material and the node.
- ``st_values`` / ``st_indices`` / ``st_interpolation``: the one ``st`` primvar
  a mesh's textures read (a ``UsdTransform2d`` applied to its values). Textures
  reading different primvars (or transforming them differently) get the first
  one's, with one warning.
- ``primvars``: ``{input name: {"values", "indices", "interpolation"}}`` for
  inputs fed by a ``UsdPrimvarReader_*`` whose primvar varies over the mesh, and
  ``geomprop:<name>`` for a MaterialX ``geompropvalue`` of one in a network.
- ``displacement_texture``: a ``UsdUVTexture`` feeding ``displacement``;
  ``displacement``: the built-in procedural displacement, from the mesh's
  ``mipray:displacement:amplitude``, ``frequency``, ``octaves`` and ``gain``;
  ``displacement_bound``: ``primvars:displacementBound`` on the mesh.

- ``face_materials`` / ``face_material_indices``: the whole networks of the
  mesh's materialBind GeomSubsets bound to UsdPreviewSurfaces (each a dict as
  ``material``; their textures read the mesh's one ``st``), and per face the
  one it renders (the mesh's own ``material`` on the other faces).

Bindings are resolved by usd-core (:func:`bound_material`): direct and
collection bindings, ``bindMaterialAs`` strength, and the ``full`` purpose
before the all-purpose binding, as Hydra does for a final-frame renderer.

A material whose surface is not a UsdPreviewSurface sends no ``material``: the
mesh renders its display color (one warning naming the material).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Sdf, Usd, UsdGeom, UsdShade

from ..errors import PrimError
from .assets import UDIM_TOKEN, local_file, udim_tiles
from .materialx import MtlxRead, mtlx_surface, read_mtlx_surface
from .primvars import primvar_argument, read_display_primvar
from .warn import warn_once

__all__ = [
    "COLOR_INPUTS",
    "FALLBACKS",
    "FLOAT_INPUTS",
    "TEXTURED_INPUTS",
    "material_might_vary",
    "shading_arguments",
]

_warn_once = warn_once(__name__)

_CHANNELS = {"rgb": 0, "r": 0, "g": 1, "b": 2, "a": 3}
#: UsdUVTexture ``sourceColorSpace`` tokens. ``auto`` (the fallback) reads 8-bit files of 3 or 4
#: channels as sRGB and everything else as raw, as Hydra's Storm does; the renderer decodes sRGB
#: files into linear MIP maps before filtering (``mipray_bridge``'s texture system).
_COLOR_SPACES = ("auto", "raw", "sRGB")

#: Colour inputs (three floats, linear RGB).
COLOR_INPUTS = ("diffuseColor", "emissiveColor", "specularColor")
#: Float inputs.
FLOAT_INPUTS = (
    "metallic",
    "roughness",
    "clearcoat",
    "clearcoatRoughness",
    "opacity",
    "opacityThreshold",
    "ior",
)
#: Inputs a texture can feed, in the order their ``st`` is chosen (the first wins).
TEXTURED_INPUTS = (
    "diffuseColor",
    "emissiveColor",
    "specularColor",
    "metallic",
    "roughness",
    "clearcoat",
    "clearcoatRoughness",
    "opacity",
    "ior",
    "normal",
)
#: UsdPreviewSurface's fallback values (its specification).
FALLBACKS: dict[str, Any] = {
    "diffuseColor": (0.18, 0.18, 0.18),
    "emissiveColor": (0.0, 0.0, 0.0),
    "useSpecularWorkflow": 0,
    "specularColor": (0.0, 0.0, 0.0),
    "metallic": 0.0,
    "roughness": 0.5,
    "clearcoat": 0.0,
    "clearcoatRoughness": 0.01,
    "opacity": 1.0,
    "opacityThreshold": 0.0,
    "ior": 1.5,
    "normal": (0.0, 0.0, 1.0),
}


def _const(shader: UsdShade.Shader, name: str, time: Usd.TimeCode) -> Any:
    """A shader input's constant value (None when connected or unauthored)."""
    inp = shader.GetInput(name)
    if not inp:
        return None
    attrs = inp.GetValueProducingAttributes()
    if not attrs or UsdShade.Utils.GetType(attrs[0].GetName()) == UsdShade.AttributeType.Output:
        return None
    return attrs[0].Get(time)


def _source(shader: UsdShade.Shader, name: str) -> tuple[UsdShade.Shader, str] | None:
    """The (shader, output name) an input is connected to, through interface inputs."""
    inp = shader.GetInput(name)
    if not inp:
        return None
    for attr in inp.GetValueProducingAttributes():
        if UsdShade.Utils.GetType(attr.GetName()) == UsdShade.AttributeType.Output:
            base, _ = UsdShade.Utils.GetBaseNameAndType(attr.GetName())
            return UsdShade.Shader(attr.GetPrim()), str(base)
    return None


def _resolve(attr: Usd.Attribute, value: Sdf.AssetPath) -> str:
    """A texture file OpenImageIO can open for ``value``, authored on ``attr``.

    Resolved by usd-core's asset resolver; a file inside a package (``.usdz``) is extracted
    (:func:`mipray.usd.assets.local_file`). A path the resolver leaves unresolved (a
    ``<UDIM>`` set, a missing file) is anchored to the layer that authored it, as usd-core
    anchors asset paths (inside a package too).
    """
    if value.resolvedPath:
        resolved = str(value.resolvedPath)
    else:
        resolved = str(value.path)
        if resolved and not os.path.isabs(resolved):
            for spec in attr.GetPropertyStack(Usd.TimeCode.Default()):
                if spec.layer and not spec.layer.anonymous:
                    resolved = str(spec.layer.ComputeAbsolutePath(resolved))
                    break
    if UDIM_TOKEN in resolved:
        return resolved
    try:
        return local_file(resolved)
    except OSError as exc:
        _warn_once(f"{attr.GetPath()}: {exc}")
        return resolved


def _floats(value: Any, n: int, default: list[float]) -> list[float]:
    try:
        out = [float(x) for x in value][:n]
    except (TypeError, ValueError):
        return default
    return out + default[len(out) :]


def _value(name: str, value: Any) -> Any:
    """A constant input as ``set_mesh`` takes it, or None when it has the wrong type."""
    try:
        if name in COLOR_INPUTS:
            r, g, b = (float(c) for c in value)
            return (r, g, b)
        if name == "useSpecularWorkflow":
            return int(value) != 0
        return float(value)
    except (TypeError, ValueError):
        return None


Transform2d = tuple[tuple[float, float], float, tuple[float, float]]


def _transform2d(shader: UsdShade.Shader, time: Usd.TimeCode) -> Transform2d:
    """A UsdTransform2d's (scale, rotation in degrees, translation)."""
    scale = _floats(_const(shader, "scale", time) or (1.0, 1.0), 2, [1.0, 1.0])
    rotation = _const(shader, "rotation", time)
    translation = _floats(_const(shader, "translation", time) or (0.0, 0.0), 2, [0.0, 0.0])
    return (scale[0], scale[1]), float(rotation or 0.0), (translation[0], translation[1])


def apply_transform2d(st: NDArray[np.float32], transform: Transform2d) -> NDArray[np.float32]:
    """``st`` through a UsdTransform2d: scaled, rotated counter-clockwise, then translated.

    This is UsdPreviewSurface's definition of the node.
    """
    (sx, sy), degrees, (tx, ty) = transform
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    x, y = st[:, 0] * sx, st[:, 1] * sy
    out = np.empty_like(st)
    out[:, 0] = x * c - y * s + tx
    out[:, 1] = x * s + y * c + ty
    return out


@dataclass(frozen=True)
class _Texture:
    """A UsdUVTexture as ``set_mesh`` takes it, and the ``st`` it reads."""

    desc: dict[str, Any]
    varname: str
    transform: Transform2d | None


def _texture_fallback(shader: UsdShade.Shader, time: Usd.TimeCode) -> list[float]:
    return _floats(_const(shader, "fallback", time), 4, [0.0, 0.0, 0.0, 1.0])


def _texture(
    owner: str, shader: UsdShade.Shader, output: str, time: Usd.TimeCode, what: str
) -> _Texture | None:
    """A UsdUVTexture's description and the primvar its ``st`` reads; None without a file.

    ``owner`` (the material, or the mesh for displacement) names the warnings.
    """
    file_inp = shader.GetInput("file")
    attrs = file_inp.GetValueProducingAttributes() if file_inp else []
    value = attrs[0].Get(time) if attrs else None
    if not isinstance(value, Sdf.AssetPath) or not value.path:
        _warn_once(f"{owner}: {what} texture {shader.GetPath()} has no file; using its fallback")
        return None
    desc: dict[str, Any] = {
        "file": _resolve(attrs[0], value),
        "channel": _CHANNELS.get(output, 0),
    }
    if UDIM_TOKEN in desc["file"]:
        # No tile found: the renderer cannot open the pattern itself, and says so.
        desc["udim_tiles"] = udim_tiles(desc["file"])
    for key, default in (
        ("scale", [1.0] * 4),
        ("bias", [0.0] * 4),
        ("fallback", [0.0, 0.0, 0.0, 1.0]),
    ):
        v = _const(shader, key, time)
        if v is not None:
            desc[key] = _floats(v, 4, default)
    for key in ("wrapS", "wrapT"):
        v = _const(shader, key, time)
        if v:
            desc[key] = str(v)
    space = _const(shader, "sourceColorSpace", time)
    if space:
        if str(space) in _COLOR_SPACES:
            desc["sourceColorSpace"] = str(space)
        else:
            _warn_once(
                f"{owner}: {what} texture {shader.GetPath()} has sourceColorSpace '{space}', "
                f"not one of {', '.join(_COLOR_SPACES)}; using auto"
            )
    varname = "st"
    transform: Transform2d | None = None
    st_src = _source(shader, "st")
    if st_src is not None:
        reader, _ = st_src
        if reader.GetShaderId() == "UsdTransform2d":
            transform = _transform2d(reader, time)
            inner = _source(reader, "in")
            reader = inner[0] if inner else reader
        if reader.GetShaderId() == "UsdPrimvarReader_float2":
            name = _const(reader, "varname", time)
            if name:
                varname = str(name)
        elif reader.GetShaderId() != "UsdTransform2d":
            _warn_once(
                f"{owner}: {what} texture's st is fed by {reader.GetPath()} "
                f"({reader.GetShaderId()}), which mipray does not support; reading primvars:st"
            )
    return _Texture(desc, varname, transform)


def _primvar_value(
    material: str,
    prim: Usd.Prim,
    reader: UsdShade.Shader,
    name: str,
    time: Usd.TimeCode,
    varying: dict[str, dict[str, Any]],
) -> Any:
    """The value a UsdPrimvarReader feeding ``name`` reads on ``prim``.

    A constant primvar is its value; one that varies over a mesh is its mean (the
    constant where the renderer cannot evaluate it) and, checked against the mesh,
    goes into ``varying[name]`` as a ``set_mesh`` ``primvars`` entry, interpolated
    as authored (a bad one: one warning naming the prim and primvar, the mean). On
    other gprims a varying primvar is its mean (one warning); a missing one the
    reader's ``fallback``, else the input's.
    """
    varname = _const(reader, "varname", time)
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar(str(varname)) if varname else None
    if not primvar or not primvar.HasValue():
        v = _value(name, _const(reader, "fallback", time))
        return FALLBACKS[name] if v is None else v
    values = np.asarray(primvar.ComputeFlattened(time), dtype=np.float64)
    width = 3 if name in COLOR_INPUTS else 1
    if values.size == 0 or values.size % width:
        return FALLBACKS[name]
    values = values.reshape(-1, width)
    if len(values) > 1 and not (values == values[0]).all() and prim.IsA(UsdGeom.Mesh):
        mesh = UsdGeom.Mesh(prim)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], dtype=np.int32)
        n_points = len(mesh.GetPointsAttr().Get(time) or [])
        try:
            read = read_display_primvar(mesh, str(varname), time, counts, n_points, width)
        except PrimError as exc:
            _warn_once(f"{exc}; {material}'s {name} uses its mean")
        else:
            if read is not None:
                varying[name] = primvar_argument(read)
    elif len(values) > 1 and not (values == values[0]).all():
        _warn_once(
            f"{material}: {name} reads primvars:{varname} of {prim.GetPath()}, which varies over "
            "the mesh; mipray uses its mean"
        )
    mean = values.mean(axis=0)
    return _value(name, mean if width == 3 else mean[0])


@dataclass
class _Material:
    """What :func:`_preview_surface` read."""

    args: dict[str, Any]
    #: (input, texture) in :data:`TEXTURED_INPUTS` order.
    textures: list[tuple[str, _Texture]]
    #: Inputs fed by a primvar varying over the mesh: ``set_mesh``'s ``primvars`` entries.
    primvars: dict[str, dict[str, Any]]


def _preview_surface(
    prim: Usd.Prim, material_path: str, surface: UsdShade.Shader, time: Usd.TimeCode
) -> _Material:
    """Every input of ``surface`` as the ``material`` argument (see the module doc)."""
    args: dict[str, Any] = {"name": material_path}
    textures: list[tuple[str, _Texture]] = []
    varying: dict[str, dict[str, Any]] = {}
    for name in (*COLOR_INPUTS, "useSpecularWorkflow", *FLOAT_INPUTS, "normal"):
        src = _source(surface, name)
        if src is None:
            if name == "normal":
                continue  # a constant normal is the surface's own (tangent-space +Z)
            raw = _const(surface, name, time)
            if raw is None:
                continue
            v = _value(name, raw)
            if v is None:
                _warn_once(f"{material_path}: {name} = {raw!r} is not a number; using its fallback")
            else:
                args[name] = v
            continue
        node, output = src
        node_id = str(node.GetShaderId() or "")
        if node_id == "UsdUVTexture" and name in TEXTURED_INPUTS:
            tex = _texture(material_path, node, output, time, name)
            if tex is not None:
                textures.append((name, tex))
            elif name != "normal":
                fallback = _texture_fallback(node, time)
                channel = _CHANNELS.get(output, 0)
                args[name] = (
                    tuple(fallback[:3]) if name in COLOR_INPUTS else fallback[min(channel, 3)]
                )
        elif node_id.startswith("UsdPrimvarReader_") and name != "normal":
            args[name] = _primvar_value(material_path, prim, node, name, time, varying)
        else:
            what = f"{node_id} node" if node_id else "node without an id"
            if node_id == "UsdUVTexture":
                what = "texture (mipray reads only a constant here)"
            _warn_once(
                f"{material_path}: {name} is fed by {node.GetPath()}, a {what} mipray does not "
                f"support; using the input's fallback {FALLBACKS[name]}"
            )
            if name != "normal":
                args[name] = FALLBACKS[name]
    order = {n: i for i, n in enumerate(TEXTURED_INPUTS)}
    textures.sort(key=lambda t: order[t[0]])
    if textures:
        args["textures"] = {name: tex.desc for name, tex in textures}
    return _Material(args, textures, varying)


def _st_arguments(prim: Usd.Prim, varname: str, time: Usd.TimeCode) -> dict[str, Any]:
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar(varname)
    if not primvar or not primvar.HasValue():
        _warn_once(f"{prim.GetPath()}: textures read primvars:{varname}, which it does not have")
        return {}
    values = np.asarray(primvar.Get(time), dtype=np.float32).reshape(-1, 2)
    out: dict[str, Any] = {
        "st_values": values,
        "st_interpolation": str(primvar.GetInterpolation()),
    }
    if primvar.IsIndexed():
        out["st_indices"] = np.asarray(primvar.GetIndices(time), dtype=np.int32)
    return out


def _procedural(prim: Usd.Prim, time: Usd.TimeCode) -> tuple[float, float, int, float] | None:
    amp = prim.GetAttribute("mipray:displacement:amplitude")
    if not amp or not amp.HasAuthoredValue():
        return None

    def get(name: str, default: float) -> float:
        a = prim.GetAttribute(f"mipray:displacement:{name}")
        v = a.Get(time) if a and a.HasAuthoredValue() else None
        return float(v) if v is not None else default

    return (
        float(amp.Get(time)),
        get("frequency", 1.0),
        int(get("octaves", 4)),
        get("gain", 0.5),
    )


def material_might_vary(prim: Usd.Prim, subsets: list[Subset] | None = None) -> bool:
    """Whether the shading :func:`shading_arguments` reads for ``prim`` may change over time.

    True when an input of the bound material's (or a subset's) surface or displacement shader,
    or of a node feeding one (textures, readers, transforms, interface inputs), is time-sampled.
    """
    bound = [bound_material(p) for p in (prim, *(s for s, _ in subsets or ()))]
    seen: set[str] = set()
    todo = [
        s
        for material in bound
        if material is not None
        for s in (
            material.ComputeSurfaceSource()[0],
            material.ComputeSurfaceSource("mtlx")[0],
            material.ComputeDisplacementSource()[0],
        )
        if s
    ]
    while todo:
        shader = todo.pop()
        key = str(shader.GetPath())
        if key in seen:
            continue
        seen.add(key)
        for inp in shader.GetInputs():
            for attr in inp.GetValueProducingAttributes():
                if UsdShade.Utils.GetType(attr.GetName()) == UsdShade.AttributeType.Output:
                    todo.append(UsdShade.Shader(attr.GetPrim()))
                elif attr.ValueMightBeTimeVarying():
                    return True
    return False


def _describe_st(varname: str, transform: Transform2d | None) -> str:
    return f"primvars:{varname}" + ("" if transform is None else f" through {transform}")


def bound_material(prim: Usd.Prim) -> UsdShade.Material | None:
    """The material bound to ``prim`` (a gprim, a GeomSubset, an instance proxy) for rendering.

    usd-core resolves it as Hydra does for a renderer of ``full`` purpose: direct and
    collection bindings, ``bindMaterialAs`` strength, the nearest ancestor's binding, a
    ``full`` binding before an all-purpose one (a ``preview``-only binding is not used).
    """
    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(UsdShade.Tokens.full)
    return material if material else None


def _surface_material(
    prim: Usd.Prim, material: UsdShade.Material, time: Usd.TimeCode, surface_st: bool = False
) -> _Material | None:
    """The ``material`` argument of ``material``'s UsdPreviewSurface on ``prim``, or None.

    ``surface_st``: ``prim``'s textures read its surface's own (u, v) (see
    :func:`shading_arguments`).
    """
    material_path = str(material.GetPath())
    surface, _, _ = material.ComputeSurfaceSource()
    if surface and surface.GetShaderId() == "UsdPreviewSurface":
        return _preview_surface(prim, material_path, surface, time)
    mtlx = mtlx_surface(material)
    if mtlx is not None:
        read = read_mtlx_surface(material_path, mtlx, time, prim, surface_st)
        for line in read.warnings:
            _warn_once(line)
        textures = [(name, _Texture(desc, varname, None)) for name, desc, varname in read.textures]
        # A network's lookups and texcoords read the mesh's st as a texture's do.
        textures += [
            (name, _Texture({}, varname, None))
            for name, _, names in read.networks
            for varname in names
        ]
        return _Material(read.args, textures, _network_primvars(prim, read, time))
    if surface:
        _warn_once(
            f"{material_path}: surface shader {surface.GetPath()} ({surface.GetShaderId()}) is "
            "not a UsdPreviewSurface; rendering the mesh's display color"
        )
    return None


def _network_primvars(
    prim: Usd.Prim, read: MtlxRead, time: Usd.TimeCode
) -> dict[str, dict[str, Any]]:
    """The ``set_mesh`` ``primvars`` entries (``geomprop:<name>``) ``read``'s networks read.

    Each checked against the mesh; a bad one is warned about once and its node's ``default``
    is read instead.
    """
    out: dict[str, dict[str, Any]] = {}
    mesh = UsdGeom.Mesh(prim)
    for _, net, _ in read.networks:
        for p in net.get("primvars", ()):
            key = f"geomprop:{p['name']}"
            if key in out:
                continue
            counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], dtype=np.int32)
            n_points = len(mesh.GetPointsAttr().Get(time) or [])
            try:
                primvar = read_display_primvar(
                    mesh, p["name"], time, counts, n_points, p["components"]
                )
            except PrimError as exc:
                _warn_once(f"{exc}; {read.args['name']} reads its geompropvalue default there")
                continue
            if primvar is not None:
                out[key] = primvar_argument(primvar)
    return out


#: A materialBind GeomSubset and its (checked) face indices.
Subset = tuple[Usd.Prim, NDArray[np.int64]]


def _face_materials(
    prim: Usd.Prim,
    own: UsdShade.Material | None,
    own_read: _Material | None,
    subsets: list[Subset],
    face_count: int,
    time: Usd.TimeCode,
    args: dict[str, Any],
) -> list[tuple[str, str, Transform2d | None]]:
    """``face_materials`` / ``face_material_indices`` for subsets bound to UsdPreviewSurfaces.

    Each such subset's faces get its material's whole network (textures included); the other
    faces keep the mesh's own material (when it is a UsdPreviewSurface), else their colour
    from the face albedo table (-1). Nothing is added when every subset renders the mesh's
    own material. Returns the subsets' texture readers, for the shared ``st``.
    """
    own_key = str(own.GetPath()) if own is not None and own_read is not None else None
    slot: dict[str, int] = {}
    materials: list[dict[str, Any]] = []
    st_users: list[tuple[str, str, Transform2d | None]] = []
    per_face: list[tuple[NDArray[np.int64], int]] = []
    if own_key is not None and own_read is not None:
        slot[own_key] = 0
        materials.append(own_read.args)
    for subset, faces in subsets:
        material = bound_material(subset)
        if material is None:
            continue
        key = str(material.GetPath())
        if key not in slot:
            read = _surface_material(prim, material, time)
            if read is None:
                continue  # not a UsdPreviewSurface: the subset's faces keep their colour
            slot[key] = len(materials)
            materials.append(read.args)
            st_users += [(name, t.varname, t.transform) for name, t in read.textures]
        per_face.append((faces, slot[key]))
    if all(k == slot.get(own_key or "") for _, k in per_face):
        return []
    indices = np.full(face_count, 0 if own_key is not None else -1, np.int32)
    for faces, k in per_face:
        indices[faces] = k
    args["face_materials"] = materials
    args["face_material_indices"] = indices
    return st_users


def shading_arguments(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    *,
    surface_st: bool = False,
    subsets: list[Subset] | None = None,
    face_count: int = 0,
) -> dict[str, Any]:
    """The ``set_mesh`` keyword arguments for ``prim``'s shading (see the module doc).

    ``surface_st``: the prim's textures read its surface's own (u, v) (implicit
    gprims and points), not an ``st`` primvar. ``subsets``: the mesh's materialBind
    GeomSubsets with their faces, of ``face_count`` faces in all.
    """
    args: dict[str, Any] = {}
    path = str(prim.GetPath())
    proc = _procedural(prim, time)
    if proc is not None:
        args["displacement"] = proc
    bound = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displacementBound")
    if bound and bound.HasValue():
        v = bound.Get(time)
        try:
            args["displacement_bound"] = float(v if not hasattr(v, "__len__") else v[0])
        except (TypeError, ValueError, IndexError):
            _warn_once(f"{path}: primvars:displacementBound {v!r} is not a number; ignored")
    material = bound_material(prim)
    # Every texture of the mesh reads one st: (who reads it, varname, transform) of the first.
    st_users: list[tuple[str, str, Transform2d | None]] = []
    read = _surface_material(prim, material, time, surface_st) if material else None
    if read is not None:
        args["material"] = read.args
        if read.primvars and not surface_st:
            args["primvars"] = read.primvars
        st_users += [(name, t.varname, t.transform) for name, t in read.textures]
    if subsets:
        st_users += _face_materials(prim, material, read, subsets, face_count, time, args)
    if not material:
        return _with_st(prim, time, args, st_users, surface_st=surface_st)
    material_path = str(material.GetPath())
    disp_shader, _, _ = material.ComputeDisplacementSource()
    if disp_shader and disp_shader.GetShaderId() == "UsdPreviewSurface":
        src = _source(disp_shader, "displacement")
        if src is not None:
            if src[0].GetShaderId() != "UsdUVTexture":
                _warn_once(
                    f"{material_path}: displacement is fed by {src[0].GetPath()} "
                    f"({src[0].GetShaderId()}), which mipray does not support; not displaced"
                )
            else:
                tex = _texture(path, src[0], src[1], time, "displacement")
                if tex is not None:
                    args["displacement_texture"] = tex.desc
                    st_users.append(("displacement", tex.varname, tex.transform))
    return _with_st(prim, time, args, st_users, surface_st=surface_st)


def _with_st(
    prim: Usd.Prim,
    time: Usd.TimeCode,
    args: dict[str, Any],
    st_users: list[tuple[str, str, Transform2d | None]],
    *,
    surface_st: bool,
) -> dict[str, Any]:
    """``args`` with the one ``st`` the mesh's textures read (the first reader's)."""
    path = str(prim.GetPath())
    if st_users:
        first, st_name, st_transform = st_users[0]
        for name, varname, transform in st_users[1:]:
            if (varname, transform) != (st_name, st_transform):
                _warn_once(
                    f"{path}: {name} texture reads {_describe_st(varname, transform)} but "
                    f"{first} reads {_describe_st(st_name, st_transform)}; a mesh's textures "
                    f"share one st: using {first}'s"
                )
        if surface_st:
            if st_transform is not None:
                _warn_once(
                    f"{path}: the UsdTransform2d on {first}'s st is not applied to an implicit "
                    "prim's (u, v)"
                )
            return args
        args.update(_st_arguments(prim, st_name, time))
        if st_transform is not None and "st_values" in args:
            # One st channel serves the mesh's textures: the UsdTransform2d applies to its values
            # (an affine map commutes with every interpolation the primvar may have).
            args["st_values"] = apply_transform2d(args["st_values"], st_transform).astype(
                np.float32
            )
    return args
