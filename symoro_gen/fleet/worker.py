"""What a fleet's Dask worker runs once, kept apart from the engine so that a worker imports only the
per-log kernel's path (:mod:`symoro_gen.fleet.kernel`), never the engine's statistics, diagnosis,
robot-file parser (SymPy) or plotting: the worker's start ("cold run") pays for those imports otherwise
(the per-worker setup of docs/fleet.md).
"""
from __future__ import annotations

import ctypes
import os
import sys

from ..observations.fused import model_column_map
from .kernel import resolve_model

try:  # the fleet extra; without it identify_fleet raises MissingDependencyError before any plugin is made
    from distributed.diagnostics.plugin import WorkerPlugin as _WorkerPlugin
except ImportError:  # pragma: no cover - depends on the installation
    _WorkerPlugin = object  # type: ignore[misc,assignment]

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "FleetWorkerSetup", "tune_malloc"]

#: glibc ``mallopt`` parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: arrays up to this size come from the heap, not from fresh ``mmap`` pages (glibc's own ceiling, 32 MiB)
MMAP_THRESHOLD = 32 << 20
#: free memory at the top of the heap kept up to this size (glibc's default ceiling, 2 x the above)
TRIM_THRESHOLD = 64 << 20


def tune_malloc() -> bool:
    """Give a worker process glibc's large-block settings back; True when applied (glibc only).

    A Dask nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (distributed's
    ``nanny.pre-spawn-environ``): setting it turns off glibc's adaptive mmap threshold, so every array
    above 128 KiB is a fresh ``mmap`` whose pages fault in one by one and every free returns them. A
    fleet task allocates arrays of a few MB (the log's columns, the filters' blocks, Welch's segments)
    all the time: measured on 1-minute LWR4 logs, 33k page faults and 0.21-0.23 s CPU per log against
    0.13-0.16 s with these settings (225 faults). Memory stays bounded: freed blocks are reused, and the
    top of the heap is still returned above :data:`TRIM_THRESHOLD`.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))


class FleetWorkerSetup(_WorkerPlugin):
    """Once per worker process (and again on a worker the nanny restarts): :func:`tune_malloc` and the
    model loaded with its column map (:func:`symoro_gen.fleet.kernel.resolve_model`'s per-process cache),
    so that no task pays for them.

    Not applied to a worker living in the client's own process (``threads:N``): the client's allocator
    is left alone there.
    """

    idempotent = True

    def __init__(self, model_ref, client_pid: int):
        self.model_ref = model_ref
        self.client_pid = client_pid
        self.malloc_tuned = False
        self.preloaded = False

    def setup(self, worker=None) -> None:
        if os.getpid() != self.client_pid:
            self.malloc_tuned = tune_malloc()
        if isinstance(self.model_ref, (str, os.PathLike)):
            try:
                model_column_map(resolve_model(self.model_ref))
                self.preloaded = True
            except Exception:  # noqa: BLE001 - a model missing on this worker is reported by each task
                pass
