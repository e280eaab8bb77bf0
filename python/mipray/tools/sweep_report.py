"""The figures and the tables of an accuracy-versus-time sweep (:mod:`mipray.tools.sweep`).

Three things live here, apart from the rendering:

* :func:`image_errors` and :func:`tess_error_figures`: the error figures of one
  rendered row against the reference image, and of its ``tessError`` AOV;
* :func:`pareto_front`: the rows no other row beats in both time and error;
* :func:`write_tables` and :func:`write_plot`: the JSON and Markdown tables
  (rewritten after every row, so an interrupted sweep keeps what it finished)
  and the PNG of error against time.

The JSON table (``schema`` :data:`SCHEMA`) is the stable form; the Markdown
table is the same rows for a person. Column meanings are in
:data:`ROW_FIELDS`.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "ROW_FIELDS",
    "SCHEMA",
    "format_markdown",
    "image_errors",
    "pareto_front",
    "setting_label",
    "tess_error_figures",
    "write_plot",
    "write_tables",
]

#: Version tag of the JSON table; bumped when a field changes meaning.
SCHEMA = "mipray-sweep/1"

#: Every field of a row in the JSON table, with its meaning and unit.
ROW_FIELDS: dict[str, str] = {
    "label": "the row's knob values as text, e.g. 'tessFactor=2, samples=4'",
    "setting": "the row's knob values (knob name → value)",
    "settings": "every render setting the row was rendered with (knobs and --set)",
    "wall_s": "median of the runs' render.wall_s, seconds (rendering only, not scene sync)",
    "wall_s_runs": "render.wall_s of each run, seconds",
    "cpu_s": "median of the runs' CPU seconds (all threads) in the render call: less "
    "sensitive than wall time to other work on a shared machine",
    "cpu_s_runs": "CPU seconds of each run",
    "peak_rss_bytes": "memory.peak_rss_bytes of the row's own process (Python and USD included)",
    "recomputed_vertices": "geometry_cache.recomputed_vertices: vertices tessellated again "
    "after eviction (the cache's cost)",
    "ray_subpatch_tests": "render.ray_subpatch_tests",
    "hemisphere_rays": "render.rays.ao + render.rays.diffuse: the hemisphere integrals' rays "
    "(irradiance caching's pre-pass included), what irradiance caching saves",
    "texture_tiles_read": "texture_cache.tiles_read: tiles OpenImageIO read from texture files "
    "(None without textures)",
    "color_rmse": "root mean square of (color - reference color) over every pixel and channel",
    "color_max_abs": "largest |color - reference color| over every pixel and channel",
    "color_mean_diff": "mean of (color - reference color): below 0, the row is darker on the "
    "whole (a systematic bias, where noise averages out)",
    "tess_error_mean": "mean of tessError channel 0 over pixels with alpha > 0: world-space "
    "distance along the camera ray from the tessellation hit to the exact limit surface",
    "tess_error_max": "largest tessError channel 0, world units",
    "tess_error_rel_mean": "mean of tessError channel 1 (channel 0 over the ray's beam width) "
    "over pixels with alpha > 0",
    "tess_error_rel_max": "largest tessError channel 1, beam widths",
    "pareto": "no other row has both a smaller wall_s and a smaller color_rmse",
}

# Markdown columns: (header, field, format).
_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("setting", "label", "s"),
    ("wall s", "wall_s", ".3g"),
    ("CPU s", "cpu_s", ".3g"),
    ("peak MB", "peak_rss_bytes", "mb"),
    ("recomputed verts", "recomputed_vertices", ",d"),
    ("RMSE", "color_rmse", ".3g"),
    ("max abs", "color_max_abs", ".3g"),
    ("mean diff", "color_mean_diff", "+.2g"),
    ("tessErr mean", "tess_error_mean", ".2e"),
    ("tessErr max", "tess_error_max", ".2e"),
    ("tessErr/beam mean", "tess_error_rel_mean", ".3g"),
    ("tessErr/beam max", "tess_error_rel_max", ".3g"),
    ("Pareto", "pareto", "mark"),
)


def setting_label(setting: Mapping[str, object]) -> str:
    """``'tessFactor=2, samples=4'``: a row's knob values, in knob order."""
    return ", ".join(f"{k}={_value_text(v)}" for k, v in setting.items()) or "(base settings)"


