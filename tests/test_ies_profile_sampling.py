"""``mipray:iesProfileSampling``: directions toward an IES light drawn by its profile.

Opt-in (it lowers the noise per sample but costs more time than it saves in the scenes
measured: docs/materials.md). Drawing by the profile changes the noise, never the mean: the
floor under a wide panel with a narrow beam renders the same picture either way, within noise.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, UsdLux
from test_lights_shaping_linking import stage_with_camera

import mipray


def render(stage, spp: int) -> tuple[np.ndarray, dict]:
    with mipray.RenderSession(stage) as session:
        r = session.render(
            "/World/Cam", width=32, settings={"samples": spp, "seed": 3}, camera_light=False
        )
    return np.asarray(r.aovs["color"][..., :3], dtype=np.float64), r.stats


def test_profile_sampling_keeps_the_mean_and_says_so(native, tmp_path) -> None:
    ies = tmp_path / "beam.ies"
    ies.write_text("TILT=NONE\n1 -1 1 4 1 1 2 0 0 0\n1 1 10\n0 10 20 90\n0\n100 100 0 0\n")
    stage = stage_with_camera()
    light = UsdLux.RectLight.Define(stage, "/World/Panel")
    light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.5))
    light.CreateWidthAttr(2.0)
    light.CreateHeightAttr(2.0)
    UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingIesFileAttr(Sdf.AssetPath(str(ies)))
    by_shape, stats = render(stage, 512)
    assert stats["scene"]["lights"][0]["shaping"]["ies"]["profile_sampling"] is False
    attr = light.GetPrim().CreateAttribute("mipray:iesProfileSampling", Sdf.ValueTypeNames.Bool)
    attr.Set(True)
    by_profile, stats = render(stage, 512)
    assert stats["scene"]["lights"][0]["shaping"]["ies"]["profile_sampling"] is True
    assert np.isfinite(by_profile).all()
    # Different samples (the test can tell the setting was read), the same mean (within
    # three standard errors of the by-shape image's mean at 512 spp).
    assert not np.array_equal(by_shape, by_profile)
    ratio = by_profile.mean() / by_shape.mean()
    assert abs(ratio - 1.0) < 0.02, ratio
