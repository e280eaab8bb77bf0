"""The two scenes of ``make bench-throughput``, and their export for the Embree harness.

- *plain*: creased Catmull-Clark cars (a box body and a box cabin with creased edges, four
  wheels with creased rims and n-gon caps) on a polygonal ground under a sun;
- *displaced*: lumpy Catmull-Clark blobs (:func:`mipray.tools.shapes.blob_cage`) whose
  UsdPreviewSurface ``displacement`` reads a height texture (UsdUVTexture on vertex ``st``),
  on the same kind of ground under the same kind of sun.

Both are deterministic (coordinates rounded to 6 decimals, a fixed seed), written as ``.usda``
with world-space points (no transforms), a square camera and a sun of angle 0 (a delta light:
exactly one shadow ray per lit shading point).

:func:`export_stage` reads a stage back — through the same readers mipray's USD front end uses
— into a small little-endian binary file (:data:`MAGIC`, laid out in :func:`export_stage`'s
docstring) that ``scripts/bench/embree_throughput.cpp`` loads: camera, sun direction, and per
mesh its scheme, points, face counts and indices, crease edges with their sharpness, corners,
vertex ``st`` and the displacement texture. :func:`read_export` reads it back for tests.
"""

from __future__ import annotations

import math
import random
import shutil
import struct
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

from ..usd.camera import camera_arguments
from ..usd.mesh import mesh_arguments
from ..usd.transform import world_transform
from .shapes import Cage, blob_cage, box_cage, wheel_cage
from .stage import look_at, new_stage

__all__ = [
    "MAGIC",
    "SCENES",
    "ExportError",
    "ExportedMesh",
    "ExportedScene",
    "crease_edges",
    "export_stage",
    "read_export",
    "write_displaced",
    "write_height_texture",
    "write_plain",
]

#: First bytes of an export file, then a u32 format version.
MAGIC = b"MPRYTHRU"
VERSION = 1
#: Scheme codes in an export file.
SCHEME_CODES = {"none": 0, "catmullClark": 1}
#: UsdUVTexture wrap tokens → the export's codes (OpenImageIO's black, clamp, periodic, mirror).
WRAP_CODES = {"black": 0, "clamp": 1, "repeat": 2, "mirror": 3, "useMetadata": 2}
#: The scenes by name.
SCENES = ("plain", "displaced")

#: ``st`` per world unit on the blobs: ``st = ST_PER_UNIT · (x, z)``, a projection from above,
#: so a texture tile spans 4 units (two blobs).
ST_PER_UNIT = 0.25
#: Height texture → object units: ``texel · DISPLACEMENT_SCALE + DISPLACEMENT_BIAS``.
DISPLACEMENT_SCALE = 0.08
DISPLACEMENT_BIAS = -0.04


class ExportError(Exception):
    """A stage the export cannot describe to the harness (message names the prim)."""


def _round(points: list[tuple[float, float, float]] | NDArray[Any]) -> list[Gf.Vec3f]:
    return [Gf.Vec3f(*(round(float(c), 6) + 0.0 for c in p)) for p in points]


def _stage(path: Path, doc: str) -> Usd.Stage:
    stage = new_stage(path, doc)
    UsdGeom.Scope.Define(stage, "/World/Looks")
    UsdGeom.Scope.Define(stage, "/World/Geo")
    return stage


def _preview(stage: Usd.Stage, name: str, rgb: tuple[float, float, float]) -> UsdShade.Material:
    """A diffuse UsdPreviewSurface (the reflection pass turns every one into a mirror)."""
    material = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
    shader = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*rgb))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.7)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def _mesh(stage: Usd.Stage, path: str, cage: Cage, scheme: str) -> UsdGeom.Mesh:
    mesh = UsdGeom.Mesh.Define(stage, path)
    points = _round(cage.points)
    mesh.CreatePointsAttr(points)
    mesh.CreateFaceVertexCountsAttr(cage.counts)
    mesh.CreateFaceVertexIndicesAttr(cage.indices)
    mesh.CreateSubdivisionSchemeAttr(scheme)
    if cage.creases:
        # One crease per edge: the simplest encoding USD has, and the harness's.
        mesh.CreateCreaseIndicesAttr([i for a, b, _ in cage.creases for i in (a, b)])
        mesh.CreateCreaseLengthsAttr([2] * len(cage.creases))
        mesh.CreateCreaseSharpnessesAttr([s for _, _, s in cage.creases])
    lo = [min(p[k] for p in points) for k in range(3)]
    hi = [max(p[k] for p in points) for k in range(3)]
    mesh.CreateExtentAttr([Gf.Vec3f(*lo), Gf.Vec3f(*hi)])
    return mesh


