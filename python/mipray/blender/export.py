"""A Blender scene to a USD file, through Blender's own USD exporter.

``bpy.ops.wm.usd_export`` writes what the depsgraph evaluates for render (modifiers applied
except a last Subdivision Surface modifier, which it keeps as the mesh's
``subdivisionScheme`` with its creases), materials as UsdPreviewSurface, lights, cameras and
the world as a dome light. Each object's Xform carries ``userProperties:blender:object_name``,
by which the render camera and the objects the exporter left out are found.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

import bpy
from pxr import Usd, UsdGeom, UsdLux

__all__ = [
    "EXPORT_OPTIONS",
    "SUN_STRENGTH_PER_INTENSITY",
    "ExportError",
    "camera_prim",
    "export_usd",
    "match_blender_lights",
    "unexported_objects",
]

#: The exporter's options. A later Blender that lacks one is told of it in the
#: ExportError rather than exporting something else silently.
EXPORT_OPTIONS: dict[str, object] = {
    # The depsgraph the final render sees (render visibility, render-level modifiers).
    "evaluation_mode": "RENDER",
    # A last Catmull-Clark Subdivision Surface modifier becomes subdivisionScheme (and its
    # creases), so mipray tessellates the limit surface itself.
    "export_subdivision": "BEST_MATCH",
    "export_materials": True,
    "generate_preview_surface": True,
    # Textures (packed and generated ones too) are written beside the layer.
    "export_textures_mode": "NEW",
    "relative_paths": True,
    "convert_world_material": True,
    "export_animation": False,
    "selected_objects_only": False,
    "author_blender_name": True,
    "export_custom_properties": True,
    "triangulate_meshes": False,
}
#: The custom property the exporter writes on each object's Xform.
OBJECT_NAME = "userProperties:blender:object_name"
#: Blender's USD exporter writes a sun of strength S (irradiance, W/m², as Cycles renders it)
#: as a DistantLight of intensity S/4, and its importer reads intensity I back as strength 4·I
#: (both measured with bpy 5.0.1). mipray reads a normalized DistantLight's intensity as the
#: irradiance, as UsdLux says, so the exported intensity is scaled back to render Blender's sun.
SUN_STRENGTH_PER_INTENSITY = 4.0
#: Blender object types that are geometry, which the render must show.
_GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD", "VOLUME"}
_GEOMETRY_TYPES |= {"GREASEPENCIL", "GPENCIL"}


class ExportError(RuntimeError):
    """Blender's USD exporter failed; the message is one line naming the file."""


def export_usd(depsgraph: Any, directory: str) -> str:
    """Export ``depsgraph``'s scene and view layer to ``directory``/scene.usdc; its path.

    Raises:
        ExportError: the exporter lacks an option mipray needs, or failed.

    """
    operator = bpy.ops.wm.usd_export
    known = set(operator.get_rna_type().properties.keys())
    missing = sorted(set(EXPORT_OPTIONS) - known)
    if missing:
        raise ExportError(
            f"Blender {bpy.app.version_string}'s USD exporter has no option {', '.join(missing)}"
        )
    path = os.path.join(directory, "scene.usdc")
    try:
        with bpy.context.temp_override(scene=depsgraph.scene, view_layer=depsgraph.view_layer):
            outcome = operator(filepath=path, **EXPORT_OPTIONS)
    except (RuntimeError, TypeError, ValueError) as exc:
        # RuntimeError: the exporter reported an error; TypeError / ValueError: it refused an
        # option's value.
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else "failed"
        raise ExportError(f"USD export to {path} failed: {reason}") from exc
    if "FINISHED" not in outcome or not os.path.exists(path):
        raise ExportError(f"USD export to {path} failed ({', '.join(sorted(outcome))})")
    return path


