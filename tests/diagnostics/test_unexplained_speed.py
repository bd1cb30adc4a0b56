"""The unexplained stage's shortcuts give the results of the plain computation.

* :func:`symoro_gen.diagnostics.unexplained.greedy_round` stops its fits once a round's decision is settled:
  the carrier search must find the carriers and report the numbers of the complete search (every fold and
  every null fit of every round), and a fit's bound must only fall, to the complete fit's ``R^2``.
* :func:`symoro_gen.diagnostics.unexplained.binned_hgb_class` bins equal training rows once: its trees must
  predict exactly what scikit-learn's own ``HistGradientBoostingRegressor`` predicts (same settings, same
  seed), for several targets fitted on the same rows (the cache's hits) and on other rows (its misses).
* :func:`symoro_gen.diagnostics.unexplained.permutation_importance` predicts every permuted column of a fold in
  one call: the importances must be those of one prediction per column and fold, value for value.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("sklearn")
from sklearn.ensemble import HistGradientBoostingRegressor
from threadpoolctl import threadpool_limits

from symoro_gen.diagnostics import unexplained as U
from symoro_gen.diagnostics.stability import blocked_folds, time_blocks


def test_binned_trees_predict_as_scikit_learn():
    rng = np.random.default_rng(3)
    s = 600
    X = np.column_stack([rng.standard_normal((s, 6)), np.round(rng.standard_normal((s, 2)), 1),
                         np.linspace(0.0, 9.0, s)])
    folds = blocked_folds(time_blocks(np.zeros(s, int), np.arange(s), 5))
    targets = [np.sin(2 * X[:, 0]) + 0.3 * X[:, 6] + 0.1 * rng.standard_normal(s),
               np.abs(X[:, 1]) * X[:, 2]]
    U.FOLD_BINS.clear()
    hgb = U.binned_hgb_class()
    with threadpool_limits(limits=1, user_api="openmp"):   # as the stage fits (OpenMP threads spin on a busy machine)
        for y in targets:
            for tr, te in folds:
                ours = hgb(random_state=0, **U.HGB_PARAMS).fit(X[tr], y[tr])
                ref = HistGradientBoostingRegressor(random_state=0, **U.HGB_PARAMS).fit(X[tr], y[tr])
                np.testing.assert_array_equal(ours.predict(X[te]), ref.predict(X[te]))
                np.testing.assert_array_equal(ours.predict(X[tr]), ref.predict(X[tr]))
    # one binning per fold's rows, whatever the number of targets
    assert len(U.FOLD_BINS) == len(folds)


def _structured(s: int, seed: int):
    """Signals and a residual of three joints: two with structure of different strength, one of coloured noise."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 12.0, s)
    X = np.column_stack([np.sin(0.7 * t + rng.uniform(0, 6, 4)[:, None]).T, rng.standard_normal((s, 2)), t])
    names = tuple(f"x{c}" for c in range(X.shape[1] - 1)) + ("t",)
    noise = np.convolve(rng.standard_normal(s + 9), np.ones(10) / 10, mode="valid")
    E = np.column_stack([np.sin(3 * X[:, 0]) + 0.3 * rng.standard_normal(s),
                         0.5 * np.sin(2 * X[:, 1]) + 0.3 * rng.standard_normal(s),
                         noise])
    return E, X, names


def _plain_search(resid, A, joint, experiment, index, X, names, seed, **kw):
    """The carrier search of ``unexplained_by_joint`` with every test complete (every round tests every joint
    outside the carriers with all its null fits), as it was before the rounds stopped their fits early."""
    n = int(joint.max()) + 1
    carriers: list[int] = []
    found = {}
    while True:
        E, e_exp, e_idx = U.rows_to_samples(U.refit_without(resid, A, joint, carriers), joint, experiment, index)
        others = [j for j in range(n) if j not in carriers]
        res = U.unexplained_structure(E, X, names, experiment=e_exp, order=e_idx, seed=seed, joints=others,
                                      signals=False, **kw)
        found.update({u.joint - 1: u for u in res})
        new = [u for u in res if u.flagged]
        if not new or len(others) == 1:
            if new:
                found.update({u.joint - 1: u for u in U.unexplained_structure(
                    E, X, names, experiment=e_exp, order=e_idx, seed=seed, joints=[u.joint - 1 for u in new], **kw)})
            break
        carriers.append(max(new, key=lambda u: u.share).joint - 1)
    if carriers:
        found.update({u.joint - 1: u for u in U.unexplained_structure(E, X, names, experiment=e_exp, order=e_idx,
                                                                       seed=seed, joints=carriers, **kw)})
    return [found[j] for j in range(n)], tuple(sorted(carriers))


