"""Excitation design: robot-file limits, the trajectory bases, the optimiser
against random trajectories, limits at every sample of a dense resampling, and the CLI contract
(CSV readable, and identifying simulated data on it recovers the truth)."""
import importlib
import itertools
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from symoro_gen import excite
from symoro_gen.description.parse import parse_robot_text
from symoro_gen.errors import RobotFileError
from symoro_gen.excite import (
    ExcitationError,
    FourierBasis,
    Limits,
    PointToPointBasis,
    SplineBasis,
    basis_eval,
    check_limits,
    cond_lower_bound,
    dense_times,
    friction_ceiling,
    friction_trajectory,
    limits_of,
    optimise_excitation,
    output_times,
    predicted_sigma,
    random_trajectory,
    refine_excitation,
    stacked_cond,
)
from symoro_gen.loader import model_for
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import (
    random_physical_parameters,
    simulate_recording,
    write_recording_csv,
)

SCARA_LIMITS = """
[limits]
angles = "deg"
q_min = [-150, -140, 0, -360]
q_max = [150, 140, 0.2, 360]
dq_max = [180, 180, 0.3, 360]
ddq_max = [600, 600, 1.5, 900]
"""


@pytest.fixture(scope="module")
def scara():
    return model_for("scara")


@pytest.fixture(scope="module")
def scara_limits(scara):
    from symoro_gen.description import robots_dir

    robot = parse_robot_text((robots_dir() / "scara.toml").read_text() + SCARA_LIMITS, file="scara+limits.toml")
    return limits_of(robot)


# -- robot-file [limits] --------------------------------------------------------------------------
def test_limits_table_in_si_units(scara_limits):
    lim = scara_limits
    assert lim.defaulted == ()
    np.testing.assert_allclose(lim.q_max, [150 * math.pi / 180, 140 * math.pi / 180, 0.2, 2 * math.pi])
    # the prismatic joint 3 is not converted from degrees
    assert lim.dq_max[2] == 0.3 and lim.ddq_max[2] == 1.5
    assert lim.tau_max is None


def test_defaulted_limits_say_what_was_used():
    """A [limits] table without ddq_max (a URDF gives no accelerations): the field is defaulted per joint kind and
    the text the command prints names the values used, in the units of each kind."""
    from symoro_gen.description import robots_dir

    text = (robots_dir() / "scara.toml").read_text() + SCARA_LIMITS.replace("ddq_max = [600, 600, 1.5, 900]\n", "")
    lim = limits_of(parse_robot_text(text, file="arm.toml"))
    assert lim.defaulted == ("ddq_max",)
    np.testing.assert_allclose(lim.ddq_max, [10.0, 10.0, 2.0, 10.0])
    assert lim.defaulted_text() == ("ddq_max (10 rad/s^2 for the revolute joints; 2 m/s^2 for the prismatic "
                                    "joints)")
    assert limits_of(parse_robot_text(text + "ddq_max = [600, 600, 1.5, 900]\n", file="arm.toml")).defaulted_text() == ""


def test_limits_errors_name_file_joint_and_field():
    from symoro_gen.description import robots_dir

    text = (robots_dir() / "scara.toml").read_text()
    bad = text + "\n[limits]\nq_min = [-1, 2, 0, -1]\nq_max = [1, 1, 1, 1]\ndq_max = [1, 1, -2, 1]\nspeed = 3\n"
    with pytest.raises(RobotFileError) as ei:
        parse_robot_text(bad, file="arm.toml")
    msgs = [str(p) for p in ei.value.problems]
    assert any("arm.toml" in m and "joint 2" in m and "q_min" in m for m in msgs), msgs
    assert any("joint 3" in m and "dq_max" in m and "positive" in m for m in msgs), msgs
    assert any("speed" in m and "unknown field" in m for m in msgs), msgs
    with pytest.raises(RobotFileError, match="list of 4 numbers"):
        parse_robot_text(text + "\n[limits]\ndq_max = [1, 1]\n", file="arm.toml")


def test_shipped_robots_have_cited_limits():
    robot, _ = model_for("lwr4")
    lim = limits_of(robot)
    assert lim.defaulted == ()
    np.testing.assert_allclose(np.degrees(lim.q_max), [170, 120, 170, 120, 170, 120, 170])
    np.testing.assert_allclose(np.degrees(lim.dq_max), [110, 110, 128, 128, 204, 184, 184])
    text = Path(robot.file).read_text().lower()
    assert "kuka" in text and "specification" in text


# -- bases ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("basis", [FourierBasis(4, 0.25), PointToPointBasis(5, 1.0, dwell=0.2), SplineBasis(12, 4.0)])
def test_bases_rest_at_ends_and_consistent_derivatives(basis):
    rng = np.random.default_rng(0)
    X = rng.standard_normal((basis.m, 3))
    T = 4.0 if basis.kind == "fourier" else basis.duration
    _, dq, ddq = basis_eval(basis, X, np.array([0.0, T]))
    np.testing.assert_allclose(dq, 0, atol=1e-9)
    np.testing.assert_allclose(ddq, 0, atol=1e-9)
    # derivatives against central finite differences of the positions / velocities
    t = np.linspace(0.05, T - 0.05, 37)
    h = 1e-5
    qp, dqp, _ = basis_eval(basis, X, t + h)
    qm, dqm, _ = basis_eval(basis, X, t - h)
    _, dq_t, ddq_t = basis_eval(basis, X, t)
    np.testing.assert_allclose((qp - qm) / (2 * h), dq_t, atol=1e-5)
    np.testing.assert_allclose((dqp - dqm) / (2 * h), ddq_t, atol=1e-3)


@pytest.mark.parametrize(("basis", "T"), [(FourierBasis(5, 0.1), 10.0), (FourierBasis(4, 0.25), 4.0),
                                          (PointToPointBasis(5, 1.0, dwell=0.2), 4.6), (SplineBasis(12, 4.0), 4.0)])
def test_random_designs_hold_an_off_centre_range(basis, T, scara_limits):
    """The SCARA's joint 3 ranges over [0, 0.2] m (centre 0.1): the design that stays at the centre is
    constant over the whole motion, and random designs (the benchmark's baseline) and structured ones stay
    inside every limit. (Before the fix, the "constant" Fourier design fitted on early samples drifted
    away from the centre later on, and random designs left their position range by up to 75 %.)"""
    t = np.linspace(0.0, T, 2001)
    centre = (scara_limits.q_max + scara_limits.q_min) / 2
    q0, dq0, ddq0 = basis_eval(basis, excite.constant_design(basis, 4, centre), t)
    np.testing.assert_allclose(q0, np.broadcast_to(centre, q0.shape), atol=1e-12)
    np.testing.assert_allclose(np.c_[dq0, ddq0], 0.0, atol=1e-12)
    rng = np.random.default_rng(0)
    for _ in range(10):
        X = random_trajectory(basis, scara_limits, rng, t)
        assert check_limits(scara_limits, *basis_eval(basis, X, t))["ok"]
    X = friction_trajectory(basis, scara_limits, rng, t, T)
    assert check_limits(scara_limits, *basis_eval(basis, X, t))["ok"]