def _value_text(value: object) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def image_errors(color: NDArray[np.float32], reference: NDArray[np.float32]) -> dict[str, float]:
    """RMSE, largest absolute and mean difference of ``color`` against ``reference``.

    Both are H×W×C arrays of the same shape (the caller checks sizes, so the
    message can name the files). Non-finite differences count as the largest
    finite value the float type holds, so a NaN never hides as a small error.
    """
    diff = color.astype(np.float64) - reference.astype(np.float64)
    big = float(np.finfo(np.float32).max)
    diff = np.nan_to_num(diff, nan=big, posinf=big, neginf=-big)
    if diff.size == 0:
        return {"color_rmse": 0.0, "color_max_abs": 0.0, "color_mean_diff": 0.0}
    return {
        "color_rmse": float(np.sqrt(np.mean(diff * diff))),
        "color_max_abs": float(np.max(np.abs(diff))),
        "color_mean_diff": float(np.mean(diff)),
    }


def tess_error_figures(
    tess_error: NDArray[np.float32], alpha: NDArray[np.float32] | None = None
) -> dict[str, float]:
    """Mean and max of both ``tessError`` channels over the pixels that hit something.

    Args:
        tess_error: H×W×2: world distance, and that over the beam width.
        alpha: H×W×1 coverage; pixels with alpha 0 (nothing hit) are left
            out of the means. Without it every pixel counts.

    """
    err = np.nan_to_num(tess_error.astype(np.float64), nan=0.0, posinf=0.0)
    mask = np.ones(err.shape[:2], dtype=bool) if alpha is None else alpha[..., 0] > 0.0
    if not mask.any():
        return dict.fromkeys(
            ("tess_error_mean", "tess_error_max", "tess_error_rel_mean", "tess_error_rel_max"), 0.0
        )
    world, rel = err[..., 0][mask], err[..., 1][mask]
    return {
        "tess_error_mean": float(world.mean()),
        "tess_error_max": float(world.max()),
        "tess_error_rel_mean": float(rel.mean()),
        "tess_error_rel_max": float(rel.max()),
    }


def pareto_front(
    rows: Sequence[Mapping[str, Any]], x: str = "wall_s", y: str = "color_rmse"
) -> list[int]:
    """Indices of the rows on the Pareto front of ``x`` and ``y`` (both smaller is better).

    A row is on the front when no other row is at least as good in both and
    better in one. Returned in order of increasing ``x``.
    """
    points = [
        (float(r[x]), float(r[y]), i)
        for i, r in enumerate(rows)
        if isinstance(r.get(x), (int, float)) and isinstance(r.get(y), (int, float))
    ]
    front: list[int] = []
    best_y = math.inf
    for _x, py, i in sorted(points):
        if py < best_y:
            front.append(i)
            best_y = py
    return front


def _cell(value: Any, fmt: str) -> str:
    if value is None:
        return "–"
    if fmt == "s":
        return str(value)
    if fmt == "mark":
        return "★" if value else ""
    if fmt == "mb":
        return f"{value / 1e6:,.0f}"
    if fmt == ",d":
        return f"{int(value):,}"
    return format(float(value), fmt)


