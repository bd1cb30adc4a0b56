"""export-mjcf: MuJoCo's inverse and forward dynamics on the exported model against ours."""
import json

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the 'mjcf' extra (mujoco wheel) is not installed")

from symoro_gen.description.mjcf_export import export_mjcf, quat_from_matrix  # noqa: E402 - after the skip
from symoro_gen.loader import model_for  # noqa: E402
from symoro_gen.simulate import (  # noqa: E402
    fourier_trajectory,
    random_payload,
    random_physical_parameters,
    simulate_recording,
    write_recording_csv,
)


def _offsets(robot, vals):
    return np.array([vals.get(f"OFF{r.j}", 0.0) for r in robot.joints])


def _inverse(m, q, dq, ddq):
    d = mujoco.MjData(m)
    out = np.empty_like(q)
    for k in range(q.shape[0]):
        d.qpos[:], d.qvel[:], d.qacc[:] = q[k], dq[k], ddq[k]
        mujoco.mj_inverse(m, d)
        out[k] = d.qfrc_inverse
    return out


def _rel_err_per_joint(a, b):
    return np.linalg.norm(a - b, axis=0) / np.linalg.norm(b, axis=0)


def test_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
        Q = Q * np.sign(np.diag(R))
        if np.linalg.det(Q) < 0:
            Q[:, 0] *= -1
        res = np.empty(9)
        mujoco.mju_quat2Mat(res, np.array(quat_from_matrix(Q)))
        assert np.allclose(res.reshape(3, 3), Q, atol=1e-12)


@pytest.mark.parametrize("name", ["lwr4", "rx90", "scara", "tx40"])
def test_mj_inverse_matches_model_with_drive_terms(name):
    """Rigid body + armature (IA) + damping (FV) + frictionloss (FS, away from zero velocity) = our
    model's torque minus the offset OFF (no MuJoCo field), on random states, per joint within 1 %."""
    robot, model = model_for(name)
    rng = np.random.default_rng(1)
    chi = np.asarray(random_physical_parameters(robot, rng))
    pay = np.asarray(random_payload(rng)) if robot.payload is not None else None
    m = mujoco.MjModel.from_xml_string(export_mjcf(robot, chi, pay))
    assert m.nv == robot.n_joints
    lim = robot.limits
    if lim is not None and lim.q_min is not None and lim.q_max is not None:  # ranges from [limits]
        assert m.jnt_limited.all()
        assert np.allclose(m.jnt_range, np.column_stack([lim.q_min, lim.q_max]))
    m.jnt_limited[:] = 0  # the dynamics are compared on random states, some of them beyond the ranges
    n = robot.n_joints
    q, dq, ddq = rng.normal(size=(3, 50, n))
    dq = np.sign(dq) * (np.abs(dq) + 0.3)  # Coulomb friction compared away from zero velocity
    ref = model.torque(q, dq, ddq, chi, pay if model.PAYLOAD_NAMES else None)
    ref = ref - _offsets(robot, dict(zip(robot.standard_names, chi)))
    tau = _inverse(m, q, dq, ddq)
    assert np.all(_rel_err_per_joint(tau, ref) < 0.01), _rel_err_per_joint(tau, ref)


@pytest.fixture(scope="module")
def identified_rx90(tmp_path_factory):
    """rx90 identified (--physical) on a simulated recording with torque noise, exported to MJCF."""
    pytest.importorskip("cvxpy", reason="the 'physical' extra is not installed")
    from symoro_gen.cli import main

    robot, model = model_for("rx90")
    rng = np.random.default_rng(11)
    truth = np.asarray(random_physical_parameters(robot, rng))
    mo = fourier_trajectory(6, 20.0, 0.001, rng, n_harmonics=5)
    rec = simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, truth, noise_tau=0.2, rng=rng)
    tmp = tmp_path_factory.mktemp("mjcf")
    write_recording_csv(tmp / "ident.csv", rec)
    assert main(["-q", "identify", "rx90", str(tmp / "ident.csv"), "--physical", "--json", str(tmp / "r.json")]) == 0
    assert main(["-q", "export-mjcf", "rx90", "--from", str(tmp / "r.json"), "-o", str(tmp / "rx90.xml")]) == 0
    res = json.loads((tmp / "r.json").read_text())
    side = json.loads((tmp / "rx90.xml.json").read_text())
    pm = dict(zip(res["parameters"]["names"], res["parameters"]["values"]))
    chi_b = np.array([pm[n] for n in model.BASE_NAMES])
    m = mujoco.MjModel.from_xml_path(str(tmp / "rx90.xml"))
    m.jnt_limited[:] = 0  # the test trajectories are random Fourier series, not kept inside [limits]
    off = np.array([side["drive"][f"joint{r.j}"]["OFF"] for r in robot.joints])
    return robot, model, truth, chi_b, m, off, side


def test_identified_mjcf_inverse_matches_identified_model(identified_rx90):
    robot, model, _, chi_b, m, off, side = identified_rx90
    assert side["exact"] is True
    rng = np.random.default_rng(12)
    mv = fourier_trajectory(6, 5.0, 0.01, rng, n_harmonics=5)
    ok = np.all(np.abs(mv.dq) > 0.1, axis=1)
    q, dq, ddq = mv.q[ok], mv.dq[ok], mv.ddq[ok]
    ref = model.regressor(q, dq, ddq) @ chi_b - off
    tau = _inverse(m, q, dq, ddq)
    assert np.all(_rel_err_per_joint(tau, ref) < 0.01), _rel_err_per_joint(tau, ref)


def computed_torque_run(m, model, chi_b, off, motion, kp=400.0, kd=40.0):
    """MuJoCo forward simulation of ``m`` tracking ``motion`` with the identified model's feed-forward
    torque (minus its offset) plus a PD; returns the applied torques and the states MuJoCo reached."""
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = motion.q[0], motion.dq[0]
    N = motion.t.size
    n = m.nv
    tau, q, dq, ddq = (np.empty((N, n)) for _ in range(4))
    ff = model.regressor(motion.q, motion.dq, motion.ddq) @ chi_b - off
    for k in range(N):
        u = ff[k] + kp * (motion.q[k] - d.qpos) + kd * (motion.dq[k] - d.qvel)
        d.ctrl[:] = u
        mujoco.mj_forward(m, d)
        tau[k], q[k], dq[k], ddq[k] = u, d.qpos, d.qvel, d.qacc
        mujoco.mj_step(m, d)
    return tau, q, dq, ddq


def test_forward_simulation_reproduces_the_true_robot(identified_rx90):
    """Data -> identification -> MJCF -> MuJoCo running a new trajectory: the torques MuJoCo needed
    are those of the *true* simulated robot on the reached states (within 5 % per joint, Coulomb
    compared away from zero velocity; measured 0.3-3.0 %), and the tracking stays tight."""
    robot, model, truth, chi_b, m, off, _ = identified_rx90
    rng = np.random.default_rng(13)
    mv = fourier_trajectory(6, 4.0, m.opt.timestep, rng, n_harmonics=4)
    tau, q, dq, ddq = computed_torque_run(m, model, chi_b, off, mv)
    assert np.abs(q - mv.q).max() < 0.01
    ok = np.all(np.abs(dq) > 0.1, axis=1)
    true = model.torque(q[ok], dq[ok], ddq[ok], truth)
    err = _rel_err_per_joint(tau[ok] + off, true)
    assert np.all(err < 0.05), err
