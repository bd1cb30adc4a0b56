"""The palletizer (robots/palletizer.toml, a parallelogram on joints 2-3): loop closure, projection,
base parameters and identification on simulated data with known truth."""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen import load_model
from symoro_gen.closedloop import ClosedLoopModel
from symoro_gen.description import load_robot
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.identification import ObservationSystem
from symoro_gen.identification.estimators import fit_ols
from symoro_gen.simulate.parameters import random_physical_parameters


@pytest.fixture(scope="module")
def pal():
    robot = load_robot("palletizer")
    model = load_model("palletizer")
    assert isinstance(model, ClosedLoopModel)
    return robot, model


def states(rng, N, span=0.6):
    """Actuated states inside the parallelogram's non-singular range (|q5 - q2| < pi/2)."""
    q = rng.uniform(-span, span, (N, 4))
    return q, rng.normal(0, 1.5, (N, 4)), rng.normal(0, 4, (N, 4))


def test_parallelogram_closed_form_and_residual(pal):
    """q3 = q5 - q2, q6 = q2 - q5, q7 = q5 - q2 (the offsets of the file make the reference zero), and
    the same for velocities and accelerations; residual at the level of rounding."""
    robot, model = pal
    rng = np.random.default_rng(1)
    q, dq, ddq = states(rng, 60)
    st = model.closure(q, dq, ddq)
    assert st.residual.max() < 1e-12
    for a, x in ((q, st.q), (dq, st.dq), (ddq, st.ddq)):
        np.testing.assert_allclose(x[:, [0, 1, 3, 4]], a, atol=0)
        np.testing.assert_allclose(x[:, 2], a[:, 3] - a[:, 1], atol=1e-10)
        np.testing.assert_allclose(x[:, 5], a[:, 1] - a[:, 3], atol=1e-10)
    np.testing.assert_allclose(st.q_cut[:, 0], q[:, 3] - q[:, 1], atol=1e-10)


def test_velocity_and_acceleration_are_the_derivatives_of_the_closure(pal):
    """Along a smooth motion of the actuated joints, the solved passive velocities and accelerations
    are the time derivatives of the solved passive positions (central differences)."""
    robot, model = pal
    t = np.linspace(0, 1, 2001)
    w = np.array([1.3, 2.1, 0.7, 1.7])
    q = 0.5 * np.sin(np.outer(t, w) + [0.1, 0.5, 0.9, 1.3])
    dq = 0.5 * w * np.cos(np.outer(t, w) + [0.1, 0.5, 0.9, 1.3])
    ddq = -0.5 * w**2 * np.sin(np.outer(t, w) + [0.1, 0.5, 0.9, 1.3])
    st = model.kinematics.solve(q, dq, ddq)
    h = t[1] - t[0]
    np.testing.assert_allclose((st.q[2:] - st.q[:-2]) / (2 * h), st.dq[1:-1], atol=1e-5)
    np.testing.assert_allclose((st.dq[2:] - st.dq[:-2]) / (2 * h), st.ddq[1:-1], atol=1e-5)


def test_projected_torque_equals_numeric_newton_euler_of_the_tree(pal):
    """tau_a = G^T tau_tree with the tree torques of the independent numeric Newton-Euler
    (symoro_gen.dynamics.numeric) at the closed state: the generated tree regressor and the regrouping
    of the closed loop reproduce them."""
    robot, model = pal
    rng = np.random.default_rng(2)
    q, dq, ddq = states(rng, 50)
    chi = np.asarray(random_physical_parameters(robot, rng))
    st = model.closure(q, dq, ddq)
    tau_tree = inverse_dynamics(robot, st.q, st.dq, st.ddq, chi)
    ref = np.einsum("nta,nt->na", st.G, tau_tree)
    np.testing.assert_allclose(model.torque(q, dq, ddq, chi), ref, atol=1e-9 * np.abs(ref).max())
    # the passive joints carry no torque in the projection: G's actuated rows are the identity
    np.testing.assert_array_equal(st.G[:, [0, 1, 3, 4], :], np.broadcast_to(np.eye(4), (50, 4, 4)))


