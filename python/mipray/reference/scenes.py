"""The scenes mipray is compared with Mitsuba 3 on, built in memory with usd-core.

Every mesh is polygonal (``subdivisionScheme = "none"``, planar faces) so both
renderers intersect the same surface; the implicit gprims (Sphere, Cylinder, a
Cylinder flat enough to be a disk, Points) are the analytic shapes Mitsuba has,
one primitive per ``implicit_*`` / ``points`` scene (:data:`RADIUS_SCALED`
builds each with its radius off, to show the comparison sees it). Both show
lights to camera rays (a dome is the background); the area lights are out of the
camera's view all the same, so that the images compare surfaces, not the edges
of bright lights.
Each :class:`Scene` names the mipray render settings and the Mitsuba integrator
that compute the same integral:

- mipray's classic integrator (direct light, shadows, ``shadowSamples`` light
  samples per area light) ↔ Mitsuba's ``direct`` with as many emitter samples,
  for scenes without specular surfaces;
- mipray's classic integrator with mirrors ↔ Mitsuba's ``path`` of the depth
  that reaches the light through the mirror, in scenes where no longer path
  carries light (a convex mirror over a single plane under a point-like light);
- mipray's path tracer (``integrator = path``, ``maxDepth`` = bounces after the
  camera hit, 0 being direct light) ↔ Mitsuba's ``path`` with ``max_depth`` =
  bounces + 2 (Mitsuba counts the camera segment and the segment to the light).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

__all__ = ["BROKEN", "RADIUS_SCALED", "SCENES", "Scene", "by_name"]

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Scene:
    """A comparison scene."""

    name: str
    #: One line: what it tests.
    what: str
    build: Callable[[], Usd.Stage]
    #: mipray render settings (``samples`` and ``seed`` are set by the comparison).
    settings: dict[str, Any] = field(default_factory=dict)
    #: Mitsuba's integrator dict.
    integrator: dict[str, Any] = field(default_factory=lambda: {"type": "direct"})
    #: Image width in pixels (the height follows the camera's aspect).
    width: int = 64
    #: The stage Mitsuba renders in this one's place, when the scene's surface has no Mitsuba
    #: shape but is exactly one Mitsuba has (a NURBS sphere: its analytic sphere); None: the
    #: same stage.
    mitsuba_stand_in: Callable[[], Usd.Stage] | None = None


# ----------------------------------------------------------------------------- building blocks


def _stage() -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.Xform.Define(stage, "/World")
    return stage


def _camera(stage: Usd.Stage, eye: Vec3, target: Vec3, focal: float = 35.0) -> None:
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    view = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(0, 1, 0))
    cam.AddTransformOp().Set(view.GetInverse())
    cam.CreateFocalLengthAttr(focal)
    cam.CreateHorizontalApertureAttr(36.0)
    cam.CreateVerticalApertureAttr(27.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1000.0))


def _material(stage: Usd.Stage, name: str, **inputs: Any) -> UsdShade.Material:
    """A UsdPreviewSurface material with the given inputs (Python values; colours as tuples)."""
    material = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
    shader = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    for key, value in inputs.items():
        if isinstance(value, tuple):
            shader.CreateInput(key, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*value))
        elif key == "useSpecularWorkflow":
            shader.CreateInput(key, Sdf.ValueTypeNames.Int).Set(int(value))
        else:
            shader.CreateInput(key, Sdf.ValueTypeNames.Float).Set(float(value))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def lambert(stage: Usd.Stage, name: str, color: Vec3) -> UsdShade.Material:
    """A pure lambertian UsdPreviewSurface: specular workflow with no specular."""
    return _material(
        stage, name, diffuseColor=color, useSpecularWorkflow=1, specularColor=(0, 0, 0)
    )


def _mesh(
    stage: Usd.Stage,
    path: str,
    points: Sequence[Vec3],
    counts: Sequence[int],
    indices: Sequence[int],
    material: UsdShade.Material,
) -> UsdGeom.Mesh:
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([Gf.Vec3f(*p) for p in points])
    mesh.CreateFaceVertexCountsAttr(list(counts))
    mesh.CreateFaceVertexIndicesAttr(list(indices))
    mesh.CreateSubdivisionSchemeAttr("none")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    return mesh


def ground(
    stage: Usd.Stage, material: UsdShade.Material, half: float = 4.0, st: bool = False
) -> None:
    """A square at y = 0, facing +Y.

    With ``st``: face-varying st over [0, 1]², s along +X and t along -Z (away from the camera).
    """
    h = half
    mesh = _mesh(
        stage,
        "/World/Ground",
        [(-h, 0, h), (h, 0, h), (h, 0, -h), (-h, 0, -h)],
        [4],
        [0, 1, 2, 3],
        material,
    )
    if st:
        primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
        )
        primvar.Set([(0, 0), (1, 0), (1, 1), (0, 1)])


def box(stage: Usd.Stage, path: str, lo: Vec3, hi: Vec3, material: UsdShade.Material) -> None:
    """An axis-aligned box, faces outward."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    pts = [
        (x0, y0, z1),
        (x1, y0, z1),
        (x1, y1, z1),
        (x0, y1, z1),
        (x0, y0, z0),
        (x1, y0, z0),
        (x1, y1, z0),
        (x0, y1, z0),
    ]
    faces = [[0, 1, 2, 3], [5, 4, 7, 6], [1, 5, 6, 2], [4, 0, 3, 7], [3, 2, 6, 7], [4, 5, 1, 0]]
    _mesh(stage, path, pts, [4] * 6, [i for f in faces for i in f], material)