def test_spline_is_the_scipy_bspline_of_its_control_points():
    """The spline basis equals scipy's B-spline with the tied end control points (independent evaluation)."""
    from scipy.interpolate import make_interp_spline

    b = SplineBasis(10, 3.0)
    x = np.random.default_rng(2).standard_normal(b.m)
    c = np.concatenate([[x[0]] * 3, x[1:-1], [x[-1]] * 3])
    assert len(c) == 10
    t = np.linspace(0, 3, 41)
    ref = make_interp_spline(np.linspace(0, 3, 10), np.zeros(10), k=3)  # only for its class: same knots below
    ref = type(ref)(b.knots, c, 3)
    q, dq, ddq = basis_eval(b, x[:, None], t)
    np.testing.assert_allclose(q[:, 0], ref(t), atol=1e-12)
    np.testing.assert_allclose(dq[:, 0], ref.derivative()(t), atol=1e-10)
    np.testing.assert_allclose(ddq[:, 0], ref.derivative(2)(t), atol=1e-9)
    with pytest.raises(Exception, match="--coefficients 6"):
        SplineBasis(6, 3.0)


def test_p2p_passes_through_via_points():
    b = PointToPointBasis(4, 0.8)
    X = np.arange(8.0).reshape(4, 2)
    q, dq, _ = basis_eval(b, X, np.arange(4) * 0.8)
    np.testing.assert_allclose(q, X, atol=1e-12)
    np.testing.assert_allclose(dq, 0, atol=1e-9)


# -- optimisation -------------------------------------------------------------------------------------
DURATION, RATE = 4.0, 50.0


@pytest.fixture(scope="module")
def optimised(scara, scara_limits):
    _, model = scara
    basis = FourierBasis(3, 1 / DURATION)
    return optimise_excitation(model, basis, scara_limits, DURATION, rate=RATE, starts=2, seed=0, max_iter=60)


def test_optimised_cond_far_below_random(scara, scara_limits, optimised):
    _, model = scara
    basis = optimised.basis
    rng = np.random.default_rng(1)
    t = output_times(DURATION, RATE)
    rand = [stacked_cond(model, *basis_eval(basis, random_trajectory(basis, scara_limits, rng, t), t)) for _ in range(20)]
    # the reported cond is the unscaled one of the output samples
    assert optimised.cond == pytest.approx(stacked_cond(model, optimised.q, optimised.dq, optimised.ddq), rel=1e-12)
    assert optimised.cond < min(rand), (optimised.cond, min(rand))
    assert optimised.cond < 0.5 * float(np.median(rand)), (optimised.cond, np.median(rand))


def test_friction_ceiling_is_the_largest_smallest_eigenvalue():
    """No velocity distribution on [-v, v] (random discrete ones, symmetric or not, with rests) has a
    moment matrix of (dq, sign dq, 1) with a larger smallest eigenvalue than ``friction_ceiling(v)``,
    and the supremum is approached (within 1 %) by slow motion at +-eps mixed with motion at +-v."""
    rng = np.random.default_rng(0)
    for v in (0.5, 1.92, 4.0):
        c = friction_ceiling(v)
        best = 0.0
        for _ in range(4000):
            k = rng.integers(2, 7)
            x = rng.uniform(-v, v, k)
            x[rng.random(k) < 0.2] = 0.0
            if rng.random() < 0.5:
                x = np.r_[x, -x]
            p = rng.dirichlet(np.ones(x.size))
            Z = np.column_stack([x, np.sign(x), np.ones_like(x)])
            lam = float(np.linalg.eigvalsh((Z * p[:, None]).T @ Z)[0])
            assert lam <= c + 1e-9, (v, lam, c)
        for w in np.linspace(0.01, 0.99, 99):
            x = np.array([1e-6, -1e-6, v, -v])
            p = np.array([1 - w, 1 - w, w, w]) / 2
            Z = np.column_stack([x, np.sign(x), np.ones_like(x)])
            best = max(best, float(np.linalg.eigvalsh((Z * p[:, None]).T @ Z)[0]))
        assert c * 0.99 < best <= c + 1e-9, (v, best, c)


@pytest.mark.parametrize("robot_name", ["scara", "lwr4"])
def test_cond_lower_bound_holds_for_every_trajectory(robot_name, scara_limits):
    """``cond_lower_bound`` is below the cond of random feasible trajectories of any length and of the
    optimised-like extremes; on the LWR4 it rests on the first moments of link 2 (squared norm g^2 at
    every sample, whatever the trajectory) and on the friction columns of the slowest joint."""
    robot, model = model_for(robot_name)
    lim = scara_limits if robot_name == "scara" else limits_of(robot)
    b = cond_lower_bound(model, lim)
    assert b is not None and b.bound > 1
    rng = np.random.default_rng(2)
    for duration, harmonics in ((4.0, 2), (10.0, 5), (20.0, 8)):
        basis = FourierBasis(harmonics, 1 / duration)
        t = output_times(duration, 20.0)
        for _ in range(5):
            q, dq, ddq = basis_eval(basis, random_trajectory(basis, lim, rng, t), t)
            assert stacked_cond(model, q, dq, ddq) >= b.bound
    if robot_name == "lwr4":
        assert set(b.smax_columns) == {"MX2", "MY2R"}
        assert b.smax2 == pytest.approx(9.81 ** 2 / 2, rel=1e-3)  # g^2 / 2 (the model's g)
        q = rng.uniform(-3, 3, (50, 7))
        W = np.asarray(model.regressor(q, rng.normal(size=(50, 7)), rng.normal(size=(50, 7)))).reshape(50, 7, -1)
        i, j = (list(model.BASE_NAMES).index(c) for c in ("MX2", "MY2R"))
        np.testing.assert_allclose((W[:, :, i] ** 2 + W[:, :, j] ** 2).sum(1), 2 * b.smax2, rtol=1e-9)
        assert b.smin2 == pytest.approx(friction_ceiling(float(lim.dq_max.min())), rel=1e-9)


def test_predicted_sigma_is_the_spread_of_least_squares_under_that_noise(scara, optimised):
    """The predicted sigma of every base parameter (Gautier 1997 eq. 9 with the noise given) against an
    independent Monte Carlo: 400 torque-noise draws on the optimised trajectory, each identified by least
    squares; the empirical standard deviations agree within 12 % (the sampling error of a standard deviation
    from 400 draws is 3.5 %). %sigma is 100 sigma / |nominal|, undefined (NaN) at 0 and at round-off."""
    robot, model = scara
    q, dq, ddq = optimised.q, optimised.dq, optimised.ddq
    noise = 0.3
    sig, pct = predicted_sigma(model, q, dq, ddq, noise)
    assert pct is None
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
    rng = np.random.default_rng(11)
    chi_b = np.asarray(model.base_parameters(np.asarray(random_physical_parameters(robot, rng))), float)
    E = noise * rng.standard_normal((W.shape[0], 400))
    est = np.linalg.lstsq(W, (W @ chi_b)[:, None] + E, rcond=None)[0]
    np.testing.assert_allclose(est.std(axis=1, ddof=1), sig, rtol=0.12)
    nominal = chi_b.copy()
    nominal[0], nominal[1] = 0.0, 1e-13 * np.abs(chi_b).max()
    _, pct = predicted_sigma(model, q, dq, ddq, noise, nominal)
    assert np.isnan(pct[:2]).all()
    np.testing.assert_allclose(pct[2:], 100 * sig[2:] / np.abs(nominal[2:]), rtol=1e-12)


def test_limits_hold_on_a_dense_resampling(scara_limits, optimised):
    assert optimised.limits_ok
    t = np.linspace(0, DURATION, 40001)
    q, dq, ddq = basis_eval(optimised.basis, optimised.X, t)
    lim = scara_limits
    assert np.all(q >= lim.q_min - 1e-12) and np.all(q <= lim.q_max + 1e-12)
    assert np.all(np.abs(dq) <= lim.dq_max * (1 + 1e-9))
    assert np.all(np.abs(ddq) <= lim.ddq_max * (1 + 1e-9))
    # the limits are used: some joint is driven to within 5% of a velocity or acceleration limit
    assert max(max(optimised.usage["dq"]), max(optimised.usage["ddq"])) > 0.95


