"""Warnings said once per distinct message (a stage re-synced every frame repeats them)."""

from __future__ import annotations

import logging
from collections.abc import Callable

__all__ = ["warn_once"]


def warn_once(logger_name: str) -> Callable[[str], None]:
    """A function that logs each distinct message once, as ``mipray: message``.

    At WARNING, on the logger ``logger_name`` (the calling module's ``__name__``).
    """
    log = logging.getLogger(logger_name)
    warned: set[str] = set()

    def warn(message: str) -> None:
        if message not in warned:
            warned.add(message)
            log.warning("mipray: %s", message)

    return warn
