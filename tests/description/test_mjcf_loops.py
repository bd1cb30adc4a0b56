"""export-mjcf of a closed-loop robot (the palletizer's parallelogram): the loop closed by MuJoCo's equality
constraints, motors on the actuated joints only, checked against MuJoCo itself and the project's loop solver."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the 'mjcf' extra (mujoco wheel) is not installed")

from symoro_gen import load_model  # noqa: E402 - after the skip
from symoro_gen.closedloop.kinematics import LoopKinematics  # noqa: E402
from symoro_gen.description import load_robot  # noqa: E402
from symoro_gen.description.mjcf_export import export_mjcf  # noqa: E402
from symoro_gen.simulate import random_physical_parameters  # noqa: E402

ACT, PAS = [0, 1, 3, 4], [2, 5]  # qpos indices of joints 1, 2, 4, 5 (actuated) and 3, 6 (passive)
#: actuated positions inside the file's [limits], passive joint 3 (= q5 - q2) at 0.8, 1.2 and 1.0 rad: reached
#: from the zero assembly without crossing the flattened parallelogram (q3 = pi/2, where the loop's constraint
#: Jacobian is singular and the assembly modes meet)
POSES = np.array([[0.2, -0.3, 0.4, 0.5], [1.0, -0.8, -1.0, 0.4], [-2.0, -1.2, 1.5, -0.2]])


@pytest.fixture(scope="module")
def exported(tmp_path_factory, cli):
    out = tmp_path_factory.mktemp("mjcf_loop") / "palletizer.xml"
    cli("export-mjcf", "palletizer", "-o", out)
    m = mujoco.MjModel.from_xml_path(str(out))
    m.jnt_limited[:] = 0  # the solves below start from the zero assembly, outside the passive ranges
    return load_robot("palletizer"), m


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _loop_gap(m, d) -> float:
    """Largest distance of the two pairs of loop sites (the closure MuJoCo sees, independent of its solver)."""
    x = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i): d.site_xpos[i] for i in range(m.nsite)}
    return max(np.linalg.norm(x["cut7"] - x["close8"]), np.linalg.norm(x["cut7_axis"] - x["close8_axis"]))


def _equality_rows(m, d):
    """MuJoCo's constraint Jacobian and violation of the equality rows (frictionloss rows left out)."""
    rows = np.flatnonzero(d.efc_type[:d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    return d.efc_J.reshape(d.nefc, m.nv)[rows], d.efc_pos[rows]


def test_motors_on_the_actuated_joints_and_the_loop_as_two_connects(exported):
    robot, m = exported
    assert m.nu == 4
    assert [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, m.actuator_trnid[a, 0]) for a in range(m.nu)] == [
        "joint1", "joint2", "joint4", "joint5"]
    assert m.neq == 2 and list(m.eq_type) == [mujoco.mjtEq.mjEQ_CONNECT] * 2
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    assert _loop_gap(m, d) < 1e-12  # q = 0 is the file's reference assembly


def test_closure_solved_on_mujocos_constraint_equals_the_loop_solver(exported):
    """Newton on MuJoCo's own constraint rows (efc_pos, efc_J) for the passive joints, the actuated ones moved
    from the zero assembly to each pose in 20 steps (the assembly mode is the reference's, as the loop solver's):
    the loop sites coincide and the passive joints equal :class:`LoopKinematics` (modulo 2 pi) to 1e-9."""
    robot, m = exported
    x, _ = LoopKinematics(robot).solve_positions(POSES)
    d = mujoco.MjData(m)
    for qa, ref in zip(POSES, x):
        d.qpos[:] = 0.0
        for s in np.linspace(0.05, 1.0, 20):
            d.qpos[ACT] = s * qa
            for _ in range(50):
                mujoco.mj_forward(m, d)
                J, e = _equality_rows(m, d)
                if np.abs(e).max() < 1e-13:
                    break
                d.qpos[PAS] -= np.linalg.lstsq(J[:, PAS], e, rcond=None)[0]
        assert _loop_gap(m, d) < 1e-12
        np.testing.assert_allclose(_wrap(d.qpos[PAS] - ref[PAS]), 0.0, atol=1e-9)


def test_static_inverse_dynamics_equal_the_closed_loop_gravity_torques(exported):
    """At a closed static pose, MuJoCo's tree torques (mj_inverse) projected on the actuated joints with
    Lagrange multipliers on its equality rows (``tau_a = tau_a,tree - J_a^T lambda``, ``J_p^T lambda =
    tau_p,tree``) equal the project's closed-loop model ``tau_a(q, 0, 0)`` (nominal and random parameters)."""
    robot, _ = exported
    model = load_model("palletizer")
    x, _ = LoopKinematics(robot).solve_positions(POSES)
    rng = np.random.default_rng(5)
    for chi in (np.asarray(robot.nominal_vector()), np.asarray(random_physical_parameters(robot, rng))):
        m = mujoco.MjModel.from_xml_string(export_mjcf(robot, chi))
        off = np.array([dict(zip(robot.standard_names, chi)).get(f"OFF{r.j}", 0.0) for r in robot.actuated])
        ref = model.torque(POSES, np.zeros_like(POSES), np.zeros_like(POSES), chi) - off
        d = mujoco.MjData(m)
        for k in range(len(POSES)):
            d.qpos[:], d.qvel[:], d.qacc[:] = x[k, :6], 0.0, 0.0
            mujoco.mj_inverse(m, d)
            J, _ = _equality_rows(m, d)
            lam = np.linalg.lstsq(J[:, PAS].T, d.qfrc_inverse[PAS], rcond=None)[0]
            tau_a = d.qfrc_inverse[ACT] - J[:, ACT].T @ lam
            np.testing.assert_allclose(tau_a, ref[k], atol=1e-9 * np.abs(ref[k]).max())


def test_simulation_holding_the_actuated_joints_keeps_the_loop_closed(exported):
    """MuJoCo's forward simulation under gravity, the four motors driven by the project's gravity torques plus
    a PD, from the zero assembly to each pose: after settling (6 s) the loop sites coincide within 1e-6 m
    (measured 1.3e-8 and 2.7e-8) and the passive joints equal the loop solver's for the actuated positions
    reached (within 2e-6 rad, measured 5.5e-8 and 2.1e-7)."""
    robot, m = exported
    m.dof_frictionloss[:] = 0  # MuJoCo's soft Coulomb friction would hold the joints anywhere near the target
    model = load_model("palletizer")
    kin = LoopKinematics(robot)
    chi = np.asarray(robot.nominal_vector())
    kp, kd, ramp = 2000.0, 200.0, 1.0
    for qa in POSES[:2]:
        g = model.torque(qa[None], np.zeros((1, 4)), np.zeros((1, 4)), chi)[0]
        d = mujoco.MjData(m)
        for k in range(6000):
            s = min(1.0, k * m.opt.timestep / ramp)
            dref = qa / ramp if s < 1 else 0.0 * qa
            d.ctrl[:] = s * g + kp * (s * qa - d.qpos[ACT]) + kd * (dref - d.qvel[ACT])
            mujoco.mj_step(m, d)
        mujoco.mj_forward(m, d)
        assert _loop_gap(m, d) < 1e-6
        assert np.abs(d.qpos[ACT] - qa).max() < 1e-3
        x, _ = kin.solve_positions(d.qpos[ACT][None])
        np.testing.assert_allclose(_wrap(d.qpos[PAS] - x[0, PAS]), 0.0, atol=2e-6)


def test_prismatic_cut_joint_refused(tmp_path, cli):
    """MuJoCo has no equality constraint that leaves a sliding motion free: a prismatic cut joint is refused,
    the loop named. The slider lies in the plane of the loop (alpha = pi/2: its axis orthogonal to the revolute
    ones), so that the loop keeps its two degrees of freedom; along the revolute axes it would be held by the
    closure and the loop, with joints 2 and 5 actuated, over-actuated (refused when the file is read)."""
    text = Path(load_robot("palletizer").file).read_text()
    line = 'cut = { ant = 6, sigma = 0, alpha = 0, d = "D3", theta = "q + pi/2", r = 0 }'
    assert line in text
    f = tmp_path / "slider.toml"
    f.write_text(text.replace(line, 'cut = { ant = 6, sigma = 1, alpha = "pi/2", d = "D3", theta = "pi/2", r = "q" }'))
    r = cli("export-mjcf", f, "-o", tmp_path / "s.xml", rc=2)
    assert r.err_lines == [
        "symoro-gen: error: export-mjcf: palletizer: the loop cut at joint 7 (closed on frame 8) has a prismatic cut "
        "joint: MuJoCo's equality constraints hold a point (connect) or a whole frame (weld), none leaves a sliding "
        "motion free",
        "hint: export-urdf writes this loop as a <loop_joint> (docs/robot-file.md#closed-loops-from-urdf); cutting "
        "the loop at one of its revolute joints instead makes it exportable to MuJoCo"]
    assert not (tmp_path / "s.xml").exists()
