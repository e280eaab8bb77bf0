"""Writing AOVs to image files: channel layout, pixel formats, color correction.

The pixels stay linear in floating-point files (EXR, TIFF). 8-bit files (PNG,
JPEG, ...) hold the color AOV only, encoded with the sRGB transfer curve unless
color correction is disabled, as usdrecord's ``--colorCorrectionMode sRGB``
does; types with an alpha channel (PNG, TGA, WebP) also hold the alpha AOV
when it was rendered (RGBA, as usdrecord writes; the colour is premultiplied).
The file itself is written by ``mipray._mipray.write_image`` (OpenImageIO).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .aovs import exr_format
from .errors import OutputError

__all__ = [
    "COLOR_CORRECTION_MODES",
    "EIGHT_BIT_EXTENSIONS",
    "eight_bit_aovs",
    "is_eight_bit",
    "output_plan",
    "srgb_encode",
    "write_aovs",
]

_log = logging.getLogger(__name__)

#: usdrecord's ``--colorCorrectionMode`` values that mipray supports.
COLOR_CORRECTION_MODES = ("sRGB", "disabled")
#: File extensions whose images hold 8 bits per channel.
EIGHT_BIT_EXTENSIONS = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tga", ".ppm", ".webp"})
#: 8-bit types with an alpha channel: they hold the color AOV as RGB and the alpha AOV as A.
_ALPHA_EXTENSIONS = frozenset({".png", ".tga", ".webp"})
_FLOAT_EXTENSIONS = frozenset({".exr", ".tif", ".tiff", ".hdr", ".pfm"})


def is_eight_bit(path: str) -> bool:
    """Whether ``path``'s extension names an 8-bit image format."""
    return os.path.splitext(path)[1].lower() in EIGHT_BIT_EXTENSIONS


def eight_bit_aovs(path: str) -> list[str]:
    """The AOVs an 8-bit file at ``path`` holds (color, and alpha where the type has it)."""
    ext = os.path.splitext(path)[1].lower()
    return ["color", "alpha"] if ext in _ALPHA_EXTENSIONS else ["color"]


def srgb_encode(linear: NDArray[np.float32]) -> NDArray[np.float32]:
    """Apply the sRGB transfer curve (IEC 61966-2-1) to linear values, clamped to [0, 1]."""
    x = np.clip(np.nan_to_num(linear, nan=0.0), 0.0, 1.0).astype(np.float32)
    low = x * np.float32(12.92)
    high = np.float32(1.055) * np.power(x, np.float32(1.0 / 2.4)) - np.float32(0.055)
    return np.where(x <= np.float32(0.0031308), low, high).astype(np.float32)


def output_plan(
    path: str,
    aov_names: Sequence[str],
    color_correction: str = "sRGB",
) -> tuple[list[str], dict[str, str] | None, bool]:
    """How to write ``aov_names`` to ``path``: ``(order, formats, encode_srgb)``.

    Raises:
        OutputError: the extension names no image type, or an 8-bit file is
            asked for without a color AOV.

    """
    if color_correction not in COLOR_CORRECTION_MODES:
        raise OutputError(
            f"unknown color correction mode '{color_correction}'; "
            f"use {' or '.join(COLOR_CORRECTION_MODES)}",
            path=path,
        )
    ext = os.path.splitext(path)[1].lower()
    if not ext:
        raise OutputError(
            f"{path}: no file extension to choose the image type (use .exr, .png, .tif...)",
            path=path,
        )
    if ext in EIGHT_BIT_EXTENSIONS:
        if "color" not in aov_names:
            raise OutputError(f"{path}: an 8-bit image needs the color AOV", path=path)
        held = [a for a in eight_bit_aovs(path) if a in aov_names]
        others = [a for a in aov_names if a not in held]
        if others:
            _log.warning(
                "mipray: %s holds only the %s AOV; write an EXR to keep %s",
                path,
                " and ".join(held),
                ", ".join(others),
            )
        return held, dict.fromkeys(held, "uint8"), color_correction == "sRGB"
    order = list(aov_names)
    if ext == ".exr":
        return order, {a: exr_format(a) for a in order}, False
    if ext in _FLOAT_EXTENSIONS:
        return order, {a: "float" for a in order}, False
    return order, None, False