def test_torque_limits_are_imposed(scara):
    robot, model = scara
    rng = np.random.default_rng(4)
    chi_b = model.base_parameters(np.asarray(random_physical_parameters(robot, rng)))
    basis = FourierBasis(3, 1 / DURATION)
    # pool=1: one plain random start, so that the torque-limited problem below stays the same small one
    free = optimise_excitation(model, basis, limits_of(robot), DURATION, rate=RATE, starts=1, seed=0, max_iter=30,
                               pool=1)
    tau_free = np.abs(model.regressor(free.q, free.dq, free.ddq) @ chi_b).max(0)
    base = limits_of(robot)
    # the horizontal joints 1, 2, 4 to 60% of their free peak; joint 3 carries the weight (kept feasible)
    lim = Limits(base.q_min, base.q_max, base.dq_max, base.ddq_max, tau_max=tau_free * [0.6, 0.6, 1.5, 0.6])
    res = optimise_excitation(model, basis, lim, DURATION, rate=RATE, starts=1, seed=0, max_iter=60, chi_b=chi_b,
                              pool=1)
    tau = model.regressor(res.q, res.dq, res.ddq) @ chi_b
    assert np.all(np.abs(tau) <= lim.tau_max * 1.02), (np.abs(tau).max(0), lim.tau_max)
    assert check_limits(lim, res.q, res.dq, res.ddq)["ok"]
    assert res.limits_ok == check_limits(lim, res.q, res.dq, res.ddq, tau)["ok"]


def _friction_lambda(v):
    z = np.column_stack([v, np.sign(v), np.ones_like(v)])
    return float(np.linalg.eigvalsh(z.T @ z / len(v))[0])


def test_friction_trajectory_alternates_slow_motion_and_bursts_at_the_limit(scara_limits):
    """The structured starts: every limit held on the output samples, and every revolute joint spends at least 15 %
    of the time above 90 % of its velocity limit and a sixth moving below 10 % of it (the two
    speeds the friction columns want); the friction block's smallest eigenvalue stays below
    :func:`friction_ceiling` (which bounds every velocity distribution)."""
    lim = scara_limits
    T = 6.0
    t = output_times(T, 100.0)
    rng = np.random.default_rng(3)
    sb = SplineBasis(60, T)
    ceil = np.array([friction_ceiling(v) for v in lim.dq_max])
    for _ in range(3):
        X = friction_trajectory(sb, lim.shrunk(0.01), rng, np.linspace(0, T, 2001), T)
        q, dq, ddq = basis_eval(sb, X, t)
        assert check_limits(lim, q, dq, ddq)["ok"]
        # the revolute joints (the prismatic joint 3 crosses its whole 0.2 m range in 0.67 s at its limit)
        u = (np.abs(dq) / lim.dq_max)[:, [0, 1, 3]]
        assert np.all((u > 0.9).mean(0) >= 0.15), (u > 0.9).mean(0)
        assert np.all(((u < 0.1) & (u > 0)).mean(0) >= 1 / 6), ((u < 0.1) & (u > 0)).mean(0)
        lam = np.array([_friction_lambda(dq[:, j]) for j in range(lim.n)])
        assert np.all(lam <= ceil + 1e-9)


def test_spline_design_from_structured_starts(scara, scara_limits):
    """A spline design optimised from the structured starts: every limit held on a dense resampling,
    and cond below the best of 20 random Fourier trajectories of the same duration (the bench's baseline)."""
    _, model = scara
    T = 4.0
    t = output_times(T, RATE)
    basis = SplineBasis(12, T)
    res = optimise_excitation(model, basis, scara_limits, T, rate=RATE, starts=1, seed=0, max_iter=30,
                              pool=1, structured=3, samples=60, powers=(8,))
    assert res.limits_ok
    assert check_limits(scara_limits, *basis_eval(basis, res.X, np.linspace(0, T, 20001)))["ok"]
    assert res.cond == pytest.approx(stacked_cond(model, res.q, res.dq, res.ddq), rel=1e-12)
    fb = FourierBasis(3, 1 / T)
    rng = np.random.default_rng(1)
    rand = [stacked_cond(model, *basis_eval(fb, random_trajectory(fb, scara_limits, rng, t), t)) for _ in range(20)]
    assert res.cond < min(rand), (res.cond, min(rand))


def test_p2p_design_respects_limits(scara, scara_limits):
    _, model = scara
    basis = PointToPointBasis(5, 1.0)
    res = optimise_excitation(model, basis, scara_limits, basis.duration, rate=RATE, starts=1, seed=0, max_iter=40)
    assert res.limits_ok
    t = np.linspace(0, basis.duration, 20001)
    assert check_limits(scara_limits, *basis_eval(basis, res.X, t))["ok"]
    assert res.cond <= min(s["cond_start"] for s in res.starts)


# -- refinement of the true cond by sequential SDP -------------------------------------------------------
@pytest.mark.parametrize("kind", ["spline", "fourier"])
def test_refinement_linearisation_is_the_derivative_of_the_information_matrix(scara, scara_limits, kind):
    """``M = W^T W / N`` and ``dM/dX`` (and the torques and their derivative) of the refinement's linearisation
    against the regressor and central differences (chunks of 64 samples: the last one padded)."""
    from symoro_gen.excite import Linearisation

    _, model = scara
    T = 4.0
    t = output_times(T, RATE)
    basis = SplineBasis(12, T) if kind == "spline" else FourierBasis(3, 1 / T)
    rng = np.random.default_rng(7)
    X = random_trajectory(basis, scara_limits, rng, t)
    chi = rng.normal(size=len(model.BASE_NAMES))
    lin = Linearisation(model, basis, t, chi, chunk=64)
    M, dM, tau, dtau = lin(X)
    W = np.asarray(model.regressor(*basis_eval(basis, X, t))).reshape(-1, len(model.BASE_NAMES))
    np.testing.assert_allclose(M, W.T @ W / len(t), atol=1e-12 * np.abs(M).max())
    np.testing.assert_allclose(tau.reshape(-1), W @ chi, atol=1e-12 * np.abs(tau).max())
    e = 1e-6
    for k, j in [(1, 0), (3, 1), (2, 2), (4, 3)]:
        Xp, Xm = X.copy(), X.copy()
        Xp[k, j] += e
        Xm[k, j] -= e
        (Mp, _, tp, _), (Mm, _, tm, _) = lin(Xp), lin(Xm)
        np.testing.assert_allclose(dM[k, j], (Mp - Mm) / (2 * e), atol=1e-6 * np.abs(dM[k, j]).max())
        np.testing.assert_allclose(dtau[:, :, k, j], (tp - tm) / (2 * e), atol=1e-6 * np.abs(dtau[:, :, k, j]).max())


def _refined_holds_limits(basis, lim, X, T):
    t = np.linspace(0, T, 40001)
    return check_limits(lim, *basis_eval(basis, X, t))["ok"]


def test_a_start_never_ends_worse_than_it_began(scara, scara_limits):
    """IPOPT minimises a smooth bound of cond, which can fall while the true cond rises (here after one
    iteration, before the fix, the second start went from 266.3 to 302.5): each start keeps the best of its
    start design and its stages."""
    _, model = scara
    res = optimise_excitation(model, FourierBasis(3, 1 / 4.0), scara_limits, 4.0, rate=50, starts=3, pool=3, seed=0,
                              max_iter=1)
    for st in res.starts:
        assert st["cond"] <= st["cond_start"] * (1 + 1e-12), st
    assert res.cond == pytest.approx(min(st["cond"] for st in res.starts), rel=1e-12)
    assert res.cond == pytest.approx(stacked_cond(model, res.q, res.dq, res.ddq), rel=1e-12) and res.limits_ok


