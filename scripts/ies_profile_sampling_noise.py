"""Directions toward an IES light drawn by its profile, measured: RMSE against a 1,024-spp render.

A 2 × 2 rect light 0.5 above a floor, facing down, with a 20° IES beam: a floor point is lit
only by the patch of the rect within ~20° of straight above it, so area sampling wastes most
samples; ``--profile`` turns ``mipray:iesProfileSampling`` on. Prints the RMSE of five 4-spp
seeds against the reference, the images' mean over the reference's (the same mean), and the
time of one render. Run from the repository root with the extension built:
``.venv/bin/python scripts/ies_profile_sampling_noise.py [--profile]`` (the reference is cached
in the temporary directory under ``--tag``). docs/materials.md quotes its output.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, UsdLux

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from test_lights_shaping_linking import stage_with_camera

import mipray

ANGLES = [0, 10, 20, 90]
CANDELA = [100, 100, 0, 0]


def main() -> None:
    """Print the RMSE of five 4-spp seeds against the reference, their mean ratio, one's time."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--tag", default="ref", help="the cached reference's name")
    parser.add_argument(
        "--profile", action="store_true", help="mipray:iesProfileSampling on (off: by shape)"
    )
    args = parser.parse_args()
    tmp = Path(tempfile.gettempdir())
    ies = tmp / "mipray_ies_profile_beam.ies"
    ies.write_text(
        f"IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 {len(ANGLES)} 1 1 2 0 0 0\n1 1 10\n"
        f"{' '.join(map(str, ANGLES))}\n0\n{' '.join(map(str, CANDELA))}\n"
    )
    stage = stage_with_camera()
    light = UsdLux.RectLight.Define(stage, "/World/Panel")
    light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.5))
    light.CreateWidthAttr(2.0)
    light.CreateHeightAttr(2.0)
    light.CreateIntensityAttr(1.0)
    UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingIesFileAttr(Sdf.AssetPath(str(ies)))
    sampling = light.GetPrim().CreateAttribute("mipray:iesProfileSampling", Sdf.ValueTypeNames.Bool)
    sampling.Set(args.profile)

    def render(spp: int, seed: int) -> np.ndarray:
        settings = {"samples": spp, "shadowSamples": 1, "seed": seed}
        with mipray.RenderSession(stage) as session:
            r = session.render("/World/Cam", width=96, settings=settings, camera_light=False)
        return np.asarray(r.aovs["color"][..., :3], dtype=np.float64)

    cached = tmp / f"mipray_ies_profile_{args.tag}.npy"
    if cached.exists():
        ref = np.load(cached)
    else:
        ref = render(1024, 7)
        np.save(cached, ref)
    images = [render(4, s) for s in range(5)]
    errors = sorted(float(np.sqrt(((im - ref) ** 2).mean())) for im in images)
    ratio = float(np.mean([im.mean() for im in images]) / ref.mean())
    times = []
    for s in range(3):
        start = time.perf_counter()
        render(4, 9 + s)
        times.append(time.perf_counter() - start)
    print(
        f"RMSE at 4 spp over 5 seeds: {[round(e, 5) for e in errors]}; median {errors[2]:.5f}; "
        f"mean / reference {ratio:.4f}; {sorted(times)[1]:.2f} s a render (median of 3)"
    )


if __name__ == "__main__":
    main()
