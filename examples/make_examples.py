#!/usr/bin/env python3
"""Write the example USD scenes of examples/ (run by ``make`` when they are missing).

    python examples/make_examples.py [OUTPUT_DIR]

``subdiv_showcase.usda``: Catmull-Clark subdivision surfaces with the tags
the paper's geometry cache has to honour — a cube with an infinitely sharp
crease loop, a semi-sharp crease and a sharp corner; a torus turning over
frames 1–24; a sphere-like cage with a hole — on a polygonal ground plane
(``subdivisionScheme = "none"``), seen by a camera, lit by a distant light that
casts shadows at an angle plus a shadowless fill, shaded with
UsdPreviewSurface ``diffuseColor``. It renders at 320 pixels in seconds.

``forest.usda``: a PointInstancer forest — 3,000 instances of three
subdivision prototypes (a conifer, a broadleaf tree, a rock), as 50 groves of
60 placed by an outer PointInstancer (nested instancing keeps the file
small). The renderer holds each prototype's geometry once: the stats report
3,000 instances and three prototypes' subpatches.

``render_settings.usda``: a scene that says how to render itself — a
UsdRender.Settings prim (the stage's ``renderSettingsPrimPath``) with its
resolution, a camera other than ``main_cam``, and two products whose
RenderVars ask for the color, alpha, depth, normal, primId and instanceId
AOVs. Its objects show GeomSubsets bound to their own materials, per-face and
per-vertex ``displayColor``, and native instances of one prototype.

``implicit_prims.usda``: one of each implicit gprim (Sphere, Cube, Cylinder,
Cone, Capsule, Cylinder_1, Capsule_1) on a Plane, under a cloud of 200 Points
of per-point widths and colours: all intersected exactly, none tessellated.

``curves.usda``: BasisCurves ray traced as curves — a tuft of 2,000 bspline hairs
coloured per curve, a catmullRom tube of varying width, a ribbon facing its normals, a
ribbon facing the camera, a periodic bezier ring — and a NurbsCurves spiral, on a Plane.

The output is deterministic (coordinates rounded to 6 decimals), so the
committed .usda files are exactly what this script writes.
"""

from __future__ import annotations

import math
import random
import sys
from pathlib import Path

from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade, Vt

from mipray.tools.stage import look_at, new_stage

HERE = Path(__file__).resolve().parent

# A cube cage: 8 points, 6 quads with outward (right-handed) winding.
CUBE_POINTS = [
    (-1, -1, 1),
    (1, -1, 1),
    (-1, 1, 1),
    (1, 1, 1),
    (-1, 1, -1),
    (1, 1, -1),
    (-1, -1, -1),
    (1, -1, -1),
]
CUBE_COUNTS = [4] * 6
CUBE_INDICES = [0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 1, 0, 1, 7, 5, 3, 6, 0, 2, 4]


def _round(points: list[tuple[float, float, float]]) -> list[Gf.Vec3f]:
    return [Gf.Vec3f(*(round(c, 6) + 0.0 for c in p)) for p in points]


def _material(
    stage: Usd.Stage, name: str, rgb: tuple[float, float, float], roughness: float | None = 0.6
) -> UsdShade.Material:
    """A UsdPreviewSurface material; ``roughness`` None leaves it unauthored.

    A GeomSubset's material renders its diffuseColor only: mipray lists any other input.
    """
    UsdGeom.Scope.Define(stage, "/World/Looks")
    material = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
    shader = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*rgb))
    if roughness is not None:
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(roughness)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def _mesh(
    stage: Usd.Stage,
    path: str,
    points: list[tuple[float, float, float]],
    counts: list[int],
    indices: list[int],
    material: UsdShade.Material | None,
    scheme: str = "catmullClark",
) -> UsdGeom.Mesh:
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(_round(points))
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(indices)
    mesh.CreateSubdivisionSchemeAttr(scheme)
    xs, ys, zs = zip(*points, strict=True)
    lo, hi = Gf.Vec3f(min(xs), min(ys), min(zs)), Gf.Vec3f(max(xs), max(ys), max(zs))
    mesh.CreateExtentAttr([lo, hi])
    if material is not None:
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    return mesh


def torus_cage(
    major: float, minor: float, rings: int, sides: int
) -> tuple[list[tuple[float, float, float]], list[int], list[int]]:
    """A quad torus control cage around +Y: ``rings`` × ``sides`` faces."""
    points = []
    for i in range(rings):
        u = 2.0 * math.pi * i / rings
        for j in range(sides):
            v = 2.0 * math.pi * j / sides
            r = major + minor * math.cos(v)
            points.append((r * math.cos(u), minor * math.sin(v), -r * math.sin(u)))
    indices = []
    for i in range(rings):
        for j in range(sides):
            a = i * sides + j
            b = ((i + 1) % rings) * sides + j
            c = ((i + 1) % rings) * sides + (j + 1) % sides
            d = i * sides + (j + 1) % sides
            indices += [a, b, c, d]
    return points, [4] * (rings * sides), indices


