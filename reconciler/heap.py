"""Gives the memory a large step freed back to the system: glibc keeps freed memory in its heap
when live objects sit between the free pages, and a 10,000-robot publish or build frees tens
of megabytes that way. `malloc_trim` returns those pages; elsewhere (musl, macOS) a no-op."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import logging
from collections.abc import Callable

log = logging.getLogger("robotconf.reconciler")


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        trim: Callable[[int], int] = ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):  # not glibc
        return None
    return trim


def release() -> None:
    """Returns the free pages of the C heap to the system (a few milliseconds)."""
    trim = _malloc_trim()
    if trim is None:
        return
    try:
        trim(0)
    except Exception:  # a step is never failed by housekeeping
        log.debug("malloc_trim failed", exc_info=True)
