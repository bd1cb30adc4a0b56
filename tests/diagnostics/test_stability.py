"""Time-blocked folds, selection frequency, confidence intervals, OLS/WLS agreement and the placebo
stop rule (symoro_gen.diagnostics.stability), against brute-force references."""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen.diagnostics.stability import (
    BlockedLS,
    blocked_folds,
    coefficient_ci,
    ols_wls_agreement,
    placebo_stop,
    selection_frequency,
    stable,
    time_blocks,
)


def test_time_blocks_are_contiguous_equal_and_shared_by_the_joints_of_a_sample():
    # two experiments of 103 and 50 samples, 3 joints each (rows joint-major)
    exp = np.concatenate([np.r_[np.zeros(103, int), np.ones(50, int)]] * 3)
    idx = np.concatenate([np.r_[np.arange(103), np.arange(50)]] * 3)
    b = time_blocks(exp, idx, 5)
    for e, N in ((0, 103), (1, 50)):
        m = exp == e
        per_sample = {}
        for i, bb in zip(idx[m], b[m]):
            assert per_sample.setdefault(i, bb) == bb          # same block for every joint of a sample
        seq = np.array([per_sample[i] for i in range(N)])
        assert np.all(np.diff(seq) >= 0) and set(seq) == set(range(5))  # contiguous, in time order
        sizes = np.bincount(seq)
        assert sizes.max() - sizes.min() <= 1
    folds = blocked_folds(b)
    assert len(folds) == 5
    assert np.all(sum(te.astype(int) for _, te in folds) == 1)          # every row tested exactly once
    assert all(not np.any(tr & te) for tr, te in folds)
    with pytest.raises(ValueError, match="n_blocks"):
        time_blocks(exp, idx, 1)


def test_blocked_ls_matches_refitting_each_fold():
    rng = np.random.default_rng(0)
    r = 400
    A = rng.standard_normal((r, 5))
    X = rng.standard_normal((r, 2))
    w = rng.uniform(0.5, 2.0, r)
    y = A @ rng.standard_normal(5) + X @ [0.3, -0.2] + 0.1 * rng.standard_normal(r)
    blocks = time_blocks(np.zeros(r, int), np.arange(r), 4)
    cv = BlockedLS(A, y, blocks, w)
    got = cv.oof_residual(X)
    ref = np.empty(r)
    M = np.hstack([A, X])
    for tr, te in blocked_folds(blocks):
        th = np.linalg.lstsq(M[tr] * w[tr, None], y[tr] * w[tr], rcond=None)[0]
        ref[te] = y[te] - M[te] @ th
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)
    ref0 = np.empty(r)
    for tr, te in blocked_folds(blocks):
        th = np.linalg.lstsq(A[tr] * w[tr, None], y[tr] * w[tr], rcond=None)[0]
        ref0[te] = y[te] - A[te] @ th
    np.testing.assert_allclose(cv.oof_residual(None), ref0, rtol=1e-9, atol=1e-12)
    assert cv.rel_err(X, np.arange(r)) < cv.rel_err(None, np.arange(r))


def test_coefficient_ci_covers_the_truth_and_rejects_no_effect_only_when_present():
    rng = np.random.default_rng(1)
    r = 600
    hits, false = 0, 0
    for _ in range(40):
        A = np.column_stack([np.ones(r), rng.standard_normal(r)])
        X = rng.standard_normal((r, 1))
        y0 = A @ [1.0, 2.0] + 0.5 * rng.standard_normal(r)
        ci = coefficient_ci(A, X, y0 + 0.2 * X[:, 0], level=0.95)
        hits += ci.low[0] <= 0.2 <= ci.high[0]
        assert ci.excludes_zero                                       # 0.2 is ~9 sigma
        false += coefficient_ci(A, X, y0, level=0.95).excludes_zero
    assert hits >= 34                 # ~95 % coverage
    assert false <= 6                 # ~5 % false "effects"
    # a serially correlated residual along a slow column: the HAC interval is wider than the iid one
    t = np.linspace(0, 1, r)
    e = np.convolve(rng.standard_normal(r + 50), np.ones(50) / 7, "valid")[:r]
    A = np.ones((r, 1))
    X = np.sin(2 * np.pi * 3 * t)[:, None]
    ci = coefficient_ci(A, X, e, level=0.99)
    Xp = X - X.mean()
    ee = e - e.mean() - Xp[:, 0] * float(Xp[:, 0] @ e / (Xp[:, 0] @ Xp[:, 0]))
    iid = np.sqrt(float(ee @ ee) / (r - 2) / float(Xp[:, 0] @ Xp[:, 0]))
    assert ci.std[0] > 1.5 * iid
    with pytest.raises(ValueError, match="level"):
        coefficient_ci(A, X, e, level=1.5)


def test_selection_frequency_and_stable():
    blocks = np.repeat(np.arange(5), 10)

    def select(train):
        held = int(np.setdiff1d(np.arange(5), np.unique(blocks[train]))[0])
        out = [("spring", 2)]
        if held in (0, 1):
            out.append(("drift", 1))
        if held < 3:
            out.append(("gain", 4))
        return out
    f = selection_frequency(select, blocks)
    assert f == {("spring", 2): 1.0, ("drift", 1): 0.4, ("gain", 4): 0.6}
    assert stable(f) == [("spring", 2), ("gain", 4)]


def test_ols_wls_agreement_and_placebo_stop():
    a = ols_wls_agreement([("delay", 5), ("spring", 7)], [("spring", 7), ("gain", 5)])
    assert a.common == (("spring", 7),) and a.only_first == (("delay", 5),) and a.only_second == (("gain", 5),)
    assert "only OLS names ('delay', 5)" in a.message and "only WLS names ('gain', 5)" in a.message
    same = ols_wls_agreement([("spring", 7)], [("spring", 7)])
    assert same.message is None and same.common == (("spring", 7),)
    assert placebo_stop({0: True, 3: False, 5: True}) == frozenset({0, 5})
    assert placebo_stop([2]) == frozenset({2})
