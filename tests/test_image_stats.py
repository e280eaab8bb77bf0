"""Output planning (formats, sRGB) and the stats table."""

from __future__ import annotations

import numpy as np
import pytest

from mipray.errors import OutputError
from mipray.image import output_plan, srgb_encode
from mipray.stats import flatten_stats, format_stats_table


def test_srgb_curve_known_values() -> None:
    x = np.array([0.0, 0.0031308, 0.18, 0.5, 1.0, 4.0, -1.0, np.nan], np.float32)
    y = srgb_encode(x)
    assert y.dtype == np.float32
    np.testing.assert_allclose(
        y, [0.0, 0.0404500, 0.4613561, 0.7353570, 1.0, 1.0, 0.0, 0.0], atol=2e-6
    )


@pytest.mark.parametrize(
    "path, order, formats, srgb",
    [
        (
            "a.exr",
            ["color", "depth", "normal"],
            {"color": "half", "depth": "float", "normal": "half"},
            False,
        ),
        (
            "a.EXR",
            ["color", "depth", "normal"],
            {"color": "half", "depth": "float", "normal": "half"},
            False,
        ),
        (
            "a.tif",
            ["color", "depth", "normal"],
            {"color": "float", "depth": "float", "normal": "float"},
            False,
        ),
        ("a.png", ["color"], {"color": "uint8"}, True),
        ("a.jpg", ["color"], {"color": "uint8"}, True),
    ],
)
def test_output_plan(path, order, formats, srgb) -> None:
    assert output_plan(path, ["color", "depth", "normal"]) == (order, formats, srgb)


def test_output_plan_disabled_correction_and_errors() -> None:
    assert output_plan("a.png", ["color"], "disabled")[2] is False
    with pytest.raises(OutputError, match="no file extension"):
        output_plan("image", ["color"])
    with pytest.raises(OutputError, match="needs the color AOV"):
        output_plan("a.png", ["depth"])
    with pytest.raises(OutputError, match="unknown color correction"):
        output_plan("a.exr", ["color"], "openColorIO")


def test_stats_table() -> None:
    stats = {
        "render": {"wall_s": 1.23456, "rays": {"camera": 1000, "shadow": 250}},
        "geometry_cache": {
            "mode": "multires",
            "tiers": [
                {"name": "coarse", "verts_per_side": 2, "hits": 90, "misses": 10, "hit_rate": 0.9},
                {"name": "fine", "verts_per_side": 17, "hits": 5, "misses": 5, "hit_rate": 0.5},
            ],
        },
        "effects": {"enabled": [{"name": "shadows", "why": "/World/Sun casts shadows"}]},
    }
    assert flatten_stats(stats)["render.rays.shadow"] == 250
    table = format_stats_table(stats, "title")
    lines = table.splitlines()
    assert lines[0] == "title"
    assert "  render.wall_s" in table and "1.235" in table
    assert "1,000" in table
    tier_rows = [line.split() for line in lines if line.strip().startswith(("coarse", "fine"))]
    assert tier_rows == [["coarse", "2", "90", "10", "0.9"], ["fine", "17", "5", "5", "0.5"]]
    assert "    shadows: /World/Sun casts shadows" in lines
