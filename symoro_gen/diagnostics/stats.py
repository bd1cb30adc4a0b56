"""Statistics used by the residual diagnosis (all with a stated null hypothesis).

* :func:`long_run_factor` - how much serial correlation inflates the variance of a sum of residuals
  (Bartlett/Newey-West long-run variance over the autocovariance); 1 for white residuals. Tests divide
  their statistics by it so that smooth, correlated residuals do not look like evidence.
* :func:`nested_f_test` - adding ``p`` columns to a least-squares model: ``F = (dRSS/p) / (RSS1/dof)``,
  p-value from the F(p, dof) distribution after the long-run correction.
* :func:`wald_test` with :func:`hac_covariance` - the same question with a covariance of the estimate
  that is robust to heteroscedastic and serially correlated residuals (Newey-West 1987): what the
  diagnosis uses, because the residual of real (and of noisy simulated) data is neither white nor
  homoscedastic - e.g. it has bursts at velocity reversals where the Coulomb column of the filtered
  velocity chatters.
* :func:`binned_anova` - structure of a residual against a signal: one-way ANOVA of the residual over
  quantile bins of the signal; ``eta2`` is the fraction of the residual variance explained by the
  bin means (explained variance); the p-value is that of a Wald test of equal bin means with a HAC
  covariance (or of ``F = (SSB/(B-1)) / (SSW/(N-B))`` divided by the long-run factor).
* :func:`fisher_g_test` - a periodic component in the residual: the largest periodogram ordinate
  against the local level of the spectrum (robust to coloured residuals).
* :func:`bonferroni`, :func:`holm` (family-wise, Holm 1979) and :func:`benjamini_hochberg` (false-discovery
  rate, Benjamini & Hochberg 1995, through ``scipy.stats.false_discovery_control``) - multiple-testing
  corrections of a family of p-values; the one home of these corrections (the fleet's drift flags use them too).
"""
from __future__ import annotations

import contextlib
import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import special as ssp

__all__ = ["single_threaded_blas", "contiguous_runs", "rows_times", "span_product", "f_sf", "long_run_factor", "segments_of", "hac_covariance", "hac_lag", "wald_test", "nested_f_test", "binned_anova", "fisher_g_test", "bonferroni", "AnovaResult"]

#: the long-run factor is floored at 1 (never makes a test less conservative than the white-noise one)
MIN_LONG_RUN = 1.0


def f_sf(x: float, dfn: float, dfd: float) -> float:
    """Survival function of the F(dfn, dfd) distribution at ``x >= 0``: ``scipy.special.fdtrc``, the
    function ``scipy.stats.f.sf`` evaluates, without the distribution object's argument checking (about
    0.5 ms a call: the diagnosis computes tens of thousands of p-values)."""
    return float(ssp.fdtrc(dfn, dfd, x))


def single_threaded_blas(fn):
    """Run ``fn`` with the BLAS/LAPACK thread pool limited to one thread (``threadpoolctl``, installed with
    scikit-learn, extra ``diagnose``; without it nothing changes).

    The diagnosis works on tall, narrow matrices (rows x ~100 columns) where a second BLAS thread gains
    little, while OpenBLAS threads spinning on a busy machine cost a lot: measured on this 2-core machine
    at load ~8, a thin SVD of a 14000 x 80 matrix took 1.6 s CPU with 2 threads and 0.065 s with one.
    Results agree to rounding (the summation order of a threaded product may differ)."""
    @functools.wraps(fn)
    def run(*args, **kwargs):
        try:
            from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]
        except ImportError:   # pragma: no cover - threadpoolctl comes with scikit-learn
            ctx: contextlib.AbstractContextManager = contextlib.nullcontext()
        else:
            ctx = threadpool_limits(limits=1, user_api="blas")
        with ctx:
            return fn(*args, **kwargs)
    return run


#: most contiguous runs an index set is handled by (:func:`contiguous_runs`); more are gathered by fancy indexing
MAX_RUNS = 64