def subdiv_showcase(path: Path) -> None:
    """Write examples/subdiv_showcase.usda."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.GetRootLayer().documentation = (
        "mipray example: subdivision surfaces with creases, corners and holes. "
        "Generated by examples/make_examples.py; render with "
        "`mipray-record examples/subdiv_showcase.usda out.exr`."
    )
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(24)
    stage.SetFramesPerSecond(24)
    stage.SetTimeCodesPerSecond(24)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())

    UsdGeom.Scope.Define(stage, "/World/Looks")
    red = _material(stage, "Red", (0.7, 0.12, 0.08))
    blue = _material(stage, "Blue", (0.1, 0.25, 0.7))
    gold = _material(stage, "Gold", (0.8, 0.6, 0.2))
    grey = _material(stage, "Ground", (0.5, 0.5, 0.5))

    UsdGeom.Scope.Define(stage, "/World/Geo")

    # Ground: one polygonal quad, not subdivided.
    _mesh(
        stage,
        "/World/Geo/Ground",
        [(-8, 0, -8), (-8, 0, 8), (8, 0, 8), (8, 0, -8)],
        [4],
        [0, 1, 2, 3],
        grey,
        scheme="none",
    )

    # Creased cube: the top face's rim an infinitely sharp loop (10 = infinite in
    # USD), the front-right vertical edge semi-sharp (2), one sharp corner.
    cube = _mesh(stage, "/World/Geo/CreasedCube", CUBE_POINTS, CUBE_COUNTS, CUBE_INDICES, red)
    cube.CreateCreaseIndicesAttr([2, 3, 5, 4, 2, 1, 3])
    cube.CreateCreaseLengthsAttr([5, 2])
    cube.CreateCreaseSharpnessesAttr([10.0, 2.0])
    cube.CreateCornerIndicesAttr([0])
    cube.CreateCornerSharpnessesAttr([10.0])
    cube.AddTranslateOp().Set(Gf.Vec3d(-2.1, 1.0, 0.0))
    cube.AddRotateYOp().Set(30.0)

    # Torus: smooth Catmull-Clark, standing tilted and turning over the frames.
    points, counts, indices = torus_cage(1.0, 0.45, 12, 6)
    torus = _mesh(stage, "/World/Geo/Torus", points, counts, indices, blue)
    torus.AddTranslateOp().Set(Gf.Vec3d(1.75, 1.35, 0.3))
    spin = torus.AddRotateYOp(opSuffix="spin")
    spin.Set(0.0, 1)
    spin.Set(90.0, 24)
    torus.AddRotateXOp().Set(60.0)

    # A sphere-like cube cage with one face left open: a hole, seen from inside.
    ball = _mesh(stage, "/World/Geo/OpenBall", CUBE_POINTS, CUBE_COUNTS, CUBE_INDICES, gold)
    ball.CreateHoleIndicesAttr([0])
    ball.CreateDoubleSidedAttr(True)
    ball.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.9, -2.6))
    ball.AddRotateYOp().Set(-35.0)
    ball.AddScaleOp().Set(Gf.Vec3f(0.9, 0.9, 0.9))

    # Camera: 36×24 mm back, 35 mm lens, looking at the group from the front.
    camera = UsdGeom.Camera.Define(stage, "/World/main_cam")
    camera.CreateFocalLengthAttr(35.0)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(24.0)
    camera.CreateClippingRangeAttr(Gf.Vec2f(0.1, 100.0))
    eye, target = Gf.Vec3d(0.0, 3.4, 7.2), Gf.Vec3d(0.0, 0.9, -0.4)
    camera.AddTransformOp().Set(look_at(eye, target))

    # Key light from the upper left, casting shadows back and to the right.
    sun = UsdLux.DistantLight.Define(stage, "/World/Lights/Sun")
    sun.CreateIntensityAttr(3.0)
    sun.CreateAngleAttr(1.0)
    sun.CreateNormalizeAttr(True)  # intensity is the irradiance, whatever the angle
    sun.CreateColorAttr(Gf.Vec3f(1.0, 0.96, 0.9))
    UsdLux.ShadowAPI.Apply(sun.GetPrim()).CreateShadowEnableAttr(True)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(-55.0, -35.0, 0.0))

    # Fill from the right, no shadows, so shadowed sides are not black.
    fill = UsdLux.DistantLight.Define(stage, "/World/Lights/Fill")
    fill.CreateIntensityAttr(0.6)
    fill.CreateNormalizeAttr(True)
    fill.CreateColorAttr(Gf.Vec3f(0.85, 0.9, 1.0))
    UsdLux.ShadowAPI.Apply(fill.GetPrim()).CreateShadowEnableAttr(False)
    fill.AddRotateXYZOp().Set(Gf.Vec3f(-20.0, 60.0, 0.0))

    stage.GetRootLayer().Save()


def _look_at_camera(
    stage: Usd.Stage,
    path: str,
    eye: tuple[float, float, float],
    target: tuple[float, float, float],
    focal_length: float = 35.0,
) -> UsdGeom.Camera:
    """A 36×24 mm camera at ``eye`` looking at ``target``, Y up."""
    camera = UsdGeom.Camera.Define(stage, path)
    camera.CreateFocalLengthAttr(focal_length)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(24.0)
    camera.CreateClippingRangeAttr(Gf.Vec2f(0.1, 500.0))
    camera.AddTransformOp().Set(look_at(Gf.Vec3d(*eye), Gf.Vec3d(*target)))
    return camera


def _sun_and_fill(stage: Usd.Stage, key: float = 3.0) -> None:
    """A shadow-casting key light from the upper left and a shadowless fill."""
    sun = UsdLux.DistantLight.Define(stage, "/World/Lights/Sun")
    sun.CreateIntensityAttr(key)
    sun.CreateAngleAttr(1.0)
    sun.CreateNormalizeAttr(True)  # intensity is the irradiance, whatever the angle
    sun.CreateColorAttr(Gf.Vec3f(1.0, 0.96, 0.9))
    UsdLux.ShadowAPI.Apply(sun.GetPrim()).CreateShadowEnableAttr(True)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(-50.0, -35.0, 0.0))
    fill = UsdLux.DistantLight.Define(stage, "/World/Lights/Fill")
    fill.CreateIntensityAttr(0.6)
    fill.CreateNormalizeAttr(True)
    fill.CreateColorAttr(Gf.Vec3f(0.85, 0.9, 1.0))
    UsdLux.ShadowAPI.Apply(fill.GetPrim()).CreateShadowEnableAttr(False)
    fill.AddRotateXYZOp().Set(Gf.Vec3f(-20.0, 60.0, 0.0))


def _box(sx: float, sy: float, sz: float, y0: float = 0.0, top: float = 1.0) -> list:
    """A cube cage from y0 to y0 + sy, sx × sz at the bottom, its top face scaled by ``top``."""
    points = []
    for x, y, z in CUBE_POINTS:
        k = top if y > 0 else 1.0
        points.append((x * sx / 2 * k, y0 + (y + 1) / 2 * sy, z * sz / 2 * k))
    return points


def _forest_prototypes(stage: Usd.Stage, root: str) -> list[str]:
    """Conifer, broadleaf tree and rock prototypes under ``root``: subdivision surfaces."""
    bark = _material(stage, "Bark", (0.3, 0.2, 0.12))
    needles = _material(stage, "Needles", (0.08, 0.3, 0.12))
    leaves = _material(stage, "Leaves", (0.25, 0.5, 0.12))
    stone = _material(stage, "Stone", (0.45, 0.44, 0.42))
    UsdGeom.Scope.Define(stage, root)
    conifer = UsdGeom.Xform.Define(stage, f"{root}/Conifer")
    _mesh(stage, f"{root}/Conifer/Trunk", _box(0.3, 1.0, 0.3), CUBE_COUNTS, CUBE_INDICES, bark)
    crown = _box(2.0, 3.4, 2.0, y0=0.6, top=0.08)
    _mesh(stage, f"{root}/Conifer/Crown", crown, CUBE_COUNTS, CUBE_INDICES, needles)
    broadleaf = UsdGeom.Xform.Define(stage, f"{root}/Broadleaf")
    trunk = _box(0.35, 1.6, 0.35, top=0.7)
    _mesh(stage, f"{root}/Broadleaf/Trunk", trunk, CUBE_COUNTS, CUBE_INDICES, bark)
    ball = _box(2.4, 2.2, 2.4, y0=1.2)
    _mesh(stage, f"{root}/Broadleaf/Crown", ball, CUBE_COUNTS, CUBE_INDICES, leaves)
    rock = _mesh(
        stage,
        f"{root}/Rock",
        _box(1.0, 0.6, 0.8, y0=-0.1, top=0.7),
        CUBE_COUNTS,
        CUBE_INDICES,
        stone,
    )
    rock.CreateCreaseIndicesAttr([0, 1, 7, 6, 0])
    rock.CreateCreaseLengthsAttr([5])
    rock.CreateCreaseSharpnessesAttr([2.0])
    return [str(p.GetPath()) for p in (conifer, broadleaf)] + [str(rock.GetPath())]


def _scatter(
    rng: random.Random, count: int, half: float, scale: tuple[float, float]
) -> tuple[list, list, list]:
    """``count`` positions on y = 0 in [-half, half]², turns about Y and uniform scales."""
    positions, orientations, scales = [], [], []
    for _ in range(count):
        x, z = (round(rng.uniform(-half, half), 3) + 0.0 for _ in range(2))
        turn = rng.uniform(0.0, math.pi)
        s = round(rng.uniform(*scale), 3)
        positions.append(Gf.Vec3f(x, 0.0, z))
        orientations.append(Gf.Quath(round(math.cos(turn), 3), 0.0, round(math.sin(turn), 3), 0.0))
        scales.append(Gf.Vec3f(s, s, s))
    return positions, orientations, scales


def forest(path: Path) -> None:
    """Write examples/forest.usda: 50 groves × 60 instances of three prototypes."""
    stage = new_stage(
        path,
        "mipray example: a PointInstancer forest, 3,000 instances of three subdivision "
        "prototypes (nested: 50 groves of 60). Generated by examples/make_examples.py; "
        "render with `make render EXAMPLE=forest`.",
    )
    rng = random.Random(2003)
    ground = _material(stage, "Ground", (0.3, 0.28, 0.2))
    UsdGeom.Scope.Define(stage, "/World/Geo")
    _mesh(
        stage,
        "/World/Geo/Ground",
        [(-60, 0, -60), (-60, 0, 60), (60, 0, 60), (60, 0, -60)],
        [4],
        [0, 1, 2, 3],
        ground,
        scheme="none",
    )
    outer = UsdGeom.PointInstancer.Define(stage, "/World/Geo/Forest")
    grove = UsdGeom.PointInstancer.Define(stage, "/World/Geo/Forest/Prototypes/Grove")
    kinds = _forest_prototypes(stage, "/World/Geo/Forest/Prototypes/Grove/Prototypes")
    grove.CreatePrototypesRel().SetTargets([Sdf.Path(k) for k in kinds])
    positions, orientations, scales = _scatter(rng, 60, 4.5, (0.6, 1.2))
    grove.CreateProtoIndicesAttr([rng.choice((0, 0, 1, 1, 2)) for _ in range(60)])
    grove.CreatePositionsAttr(positions)
    grove.CreateOrientationsAttr(orientations)
    grove.CreateScalesAttr(scales)
    # Groves on a jittered 10 × 5 grid, each turned and scaled: 3,000 instances.
    outer.CreatePrototypesRel().SetTargets([grove.GetPath()])
    cells = [(i, j) for j in range(5) for i in range(10)]
    outer.CreateProtoIndicesAttr([0] * len(cells))
    outer.CreatePositionsAttr(
        [
            Gf.Vec3f(
                round((i - 4.5) * 10 + rng.uniform(-1, 1), 3),
                0.0,
                round(-j * 10 + rng.uniform(-1, 1), 3),
            )
            for i, j in cells
        ]
    )
    _, turns, sizes = _scatter(rng, len(cells), 0.0, (0.9, 1.1))
    outer.CreateOrientationsAttr(turns)
    outer.CreateScalesAttr(sizes)

    _look_at_camera(stage, "/World/main_cam", (0.0, 9.0, 16.0), (0.0, 0.0, -14.0), 28.0)
    _sun_and_fill(stage)
    stage.GetRootLayer().Save()


def _gem(stage: Usd.Stage, path: str, body: UsdShade.Material, top: UsdShade.Material) -> None:
    """A subdivided cube whose top face is a GeomSubset bound to its own material."""
    mesh = _mesh(stage, path, CUBE_POINTS, CUBE_COUNTS, CUBE_INDICES, body)
    subset = UsdShade.MaterialBindingAPI(mesh.GetPrim()).CreateMaterialBindSubset(
        "Top", Vt.IntArray([1])
    )
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(top)


def render_settings(path: Path) -> None:
    """Write examples/render_settings.usda: UsdRender settings, several AOVs, subsets."""
    stage = new_stage(
        path,
        "mipray example: the stage says how to render itself (UsdRender.Settings: "
        "resolution, camera, AOVs). Generated by examples/make_examples.py; render with "
        "`mipray-record examples/render_settings.usda out/render_settings.exr`.",
    )
    grey = _material(stage, "Grey", (0.5, 0.5, 0.5))
    blue = _material(stage, "Blue", (0.1, 0.25, 0.7))
    red = _material(stage, "Red", (0.75, 0.1, 0.06), roughness=None)  # on GeomSubsets
    gold = _material(stage, "Gold", (0.85, 0.62, 0.18), roughness=None)
    UsdGeom.Scope.Define(stage, "/World/Geo")
    _mesh(
        stage,
        "/World/Geo/Ground",
        [(-10, 0, -10), (-10, 0, 10), (10, 0, 10), (10, 0, -10)],
        [4],
        [0, 1, 2, 3],
        grey,
        scheme="none",
    )
    # A block whose top is red and sides blue: a GeomSubset with its own material.
    block = _mesh(stage, "/World/Geo/Block", CUBE_POINTS, CUBE_COUNTS, CUBE_INDICES, blue)
    subset = UsdShade.MaterialBindingAPI(block.GetPrim()).CreateMaterialBindSubset(
        "Top", Vt.IntArray([1])
    )
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(red)
    block.CreateCreaseIndicesAttr([2, 3, 5, 4, 2])
    block.CreateCreaseLengthsAttr([5])
    block.CreateCreaseSharpnessesAttr([10.0])
    block.AddTranslateOp().Set(Gf.Vec3d(-2.4, 1.0, 0.0))
    # A torus with no material: its displayColor, one colour per face (uniform).
    points, counts, indices = torus_cage(0.9, 0.4, 12, 6)
    torus = _mesh(stage, "/World/Geo/Torus", points, counts, indices, None)
    palette = [(0.9, 0.3, 0.1), (0.95, 0.8, 0.2), (0.2, 0.6, 0.3), (0.2, 0.4, 0.9)]
    colors = [palette[(i // 6 + i % 6) % 4] for i in range(len(counts))]
    torus.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set(colors)
    torus.AddTranslateOp().Set(Gf.Vec3d(0.4, 0.9, 0.2))
    torus.AddRotateXOp().Set(70.0)
    # Native instances of one prototype (a gem with a gold top), in a row at the back.
    UsdGeom.Xform.Define(stage, "/World/Prototypes/Gem")
    stage.GetPrimAtPath("/World/Prototypes").SetSpecifier(Sdf.SpecifierClass)
    _gem(stage, "/World/Prototypes/Gem/Body", blue, gold)
    UsdGeom.Xform.Define(stage, "/World/Geo/Gems")
    for i in range(5):
        gem = UsdGeom.Xform.Define(stage, f"/World/Geo/Gems/Gem{i}")
        gem.GetPrim().GetInherits().AddInherit("/World/Prototypes/Gem")
        gem.GetPrim().SetInstanceable(True)
        gem.AddTranslateOp().Set(Gf.Vec3d(-3.0 + 1.5 * i, 0.35, -3.0))
        gem.AddRotateYOp().Set(15.0 * i)
        gem.AddScaleOp().Set(Gf.Vec3f(0.35, 0.35, 0.35))

    _look_at_camera(stage, "/World/main_cam", (0.0, 6.0, 12.0), (0.0, 0.6, -1.0))
    _look_at_camera(stage, "/World/Cameras/Closeup", (1.5, 3.2, 6.0), (-0.6, 0.8, -1.0))
    _sun_and_fill(stage)

    # How to render: 480×270 through the close-up, beauty and data AOVs.
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateResolutionAttr(Gf.Vec2i(480, 270))
    settings.CreateCameraRel().SetTargets(["/World/Cameras/Closeup"])
    settings.CreateIncludedPurposesAttr(["default", "render"])
    products = {"Beauty": ["color", "alpha"], "Data": ["depth", "normal", "primId", "instanceId"]}
    for name, sources in products.items():
        product = UsdRender.Product.Define(stage, f"/Render/{name}")
        product.CreateProductNameAttr(f"render_settings.{name.lower()}.exr")
        targets = []
        for source in sources:
            var = UsdRender.Var.Define(stage, f"/Render/Vars/{source}")
            var.CreateSourceNameAttr(source)
            var.CreateDataTypeAttr("color3f" if source in ("color", "normal") else "float")
            targets.append(var.GetPath())
        product.CreateOrderedVarsRel().SetTargets(targets)
        settings.GetProductsRel().AddTarget(product.GetPath())
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    stage.GetRootLayer().Save()


def _textured_material(stage: Usd.Stage, name: str, displacement: float) -> UsdShade.Material:
    """UsdPreviewSurface with diffuseColor and displacement from maketx'd brick textures."""
    root = f"/World/Looks/{name}"
    UsdGeom.Scope.Define(stage, "/World/Looks")
    material = UsdShade.Material.Define(stage, root)
    surface = UsdShade.Shader.Define(stage, f"{root}/PreviewSurface")
    surface.CreateIdAttr("UsdPreviewSurface")
    surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.8)
    reader = UsdShade.Shader.Define(stage, f"{root}/StReader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    color = UsdShade.Shader.Define(stage, f"{root}/ColorTexture")
    color.CreateIdAttr("UsdUVTexture")
    color.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("textures/bricks_color.tx")
    color.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
    color.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
    color.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
    color.CreateInput("fallback", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(0.5, 0.2, 0.15, 1.0))
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        color.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    )
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    if displacement > 0.0:
        height = UsdShade.Shader.Define(stage, f"{root}/HeightTexture")
        height.CreateIdAttr("UsdUVTexture")
        height.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("textures/bricks_height.tx")
        height.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
        height.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
        height.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
        height.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(displacement))
        height.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(-displacement))
        surface.CreateInput("displacement", Sdf.ValueTypeNames.Float).ConnectToSource(
            height.CreateOutput("r", Sdf.ValueTypeNames.Float)
        )
        material.CreateDisplacementOutput().ConnectToSource(
            surface.ConnectableAPI(), "displacement"
        )
    return material


