"""Render statistics as a person reads them: a flat table, and the cache tiers.

The stats themselves come from the renderer as JSON (names in DESIGN.md,
"Statistics and stats JSON"); this module only lays them out for a terminal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["flatten_stats", "format_stats_table"]

_TIER_COLUMNS = (
    "name",
    "verts_per_side",
    "capacity_entries",
    "cold_tessellations",
    "lookups",
    "hits",
    "misses",
    "hit_rate",
    "recomputed_vertices",
    "peak_bytes",
)


def flatten_stats(stats: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested stats as ``{"render.wall_s": 1.2, ...}``; lists are kept whole."""
    flat: dict[str, Any] = {}
    for key, value in stats.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten_stats(value, name + "."))
        else:
            flat[name] = value
    return flat


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, int):
        return f"{value:,}"
    return str(value)


def format_stats_table(stats: Mapping[str, Any], title: str | None = None) -> str:
    """A readable table of ``stats``: one ``name  value`` line per figure.

    ``geometry_cache.tiers`` becomes a table with one row per tier, and
    ``effects.enabled`` one line per effect with why it is on.
    """
    lines: list[str] = []
    if title:
        lines.append(title)
    flat = flatten_stats(stats)
    tiers = flat.pop("geometry_cache.tiers", None)
    effects = flat.pop("effects.enabled", None)
    width = max((len(k) for k in flat), default=0)
    for key in sorted(flat):
        value = flat[key]
        text = ", ".join(_cell(v) for v in value) if isinstance(value, list) else _cell(value)
        lines.append(f"  {key:<{width}}  {text}")
    if isinstance(tiers, list) and tiers:
        columns = [c for c in _TIER_COLUMNS if any(c in t for t in tiers)]
        rows = [[_cell(t.get(c, "")) for c in columns] for t in tiers]
        widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(columns)]
        lines.append("  geometry cache tiers:")
        lines.append("    " + "  ".join(c.rjust(w) for c, w in zip(columns, widths, strict=True)))
        for row in rows:
            lines.append("    " + "  ".join(v.rjust(w) for v, w in zip(row, widths, strict=True)))
    if isinstance(effects, list) and effects:
        lines.append("  effects enabled:")
        for effect in effects:
            if isinstance(effect, Mapping):
                lines.append(f"    {effect.get('name', '?')}: {effect.get('why', '')}")
            else:
                lines.append(f"    {effect}")
    return "\n".join(lines)