def uv_sphere(
    stage: Usd.Stage,
    path: str,
    center: Vec3,
    radius: float,
    material: UsdShade.Material,
    rings: int = 12,
    segments: int = 24,
) -> None:
    """A latitude-longitude sphere: planar trapezoids between rings, triangles at the poles."""
    cx, cy, cz = center
    pts: list[Vec3] = [(cx, cy + radius, cz)]
    for i in range(1, rings):
        th = math.pi * i / rings
        for j in range(segments):
            ph = 2.0 * math.pi * j / segments
            pts.append(
                (
                    cx + radius * math.sin(th) * math.cos(ph),
                    cy + radius * math.cos(th),
                    cz - radius * math.sin(th) * math.sin(ph),
                )
            )
    pts.append((cx, cy - radius, cz))
    south = len(pts) - 1

    def ring(i: int, j: int) -> int:
        return 1 + (i - 1) * segments + j % segments

    counts: list[int] = []
    idx: list[int] = []
    for j in range(segments):
        counts.append(3)
        idx += [0, ring(1, j), ring(1, j + 1)]
    for i in range(1, rings - 1):
        for j in range(segments):
            counts.append(4)
            idx += [ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)]
    for j in range(segments):
        counts.append(3)
        idx += [ring(rings - 1, j), south, ring(rings - 1, j + 1)]
    _mesh(stage, path, pts, counts, idx, material)


def _place(
    light: UsdLux.BoundableLightBase | UsdLux.NonboundableLightBase, eye: Vec3, target: Vec3
) -> None:
    """Points the light's -Z from ``eye`` toward ``target``."""
    view = Gf.Matrix4d().SetLookAt(
        Gf.Vec3d(*eye),
        Gf.Vec3d(*target),
        Gf.Vec3d(0, 0, 1)
        if abs(eye[0] - target[0]) + abs(eye[2] - target[2]) < 1e-9
        else Gf.Vec3d(0, 1, 0),
    )
    UsdGeom.Xformable(light).AddTransformOp().Set(view.GetInverse())


def _set(light: Any, intensity: float, color: Vec3 = (1.0, 1.0, 1.0), **inputs: float) -> None:
    light.CreateIntensityAttr(intensity)
    light.CreateColorAttr(Gf.Vec3f(*color))
    for key, value in inputs.items():
        light.GetPrim().CreateAttribute(f"inputs:{key}", Sdf.ValueTypeNames.Float).Set(value)


def _still_life(
    stage: Usd.Stage,
    sphere_material: UsdShade.Material | None = None,
    ground_material: UsdShade.Material | None = None,
) -> None:
    """Ground, a box and a sphere (lambertian unless given materials), a camera.

    A ``ground_material`` comes with st on the ground (it is textured).
    """
    if ground_material is None:
        ground(stage, lambert(stage, "Ground", (0.6, 0.6, 0.6)))
    else:
        ground(stage, ground_material, st=True)
    box(
        stage,
        "/World/Box",
        (-1.6, 0.0, -0.8),
        (-0.4, 1.2, 0.4),
        lambert(stage, "Red", (0.7, 0.15, 0.1)),
    )
    uv_sphere(
        stage,
        "/World/Ball",
        (0.9, 0.8, 0.3),
        0.8,
        sphere_material or lambert(stage, "Blue", (0.15, 0.3, 0.7)),
    )
    _camera(stage, (0.5, 4.5, 6.5), (0.2, 0.3, -0.3))


# ----------------------------------------------------------------------------- scenes


def _distant() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    _sun(stage, (3.0, 5.0, 2.0))
    return stage


def _sphere_light() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    light = UsdLux.SphereLight.Define(stage, "/World/Bulb")
    _set(light, 60.0, (1.0, 0.9, 0.8))
    light.CreateRadiusAttr(0.4)
    light.AddTranslateOp().Set(Gf.Vec3d(1.5, 4.5, -1.5))
    return stage


def _rect_light() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    light = UsdLux.RectLight.Define(stage, "/World/Panel")
    _set(light, 12.0)
    light.CreateWidthAttr(2.0)
    light.CreateHeightAttr(1.0)
    _place(light, (-1.0, 4.5, -2.0), (0.0, 0.0, 0.0))
    return stage


def _disk_light() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    light = UsdLux.DiskLight.Define(stage, "/World/Disk")
    _set(light, 40.0, (0.9, 0.95, 1.0))
    light.CreateRadiusAttr(0.3)
    light.CreateNormalizeAttr(True)
    light.GetIntensityAttr().Set(20.0)
    _place(light, (2.5, 4.5, 1.0), (0.0, 0.0, 0.0))
    return stage


def _cylinder_light(axis_y: bool = False) -> Usd.Stage:
    """A long thin CylinderLight above and behind the objects, out of the frame.

    Along its X (world X), tilted 20° about it; ``axis_y``: turned to lie along world Y
    instead (for checking that the comparison sees the tube's axis).
    """
    stage = _stage()
    _still_life(stage)
    light = UsdLux.CylinderLight.Define(stage, "/World/Tube")
    _set(light, 10.0, (1.0, 0.9, 0.75))
    light.CreateRadiusAttr(0.15)
    light.CreateLengthAttr(3.0)
    light.AddTranslateOp().Set(Gf.Vec3d(-0.5, 3.2, -1.8))
    if axis_y:
        light.AddRotateZOp().Set(90.0)
    light.AddRotateXOp().Set(20.0)
    return stage


def _mesh_light() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    # The L sits where the rect light does, facing the objects.
    mesh = _l_mesh(stage, "/World/Glow")
    light = UsdLux.MeshLightAPI.Apply(mesh.GetPrim())
    UsdLux.LightAPI(light).CreateIntensityAttr(12.0)
    UsdLux.LightAPI(light).CreateColorAttr(Gf.Vec3f(1.0, 0.85, 0.7))
    return stage


def _dome() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    dome = UsdLux.DomeLight.Define(stage, "/World/Sky")
    _set(dome, 1.0, (0.8, 0.9, 1.0))
    return stage


def _spot(
    cone: float = 22.0, softness: float = 0.0, focus: float = 0.0, tint: Vec3 = (0.0, 0.0, 0.0)
) -> Callable[[], Usd.Stage]:
    """The still life under a small sphere light with ShapingAPI, aimed at the scene.

    Radius 0.02 at about 5.4 units (Mitsuba's ``spot`` is a point: the sphere blurs the
    cone's edge by 0.2°), normalized, so its intensity is 120/4 W/sr at the axis; the cone's
    edge crosses the ground, the box and the ball. ``cone`` = 180 is no cone.
    """

    def build() -> Usd.Stage:
        stage = _stage()
        _still_life(stage)
        light = UsdLux.SphereLight.Define(stage, "/World/Spot")
        _set(light, 120.0, (1.0, 0.95, 0.85))
        light.CreateRadiusAttr(0.02)
        light.CreateNormalizeAttr(True)
        _place(light, (2.0, 5.0, 1.5), (0.1, 0.3, -0.2))
        if cone < 180.0 or focus > 0.0:
            shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
            shaping.CreateShapingConeAngleAttr(cone)
            shaping.CreateShapingConeSoftnessAttr(softness)
            shaping.CreateShapingFocusAttr(focus)
            shaping.CreateShapingFocusTintAttr(Gf.Vec3f(*tint))
        return stage

    return build


