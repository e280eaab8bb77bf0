"""Write a Catmull-Clark pole as an OBJ shape: one centre vertex and ``n`` quads fanned around it.

    python3 scripts/pole_shape.py 360 > catmark_val360.obj
    .venv/bin/mipray-subdiv-compare --json catmark_val360.obj

The disk is slightly domed (the centre above its first ring, the outer ring below it) so the
limit surface is not planar; vertex ``i`` of the first ring is at angle 2πi/n, the outer ring
half a step further. The cost of ``mipray-subdiv-compare`` at high valence (issue 15) is measured
on it; catmark_pole64 in ``../shared/osd-shapes`` is the same kind of shape, closed.
"""

from __future__ import annotations

import math
import sys


def pole_obj(n: int) -> str:
    """The OBJ text of a disk of ``n`` quads around one vertex of valence ``n`` (n ≥ 3)."""
    if n < 3:
        raise ValueError(f"a pole needs at least 3 quads, got {n}")
    # The shape format's header names the scheme.
    lines = [f"# {n} quads around one vertex (scripts/pole_shape.py), scheme: catmark"]
    lines.append("v 0 0 0.3")
    for i in range(n):
        a = 2.0 * math.pi * i / n
        b = 2.0 * math.pi * (i + 0.5) / n
        lines.append(f"v {math.cos(a):.9g} {math.sin(a):.9g} 0.1")
        lines.append(f"v {1.4 * math.cos(b):.9g} {1.4 * math.sin(b):.9g} 0")
    # OBJ indices are 1-based: the centre is 1, ring vertex i is 2 + 2i, outer vertex i 3 + 2i.
    for i in range(n):
        j = (i + 1) % n
        lines.append(f"f 1 {2 + 2 * i} {3 + 2 * i} {2 + 2 * j}")
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    """Write the OBJ of ``argv[1]`` quads to stdout; returns the exit status."""
    if len(argv) != 2 or not argv[1].isdigit():
        print("usage: pole_shape.py N  (writes the OBJ to stdout)", file=sys.stderr)
        return 2
    try:
        sys.stdout.write(pole_obj(int(argv[1])))
    except ValueError as e:
        print(f"pole_shape.py: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
