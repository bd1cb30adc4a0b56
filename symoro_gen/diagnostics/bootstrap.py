"""The noise band of a joint's error: circular block bootstrap of a relative error norm.

A residual time series is autocorrelated (filtered, decimated torques; unmodelled slow effects), so
resampling single rows understates the variability of its norm. The *moving-block* bootstrap (Künsch,
"The jackknife and the bootstrap for general stationary observations", Ann. Statist. 17, 1989)
resamples blocks of consecutive rows; its *circular* version (Politis & Romano, "A circular
block-resampling procedure for stationary data", 1992; and "The stationary bootstrap", JASA 89, 1994)
wraps the series so that every row is equally likely to be drawn. The block length is chosen from the
residual's autocorrelation by the rule of Politis & White ("Automatic block-length selection for the
dependent bootstrap", Econometric Rev. 23, 2004) with the correction of Patton, Politis & White (2009):
``b = (2 G^2 / D_CB)^(1/3) n^(1/3)``, ``G = sum lambda(k/M) |k| R(k)``, ``D_CB = 4/3 (sum lambda(k/M) R(k))^2``,
``lambda`` the flat-top window and ``M`` twice the first lag after which ``K_N`` autocorrelations in a row
are insignificant.

The statistic is the relative error norm ``||e|| / ||y||`` (the report's metric); since it is a ratio of
sums, a replicate of ``k`` whole blocks (``k b ~ n`` rows) estimates it without trimming. The interval is
the percentile interval of the replicates.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["optimal_block_length", "rel_err_band", "rel_err_bands", "N_BOOT", "LEVEL"]

#: bootstrap replicates of a band
N_BOOT = 999
#: coverage of a band
LEVEL = 0.95


def _flat_top(t: np.ndarray) -> np.ndarray:
    """Flat-top lag window of Politis & Romano (1995): 1 on |t| <= 1/2, 2 (1 - |t|) to |t| = 1, then 0."""
    a = np.abs(t)
    return np.where(a <= 0.5, 1.0, np.where(a <= 1.0, 2.0 * (1.0 - a), 0.0))


def optimal_block_length(x) -> int:
    """Block length of the circular block bootstrap of the mean of ``x`` (Politis & White 2004 with the
    correction of Patton, Politis & White 2009); at least 1, at most ``n / 3``. White noise gives 1-2, an
    AR(1) with coefficient ``phi`` grows with ``phi``."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    n = x.size
    if n < 8:
        return 1
    x = x - x.mean()
    kn = max(5, int(math.ceil(math.sqrt(math.log10(n)))))
    mmax = min(int(math.ceil(math.sqrt(n))) + kn, n - 1)
    f = np.fft.rfft(x, 2 * n)
    acov = np.fft.irfft(f * np.conj(f))[:mmax + 1] / n
    if acov[0] <= 0:
        return 1
    rho = acov / acov[0]
    c = 2.0 * math.sqrt(math.log10(n) / n)
    mhat = mmax
    for m in range(mmax - kn + 1):
        if np.all(np.abs(rho[m + 1:m + 1 + kn]) < c):
            mhat = m
            break
    M = min(2 * max(mhat, 1), mmax)
    k = np.arange(1, M + 1)
    lam = _flat_top(k / M)
    g0 = acov[0] + 2.0 * float(np.sum(lam * acov[1:M + 1]))
    G = 2.0 * float(np.sum(lam * k * acov[1:M + 1]))
    d_cb = 4.0 / 3.0 * g0 ** 2
    if d_cb <= 0:
        return 1
    b = (2.0 * G ** 2 / d_cb) ** (1.0 / 3.0) * n ** (1.0 / 3.0)
    return int(min(max(1, round(b)), max(1, n // 3)))


def rel_err_band(e, y=None, *, level: float = LEVEL, n_boot: int = N_BOOT, block: int | None = None,
                 rng: np.random.Generator | None = None) -> tuple[float, float]:
    """``level`` percentile interval of ``||e|| / ||y||`` (``y`` None: the RMS of ``e``) by the circular block
    bootstrap of the rows (in time order; several experiments concatenated), the block length from ``e``'s
    autocorrelation (:func:`optimal_block_length`) unless given."""
    e = np.asarray(e, float)
    n = e.size
    if n == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(0) if rng is None else rng
    b = optimal_block_length(e) if block is None else max(1, min(int(block), n))
    k = max(1, int(round(n / b)))
    # circular block sums of e^2 and y^2 starting at every row
    e2 = np.concatenate([e ** 2, (e ** 2)[:b - 1]])
    ce = np.concatenate([[0.0], np.cumsum(e2)])
    se = ce[b:b + n] - ce[:n]
    if y is None:
        sy = np.full(n, float(b))
    else:
        y2 = np.asarray(y, float) ** 2
        y2 = np.concatenate([y2, y2[:b - 1]])
        cy = np.concatenate([[0.0], np.cumsum(y2)])
        sy = cy[b:b + n] - cy[:n]
    starts = rng.integers(0, n, size=(n_boot, k))
    num = se[starts].sum(axis=1)
    den = sy[starts].sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        reps = np.sqrt(num / den)
    reps = reps[np.isfinite(reps)]
    if reps.size == 0:
        return math.nan, math.nan
    a = (1.0 - level) / 2.0
    return float(np.quantile(reps, a)), float(np.quantile(reps, 1.0 - a))


def rel_err_bands(e, y, joint, n: int, *, level: float = LEVEL, n_boot: int = N_BOOT,
                  rng: np.random.Generator | None = None) -> np.ndarray:
    """Per joint ``(low, high)`` band of ``||e_j|| / ||y_j||`` (:func:`rel_err_band` on the joint's rows, in
    their order: the assembly's, experiment after experiment). Shape ``(n, 2)``; NaN for a joint without rows."""
    e, y, joint = np.asarray(e, float), np.asarray(y, float), np.asarray(joint)
    rng = np.random.default_rng(0) if rng is None else rng
    out = np.full((n, 2), math.nan)
    for j in range(n):
        m = joint == j
        if m.any():
            out[j] = rel_err_band(e[m], y[m], level=level, n_boot=n_boot, rng=rng)
    return out
