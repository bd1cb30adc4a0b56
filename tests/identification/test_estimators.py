"""OLS / WLS / TLS: agreement with literal implementations of the papers' equations, statistical
coverage on simulated data with known truth, errors-in-variables behaviour, warnings and errors."""
import numpy as np
import pytest

from symoro_gen.errors import IdentificationError
from symoro_gen.identification import ObservationSystem, fit_ols, fit_tls, fit_wls, identify

from .simdata import joint_noise

N_SEEDS = 150


def random_system(rng, r_per_joint=100, n_joints=3, c=6, sigmas=(0.2, 0.2, 0.2), x=None, w_noise=0.0):
    """Well-conditioned random W (r, c), rows grouped per joint; returns system, truth, W_true."""
    r = r_per_joint * n_joints
    W = rng.normal(size=(r, c))
    x = rng.uniform(1.0, 4.0, c) * rng.choice([-1, 1], c) if x is None else np.asarray(x, float)
    joint = np.repeat(np.arange(n_joints), r_per_joint)
    sig = np.asarray(sigmas)[joint]
    Y = W @ x + sig * rng.normal(size=r)
    Wobs = W + w_noise * sig[:, None] * rng.normal(size=W.shape) if w_noise else W
    return ObservationSystem(Wobs, Y, tuple(f"p{i + 1}" for i in range(c)), joint), x, W


def coverage_ok(z, label):
    z = np.abs(np.concatenate(z))
    in1, in3 = np.mean(z < 1), np.mean(z < 3)
    # N(0,1): P(|z|<1) = 0.683, P(|z|<3) = 0.9973; bounds are ~3 standard errors for ~900 draws
    assert 0.63 < in1 < 0.74, f"{label}: {in1:.3f} of the errors within 1 sigma (expected 0.683)"
    assert in3 > 0.985, f"{label}: {in3:.4f} of the errors within 3 sigma (expected 0.997)"


# ---------------------------------------------------------------- literal references
def test_ols_matches_literal_equations():
    rng = np.random.default_rng(0)
    s, x, _ = random_system(rng)
    res = fit_ols(s)
    W, Y = s.W, s.Y
    xh = np.linalg.pinv(W) @ Y                                       # eq. 17
    r, c = W.shape
    sig2 = np.sum((Y - W @ xh) ** 2) / (r - c)                        # eq. 19
    C = sig2 * np.linalg.inv(W.T @ W)                                 # eq. 20
    np.testing.assert_allclose(res.values, xh, rtol=1e-12)
    np.testing.assert_allclose(res.sigma, np.sqrt(sig2), rtol=1e-12)
    np.testing.assert_allclose(res.cov, C, rtol=1e-10)
    np.testing.assert_allclose(res.rel_std_pct, 100 * np.sqrt(np.diag(C)) / np.abs(xh), rtol=1e-10)  # eq. 21
    np.testing.assert_allclose(res.cond, np.linalg.cond(W), rtol=1e-10)
    np.testing.assert_allclose(res.residual, Y - W @ xh, atol=1e-12)
    for j in range(3):
        m = s.joint == j
        np.testing.assert_allclose(res.rel_err[j], np.linalg.norm((Y - W @ xh)[m]) / np.linalg.norm(Y[m]), rtol=1e-10)


def test_wls_matches_literal_equations():
    rng = np.random.default_rng(1)
    s, x, _ = random_system(rng, sigmas=(0.05, 0.5, 2.0))
    res = fit_wls(s)
    W, Y = s.W, s.Y
    sig = np.zeros(3)
    for j in range(3):                                                # eq. 22: OLS of joint j alone
        m = s.joint == j
        xj = np.linalg.lstsq(W[m], Y[m], rcond=None)[0]
        sig[j] = np.sqrt(np.sum((Y[m] - W[m] @ xj) ** 2) / (m.sum() - W.shape[1]))
    w = 1 / sig[s.joint]
    Ww, Yw = W * w[:, None], Y * w
    xh = np.linalg.lstsq(Ww, Yw, rcond=None)[0]
    s2 = np.sum((Yw - Ww @ xh) ** 2) / (W.shape[0] - W.shape[1])
    np.testing.assert_allclose(res.joint_sigma, sig, rtol=1e-10)
    np.testing.assert_allclose(res.values, xh, rtol=1e-11)
    np.testing.assert_allclose(res.cov, s2 * np.linalg.inv(Ww.T @ Ww), rtol=1e-9)
    np.testing.assert_allclose(res.residual, Y - W @ xh, atol=1e-12)   # unweighted residual


