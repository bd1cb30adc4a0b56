"""The statistics of the diagnosis against direct computations and known null distributions."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sst

from symoro_gen.diagnostics.stats import (
    binned_anova,
    fisher_g_test,
    hac_covariance,
    long_run_factor,
    nested_f_test,
    wald_test,
)


def _hac_reference(Z, groups, L):
    S = np.zeros((Z.shape[1], Z.shape[1]))
    for g in np.unique(groups):
        z = Z[groups == g]
        S += z.T @ z
        for l in range(1, min(L, len(z) - 1) + 1):
            C = z[l:].T @ z[:-l]
            S += (1 - l / (L + 1)) * (C + C.T)
    return S


@pytest.mark.parametrize("L", [0, 1, 4, 9, 40])
def test_hac_equals_bartlett_sum(L):
    rng = np.random.default_rng(L)
    Z = rng.standard_normal((73, 3))
    g = np.r_[np.zeros(30), np.ones(43)]
    np.testing.assert_allclose(hac_covariance(Z, g, L), _hac_reference(Z, g, L), rtol=1e-12, atol=1e-12)


def test_long_run_factor_white_and_ar1():
    rng = np.random.default_rng(0)
    e = rng.standard_normal(20000)
    assert long_run_factor(e, max_lag=20) == pytest.approx(1.0, abs=0.1)
    x = np.zeros(20000)
    for i in range(1, x.size):                       # AR(1), rho = 0.8: (1 + rho) / (1 - rho) = 9
        x[i] = 0.8 * x[i - 1] + rng.standard_normal()
    assert 6.0 < long_run_factor(x, max_lag=60) < 10.0


def test_wald_and_f_tests_are_calibrated_under_the_null():
    """White noise, a column unrelated to it: p-values are uniform (5 % below 0.05)."""
    rng = np.random.default_rng(1)
    pw, pf = [], []
    for _ in range(400):
        x = rng.standard_normal(200)
        e = rng.standard_normal(200)
        b = x @ e / (x @ x)
        r1 = e - b * x
        pw.append(wald_test([b], [[float(r1 @ r1) / 199 / (x @ x)]], 199)[1])
        pf.append(nested_f_test(float((b * x) @ (b * x)), float(r1 @ r1), 1, 199)[1])
    for p in (pw, pf):
        assert 0.02 < np.mean(np.array(p) < 0.05) < 0.09
    np.testing.assert_allclose(pw, pf, rtol=1e-9)


def test_binned_anova_finds_structure_and_not_noise():
    rng = np.random.default_rng(2)
    v = rng.uniform(-1, 1, 2000)
    noise = rng.standard_normal(2000)
    flat = binned_anova(noise, v)
    assert flat.p_value > 1e-3 and flat.eta2 < 0.02
    stribeck = np.sign(v) * np.exp(-(v / 0.1) ** 2) + 0.3 * noise
    a = binned_anova(stribeck, v)
    assert a.p_value < 1e-10 and a.eta2 > 0.3
    # F statistic by hand (one-way ANOVA, no serial-correlation correction for white data)
    ref = sst.f_oneway(*[stribeck[(v >= lo) & (v < hi)] for lo, hi in zip(np.quantile(v, np.linspace(0, 1, 17))[:-1],
                                                                         np.quantile(v, np.linspace(0, 1, 17))[1:])])
    b = binned_anova(stribeck, v, inflation=1.0, robust=False)
    assert pytest.approx(ref.statistic, rel=0.05) == b.F


def test_fisher_g_detects_a_sinusoid():
    rng = np.random.default_rng(3)
    t = np.arange(1000) * 0.01
    f, g, p = fisher_g_test(rng.standard_normal(1000), 0.01)
    assert p > 1e-3
    f, g, p = fisher_g_test(rng.standard_normal(1000) + 0.5 * np.sin(2 * np.pi * 7.0 * t), 0.01)
    assert f == pytest.approx(7.0, abs=0.1) and p < 1e-10
