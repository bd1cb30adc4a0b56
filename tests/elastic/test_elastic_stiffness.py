"""K and D of declared elastic joints from a simulated two-encoder log: tau from the rigid dynamics of a known
model (numeric Newton-Euler), the motor side q_m/N = q + delta with K delta + D d(delta)/dt = tau (Spong 1987),
read back through the log reader (q_link column) and ``identify``."""
import json

import numpy as np
import pytest
from scipy import signal

from symoro_gen.description.parse import parse_robot_text
from symoro_gen.errors import OptionError
from symoro_gen.identification.elastic import estimate_stiffness, link_side
from symoro_gen.preprocessing.readers.options import make_format
from symoro_gen.simulate import fourier_trajectory
from symoro_gen.simulate.recording import true_torques

K_TRUE = (4000.0, 2500.0)
D_TRUE = (15.0, 6.0)

ROBOT = """
name = "arm2e"
drive = ["FV"]

[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = 0
elastic = {{K = {k1}, D = {d1}}}

[[frames]]
j = 2
ant = 1
sigma = 0
alpha = "pi/2"
d = 0.3
theta = "q"
r = 0
elastic = {{K = {k2}, D = {d2}}}

[nominal]
ZZ1 = 0.4
M1 = 3.0
XX2 = 0.02
YY2 = 0.45
ZZ2 = 0.44
MX2 = 0.9
M2 = 2.5
FV1 = 1.5
FV2 = 0.8
"""


def _robot(k=K_TRUE, d=D_TRUE):
    return parse_robot_text(ROBOT.format(k1=k[0], k2=k[1], d1=d[0], d2=d[1]), file="arm2e.toml")


def two_encoder_log(robot, seed=0, duration=6.0, dt=0.001, noise_tau=0.05):
    """``t, q_motor/N, tau measured, q_link`` of a simulated elastic arm (true K, D of ``robot``)."""
    rng = np.random.default_rng(seed)
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, duration, dt, rng, amplitude=1.0, vmax=2.0, amax=12.0)
    tau = true_torques(robot, q, dq, ddq, np.asarray(robot.nominal_vector()))
    delta = np.empty_like(tau)
    for i, e in enumerate(robot.elastic):  # D d' + K d = tau, from rest at the static deflection
        sys = signal.StateSpace([[-e.K / e.D]], [[1.0 / e.D]], [[1.0]], [[0.0]])
        _, y, _ = signal.lsim(sys, tau[:, i], t, X0=[tau[0, i] / e.K])
        delta[:, i] = y
    return t, q + delta, tau + noise_tau * rng.normal(size=tau.shape), q, delta, tau


def test_deflection_from_the_simulation_obeys_the_spring_law():
    """The simulated deflection itself: K delta + D d(delta)/dt = tau (independent of the estimator)."""
    robot = _robot()
    t, _, _, _, delta, tau = two_encoder_log(robot, noise_tau=0.0)
    for i, e in enumerate(robot.elastic):
        r = e.K * delta[:, i] + e.D * np.gradient(delta[:, i], t) - tau[:, i]
        assert np.linalg.norm(r[5:-5]) < 1e-3 * np.linalg.norm(tau[:, i])


def test_stiffness_and_damping_recovered_through_identify(tmp_path):
    robot = _robot()
    t, qm, tau, ql, _, _ = two_encoder_log(robot)
    csv = tmp_path / "encoders.csv"
    head = "t,qm0,qm1,tau0,tau1,ql0,ql1"
    np.savetxt(csv, np.column_stack([t, qm, tau, ql]), delimiter=",", header=head, comments="", fmt="%.12g")
    f = tmp_path / "arm2e.toml"
    # the declared K, D are not what is estimated: declare other values, the estimate must find the true ones
    f.write_text(ROBOT.format(k1=1000.0, k2=1000.0, d1=0.0, d2=0.0))
    from symoro_gen.workflows.identify import identify

    fmt = make_format(columns="t=t,q=qm0:qm1,tau=tau0:tau1,q_link=ql0:ql1")
    res = identify(str(f), [csv], method="ols", data_format=fmt)
    est = res.elasticity
    assert est is not None and est.joints == (1, 2)
    for i in range(2):
        assert abs(est.K[i] - K_TRUE[i]) < max(4 * est.K_std[i], 0.005 * K_TRUE[i]), (est.K, est.K_std)
        assert abs(est.K[i] - K_TRUE[i]) < 0.01 * K_TRUE[i], est.K
        # D rests on the small deflection rate: within 4 sigma of the truth, sigma a fraction of D
        assert abs(est.D[i] - D_TRUE[i]) < 4 * est.D_std[i], (est.D, est.D_std)
        assert 0 < est.K_std[i] < 0.01 * K_TRUE[i] and 0 < est.D_std[i] < 0.15 * D_TRUE[i]
    assert est.declared_K == (1000.0, 1000.0)
    full = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    from tests.docs.test_schemas import check

    check(full, "identify")  # docs/schemas/identify.schema.json, with the elasticity block
    d = full["elasticity"]
    assert [j["joint"] for j in d["joints"]] == [1, 2]
    assert d["joints"][0]["K"] == pytest.approx(est.K[0])
    assert "Joint stiffness" in res.summary()
    # the model used the link side: the rigid model fits the torque (FV and inertia), not the motor side
    assert max(res.result.rel_err) < 0.05


def test_errors_without_elastic_joint_or_deflection():
    robot = _robot()
    t, qm, tau, _, _, _ = two_encoder_log(robot, duration=1.0)
    from symoro_gen.preprocessing.trajectory import Trajectory

    tr = Trajectory(t=t, q=qm, tau=tau, source="motor.csv")
    with pytest.raises(OptionError, match="no recording has a link-side position"):
        estimate_stiffness(robot, [tr])
    rigid = parse_robot_text(ROBOT.replace("elastic = {{K = {k1}, D = {d1}}}", "")
                             .replace("elastic = {{K = {k2}, D = {d2}}}", ""), file="rigid.toml")
    with pytest.raises(OptionError, match=r"rigid\.toml.*no elastic joint"):
        estimate_stiffness(rigid, [tr])
    two = Trajectory(t=t, q=qm, tau=tau, deflection=qm - qm, source="two.csv")
    with pytest.raises(OptionError, match=r"two\.csv has a link-side position"):
        link_side(robot, [two])
