"""Motor side <-> joint side mapping (DriveChain convention, TX40 wrist coupling)."""
from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from symoro_gen.description import parse_robot_text
from symoro_gen.description.model import DriveChain
from symoro_gen.preprocessing.drive_chain import chain_matrix, joint_to_motor, motor_to_joint

TX40_TOML = """
name = "tx40chain"
[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = 0
[[frames]]
j = 2
ant = 1
sigma = 0
alpha = "-pi/2"
d = 0
theta = "q"
r = 0
[[frames]]
j = 3
ant = 2
sigma = 0
alpha = 0
d = 0.225
theta = "q"
r = 0.035
[[frames]]
j = 4
ant = 3
sigma = 0
alpha = "pi/2"
d = 0
theta = "q"
r = 0.225
[[frames]]
j = 5
ant = 4
sigma = 0
alpha = "-pi/2"
d = 0
theta = "q"
r = 0
[[frames]]
j = 6
ant = 5
sigma = 0
alpha = "pi/2"
d = 0
theta = "q"
r = 0
[drive_chain]
ratios = [32, 32, 45, -48, 45, 32]
coupling = [[1,0,0,0,0,0],[0,1,0,0,0,0],[0,0,1,0,0,0],[0,0,0,1,0,0],[0,0,0,0,1,0],[0,0,0,0,1,1]]
offsets = [0, -1.5707963267948966, 1.5707963267948966, 0, 0, 0]
"""


def test_tx40_wrist_coupling_from_a_robot_file():
    """The TX40 numbers of figaroh's TX40_config.yaml: motor 6 turns as 32 (q5 + q6), tau5 = 45 tm5 + 32 tm6."""
    chain = parse_robot_text(TX40_TOML).drive_chain
    q = np.array([[0.1, 0.2, -0.3, 0.4, 0.5, -0.6]])
    qm, _, _, _ = joint_to_motor(chain, q=q)
    assert math.isclose(qm[0, 5], 32 * (0.5 - 0.6))
    assert math.isclose(qm[0, 3], -48 * 0.4)
    assert math.isclose(qm[0, 1], 32 * (0.2 + math.pi / 2))  # q2 = q2_motor/32 - pi/2
    assert math.isclose(qm[0, 2], 45 * (-0.3 - math.pi / 2))
    tm = np.array([[0.1, -0.2, 0.3, 0.05, 0.2, -0.1]])
    _, tau, _, _ = motor_to_joint(chain, tau_motor=tm)
    np.testing.assert_allclose(tau[0], [3.2, -6.4, 13.5, -2.4, 45 * 0.2 + 32 * -0.1, 32 * -0.1])
    # staubli zero pose of the recording: motor 2 at 16 pi, motor 3 at -22.5 pi  ->  MDH q = 0
    q0, _, _, _ = motor_to_joint(chain, q_motor=np.array([[0, 16 * math.pi, -22.5 * math.pi, 0, 0, 0]]))
    np.testing.assert_allclose(q0, 0.0, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 6), seed=st.integers(0, 2**16))
def test_roundtrip_and_power_balance(n, seed):
    rng = np.random.default_rng(seed)
    C = np.eye(n) + np.triu(rng.uniform(-1, 1, (n, n)) * (rng.uniform(size=(n, n)) < 0.3), 1)
    chain = DriveChain(ratios=tuple(rng.choice([-1, 1], n) * rng.uniform(5, 100, n)),
                       coupling=tuple(map(tuple, C)), offsets=tuple(rng.uniform(-2, 2, n)),
                       directions=tuple(rng.choice([-1.0, 1.0], n)))
    q, tau, dq, ddq = (rng.standard_normal((7, n)) for _ in range(4))
    qm, taum, dqm, ddqm = joint_to_motor(chain, q, tau, dq, ddq)
    back = motor_to_joint(chain, qm, taum, dqm, ddqm)
    for a, b in zip((q, tau, dq, ddq), back):
        np.testing.assert_allclose(b, a, atol=1e-9 * max(1, np.abs(a).max()))
    # the mapping is a change of coordinates of the same mechanical power
    np.testing.assert_allclose(np.sum(tau * dq, axis=1), np.sum(taum * dqm, axis=1), rtol=1e-9, atol=1e-9)
    # velocities map through R D
    np.testing.assert_allclose(dqm, (dq * np.asarray(chain.directions)) @ chain_matrix(chain).T, rtol=1e-12)
