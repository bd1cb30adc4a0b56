"""The unexplained stage's shortcuts give the results of the plain computation.

* :func:`symoro_gen.diagnostics.unexplained.binned_hgb_class` bins equal training rows once: its trees must
  predict exactly what scikit-learn's own ``HistGradientBoostingRegressor`` predicts (same settings, same
  seed), for several targets fitted on the same rows (the cache's hits) and on other rows (its misses).
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