def _ground(stage: Usd.Stage, half: float) -> None:
    cage = Cage()
    cage.points = [(-half, 0.0, -half), (-half, 0.0, half), (half, 0.0, half), (half, 0.0, -half)]
    cage.counts = [4]
    cage.indices = [0, 1, 2, 3]
    ground = _mesh(stage, "/World/Geo/Ground", cage, "none")
    look = _preview(stage, "Ground", (0.5, 0.5, 0.5))
    UsdShade.MaterialBindingAPI.Apply(ground.GetPrim()).Bind(look)


def _camera_and_sun(stage: Usd.Stage, eye: Gf.Vec3d, target: Gf.Vec3d, focal: float) -> None:
    """A square camera (36 mm film) at ``eye`` looking at ``target``, and a delta sun."""
    camera = UsdGeom.Camera.Define(stage, "/World/main_cam")
    camera.CreateFocalLengthAttr(focal)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(36.0)
    camera.CreateClippingRangeAttr(Gf.Vec2f(0.1, 1000.0))
    camera.AddTransformOp().Set(look_at(eye, target))
    sun = UsdLux.DistantLight.Define(stage, "/World/Lights/Sun")
    sun.CreateIntensityAttr(3.0)
    # Angle 0: a delta light, one shadow ray per lit point in mipray, as in the harness.
    sun.CreateAngleAttr(0.0)
    UsdLux.ShadowAPI.Apply(sun.GetPrim()).CreateShadowEnableAttr(True)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(-50.0, -35.0, 0.0))


def _transformed(cage: Cage, scale: tuple[float, float, float], yaw: float, at: Gf.Vec3d) -> Cage:
    """``cage`` scaled, turned ``yaw`` degrees about +y and moved to ``at`` (world space)."""
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    out = Cage()
    out.counts, out.indices, out.creases = cage.counts, cage.indices, cage.creases
    for x, y, z in cage.points:
        x, y, z = x * scale[0], y * scale[1], z * scale[2]
        out.points.append((c * x + s * z + at[0], y + at[1], -s * x + c * z + at[2]))
    return out


def car_cage(rng: random.Random) -> Cage:
    """One car, nose along +x, wheels on y = 0: 324 control faces, creased edges and rims."""
    length = rng.uniform(3.8, 4.4)
    car = box_cage((length, 0.8, 1.8), (8, 3, 4), sharpness=2.0)
    car = _transformed(car, (1, 1, 1), 0.0, Gf.Vec3d(0.0, 0.75, 0.0))
    cabin = box_cage((length * 0.5, 0.7, 1.6), (4, 2, 3), sharpness=1.5)
    car.append(_transformed(cabin, (1, 1, 1), 0.0, Gf.Vec3d(-0.1 * length, 1.45, 0.0)))
    wheel = wheel_cage(0.38, 0.3, segments=16, sharpness=3.0)
    for x in (-0.32 * length, 0.32 * length):
        for z in (-0.85, 0.85):
            car.append(_transformed(wheel, (1, 1, 1), 0.0, Gf.Vec3d(x, 0.38, z)))
    return car


