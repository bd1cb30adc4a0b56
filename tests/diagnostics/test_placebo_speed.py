"""The friction-law stage's shortcuts give what the long way gives: the out-of-fold residual computed on
the reported rows only, from fold supports kept per support, equals the straightforward rank-revealing solve
(and an independent refit of each fold); the simulated-noise placebo of a law selection, run with every
factor and column kept between its replicates, equals the one run with nothing kept."""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen.diagnostics import friction, stability
from tests.diagnostics.simdata import friction_selection_case, joint_design_case


def _joint_design(seed: int, n: int = 4, s: int = 250, k: int = 12):
    return joint_design_case(seed, n, s, k)


@pytest.mark.parametrize("seed", [0, 1])
def test_oof_residual_on_reported_rows_equals_the_straightforward_solve(seed):
    """``oof_residual(X, rows)`` against ``oof_residual_direct(X)[rows]`` and a refit of each fold, for
    columns on one joint's rows with some zero rows (a joint at rest), on all rows, nearly collinear ones
    (the rank-revealing path), reported rows of one joint and scattered ones, kept supports on a new y."""
    rng, joint, A, w, blocks = _joint_design(seed)
    r, s = joint.size, int(np.sum(joint == 0))
    one = np.zeros((r, 2))
    one[joint == 1] = rng.standard_normal((s, 2))
    one[np.flatnonzero(joint == 1)[40:90]] = 0.0          # rest: not in the support
    dense = rng.standard_normal((r, 3))
    z = rng.standard_normal(s)
    collinear = np.zeros((r, 2))
    collinear[joint == 2] = np.column_stack([z, z + 1e-9 * rng.standard_normal(s)])
    scattered = rng.random(r) < 0.3
    stability._FOLD_CACHE.clear()
    for X in (one, dense, collinear, one, dense):      # the last two: supports and factors kept, new y
        y = A @ rng.standard_normal(A.shape[1]) + X @ rng.standard_normal(X.shape[1]) + rng.standard_normal(r)
        cv = stability.BlockedLS(A, y, blocks, w)
        direct = cv.oof_residual_direct(X)
        ref = np.empty(r)
        M = np.hstack([A, X])
        for tr, te in stability.blocked_folds(blocks):
            th = np.linalg.lstsq(M[tr] * w[tr, None], y[tr] * w[tr], rcond=None)[0]
            ref[te] = y[te] - M[te] @ th
        scale = float(np.max(np.abs(direct)))
        for rows in (joint == 1, joint == 2, scattered, None):
            got = cv.oof_residual(X, rows)
            want = direct if rows is None else direct[rows]
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-10 * scale)
            if X is not collinear:
                np.testing.assert_allclose(got, ref if rows is None else ref[rows], rtol=0, atol=1e-10 * scale)
        # the reported rows do not mix in the cache: all rows after some rows give the full residual
        np.testing.assert_array_equal(cv.oof_residual(X), cv.oof_residual(X, None))


def _friction_case(seed: int = 11):
    J, dq_rows, A, blocks, hook, signal, rng = friction_selection_case(seed)
    return J, dq_rows, A, blocks, hook, signal + 0.05 * rng.standard_normal(signal.size)


def test_noise_placebo_with_kept_factors_equals_one_that_keeps_nothing(monkeypatch):
    """The whole simulated-noise placebo (its replicates re-run the law selection on null data with the same
    columns hook, :func:`.stability.simulated_noise_placebo`) gives the same null gains, to 1e-10, when the law
    columns, fold supports and column factors are kept between replicates as when every replicate starts
    from nothing."""
    J, dq_rows, A, blocks, hook, y = _friction_case()
    search = friction.LawSearch(laws=("tanh", "stribeck", "power"), v_grid=friction.velocity_grid(dq_rows[J == 1], 6))
    Xd = hook(lambda v: np.column_stack([np.sign(v), v]), 2)
    M = np.hstack([A, Xd])
    fitted = M @ np.linalg.lstsq(M, y, rcond=None)[0]

    def gain(yy):
        ch = friction.select_friction(A, yy, J, 1, dq_rows, blocks, columns=hook, search=search)
        return ch.declared_cv_rel_err - ch.cv_rel_err

    def placebo(g):
        return stability.simulated_noise_placebo(g, fitted, y - fitted, J * 100000, np.zeros(J.size, int),
                                                 np.inf, n_rep=4, rng=np.random.default_rng(3))[1]

    def fresh_gain(yy):          # every replicate from nothing: no folds, supports, factors or columns kept
        stability._FOLD_CACHE.clear()
        friction._LAW_COLUMNS.clear()
        return gain(yy)

    stability._FOLD_CACHE.clear()
    friction._LAW_COLUMNS.clear()
    kept = placebo(gain)
    monkeypatch.setattr(friction, "LAW_COLUMNS_BYTES", 0)
    monkeypatch.setattr(stability, "COLUMN_CACHE_BYTES", 0)
    fresh = placebo(fresh_gain)
    assert len(kept) == len(fresh) == 4
    assert all(np.isfinite(kept)) and max(kept) > 0
    np.testing.assert_allclose(kept, fresh, rtol=1e-10, atol=1e-12)
