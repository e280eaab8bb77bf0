"""``.mtlx`` documents referenced from USD, read with the MaterialX package.

usd-core ships no ``usdMtlx`` file-format plugin, so a reference such as
``references = @./looks.mtlx@</MaterialX/Materials/Wood>`` fails to compose (a composition
error) and the material comes out empty. :func:`load_mtlx_references` reads each such
document with MaterialX (the ``MaterialX`` PyPI package) and writes what ``usdMtlx`` would
have composed there — a Shader prim per node (``info:id`` its nodedef), their inputs and
connections, ``outputs:mtlx:surface`` — into an anonymous layer under the stage's session
layer, so the rest of the front end reads it as any inline MaterialX network
(:mod:`mipray.usd.materialx`). Custom nodedefs (the document's, its includes', or those of
the folders in ``PXR_MTLX_PLUGIN_SEARCH_PATHS``, as usdMtlx finds them) implemented by a
nodegraph are flattened into that graph's standard-library nodes. A document that cannot be
read is warned about once, naming the prim and the file; the material then renders as if
unbound.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from typing import Any

from pxr import Gf, Sdf, Usd

__all__ = ["LOADED", "load_mtlx_references"]

_log = logging.getLogger(__name__)

#: MaterialX types → USD value types (what usdMtlx uses).
_TYPES = {
    "float": Sdf.ValueTypeNames.Float,
    "integer": Sdf.ValueTypeNames.Int,
    "boolean": Sdf.ValueTypeNames.Bool,
    "color3": Sdf.ValueTypeNames.Color3f,
    "color4": Sdf.ValueTypeNames.Color4f,
    "vector2": Sdf.ValueTypeNames.Float2,
    "vector3": Sdf.ValueTypeNames.Float3,
    "vector4": Sdf.ValueTypeNames.Float4,
    "string": Sdf.ValueTypeNames.String,
    "filename": Sdf.ValueTypeNames.Asset,
}


def _mtlx_references(prim: Usd.Prim) -> list[tuple[str, str, str, bool]]:
    """The .mtlx references of ``prim``: (document, material name, its directory, nested).

    ``nested``: the whole document composes under ``<prim>/Materials``.
    """
    found = []
    for spec in prim.GetPrimStack():
        items = spec.referenceList.GetAddedOrExplicitItems()
        for ref in items:
            path = str(ref.assetPath)
            if path.lower().endswith(".mtlx"):
                anchor = spec.layer.ComputeAbsolutePath(path) if spec.layer else path
                if not os.path.isfile(anchor):
                    continue  # usd-core's composition error already names the missing file
                # </MaterialX/Materials/Wood> names one material; </MaterialX/Materials> the
                # document's materials, composed as <prim>'s children; </MaterialX> (or no path)
                # the whole document, its materials under <prim>/Materials: usdMtlx's layout.
                target = ref.primPath
                depth = target.pathElementCount
                name = target.name if depth >= 3 else ""
                found.append((anchor, name, os.path.dirname(anchor), depth <= 1))
    return found


def _value(mx: Any, value: Any, kind: str, folder: str) -> Any:
    if kind in ("color3", "vector3"):
        return Gf.Vec3f(*value.asTuple())
    if kind in ("color4", "vector4"):
        return Gf.Vec4f(*value.asTuple())
    if kind == "vector2":
        return Gf.Vec2f(*value.asTuple())
    if kind == "filename":
        text = str(value)
        return Sdf.AssetPath(text if os.path.isabs(text) else os.path.join(folder, text))
    del mx
    return value


#: How deep custom nodes may nest in their implementations (a nodedef implemented by itself).
_MAX_NESTING = 32


@dataclass(frozen=True)
class _Call:
    """A custom node expanded into its implementation graph.

    The graph's ``interfacename`` inputs read ``node``'s inputs, which belong to the graph
    ``prefix`` names (itself inside ``outer``).
    """

    node: Any
    nodedef: Any
    prefix: str
    outer: _Call | None
    depth: int


def _translate(
    mx: Any,
    doc: Any,
    name: str,
    folder: str,
    layer: Sdf.Layer,
    at: Sdf.Path,
    *,
    define: bool,
    stdlib: Any = None,
) -> None:
    """Author material ``name`` of ``doc`` at ``at`` in ``layer`` (see the module doc).

    A node whose nodedef is not the standard library's (``stdlib``) and is implemented by a
    nodegraph is replaced by that graph (MaterialX's ``flattenSubgraphs``, done here so a
    namespaced node's connections survive): its nodes are authored as
    ``<node>_<graph node>``, the graph's ``interfacename`` inputs read the node's own inputs
    (else the nodedef's defaults).
    """
    material = doc.getChild(name)
    if material is None or material.getCategory() != "surfacematerial":
        raise ValueError(f"it has no surfacematerial named {name}")
    root = Sdf.CreatePrimInLayer(layer, at)
    root.specifier = Sdf.SpecifierDef if define else Sdf.SpecifierOver
    if define:
        root.typeName = "Material"
    done: dict[str, Sdf.Path] = {}

    def implementation(node: Any) -> tuple[Any, Any] | None:
        """(nodedef, implementation graph) of a custom node built as a nodegraph."""
        nodedef = node.getNodeDef()
        if nodedef is None or stdlib is None or stdlib.getNodeDef(nodedef.getName()) is not None:
            return None
        graph = nodedef.getImplementation()
        return (nodedef, graph) if isinstance(graph, mx.NodeGraph) else None

    def shader(node: Any, prefix: str, call: _Call | None, output: str = "") -> Sdf.Path:
        custom = implementation(node)
        depth = call.depth + 1 if call else 1
        if custom is not None and depth <= _MAX_NESTING:
            # Expanded, unless nested deeper (a nodedef implemented by itself) or the graph's
            # output is no node's: then the node stays, warned about by its nodedef's name.
            nodedef, graph = custom
            out = graph.getOutput(output) if output else None
            out = out or (graph.getOutputs() or [None])[0]
            upstream = out.getConnectedNode() if out is not None else None
            if upstream is not None:
                inner = _Call(node, nodedef, prefix, call, depth)
                return shader(upstream, f"{prefix}{node.getName()}_", inner)
        key = prefix + node.getName()
        if key in done:
            return done[key]
        path = at.AppendChild(key)
        done[key] = path
        spec = Sdf.CreatePrimInLayer(layer, path)
        spec.specifier = Sdf.SpecifierDef
        spec.typeName = "Shader"
        nodedef = node.getNodeDef()
        node_id = nodedef.getName() if nodedef is not None else f"ND_{node.getCategory()}"
        attr = Sdf.AttributeSpec(spec, "info:id", Sdf.ValueTypeNames.Token, Sdf.VariabilityUniform)
        attr.default = node_id
        out_type = _TYPES.get(node.getType(), Sdf.ValueTypeNames.Token)
        Sdf.AttributeSpec(spec, "outputs:out", out_type)
        for inp in node.getInputs():
            kind = inp.getType()
            a = Sdf.AttributeSpec(
                spec, f"inputs:{inp.getName()}", _TYPES.get(kind, Sdf.ValueTypeNames.Token)
            )
            author(a, inp, kind, prefix, call)
        return path

    def author(a: Sdf.AttributeSpec, inp: Any, kind: str, prefix: str, call: _Call | None) -> None:
        """``inp``'s connection or value on ``a``."""
        space = inp.getColorSpace()
        iface = inp.getInterfaceName()
        if iface and call is not None:
            # An implementation graph's interface input: the custom node's own input, else the
            # nodedef's default; the graph's colour space unless the node's input has its own.
            outer = call.node.getInput(iface)
            if outer is not None:
                if space and not outer.getColorSpace():
                    a.SetInfo("colorSpace", space)
                author(a, outer, kind, call.prefix, call.outer)
                return
            inp = call.nodedef.getActiveInput(iface) or inp
            space = space or inp.getColorSpace()
        upstream = inp.getConnectedNode()
        graph_name = inp.getNodeGraphString()
        if upstream is None and graph_name:
            graph = doc.getNodeGraph(graph_name)
            out = graph.getOutput(inp.getOutputString() or "out") if graph else None
            upstream = out.getConnectedNode() if out is not None else None
            if upstream is not None:
                source = shader(upstream, graph_name + "_", None)
                a.connectionPathList.Append(source.AppendProperty("outputs:out"))
                return
        if upstream is not None:
            source = shader(upstream, prefix, call, inp.getOutputString())
            a.connectionPathList.Append(source.AppendProperty("outputs:out"))
            return
        value = inp.getResolvedValueString() if kind == "filename" else inp.getValue()
        if value is not None:
            a.default = _value(mx, value, kind, folder)
        if space:
            a.SetInfo("colorSpace", space)

    surface_input = material.getInput("surfaceshader")
    surface = surface_input.getConnectedNode() if surface_input is not None else None
    if surface is None:
        raise ValueError(f"material {name} has no surfaceshader")
    out = Sdf.AttributeSpec(root, "outputs:mtlx:surface", Sdf.ValueTypeNames.Token)
    out.connectionPathList.Append(shader(surface, "", None).AppendProperty("outputs:out"))


def load_mtlx_references(stage: Usd.Stage) -> list[tuple[str, str]]:
    """Compose the stage's ``.mtlx`` references (see the module doc).

    Returns the (prim, problem) of each that could not be read (also warned about once).
    """
    mentioned = any(
        str(path).lower().endswith(".mtlx")
        for layer in stage.GetUsedLayers()
        for path in layer.GetExternalReferences()
    )
    if not mentioned:  # the common case: no prim walk at all
        return []
    targets = [(prim, refs) for prim in stage.TraverseAll() if (refs := _mtlx_references(prim))]
    if not targets:
        return []
    problems: list[tuple[str, str]] = []
    try:
        import MaterialX as mx
    except ImportError:
        for prim, refs in targets:
            problems.append(
                (str(prim.GetPath()), f"{refs[0][0]}: the MaterialX package is not installed")
            )
        for prim_path, problem in problems:
            _log.warning("mipray: %s: cannot read %s", prim_path, problem)
        return problems
    layer = Sdf.Layer.CreateAnonymous("mipray-mtlx.usda")
    docs: dict[str, Any] = {}
    stdlib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), stdlib)
    for prim, refs in targets:
        for file, name, folder, nested in refs:
            try:
                if file not in docs:
                    doc = mx.createDocument()
                    mx.readFromXmlFile(doc, file)
                    for custom in _plugin_documents(mx):
                        doc.importLibrary(custom)
                    doc.importLibrary(stdlib)
                    docs[file] = doc
                doc = docs[file]
                if name:
                    _translate(
                        mx, doc, name, folder, layer, prim.GetPath(), define=False, stdlib=stdlib
                    )
                elif nested:
                    scope = Sdf.CreatePrimInLayer(layer, prim.GetPath().AppendChild("Materials"))
                    scope.specifier, scope.typeName = Sdf.SpecifierDef, "Scope"
                else:
                    scope = Sdf.CreatePrimInLayer(layer, prim.GetPath())
                if not name:
                    for node in doc.getMaterialNodes():
                        at = scope.path.AppendChild(node.getName())
                        _translate(
                            mx, doc, node.getName(), folder, layer, at, define=True, stdlib=stdlib
                        )
                LOADED.add(file)
            except Exception as exc:
                text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                problems.append((str(prim.GetPath()), f"{file}: {text}"))
    if len(layer.rootPrims):
        stage.GetSessionLayer().subLayerPaths.append(layer.identifier)
        # The session layer holds it only by identifier: keep the layer alive with the stage.
        _keep_alive.setdefault(id(stage), []).append(layer)
    for prim_path, problem in problems:
        _log.warning("mipray: %s: cannot read MaterialX document %s", prim_path, problem)
    return problems


