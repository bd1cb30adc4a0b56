"""Statistics of a fleet: a robot against the fleet's own spread, the trend of a robot over days, and
the multiple-testing correction of the flags.

* **Level** (random effects, DerSimonian & Laird, "Meta-analysis in clinical trials", Controlled
  Clinical Trials 7, 1986): for parameter k, robot r's estimate ``theta_rk`` (variance ``v_rk`` from its
  covariance) is compared with the random-effects mean ``m_k`` of the *other* robots (leave-one-out, so a
  deviating robot does not pull the reference), whose variance ``var(m_k)`` comes from their
  covariances and the between-robot variance ``tau2_k`` estimated by DerSimonian-Laird from them::

      z_rk = (theta_rk - m_k) / sqrt(v_rk + tau2_k + var(m_k))

  With few robots ``tau2`` is poorly known: the p-value uses Student's t with ``n_ref - 1`` degrees of
  freedom (``n_ref`` robots in the reference; Hartung & Knapp, Stat. Med. 20, 2001, in spirit), so ordinary
  unit-to-unit scatter is not flagged.
* **Robust reference** (:func:`hampel_outliers`): leaving the judged robot out protects its own z from
  itself, not from *another* deviating robot: one strongly drifting robot inflates the DerSimonian-Laird
  ``tau2`` of every other robot's reference and masks a second, milder one (and two drifters deflate
  each other's z). So, from ``HAMPEL_MIN_ROBOTS`` robots on, the robots whose estimate lies more than
  ``HAMPEL_C`` robust standard deviations from the fleet's median (the Hampel identifier: median and
  1.4826 MAD, breakdown point 50 %; Hampel, JASA 69, 1974; Davies & Gather, JASA 88, 1993, whose
  finite-sample thresholds for 10-50 observations at a 5 % chance of screening out a clean one are close
  to 5) are left out of every *other* robot's reference (each is still judged against the rest). Why this
  and not a median/MAD between-robot variance itself: the MAD has 37 % of the standard deviation's
  efficiency, so with 5-20 robots its scatter needs a far heavier-tailed reference (drifts missed) or
  gives false flags; the screen keeps DerSimonian-Laird's efficiency and the t calibration above, and
  changes nothing on a fleet without outliers (same numbers). The spread reported for the fleet
  (``tau_all``) is DerSimonian-Laird on the robots not screened out.
* **Trend**: weighted least-squares line of ``theta_rdk`` over the day index ``d`` (days in string
  order), weights ``1 / std_rdk^2``. The daily standard deviations of short logs understate how much
  the days really scatter (each day is a different trajectory: its filter and model errors differ), and
  one robot's own scatter about its line (``chi2 / (D - 2)``, the Birge ratio) has only ``D - 2``
  degrees of freedom: with 5 days, 3. So the excess scatter is estimated once per parameter for the
  whole fleet, an empirical-Bayes pooling of every robot's line residuals (a drift along a line does
  not inflate it)::

      phi_k = sum_r chi2_rk / sum_r (D_r - 2)        (dof nu_k = sum_r (D_r - 2))

  the slope's standard error is ``sqrt(max(1, phi_k, chi2_rk / (D_r - 2)) / S_xx)`` (a robot that
  scatters more than the fleet keeps its own larger factor: a guard that never lowers the standard
  error). ``phi_k`` is the empirical-Bayes estimate of every robot's excess scatter (its own residuals
  pooled with the others'); when a ratio above 1 sets the scale, the scale is an estimate and the
  p-value is Student's t with ``nu_k`` degrees of freedom, as for a regression with estimated variance;
  when the daily standard deviations are not exceeded (factor 1) they are trusted and the reference is
  normal (Birge, Phys. Rev. 40, 1932, for the ratio). The robot's own ratio alone has ``D - 2`` degrees
  of freedom (2 with 4 days): as the reference it would hide a drift whose days also scatter (a drifting
  torque gain, measured z = 52 at p = 4e-4). Without fleet information (:func:`trend_test` alone) the
  robot's own ratio and ``D - 2`` degrees of freedom are used. The pool is screened like the level's
  reference (:func:`dispersion_outliers`, from ``HAMPEL_MIN_ROBOTS`` robots on): a robot whose scatter
  about its line exceeds ``phi_0 chi2_{1-p}(D_r - 2)`` (``phi_0`` the median of the robots' ratios, each
  scaled by the median of its chi-square law; ``p = DISPERSION_SCREEN_P``) is left out of ``phi_k`` — one
  wildly scattering robot otherwise sets every other robot's slope error and masks their drifts — and
  keeps its own ratio.
* **Correction**: Holm's step-down procedure (Holm, Scand. J. Statist. 6, 1979) over every test of
  every robot and parameter controls the family-wise error rate at ``alpha`` (default 0.01), or
  Benjamini-Hochberg (``correction="bh"``) controls the false-discovery rate.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from ..diagnostics.stats import benjamini_hochberg, holm

__all__ = ["HAMPEL_C", "HAMPEL_MIN_ROBOTS", "DISPERSION_SCREEN_P", "adjust", "dersimonian_laird",
           "dispersion_outliers", "hampel_outliers", "level_z", "line_fit", "pooled_dispersion", "trend_test"]

#: robust standard deviations (1.4826 MAD, with the robot's own variance) beyond which a robot is left out
#: of the other robots' reference
HAMPEL_C = 5.0
#: fewest robots with which the screen runs (with 4, the median and MAD of the fleet are not reliable)
HAMPEL_MIN_ROBOTS = 5
#: chance that a robot whose days scatter like the fleet's is screened out of the pooled dispersion
DISPERSION_SCREEN_P = 1e-4


def hampel_outliers(theta: np.ndarray, var: np.ndarray, c: float = HAMPEL_C) -> np.ndarray:
    """Robots whose estimate is far from the fleet's median: ``|theta_r - med| > c sqrt(s^2 + var_r)``
    with ``s = 1.4826 MAD`` (the Hampel identifier; ``var_r`` keeps a robot with a large own variance, a
    short log, from being screened out for it). All False below :data:`HAMPEL_MIN_ROBOTS` robots.

    Parameters
    ----------
    theta, var : ndarray, shape (R,)

    Returns
    -------
    ndarray of bool, shape (R,)
    """
    theta, var = np.asarray(theta, float), np.asarray(var, float)
    out = np.zeros(theta.shape, bool)
    if theta.size < HAMPEL_MIN_ROBOTS or not (np.all(np.isfinite(theta)) and np.all(np.isfinite(var))):
        return out
    med = float(np.median(theta))
    s = 1.4826 * float(np.median(np.abs(theta - med)))
    return np.abs(theta - med) > c * np.sqrt(s * s + var)


def dersimonian_laird(theta: np.ndarray, var: np.ndarray) -> tuple[float, float, float]:
    """Random-effects mean, its variance and the between-unit variance ``tau2`` (DerSimonian-Laird).

    Parameters
    ----------
    theta, var : ndarray, shape (R,)
        Estimates and their (within-unit) variances; ``var > 0``.

    Returns
    -------
    mean, var_mean, tau2 : float
    """
    theta = np.asarray(theta, float)
    w = 1.0 / np.maximum(np.asarray(var, float), np.finfo(float).tiny)
    R = theta.size
    mean_fe = float(w @ theta / w.sum())
    Q = float(w @ (theta - mean_fe) ** 2)
    denom = w.sum() - (w @ w) / w.sum()
    tau2 = max(0.0, (Q - (R - 1)) / denom) if R > 1 and denom > 0 else 0.0
    ws = 1.0 / (1.0 / w + tau2)
    return float(ws @ theta / ws.sum()), float(1.0 / ws.sum()), tau2


def level_z(theta: np.ndarray, std: np.ndarray, *, robust: bool = True
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Leave-one-out random-effects distance of every robot to the rest of the fleet.

    Parameters
    ----------
    theta, std : ndarray, shape (R, P)
        Per robot (all its days) estimates and standard deviations.
    robust : bool
        Leave the robots :func:`hampel_outliers` screens out of the other robots' references (default);
        False: every other robot is in each reference (plain leave-one-out DerSimonian-Laird).

    Returns
    -------
    z, p : ndarray (R, P)
        Standardised distance and two-sided p-value (t with ``n_ref - 1`` dof, ``n_ref`` the robots in the
        reference; NaN when R < 3).
    mean, mean_std, tau : ndarray (R, P)
        The leave-one-out reference of each robot, its standard deviation and the between-robot spread.
    """
    theta, std = np.asarray(theta, float), np.asarray(std, float)
    R, P = theta.shape
    z = np.full((R, P), np.nan)
    p = np.full((R, P), np.nan)
    mean, mstd, tau = (np.full((R, P), np.nan) for _ in range(3))
    if R < 3:
        return z, p, mean, mstd, tau
    var = std ** 2
    df = np.full((R, P), np.nan)
    for k in range(P):
        if not (np.all(np.isfinite(var[:, k])) and np.all(np.isfinite(theta[:, k]))):
            continue
        screened = hampel_outliers(theta[:, k], var[:, k]) if robust else np.zeros(R, bool)
        for r in range(R):
            ref = ~screened
            ref[r] = False
            if ref.sum() < 2:                      # (cannot happen: the screen leaves more than half)
                ref = np.arange(R) != r
            m, vm, t2 = dersimonian_laird(theta[ref, k], var[ref, k])
            mean[r, k], mstd[r, k], tau[r, k] = m, np.sqrt(vm), np.sqrt(t2)
            den = np.sqrt(var[r, k] + t2 + vm)
            z[r, k] = (theta[r, k] - m) / den if den > 0 else 0.0
            df[r, k] = ref.sum() - 1
    ok = np.isfinite(z)
    p[ok] = 2.0 * stats.t.sf(np.abs(z[ok]), df=df[ok])
    return z, p, mean, mstd, tau