def match_blender_lights(stage: Usd.Stage, depsgraph: Any) -> None:
    """Make the exported lights mean what they mean in Blender, in ``stage``'s session layer.

    A DistantLight's intensity is scaled by :data:`SUN_STRENGTH_PER_INTENSITY`; and the
    exporter turns ``enableColorTemperature`` on for every light, while Blender (and Cycles)
    tint a light only with its Use Temperature switch on, so it is set from that switch.
    """
    lights = {obj.name: obj.data for obj in depsgraph.objects if obj.type == "LIGHT" and obj.data}
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        for name, prim in _exported_objects(stage):
            data = lights.get(name)
            if data is None:
                continue
            for child in Usd.PrimRange(prim):
                if not child.HasAPI(UsdLux.LightAPI):
                    continue
                api = UsdLux.LightAPI(child)
                if child.IsA(UsdLux.DistantLight):
                    intensity = api.GetIntensityAttr().Get()
                    api.GetIntensityAttr().Set(float(intensity) * SUN_STRENGTH_PER_INTENSITY)
                api.CreateEnableColorTemperatureAttr().Set(
                    bool(getattr(data, "use_temperature", False))
                )


def _exported_objects(stage: Usd.Stage) -> Iterator[tuple[str, Usd.Prim]]:
    for prim in stage.Traverse():
        attr = prim.GetAttribute(OBJECT_NAME)
        if attr and attr.HasAuthoredValue():
            yield str(attr.Get()), prim


def _named_ancestors(prim: Usd.Prim) -> list[Usd.Prim]:
    """``prim``'s ancestors (and itself) that carry a Blender object name, nearest first."""
    named = []
    while prim and not prim.IsPseudoRoot():
        attr = prim.GetAttribute(OBJECT_NAME)
        if attr and attr.HasAuthoredValue():
            named.append(prim)
        prim = prim.GetParent()
    return named


def camera_prim(stage: Usd.Stage, camera_object: Any) -> str | None:
    """Path of the UsdGeom.Camera the exporter made of Blender's ``camera_object``."""
    if camera_object is None:
        return None
    for name, prim in _exported_objects(stage):
        if name != camera_object.name:
            continue
        for child in Usd.PrimRange(prim):
            if child.IsA(UsdGeom.Camera):
                return str(child.GetPath())
    return None


def unexported_objects(depsgraph: Any, stage: Usd.Stage) -> list[str]:
    """One line per geometry object of ``depsgraph`` that the render will lack.

    mipray renders meshes (subdivision surfaces among them); a volume, a grease pencil, or an
    object the exporter dropped is named with its type, so the report can say what is missing.
    Instances made by geometry nodes are checked too: Blender 5.0's exporter writes an instance
    whose Object Info node lacks *As Instance* (or whose geometry it cannot express) as an empty
    Mesh, which would render as nothing without a word; such meshes are counted per object.
    """
    with_mesh = set()
    empty: dict[str, int] = {}
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        owners = [str(a.GetAttribute(OBJECT_NAME).Get()) for a in _named_ancestors(prim)]
        if not owners:
            continue
        counts = UsdGeom.Mesh(prim).GetFaceVertexCountsAttr().Get()
        if len(owners) > 1 and counts is not None and len(counts) == 0:
            # An instance (an object's Xform under another's) that came out empty; counted on
            # the object that instances it.
            empty[owners[-1]] = empty.get(owners[-1], 0) + 1
        else:
            with_mesh.add(owners[0])
    lines = set()
    for instance in depsgraph.object_instances:
        if instance.is_instance:
            continue
        obj = instance.object
        if obj.type in _GEOMETRY_TYPES and obj.name not in with_mesh | set(empty):
            lines.add(f"object '{obj.name}' ({obj.type.lower()}): no mesh in the USD export")
    for name, count in empty.items():
        what = "instance" if count == 1 else "instances"
        lines.add(
            f"object '{name}': {count} geometry-node {what} came out of the USD export empty "
            "(an Object Info node without 'As Instance', or geometry the exporter cannot write)"
        )
    return sorted(lines)
