"""Shading inputs of a mesh beyond its constant albedo.

Read from the ``UsdPreviewSurface`` of the bound material (``full`` purpose, as
:mod:`mipray.usd.material` resolves it) and from the mesh itself:

- ``mirror``: a ``metallic`` surface with ``roughness`` ≈ 0 is a perfect mirror
  of reflectance ``diffuseColor × metallic`` (rough metals render diffuse until
  glossy reflection lands, with one warning);
- ``diffuse_texture`` / ``displacement_texture``: a ``UsdUVTexture`` feeding
  ``diffuseColor`` or ``displacement`` (``file``, ``scale``, ``bias``,
  ``fallback``, ``wrapS``, ``wrapT`` and the output used), its ``st`` read by a
  ``UsdPrimvarReader_float2`` (``varname``, default ``st``);
- ``st_values`` / ``st_indices`` / ``st_interpolation``: that primvar;
- ``displacement``: the built-in procedural displacement, from the mesh's
  ``mipray:displacement:amplitude``, ``frequency``, ``octaves`` and ``gain``;
- ``displacement_bound``: ``primvars:displacementBound`` on the mesh.
"""

from __future__ import annotations

import logging
import math
import os
from typing import Any

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdShade

__all__ = ["shading_arguments"]

_log = logging.getLogger(__name__)
_warned: set[str] = set()

_CHANNELS = {"rgb": 0, "r": 0, "g": 1, "b": 2, "a": 3}


def _warn_once(message: str) -> None:
    if message not in _warned:
        _warned.add(message)
        _log.warning("mipray: %s", message)


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
    if value.resolvedPath:
        return str(value.resolvedPath)
    path = value.path
    if not path or os.path.isabs(path):
        return path
    for spec in attr.GetPropertyStack(Usd.TimeCode.Default()):
        layer = spec.layer
        if layer and layer.realPath:
            return os.path.normpath(os.path.join(os.path.dirname(layer.realPath), path))
    return path


def _floats(value: Any, n: int, default: list[float]) -> list[float]:
    try:
        out = [float(x) for x in value][:n]
    except TypeError:
        return default
    return out + default[len(out) :]


Transform2d = tuple[tuple[float, float], float, tuple[float, float]]


def _transform2d(shader: UsdShade.Shader, time: Usd.TimeCode) -> Transform2d:
    """A UsdTransform2d's (scale, rotation in degrees, translation)."""
    scale = _floats(_const(shader, "scale", time) or (1.0, 1.0), 2, [1.0, 1.0])
    rotation = _const(shader, "rotation", time)
    translation = _floats(_const(shader, "translation", time) or (0.0, 0.0), 2, [0.0, 0.0])
    return (scale[0], scale[1]), float(rotation or 0.0), (translation[0], translation[1])


def apply_transform2d(st: np.ndarray, transform: Transform2d) -> np.ndarray:
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


def _texture(
    prim_path: str, shader: UsdShade.Shader, output: str, time: Usd.TimeCode, what: str
) -> tuple[dict[str, Any], str, Transform2d | None] | None:
    """A UsdUVTexture's description and the primvar its ``st`` reads."""
    if shader.GetShaderId() != "UsdUVTexture":
        _warn_once(
            f"{prim_path}: {what} is fed by {shader.GetPath()} ({shader.GetShaderId()}), "
            "which mipray does not support; using the input's fallback"
        )
        return None
    file_inp = shader.GetInput("file")
    attrs = file_inp.GetValueProducingAttributes() if file_inp else []
    value = attrs[0].Get(time) if attrs else None
    if not isinstance(value, Sdf.AssetPath) or not value.path:
        _warn_once(
            f"{prim_path}: {what} texture {shader.GetPath()} has no file; using its fallback"
        )
        return None
    desc: dict[str, Any] = {
        "file": _resolve(attrs[0], value),
        "channel": _CHANNELS.get(output, 0),
    }
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
    return desc, varname, transform


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


def shading_arguments(prim: Usd.Prim, time: Usd.TimeCode) -> dict[str, Any]:
    """The ``set_mesh`` keyword arguments for ``prim``'s shading (see the module doc)."""
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
    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(UsdShade.Tokens.full)
    if not material:
        return args
    surface, _, _ = material.ComputeSurfaceSource()
    st_name: str | None = None
    st_transform: Transform2d | None = None
    if surface and surface.GetShaderId() == "UsdPreviewSurface":
        metallic = _const(surface, "metallic", time)
        roughness = _const(surface, "roughness", time)
        diffuse = _const(surface, "diffuseColor", time)
        if metallic is not None and float(metallic) > 0.0:
            rough = 0.5 if roughness is None else float(roughness)
            if rough <= 0.05:
                base = _floats(
                    diffuse if diffuse is not None else (0.18, 0.18, 0.18), 3, [0.18] * 3
                )
                m = min(max(float(metallic), 0.0), 1.0)
                args["mirror"] = tuple(min(max(c * m, 0.0), 1.0) for c in base)
            else:
                _warn_once(
                    f"{path}: rough metal (roughness {rough}) renders diffuse "
                    "until glossy reflection is supported"
                )
        src = _source(surface, "diffuseColor")
        if src is not None:
            tex = _texture(path, src[0], src[1], time, "diffuseColor")
            if tex is not None:
                args["diffuse_texture"], st_name, st_transform = tex
    disp_shader, _, _ = material.ComputeDisplacementSource()
    if disp_shader and disp_shader.GetShaderId() == "UsdPreviewSurface":
        src = _source(disp_shader, "displacement")
        if src is not None:
            tex = _texture(path, src[0], src[1], time, "displacement")
            if tex is not None:
                args["displacement_texture"], name, transform = tex
                if st_name is not None and transform != st_transform:
                    _warn_once(
                        f"{path}: diffuseColor and displacement read st differently; "
                        "using diffuseColor's"
                    )
                if st_name is None:
                    st_name, st_transform = name, transform
    if st_name is not None:
        args.update(_st_arguments(prim, st_name, time))
        if st_transform is not None and "st_values" in args:
            # One st channel serves the mesh's textures: the UsdTransform2d applies to its values
            # (an affine map commutes with every interpolation the primvar may have).
            args["st_values"] = apply_transform2d(args["st_values"], st_transform).astype(
                np.float32
            )
    if not all(math.isfinite(float(c)) for c in args.get("mirror", ())):
        args.pop("mirror")
    return args
