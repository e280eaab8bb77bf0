#!/usr/bin/env python3
"""Make the textures of ``examples/textured.usda``: brick colour and height maps.

They are drawn with numpy, written through OpenImageIO (``mipray._mipray.write_image``) and
turned into tiled MIP maps with OpenImageIO's ``maketx``.

    .venv/bin/python examples/make_textures.py [OUTPUT_DIR]     (default examples/textures)

Writes ``bricks_color.tx`` and ``bricks_height.tx``; skips files that are already there.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

SIZE = 1024
ROWS = 8
COLS = 4


def bricks() -> tuple[np.ndarray, np.ndarray]:
    """(colour H×W×3, height H×W×1) float32 for a running-bond brick wall."""
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32) / SIZE
    row = np.floor(y * ROWS)
    xs = x * COLS + 0.5 * (row % 2)
    col = np.floor(xs)
    fx, fy = xs - col, y * ROWS - row
    mortar = 0.06
    edge = np.minimum(np.minimum(fx, 1 - fx) * (ROWS / COLS), np.minimum(fy, 1 - fy))
    brick = np.clip((edge - mortar / 2) / (mortar / 2), 0.0, 1.0)
    rng = np.random.default_rng(7)
    tint = rng.uniform(0.75, 1.15, size=(ROWS + 1, COLS + 2))
    t = tint[row.astype(int) % (ROWS + 1), col.astype(int) % (COLS + 2)]
    grain = 0.9 + 0.1 * np.sin(x * 311.0) * np.sin(y * 173.0)
    red = np.stack([0.55 * t * grain, 0.22 * t * grain, 0.15 * t * grain], axis=-1)
    grey = np.full_like(red, 0.45)
    colour = red * brick[..., None] + grey * (1 - brick[..., None])
    return colour.astype(np.float32), brick[..., None].astype(np.float32)


def main(argv: list[str]) -> int:
    """Write the textures; returns the exit code."""
    out = Path(argv[0]) if argv else Path(__file__).parent / "textures"
    out.mkdir(parents=True, exist_ok=True)
    maketx = shutil.which("maketx")
    if maketx is None:
        print(
            "make_textures: maketx not found (apt-get install openimageio-tools)", file=sys.stderr
        )
        return 1
    from mipray import _mipray

    targets = {"bricks_color": None, "bricks_height": None}
    if all((out / f"{n}.tx").exists() for n in targets):
        return 0
    colour, height = bricks()
    for name, img, channels in (
        ("bricks_color", colour, "color"),
        ("bricks_height", height, "height"),
    ):
        src = out / f"{name}.exr"
        _mipray.write_image(str(src), {channels: img}, [channels], {channels: "float"})
        subprocess.run(
            [maketx, "--oiio", "--wrap", "periodic", str(src), "-o", str(out / f"{name}.tx")],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        src.unlink()
        print(out / f"{name}.tx")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
