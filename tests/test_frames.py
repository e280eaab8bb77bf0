"""Frame specs and placeholders behave as usdrecord's."""

from __future__ import annotations

import pytest
from pxr import UsdUtils

from mipray.frames import (
    FrameSpecError,
    format_frame_path,
    frame_placeholder,
    frames_precision,
    parse_frame_spec,
)


@pytest.mark.parametrize(
    "spec, frames",
    [
        ("5", [5.0]),
        ("101:105", [101.0, 102.0, 103.0, 104.0, 105.0]),
        ("105:101", [105.0, 104.0, 103.0, 102.0, 101.0]),
        ("101:109x2", [101.0, 103.0, 105.0, 107.0, 109.0]),
        ("101:110x2", [101.0, 103.0, 105.0, 107.0, 109.0]),
        ("101:104x0.5", [101.0, 101.5, 102.0, 102.5, 103.0, 103.5, 104.0]),
        ("10:1x-3", [10.0, 7.0, 4.0, 1.0]),
        ("1:3,10", [1.0, 2.0, 3.0, 10.0]),
        ("-2:0", [-2.0, -1.0, 0.0]),
    ],
)
def test_parse_frame_spec(spec: str, frames: list[float]) -> None:
    assert parse_frame_spec(spec) == pytest.approx(frames)
    # Same as USD's own parser, part by part.
    expected = [
        t.GetValue()
        for part in spec.split(",")
        for t in UsdUtils.TimeCodeRange.CreateFromFrameSpec(part)
    ]
    assert parse_frame_spec(spec) == pytest.approx(expected)


@pytest.mark.parametrize(
    "spec", ["", "abc", "1:", ":5", "1:5x0", "1:5x-1", "5:1x2", "1:2:3", "1,,2"]
)
def test_bad_frame_specs_are_one_line_errors(spec: str) -> None:
    with pytest.raises(FrameSpecError) as info:
        parse_frame_spec(spec)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "path, frame, expected",
    [
        ("out.####.exr", 1.0, "out.0001.exr"),
        ("out.####.exr", 101.0, "out.0101.exr"),
        ("out.#.exr", 101.0, "out.101.exr"),
        ("out.###.##.exr", 101.5, "out.101.50.exr"),
        ("out.####.exr", -3.0, "out.-003.exr"),
        ("out.exr", 7.0, "out.exr"),
        ("shots/a_b/frame_###.png", 12.0, "shots/a_b/frame_012.png"),
    ],
)
def test_frame_placeholder_padding(path: str, frame: float, expected: str) -> None:
    assert format_frame_path(path, frame) == expected


def test_placeholder_detection() -> None:
    assert frame_placeholder("a.####.exr") == "####"
    assert frame_placeholder("a.##.#.exr") == "##.#"
    assert frame_placeholder("a.exr") is None
    with pytest.raises(FrameSpecError, match="2 frame placeholders"):
        frame_placeholder("a.##.b.##.exr")


def test_frames_precision() -> None:
    assert frames_precision([1.0, 2.0]) == 0
    assert frames_precision([1.0, 1.5]) == 1
    assert frames_precision([1.0, 1.25]) == 2
