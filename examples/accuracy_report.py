#!/usr/bin/env python3
"""Regenerate docs/accuracy-vs-time.md: what accuracy costs in time, measured with mipray-sweep.

    make accuracy                                   # the documented command
    python examples/accuracy_report.py [--quick] [--resume] [--docs DIR] [--work DIR]

Runs the sweeps below through :func:`mipray.tools.sweep.sweep` (each setting in its
own process), then writes ``docs/accuracy-vs-time.md``, the raw tables in
``docs/accuracy-vs-time.json`` and the figures ``docs/images/accuracy-*.png``.
Every number and every verdict in the page comes from this run; nothing is
typed in by hand. ``--quick`` is a smoke run (tiny images, one run, fewer
values) that writes to ``--work`` only, unless ``--docs`` is given. ``--resume`` reads
back each sweep an earlier run finished with the same build and settings (after an
interruption, or a change to the page's text) instead of rendering it again.

The experiments, on ``examples/cache_scene.usda`` (many subdivision blobs, AO)
and ``examples/subdiv_showcase.usda``, with 8 AO rays per shading point so that
incoherent rays matter:

* **incoherent**: ``tessFactorIncoherent`` 1…32 at ``tessFactor`` 1 — coarser
  tessellation for wide rays (AO) only;
* **all**: ``tessFactor`` 0.25…16 with ``tessFactorIncoherent`` fixed at 1 —
  coarser for every ray, narrow camera rays included;
* **coherent only** (cache scene): ``tessFactor`` and ``tessFactorIncoherent``
  zipped so the AO rays' rate stays put while the camera rays coarsen;
* **samples** (cache scene): 1, 4, 16 camera samples at the defaults, against
  a converged reference: the noise the geometric error competes with;
* **cache** (cache scene): ``geometryCacheMb`` × ``tessFactorIncoherent``:
  what a small cache costs in recomputed vertices and time.

The first three compare against a *paired* reference: the most accurate
geometry (tess factor 0.25, unbounded cache) rendered with the rows' own
samples and seed, so the pixel noise cancels and the error is the bias of the
tessellation alone.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

sw: Any = None  # mipray.tools.sweep, imported by _load (from a snapshot while sweeping)
pareto_front: Any = None
write_plot: Any = None


def _load(snapshot: Path | None = None) -> None:
    """Import mipray.tools.sweep; with ``snapshot``, from a private copy of the package.

    Each setting renders in a new process that imports the extension afresh:
    on a machine where the extension is rebuilt while the sweeps run (other
    work in the same checkout), the copy keeps every row on one build.
    """
    global sw, pareto_front, write_plot
    if importlib.util.find_spec("mipray") is None:  # a source tree, not installed
        sys.path.insert(0, str(ROOT / "python"))
    if snapshot is not None:
        spec = importlib.util.find_spec("mipray")
        assert spec is not None and spec.submodule_search_locations
        source = Path(next(iter(spec.submodule_search_locations)))
        shutil.rmtree(snapshot, ignore_errors=True)
        shutil.copytree(source, snapshot / "mipray", ignore=shutil.ignore_patterns("__pycache__"))
        sys.path.insert(0, str(snapshot))
    from mipray.tools import sweep
    from mipray.tools.sweep_report import pareto_front as front
    from mipray.tools.sweep_report import write_plot as plot

    sw, pareto_front, write_plot = sweep, front, plot


BASE = {"aoSamples": 8, "samples": 4}
#: The irradiance-cache sweep: enough hemisphere rays a shading point for caching to matter (the
#: paper: "typically at least 256"), one camera ray a pixel, as the cache's pre-pass assumes.
IRRADIANCE_BASE = {"aoSamples": 64, "samples": 1}
PAIRED = {"samples": 4, "seed": 0}
#: The control scene, written into the work directory by :func:`convex_ball`.
BALL = "convex_ball"
#: The geometry-cache benchmark's scene at its full size (480 blobs, 486,720 control faces, a
#: third displaced), written as USD into the work directory by ``make_cache_scene.py --grid
#: 24x20 --face-res 13 --displace-every 3`` (``--grid 6x4 --face-res 4`` with --quick).
BENCH = "bench_scene"


@dataclass
class Experiment:
    """One sweep of the report."""

    key: str
    scene: str
    title: str
    knobs: dict[str, list[Any]]
    zip_knobs: bool = False
    runs: int = 3
    #: "paired" (the rows' samples and seed, tess factor 0.25) or "converged".
    reference: str = "paired"
    base: dict[str, Any] = field(default_factory=lambda: dict(BASE))
    #: Camera samples of a converged reference (None: run_all's); experiments with the same
    #: scene, kind of reference and base settings share one.
    reference_samples: int | None = None
    #: Settings of the reference that override the auto reference's (the paired one's are
    #: ``PAIRED``).
    reference_set: dict[str, Any] | None = None


def experiments(quick: bool) -> list[Experiment]:
    """The sweeps, smaller with ``quick``."""
    inc = [1, 2, 4, 8, 16, 32] if not quick else [1, 16]
    tess = [0.25, 0.5, 1, 2, 4, 8, 16] if not quick else [0.25, 1, 16]
    coh = [1, 2, 4, 8, 16] if not quick else [1, 16]
    runs = 1 if quick else 3
    cache, show = "cache_scene", "subdiv_showcase"
    return [
        Experiment(
            "cache-incoherent",
            cache,
            "tessFactorIncoherent (AO rays only)",
            {"tessFactorIncoherent": inc},
            runs=runs,
        ),
        Experiment(
            "cache-all",
            cache,
            "tessFactor (every ray; tessFactorIncoherent 1)",
            {"tessFactor": tess},
            runs=runs,
        ),
        Experiment(
            "cache-coherent",
            cache,
            "tessFactor with AO rays' rate held (zipped)",
            {"tessFactor": coh, "tessFactorIncoherent": [1 / f for f in coh]},
            zip_knobs=True,
            runs=1,
        ),
        Experiment(
            "cache-samples",
            cache,
            "camera samples at the defaults",
            {"samples": [1, 4, 16] if not quick else [1, 4]},
            runs=1,
            reference="converged",
            base={"aoSamples": 8},
        ),
        Experiment(
            "cache-budget",
            cache,
            "geometry cache budget × tessFactorIncoherent",
            {
                "geometryCacheMb": [1, 3, 30] if not quick else [1, 30],
                "tessFactorIncoherent": [1, 8],
            },
            runs=runs,
        ),
        Experiment(
            "showcase-incoherent",
            show,
            "tessFactorIncoherent (AO rays only)",
            {"tessFactorIncoherent": inc},
            runs=runs,
        ),
        Experiment(
            "showcase-all",
            show,
            "tessFactor (every ray; tessFactorIncoherent 1)",
            {"tessFactor": tess},
            runs=runs,
        ),
        Experiment(
            "ball-incoherent",
            BALL,
            "tessFactorIncoherent on one convex object alone",
            {"tessFactorIncoherent": [1, 4, 16] if not quick else [1, 16]},
            runs=1,
        ),
        Experiment(
            "cache-irradiance",
            cache,
            "irradiance (occlusion) caching off, then on by its error bound (64 AO rays)",
            # Off twice over (the bound means nothing then), on at each bound.
            {
                "irradianceCache": [0, 1],
                "irradianceCacheError": [0.4, 0.2, 0.1] if not quick else [0.2],
            },
            runs=runs,
            reference="converged",
            base=dict(IRRADIANCE_BASE),
            # The rows' own camera rays (the pixel centres), 16 times their AO rays: what is
            # left is AO noise and interpolation error, not antialiasing.
            reference_set={"samples": 1, "aoSamples": 1024},
        ),
        Experiment(
            "forest-all",
            "forest",
            "tessFactor (every ray)",
            {"tessFactor": [0.25, 1, 4, 16] if not quick else [1, 16]},
            runs=1,
        ),
        Experiment(
            "textured-all",
            "textured",
            "tessFactor (every ray; texture displacement at each tier's spacing)",
            {"tessFactor": [0.25, 1, 4, 16] if not quick else [1, 16]},
            runs=1,
        ),
        Experiment(
            "textured-filter",
            "textured",
            "texture filtering: by the ray differentials, or the finest MIP level forced",
            {"textureFilter": ["differentials", "finest"]},
            runs=runs,
        ),
        Experiment(
            "bench-incoherent",
            BENCH,
            "tessFactorIncoherent (AO rays only)",
            {"tessFactorIncoherent": [1, 16] if not quick else [16]},
            runs=1,
        ),
        Experiment(
            "bench-all",
            BENCH,
            "tessFactor (every ray; tessFactorIncoherent 1)",
            {"tessFactor": [1, 16]},
            runs=1,
        ),
    ]


def convex_ball(path: Path) -> None:
    """Write a control scene: one smooth convex Catmull-Clark cube alone, and a camera.

    Exact geometry cannot occlude itself here: any AO darkening a knob adds is the
    renderer's self-occlusion, not a property of coarse tessellations.
    """
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.Xform.Define(stage, "/World")
    mesh = UsdGeom.Mesh.Define(stage, "/World/Ball")
    corners = [(x, y, z) for z in (0.5, -0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)]
    mesh.CreatePointsAttr([Gf.Vec3f(*p) for p in corners])
    mesh.CreateFaceVertexCountsAttr([4] * 6)
    mesh.CreateFaceVertexIndicesAttr(
        [0, 1, 3, 2, 2, 3, 7, 6, 6, 7, 5, 4, 4, 5, 1, 0, 1, 5, 7, 3, 4, 0, 2, 6]
    )
    mesh.CreateSubdivisionSchemeAttr("catmullClark")
    # White and filling most of the frame, so AO darkening shows plainly in the color.
    mesh.CreateDisplayColorAttr([Gf.Vec3f(1.0, 1.0, 1.0)])
    camera = UsdGeom.Camera.Define(stage, "/World/main_cam")
    camera.CreateFocalLengthAttr(35.0)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(24.0)
    camera.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 1.5))
    stage.GetRootLayer().Save()


def bench_scene(work: Path, quick: bool) -> Path:
    """Write the cache benchmark's scene as USD into ``work`` (once) and return its path."""
    path = work / f"{BENCH}.usda"
    if not path.exists():
        out = work / "bench_scene_dir"
        size = (
            ["--grid", "6x4", "--face-res", "4"]
            if quick
            else ["--grid", "24x20", "--face-res", "13"]
        )
        size += ["--displace-every", "3"]
        subprocess.run(
            [sys.executable, str(HERE / "make_cache_scene.py"), str(out), *size], check=True
        )
        (out / "cache_scene.usda").replace(path)
    return path