def check_output(path: str, aov_names: Sequence[str], color_correction: str = "sRGB") -> None:
    """Refuse, before anything renders, an output the write would refuse after the render.

    Raises:
        OutputError: as :func:`output_plan`; or ``path`` is a directory or
            another non-regular file (a device, a FIFO), or its directory
            cannot be made (missing folders are made when the image is
            written) or written to.

    """
    output_plan(path, aov_names, color_correction)
    if os.path.isdir(path):
        raise OutputError(f"{path}: is a directory", path=path)
    if os.path.lexists(path) and not os.path.isfile(path):
        raise OutputError(f"{path}: not a regular file", path=path)
    folder = os.path.dirname(os.path.abspath(path))
    while not os.path.lexists(folder):
        folder = os.path.dirname(folder)
    if not os.path.isdir(folder):
        raise OutputError(f"{path}: {folder} is not a directory", path=path)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: directory {folder} is not writable", path=path)


def _scalar_metadata(metadata: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in metadata.items() if isinstance(v, (str, int, float))}


def write_aovs(
    path: str,
    aovs: Mapping[str, NDArray[np.float32]],
    order: Sequence[str] | None = None,
    *,
    formats: Mapping[str, str] | None = None,
    color_correction: str = "sRGB",
    metadata: Mapping[str, Any] | None = None,
    atomic: bool = False,
) -> None:
    """Write AOVs to one image file, creating its directory if needed.

    Args:
        path: output file; its extension chooses the type (see the module doc).
        aovs: name → H×W×C float32 array, linear.
        order: AOVs to write, in channel order (default: all, as given).
        formats: per-AOV ``"half"``/``"float"``/``"uint8"``, overriding the
            defaults for the file type.
        color_correction: ``"sRGB"`` or ``"disabled"``; affects 8-bit files only.
        metadata: extra image attributes (strings, numbers, 4×4 matrices as 16
            floats).
        atomic: write a hidden temporary file in the same directory (same
            extension, so the same image type) and rename it over ``path``,
            so a reader of ``path`` sees the old image or the new one, never
            a half-written file; the temporary file is removed on failure.

    Raises:
        OutputError: the file cannot be written; the message names it.

    """
    from . import _mipray

    names = list(order) if order is not None else list(aovs)
    missing = [n for n in names if n not in aovs]
    if missing:
        raise OutputError(f"{path}: no AOV named {missing[0]!r} was rendered", path=path)
    order_out, default_formats, encode = output_plan(path, names, color_correction)
    pixels = dict(aovs)
    if encode:
        pixels["color"] = srgb_encode(pixels["color"])
    chosen = dict(default_formats or {})
    chosen.update(formats or {})
    directory = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{path}: cannot create directory: {exc.strerror}", path=path) from exc
    extra = dict(metadata or {})
    target = _temporary_path(path) if atomic else path
    try:
        try:
            _mipray.write_image(target, pixels, order_out, chosen or None, extra or None)
        except TypeError:
            # A binding that takes only scalar attributes: keep what it can store.
            scalars = _scalar_metadata(extra)
            if scalars == extra:
                raise
            _log.debug("mipray: %s: writing without matrix metadata", path)
            _mipray.write_image(target, pixels, order_out, chosen or None, scalars or None)
        if atomic:
            os.replace(target, path)
    except (OSError, ValueError, TypeError, RuntimeError) as exc:
        if atomic:
            _remove_quietly(target)
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        reason = reason.replace(target, path)
        if path not in reason:
            reason = f"{path}: {reason}"
        raise OutputError(f"cannot write image {reason}", path=path) from exc


def _temporary_path(path: str) -> str:
    """A hidden file beside ``path`` with its extension (OpenImageIO picks the type by it).

    The same directory, so the rename is atomic (one file system); the process
    id, so two processes writing one path do not write one temporary file.
    """
    directory, name = os.path.split(os.path.abspath(path))
    stem, ext = os.path.splitext(name)
    return os.path.join(directory, f".{stem}.mipray-{os.getpid()}.tmp{ext}")


def _remove_quietly(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass
