"""The renderer's settings as the compiled core states them, once (``mipray::settings``).

:data:`TABLE` is that table (``mipray._mipray.settings()``): each setting's key,
type, range or choices, default, help and scope. :func:`parse` checks a value
with the renderer's own rules, the ones the delegate applies to every render's
settings, so a ``mipray-record`` flag, ``--setting key=value``, a sweep's knob
and a ``settings=`` dict accept and refuse the same values. The package imports
without the compiled module; the table is then empty and :func:`parse` passes
values through (rendering needs the module anyway).
"""

from __future__ import annotations

from types import ModuleType
from typing import TypedDict

from .errors import RenderSettingsError

__all__ = ["TABLE", "SettingRow", "describe", "parse"]


class SettingRow(TypedDict):
    """One row of the settings table."""

    key: str
    #: ``"int"``, ``"float"``, ``"bool"`` (0 or 1), ``"choice"`` or ``"window"``
    #: (``crop``: ``"xmin,ymin,xmax,ymax"`` in NDC).
    type: str
    #: Bounds of a number (None for a choice); ``min_open``/``max_open`` exclude them.
    min: float | None
    max: float | None
    min_open: bool
    max_open: bool
    choices: list[str]
    #: None for a setting unset unless given.
    default: int | float | str | None
    #: The values it takes, in words: ``"integer, 1 ≤ x ≤ 1000000"``.
    range: str
    help: str
    #: The part of the renderer that reads it: render, geometryCache, textures, scene.
    scope: str


def _native() -> ModuleType | None:
    try:
        from . import _mipray
    except ImportError:
        return None
    return _mipray


# Bound once at import: the table is a fact of the build, like the version.
_NATIVE = _native()

#: Every setting the renderer takes, by key, in the table's order.
TABLE: dict[str, SettingRow] = (
    {row["key"]: row for row in _NATIVE.settings()} if _NATIVE is not None else {}
)


def parse(key: str, value: object) -> object:
    """``value`` (a number, or text as typed) checked as setting ``key``'s.

    Returns it as the renderer holds it: int, float or str (on/off settings
    as 0 or 1).

    Raises:
        RenderSettingsError: an unknown key (the message lists the valid
            ones), or a value the setting does not take (the message names the
            setting, the value and its range).

    """
    if _NATIVE is None:
        return value
    try:
        return _NATIVE.parse_setting(key, value)
    except ValueError as exc:
        raise RenderSettingsError(str(exc)) from exc


def describe(key: str) -> str:
    """One line on setting ``key``: what it does, what it takes, its default."""
    row = TABLE[key]
    default = "unset" if row["default"] is None else row["default"]
    return f"{row['help']} ({row['range']}; default {default})"