def test_refinement_lowers_the_true_cond_where_the_smooth_criterion_stops_short(scara, scara_limits):
    """IPOPT on the smooth criterion stopped after 5 iterations: the SDP refinement of the same start lowers the
    true cond by more than 20 %, every accepted step lowers it (the history never goes up), and every limit
    holds at every output sample and on a 40,000-sample resampling."""
    _, model = scara
    basis = FourierBasis(3, 1 / DURATION)
    kw = dict(rate=RATE, starts=1, seed=0, max_iter=5, pool=1, powers=(8,))
    plain = optimise_excitation(model, basis, scara_limits, DURATION, **kw)
    steps: list[int] = []
    refined = optimise_excitation(model, basis, scara_limits, DURATION, refine=10, progress=steps.append, **kw)
    st = refined.starts[0]
    # progress: one step per IPOPT stage and per SDP, reported as they end (then the unused SDPs at once)
    assert sum(steps) == 1 + 10 and len(steps) >= 1 + st["refine_sdps"], steps
    assert st["cond_ipopt"] == pytest.approx(plain.cond, rel=1e-9)  # the same IPOPT result, then refined
    assert refined.cond < 0.8 * plain.cond, (refined.cond, plain.cond)
    assert refined.cond == pytest.approx(stacked_cond(model, refined.q, refined.dq, refined.ddq), rel=1e-12)
    assert refined.limits_ok and _refined_holds_limits(basis, scara_limits, refined.X, DURATION)
    assert st["refine_accepted"] >= 3
    # the true cond at the start of every SDP iteration never increases
    conds = st["refine_conds"]
    assert conds[0] == pytest.approx(plain.cond, rel=1e-9) and conds[-1] == pytest.approx(refined.cond, rel=1e-9)
    assert all(b <= a for a, b in itertools.pairwise(conds)), conds


@pytest.fixture
def refinement_grids(monkeypatch):
    """The output samples each call of refine_excitation inside optimise_excitation is given (a spy)."""
    seen: list[np.ndarray] = []
    real = excite.refine_excitation

    def spy(model_, basis_, limits_, X_, t_out_, *a, **k):
        seen.append(np.asarray(t_out_))
        return real(model_, basis_, limits_, X_, t_out_, *a, **k)

    monkeypatch.setattr(excite.optimise, "refine_excitation", spy)  # where the optimiser looks it up
    return seen


def test_refinement_of_a_repeated_period_works_on_one_period(scara, scara_limits, refinement_grids):
    """A Fourier design of period 2 s output over 6 s: the refinement sees the first period's samples only (the
    others repeat them), and the cond reported is that of all the output samples, equal to one period's (the
    Gram matrix of three periods is three times one period's, up to the rest sample at the ends: 2 of one
    period's 101 samples, 4 of the 301)."""
    _, model = scara
    seen = refinement_grids
    basis = FourierBasis(3, 0.5)
    res = optimise_excitation(model, basis, scara_limits, 6.0, rate=RATE, starts=1, seed=0, max_iter=5, pool=1,
                              powers=(8,), refine=5)
    assert len(seen) == 1 and seen[0][-1] == pytest.approx(2.0) and len(seen[0]) == round(2.0 * RATE) + 1
    assert len(res.t) == round(6.0 * RATE) + 1 and res.starts[0]["refine_accepted"] >= 1
    assert res.cond == pytest.approx(stacked_cond(model, res.q, res.dq, res.ddq), rel=1e-12)
    one = stacked_cond(model, *basis_eval(basis, res.X, seen[0]))
    assert res.cond == pytest.approx(one, rel=2e-2)
    tiled = np.concatenate([seen[0][:-1], seen[0][:-1] + 2.0, seen[0][:-1] + 4.0, [6.0]])
    assert res.cond == pytest.approx(stacked_cond(model, *basis_eval(basis, res.X, tiled)), rel=1e-9)
    assert res.limits_ok and _refined_holds_limits(basis, scara_limits, res.X, 6.0)


def test_refinement_of_a_fast_output_works_on_a_coarser_grid(scara, scara_limits, refinement_grids):
    """A 1-kHz output (a KUKA FRI or Franka controller's rate): the SDP refinement linearises on every 10th
    sample (REFINE_RATE, 100 Hz, the last sample kept) - its memory grows with the samples, a smooth design's
    cond does not - while the cond reported and the limits are those of every 1-kHz sample."""
    _, model = scara
    seen = refinement_grids
    basis = FourierBasis(3, 1 / DURATION)
    res = optimise_excitation(model, basis, scara_limits, DURATION, rate=1000.0, starts=1, seed=0, max_iter=5, pool=1,
                              powers=(8,), refine=5)
    assert len(seen) == 1 and len(seen[0]) == round(DURATION * excite.REFINE_RATE) + 1
    np.testing.assert_allclose(seen[0], res.t[::10], atol=1e-12)
    assert len(res.t) == round(DURATION * 1000) + 1 and res.starts[0]["refine_accepted"] >= 1
    assert res.starts[0]["cond"] < res.starts[0]["cond_ipopt"]
    assert res.cond == pytest.approx(stacked_cond(model, res.q, res.dq, res.ddq), rel=1e-12)
    assert res.limits_ok and _refined_holds_limits(basis, scara_limits, res.X, DURATION)


def test_refinement_of_a_converged_spline_design_never_increases_cond(scara, scara_limits):
    """From an IPOPT optimum of a spline design (structured start), the refinement keeps cond at or below it and
    every limit on a dense resampling; the sign of every moving output velocity is kept (the Coulomb columns)."""
    _, model = scara
    T = 4.0
    basis = SplineBasis(12, T)
    t = output_times(T, RATE)
    res = optimise_excitation(model, basis, scara_limits, T, rate=RATE, starts=1, seed=0, max_iter=20, pool=1,
                              structured=2, samples=60, powers=(8,))
    X, hist = refine_excitation(model, basis, scara_limits, res.X, t, np.linspace(0, T, 400), iterations=5)
    c = stacked_cond(model, *basis_eval(basis, X, t))
    assert c <= res.cond * (1 + 1e-12)
    assert _refined_holds_limits(basis, scara_limits, X, T)
    dq0, dq1 = basis_eval(basis, res.X, t)[1], basis_eval(basis, X, t)[1]
    moving = dq0 != 0
    assert np.all(np.sign(dq1[moving]) == np.sign(dq0[moving]))


def test_refinement_holds_torque_limits(scara):
    """With nominal parameters and torque limits, every refined step keeps the torques within them."""
    robot, model = scara
    rng = np.random.default_rng(4)
    chi_b = model.base_parameters(np.asarray(random_physical_parameters(robot, rng)))
    basis = FourierBasis(3, 1 / DURATION)
    base = limits_of(robot)
    free = optimise_excitation(model, basis, base, DURATION, rate=RATE, starts=1, seed=0, max_iter=5, pool=1,
                               powers=(8,))
    tau_free = np.abs(model.regressor(free.q, free.dq, free.ddq) @ chi_b).max(0)
    lim = Limits(base.q_min, base.q_max, base.dq_max, base.ddq_max, tau_max=tau_free * 1.05)
    t = output_times(DURATION, RATE)
    X, hist = refine_excitation(model, basis, lim, free.X, t, np.linspace(0, DURATION, 400), iterations=10,
                                chi_b=chi_b)
    assert sum(1 for h in hist if h.get("accepted")) >= 2
    q, dq, ddq = basis_eval(basis, X, t)
    tau = model.regressor(q, dq, ddq) @ chi_b
    assert check_limits(lim, q, dq, ddq, tau)["ok"], (np.abs(tau).max(0), lim.tau_max)
    assert stacked_cond(model, q, dq, ddq) < free.cond