#: The soft spot's shaping: (cone angle in degrees, softness, focus, focus tint).
SOFT_SPOT = (30.0, 0.6, 3.0, (0.3, 0.15, 0.05))


def light_texture_file() -> str:
    """An 8-bit sRGB PNG for a rect light: red rising along s, blue falling, green with t.

    A flipped or swapped coordinate moves colour across what the light lights.
    """
    import numpy as np

    def ramps(s: Any, t: Any) -> Any:
        return np.stack([0.1 + 0.9 * s, 0.15 + 0.7 * t * t, 1.0 - 0.9 * s * t], axis=-1)

    return _png_once("light-ramps-v1.png", 64, np.float32, ramps)


def _textured_rect_light(flip_t: bool = False) -> Usd.Stage:
    """A big rect light with ``texture:file`` close over the objects, out of the frame.

    With ``flip_t`` the texture is a copy turned upside down (for checking that the
    comparison sees the texture's orientation).
    """
    stage = _stage()
    _still_life(stage)
    light = UsdLux.RectLight.Define(stage, "/World/Panel")
    _set(light, 6.0)
    light.CreateWidthAttr(4.0)
    light.CreateHeightAttr(3.0)
    file = light_texture_file()
    if flip_t:
        file = _flipped(file)
    light.CreateTextureFileAttr(file)
    _place(light, (-1.5, 3.5, -2.5), (0.0, 0.0, 0.0))
    return stage


def _rect_light_untextured() -> Usd.Stage:
    stage = _textured_rect_light()
    stage.GetPrimAtPath("/World/Panel").GetAttribute("inputs:texture:file").Clear()
    return stage


def _flipped(file: str) -> str:
    """``file`` (a PNG this module wrote) upside down, beside it (its codes as they are)."""
    from pathlib import Path

    import numpy as np

    from mipray import _mipray

    out = file[: -len(".png")] + "-flipped.png"
    if not Path(out).exists():
        pixels, _ = _mipray.read_image(file)
        codes = np.ascontiguousarray(pixels[::-1, :, :3], dtype=np.float32)
        _mipray.write_image(out, {"color": codes}, atomic=True)
    return out


def _l_mesh(stage: Usd.Stage, path: str) -> UsdGeom.Mesh:
    """An L of three squares (0.8 units) high above the objects and out of the frame.

    Facing the origin: its right-hand normal e1 × e2 is the direction from it to the origin;
    faces 0 and 1 are the L's foot, 2 its upright; vertex ``st`` (0.5 per square).
    """
    c, s = (-1.0, 4.5, -2.0), 0.8
    length = math.sqrt(1.0 + 4.5**2 + 2.0**2)
    d = (1.0 / length, -4.5 / length, 2.0 / length)
    across = math.hypot(d[0], d[2])
    u = (-d[2] / across, 0.0, d[0] / across)  # d × +Y, normalized
    v = (d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2], d[0] * u[1] - d[1] * u[0])
    e1, e2 = tuple(s * x for x in u), tuple(s * x for x in v)
    grid = [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1), (0, 2), (1, 2)]
    points = [
        tuple(c[k] + (x - 1.0) * e1[k] + (y - 1.0) * e2[k] for k in range(3)) for x, y in grid
    ]
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([Gf.Vec3f(*p) for p in points])
    mesh.CreateFaceVertexCountsAttr([4, 4, 4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 4, 3, 1, 2, 5, 4, 3, 4, 7, 6])
    mesh.CreateSubdivisionSchemeAttr("none")
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    st.Set([(0.5 * x, 0.5 * y) for x, y in grid])
    return mesh


def _mesh_light_subsets(one_tint: bool = False) -> Usd.Stage:
    """mesh_light's L, its foot warm and its upright cool (``one_tint``: both warm)."""
    stage = _stage()
    _still_life(stage)
    mesh = _l_mesh(stage, "/World/Glow")
    light = UsdLux.MeshLightAPI.Apply(mesh.GetPrim())
    UsdLux.LightAPI(light).CreateIntensityAttr(12.0)
    # materialGlowTintsLight (MeshLightAPI's fallback): each subset's emissiveColor tints it.
    warm = _material(stage, "Warm", diffuseColor=(0.0, 0.0, 0.0), emissiveColor=(1.0, 0.45, 0.1))
    cool = _material(stage, "Cool", diffuseColor=(0.0, 0.0, 0.0), emissiveColor=(0.1, 0.5, 1.0))
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    for name, faces, material in (
        ("Foot", [0, 1], warm),
        ("Upright", [2], warm if one_tint else cool),
    ):
        subset = UsdGeom.Subset.CreateGeomSubset(
            mesh, name, UsdGeom.Tokens.face, faces, UsdShade.Tokens.materialBind
        )
        UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(material)
    return stage


def _mesh_light_textured(flip_t: bool = False) -> Usd.Stage:
    """mesh_light's L emitting a texture (``flip_t``: the texture upside down)."""
    stage = _stage()
    _still_life(stage)
    mesh = _l_mesh(stage, "/World/Glow")
    light = UsdLux.MeshLightAPI.Apply(mesh.GetPrim())
    UsdLux.LightAPI(light).CreateIntensityAttr(16.0)
    glow = _material(stage, "Glow", diffuseColor=(0.0, 0.0, 0.0))
    shader = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/Glow/Surface"))
    file = _flipped(light_texture_file()) if flip_t else light_texture_file()
    tex = _uv_texture(stage, "/World/Looks/Glow", "Texture", file)
    shader.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    )
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(glow)
    return stage