def write_plain(path: Path, grid: tuple[int, int] = (6, 3), seed: int = 14) -> Path:
    """Write the *plain* scene: ``grid`` cars (across x, rows in depth) of 324 faces each."""
    rng = random.Random(seed)
    stage = _stage(
        path,
        f"mipray throughput benchmark, plain: {grid[0] * grid[1]} creased Catmull-Clark cars. "
        "Generated by python -m mipray.tools.throughput (mipray/tools/throughput_scenes.py).",
    )
    paints = [
        _preview(stage, name, rgb)
        for name, rgb in (
            ("Red", (0.6, 0.1, 0.08)),
            ("Blue", (0.1, 0.2, 0.55)),
            ("Silver", (0.6, 0.6, 0.62)),
        )
    ]
    spacing = (5.5, 3.6)
    for j in range(grid[1]):
        for i in range(grid[0]):
            k = j * grid[0] + i
            x = (i - (grid[0] - 1) / 2) * spacing[0] + rng.uniform(-0.4, 0.4)
            z = -j * spacing[1] + rng.uniform(-0.3, 0.3)
            cage = _transformed(car_cage(rng), (1, 1, 1), rng.uniform(-25, 25), Gf.Vec3d(x, 0, z))
            mesh = _mesh(stage, f"/World/Geo/Car_{k:03d}", cage, "catmullClark")
            UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(paints[k % len(paints)])
    _ground(stage, 60.0)
    width = grid[0] * spacing[0]
    depth = (grid[1] - 1) * spacing[1]
    _camera_and_sun(
        stage,
        Gf.Vec3d(0.0, 0.5 * width + 2.0, 0.4 * width + 2.0),
        Gf.Vec3d(0.0, 0.5, -0.5 * depth),
        focal=34.0,
    )
    stage.GetRootLayer().Save()
    return path


def height_image(size: int) -> NDArray[np.float32]:
    """A periodic height field in [0, 1]: 8×8 round bumps with a finer ripple (H×W×1)."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64) / size
    bumps = np.sin(np.pi * ((8 * x) % 1.0)) * np.sin(np.pi * ((8 * y) % 1.0))
    ripple = 0.5 + 0.5 * np.sin(2 * np.pi * (32 * x + 16 * y))
    height = 0.75 * bumps**2 + 0.25 * ripple
    out: NDArray[np.float32] = height[..., None].astype(np.float32)
    return out


def write_height_texture(path: Path, size: int = 1024) -> Path:
    """Write :func:`height_image` as a tiled, MIP-mapped ``.tx`` (maketx, periodic wrap).

    Raises:
        ExportError: ``maketx`` (openimageio-tools) is not installed.

    """
    maketx = shutil.which("maketx")
    if maketx is None:
        raise ExportError(f"{path}: maketx not found (apt-get install openimageio-tools)")
    from .. import _mipray

    src = path.with_suffix(".exr")
    _mipray.write_image(str(src), {"height": height_image(size)}, ["height"], {"height": "float"})
    subprocess.run(
        [maketx, "--oiio", "--wrap", "periodic", str(src), "-o", str(path)],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    src.unlink()
    return path


def _displaced_material(stage: Usd.Stage, texture: str) -> UsdShade.Material:
    """A diffuse UsdPreviewSurface displaced by ``texture``'s r along the normal."""
    material = _preview(stage, "Blob", (0.55, 0.45, 0.35))
    surface = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/Blob/PreviewSurface"))
    reader = UsdShade.Shader.Define(stage, "/World/Looks/Blob/StReader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    height = UsdShade.Shader.Define(stage, "/World/Looks/Blob/HeightTexture")
    height.CreateIdAttr("UsdUVTexture")
    height.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(texture)
    height.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
    height.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
    height.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
    height.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(DISPLACEMENT_SCALE))
    height.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(DISPLACEMENT_BIAS))
    surface.CreateInput("displacement", Sdf.ValueTypeNames.Float).ConnectToSource(
        height.CreateOutput("r", Sdf.ValueTypeNames.Float)
    )
    material.CreateDisplacementOutput().ConnectToSource(surface.ConnectableAPI(), "displacement")
    return material


