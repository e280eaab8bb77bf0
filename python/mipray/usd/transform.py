"""World transforms as the render delegate takes them.

USD matrices are row-vector (``p_world = p @ m``, translation in the last row);
``numpy.array(Gf.Matrix4d)`` keeps that layout, and so does the delegate, so no
transpose happens anywhere.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pxr import Gf, Usd, UsdGeom

__all__ = ["ancestors_might_vary", "matrix_to_numpy", "world_transform"]


def matrix_to_numpy(m: Gf.Matrix4d) -> NDArray[np.float64]:
    """A ``Gf.Matrix4d`` as a (4, 4) float64 array in the same row-vector layout."""
    return np.array(m, dtype=np.float64).reshape(4, 4)


def world_transform(cache: UsdGeom.XformCache, prim: Usd.Prim) -> NDArray[np.float64]:
    """``prim``'s local-to-world matrix at the cache's time code."""
    return matrix_to_numpy(cache.GetLocalToWorldTransform(prim))


def ancestors_might_vary(prim: Usd.Prim, memo: dict[str, bool]) -> bool:
    """Whether ``prim``'s world transform might change over time.

    True when ``prim`` or any ancestor has time-sampled (or otherwise varying)
    xform ops. ``memo`` caches the answer per path across one traversal, so a
    walk over N prims costs O(N), not O(N × depth).
    """
    chain: list[Usd.Prim] = []
    p = prim
    result = False
    while p and not p.IsPseudoRoot():
        key = str(p.GetPath())
        if key in memo:
            result = memo[key]
            break
        chain.append(p)
        p = p.GetParent()
    # Resolve from the topmost unknown ancestor downward.
    for q in reversed(chain):
        xf = UsdGeom.Xformable(q)
        if not result and xf:
            result = bool(xf.TransformMightBeTimeVarying())
        memo[str(q.GetPath())] = result
    return result
