"""Control cages for generated benchmark scenes: lumpy blobs, creased boxes and wheels.

Each function returns plain lists (points, face-vertex counts or indices, crease edges) in the
shape's own object space, so a scene script can transform them and write them as a
``UsdGeom.Mesh``. Points are unrounded; rounding for a deterministic ``.usda`` is the writer's.
"""

from __future__ import annotations

import math
import random

__all__ = ["Cage", "blob_cage", "box_cage", "cube_grid", "wheel_cage"]

Point = tuple[float, float, float]

# The six cube faces as (normal, a, b) with a × b = normal, so quads wind outward.
_FACES = (
    ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
    ((0, 1, 0), (0, 0, 1), (1, 0, 0)),
    ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
    ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
    ((0, 0, -1), (0, 1, 0), (1, 0, 0)),
)


class Cage:
    """A control cage: points, face-vertex counts and indices, and crease edges.

    ``creases`` holds ``(a, b, sharpness)`` per crease edge (OpenSubdiv's sharpness: 10 is
    infinitely sharp).
    """

    def __init__(self) -> None:
        self.points: list[Point] = []
        self.counts: list[int] = []
        self.indices: list[int] = []
        self.creases: list[tuple[int, int, float]] = []

    def append(self, other: Cage) -> None:
        """Add ``other``'s faces and creases after this cage's, its indices offset."""
        base = len(self.points)
        self.points += other.points
        self.counts += other.counts
        self.indices += [i + base for i in other.indices]
        self.creases += [(a + base, b + base, s) for a, b, s in other.creases]


def _face_point(face: tuple[tuple[int, ...], ...], s: float, t: float) -> Point:
    """The point at (s, t) ∈ [0, 1]² of a cube face given as (normal, a, b)."""
    nrm, a, b = face
    u, v = 2.0 * s - 1.0, 2.0 * t - 1.0
    x, y, z = (nrm[k] + a[k] * u + b[k] * v for k in range(3))
    return (x, y, z)


def cube_grid(divisions: tuple[int, int, int]) -> tuple[list[Point], list[int]]:
    """The surface of the cube [-1, 1]³ as a quad grid of ``divisions`` quads along x, y, z.

    Returns (points, face-vertex indices), four indices a quad, wound outward; a point shared
    by several faces appears once, in the order first met (faces in ``_FACES`` order, rows,
    columns).
    """
    points: list[Point] = []
    index: dict[tuple[int, int, int], int] = {}

    def vertex(p: Point) -> int:
        key = (round(p[0] * 4096), round(p[1] * 4096), round(p[2] * 4096))
        if key not in index:
            points.append(p)
            index[key] = len(points) - 1
        return index[key]

    indices: list[int] = []
    for face in _FACES:
        na = divisions[face[1].index(1)]
        nb = divisions[face[2].index(1)]
        for j in range(nb):
            for i in range(na):
                corners = ((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1))
                indices += [vertex(_face_point(face, ci / na, cj / nb)) for ci, cj in corners]
    return points, indices


def blob_cage(n: int, rng: random.Random) -> tuple[list[Point], list[int]]:
    """A closed lumpy control cage: ``6·n²`` quads, as (points, face-vertex indices).

    A cube of n² quads a side pushed onto the unit sphere and dented by five smooth lumps drawn
    from ``rng``.
    """
    lumps = []
    for _ in range(5):
        d = [rng.uniform(-0.5, 0.5) for _ in range(3)]
        length = math.sqrt(sum(c * c for c in d)) or 1.0
        lumps.append(([c / length for c in d], 0.5 * (rng.random() - 0.4)))
    cube, indices = cube_grid((n, n, n))
    points: list[Point] = []
    for p in cube:
        length = math.sqrt(sum(c * c for c in p))
        s = [c / length for c in p]
        r = 1.0 + sum(
            a * math.exp(-(1.0 - sum(si * di for si, di in zip(s, d, strict=True))) * 4.0)
            for d, a in lumps
        )
        points.append((s[0] * r, s[1] * r, s[2] * r))
    return points, indices


def box_cage(
    size: tuple[float, float, float], divisions: tuple[int, int, int], sharpness: float
) -> Cage:
    """A box of ``size`` (full extents, centred at the origin) with its 12 edges creased.

    ``divisions`` quads along x, y, z; every control edge on a box edge gets ``sharpness``, so
    the limit surface has rounded but crisp edges, like a car body.
    """
    cube, indices = cube_grid(divisions)
    cage = Cage()
    cage.points = [(p[0] * size[0] / 2, p[1] * size[1] / 2, p[2] * size[2] / 2) for p in cube]
    cage.counts = [4] * (len(indices) // 4)
    cage.indices = indices

    def on_box_edge(p: Point, q: Point) -> bool:
        # Both ends on the same two faces of the cube (the same ±1 in two coordinates).
        same = [k for k in range(3) if abs(abs(p[k]) - 1.0) < 1e-9 and p[k] == q[k]]
        return len(same) >= 2

    seen: set[tuple[int, int]] = set()
    for f in range(0, len(indices), 4):
        quad = indices[f : f + 4]
        for k in range(4):
            a, b = quad[k], quad[(k + 1) % 4]
            edge = (min(a, b), max(a, b))
            if edge in seen:
                continue
            seen.add(edge)
            if on_box_edge(cube[a], cube[b]):
                cage.creases.append((edge[0], edge[1], sharpness))
    return cage


def wheel_cage(radius: float, width: float, segments: int, sharpness: float) -> Cage:
    """A wheel: a cylinder along z, centred at the origin, capped by two ``segments``-gons.

    The side is ``segments`` × 2 quads (a middle ring bulges the tyre by 4 %); both rims are
    creased with ``sharpness``. The caps are single n-gons, so the cage has two extraordinary
    faces (each becomes an extraordinary vertex of valence ``segments`` after one step).
    """
    cage = Cage()
    rings = ((-width / 2, 1.0), (0.0, 1.04), (width / 2, 1.0))
    for z, bulge in rings:
        for s in range(segments):
            angle = 2.0 * math.pi * s / segments
            r = radius * bulge
            cage.points.append((r * math.cos(angle), r * math.sin(angle), z))
    for ring in range(len(rings) - 1):
        for s in range(segments):
            a = ring * segments + s
            b = ring * segments + (s + 1) % segments
            cage.counts.append(4)
            # Around, then along +z: (tangent × z) points outward.
            cage.indices += [a, b, b + segments, a + segments]
    last = (len(rings) - 1) * segments
    # Caps wound outward: the -z cap clockwise seen from +z, the +z cap counter-clockwise.
    cage.counts += [segments, segments]
    cage.indices += [(segments - s) % segments for s in range(segments)]
    cage.indices += [last + s for s in range(segments)]
    for rim in (0, last):
        for s in range(segments):
            cage.creases.append((rim + s, rim + (s + 1) % segments, sharpness))
    return cage
