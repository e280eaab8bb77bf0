"""Inline MaterialX networks in USD (``outputs:mtlx:surface``) as the renderer's BSDF.

The renderer's BSDF is UsdPreviewSurface's (``mipray::bsdf::preview``), so a MaterialX
surface is mapped onto its inputs; ``docs/materials.md`` has the table and what each
lobe mipray lacks becomes. Three surface shaders are read:
``ND_UsdPreviewSurface_surfaceshader`` (its inputs as they are),
``ND_standard_surface_surfaceshader`` and ``ND_open_pbr_surface_surfaceshader``.

What feeds an input is evaluated to a constant, or to one texture lookup under an affine
map (``texel · scale + bias``, what a ``UsdUVTexture`` is): ``ND_constant_*``,
``ND_image_*`` / ``ND_tiledimage_*`` (their ``texcoord`` from ``ND_texcoord_vector2`` or
``ND_geompropvalue_vector2``), ``ND_normalmap*`` on ``normal``, and ``ND_multiply_*``,
``ND_add_*``, ``ND_subtract_*``, ``ND_divide_*`` and ``ND_mix_*`` where at most one operand is a
texture. Anything else — another node, two textures combined, an input value of the wrong
type (a string where a number goes, an image's ``file`` that is no asset) — leaves the input
at its default; the stats' ``unsupported`` list names the material and the node (and the
input, for a wrong type), with one warning (:mod:`mipray.usd.unsupported`, row
``MaterialX node``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import Any

from pxr import Sdf, Usd, UsdShade

__all__ = [
    "MTLX_SURFACES",
    "SUPPORTED_NODE_PREFIXES",
    "MtlxRead",
    "mtlx_surface",
    "read_mtlx_surface",
    "unsupported_nodes",
]

_log = logging.getLogger(__name__)

#: The MaterialX surface shaders mapped onto the BSDF.
MTLX_SURFACES = (
    "ND_UsdPreviewSurface_surfaceshader",
    "ND_standard_surface_surfaceshader",
    "ND_open_pbr_surface_surfaceshader",
)
#: Node definitions evaluated (a prefix, then the output type).
SUPPORTED_NODE_PREFIXES = (
    "ND_constant_",
    "ND_image_",
    "ND_tiledimage_",
    "ND_texcoord_",
    "ND_geompropvalue_vector2",
    "ND_normalmap",
    "ND_multiply_",
    "ND_add_",
    "ND_subtract_",
    "ND_divide_",
    "ND_mix_",
    "ND_dot_",
)

_WRAPS = {"periodic": "repeat", "clamp": "clamp", "constant": "black", "mirror": "mirror"}


@dataclass(frozen=True)
class _Tex:
    """One texture lookup under an affine map: ``texel · scale + bias`` (four channels)."""

    desc: dict[str, Any]
    varname: str
    scale: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    bias: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def affine(self, k: tuple[float, ...], c: tuple[float, ...]) -> _Tex:
        """``(texel · scale + bias) · k + c``."""
        k4, c4 = _four(k), _four(c, 0.0)
        scale = tuple(s * m for s, m in zip(self.scale, k4, strict=True))
        bias = tuple(b * m + a for b, m, a in zip(self.bias, k4, c4, strict=True))
        return replace(self, scale=scale, bias=bias)  # type: ignore[arg-type]


@dataclass(frozen=True)
class _Coord:
    """A texcoord source: the primvar read."""

    varname: str


_Value = tuple[float, ...] | _Tex | _Coord | None


def _four(v: tuple[float, ...], pad: float = 1.0) -> tuple[float, float, float, float]:
    if len(v) == 1:
        return (v[0], v[0], v[0], v[0] if pad == 1.0 else pad)
    out = [*v[:4]] + [pad] * (4 - min(len(v), 4))
    return (out[0], out[1], out[2], out[3])


def _floats(value: Any) -> tuple[float, ...] | None:
    if value is None:
        return None
    try:
        return tuple(float(x) for x in value)
    except TypeError:
        try:
            return (float(value),)
        except (TypeError, ValueError):
            return None
    except ValueError:
        return None


def _const(a: tuple[float, ...], b: tuple[float, ...], op: str) -> tuple[float, ...]:
    n = max(len(a), len(b))
    a = a * n if len(a) == 1 else a
    b = b * n if len(b) == 1 else b
    if op == "multiply":
        return tuple(x * y for x, y in zip(a, b, strict=False))
    if op == "add":
        return tuple(x + y for x, y in zip(a, b, strict=False))
    if op == "subtract":
        return tuple(x - y for x, y in zip(a, b, strict=False))
    return tuple(x / y if y else 0.0 for x, y in zip(a, b, strict=False))


@dataclass
class _Eval:
    """Evaluates the nodes feeding one material's surface."""

    material: str
    time: Usd.TimeCode
    #: Nodes not evaluated: (node path, id).
    unsupported: list[tuple[str, str]] = field(default_factory=list)

    def input(self, shader: UsdShade.Shader, name: str) -> _Value:
        """The value of ``shader``'s input ``name``: constant, texture, or None (unauthored)."""
        inp = shader.GetInput(name)
        if not inp:
            return None
        for attr in inp.GetValueProducingAttributes():
            if UsdShade.Utils.GetType(attr.GetName()) == UsdShade.AttributeType.Output:
                return self.node(UsdShade.Shader(attr.GetPrim()))
            if not attr.HasAuthoredValue():
                return None
            value = _floats(attr.Get(self.time))
            if value is None:
                # A value of the wrong type (a string where a number goes): named, and the
                # input is left at its default rather than read as something else.
                kind = attr.GetTypeName()
                self._skip(shader, f"{shader.GetShaderId() or 'no id'} input {name} of type {kind}")
            return value
        return None

    def _skip(self, node: UsdShade.Shader, node_id: str) -> None:
        self.unsupported.append((str(node.GetPath()), node_id or "no id"))

    def node(self, node: UsdShade.Shader) -> _Value:
        node_id = str(node.GetShaderId() or "")
        kind = node_id[3:].split("_")[0] if node_id.startswith("ND_") else ""
        if node_id.startswith("ND_constant_"):
            return self.input(node, "value")
        if node_id.startswith(("ND_image_", "ND_tiledimage_")):
            return self.image(node, node_id)
        if node_id.startswith("ND_texcoord_"):
            return _Coord("st")
        if node_id == "ND_geompropvalue_vector2":
            name = node.GetInput("geomprop")
            value = name.Get(self.time) if name else None
            return _Coord(str(value) if value else "st")
        if node_id.startswith("ND_normalmap"):
            inner = self.input(node, "in")
            if isinstance(inner, _Tex):
                # MaterialX stores normals in [0, 1]: n = 2 · texel − 1, as UsdPreviewSurface's
                # normal map with scale 2 and bias −1.
                return inner.affine((2.0, 2.0, 2.0, 1.0), (-1.0, -1.0, -1.0, 0.0))
            self._skip(node, node_id)
            return None
        if node_id.startswith("ND_dot_"):
            return self.input(node, "in")
        if kind in ("multiply", "add", "subtract", "divide"):
            return self.binary(node, node_id, kind)
        if kind == "mix":
            return self.mix(node, node_id)
        self._skip(node, node_id)
        return None

    def image(self, node: UsdShade.Shader, node_id: str) -> _Value:
        file_inp = node.GetInput("file")
        attrs = file_inp.GetValueProducingAttributes() if file_inp else []
        value = attrs[0].Get(self.time) if attrs else None
        default = _floats(_get(node, "default", self.time)) or (0.0,)
        if value is not None and not isinstance(value, Sdf.AssetPath):
            kind = attrs[0].GetTypeName()
            self._skip(node, f"{node_id} input file of type {kind} (not an asset)")
            return default
        if not isinstance(value, Sdf.AssetPath) or not value.path:
            return default
        from .shading import _resolve

        desc: dict[str, Any] = {
            "file": _resolve(attrs[0], value),
            "channel": 0,
            "fallback": list(_four(default)),
        }
        space = attrs[0].GetColorSpace() if attrs[0].HasColorSpace() else ""
        if space:
            desc["sourceColorSpace"] = "sRGB" if space == "srgb_texture" else "raw"
        for key, usd_key in (("uaddressmode", "wrapS"), ("vaddressmode", "wrapT")):
            mode = _get(node, key, self.time)
            if mode and str(mode) in _WRAPS:
                desc[usd_key] = _WRAPS[str(mode)]
        coord = self.input(node, "texcoord")
        varname = coord.varname if isinstance(coord, _Coord) else "st"
        tex = _Tex(desc, varname)
        if node_id.startswith("ND_tiledimage_"):
            tiling = _floats(_get(node, "uvtiling", self.time)) or (1.0, 1.0)
            if tiling != (1.0, 1.0):
                self._skip(node, node_id + " uvtiling")
        return tex

    def binary(self, node: UsdShade.Shader, node_id: str, op: str) -> _Value:
        a, b = self.input(node, "in1"), self.input(node, "in2")
        a = a if a is not None else (1.0,) if op in ("multiply", "divide") else (0.0,)
        b = b if b is not None else (1.0,) if op in ("multiply", "divide") else (0.0,)
        if isinstance(a, tuple) and isinstance(b, tuple):
            return _const(a, b, op)
        if isinstance(a, _Tex) and isinstance(b, tuple):
            if op == "multiply":
                return a.affine(b, (0.0,))
            if op == "add":
                return a.affine((1.0,), b)
            if op == "subtract":
                return a.affine((1.0,), tuple(-x for x in b))
            return a.affine(tuple(1.0 / x if x else 0.0 for x in b), (0.0,))
        if isinstance(b, _Tex) and isinstance(a, tuple):
            if op == "multiply":
                return b.affine(a, (0.0,))
            if op == "add":
                return b.affine((1.0,), a)
            if op == "subtract":
                return b.affine((-1.0,), a)
        self._skip(node, node_id)
        return None

    def mix(self, node: UsdShade.Shader, node_id: str) -> _Value:
        # MaterialX: bg · (1 − mix) + fg · mix.
        fg, bg, m = self.input(node, "fg"), self.input(node, "bg"), self.input(node, "mix")
        fg = fg if fg is not None else (0.0,)
        bg = bg if bg is not None else (0.0,)
        m = m if m is not None else (0.0,)
        if not isinstance(m, tuple):
            self._skip(node, node_id)
            return None
        w = m[0]
        if isinstance(fg, tuple) and isinstance(bg, tuple):
            return _const(_const(fg, (w,), "multiply"), _const(bg, (1.0 - w,), "multiply"), "add")
        if isinstance(fg, _Tex) and isinstance(bg, tuple):
            return fg.affine((w,), _const(bg, (1.0 - w,), "multiply"))
        if isinstance(bg, _Tex) and isinstance(fg, tuple):
            return bg.affine((1.0 - w,), _const(fg, (w,), "multiply"))
        self._skip(node, node_id)
        return None


