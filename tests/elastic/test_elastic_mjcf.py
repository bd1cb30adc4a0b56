"""export-mjcf of elastic joints: a rotor coupled to the link by a fixed tendon of stiffness K, damping D (Spong
1987). Under gravity at rest the deflection is tau/K (LWR4 paper eq. 17), tau the gravity torque of our own
Newton-Euler model (an independent reference for MuJoCo's)."""
import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the 'mjcf' extra (mujoco wheel) is not installed")

from symoro_gen.description.mjcf_export import export_mjcf, rotor_armature  # noqa: E402 - after the skip
from symoro_gen.description.parse import parse_robot_text  # noqa: E402
from symoro_gen.simulate.recording import true_torques  # noqa: E402

from .test_elastic_identify import LWR4_K, lwr4_elastic_text  # noqa: E402


def _robot_and_chi():
    robot = parse_robot_text(lwr4_elastic_text().replace("elastic = {K = 10000}", "elastic = {K = 10000, D = 30}"))
    chi = np.array(robot.nominal_vector(), float)
    # no Coulomb friction: MuJoCo's frictionloss holds a joint at rest by itself and would hide the balance
    chi[[i for i, n in enumerate(robot.standard_names) if n.startswith("FS")]] = 0.0
    return robot, chi


def _model(robot, chi):
    return mujoco.MjModel.from_xml_string(export_mjcf(robot, chi, robot.nominal_payload(), report=[]))


def _ids(m, prefix, n):
    return [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{prefix}{j}")] for j in range(1, n + 1)]


def test_structure():
    robot, chi = _robot_and_chi()
    xml = export_mjcf(robot, chi, robot.nominal_payload(), report=[])
    m = mujoco.MjModel.from_xml_string(xml)
    assert m.njnt == 14 and m.ntendon == 7 and m.nu == 7
    for j, K in enumerate(LWR4_K, start=1):
        t = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, f"transmission{j}")
        assert m.tendon_stiffness[t] == pytest.approx(K)
        assert m.tendon_damping[t] == pytest.approx(30.0 if j <= 5 else 0.0)
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"motor{j}")
        assert m.actuator_trnid[a, 0] == mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"rotor{j}")
        r = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"rotor{j}")]
        assert m.dof_armature[r] == pytest.approx(rotor_armature(K, 0.001))  # the LWR4 file declares no IA


@pytest.mark.parametrize("seed", [0, 1])
def test_deflection_at_rest_under_gravity_is_tau_over_k(seed):
    robot, chi = _robot_and_chi()
    m = _model(robot, chi)
    d = mujoco.MjData(m)
    q = np.random.default_rng(seed).uniform(-1.2, 1.2, 7)
    tau = true_torques(robot, q[None], np.zeros((1, 7)), np.zeros((1, 7)), chi, robot.nominal_payload())[0]
    tau -= chi[[robot.standard_names.index(f"OFF{j}") for j in range(1, 8)]]  # a torque offset is no force
    assert np.max(np.abs(tau)) > 5.0  # a real load on the joints
    link, rot = _ids(m, "joint", 7), _ids(m, "rotor", 7)
    defl = tau / np.array(LWR4_K)

    def acc(deflection):
        d.qpos[:] = 0
        d.qvel[:] = 0
        d.qpos[link] = q
        d.qpos[rot] = q + deflection
        d.ctrl[:] = tau  # the motors hold the gravity torque
        mujoco.mj_forward(m, d)
        return np.array([[d.qacc[m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{p}{j}")]]
                          for j in range(1, 8)] for p in ("joint", "rotor")])

    still = acc(defl)  # at rest: rotor ahead of the link by tau/K
    assert np.max(np.abs(still)) < 1e-6 * np.max(np.abs(acc(np.zeros(7)))), still
    # a deflection 1 % off (or of the other sign) does not hold the arm
    assert np.max(np.abs(acc(1.01 * defl))) > 100 * np.max(np.abs(still))
    assert np.max(np.abs(acc(-defl)[0])) > 1.0


def test_motor_side_pd_settles_with_the_link_at_its_target():
    """A PD on the rotor with gravity compensation, the rotor target ahead of the link target by tau/K (the
    regulator of elastic-joint robots: Tomei, IEEE TAC 36(10), 1991): the link settles at its target only if the
    exported transmission passes K (theta - q) to it."""
    robot, chi = _robot_and_chi()
    text = lwr4_elastic_text().replace("elastic = {K = 10000}", "elastic = {K = 10000, D = 30}")
    robot = parse_robot_text(text.replace("elastic = {K = 7500}", "elastic = {K = 7500, D = 10}"))
    m = _model(robot, chi)
    d = mujoco.MjData(m)
    q_d = np.array([0.3, 0.8, -0.4, -1.0, 0.5, 0.6, -0.2])
    tau = true_torques(robot, q_d[None], np.zeros((1, 7)), np.zeros((1, 7)), chi, robot.nominal_payload())[0]
    tau -= chi[[robot.standard_names.index(f"OFF{j}") for j in range(1, 8)]]
    link, rot = _ids(m, "joint", 7), _ids(m, "rotor", 7)
    rot_dof = [m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"rotor{j}")] for j in range(1, 8)]
    theta_d = q_d + tau / np.array(LWR4_K)
    d.qpos[link] = q_d - 0.05
    d.qpos[rot] = q_d - 0.05
    kp, kd = 2000.0, 60.0
    for _ in range(4000):
        d.ctrl[:] = tau + kp * (theta_d - d.qpos[rot]) - kd * d.qvel[rot_dof]
        mujoco.mj_step(m, d)
    np.testing.assert_allclose(d.qpos[link], q_d, atol=1e-5)
    np.testing.assert_allclose(d.qpos[rot] - d.qpos[link], tau / np.array(LWR4_K), rtol=0.01, atol=1e-6)