def contiguous_runs(idx: np.ndarray) -> list[tuple[int, int, int]] | None:
    """Contiguous runs of the sorted indices ``idx`` as ``(position in idx, first, stop)``; None when there
    are more than :data:`MAX_RUNS`. The rows of a time-blocked fold, or those a candidate of one joint
    touches, are a few runs (rows are joint-major, blocks contiguous in time): products on slices of the
    large factors avoid copying their rows."""
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) != 1) + 1
    if cut.size >= MAX_RUNS:
        return None
    starts = np.r_[0, cut]
    stops = np.r_[cut, idx.size]
    return [(int(i), int(idx[i]), int(idx[k - 1]) + 1) for i, k in zip(starts, stops)]


def rows_times(A: np.ndarray, rows: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``A[rows] @ v`` for a boolean mask ``rows``, the product taken on contiguous slices of ``A``."""
    runs = contiguous_runs(np.flatnonzero(rows))
    if runs is None:
        return A[rows] @ v
    out = np.empty((int(np.count_nonzero(rows)),) + v.shape[1:])
    for i, a, b in runs:
        out[i:i + b - a] = A[a:b] @ v
    return out


def span_product(U: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``U.T @ X`` summed over the rows where ``X`` is not zero only (a candidate of one joint is zero on
    the other joints' rows: a sixth to a seventh of the passes over ``U``); equal to rounding."""
    nz = np.flatnonzero(np.any(X != 0.0, axis=1))
    runs = contiguous_runs(nz)
    if runs is None or 2 * nz.size > X.shape[0]:
        return U.T @ X
    out = np.zeros((U.shape[1], X.shape[1]))
    for _, a, b in runs:
        out += U[a:b].T @ X[a:b]
    return out


def _segments(groups: np.ndarray | None, n: int):
    if groups is None:
        return [np.arange(n)]
    groups = np.asarray(groups)
    return [np.flatnonzero(groups == g) for g in np.unique(groups)]


def long_run_factor(e, groups=None, *, max_lag: int | None = None) -> float:
    """Long-run variance / variance of a residual sequence (Bartlett window), at least 1.

    Parameters
    ----------
    e : array_like, shape (N,)
        Residuals in time order within each group.
    groups : array_like, shape (N,), optional
        Contiguous-time segment of each sample (e.g. experiment); lags never cross segments.
    max_lag : int, optional
        Largest lag; default the Newey-West rule ``floor(4 (N/100)^(2/9))``, at least 2.

    Returns
    -------
    float
        ``1 + 2 sum_k (1 - k/(L+1)) rho_k``, floored at 1.
    """
    e = np.asarray(e, float)
    n = e.size
    if n < 8:
        return MIN_LONG_RUN
    L = max_lag if max_lag is not None else max(2, int(math.floor(4.0 * (n / 100.0) ** (2.0 / 9.0))))
    segs = _segments(groups, n)
    c0 = 0.0
    ck = np.zeros(L + 1)
    for idx in segs:
        x = e[idx] - e[idx].mean()
        c0 += float(x @ x)
        for k in range(1, min(L, x.size - 1) + 1):
            ck[k] += float(x[k:] @ x[:-k])
    if c0 <= 0:
        return MIN_LONG_RUN
    w = 1.0 - np.arange(L + 1) / (L + 1.0)
    f = 1.0 + 2.0 * float(np.sum(w[1:] * ck[1:]) / c0)
    return max(MIN_LONG_RUN, f)


def hac_lag(e, groups=None, *, rho_stop: float = 0.1, max_share: float = 0.25) -> int:
    """Bartlett bandwidth for :func:`hac_covariance`: the Newey-West rule ``floor(4 (N/100)^(2/9))``,
    raised to twice the lag where the residual's autocorrelation first falls below ``rho_stop``
    (structured residuals stay correlated much longer than the rule assumes), at most ``max_share``
    of the shortest segment."""
    e = np.asarray(e, float)
    n = e.size
    segs = [s for s in _segments(groups, n) if s.size > 4]
    if not segs:
        return 1
    shortest = min(s.size for s in segs)
    L0 = max(2, int(math.floor(4.0 * (n / 100.0) ** (2.0 / 9.0))))
    cap = max(1, int(max_share * shortest))
    c0 = 0.0
    xs = []
    for idx in segs:
        x = e[idx] - e[idx].mean()
        xs.append(x)
        c0 += float(x @ x)
    if c0 <= 0:
        return min(L0, cap)
    lag = cap
    for k in range(1, cap + 1):
        ck = sum(float(x[k:] @ x[:-k]) for x in xs if x.size > k)
        if ck / c0 < rho_stop:
            lag = k
            break
    return int(min(max(L0, 2 * lag), cap))


def segments_of(groups, n: int) -> list[np.ndarray]:
    """Row indices of each contiguous-time segment (``groups`` labels, or one segment)."""
    return _segments(groups, n)


def hac_covariance(Z, groups=None, max_lag: int = 4, *, segments: list | None = None) -> np.ndarray:
    """Heteroscedasticity and autocorrelation consistent (Newey-West, Bartlett weights) covariance of
    the sum of the rows of ``Z``.

    Computed exactly as ``(1/(L+1)) sum_t M_t M_t'`` with ``M_t`` the sums of ``L+1`` consecutive rows
    (zero-padded), which equals ``sum_{|l|<=L} (1 - |l|/(L+1)) sum_t z_t z_{t+l}'``.

    Parameters
    ----------
    Z : ndarray, shape (N, p)
        Per-row score contributions (e.g. ``x_i e_i``), in time order within each group.
    groups : array_like, shape (N,), optional
        Segments; lags never cross them.
    max_lag : int
        Bartlett bandwidth L (weights ``1 - l/(L+1)``).
    segments : list of index arrays, optional
        Precomputed :func:`segments_of` (instead of ``groups``).

    Returns
    -------
    ndarray, shape (p, p)
    """
    Z = np.asarray(Z, float)
    if Z.ndim == 1:
        Z = Z[:, None]
    p = Z.shape[1]
    L = max(int(max_lag), 0)
    S = np.zeros((p, p))
    segs = segments if segments is not None else _segments(groups, Z.shape[0])
    for idx in segs:
        n_i = idx.size
        # a contiguous run of rows (the usual case: rows grouped per joint and experiment) is sliced, not copied
        z = Z[idx[0]:idx[0] + n_i] if n_i and idx[-1] - idx[0] + 1 == n_i else Z[idx]
        if L == 0:
            S += z.T @ z
            continue
        c = np.empty((n_i + L + 1, p))
        c[0] = 0.0
        np.cumsum(z, axis=0, out=c[1:n_i + 1])
        c[n_i + 1:] = c[n_i]
        # M_t = c[t + L + 1] - c[t] for t = -L .. N-1 (c extended by 0 before the start)
        M = np.empty_like(c)
        M[:L + 1] = c[:L + 1]
        np.subtract(c[L + 1:], c[:-(L + 1)], out=M[L + 1:])
        S += (M.T @ M) / (L + 1.0)
    return S


def wald_test(b, cov, dof: int | None = None) -> tuple[float, float]:
    """Wald test of ``b = 0`` with covariance ``cov``: statistic ``b' cov^-1 b`` (chi2 with p degrees
    of freedom, or F(p, dof) of statistic/p when ``dof`` is given). Returns (statistic, p-value)."""
    b = np.asarray(b, float).reshape(-1)
    p = b.size
    try:
        W = float(b @ np.linalg.solve(cov, b))
    except np.linalg.LinAlgError:
        W = float(b @ np.linalg.pinv(cov) @ b)
    W = max(W, 0.0)
    if dof is None:
        return W, float(ssp.chdtrc(p, W))    # = scipy.stats.chi2.sf(W, p)
    return W, f_sf(W / p, p, dof)


def nested_f_test(drss: float, rss1: float, p: int, dof: int, inflation: float = 1.0) -> tuple[float, float]:
    """F test of ``p`` added columns.

    Parameters
    ----------
    drss : float
        Decrease of the residual sum of squares.
    rss1 : float
        Residual sum of squares with the columns.
    p, dof : int
        Added columns; residual degrees of freedom with them.
    inflation : float
        Long-run factor dividing the statistic (>= 1).

    Returns
    -------
    (F, p_value)
    """
    if p <= 0 or dof <= 0 or rss1 <= 0:
        return (math.inf, 0.0) if drss > 0 and rss1 <= 0 else (0.0, 1.0)
    F = (max(drss, 0.0) / p) / (rss1 / dof) / max(inflation, MIN_LONG_RUN)
    return float(F), f_sf(F, p, dof)


@dataclass(frozen=True)
class AnovaResult:
    """One-way ANOVA of a residual over bins of a signal.

    Attributes
    ----------
    eta2 : float
        Explained variance of the residual by the bin means, in [0, 1].
    F, p_value : float
        Statistic (divided by the long-run factor) and its p-value.
    centers, means : ndarray, shape (B,)
        Mean signal value and mean residual of each bin.
    """

    eta2: float
    F: float
    p_value: float
    centers: np.ndarray
    means: np.ndarray


def binned_anova(resid, signal, *, n_bins: int = 16, groups=None, inflation: float | None = None,
                 robust: bool = True) -> AnovaResult:
    """Structure of ``resid`` against ``signal`` (quantile bins).

    Parameters
    ----------
    resid, signal : array_like, shape (N,)
    n_bins : int
        Number of quantile bins (fewer when the signal takes few values).
    groups : array_like, optional
        Contiguous-time segments (serial correlation is estimated within them).
    inflation : float, optional
        Long-run factor dividing the classical F statistic (default: estimated from the within-bin
        residual).
    robust : bool
        Also test the bin means with a Wald test whose covariance is HAC (Newey-West on the within-bin
        residual, :func:`hac_covariance`), for heteroscedastic residuals (bursts at velocity
        reversals...), and keep the larger p-value.
    """
    r = np.asarray(resid, float)
    s = np.asarray(signal, float)
    N = r.size
    empty = AnovaResult(0.0, 0.0, 1.0, np.zeros(0), np.zeros(0))
    if 3 * n_bins > N or not np.isfinite(s).all() or np.ptp(s) == 0:
        return empty
    edges = np.unique(np.quantile(s, np.linspace(0, 1, n_bins + 1)))
    if edges.size < 3:
        return empty
    b = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, edges.size - 2)
    B = edges.size - 1
    cnt = np.bincount(b, minlength=B).astype(float)
    ok = cnt > 0
    sums = np.bincount(b, weights=r, minlength=B)
    means = np.where(ok, sums / np.maximum(cnt, 1), 0.0)
    grand = r.mean()
    ssb = float(np.sum(cnt * (means - grand) ** 2))
    within = r - means[b]
    ssw = float(within @ within)
    sst_ = ssb + ssw
    Bk = int(ok.sum())
    if Bk < 2 or ssw <= 0:
        return empty
    centers = np.bincount(b, weights=s, minlength=B) / np.maximum(cnt, 1)
    if robust:
        keep = np.flatnonzero(ok)
        Z = np.zeros((N, keep.size))
        col = -np.ones(B, int)
        col[keep] = np.arange(keep.size)
        Z[np.arange(N), col[b]] = within
        S = hac_covariance(Z, groups, hac_lag(within, groups))
        Cm = S / np.outer(cnt[keep], cnt[keep])
        d = means[keep][:-1] - means[keep][-1]
        K = np.hstack([np.eye(keep.size - 1), -np.ones((keep.size - 1, 1))])
        W, p_hac = wald_test(d, K @ Cm @ K.T)
    infl = long_run_factor(within, groups) if inflation is None else inflation
    F = (ssb / (Bk - 1)) / (ssw / (N - Bk)) / infl
    p = f_sf(F, Bk - 1, N - Bk)
    if robust:   # the larger p-value: HAC Wald tests of many bins are unstable in few effective samples
        F = min(F, W / (keep.size - 1))
        p = max(p, p_hac)
    return AnovaResult(ssb / sst_ if sst_ > 0 else 0.0, float(F), float(p), centers[ok], means[ok])


