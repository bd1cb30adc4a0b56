"""Property tests over random MDH robots: numeric Newton-Euler and the symbolic graph == Pinocchio."""
from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, find, given, settings
from hypothesis import strategies as st

from symoro_gen.description import parse_robot_text
from symoro_gen.dynamics.newton_euler import build_regressor
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.simulate import random_states
from tests.strategies import mdh_robots

from .graph_eval import graph_function
from .pinocchio_model import max_relative_error, pin_torque, random_parameters

RTOL = 1e-9
SEEDS = st.integers(0, 2**32 - 1)


def _states(rng, n, N=6):
    return random_states(rng, N, n)


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(text=mdh_robots(2, 7, random_gravity=True), seed=SEEDS)
def test_numeric_newton_euler_matches_pinocchio_on_random_robots(text, seed):
    robot = parse_robot_text(text)
    rng = np.random.default_rng(seed)
    chi, pay = random_parameters(robot, rng)
    q, dq, ddq = _states(rng, robot.n_joints)
    ours = inverse_dynamics(robot, q, dq, ddq, chi, pay)
    assert max_relative_error(ours, pin_torque(robot, q, dq, ddq, chi, pay)) < RTOL


@settings(max_examples=6, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(text=mdh_robots(2, 4, random_gravity=True), seed=SEEDS)
def test_symbolic_graph_matches_pinocchio_on_random_robots(text, seed):
    robot = parse_robot_text(text)
    rng = np.random.default_rng(seed)
    q, dq, ddq = _states(rng, robot.n_joints)
    W, Wp = graph_function(build_regressor(robot))(q, dq, ddq)
    chi, pay = random_parameters(robot, rng)
    tau = W @ chi + (Wp @ pay if pay is not None else 0.0)
    assert max_relative_error(tau, pin_torque(robot, q, dq, ddq, chi, pay)) < RTOL


FEATURES = {
    "prismatic joint": lambda t: "sigma = 1" in t,
    "-q direction": lambda t: '"-q' in t,
    "theta offset": lambda t: re.search(r'theta = "-?q [+-] ', t) is not None,
    "arbitrary alpha": lambda t: re.search(r'alpha = "-?\d', t) is not None and 'alpha = "0"' not in t,
    "symbolic length": lambda t: "[values]" in t,
    "gamma and b": lambda t: "gamma = " in t and 'b = "B' in t,
    "payload": lambda t: "payload = " in t,
    "drive subset": lambda t: "drive = [" in t,
    "empty drive": lambda t: "drive = []" in t,
    "seven joints": lambda t: "j = 7\nant = 6\nsigma = 0" in t or "j = 7\nant = 6\nsigma = 1" in t,
    "non-vertical gravity": lambda t: "gravity = [0, 0, -9.81]" not in t,
}


@pytest.mark.parametrize("feature", sorted(FEATURES))
def test_strategy_reaches_every_feature(feature):
    """The strategy can produce each construct the robot-file format allows (and it parses)."""
    text = find(
        mdh_robots(random_gravity=True),
        FEATURES[feature],
        settings=settings(max_examples=2000, database=None, phases=[Phase.generate], suppress_health_check=list(HealthCheck)),
    )
    robot = parse_robot_text(text)
    assert 2 <= robot.n_joints <= 7
