"""mipray as a Blender render engine (Blender 4.2 and later; tested with ``bpy`` 5.0).

``register()`` adds the ``MIPRAY`` engine, its settings on ``scene.mipray`` (generated from
the renderer's settings table, saved in the .blend), its pass switches on
``view_layer.mipray`` (generated from the AOV table) and their panels in the Render and View
Layer properties. Blender installs it from the zip ``make blender-addon`` writes, whose
``__init__.py`` (``bl_addon.py``) calls these. Viewport rendering (``view_update`` /
``view_draw``) is not implemented: the viewport's Rendered mode shows nothing with mipray.
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from .. import settings as _settings
from .engine import MiprayRenderEngine
from .passes import blender_passes
from .properties import (
    SCOPE_LABELS,
    USE_PREFIX,
    make_property,
    pass_properties,
    settings_properties,
)

__all__ = ["register", "unregister"]


def _update_passes(_group: Any, context: Any) -> None:
    """A pass switched on or off: the compositor's Render Layers node follows."""
    context.view_layer.update_render_passes()


def _group(name: str, specs: list[Any], update: Any = None) -> type:
    annotations = {}
    for spec in specs:
        if update is not None:
            spec.kwargs["update"] = update
        annotations[spec.name] = make_property(bpy.props, spec)
    return type(name, (bpy.types.PropertyGroup,), {"__annotations__": annotations})


class _PropertiesPanel:
    """What mipray's panels share: the Properties editor, shown while mipray renders."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES: ClassVar[set[str]] = {MiprayRenderEngine.bl_idname}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return bool(context.engine in cls.COMPAT_ENGINES)


class RENDER_PT_mipray(_PropertiesPanel, bpy.types.Panel):  # type: ignore[misc]  # no stubs
    """mipray's settings, a box per part of the renderer that reads them."""

    bl_label = "mipray"
    bl_context = "render"

    def draw(self, context: Any) -> None:
        layout = self.layout
        layout.use_property_split = True
        values = context.scene.mipray
        for scope, label in SCOPE_LABELS.items():
            keys = [
                s.name
                for s in settings_properties()
                if s.name in _settings.TABLE and _settings.TABLE[s.name]["scope"] == scope
            ]
            if not keys:
                continue
            box = layout.box()
            box.label(text=label)
            for key in keys:
                if hasattr(values, USE_PREFIX + key):
                    row = box.row(heading=key)
                    row.prop(values, USE_PREFIX + key, text="")
                    sub = row.row()
                    sub.active = getattr(values, USE_PREFIX + key)
                    sub.prop(values, key, text="")
                else:
                    box.prop(values, key)


class VIEWLAYER_PT_mipray_passes(_PropertiesPanel, bpy.types.Panel):  # type: ignore[misc]
    """mipray's AOVs as passes of this view layer."""

    bl_label = "mipray passes"
    bl_context = "view_layer"

    def draw(self, context: Any) -> None:
        layout = self.layout
        layout.use_property_split = True
        switches = context.view_layer.mipray
        for p in blender_passes():
            layout.prop(switches, p.aov, text=f"{p.name} ({p.aov})" if p.name != p.aov else p.name)


_classes: list[type] = []


def register() -> None:
    """Add the engine, its properties and its panels to Blender."""
    settings_group = _group("MiprayRenderSettings", settings_properties())
    passes_group = _group("MiprayPasses", pass_properties(), update=_update_passes)
    _classes[:] = [
        settings_group,
        passes_group,
        MiprayRenderEngine,
        RENDER_PT_mipray,
        VIEWLAYER_PT_mipray_passes,
    ]
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.mipray = bpy.props.PointerProperty(type=settings_group)
    bpy.types.ViewLayer.mipray = bpy.props.PointerProperty(type=passes_group)


def unregister() -> None:
    """Remove what :func:`register` added."""
    del bpy.types.ViewLayer.mipray
    del bpy.types.Scene.mipray
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
    _classes.clear()
