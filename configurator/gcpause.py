"""The cyclic garbage collector paused while a build allocates: a build makes millions of
objects that all live on, and each collection of the young ones walks them again (a third of
the time to validate a 10,000-robot repository)."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def collector_paused() -> Iterator[None]:
    """Reference counting still frees everything at once; cycles left by the build (a few
    per file read) are collected after it. Nested pauses resume only at the outermost."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()
