"""The diagnosis tests run with one BLAS thread (as ``diagnose`` itself, :func:`symoro_gen.diagnostics.stats.single_threaded_blas`).

Many of them call the scoring functions directly (``score_composed``, ``BlockedLS``, ``select_friction``) on
tall, narrow matrices; with OpenBLAS's default two threads on this shared 2-core machine the threads spin
while waiting for a core: ``score_composed`` on the 12,000 rows of ``test_compose`` took 18.6 s CPU (63 s
wall) with two threads and 1.4 s CPU (7.9 s wall) with one, at load ~18. Results differ by rounding only."""
from __future__ import annotations

import pytest


@pytest.fixture(autouse=True, scope="session")
def _one_blas_thread():
    try:
        from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]
    except ImportError:   # pragma: no cover - comes with scikit-learn
        yield
        return
    with threadpool_limits(limits=1, user_api="blas"):
        yield