def tls_reference(A, b):
    """LWR4 paper eq. 10-16, literally, on the full matrix."""
    Wtot = np.column_stack([A, -b])
    r, c = Wtot.shape
    U, s, Vt = np.linalg.svd(Wtot, full_matrices=False)                 # eq. 12
    V = Vt.T
    What = Wtot - s[-1] * np.outer(U[:, -1], V[:, -1])                  # eq. 13
    xtot = V[:, -1] / V[-1, -1]                                        # normalised: last coefficient 1
    x = xtot[:-1]
    sw = s[-1] / np.sqrt(r - c)                                        # eq. 15
    C = sw ** 2 * (1 + x @ x) * np.linalg.inv(What[:, :-1].T @ What[:, :-1])   # eq. 16
    return x, sw, C


@pytest.mark.parametrize("w_noise", [0.0, 1.0])
def test_tls_matches_literal_equations(w_noise):
    rng = np.random.default_rng(2)
    s, x, _ = random_system(rng, w_noise=w_noise)
    res = fit_tls(s)
    xr, sw, C = tls_reference(s.W, s.Y)
    np.testing.assert_allclose(res.values, xr, rtol=1e-10)
    np.testing.assert_allclose(res.sigma, sw, rtol=1e-10)
    np.testing.assert_allclose(res.cov, C, rtol=1e-8)
    assert res.method == "TLS"


def test_tls_joint_weighting_is_tls_of_weighted_rows():
    rng = np.random.default_rng(3)
    s, x, _ = random_system(rng, sigmas=(0.02, 0.05, 0.2), w_noise=1.0)
    res = fit_tls(s, weighting="joint")
    assert res.method == "TLS-W"
    # the stated weights reproduce the estimate through the literal TLS
    w = 1 / res.joint_sigma[s.joint]
    xr, sw, C = tls_reference(s.W * w[:, None], s.Y * w)
    np.testing.assert_allclose(res.values, xr, rtol=1e-10)
    np.testing.assert_allclose(res.cov, C, rtol=1e-8)
    # and they follow the per-joint noise levels (ratio of true sigmas 1 : 2.5 : 10)
    ratio = res.joint_sigma / res.joint_sigma[0]
    np.testing.assert_allclose(ratio, [1, 2.5, 10], rtol=0.25)


# ---------------------------------------------------------------- statistics with known truth
def test_ols_coverage_over_seeds():
    z = []
    for seed in range(N_SEEDS):
        s, x, _ = random_system(np.random.default_rng(1000 + seed))
        res = fit_ols(s)
        z.append((res.values - x) / res.std)
    coverage_ok(z, "OLS")


def test_wls_coverage_and_efficiency_over_seeds():
    z, e_wls, e_ols = [], [], []
    for seed in range(N_SEEDS):
        s, x, _ = random_system(np.random.default_rng(2000 + seed), sigmas=(0.05, 0.5, 2.0))
        res = fit_wls(s)
        z.append((res.values - x) / res.std)
        e_wls.append(np.sum((res.values - x) ** 2))
        e_ols.append(np.sum((fit_ols(s).values - x) ** 2))
    coverage_ok(z, "WLS")
    # weighting by 1/sigma_j helps a lot when the joints' noise levels differ
    assert np.mean(e_wls) < 0.3 * np.mean(e_ols)


