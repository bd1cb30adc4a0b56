"""The shortcuts that make ``diagnose`` fast (60 s budget) give what the long way gives:
p-value tails from ``scipy.special`` against ``scipy.stats``, the HAC covariance on sliced contiguous
segments against the Bartlett sum, confidence intervals from a fold's basis against a fresh SVD,
reused time-blocked folds against new ones (and never stale), fit-independent candidate columns
built once per frame against a fresh build, and the BLAS thread limit."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sst

from symoro_gen.diagnostics import stability
from symoro_gen.diagnostics.candidates import make_families
from symoro_gen.diagnostics.stats import f_sf, hac_covariance, segments_of, single_threaded_blas, wald_test
from tests.diagnostics.simdata import friction_selection_case, joint_design_case


def test_f_and_chi2_tails_equal_scipy_stats():
    rng = np.random.default_rng(3)
    for _ in range(200):
        x = float(rng.exponential(3.0))
        d1, d2 = int(rng.integers(1, 30)), int(rng.integers(1, 5000))
        assert f_sf(x, d1, d2) == pytest.approx(float(sst.f.sf(x, d1, d2)), rel=1e-12, abs=1e-300)
    b = rng.standard_normal(3)
    C = np.diag(rng.uniform(0.5, 2.0, 3))
    W, p = wald_test(b, C)
    assert p == pytest.approx(float(sst.chi2.sf(W, 3)), rel=1e-12)
    W, p = wald_test(b, C, 40)
    assert p == pytest.approx(float(sst.f.sf(W / 3, 3, 40)), rel=1e-12)


@pytest.mark.parametrize("L", [0, 1, 7])
def test_hac_on_contiguous_and_scattered_segments_is_the_bartlett_sum(L):
    """Contiguous segments are sliced, scattered ones indexed: both equal the explicit Newey-West sum."""
    rng = np.random.default_rng(L)
    r, p = 300, 2
    Z = rng.standard_normal((r, p))
    for groups in (np.repeat([0, 1, 2], 100), rng.integers(0, 3, r)):
        ref = np.zeros((p, p))
        for idx in segments_of(groups, r):
            z = Z[idx]
            for lag in range(-L, L + 1):
                w = 1.0 - abs(lag) / (L + 1.0)
                a, b = (z[lag:], z[:z.shape[0] - lag]) if lag >= 0 else (z[:lag], z[-lag:])
                ref += w * a.T @ b
        got = hac_covariance(Z, max_lag=L, segments=segments_of(groups, r))
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)


def _design(seed=0, r=600, k=5):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((r, k))
    X = rng.standard_normal((r, 2))
    y = A @ rng.standard_normal(k) + 0.3 * X[:, 0] + rng.standard_normal(r)
    blocks = stability.time_blocks(np.zeros(r, int), np.arange(r), 5)
    w = rng.uniform(0.5, 2.0, r)
    return A, X, y, blocks, w


def test_ci_from_a_fold_basis_equals_the_ci_from_its_own_svd():
    A, X, y, blocks, w = _design()
    cv = stability.BlockedLS(A, y, blocks, w)
    groups = np.zeros(y.size, int)
    for f in cv.folds:
        tr = f.train
        a = stability.coefficient_ci(A[tr], X[tr], y[tr], weights=w[tr], groups=groups[tr], level=0.99)
        b = stability.coefficient_ci(A[tr], X[tr], y[tr], weights=w[tr], groups=groups[tr], level=0.99,
                                     basis=(f.U, f.rank))
        np.testing.assert_allclose(b.values, a.values, rtol=1e-12)
        np.testing.assert_allclose(b.std, a.std, rtol=1e-12)
        assert b.p_value == pytest.approx(a.p_value, rel=1e-9, abs=1e-300)
    # and the t quantile of the intervals is scipy.stats' one
    ci = stability.coefficient_ci(A, X, y, level=0.95)
    tq = (ci.high - ci.values) / ci.std
    np.testing.assert_allclose(tq, sst.t.ppf(0.975, y.size - A.shape[1] - 2), rtol=1e-10)


def test_reused_folds_are_never_stale():
    A, X, y, blocks, w = _design(1)
    first = stability.BlockedLS(A, y, blocks).oof_residual(X)
    again = stability.BlockedLS(A, y, blocks)            # same inputs: the folds are reused
    np.testing.assert_array_equal(again.oof_residual(X), first)
    A[:, 0] *= 2.0                                        # changed in place: refitted, not reused
    A[:, 1] += 0.5 * A[:, 2] + np.linspace(0.0, 1.0, A.shape[0])
    fresh = stability.BlockedLS(A, y, blocks)
    stability._FOLD_CACHE.clear()
    ref = stability.BlockedLS(A, y, blocks)
    np.testing.assert_allclose(fresh.oof_residual(X), ref.oof_residual(X), rtol=1e-12, atol=1e-12)
    assert not np.allclose(fresh.oof_residual(X), first)
    yw = y + 0.1                                          # another y (or weights): refitted too
    np.testing.assert_allclose(stability.BlockedLS(A, yw, blocks, w).oof_residual(X),
                               _fresh(A, yw, blocks, w).oof_residual(X), rtol=1e-12, atol=1e-12)


def _fresh(A, y, blocks, w):
    stability._FOLD_CACHE.clear()
    return stability.BlockedLS(A, y, blocks, w)


def test_fit_independent_columns_are_built_once_per_frame_and_equal_a_fresh_build():
    from dataclasses import replace

    from symoro_gen.diagnostics.frame import build_frame

    from .simdata import recording

    model, tr = recording("scara", 5, duration=8.0, dt=0.01)
    F = build_frame(model, [tr])
    fams = [f for f in make_families(F) if not f.depends_on_fit]
    assert fams
    raw = make_families(F)      # a second set: its own caches
    for fam in fams:
        X1 = fam.build(F, None)
        X2 = fam.build(replace(F, sig=dict(F.sig)), None)    # same signals (the model torque re-attached)
        assert all(a is b for a, b in zip(X1, X2))
        assert all(not a.flags.writeable for a in X1)
        ref = next(f for f in raw if f.key == fam.key).build(F, None)
        for a, b in zip(X1, ref):
            np.testing.assert_array_equal(a, b)
    # other signals (another recording of the same robot): built anew
    model2, tr2 = recording("scara", 6, duration=8.0, dt=0.01)
    F2 = build_frame(model2, [tr2])
    fam = next(f for f in fams if f.kind == "spring")
    assert not np.array_equal(fam.build(F2, None)[0], fam.build(F, None)[0])


def test_blas_is_single_threaded_inside_diagnose_only():
    threadpoolctl = pytest.importorskip("threadpoolctl", reason="threadpoolctl comes with scikit-learn (extra diagnose)")

    def blas_threads():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

    if not blas_threads():
        pytest.skip("no BLAS library seen by threadpoolctl")
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):   # (these tests run with one: conftest)
        outside = blas_threads()
        if max(outside) < 2:
            pytest.skip("the BLAS library here runs one thread only")
        inside = single_threaded_blas(blas_threads)()
        assert inside and all(n == 1 for n in inside)
        assert blas_threads() == outside


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_blocked_ls_column_factors_equal_the_straightforward_solve(seed):
    """The out-of-fold fit of added columns from factors kept per (folds, X) - computed on the rows where
    X is not zero and reused for every y - equals the rank-revealing solve on all training rows (and an
    independent refit of each fold), for columns on one joint's rows, on all rows, nearly collinear
    columns (which take the rank-revealing path) and a y changed under kept factors."""
    n, s, k = 4, 250, 12
    r = n * s
    rng, joint, A, w, blocks = joint_design_case(seed, n, s, k)
    one = np.zeros((r, 2))
    one[joint == 1] = rng.standard_normal((s, 2))
    dense = rng.standard_normal((r, 3))
    z = rng.standard_normal(s)
    collinear = np.zeros((r, 2))
    collinear[joint == 2] = np.column_stack([z, z + 1e-9 * rng.standard_normal(s)])
    stability._FOLD_CACHE.clear()
    for X in (one, dense, collinear, one):      # the last: factors kept, new y
        y = A @ rng.standard_normal(k) + X @ rng.standard_normal(X.shape[1]) + rng.standard_normal(r)
        cv = stability.BlockedLS(A, y, blocks, w)
        got = cv.oof_residual(X)
        direct = cv.oof_residual_direct(X)
        scale = float(np.max(np.abs(direct)))
        np.testing.assert_allclose(got, direct, rtol=0, atol=1e-10 * scale)
        if X is collinear:
            continue
        ref = np.empty(r)
        M = np.hstack([A, X])
        for tr, te in stability.blocked_folds(blocks):
            th = np.linalg.lstsq(M[tr] * w[tr, None], y[tr] * w[tr], rcond=None)[0]
            ref[te] = y[te] - M[te] @ th
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * scale)


def test_friction_law_selection_with_kept_columns_equals_a_fresh_one(monkeypatch):
    """The friction-law selection re-run on another y with the same columns hook (as its simulated-noise
    placebo does) - law columns and column factors kept from the first run - chooses and scores exactly
    what a run that keeps nothing gives."""
    from symoro_gen.diagnostics import friction
    from symoro_gen.diagnostics.friction import select_friction

    J, dq_rows, A, blocks, hook, signal, rng = friction_selection_case(11, 600)

    def run(y):
        ch = select_friction(A, y, J, 1, dq_rows, blocks, columns=hook)
        return ch.coulomb, ch.viscous, [(c.law, c.param, c.cv_rel_err) for c in ch.candidates]

    ys = [signal + 0.05 * rng.standard_normal(signal.size) for _ in range(3)]
    kept = [run(y) for y in ys]                     # the 2nd and 3rd hit the kept columns and factors
    monkeypatch.setattr(friction, "LAW_COLUMNS_BYTES", 0)
    monkeypatch.setattr(stability, "COLUMN_CACHE_BYTES", 0)
    for y, (c, v, tried) in zip(ys, kept):
        friction._LAW_COLUMNS.clear()
        stability._FOLD_CACHE.clear()
        c0, v0, tried0 = run(y)
        assert (c.law, v.law) == (c0.law, v0.law)
        assert [x[0] for x in tried] == [x[0] for x in tried0]
        np.testing.assert_allclose([x[2] for x in tried], [x[2] for x in tried0], rtol=1e-10)
        np.testing.assert_allclose([x[1] for x in tried if x[1] is not None],
                                   [x[1] for x in tried0 if x[1] is not None], rtol=1e-6)


def test_products_on_contiguous_row_runs_equal_the_gathered_products():
    """Products taken on the contiguous runs of a row set (a joint's rows of a fold) equal those on the
    gathered rows, with few runs and with more than MAX_RUNS (the gathered fallback)."""
    from symoro_gen.diagnostics.stats import MAX_RUNS, contiguous_runs, rows_times, span_product

    rng = np.random.default_rng(5)
    r = 900
    U = rng.standard_normal((r, 7))
    v = rng.standard_normal((7, 2))
    for rows in (np.zeros(r, bool), (np.arange(r) // 50) % 4 == 1, rng.random(r) < 0.3):
        idx = np.flatnonzero(rows)
        runs = contiguous_runs(idx)
        if runs is not None:
            assert np.array_equal(np.concatenate([np.arange(a, b) for _, a, b in runs] or [np.zeros(0, int)]), idx)
            assert all(idx[i] == a for i, a, _ in runs)
        else:
            assert np.count_nonzero(np.diff(idx) != 1) >= MAX_RUNS
        np.testing.assert_allclose(rows_times(U, rows, v), U[rows] @ v, rtol=1e-13, atol=1e-13)
        X = np.where(rows[:, None], rng.standard_normal((r, 2)), 0.0)
        np.testing.assert_allclose(span_product(U, X), U.T @ X, rtol=1e-12, atol=1e-12)
