"""Texture asset paths as files OpenImageIO can open: packaged assets and ``<UDIM>`` tile sets.

**Packages.** A texture inside a ``.usdz`` resolves to a package-relative path
(``/a/model.usdz[textures/wood.png]``) that no image library opens. Its bytes are
read through usd-core's asset resolver (``Ar.GetResolver().OpenAsset``, so any
resolver or package format usd-core knows works) and written once to a private
per-user cache, ``$MIPRAY_TEXTURE_CACHE/packaged`` (else
``~/.cache/mipray/textures/packaged``, the directory the renderer keeps its
decoded textures in), named by a hash of the bytes: the same texture in two
packages is one file, and an edited package gives a new name.

**UDIM.** A file path holding ``<UDIM>`` names a set of tiles, ``1001`` for
``st`` in [0, 1)², ``1002`` one to the right, ``1011`` one up (``1001 + u + 10
v``). The tiles present on disk (or in the package) are listed here; the
renderer looks each ``st`` up in its own tile.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import tempfile
from pathlib import Path

from pxr import Ar

__all__ = ["UDIM_TOKEN", "cache_dir", "local_file", "udim_tiles"]

_log = logging.getLogger(__name__)

#: The tile token in a UDIM file path (as UsdUVTexture and Hydra spell it).
UDIM_TOKEN = "<UDIM>"
#: UDIM tiles are 1001 ... 1100 (10 across, 10 up is as far as the convention goes).
_FIRST_TILE, _LAST_TILE = 1001, 1100

_extracted: dict[str, str] = {}


def cache_dir() -> Path:
    """Where packaged textures are extracted (made private to the user on first use)."""
    root = os.environ.get("MIPRAY_TEXTURE_CACHE")
    if root:
        base = Path(root)
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        home = Path(xdg) if xdg else Path.home() / ".cache"
        base = home / "mipray" / "textures"
    return base / "packaged"


def local_file(resolved: str) -> str:
    """A path OpenImageIO can open for the resolved asset path ``resolved``.

    A plain file path is returned as it is; a package-relative one is extracted (see the
    module doc). Raises OSError (naming the asset) when the package cannot be read.
    """
    if not Ar.IsPackageRelativePath(resolved):
        return resolved
    done = _extracted.get(resolved)
    if done is not None and os.path.exists(done):
        return done
    asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    data = asset.GetBuffer() if asset else None
    if data is None:
        raise OSError(f"cannot read {resolved} from its package")
    _, inner = Ar.SplitPackageRelativePathInner(resolved)
    suffix = Path(inner).suffix.lower()
    folder = cache_dir()
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    target = folder / f"{hashlib.sha256(data).hexdigest()[:32]}{suffix}"
    if not target.exists():
        # Written beside the target and renamed over it: a reader never sees half a file.
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".extract-", suffix=suffix)
        try:
            with os.fdopen(fd, "wb") as out:
                out.write(data)
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    _extracted[resolved] = str(target)
    return str(target)


def udim_tiles(pattern: str) -> list[tuple[int, str]]:
    """The tiles of the UDIM set ``pattern`` (a path holding ``<UDIM>``) that exist.

    As ``(tile number, path OpenImageIO can open)``, in tile order. ``pattern`` is
    resolved per tile: a plain path by looking for the file, a package-relative one
    through the asset resolver (and extracted).
    """
    tiles: list[tuple[int, str]] = []
    if Ar.IsPackageRelativePath(pattern):
        resolver = Ar.GetResolver()
        for tile in range(_FIRST_TILE, _LAST_TILE + 1):
            path = pattern.replace(UDIM_TOKEN, str(tile))
            asset = resolver.OpenAsset(Ar.ResolvedPath(path))
            if asset:
                tiles.append((tile, local_file(path)))
        return tiles
    folder, name = os.path.split(pattern)
    regex = re.compile("^" + re.escape(name).replace(re.escape(UDIM_TOKEN), r"(1\d\d\d)") + "$")
    try:
        entries = os.listdir(folder or ".")
    except OSError:
        return []
    for entry in entries:
        match = regex.match(entry)
        if match and _FIRST_TILE <= int(match.group(1)) <= _LAST_TILE:
            tiles.append((int(match.group(1)), os.path.join(folder, entry)))
    return sorted(tiles)