def _get(shader: UsdShade.Shader, name: str, time: Usd.TimeCode) -> Any:
    inp = shader.GetInput(name)
    return inp.Get(time) if inp else None


#: Each surface's inputs mapped onto UsdPreviewSurface's: preview input → (MaterialX input,
#: its weight input or None, MaterialX's default of each).
_STANDARD = {
    "diffuseColor": ("base_color", "base", (0.8, 0.8, 0.8), 1.0),
    "metallic": ("metalness", None, (0.0,), 1.0),
    "roughness": ("specular_roughness", None, (0.2,), 1.0),
    "ior": ("specular_IOR", None, (1.5,), 1.0),
    "clearcoat": ("coat", None, (0.0,), 1.0),
    "clearcoatRoughness": ("coat_roughness", None, (0.1,), 1.0),
    "emissiveColor": ("emission_color", "emission", (1.0, 1.0, 1.0), 0.0),
}
_OPEN_PBR = {
    "diffuseColor": ("base_color", "base_weight", (0.8, 0.8, 0.8), 1.0),
    "metallic": ("base_metalness", None, (0.0,), 1.0),
    "roughness": ("specular_roughness", None, (0.3,), 1.0),
    "ior": ("specular_ior", None, (1.5,), 1.0),
    "clearcoat": ("coat_weight", None, (0.0,), 1.0),
    "clearcoatRoughness": ("coat_roughness", None, (0.0,), 1.0),
    # emission_luminance is in nits; UsdPreviewSurface's emissiveColor is radiance in the
    # scene's units: the luminance is taken as the scale (docs/materials.md).
    "emissiveColor": ("emission_color", "emission_luminance", (1.0, 1.0, 1.0), 0.0),
}
#: Lobes and inputs the BSDF has no counterpart for (listed when authored non-default).
LACKING = {
    "ND_standard_surface_surfaceshader": (
        "diffuse_roughness", "specular_color", "specular_anisotropy", "transmission_color",
        "transmission_depth", "transmission_scatter", "subsurface", "sheen", "coat_color",
        "coat_anisotropy", "thin_film_thickness", "thin_walled",
    ),
    "ND_open_pbr_surface_surfaceshader": (
        "base_diffuse_roughness", "specular_color", "specular_roughness_anisotropy",
        "transmission_color", "transmission_depth", "subsurface_weight", "fuzz_weight",
        "coat_color", "thin_film_weight", "geometry_thin_walled",
    ),
}  # fmt: skip


