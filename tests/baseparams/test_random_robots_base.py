"""Property tests over random serial MDH robots: the whole generator pipeline.

For every drawn robot: emitted regressor == numeric Newton-Euler; base regressor x base
parameters == standard regressor x standard parameters (with the closed-form relations);
number of base parameters == numeric rank of the standard regressor.
"""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from symoro_gen.baseparams.regroup import numeric_rank
from symoro_gen.description import parse_robot_text
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.emit.package import build_in_memory
from symoro_gen.simulate import random_states
from tests.strategies import mdh_robots

REL = 1e-9


def _states(rng, n, N):
    return random_states(rng, N, n)


@pytest.mark.slow
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=mdh_robots(2, 7))
def test_pipeline_identities_on_random_robots(text):
    robot = parse_robot_text(text, file="random.toml")
    m = build_in_memory(robot)  # the emitter's optimised NumPy kernels, without files
    rng = np.random.default_rng(0)
    n = robot.n_joints
    q, dq, ddq = _states(rng, n, 25)
    chi = rng.normal(size=len(m.STANDARD_NAMES))
    pay = rng.normal(size=len(m.PAYLOAD_NAMES)) if m.PAYLOAD_NAMES else None
    ref = inverse_dynamics(robot, q, dq, ddq, chi, pay)
    tau = m.torque(q, dq, ddq, chi, pay)
    assert np.max(np.abs(tau - ref)) <= REL * max(1.0, np.abs(ref).max())
    Ws = m.standard_regressor(q, dq, ddq)
    Wb = m.regressor(q, dq, ddq)
    assert np.max(np.abs(Wb @ m.base_parameters(chi) - Ws @ chi)) <= REL * max(1.0, np.abs(Ws @ chi).max())
    q, dq, ddq = _states(rng, n, 80)
    Ws = m.standard_regressor(q, dq, ddq).reshape(-1, len(m.STANDARD_NAMES))
    assert numeric_rank(Ws) == len(m.BASE_NAMES), text
