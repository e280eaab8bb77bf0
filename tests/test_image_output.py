"""Image output through the renderer's one writer (``mipray::image_output``): the files hold the
film's pixels in the file type's pixel type, 8-bit files the sRGB curve of the colour, the
metadata once, and an atomic write that fails leaves the old file and no temporary one.

The truths are the film itself (``RenderResult.aovs``), IEEE half rounding (numpy's float16)
and the sRGB formula of IEC 61966-2-1 written out here, not the writer's own functions.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import mipray
from mipray.errors import OutputError
from mipray.image import write_aovs

from stages import add_camera, add_cube, add_distant_light, new_stage

AOVS = ("color", "depth", "normal")


@pytest.fixture(scope="module")
def result() -> mipray.RenderResult:
    """A lit cube: colours in (0, 1) and a few above 1 nowhere, depth, normals."""
    pytest.importorskip("mipray._mipray")
    stage = new_stage()
    add_cube(stage, "/World/Cube", scheme="catmullClark")
    add_camera(stage, "/World/Cam", eye=(0.2, 0.3, 2.6))
    add_distant_light(stage, "/World/Sun", intensity=3.0)
    return mipray.render(stage, width=48, aovs=AOVS, settings={"samples": 2, "seed": 1})


def srgb_formula(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1, in float64."""
    x = np.clip(linear.astype(np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1.0 / 2.4) - 0.055)


def test_exr_holds_the_film_in_the_tables_pixel_types_with_metadata_once(
    native, result: mipray.RenderResult, tmp_path: Path
) -> None:
    path = tmp_path / "deep" / "beauty.exr"
    result.write(path, metadata={"shot": "sq010"})
    pixels, channels = native.read_image(str(path))
    assert channels == ["R", "G", "B", "Z", "N.x", "N.y", "N.z"]
    color, depth, normal = (result.aovs[a] for a in AOVS)
    assert (color > 0.01).mean() > 0.25, "the lit cube fills much of the frame"
    # Half for colour and normals (rounded as IEEE half rounds), float for depth: exactly.
    half = lambda a: a.astype(np.float16).astype(np.float32)  # noqa: E731
    np.testing.assert_array_equal(pixels[..., 0:3], half(color))
    np.testing.assert_array_equal(pixels[..., 3:4], depth)
    np.testing.assert_array_equal(pixels[..., 4:7], half(normal))
    meta = native.read_metadata(str(path))
    assert meta["Software"] == f"mipray {native.version()}"
    assert meta["mipray:camera"] == "/World/Cam" and meta["shot"] == "sq010"
    assert not any(k.lower() == "software" and k != "Software" for k in meta), meta
    assert sorted(p.name for p in path.parent.iterdir()) == ["beauty.exr"]


def test_tiff_is_32_bit_float_and_exact(
    native, result: mipray.RenderResult, tmp_path: Path
) -> None:
    path = tmp_path / "beauty.tif"
    result.write(path, ["color", "depth"])
    pixels, channels = native.read_image(str(path))
    # TIFF keeps no channel names (a reader calls the fourth "channel3"); the order is kept.
    assert len(channels) == 4
    np.testing.assert_array_equal(pixels[..., 0:3], result.aovs["color"])
    np.testing.assert_array_equal(pixels[..., 3:4], result.aovs["depth"])


@pytest.mark.parametrize("mode", ["sRGB", "disabled"])
def test_png_is_the_8_bit_code_of_the_srgb_formula(
    native, result: mipray.RenderResult, tmp_path: Path, mode: str
) -> None:
    path = tmp_path / f"beauty-{mode}.png"
    result.write(path, color_correction=mode)  # depth and normal cannot go in: left out
    pixels, channels = native.read_image(str(path))
    assert channels == ["R", "G", "B"]
    linear = result.aovs["color"]
    encoded = srgb_formula(linear) if mode == "sRGB" else np.clip(linear, 0.0, 1.0)
    expected = np.round(encoded * 255.0)
    codes = np.round(pixels * 255.0)
    # One code apart at most, where float32's curve and float64's round on either side of .5.
    assert np.abs(codes - expected).max() <= 1
    assert (codes == expected).mean() > 0.99
    if mode == "sRGB":
        lit = linear > 0.01
        lifted = (expected != np.round(np.clip(linear, 0, 1) * 255.0))[lit].mean()
        assert lifted > 0.9, "the curve was applied, not the linear values"


def test_arrays_from_python_go_through_the_same_writer(native, tmp_path: Path) -> None:
    """The package's writer of numpy arrays (assembled tiles, a user's own pixels)."""
    ramp = np.linspace(-1.0, 2.0, 12, dtype=np.float32).reshape(1, 4, 3)
    sliced = np.ascontiguousarray(np.repeat(ramp, 2, axis=0))[:, ::-1]  # not C-contiguous
    path = tmp_path / "tiles.png"
    write_aovs(str(path), {"color": sliced, "extra": sliced[..., :1]}, atomic=True)
    pixels, _ = native.read_image(str(path))
    np.testing.assert_array_equal(np.round(pixels * 255), np.round(srgb_formula(sliced) * 255))
    with pytest.raises(OutputError, match="needs the color AOV"):
        write_aovs(str(tmp_path / "x.png"), {"extra": sliced[..., :1]})
    with pytest.raises(OutputError, match="no AOV named 'depth' was rendered"):
        write_aovs(str(tmp_path / "x.exr"), {"color": sliced}, ["depth"])
    with pytest.raises(OutputError, match="unknown color correction mode"):
        write_aovs(str(tmp_path / "x.png"), {"color": sliced}, color_correction="openColorIO")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiles.png"]


def test_an_atomic_write_that_fails_leaves_the_old_image_and_no_temporary_file(
    native, tmp_path: Path
) -> None:
    """A real failure: the file size limit (as a full disk) stops OpenImageIO mid-file."""
    target = tmp_path / "img.exr"
    target.write_text("the previous image")
    script = textwrap.dedent(
        f"""
        import resource, signal
        import numpy as np
        from mipray.errors import OutputError
        from mipray.image import write_aovs
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
        color = np.random.default_rng(1).random((64, 64, 3), dtype=np.float32)
        try:
            write_aovs({str(target)!r}, {{"color": color}}, formats={{"color": "float"}}, atomic=True)
        except OutputError as exc:
            print(exc)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    message = done.stdout.strip()
    assert message.startswith("cannot write image") and str(target) in message, done
    assert ".tmp" not in message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["img.exr"]
    assert target.read_text() == "the previous image", "a failed write keeps the old image"