@dataclass
class MtlxRead:
    """A MaterialX surface as the ``material`` argument, with its textures' ``st``."""

    args: dict[str, Any]
    #: (input, texture description, primvar its st reads), in the inputs' order.
    textures: list[tuple[str, dict[str, Any], str]]
    unsupported: list[tuple[str, str]]


def _set(out: MtlxRead, name: str, value: _Value, colour: bool, normal: bool = False) -> None:
    if value is None or isinstance(value, _Coord):
        return
    if isinstance(value, _Tex):
        desc = dict(value.desc)
        desc["scale"], desc["bias"] = list(value.scale), list(value.bias)
        out.textures.append((name, desc, value.varname))
        return
    if normal:
        return
    if colour:
        v = value * 3 if len(value) == 1 else value
        out.args[name] = (v[0], v[1], v[2])
    else:
        out.args[name] = float(value[0])


def read_mtlx_surface(material_path: str, surface: UsdShade.Shader, time: Usd.TimeCode) -> MtlxRead:
    """``surface`` (one of :data:`MTLX_SURFACES`) as UsdPreviewSurface inputs."""
    node_id = str(surface.GetShaderId())
    ev = _Eval(material_path, time)
    out = MtlxRead({"name": material_path}, [], ev.unsupported)
    colours = ("diffuseColor", "emissiveColor", "specularColor")
    if node_id == "ND_UsdPreviewSurface_surfaceshader":
        from .shading import COLOR_INPUTS, FLOAT_INPUTS

        for name in (*COLOR_INPUTS, *FLOAT_INPUTS, "useSpecularWorkflow", "normal"):
            _set(out, name, ev.input(surface, name), name in colours, name == "normal")
        if "useSpecularWorkflow" in out.args:
            out.args["useSpecularWorkflow"] = bool(out.args["useSpecularWorkflow"])
    else:
        table = _STANDARD if node_id == "ND_standard_surface_surfaceshader" else _OPEN_PBR
        for name, (mtlx, weight, default, weight_default) in table.items():
            # Unauthored inputs take MaterialX's defaults, which are not UsdPreviewSurface's.
            value = ev.input(surface, mtlx)
            value = value if value is not None else default
            w = ev.input(surface, weight) if weight else None
            w = w if w is not None else ((weight_default,) if weight else None)
            if w is not None:
                if isinstance(w, tuple) and isinstance(value, tuple):
                    value = _const(value, w, "multiply")
                elif isinstance(w, tuple) and isinstance(value, _Tex):
                    value = value.affine(w, (0.0,))
                elif isinstance(w, _Tex) and isinstance(value, tuple):
                    value = w.affine(value, (0.0,))
                else:
                    ev.unsupported.append((str(surface.GetPath()), f"{mtlx} × {weight}"))
                    continue
            _set(out, name, value, name in colours)
        _transmission(ev, surface, node_id, out)
        _set(out, "normal", ev.input(surface, "normal"), True, True)
        for lacking in LACKING.get(node_id, ()):
            inp = surface.GetInput(lacking)
            if inp and (inp.HasConnectedSource() or inp.GetAttr().HasAuthoredValue()):
                value = _floats(inp.Get(time))
                if value is None or any(v != 0.0 for v in value) or inp.HasConnectedSource():
                    ev.unsupported.append((str(surface.GetPath()), f"{node_id} input {lacking}"))
    if out.textures:
        out.args["textures"] = {name: desc for name, desc, _ in out.textures}
    return out


