"""Write the Blender add-on zip: ``python scripts/make_blender_addon.py OUT.zip``.

The zip has one folder, ``mipray_blender/``: ``__init__.py`` is
``python/mipray/blender/bl_addon.py`` and ``lib/mipray/`` the ``mipray`` package with its
compiled module, debug symbols stripped when ``strip`` is on the PATH (the dev build's are
most of its size). Blender installs it with Edit > Preferences > Add-ons > Install from Disk.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "python" / "mipray"
ADDON = "mipray_blender"


def _compiled_module() -> Path:
    found = sorted(PACKAGE.glob("_mipray*.so")) + sorted(PACKAGE.glob("_mipray*.pyd"))
    if not found:
        sys.exit(f"make_blender_addon: no compiled module in {PACKAGE}: run `make setup` first")
    return found[0]


def build(out: Path) -> None:
    """Write the add-on zip to ``out``."""
    module = _compiled_module()
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        stripped = Path(tmp) / module.name
        shutil.copy2(module, stripped)
        if shutil.which("strip"):
            subprocess.run(["strip", "--strip-debug", str(stripped)], check=True)
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.write(PACKAGE / "blender" / "bl_addon.py", f"{ADDON}/__init__.py")
            for path in sorted(PACKAGE.rglob("*")):
                relative = path.relative_to(PACKAGE)
                if path.is_dir() or "__pycache__" in relative.parts or path == module:
                    continue
                archive.write(path, f"{ADDON}/lib/mipray/{relative.as_posix()}")
            archive.write(stripped, f"{ADDON}/lib/mipray/{module.name}")
    print(out)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: make_blender_addon.py OUT.zip")
    build(Path(sys.argv[1]))
