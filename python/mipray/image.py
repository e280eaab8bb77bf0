"""Writing AOVs to image files: Python's names for the core's one image writer.

Format choice (each AOV's EXR pixel type from the AOV table, 32-bit float in
other float types, the color AOV only in 8-bit types, and the alpha AOV too in
those with an alpha channel: PNG, TGA and WebP are RGBA as usdrecord writes
them), the sRGB transfer curve
for 8-bit files (unless color correction is disabled, as usdrecord's
``--colorCorrectionMode sRGB``), values a pixel type cannot hold clamped, the
atomic replace and the ``Software`` attribute all live in Rust
(``mipray::image_output``, OpenImageIO through the bridge); this module passes
paths, arrays and options, and turns failures into :class:`OutputError`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import OutputError

__all__ = [
    "COLOR_CORRECTION_MODES",
    "EIGHT_BIT_EXTENSIONS",
    "check_output",
    "eight_bit_aovs",
    "is_eight_bit",
    "output_plan",
    "srgb_encode",
    "write_aovs",
]

#: usdrecord's ``--colorCorrectionMode`` values that mipray supports.
COLOR_CORRECTION_MODES = ("sRGB", "disabled")
#: File extensions whose images hold 8 bits per channel.
EIGHT_BIT_EXTENSIONS = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tga", ".ppm", ".webp"})


def is_eight_bit(path: str) -> bool:
    """Whether ``path``'s extension names an 8-bit image format."""
    return os.path.splitext(path)[1].lower() in EIGHT_BIT_EXTENSIONS


def eight_bit_aovs(path: str) -> list[str]:
    """The AOVs an 8-bit file at ``path`` holds: color, and alpha where the type has alpha."""
    from . import _mipray

    return _mipray.eight_bit_aovs(path)


def srgb_encode(linear: NDArray[np.float32]) -> NDArray[np.float32]:
    """Apply the sRGB transfer curve (IEC 61966-2-1) to linear values, clamped to [0, 1].

    The writer's own curve (``mipray::image_output::srgb_encode``); NaN becomes 0.
    """
    from . import _mipray

    return _mipray.srgb_encode(np.ascontiguousarray(linear, dtype=np.float32))


def output_plan(
    path: str,
    aov_names: Sequence[str],
    color_correction: str = "sRGB",
) -> tuple[list[str], dict[str, str], bool]:
    """How the writer writes ``aov_names`` to ``path``: ``(order, formats, encode_srgb)``.

    Raises:
        OutputError: the extension names no image type, an 8-bit file is
            asked for without a color AOV, or the color correction mode is
            unknown.

    """
    from . import _mipray

    try:
        return _mipray.output_plan(path, list(aov_names), color_correction)
    except ValueError as exc:
        raise OutputError(str(exc).splitlines()[0], path=path) from exc


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


def write_aovs(
    path: str | os.PathLike[str],
    aovs: Mapping[str, NDArray[np.float32]],
    order: Sequence[str] | None = None,
    *,
    formats: Mapping[str, str] | None = None,
    color_correction: str = "sRGB",
    metadata: Mapping[str, Any] | None = None,
    atomic: bool = False,
) -> None:
    """Write AOV arrays to one image file, creating its directory if needed.

    The arrays are read where they are (a render's arrays are Rust's own
    buffers), not copied back.

    Args:
        path: output file; its extension chooses the type (see the module doc).
        aovs: name → H×W×C float32 array, linear.
        order: AOVs to write, in channel order (default: all, as given).
        formats: per-AOV ``"half"``/``"float"``/``"uint8"``, overriding the
            defaults for the file type.
        color_correction: ``"sRGB"`` or ``"disabled"``; affects 8-bit files only.
        metadata: extra image attributes (strings, numbers, 4×4 matrices as 16
            floats); ``Software`` is the writer's.
        atomic: write a hidden temporary file in the same directory (same
            extension, so the same image type) and rename it over ``path``,
            so a reader of ``path`` sees the old image or the new one, never
            a half-written file; the temporary file is removed on failure.

    Raises:
        OutputError: the file cannot be written; the message names it.

    """
    from . import _mipray

    target = os.fspath(path)
    try:
        _mipray.write_image(
            target,
            dict(aovs),
            list(order) if order is not None else None,
            dict(formats) if formats else None,
            dict(metadata) if metadata else None,
            color_correction=color_correction,
            atomic=atomic,
        )
    except (OSError, ValueError, TypeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if target not in reason:
            reason = f"{target}: {reason}"
        raise OutputError(f"cannot write image {reason}", path=target) from exc