def test_tls_coverage_and_lower_bias_than_ols_with_noisy_regressor():
    """Errors in variables: W observed with noise of the same level as Y. OLS is biased towards 0
    (attenuation), TLS is consistent and its eq. 16 standard deviations cover the truth."""
    z, rel_ols, rel_tls = [], [], []
    for seed in range(N_SEEDS):
        s, x, _ = random_system(np.random.default_rng(3000 + seed), r_per_joint=200, sigmas=(0.3,) * 3,
                                w_noise=1.0)
        t, o = fit_tls(s), fit_ols(s)
        z.append((t.values - x) / t.std)
        rel_tls.append((t.values - x) / x)
        rel_ols.append((o.values - x) / x)
    coverage_ok(z, "TLS")
    bias_ols = np.mean(rel_ols)            # expected about -0.3^2 / (1 + 0.3^2) = -8 %
    bias_tls = np.mean(rel_tls)
    se = np.std(np.concatenate(rel_tls)) / np.sqrt(np.size(rel_tls))
    assert bias_ols < -0.05, bias_ols
    assert abs(bias_tls) < 4 * se and abs(bias_tls) < 0.1 * abs(bias_ols), (bias_tls, bias_ols)


@pytest.mark.parametrize("method", ["ols", "wls", "tls"])
def test_robot_base_parameters_recovered_within_3_sigma(rx90_sim, method):
    """RX-90 base regressor (numeric Newton-Euler, base columns by pivoted QR); noise seeds vary on
    a fixed W. Each estimator gets the noise its statistics assume: OLS one sigma for all rows
    (eq. 18; 2 % of the torque RMS), WLS per-joint sigmas (2 % of each joint's torque RMS), TLS
    i.i.d. errors on every entry of W and Y (eq. 14)."""
    sim = rx90_sim
    z = []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        W = sim.Wa
        if method == "wls":
            noise = joint_noise(rng, sim.tau_a, sim.joint_a, 0.02)
        elif method == "ols":
            noise = 0.02 * np.sqrt(np.mean(sim.tau_a ** 2)) * rng.normal(size=sim.tau_a.shape)
        else:
            noise = 0.1 * rng.normal(size=sim.tau_a.shape)
            W = W + 0.1 * rng.normal(size=W.shape)
        res = identify(ObservationSystem(W, sim.tau_a + noise, sim.names, sim.joint_a), method=method)
        z.append((res.values - sim.chi_base) / res.std)
    z = np.abs(np.concatenate(z))
    assert np.mean(z < 3) > 0.98, f"{method}: {np.mean(z < 3):.3f} within 3 sigma"
    assert 0.6 < np.mean(z < 1) < 0.77, f"{method}: {np.mean(z < 1):.3f} within 1 sigma"


def test_robot_tls_beats_ols_with_noisy_regressor(rx90_sim):
    """Same errors-in-variables data: OLS estimates miss their own 3-sigma bands far more often."""
    sim = rx90_sim
    err_t, err_o, z_o = [], [], []
    for seed in range(6):
        rng = np.random.default_rng(50 + seed)
        s = ObservationSystem(sim.Wa + 0.15 * rng.normal(size=sim.Wa.shape),
                              sim.tau_a + 0.15 * rng.normal(size=sim.tau_a.shape), sim.names, sim.joint_a)
        t, o = fit_tls(s), fit_ols(s)
        err_t.append(np.abs(t.values - sim.chi_base) / np.abs(sim.chi_base))
        err_o.append(np.abs(o.values - sim.chi_base) / np.abs(sim.chi_base))
        z_o.append((o.values - sim.chi_base) / o.std)
    assert np.median(np.concatenate(err_t)) < 0.8 * np.median(np.concatenate(err_o))
    assert np.mean(np.abs(np.concatenate(z_o)) < 3) < 0.95