def line_fit(x: np.ndarray, y: np.ndarray, s: np.ndarray) -> tuple[float, float, float, int]:
    """Weighted least-squares slope of ``y`` over ``x`` (standard deviations ``s``; non-finite points
    dropped).

    Returns
    -------
    slope, sxx, chi2, dof : float, float, float, int
        The slope, ``sum w (x - x_w)^2``, the weighted residual sum of squares about the line and its
        degrees of freedom ``D - 2``; NaN (dof 0) when fewer than 3 points or no spread in ``x``.
    """
    x, y, s = (np.asarray(a, float) for a in (x, y, s))
    ok = np.isfinite(y) & np.isfinite(s) & (s > 0)
    x, y, s = x[ok], y[ok], s[ok]
    D = x.size
    if D < 3:
        return np.nan, np.nan, np.nan, 0
    w = 1.0 / s ** 2
    xm, ym = w @ x / w.sum(), w @ y / w.sum()
    sxx = float(w @ (x - xm) ** 2)
    if sxx <= 0:
        return np.nan, np.nan, np.nan, 0
    slope = float(w @ ((x - xm) * (y - ym)) / sxx)
    chi2 = float(w @ (y - ym - slope * (x - xm)) ** 2)
    return slope, sxx, chi2, D - 2


def dispersion_outliers(chi2: np.ndarray, dof: np.ndarray, p: float = DISPERSION_SCREEN_P) -> np.ndarray:
    """Robots whose scatter about their own line is incompatible with the fleet's common dispersion:
    ``chi2_r > phi_0 * chi2_{1-p}(nu_r)``, with ``phi_0 = median_r(chi2_r / median of chi2(nu_r))`` (each
    robot's ratio scaled by the median of its chi-square law estimates the common ``phi``; the median over
    robots, breakdown point 50 %, is not moved by a few wild series). All False below
    :data:`HAMPEL_MIN_ROBOTS` robots with a line (the median of fewer is not a reference).

    Parameters
    ----------
    chi2, dof : ndarray, shape (R,)
        Weighted residual sums of squares about each robot's line and their degrees of freedom
        (:func:`line_fit`); NaN / 0 for robots without a line (never screened).
    p : float
        Chance that a robot sharing the common dispersion is screened out.
    """
    chi2, dof = np.asarray(chi2, float), np.asarray(dof, float)
    ok = np.isfinite(chi2) & (dof > 0)
    out = np.zeros(chi2.shape, bool)
    if int(ok.sum()) < HAMPEL_MIN_ROBOTS:
        return out
    phi0 = float(np.median(chi2[ok] / stats.chi2.median(dof[ok])))
    if not phi0 > 0:
        return out
    out[ok] = chi2[ok] > phi0 * stats.chi2.isf(p, dof[ok])
    return out