# --- running -------------------------------------------------------------------------


def _progress(message: str) -> None:
    if sys.stderr.isatty():
        sys.stderr.write(f"\r\033[Kaccuracy: {message}")
        sys.stderr.flush()


def _fingerprint(exp: Experiment, scene: Path, width: int, converged_samples: int) -> str:
    """What an experiment's table depends on, besides the build: to tell a reusable one."""
    return json.dumps(
        {
            "scene": str(scene),
            "knobs": exp.knobs,
            "zip": exp.zip_knobs,
            "runs": exp.runs,
            "base": exp.base,
            "reference": exp.reference,
            "reference_set": exp.reference_set,
            "reference_samples": exp.reference_samples or converged_samples,
            "width": width,
        },
        sort_keys=True,
    )


def run_all(
    quick: bool, work: Path, width: int, converged_samples: int, resume: bool = False
) -> dict[str, Any]:
    """Run every experiment; a scene's paired and converged references are rendered once.

    With ``resume``, an experiment whose finished table in ``work`` was made by this build of
    the extension with the same settings is read back instead of rendered again.
    """
    work.mkdir(parents=True, exist_ok=True)
    tables: dict[str, Any] = {}
    references: dict[tuple[str, str, str], str] = {}
    identity = sw.extension_identity()
    for exp in experiments(quick):
        scene = HERE / f"{exp.scene}.usda"
        if exp.scene == BALL:
            scene = work / f"{BALL}.usda"
            convex_ball(scene)
        elif exp.scene == BENCH:
            scene = bench_scene(work, quick)
        ref_key = (exp.scene, exp.reference, json.dumps(exp.base, sort_keys=True))
        if exp.reference == "paired" or exp.base == {"aoSamples": 8}:
            ref_key = (exp.scene, exp.reference, "")
        reference = references.get(ref_key, "auto")
        overrides = exp.reference_set or (PAIRED if exp.reference == "paired" else None)
        if reference != "auto":
            overrides = None
        prefix = work / exp.key
        fingerprint = _fingerprint(exp, scene, width, converged_samples)
        saved = Path(f"{prefix}.report.json")
        if resume and saved.exists():
            old = json.loads(saved.read_text())
            if old.get("fingerprint") == fingerprint and old.get("extension") == identity:
                print(f"accuracy: {exp.key}: reused {saved}", file=sys.stderr)
                if old["reference"].get("source") != "shared":
                    references[ref_key] = old["reference"]["written"]
                tables[exp.key] = old
                continue
        started = time.monotonic()
        print(f"accuracy: {exp.key}: {exp.title}", file=sys.stderr)
        sw.sweep(
            scene,
            exp.knobs,
            reference=reference,
            reference_settings=overrides,
            reference_samples=exp.reference_samples or converged_samples,
            runs=exp.runs,
            out=prefix,
            width=width,
            settings=exp.base,
            zip_knobs=exp.zip_knobs,
            plot=True,
            progress=_progress,
        )
        if sys.stderr.isatty():
            sys.stderr.write("\r\033[K")
        table = json.loads(Path(f"{prefix}.json").read_text())
        if reference == "auto":
            references[ref_key] = table["reference"]["written"]
            table["reference"]["kind"] = exp.reference
        else:
            first = tables[
                next(k for k, t in tables.items() if t["reference"].get("written") == reference)
            ]
            table["reference"] = {**first["reference"], "source": "shared"}
        table["title"] = exp.title
        table["commit"] = _git_head()
        table["elapsed_s"] = time.monotonic() - started
        table["fingerprint"] = fingerprint
        saved.write_text(json.dumps(table, indent=1) + "\n")
        tables[exp.key] = table
    return tables


