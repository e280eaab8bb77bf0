"""The light tree's IES weighting, measured: RMSE of 4-spp renders against a 1,024-spp one.

A 7 × 7 grid of small sphere lights 0.9 apart, 2 above a floor, each a 12° IES beam pointing
down: a floor point sees one beam, so a tree that weighs lights by distance alone wastes most
samples. Run from the repository root with the extension built:
``.venv/bin/python scripts/ies_tree_noise.py`` (the reference render is cached in the
temporary directory). docs/materials.md quotes its output.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, UsdLux

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from test_lights_shaping_linking import stage_with_camera

import mipray

ANGLES = [0, 5, 10, 12, 90]
CANDELA = [1000, 1000, 800, 0, 0]


def main() -> None:
    """Print the RMSE of five 4-spp seeds against the reference, and the time of one."""
    tmp = Path(tempfile.gettempdir())
    ies = tmp / "mipray_ies_tree_beam.ies"
    ies.write_text(
        f"IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 {len(ANGLES)} 1 1 2 0 0 0\n1 1 10\n"
        f"{' '.join(map(str, ANGLES))}\n0\n{' '.join(map(str, CANDELA))}\n"
    )
    stage = stage_with_camera()
    for k, (ix, iy) in enumerate((ix, iy) for ix in range(-3, 4) for iy in range(-3, 4)):
        light = UsdLux.SphereLight.Define(stage, f"/World/Spot{k}")
        light.AddTranslateOp().Set(Gf.Vec3d(ix * 0.9, iy * 0.9, 2.0))
        light.CreateRadiusAttr(0.02)
        light.CreateIntensityAttr(500.0)
        UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingIesFileAttr(Sdf.AssetPath(str(ies)))

    def render(spp: int, seed: int) -> np.ndarray:
        settings = {"samples": spp, "shadowSamples": 1, "seed": seed}
        with mipray.RenderSession(stage) as session:
            r = session.render("/World/Cam", width=96, settings=settings, camera_light=False)
        return np.asarray(r.aovs["color"][..., :3], dtype=np.float64)

    cached = tmp / "mipray_ies_tree_ref.npy"
    if cached.exists():
        ref = np.load(cached)
    else:
        ref = render(1024, 7)
        np.save(cached, ref)
    errors = sorted(float(np.sqrt(((render(4, s) - ref) ** 2).mean())) for s in range(5))
    start = time.perf_counter()
    render(4, 9)
    seconds = time.perf_counter() - start
    print(f"RMSE at 4 spp over 5 seeds: {errors}; median {errors[2]:.4f}; {seconds:.2f} s a render")


if __name__ == "__main__":
    main()
