"""Blender properties generated from mipray's tables, never copied by hand.

:func:`settings_properties` turns each row of the settings table
(:data:`mipray.settings.TABLE`) into a ``bpy.props`` property with the row's type, range,
choices, default and help; they live on ``scene.mipray`` and are saved in the .blend.
:func:`pass_properties` gives each AOV that can be a pass (:mod:`.passes`) an on/off switch on
``view_layer.mipray``. This module only describes the properties (``make_property`` takes the
``bpy.props`` module), so it is tested without Blender.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from .. import settings as _settings
from .passes import blender_passes

__all__ = [
    "ENGINE_SETTINGS",
    "SCOPE_LABELS",
    "PropertySpec",
    "make_property",
    "pass_properties",
    "render_settings",
    "settings_properties",
]

#: Settings the engine sets itself, with why; the panel does not show them.
ENGINE_SETTINGS = {
    "progressive": "always on: Blender shows each pass as it comes",
}
#: Panel headings of the table's scopes.
SCOPE_LABELS = {
    "render": "Sampling and integrator",
    "geometryCache": "Geometry cache",
    "textures": "Textures",
    "scene": "Scene",
}
#: Blender's IntProperty is a signed 32-bit integer.
_INT_MAX = 2**31 - 1
#: Prefix of the switch that turns an optional setting (one unset unless given) on.
USE_PREFIX = "use_"


@dataclass(frozen=True)
class PropertySpec:
    """One Blender property: the ``bpy.props`` function's name and its keyword arguments."""

    name: str
    function: str
    kwargs: dict[str, Any]


def _number_kwargs(row: _settings.SettingRow, integer: bool) -> dict[str, Any]:
    low, high = row["min"], row["max"]
    kwargs: dict[str, Any] = {}
    if integer:
        kwargs["min"] = int(low if low is not None else 0)
        kwargs["max"] = int(min(high if high is not None else _INT_MAX, _INT_MAX))
        return kwargs
    # Open ends cannot be said in Blender; the renderer refuses such a value with its own
    # one-line message, which the engine reports.
    if low is not None and math.isfinite(low):
        kwargs["min"] = float(low)
    if high is not None and math.isfinite(high):
        kwargs["max"] = float(high)
    return kwargs


def settings_properties(
    table: Mapping[str, _settings.SettingRow] | None = None,
) -> list[PropertySpec]:
    """A property per setting of ``table`` (default: the renderer's), in its order.

    An optional setting (default None) gets its value property and a ``use_<key>`` switch;
    an infinite default (``aoDistance``) is held as Blender's largest float.
    """
    specs = []
    for key, row in (table if table is not None else _settings.TABLE).items():
        if key in ENGINE_SETTINGS:
            continue
        description = f"{row['help']} ({row['range']})"
        kwargs: dict[str, Any] = {"name": key, "description": description}
        default = row["default"]
        kind = row["type"]
        if kind == "choice":
            kwargs["items"] = [(c, c, "") for c in row["choices"]]
            if default is not None:
                kwargs["default"] = str(default)
            specs.append(PropertySpec(key, "EnumProperty", kwargs))
        elif kind == "bool":
            kwargs["default"] = bool(default)
            specs.append(PropertySpec(key, "BoolProperty", kwargs))
        elif kind == "window":
            # A window of the frame (xmin, ymin, xmax, ymax in NDC): four floats in [0, 1].
            kwargs.update(size=4, min=0.0, max=1.0)
            if default is not None:
                kwargs["default"] = tuple(float(x) for x in str(default).split(","))
            specs.append(PropertySpec(key, "FloatVectorProperty", kwargs))
        else:
            integer = kind == "int"
            kwargs.update(_number_kwargs(row, integer))
            if default is not None:
                value = float(default)
                kwargs["default"] = int(min(value, _INT_MAX)) if integer else min(value, 3.0e38)
            specs.append(PropertySpec(key, "IntProperty" if integer else "FloatProperty", kwargs))
        if default is None:
            specs.append(
                PropertySpec(
                    USE_PREFIX + key,
                    "BoolProperty",
                    {"name": f"Set {key}", "description": f"set {key}; else it is left unset"},
                )
            )
    return specs


def pass_properties() -> list[PropertySpec]:
    """A switch per AOV that can be a Blender pass (:func:`.passes.blender_passes`)."""
    return [
        PropertySpec(
            p.aov,
            "BoolProperty",
            {"name": p.name, "description": f"{p.aov}: {p.meaning}", "default": False},
        )
        for p in blender_passes()
    ]


def make_property(props: ModuleType, spec: PropertySpec) -> Any:
    """``spec`` made with ``props`` (``bpy.props``)."""
    return getattr(props, spec.function)(**spec.kwargs)


def render_settings(values: Any) -> dict[str, object]:
    """The renderer's settings from a property group made by :func:`settings_properties`.

    Optional settings whose switch is off are left out; a float at Blender's largest value
    (an infinite default) is sent as the text ``"inf"``, the table's spelling of it.
    """
    chosen: dict[str, object] = {}
    for key, row in _settings.TABLE.items():
        if key in ENGINE_SETTINGS:
            continue
        if row["default"] is None and not getattr(values, USE_PREFIX + key):
            continue
        value = getattr(values, key)
        if row["type"] == "bool":
            value = int(bool(value))
        elif row["type"] == "float" and value >= 3.0e38:
            value = "inf"
        elif row["type"] == "window":
            value = ",".join(f"{float(x):.9g}" for x in value)
        chosen[key] = value
    return chosen