def textured_package() -> str:
    """*textured*'s stage as a ``.usdz`` package holding its texture (written once).

    The layer names the texture by a package-relative path, so it is read from inside the
    package (mipray through usd-core's resolver).
    """
    import shutil
    import tempfile
    from pathlib import Path

    from pxr import UsdUtils

    folder = Path(tempfile.gettempdir()) / "mipray-reference"
    package = folder / "textured-v1.usdz"
    if package.exists():
        return str(package)
    work = Path(tempfile.mkdtemp(dir=folder.parent, prefix="mipray-usdz-"))
    try:
        shutil.copy(texture_file(), work / "waves.png")
        stage = _stage()
        _still_life(stage, ground_material=textured_lambert(stage, "Waves", "./waves.png"))
        _sun(stage, (3.0, 5.0, 2.0))
        stage.GetRootLayer().Export(str(work / "textured.usdc"))
        if not UsdUtils.CreateNewUsdzPackage(str(work / "textured.usdc"), str(work / "p.usdz")):
            raise RuntimeError(f"could not package {work / 'textured.usdc'}")
        # Renamed into place: a concurrent run sees the whole package or none.
        (work / "p.usdz").replace(package)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return str(package)


def _textured_usdz() -> Usd.Stage:
    return Usd.Stage.Open(textured_package())


def _mirror() -> Usd.Stage:
    stage = _stage()
    ground(stage, lambert(stage, "Ground", (0.6, 0.6, 0.6)))
    chrome = _material(stage, "Chrome", diffuseColor=(0.9, 0.8, 0.6), metallic=1.0, roughness=0.0)
    uv_sphere(stage, "/World/Ball", (0.0, 0.9, 0.0), 0.9, chrome, rings=16, segments=32)
    _camera(stage, (0.5, 4.5, 6.5), (0.2, 0.3, -0.3))
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    _set(sun, 3.0)
    sun.CreateAngleAttr(0.0)
    _place(sun, (3.0, 5.0, 2.0), (0.0, 0.0, 0.0))
    return stage


def _png_once(name: str, n: int, dtype: Any, texels: Callable[[Any, Any], Any]) -> str:
    """An n×n 8-bit RGB PNG of ``texels(s, t)`` (values in [0, 1], H×W×3), written once.

    It goes under the temporary directory as ``name`` (a new version of a texture gets a new
    name, so a file there is always whole and current); ``s`` and ``t`` are texel centres of
    ``dtype``, t up the image. Written aside and renamed: a concurrent run sees the whole file
    or none.
    """
    import tempfile
    from pathlib import Path

    import numpy as np

    path = Path(tempfile.gettempdir()) / "mipray-reference" / name
    if not path.exists():
        from mipray import _mipray

        path.parent.mkdir(parents=True, exist_ok=True)
        t, s = np.mgrid[0:n, 0:n].astype(dtype)
        s, t = (s + 0.5) / n, 1.0 - (t + 0.5) / n  # rows run down the image, t up
        codes = (np.round(texels(s, t) * 255.0) / 255.0).astype(np.float32)
        # The codes as they are (no sRGB curve), replaced atomically: another process may read it.
        _mipray.write_image(str(path), {"color": codes}, atomic=True)
    return str(path)


def texture_file() -> str:
    """An 8-bit sRGB PNG that varies slowly and differently along s and t.

    Red waves along s, green rises with t, blue waves along both, so a flipped or swapped
    coordinate shows.
    """
    import numpy as np

    def waves(s: Any, t: Any) -> Any:
        return np.stack(
            [
                0.5 + 0.35 * np.sin(2 * np.pi * 2 * s),
                0.15 + 0.7 * t,
                0.5 + 0.3 * np.cos(2 * np.pi * (s + 1.5 * t)),
            ],
            axis=-1,
        )

    return _png_once("waves-v1.png", 128, np.float32, waves)


def normal_map_file() -> str:
    """An 8-bit tangent-space normal map (raw, 2·texel − 1) of gentle crossed waves.

    Heights h = a·sin(2π·3s)·sin(2π·2t): normals (−∂h/∂s, −∂h/∂t, 1) normalized, tilting at
    most about 25°, so both renderers' shading stays away from the horizon.
    """
    import numpy as np

    def normals(s: Any, t: Any) -> Any:
        a = 0.018
        dhds = a * 2 * np.pi * 3 * np.cos(2 * np.pi * 3 * s) * np.sin(2 * np.pi * 2 * t)
        dhdt = a * 2 * np.pi * 2 * np.sin(2 * np.pi * 3 * s) * np.cos(2 * np.pi * 2 * t)
        nrm = np.stack([-dhds, -dhdt, np.ones_like(s)], axis=-1)
        nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
        return nrm * 0.5 + 0.5

    return _png_once("waves-normal-v1.png", 256, np.float64, normals)


def _uv_texture(
    stage: Usd.Stage, material: str, name: str, file: str, **inputs: Any
) -> UsdShade.Shader:
    """A UsdUVTexture of ``file`` reading ``st``, wrapping with repeat, with extra inputs."""
    tex = UsdShade.Shader.Define(stage, f"{material}/{name}")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(file)
    for wrap in ("wrapS", "wrapT"):
        tex.CreateInput(wrap, Sdf.ValueTypeNames.Token).Set("repeat")
    for key, value in inputs.items():
        if isinstance(value, str):
            tex.CreateInput(key, Sdf.ValueTypeNames.Token).Set(value)
        else:
            tex.CreateInput(key, Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*value))
    reader = UsdShade.Shader.Define(stage, f"{material}/{name}Reader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    )
    return tex


def normal_mapped_lambert(stage: Usd.Stage, name: str, color: Vec3, file: str) -> UsdShade.Material:
    """A lambertian UsdPreviewSurface with a tangent-space normal map (raw, scale 2, bias −1)."""
    material = lambert(stage, name, color)
    shader = UsdShade.Shader(stage.GetPrimAtPath(f"/World/Looks/{name}/Surface"))
    tex = _uv_texture(
        stage,
        f"/World/Looks/{name}",
        "NormalTexture",
        file,
        sourceColorSpace="raw",
        scale=(2.0, 2.0, 2.0, 1.0),
        bias=(-1.0, -1.0, -1.0, 0.0),
    )
    shader.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    )
    return material


