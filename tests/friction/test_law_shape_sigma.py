"""The standard deviations of a friction law's constants with its searched shape estimated too
(:func:`symoro_gen.diagnostics.friction.shape_uncertainty`, the linearised covariance of the nonlinear least
squares, Seber & Wild 1989 sec. 2.1) against the scatter of the nonlinear least-squares estimates over simulated
noise (Monte Carlo: the reference the linearisation approximates)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from symoro_gen.diagnostics.friction import FrictionChoice, LawFit, shape_physical, shape_uncertainty

FC, DIP, VS, FV, NOISE = 1.0, 0.6, 0.02, 0.5, 0.1


def _problem(n: int = 1200):
    t = np.linspace(0.0, 12.0, n)
    v = 3.0 * np.sin(2 * np.pi * 0.5 * t) + 0.05 * np.sin(2 * np.pi * 2.3 * t)
    R = np.column_stack([np.cos(2 * np.pi * 0.3 * t), np.sin(2 * np.pi * 1.1 * t), np.ones(n)])
    return v, R


def _choice(vs: float) -> FrictionChoice:
    return FrictionChoice(0, LawFit("stribeck", vs, 0.0), LawFit("linear", None, 0.0), ())


def _design(v, R, vs):
    return np.hstack([R, _choice(vs).columns(v)])


def _fit(v, R, y):
    """Nonlinear least squares: the constants linear, ``vs`` by a bounded search of the residual in ``log vs``."""
    def rss(lv):
        A = _design(v, R, float(np.exp(lv)))
        r = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
        return float(r @ r)
    lv = optimize.minimize_scalar(rss, bounds=(np.log(0.005), np.log(0.1)), method="bounded",
                                  options={"xatol": 1e-6}).x
    vs = float(np.exp(lv))
    A = _design(v, R, vs)
    theta, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    s2 = float(np.sum((y - A @ theta) ** 2)) / (y.size - A.shape[1] - 1)
    std = np.sqrt(s2 * np.diag(np.linalg.inv(A.T @ A)))
    return vs, A, theta, std


def test_shape_sigma_matches_the_scatter_of_the_nonlinear_fit():
    """Over 120 noise draws, the scatter of ``Fs - Fc`` and ``vs`` is the sigma with the shape estimated (within
    20 %), and that sigma is wider than the one at the shape held, which underestimates the scatter."""
    v, R = _problem()
    theta_true = np.array([0.3, -0.2, 0.1, FC, DIP, FV])
    y0 = _design(v, R, VS) @ theta_true
    rng = np.random.default_rng(3)
    dips, vss, held, free, free_vs = [], [], [], [], []
    for _ in range(120):
        y = y0 + NOISE * rng.standard_normal(y0.size)
        vs, A, theta, std = _fit(v, R, y)
        idx = [3, 4, 5]
        unc = shape_uncertainty(_choice(vs), lambda c: c.columns(v), A, idx, theta[idx], std[idx])
        assert unc is not None and unc.names == ("vs",)
        dips.append(theta[4])
        vss.append(vs)
        held.append(std[4])
        free.append(unc.law_std[1])
        free_vs.append(unc.std[0])
    scatter, scatter_vs = float(np.std(dips, ddof=1)), float(np.std(vss, ddof=1))
    assert np.median(free) == pytest.approx(scatter, rel=0.2)
    assert np.median(free_vs) == pytest.approx(scatter_vs, rel=0.2)
    assert np.median(held) < 0.9 * scatter


def test_shape_sigma_of_the_dahl_law_reports_x0_and_sigma0():
    """The Dahl law's shape ``vp`` reported as ``x0 = vp / fs`` and ``sigma0 = |Fc| / x0`` with their sigma by
    first-order propagation of the joint covariance (checked against a numerical gradient of ``sigma0``)."""
    fs = 1000.0
    t = np.arange(0.0, 6.0, 1.0 / fs)
    v = 0.3 * np.sin(2 * np.pi * 0.7 * t)
    ch = FrictionChoice(0, LawFit("dahl", 0.4, 0.0), LawFit("linear", None, 0.0), (), rate_hz=fs)
    A = ch.columns(v)
    rng = np.random.default_rng(0)
    y = A @ np.array([1.0, 0.5]) + 0.05 * rng.standard_normal(v.size)
    theta = np.linalg.lstsq(A, y, rcond=None)[0]
    s2 = float(np.sum((y - A @ theta) ** 2)) / (y.size - 3)
    std = np.sqrt(s2 * np.diag(np.linalg.inv(A.T @ A)))
    unc = shape_uncertainty(ch, lambda c: c.columns(v), A, [0, 1], theta, std)
    assert unc is not None and unc.names == ("vp",) and unc.std[0] > 0
    assert np.all(unc.law_std >= std)
    phys = shape_physical(ch, unc, theta)
    assert phys["x0_std"] == pytest.approx(unc.std[0] / fs)

    def sigma0(p):   # (Fc, Fv, vp) -> |Fc| fs / vp
        return abs(p[0]) * fs / p[2]
    p0 = np.array([theta[0], theta[1], 0.4])
    g = np.array([(sigma0(p0 + h) - sigma0(p0 - h)) / (2 * h[i]) if h[i] else 0.0
                  for i, h in enumerate(np.diag([1e-6, 0.0, 1e-6]))])
    assert phys["sigma0_std"] == pytest.approx(float(np.sqrt(g @ unc.cov @ g)), rel=1e-4)
