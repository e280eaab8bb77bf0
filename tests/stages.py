"""Small in-memory USD stages for tests (built with usd-core, never on disk)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

#: A unit cube: 8 points, 6 quads, outward-facing with right-handed winding.
CUBE_POINTS = [
    (-0.5, -0.5, 0.5),
    (0.5, -0.5, 0.5),
    (-0.5, 0.5, 0.5),
    (0.5, 0.5, 0.5),
    (-0.5, 0.5, -0.5),
    (0.5, 0.5, -0.5),
    (-0.5, -0.5, -0.5),
    (0.5, -0.5, -0.5),
]
CUBE_COUNTS = [4, 4, 4, 4, 4, 4]
CUBE_INDICES = [0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 1, 0, 1, 7, 5, 3, 6, 0, 2, 4]


def new_stage() -> Usd.Stage:
    """An empty in-memory stage, Y up."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    return stage


def add_cube(
    stage: Usd.Stage,
    path: str,
    *,
    points: Sequence[tuple[float, float, float]] = CUBE_POINTS,
    counts: Sequence[int] = CUBE_COUNTS,
    indices: Sequence[int] = CUBE_INDICES,
    translate: tuple[float, float, float] | None = None,
    scheme: str | None = None,
) -> UsdGeom.Mesh:
    """A cube mesh at ``path`` (parents are defined as Xforms)."""
    parent = Sdf.Path(path).GetParentPath()
    if parent != Sdf.Path.absoluteRootPath and not stage.GetPrimAtPath(parent):
        UsdGeom.Xform.Define(stage, parent)
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(points)
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(indices)
    if scheme is not None:
        mesh.CreateSubdivisionSchemeAttr(scheme)
    if translate is not None:
        mesh.AddTranslateOp().Set(Gf.Vec3d(*translate))
    return mesh


def add_camera(
    stage: Usd.Stage, path: str, eye: tuple[float, float, float] = (0, 0, 10)
) -> UsdGeom.Camera:
    """A camera at ``eye`` looking down -Z."""
    camera = UsdGeom.Camera.Define(stage, path)
    camera.AddTranslateOp().Set(Gf.Vec3d(*eye))
    return camera


#: The tangent of half the default camera's field of view: a 20 mm film back at 50 mm.
HALF_TAN = 10.0 / 50.0


def pinhole_directions(width: int) -> np.ndarray:
    """Unit directions through the pixel centres of a square ``width``-pixel render from a
    camera of the default lens (50 mm focal length, 20 mm square film back) looking down -Z,
    rows from the top: shape (width, width, 3)."""
    xs = (np.arange(width) + 0.5) / width * 2 * HALF_TAN - HALF_TAN
    dx, dy = np.meshgrid(xs, -xs)
    d = np.stack([dx, dy, -np.ones_like(dx)], -1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def add_distant_light(stage: Usd.Stage, path: str, intensity: float = 2.0) -> UsdLux.DistantLight:
    """A distant light tilted 45° down."""
    light = UsdLux.DistantLight.Define(stage, path)
    light.CreateIntensityAttr(intensity)
    light.CreateNormalizeAttr(True)  # intensity = irradiance facing the light (UsdLux)
    light.AddRotateXOp().Set(-45.0)
    return light


def add_preview_material(
    stage: Usd.Stage, path: str, diffuse: tuple[float, float, float] | None
) -> UsdShade.Material:
    """A material whose surface is a UsdPreviewSurface with ``diffuse`` (None: unauthored)."""
    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    if diffuse is not None:
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*diffuse))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def add_textured_material(
    stage: Usd.Stage,
    path: str,
    file: str,
    *,
    output: str = "rgb",
    space: str | None = None,
    wrap: str = "clamp",
) -> UsdShade.Material:
    """A UsdPreviewSurface whose diffuseColor (or opacity, for ``output`` ``a``) reads ``file``
    at the mesh's ``st``, wrapping by ``wrap``; ``sourceColorSpace`` is ``space`` (None:
    unauthored)."""
    material = add_preview_material(stage, path, None)
    surface = UsdShade.Shader(stage.GetPrimAtPath(f"{path}/PreviewSurface"))
    reader = UsdShade.Shader.Define(stage, f"{path}/St")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    tex = UsdShade.Shader.Define(stage, f"{path}/Image")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(file)
    if space is not None:
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(space)
    for name in ("wrapS", "wrapT"):
        tex.CreateInput(name, Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.ConnectableAPI(), "result"
    )
    if output == "a":
        tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
        surface.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(
            tex.ConnectableAPI(), "a"
        )
        surface.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
    else:
        tex.CreateOutput(output, Sdf.ValueTypeNames.Float3)
        surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
            tex.ConnectableAPI(), output
        )
    return material


def bind(prim: Usd.Prim, material: UsdShade.Material) -> None:
    """Bind ``material`` to ``prim`` (applying MaterialBindingAPI, as USD requires)."""
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)