# -- CLI ------------------------------------------------------------------------------------------------
def test_cli_contract_and_identification_on_the_trajectory(cli, tmp_path, scara):
    robot, model = scara
    csv, js = tmp_path / "traj.csv", tmp_path / "traj.json"
    cli("--quiet", "excite", "scara", "-o", csv, "--duration", "4", "--harmonics", "3", "--rate", "100",
        "--seed", "2", "--starts", "1", "--max-iter", "40", "--json", js, rc=0)
    head = csv.read_text().splitlines()[0].split(",")
    n = model.N_JOINTS
    assert head == ["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"dq{j}" for j in range(1, n + 1)] + [
        f"ddq{j}" for j in range(1, n + 1)]
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    t, q, dq, ddq = data[:, 0], data[:, 1:n + 1], data[:, n + 1:2 * n + 1], data[:, 2 * n + 1:]
    out = json.loads(js.read_text())
    assert out["limits_ok"] is True
    assert out["cond"] == pytest.approx(stacked_cond(model, q, dq, ddq), rel=1e-9)
    assert len(out["sigma"]) == len(model.BASE_NAMES)
    assert np.all(np.diff(t) > 0) and t[-1] == pytest.approx(4.0)
    # a recording simulated on this trajectory identifies the truth
    rng = np.random.default_rng(5)
    chi = np.asarray(random_physical_parameters(robot, rng))
    rec = simulate_recording(model, t, q, dq, ddq, chi, noise_tau=1e-3, rng=rng, keep_derivatives=True)
    assert isinstance(rec, Trajectory)
    f = tmp_path / "rec.csv"
    write_recording_csv(f, rec)
    res_js = tmp_path / "id.json"
    cli("--quiet", "identify", "scara", f, "--json", res_js, rc=0)
    got = json.loads(res_js.read_text())["parameters"]
    truth = dict(zip(model.BASE_NAMES, model.base_parameters(chi)))
    est = dict(zip(got["names"], got["values"]))
    scale = max(abs(v) for v in truth.values())
    for name, v in truth.items():
        assert est[name] == pytest.approx(v, abs=2e-2 * scale), name


def test_cli_progress_bar_only_when_asked_and_same_trajectory(cli, tmp_path, monkeypatch):
    """The design can take minutes: a bar names the start and the best cond when stderr is a terminal
    (forced here by SYMORO_PROGRESS=1), nothing otherwise or with --quiet; the CSV is the same."""
    args = ["excite", "scara", "--duration", "4", "--harmonics", "3", "--starts", "2", "--max-iter", "5",
            "--refine", "2"]
    plain = cli(*args, "-o", tmp_path / "a.csv", rc=0)
    assert "excite scara" not in plain.err
    monkeypatch.setenv("SYMORO_PROGRESS", "1")
    forced = cli(*args, "-o", tmp_path / "b.csv", rc=0)
    assert "excite scara: start 2/2, best cond" in forced.err, forced.err
    assert cli("--quiet", *args, "-o", tmp_path / "c.csv", rc=0).err == ""
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes() == (tmp_path / "c.csv").read_bytes()


@pytest.mark.skipif("fork" not in __import__("multiprocessing").get_all_start_methods(), reason="needs fork")
def test_starts_in_parallel_processes_give_the_same_design(scara, scara_limits):
    """jobs=2 runs the starts in two forked processes: the same records, the same design, the same cond as
    one process (each start is computed alone from its own design; the first of the lowest cond is kept)."""
    _, model = scara
    kw = dict(rate=RATE, starts=3, seed=2, max_iter=8, pool=6, powers=(8,), refine=2)
    basis = FourierBasis(3, 1 / DURATION)
    one = optimise_excitation(model, basis, scara_limits, DURATION, **kw)
    steps: list[int] = []
    two = optimise_excitation(model, basis, scara_limits, DURATION, jobs=2, progress=steps.append, **kw)
    assert np.array_equal(one.X, two.X) and one.cond == two.cond
    drop = ("refine_time",)
    assert [{k: v for k, v in r.items() if k not in drop} for r in one.starts] == \
        [{k: v for k, v in r.items() if k not in drop} for r in two.starts]
    assert steps == [1 + 2] * 3  # each finished start reports its IPOPT stage and SDPs at once


# -- closed-loop robots: a linear closure (the palletizer's parallelogram) --------------------------------------
@pytest.fixture(scope="module")
def palletizer():
    return model_for("palletizer")


def _short_design(model, lim):
    """A short 10-s Fourier design (one start, 20 IPOPT iterations, 2 SDPs) and its positions on the output
    samples and on the 10x resampling the limits are checked on."""
    basis = FourierBasis(5, 0.1)
    res = optimise_excitation(model, basis, lim, 10.0, starts=1, seed=0, max_iter=20, pool=3, refine=2)
    return res, [basis_eval(basis, res.X, t)[0] for t in (res.t, dense_times(res.t, 10.0, basis))]


def test_closed_loop_casadi_regressor_equals_the_projected_numeric_model(palletizer):
    """``A^T W_tree(A q + b, ...)[:, keep]`` in CasADi against the numeric closure + projection (Newton on the
    loop equations, ``G`` from the constraint Jacobian): the same regressor, actuated joints 1, 2, 4, 5."""
    _, model = palletizer
    F = model.casadi_regressor()
    q, dq, ddq = np.random.default_rng(3).uniform(-1.2, 1.2, (3, 12, 4))
    W = model.regressor(q, dq, ddq)
    Wc = np.array([np.array(F(q[i], dq[i], ddq[i])) for i in range(len(q))])
    assert Wc.shape == W.shape == (12, 4, len(model.BASE_NAMES))
    np.testing.assert_allclose(Wc, W, atol=1e-10 * np.abs(W).max())


@pytest.mark.parametrize("basis", [FourierBasis(4, 0.25), SplineBasis(12, 4.0), PointToPointBasis(5, 0.8, 0.2)],
                         ids=["fourier", "spline", "p2p"])
def test_random_designs_are_scaled_into_passive_ranges(basis):
    """A passive row ``q2 - q1 + 0.1`` in [0.2, 0.9] whose centre is not the box centre's: every random design
    is built about the LP centre (inside every range) and scaled into all ranges, passive included."""
    from symoro_gen.excite import PassiveRange

    box = Limits(np.array([-1.0, -0.5]), np.array([1.0, 1.5]), np.array([2.0, 2.0]), np.array([8.0, 8.0]))
    lim = Limits(box.q_min, box.q_max, box.dq_max, box.ddq_max,
                 passive=(PassiveRange(3, np.array([-1.0, 1.0]), 0.1, 0.2, 0.9),))
    c = lim.centre
    assert np.all(c > box.q_min) and np.all(c < box.q_max) and 0.2 < c[1] - c[0] + 0.1 < 0.9
    t = np.linspace(0.0, 4.0, 401)
    rng = np.random.default_rng(2)
    for _ in range(10):
        X = random_trajectory(basis, lim, rng, t)
        q, dq, ddq = basis_eval(basis, X, t)
        chk = check_limits(lim, q, dq, ddq)
        assert chk["ok"] and max(chk["usage"]["passive"]) <= 1 + 1e-9
        assert np.all(q[:, 1] - q[:, 0] + 0.1 >= 0.2 - 1e-9) and np.all(q[:, 1] - q[:, 0] + 0.1 <= 0.9 + 1e-9)


