"""Exceptions raised by mipray.

Every message is one line and names the prim path or file it is about, so a
pipeline log shows what to fix without a traceback.
"""

from __future__ import annotations

__all__ = [
    "InternalError",
    "MiprayError",
    "OutputError",
    "PrimDataError",
    "PrimError",
    "RenderSettingsError",
    "StageError",
]


class MiprayError(Exception):
    """Base class of every error mipray raises on purpose."""


class StageError(MiprayError):
    """A USD stage could not be opened or has nothing mipray can render."""

    def __init__(self, message: str, *, path: str | None = None) -> None:
        super().__init__(message)
        #: The USD file the error is about, if any.
        self.path = path


class PrimError(MiprayError):
    """A prim is missing, of the wrong type, or holds data mipray cannot use."""

    def __init__(self, prim_path: str, message: str) -> None:
        super().__init__(f"{prim_path}: {message}")
        #: The USD path of the prim the error is about.
        self.prim_path = prim_path
        #: The problem, without the path.
        self.reason = message

    def __reduce__(self) -> tuple[type[PrimError], tuple[str, str]]:
        # Pickled whole (a Dask worker's error reaches the client so), not from the joined line.
        return (type(self), (self.prim_path, self.reason))


class PrimDataError(PrimError, ValueError):
    """The render delegate refused a prim's data (``mipray._mipray``'s ``set_*``).

    The delegate checks the data once, in Rust, and raises this naming the prim; it is a
    ``ValueError`` too, as the delegate's refusals always were.
    """


class RenderSettingsError(MiprayError):
    """A render setting (image size, AOV, sample count, ...) is invalid."""


class InternalError(MiprayError):
    """The renderer failed outside any one prim's work (a bug); the message says where.

    A failure inside one prim's work drops that prim instead: the render completes and the
    stats' ``prim_errors`` name it (``internal_errors`` counts them).
    """


class OutputError(MiprayError):
    """An output image or statistics file could not be written."""

    def __init__(self, message: str, *, path: str | None = None) -> None:
        super().__init__(message)
        #: The file the error is about, if any.
        self.path = path