def pooled_dispersion(chi2: np.ndarray, dof: np.ndarray, *, robust: bool = True) -> tuple[float, int]:
    """The fleet's excess day-to-day scatter of one parameter: ``sum chi2 / sum dof`` over the robots
    (NaN entries and robots with no degree of freedom skipped), and the pooled degrees of freedom.

    With ``robust`` (default) the robots :func:`dispersion_outliers` screens out are left out of the pool:
    one robot whose days scatter wildly (a faulty sensor, a log of another trajectory) would otherwise
    inflate every other robot's slope error and mask their drifts. It keeps its own, larger, ratio in
    :func:`trend_test` (the guard ``max(1, phi, own)``)."""
    chi2, dof = np.asarray(chi2, float), np.asarray(dof, float)
    ok = np.isfinite(chi2) & (dof > 0)
    if robust:
        ok &= ~dispersion_outliers(chi2, dof)
    nu = int(dof[ok].sum())
    return (float(chi2[ok].sum() / nu), nu) if nu > 0 else (np.nan, 0)


def trend_test(x: np.ndarray, y: np.ndarray, s: np.ndarray, *, dispersion: float | None = None,
               dof: int | None = None) -> tuple[float, float, float, float]:
    """Weighted slope of ``y`` over ``x`` with standard deviations ``s``, its standard error inflated by
    ``max(1, dispersion, own Birge ratio)`` and a Student-t p-value (see the module notes).

    Parameters
    ----------
    x, y, s : ndarray, shape (D,)
    dispersion, dof : float, int, optional
        The fleet's pooled ratio and its degrees of freedom (:func:`pooled_dispersion`); default: this
        series' own Birge ratio with ``D - 2`` degrees of freedom.

    Returns
    -------
    slope, se, z, p : float
        NaN when fewer than 3 points.
    """
    slope, sxx, chi2, nu = line_fit(x, y, s)
    if nu < 1:
        return (np.nan,) * 4
    own = chi2 / nu
    if dispersion is None or not np.isfinite(dispersion) or not dof:
        dispersion, dof = own, nu
    factor = max(1.0, float(dispersion), own)
    se = float(np.sqrt(factor / sxx))
    z = slope / se
    # the daily sigmas trusted: normal reference; the scale estimated from the scatter: Student's t with the
    # pooled estimate's degrees of freedom (the robot's own ratio only guards, it never lowers se)
    p = stats.norm.sf(abs(z)) if factor == 1.0 else stats.t.sf(abs(z), df=dof)
    return slope, se, z, float(2.0 * p)


def adjust(p: np.ndarray, alpha: float, correction: str = "holm") -> tuple[np.ndarray, np.ndarray]:
    """Multiple-testing correction by name: ``"holm"`` (family-wise) or ``"bh"`` (false-discovery rate)."""
    if correction in ("holm", "bh"):
        adj = (holm if correction == "holm" else benjamini_hochberg)(p)
        return np.nan_to_num(adj, nan=2.0) <= alpha, adj
    raise ValueError(f"correction must be 'holm' or 'bh', got {correction!r}")