@pytest.mark.slow
def test_closed_loop_design_keeps_the_passive_joints_within_their_limits(palletizer):
    """The shipped palletizer's [limits] passive_q_min/passive_q_max (joint 3 in [20, 160] deg, joint 6 in
    [-160, -20]) reach the design through the linear closure: every output sample and a 10x resampling keep
    the passive joints (solved numerically by the loop closure, not by the rows the optimiser used) in range;
    without them, the same actuated limits let the same design problem leave that range."""
    import dataclasses

    robot, model = palletizer
    lim = limits_of(robot, model.N_JOINTS, model)
    assert [p.joint for p in lim.passive] == [3, 6]
    np.testing.assert_allclose([p.lo for p in lim.passive], np.radians([20, -160]))
    res, grids = _short_design(model, lim)
    assert res.limits_ok and max(res.usage["passive"]) <= 1.0
    for q in grids:
        z = np.zeros_like(q)
        qt = model.closure(q, z, z).q
        for p in lim.passive:
            assert np.all(qt[:, p.joint - 1] >= p.lo - 1e-9) and np.all(qt[:, p.joint - 1] <= p.hi + 1e-9)
    free, _ = _short_design(model, dataclasses.replace(lim, passive=()))
    lo3, hi3 = excite.passive_ranges(model, free.q)[3]
    assert lo3 < math.radians(20) - 0.05 or hi3 > math.radians(160) + 0.05  # the constraint was not idle


def test_closed_loop_passive_limits_that_no_actuated_position_meets_are_one_error(palletizer):
    robot0, model0 = palletizer
    """Actuated joints within +-10 deg leave the elbow angle q5 - q2 within +-20 deg: no position meets 50 .. 160."""
    text = Path(robot0.file).read_text(encoding="utf-8")
    for old, new in (("q_min = [-180, -90, -120, -30]", "q_min = [-10, -10, -10, -10]"),
                     ("q_max = [180, 30, 120, 120]", "q_max = [10, 10, 10, 10]"), ("passive_q_min = [20,", "passive_q_min = [50,")):
        assert old in text
        text = text.replace(old, new)
    robot = parse_robot_text(text, file="palletizer+bad.toml")
    from symoro_gen.closedloop import ClosedLoopModel

    model = ClosedLoopModel(robot, model0.tree)
    with pytest.raises(ExcitationError, match=r"passive joints within passive_q_min/passive_q_max \(joint 3"):
        limits_of(robot, 4, model)  # said when the limits are read, before any optimisation


def test_cli_closed_loop_robot_writes_actuated_columns_and_the_passive_ranges(cli, tmp_path):
    """``excite palletizer``: q1..q4 are its actuated joints 1, 2, 4, 5 (the CSV convention of identify), said on
    stdout and in the JSON beside the passive joints' ranges; a recording simulated on the CSV identifies the
    closed-loop base parameters through ``symoro-gen identify palletizer``."""
    out, js = tmp_path / "p.csv", tmp_path / "p.json"
    r = cli("excite", "palletizer", "-o", out, "--json", js, "--starts", "1", "--pool", "2", "--max-iter", "5",
            "--refine", "1")
    assert out.read_text().splitlines()[0] == "t," + ",".join(f"{k}{j}" for k in ("q", "dq", "ddq") for j in range(1, 5))
    d = json.loads(js.read_text())
    assert d["joints"] == [1, 2, 4, 5] and sorted(d["passive_ranges"]) == ["3", "6"]
    assert "actuated joints 1, 2, 4, 5" in r.out and "joint 3 " in r.out and "(limits 20.0 .. 160.0)" in r.out, r.out
    # a recording simulated on it (the closed chain's torques at the actuated joints) identifies the nominal values
    robot, model = model_for("palletizer")
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    t, q, dq, ddq = data[:, 0], data[:, 1:5], data[:, 5:9], data[:, 9:13]
    chi = np.asarray(robot.nominal_vector(), float)
    rec = simulate_recording(model, t, q, dq, ddq, chi, noise_tau=1e-2, rng=np.random.default_rng(5),
                             keep_derivatives=True)
    write_recording_csv(tmp_path / "rec.csv", rec)
    cli("--quiet", "identify", "palletizer", tmp_path / "rec.csv", "--json", tmp_path / "id.json", rc=0)
    got = json.loads((tmp_path / "id.json").read_text())["parameters"]
    est = dict(zip(got["names"], got["values"]))
    truth = dict(zip(model.BASE_NAMES, model.base_parameters(chi)))
    scale = max(abs(v) for v in truth.values())
    assert max(abs(est[k] - v) for k, v in truth.items()) < 2e-2 * scale


# -- a floor: every moving frame origin above z_min (excite --z-min) ------------------------------------------
def _origins_z(robot, q_tree):
    """Heights of every frame origin by the numeric MDH transforms chained frame by frame (independent of the
    sympy forward kinematics that Workspace builds)."""
    from symoro_gen.description.mdh import row_transform

    subs, N = robot.geometry_subs(), q_tree.shape[0]
    col = {r.j: i for i, r in enumerate(robot.joints)}
    T = {0: np.broadcast_to(np.eye(4), (N, 4, 4))}
    for row in robot.rows:
        T[row.j] = T[row.ant] @ row_transform(row, subs, q_tree[:, col[row.j]] if row.j in col else np.zeros(N))
    return {j: T[j][:, 2, 3] for j in T if j}


@pytest.fixture(scope="module")
def lwr4():
    return model_for("lwr4")


def test_workspace_heights_and_their_casadi_jacobian_against_the_numeric_transforms(lwr4):
    robot, model = lwr4
    ws = excite.Workspace(robot, -0.3, model.N_JOINTS)
    q = np.random.default_rng(4).uniform(-2, 2, (20, 7))
    ref = _origins_z(robot, q)
    assert ws.frames == tuple(j for j in ref if np.ptp(ref[j]) > 0)  # the frames whose origin moves
    np.testing.assert_allclose(ws.heights(q), np.column_stack([ref[j] for j in ws.frames]), atol=1e-12)
    h, J = excite.floor_linearisation(ws)(q)
    np.testing.assert_allclose(h, ws.heights(q), atol=1e-12)
    for j in range(7):
        dq = np.zeros(7)
        dq[j] = 1e-6
        np.testing.assert_allclose(J[:, :, j], (ws.heights(q + dq) - ws.heights(q - dq)) / 2e-6, atol=1e-7)


@pytest.mark.slow
def test_a_design_keeps_every_frame_origin_above_the_floor(lwr4):
    """A floor at the LWR4's shoulder (z = 0 of its base frame): every output sample and the 10x resampling keep
    every frame origin above it (the independent transforms), through IPOPT, the refinement and the starts;
    without it the same design problem takes the elbow and the wrist half a metre lower."""
    robot, model = lwr4
    free_lim = limits_of(robot, 7, model)
    lim = excite.with_floor(free_lim, robot, model, 0.0)
    res, grids = _short_design(model, lim)
    assert res.limits_ok and max(res.usage["workspace"]) <= 1.0
    for q in grids:
        assert min(z.min() for z in _origins_z(robot, q).values()) >= -1e-9
    free, _ = _short_design(model, free_lim)
    assert min(z.min() for z in _origins_z(robot, free.q).values()) < -0.3  # the floor was not idle


