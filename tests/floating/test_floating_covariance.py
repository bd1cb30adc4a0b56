"""The covariance of floating-base estimates with the rows' noise correlated within a sample
(:func:`symoro_gen.identification.floating.with_sample_covariance`, docs/floating-base.md "Standard deviations").

Reference: the empirical covariance of the WLS estimates over independent draws of the noise (Monte Carlo), for a
linear system whose rows of one sample share their noise as a contact wrench's does through ``J_c^T``.
"""
from __future__ import annotations

import numpy as np

from symoro_gen.identification.estimators import fit_wls
from symoro_gen.identification.floating import with_sample_covariance
from symoro_gen.identification.observation import ObservationSystem

M, N, C, DRAWS = 3, 300, 4, 400


def _system(rng, L):
    """Rows grouped by row position (row ``r N + s`` is position ``r`` of sample ``s``), noise ``L e`` per sample."""
    A = rng.normal(size=(M, N, C))
    A[:, :, 0] += 2.0  # a column common to the row positions: the correlation reaches it
    chi = rng.normal(size=C)
    W = A.reshape(-1, C)
    joint = np.repeat(np.arange(M), N)
    noise = np.einsum("ij,djs->dis", L, rng.normal(size=(DRAWS, M, N))).reshape(DRAWS, -1)
    return W, joint, chi, noise


def _ratios(L, seed):
    """Per parameter: the mean predicted variance over the draws / the empirical variance, for the rows taken as
    independent and with the within-sample covariance."""
    rng = np.random.default_rng(seed)
    W, joint, chi, noise = _system(rng, L)
    est, naive, sandwich = [], [], []
    for e in noise:
        system = ObservationSystem(W=W, Y=W @ chi + e, names=tuple(f"p{i}" for i in range(C)), joint=joint)
        res = fit_wls(system)
        new = with_sample_covariance(res, system, N)
        assert np.array_equal(new.values, res.values)  # the estimates are unchanged
        est.append(res.values)
        naive.append(np.diag(res.cov))
        sandwich.append(np.diag(new.cov))
    var = np.var(np.array(est), axis=0, ddof=1)
    return np.mean(naive, axis=0) / var, np.mean(sandwich, axis=0) / var


def test_correlated_rows_covariance_matches_monte_carlo():
    """A noise shared by the three rows of a sample (correlation 0.8): the rows taken as independent give the common
    column's variance far too small, the within-sample covariance its empirical value (400 draws: the empirical
    variance's relative standard deviation is sqrt(2 / 399), 7 %)."""
    L = np.linalg.cholesky(np.array([[1.0, 0.8, 0.8], [0.8, 1.0, 0.8], [0.8, 0.8, 1.0]]) * 0.04)
    naive, sandwich = _ratios(L, seed=3)
    print("independent rows:", np.round(naive, 2), "within-sample:", np.round(sandwich, 2))
    assert naive[0] < 0.6
    assert np.all(np.abs(sandwich - 1) < 0.25)


def test_independent_rows_keep_the_usual_covariance():
    """Independent rows of unequal variance per position (each weighted by WLS): both agree with the draws."""
    L = np.diag([0.1, 0.3, 0.05])
    naive, sandwich = _ratios(L, seed=4)
    print("independent rows:", np.round(naive, 2), "within-sample:", np.round(sandwich, 2))
    assert np.all(np.abs(naive - 1) < 0.25)
    assert np.all(np.abs(sandwich - 1) < 0.25)


def test_poorly_identified_warning_uses_the_new_sigma():
    """A parameter of true value 0 is poorly identified; its warning quotes the %sigma of the new covariance."""
    rng = np.random.default_rng(5)
    L = np.linalg.cholesky(np.full((M, M), 0.8) + 0.2 * np.eye(M))
    W, joint, chi, noise = _system(rng, L)
    chi[3] = 1e-6
    system = ObservationSystem(W=W, Y=W @ chi + noise[0], names=tuple(f"p{i}" for i in range(C)), joint=joint)
    new = with_sample_covariance(fit_wls(system), system, N)
    poorly = [w for w in new.warnings if "poorly identified" in w]
    assert len(poorly) == 1
    assert f"p3 ({new.rel_std_pct[3]:.3g}%)" in poorly[0]