def write_displaced(
    path: Path,
    texture: str,
    grid: tuple[int, int] = (6, 6),
    face_res: int = 6,
    seed: int = 2003,
) -> Path:
    """Write the *displaced* scene: ``grid`` blobs of ``6·face_res²`` faces, texture-displaced.

    ``texture`` is the height texture's asset path as written (relative to ``path``'s
    directory, or absolute). Each blob's ``st`` is vertex-interpolated, ``ST_PER_UNIT · (x, z)``
    of its world-space control points.
    """
    rng = random.Random(seed)
    stage = _stage(
        path,
        f"mipray throughput benchmark, displaced: {grid[0] * grid[1]} texture-displaced "
        "Catmull-Clark blobs. Generated by python -m mipray.tools.throughput "
        "(mipray/tools/throughput_scenes.py).",
    )
    look = _displaced_material(stage, texture)
    spacing = 2.4
    for j in range(grid[1]):
        for i in range(grid[0]):
            k = j * grid[0] + i
            cage = Cage()
            cage.points, cage.indices = blob_cage(face_res, rng)
            cage.counts = [4] * (len(cage.indices) // 4)
            s = rng.uniform(0.7, 1.0)
            lowest = min(p[1] for p in cage.points)
            x = (i - (grid[0] - 1) / 2) * spacing + rng.uniform(-0.3, 0.3)
            z = -j * spacing + rng.uniform(-0.3, 0.3)
            at = Gf.Vec3d(x, -lowest * s, z)
            cage = _transformed(cage, (s, s, s), rng.uniform(0.0, 360.0), at)
            mesh = _mesh(stage, f"/World/Geo/Blob_{k:03d}", cage, "catmullClark")
            points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
            st = [
                Gf.Vec2f(round(ST_PER_UNIT * p[0], 6), round(ST_PER_UNIT * p[2], 6)) for p in points
            ]
            UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
                "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
            ).Set(st)
            UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
                "displacementBound", Sdf.ValueTypeNames.Float, UsdGeom.Tokens.constant
            ).Set(max(abs(DISPLACEMENT_SCALE + DISPLACEMENT_BIAS), abs(DISPLACEMENT_BIAS)))
            UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(look)
    _ground(stage, 60.0)
    width = grid[0] * spacing
    depth = (grid[1] - 1) * spacing
    _camera_and_sun(
        stage,
        Gf.Vec3d(0.0, 0.6 * depth + 4.5, 7.0),
        Gf.Vec3d(0.0, 0.4, -0.45 * depth),
        focal=2.4 * 36.0 * 6.0 / max(width, 1.0),
    )
    stage.GetRootLayer().Save()
    return path


# --- export -------------------------------------------------------------------------------


def crease_edges(
    indices: NDArray[Any] | None, lengths: NDArray[Any] | None, sharpnesses: NDArray[Any] | None
) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
    """USD creases (chains of ``lengths`` vertices) as edges: ((n, 2) pairs, (n,) sharpness).

    USD gives one sharpness per crease or one per crease edge; both are expanded to one per
    edge, as Embree's ``RTC_BUFFER_TYPE_EDGE_CREASE_*`` buffers take them.
    """
    if indices is None or lengths is None or sharpnesses is None:
        return np.zeros((0, 2), np.int32), np.zeros(0, np.float32)
    per_edge = len(sharpnesses) == int(np.sum(np.asarray(lengths) - 1)) and len(sharpnesses) != len(
        lengths
    )
    pairs: list[tuple[int, int]] = []
    weights: list[float] = []
    start = 0
    for c, n in enumerate(lengths):
        chain = indices[start : start + n]
        for e in range(n - 1):
            pairs.append((int(chain[e]), int(chain[e + 1])))
            weights.append(float(sharpnesses[len(weights) if per_edge else c]))
        start += n
    return np.asarray(pairs, np.int32).reshape(-1, 2), np.asarray(weights, np.float32)


@dataclass
class ExportedMesh:
    """One mesh as the harness reads it; points in world space."""

    path: str
    scheme: str
    points: NDArray[np.float32]
    counts: NDArray[np.int32]
    indices: NDArray[np.int32]
    crease_pairs: NDArray[np.int32]
    crease_weights: NDArray[np.float32]
    corner_indices: NDArray[np.int32]
    corner_weights: NDArray[np.float32]
    #: Vertex-interpolated ``st`` (n, 2), or None.
    st: NDArray[np.float32] | None = None
    #: Displacement texture (absolute path), ``scale``, ``bias`` (object units per texel unit,
    #: object units), channel, wrap s and t codes (:data:`WRAP_CODES`); None if undisplaced.
    displacement: tuple[str, float, float, int, int, int] | None = None