def textured_lambert(stage: Usd.Stage, name: str, file: str) -> UsdShade.Material:
    """A lambertian UsdPreviewSurface whose diffuseColor is a UsdUVTexture of ``file``.

    The texture reads ``st``; its ``sourceColorSpace`` is left to auto.
    """
    material = lambert(stage, name, (0.0, 0.0, 0.0))
    shader = UsdShade.Shader(stage.GetPrimAtPath(f"/World/Looks/{name}/Surface"))
    tex = _uv_texture(stage, f"/World/Looks/{name}", "Texture", file)
    shader.GetInput("diffuseColor").ConnectToSource(
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    )
    return material


def _sun(stage: Usd.Stage, eye: Vec3) -> None:
    """A distant light (angle 0) shining from ``eye`` toward the origin."""
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    _set(sun, 3.0, (1.0, 0.95, 0.9))
    sun.CreateAngleAttr(0.0)
    _place(sun, eye, (0.0, 0.0, 0.0))


def _textured() -> Usd.Stage:
    stage = _stage()
    _still_life(stage, ground_material=textured_lambert(stage, "Waves", texture_file()))
    _sun(stage, (3.0, 5.0, 2.0))
    return stage


def _subsets_textured(bind_subset: bool = True) -> Usd.Stage:
    """The still life on a ground of two quads, the left one a textured GeomSubset.

    A materialBind subset gives the left quad the textured material (its whole network); the
    right one keeps the mesh's grey.

    ``bind_subset`` False leaves the subset unbound (the whole ground grey: what a renderer
    that drops subset bindings shows).
    """
    stage = _stage()
    _still_life(stage)
    h = 4.0
    mesh = _mesh(
        stage,
        "/World/Ground",
        [(-h, 0, h), (0, 0, h), (h, 0, h), (h, 0, -h), (0, 0, -h), (-h, 0, -h)],
        [4, 4],
        [0, 1, 4, 5, 1, 2, 3, 4],
        lambert(stage, "Ground", (0.6, 0.6, 0.6)),
    )
    primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
    )
    primvar.Set([(0, 0), (0.5, 0), (0.5, 1), (0, 1), (0.5, 0), (1, 0), (1, 1), (0.5, 1)])
    subset = UsdGeom.Subset.CreateGeomSubset(
        mesh, "Left", UsdGeom.Tokens.face, [0], UsdShade.Tokens.materialBind
    )
    if bind_subset:
        waves = textured_lambert(stage, "Waves", texture_file())
        UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(waves)
    _sun(stage, (3.0, 5.0, 2.0))
    return stage


def _normal_mapped() -> Usd.Stage:
    stage = _stage()
    bumps = normal_mapped_lambert(stage, "Bumps", (0.6, 0.6, 0.6), normal_map_file())
    _still_life(stage, ground_material=bumps)
    # A low sun, so the bumps' tilt changes the shading a lot.
    _sun(stage, (4.0, 2.5, 1.0))
    return stage


def _bulb(stage: Usd.Stage, intensity: float = 60.0) -> None:
    light = UsdLux.SphereLight.Define(stage, "/World/Bulb")
    _set(light, intensity, (1.0, 0.9, 0.8))
    light.CreateRadiusAttr(0.4)
    light.AddTranslateOp().Set(Gf.Vec3d(1.5, 4.5, -1.5))


def _path_diffuse() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    # A white wall behind, for light to bounce off.
    white = lambert(stage, "White", (0.8, 0.8, 0.8))
    box(stage, "/World/Wall", (-4.0, 0.0, -2.6), (4.0, 3.0, -2.4), white)
    _bulb(stage)
    return stage


def _metal() -> Usd.Stage:
    stage = _stage()
    gold = _material(stage, "Gold", diffuseColor=(0.95, 0.7, 0.3), metallic=1.0, roughness=0.5)
    _still_life(stage, sphere_material=gold)
    # A big panel: its highlight on the sphere spans pixels rather than hiding inside one,
    # whose sub-pixel coverage would make the noise estimate heavy-tailed.
    light = UsdLux.RectLight.Define(stage, "/World/Panel")
    _set(light, 4.0)
    light.CreateWidthAttr(4.0)
    light.CreateHeightAttr(2.0)
    _place(light, (-1.0, 4.5, -2.0), (0.0, 0.0, 0.0))
    return stage


def _glass(roughness: float) -> Callable[[], Usd.Stage]:
    def build() -> Usd.Stage:
        stage = _stage()
        glass = _material(stage, "Glass", opacity=0.0, ior=1.5, roughness=roughness)
        _still_life(stage, sphere_material=glass)
        sky = UsdLux.DomeLight.Define(stage, "/World/Sky")
        _set(sky, 1.0, (0.8, 0.9, 1.0))
        return stage

    return build


def _emissive() -> Usd.Stage:
    stage = _stage()
    _still_life(stage)
    panel = _material(
        stage,
        "Panel",
        diffuseColor=(0.0, 0.0, 0.0),
        useSpecularWorkflow=1,
        emissiveColor=(4.0, 3.6, 3.0),
    )
    # A glowing panel standing behind the objects, facing them (+Z).
    corners = [(-2.0, 0.2, -2.0), (2.0, 0.2, -2.0), (2.0, 1.8, -2.0), (-2.0, 1.8, -2.0)]
    _mesh(stage, "/World/Glow", corners, [4], [0, 1, 2, 3], panel)
    return stage


def _plastic() -> Usd.Stage:
    stage = _stage()
    red = _material(stage, "Plastic", diffuseColor=(0.7, 0.1, 0.1), roughness=0.3, ior=1.5)
    _still_life(stage, sphere_material=red)
    _bulb(stage)
    return stage


def _implicit_still_life(stage: Usd.Stage, ball: UsdShade.Material) -> None:
    """An implicit Sphere of material ``ball`` and a red Cylinder on the ground, a camera.

    The Cylinder is capped, along X and turned 30° about Y.
    """
    ground(stage, lambert(stage, "Ground", (0.6, 0.6, 0.6)))
    sphere = UsdGeom.Sphere.Define(stage, "/World/Ball")
    sphere.CreateRadiusAttr(0.8)
    sphere.AddTranslateOp().Set(Gf.Vec3d(0.9, 0.8, 0.3))
    UsdShade.MaterialBindingAPI.Apply(sphere.GetPrim()).Bind(ball)
    cylinder = UsdGeom.Cylinder.Define(stage, "/World/Log")
    cylinder.CreateRadiusAttr(0.5)
    cylinder.CreateHeightAttr(1.6)
    cylinder.CreateAxisAttr("X")
    cylinder.AddTranslateOp().Set(Gf.Vec3d(-1.0, 0.5, -0.2))
    cylinder.AddRotateYOp().Set(30.0)
    red = lambert(stage, "Red", (0.7, 0.15, 0.1))
    UsdShade.MaterialBindingAPI.Apply(cylinder.GetPrim()).Bind(red)
    _camera(stage, (0.5, 4.5, 6.5), (0.2, 0.3, -0.3))


