"""What is still missing after the loop: structure in the residual that no candidate explains
(the loop's last stage).

For each joint ``j``, a non-parametric model (scikit-learn's ``HistGradientBoostingRegressor``,
gradient-boosted trees) predicts the final residual ``e_j`` from the signals of *all* joints
(``q, dq, ddq, tau_hat`` and the time since the start of the experiment). It is fitted and evaluated
out of fold on contiguous time blocks (:func:`.stability.time_blocks`; ``K`` blocks per experiment,
no shuffling), so a model that only memorises serially correlated noise scores ``R^2 <= 0``. The
share of the residual variance that is predictable but unexplained is the out-of-fold ``R^2``,
clipped to [0, 1].

Noise calibration
-----------------
The threshold is calibrated on the residual itself: the same out-of-fold model is fitted ``n_null``
times on the residual *block-permuted* against the signals: within each experiment the residual is
rotated by a random offset, cut into blocks of its correlation length (twice the lag where its
autocorrelation falls below 0.1, at most ``MAX_BLOCK_SHARE`` of the experiment) and the blocks are
shuffled (a moving-block permutation, Kuensch 1989). This keeps the residual's distribution and its
short-range autocorrelation (coloured noise stays coloured) and breaks its alignment with the signals,
also for periodic excitations, where a plain circular time shift would keep the residual a function of
the motion's phase. What the trees "predict" then is chance. A joint is flagged when its share exceeds
``max(MIN_SHARE, max(null R^2) + NULL_MARGIN)``; white-noise residuals give a share ~0 and are not
flagged.

Specific to the joints that carry it
------------------------------------
The final residual comes from one least-squares fit of all joints' rows: a torque missing on joint ``c``
moves the parameters ``c`` shares with the joints coupled to it, and leaves ``-A_k delta`` - a smooth
function of the motion the trees predict well - in the residual of every such joint ``k``. Tested on
that residual, every joint was flagged. :func:`unexplained_by_joint` tests each joint on the residual of
a fit that the joints found to carry structure do not move (:func:`refit_without`, a leave-the-group-out
refit): greedily, the joint with the largest flagged share joins the carriers and the others are tested
again; the carriers are tested last, on a residual that keeps their whole missing torque. Each test has
its own null (that joint's residual block-permuted). A residual longer than ``MAX_TREE_SAMPLES`` samples
is thinned in time before the trees see it.

Joints of unequal noise
-----------------------
The same spread comes from the noise when the joints' noise levels differ by an order of magnitude: the
unweighted fit's estimation error, driven by the noisy joints' rows, leaves a smooth ``-A_k delta`` on the quiet
joints, which are then flagged on clean data. :func:`joint_weighted_residual` gives the residual of the per-joint
weighted refit ([GB-gains] eq. 22), on which each joint keeps its own residual; the loop tests it when
``DiagnoseSettings.unexplained_weighted`` is set (a floating-base robot's rows, docs/floating-base.md).

A round that adds a carrier passes on its decision only (each joint it tested is tested again), so its
fits stop once that decision is settled (:func:`greedy_round`, the sequential Monte Carlo rule of Besag &
Clifford 1991): the out-of-fold ``R^2`` can only fall as folds are added, so a joint's fit stops when it
can no longer beat the flagged joint found before it, and a null fit when it can no longer unflag its
joint. The carriers, flags and every reported number are those of the complete search.

Which signals
-------------
For a flagged joint, the permutation importance of each signal (Breiman 2001; each column permuted
in the held-out block, the drop of out-of-fold ``R^2``), summed over the joint's signals of the same
name; the signals carrying at least ``IMPORTANCE_SHARE`` of the total are listed, most important first.
On a periodic excitation (Fourier series) every signal is a function of the motion's phase, so the
trees may use another joint's signal as a proxy: the signals listed are those the model used, a hint
rather than a cause.

``scikit-learn`` is an optional dependency (extra ``diagnose``), imported when this runs.
"""
from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .stability import N_FOLDS, blocked_folds, time_blocks

__all__ = ["MIN_SHARE", "NULL_MARGIN", "FoldFits", "Unexplained", "greedy_round", "joint_weighted_residual",
           "permutation_importance", "refit_without",
           "rows_to_samples", "signal_matrix", "unexplained_by_joint", "unexplained_structure"]

