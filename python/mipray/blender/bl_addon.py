"""The add-on's ``__init__.py`` in the zip ``make blender-addon`` writes (mipray_blender.zip).

The zip holds this file as ``mipray_blender/__init__.py`` and the ``mipray`` package, with its
compiled module, under ``mipray_blender/lib/``. Blender's add-on installer reads ``bl_info``
from here; ``register`` puts ``lib`` first on ``sys.path`` so the mipray shipped with the
add-on is the one imported, then registers :mod:`mipray.blender`. numpy and ``pxr`` come from
Blender's own Python. The compiled module is built for one platform and Python (that of the
machine that made the zip: Linux x86-64, CPython 3.11, Blender 4.2 to 5.0) and links the
system's OpenImageIO and OpenSubdiv.
"""

import os
import sys

bl_info = {
    "name": "mipray",
    "author": "mipray",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "Properties > Render > Render Engine > mipray",
    "description": "mipray: multiresolution geometry caching ray tracer (Christensen et al. 2003)",
    "category": "Render",
}

_LIB = os.path.join(os.path.dirname(os.path.abspath(__file__)), "lib")


def register() -> None:
    """Register mipray's render engine, from the mipray this add-on ships."""
    if _LIB not in sys.path:
        sys.path.insert(0, _LIB)
    from mipray import blender

    blender.register()


def unregister() -> None:
    """Unregister what :func:`register` registered."""
    from mipray import blender

    blender.unregister()