@dataclass
class ExportedScene:
    """What the harness traces: camera, sun and meshes (world space)."""

    #: Camera position, and the world-space offsets of the image's right and top edges from
    #: the view direction at unit distance (``right`` = X axis · tan(half horizontal fov)).
    eye: tuple[float, float, float]
    forward: tuple[float, float, float]
    right: tuple[float, float, float]
    up: tuple[float, float, float]
    #: Unit direction toward the sun.
    to_sun: tuple[float, float, float]
    meshes: list[ExportedMesh] = field(default_factory=list)


def _displacement(prim: Usd.Prim, st: NDArray[Any] | None) -> tuple[Any, ...] | None:
    """The bound UsdPreviewSurface's displacement texture, as :attr:`ExportedMesh.displacement`."""
    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    if not material:
        return None
    output = material.GetDisplacementOutput()
    if not output or not output.HasConnectedSource():
        return None
    surface = UsdShade.Shader(output.GetConnectedSource()[0].GetPrim())
    disp = surface.GetInput("displacement")
    if not disp or not disp.HasConnectedSource():
        return None
    source, channel_name, _ = disp.GetConnectedSource()
    texture = UsdShade.Shader(source.GetPrim())
    where = f"{prim.GetPath()}: displacement from {texture.GetPath()}"
    if texture.GetIdAttr().Get() != "UsdUVTexture":
        raise ExportError(f"{where} is not a UsdUVTexture; the harness reads only those")
    if st is None:
        raise ExportError(f"{prim.GetPath()}: a displacement texture needs a vertex primvar st")
    channels = {"r": 0, "g": 1, "b": 2, "a": 3}
    if channel_name not in channels:
        raise ExportError(f"{where}: output {channel_name!r} is not one of r, g, b, a")
    channel = channels[channel_name]
    asset = texture.GetInput("file").Get()
    resolved = asset.resolvedPath if asset is not None else ""
    if not resolved:
        raise ExportError(f"{where}: inputs:file {asset} does not resolve to a file")

    def component(name: str, default: float) -> float:
        value = texture.GetInput(name).Get() if texture.GetInput(name) else None
        return default if value is None else float(value[channel])

    def wrap(name: str) -> int:
        value = texture.GetInput(name).Get() if texture.GetInput(name) else None
        token = str(value) if value else "useMetadata"
        if token not in WRAP_CODES:
            raise ExportError(f"{where}: inputs:{name} {token!r} is not a UsdUVTexture wrap")
        return WRAP_CODES[token]

    scale, bias = component("scale", 1.0), component("bias", 0.0)
    return (resolved, scale, bias, channel, wrap("wrapS"), wrap("wrapT"))


def _vertex_st(prim: Usd.Prim, n_points: int) -> NDArray[np.float32] | None:
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    if not primvar or not primvar.HasValue():
        return None
    if primvar.GetInterpolation() != UsdGeom.Tokens.vertex:
        raise ExportError(
            f"{prim.GetPath()}: primvars:st is {primvar.GetInterpolation()}; the harness reads "
            "only vertex st"
        )
    values = np.asarray(primvar.ComputeFlattened(), dtype=np.float32).reshape(-1, 2)
    if len(values) != n_points:
        raise ExportError(f"{prim.GetPath()}: primvars:st has {len(values)} values, not {n_points}")
    return values


