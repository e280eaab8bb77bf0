"""mipray: a ray tracer for USD scenes with multiresolution geometry caching.

Render a USD file, or a ``Usd.Stage`` you hold, from Python::

    import mipray

    result = mipray.render("shot.usda", camera="/World/cam", width=640,
                           aovs=("color", "depth"), settings={"samples": 4})
    result.aovs["color"]          # H×W×3 float32, linear
    result.stats["render"]["wall_s"]
    result.write("shot.exr")      # every AOV; .png gets sRGB color

For several renders of a stage you edit, keep a :class:`RenderSession`: it
re-syncs only the prims your edits touch. The command ``mipray-record``
(:mod:`mipray.record`) is the usdrecord-like front end. The compiled render
delegate is ``mipray._mipray``; this package imports without it, so the USD
reading side (:mod:`mipray.usd`) can be used and tested on its own.
"""

from __future__ import annotations

import logging
from importlib import metadata as _metadata

# After .session, which it builds on: `mipray.distributed.render_frames` without another import.
from . import distributed
from .errors import (
    InternalError,
    MiprayError,
    OutputError,
    PrimError,
    RenderSettingsError,
    StageError,
)
from .session import SETTINGS, RenderResult, RenderSession, open_stage, render

__all__ = [
    "SETTINGS",
    "InternalError",
    "MiprayError",
    "OutputError",
    "PrimError",
    "RenderResult",
    "RenderSession",
    "RenderSettingsError",
    "StageError",
    "__version__",
    "distributed",
    "open_stage",
    "render",
]

try:
    __version__: str = _metadata.version("mipray")
except _metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())
