"""Reading USD stages into the render delegate (the scene delegate).

The entry point is :class:`UsdSceneDelegate`; the modules beside it each read
one kind of prim (``mesh``, ``camera``, ``light``, ``instancing`` for
PointInstancers and native instances, ``render_settings`` for UsdRender) or
one concern (``material`` and ``face_albedo`` for diffuse colours,
``primvars`` for display primvars, ``transform`` for world matrices).
"""

from .camera import DEFAULT_CAMERA_PATH, find_camera_prim, image_height
from .light import CAMERA_LIGHT_PATH
from .protocol import RenderDelegateLike
from .render_settings import RenderSettingsSpec, read_render_settings
from .scene_delegate import PURPOSES, SyncError, UsdSceneDelegate

__all__ = [
    "CAMERA_LIGHT_PATH",
    "DEFAULT_CAMERA_PATH",
    "PURPOSES",
    "RenderDelegateLike",
    "RenderSettingsSpec",
    "SyncError",
    "UsdSceneDelegate",
    "find_camera_prim",
    "image_height",
    "read_render_settings",
]
