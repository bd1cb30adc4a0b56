"""The composed library's batched tests (:meth:`symoro_gen.diagnostics.compose._Tester.batch`: the candidates of
one plain design and width stacked, one product with the basis, one Gram and one HAC pass) give what the tests
one at a time give (:meth:`_Tester.__call__`), and those equal an independent refit of the augmented weighted
least squares with the explicit Newey-West sum."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sst

from symoro_gen.diagnostics.compose import (
    IDENTIFIABILITY_TOL,
    MIN_ONE_MINUS_LEVERAGE,
    _Tester,
    library,
    score_composed,
)

from .test_compose import setup


def _random_case(seed, n=3, samples=400, k=7):
    """Joint-major rows of ``n`` joints, two experiments each (the HAC segments), a random design, weights per
    joint and a serially correlated residual."""
    rng = np.random.default_rng(seed)
    joint = np.repeat(np.arange(n), samples)
    experiment = np.tile(np.repeat([0, 1], samples // 2), n)
    r = joint.size
    A = rng.standard_normal((r, k))
    A[:, 0] = 0.0                       # a zero column: the basis has the design's rank, not its width
    w = (1.0 + rng.uniform(0.0, 1.0, n))[joint]
    y = A @ rng.standard_normal(k) + np.convolve(rng.standard_normal(r + 9), np.ones(10) / 10, "valid")
    return rng, A, y, w, joint, joint * 100000 + experiment


def _candidates(rng, joint, j, p, m, P):
    """``m`` candidates of ``p`` columns on the rows of joint ``j``; one of them in the span of the plain effect
    ``P`` (skipped by both paths) when ``m > 2``."""
    rows = joint == j
    out = []
    for i in range(m):
        X = np.zeros((joint.size, p))
        X[rows] = rng.standard_normal((int(rows.sum()), p)) * (1.0 + i)
        out.append(X)
    if m > 2:
        out[1] = P * np.arange(1.0, p + 1.0)
    return out


def _refit(A, y, w, X, groups, joint, j, lag):
    """The straightforward test: the weighted least squares of ``y`` on ``[A, X]`` refitted from scratch, HC3
    scores, the Newey-West covariance summed lag by lag within each segment, the Wald tests."""
    Aw, Xw, yw = A * w[:, None], X * w[:, None], y * w
    D = np.hstack([Aw, Xw])
    Q, s, _ = np.linalg.svd(D, full_matrices=False)
    Q = Q[:, s > 1e-10 * s[0]]
    e = yw - Q @ (Q.T @ yw)
    Qa, sa, _ = np.linalg.svd(Aw, full_matrices=False)
    Qa = Qa[:, sa > 1e-10 * sa[0]]
    Xp = Xw - Qa @ (Qa.T @ Xw)
    b = np.linalg.lstsq(Xp, yw - Qa @ (Qa.T @ yw), rcond=None)[0]
    Ginv = np.linalg.inv(Xp.T @ Xp)
    r, p = y.size, X.shape[1]
    dof = max(r - Q.shape[1], 1)
    e3 = e / np.clip(1.0 - np.einsum("ij,ij->i", Q, Q), MIN_ONE_MINUS_LEVERAGE, 1.0)
    Z = Xp * e3[:, None]
    S = np.zeros((p, p))
    for g in np.unique(groups):
        z = Z[groups == g]
        for k in range(-lag, lag + 1):
            wt = 1.0 - abs(k) / (lag + 1.0)
            a, c = (z[k:], z[:z.shape[0] - k]) if k >= 0 else (z[:k], z[-k:])
            S += wt * a.T @ c
    pv = []
    for C in (Ginv @ S @ Ginv * (r / dof), Ginv * float(e @ e) / dof):
        W = float(b @ np.linalg.solve(C, b))
        pv.append(float(sst.f.sf(W / p, p, dof)))
    rows = joint == j
    e0 = yw - Qa @ (Qa.T @ yw)
    return max(pv), b, 1.0 - float(np.sum(e[rows] ** 2)) / float(np.sum(e0[rows] ** 2))


def _same(got, ref, rtol=1e-10):
    assert (got is None) == (ref is None)
    if ref is None:
        return
    assert got[0] == pytest.approx(ref[0], rel=rtol, abs=1e-300)
    np.testing.assert_allclose(got[1], ref[1], rtol=rtol, atol=0)
    assert got[2] == pytest.approx(ref[2], rel=rtol, abs=1e-12)


@pytest.mark.parametrize("seed,p,m", [(0, 1, 9), (1, 2, 7), (2, 2, 1), (3, 1, 2)])
def test_batched_composed_tests_equal_the_tests_one_at_a_time_and_a_refit(seed, p, m):
    rng, A, y, w, joint, groups = _random_case(seed)
    tester = _Tester(A, y, w, joint, groups)
    j = seed % 3
    P = np.zeros((joint.size, 1))
    P[joint == j, 0] = rng.standard_normal(int((joint == j).sum()))      # a plain effect partialled out
    Xs = _candidates(rng, joint, j, p, m, P)
    base = tester.with_plain(P)
    got = tester.batch(np.hstack(Xs), p, j, base)
    one = [tester(X, j, base=base) for X in Xs]
    assert len(got) == m
    if m > 2:
        assert got[1] is None and one[1] is None     # in the span of the model: skipped
    assert sum(g is not None for g in got) >= m - 1
    for X, g, o in zip(Xs, got, one):
        _same(g, o)
        if o is not None:
            _same(o, _refit(np.hstack([A, P]), y, w, X, groups, joint, j, tester.lag), rtol=1e-8)


def test_nearly_in_span_candidate_is_skipped_by_both_paths():
    """A candidate with less than IDENTIFIABILITY_TOL of its norm outside the model is "already in the model" in
    the batch exactly when it is one at a time, next to candidates that are tested."""
    rng, A, y, w, joint, groups = _random_case(5)
    tester = _Tester(A, y, w, joint, groups)
    rows = joint == 0
    P = np.zeros((joint.size, 1))
    P[rows, 0] = rng.standard_normal(int(rows.sum()))
    X_in = P + 0.1 * IDENTIFIABILITY_TOL * np.where(rows, rng.standard_normal(joint.size), 0.0)[:, None]
    X_out = np.zeros((joint.size, 1))
    X_out[rows, 0] = rng.standard_normal(int(rows.sum()))
    base = tester.with_plain(P)
    got = tester.batch(np.hstack([X_out, X_in, X_out * 2.0]), 1, 0, base)
    assert got[1] is None and tester(X_in, 0, base=base) is None
    _same(got[0], tester(X_out, 0, base=base))
    _same(got[2], tester(X_out * 2.0, 0, base=base))


def test_score_composed_equals_each_member_tested_alone():
    """The whole library scored (grouped, batched) against each member tested one at a time on its own plain
    design: every family's best member, p-value, coefficients and drop."""
    d, sig, y, _ = setup(4, duration=10.0)
    A = d["W"]
    fams = library(sig, joints=[1, 2])
    tester = _Tester(A, y, np.ones(y.size), np.asarray(sig.joint), sig.joint)
    res = score_composed(A, y, sig, families=fams, alpha=0.5)
    assert len(res) > 20
    for r in res:
        c = r.candidate
        fam = next(f for f in fams if c in f)
        best = None
        for m in fam:
            base = tester.with_plain(np.hstack([m.plain_columns(sig), m.confounder_columns(sig)]))
            o = tester(m.columns(sig), m.joint, base=base)
            if o is not None and (best is None or o[0] < best[1][0] or (o[0] == best[1][0] and o[2] > best[1][2])):
                best = (m, o)
        assert best is not None and best[0] == c
        _same((r.p_value, r.coefficients, r.rss_drop), best[1])
