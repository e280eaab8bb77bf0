"""Shared fixtures: the fake delegate, the compiled module (or a skip), stage builders.

Tests that need the compiled ``mipray._mipray`` use the ``native`` fixture; it
skips, with the reason, when the module is not built. ``make test`` builds and
installs it first, so in CI they run.
"""

from __future__ import annotations

import importlib
import os
import sys
import types
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TESTS = Path(__file__).resolve().parent

# Use the installed package (maturin develop); fall back to the source tree so
# the pure-Python tests run without a build.
try:
    import mipray  # noqa: F401
except ImportError:
    sys.path.insert(0, str(ROOT / "python"))
if str(TESTS) not in sys.path:
    sys.path.insert(0, str(TESTS))

from fake_delegate import FakeRenderDelegate, fake_module  # noqa: E402

# Linear copies of sRGB textures go to a directory of this run, not the user's ~/.cache.
if not os.environ.get("MIPRAY_TEXTURE_CACHE"):
    import tempfile

    os.environ["MIPRAY_TEXTURE_CACHE"] = tempfile.mkdtemp(prefix="mipray-tx-")


def _native_module() -> tuple[types.ModuleType | None, str]:
    try:
        return importlib.import_module("mipray._mipray"), ""
    except ImportError as exc:
        return None, f"mipray._mipray is not built ({exc}); run `make test` to build it"


@pytest.fixture
def fake() -> FakeRenderDelegate:
    """A fresh recording render delegate."""
    return FakeRenderDelegate()


@pytest.fixture
def native() -> types.ModuleType:
    """The compiled ``mipray._mipray``; skips the test if it is not built.

    In CI (``CI`` set) a missing module is a failure, not a skip: ``make test``
    must have built it.
    """
    module, reason = _native_module()
    if module is None:
        if os.environ.get("CI") and os.environ.get("MIPRAY_REQUIRE_NATIVE", "1") != "0":
            pytest.fail(reason)
        pytest.skip(reason)
    return module


@pytest.fixture
def fake_native(monkeypatch: pytest.MonkeyPatch) -> Iterator[types.ModuleType]:
    """Stand the fake module in for ``mipray._mipray`` for one test."""
    import mipray

    module = fake_module()
    monkeypatch.setitem(sys.modules, "mipray._mipray", module)
    monkeypatch.setattr(mipray, "_mipray", module, raising=False)
    yield module


@pytest.fixture
def repo_root() -> Path:
    """The repository root."""
    return ROOT