def textured(path: Path) -> None:
    """Write examples/textured.usda: a brick wall and a brick-wrapped cube.

    The textures are drawn by examples/make_textures.py and made into tiled MIP maps with maketx.
    """
    stage = new_stage(
        path,
        "mipray example: UsdUVTexture on diffuseColor (filtered by the ray differentials) and on "
        "displacement (applied when tessellating, filtered at each tier's grid spacing). Make the "
        "textures first: .venv/bin/python examples/make_textures.py",
    )
    wall_mat = _textured_material(stage, "BrickWall", 0.04)
    cube_mat = _textured_material(stage, "BrickCube", 0.0)
    n = 8
    points, st, indices = [], [], []
    for j in range(n + 1):
        for i in range(n + 1):
            points.append((-3.0 + 6.0 * i / n, 6.0 * j / n, 0.0))
            st.append((2.0 * i / n, 2.0 * j / n))
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            indices += [a, a + 1, a + n + 2, a + n + 1]
    wall = _mesh(stage, "/World/Geo/Wall", points, [4] * (n * n), indices, wall_mat)
    wall.GetPrim().CreateAttribute("primvars:displacementBound", Sdf.ValueTypeNames.Float).Set(0.05)
    pv = UsdGeom.PrimvarsAPI(wall.GetPrim()).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    pv.Set([Gf.Vec2f(*uv) for uv in st])
    wall.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, -2.0))
    cube = _mesh(stage, "/World/Geo/Cube", CUBE_POINTS, CUBE_COUNTS, CUBE_INDICES, cube_mat)
    face_st = [(0, 0), (1, 0), (1, 1), (0, 1)] * 6
    cpv = UsdGeom.PrimvarsAPI(cube.GetPrim()).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
    )
    cpv.Set([Gf.Vec2f(*uv) for uv in face_st])
    cube.CreateFaceVaryingLinearInterpolationAttr(UsdGeom.Tokens.all)
    cube.AddTranslateOp().Set(Gf.Vec3d(1.2, 0.9, 0.5))
    cube.AddRotateYOp().Set(30.0)
    cube.AddScaleOp().Set(Gf.Vec3f(0.9))
    ground = _mesh(
        stage,
        "/World/Geo/Ground",
        [(-20, 0, -20), (20, 0, -20), (20, 0, 20), (-20, 0, 20)],
        [4],
        [0, 3, 2, 1],
        _material(stage, "Ground", (0.35, 0.35, 0.33)),
        scheme="none",
    )
    del ground
    _look_at_camera(stage, "/World/Cam", (1.0, 2.5, 7.0), (0.0, 2.0, -2.0), 30.0)
    _sun_and_fill(stage)
    stage.GetRootLayer().Save()