def test_ols_statistics_are_wrong_under_heteroscedastic_noise_and_wls_fixes_them(rx90_sim):
    """Why eq. 22 exists: with per-joint noise levels, OLS's single sigma_rho misstates the std."""
    sim = rx90_sim
    z_ols, z_wls = [], []
    for seed in range(6):
        rng = np.random.default_rng(100 + seed)
        s = sim.unloaded(sim.tau_a + joint_noise(rng, sim.tau_a, sim.joint_a, 0.02))
        for fit, z in ((fit_ols, z_ols), (fit_wls, z_wls)):
            res = fit(s)
            z.append((res.values - sim.chi_base) / res.std)
    assert np.mean(np.abs(np.concatenate(z_ols)) < 3) < 0.98
    assert np.mean(np.abs(np.concatenate(z_wls)) < 3) > 0.98


# ---------------------------------------------------------------- warnings
def test_rank_deficient_w_warns_names_the_parameters_and_still_solves():
    rng = np.random.default_rng(4)
    s, x, W = random_system(rng, c=5)
    Wd = np.column_stack([s.W, s.W[:, 1] - 2 * s.W[:, 3]])           # p6 = p2 - 2 p4
    sd = ObservationSystem(Wd, s.Y, s.names + ("p6",), s.joint)
    res = fit_ols(sd)
    msg = [w for w in res.warnings if "rank-deficient" in w]
    assert len(msg) == 1 and all(p in msg[0] for p in ("p2", "p4", "p6")), res.warnings
    assert "p1 " not in msg[0] and "p3 " not in msg[0]
    assert np.isinf(res.std[[1, 3, 5]]).all() and np.isfinite(res.std[[0, 2, 4]]).all()
    np.testing.assert_allclose(res.values[[0, 2, 4]], x[[0, 2, 4]], atol=5 * res.std[[0, 2, 4]].max())
    np.testing.assert_allclose(Wd @ res.values, s.W @ fit_ols(s).values, atol=1e-9)   # same fit
    assert "Warnings:" in res.summary() and "[1]" in res.summary()


def test_ill_conditioned_w_warns_with_the_weak_direction():
    rng = np.random.default_rng(5)
    s, x, _ = random_system(rng, c=4)
    Wi = s.W.copy()
    Wi[:, 3] = Wi[:, 0] + Wi[:, 1] + 1e-4 * rng.normal(size=s.Y.size)
    res = fit_ols(ObservationSystem(Wi, s.Y, s.names, s.joint))
    msg = [w for w in res.warnings if "ill-conditioned" in w]
    assert msg and all(p in msg[0] for p in ("p1", "p2", "p4")) and "p3" not in msg[0], res.warnings
    assert res.cond_scaled > 1e3
    assert not [w for w in fit_ols(s).warnings if "conditioned" in w]


def test_poorly_identified_parameter_is_reported():
    rng = np.random.default_rng(6)
    s, x, _ = random_system(rng, x=[2.0, -3.0, 1e-3, 4.0, 1.5, -2.5])
    res = fit_ols(s)
    msg = [w for w in res.warnings if "poorly identified" in w]
    assert len(msg) == 1 and "p3" in msg[0] and "p1 " not in msg[0]


# ---------------------------------------------------------------- errors
def test_mismatched_shapes_are_clear_errors():
    W = np.ones((10, 3))
    with pytest.raises(IdentificationError, match=r"W \(10, 3\) and Y \(9,\) do not match"):
        ObservationSystem(W, np.ones(9), ("a", "b", "c"), np.zeros(10, int))
    with pytest.raises(IdentificationError, match="2 names for 3 columns"):
        ObservationSystem(W, np.ones(10), ("a", "b"), np.zeros(10, int))
    with pytest.raises(IdentificationError, match="joint has 9 entries for 10 rows"):
        ObservationSystem(W, np.ones(10), ("a", "b", "c"), np.zeros(9, int))
    with pytest.raises(IdentificationError, match="duplicate column names"):
        ObservationSystem(W, np.ones(10), ("a", "b", "a"), np.zeros(10, int))
    with pytest.raises(ValueError):      # still a ValueError, as before
        ObservationSystem(W, np.ones(9), ("a", "b", "c"), np.zeros(10, int))