def _implicit() -> Usd.Stage:
    stage = _stage()
    _implicit_still_life(stage, lambert(stage, "Blue", (0.15, 0.3, 0.7)))
    _sun(stage, (3.0, 5.0, 2.0))
    return stage


def _implicit_glass() -> Usd.Stage:
    stage = _stage()
    _implicit_still_life(stage, _material(stage, "Glass", opacity=0.0, ior=1.5, roughness=0.0))
    sky = UsdLux.DomeLight.Define(stage, "/World/Sky")
    _set(sky, 1.0, (0.8, 0.9, 1.0))
    return stage


def _on_ground(stage: Usd.Stage, prim: UsdGeom.Gprim, color: Vec3) -> None:
    """Binds a lambertian ``color`` to ``prim``; a grey mesh ground, the still life's camera."""
    ground(stage, lambert(stage, "Ground", (0.6, 0.6, 0.6)))
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(lambert(stage, "Paint", color))
    _camera(stage, (0.5, 4.5, 6.5), (0.2, 0.3, -0.3))
    _sun(stage, (3.0, 5.0, 2.0))


def _one_sphere(radius_scale: float = 1.0) -> Usd.Stage:
    stage = _stage()
    sphere = UsdGeom.Sphere.Define(stage, "/World/Ball")
    sphere.CreateRadiusAttr(1.1 * radius_scale)
    sphere.AddTranslateOp().Set(Gf.Vec3d(0.3, 1.1, 0.0))
    _on_ground(stage, sphere, (0.15, 0.3, 0.7))
    return stage


def _one_cylinder(radius_scale: float = 1.0) -> Usd.Stage:
    stage = _stage()
    cylinder = UsdGeom.Cylinder.Define(stage, "/World/Post")
    cylinder.CreateRadiusAttr(0.7 * radius_scale)
    cylinder.CreateHeightAttr(1.8)
    cylinder.CreateAxisAttr("Y")
    cylinder.AddTranslateOp().Set(Gf.Vec3d(0.2, 0.9, -0.2))
    _on_ground(stage, cylinder, (0.7, 0.15, 0.1))
    return stage


def _one_disk(radius_scale: float = 1.0) -> Usd.Stage:
    # UsdGeom has no disk: a Cylinder 2 % as high as it is wide is a coin whose caps are the
    # disks (Mitsuba's ``disk`` shapes, as the cap of every exported Cylinder), tilted toward
    # the camera so the top cap fills most of its silhouette.
    stage = _stage()
    coin = UsdGeom.Cylinder.Define(stage, "/World/Coin")
    coin.CreateRadiusAttr(1.2 * radius_scale)
    coin.CreateHeightAttr(0.05)
    coin.CreateAxisAttr("Y")
    coin.AddTranslateOp().Set(Gf.Vec3d(0.2, 0.9, 0.0))
    coin.AddRotateXOp().Set(35.0)
    _on_ground(stage, coin, (0.8, 0.6, 0.1))
    return stage


def _nurbs_sphere() -> Usd.Stage:
    """:func:`_one_sphere`'s sphere, 1.1 in radius, as a rational biquadratic NurbsPatch.

    The nine-point circle swept along the five-point half circle, weights 1 and √½.
    """
    stage = _stage()
    patch = UsdGeom.NurbsPatch.Define(stage, "/World/Ball")
    h = math.sqrt(0.5)
    circle = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)]
    profile = [(0, -1), (1, -1), (1, 0), (1, 1), (0, 1)]
    points, weights = [], []
    for j, (r, y) in enumerate(profile):
        for i, (x, z) in enumerate(circle):
            points.append(Gf.Vec3f(1.1 * x * r, 1.1 * y, 1.1 * z * r))
            weights.append((h if i % 2 else 1.0) * (h if j % 2 else 1.0))
    patch.CreatePointsAttr(points)
    patch.CreatePointWeightsAttr(weights)
    patch.CreateUVertexCountAttr(9)
    patch.CreateVVertexCountAttr(5)
    patch.CreateUOrderAttr(3)
    patch.CreateVOrderAttr(3)
    patch.CreateUKnotsAttr([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])
    patch.CreateVKnotsAttr([0, 0, 0, 0.5, 0.5, 1, 1, 1])
    # Swept about +Y from −Y to +Y, u around: dP/du × dP/dv points inward, so the patch is
    # left-handed for an outward front (as the sphere's).
    patch.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    patch.AddTranslateOp().Set(Gf.Vec3d(0.3, 1.1, 0.0))
    _on_ground(stage, patch, (0.15, 0.3, 0.7))
    return stage


def _points(radius_scale: float = 1.0) -> Usd.Stage:
    stage = _stage()
    points = UsdGeom.Points.Define(stage, "/World/Beads")
    centres = [
        (-1.5, 0.4, 0.5),
        (-0.6, 0.6, -0.4),
        (0.4, 0.5, 0.8),
        (1.3, 0.8, -0.2),
        (0.0, 1.6, -1.2),
    ]
    widths = [0.8, 1.2, 1.0, 1.6, 1.4]
    points.CreatePointsAttr([Gf.Vec3f(*c) for c in centres])
    points.CreateWidthsAttr([w * radius_scale for w in widths])
    points.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    _on_ground(stage, points, (0.2, 0.6, 0.3))
    return stage


