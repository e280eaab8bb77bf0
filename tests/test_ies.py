"""UsdLux ShapingAPI IES profiles, rendered from USD against closed forms.

A small disk light facing down from height h with an axially symmetric profile lights the
floor point at angle θ off its axis, distance d, with E = L·πr²·cos θ·I(θ)·cos θ / d², where
I(θ) is the file's candela (× its multiplier) interpolated linearly, or I(θ)/mean with
``ies:normalize`` (the mean over the hemisphere the profile covers); a file that cannot be
parsed is named in one warning and the light renders without it; the stats name the profile.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdLux
from test_lights_shaping_linking import ALBEDO, floor_radius, render, stage_with_camera

import mipray

H, RADIUS, INTENSITY = 2.0, 0.01, 1.0e4
#: Vertical angles (degrees) and candela of the test profile (multiplier 2).
ANGLES = [0.0, 20.0, 40.0, 60.0, 90.0]
CANDELA = [1.0, 0.8, 0.3, 0.1, 0.0]
MULTIPLIER = 2.0


def profile_text(tilt: str = "NONE") -> str:
    return (
        "IESNA:LM-63-2002\n[TEST] mipray\n[MANUFAC] none\n"
        f"TILT={tilt}\n"
        f"1 1000 {MULTIPLIER} {len(ANGLES)} 1 1 2 0.1 0.1 0\n"
        "1.0 1.0 50\n"
        + " ".join(f"{a:g}" for a in ANGLES)
        + "\n0\n"
        + " ".join(f"{c:g}" for c in CANDELA)
        + "\n"
    )


def spot(stage, path: Path, normalize: bool = False, scale: float = 0.0) -> UsdLux.DiskLight:
    light = UsdLux.DiskLight.Define(stage, "/World/Spot")
    light.AddTranslateOp().Set(Gf.Vec3d(0, 0, H))
    light.CreateRadiusAttr(RADIUS)
    light.CreateIntensityAttr(INTENSITY)
    shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
    # The schema's 90° cone fallback lets the whole lower hemisphere through.
    shaping.CreateShapingIesFileAttr(Sdf.AssetPath(str(path)))
    shaping.CreateShapingIesNormalizeAttr(normalize)
    if scale:
        shaping.CreateShapingIesAngleScaleAttr(scale)
    return light


def candela(theta_deg: np.ndarray) -> np.ndarray:
    return MULTIPLIER * np.interp(theta_deg, ANGLES, CANDELA)


def hemisphere_mean() -> float:
    """Mean candela over the lower hemisphere, by a fine midpoint rule (independent of mipray)."""
    n = 200_000
    theta = (np.arange(n) + 0.5) * (math.pi / 2) / n
    return float((candela(np.degrees(theta)) * np.sin(theta)).sum() * (math.pi / 2) / n)


@pytest.mark.parametrize("normalize", [False, True])
def test_the_floor_under_an_ies_spot_gets_the_profiles_candela(
    native, tmp_path: Path, normalize: bool
) -> None:
    path = tmp_path / "spot.ies"
    path.write_text(profile_text())
    stage = stage_with_camera()
    spot(stage, path, normalize)
    image = render(stage, samples=32)
    r = floor_radius(image, stage)
    theta = np.degrees(np.arctan2(r, H))
    d2 = r**2 + H * H
    factor = candela(theta) / (hemisphere_mean() if normalize else 1.0)
    truth = INTENSITY * math.pi * RADIUS**2 * (H * H / d2) / d2 * factor * ALBEDO / math.pi
    # Each pixel averages the profile over its footprint (it is steep between 20° and 60°):
    # a few percent per pixel, a fraction of a percent over the lit floor.
    lit = truth > 0.02 * truth.max()
    assert lit.sum() > 200
    rel = image[..., 0][lit] / truth[lit] - 1.0
    assert abs(float(rel.mean())) < 0.005, float(rel.mean())
    assert float(np.abs(rel).max()) < 0.04, float(np.abs(rel).max())


def test_a_bad_ies_file_is_named_once_and_the_light_renders_without_it(
    native, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    bad = tmp_path / "tilted.ies"
    bad.write_text(profile_text(tilt="INCLUDE"))
    stage = stage_with_camera()
    spot(stage, bad)
    with caplog.at_level(logging.WARNING):
        with mipray.RenderSession(stage) as session:
            for _ in range(2):
                shaped = session.render(
                    "/World/Cam", width=24, settings={"samples": 2}, camera_light=False
                )
    named = [r for r in caplog.records if "tilted.ies" in r.getMessage()]
    assert len(named) == 1, [r.getMessage() for r in named]
    assert "/World/Spot" in named[0].getMessage() and "TILT" in named[0].getMessage()
    # The same light without a profile: the same picture.
    stage.GetPrimAtPath("/World/Spot").RemoveProperty("inputs:shaping:ies:file")
    plain = render(stage, width=24, samples=2)
    assert np.array_equal(np.asarray(shaped.aovs["color"])[..., :3], plain)


def test_the_stats_name_the_profile(native, tmp_path: Path) -> None:
    path = tmp_path / "spot.ies"
    path.write_text(profile_text())
    stage = stage_with_camera()
    spot(stage, path, normalize=True, scale=0.5)
    with mipray.RenderSession(stage) as session:
        result = session.render("/World/Cam", width=8, settings={}, camera_light=False)
    (light,) = result.stats["scene"]["lights"]
    ies = light["shaping"]["ies"]
    assert Path(ies["file"]).name == "spot.ies"
    assert ies["normalize"] is True and ies["angle_scale"] == 0.5
    assert ies["peak_candela"] == MULTIPLIER * max(CANDELA)
    assert math.isclose(ies["mean_candela"], hemisphere_mean(), rel_tol=2e-3)