def _vec(v: Any) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def read_stage(usd_path: Path) -> ExportedScene:
    """The stage at ``usd_path`` as :class:`ExportedScene` (camera ``main_cam``, one sun).

    Raises:
        ExportError: no camera or distant light, or a mesh the harness cannot take.

    """
    stage = Usd.Stage.Open(str(usd_path))
    if stage is None:
        raise ExportError(f"{usd_path}: cannot open the stage")
    time = Usd.TimeCode.Default()
    xforms = UsdGeom.XformCache(time)
    cameras = [p for p in stage.Traverse() if p.IsA(UsdGeom.Camera)]
    suns = [p for p in stage.Traverse() if p.IsA(UsdLux.DistantLight)]
    if len(cameras) != 1 or len(suns) != 1:
        raise ExportError(
            f"{usd_path}: {len(cameras)} cameras and {len(suns)} distant lights; the harness "
            "needs exactly one of each"
        )
    cam = camera_arguments(UsdGeom.Camera(cameras[0]), time, world_transform(xforms, cameras[0]))
    m = cam["transform"]  # row-vector convention: rows are the camera's axes, then its origin
    tan_x = 0.5 * cam["horizontal_aperture"] / cam["focal_length"]
    tan_y = 0.5 * cam["vertical_aperture"] / cam["focal_length"]

    def axis(row: int, scale: float) -> tuple[float, float, float]:
        v = np.asarray(m[row][:3], dtype=np.float64)
        return _vec(scale * v / np.linalg.norm(v))

    sun_z = np.asarray(world_transform(xforms, suns[0])[2][:3], dtype=np.float64)
    scene = ExportedScene(
        eye=_vec(m[3][:3]),
        forward=axis(2, -1.0),
        right=axis(0, tan_x),
        up=axis(1, tan_y),
        # A distant light shines down its -Z axis: the sun is toward +Z.
        to_sun=_vec(sun_z / np.linalg.norm(sun_z)),
    )
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        transform = world_transform(xforms, prim)
        args = mesh_arguments(UsdGeom.Mesh(prim), time, transform)
        if args is None:
            continue
        scheme = args["scheme"]
        if scheme not in SCHEME_CODES:
            raise ExportError(f"{prim.GetPath()}: subdivisionScheme {scheme!r} not exported")
        if args["interpolate_boundary"] != "edgeAndCorner" or args["hole_indices"] is not None:
            raise ExportError(
                f"{prim.GetPath()}: only interpolateBoundary edgeAndCorner without holes is "
                "exported (Embree's RTC_SUBDIVISION_MODE_PIN_CORNERS)"
            )
        points = np.asarray(args["points"], np.float64)
        world = points @ transform[:3, :3] + transform[3, :3]
        pairs, weights = crease_edges(
            args["crease_indices"], args["crease_lengths"], args["crease_sharpnesses"]
        )
        st = _vertex_st(prim, len(points))
        corners = args["corner_indices"]
        scene.meshes.append(
            ExportedMesh(
                path=str(prim.GetPath()),
                scheme=scheme,
                points=world.astype(np.float32),
                counts=np.asarray(args["face_vertex_counts"], np.int32),
                indices=np.asarray(args["face_vertex_indices"], np.int32),
                crease_pairs=pairs,
                crease_weights=weights,
                corner_indices=np.zeros(0, np.int32) if corners is None else corners,
                corner_weights=np.asarray(
                    args["corner_sharpnesses"] if corners is not None else [], np.float32
                ),
                st=st,
                displacement=_displacement(prim, st),
            )
        )
    return scene


def _u32(f: BinaryIO, value: int) -> None:
    f.write(struct.pack("<I", value))


def _array_out(f: BinaryIO, values: NDArray[Any], dtype: str) -> None:
    data = np.ascontiguousarray(values, dtype=dtype)
    _u32(f, data.size)
    f.write(data.tobytes())