#: smallest share of residual variance ever flagged
MIN_SHARE = 0.05
#: margin above the largest time-shifted (null) share
NULL_MARGIN = 0.05
#: time-shift null fits per joint
N_NULL = 3
#: longest block of the block permutation, as a share of the experiment
MAX_BLOCK_SHARE = 0.05
#: a signal is listed when it carries this share of the total permutation importance
IMPORTANCE_SHARE = 0.1
#: most signals listed
MAX_SIGNALS = 3
#: most samples the trees see per joint: a longer residual is thinned to every k-th sample (it is
#: low-passed at the decimation cut-off, so neighbouring samples carry little new information; the trees'
#: cost grows with the samples, the information with the band-limited residual's length in time)
MAX_TREE_SAMPLES = 4000
#: gradient-boosting settings (small: the residual has a few thousand rows per joint)
HGB_PARAMS = {"max_iter": 60, "learning_rate": 0.15, "max_leaf_nodes": 15, "min_samples_leaf": 40,
              "l2_regularization": 1.0, "early_stopping": False}


@dataclass(frozen=True)
class Unexplained:
    """Structure left in one joint's residual.

    Attributes
    ----------
    joint : int
        1-based (the JSON contract of ``diagnose``).
    share : float
        Out-of-fold R^2 of the residual, in [0, 1].
    threshold : float
        Noise-calibrated threshold it was compared with.
    flagged : bool
    signals : tuple of str
        Signals it depends on (permutation importance), most important first.
    """

    joint: int
    share: float
    threshold: float
    flagged: bool
    signals: tuple

    def to_dict(self) -> dict:
        return {"joint": self.joint, "share": self.share, "signals": list(self.signals)}


def signal_matrix(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, tau_hat: np.ndarray | None, t: np.ndarray
                  ) -> tuple[np.ndarray, tuple[str, ...]]:
    """Feature matrix (s, 4n + 1) and names (``q1 .. qn, dq1.., ddq1.., tau_hat1.., t``) per sample."""
    q = np.asarray(q, float)
    n = q.shape[1]
    parts, names = [], []
    for nm, x in (("q", q), ("dq", dq), ("ddq", ddq), ("tau_hat", tau_hat)):
        if x is None:
            continue
        parts.append(np.asarray(x, float))
        names += [f"{nm}{j + 1}" for j in range(n)]
    parts.append(np.asarray(t, float)[:, None])
    names.append("t")
    return np.hstack(parts), tuple(names)


