"""``_mipray.pyi`` states the delegate interface; mypy's stubtest holds it to the compiled
extension (every function, method and parameter: names, kinds, defaults), so the stub cannot
drift from ``python/src``. ``test_protocol.py`` holds the fake delegate to the stub."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import mipray

#: What stubtest cannot read from a pyo3 extension, one reason a line (see the file).
ALLOWLIST = Path(__file__).with_name("stubtest_allowlist.txt")


def test_the_stub_matches_the_extension(native) -> None:
    pytest.importorskip("mypy.stubtest", reason="mypy is in scripts/requirements.txt")
    stub_dir = Path(mipray.__file__).parent.parent
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy.stubtest",
            "mipray._mipray",
            "--allowlist",
            str(ALLOWLIST),
            "--mypy-config-file",
            str(stub_dir / "pyproject.toml"),
        ],
        capture_output=True,
        text=True,
        cwd=stub_dir,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout + done.stderr
