#!/usr/bin/env python3
"""Plot the geometry-cache benchmark (docs/cache-benchmark.json) as the paper's comparison.

    python scripts/plot_cache_bench.py docs/cache-benchmark.json docs/cache-benchmark.png

Left: recomputed vertices (the paper's "cache cost") against the cache budget, single- against
multiresolution. Right: median wall time against budget, with the unbounded cache as a line.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    """Read the benchmark JSON and write the PNG; returns the exit code."""
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("plot_cache_bench: matplotlib is not installed (pip install matplotlib)", file=sys.stderr)
        return 1
    doc = json.loads(Path(argv[0]).read_text())
    rows = doc["rows"]
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4), dpi=100)
    for mode, colour in (("single", "tab:red"), ("multires", "tab:blue")):
        sel = sorted((r for r in rows if r["mode"] == mode), key=lambda r: r["budget_mb"])
        mb = [r["budget_mb"] for r in sel]
        cost = [max(r["stats"]["geometry_cache"]["recomputed_vertices"], 1) for r in sel]
        wall = [r["wall_s_median"] for r in sel]
        ax0.plot(mb, cost, "o-", color=colour, label=f"{mode}-resolution" if mode == "single" else mode)
        ax1.plot(mb, wall, "o-", color=colour, label=mode)
    unbounded = [r for r in rows if r["mode"] == "unbounded"]
    if unbounded:
        ax1.axhline(unbounded[0]["wall_s_median"], color="gray", ls="--", label="unbounded")
    for ax in (ax0, ax1):
        ax.set_xscale("log")
        ax.set_xlabel("geometry cache budget (MB)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    ax0.set_yscale("log")
    ax0.set_ylabel("recomputed vertices (cache cost)")
    ax1.set_ylabel("render wall time, median (s)")
    scene = rows[0]["stats"]["scene"]
    fig.suptitle(
        f"{scene['subpatches']:,} subpatches, full tessellation "
        f"{scene['full_tessellation_bytes'] / 1e9:.2f} GB"
    )
    fig.tight_layout()
    fig.savefig(argv[1])
    print(argv[1])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
