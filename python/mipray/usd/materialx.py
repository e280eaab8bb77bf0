"""Inline MaterialX networks in USD (``outputs:mtlx:surface``) as the renderer's BSDF.

The renderer's BSDF is UsdPreviewSurface's (``mipray::bsdf::preview``), so a MaterialX
surface is mapped onto its inputs; ``docs/materials.md`` has the table and what each
lobe mipray lacks becomes. Three surface shaders are read:
``ND_UsdPreviewSurface_surfaceshader`` (its inputs as they are),
``ND_standard_surface_surfaceshader`` and ``ND_open_pbr_surface_surfaceshader``.

What feeds an input is folded here to a constant, or to one texture lookup under an affine map
(``texel · scale + bias``, what a ``UsdUVTexture`` is, the renderer's fast path); anything else
of the nodes in :data:`EVALUATED` is lowered to a node network the renderer evaluates per
shading point (``mipray::material::network``: ``"networks"`` in the ``material`` argument).
Each node's inputs default as its nodedef in the MaterialX package's standard library says
(``libraries/stdlib/stdlib_defs.mtlx``), and each operator is the one of the library's GLSL
implementation (``genglsl/stdlib_genglsl_impl.mtlx``; ``place2d``, ``tiledimage``, ``convert``
and ``checkerboard`` as their nodegraphs in ``stdlib_ng.mtlx`` build them). Texture
coordinates (``texcoord``, ``geompropvalue`` of a vector2, ``place2d``, tiling, arithmetic with
constants) are kept as affine maps of the ``st`` primvar, so each lookup is filtered at its own
footprint. A ``geompropvalue`` reads the shaded gprim's primvar (its ``default`` where the
gprim has none: a constant texcoord, or value); one of another type varying over a mesh is read
per shading point (the network's ``"primvars"``). ``position`` and ``normal`` are read at the
shading point in object or world space, and the float ``noise2d``/``noise3d``/``fractal2d``/
``fractal3d`` are the stdlib's Perlin noise (``mipray::material::noise``). Any other node, a
texture coordinate that is not affine in ``st``, or an input value of the wrong type (a string
where a number goes, an image's ``file`` that is no asset) leaves the input at its default; the
stats' ``unsupported`` list names the material and the node (and the input, for a wrong type),
with one warning (:mod:`mipray.usd.unsupported`, row ``MaterialX node``).
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdShade

__all__ = [
    "EVALUATED",
    "MTLX_SURFACES",
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
#: Nodes evaluated (the node name of ``ND_<node>_<types>``); ``geompropvalue`` of a vector2 as
#: a texcoord, of another type as its primvar's (constant or mean) value.
EVALUATED = (
    "constant", "image", "tiledimage", "texcoord", "geompropvalue", "place2d", "normalmap",
    "dot", "add", "subtract", "multiply", "divide", "modulo", "power", "min", "max", "mix",
    "clamp", "invert", "absval", "floor", "ceil", "dotproduct", "normalize", "magnitude",
    "extract", "combine2", "combine3", "combine4", "convert", "checkerboard", "remap",
    "luminance", "sqrt", "ifgreater", "ifgreatereq", "ifequal", "separate2", "separate3",
    "separate4", "sin", "cos", "tan", "asin", "acos", "atan2", "sign", "exp", "ln",
    "position", "normal", "noise2d", "noise3d", "fractal2d", "fractal3d",
)  # fmt: skip
#: The geometric nodes' ``space`` (the core's argument): ``model`` is ``object``.
_SPACES = {"object": 0, "model": 0, "world": 1}
#: A nodedef's ``defaultgeomprop`` read by the core's position and normal ops.
_GEOMPROPS = {
    "Pobject": ("position", 0), "Pworld": ("position", 1),
    "Nobject": ("normal", 0), "Nworld": ("normal", 1),
}  # fmt: skip

_WRAPS = {"periodic": "repeat", "clamp": "clamp", "constant": "black", "mirror": "mirror"}
_WIDTH = {
    "float": 1, "integer": 1, "boolean": 1, "vector2": 2, "color3": 3, "vector3": 3,
    "color4": 4, "vector4": 4,
}  # fmt: skip
#: An affine map of st: s' = a·s + b·t + c, t' = d·s + e·t + f.
Affine = tuple[float, float, float, float, float, float]
_IDENTITY: Affine = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)


def _then(m: Affine, lin: tuple[float, float, float, float], t: tuple[float, float]) -> Affine:
    """``lin · m(st) + t`` (``lin`` row-major 2×2)."""
    a, b, c, d, e, f = m
    l00, l01, l10, l11 = lin
    return (
        l00 * a + l01 * d, l00 * b + l01 * e, l00 * c + l01 * f + t[0],
        l10 * a + l11 * d, l10 * b + l11 * e, l10 * c + l11 * f + t[1],
    )  # fmt: skip


@dataclass(frozen=True)
class _Tex:
    """One texture lookup under an affine map: ``texel · scale + bias`` (four lanes).

    It reads ``channels`` channels at the texcoord ``transform`` of the primvar ``varname``.
    """

    desc: dict[str, Any]
    varname: str
    scale: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    bias: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    channels: int = 3
    transform: Affine = _IDENTITY

    def affine(self, k: tuple[float, ...], c: tuple[float, ...]) -> _Tex:
        """``(texel · scale + bias) · k + c``."""
        k4, c4 = _four(k), _four(c, 0.0)
        scale = tuple(s * m for s, m in zip(self.scale, k4, strict=True))
        bias = tuple(b * m + a for b, m, a in zip(self.bias, k4, c4, strict=True))
        return replace(self, scale=scale, bias=bias)  # type: ignore[arg-type]


@dataclass(frozen=True)
class _Coord:
    """A texcoord: the primvar ``varname`` under an affine map."""

    varname: str
    transform: Affine = _IDENTITY


@dataclass(frozen=True)
class _Net:
    """``op`` (the core's op name and arguments) applied to ``args``; ``width`` lanes."""

    op: tuple[Any, ...]
    args: tuple[Any, ...]
    width: int


@dataclass(frozen=True)
class _Var:
    """Primvar ``varname`` of the mesh, varying over it, read per shading point.

    ``components`` (1–4) floats, one splatted, else the components and zeros; ``fallback``
    (four lanes) where the mesh lacks it.
    """

    varname: str
    components: int
    fallback: tuple[float, float, float, float]


_Value = tuple[float, ...] | _Tex | _Coord | _Net | _Var


class _Unsupported(Exception):
    """A node or input value the input cannot be evaluated through (already recorded)."""


def _four(v: tuple[float, ...], pad: float = 1.0) -> tuple[float, float, float, float]:
    if len(v) == 1:
        return (v[0], v[0], v[0], v[0] if pad == 1.0 else pad)
    out = [*v[:4]] + [pad] * (4 - min(len(v), 4))
    return (out[0], out[1], out[2], out[3])


def _floats(value: Any) -> tuple[float, ...] | None:
    if value is None:
        return None
    if hasattr(value, "asTuple"):  # a MaterialX Color3, Vector2, ...
        value = value.asTuple()
    if isinstance(value, str):
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


def _width(v: _Value) -> int:
    if isinstance(v, tuple):
        return len(v)
    if isinstance(v, _Tex):
        return v.channels
    if isinstance(v, _Coord):
        return 2
    if isinstance(v, _Var):
        return v.components
    return v.width


def _pow(x: float, y: float) -> float:
    try:
        return math.pow(x, y)
    except (ValueError, OverflowError):
        return math.nan


def _mod(x: float, y: float) -> float:
    return x - y * math.floor(x / y) if y else math.nan


def _divide(x: float, y: float) -> float:
    return x / y if y else (math.copysign(math.inf, x) if x else math.nan)


#: Constant folding of the lane-wise operators, as GLSL computes them.
_FOLD: dict[str, Callable[[float, float], float]] = {
    "add": lambda x, y: x + y,
    "subtract": lambda x, y: x - y,
    "multiply": lambda x, y: x * y,
    "divide": _divide,
    "modulo": _mod,
    "power": _pow,
    "min": min,
    "max": max,
}


def _domain(f: Callable[[float], float]) -> Callable[[float], float]:
    """``f``, NaN outside its domain and ±inf past overflow (as GLSL and the core give)."""

    def g(x: float) -> float:
        try:
            return float(f(x))
        except OverflowError:
            return math.inf
        except ValueError:
            return math.nan

    return g


def _ln(x: float) -> float:
    return math.log(x) if x > 0 else (-math.inf if x == 0 else math.nan)


#: The one-argument nodes, as GLSL computes them (the core's ``Op::Unary``, ``abs``, …).
_UNARY: dict[str, Callable[[float], float]] = {
    "absval": abs,
    "floor": _domain(math.floor),
    "ceil": _domain(math.ceil),
    "sin": _domain(math.sin),
    "cos": _domain(math.cos),
    "tan": _domain(math.tan),
    "asin": _domain(math.asin),
    "acos": _domain(math.acos),
    "exp": _domain(math.exp),
    "ln": _ln,
    "sign": lambda x: 1.0 if x > 0 else (-1.0 if x < 0 else 0.0),
}


def _const(a: tuple[float, ...], b: tuple[float, ...], op: str) -> tuple[float, ...]:
    n = max(len(a), len(b))
    a = a * n if len(a) == 1 else a
    b = b * n if len(b) == 1 else b
    return tuple(_FOLD[op](x, y) for x, y in zip(a, b, strict=False))


@functools.cache
def _stdlib() -> Any:
    """The MaterialX standard library's definitions (None without the package)."""
    try:
        import MaterialX as mx
    except ImportError:
        return None
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


@functools.cache
def _nodedef(node_id: str) -> tuple[dict[str, tuple[str, Any]], str] | None:
    """``node_id``'s inputs and output type, from the standard library.

    Inputs: name → (type, default value; a geomprop's name as ``geomprop:<name>``).
    """
    lib = _stdlib()
    nd = lib.getNodeDef(node_id) if lib is not None else None
    if nd is None:
        return None
    inputs: dict[str, tuple[str, Any]] = {}
    for i in nd.getActiveInputs():
        geomprop = i.getDefaultGeomPropString()
        inputs[i.getName()] = (i.getType(), f"geomprop:{geomprop}" if geomprop else i.getValue())
    outputs = nd.getActiveOutputs()
    return inputs, outputs[0].getType() if outputs else ""


@dataclass
class _Eval:
    """Evaluates the nodes feeding one material's surface."""

    material: str
    time: Usd.TimeCode
    #: The gprim being shaded (None: the material alone, as the audit reads it): a
    #: ``geompropvalue`` naming a primvar it lacks is the node's ``default``.
    prim: Usd.Prim | None = None
    #: The gprim's textures read its surface's own (u, v) for ``st`` (implicit gprims).
    surface_st: bool = False
    #: Nodes not evaluated: (node path, id).
    unsupported: list[tuple[str, str]] = field(default_factory=list)
    #: What of the gprim's own data is approximated, one line each (warned once by the caller).
    warnings: list[str] = field(default_factory=list)
    #: Each (node, output) evaluated so far (None: not evaluated), so a node read by several
    #: others is evaluated, and named, once.
    _done: dict[tuple[str, str], _Value | None] = field(default_factory=dict)
    #: The (node, output)s being evaluated: a connection back to one of them is a cycle.
    _open: set[tuple[str, str]] = field(default_factory=set)

    def input(self, shader: UsdShade.Shader, name: str) -> _Value | None:
        """``shader``'s input ``name``: a value, or None.

        None: unauthored, or fed by something not evaluated (recorded in ``unsupported``).
        """
        try:
            return self._input(shader, name)
        except _Unsupported:
            return None

    def _input(self, shader: UsdShade.Shader, name: str) -> _Value | None:
        inp = shader.GetInput(name)
        if not inp:
            return None
        for attr in inp.GetValueProducingAttributes():
            if UsdShade.Utils.GetType(attr.GetName()) == UsdShade.AttributeType.Output:
                output, _ = UsdShade.Utils.GetBaseNameAndType(attr.GetName())
                return self.output(UsdShade.Shader(attr.GetPrim()), str(output))
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
        raise _Unsupported

    def arg(self, node: UsdShade.Shader, node_id: str, name: str) -> _Value:
        """Input ``name`` of ``node``, else its nodedef's default (a texcoord's: ``st``)."""
        v = self._input(node, name)
        if v is not None:
            return v
        nd = _nodedef(node_id)
        default = nd[0].get(name, (None, None))[1] if nd else None
        if isinstance(default, str) and default.startswith("geomprop:"):
            geomprop = _GEOMPROPS.get(default.removeprefix("geomprop:"))
            return _Net(geomprop, (), 3) if geomprop else _Coord("st")
        f = _floats(default)
        if f is None:
            self._skip(node, f"{node_id} input {name} (no value and no default)")
        return f  # type: ignore[return-value]

    def const(self, node: UsdShade.Shader, node_id: str, name: str) -> tuple[float, ...]:
        v = self.arg(node, node_id, name)
        if not isinstance(v, tuple):
            self._skip(node, f"{node_id} input {name} not a constant")
        return v  # type: ignore[return-value]

    def output(self, node: UsdShade.Shader, output: str) -> _Value:
        """:meth:`node`, once per (node, output), refusing cycles."""
        key = (str(node.GetPath()), output)
        if key in self._done:
            value = self._done[key]
            if value is None:
                raise _Unsupported
            return value
        if key in self._open:
            self._skip(node, f"{node.GetShaderId() or 'no id'} in a cycle of connections")
        self._open.add(key)
        try:
            value = self.node(node, output)
        except _Unsupported:
            self._done[key] = None
            raise
        finally:
            self._open.discard(key)
        self._done[key] = value
        return value

    def node(self, node: UsdShade.Shader, output: str = "out") -> _Value:
        """The value of ``node``'s output ``output``."""
        node_id = str(node.GetShaderId() or "")
        # MaterialX 1.38's normalmap, before 1.39 split it by its scale's type.
        node_id = "ND_normalmap_float" if node_id == "ND_normalmap" else node_id
        parts = node_id.split("_")
        kind = parts[1] if node_id.startswith("ND_") and len(parts) > 2 else ""
        nd = _nodedef(node_id)
        out_type = nd[1] if nd else parts[-1]
        width = _WIDTH.get(out_type, 0)
        if kind not in EVALUATED or not width:
            self._skip(node, node_id)
        a = functools.partial(self.arg, node, node_id)
        if kind == "constant":
            return a("value")
        if kind in ("image", "tiledimage"):
            return self.image(node, node_id, width)
        if kind == "texcoord" and width == 2:
            return _Coord("st")
        if kind == "geompropvalue":
            name = node.GetInput("geomprop")
            value = name.Get(self.time) if name else None
            varname = str(value) if value else "st"
            if self.lacks(varname):
                # MaterialX: the node's `default` where the geometry has no such property (as
                # Storm renders it); a texcoord then is a constant one.
                return a("default")
            if width == 2:
                return _Coord(varname)
            return self.primvar(node, node_id, varname, width)
        if kind == "place2d":
            return self.place2d(node, node_id)
        if kind == "normalmap":
            s = _four(self.const(node, node_id, "scale"))
            # MaterialX stores normals in [0, 1]: n = (2 · texel − 1) · (scale, scale, 1)
            # (mx_normalmap_vector2), as UsdPreviewSurface's normal map with scale 2, bias −1.
            k, c = (2 * s[0], 2 * s[1], 2.0, 1.0), (-s[0], -s[1], -1.0, 0.0)
            return self.binary("add", self.binary("multiply", a("in"), k, 3), c, 3)
        if kind == "dot":
            return a("in")
        if kind in _FOLD:
            return self.binary(kind, a("in1"), a("in2"), width)
        if kind == "invert":
            return self.binary("subtract", a("amount"), a("in"), width)
        if kind == "mix":
            return self.mix(a("bg"), a("fg"), a("mix"), width)
        if kind == "clamp":
            return self.op(("clamp",), (a("in"), a("low"), a("high")), width)
        if kind in _UNARY:
            return self.op((kind,), (a("in"),), width)
        if kind == "atan2":
            # genglsl mx_atan({{iny}}, {{inx}}).
            return self.op(("atan2",), (a("iny"), a("inx")), width)
        if kind == "sqrt":
            return self.binary("power", a("in"), (0.5,), width)
        if kind == "remap":
            # outlow + (in − inlow) · (outhigh − outlow) / (inhigh − inlow), GLSL's order; an
            # image with constant bounds stays one affine lookup.
            span = self.binary("subtract", a("outhigh"), a("outlow"), width)
            v = self.binary(
                "multiply", self.binary("subtract", a("in"), a("inlow"), width), span, width
            )
            v = self.binary(
                "divide", v, self.binary("subtract", a("inhigh"), a("inlow"), width), width
            )
            return self.binary("add", a("outlow"), v, width)
        if kind == "luminance" and width == 3:
            # mx_luminance_color3: vec3(dot(in, lumacoeffs)).
            return self.op(("dotproduct", 3), (a("in"), a("lumacoeffs")), 3)
        if kind in ("ifgreater", "ifgreatereq", "ifequal"):
            return self.op((kind,), (a("value1"), a("value2"), a("in1"), a("in2")), width)
        if kind in ("dotproduct", "normalize", "magnitude"):
            n = _width(a("in1") if kind == "dotproduct" else a("in"))
            ins = (a("in1"), a("in2")) if kind == "dotproduct" else (a("in"),)
            return self.op((kind, n), ins, width)
        if kind in ("separate2", "separate3", "separate4"):
            # One float output per channel: outr/outx, outg/outy, outb/outz, outa/outw.
            v = a("in")
            index = {"r": 0, "x": 0, "g": 1, "y": 1, "b": 2, "z": 2, "a": 3, "w": 3}.get(
                output[-1:]
            )
            if index is None or not output.startswith("out") or index >= _width(v):
                self._skip(node, f"{node_id} output {output}")
            return self.extract(v, index)  # type: ignore[arg-type]
        if kind == "extract":
            index = int(self.const(node, node_id, "index")[0])
            v = a("in")
            if not 0 <= index < _width(v):
                self._skip(node, f"{node_id} index {index}")
            return self.extract(v, index)
        if kind.startswith("combine"):
            names = [f"in{i}" for i in range(1, int(kind[-1]) + 1)]
            return self.combine(tuple(a(n) for n in names))
        if kind == "convert":
            v = a("in")
            return self.convert(v, _width(v), width)
        if kind in ("position", "normal"):
            space = node.GetInput("space")
            value = space.Get(self.time) if space else None
            name = str(value) if value else "object"
            if name not in _SPACES:
                self._skip(node, f"{node_id} space {name!r}")
            return _Net((kind, _SPACES[name]), (), 3)
        if kind in ("noise2d", "noise3d", "fractal2d", "fractal3d"):
            if width != 1:
                # The vector noises hash per lane (mx_hash_vec3), which the core lacks.
                self._skip(node, node_id)
            where = a("position" if kind.endswith("3d") else "texcoord")
            if kind.startswith("noise"):
                # mx_noise3d_float: noise · amplitude + pivot.
                v = self.op((kind,), (where,), 1)
                amplitude, pivot = a("amplitude"), a("pivot")
                v = v if amplitude == (1.0,) else self.binary("multiply", v, amplitude, 1)
                return v if pivot == (0.0,) else self.binary("add", v, pivot, 1)
            octaves = int(self.const(node, node_id, "octaves")[0])
            lacunarity = self.const(node, node_id, "lacunarity")[0]
            diminish = self.const(node, node_id, "diminish")[0]
            if not 0 <= octaves <= MAX_OCTAVES:
                self._skip(node, f"{node_id} octaves {octaves} (0–{MAX_OCTAVES} are evaluated)")
            v = self.op((kind, octaves, lacunarity, diminish), (where,), 1)
            # mx_fractal3d_float: fractal noise · amplitude.
            amplitude = a("amplitude")
            return v if amplitude == (1.0,) else self.binary("multiply", v, amplitude, 1)
        if kind == "checkerboard":
            # NG_checkerboard_color3: mix(color2, color1, mod(dot(floor(uv·tiling − offset),
            # (1, 1)), 2)).
            uv = self.coord(node, node_id, a("texcoord"))
            tiling, offset = (
                self.const(node, node_id, "uvtiling"),
                self.const(node, node_id, "uvoffset"),
            )
            uv = _Coord(
                uv.varname,
                _then(uv.transform, (tiling[0], 0, 0, tiling[1]), (-offset[0], -offset[1])),
            )
            cell = self.op(("dotproduct", 2), (self.op(("floor",), (uv,), 2), (1.0, 1.0)), 1)
            mask = self.binary("modulo", cell, (2.0,), 1)
            return self.mix(a("color2"), a("color1"), mask, width)
        self._skip(node, node_id)
        raise AssertionError  # unreachable: _skip raises

    def op(self, op: tuple[Any, ...], args: tuple[_Value, ...], width: int) -> _Value:
        """``op`` of ``args``: folded when every argument is a constant."""
        if all(isinstance(x, tuple) for x in args):
            folded = _fold(op, args)  # type: ignore[arg-type]
            if folded is not None:
                return folded
        return _Net(op, args, width)

    def primvar(self, node: UsdShade.Shader, node_id: str, varname: str, width: int) -> _Value:
        """A ``geompropvalue`` of ``width`` lanes: primvar ``varname`` of the gprim, as a constant.

        Lanes as ``convert`` makes them: a one-component primvar splatted, extra components
        dropped, missing ones 0 (a fourth 1). A primvar varying over the gprim is its mean, named
        once (the evaluator reads no primvar but ``st``). Without a gprim (the audit), the
        node's ``default``.
        """
        if self.prim is None:
            return self.arg(node, node_id, "default")
        primvar = UsdGeom.PrimvarsAPI(self.prim).GetPrimvar(varname)
        try:
            values = np.asarray(primvar.ComputeFlattened(self.time), dtype=np.float64)
        except (TypeError, ValueError):
            self._skip(node, f"{node_id} of primvars:{varname} of type {primvar.GetTypeName()}")
        array = primvar.GetTypeName().isArray and values.ndim
        rows = values.reshape(len(values), -1) if array else values.reshape(1, -1)
        if not rows.size:
            return self.arg(node, node_id, "default")
        if len(rows) > 1 and not (rows == rows[0]).all():
            if self.prim.IsA(UsdGeom.Mesh) and not self.surface_st and rows.shape[1] <= 4:
                # Read per shading point, interpolated as authored (the mesh's primvar channels).
                default = _floats(self.arg(node, node_id, "default")) or (0.0,)
                fallback = _four(default, 0.0) if len(default) > 1 else (default[0],) * 4
                var = _Var(varname, rows.shape[1], fallback)
                return self.convert(var, rows.shape[1], width)
            self.warnings.append(
                f"{self.material}: {node.GetPath()} ({node_id}) reads primvars:{varname}, which "
                f"varies over {self.prim.GetPath()}; mipray uses its mean"
            )
        row = tuple(float(x) for x in rows.mean(axis=0))
        if len(row) == 1:
            return row
        return row[:width] + tuple(1.0 if k == 3 else 0.0 for k in range(len(row), width))

    def lacks(self, varname: str) -> bool:
        """Whether the gprim being shaded has no primvar ``varname`` (False when unknown)."""
        if self.prim is None or (self.surface_st and varname == "st"):
            return False
        primvar = UsdGeom.PrimvarsAPI(self.prim).GetPrimvar(varname)
        return not primvar or not primvar.HasValue()

    def coord(self, node: UsdShade.Shader, node_id: str, v: _Value) -> _Coord:
        if isinstance(v, tuple) and len(v) in (1, 2):
            # A constant texcoord (a geompropvalue's default): a map of st with no linear part.
            return _Coord("", (0.0, 0.0, v[0], 0.0, 0.0, v[-1]))
        if not isinstance(v, _Coord):
            self._skip(node, f"{node_id} texcoord that is not an affine map of a primvar")
        return v  # type: ignore[return-value]

    def image(self, node: UsdShade.Shader, node_id: str, width: int) -> _Value:
        file_inp = node.GetInput("file")
        attrs = file_inp.GetValueProducingAttributes() if file_inp else []
        value = attrs[0].Get(self.time) if attrs else None
        default = _floats(_get(node, "default", self.time)) or self.const(node, node_id, "default")
        if value is not None and not isinstance(value, Sdf.AssetPath):
            kind = attrs[0].GetTypeName()
            self.unsupported.append(
                (str(node.GetPath()), f"{node_id} input file of type {kind} (not an asset)")
            )
            return default
        if not isinstance(value, Sdf.AssetPath) or not value.path:
            return default
        from .shading import _resolve

        desc: dict[str, Any] = {
            "file": _resolve(attrs[0], value),
            "channel": 0,
            "fallback": list(_four(default, 0.0)),
        }
        space = attrs[0].GetColorSpace() if attrs[0].HasColorSpace() else ""
        if space:
            desc["sourceColorSpace"] = "sRGB" if space == "srgb_texture" else "raw"
        tiled = node_id.startswith("ND_tiledimage_")
        for key, usd_key in (("uaddressmode", "wrapS"), ("vaddressmode", "wrapT")):
            # NG_tiledimage_* reads its image with periodic address modes.
            nd = _nodedef(node_id)
            unset = nd[0].get(key, (None, "periodic"))[1] if nd else "periodic"
            mode = "periodic" if tiled else (_get(node, key, self.time) or unset)
            if mode and str(mode) in _WRAPS:
                desc[usd_key] = _WRAPS[str(mode)]
        uv = self.coord(node, node_id, self.arg(node, node_id, "texcoord"))
        transform = uv.transform
        if tiled:
            # NG_tiledimage_*: (uv · uvtiling − uvoffset) / realworldimagesize · realworldtilesize.
            tiling, offset = (
                self.const(node, node_id, "uvtiling"),
                self.const(node, node_id, "uvoffset"),
            )
            image = self.const(node, node_id, "realworldimagesize")
            tile = self.const(node, node_id, "realworldtilesize")
            if not image[0] or not image[1]:
                self._skip(node, f"{node_id} realworldimagesize 0")
            k = (tile[0] / image[0], tile[1] / image[1])
            transform = _then(
                transform,
                (tiling[0] * k[0], 0.0, 0.0, tiling[1] * k[1]),
                (-offset[0] * k[0], -offset[1] * k[1]),
            )
        return _Tex(desc, uv.varname, channels=width, transform=transform)

    def place2d(self, node: UsdShade.Shader, node_id: str) -> _Coord:
        """A ``place2d`` node's texcoord, as NG_place2d_vector2 builds it.

        SRT (``operationorder`` 0): rotate((uv − pivot) / scale) − offset + pivot; TRS (1):
        rotate(uv − pivot − offset) / scale + pivot; ``rotate`` in degrees, mx_rotate_vector2's
        (x cos + y sin, −x sin + y cos).
        """
        uv = self.coord(node, node_id, self.arg(node, node_id, "texcoord"))
        pivot, scale = self.const(node, node_id, "pivot"), self.const(node, node_id, "scale")
        offset = self.const(node, node_id, "offset")
        degrees = self.const(node, node_id, "rotate")[0]
        order = int(self.const(node, node_id, "operationorder")[0])
        if not scale[0] or not scale[1]:
            self._skip(node, f"{node_id} scale 0")
        r = math.radians(degrees)
        ca, sa = math.cos(r), math.sin(r)
        rot = (ca, sa, -sa, ca)
        inv = (1.0 / scale[0], 0.0, 0.0, 1.0 / scale[1])
        one = (1.0, 0.0, 0.0, 1.0)
        if order == 0:
            m = _then(uv.transform, one, (-pivot[0], -pivot[1]))
            m = _then(_then(m, inv, (0.0, 0.0)), rot, (pivot[0] - offset[0], pivot[1] - offset[1]))
        else:
            m = _then(uv.transform, one, (-pivot[0] - offset[0], -pivot[1] - offset[1]))
            m = _then(_then(m, rot, (0.0, 0.0)), inv, (pivot[0], pivot[1]))
        return _Coord(uv.varname, m)

    def binary(self, op: str, a: _Value, b: _Value, width: int) -> _Value:
        """``op(a, b)`` lane by lane (a float operand splatted).

        Folded into a constant, into a lookup's affine map, or into a texcoord's, where it can be.
        """
        if isinstance(a, tuple) and isinstance(b, tuple):
            return _const(a, b, op)
        affine = op in ("add", "subtract", "multiply", "divide")
        if affine and isinstance(a, _Tex) and isinstance(b, tuple):
            if op == "multiply":
                return a.affine(b, (0.0,))
            if op == "add":
                return a.affine((1.0,), b)
            if op == "subtract":
                return a.affine((1.0,), tuple(-x for x in b))
            if all(b):
                return a.affine(tuple(1.0 / x for x in b), (0.0,))
        if affine and isinstance(b, _Tex) and isinstance(a, tuple) and op != "divide":
            if op == "multiply":
                return b.affine(a, (0.0,))
            if op == "add":
                return b.affine((1.0,), a)
            return b.affine((-1.0,), a)
        if affine and isinstance(a, _Coord) and isinstance(b, tuple) and len(b) <= 2:
            v = (b[0], b[-1])
            if op == "add":
                return _Coord(a.varname, _then(a.transform, (1, 0, 0, 1), v))
            if op == "subtract":
                return _Coord(a.varname, _then(a.transform, (1, 0, 0, 1), (-v[0], -v[1])))
            if op == "multiply":
                return _Coord(a.varname, _then(a.transform, (v[0], 0, 0, v[1]), (0, 0)))
            if v[0] and v[1]:
                return _Coord(a.varname, _then(a.transform, (1 / v[0], 0, 0, 1 / v[1]), (0, 0)))
        return _Net((op,), (a, b), width)

    def mix(self, bg: _Value, fg: _Value, m: _Value, width: int) -> _Value:
        """GLSL ``mix(bg, fg, m)`` = bg · (1 − m) + fg · m."""
        if isinstance(m, tuple) and len(m) == 1:
            w = m[0]
            if isinstance(fg, tuple) and isinstance(bg, tuple):
                return _const(
                    _const(fg, (w,), "multiply"), _const(bg, (1.0 - w,), "multiply"), "add"
                )
            if isinstance(fg, _Tex) and isinstance(bg, tuple):
                return fg.affine((w,), _const(bg, (1.0 - w,), "multiply"))
            if isinstance(bg, _Tex) and isinstance(fg, tuple):
                return bg.affine((1.0 - w,), _const(fg, (w,), "multiply"))
        return self.op(("mix",), (bg, fg, m), width)

    def extract(self, v: _Value, index: int) -> _Value:
        if isinstance(v, tuple):
            return (v[index],)
        if isinstance(v, _Tex):
            # One channel of the file: its own lookup (and the fast path, on a float input).
            def splat(t: tuple[float, ...]) -> tuple[float, float, float, float]:
                return (t[index],) * 4

            desc = dict(v.desc, channel=v.desc.get("channel", 0) + index)
            desc["fallback"] = list(splat(tuple(v.desc.get("fallback", (0.0,) * 4))))
            return replace(v, desc=desc, scale=splat(v.scale), bias=splat(v.bias), channels=1)
        return _Net(("swizzle", index, index, index, index), (v,), 1)

    def combine(self, parts: tuple[_Value, ...]) -> _Value:
        if all(isinstance(p, tuple) for p in parts):
            out: tuple[float, ...] = ()
            for p in parts:
                out += p  # type: ignore[operator]
            return out
        return _Net(("combine",), parts, sum(_width(p) for p in parts))

    def convert(self, v: _Value, n_in: int, n_out: int) -> _Value:
        """NG_convert_*'s value.

        A float is splatted; otherwise the first lanes are kept, and new ones are 0 but a
        color4's or vector4's fourth, 1.
        """
        if n_in == 1 or n_in == n_out:
            return v
        pad = tuple(1.0 if k == 3 else 0.0 for k in range(n_in, n_out))
        if isinstance(v, tuple):
            return v[:n_out] + pad
        if n_out < n_in and isinstance(v, _Var):
            return v  # the lanes past the type's are not read
        if n_out < n_in:
            return (
                replace(v, channels=n_out) if isinstance(v, _Tex) else _Net(("pass",), (v,), n_out)
            )
        return _Net(("combine",), (v, pad), n_out)


def _fold(op: tuple[Any, ...], args: tuple[tuple[float, ...], ...]) -> tuple[float, ...] | None:
    """``op`` of constant ``args``, or None when it is left to the renderer."""
    name = op[0]
    if name == "mix":
        bg, fg, m = args
        return _const(
            _const(fg, m, "multiply"), _const(bg, _const((1.0,), m, "subtract"), "multiply"), "add"
        )
    if name == "clamp":
        v, lo, hi = args
        return _const(_const(v, lo, "max"), hi, "min")
    if name in _UNARY:
        return tuple(_UNARY[name](x) for x in args[0])
    if name == "atan2":
        y, x = args
        n = max(len(y), len(x))
        y, x = (v * n if len(v) == 1 else v for v in (y, x))
        return tuple(math.atan2(a, b) for a, b in zip(y, x, strict=False))
    if name in ("ifgreater", "ifgreatereq", "ifequal"):
        v1, v2, in1, in2 = args
        test = {
            "ifgreater": v1[0] > v2[0],
            "ifgreatereq": v1[0] >= v2[0],
            "ifequal": v1[0] == v2[0],
        }
        return in1 if test[name] else in2
    if name == "dotproduct":
        n = op[1]
        a, b = (_four(x, 0.0) for x in args)
        return (sum(a[k] * b[k] for k in range(n)),)
    return None


def _lower(
    v: _Value,
    ops: list[tuple[Any, ...]],
    lookups: list[dict[str, Any]],
    st: set[str],
    primvars: list[dict[str, Any]],
) -> None:
    """Appends the core's ops computing ``v``.

    Its lookups go to ``lookups``, its texcoords' primvars to ``st``, the primvars it reads as
    values to ``primvars`` (the network's ``"primvars"``).
    """
    if isinstance(v, _Var):
        names = [p["name"] for p in primvars]
        if v.varname not in names:
            entry = {"name": v.varname, "components": v.components, "fallback": list(v.fallback)}
            primvars.append(entry)
            names.append(v.varname)
        ops.append(("primvar", names.index(v.varname)))
    elif isinstance(v, tuple):
        lanes = _four(v, 0.0) if len(v) > 1 else (v[0],) * 4
        # Folded constants may be infinite (1/0) or NaN (0/0); the core takes finite numbers.
        ops.append(
            ("const", *(0.0 if math.isnan(x) else max(-3.4e38, min(3.4e38, x)) for x in lanes))
        )
    elif isinstance(v, _Tex):
        if v.varname:  # "": a constant texcoord, which reads no primvar
            st.add(v.varname)
        lookups.append(dict(v.desc, channels=v.channels, st_transform=list(v.transform)))
        ops.append(("texture", len(lookups) - 1))
        if v.scale != (1.0,) * 4:
            _lower(v.scale, ops, lookups, st, primvars)
            ops.append(("multiply",))
        if v.bias != (0.0,) * 4:
            _lower(v.bias, ops, lookups, st, primvars)
            ops.append(("add",))
    elif isinstance(v, _Coord):
        if v.varname:
            st.add(v.varname)
        ops.append(("coord", *v.transform))
    elif v.op[0] == "combine":
        _lower(v.args[0], ops, lookups, st, primvars)
        k = _width(v.args[0])
        for part in v.args[1:]:
            if k >= 4:
                break
            _lower(part, ops, lookups, st, primvars)
            ops.append(("combine", k))
            k += _width(part)
    else:
        for a in v.args:
            _lower(a, ops, lookups, st, primvars)
        if v.op[0] != "pass":
            ops.append(v.op)


#: The values the core's network evaluator holds at once (``mipray::material::network::MAX_STACK``).
MAX_STACK = 16
#: The most octaves a fractal noise sums (``mipray::material::network::MAX_OCTAVES``).
MAX_OCTAVES = 32


def _depth(v: _Value) -> int:
    """The stack values :func:`_lower`'s ops for ``v`` need at once (post-order)."""
    if isinstance(v, _Tex):
        return 2 if v.scale != (1.0,) * 4 or v.bias != (0.0,) * 4 else 1
    if not isinstance(v, _Net):
        return 1
    if v.op[0] == "combine":
        return max([_depth(v.args[0])] + [1 + _depth(p) for p in v.args[1:]])
    return max((i + _depth(a) for i, a in enumerate(v.args)), default=1)


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
    #: (input, node network as the ``material`` argument's ``networks`` entry, the primvars its
    #: lookups and texcoords read).
    networks: list[tuple[str, dict[str, Any], list[str]]] = field(default_factory=list)
    #: What of the gprim's own data is approximated (a varying primvar's mean), one line each.
    warnings: list[str] = field(default_factory=list)


def _set(
    out: MtlxRead, name: str, value: _Value | None, colour: bool, normal: bool = False
) -> None:
    if value is None or isinstance(value, _Coord):
        return
    if (
        isinstance(value, _Tex)
        and value.transform == _IDENTITY
        and (value.channels >= 3 or not (colour or normal))
    ):
        # The fast path: one UsdUVTexture-like lookup (a float input reads its first channel).
        desc = dict(value.desc)
        desc["scale"], desc["bias"] = list(value.scale), list(value.bias)
        out.textures.append((name, desc, value.varname))
        return
    if isinstance(value, _Tex | _Net | _Var):
        if _depth(value) > MAX_STACK:
            what = f"{name} network needing more than {MAX_STACK} values at once"
            out.unsupported.append((str(out.args["name"]), what))
            return
        ops: list[tuple[Any, ...]] = []
        lookups: list[dict[str, Any]] = []
        st: set[str] = set()
        primvars: list[dict[str, Any]] = []
        _lower(value, ops, lookups, st, primvars)
        net: dict[str, Any] = {"ops": ops, "lookups": lookups}
        if primvars:
            net["primvars"] = primvars
        out.networks.append((name, net, sorted(st)))
        return
    if normal:
        return
    if colour:
        v = value * 3 if len(value) == 1 else value
        out.args[name] = (v[0], v[1], v[2])
    else:
        out.args[name] = float(value[0])


def read_mtlx_surface(
    material_path: str,
    surface: UsdShade.Shader,
    time: Usd.TimeCode,
    prim: Usd.Prim | None = None,
    surface_st: bool = False,
) -> MtlxRead:
    """``surface`` (one of :data:`MTLX_SURFACES`) as UsdPreviewSurface inputs on ``prim``.

    ``prim``: the gprim shaded, whose primvars ``geompropvalue`` nodes read (None: the
    material alone); ``surface_st``: its textures read its surface's own (u, v) as ``st``.
    """
    node_id = str(surface.GetShaderId())
    ev = _Eval(material_path, time, prim, surface_st)
    out = MtlxRead({"name": material_path}, [], ev.unsupported, warnings=ev.warnings)
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
                value = ev.binary("multiply", value, w, 3 if name in colours else 1)
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
    if out.networks:
        out.args["networks"] = {name: net for name, net, _ in out.networks}
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
    elif t is not None and not isinstance(t, tuple | _Coord):
        _set(out, "opacity", ev.binary("subtract", (1.0,), t, 1), False)
    cutout = "opacity" if node_id == "ND_standard_surface_surfaceshader" else "geometry_opacity"
    c = ev.input(surface, cutout)
    if isinstance(c, tuple) and min(c) < 1.0:
        out.args["opacity"] = sum(c) / len(c)
        out.args["opacityThreshold"] = 1e-3  # MaterialX opacity is coverage: a cut-out
    elif c is not None and not isinstance(c, tuple | _Coord):
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
