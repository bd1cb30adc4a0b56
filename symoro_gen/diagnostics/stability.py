"""Stability of what the diagnosis loop names: time-blocked folds, selection frequency, confidence
intervals, OLS-vs-WLS agreement and the placebo stop rule (the loop's stability stage).

Everything here works on plain arrays and small frozen dataclasses, so that the staged
``diagnose`` can call it at any stage.

Time-blocked cross-validation
-----------------------------
:func:`time_blocks` cuts every experiment into ``n_blocks`` *contiguous* blocks of equal length (rows in
time order, never shuffled); fold ``k`` holds out block ``k`` of every experiment (:func:`blocked_folds`).
Rows of the decimated system are low-passed at the decimation cut-off, so neighbouring rows are
correlated over a few filter lengths: a shuffled K-fold would leak that correlation from the training
rows into the test rows and reward over-fitting (Arlot & Celisse 2010, "A survey of cross-validation
procedures for model selection", sec. 8.1; Bergmeir & Benitez 2012 for blocked CV of dependent data).
With a few long blocks, the leak is limited to one filter length at each block edge.

:class:`BlockedLS` fits a weighted least-squares model ``y ~ A`` on each fold's training rows once
and then evaluates extra columns ``X`` against it in ``O(r k p)`` (projection of ``X`` out of the span
of ``A``, Frisch-Waugh-Lovell), which makes 1-D searches over a grid of column shapes cheap.

Acceptance rules
----------------
* :func:`selection_frequency` - run a selection on the training rows of each fold and count, for every
  named effect, the share of folds that select it; :func:`stable` keeps those selected in *most* folds
  (``> MIN_SELECTION_FREQUENCY``).
* :func:`coefficient_ci` - HAC (Newey-West) covariance of the added coefficients, per-parameter
  Student-t intervals and the joint Wald test of "no effect"; an effect is kept only when the Wald
  test rejects ``beta = 0`` at ``level`` (its confidence ellipsoid excludes the origin).
* :func:`ols_wls_agreement` - the effects named under OLS and under WLS: their intersection, and a
  message when they differ (keep only the common ones).
* :func:`placebo_stop` - joints on which a placebo column passed the tests: the loop stops there.
* :func:`sided_selection` - a change in time (a step) must be confirmed by held-out blocks on both sides
  of it: its selection frequency is the smaller of the two sides'.
* :func:`simulated_noise_placebo` - a selection whose searched shape parameters are judged on the folds
  that chose them is re-run on null data (the declared model's prediction plus its own residual shifted
  in time); the observed gain must beat every null replicate.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special as ssp

from .stats import contiguous_runs, f_sf, hac_covariance, hac_lag, segments_of

__all__ = [
    "MIN_SELECTION_FREQUENCY",
    "N_FOLDS",
    "N_NOISE_PLACEBO",
    "Agreement",
    "BlockedLS",
    "CoefficientCI",
    "blocked_folds",
    "coefficient_ci",
    "ols_wls_agreement",
    "placebo_stop",
    "selection_frequency",
    "shifted_residual",
    "sided_selection",
    "simulated_noise_placebo",
    "stable",
    "time_blocks",
]

#: default number of contiguous time blocks (= folds)
N_FOLDS = 5
#: an effect is stable when selected in more than this share of the folds ("most folds")
MIN_SELECTION_FREQUENCY = 0.5
#: relative singular-value tolerance of the fold fits
RANK_TOL = 1e-10


def time_blocks(experiment: np.ndarray, order: np.ndarray, n_blocks: int = N_FOLDS) -> np.ndarray:
    """Contiguous time blocks: block id (0 .. n_blocks-1) of every row.

    Parameters
    ----------
    experiment : array_like of int, shape (r,)
        Experiment of each row.
    order : array_like, shape (r,)
        Position of the row in time within its experiment (sample index or time); rows of several joints
        at the same sample get the same block.
    n_blocks : int
        Blocks per experiment (>= 2).

    Returns
    -------
    ndarray of int, shape (r,)
        Block ``k`` of every experiment is the ``k``-th contiguous ``1/n_blocks`` of its time span.
    """
    experiment = np.asarray(experiment)
    order = np.asarray(order, float)
    if experiment.shape != order.shape or experiment.ndim != 1:
        raise ValueError(f"time_blocks: experiment {experiment.shape} and order {order.shape} must be equal 1-D shapes")
    if int(n_blocks) < 2:
        raise ValueError(f"time_blocks: n_blocks must be >= 2, got {n_blocks!r}")
    out = np.zeros(order.size, int)
    for e in np.unique(experiment):
        m = experiment == e
        o = order[m]
        u = np.unique(o)
        # equal numbers of distinct samples per block
        rank = np.searchsorted(u, o)
        out[m] = np.minimum((rank * n_blocks) // max(u.size, 1), n_blocks - 1)
    return out


def blocked_folds(blocks: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(train, test)`` boolean masks, one fold per block id (test = that block of every experiment)."""
    blocks = np.asarray(blocks)
    return [(blocks != b, blocks == b) for b in np.unique(blocks)]