# --- reading the results -------------------------------------------------------------


def _row(table: dict[str, Any], **setting: Any) -> dict[str, Any]:
    for row in table["rows"]:
        if all(row["setting"].get(k) == v for k, v in setting.items()):
            return row
    raise KeyError(f"no row {setting} in {table.get('title')}")


def _pct(new: float, old: float) -> str:
    return f"{100.0 * (new - old) / old:+.0f}%" if old else "n/a"


def _speed(new: float, old: float) -> str:
    return f"{old / new:.2f}×" if new else "n/a"


def claim(tables: dict[str, Any], scene: str) -> dict[str, Any]:
    """The paper's claim on one scene, as numbers: the bias of coarsening each kind of ray."""
    inc, every = tables[f"{scene}-incoherent"], tables[f"{scene}-all"]
    top = max(r["setting"]["tessFactorIncoherent"] for r in inc["rows"])
    top_all = max(r["setting"]["tessFactor"] for r in every["rows"])
    factor = min(top, top_all)
    base = _row(every, tessFactor=1.0)
    finest = _row(every, tessFactor=min(r["setting"]["tessFactor"] for r in every["rows"]))
    coarse_inc = _row(inc, tessFactorIncoherent=float(factor))
    coarse_all = _row(every, tessFactor=float(factor))
    d_inc = coarse_inc["color_rmse"] - base["color_rmse"]
    d_all = coarse_all["color_rmse"] - base["color_rmse"]
    return {
        "factor": factor,
        "base": base,
        "finest": finest,
        "coarse_inc": coarse_inc,
        "coarse_all": coarse_all,
        "d_inc": d_inc,
        "d_all": d_all,
        # The claim: coarsening the wide rays adds well under a quarter of the error that
        # coarsening every ray by the same factor adds.
        "holds": d_all > 0 and d_inc < 0.25 * d_all,
    }


# --- the page ------------------------------------------------------------------------

_COLS = (
    ("setting", "label", "{}"),
    ("wall s", "wall_s", "{:.3g}"),
    ("CPU s", "cpu_s", "{:.3g}"),
    ("peak MB", "peak_rss_bytes", "mb"),
    ("recomputed verts", "recomputed_vertices", "{:,}"),
    ("RMSE", "color_rmse", "{:.4f}"),
    ("max abs", "color_max_abs", "{:.3f}"),
    ("mean diff", "color_mean_diff", "{:+.4f}"),
    ("tessErr/beam mean", "tess_error_rel_mean", "{:.2e}"),
    ("tessErr/beam max", "tess_error_rel_max", "{:.3g}"),
    ("Pareto", "pareto", "mark"),
)


#: Columns some tables add after recomputed vertices.
_EXTRA_COLS = {
    "hemisphere_rays": ("hemisphere rays", "hemisphere_rays", "{:,}"),
    "texture_tiles_read": ("texture tiles read", "texture_tiles_read", "{:,}"),
}


def _table_md(table: dict[str, Any], extra: tuple[str, ...] = ()) -> str:
    cols = list(_COLS)
    for key in extra:
        cols.insert(5, _EXTRA_COLS[key])
    lines = [
        "| " + " | ".join(c[0] for c in cols) + " |",
        "|" + "|".join("---" if c[1] == "label" else "---:" for c in cols) + "|",
    ]
    for row in table["rows"]:
        cells = []
        for _, key, fmt in cols:
            value = row.get(key)
            if value is None:
                cells.append("–")
            elif fmt == "mb":
                cells.append(f"{value / 1e6:,.0f}")
            elif fmt == "mark":
                cells.append("★" if value else "")
            else:
                cells.append(fmt.format(value))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _setting_text(settings: dict[str, Any]) -> str:
    return ", ".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in settings.items()
    )