def test_a_floor_above_the_rest_posture_or_a_fixed_frame_is_one_error(lwr4):
    """Designs are built about the centre of the ranges: joint 2 in [80, 120] deg leans the upper arm 100 deg from
    upright, its wrist (frame 5, 0.79 m out) 0.79 cos(100 deg) = -0.137 m below the shoulder, the lowest origin;
    a frame that cannot move is checked alone."""
    import dataclasses

    robot, model = lwr4
    lim = limits_of(robot, 7, model)
    lo, hi = lim.q_min.copy(), lim.q_max.copy()
    lo[1], hi[1] = math.radians(80), math.radians(120)
    leaning = dataclasses.replace(lim, q_min=lo, q_max=hi)
    with pytest.raises(ExcitationError, match=r"--z-min -0.05: at the centre of the joint ranges .* frame 5 is at "
                                              r"z = -0\.137\d* m, already below the floor"):
        excite.with_floor(leaning, robot, model, -0.05)
    with pytest.raises(ExcitationError, match=r"--z-min 0.1: the origin of frame 1 is fixed at z = 0 m"):
        excite.with_floor(lim, robot, model, 0.1)


def test_a_closed_loop_floor_goes_through_the_closure(palletizer):
    """The palletizer's floor: its passive joints from the linear closure, the same heights as the tree's
    transforms at the numerically closed state."""
    robot, model = palletizer
    lim = excite.with_floor(limits_of(robot, 4, model), robot, model, -0.5)
    q = np.random.default_rng(6).uniform(-1, 1, (10, 4))
    z0 = np.zeros_like(q)
    ref = _origins_z(robot, model.closure(q, z0, z0).q)
    np.testing.assert_allclose(lim.workspace.heights(q), np.column_stack([ref[j] for j in lim.workspace.frames]),
                               atol=1e-12)


def test_cli_z_min_writes_the_lowest_heights(cli, tmp_path):
    out, js = tmp_path / "f.csv", tmp_path / "f.json"
    r = cli("excite", "scara", "-o", out, "--json", js, "--z-min", "-0.5", "--starts", "1", "--pool", "2",
            "--max-iter", "5", "--refine", "1", "--duration", "4", "--rate", "50")
    d = json.loads(js.read_text())
    ws = d["workspace"]
    assert ws["z_min"] == -0.5 and len(ws["frames"]) == len(ws["lowest_z"]) and min(ws["lowest_z"]) >= -0.5
    assert "floor z >= -0.5 m (base frame): lowest frame origins" in r.out, r.out


def test_cli_jobs_rejects_a_negative_count(cli, tmp_path):
    r = cli("excite", "scara", "-o", tmp_path / "x.csv", "--jobs", "-1", rc=2)
    assert "--jobs -1" in r.err and not (tmp_path / "x.csv").exists()


def test_cli_rejects_duration_not_whole_periods(cli, tmp_path):
    r = cli("excite", "scara", "-o", tmp_path / "x.csv", "--duration", "3", "--base-frequency", "0.5", rc=2)
    assert "--duration 3" in r.err and "whole number of periods" in r.err


# -- URDF <limit> import ------------------------------------------------------------------------------
URDF = """<robot name="two">
  <link name="base"/>
  <link name="l1"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="l2"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.0" velocity="1.5" effort="40"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.3 0 0"/><axis xyz="0 0 -1"/>
    <limit lower="-1.0" upper="1.2" velocity="2.5" effort="0"/></joint>
</robot>"""


def test_urdf_limits_are_imported():
    from symoro_gen.description.urdf import import_urdf_text

    text = import_urdf_text(URDF, file="two.urdf")
    assert "[limits]" in text
    robot = parse_robot_text(text, file="two.toml")
    # the robot file's q is the URDF joint value (joint 2's axis is reversed in theta = -q, not in q)
    assert robot.limits.q_min == (-2.5, -1.0) and robot.limits.q_max == (2.0, 1.2)
    assert robot.limits.dq_max == (1.5, 2.5)
    assert robot.limits.tau_max is None  # effort="0" (unknown) on joint 2: not written


def test_plot_of_the_trajectory_against_limits(optimised, tmp_path):
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the 'plots' extra)")
    from symoro_gen.excite import plot_trajectory

    f = tmp_path / "traj.png"
    plot_trajectory(optimised, f)
    assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_point_to_point(cli, tmp_path, scara):
    _, model = scara
    csv, js = tmp_path / "p2p.csv", tmp_path / "p2p.json"
    cli("--quiet", "excite", "scara", "--kind", "p2p", "-o", csv, "--duration", "3", "--via-points", "4",
        "--rate", "50", "--starts", "1", "--max-iter", "20", "--refine", "4", "--json", js, rc=0)
    out = json.loads(js.read_text())
    assert out["kind"] == "p2p" and out["limits_ok"] is True
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    n = model.N_JOINTS
    vias = np.asarray(out["design"]["via_points"])
    # at rest on every via-point (t = 0, 1, 2, 3 s), which are the design's positions
    idx = [0, 50, 100, 150]
    np.testing.assert_allclose(data[idx, 1:n + 1], vias, atol=1e-9)
    np.testing.assert_allclose(data[idx, n + 1:2 * n + 1], 0, atol=1e-9)


def test_cli_spline(cli, tmp_path, scara):
    _, model = scara
    csv, js = tmp_path / "spline.csv", tmp_path / "spline.json"
    cli("--quiet", "excite", "scara", "--kind", "spline", "-o", csv, "--duration", "3", "--coefficients", "10",
        "--structured-starts", "2", "--rate", "50", "--starts", "1", "--pool", "1", "--max-iter", "10",
        "--samples", "40", "--refine", "3", "--json", js, rc=0)
    out = json.loads(js.read_text())
    assert out["kind"] == "spline" and out["limits_ok"] is True
    st = out["starts"][0]
    assert st["refine_sdps"] >= 1 and out["cond"] == pytest.approx(min(st["cond_ipopt"], st["cond"]), rel=1e-12)
    assert out["cond"] <= st["cond_ipopt"]
    assert len(out["design"]["control_points"]) == 10
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    n = model.N_JOINTS
    assert data.shape == (151, 1 + 3 * n)
    # at rest at both ends
    np.testing.assert_allclose(data[[0, -1], n + 1:], 0, atol=1e-9)
    assert out["cond"] == pytest.approx(stacked_cond(model, data[:, 1:n + 1], data[:, n + 1:2 * n + 1],
                                                     data[:, 2 * n + 1:]), rel=1e-9)


def test_cli_refinement_without_cvxpy(cli, tmp_path, monkeypatch):
    """cvxpy is an extra: without it the default skips the refinement with a note, an explicit --refine is a
    one-line error naming the option, and nothing is written."""
    ex = importlib.import_module("symoro_gen.workflows.excite")  # the workflow looks has_cvxpy up there (the
    # module: `import symoro_gen.workflows.excite as ex` binds the function of the same name)

    monkeypatch.setattr(ex, "has_cvxpy", lambda: False)
    csv, js = tmp_path / "t.csv", tmp_path / "t.json"
    r = cli("excite", "scara", "-o", csv, "--duration", "4", "--harmonics", "3", "--rate", "50", "--starts", "1",
            "--pool", "1", "--max-iter", "5", "--json", js, rc=0)
    assert "refinement of the true cond was skipped" in r.out
    assert all("refine_sdps" not in st for st in json.loads(js.read_text())["starts"])
    r = cli("excite", "scara", "-o", tmp_path / "u.csv", "--refine", "3", rc=2)
    assert "--refine 3 needs cvxpy" in r.err and not (tmp_path / "u.csv").exists()


