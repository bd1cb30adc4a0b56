"""Random physical parameters are those of rigid bodies; synthetic recordings carry the given truth."""
from __future__ import annotations

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.params import INERTIAL_KINDS
from symoro_gen.preprocessing import load_trajectory
from symoro_gen.simulate import (
    check_physical_consistency,
    fourier_trajectory,
    numeric_model,
    random_payload,
    random_physical_parameters,
    simulate_recording,
    true_torques,
    write_recording_csv,
)


def _link(ps, j):
    return np.array([ps[f"{k}{j}"] for k in INERTIAL_KINDS])


@pytest.mark.parametrize("name", ["lwr4", "rx90", "scara"])
def test_random_parameters_are_physical(name):
    robot = load_robot(name)
    rng = np.random.default_rng(11)
    for _ in range(5):
        ps = random_physical_parameters(robot, rng, mass_range=(1.0, 8.0))
        assert ps.names == robot.standard_names
        for row in robot.joints:
            p = _link(ps, row.j)
            assert check_physical_consistency(p) == []
            assert 1.0 <= p[-1] <= 8.0
        for nm in ps.names:
            if nm.startswith(("FV", "FS", "IA")):
                assert ps[nm] > 0
        # an independent consequence: the joint-space inertia matrix is positive definite
        q = rng.uniform(-np.pi, np.pi, robot.n_joints)
        z = np.zeros(robot.n_joints)
        chi = np.asarray(ps)
        base = inverse_dynamics(robot, q, z, z, chi)
        M = np.column_stack([inverse_dynamics(robot, q, z, e, chi) - base for e in np.eye(robot.n_joints)])
        np.testing.assert_allclose(M, M.T, atol=1e-10)
        assert np.linalg.eigvalsh(M).min() > 0


def test_consistency_checker_rejects_non_physical_values():
    good = np.array([0.1, 0.0, 0.0, 0.1, 0.0, 0.1, 0.0, 0.0, 0.0, 2.0])
    assert check_physical_consistency(good) == []
    massless = good.copy()
    massless[9] = -1.0
    assert "mass" in check_physical_consistency(massless)[0]
    flat = good.copy()
    flat[[0, 3]] = 0.01  # I_zz = 0.1 > 0.01 + 0.01: triangle inequality violated
    assert any("triangle" in m for m in check_physical_consistency(flat))
    neg = good.copy()
    neg[0] = -0.1
    assert any("positive definite" in m for m in check_physical_consistency(neg))
    # the first moment shifts the inertia: a far centre of mass with a tiny J at the origin is impossible
    far = good.copy()
    far[6] = 2.0 * 1.0  # c = 1 m with J_O = 0.1 kg m^2 < M c^2
    assert check_physical_consistency(far) != []


def test_random_payload_names_and_physics():
    rng = np.random.default_rng(2)
    pl = random_payload(rng, robot=load_robot("rx90"), mass_range=(3.0, 4.0))
    assert pl.names == ("XX7", "XY7", "XZ7", "YY7", "YZ7", "ZZ7", "MX7", "MY7", "MZ7", "M7")
    assert 3.0 <= pl["M7"] <= 4.0 and check_physical_consistency(np.asarray(pl)) == []
    assert random_payload(rng).names[0] == "XXL"


