"""Session fixtures: regressors of rx90 and lwr4 at random states (numeric Newton-Euler, slow,
computed once), with plausible random parameters and a payload with sizeable first moments."""
import pytest

from .simdata import make_robot_sim

#: payload of the RX-90 tests (7.025 kg as Table 2, with sizeable MX/MY/MZ so that the wrist
#: joints feel it) and of the LWR4 tests (4.6136 kg, Sec. IV-B)
RX90_PAYLOAD = dict(payload_mass=7.025, payload_com=(0.10, -0.08, 0.14))
LWR4_PAYLOAD = dict(payload_mass=4.6136, payload_com=(0.09, -0.10, 0.15))


@pytest.fixture(scope="session")
def rx90_sim():
    return make_robot_sim("rx90", 400, 400, seed=11, **RX90_PAYLOAD)


@pytest.fixture(scope="session")
def lwr4_sim():
    return make_robot_sim("lwr4", 400, 400, seed=12, **LWR4_PAYLOAD)
