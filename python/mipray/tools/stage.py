"""Building blocks of the scripts that write USD scenes (examples, benchmark scenes)."""

from __future__ import annotations

from pathlib import Path

from pxr import Gf, Usd, UsdGeom

__all__ = ["look_at", "new_stage"]


def new_stage(path: Path, documentation: str) -> Usd.Stage:
    """A new Y-up, metre stage at ``path`` with /World as its default prim."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.GetRootLayer().documentation = documentation
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    return stage


def look_at(eye: Gf.Vec3d, target: Gf.Vec3d) -> Gf.Matrix4d:
    """Camera-to-world of a camera at ``eye`` looking at ``target``, Y up.

    Rounded to 6 decimals (and -0 made 0) so a written ``.usda`` is the same on every machine.
    """
    view = Gf.Matrix4d().SetLookAt(eye, target, Gf.Vec3d(0, 1, 0))
    return Gf.Matrix4d([[round(v, 6) + 0.0 for v in row] for row in view.GetInverse()])