def test_cli_plot_without_matplotlib_fails_before_optimising(cli, tmp_path, monkeypatch):
    """matplotlib is an extra: --plot or --report without it is a one-line error naming the extra, said
    before the optimisation (which would run for minutes), with nothing written."""
    ex = importlib.import_module("symoro_gen.workflows.excite")  # the workflow looks optimise_excitation up there

    def never(*a, **k):
        raise AssertionError("the optimisation ran")

    monkeypatch.setattr(ex, "optimise_excitation", never)
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)  # its import fails
    for extra in (["--plot", tmp_path / "t.png"], ["--report", tmp_path / "t.html"]):
        r = cli("excite", "scara", "-o", tmp_path / "t.csv", *extra, rc=2)
        assert "matplotlib" in r.err and "plots" in r.err, r.err
        assert not list(tmp_path.iterdir())


def test_cli_report_html(cli, tmp_path, scara):
    """``excite --report``: one self-contained page with the trajectory plot, the cond of the CSV and the
    predicted sigma of every base parameter (those of the JSON, i.e. noise * sqrt(diag((W'W)^-1)))."""
    pytest.importorskip("matplotlib", reason="the report's plot needs matplotlib (the 'plots' extra)")
    import re

    _, model = scara
    csv, js, rep = tmp_path / "t.csv", tmp_path / "t.json", tmp_path / "t.html"
    # --effort thorough: the search this test was written for (the default quick one draws another figure, whose
    # base64 text happens to contain "http")
    cli("--quiet", "excite", "scara", "-o", csv, "--duration", "4", "--harmonics", "3", "--rate", "50", "--effort",
        "thorough", "--starts", "1", "--pool", "3", "--max-iter", "20", "--refine", "0", "--noise", "0.5", "--json", js,
        "--report", rep, rc=0)
    html = rep.read_text()
    out = json.loads(js.read_text())
    assert "data:image/png;base64," in html and "http" not in html.replace("http-equiv", "")
    assert f"cond = {out['cond']:.6g}" in html
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    n = model.N_JOINTS
    W = model.regressor(data[:, 1:n + 1], data[:, n + 1:2 * n + 1], data[:, 2 * n + 1:]).reshape(-1, len(model.BASE_NAMES))
    sig = 0.5 * np.sqrt(np.diag(np.linalg.inv(W.T @ W)))
    for name, s in zip(model.BASE_NAMES, sig):
        m = re.search(rf"<td>{name}</td><td[^>]*>[^<]*</td><td[^>]*>([^<]+)</td>", html)
        assert m is not None, name
        assert float(m.group(1)) == pytest.approx(s, rel=1e-3), name
    # a bad suffix is refused before the optimisation, and nothing is written
    r = cli("excite", "scara", "-o", tmp_path / "x.csv", "--report", tmp_path / "r.pdf", rc=None)
    assert r.rc != 0 and "unknown suffix" in r.err and not (tmp_path / "x.csv").exists()


def test_ipopt_starts_are_the_best_of_the_random_pool(scara, scara_limits, monkeypatch):
    """``pool`` random feasible designs are drawn; the ``starts`` of lowest cond start IPOPT."""
    import symoro_gen.excite.optimise as ex  # the pool of starts looks random_trajectory up there

    _, model = scara
    drawn = []
    real = ex.random_trajectory

    def recording(*a, **kw):
        X = real(*a, **kw)
        drawn.append(X)
        return X

    monkeypatch.setattr(ex, "random_trajectory", recording)
    basis = FourierBasis(3, 1 / DURATION)
    res = optimise_excitation(model, basis, scara_limits, DURATION, rate=RATE, starts=2, pool=7, seed=3, max_iter=1)
    assert len(drawn) == 7
    t = output_times(DURATION, RATE)
    conds = sorted(stacked_cond(model, *basis_eval(basis, X, t)) for X in drawn)
    np.testing.assert_allclose([s["cond_start"] for s in res.starts], conds[:2], rtol=1e-10)


# -- settings and efforts ----------------------------------------------------------------------------------------
def test_settings_are_checked_once_and_keywords_override_them(scara, scara_limits):
    """``ExciteSettings`` refuses a bad value when made (the error names the option); ``optimise_excitation`` takes
    a settings object, its fields as keywords, or both (the keywords win), with the same design either way."""
    import re

    from symoro_gen.excite import ExciteSettings, RefineSettings

    for bad, option in (({"starts": 0}, "--starts 0"), ({"jobs": -1}, "--jobs -1"), ({"refine": -2}, "--refine -2"),
                        ({"criterion": "trace"}, "--criterion 'trace'"), ({"powers": (8, 12)}, "power 12")):
        with pytest.raises(ExcitationError, match=re.escape(option)):
            ExciteSettings(**bad)
    with pytest.raises(ExcitationError, match="--refine -1"):
        RefineSettings(iterations=-1)
    assert ExciteSettings(powers=[8, 64]).powers == (8, 64) and ExciteSettings().stages == excite.COND_POWERS
    assert ExciteSettings(criterion="logdet", powers=(16,)).stages == (excite.COND_POWER,)
    _, model = scara
    basis = FourierBasis(3, 1 / DURATION)
    kw = dict(starts=1, pool=2, seed=4, max_iter=5, powers=(8,))
    a = optimise_excitation(model, basis, scara_limits, DURATION, ExciteSettings(**kw), rate=RATE)
    b = optimise_excitation(model, basis, scara_limits, DURATION, rate=RATE, **kw)
    c = optimise_excitation(model, basis, scara_limits, DURATION, ExciteSettings(**{**kw, "seed": 9}), rate=RATE, seed=4)
    assert np.array_equal(a.X, b.X) and np.array_equal(a.X, c.X) and a.cond == b.cond == c.cond
    with pytest.raises(TypeError):
        optimise_excitation(model, basis, scara_limits, DURATION, no_such_setting=1)


def _excite_args(*argv: str):
    import argparse

    from symoro_gen.commands.excite import add_parser

    ap = argparse.ArgumentParser()
    add_parser(ap.add_subparsers())
    return ap.parse_args(["excite", "scara", "-o", "x.csv", *argv])


def test_the_command_runs_the_quick_effort_unless_told_and_options_override_it(monkeypatch):
    """Without options the command runs ``--effort quick``; ``--effort thorough`` is what the command ran before
    (4 starts, the best of 40 random designs, IPOPT with p = 8 then 64 at most 200 iterations each, 20 SDPs);
    ``--starts``, ``--pool``, ``--max-iter`` and ``--refine`` override the effort's value."""
    excite_workflow = importlib.import_module("symoro_gen.workflows.excite")
    from symoro_gen.commands.excite import options_from_args
    from symoro_gen.excite import EFFORTS, ExciteSettings

    def settings_of(args):
        return options_from_args(args).settings()

    monkeypatch.setattr(excite_workflow, "has_cvxpy", lambda: True)
    quick, _ = settings_of(_excite_args())
    assert quick == ExciteSettings(**EFFORTS["quick"]) and quick.starts == 1 and quick.refine > 0
    thorough, _ = settings_of(_excite_args("--effort", "thorough"))
    assert thorough == ExciteSettings(starts=4, pool=None, max_iter=200, powers=(8, 64), refine=20)
    mixed, _ = settings_of(_excite_args("--effort", "thorough", "--starts", "2", "--refine", "0",
                                                   "--max-iter", "50", "--seed", "3", "--jobs", "2"))
    assert (mixed.starts, mixed.refine, mixed.max_iter, mixed.powers, mixed.seed, mixed.jobs) == (2, 0, 50, (8, 64), 3, 2)
    more, _ = settings_of(_excite_args("--starts", "8"))
    assert more.starts == 8 and more.pool == 80  # at least 10 per start, as the thorough effort draws
    monkeypatch.setattr(excite_workflow, "has_cvxpy", lambda: False)
    skipped, note = settings_of(_excite_args())
    assert skipped.refine == 0 and "skipped" in (note or "")