def claim_figure(tables: dict[str, Any], scene: str, path: Path) -> bool:
    """RMSE against the tess factor multiplier and against time, for the claim's sweeps."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print(
            "accuracy: matplotlib is not installed (pip install 'matplotlib>=3.7'): "
            f"{path} not drawn",
            file=sys.stderr,
        )
        return False
    series = [(f"{scene}-incoherent", "tessFactorIncoherent", "AO rays coarsened", "tab:blue")]
    series.append((f"{scene}-all", "tessFactor", "every ray coarsened", "tab:red"))
    if f"{scene}-coherent" in tables:
        series.append(
            (f"{scene}-coherent", "tessFactor", "camera rays only (AO rate held)", "tab:gray")
        )
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    every: list[dict[str, Any]] = []
    for key, knob, label, color in series:
        rows = tables[key]["rows"]
        xs = [r["setting"][knob] for r in rows]
        left.plot(xs, [r["color_rmse"] for r in rows], "o-", color=color, label=label)
        right.scatter(
            [r["cpu_s"] for r in rows],
            [r["color_rmse"] for r in rows],
            s=24,
            color=color,
            label=label,
            zorder=2,
        )
        if key != f"{scene}-coherent":
            every += rows
    front = [every[i] for i in pareto_front(every)]
    right.step(
        [r["cpu_s"] for r in front],
        [r["color_rmse"] for r in front],
        where="post",
        color="black",
        lw=1,
        zorder=1,
        label="Pareto front",
    )
    left.set_xscale("log", base=2)
    left.set_xlabel("coarsening factor (tessFactor or tessFactorIncoherent)")
    left.set_ylabel("color RMSE against the paired reference")
    left.set_yscale("symlog", linthresh=1e-3)
    right.set_xlabel("CPU time of the render, s (median)")
    right.set_ylabel("color RMSE against the paired reference")
    right.set_yscale("symlog", linthresh=1e-3)
    for ax in (left, right):
        ax.set_ylim(bottom=0.0)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    name = Path(tables[f"{scene}-all"]["scene"]).name
    fig.suptitle(f"{name}: coarsening the tessellation for wide rays versus for every ray")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True


def _git_head() -> str:
    try:
        out = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        )
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return out.stdout.strip()


def _change(new: float, old: float) -> str:
    """``'0.647 → 0.403 s (−38%)'``."""
    pct = f" ({100.0 * (new - old) / old:+.0f}%)".replace("-", "−") if old else ""
    return f"{old:.3g} → {new:.3g} s{pct}"


def _figures(tables: dict[str, Any], images: Path, work: Path) -> dict[str, str]:
    figures: dict[str, str] = {}
    for scene in ("cache", "showcase", "bench"):
        png = images / f"accuracy-{scene}-claim.png"
        if claim_figure(tables, scene, png):
            figures[scene] = f"images/{png.name}"
    for key in ("cache-samples", "cache-budget"):
        try:
            write_plot(tables[key], str(images / f"accuracy-{key}.png"))
        except ImportError:
            continue  # claim_figure has said matplotlib is missing
        figures[key] = f"images/accuracy-{key}.png"
    return figures


def _saved(inc_s: float, base_s: float, all_s: float) -> str:
    """``'it saves 80%'``: the AO-only time saving as a share of the every-ray one."""
    if base_s - all_s <= 0:
        return "it saves none"
    return f"it saves {(base_s - inc_s) / (base_s - all_s):.0%}"


def _factor_table(tables: dict[str, Any], scene: str) -> str:
    """Per coarsening factor: the error each sweep adds over factor 1, and the time."""
    inc, every = tables[f"{scene}-incoherent"], tables[f"{scene}-all"]
    base = _row(every, tessFactor=1.0)
    inc_rows = {r["setting"]["tessFactorIncoherent"]: r for r in inc["rows"]}
    all_rows = {r["setting"]["tessFactor"]: r for r in every["rows"]}
    lines = [
        "| factor | AO only: +RMSE | every ray: +RMSE | AO share | AO only: mean diff | "
        "AO only: CPU s | every ray: CPU s |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for f in sorted(set(inc_rows) & set(all_rows)):
        if f <= 1.0:
            continue
        a, b = inc_rows[f], all_rows[f]
        da, db = a["color_rmse"] - base["color_rmse"], b["color_rmse"] - base["color_rmse"]
        share = f"{da / db:.0%}" if db > 0 else "–"
        lines.append(
            f"| {f:g} | {da:+.4f} | {db:+.4f} | {share} | {a['color_mean_diff']:+.4f} | "
            f"{a['cpu_s']:.3g} | {b['cpu_s']:.3g} |"
        )
    return "\n".join(lines)


def _claim_section(tables: dict[str, Any], scene: str, name: str, figure: str | None) -> str:
    c = claim(tables, scene)
    f, base, ci, ca = c["factor"], c["base"], c["coarse_inc"], c["coarse_all"]
    stats = tables[f"{scene}-incoherent"].get("scene_stats", {})
    parts = [f"### {name}\n"]
    if scene == "bench":
        parts.append(
            f"The geometry-cache benchmark's own scene at full size "
            f"({stats.get('control_faces', 0):,} control faces in 480 individually modelled "
            "blobs, half chrome, a third displaced; every subpatch at 17×17 would take "
            f"{stats.get('full_tessellation_bytes', 0) / 1e9:.2f} GB), written as USD by "
            "`examples/make_cache_scene.py --grid 24x20 --face-res 13 --displace-every 3`, "
            f"rendered in the default 30 MB cache; fixed settings {_setting_text(BASE)}, one "
            "run per setting.\n"
        )
    elif scene == "cache":
        parts.append(
            f"{stats.get('control_faces', 0):,} control faces in lumpy Catmull-Clark blobs, no "
            "two alike (the geometry-cache benchmark scene's kind, written by "
            "`examples/make_cache_scene.py`; every subpatch at 17×17 would take "
            f"{stats.get('full_tessellation_bytes', 0) / 1e6:.0f} MB); fixed settings "
            f"{_setting_text(BASE)}.\n"
        )
    else:
        parts.append(
            f"Creased, cornered and holed subdivision surfaces on a ground plane "
            f"({stats.get('control_faces', 0):,} control faces); fixed settings "
            f"{_setting_text(BASE)}.\n"
        )
    parts.append(
        f"- Coarsening **AO rays only** {f:g}× (tessFactorIncoherent {f:g}): RMSE "
        f"{base['color_rmse']:.4f} → {ci['color_rmse']:.4f} ({c['d_inc']:+.4f}); CPU time "
        f"{_change(ci['cpu_s'], base['cpu_s'])}.\n"
        f"- Coarsening **every ray** {f:g}× (tessFactor {f:g}): RMSE "
        f"{base['color_rmse']:.4f} → {ca['color_rmse']:.4f} ({c['d_all']:+.4f}); CPU time "
        f"{_change(ca['cpu_s'], base['cpu_s'])}.\n"
    )
    parts.append(_factor_table(tables, scene) + "\n")
    if c["d_all"] > 0:
        share = f"adds {c['d_inc'] / c['d_all']:.0%} of the error that coarsening every ray"
    else:
        share = "is compared with coarsening every ray, which adds no error"
    verdict = "**holds**" if c["holds"] else "**does not hold**"
    shift = ci["color_mean_diff"] - base["color_mean_diff"]
    if abs(shift) >= 0.25 * max(c["d_inc"], 1e-9):
        kind = (
            f"Much of the AO-only error is a bias: the image turns "
            f"{'darker' if shift < 0 else 'brighter'} on the whole (mean difference "
            f"{base['color_mean_diff']:+.4f} → {ci['color_mean_diff']:+.4f}), which more "
            "samples would not remove."
        )
    else:
        kind = (
            "The AO-only error is mostly decorrelation (rays flipping between hit and miss), "
            f"not a shift of the whole image (mean difference {base['color_mean_diff']:+.4f} "
            f"→ {ci['color_mean_diff']:+.4f})."
        )
    parts.append(
        f"Verdict at {f:g}×: the claim {verdict} on this scene — coarsening the wide rays "
        f"{share} by the same factor adds (the test: under 25%), while "
        f"{_saved(ci['cpu_s'], base['cpu_s'], ca['cpu_s'])} of the time that coarsening "
        f"every ray saves. {kind} The camera rays' geometric error (`tessError`) stays "
        "where it was in the AO-only sweep "
        f"({ci['tess_error_rel_mean']:.2e} beam widths mean, as at tessFactorIncoherent 1: "
        f"{base['tess_error_rel_mean']:.2e}); in the every-ray sweep it grows to "
        f"{ca['tess_error_rel_mean']:.2e} mean and {ca['tess_error_rel_max']:.3g} max. "
        "Read the AO-only numbers with the self-occlusion control below.\n"
    )
    if figure:
        parts.append(f"![{name}: RMSE against the coarsening factor and against time]({figure})\n")
    parts.append(f"<details><summary>{name}: the tables</summary>\n")
    for key in (f"{scene}-incoherent", f"{scene}-all", f"{scene}-coherent"):
        if key in tables:
            parts.append(f"**{tables[key]['title']}**\n\n{_table_md(tables[key])}\n")
    parts.append("</details>\n")
    return "\n".join(parts)


def _self_occlusion_section(tables: dict[str, Any]) -> str:
    """The control for self-occlusion at a ray's origin, from the sweeps' numbers."""
    parts = ["### Self-occlusion at the ray origin: the control\n"]
    ball = tables.get("ball-incoherent")
    if ball:
        one = _row(ball, tessFactorIncoherent=1.0)
        top = max(ball["rows"], key=lambda r: r["setting"]["tessFactorIncoherent"])
        f = top["setting"]["tessFactorIncoherent"]
        mechanism = (
            "An AO ray starts on the camera ray's fine tessellation. Near a coarser "
            "tessellation's vertices, where its facets touch the limit surface and the fine "
            "chords sag below it, the ray's origin lies *inside* the coarser polyhedron, and "
            "the ray would hit it on the way out. So a secondary ray ignores, within the two "
            "grids' chord errors along it, the other tessellations of its own subpatch and of "
            "every subpatch of the same surface whose box holds its origin (its neighbours "
            "across a patch edge; `Tracer::intersect_from` in `rust/src/trace.rs`), and the "
            "seam boxes that close cracks between rates stand off the surface only as far as "
            "its edge curves do (`rust/src/seam.rs`). Before the neighbour rule, this control "
            "read RMSE 0.0187 at tessFactorIncoherent 16 (largest error 0.41, darker), as large "
            "as the AO-only error on the scenes above."
        )
        intro = (
            "One smooth, white, convex object alone (a subdivided cube, no ground), where "
            "exact geometry cannot occlude itself, so every AO ray should escape. "
        )
        if top["color_rmse"] > 2.0 * one["color_rmse"] + 0.002:
            parts.append(
                intro + f"Coarsening its AO rays still changes it: RMSE {one['color_rmse']:.4f} "
                f"at tessFactorIncoherent 1, {top['color_rmse']:.4f} at {f:g} (largest error "
                f"{top['color_max_abs']:.2f}, mean difference {top['color_mean_diff']:+.4f}): "
                "self-occlusion the renderer still has. " + mechanism + "\n"
            )
        else:
            parts.append(
                intro + "Coarsening its AO rays leaves it as it was: RMSE "
                f"{one['color_rmse']:.4f} at tessFactorIncoherent 1, {top['color_rmse']:.4f} "
                f"at {f:g} (largest error {top['color_max_abs']:.3f}, mean difference "
                f"{top['color_mean_diff']:+.4f}). The AO-only errors above are the coarse "
                "tessellations' own, not the renderer's. " + mechanism + "\n"
            )
    coh = tables.get("cache-coherent")
    if coh:
        worst = max(coh["rows"], key=lambda r: r["color_rmse"])
        first = coh["rows"][0]
        same = _row(tables["cache-all"], tessFactor=worst["setting"]["tessFactor"])
        if worst["color_rmse"] > 2 * same["color_rmse"]:
            parts.append(
                "The other way round is worse. Holding the AO rays' rate while only the camera "
                "rays coarsen (`--zip --knob tessFactor=1,2,4,8,16 --knob "
                "tessFactorIncoherent=1,0.5,0.25,0.125,0.0625`) was meant to isolate the "
                f"narrow rays' share; instead RMSE goes from {first['color_rmse']:.4f} to "
                f"{worst['color_rmse']:.3f} at {worst['label']} (mean difference "
                f"{worst['color_mean_diff']:+.3f}), against {same['color_rmse']:.4f} when "
                "every ray coarsens by as much: from a point on coarse chords, deep inside the "
                "surface, AO rays tested against a *finer* tessellation of the neighbourhood "
                "beyond the skipped band hit it. Keep `tessFactorIncoherent` at 1 or above.\n"
            )
        else:
            parts.append(
                "Holding the AO rays' rate while only the camera rays coarsen (`--zip`) gives "
                f"RMSE {first['color_rmse']:.4f} → {worst['color_rmse']:.4f} at "
                f"{worst['label']}, against {same['color_rmse']:.4f} when every ray coarsens.\n"
            )
    return "\n".join(parts)


def _examples_section(tables: dict[str, Any]) -> str:
    """The tess factor on the other examples, and texture filtering."""
    parts = [
        "## The other examples\n",
        "`tessFactor` on every ray, one run per setting, against the paired reference at tess "
        f"factor 0.25 ({_setting_text(BASE)}).\n",
    ]
    for key, name, what in (
        (
            "forest-all",
            "examples/forest.usda",
            "3,000 PointInstancer instances of three subdivision prototypes",
        ),
        (
            "textured-all",
            "examples/textured.usda",
            "a UsdUVTexture on diffuseColor and on displacement",
        ),
    ):
        table = tables.get(key)
        if not table:
            continue
        base = _row(table, tessFactor=1.0)
        coarse = max(table["rows"], key=lambda r: r["setting"]["tessFactor"])
        finest = min(table["rows"], key=lambda r: r["setting"]["tessFactor"])
        parts.append(
            f"**{name}** ({what}): tess factor 1 against {finest['setting']['tessFactor']:g}: "
            f"CPU time {_change(base['cpu_s'], finest['cpu_s'])} for RMSE "
            f"{base['color_rmse']:.4f} and {base['tess_error_rel_mean']:.1e} beam widths of "
            f"camera-ray geometric error; at {coarse['setting']['tessFactor']:g}, "
            f"{_change(coarse['cpu_s'], finest['cpu_s'])} for RMSE {coarse['color_rmse']:.4f} "
            f"({coarse['tess_error_rel_mean']:.1e} beam widths).\n"
        )
        parts.append(_table_md(table) + "\n")
    filt = tables.get("textured-filter")
    if filt:
        diff = _row(filt, textureFilter="differentials")
        fine = _row(filt, textureFilter="finest")
        if diff.get("texture_tiles_read"):
            tiles = (
                f"{fine['texture_tiles_read'] / diff['texture_tiles_read']:.0f}× the texture "
                f"tiles ({diff['texture_tiles_read']:,} → {fine['texture_tiles_read']:,})"
            )
        else:
            tiles = f"{fine.get('texture_tiles_read')} texture tiles against none"
        parts.append(
            "### Texture filtering by the ray differentials (the paper's §6.3.3)\n\n"
            "On `examples/textured.usda`, the finest MIP level forced for every lookup "
            f"(`textureFilter=finest`) reads {tiles} that filtering by the differentials reads, "
            f"and changes the image's RMSE against the reference from {diff['color_rmse']:.4f} "
            f"to {fine['color_rmse']:.4f}"
            + (
                ": the aliasing of unfiltered texels."
                if fine["color_rmse"] > diff["color_rmse"] + 0.001
                else f" — with {BASE['samples']} camera rays a pixel the finest level's aliasing "
                "mostly averages out here; what forcing it costs is texture I/O."
            )
            + f" CPU time {_change(fine['cpu_s'], diff['cpu_s'])}.\n"
        )
        parts.append(_table_md(filt, ("texture_tiles_read",)) + "\n")
    return "\n".join(parts)


def _irradiance_section(tables: dict[str, Any]) -> str:
    """Irradiance (occlusion) caching on the cache scene: time, rays and error by its bound."""
    table = tables.get("cache-irradiance")
    if not table:
        return ""
    off = _row(table, irradianceCache=0)
    on = sorted(
        (r for r in table["rows"] if r["setting"]["irradianceCache"] == 1),
        key=lambda r: -r["setting"]["irradianceCacheError"],
    )

    def cells(label: str, r: dict[str, Any]) -> str:
        return (
            f"| {label} | {r['cpu_s']:.3g} | {_speed(r['cpu_s'], off['cpu_s'])} | "
            f"{r.get('hemisphere_rays') or 0:,} | {r['color_rmse']:.4f} | "
            f"{r['color_max_abs']:.3f} | {r['color_mean_diff']:+.4f} |"
        )

    lines = [
        "| irradianceCacheError | CPU s | speed-up | hemisphere rays | RMSE | max abs | "
        "mean diff |",
        "|---:|---:|---:|---:|---:|---:|---:|",
        cells("off", off),
    ]
    lines += [cells(f"{r['setting']['irradianceCacheError']:g}", r) for r in on]
    fastest = min(on, key=lambda r: r["cpu_s"])
    ref = table["reference"].get("settings", {})
    verdict = (
        "more accurate than sampling at every point, and faster"
        if fastest["color_rmse"] <= off["color_rmse"] and fastest["cpu_s"] < off["cpu_s"]
        else "faster, for the error in the table"
        if fastest["cpu_s"] < off["cpu_s"]
        else "not faster here"
    )
    return "\n".join(
        [
            "## Irradiance (occlusion) caching (the paper's §5.1)\n",
            f"On the cache scene with {_setting_text(IRRADIANCE_BASE)}: ambient occlusion "
            "sampled at every shading point, or interpolated from records with gradients "
            "(`irradianceCache=1`) by the cache's error bound (Ward's a), against a reference "
            f"through the same pixel centres with 16 times the AO rays ({_setting_text(ref)}); "
            "the RMSE is the AO sampling noise and, cached, the interpolation's error. "
            f"At a = {fastest['setting']['irradianceCacheError']:g} the "
            f"cache is {verdict}: CPU time {_change(fastest['cpu_s'], off['cpu_s'])}, hemisphere "
            f"rays {off.get('hemisphere_rays') or 0:,} → {fastest.get('hemisphere_rays') or 0:,} "
            f"(the pre-pass's included), RMSE {off['color_rmse']:.4f} → "
            f"{fastest['color_rmse']:.4f}. `docs/irradiance-cache.md` measures it on a scene "
            "built for it, for color bleeding too.\n",
            "\n".join(lines) + "\n",
        ]
    )


def _budget_verdict(fine_n: int, coarse_n: int) -> str:
    if fine_n <= 0 or coarse_n >= fine_n:
        return (
            "— no fewer: at this scene's size the AO rays' tessellations are not what "
            "overflows the cache."
        )
    cut = 1.0 - coarse_n / fine_n
    if cut >= 0.5:
        return (
            f"({cut:.0%} fewer): coarse tessellations for the wide rays are what let a small "
            "cache work, the paper's point."
        )
    return (
        f"({cut:.0%} fewer): coarse tessellations for the wide rays help a small cache, "
        "modestly here: most of what it recomputes is not the AO rays' tessellations."
    )


def _defaults_section(tables: dict[str, Any], figures: dict[str, str]) -> str:
    c = claim(tables, "cache")
    base, finest = c["base"], c["finest"]
    samples = tables["cache-samples"]
    s_rows = sorted(((r["setting"]["samples"], r) for r in samples["rows"]), key=lambda t: t[0])
    most, most_row = s_rows[-1]
    noise = "; ".join(
        f"{n} sample{'s' if n > 1 else ''}: RMSE {r['color_rmse']:.4f} in {r['cpu_s']:.3g} CPU s"
        for n, r in s_rows
    )
    if base["color_rmse"] < 0.5 * most_row["color_rmse"]:
        scale = (
            f"The default tess factor's bias ({base['color_rmse']:.4f}) is well under the noise "
            f"of even {most} camera samples ({most_row['color_rmse']:.4f}): at the defaults, "
            "time spent on finer geometry would not show."
        )
    else:
        scale = (
            f"The default tess factor's bias ({base['color_rmse']:.4f}) is comparable with the "
            f"noise of {most} camera samples ({most_row['color_rmse']:.4f}): at that many "
            "samples a finer tess factor starts to show."
        )
    inc = c["coarse_inc"]
    parts = [
        "## What the defaults cost and buy\n",
        "Defaults: tessFactor 1, tessFactorIncoherent 1, the multires cache of 30 MB, 1 camera "
        f"sample, no AO. On the cache scene (with {_setting_text(BASE)}), tess factor 1 against "
        f"the finest geometry (tess factor {finest['setting']['tessFactor']:g}): CPU time "
        f"{_change(base['cpu_s'], finest['cpu_s'])}, recomputed vertices "
        f"{finest['recomputed_vertices']:,} → {base['recomputed_vertices']:,}, peak memory "
        f"{finest['peak_rss_bytes'] / 1e6:,.0f} → {base['peak_rss_bytes'] / 1e6:,.0f} MB; it "
        f"buys that for a bias of {base['color_rmse']:.4f} RMSE and a camera-ray geometric "
        f"error of {base['tess_error_rel_mean']:.1e} beam widths on average "
        f"({base['tess_error_rel_max']:.2g} at worst). For scale, the noise against the "
        f"converged reference — {noise}. {scale} Raising the default tessFactorIncoherent to "
        f"{c['factor']:g} would change the time by {_change(inc['cpu_s'], base['cpu_s'])} "
        f"for {c['d_inc']:+.4f} RMSE.\n",
    ]
    if "cache-samples" in figures:
        parts.append(f"![camera samples: RMSE against time]({figures['cache-samples']})\n")
    parts.append(_table_md(samples) + "\n")
    budget = tables["cache-budget"]
    mbs = sorted({r["setting"]["geometryCacheMb"] for r in budget["rows"]})
    small1 = _row(budget, geometryCacheMb=mbs[0], tessFactorIncoherent=1.0)
    small8 = _row(budget, geometryCacheMb=mbs[0], tessFactorIncoherent=8.0)
    big1 = _row(budget, geometryCacheMb=mbs[-1], tessFactorIncoherent=1.0)
    parts.append("### The geometry cache budget\n")
    parts.append(
        "The cache never changes pixels (each row's RMSE is that of its tess factors); it "
        f"trades memory for recomputation. At {mbs[0]:g} MB the cache recomputes "
        f"{small1['recomputed_vertices']:,} vertices against {big1['recomputed_vertices']:,} "
        f"at {mbs[-1]:g} MB; CPU time {_change(small1['cpu_s'], big1['cpu_s'])} from "
        f"{mbs[-1]:g} MB to {mbs[0]:g} MB. With tessFactorIncoherent 8 the small cache "
        f"recomputes {small8['recomputed_vertices']:,} "
        + _budget_verdict(small1["recomputed_vertices"], small8["recomputed_vertices"])
        + "\n"
    )
    if "cache-budget" in figures:
        parts.append(f"![cache budget: RMSE against time]({figures['cache-budget']})\n")
    parts.append(_table_md(budget) + "\n")
    return "\n".join(parts)


def _chrome_note(tables: dict[str, Any]) -> str:
    rays = tables["cache-incoherent"]["reference"].get("rays", {})
    if rays.get("reflection", 0) > 0:
        return (
            "- The cache scene's chrome blobs are mirrors (UsdPreviewSurface metallic 1, "
            f"roughness 0): its reference traced {rays['reflection']:,} reflection rays beside "
            f"{rays.get('ao', 0):,} AO rays. Mirror rays are not incoherent in the knob's "
            "sense (`tessFactorIncoherent` covers AO, diffuse and glossy rays); their beams "
            "widen on curved mirrors by their own differentials.\n"
        )
    return (
        "- The USD reader in this build does not turn UsdPreviewSurface `metallic` into mirror "
        'reflection, so the cache scene\'s "chrome" blobs render diffuse and no mirror rays '
        "are traced; AO carries the incoherent rays.\n"
    )


def write_page(tables: dict[str, Any], docs: Path, work: Path, width: int, quick: bool) -> Path:
    """Write the page, its JSON and its figures into ``docs``."""
    images = docs / "images"
    images.mkdir(parents=True, exist_ok=True)
    figures = _figures(tables, images, work)
    (docs / "accuracy-vs-time.json").write_text(json.dumps(tables, indent=1) + "\n")
    total_s = sum(t["elapsed_s"] for t in tables.values())
    size = tables["cache-all"]["image_size"]
    ref = tables["cache-incoherent"]["reference"]
    conv = tables["cache-samples"]["reference"]
    runs = tables["cache-all"]["runs"]
    commit = tables["cache-all"].get("commit") or _git_head()
    parts = [
        "# Accuracy versus time: what the tessellation settings cost and buy\n",
        "<!-- Generated by `make accuracy` (examples/accuracy_report.py): do not edit. -->\n",
        "Every number, figure and verdict on this page was measured by `mipray-sweep` "
        "(`python/mipray/tools/sweep.py`) and is regenerated by one command:\n",
        "```\nmake accuracy    # = python examples/accuracy_report.py, about 15 minutes on "
        "2 cores\n```\n",
        f"This run: commit `{commit}` plus the working tree, {size[0]}×{size[1]} pixels, "
        f"median of {runs} run(s) per setting (the zipped and samples sweeps: 1), all cores, "
        "the extension as `make setup` builds it (dev profile), "
        f"{total_s / 60:.1f} minutes in all. Wall time is `render.wall_s` (rendering, not "
        "scene sync). Other work shares this machine, so wall times of one setting moved by "
        "up to a factor of two from run to run; the text therefore compares **CPU time** (all "
        "threads of the setting's process during the render call), which other processes "
        "barely move. Peak memory is `memory.peak_rss_bytes` of each setting's own process, "
        "Python and USD (about 250 MB) included.\n",
    ]
    if quick:
        parts.append(
            "> **Quick run** (`--quick`): tiny images and few values; a smoke test of the "
            "page, not results.\n"
        )
    parts += [
        "## How to read it\n",
        "`mipray-sweep scene.usda --knob NAME=V1,V2,...` renders the scene once per setting "
        "and compares each image with a reference. Columns: wall and CPU time; peak memory; "
        "vertices "
        "the geometry cache tessellated again after evicting them (its cost); color RMSE and "
        "largest absolute error against the reference; and the `tessError` AOV — per pixel, "
        "the distance along the camera ray from its hit on the tessellation to the exact limit "
        "surface, in world units (channel 0) and over the ray's beam width (channel 1) — as "
        "mean and max over covered pixels. ★ marks the Pareto front: no other row is both "
        "faster and closer to the reference.\n",
        "Two references. The **paired** reference is the most accurate geometry "
        f"({_setting_text(ref.get('settings', {}))}) rendered with the rows' own samples and "
        "seed (`--reference-set samples=4 --reference-set seed=0`): the pixel noise is the "
        "same in both, so what is left is the tessellation's bias (the cache never changes "
        "pixels, so the tess factor 0.25 row scores exactly 0). The **converged** reference "
        f"({_setting_text(conv.get('settings', {}))}) is what `--reference auto` renders: "
        "there the error is noise plus bias.\n",
        "## The paper's claim: wide rays can take coarse tessellations\n",
        "Christensen et al. (2003) tessellate each subpatch at the rate the ray's beam width "
        "asks for, and argue that incoherent rays (ambient occlusion, diffuse, glossy) are "
        "wide, so a coarse tessellation serves them with little error, while narrow, coherent "
        "camera and mirror rays need a fine one. Here `tessFactorIncoherent` multiplies the "
        "tess factor of AO, diffuse and glossy rays only; `tessFactor` sets every ray's. Each "
        "scene renders with 8 AO rays per shading point, so the incoherent rays matter.\n",
        _claim_section(tables, "cache", "examples/cache_scene.usda", figures.get("cache")),
        _claim_section(
            tables, "showcase", "examples/subdiv_showcase.usda", figures.get("showcase")
        ),
        _claim_section(tables, "bench", "The cache benchmark scene", figures.get("bench")),
    ]
    parts.append(_self_occlusion_section(tables))
    parts.append(_defaults_section(tables, figures))
    parts.append(_irradiance_section(tables))
    parts.append(_examples_section(tables))
    parts += [
        "## Limits of these measurements\n",
        "- Small images on a shared 2-core machine: compare CPU times within a table; wall "
        "times there also carry the other work's load.\n"
        + _chrome_note(tables)
        + "- `tessError` is measured for camera rays only; the AO rays' geometric error shows "
        "only through the color RMSE.\n"
        "- Swept here: the tessellation, cache, sample, irradiance-cache and texture-filter "
        "knobs; `mipray-sweep --list-knobs` shows every knob this build offers"
        + (
            f", and refuses the ones it does not have yet ({', '.join(sw.unavailable_knobs())}) "
            "with a message saying so.\n"
            if sw.unavailable_knobs()
            else ".\n"
        ),
        "## One sweep by hand\n",
        "```\n"
        "mipray-sweep examples/cache_scene.usda --set aoSamples=8 --set samples=4 \\\n"
        f"    --knob tessFactorIncoherent=1,2,4,8,16,32 --runs 3 --width {width} \\\n"
        "    --reference-set samples=4 --reference-set seed=0 --out out/incoherent\n"
        "```\n",
        "It writes `out/incoherent.{json,md,png}` and `out/incoherent.reference.exr`; "
        "`mipray-sweep --help` lists every knob and its range.\n",
    ]
    page = docs / "accuracy-vs-time.md"
    page.write_text("\n".join(parts))
    return page


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """Run the sweeps and write the page; print its path."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a smoke run: tiny, few values")
    parser.add_argument(
        "--docs",
        type=Path,
        help="where the page goes (default: docs/, or only --work with --quick)",
    )
    parser.add_argument(
        "--work",
        type=Path,
        default=ROOT / "out" / "accuracy",
        help="where each sweep's own files go (default: out/accuracy)",
    )
    parser.add_argument("--width", type=int, help="image width (default 128; 24 with --quick)")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="read back the sweeps a run before finished with this build and these settings "
        "(from --work) instead of rendering them again",
    )
    parser.add_argument(
        "--from",
        dest="from_json",
        type=Path,
        metavar="JSON",
        help="skip the sweeps: rewrite the page from a saved docs/accuracy-vs-time.json",
    )
    args = parser.parse_args(argv)
    width = args.width or (24 if args.quick else 128)
    docs = args.docs or (args.work / "docs" if args.quick else ROOT / "docs")
    if args.from_json:
        _load()
        tables = json.loads(args.from_json.read_text())
        print(write_page(tables, docs, args.work, width, args.quick))
        return 0
    _load(args.work / "snapshot")
    if not (HERE / "cache_scene.usda").exists():
        subprocess.run([sys.executable, str(HERE / "make_cache_scene.py")], check=True)
    # Stopped with SIGTERM as with Ctrl-C: each sweep stops its worker and keeps its rows.
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        tables = run_all(args.quick, args.work, width, 8 if args.quick else 32, args.resume)
    except KeyboardInterrupt:
        print(
            f"accuracy: interrupted; each sweep's finished rows are in {args.work}/*.json",
            file=sys.stderr,
        )
        return 130
    except sw.SweepError as exc:
        print(f"accuracy: {exc}", file=sys.stderr)
        return 1
    print(write_page(tables, docs, args.work, width, args.quick))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
