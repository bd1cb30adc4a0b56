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
    shifted_residual,
    simulated_noise_placebo,
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


def test_shifted_residual_rotates_every_segment_by_one_shift_per_experiment():
    # rows joint-major: 3 joints x (experiment 0: 40 samples, experiment 1: 25 samples)
    exp = np.concatenate([np.r_[np.zeros(40, int), np.ones(25, int)]] * 3)
    joint = np.repeat(np.arange(3), 65)
    e = np.random.default_rng(0).normal(size=exp.size)
    out = shifted_residual(e, joint * 100000 + exp, exp, np.random.default_rng(1))
    for x in (0, 1):
        shifts = set()
        for j in range(3):
            m = (joint == j) & (exp == x)
            seg, new = e[m], out[m]
            k = [s for s in range(seg.size) if np.array_equal(np.roll(seg, s), new)]
            assert len(k) == 1, (x, j)                 # a circular shift of the segment
            assert 0.2 * seg.size - 1 <= k[0] <= 0.8 * seg.size + 1
            shifts.add(k[0])
        assert len(shifts) == 1                        # the same for every joint of the experiment
    fixed = shifted_residual(e, joint * 100000 + exp, exp, np.random.default_rng(1), fraction=0.5)
    np.testing.assert_array_equal(fixed[:40], np.roll(e[:40], 20))


def _searched_selection(A, blocks, cols):
    """Best of many candidate columns by time-blocked CV: the gain it claims (relative decrease of the
    out-of-fold squared error), 0 when no column lowers it."""
    def gain(y):
        cv = BlockedLS(A, y, blocks)
        e0 = cv.oof_residual()
        s0 = float(e0 @ e0)
        best = min(float(np.sum(cv.oof_residual(cols[:, [i]]) ** 2)) for i in range(cols.shape[1]))
        return max(0.0, 1.0 - best / s0)
    return gain


def test_simulated_noise_placebo_rejects_a_searched_gain_on_noise_and_keeps_a_real_effect():
    """A selection that searches 25 shapes on the folds that judge them claims a CV gain on pure noise in
    most recordings; against its own null replicates (the fit plus the residual shifted in time) such a
    gain passes about as often as the Monte Carlo level, a real effect always."""
    r = 200
    t = np.linspace(0.0, 1.0, r)
    A = np.column_stack([np.ones(r), np.sin(2 * np.pi * t), np.cos(2 * np.pi * 3 * t)])
    blocks = time_blocks(np.zeros(r, int), np.arange(r), 5)
    rng = np.random.default_rng(3)
    cols = np.column_stack([np.sin(2 * np.pi * f * t + ph) for f, ph in zip(rng.uniform(2, 30, 25),
                                                                              rng.uniform(0, 6.3, 25))])
    gain = _searched_selection(A, blocks, cols)
    seg = np.zeros(r, int)
    claimed, passed_null, passed_real = 0, 0, 0
    for k in range(10):
        nrng = np.random.default_rng(100 + k)
        y0 = A @ np.array([1.0, 2.0, -1.0])
        for real in (False, True):
            y = y0 + 0.3 * nrng.normal(size=r) + (0.25 * cols[:, 7] if real else 0.0)
            fit = A @ np.linalg.lstsq(A, y, rcond=None)[0]
            g = gain(y)
            ok, null = simulated_noise_placebo(gain, fit, y - fit, seg, seg, g, n_rep=19,
                                               rng=np.random.default_rng(k))
            if real:
                passed_real += ok
            else:
                claimed += g > 0
                passed_null += ok
    assert claimed >= 7            # the searched selection claims a gain on noise most of the time
    assert passed_null <= 2        # ~5 % expected
    assert passed_real == 10


def test_blocked_ls_with_a_new_y_equals_a_fresh_fit():
    """The fold bases are reused for another y on the same design (the placebo's replicates)."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(120, 4))
    X = rng.normal(size=(120, 2))
    blocks = time_blocks(np.zeros(120, int), np.arange(120), 5)
    y1, y2 = rng.normal(size=120), rng.normal(size=120)
    BlockedLS(A, y1, blocks)                                   # caches the bases of (A, blocks)
    reused = BlockedLS(A, y2, blocks).oof_residual(X)
    from symoro_gen.diagnostics import stability
    stability._FOLD_CACHE.clear()
    np.testing.assert_allclose(reused, BlockedLS(A, y2, blocks).oof_residual(X), rtol=1e-12, atol=1e-12)


def test_sided_selection_needs_both_sides_of_a_change():
    """Five held-out blocks of 20 rows, a change at row 30: blocks 0 (before), 1 (straddling), 2-4 (after)."""
    from symoro_gen.diagnostics.stability import sided_selection

    rows = np.arange(100)
    tests = [(rows // 20) == k for k in range(5)]
    before = rows < 30
    # lowers the held-out error after the change only (the TX40 joint-5 viscous step): rejected
    assert sided_selection(lambda k, r: not np.any(r & before), tests, before) == 0.0
    # on both sides everywhere: 1
    assert sided_selection(lambda k, r: True, tests, before) == 1.0
    # before: blocks 0 and the first half of 1; selected in 1 of those 2 -> 0.5 (not "most")
    assert sided_selection(lambda k, r: k != 0, tests, before) == 0.5
    # a change no held-out rows precede is not testable
    assert sided_selection(lambda k, r: True, tests, np.zeros(100, bool)) == 0.0
