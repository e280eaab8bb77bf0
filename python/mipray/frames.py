"""Frame specs and frame placeholders, as usdrecord takes them.

A frame spec is ``F``, ``F:L`` or ``F:LxS`` (start, end and stride time codes;
the stride defaults to 1, or -1 when ``L < F``), several joined by commas:
``101:109x2,120``. An output path for several frames holds exactly one
placeholder of ``#`` marks, optionally with a fractional part:
``out.####.exr`` gives ``out.0101.exr``, ``out.###.##.exr`` gives
``out.101.50.exr``; the placeholder's width is the zero-padded width.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .session import RenderResult
    from .usd.unsupported import Unsupported

__all__ = [
    "FrameSpecError",
    "format_frame_path",
    "frame_placeholder",
    "frames_precision",
    "parse_frame_spec",
    "write_frame",
]

_PLACEHOLDER = re.compile(r"#+(?:\.#+)?")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_SPEC = re.compile(rf"^\s*({_NUMBER})\s*(?::\s*({_NUMBER})\s*(?:x\s*({_NUMBER})\s*)?)?$")

#: Bound on the frames one spec may expand to, so a typo cannot hang a farm job.
MAX_FRAMES = 1_000_000


class FrameSpecError(ValueError):
    """A frame spec or frame placeholder that cannot be used; one-line message."""


def parse_frame_spec(spec: str) -> list[float]:
    """The time codes of a comma-separated list of frame specs, in order.

    Raises:
        FrameSpecError: a malformed spec, a zero stride, or a stride going
            away from the end frame.

    """
    frames: list[float] = []
    for part in spec.split(","):
        match = _SPEC.match(part)
        if not match:
            raise FrameSpecError(f"invalid frame spec '{part.strip()}'; expected F, F:L or F:LxS")
        start = float(match.group(1))
        if match.group(2) is None:
            frames.append(start)
            continue
        end = float(match.group(2))
        if match.group(3) is None:
            stride = 1.0 if end >= start else -1.0
        else:
            stride = float(match.group(3))
        if stride == 0.0 or not all(math.isfinite(v) for v in (start, end, stride)):
            raise FrameSpecError(f"invalid frame spec '{part.strip()}': stride must be non-zero")
        if (end - start) * stride < 0.0:
            raise FrameSpecError(
                f"invalid frame spec '{part.strip()}': stride {stride:g} never reaches {end:g}"
            )
        count = math.floor((end - start) / stride + 1e-9) + 1
        if len(frames) + count > MAX_FRAMES:
            raise FrameSpecError(f"frame spec '{spec}' gives more than {MAX_FRAMES} frames")
        frames.extend(start + i * stride for i in range(count))
    return frames


def frames_precision(frames: list[float]) -> int:
    """Decimal places needed to write every frame exactly (0 for whole frames, at most 6)."""
    precision = 0
    for frame in frames:
        while precision < 6:
            scaled = frame * 10**precision
            if abs(scaled - round(scaled)) < 1e-6 * max(1.0, abs(scaled)):
                break
            precision += 1
    return precision


def frame_placeholder(path: str) -> str | None:
    """The single ``###`` or ``###.##`` placeholder in ``path``, or None.

    Raises:
        FrameSpecError: more than one placeholder.

    """
    found = _PLACEHOLDER.findall(path)
    if len(found) > 1:
        raise FrameSpecError(f"'{path}' has {len(found)} frame placeholders; use exactly one")
    return found[0] if found else None


def format_frame_path(path: str, frame: float) -> str:
    """``path`` with its placeholder replaced by ``frame``, zero-padded to its width.

    A path without a placeholder is returned unchanged.
    """
    placeholder = frame_placeholder(path)
    if placeholder is None:
        return path
    decimals = len(placeholder.split(".")[1]) if "." in placeholder else 0
    text = f"{frame:0{len(placeholder)}.{decimals}f}"
    return path.replace(placeholder, text, 1)


def write_frame(
    result: RenderResult,
    path: str,
    aovs: Sequence[str],
    *,
    color_correction: str,
    metadata: Mapping[str, Any] | None,
    unsupported: Sequence[Unsupported],
    dome_opaque: bool,
    atomic: bool,
) -> None:
    """Write one frame of ``mipray-record``, rendered here or on a cluster, the same way.

    What the render settings author that mipray ignores (``unsupported``) joins the stats'
    ``unsupported`` list, and with ``dome_opaque`` (``--enableDomeLightVisibility``) an 8-bit
    image of a scene with a dome light is opaque everywhere, as usdrecord writes it: the
    dome fills every pixel (the alpha AOV itself stays the surfaces' coverage).
    """
    import numpy as np

    from .image import is_eight_bit
    from .usd.unsupported import Unsupported

    if unsupported:
        listed = [Unsupported(**u) for u in result.stats.get("unsupported", [])]
        result.stats["unsupported"] = [u.as_dict() for u in sorted({*listed, *unsupported})]
    if dome_opaque and is_eight_bit(path) and result.dome_background and "alpha" in result.aovs:
        result.aovs["alpha"] = np.ones_like(result.aovs["alpha"])
    result.write(path, aovs, color_correction=color_correction, metadata=metadata, atomic=atomic)
