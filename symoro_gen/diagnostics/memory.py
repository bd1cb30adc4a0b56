"""Freed memory handed back to the operating system between the stages of the diagnosis loop.

The loop's transients (candidate columns decimated by stretches, out-of-fold bases, model torques of each
refit) are arrays of a few MB, below glibc's dynamic mmap threshold (up to 32 MB), so they live in the heap
and, once freed, stay there: the heap's free space is fragmented between longer-lived arrays, and the
resident set grows with the recording although the arrays alive do not (measured in
``docs/benchmarks.md``, "Memory: freed heap returned at the stage boundaries"). glibc's ``malloc_trim(0)``
returns every free page of the heap, not only its top (``madvise(MADV_DONTNEED)`` on the free chunks'
whole pages, glibc >= 2.8; ``man 3 malloc_trim``). :func:`release_freed_memory` calls it where the loop
has just dropped a stage's or a round's transients; it moves no live object and changes no number.
Elsewhere than glibc (musl, macOS, Windows) it does nothing.
"""
from __future__ import annotations

import ctypes
import functools
import sys
from collections.abc import Callable

__all__ = ["release_freed_memory"]


@functools.lru_cache(maxsize=1)
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim`` of this process, or None where the C library has none."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_size_t]
    fn.restype = ctypes.c_int
    return fn


def release_freed_memory() -> bool:
    """Return the heap's free pages to the operating system (glibc ``malloc_trim(0)``).

    Returns True when memory was released, False when none was or the C library has no ``malloc_trim``."""
    fn = _malloc_trim()
    return bool(fn(0)) if fn is not None else False
