"""Streaming (TSQR accumulation of per-joint R factors) gives the full-matrix results."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from symoro_gen.errors import IdentificationError
from symoro_gen.identification import (
    Accumulator,
    ObservationSystem,
    accumulate,
    essential_parameters,
    fit_ols,
    fit_tls,
    fit_wls,
)

from .simdata import joint_noise
from .test_estimators import tls_reference

REL = 1e-10


def chunks_of(system: ObservationSystem, rng, n_chunks: int):
    """Shuffled rows (joints interleaved) cut into chunks of random sizes, as a generator."""
    perm = rng.permutation(system.Y.size)
    cuts = np.sort(rng.choice(np.arange(1, system.Y.size), n_chunks - 1, replace=False))
    for idx in np.split(perm, cuts):
        yield ObservationSystem(system.W[idx], system.Y[idx], system.names, system.joint[idx])


def close(a, b, label):
    a, b = np.asarray(a, float), np.asarray(b, float)
    finite = np.isfinite(b)
    assert np.array_equal(np.isfinite(a), finite), label
    scale = np.abs(b[finite]).max() if finite.any() else 1.0
    np.testing.assert_allclose(a[finite], b[finite], rtol=REL, atol=REL * scale, err_msg=label)


def close_relative_std(ra, rf):
    """``rel_std_pct = 100 std / |value|`` (eq. 21) within the tolerance the values' own comparison carries over: a
    value near 0 is equal only to ``REL * max|value|`` absolute, so its relative std only to that share of it
    (a parameter at 5e5 % moved 2e-9 relative with the summation order)."""
    a, b = np.asarray(ra.rel_std_pct, float), np.asarray(rf.rel_std_pct, float)
    finite = np.isfinite(b)
    assert np.array_equal(np.isfinite(a), finite), "rel_std_pct"
    v = np.abs(np.asarray(rf.values, float))
    tol = b[finite] * REL * (2.0 + v.max() / v[finite])
    assert np.all(np.abs(a[finite] - b[finite]) <= tol), ("rel_std_pct", a, b)


def same_result(ra, rf):
    assert ra.names == rf.names and ra.method == rf.method and ra.n_rows == rf.n_rows
    for f in ("values", "std", "cov", "rel_err"):
        close(getattr(ra, f), getattr(rf, f), f)
    close_relative_std(ra, rf)
    for f in ("sigma", "cond", "cond_scaled"):
        close(getattr(ra, f), getattr(rf, f), f)
    if rf.joint_sigma is not None:
        close(ra.joint_sigma, rf.joint_sigma, "joint_sigma")
    assert ra.residual is None and rf.residual is not None


@pytest.fixture(scope="module")
def robot_system(rx90_sim):
    rng = np.random.default_rng(21)
    sim = rx90_sim
    return sim.unloaded(sim.tau_a + joint_noise(rng, sim.tau_a, sim.joint_a, 0.02))


@pytest.mark.parametrize("fit", [fit_ols, fit_wls, fit_tls, lambda d: fit_tls(d, weighting="joint")],
                         ids=["ols", "wls", "tls", "tls-w"])
def test_accumulated_equals_full(robot_system, fit):
    acc = accumulate(chunks_of(robot_system, np.random.default_rng(1), 17))
    assert acc.n_rows == robot_system.Y.size
    same_result(fit(acc), fit(robot_system))


def test_accumulated_tls_equals_literal_full_svd(robot_system):
    acc = accumulate(chunks_of(robot_system, np.random.default_rng(2), 9))
    x, sw, C = tls_reference(robot_system.W, robot_system.Y)      # SVD of the whole r x c matrix
    res = fit_tls(acc)
    np.testing.assert_allclose(res.values, x, rtol=1e-8, atol=1e-10 * np.abs(x).max())
    np.testing.assert_allclose(res.sigma, sw, rtol=1e-9)
    np.testing.assert_allclose(res.cov, C, rtol=1e-6, atol=1e-10 * np.abs(C).max())


def test_accumulated_ols_equals_lstsq_on_full_matrix(robot_system):
    acc = accumulate(chunks_of(robot_system, np.random.default_rng(3), 5))
    x = np.linalg.lstsq(robot_system.W, robot_system.Y, rcond=None)[0]
    np.testing.assert_allclose(fit_ols(acc).values, x, rtol=1e-9, atol=1e-11 * np.abs(x).max())


@pytest.mark.parametrize("method", ["ols", "tls"])
def test_accumulated_essential_equals_full(robot_system, method):
    acc = accumulate(chunks_of(robot_system, np.random.default_rng(4), 6))
    ea, ef = essential_parameters(acc, method=method), essential_parameters(robot_system, method=method)
    assert ea.removed == ef.removed and len(ea.removed) > 0
    same_result(ea.result, ef.result)


def test_accumulator_is_an_immutable_value():
    rng = np.random.default_rng(5)
    W = rng.normal(size=(60, 3))
    s = ObservationSystem(W, W @ [1.0, 2.0, 3.0] + 0.1 * rng.normal(size=60), ("a", "b", "c"),
                          np.repeat([0, 1], 30))
    a0 = Accumulator.empty(s.names)
    a1 = a0.add(s)
    assert a0.n_rows == 0 and a0.n_joints == 0 and a1.n_rows == 60 and a1.n_joints == 2
    with pytest.raises(ValueError):
        a1.R[0][0, 0] = 1.0
    # Y'Y per joint kept exactly
    np.testing.assert_allclose(a1.yy, [s.Y[:30] @ s.Y[:30], s.Y[30:] @ s.Y[30:]], rtol=1e-13)
    # joints can appear in later chunks
    s2 = ObservationSystem(W[:10], s.Y[:10], s.names, np.full(10, 3))
    a2 = a1.add(s2)
    assert a2.n_joints == 4 and a2.rows == (30, 30, 0, 10)
    assert np.isnan(fit_ols(a2).rel_err[2])


def test_accumulator_errors():
    rng = np.random.default_rng(6)
    s = ObservationSystem(rng.normal(size=(20, 2)), rng.normal(size=20), ("a", "b"), np.zeros(20, int))
    other = ObservationSystem(s.W, s.Y, ("a", "c"), s.joint)
    with pytest.raises(IdentificationError, match=r"chunk columns differ.*\['c', 'b'\]"):
        accumulate([s, other])
    with pytest.raises(IdentificationError, match="same names, different order"):
        accumulate([s, ObservationSystem(s.W, s.Y, ("b", "a"), s.joint)])
    weighted = ObservationSystem(s.W, s.Y, s.names, s.joint, np.ones(20))
    with pytest.raises(IdentificationError, match="row weights but the accumulator is unweighted"):
        accumulate([weighted])
    with pytest.raises(IdentificationError, match="no chunks"):
        accumulate([])
    bad = ObservationSystem(np.where(np.arange(20)[:, None] == 4, np.nan, s.W), s.Y, s.names, s.joint)
    with pytest.raises(IdentificationError, match="chunk: column 'a' of W has 1 non-finite"):
        accumulate([s, bad])


def test_weighted_accumulator_applies_chunk_weights():
    rng = np.random.default_rng(7)
    W = rng.normal(size=(80, 3))
    w = rng.uniform(0.5, 2.0, 80)
    s = ObservationSystem(W, W @ [1.0, -2.0, 0.5] + rng.normal(size=80) / w, ("a", "b", "c"),
                          np.repeat([0, 1], 40), w)
    acc = accumulate([s], weighted=True)
    ref = np.linalg.lstsq(W * w[:, None], s.Y * w, rcond=None)[0]
    np.testing.assert_allclose(fit_ols(acc).values, ref, rtol=1e-11)
    np.testing.assert_allclose(fit_ols(acc).values, fit_ols(s).values, rtol=1e-11)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_joints=st.integers(1, 4), c=st.integers(1, 8),
       n_chunks=st.integers(1, 6), zero_frac=st.floats(0.0, 0.7))
def test_property_streaming_equals_full(seed, n_joints, c, n_chunks, zero_frac):
    """Random sizes, random per-joint sparsity of the columns (as a serial robot's regressor),
    random chunking: OLS, WLS and TLS on the accumulator equal those on the whole system."""
    rng = np.random.default_rng(seed)
    r = 40 * n_joints + 10 * c
    joint = rng.integers(0, n_joints, r)
    joint[:n_joints] = np.arange(n_joints)
    W = rng.normal(size=(r, c)) * rng.uniform(0.01, 100.0, c)
    mask = rng.random((n_joints, c)) < zero_frac                       # column k absent from joint j
    mask[0] = False                                                    # every column excited somewhere
    W[mask[joint]] = 0.0
    Y = W @ rng.normal(size=c) + rng.normal(size=r)
    s = ObservationSystem(W, Y, tuple(f"p{i}" for i in range(c)), joint)
    acc = accumulate(chunks_of(s, rng, min(n_chunks, r - 1)))
    for fit in (fit_ols, fit_wls, fit_tls):
        same_result(fit(acc), fit(s))
    ref = np.linalg.lstsq(W, Y, rcond=None)[0]                         # independent of the TSQR path
    res = fit_ols(acc)
    assert np.all(np.abs(res.values - ref) <= 1e-8 * (np.abs(ref) + res.std))