def wls_basis(Aw: np.ndarray, pinv: bool = True):
    """Orthonormal basis U, pseudo-inverse and rank of the weighted design (shared by the candidate fits).

    With ``pinv=False`` the pseudo-inverse is not formed (None in its place): a caller that needs the basis
    only (the composed tests, :mod:`.compose`) does not allocate that array, as large as ``U``, at the peak."""
    if Aw.shape[1] == 0:
        return np.zeros((Aw.shape[0], 0)), (np.zeros((0, Aw.shape[0])) if pinv else None), 0
    U, s, Vt = np.linalg.svd(Aw, full_matrices=False)
    rank = int(np.sum(s > RANK_TOL * s[0])) if s.size and s[0] > 0 else 0
    U, s, Vt = U[:, :rank], s[:rank], Vt[:rank]
    return U, ((Vt.T / s) @ U.T if pinv else None), rank


def _wls_factors(Aw: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`wls_basis` with ``V / s`` (k, rank) in place of the pseudo-inverse (``pinv = (V / s) U^T``):
    half the memory of a fold (the pseudo-inverse is as large as ``U``)."""
    if Aw.shape[1] == 0:
        return np.zeros((Aw.shape[0], 0)), np.zeros((0, 0)), 0
    U, s, Vt = np.linalg.svd(Aw, full_matrices=False)
    rank = int(np.sum(s > RANK_TOL * s[0])) if s.size and s[0] > 0 else 0
    return U[:, :rank], Vt[:rank].T / s[:rank], rank


@dataclass(frozen=True, eq=False)
class _Fold:
    train: np.ndarray
    test: np.ndarray
    w: np.ndarray          # weights of the training rows
    U: np.ndarray          # orthonormal basis of A_train * w
    VS: np.ndarray         # (k, rank): V / s, the pseudo-inverse is VS @ U.T
    e0: np.ndarray         # weighted training residual of y on A
    pred0: np.ndarray      # test prediction of A alone
    rank: int = 0          # rank of A_train * w


#: the folds of the last BlockedLS (see BlockedLS.__init__)
_FOLD_CACHE: dict = {}


def clear_fold_cache() -> None:
    """Drop the fold bases and column factors kept for the next :class:`BlockedLS` of the same design (the
    diagnosis clears them once its loop is done: the report's designs are other ones, and nothing of a
    diagnosis stays alive after it returns)."""
    _FOLD_CACHE.clear()


def _digest(x: np.ndarray) -> str:
    """BLAKE2b digest of an array's bytes (its contents, for the fold cache: equal digests mean equal
    arrays for any practical purpose)."""
    import hashlib

    x = np.ascontiguousarray(x)
    data = x.data.cast("B") if x.size else memoryview(b"")
    return hashlib.blake2b(data, digest_size=20).hexdigest() + str(x.dtype)


def _fingerprint(x: np.ndarray) -> tuple:
    x = np.asarray(x)
    return (x.shape, float(np.sum(x)), float(np.sum(x[::97] ** 2)) if x.size else 0.0)


#: largest condition number of the added columns' Gram matrix (after projection) solved by the normal
#: equations of :class:`_ColumnFactors`; above it the rank-revealing solve is used
MAX_GRAM_COND = 1e8
#: bytes of column factors kept per fold set (:class:`_ColumnCache`)
COLUMN_CACHE_BYTES = 64 * 2 ** 20


@dataclass(frozen=True, eq=False)
class _ColumnFactors:
    """What one fold needs to fit added columns ``X`` to any ``y``: ``X`` is zero outside a few rows
    (a candidate of one joint touches that joint's rows only), so the projection of ``X`` out of the
    span of ``A`` is computed there and its remainder through the fold's basis.

    With ``U`` the fold's orthonormal basis of ``A_train w``, ``S`` the training rows where ``X`` is
    not zero (``S'`` the others), ``Xw = X w`` and ``c = U_S^T Xw_S``: the projected columns are
    ``Xp_S = Xw_S - U_S c`` on ``S`` and ``-U_S' c`` elsewhere, so
    ``Xp^T Xp = Xp_S^T Xp_S + c^T (U_S'^T U_S') c`` (two positive semi-definite terms, no cancellation),
    and ``Xp^T e0 = Xw_S^T e0_S`` because ``U^T e0 = 0`` (Frisch-Waugh-Lovell; the Gram-matrix update
    of an added block, Golub & Van Loan 2013, sec. 6.5). The test prediction
    ``X_te b - A_te pinv (Xw b)`` is ``D b`` with ``D`` kept."""

    local: np.ndarray      # positions of S within the fold's training rows
    Xw_S: np.ndarray       # (|S|, p)
    Ginv: np.ndarray       # (p, p) inverse of Xp^T Xp
    D: np.ndarray          # (r_test, p) on the reported test rows
    test: np.ndarray       # row indices of the reported test rows (shared with the fold's support)
    test_pos: np.ndarray   # their positions within the fold's test rows

    @property
    def nbytes(self) -> int:
        return self.local.nbytes + self.Xw_S.nbytes + self.Ginv.nbytes + self.D.nbytes

    @staticmethod
    def build(A: np.ndarray, X: np.ndarray, f: _Fold, sup: _FoldSupport) -> _ColumnFactors | None:
        """``sup``: the fold's rows where ``X`` is not zero and the test rows reported (:class:`_FoldSupport`,
        kept per support). ``pinv_S Xw_S = VS c`` (``pinv = VS U^T``)."""
        Xw_S = X[sup.rows_S] * sup.w_S[:, None]
        # U_S = U[local] by its contiguous runs (one joint's training rows: one or two runs), not copied
        runs = sup.runs
        if runs is None:
            U_S = f.U[sup.local]
            c = U_S.T @ Xw_S
            Xp_S = Xw_S - U_S @ c
        else:
            c = sum((f.U[a:b].T @ Xw_S[i:i + b - a] for i, a, b in runs), np.zeros((f.U.shape[1], X.shape[1])))
            Xp_S = np.concatenate([Xw_S[i:i + b - a] - f.U[a:b] @ c for i, a, b in runs]) if runs else Xw_S
        G = Xp_S.T @ Xp_S + c.T @ sup.outside @ c
        d = np.sqrt(np.diag(G))
        if not np.all(d > 0):
            return None
        Gs = G / np.outer(d, d)
        if _condition(Gs) > MAX_GRAM_COND:
            return None
        Ginv = np.linalg.inv(Gs) / np.outer(d, d)
        v = f.VS @ c
        if sup.test_runs is None:
            D = X[sup.test] - A[sup.test] @ v
        else:      # A[test] @ v on the test rows' contiguous runs (stats.rows_times)
            D = X[sup.test]
            for i, a, b in sup.test_runs:
                D[i:i + b - a] -= A[a:b] @ v
        return _ColumnFactors(sup.local, Xw_S, Ginv, D, sup.test, sup.test_pos)


def _condition(G: np.ndarray) -> float:
    """``numpy.linalg.cond(G)`` (2-norm: largest over smallest singular value, ``inf`` for a singular
    ``G``) without its argument handling: one small SVD per fold and added column set."""
    s = np.linalg.svd(G, compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = float(s[0] / s[-1])
    return math.inf if math.isnan(k) else k


@dataclass(frozen=True, eq=False)
class _FoldSupport:
    """The rows of one fold that a set of added columns touches, kept per support: every law of a joint's
    friction search, on every ``y`` of its simulated-noise placebo, is zero outside the same rows."""

    local: np.ndarray      # positions of S (training rows where X is not zero) within the fold's training rows
    rows_S: np.ndarray     # row indices of S
    w_S: np.ndarray        # weights of S
    runs: list | None      # contiguous runs of ``local`` (stats.contiguous_runs)
    outside: np.ndarray    # U_S'^T U_S' over the training rows outside S
    test: np.ndarray       # row indices of the test rows reported (all, or those asked for)
    test_pos: np.ndarray   # their positions within the fold's test rows
    test_runs: list | None

    @staticmethod
    def build(f: _Fold, nonzero: np.ndarray, report: np.ndarray | None) -> _FoldSupport:
        """``nonzero``: rows where the columns are not zero; ``report``: mask of the rows whose residual is
        wanted (None: all)."""
        tr_idx = np.flatnonzero(f.train)
        nz = nonzero[tr_idx]
        local = np.flatnonzero(nz)
        U_o = f.U[~nz]
        te_idx = np.flatnonzero(f.test)
        pos = np.arange(te_idx.size) if report is None else np.flatnonzero(report[te_idx])
        test = te_idx[pos]
        return _FoldSupport(local, tr_idx[local], f.w[local], contiguous_runs(local), U_o.T @ U_o, test, pos,
                            contiguous_runs(test))


class _ColumnCache:
    """Column factors of one fold set, by the content of ``X`` (checked exactly on a hit), oldest
    dropped beyond :data:`COLUMN_CACHE_BYTES`."""

    def __init__(self) -> None:
        self._d: dict = {}
        self._bytes = 0
        self._supports: dict = {}

    def support(self, k: int, f: _Fold, nonzero: np.ndarray, report: np.ndarray | None,
                key: tuple) -> _FoldSupport:
        """:class:`_FoldSupport` of fold ``k`` for the rows ``nonzero`` and the reported rows ``report``
        (``key``: digests of both; a candidate of one joint has the rows of that joint: a few supports per
        fold set)."""
        hit = self._supports.get((k, key))
        if hit is not None:
            return hit
        if len(self._supports) > 64:
            self._supports.clear()
        sup = self._supports[(k, key)] = _FoldSupport.build(f, nonzero, report)
        return sup

    def get(self, X: np.ndarray, tag: str | None = None) -> list | None:
        hit = self._d.get((_fingerprint(X), tag))
        return hit[1] if hit is not None and np.array_equal(hit[0], X) else None

    def put(self, X: np.ndarray, facs: list, tag: str | None = None) -> None:
        size = X.nbytes + sum(fc.nbytes for fc in facs if fc is not None)
        if size > COLUMN_CACHE_BYTES:
            return
        while self._d and self._bytes + size > COLUMN_CACHE_BYTES:
            old = self._d.pop(next(iter(self._d)))
            self._bytes -= old[2]
        self._d[(_fingerprint(X), tag)] = (X.copy(), facs, size)
        self._bytes += size


class BlockedLS:
    """Weighted LS of ``y`` on ``A`` on the training rows of each time-blocked fold, reused for many
    candidate column sets ``X`` (added to ``A``).

    Parameters
    ----------
    A : ndarray, shape (r, k)
        The fixed part of the design (may have zero columns).
    y : ndarray, shape (r,)
    blocks : ndarray of int, shape (r,)
        :func:`time_blocks`.
    weights : ndarray, shape (r,), optional
        Row weights of the fit (e.g. ``1/sigma_j`` for WLS); default 1.
    """

    def __init__(self, A: np.ndarray, y: np.ndarray, blocks: np.ndarray, weights: np.ndarray | None = None):
        A = np.asarray(A, float)
        y = np.asarray(y, float)
        if A.ndim != 2 or A.shape[0] != y.size:
            raise ValueError(f"BlockedLS: A {A.shape} and y {y.shape} do not have the same rows")
        w = np.ones(y.size) if weights is None else np.asarray(weights, float)
        if w.shape != y.shape or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("BlockedLS: weights must be finite, non-negative and one per row")
        self.A, self.y, self.w = A, y, w
        # the fold bases depend on A, the weights and the blocks only: reused for equal ones (the
        # friction-law stage builds the same folds several times per joint, and its simulated-noise
        # placebo refits them on many y), the y-dependent parts are recomputed
        # keyed by a digest of the contents (no copy of A kept: it is the largest array of a diagnosis)
        key = (A.shape, _digest(A), _digest(w), _digest(np.asarray(blocks)))
        hit = _FOLD_CACHE.get(key)
        if hit is not None:
            bases = hit[3]
        else:
            bases = []
            for tr, te in blocked_folds(blocks):
                wt = w[tr]
                U, VS, rank = _wls_factors(A[tr] * wt[:, None])
                bases.append((tr, te, wt, U, VS, rank))
            _FOLD_CACHE.clear()
            _FOLD_CACHE[key] = (None, None, None, bases, _ColumnCache())
            hit = _FOLD_CACHE[key]
        self._columns: _ColumnCache = hit[4]
        self.folds: list[_Fold] = []
        for tr, te, wt, U, VS, rank in bases:
            yw = y[tr] * wt
            c = U.T @ yw
            self.folds.append(_Fold(tr, te, wt, U, VS, yw - U @ c, A[te] @ (VS @ c), rank))

    def oof_residual(self, X: np.ndarray | None = None, rows: np.ndarray | None = None) -> np.ndarray:
        """Out-of-fold residual ``y - prediction`` of every row (each row predicted by the fold that
        holds it out), with the columns ``X`` (r, p) added to ``A``; with ``rows`` (a boolean mask), only
        those rows' residuals (``oof_residual(X)[rows]``, computed on those rows only).

        Equal to :meth:`oof_residual_direct` (to rounding): the fold's factors of ``X`` that do not
        depend on ``y`` (:class:`_ColumnFactors`) are computed on the rows where ``X`` is not zero and
        kept for the next ``y`` fitted with the same ``A``, weights, blocks and ``X`` (the friction-law
        search and its simulated-noise placebo evaluate the same columns on many ``y``); the rows where
        ``X`` is not zero and the fold's reported test rows (:class:`_FoldSupport`) are kept per support."""
        if X is None or not X.shape[1]:
            out = self.oof_residual_direct(X)
            return out if rows is None else out[rows]
        X = np.asarray(X, float)
        report = None if rows is None else np.asarray(rows, bool)
        tag = None if report is None else _digest(np.packbits(report))
        facs = self._columns.get(X, tag)
        if facs is None:
            cc = self._columns
            nonzero = X[:, 0] != 0.0
            for i in range(1, X.shape[1]):
                nonzero |= X[:, i] != 0.0
            key = (_digest(np.packbits(nonzero)), tag)
            facs = [_ColumnFactors.build(self.A, X, f, cc.support(k, f, nonzero, report, key))
                    for k, f in enumerate(self.folds)]
            self._columns.put(X, facs, tag)
        out = np.empty(self.y.size)
        for f, fc in zip(self.folds, facs):
            if fc is None:     # ill-conditioned added columns: the rank-revealing solve
                out[f.test] = self.y[f.test] - self._fold_prediction(f, X)
                continue
            b = fc.Ginv @ (fc.Xw_S.T @ f.e0[fc.local])
            if report is None:
                out[f.test] = self.y[f.test] - (f.pred0 + fc.D @ b)
            else:
                te = fc.test
                out[te] = self.y[te] - (f.pred0[fc.test_pos] + fc.D @ b)
        return out if report is None else out[report]

    def _fold_prediction(self, f: _Fold, X: np.ndarray | None) -> np.ndarray:
        pred = f.pred0
        if X is not None and X.shape[1]:
            Xw = X[f.train] * f.w[:, None]
            Xp = Xw - f.U @ (f.U.T @ Xw)
            b = np.linalg.lstsq(Xp, f.e0, rcond=None)[0]
            pred = pred + X[f.test] @ b - self.A[f.test] @ (f.VS @ (f.U.T @ (Xw @ b)))
        return pred

    def oof_residual_direct(self, X: np.ndarray | None = None) -> np.ndarray:
        """:meth:`oof_residual` by the straightforward solve: ``X`` projected out of the span of ``A``
        on all training rows of each fold and fitted to the fold's residual by a rank-revealing least
        squares (Frisch-Waugh-Lovell)."""
        out = np.empty(self.y.size)
        for f in self.folds:
            out[f.test] = self.y[f.test] - self._fold_prediction(f, X)
        return out

    def rel_err(self, X: np.ndarray | None, rows: np.ndarray) -> float:
        """Out-of-fold relative error norm ``||e||/||y||`` on the rows ``rows`` (mask or indices)."""
        e = self.oof_residual(X)[rows]
        den = float(np.sum(self.y[rows] ** 2))
        return math.sqrt(float(e @ e) / den) if den > 0 else math.inf


# ------------------------------------------------------------------------------------------------
def selection_frequency(select: Callable[[np.ndarray], Iterable[Hashable]], blocks: np.ndarray) -> dict:
    """Share of the time-blocked folds in which each effect is selected.

    Parameters
    ----------
    select : callable
        ``select(train_mask) -> iterable of keys`` (e.g. ``(kind, joint, modulation)``): the effects a
        selection run on the training rows names.
    blocks : ndarray of int, shape (r,)
        :func:`time_blocks` of the rows.

    Returns
    -------
    dict key -> float in [0, 1]
    """
    folds = blocked_folds(blocks)
    count: dict = {}
    for tr, _ in folds:
        for key in set(select(tr)):
            count[key] = count.get(key, 0) + 1
    return {k: c / len(folds) for k, c in count.items()}


def stable(freq: Mapping, min_frequency: float = MIN_SELECTION_FREQUENCY) -> list:
    """Keys selected in more than ``min_frequency`` of the folds, most frequent first."""
    return [k for k, f in sorted(freq.items(), key=lambda kv: -kv[1]) if f > min_frequency]


@dataclass(frozen=True)
class CoefficientCI:
    """Confidence intervals of added coefficients.

    Attributes
    ----------
    values, std : ndarray, shape (p,)
        Estimates and HAC standard deviations.
    low, high : ndarray, shape (p,)
        Per-parameter Student-t intervals at ``level``.
    p_value : float
        Joint Wald test of ``beta = 0`` (F(p, dof)).
    excludes_zero : bool
        ``p_value < 1 - level``: the joint confidence region excludes "no effect".
    level : float
    """

    values: np.ndarray
    std: np.ndarray
    low: np.ndarray
    high: np.ndarray
    p_value: float
    excludes_zero: bool
    level: float


def coefficient_ci(A: np.ndarray, X: np.ndarray, y: np.ndarray, *, weights: np.ndarray | None = None,
                   groups: np.ndarray | None = None, level: float = 0.99,
                   basis: tuple[np.ndarray, int] | None = None) -> CoefficientCI:
    """Confidence intervals of the coefficients of ``X`` in the weighted LS fit ``y ~ [A X]``.

    The covariance is Newey-West (Bartlett weights, lag by :func:`.stats.hac_lag` on the residual,
    lags not crossing ``groups``) of the Frisch-Waugh-Lovell regression of the residual on ``X``
    projected out of ``A``, never smaller than the white-noise one (as in :mod:`.core`): a residual
    that is serially correlated or heteroscedastic does not make a spurious effect "significant".

    Parameters
    ----------
    A : ndarray, shape (r, k)
    X : ndarray, shape (r, p)
    y : ndarray, shape (r,)
    weights : ndarray, shape (r,), optional
    groups : ndarray, shape (r,), optional
        Contiguous-time segments (e.g. ``joint * 100000 + experiment``).
    level : float
        Confidence level in (0, 1).
    basis : (U, rank), optional
        Orthonormal basis of ``A * weights`` and its rank when already computed (e.g. a
        :class:`BlockedLS` fold's ``U``, ``rank`` on the same rows and weights): skips the SVD.
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"coefficient_ci: level must lie in (0, 1), got {level!r}")
    X = np.asarray(X, float).reshape(len(y), -1)
    w = np.ones(len(y)) if weights is None else np.asarray(weights, float)
    U, rank = basis if basis is not None else _wls_factors(np.asarray(A, float) * w[:, None])[::2]
    Xw = X * w[:, None]
    Xp = Xw - U @ (U.T @ Xw)
    yw = np.asarray(y, float) * w
    e0 = yw - U @ (U.T @ yw)
    G = Xp.T @ Xp
    p = X.shape[1]
    Ginv = np.linalg.pinv(G)
    b = Ginv @ (Xp.T @ e0)
    e = e0 - Xp @ b
    dof = max(len(y) - rank - p, 1)
    segs = segments_of(groups, len(y))
    lag = hac_lag(e, groups)
    S = hac_covariance(Xp * e[:, None], max_lag=lag, segments=segs)
    C_hac = Ginv @ S @ Ginv * (len(y) / dof)
    C_iid = Ginv * float(e @ e) / dof
    C = C_hac if np.trace(C_hac @ np.linalg.pinv(C_iid)) >= p else C_iid
    std = np.sqrt(np.maximum(np.diag(C), 0.0))
    tq = float(ssp.stdtrit(dof, 0.5 + level / 2.0))    # = scipy.stats.t.ppf(0.5 + level / 2, dof)
    try:
        W = float(b @ np.linalg.solve(C, b))
    except np.linalg.LinAlgError:
        W = float(b @ np.linalg.pinv(C) @ b)
    pv = f_sf(max(W, 0.0) / p, p, dof)
    return CoefficientCI(b, std, b - tq * std, b + tq * std, pv, bool(pv < 1.0 - level), level)


@dataclass(frozen=True)
class Agreement:
    """Effects named under two estimators.

    Attributes
    ----------
    common : tuple
        Keys named by both, in the order of the first list.
    only_first, only_second : tuple
    message : str or None
        Says which effects depend on the estimator (None when both name the same effects).
    """

    common: tuple
    only_first: tuple
    only_second: tuple
    message: str | None


def ols_wls_agreement(first: Sequence[Hashable], second: Sequence[Hashable], *,
                      labels: tuple[str, str] = ("OLS", "WLS"), describe: Callable[[Hashable], str] = str) -> Agreement:
    """Intersection of the effects named by two estimators (keys such as ``(kind, joint, modulation)``);
    the loop keeps only the common ones and reports the others with ``message``."""
    s1, s2 = list(dict.fromkeys(first)), list(dict.fromkeys(second))
    common = tuple(k for k in s1 if k in set(s2))
    a = tuple(k for k in s1 if k not in set(s2))
    b = tuple(k for k in s2 if k not in set(s1))
    msg = None
    if a or b:
        parts = []
        if a:
            parts.append(f"only {labels[0]} names " + ", ".join(describe(k) for k in a))
        if b:
            parts.append(f"only {labels[1]} names " + ", ".join(describe(k) for k in b))
        msg = ("the named effects depend on the estimator: " + "; ".join(parts)
               + f"; kept only the {len(common)} effect(s) both name")
    return Agreement(common, a, b, msg)


def placebo_stop(placebo_passed: Mapping[int, bool] | Iterable[int]) -> frozenset:
    """Joints (0-based) on which the loop stops: a placebo column (no physical meaning) passed the
    significance and validation tests there, so the residual of that joint holds structure the library
    cannot name specifically and any candidate accepted on it would be a coincidence of the same kind.

    ``placebo_passed``: ``{joint: passed}`` or the joints where one passed."""
    if isinstance(placebo_passed, Mapping):
        return frozenset(int(j) for j, ok in placebo_passed.items() if ok)
    return frozenset(int(j) for j in placebo_passed)


# ------------------------------------------------------------------------------------------------
#: simulated-noise replicates of a selection's null distribution (:func:`simulated_noise_placebo`); an
#: observed gain must exceed all of them (one-sided Monte Carlo p-value <= 1 / (N_NOISE_PLACEBO + 1))
N_NOISE_PLACEBO = 19


def shifted_residual(resid: np.ndarray, groups: np.ndarray, experiment: np.ndarray,
                     rng: np.random.Generator, fraction: float | None = None) -> np.ndarray:
    """``resid`` circularly shifted in time within each contiguous segment of ``groups`` (e.g. one joint
    of one experiment), by the same random fraction (in [0.2, 0.8] of the segment) for every segment of
    an experiment: the residual keeps its spectrum, its heteroscedasticity per joint and its correlation
    between joints, and loses any relation to the motion at the same instant (the circular block
    bootstrap of Politis & Romano 1992 with one block per segment). ``fraction`` fixes the shift of
    the first experiment (the others stay random)."""
    resid = np.asarray(resid, float)
    groups = np.asarray(groups)
    experiment = np.asarray(experiment)
    out = np.empty_like(resid)
    frac = {int(e): float(rng.uniform(0.2, 0.8)) for e in np.unique(experiment)}
    if fraction is not None and frac:
        frac[min(frac)] = float(fraction)
    for idx in segments_of(groups, resid.size):
        out[idx] = np.roll(resid[idx], int(round(frac[int(experiment[idx[0]])] * idx.size)))
    return out


def simulated_noise_placebo(gain: Callable[[np.ndarray], float], fitted: np.ndarray, resid: np.ndarray,
                            groups: np.ndarray, experiment: np.ndarray, observed: float, *,
                            n_rep: int = N_NOISE_PLACEBO, rng: np.random.Generator | None = None) -> tuple[bool, list]:
    """Does a selection's observed gain beat what the same selection finds on data where the declared
    model is the truth and the noise is the data's own?

    The null data are ``fitted + shifted_residual(resid)`` (the declared model's prediction plus its own
    residual moved in time, :func:`shifted_residual`); ``gain(y_null)`` re-runs the *whole* selection
    (its searches of shape parameters, its choice among laws, its one-standard-error rule) on them and
    returns the gain it would claim (0 when it keeps the declared model). Searching a shape on the same
    folds that then judge it biases any cross-validated gain upwards (Cawley & Talbot 2010, "On
    over-fitting in model selection and subsequent selection bias", JMLR 11); replicating the selection
    on null data calibrates that bias with the data's noise (a parametric bootstrap of the selection,
    Efron & Tibshirani 1993, ch. 16). The observed gain passes when it exceeds every null gain:
    a Monte Carlo p-value ``<= 1 / (n_rep + 1)``. Stops at the first null gain reaching ``observed``.

    Returns ``(passed, null_gains)``."""
    rng = np.random.default_rng(0) if rng is None else rng
    fitted = np.asarray(fitted, float)
    null: list[float] = []
    # stratified shifts of the first experiment (distinct ones even for short segments), in random order
    fractions = 0.2 + 0.6 * (rng.permutation(int(n_rep)) + rng.uniform(size=int(n_rep))) / max(int(n_rep), 1)
    for k in range(int(n_rep)):
        g = float(gain(fitted + shifted_residual(resid, groups, experiment, rng, fractions[k])))
        null.append(g)
        if not g < observed:
            return False, null
    return True, null


def sided_selection(selected_on: Callable[[int, np.ndarray], bool], tests: Sequence[np.ndarray],
                    before: np.ndarray) -> float:
    """Selection frequency of a change in time (a step at ``t_s``), judged on each side of the change.

    A time-invariant effect may be confirmed by any held-out block; a change at ``t_s`` is only confirmed
    by held-out data on *both* sides of it: blocks after ``t_s`` show that the later level differs from
    the whole fit's, which any misfit concentrated early gives too (and validation data held out at the end
    of a recording lie wholly after the change); blocks before ``t_s`` show that the earlier level differs
    as well. ``selected_on(k, rows)`` says whether fold ``k`` selects the effect judged on the held-out
    ``rows`` (significant on its training rows and lowering the error on ``rows``); it is asked on the part
    before ``t_s`` and the part after of each held-out block ``tests[k]`` (rows of the effect's joints), and
    the frequency is the smaller of the two sides' (each over the blocks that have rows on that side). A side without any held-out rows gives 0: a change that no data precede or follow is
    not testable."""
    before = np.asarray(before, bool)
    freq = []
    for side in (before, ~before):
        hits = [bool(selected_on(k, te & side)) for k, te in enumerate(tests) if np.any(te & side)]
        freq.append(float(np.mean(hits)) if hits else 0.0)
    return min(freq)
