"""The renderer's AOVs as the compiled core states them, once (``mipray::aov``).

:data:`TABLE` maps each AOV's name to its row (``mipray._mipray.aovs()``):
channels, meaning, whether a pixel averages its samples, clear value, file
channel names and EXR pixel type. RenderVar source names come from it (the image writer reads
the pixel types in Rust). The package imports without the compiled
module; the table is then empty (rendering needs the module anyway).
"""

from __future__ import annotations

from typing import TypedDict, cast

__all__ = ["TABLE", "AovRow"]


class AovRow(TypedDict):
    """One AOV."""

    name: str
    channels: int
    #: What it holds, its units and its space.
    meaning: str
    #: Averaged over a pixel's samples (else the pixel centre's value).
    averaged: bool
    #: A pixel's value where nothing renders.
    clear: float
    file_channels: list[str]
    #: ``"half"`` or ``"float"``: the pixel type in an EXR.
    format: str


def _rows() -> list[AovRow]:
    try:
        from . import _mipray
    except ImportError:
        return []
    return cast("list[AovRow]", _mipray.aovs())


#: Every AOV the renderer produces, by name, in the table's order.
TABLE: dict[str, AovRow] = {row["name"]: row for row in _rows()}