def fisher_g_test(x, dt: float, *, f_max: float | None = None, local_bins: int = 8) -> tuple[float, float, float]:
    """Largest periodic component of ``x`` (mean removed).

    The periodogram ordinate at the peak is compared with the local level of the spectrum (median of
    the ``2 local_bins`` neighbouring ordinates / ln 2, the mean of an exponential variable) rather than
    with a white-noise level, so a coloured residual spectrum (filters, decimation) is not taken for a
    periodic component; p-value ``m exp(-I_peak / level)`` (Bonferroni over the ``m`` ordinates tested).

    Parameters
    ----------
    x : array_like, shape (N,)
    dt : float
        Sampling period [s].
    f_max : float, optional
        Highest frequency searched [Hz] (e.g. below the decimation filter's transition band).

    Returns
    -------
    (frequency_hz, share, p_value)
        Frequency of the peak, its share of the (non-DC) energy, and the p-value.
    """
    x = np.asarray(x, float)
    x = x - x.mean()
    n = x.size
    if n < 16:
        return 0.0, 0.0, 1.0
    P = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(n, dt)
    P = P[1:(n - 1) // 2 + 1]
    f = f[1:(n - 1) // 2 + 1]
    tot = P.sum()
    if tot <= 0 or P.size < 2 * local_bins + 1:
        return 0.0, 0.0, 1.0
    sel = np.flatnonzero(f <= f_max) if f_max is not None else np.arange(P.size)
    if sel.size == 0:
        return 0.0, 0.0, 1.0
    i = int(sel[np.argmax(P[sel])])
    lo, hi = max(0, i - local_bins), min(P.size, i + local_bins + 1)
    neigh = np.r_[P[lo:i], P[i + 1:hi]]
    level = float(np.median(neigh)) / math.log(2.0) if neigh.size else float(np.mean(P))
    p = sel.size * math.exp(-P[i] / max(level, 1e-300))
    return float(f[i]), float(P[i] / tot), float(min(max(p, 0.0), 1.0))


def bonferroni(p: float, m: int) -> float:
    """``min(1, m p)``."""
    return float(min(1.0, p * max(int(m), 1)))


def holm(p) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error control, Holm 1979), same shape as ``p``.

    ``adj_(i) = max_{k <= i} min(1, (m - k + 1) p_(k))`` over the sorted finite p-values; a NaN p-value
    (a test that could not be run) stays NaN and does not count in ``m``. Reject where ``adj <= alpha``.
    """
    p = np.asarray(p, float)
    flat = p.reshape(-1)
    adj = np.full(flat.shape, np.nan)
    idx = np.flatnonzero(np.isfinite(flat))
    m = idx.size
    if m:
        order = idx[np.argsort(flat[idx], kind="stable")]
        adj[order] = np.maximum.accumulate(np.minimum(1.0, (m - np.arange(m)) * flat[order]))
    return adj.reshape(p.shape)


def benjamini_hochberg(p) -> np.ndarray:
    """Benjamini-Hochberg step-up adjusted p-values (false-discovery rate, Benjamini & Hochberg 1995), same
    shape as ``p``; NaN p-values stay NaN and do not count. Reject where ``adj <= alpha``."""
    from scipy.stats import false_discovery_control

    p = np.asarray(p, float)
    flat = p.reshape(-1)
    adj = np.full(flat.shape, np.nan)
    idx = np.flatnonzero(np.isfinite(flat))
    if idx.size:
        adj[idx] = false_discovery_control(flat[idx], method="bh")
    return adj.reshape(p.shape)