def test_base_count_equals_numeric_rank_and_the_loop_groupings(pal):
    robot, model = pal
    rng = np.random.default_rng(3)
    q, dq, ddq = states(rng, 150)
    Ws = model.standard_regressor(q, dq, ddq).reshape(-1, len(model.STANDARD_NAMES))
    norms = np.linalg.norm(Ws, axis=0)
    live = norms > 1e-10 * norms.max()  # columns that are zero up to rounding are not scaled up
    s = np.linalg.svd(Ws[:, live] / norms[live], compute_uv=False)
    assert int(np.sum(s > 1e-9 * s[0])) == len(model.BASE_NAMES) == 38
    Wb = model.regressor(q, dq, ddq).reshape(-1, len(model.BASE_NAMES))
    assert np.linalg.matrix_rank(Wb) == len(model.BASE_NAMES)
    chi = rng.normal(size=len(model.STANDARD_NAMES))
    np.testing.assert_allclose(Wb @ model.base_parameters(chi), Ws @ chi, atol=1e-9)
    # the parallelogram: the rod (link 6) turns with the upper arm (link 2), the crank (link 5) with the
    # forearm (link 3), so their inertias regroup there (Khalil & Bennis 1995)
    text = model.base_parameters_text()
    K = dict(zip(model.BASE_NAMES, model.base.K))
    for g in ("ZZ2R = ZZ2R + 1 ZZ6", "ZZ3R = ZZ3R + 1 ZZ5R", "XX2R = XX2R + 1 XX6R"):
        assert g in text
    # the rod's first moment: the parallelogram's side ratio, recognised as a closed form
    assert "MX5R = MX5R - 0.318181818182 [= L5/D3] MX6" in text
    assert K["MX5R"][model.STANDARD_NAMES.index("MX6")] == pytest.approx(-0.35 / 1.1, abs=1e-12)
    assert K["ZZ3R"][model.STANDARD_NAMES.index("IA5")] == pytest.approx(1.0)  # motor 5 turns with the forearm


def test_identification_on_simulated_data_recovers_the_base_parameters(pal):
    """OLS on a simulated exciting motion with known truth and noise: every base parameter within
    3 standard deviations (the torques come from the numeric Newton-Euler of the tree, projected)."""
    robot, model = pal
    rng = np.random.default_rng(11)
    t = np.arange(0, 20, 0.01)
    n = 4
    q = np.zeros((t.size, n))
    dq, ddq = np.zeros_like(q), np.zeros_like(q)
    for k in range(1, 6):  # a 5-harmonic Fourier motion per joint (Swevers 1997), |q| < 0.6 rad
        wk = 2 * np.pi * 0.1 * k
        a, b = rng.uniform(-0.12, 0.12, (2, n)) / k
        q += np.sin(wk * t)[:, None] * a - np.cos(wk * t)[:, None] * b
        dq += wk * (np.cos(wk * t)[:, None] * a + np.sin(wk * t)[:, None] * b)
        ddq += wk**2 * (-np.sin(wk * t)[:, None] * a + np.cos(wk * t)[:, None] * b)
    chi = np.asarray(random_physical_parameters(robot, rng))
    st = model.closure(q, dq, ddq)
    tau = np.einsum("nta,nt->na", st.G, inverse_dynamics(robot, st.q, st.dq, st.ddq, chi))
    sigma = np.array([0.5, 0.5, 0.1, 0.3])
    Y = tau + rng.normal(size=tau.shape) * sigma
    W = model.regressor(q, dq, ddq)
    system = ObservationSystem(np.transpose(W, (1, 0, 2)).reshape(-1, W.shape[2]), Y.T.reshape(-1),
                               model.BASE_NAMES, np.repeat(np.arange(n), t.size))
    res = fit_ols(system)
    truth = model.base_parameters(chi)
    z = (res.values - truth) / res.std
    assert np.all(np.abs(z) < 3.0), dict(zip(model.BASE_NAMES, np.round(z, 2)))
