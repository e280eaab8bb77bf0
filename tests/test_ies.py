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


#: A type A or B test profile: vertical angles from 0 (symmetric about the horizontal plane),
#: horizontal angles over both sides; one row of candela per horizontal angle.
AB_V = [0.0, 30.0, 60.0, 90.0]
AB_H = [-90.0, -45.0, 0.0, 45.0, 90.0]
AB_CD = [
    [2.0, 1.5, 1.0, 0.5],
    [6.0, 4.0, 2.0, 1.0],
    [10.0, 7.0, 3.0, 1.0],
    [8.0, 5.0, 2.5, 1.0],
    [4.0, 3.0, 1.5, 0.5],
]


def ab_text(kind: int, tilt: str = "NONE") -> str:
    rows = "\n".join(" ".join(f"{c:g}" for c in row) for row in AB_CD)
    return (
        f"IESNA:LM-63-2002\n[TEST] mipray type {kind}\nTILT={tilt}\n"
        f"1 1000 {MULTIPLIER} {len(AB_V)} {len(AB_H)} {kind} 2 0.1 0.1 0\n1.0 1.0 50\n"
        + " ".join(f"{a:g}" for a in AB_V)
        + "\n"
        + " ".join(f"{a:g}" for a in AB_H)
        + f"\n{rows}\n"
    )


def ab_candela(kind: int, d: np.ndarray) -> np.ndarray:
    """The test profile toward unit directions ``d`` (light frame, aim −Z), bilinear in (H, V).

    Type B (2): H = asin(d·X), V = atan2(d·Y, −d·Z); type A (3): V = asin(d·Y),
    H = atan2(d·X, −d·Z) (LM-63's planes about the horizontal and the vertical axis).
    """
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    if kind == 2:
        h, v = np.degrees(np.arcsin(np.clip(x, -1, 1))), np.degrees(np.arctan2(y, -z))
    else:
        h, v = np.degrees(np.arctan2(x, -z)), np.degrees(np.arcsin(np.clip(y, -1, 1)))
    v = np.abs(v)  # the file starts at V = 0
    by_row = np.stack([np.interp(v, AB_V, row) for row in AB_CD])  # (rows, ...)
    hi = np.clip(np.searchsorted(AB_H, h, side="right") - 1, 0, len(AB_H) - 2)
    t = (h - np.take(AB_H, hi)) / (np.take(AB_H, hi + 1) - np.take(AB_H, hi))
    lo = np.take_along_axis(by_row, hi[None], 0)[0]
    up = np.take_along_axis(by_row, hi[None] + 1, 0)[0]
    return MULTIPLIER * (lo + (up - lo) * np.clip(t, 0, 1))


def floor_points(image: np.ndarray, stage) -> tuple[np.ndarray, np.ndarray]:
    from pxr import UsdGeom

    camera = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam")).GetCamera()
    n = image.shape[0]
    half = 8.0 * camera.horizontalAperture / (2.0 * camera.focalLength)
    pixel = 2.0 * half / n
    ys, xs = np.mgrid[0:n, 0:n]
    return (xs + 0.5 - n / 2) * pixel, (n / 2 - ys - 0.5) * pixel


@pytest.mark.parametrize("kind", [2, 3])
def test_type_a_and_b_profiles_light_the_floor_with_their_candela(
    native, tmp_path: Path, kind: int
) -> None:
    path = tmp_path / f"type{kind}.ies"
    path.write_text(ab_text(kind))
    stage = stage_with_camera()
    spot(stage, path)
    image = render(stage, width=49, samples=32)
    x, y = floor_points(image, stage)
    d2 = x**2 + y**2 + H * H
    d = np.stack([x, y, np.full_like(x, -H)], axis=-1) / np.sqrt(d2)[..., None]
    cos = H / np.sqrt(d2)
    truth = (
        INTENSITY * math.pi * RADIUS**2 * cos * ab_candela(kind, d) * cos / d2 * ALBEDO / math.pi
    )
    lit = truth > 0.02 * truth.max()
    assert lit.sum() > 400
    rel = image[..., 0][lit] / truth[lit] - 1.0
    assert abs(float(rel.mean())) < 0.005, float(rel.mean())
    assert float(np.abs(rel).max()) < 0.04, float(np.abs(rel).max())
    # The other type's planes differ off the axes by more than the tolerance above: the test
    # tells them apart.
    other = ab_candela(5 - kind, d)
    assert float(np.abs(other[lit] / ab_candela(kind, d)[lit] - 1.0).max()) > 0.06


@pytest.mark.parametrize("up", ["Z", "Y"])
@pytest.mark.parametrize("inline", [True, False])
def test_a_tilt_table_scales_the_light_at_its_tilt_from_the_stages_down(
    native, tmp_path: Path, up: str, inline: bool
) -> None:
    table = "1\n2\n0 90\n0.5 1.0"
    path = tmp_path / "tilted.ies"
    if inline:
        path.write_text(profile_text(tilt=f"INCLUDE\n{table}"))
    else:
        (tmp_path / "lamp.tilt").write_text(table + "\n")
        path.write_text(profile_text(tilt="lamp.tilt"))
    stage = stage_with_camera()
    from pxr import UsdGeom

    UsdGeom.SetStageUpAxis(stage, up)
    spot(stage, path)
    with mipray.RenderSession(stage) as session:
        result = session.render(
            "/World/Cam", width=48, settings={"samples": 32}, camera_light=False
        )
    image = np.asarray(result.aovs["color"][..., :3], dtype=np.float64)
    r = floor_radius(image, stage)
    theta = np.degrees(np.arctan2(r, H))
    d2 = r**2 + H * H
    # Aimed down (−Z): no tilt on a Z-up stage (factor 0.5); on a Y-up stage the same aim is
    # 90° from down (factor 1).
    factor = 0.5 if up == "Z" else 1.0
    truth = INTENSITY * math.pi * RADIUS**2 * (H * H / d2) / d2 * candela(theta) * factor
    truth = truth * ALBEDO / math.pi
    lit = truth > 0.02 * truth.max()
    rel = image[..., 0][lit] / truth[lit] - 1.0
    assert abs(float(rel.mean())) < 0.005, float(rel.mean())
    (light,) = result.stats["scene"]["lights"]
    tilt = light["shaping"]["ies"]["tilt"]
    assert tilt["geometry"] == 1 and math.isclose(tilt["factor"], factor, rel_tol=1e-5)
    assert math.isclose(tilt["angle_deg"], 0.0 if up == "Z" else 90.0, abs_tol=1e-3)


def test_a_tilt_table_of_the_wrong_length_is_named_and_the_light_renders_unshaped(
    native, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    bad = tmp_path / "short.ies"
    # Four angles announced, three given: the factors slide into the angles.
    bad.write_text(profile_text(tilt="INCLUDE\n1\n4\n0 45 90\n1 0.8 0.5"))
    stage = stage_with_camera()
    spot(stage, bad)
    with caplog.at_level(logging.WARNING):
        shaped = render(stage, width=24, samples=2)
    named = [r.getMessage() for r in caplog.records if "short.ies" in r.getMessage()]
    assert len(named) == 1 and "/World/Spot" in named[0] and "tilt" in named[0], named
    stage.GetPrimAtPath("/World/Spot").RemoveProperty("inputs:shaping:ies:file")
    assert np.array_equal(shaped, render(stage, width=24, samples=2))
