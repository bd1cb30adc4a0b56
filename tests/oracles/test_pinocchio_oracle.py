"""Numeric Newton-Euler and the symbolic regressor graph against Pinocchio (independent oracle)."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.dynamics.newton_euler import build_regressor
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.simulate import random_states

from .graph_eval import graph_function
from .pinocchio_model import (
    build_pinocchio_model,
    inertia_to_standard,
    max_relative_error,
    pin_torque,
    random_inertial,
    random_parameters,
    standard_to_inertia,
)

RTOL = 1e-9
ROBOTS = ("lwr4", "rx90", "scara")
N_SAMPLES = 8


def _states(rng: np.random.Generator, n: int, N: int = N_SAMPLES):
    return random_states(rng, N, n)


@functools.cache
def _graph(name: str):
    return graph_function(build_regressor(load_robot(name)))


# ---- the oracle itself ----------------------------------------------------------------
def test_inertia_conversion_matches_point_masses():
    """standard (frame origin) -> pin.Inertia: a cloud of point masses, summed directly, gives the
    mass, centre of mass and inertia about it that Pinocchio reports (and back)."""
    rng = np.random.default_rng(1)
    for _ in range(5):
        m = rng.uniform(0.1, 2.0, 7)
        r = rng.normal(scale=0.3, size=(7, 3)) + rng.normal(scale=0.2, size=3)
        J_O = sum(mi * (ri @ ri * np.eye(3) - np.outer(ri, ri)) for mi, ri in zip(m, r))
        MS = (m[:, None] * r).sum(0)
        p = [J_O[0, 0], J_O[0, 1], J_O[0, 2], J_O[1, 1], J_O[1, 2], J_O[2, 2], *MS, m.sum()]
        ours = standard_to_inertia(p)
        c = MS / m.sum()
        I_c = sum(mi * ((ri - c) @ (ri - c) * np.eye(3) - np.outer(ri - c, ri - c)) for mi, ri in zip(m, r))
        np.testing.assert_allclose(ours.mass, m.sum(), rtol=1e-14)
        np.testing.assert_allclose(ours.lever, c, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(ours.inertia, I_c, rtol=1e-10, atol=1e-13)
        np.testing.assert_allclose(inertia_to_standard(ours), p, rtol=1e-12, atol=1e-14)
    p = random_inertial(rng)
    np.testing.assert_allclose(inertia_to_standard(standard_to_inertia(p)), p, rtol=1e-12, atol=1e-14)


def test_oracle_pendulum_closed_form():
    """One revolute joint about -y0 (alpha = pi/2): tau = ZZ1 ddq + m g l cos q (+ drive terms)."""
    robot = parse_robot_text(
        'name = "pendulum"\ngravity = [0, 0, -9.81]\n'
        '[[frames]]\nj = 1\nant = 0\nsigma = 0\nalpha = "pi/2"\nd = 0\ntheta = "q"\nr = 0\n'
    )
    m, l, zz = 2.0, 0.3, 0.5
    vals = {"M1": m, "MX1": m * l, "ZZ1": zz, "XX1": 0.1, "YY1": 0.4, "FV1": 0.7, "FS1": 0.2, "OFF1": -0.3, "IA1": 0.05}
    chi = np.array([vals.get(n, 0.0) for n in robot.standard_names])
    q = np.array([[0.3], [-1.2], [2.0]])
    dq = np.array([[0.5], [-0.4], [1.0]])
    ddq = np.array([[1.5], [0.2], [-3.0]])
    expected = (zz + 0.05) * ddq + m * 9.81 * l * np.cos(q) + 0.7 * dq + 0.2 * np.sign(dq) - 0.3
    np.testing.assert_allclose(pin_torque(robot, q, dq, ddq, chi), expected, rtol=1e-12)
    np.testing.assert_allclose(inverse_dynamics(robot, q, dq, ddq, chi), expected, rtol=1e-12)


def test_oracle_negative_joint_is_mirrored_positive_joint():
    """A '-q' joint is the '+q' joint driven by -q: tau(-q robot; q) = -tau(+q robot; -q)."""
    base = (
        'name = "two"\n'
        '[[frames]]\nj = 1\nant = 0\nsigma = 0\nalpha = 0\nd = 0\ntheta = "{t1}"\nr = 0\n'
        '[[frames]]\nj = 2\nant = 1\nsigma = 1\nalpha = "pi/2"\nd = 0.3\ntheta = 0.4\nr = "{r2}"\n'
    )
    pos = parse_robot_text(base.format(t1="q", r2="q"))
    neg = parse_robot_text(base.format(t1="-q", r2="-q"))
    rng = np.random.default_rng(2)
    chi, _ = random_parameters(pos, rng)
    chi[[n.startswith(("FS", "OFF")) for n in pos.standard_names]] = 0.0  # odd-symmetric drive terms only
    q, dq, ddq = _states(rng, 2)
    np.testing.assert_allclose(pin_torque(neg, q, dq, ddq, chi), -pin_torque(pos, -q, -dq, -ddq, chi), rtol=1e-12, atol=1e-12)
    assert max_relative_error(pin_torque(neg, q, dq, ddq, chi), pin_torque(pos, q, dq, ddq, chi)) > 1e-3


def test_oracle_gravity_comes_from_robot_file():
    robot = load_robot("scara")
    model, _ = build_pinocchio_model(robot, np.zeros(len(robot.standard_names)))
    np.testing.assert_array_equal(model.gravity.linear, np.asarray(robot.gravity))
    assert model.nq == model.nv == robot.n_joints


# ---- numeric Newton-Euler == Pinocchio ----------------------------------------------------
@pytest.mark.parametrize("name", ROBOTS)
def test_numeric_newton_euler_matches_pinocchio(name):
    robot = load_robot(name)
    rng = np.random.default_rng(100 + ROBOTS.index(name))
    for _ in range(3):
        chi, pay = random_parameters(robot, rng)
        q, dq, ddq = _states(rng, robot.n_joints)
        ours = inverse_dynamics(robot, q, dq, ddq, chi, pay)
        ref = pin_torque(robot, q, dq, ddq, chi, pay)
        assert max_relative_error(ours, ref) < RTOL
        if pay is not None:  # the payload matters: leaving it out changes the torques
            assert max_relative_error(inverse_dynamics(robot, q, dq, ddq, chi), ref) > 1e-3


@pytest.mark.parametrize("name", ROBOTS)
def test_symbolic_regressor_graph_matches_pinocchio(name):
    robot = load_robot(name)
    evaluate = _graph(name)
    rng = np.random.default_rng(7 + len(name))
    q, dq, ddq = _states(rng, robot.n_joints)
    W, Wp = evaluate(q, dq, ddq)
    assert W.shape == (N_SAMPLES, robot.n_joints, len(robot.standard_names))
    for _ in range(3):
        chi, pay = random_parameters(robot, rng)
        tau = W @ chi + (Wp @ pay if pay is not None else 0.0)
        assert max_relative_error(tau, pin_torque(robot, q, dq, ddq, chi, pay)) < RTOL


@pytest.mark.parametrize("name", ROBOTS)
def test_symbolic_graph_matches_numeric_regressor_columnwise(name):
    """Column by column (also parameters Pinocchio cannot hold alone, e.g. a lone MX)."""
    from symoro_gen.dynamics.numeric import numeric_regressor

    robot = load_robot(name)
    rng = np.random.default_rng(11)
    q, dq, ddq = _states(rng, robot.n_joints, N=4)
    W, Wp = _graph(name)(q, dq, ddq)
    A, Ap = numeric_regressor(robot, q, dq, ddq)
    assert max_relative_error(W, A) < RTOL
    if Ap.size:
        assert max_relative_error(Wp, Ap) < RTOL