def implicit_prims(path: Path) -> None:
    """Write examples/implicit_prims.usda: one of each implicit gprim and a Points cloud."""
    stage = new_stage(
        path,
        "mipray example: the implicit gprims (Sphere, Cube, Cylinder, Cone, Capsule, "
        "Cylinder_1, Capsule_1, Plane) and a Points cloud, intersected exactly. Generated by "
        "examples/make_examples.py; render with `make render EXAMPLE=implicit_prims`.",
    )
    rng = random.Random(18)

    def place(gprim, name: str, at: tuple[float, float, float], rgb: tuple[float, float, float]):
        gprim.AddTranslateOp().Set(Gf.Vec3d(*at))
        UsdShade.MaterialBindingAPI.Apply(gprim.GetPrim()).Bind(_material(stage, name, rgb))
        return gprim

    ball = place(
        UsdGeom.Sphere.Define(stage, "/World/Ball"), "Blue", (0.9, 0.8, 0.3), (0.2, 0.4, 0.8)
    )
    ball.CreateRadiusAttr(0.8)
    box = place(UsdGeom.Cube.Define(stage, "/World/Box"), "Red", (-1.3, 0.5, 0.0), (0.8, 0.3, 0.2))
    box.CreateSizeAttr(1.0)
    box.AddRotateYOp().Set(25.0)
    can = place(
        UsdGeom.Cylinder.Define(stage, "/World/Can"), "Green", (0.0, 0.6, -1.4), (0.3, 0.7, 0.3)
    )
    can.CreateRadiusAttr(0.4)
    can.CreateHeightAttr(1.2)
    can.CreateAxisAttr("Y")
    cone = place(
        UsdGeom.Cone.Define(stage, "/World/Cone"), "Yellow", (-0.4, 0.5, 1.3), (0.9, 0.7, 0.1)
    )
    cone.CreateRadiusAttr(0.4)
    cone.CreateHeightAttr(1.0)
    cone.CreateAxisAttr("Y")
    pill = place(
        UsdGeom.Capsule.Define(stage, "/World/Pill"), "Violet", (1.6, 0.25, -1.2), (0.7, 0.2, 0.7)
    )
    pill.CreateRadiusAttr(0.25)
    pill.CreateHeightAttr(0.8)
    pill.CreateAxisAttr("X")
    frustum = place(
        UsdGeom.Cylinder_1.Define(stage, "/World/Frustum"), "Grey", (2.2, 0.3, 1.0), (0.5, 0.5, 0.5)
    )
    frustum.CreateRadiusBottomAttr(0.5)
    frustum.CreateRadiusTopAttr(0.2)
    frustum.CreateHeightAttr(0.6)
    frustum.CreateAxisAttr("Y")
    drop = place(
        UsdGeom.Capsule_1.Define(stage, "/World/Drop"), "Teal", (-2.2, 0.3, 1.2), (0.1, 0.6, 0.6)
    )
    drop.CreateRadiusBottomAttr(0.3)
    drop.CreateRadiusTopAttr(0.15)
    drop.CreateHeightAttr(0.5)
    drop.CreateAxisAttr("Z")
    floor = UsdGeom.Plane.Define(stage, "/World/Floor")
    floor.CreateWidthAttr(12.0)
    floor.CreateLengthAttr(12.0)
    floor.CreateAxisAttr("Y")
    UsdShade.MaterialBindingAPI.Apply(floor.GetPrim()).Bind(
        _material(stage, "Floor", (0.6, 0.6, 0.6))
    )
    dust = UsdGeom.Points.Define(stage, "/World/Dust")
    points = [
        (rng.uniform(-2.5, 2.5), rng.uniform(1.8, 2.8), rng.uniform(-1.5, 1.5)) for _ in range(200)
    ]
    dust.CreatePointsAttr(_round(points))
    dust.CreateWidthsAttr([round(rng.uniform(0.05, 0.2), 6) for _ in points])
    dust.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    colors = UsdGeom.PrimvarsAPI(dust).CreatePrimvar(
        "displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex
    )
    colors.Set([Gf.Vec3f(*(round(rng.random(), 6) for _ in range(3))) for _ in points])
    _look_at_camera(stage, "/World/Camera", (0.5, 4.0, 9.5), (0.0, 0.9, 0.0))
    _sun_and_fill(stage)
    stage.GetRootLayer().Save()


