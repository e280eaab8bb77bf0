"""The ``MIPRAY`` render engine: export, render with mipray, fill Blender's render result.

``render`` runs where Blender calls it: on the render job's thread for F12 (Blender's UI keeps
running), on the caller's for ``bpy.ops.render.render()``. mipray renders with the GIL
released, so Blender's Python stays responsive; each progressive pass (1, 2, 4, ... samples
per pixel) is copied into the result and shown through ``update_result``, progress goes to
``update_progress`` and Esc (``test_break``) stops the render after the pass in flight, keeping
the last pass shown.
"""

from __future__ import annotations

import math
import tempfile
from typing import Any

import bpy
import numpy as np
from numpy.typing import NDArray

from .. import errors as _errors
from ..session import RenderSession, open_stage
from . import export
from .passes import COMBINED, BlenderPass, blender_passes, pass_pixels
from .properties import render_settings

__all__ = ["MiprayRenderEngine", "esc_pressed", "stats_line"]


#: One pass's AOVs: name → H×W×C float32, linear.
_Images = dict[str, NDArray[np.float32]]


class _Cancelled(Exception):
    """Blender asked the render to stop (Esc)."""


def stats_line(stats: dict[str, Any]) -> str:
    """Blender's stats line after a render.

    The geometry cache's hit rate per tier, its recomputed vertices, rays per second, time.
    """
    cache = stats.get("geometry_cache", {})
    tiers = " ".join(
        f"{t['name']} {100.0 * t['hit_rate']:.0f}%" for t in cache.get("tiers", []) if t["lookups"]
    )
    render = stats.get("render", {})
    rays = sum(render.get("rays", {}).values())
    wall = float(render.get("wall_s", 0.0))
    parts = [
        f"cache hits {tiers or 'none'}",
        f"recomputed vertices {cache.get('recomputed_vertices', 0):,}",
        f"{rays / wall / 1e6:.2f} Mrays/s" if wall > 0 else "",
        f"{wall:.2f} s",
    ]
    return "mipray | " + " | ".join(p for p in parts if p)


def esc_pressed(engine: Any) -> bool:
    """Whether Blender asks ``engine``'s render to stop (Esc).

    A module function so that tests can press Esc: an RNA method cannot be replaced on the class.
    """
    return bool(engine.test_break())


def _passes(view_layer: Any) -> list[BlenderPass]:
    """The passes ``view_layer`` asks for besides Combined."""
    switches = getattr(view_layer, "mipray", None)
    return [p for p in blender_passes() if switches is not None and getattr(switches, p.aov)]


class MiprayRenderEngine(bpy.types.RenderEngine):  # type: ignore[misc]  # bpy has no stubs
    """mipray as a Blender render engine."""

    bl_idname = "MIPRAY"
    bl_label = "mipray"
    bl_use_preview = False
    # Materials reach mipray as the exporter's UsdPreviewSurface, made from shading nodes.
    bl_use_shading_nodes_custom = False

    def update_render_passes(self, scene: Any = None, renderlayer: Any = None) -> None:
        """Tell the compositor which passes the view layer will have."""
        self.register_pass(scene, renderlayer, COMBINED, 4, "RGBA", "COLOR")
        for p in _passes(renderlayer):
            self.register_pass(scene, renderlayer, p.name, p.channels, p.chan_id, p.type)

    def render(self, depsgraph: Any) -> None:
        """Render ``depsgraph``'s view layer into Blender's render result.

        Every failure is one error report (``bpy.ops.render.render`` raises it as a
        RuntimeError); nothing escapes into Blender as a Python traceback.
        """
        try:
            self._render(depsgraph)
        except Exception as exc:
            self.report({"ERROR"}, f"mipray: {type(exc).__name__}: {exc}")

    def _render(self, depsgraph: Any) -> None:
        scene = depsgraph.scene
        view_layer = depsgraph.view_layer
        scale = scene.render.resolution_percentage / 100.0
        width = max(1, int(scene.render.resolution_x * scale))
        height = max(1, int(scene.render.resolution_y * scale))
        self.update_stats("", "mipray | exporting to USD")
        with tempfile.TemporaryDirectory(prefix="mipray-blender-") as directory:
            try:
                path = export.export_usd(depsgraph, directory)
                stage = open_stage(path)
            except (export.ExportError, _errors.MiprayError) as exc:
                self.report({"ERROR"}, f"mipray: {exc}")
                return
            export.match_blender_lights(stage, depsgraph)
            for line in export.unexported_objects(depsgraph, stage):
                self.report({"WARNING"}, f"mipray: {line}; rendered without it")
            camera = export.camera_prim(stage, scene.camera)
            if camera is None:
                self.report({"ERROR"}, "mipray: the scene has no camera to render through")
                return
            self._render_stage(stage, camera, width, height, scene, view_layer)

    def _render_stage(
        self, stage: Any, camera: str, width: int, height: int, scene: Any, view_layer: Any
    ) -> None:
        passes = _passes(view_layer)
        for p in passes:
            self.add_pass(p.name, p.channels, p.chan_id, layer=view_layer.name)
        aovs = ["color", "alpha", *(p.aov for p in passes)]
        settings = render_settings(scene.mipray)
        total_passes = math.ceil(math.log2(max(1, scene.mipray.samples))) + 1
        result = self.begin_result(0, 0, width, height, layer=view_layer.name)
        layer = result.layers[0]
        shown = 0

        def on_update(samples: int, converged: bool, images: _Images) -> None:
            nonlocal shown
            self._fill(layer, passes, images)
            self.update_result(result)
            shown += 1
            self.update_stats("", f"mipray | pass {shown}/{total_passes} ({samples} spp)")
            if not converged and esc_pressed(self):
                raise _Cancelled

        def progress(done: int, total: int) -> None:
            self.update_progress(done / max(total, 1))

        try:
            with RenderSession(stage) as session:
                rendered = session.render(
                    camera,
                    width,
                    aovs,
                    settings,
                    height=height,
                    camera_light=False,
                    progressive=True,
                    on_update=on_update,
                    progress=progress,
                )
        except (_Cancelled, KeyboardInterrupt):
            self.end_result(result)
            self.update_stats("", f"mipray | cancelled after pass {shown}/{total_passes}")
            return
        except _errors.MiprayError as exc:
            self.end_result(result, cancel=True)
            self.report({"ERROR"}, f"mipray: {exc}")
            return
        self.end_result(result)
        for error in rendered.errors:
            self.report({"WARNING"}, f"mipray: {error}")
        self.update_stats("", stats_line(rendered.stats))

    @staticmethod
    def _fill(layer: Any, passes: list[BlenderPass], images: _Images) -> None:
        """Copy one pass's AOVs into the render layer's passes."""
        combined = pass_pixels(images["color"], 4, alpha=images["alpha"])
        layer.passes.find_by_name(COMBINED, "").rect.foreach_set(combined.ravel())
        for p in passes:
            pixels = pass_pixels(images[p.aov], p.channels)
            layer.passes.find_by_name(p.name, "").rect.foreach_set(pixels.ravel())