def test_simulated_recording_carries_gains_and_noise():
    robot = load_robot("rx90")
    rng = np.random.default_rng(4)
    chi = random_physical_parameters(robot, rng)
    pl = random_payload(rng, robot=robot)
    t, q, dq, ddq = fourier_trajectory(6, 4.0, 0.002, rng, n_harmonics=3)
    gains = np.array([1.1, 0.9, 1.0, 1.05, 0.95, 1.2])
    clean = simulate_recording(robot, t, q, dq, ddq, chi, chi_payload=pl, gains=gains)
    tau_true = inverse_dynamics(robot, q, dq, ddq, np.asarray(chi), np.asarray(pl))
    np.testing.assert_allclose(clean.tau * gains, tau_true, rtol=1e-12, atol=1e-12)
    assert clean.loaded and clean.dq is None and clean.meta["gains"] == pytest.approx(gains.tolist())
    noisy = simulate_recording(robot, t, q, dq, ddq, chi, chi_payload=pl, gains=gains, noise_q=1e-3,
                               noise_tau=[0.5, 0.5, 0.2, 0.1, 0.1, 0.1], rng=np.random.default_rng(0),
                               keep_derivatives=True)
    assert np.std(noisy.q - q) == pytest.approx(1e-3, rel=0.05)
    np.testing.assert_allclose(np.std(noisy.tau - clean.tau, axis=0), [0.5, 0.5, 0.2, 0.1, 0.1, 0.1], rtol=0.1)
    np.testing.assert_array_equal(noisy.dq, dq)
    with pytest.raises(ValueError, match="rng"):
        simulate_recording(robot, t, q, dq, ddq, chi, noise_tau=0.1)
    with pytest.raises(TypeError, match="unexpected keyword argument 'noise'"):   # a misspelt logging keyword
        simulate_recording(robot, t, q, dq, ddq, chi, noise=0.1)


def test_model_and_robot_paths_agree():
    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    rng = np.random.default_rng(9)
    chi = random_physical_parameters(robot, rng)
    pl = random_payload(rng, robot=robot)
    t, q, dq, ddq = fourier_trajectory(7, 1.0, 0.005, rng)
    a = true_torques(robot, q, dq, ddq, chi, pl, chunk_samples=37)
    b = true_torques(model, q, dq, ddq, chi, pl)
    c = true_torques(numeric_model(robot), q, dq, ddq, chi, pl)
    np.testing.assert_allclose(b, a, atol=1e-9 * np.abs(a).max())
    np.testing.assert_allclose(c, a, atol=1e-9 * np.abs(a).max())


def test_motor_side_recording_loads_back(tmp_path):
    robot = parse_robot_text(
        'name = "rr"\ndrive = ["FV"]\n'
        '[[frames]]\nj = 1\nant = 0\nsigma = 0\nalpha = 0\nd = 0\ntheta = "q"\nr = 0\n'
        '[[frames]]\nj = 2\nant = 1\nsigma = 0\nalpha = "pi/2"\nd = 0\ntheta = "q"\nr = 0\n'
        '[drive_chain]\nratios = [50, -80]\ncoupling = [[1, 0], [1, 1]]\noffsets = [0.1, -1.0]\n')
    rng = np.random.default_rng(1)
    chi = random_physical_parameters(robot, rng)
    t, q, dq, ddq = fourier_trajectory(2, 2.0, 0.001, rng)
    rec = simulate_recording(robot, t, q, dq, ddq, chi, drive_chain=robot.drive_chain)
    assert rec.meta["motor_side"] and np.abs(rec.q).max() > 5  # motor angles
    np.savetxt(tmp_path / "pos.csv", rec.q, delimiter=",")
    np.savetxt(tmp_path / "cur.csv", rec.tau, delimiter=",")
    back = load_trajectory("q=pos.csv,tau=cur.csv,dt=0.001", robot=robot, drive_chain=robot.drive_chain,
                           base_dir=tmp_path)
    np.testing.assert_allclose(back.q, q, atol=1e-12)
    np.testing.assert_allclose(back.tau, inverse_dynamics(robot, q, dq, ddq, np.asarray(chi)), atol=1e-10)


def test_recording_csv_loads_back(tmp_path):
    """write_recording_csv writes what load_trajectory (and so ``symoro-gen identify``) reads, exactly."""
    robot = load_robot("scara")
    rng = np.random.default_rng(4)
    chi = random_physical_parameters(robot, rng)
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, 1.0, 0.002, rng)
    rec = simulate_recording(robot, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.01, rng=rng)
    f = tmp_path / "sub" / "rec.csv"
    write_recording_csv(f, rec)
    assert f.read_text().splitlines()[0] == "t,q1,q2,q3,q4,tau1,tau2,tau3,tau4"
    back = load_trajectory(f, n_joints=robot.n_joints)
    np.testing.assert_array_equal(back.t, rec.t)
    np.testing.assert_array_equal(back.q, rec.q)
    np.testing.assert_array_equal(back.tau, rec.tau)