def curves(path: Path) -> None:
    """Write examples/curves.usda: BasisCurves of each basis and style, and a NurbsCurves."""
    stage = new_stage(
        path,
        "mipray example: BasisCurves (bspline hair, a catmullRom tube, oriented and "
        "camera-facing ribbons, a periodic bezier ring) and a NurbsCurves spiral, ray traced "
        "as curves. Generated by examples/make_examples.py; render with "
        "`make render EXAMPLE=curves`.",
    )
    rng = random.Random(18)
    hair = UsdGeom.BasisCurves.Define(stage, "/World/Hair")
    hair.CreateBasisAttr("bspline")
    points, colours = [], []
    for _ in range(2000):
        x, z = rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)
        lean = (rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4))
        for k in range(6):
            t = k / 5
            points.append((x + lean[0] * t * t, 1.2 * t, z + lean[1] * t * t))
        colours.append(
            (round(0.5 + 0.3 * rng.random(), 6), round(0.3 + 0.2 * rng.random(), 6), 0.1)
        )
    hair.CreatePointsAttr(_round(points))
    hair.CreateCurveVertexCountsAttr([6] * 2000)
    hair.CreateWidthsAttr([0.012])
    hair.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    primvar = UsdGeom.PrimvarsAPI(hair).CreatePrimvar(
        "displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.uniform
    )
    primvar.Set([Gf.Vec3f(*c) for c in colours])
    hair.AddTranslateOp().Set(Gf.Vec3d(-1.6, 0.0, 0.0))
    tube = UsdGeom.BasisCurves.Define(stage, "/World/Tube")
    tube.CreateBasisAttr("catmullRom")
    tube.CreatePointsAttr(
        _round(
            [(0.4, 0.1, 1.2), (0.6, 0.9, 0.8), (1.2, 0.4, 0.2), (1.8, 1.2, 0.0), (2.4, 0.5, 0.6)]
        )
    )
    tube.CreateCurveVertexCountsAttr([5])
    tube.CreateWrapAttr("pinned")
    tube.CreateWidthsAttr([0.05, 0.25, 0.15, 0.3, 0.05])
    tube.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    UsdShade.MaterialBindingAPI.Apply(tube.GetPrim()).Bind(
        _material(stage, "Blue", (0.2, 0.4, 0.8))
    )
    ribbon = UsdGeom.BasisCurves.Define(stage, "/World/Ribbon")
    ribbon.CreatePointsAttr(
        _round([(0.2, 1.6, -1.0), (1.0, 2.4, -1.2), (2.0, 1.2, -1.0), (2.8, 1.9, -1.1)])
    )
    ribbon.CreateCurveVertexCountsAttr([4])
    ribbon.CreateWidthsAttr([0.4])
    ribbon.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    ribbon.CreateNormalsAttr([Gf.Vec3f(0, 0.3, 1), Gf.Vec3f(0, 1, 0.2)])
    ribbon.SetNormalsInterpolation(UsdGeom.Tokens.varying)
    UsdShade.MaterialBindingAPI.Apply(ribbon.GetPrim()).Bind(
        _material(stage, "Red", (0.8, 0.3, 0.2))
    )
    facing = UsdGeom.BasisCurves.Define(stage, "/World/Facing")
    facing.CreateTypeAttr("linear")
    facing.CreatePointsAttr(_round([(-2.8, 2.6, -1.0), (-1.8, 2.9, -1.0), (-0.8, 2.5, -1.0)]))
    facing.CreateCurveVertexCountsAttr([3])
    facing.CreateWidthsAttr([0.2])
    facing.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    UsdGeom.PrimvarsAPI(facing.GetPrim()).CreatePrimvar(
        "mipray:curveStyle", Sdf.ValueTypeNames.Token, UsdGeom.Tokens.constant
    ).Set("ribbon")
    ring = UsdGeom.BasisCurves.Define(stage, "/World/Ring")
    ring.CreateWrapAttr("periodic")
    k = 0.5523
    ring.CreatePointsAttr(
        _round(
            [
                (1, 0, 0), (1, k, 0), (k, 1, 0), (0, 1, 0), (-k, 1, 0), (-1, k, 0),
                (-1, 0, 0), (-1, -k, 0), (-k, -1, 0), (0, -1, 0), (k, -1, 0), (1, -k, 0),
            ]
        )
    )  # fmt: skip
    ring.CreateCurveVertexCountsAttr([12])
    ring.CreateWidthsAttr([0.08])
    ring.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    ring.AddTranslateOp().Set(Gf.Vec3d(-0.2, 1.2, 1.6))
    ring.AddScaleOp().Set(Gf.Vec3f(0.5, 0.5, 0.5))
    UsdShade.MaterialBindingAPI.Apply(ring.GetPrim()).Bind(
        _material(stage, "Yellow", (0.9, 0.7, 0.1))
    )
    spiral = UsdGeom.NurbsCurves.Define(stage, "/World/Spiral")
    cps = [(0.4 * math.cos(a * 0.8), 0.15 * a, 0.4 * math.sin(a * 0.8)) for a in range(12)]
    spiral.CreatePointsAttr(_round(cps))
    spiral.CreateCurveVertexCountsAttr([12])
    spiral.CreateOrderAttr([4])
    spiral.CreateKnotsAttr([0, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 9])
    spiral.CreateWidthsAttr([0.06])
    spiral.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    spiral.AddTranslateOp().Set(Gf.Vec3d(1.0, 0.0, -2.2))
    UsdShade.MaterialBindingAPI.Apply(spiral.GetPrim()).Bind(
        _material(stage, "Green", (0.3, 0.7, 0.3))
    )
    floor = UsdGeom.Plane.Define(stage, "/World/Floor")
    floor.CreateWidthAttr(12.0)
    floor.CreateLengthAttr(12.0)
    floor.CreateAxisAttr("Y")
    UsdShade.MaterialBindingAPI.Apply(floor.GetPrim()).Bind(
        _material(stage, "Floor", (0.6, 0.6, 0.6))
    )
    _look_at_camera(stage, "/World/Camera", (0.3, 3.0, 7.5), (0.0, 1.0, 0.0))
    _sun_and_fill(stage)
    stage.GetRootLayer().Save()


EXAMPLES = {
    "subdiv_showcase.usda": subdiv_showcase,
    "implicit_prims.usda": implicit_prims,
    "curves.usda": curves,
    "forest.usda": forest,
    "render_settings.usda": render_settings,
    "textured.usda": textured,
}


def main(argv: list[str] | None = None) -> int:
    """Write every example into the given directory (default: examples/)."""
    args = sys.argv[1:] if argv is None else argv
    out_dir = Path(args[0]) if args else HERE
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, make in EXAMPLES.items():
        path = out_dir / name
        if path.exists():
            path.unlink()
        make(path)
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
