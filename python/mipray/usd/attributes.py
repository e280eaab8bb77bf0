"""Attribute readers shared by :mod:`mipray.usd.gprim` and :mod:`mipray.usd.curves`."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import DTypeLike, NDArray
from pxr import Usd

from ..errors import PrimError

__all__ = ["check_vertex_counts", "read_array"]


def read_array(
    attr: Usd.Attribute, time: Usd.TimeCode, dtype: DTypeLike, *shape: int
) -> NDArray[Any]:
    """``attr``'s value at ``time`` as ``dtype``, one element of ``shape`` a row.

    An unauthored or empty attribute reads as no rows.
    """
    return np.asarray(attr.Get(time) or [], dtype=dtype).reshape(-1, *shape)


def check_vertex_counts(path: str, counts: NDArray[np.integer[Any]], n_points: int) -> None:
    """Checks that ``curveVertexCounts`` (``counts``) add up to the ``n_points`` points.

    Raises:
        PrimError: they do not (the message names both attributes).

    """
    if int(counts.sum()) != n_points:
        # The delegate would refuse it too; said here with the attribute's USD name.
        raise PrimError(
            path,
            f"curveVertexCounts add up to {int(counts.sum())} vertices but points has {n_points}",
        )