def format_markdown(table: Mapping[str, Any]) -> str:
    """The sweep table as Markdown: a short header, then one row per setting."""
    ref = table.get("reference", {})
    size = table.get("image_size")
    lines = [f"## mipray-sweep: {os.path.basename(str(table.get('scene', '')))}", ""]
    lines.append(
        f"- image: {size[0]}×{size[1]} pixels, camera `{table.get('camera')}`, "
        f"median of {table.get('runs')} run(s)"
        if size
        else f"- median of {table.get('runs')} run(s)"
    )
    if table.get("base_settings"):
        lines.append(f"- fixed settings: {setting_label(table['base_settings'])}")
    if ref:
        how = (
            f"auto ({setting_label(ref.get('settings', {}))})"
            if ref.get("source") == "auto"
            else f"`{ref.get('source')}`"
        )
        took = f", rendered in {ref['wall_s']:.3g} s" if ref.get("wall_s") is not None else ""
        lines.append(f"- reference: {how}{took}")
    rows = list(table.get("rows", []))
    total = table.get("planned_rows", len(rows))
    if not table.get("complete", False):
        why = table.get("stopped") or "not finished"
        lines.append(f"- **incomplete**: {len(rows)} of {total} rows ({why})")
    lines += ["", "| " + " | ".join(h for h, _, _ in _COLUMNS) + " |"]
    lines.append("|" + "|".join("---" if f == "s" else "---:" for _, _, f in _COLUMNS) + "|")
    for row in rows:
        cells = [_cell(row.get(field), fmt) for _, field, fmt in _COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    return "\n".join(lines)


def _atomic_write(path: str, text: str) -> None:
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".sweep-", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_tables(table: dict[str, Any], prefix: str) -> list[str]:
    """Write ``PREFIX.json`` and ``PREFIX.md``; mark the Pareto rows first.

    Each file is replaced atomically, so a sweep stopped at any moment leaves
    the table of the rows finished so far. Returns the paths written.
    """
    rows = table.get("rows", [])
    front = set(pareto_front(rows))
    for i, row in enumerate(rows):
        row["pareto"] = i in front
    json_path, md_path = f"{prefix}.json", f"{prefix}.md"
    _atomic_write(json_path, json.dumps(table, indent=2, sort_keys=False) + "\n")
    _atomic_write(md_path, format_markdown(table))
    return [json_path, md_path]


def write_plot(table: Mapping[str, Any], path: str, title: str | None = None) -> None:
    """Plot color RMSE and geometric error against wall time, Pareto front marked.

    Points are numbered in table order; the key under the plot names each
    setting, so long labels never overlap.

    Raises:
        ImportError: matplotlib is not installed (the caller says how to get it).

    """
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(table.get("rows", []))
    key = "   ".join(f"{i}: {r['label']}" for i, r in enumerate(rows, start=1))
    key_lines = textwrap.wrap(key, 150) or [""]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4 + 0.18 * len(key_lines)))
    panels = (
        ("color_rmse", "color RMSE against the reference"),
        ("tess_error_rel_mean", "mean tessError / beam width"),
    )
    for ax, (name, ylabel) in zip(axes, panels, strict=True):
        xs = [float(r["wall_s"]) for r in rows]
        ys = [float(r.get(name) or 0.0) for r in rows]
        ax.scatter(xs, ys, s=22, color="0.45", zorder=2, label="setting")
        for i, (px, py) in enumerate(zip(xs, ys, strict=True), start=1):
            ax.annotate(str(i), (px, py), textcoords="offset points", xytext=(4, 3), fontsize=8)
        front = pareto_front(rows, "wall_s", name)
        if front:
            fx = [xs[i] for i in front]
            fy = [ys[i] for i in front]
            ax.step(fx, fy, where="post", color="tab:red", lw=1.2, zorder=1)
            ax.scatter(fx, fy, s=40, color="tab:red", zorder=3, label="Pareto front")
        ax.set_xlabel("wall time, s (median)")
        ax.set_ylabel(ylabel)
        if xs and min(xs) > 0 and max(xs) / min(xs) > 8:
            ax.set_xscale("log")
        if ys and min(ys) > 0 and max(ys) / min(ys) > 20:
            ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    fig.suptitle(title or f"mipray-sweep: {os.path.basename(str(table.get('scene', '')))}")
    bottom = (0.3 + 0.18 * len(key_lines)) / fig.get_figheight()
    fig.text(0.01, 0.01, "\n".join(key_lines), fontsize=7.5, va="bottom", family="monospace")
    fig.tight_layout(rect=(0.0, bottom, 1.0, 0.95))
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
