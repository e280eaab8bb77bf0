"""``mipray-subdiv-compare``: mipray's subdivision results compared with OpenSubdiv's.

    mipray-subdiv-compare shapes/catmark_pole8.obj
    mipray-subdiv-compare --json scene.usda:/World/Body
    mipray-subdiv-compare --heatmap err.png --heatmap-rate 2 shape.obj

The input is an OBJ in OpenSubdiv's regression-shape format (``t`` tags for
creases, corners, holes, boundary rules) or a ``UsdGeom.Mesh`` given as
``file.usda:/Prim/Path`` (read with :func:`mipray.usd.mesh.mesh_arguments`).
The comparison itself runs in Rust (``mipray._mipray.subdiv_compare``): limit
evaluation against OpenSubdiv's own (its patch table and basis), each tier's, rate's and
split's tessellation against the limit surface, the seams between rates, and
OpenSubdiv's uniform refinement. See docs/subdivision-compare.md.

A table (or one JSON object with ``--json``) goes to stdout; one-line errors
(``mipray-subdiv-compare: ...``) to stderr. Exit status 0 when compared, 1 on
failure (shapes with hierarchical edits are refused as not supported).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

__all__ = ["build_parser", "compare", "main", "split_usd_input"]

PROG = "mipray-subdiv-compare"
RATES = (1, 2, 4, 8, 16)


class _UsageError(Exception):
    """A bad command line."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{message} (see --help)")


def _non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


_non_negative_int.__name__ = "integer >= 0"


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser (documented by ``--help``)."""
    parser = _Parser(
        prog=PROG,
        description=(
            "Compare mipray's limit evaluation, tessellations and seams with\n"
            "OpenSubdiv's. Errors are relative to the control mesh's bounding-box diagonal."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  mipray-subdiv-compare shapes/catmark_pole8.obj\n"
            "  mipray-subdiv-compare --json scene.usda:/World/Body\n"
            "  mipray-subdiv-compare --heatmap err.png shape.obj"
        ),
    )
    parser.add_argument("input", help="an OBJ shape file, or file.usd[a|c|z]:/Prim/Path")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--heatmap", metavar="FILE", help="draw the tessellation error (PNG, ...)")
    parser.add_argument(
        "--heatmap-rate",
        type=int,
        choices=RATES,
        default=4,
        help="rate drawn, quads per patch side (default 4)",
    )
    parser.add_argument(
        "--level",
        type=_non_negative_int,
        default=2,
        help="OpenSubdiv uniform refinement level to compare with (default 2; 0 skips)",
    )
    parser.add_argument(
        "--samples", type=_non_negative_int, default=5, help="limit samples per patch side"
    )
    parser.add_argument(
        "--patches",
        type=_non_negative_int,
        default=512,
        help="patches whose tessellations are measured (0 = all)",
    )
    parser.add_argument(
        "--split-depth", type=_non_negative_int, default=2, help="deepest split measured"
    )
    parser.add_argument(
        "--split-patches",
        type=_non_negative_int,
        default=64,
        help="patches whose split children are measured (0 = all)",
    )
    parser.add_argument("--quick", action="store_true", help="the corpus test's small settings")
    parser.add_argument("--time", metavar="T", help="USD time code (default: the default time)")
    return parser


def split_usd_input(text: str) -> tuple[str, str] | None:
    """``("file.usda", "/Prim/Path")`` for a USD input, or None for anything else.

    The split is at the last ``:/`` whose left part names a USD file, so
    paths with colons (``C:/...``) still work.
    """
    at = text.rfind(":/")
    while at > 0:
        path, prim = text[:at], text[at + 1 :]
        if os.path.splitext(path)[1].lower() in (".usd", ".usda", ".usdc", ".usdz"):
            return path, prim
        at = text.rfind(":/", 0, at)
    return None


def _usd_mesh_kwargs(path: str, prim_path: str, time: str | None) -> dict[str, Any]:
    import numpy as np
    from pxr import Usd, UsdGeom

    from ..errors import PrimError
    from ..session import open_stage
    from ..usd.mesh import mesh_arguments

    stage = open_stage(path)
    prim = stage.GetPrimAtPath(prim_path)
    if not prim or not prim.IsValid():
        raise PrimError(prim_path, f"no such prim in {path}")
    if not prim.IsA(UsdGeom.Mesh):
        raise PrimError(prim_path, f"is a {prim.GetTypeName() or 'typeless prim'}, not a Mesh")
    code = Usd.TimeCode(float(time)) if time is not None else Usd.TimeCode.Default()
    args = mesh_arguments(UsdGeom.Mesh(prim), code, np.eye(4))
    if args is None:
        raise PrimError(prim_path, "the mesh has no faces")
    for key in ("transform", "double_sided"):
        args.pop(key, None)
    return args


def compare(
    input_spec: str,
    *,
    table: bool = False,
    heatmap: str | None = None,
    heatmap_rate: int = 4,
    uniform_level: int = 2,
    samples_per_side: int = 5,
    tessellation_patches: int = 512,
    split_depth: int = 2,
    split_patches: int = 64,
    quick: bool = False,
    time: str | None = None,
) -> Any:
    """Compare one mesh; returns the report as a dict (or the table text with ``table``).

    Raises:
        MiprayError: the USD stage or prim cannot be used.
        OSError: the OBJ file cannot be read.
        ValueError: the mesh is refused (message names it; "not supported" for
            hierarchical edits).

    """
    from .. import _mipray

    options: dict[str, Any] = {
        "uniform_level": uniform_level,
        "samples_per_side": samples_per_side,
        "tessellation_patches": tessellation_patches,
        "split_depth": split_depth,
        "split_patches": split_patches,
        "quick": quick,
        "table": table,
        "heatmap": heatmap,
        "heatmap_rate": heatmap_rate,
    }
    usd = split_usd_input(input_spec)
    if usd is not None:
        path, prim_path = usd
        out = _mipray.subdiv_compare(
            prim_path, **_usd_mesh_kwargs(path, prim_path, time), **options
        )
    else:
        with open(input_spec, encoding="utf-8") as f:
            text = f.read()
        name = os.path.splitext(os.path.basename(input_spec))[0]
        out = _mipray.subdiv_compare(name, obj_text=text, **options)
    return out if table else json.loads(out)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; returns the exit status."""
    from ..errors import MiprayError

    try:
        args = build_parser().parse_args(argv)
    except _UsageError as e:
        print(f"{PROG}: {e}", file=sys.stderr)
        return 1
    try:
        out = compare(
            args.input,
            table=not args.json,
            heatmap=args.heatmap,
            heatmap_rate=args.heatmap_rate,
            uniform_level=args.level,
            samples_per_side=args.samples,
            tessellation_patches=args.patches,
            split_depth=args.split_depth,
            split_patches=args.split_patches,
            quick=args.quick,
            time=args.time,
        )
    except (MiprayError, OSError, ValueError) as e:
        print(f"{PROG}: {e}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(out))
    else:
        print(out, end="")
        if args.heatmap:
            print(f"{'heatmap':<44} {args.heatmap} (rate {args.heatmap_rate})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