@pytest.mark.parametrize("null_margin", [pytest.param(U.NULL_MARGIN, marks=pytest.mark.slow), 0.57])
def test_greedy_rounds_decide_and_report_as_the_complete_search(null_margin):
    """The rounds that stop their fits once the decision is settled give the complete search's carriers and
    every reported number, bit for bit. With the default margin both structured joints are carriers; a margin
    of 0.57 keeps the stronger one and leaves the other unflagged with a share above ``MIN_SHARE`` (the round
    that reports it completes the null fits it had stopped)."""
    s, n, p = 300, 3, 4
    E, X, names = _structured(s, 7)
    rng = np.random.default_rng(8)
    joint, index = np.repeat(np.arange(n), s), np.tile(np.arange(s), n)
    A = rng.standard_normal((n * s, p))
    y = E.T.reshape(-1) + A @ rng.standard_normal(p)
    resid = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
    args = (resid, A, joint, np.zeros(n * s, int), index, X, names)
    fast = U.unexplained_by_joint(*args, seed=2, null_margin=null_margin, n_null=2)
    assert fast == _plain_search(*args, seed=2, null_margin=null_margin, n_null=2)
    if null_margin == U.NULL_MARGIN:
        assert fast[1] == (0, 1)
    else:
        assert fast[1] == (0,) and not fast[0][1].flagged and fast[0][1].share > U.MIN_SHARE


def test_fold_bound_only_falls_to_the_complete_share():
    E, X, _ = _structured(300, 3)
    folds = blocked_folds(time_blocks(np.zeros(300, int), np.arange(300), 5))
    f = U.FoldFits(X, E[:, 0], folds, 0)
    bounds = []
    with threadpool_limits(limits=1, user_api="openmp"):
        while not f.done:
            f.step()
            bounds.append(f.bound())
        pred = np.empty(300)   # scikit-learn's own fits, fold by fold
        for tr, te in folds:
            pred[te] = HistGradientBoostingRegressor(random_state=0, **U.HGB_PARAMS).fit(X[tr], E[tr, 0]).predict(X[te])
    np.testing.assert_array_equal(f.pred, pred)
    assert np.all(np.diff(bounds) <= 0)
    assert bounds[-1] == pytest.approx(1 - np.sum((E[:, 0] - pred) ** 2) / np.sum((E[:, 0] - E[:, 0].mean()) ** 2))


def test_stacked_permutation_importance_is_the_column_by_column_loop():
    """The importances from one stacked prediction per fold equal, bit for bit, the loop that permutes one column
    of one fold's held-out rows at a time and predicts it (the same draws, in the same order)."""
    rng = np.random.default_rng(5)
    s = 500
    X = np.column_stack([rng.standard_normal((s, 5)), np.linspace(0.0, 5.0, s)])
    e = np.sin(2 * X[:, 0]) * X[:, 1] + 0.2 * X[:, 5] + 0.1 * rng.standard_normal(s)
    folds = blocked_folds(time_blocks(np.zeros(s, int), np.arange(s), 5))
    U.binned_hgb_class()                  # scikit-learn loaded before the one-thread limit
    with threadpool_limits(limits=1, user_api="openmp"):
        fits = U.FoldFits(X, e, folds, 0).finish()
    models = fits.models

    def r2(p):
        return 1.0 - float(np.sum((e - p) ** 2)) / float(np.sum((e - e.mean()) ** 2))

    base = r2(fits.pred)
    got = U.permutation_importance(X, e, folds, models, base, np.random.default_rng([0, 2]))
    ref = np.zeros(X.shape[1])
    draws = np.random.default_rng([0, 2])
    with threadpool_limits(limits=1, user_api="openmp"):
        for c in range(X.shape[1]):
            p2 = np.empty_like(e)
            for (_tr, te), m in zip(folds, models):
                Xt = X[te].copy()
                Xt[:, c] = draws.permutation(Xt[:, c])
                p2[te] = m.predict(Xt)
            ref[c] = max(base - r2(p2), 0.0)
    np.testing.assert_array_equal(got, ref)
    assert ref[0] > 0.1 and ref[1] > 0.01      # the signals the residual depends on matter