def rows_to_samples(values: np.ndarray, joint: np.ndarray, experiment: np.ndarray, index: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stacked rows (joint-major, as the observation systems) to one line per sample.

    Parameters
    ----------
    values : ndarray, shape (r,) or (r, m)
        Per-row values (e.g. the residual) - for per-row signals of all joints ``(r, n)``, take the rows
        of one joint instead.
    joint, experiment, index : ndarray of int, shape (r,)
        Joint (0-based), experiment and sample index within the experiment of each row.

    Returns
    -------
    per_sample : ndarray, shape (s, n) (or (s, n, m))
        Value of each joint at each sample (samples ordered by experiment, then index).
    sample_experiment, sample_index : ndarray of int, shape (s,)
    """
    values = np.asarray(values, float)
    joint, experiment, index = (np.asarray(x) for x in (joint, experiment, index))
    keys = np.unique(np.column_stack([experiment, index]), axis=0)
    s = keys.shape[0]
    n = int(joint.max()) + 1
    pos = {(int(e), int(i)): k for k, (e, i) in enumerate(keys)}
    where = np.array([pos[(int(e), int(i))] for e, i in zip(experiment, index)])
    out = np.full((s, n) + values.shape[1:], np.nan)
    out[where, joint] = values
    if np.isnan(out).any():
        raise ValueError("rows_to_samples: some joints lack rows at some samples (every joint must have a row "
                         "at every sample)")
    return out, keys[:, 0], keys[:, 1]


def refit_without(resid: np.ndarray, A: np.ndarray, joint: np.ndarray, carriers: Sequence[int],
                  rcond: float = 1e-10) -> np.ndarray:
    """The residual of the fit in which the rows of the ``carriers`` joints do not move the parameters the
    other joints determine.

    The stacked least-squares fit spreads an effect missing on joint ``c`` over every joint coupled to it:
    the shared parameters move by ``delta`` and leave ``-A_k delta`` (a smooth function of the motion) in
    the residual of each joint ``k``. Re-fitted on the rows of the other joints only (the parameters they
    leave undetermined, such as ``c``'s own friction, fitted on ``c``'s rows within that null space), the
    other joints' residuals lose the spread and ``c``'s residual keeps the whole missing torque (a
    leave-one-group-out fit; the least-squares limit of weight 0 on ``c``'s rows, Bjoerck 1996, sec. 5.1).

    Parameters
    ----------
    resid : ndarray, shape (r,)
        Stacked residual ``Y - A theta`` of the fit over all rows.
    A : ndarray, shape (r, p)
        Design it was fitted with.
    joint : ndarray of int, shape (r,)
        Joint (0-based) of each row.
    carriers : sequence of int
        0-based joints whose rows are left out of the shared parameters (none: ``resid`` unchanged).
    rcond : float
        Relative singular-value cut-off that defines the null space of the other joints' rows.

    Returns
    -------
    ndarray, shape (r,)
        ``resid - A gamma`` (the refit starts from ``theta``: the correction ``gamma`` is linear in ``resid``).
    """
    resid = np.asarray(resid, float)
    A = np.asarray(A, float)
    joint = np.asarray(joint)
    if A.shape[0] != resid.shape[0] or joint.shape[0] != resid.shape[0]:
        raise ValueError(f"refit_without: residual ({resid.shape[0]} rows), design {A.shape} and joint "
                         f"({joint.shape[0]} rows) disagree")
    inC = np.isin(joint, np.asarray(list(carriers), int))
    if not inC.any():
        return resid.copy()
    Ao, Ac = A[~inC], A[inC]
    _, sv, Vt = np.linalg.svd(Ao, full_matrices=False) if Ao.shape[0] else (None, np.zeros(0), np.zeros((0, A.shape[1])))
    keep = sv > rcond * sv[0] if sv.size and sv[0] > 0 else np.zeros(sv.size, bool)
    V1 = Vt[keep].T
    # the other joints' parameters: min-norm least squares on their rows (in the row space V1 of Ao)
    g1 = V1 @ np.linalg.lstsq(Ao @ V1, resid[~inC], rcond=None)[0] if V1.shape[1] else np.zeros(A.shape[1])
    # what they leave undetermined (the null space N of Ao) is fitted on the carriers' rows
    N = np.linalg.svd(V1.T, full_matrices=True)[2][V1.shape[1]:].T if V1.shape[1] else np.eye(A.shape[1])
    g2 = N @ np.linalg.lstsq(Ac @ N, resid[inC] - Ac @ g1, rcond=None)[0] if N.shape[1] else 0.0
    return resid - A @ (g1 + g2)


def joint_weighted_residual(resid: np.ndarray, A: np.ndarray, joint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The residual and design of the per-joint weighted least-squares refit (IDIM-WLS, [GB-gains] eq. 22),
    weighted: each joint's rows divided by the RMS of its residual ``resid`` (the first step's ``Y - A theta``),
    and ``resid`` refitted on the weighted design (the correction is linear in ``resid``: the refit starts from
    ``theta``).

    Where the joints' noise levels differ by an order of magnitude, the unweighted fit's estimation error
    ``delta``, driven by the noisy joints' rows, leaves ``-A_k delta`` - a smooth function of the motion that
    the trees predict - on the residual of each quiet joint ``k`` coupled to them: the quiet joints are then
    flagged on a clean log (a floating-base robot's joint rows beside its base-wrench rows, which carry the
    contact sensors' noise and, through the base's columns, the IMU's). On the weighted refit each joint's
    rows count by their own noise, and the quiet joints keep their own residual. A joint's weight is a
    constant of its residual, so its out-of-fold ``R^2`` does not depend on it; the weighted design makes
    :func:`refit_without` weighted too (pass both to :func:`unexplained_by_joint`).

    Returns
    -------
    (ndarray (r,), ndarray (r, p))
        The weighted residual of the refit and the weighted design.
    """
    resid, A, joint = np.asarray(resid, float), np.asarray(A, float), np.asarray(joint)
    if A.shape[0] != resid.shape[0] or joint.shape[0] != resid.shape[0]:
        raise ValueError(f"joint_weighted_residual: residual ({resid.shape[0]} rows), design {A.shape} and joint "
                         f"({joint.shape[0]} rows) disagree")
    rms = np.zeros(int(joint.max()) + 1)
    np.add.at(rms, joint, resid ** 2)
    rms = np.sqrt(rms / np.maximum(np.bincount(joint, minlength=rms.size), 1))
    w = 1.0 / np.where(rms > 0, rms, 1.0)[joint]
    rw, Aw = resid * w, A * w[:, None]
    return rw - Aw @ np.linalg.lstsq(Aw, rw, rcond=None)[0], Aw


#: fitted bin mappers and binned training matrices of the folds' feature rows (:func:`binned_hgb_class`), keyed
#: by a digest of the rows; a few entries (one per fold of the current stage)
FOLD_BINS: dict = {}
#: most entries of :data:`FOLD_BINS` before it is emptied
MAX_BIN_ENTRIES = 32
_HGB: list = []


def binned_hgb_class():
    """``HistGradientBoostingRegressor`` that bins equal training rows once.

    The stage fits ``5 x (1 + n_null)`` models per joint test, and a few tests per joint, all on the same
    fold rows of the same signals (only the target changes): the quantile binning of the features
    (``_BinMapper``, ~1/6 of a fit on a thousand rows) depends on those rows alone (its subsampling, above
    200,000 rows, on the fixed seed), so its result is kept and reused; the trees are then grown exactly
    as without the cache (``tests/diagnostics/test_unexplained_speed.py`` compares the predictions).
    Any other call (validation data, sample weights) takes scikit-learn's own path."""
    if _HGB:
        return _HGB[0]
    from sklearn.ensemble import HistGradientBoostingRegressor

    class FoldBinnedHGB(HistGradientBoostingRegressor):
        def _bin_data(self, X, *args, is_training_data, **kwargs):
            plain = (not is_training_data or any(a is not None for a in args)
                     or kwargs.get("sample_weight") is not None)
            if plain:
                return super()._bin_data(X, *args, is_training_data=is_training_data, **kwargs)
            Xc = np.ascontiguousarray(X)
            key = (Xc.shape, str(Xc.dtype), self.max_bins, self.random_state,
                   hashlib.blake2b(Xc.data, digest_size=16).digest())
            hit = FOLD_BINS.get(key)
            if hit is None:
                binned = super()._bin_data(X, *args, is_training_data=True, **kwargs)
                if len(FOLD_BINS) >= MAX_BIN_ENTRIES:
                    FOLD_BINS.clear()
                FOLD_BINS[key] = (self._bin_mapper, binned)
                return binned
            self._bin_mapper = hit[0]
            return hit[1]

    _HGB.append(FoldBinnedHGB)
    return FoldBinnedHGB


class FoldFits:
    """Out-of-fold predictions of one target, grown one fold at a time (the folds partition the rows).

    After ``k`` folds the sum of squared out-of-fold errors ``SSE_k`` only grows with the next folds, so
    ``1 - SSE_k / SST`` (:meth:`bound`) is an upper bound of the out-of-fold ``R^2`` that the remaining folds
    can only lower: the greedy rounds of :func:`unexplained_by_joint` stop a fit once this bound settles
    the round's decision. Completed (:meth:`finish`), the predictions are those of the plain loop over the
    folds, model for model."""

    def __init__(self, X: np.ndarray, e: np.ndarray, folds: Sequence, seed: int):
        self.X, self.e, self.folds, self.seed = X, e, folds, seed
        self.pred = np.empty_like(e)
        self.models: list = []
        self.sse = 0.0
        self.sst = float(np.sum((e - e.mean()) ** 2))

    @property
    def done(self) -> bool:
        return len(self.models) == len(self.folds)

    def step(self) -> None:
        """Fit the next fold (call under one OpenMP thread, :func:`_oof`)."""
        tr, te = self.folds[len(self.models)]
        m = binned_hgb_class()(random_state=self.seed, **HGB_PARAMS).fit(self.X[tr], self.e[tr])
        self.pred[te] = m.predict(self.X[te])
        self.models.append(m)
        self.sse += float(np.sum((self.e[te] - self.pred[te]) ** 2))

    def bound(self) -> float:
        """Upper bound of the completed fit's out-of-fold ``R^2`` (exact once :attr:`done`, to rounding)."""
        return 1.0 - self.sse / self.sst if self.sst > 0 else 0.0

    def finish(self) -> FoldFits:
        while not self.done:
            self.step()
        return self

    def share(self) -> float:
        """Out-of-fold ``R^2`` clipped to [0, 1] (the folds completed first)."""
        self.finish()
        return float(np.clip(_r2(self.e, self.pred), 0.0, 1.0))


def _oof(X, e, folds, seed):
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    # one thread: the trees are small, and OpenMP threads spinning on a busy machine cost far more than
    # they save (measured: 2.4 s per fit with all cores on a loaded 2-core machine, ~0.1 s with one).
    # scikit-learn (and its OpenMP runtime) is loaded first: threadpoolctl limits only the loaded libraries
    binned_hgb_class()
    with threadpool_limits(limits=1, user_api="openmp"):
        f = FoldFits(X, e, folds, seed).finish()
    return f.pred, f.models


def _r2(e, pred):
    ss = float(np.sum((e - e.mean()) ** 2))
    return 1.0 - float(np.sum((e - pred) ** 2)) / ss if ss > 0 else 0.0


def _block_length(e: np.ndarray, n: int) -> int:
    """Twice the lag where the residual's autocorrelation first falls below 0.1, at most
    ``MAX_BLOCK_SHARE`` of the experiment (at least 1)."""
    x = e - e.mean()
    c0 = float(x @ x)
    cap = max(1, int(MAX_BLOCK_SHARE * n))
    if c0 <= 0:
        return 1
    for k in range(1, cap + 1):
        if float(x[k:] @ x[:-k]) / c0 < 0.1:
            return max(1, min(2 * k, cap))
    return cap


def _block_permute(e, experiment, rng):
    """The residual cut into blocks of its correlation length, blocks shuffled within each experiment."""
    out = np.empty_like(e)
    for x in np.unique(experiment):
        idx = np.flatnonzero(experiment == x)
        ex = np.roll(e[idx], int(rng.integers(idx.size)))
        L = _block_length(ex, idx.size)
        blocks = [ex[i:i + L] for i in range(0, idx.size, L)]
        out[idx] = np.concatenate([blocks[i] for i in rng.permutation(len(blocks))])
    return out


def _tree_rows(residual, features, names, experiment, order, n_folds):
    """Residual (s, n), features, experiment of each sample and the time-blocked folds the trees see: the
    samples thinned to every ``ceil(s / MAX_TREE_SAMPLES)``-th one (in time order within each experiment)."""
    E = np.asarray(residual, float)
    if E.ndim == 1:
        E = E[:, None]
    X = np.asarray(features, float)
    s = E.shape[0]
    if X.shape[0] != s or len(names) != X.shape[1]:
        raise ValueError(f"unexplained_structure: residual {E.shape}, features {X.shape} and {len(names)} names disagree")
    experiment = np.zeros(s, int) if experiment is None else np.asarray(experiment)
    order = np.arange(s) if order is None else np.asarray(order)
    stride = -(-s // MAX_TREE_SAMPLES)
    if stride > 1:
        keep = np.concatenate([np.flatnonzero(experiment == x)[np.argsort(order[experiment == x], kind="stable")][::stride]
                               for x in np.unique(experiment)])
        E, X, experiment, order = E[keep], X[keep], experiment[keep], order[keep]
    return E, X, experiment, blocked_folds(time_blocks(experiment, order, n_folds))


def unexplained_structure(residual: np.ndarray, features: np.ndarray, names: Sequence[str], *,
                          experiment: np.ndarray | None = None, order: np.ndarray | None = None,
                          n_folds: int = N_FOLDS, n_null: int = N_NULL, min_share: float = MIN_SHARE,
                          null_margin: float = NULL_MARGIN, seed: int = 0, joints: Sequence[int] | None = None,
                          signals: bool = True) -> list[Unexplained]:
    """Share of each joint's residual that the signals predict out of fold, with a noise-calibrated threshold.

    Parameters
    ----------
    residual : ndarray, shape (s, n)
        Final residual per sample and joint (decimated rows of each joint, in sample order).
    features : ndarray, shape (s, f)
        Signals per sample (:func:`signal_matrix`).
    names : sequence of str
        Feature names; ``q3`` and the like (signal name + 1-based joint) are reported as they are.
    experiment : ndarray of int, shape (s,), optional
        Experiment of each sample (default: one).
    order : ndarray, shape (s,), optional
        Sample index within the experiment (default: position in the array).
    n_folds : int
        Contiguous time blocks per experiment.
    n_null : int
        Time-shift null fits per joint.
    min_share, null_margin : float
        Threshold ``max(min_share, max(null) + null_margin)``.
    seed : int
        Seeds the shifts, the permutations and the trees.
    joints : sequence of int, optional
        0-based joints to analyse (default all).
    signals : bool
        Compute the signals a flagged joint depends on (permutation importance; False: ``signals`` empty).

    Returns
    -------
    list of Unexplained
        One per joint analysed (``flagged`` says which go to the JSON ``unexplained`` list).
    """
    E, X, experiment, folds = _tree_rows(residual, features, names, experiment, order, n_folds)
    n = E.shape[1]
    rng = np.random.default_rng(seed)
    out = []
    for j in (range(n) if joints is None else joints):
        e = E[:, j]
        pred, models = _oof(X, e, folds, seed)
        share = float(np.clip(_r2(e, pred), 0.0, 1.0))
        # a share at or below min_share is never flagged whatever the null gives: skip the null fits
        null = [float(np.clip(_r2(es, _oof(X, es, folds, seed)[0]), 0.0, 1.0))
                for es in (_block_permute(e, experiment, rng) for _ in range(n_null))] if share > min_share else []
        thr = max(min_share, (max(null) if null else 0.0) + null_margin)
        flagged = share > thr
        sigs: tuple = ()
        if flagged and signals:
            rng_imp = np.random.default_rng([seed, int(j)])   # the null draws do not depend on ``signals``
            imp = permutation_importance(X, e, folds, models, _r2(e, pred), rng_imp)
            tot = imp.sum()
            if tot > 0:
                ordr = np.argsort(-imp)
                sigs = tuple(names[c] for c in ordr[:MAX_SIGNALS] if imp[c] >= IMPORTANCE_SHARE * tot)
        out.append(Unexplained(int(j) + 1, share, float(thr), bool(flagged), sigs))
    return out


def permutation_importance(X: np.ndarray, e: np.ndarray, folds: Sequence, models: Sequence, base: float,
                           rng: np.random.Generator) -> np.ndarray:
    """Drop of the out-of-fold ``R^2`` (from ``base``) when each column of ``X`` is permuted in the held-out
    block of every fold (Breiman 2001), at least 0. The permutations are drawn column by column, fold by fold
    from ``rng``; each fold's model then predicts its held-out rows with every column permuted in one call
    (the rows stacked, one block per column): a tree ensemble predicts each row on its own, so the predictions
    are those of one call per column and fold, value for value (``tests/diagnostics/test_unexplained_speed.py``).
    """
    from threadpoolctl import threadpool_limits

    ncol = X.shape[1]
    perms = [[rng.permutation(X[te, c]) for _tr, te in folds] for c in range(ncol)]
    P = np.empty((ncol, e.size))
    with threadpool_limits(limits=1, user_api="openmp"):
        for k, ((_tr, te), m) in enumerate(zip(folds, models)):
            Xt = X[te]
            n = Xt.shape[0]
            Xs = np.tile(Xt, (ncol, 1))
            for c in range(ncol):
                Xs[c * n:(c + 1) * n, c] = perms[c][k]
            P[:, te] = m.predict(Xs).reshape(ncol, n)
    return np.array([max(base - _r2(e, P[c]), 0.0) for c in range(ncol)])


#: rounding guard of the fold bounds' comparisons (a sum of squares accumulated fold by fold against the
#: whole one)
BOUND_TOL = 1e-9


class _Draws:
    """The block permutations of a round, drawn from one stream in the order :func:`unexplained_structure`
    draws them: ``n_null`` for each joint whose share exceeds ``min_share``, in joint order. A joint whose
    share fit was stopped early is completed first unless its bound already puts it at or below
    ``min_share`` (then it draws nothing, as in the plain test)."""

    def __init__(self, joints, fits, experiment, rng, n_null, min_share):
        self.joints, self.fits, self.experiment, self.rng = list(joints), fits, experiment, rng
        self.n_null, self.min_share = n_null, min_share
        self.perms: dict[int, list] = {}
        self.drawn = 0

    def of(self, k: int) -> list:
        """Permutations of ``joints[k]`` (after those of the joints before it)."""
        while self.drawn <= k:
            f = self.fits[self.joints[self.drawn]]
            if not f.done and f.bound() > self.min_share - BOUND_TOL:
                f.finish()
            if f.done and f.share() > self.min_share:
                self.perms[self.joints[self.drawn]] = [_block_permute(f.e, self.experiment, self.rng)
                                                       for _ in range(self.n_null)]
            self.drawn += 1
        return self.perms[self.joints[k]]


def _null_flags(X, share, perms, folds, seed, null_margin) -> tuple[bool, list[FoldFits]]:
    """Whether a joint of out-of-fold share ``share`` stays flagged against its nulls, each null fit stopped
    once its bound can no longer reach ``share - null_margin``; the first null that unflags ends the test."""
    nulls = []
    for es in perms:
        g = FoldFits(X, es, folds, seed)
        nulls.append(g)
        while not g.done and max(g.bound(), 0.0) + null_margin >= share - BOUND_TOL:
            g.step()
        if g.done and g.share() + null_margin >= share:
            return False, nulls
    return True, nulls


def greedy_round(residual: np.ndarray, features: np.ndarray, names: Sequence[str], *, experiment: np.ndarray,
                 order: np.ndarray, joints: Sequence[int], n_folds: int = N_FOLDS, n_null: int = N_NULL,
                 min_share: float = MIN_SHARE, null_margin: float = NULL_MARGIN, seed: int = 0
                 ) -> tuple[list[Unexplained] | None, int | None]:
    """One round of the carrier search of :func:`unexplained_by_joint`: the flagged joint with the largest
    share (the first in joint order on ties), or, when no joint is flagged, the results of
    ``unexplained_structure(..., signals=False)`` number for number.

    A round that finds a carrier only passes on its decision (every joint it tested is tested again, in the
    next round or among the carriers), so its fits stop as soon as the decision is settled - the sequential
    Monte Carlo test's rule of sampling only until the decision is certain (Besag & Clifford, "Sequential
    Monte Carlo p-values", Biometrika 78, 1991), here on the folds of each out-of-fold fit, whose ``R^2``
    can only fall as folds are added (:meth:`FoldFits.bound`):

    * a joint's fit stops once its bound is below the share of a flagged joint found before it (it can no
      longer be the carrier), and a joint whose share does not exceed that flagged share gets no null fits;
    * a null fit stops once its bound plus ``null_margin`` is below the joint's share (it can no longer
      unflag it); the first null that unflags the joint ends its test.

    The permutations come from the stream and in the order of :func:`unexplained_structure` (:class:`_Draws`);
    when no joint is flagged, every fit is completed (no share fit stopped, the unflagging nulls' tests
    finished), so the results are the plain test's (``tests/diagnostics/test_unexplained_speed.py``).

    Returns
    -------
    (results, None) when no joint is flagged (one per joint of ``joints``, in that order), else
    (None, carrier) with the carrier 0-based.
    """
    from threadpoolctl import threadpool_limits

    E, X, experiment, folds = _tree_rows(residual, features, names, experiment, order, n_folds)
    joints = list(joints)
    fits: dict[int, FoldFits] = {}
    draws = _Draws(joints, fits, experiment, np.random.default_rng(seed), n_null, min_share)
    best: tuple[float, int] | None = None
    results: dict[int, Unexplained] = {}
    unflagged: dict[int, tuple[float, list[FoldFits]]] = {}
    binned_hgb_class()   # loads scikit-learn's OpenMP runtime before the one-thread limit (:func:`_oof`)
    with threadpool_limits(limits=1, user_api="openmp"):
        for k, j in enumerate(joints):
            f = fits[j] = FoldFits(X, E[:, j], folds, seed)
            while not f.done and (best is None or f.bound() >= best[0] - BOUND_TOL):
                f.step()
            if not f.done:
                continue
            share = f.share()
            if share <= min_share:
                results[j] = Unexplained(int(j) + 1, share, float(max(min_share, null_margin)), False, ())
                continue
            if best is not None and share <= best[0]:
                continue
            flagged, nulls = _null_flags(X, share, draws.of(k), folds, seed, null_margin)
            if flagged:
                best = (share, j)
            else:
                unflagged[j] = (share, nulls)
        if best is not None:
            return None, best[1]
        for j, (share, nulls) in unflagged.items():
            nulls += [FoldFits(X, es, folds, seed) for es in draws.of(joints.index(j))[len(nulls):]]
            thr = max(min_share, max(g.share() for g in nulls) + null_margin)
            results[j] = Unexplained(int(j) + 1, share, float(thr), bool(share > thr), ())
    return [results[j] for j in joints], None


def unexplained_by_joint(resid: np.ndarray, A: np.ndarray, joint: np.ndarray, experiment: np.ndarray,
                         index: np.ndarray, features: np.ndarray, names: Sequence[str], *, seed: int = 0,
                         **kw) -> tuple[list[Unexplained], tuple[int, ...]]:
    """:func:`unexplained_structure` made specific to the joints that carry the structure.

    A joint is tested on its residual from a fit that the joints found to carry structure do not move
    (:func:`refit_without`), found greedily: every joint is tested on the stacked fit's residual; while
    a joint outside the carriers is flagged, the one with the largest share joins them, the fit is redone
    without their rows and the joints outside are tested again. The carriers are tested last on the final
    residual, which keeps their whole missing torque (a joint wrongly taken as a carrier is then not flagged).
    Each test keeps its own noise calibration (block-permuted residual of that joint).

    Parameters
    ----------
    resid, A, joint, experiment, index : ndarray
        Stacked residual (r,), the design (r, p) it was fitted with, and the joint (0-based), experiment
        and sample index of each row (joint-major, as the observation systems).
    features, names :
        Signals per sample (:func:`signal_matrix`, samples ordered by experiment then index).
    seed : int
        Seeds every test.
    **kw :
        Passed to :func:`unexplained_structure`.

    Returns
    -------
    results : list of Unexplained
        One per joint, in joint order.
    carriers : tuple of int
        0-based joints whose rows were left out of the final fit.
    """
    joint = np.asarray(joint)
    n = int(joint.max()) + 1
    carriers: list[int] = []
    found: dict[int, Unexplained] = {}
    while True:
        r = refit_without(resid, A, joint, carriers)
        E, e_exp, e_idx = rows_to_samples(r, joint, experiment, index)
        others = [j for j in range(n) if j not in carriers]
        res, carrier = greedy_round(E, features, names, experiment=e_exp, order=e_idx, joints=others, seed=seed,
                                    **kw)
        if carrier is None:
            found.update({u.joint - 1: u for u in res or ()})
            break
        if len(others) == 1:
            # the last joint outside the carriers is flagged: tested again with the signals it depends on
            found.update({u.joint - 1: u for u in unexplained_structure(
                E, features, names, experiment=e_exp, order=e_idx, seed=seed, joints=[carrier], **kw)})
            break
        carriers.append(carrier)
    if carriers:
        found.update({u.joint - 1: u for u in unexplained_structure(E, features, names, experiment=e_exp,
                                                                     order=e_idx, seed=seed, joints=carriers, **kw)})
    return [found[j] for j in range(n)], tuple(sorted(carriers))