def test_too_few_rows():
    rng = np.random.default_rng(7)
    s = ObservationSystem(rng.normal(size=(4, 4)), rng.normal(size=4), ("a", "b", "c", "d"), np.zeros(4, int))
    with pytest.raises(IdentificationError, match="too few equations: 4 rows for 4 parameters"):
        fit_ols(s)
    s5 = ObservationSystem(rng.normal(size=(5, 4)), rng.normal(size=5), ("a", "b", "c", "d"), np.zeros(5, int))
    fit_ols(s5)
    with pytest.raises(IdentificationError, match="too few equations"):
        fit_tls(s5)                        # TLS needs r > c + 1 (sigma_W = s_c / sqrt(r - c))


def test_all_zero_column_is_named():
    rng = np.random.default_rng(8)
    s, _, _ = random_system(rng, c=3)
    W = s.W.copy()
    W[:, 1] = 0.0
    bad = ObservationSystem(W, s.Y, ("XX1", "ZZ2", "MX3"), s.joint)
    for fit in (fit_ols, fit_wls, fit_tls):
        with pytest.raises(IdentificationError, match=r"column\(s\) \['ZZ2'\] of W are all zero"):
            fit(bad)


def test_non_finite_data_names_column_and_rows():
    rng = np.random.default_rng(9)
    s, _, _ = random_system(rng, c=3)
    W = s.W.copy()
    W[150:153, 2] = np.nan
    with pytest.raises(IdentificationError, match=r"column 'p3' of W has 3 non-finite value\(s\), rows 150-152 \(joint 2\)"):
        fit_ols(ObservationSystem(W, s.Y, s.names, s.joint))
    Y = s.Y.copy()
    Y[7] = np.inf
    with pytest.raises(IdentificationError, match=r"Y has 1 non-finite value\(s\), rows 7-7 \(joint 1\)"):
        fit_wls(ObservationSystem(s.W, Y, s.names, s.joint))


def test_unknown_method_and_bad_input_type():
    rng = np.random.default_rng(10)
    s, _, _ = random_system(rng, c=3)
    with pytest.raises(IdentificationError, match="unknown identification method 'gls'"):
        identify(s, method="gls")
    with pytest.raises(IdentificationError, match="unknown TLS weighting"):
        fit_tls(s, weighting="columns")
    with pytest.raises(IdentificationError, match="expected an ObservationSystem or an Accumulator"):
        fit_ols(np.ones((5, 2)))


def test_given_row_weights_are_applied_by_ols_and_ignored_by_wls():
    rng = np.random.default_rng(11)
    s, x, _ = random_system(rng, sigmas=(0.05, 0.5, 2.0))
    w = 1 / np.array([0.05, 0.5, 2.0])[s.joint]
    sw = ObservationSystem(s.W, s.Y, s.names, s.joint, w)
    ref = np.linalg.lstsq(s.W * w[:, None], s.Y * w, rcond=None)[0]
    np.testing.assert_allclose(fit_ols(sw).values, ref, rtol=1e-11)
    np.testing.assert_allclose(fit_wls(sw).values, fit_wls(s).values, rtol=1e-12)


def test_tls_warns_when_its_error_model_does_not_hold():
    """Noise in Y only and a weak direction in W (p4 ~ p1) with a singular value of the order of
    the noise: TLS 'corrects' W along it, its parameters run away and its residual is several times
    the LS one (what plain TLS does on the real LWR4 recordings); the result says so."""
    rng = np.random.default_rng(12)
    s, x, _ = random_system(rng, c=4, sigmas=(1.0,) * 3)
    W = s.W.copy()
    W[:, 3] = W[:, 0] + 0.1 * rng.normal(size=s.Y.size)
    bad = ObservationSystem(W, W @ x + rng.normal(size=s.Y.size), s.names, s.joint)
    t = fit_tls(bad)
    assert any("TLS residual is" in w for w in t.warnings), t.warnings
    assert abs(t.values[0] - x[0]) > 10 * abs(fit_ols(bad).values[0] - x[0])
    assert not any("TLS residual is" in w for w in fit_tls(s).warnings)
