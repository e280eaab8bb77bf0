"""mipray's AOVs as Blender render passes, from the AOV table (:data:`mipray.aovs.TABLE`).

Blender names its standard passes itself (``Combined``, ``Depth``, ``Normal``, ``AO``,
``DiffCol``), so the AOVs that mean the same take those names and the compositor's Render
Layers node and the image editor treat them as Cycles' passes; every other AOV is a pass of
its own name (``beamWidth``, ``tessRate``, ``tessError``, ...). This module needs no ``bpy``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import aovs as _aovs

__all__ = ["COMBINED", "BlenderPass", "blender_passes", "pass_pixels"]

#: Blender's pass that holds the image: mipray's ``color`` with ``alpha`` as its fourth channel.
COMBINED = "Combined"

#: AOV → (Blender's pass name, channel ids, pass type) where Blender has a pass of that meaning.
#: ``ao`` is one channel in mipray and RGB in Blender (grey), ``albedo`` is Cycles' Diffuse
#: Color.
_STANDARD = {
    "depth": ("Depth", "Z", "VALUE"),
    "normal": ("Normal", "XYZ", "VECTOR"),
    "ao": ("AO", "RGB", "COLOR"),
    "albedo": ("DiffCol", "RGB", "COLOR"),
}
#: Channel ids of mipray's own passes, by channel count (Blender's passes take 1 to 4).
_CHANNEL_IDS = {1: "X", 2: "XY", 3: "XYZ", 4: "XYZW"}
#: AOVs Combined holds; never passes of their own.
_IN_COMBINED = ("color", "alpha")


@dataclass(frozen=True)
class BlenderPass:
    """One Blender render pass made from one mipray AOV."""

    #: The AOV's name in mipray's table.
    aov: str
    #: The pass's name in Blender's render result and compositor.
    name: str
    #: One letter a channel (``"Z"``, ``"XYZ"``, ``"RGB"``); its length is the channel count.
    chan_id: str
    #: ``"VALUE"``, ``"VECTOR"`` or ``"COLOR"`` (the compositor socket's type).
    type: str
    #: Tooltip: the AOV's meaning from the table.
    meaning: str

    @property
    def channels(self) -> int:
        """Channels of the pass in Blender's render result."""
        return len(self.chan_id)


def blender_passes() -> list[BlenderPass]:
    """Every AOV that can be a Blender pass besides Combined, in the AOV table's order."""
    passes = []
    for name, row in _aovs.TABLE.items():
        if name in _IN_COMBINED:
            continue
        if name in _STANDARD:
            blender_name, chan_id, kind = _STANDARD[name]
        else:
            chan_id = _CHANNEL_IDS[row["channels"]]
            blender_name, kind = name, "VALUE" if row["channels"] == 1 else "VECTOR"
        passes.append(BlenderPass(name, blender_name, chan_id, kind, row["meaning"]))
    return passes


def pass_pixels(
    aov: NDArray[np.float32], channels: int, alpha: NDArray[np.float32] | None = None
) -> NDArray[np.float32]:
    """An H×W×C AOV as the rows of a Blender pass: bottom row first, ``channels`` wide.

    Blender's image rows run bottom to top, mipray's top to bottom. A one-channel AOV shown
    in a colour pass (``ao``) is repeated in each channel; ``alpha`` (H×W×1) is appended as
    the fourth channel of Combined.

    Returns:
        A C-contiguous (H·W)×channels float32 array.

    """
    pixels = aov if alpha is None else np.concatenate([aov, alpha], axis=2)
    have = pixels.shape[2]
    if have == 1 and channels > 1:
        pixels = np.repeat(pixels, channels, axis=2)
    elif have != channels:
        raise ValueError(f"AOV has {have} channels, the Blender pass {channels}")
    flipped = pixels[::-1].reshape(-1, channels)
    # No NaN or Inf reaches Blender's buffers (mipray's depth is inf where nothing is hit).
    return np.ascontiguousarray(np.nan_to_num(flipped, nan=0.0, posinf=1e10, neginf=-1e10))
