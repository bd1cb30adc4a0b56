"""Memory of ``diagnose`` bounded by the decimated system, not by the number of candidates or the full-rate rows:
the composed tests keep one plain design at a time (:func:`symoro_gen.diagnostics.compose.score_composed`), and
the full-rate validation frame of the report builds its per-row signals only when a column reads them
(:func:`symoro_gen.diagnostics.core._full_rate_frame`). Both give the same numbers as before."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from symoro_gen.diagnostics.compose import TIME_SIGNALS, _Tester, library, score_composed
from symoro_gen.diagnostics.core import _full_rate_frame
from symoro_gen.diagnostics.frame import build_frame, common_bandwidth

from .simdata import recording
from .test_compose import setup


def _one_design_per_test(A, y, sig, fams):
    """The composed tests as written before the grouping: every member's plain design built afresh (the
    independent reference of the grouped path)."""
    tester = _Tester(A, y, np.ones(y.size), np.asarray(sig.joint), sig.joint)
    out = {}
    for f, fam in enumerate(fams):
        for i, c in enumerate(fam):
            base = tester.with_plain(np.hstack([c.plain_columns(sig), c.confounder_columns(sig)]))
            out[f, i] = tester(c.columns(sig), c.joint, base=base)
    return out


def _peak(fn):
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_composed_tests_hold_one_plain_design_at_a_time():
    """score_composed's p-values, coefficients and drops equal the tests with each member's plain design built
    afresh, and its peak memory stays within a few bases of the model (r x rank) although the library has
    dozens of plain designs (keeping them all was the growth of a diagnose round with the recording)."""
    d, sig, y, _ = setup(3, duration=10.0)
    A = d["W"]
    fams = library(sig, joints=[0])
    keys = {(c.effect, c.joint, c.order if c.effect == "ripple" else None, c.coulomb_v, c.signal in TIME_SIGNALS)
            for fam in fams for c in fam}
    assert len(keys) >= 20
    ref = _one_design_per_test(A, y, sig, fams)
    res = score_composed(A, y, sig, families=fams, alpha=0.5)
    assert res
    for r in res:
        f = next(k for k, fam in enumerate(fams) if r.candidate in fam)
        i = fams[f].index(r.candidate)
        pv, b, drop = ref[f, i]
        assert r.p_value == pytest.approx(pv, rel=1e-12, abs=1e-300)
        np.testing.assert_allclose(r.coefficients, b, rtol=1e-12, atol=0)
        assert r.rss_drop == pytest.approx(drop, rel=1e-12, abs=1e-15)
    basis = A.shape[0] * np.linalg.matrix_rank(A) * 8
    peak = _peak(lambda: score_composed(A, y, sig, families=fams))
    assert peak < 6 * basis, (peak / basis, len(keys))


@pytest.fixture(scope="module")
def scara_frame():
    model, tr = recording("scara", 21, noise_q=1e-4)
    return build_frame(model, [tr], dynamics_bandwidth_hz=common_bandwidth([tr]))


def test_full_rate_frame_builds_its_row_signals_on_access(scara_frame):
    """The full-rate frame's row signals are every joint's full-rate signals at each row's sample (built from
    the experiments here, independently), its Y the raw torque of the row's joint; building the frame without
    reading them allocates less than the four (r, n) signals a frame built up front holds (on top of the same
    row indices)."""
    F = scara_frame
    R = _full_rate_frame(F)
    ex = F.experiments[0]
    n, M = F.n_joints, ex.n_samples
    assert R.n_rows == n * M
    np.testing.assert_array_equal(R.system.Y, ex.tau.T.ravel())
    for k in ("q", "dq", "ddq", "tau"):
        np.testing.assert_array_equal(R.sig[k], np.tile(getattr(ex, k), (n, 1)))
    np.testing.assert_array_equal(R.sig["t"], np.tile(ex.t, n))
    assert set(R.sig) == {"q", "dq", "ddq", "tau", "t"}
    one_signal = n * M * n * 8
    peak = _peak(lambda: _full_rate_frame(F))
    assert peak < 4 * one_signal, (peak, one_signal)


def _rss_bytes() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS line")


def test_release_freed_memory_returns_the_fragmented_heap():
    """Arrays of 64 KB (below glibc's smallest mmap threshold, 128 KB: always in the heap) freed between
    small arrays still alive leave a heap whose top cannot shrink; ``malloc_trim(0)`` hands the free
    pages back, so the resident set falls by most of what was freed (the loop's transients between
    stages, :mod:`symoro_gen.diagnostics.memory`)."""
    from symoro_gen.diagnostics.memory import _malloc_trim, release_freed_memory

    if _malloc_trim() is None:
        pytest.skip("no glibc malloc_trim in this process")
    release_freed_memory()
    count, size = 1024, 64 * 1024            # 64 MB of transients
    transient, alive = [], []
    for _ in range(count):
        transient.append(np.ones(size // 8))  # written: its pages are resident
        alive.append(np.ones(512))            # small arrays (above numpy's cache of small buffers) pin the heap
    before = _rss_bytes()
    del transient
    kept = _rss_bytes()
    assert release_freed_memory()
    after = _rss_bytes()
    freed = count * size
    assert kept - after > 0.5 * freed, (before, kept, after)
    assert len(alive) == count


@pytest.mark.slow
def test_diagnose_keeps_no_fold_bases_once_it_returns():
    """The blocked least squares keep the fold bases of their last design for the next fit on it (module
    cache); a diagnosis leaves that cache empty when it returns, so none of its designs stays alive
    (measured: its out-of-fold bases and column factors are the largest arrays of the loop after ``W``).
    The cache is filled during the loop (checked by a fit on the frame before the call)."""
    from symoro_gen.diagnostics import diagnose, stability

    model, tr = recording("scara", 21, noise_q=1e-4)
    F = build_frame(model, [tr], dynamics_bandwidth_hz=common_bandwidth([tr]))
    stability.BlockedLS(F.system.W, F.system.Y, stability.time_blocks(F.row_experiment, F.row_index, 5))
    assert stability._FOLD_CACHE
    rep = diagnose(model, [tr])
    assert rep.n_joints == model.N_JOINTS
    assert not stability._FOLD_CACHE