def _plugin_documents(mx: Any) -> list[Any]:
    """The ``.mtlx`` files of the folders in ``PXR_MTLX_PLUGIN_SEARCH_PATHS``.

    usdMtlx (and so Storm) finds custom nodedefs there; one that cannot be read is warned about
    once.
    """
    docs = []
    for folder in os.environ.get("PXR_MTLX_PLUGIN_SEARCH_PATHS", "").split(os.pathsep):
        if not folder or not os.path.isdir(folder):
            continue
        for base, _, files in sorted(os.walk(folder)):
            for f in sorted(files):
                if not f.lower().endswith(".mtlx"):
                    continue
                path = os.path.join(base, f)
                doc = mx.createDocument()
                try:
                    mx.readFromXmlFile(doc, path)
                except Exception as exc:
                    if path not in _UNREADABLE:
                        _UNREADABLE.add(path)
                        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                        _log.warning(
                            "mipray: PXR_MTLX_PLUGIN_SEARCH_PATHS: cannot read %s: %s", path, text
                        )
                    continue
                docs.append(doc)
    return docs


_UNREADABLE: set[str] = set()
_keep_alive: dict[int, list[Sdf.Layer]] = {}
#: The .mtlx documents composed here: usd-core's composition errors about them are not news.
LOADED: set[str] = set()
