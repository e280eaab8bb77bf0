"""Lights: ``UsdLux.DistantLight``, and the camera light for a stage without lights.

``UsdLux.DistantLight`` goes into ``RenderDelegate.set_distant_light``; a stage
with no light at all is lit from the camera, as usdrecord does by default.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pxr import Usd, UsdLux

from ..errors import PrimError

__all__ = ["CAMERA_LIGHT_PATH", "camera_light_arguments", "distant_light_arguments"]

#: Path of the light mipray adds at the camera when a stage has no light.
CAMERA_LIGHT_PATH = "/__mipray_camera_light"


def distant_light_arguments(
    light: UsdLux.DistantLight, time: Usd.TimeCode, transform: NDArray[np.float64]
) -> dict[str, Any]:
    """The keyword arguments of ``RenderDelegate.set_distant_light`` for ``light``.

    ``inputs:shadow:enable`` is read whether or not ``ShadowAPI`` is applied;
    unauthored, shadows are on (the API's fallback).

    Raises:
        PrimError: a non-finite or negative value, or a non-finite transform.

    """
    path = str(light.GetPath())

    def get(attr: Usd.Attribute, default: Any) -> Any:
        value = attr.Get(time) if attr else None
        return default if value is None else value

    shadow_attr = light.GetPrim().GetAttribute("inputs:shadow:enable")
    color = tuple(float(c) for c in get(light.GetColorAttr(), (1.0, 1.0, 1.0)))
    args: dict[str, Any] = {
        "transform": transform,
        "intensity": float(get(light.GetIntensityAttr(), 50000.0)),
        "exposure": float(get(light.GetExposureAttr(), 0.0)),
        "color": color,
        "angle": float(get(light.GetAngleAttr(), 0.53)),
        "normalize": bool(get(light.GetNormalizeAttr(), False)),
        "shadow_enable": bool(get(shadow_attr, True)),
    }
    for key in ("intensity", "exposure", "angle"):
        if not math.isfinite(args[key]):
            raise PrimError(path, f"inputs:{key} is not finite")
    if args["intensity"] < 0.0:
        raise PrimError(path, f"inputs:intensity is {args['intensity']}; it must be >= 0")
    if not (0.0 <= args["angle"] <= 180.0):
        raise PrimError(path, f"inputs:angle is {args['angle']}; it must be in [0, 180] degrees")
    if len(color) != 3 or not all(math.isfinite(c) and c >= 0.0 for c in color):
        raise PrimError(path, f"inputs:color {color} is not a finite non-negative color")
    if not np.isfinite(transform).all():
        raise PrimError(path, "the world transform is not finite")
    return args


def camera_light_arguments(camera_transform: NDArray[np.float64]) -> dict[str, Any]:
    """A shadowless distant light shining along the camera's view direction.

    A distant light at the camera's transform shines down the camera's -Z
    axis. Its intensity is π so that, with a Lambertian BRDF (albedo / π), a
    surface facing the camera has radiance equal to its albedo, as the
    fixed-function headlight of usdrecord's default renderer shows it.
    """
    return {
        "transform": camera_transform,
        "intensity": math.pi,
        "exposure": 0.0,
        "color": (1.0, 1.0, 1.0),
        "angle": 0.53,
        "normalize": False,
        "shadow_enable": False,
    }