def export_stage(usd_path: Path, out_path: Path) -> ExportedScene:
    """Write the stage at ``usd_path`` for the harness; returns what was written.

    Layout (little-endian; ``arr<T>`` is a u32 element count, then the elements)::

        "MPRYTHRU" u32 version
        f32[3] eye, forward, right, up, to_sun
        u32 mesh count, then per mesh:
          arr<u8> prim path   u32 scheme (0 none, 1 catmullClark)
          arr<f32> points (x y z …)   arr<i32> face counts   arr<i32> face indices
          arr<i32> crease pairs (a b …)   arr<f32> crease weights
          arr<i32> corner indices   arr<f32> corner weights
          arr<f32> vertex st (s t …; empty if none)
          u32 displaced; if 1: arr<u8> texture path, f32 scale, f32 bias, u32 channel,
                                u32 wrap s, u32 wrap t
    """
    scene = read_stage(usd_path)
    with open(out_path, "wb") as f:
        f.write(MAGIC)
        _u32(f, VERSION)
        for v in (scene.eye, scene.forward, scene.right, scene.up, scene.to_sun):
            f.write(struct.pack("<3f", *v))
        _u32(f, len(scene.meshes))
        for mesh in scene.meshes:
            _array_out(f, np.frombuffer(mesh.path.encode(), np.uint8), "<u1")
            _u32(f, SCHEME_CODES[mesh.scheme])
            _array_out(f, mesh.points, "<f4")
            _array_out(f, mesh.counts, "<i4")
            _array_out(f, mesh.indices, "<i4")
            _array_out(f, mesh.crease_pairs, "<i4")
            _array_out(f, mesh.crease_weights, "<f4")
            _array_out(f, mesh.corner_indices, "<i4")
            _array_out(f, mesh.corner_weights, "<f4")
            _array_out(f, mesh.st if mesh.st is not None else np.zeros(0), "<f4")
            _u32(f, 0 if mesh.displacement is None else 1)
            if mesh.displacement is not None:
                path, scale, bias, channel, wrap_s, wrap_t = mesh.displacement
                _array_out(f, np.frombuffer(path.encode(), np.uint8), "<u1")
                f.write(struct.pack("<ffIII", scale, bias, channel, wrap_s, wrap_t))
    return scene


class _Reader:
    def __init__(self, data: bytes, path: Path) -> None:
        self.data, self.at, self.path = data, 0, path

    def take(self, fmt: str) -> tuple[Any, ...]:
        size = struct.calcsize(fmt)
        if self.at + size > len(self.data):
            raise ExportError(f"{self.path}: truncated at byte {self.at}")
        values = struct.unpack_from(fmt, self.data, self.at)
        self.at += size
        return values

    def array(self, dtype: str) -> NDArray[Any]:
        (n,) = self.take("<I")
        size = n * np.dtype(dtype).itemsize
        if self.at + size > len(self.data):
            raise ExportError(f"{self.path}: array of {n} runs past the end")
        values = np.frombuffer(self.data, dtype, n, self.at).copy()
        self.at += size
        return values


def read_export(path: Path) -> ExportedScene:
    """Read a file :func:`export_stage` wrote.

    Raises:
        ExportError: not an export file, another version, or truncated.

    """
    r = _Reader(Path(path).read_bytes(), Path(path))
    if r.take("<8s")[0] != MAGIC or r.take("<I")[0] != VERSION:
        raise ExportError(f"{path}: not a version {VERSION} throughput export")
    eye, forward, right, up, to_sun = (r.take("<3f") for _ in range(5))
    scene = ExportedScene(eye=eye, forward=forward, right=right, up=up, to_sun=to_sun)
    schemes = {code: name for name, code in SCHEME_CODES.items()}
    (count,) = r.take("<I")
    for _ in range(count):
        name = r.array("<u1").tobytes().decode()
        (scheme,) = r.take("<I")
        points = r.array("<f4").reshape(-1, 3)
        counts, indices = r.array("<i4"), r.array("<i4")
        pairs, weights = r.array("<i4").reshape(-1, 2), r.array("<f4")
        corners, corner_weights = r.array("<i4"), r.array("<f4")
        st = r.array("<f4").reshape(-1, 2)
        (displaced,) = r.take("<I")
        displacement = None
        if displaced:
            texture = r.array("<u1").tobytes().decode()
            displacement = (texture, *r.take("<ffIII"))
        scene.meshes.append(
            ExportedMesh(
                path=name,
                scheme=schemes[scheme],
                points=points,
                counts=counts,
                indices=indices,
                crease_pairs=pairs,
                crease_weights=weights,
                corner_indices=corners,
                corner_weights=corner_weights,
                st=st if len(st) else None,
                displacement=displacement,
            )
        )
    return scene
