"""IDIM-IV, DIDIM and the closed-loop simulator they rest on.

The truth is known: a SCARA (4 joints) with random physical parameters tracks a Fourier reference under
a digital PD controller (:func:`symoro_gen.simulate.closed_loop.simulate_closed_loop`); the logged
positions carry heavy white noise (5 mrad at 200 Hz), the logged torque a little. The band-pass
derivatives of the noisy positions make the IDIM-OLS observation matrix noisy (errors in variables):
OLS is visibly biased (several sigma) on the parameters of the accelerations, while IDIM-IV and DIDIM,
whose instruments / regressors come from the noise-free closed-loop simulation, are not.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from symoro_gen.errors import IdentificationError
from symoro_gen.identification import identify
from symoro_gen.identification.didim import identify_didim
from symoro_gen.identification.iv import identify_iv, iv_fit
from symoro_gen.loader import model_for
from symoro_gen.observations import AssemblyOptions
from symoro_gen.observations.system import ObservationSystem
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques, write_recording_csv
from symoro_gen.simulate.closed_loop import ForwardDynamics, PIDGains, default_gains, simulate_closed_loop

DT = 0.005
NOISE_Q = 5e-3


@pytest.fixture(scope="module")
def scara():
    robot, model = model_for("scara")
    rng = np.random.default_rng(3)
    chi = np.asarray(random_physical_parameters(robot, rng, fs_range=(0.5, 2.0)))
    return robot, model, chi, model.base_parameters(chi), rng


@pytest.fixture(scope="module")
def experiment(scara):
    """The closed-loop recording: truth, reference, gains, noisy log."""
    robot, model, chi, theta, rng = scara
    mot = fourier_trajectory(4, 10.0, DT, rng, amplitude=1.0, vmax=2.0, amax=10.0, base_frequency_hz=0.2)
    gains = default_gains(model, theta, mot.q, DT)
    run = simulate_closed_loop(model, theta, mot.t, mot.q, mot.dq, gains=gains)
    q_meas = run.q + NOISE_Q * rng.standard_normal(run.q.shape)
    tau_meas = run.tau + 0.005 * np.abs(run.tau).max(0) * rng.standard_normal(run.tau.shape)
    log = Trajectory(t=mot.t, q=q_meas, tau=tau_meas, source="closed-loop", meta={"q_ref": mot.q})
    return dict(theta=theta, mot=mot, gains=gains, run=run, log=log)


@pytest.fixture(scope="module")
def fits(scara, experiment):
    _, model, *_ = scara
    iv = identify_iv(model, experiment["log"], AssemblyOptions(), gains=experiment["gains"])
    didim = identify_didim(model, experiment["log"], AssemblyOptions(), gains=experiment["gains"], jacobian="simulated")
    return iv, didim


# ----------------------------------------------------------------------------- forward dynamics
def test_forward_dynamics_inverts_the_numeric_newton_euler(scara):
    """``M(q) ddq + h(q, dq)`` from the regressor equals the torque of the exact numeric Newton–Euler
    of the robot file (standard parameters; an independent implementation), and ``ddq`` is recovered."""
    robot, model, chi, theta, rng = scara
    fd = ForwardDynamics(model, theta, friction_eps=0.0)
    for _ in range(5):
        q, dq, ddq = rng.uniform(-2, 2, (3, 4))
        M, h = fd.mass_and_bias(q, dq)
        ref = true_torques(robot, q[None], dq[None], ddq[None], chi)[0]
        np.testing.assert_allclose(M @ ddq + h, ref, rtol=1e-9, atol=1e-9)
        assert np.all(np.linalg.eigvalsh(M) > 0)
        np.testing.assert_allclose(fd.acceleration(q, dq, ref), ddq, rtol=1e-8, atol=1e-8)


def test_closed_loop_matches_a_stiff_reference_integrator(scara, experiment):
    """The RK4/ZOH simulation equals scipy's Radau integration of the same held torques (rtol 1e-10),
    its logged torque is the inverse dynamics of its logged states, and the PD tracks the reference."""
    robot, model, chi, theta, _ = scara
    run = experiment["run"]
    fd = ForwardDynamics(model, theta)
    k = 100  # 0.5 s
    x = np.r_[run.q[0], run.dq[0]]
    for i in range(k):
        sol = solve_ivp(lambda _t, s, u=run.tau[i]: np.r_[s[4:], fd.acceleration(s[:4], s[4:], u, False)],
                        (0, DT), x, method="Radau", rtol=1e-10, atol=1e-12)
        x = sol.y[:, -1]
    np.testing.assert_allclose(x[:4], run.q[k], atol=2e-6)
    np.testing.assert_allclose(x[4:], run.dq[k], atol=2e-4)
    for i in (10, 500, 1500):
        M, h = fd.mass_and_bias(run.q[i], run.dq[i])
        np.testing.assert_allclose(M @ run.ddq[i] + h, run.tau[i], rtol=1e-9, atol=1e-9)
    amp = np.abs(experiment["mot"].q).max(0)
    assert np.all(run.tracking_error() < 0.05 * amp)


def test_simulation_errors_are_clear(scara, experiment):
    _, model, _, theta, _ = scara
    mot = experiment["mot"]
    bad = theta.copy()
    bad[list(model.BASE_NAMES).index("ZZ1R")] = -5.0
    with pytest.raises(IdentificationError, match="not positive definite"):
        simulate_closed_loop(model, bad, mot.t[:50], mot.q[:50])
    with pytest.raises(IdentificationError, match="q_ref has shape"):
        simulate_closed_loop(model, theta, mot.t[:50], mot.q[:40])
    with pytest.raises(IdentificationError, match="gain kp"):
        PIDGains(kp=[-1.0, 1, 1, 1], kd=[1.0] * 4, ki=[0.0] * 4)
    with pytest.raises(IdentificationError, match=r"cannot simulate the IDIM-OLS start|physical start"):
        identify_didim(model, experiment["log"], AssemblyOptions(), gains=experiment["gains"], start=bad, max_iter=1)


# ----------------------------------------------------------------------------- estimators
def _errors(res, theta):
    return res.values - theta, (res.values - theta) / res.std


def test_ols_is_biased_by_position_noise_iv_and_didim_are_not(fits, experiment):
    iv, didim = fits
    theta = experiment["theta"]
    e_ols, z_ols = _errors(iv.ols, theta)
    biased = np.flatnonzero(np.abs(z_ols) > 4)
    assert biased.size >= 1, f"the scenario must bias OLS visibly, z = {np.round(z_ols, 1)}"
    for fit in (iv, didim):
        e, z = _errors(fit.result, theta)
        for i in biased:
            name = fit.result.names[i]
            assert abs(z[i]) <= 3 or abs(e[i]) <= abs(e_ols[i]) / 3, (
                f"{fit.result.method} {name}: error {e[i]:.3g} ({z[i]:.1f} sigma), OLS {e_ols[i]:.3g} ({z_ols[i]:.1f} sigma)")
        # over all parameters (scaled by the truth), the error is well below that of OLS
        scale = np.maximum(np.abs(theta), 0.1)
        assert np.linalg.norm(e / scale) < 0.5 * np.linalg.norm(e_ols / scale), fit.result.method
    # IV's and DIDIM's statistics cover the truth (DIDIM's output error is taken on the simulated torque:
    # with Y - W_s chi instead, its fixed point was 3-9 sigma off, bench/bench_iv_didim.py)
    for fit in (iv, didim):
        _, z = _errors(fit.result, theta)
        assert np.max(np.abs(z)) < 3.5, (fit.result.method, np.round(z, 1))


def test_iterations_converge(fits):
    for fit in fits:
        assert fit.converged and 1 <= fit.iterations < 20
        assert fit.changes[-1] < 1e-3
        assert fit.changes[-1] < fit.changes[0]
        assert fit.history.shape == (fit.iterations + 1, len(fit.result.names))
        assert fit.setup.reference_source == ("recorded",)
        d = fit.to_dict()
        assert d["method"] == fit.result.method and d["iterations"] == fit.iterations
    assert fits[0].result.method == "IV" and fits[1].result.method == "DIDIM"


def test_iv_statistics_against_monte_carlo(scara):
    """The IV covariance ``sigma^2 (Z'W)^-1 Z'Z (W'Z)^-1`` predicts the scatter of the estimate over
    noise draws (independent instruments, noisy regressors)."""
    *_, rng = scara
    r, c = 400, 3
    X = rng.standard_normal((r, c))
    chi = np.array([1.0, -2.0, 0.5])
    est, std = [], []
    for _ in range(300):
        W = X + 0.3 * rng.standard_normal((r, c))
        Y = X @ chi + 0.2 * rng.standard_normal(r)
        res = iv_fit(ObservationSystem(W, Y, ("a", "b", "c"), np.zeros(r, int)), X)
        est.append(res.values)
        std.append(res.std)
    est, std = np.array(est), np.array(std)
    assert np.all(np.abs(est.mean(0) - chi) < 4 * est.std(0) / np.sqrt(len(est)))
    np.testing.assert_allclose(est.std(0), std.mean(0), rtol=0.2)


def test_identify_dispatches_to_the_closed_loop_methods(scara, experiment, fits):
    _, model, *_ = scara
    res = identify(experiment["log"], "iv", model=model, options=AssemblyOptions(),
                   closed_loop=dict(gains=experiment["gains"], max_iter=1))
    np.testing.assert_allclose(res.values, fits[0].history[1], rtol=1e-10)
    with pytest.raises(IdentificationError, match="pass model"):
        identify(experiment["log"], "didim")
    with pytest.raises(IdentificationError, match="use one of"):
        identify(experiment["log"], "foo")


def test_cli_identify_didim(scara, experiment, cli, tmp_path):
    """``identify --method didim``: reference = filtered measured positions, default PD gains;
    the JSON names the method and the iterations; the estimate is close to the truth."""
    _, model, _, theta, _ = scara
    log = experiment["log"]
    n = 1200  # 6 s
    short = Trajectory(t=log.t[:n], q=log.q[:n], tau=log.tau[:n], source="short")
    csv = tmp_path / "log.csv"
    write_recording_csv(csv, short)
    out = tmp_path / "r.json"
    r = cli("identify", "scara", str(csv), "--method", "didim", "--json", str(out), "--max-iter", "8",
            "--kp", *map(str, experiment["gains"].kp), "--kd", *map(str, experiment["gains"].kd))
    assert "DIDIM:" in r.out and "iteration(s)" in r.out
    d = json.loads(out.read_text())
    assert d["method"] == "DIDIM"
    assert d["iterations"]["reference"] == ["filtered q"]
    assert d["iterations"]["iterations"] >= 1
    np.testing.assert_allclose(d["iterations"]["controller_gains"][0]["kp"], experiment["gains"].kp)
    vals = dict(zip(d["parameters"]["names"], d["parameters"]["values"]))
    assert abs(vals["M3R"] - theta[list(model.BASE_NAMES).index("M3R")]) < 0.05 * abs(theta[list(model.BASE_NAMES).index("M3R")])
    bad = cli("identify", "scara", str(csv), "--method", "iv", "--kp", "1", rc=None)
    assert bad.rc != 0 and "--kp and --kd go together" in bad.err


def test_non_physical_ols_start_falls_back_to_the_reference_states(scara):
    """Heavy position noise can make IDIM-OLS non-physical (M(q) indefinite: it cannot be simulated);
    the iterations then start from the OLS fit on the recorded reference states, and say so."""
    robot, model, *_ = scara
    rng = np.random.default_rng(6)
    chi = np.asarray(random_physical_parameters(robot, rng, fs_range=(0.5, 2.0)))
    theta = model.base_parameters(chi)
    mot = fourier_trajectory(4, 10.0, DT, rng, amplitude=1.0, vmax=2.0, amax=10.0, base_frequency_hz=0.2)
    gains = default_gains(model, theta, mot.q, DT)
    run = simulate_closed_loop(model, theta, mot.t, mot.q, mot.dq, gains=gains)
    log = Trajectory(t=mot.t, q=run.q + NOISE_Q * rng.standard_normal(run.q.shape),
                     tau=run.tau + 0.005 * np.abs(run.tau).max(0) * rng.standard_normal(run.tau.shape),
                     source="noisy", meta={"q_ref": mot.q})
    fit = identify_iv(model, log, AssemblyOptions(), gains=gains, max_iter=2)
    with pytest.raises(IdentificationError, match=r"not positive definite|diverged"):
        simulate_closed_loop(model, fit.ols.values, mot.t, mot.q, mot.dq, gains=gains)
    assert fit.start_source == "OLS on the reference states"
    assert any("started from the OLS fit on the reference states" in w for w in fit.result.warnings)
    scale = np.maximum(np.abs(theta), 0.1)
    assert np.linalg.norm((fit.result.values - theta) / scale) < 0.5 * np.linalg.norm((fit.ols.values - theta) / scale)


# ----------------------------------------------------------------------------- robustness, DIDIM statistics
def test_didim_statistics_from_the_output_error_of_the_final_simulation(scara, fits):
    """GJV2013 output error ``e = Y - T(chi)`` (the simulated torque, decimated as Y) of a simulation WITH
    the final estimate; ``C = (W_s'J)^-1 S (J'W_s)^-1`` with ``S`` the Bartlett long-run covariance of the
    scores (recomputed here lag by lag on the time-ordered samples); the header names the method DIDIM."""
    from symoro_gen.identification.iv import simulated_output

    _, model, *_ = scara
    didim = fits[1]
    res = didim.result
    so = simulated_output(model, didim.setup, res.values)
    e = so.Y - so.T
    r, c = so.W.shape
    assert res.sigma == pytest.approx(np.sqrt(e @ e / (r - c)), rel=1e-9)
    np.testing.assert_allclose(res.residual, e, rtol=1e-9, atol=1e-12)
    assert didim.statistics["jacobian"] == "W_s" and didim.to_dict()["statistics"] == didim.statistics
    L = didim.statistics["hac_lags"]
    assert L >= 1
    ms = didim.setup.measured
    t = ms.row_sample
    samples = np.unique(t)
    G = np.array([(so.W[t == k] * e[t == k, None]).sum(0) for k in samples])
    S = G.T @ G
    for lag in range(1, L + 1):
        A = G[lag:].T @ G[:-lag]
        S = S + (1 - lag / (L + 1)) * (A + A.T)
    Ainv = np.linalg.inv(so.W.T @ so.W)
    cov = Ainv @ (S * r / (r - c)) @ Ainv
    np.testing.assert_allclose(res.std, np.sqrt(np.diag(cov)), rtol=1e-6)
    head = res.summary().splitlines()[0]
    assert head.startswith("DIDIM identification") and "IDIM-DIDIM" not in res.summary()
    assert fits[0].result.summary().startswith("IDIM-IV identification")


def test_didim_fixed_point_is_the_truth_on_noise_free_torque(scara, experiment):
    """With the exact torque of the closed loop the truth is a fixed point of DIDIM: one step from it
    does not move (the output error is on the simulated torque; ``Y - W_s chi`` on the decimated data
    moved it by several sigma)."""
    _, model, _, theta, _ = scara
    log = experiment["log"]
    q_ref = log.meta["q_ref"]
    # the "real" robot driven by the reference exactly as DIDIM's simulation is (velocity by differences)
    run = simulate_closed_loop(model, theta, log.t, q_ref, np.gradient(q_ref, DT, axis=0), gains=experiment["gains"])
    clean = Trajectory(t=log.t, q=log.q, tau=run.tau, source="clean", meta=log.meta)
    fit = identify_didim(model, clean, AssemblyOptions(), gains=experiment["gains"], start=theta, max_iter=1,
                         jacobian="simulated")
    scale = np.maximum(np.abs(theta), 0.1)
    assert np.max(np.abs(fit.history[1] - theta) / scale) < 1e-6
    assert fit.converged


def test_hac_sandwich_matches_monte_carlo_with_correlated_errors():
    """The covariance of :func:`output_error_statistics` (Bartlett long-run covariance of the scores,
    Newey & West 1987) predicts the spread of least-squares estimates under AR(1) errors (rho = 0.8)
    within 25 %, where ``sigma^2 (W'W)^-1`` understates it about twofold."""
    from symoro_gen.identification.didim import hac_score_covariance

    rng = np.random.default_rng(0)
    K, c, rho = 1500, 3, 0.8
    tt = np.arange(K)
    X = np.column_stack([np.sin(2 * np.pi * tt / 150), np.cos(2 * np.pi * tt / 400), np.ones(K)])
    keys = tt.astype(np.int64)
    est, hac, naive = [], [], []
    for _ in range(300):
        u = rng.standard_normal(K)
        e = np.empty(K)
        e[0] = u[0] / np.sqrt(1 - rho ** 2)
        for k in range(1, K):
            e[k] = rho * e[k - 1] + u[k]
        y = X @ np.array([1.0, -0.5, 0.2]) + e
        b = np.linalg.lstsq(X, y, rcond=None)[0]
        res = y - X @ b
        A = np.linalg.inv(X.T @ X)
        S = hac_score_covariance(X * res[:, None], keys, 30)
        est.append(b)
        hac.append(np.sqrt(np.diag(A @ S @ A)))
        naive.append(np.sqrt(res @ res / (K - c) * np.diag(A)))
    spread = np.array(est).std(0)
    np.testing.assert_allclose(np.mean(hac, 0), spread, rtol=0.25)
    assert np.all(np.mean(naive, 0) < 0.6 * spread)


def test_didim_sensitivity_is_the_derivative_of_the_simulated_torque(scara, experiment):
    """The finite-difference ``J = dT/dchi`` predicts the change of the simulated torque along a random
    direction (an independent perturbation), and GJV2013's ``W_s`` approximates it within 30 %."""
    from symoro_gen.identification.didim import _sensitivity
    from symoro_gen.identification.iv import closed_loop_setup, simulated_output

    _, model, _, theta, rng = scara
    log = experiment["log"]
    n = 600
    short = Trajectory(t=log.t[:n], q=log.q[:n], tau=log.tau[:n], source="short", meta={"q_ref": log.meta["q_ref"][:n]})
    setup = closed_loop_setup(model, short, AssemblyOptions(), theta, gains=experiment["gains"])
    base = simulated_output(model, setup, theta)
    J = _sensitivity(model, setup, theta, base, base.substeps)
    d = 1e-3 * np.maximum(np.abs(theta), 0.05) * rng.choice([-1.0, 1.0], theta.size)
    moved = simulated_output(model, setup, theta + d, substeps=base.substeps).T - base.T
    assert np.linalg.norm(moved - J @ d) < 0.02 * np.linalg.norm(moved)
    assert np.linalg.norm(J - base.W) < 0.3 * np.linalg.norm(base.W)


def test_physical_projection_of_base_parameters(scara, experiment):
    pytest.importorskip("cvxpy", reason="the physical projection needs cvxpy")
    from symoro_gen.identification.iv import physical_projection

    _, model, _, theta, _ = scara
    # a physical estimate is its own projection
    np.testing.assert_allclose(physical_projection(model, theta), theta, atol=1e-5 * np.abs(theta).max())
    bad = theta.copy()
    bad[list(model.BASE_NAMES).index("ZZ1R")] = -5.0
    proj = physical_projection(model, bad)
    mot = experiment["mot"]
    simulate_closed_loop(model, proj, mot.t[:50], mot.q[:50])  # simulable: no exception
    from symoro_gen.identification.physical import standard_from_base

    assert not standard_from_base(model, bad).exact  # the given one is not physical
    assert standard_from_base(model, proj).exact  # its projection is
    assert np.abs(proj - bad).max() > 0.1


def test_non_simulable_iterate_is_replaced_by_its_physical_projection(scara, experiment):
    """An iterate that cannot be simulated (here a step forced to a negative ZZ1R) is replaced by its
    physically consistent projection; the iterations then converge to the same estimate."""
    pytest.importorskip("cvxpy", reason="the physical projection needs cvxpy")
    from dataclasses import replace

    from symoro_gen.identification.iv import iterate

    _, model, _, theta, _ = scara
    calls = []

    def step(measured, sim):
        fit = iv_fit(measured, sim.W)
        calls.append(1)
        if len(calls) == 1:
            v = fit.values.copy()
            v[list(model.BASE_NAMES).index("ZZ1R")] = -1.0  # M(q) not positive definite
            return replace(fit, values=v)
        return fit

    it = iterate(model, experiment["log"], AssemblyOptions(), step, "IDIM-IV", gains=experiment["gains"])
    assert any("physically consistent projection" in w for w in it.result.warnings), it.result.warnings
    assert it.converged
    ref = identify_iv(model, experiment["log"], AssemblyOptions(), gains=experiment["gains"])
    scale = np.maximum(np.abs(theta), 0.1)
    assert np.linalg.norm((it.result.values - ref.result.values) / scale) < 1e-2


def test_start_falls_back_to_the_physical_projection(scara, experiment, fits, monkeypatch):
    """When neither IDIM-OLS nor the OLS fit on the reference states can be simulated, the
    iterations start from the physically consistent projection of IDIM-OLS, and say so."""
    pytest.importorskip("cvxpy", reason="the physical projection needs cvxpy")
    import symoro_gen.identification.iv as ivmod

    _, model, _, theta, _ = scara
    bad = theta.copy()
    bad[list(model.BASE_NAMES).index("ZZ1R")] = -1.0  # M(q) not positive definite
    real_fit_ols = ivmod.fit_ols

    def non_physical_ols(system, **kw):  # IDIM-OLS and the reference OLS both made non-physical
        return replace_values(real_fit_ols(system, **kw), bad)

    def replace_values(res, v):
        from dataclasses import replace

        return replace(res, values=v.copy())

    monkeypatch.setattr(ivmod, "fit_ols", non_physical_ols)
    fit = identify_didim(model, experiment["log"], AssemblyOptions(), gains=experiment["gains"])
    assert fit.start_source == "physical projection of IDIM-OLS"
    assert any("physically consistent projection of the IDIM-OLS" in w for w in fit.result.warnings)
    scale = np.maximum(np.abs(theta), 0.1)
    # the same fixed point as the iterations from a physical start
    assert np.linalg.norm((fit.result.values - fits[1].result.values) / scale) < 1e-2


def test_didim_not_converged_says_why(scara, experiment):
    """A DIDIM that stops before converging ends with one warning naming the output error per joint, the
    worst simulated tracking error, the reference and the controller it used."""
    _, model, *_ = scara
    fit = identify_didim(model, experiment["log"], AssemblyOptions(), gains=experiment["gains"], max_iter=1,
                         jacobian="simulated")
    assert not fit.converged
    last = fit.result.warnings[-1]
    assert last.startswith("DIDIM did not converge: the simulated closed loop does not reproduce the recording")
    assert "reference: recorded" in last and "controller: given" in last and "--kp/--kd/--ki" in last