def _transmission(ev: _Eval, surface: UsdShade.Shader, node_id: str, out: MtlxRead) -> None:
    """Transmission (and standard_surface's opacity) as UsdPreviewSurface's opacity."""
    name = (
        "transmission"
        if node_id == "ND_standard_surface_surfaceshader"
        else ("transmission_weight")
    )
    t = ev.input(surface, name)
    if isinstance(t, tuple) and t[0] > 0.0:
        out.args["opacity"] = 1.0 - min(max(t[0], 0.0), 1.0)  # glass, with ior
    elif isinstance(t, _Tex):
        _set(out, "opacity", t.affine((-1.0,), (1.0,)), False)
    cutout = "opacity" if node_id == "ND_standard_surface_surfaceshader" else "geometry_opacity"
    c = ev.input(surface, cutout)
    if isinstance(c, tuple) and min(c) < 1.0:
        out.args["opacity"] = sum(c) / len(c)
        out.args["opacityThreshold"] = 1e-3  # MaterialX opacity is coverage: a cut-out
    elif isinstance(c, _Tex):
        _set(out, "opacity", c, False)
        out.args["opacityThreshold"] = 1e-3


def mtlx_surface(material: UsdShade.Material) -> UsdShade.Shader | None:
    """The surface of ``material``'s own ``outputs:mtlx:surface``, when mipray maps it.

    Only an authored mtlx output counts: ComputeSurfaceSource("mtlx") would fall back to the
    universal output, whose non-UsdPreviewSurface shaders keep rendering the display colour.
    """
    output = material.GetSurfaceOutput("mtlx")
    if not output or not output.HasConnectedSource():
        return None
    surface, _, _ = material.ComputeSurfaceSource("mtlx")
    return surface if surface and str(surface.GetShaderId()) in MTLX_SURFACES else None


def unsupported_nodes(material: UsdShade.Material, time: Usd.TimeCode) -> list[str]:
    """What of ``material``'s MaterialX surface is not rendered, one line each (the audit)."""
    surface = mtlx_surface(material)
    if surface is None:
        return []
    read = read_mtlx_surface(str(material.GetPath()), surface, time)
    return sorted({f"{what} at {path}" for path, what in read.unsupported})