def _arches(basis: str, width_scale: float) -> Usd.Stage:
    """Three round tubes arching over the ground, ``linear`` or cubic ``bspline``.

    Each curve's ends lie below the ground, so how a renderer closes a tube's end (mipray: a
    sphere; Mitsuba's B-spline: not) plays no part; widths are one per curve (uniform), since
    a tube of varying radius is a frustum per piece in mipray and a swept sphere in Mitsuba.
    """
    stage = _stage()
    curves = UsdGeom.BasisCurves.Define(stage, "/World/Arches")
    points: list[Gf.Vec3f] = []
    counts = []
    for x0, z0, height, span, turn in (
        (-0.9, 0.6, 1.6, 1.4, 0.3),
        (0.6, -0.3, 2.1, 1.8, -0.5),
        (0.1, -1.4, 1.2, 2.6, 0.1),
    ):
        n = 9
        for i in range(n):
            t = -0.25 + 1.5 * i / (n - 1)
            y = height * math.sin(math.pi * t) - 0.3
            x = x0 + span * (t - 0.5)
            points.append(Gf.Vec3f(x, y, z0 + turn * (t - 0.5) ** 2))
        counts.append(n)
    curves.CreatePointsAttr(points)
    curves.CreateCurveVertexCountsAttr(counts)
    if basis == "linear":
        curves.CreateTypeAttr("linear")
    else:
        curves.CreateTypeAttr("cubic")
        curves.CreateBasisAttr(basis)
    curves.CreateWidthsAttr([0.56 * width_scale, 0.48 * width_scale, 0.4 * width_scale])
    curves.SetWidthsInterpolation(UsdGeom.Tokens.uniform)
    _on_ground(stage, curves, (0.7, 0.35, 0.15))
    return stage


def _linear_arches(width_scale: float = 1.0) -> Usd.Stage:
    return _arches("linear", width_scale)


def _bspline_arches(width_scale: float = 1.0) -> Usd.Stage:
    return _arches("bspline", width_scale)


#: Per implicit-prim and curves scene: its builder with the primitive's radius (or widths)
#: scaled, for checking that the comparison sees a geometric error as small as 5 %.
RADIUS_SCALED: dict[str, Callable[[float], Usd.Stage]] = {
    "implicit_sphere": _one_sphere,
    "implicit_cylinder": _one_cylinder,
    "implicit_disk": _one_disk,
    "points": _points,
    "curves_linear": _linear_arches,
    "curves_bspline": _bspline_arches,
    # Mitsuba's stand-in for the NURBS sphere is the implicit one.
    "nurbs_sphere": _one_sphere,
}


#: Per light (and subset) scene: Mitsuba stages with the feature the scene checks broken, each
#: as the export (or mipray) would render it with that bug, for checking that the comparison
#: sees it.
BROKEN: dict[str, dict[str, Callable[[], Usd.Stage]]] = {
    "subsets_textured": {"subset binding dropped": lambda: _subsets_textured(bind_subset=False)},
    "cylinder_light": {"axis along Y": lambda: _cylinder_light(axis_y=True)},
    "spot_light": {"cone ignored": _spot(180.0)},
    "spot_light_soft": {
        "softness ignored": _spot(SOFT_SPOT[0], 0.0, SOFT_SPOT[2], SOFT_SPOT[3]),
        "focus ignored": _spot(SOFT_SPOT[0], SOFT_SPOT[1], 0.0),
    },
    "rect_light_textured": {
        "texture ignored": _rect_light_untextured,
        "texture upside down": lambda: _textured_rect_light(flip_t=True),
    },
    "mesh_light_subsets": {"one tint": lambda: _mesh_light_subsets(one_tint=True)},
    "mesh_light_textured": {"texture upside down": lambda: _mesh_light_textured(flip_t=True)},
}


def _direct(samples: int, delta: bool = False) -> dict[str, Any]:
    """Mitsuba's direct-light integrator with ``samples`` light samples.

    mipray's ``shadowSamples`` and no BSDF samples: what its classic integrator estimates.
    ``delta``: the scene's light is a point (a spot), which needs one sample, and must have
    one: Mitsuba 3.9's ``direct`` sums a delta emitter's samples without dividing by their
    number (4 emitter samples light a spot 4 times over; measured).
    """
    assert samples == 1 or not delta
    return {"type": "direct", "emitter_samples": samples, "bsdf_samples": 0}


def _path(bounces: int) -> dict[str, Any]:
    """Mitsuba's path tracer for mipray's ``maxDepth = bounces`` (bounces after the camera hit).

    Mitsuba's max_depth counts the camera segment and the segment to the light as well.
    """
    return {"type": "path", "max_depth": bounces + 2}


SCENES: tuple[Scene, ...] = (
    Scene(
        "distant",
        "lambertian box, sphere and ground under a distant light (angle 0): hard shadows",
        _distant,
        settings={},
    ),
    Scene(
        "implicit",
        "an implicit Sphere and a capped Cylinder (axis X, rotated), lambertian, on the ground "
        "under a distant light: mipray's exact quadrics against Mitsuba's sphere, cylinder "
        "and disk shapes",
        _implicit,
        settings={},
    ),
    Scene(
        "implicit_sphere",
        "an implicit Sphere alone on the ground under a distant light: mipray's exact sphere "
        "against Mitsuba's analytic sphere",
        _one_sphere,
    ),
    Scene(
        "implicit_cylinder",
        "an implicit capped Cylinder standing on the ground (axis Y): Mitsuba's cylinder and "
        "two disks",
        _one_cylinder,
    ),
    Scene(
        "implicit_disk",
        "a coin: an implicit Cylinder 0.05 high and 1.2 in radius, tilted 35° so its top cap "
        "faces the camera: the caps are Mitsuba's disk shapes",
        _one_disk,
    ),
    Scene(
        "points",
        "UsdGeom.Points of five widths (vertex interpolation) as exact spheres, against a "
        "Mitsuba sphere per point",
        _points,
    ),
    Scene(
        "nurbs_sphere",
        "implicit_sphere's sphere as a rational biquadratic NurbsPatch (eight Bézier patches "
        "tessellated on demand at the beam's rate) against Mitsuba's analytic sphere",
        _nurbs_sphere,
        mitsuba_stand_in=_one_sphere,
    ),
    Scene(
        "curves_linear",
        "linear BasisCurves: three polyline tubes (one width per curve) arching over the "
        "ground, ray traced as curves (mipray's frusta and joint spheres, tessellated at the "
        "beam's rate) against Mitsuba's linearcurve",
        _linear_arches,
    ),
    Scene(
        "curves_bspline",
        "cubic bspline BasisCurves: the same arches as smooth tubes, mipray's on-demand "
        "linear pieces within the beam's chord error against Mitsuba's bsplinecurve",
        _bspline_arches,
    ),
    Scene(
        "implicit_glass",
        "the implicit still life with a smooth glass Sphere (opacity 0, ior 1.5) under a dome, "
        "path traced to 8 bounces: refraction into and out of an exact quadric",
        _implicit_glass,
        settings={"integrator": "path", "maxDepth": 8},
        integrator=_path(8),
    ),
    Scene(
        "sphere_light",
        "the same under a sphere light: soft shadows sampled on the sphere",
        _sphere_light,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "rect_light",
        "the same under a rect light (one-sided, emitting along its -Z)",
        _rect_light,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "disk_light",
        "the same under a normalized disk light",
        _disk_light,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "cylinder_light",
        "the same under a CylinderLight 3 long and 0.15 in radius (along its X, no end caps, "
        "emitting outward) against Mitsuba's cylinder with an area emitter",
        _cylinder_light,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "mesh_light",
        "the same under an L-shaped polygonal mesh with MeshLightAPI (one-sided, facing the "
        "objects from above): area sampling over its triangles against Mitsuba's area emitter",
        _mesh_light,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "mesh_light_subsets",
        "mesh_light's L with two materialBind GeomSubsets, warm and cool emissiveColor "
        "(materialGlowTintsLight): each subset's faces emit their own material's colour",
        _mesh_light_subsets,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "mesh_light_textured",
        "mesh_light's L tinted by a textured emissiveColor (8-bit sRGB PNG, vertex st): "
        "radiance read at each emitting point against Mitsuba's bitmap radiance",
        _mesh_light_textured,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "spot_light",
        "the same under a small sphere light (radius 0.02) with ShapingAPI, a hard 22° cone "
        "crossing the ground, box and ball, against Mitsuba's spot of that cutoff",
        _spot(),
        settings={"shadowSamples": 4},
        integrator=_direct(1, delta=True),
    ),
    Scene(
        "spot_light_soft",
        "the same spot with a 30° cone, softness 0.6, focus 3 and focus tint (0.3, 0.15, "
        "0.05): UsdLux's smoothstep and focus as the Mitsuba spot's projected texture",
        _spot(*SOFT_SPOT),
        settings={"shadowSamples": 4},
        integrator=_direct(1, delta=True),
    ),
    Scene(
        "rect_light_textured",
        "a 4 × 3 rect light with texture:file (an 8-bit sRGB PNG of colour ramps), over the "
        "objects: s along its +X, t along its +Y, against Mitsuba's rectangle with a bitmap "
        "radiance",
        _textured_rect_light,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "dome",
        "the same under a constant dome: direct sky light with its occlusion",
        _dome,
        settings={"shadowSamples": 4},
        integrator=_direct(4),
    ),
    Scene(
        "textured",
        "the still life on a ground whose diffuseColor is an 8-bit sRGB PNG (UsdUVTexture, "
        "sourceColorSpace auto): texture coordinates, sRGB decoding and filtering; Mitsuba "
        "decodes the file itself",
        _textured,
        settings={},
    ),
    Scene(
        "subsets_textured",
        "the still life on a two-quad ground whose left quad is a materialBind GeomSubset "
        "bound to textured's material (texture included), the right one the mesh's grey",
        _subsets_textured,
        settings={},
    ),
    Scene(
        "textured_usdz",
        "textured's stage packaged in a .usdz with its PNG: the texture read from inside the "
        "package (usd-core's resolver); the export hands Mitsuba the file extracted from it",
        _textured_usdz,
        settings={},
    ),
    Scene(
        "normal_mapped",
        "the still life on a ground with a tangent-space normal map (8-bit, raw, scale 2, "
        "bias -1) under a low distant light: the tangent frame from st and the mapped "
        "shading normal",
        _normal_mapped,
        settings={},
    ),
    Scene(
        "mirror",
        "a chrome sphere (metallic 1, roughness 0) over the ground under a distant light: "
        "mipray's classic integrator follows the mirror, Mitsuba's path tracer goes to the same "
        "depth (no longer path carries light here)",
        _mirror,
        settings={},
        integrator={"type": "path", "max_depth": 3},
    ),
    Scene(
        "path_diffuse",
        "the lambertian still life and a white wall under a sphere light, path traced: "
        "indirect diffuse (colour bleeding) to 3 bounces",
        _path_diffuse,
        settings={"integrator": "path", "maxDepth": 3},
        integrator=_path(3),
    ),
    Scene(
        "metal",
        "a rough gold sphere (metallic 1, roughness 0.5) under a rect light, path traced to "
        "2 bounces",
        _metal,
        settings={"integrator": "path", "maxDepth": 2},
        integrator=_path(2),
    ),
    Scene(
        "glass",
        "a smooth glass sphere (opacity 0, ior 1.5) under a dome, path traced to 8 bounces",
        _glass(0.0),
        settings={"integrator": "path", "maxDepth": 8},
        integrator=_path(8),
    ),
    Scene(
        "rough_glass",
        "a rough glass sphere (roughness 0.3) under a dome, path traced to 8 bounces",
        _glass(0.3),
        settings={"integrator": "path", "maxDepth": 8},
        integrator=_path(8),
    ),
    Scene(
        "emissive",
        "the still life lit only by an emissive quad (emissiveColor), path traced to 2 bounces",
        _emissive,
        settings={"integrator": "path", "maxDepth": 2},
        integrator=_path(2),
    ),
    Scene(
        "plastic",
        "a red plastic sphere (metallic 0, ior 1.5, roughness 0.3) under a sphere light, path "
        "traced to 2 bounces; Mitsuba's roughplastic couples diffuse and specular differently",
        _plastic,
        settings={"integrator": "path", "maxDepth": 2},
        integrator=_path(2),
    ),
)


def by_name(name: str) -> Scene:
    """The scene called ``name``."""
    for s in SCENES:
        if s.name == name:
            return s
    raise KeyError(f"no comparison scene '{name}' (scenes: {', '.join(s.name for s in SCENES)})")
