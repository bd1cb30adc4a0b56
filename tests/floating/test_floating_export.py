"""export-urdf and export-mjcf of a floating-base robot (``base = "floating"``) against independent oracles.

* URDF: the exported file, read back by ``import-urdf`` (the ``world`` link and ``floating`` joint make its
  child the floating base), gives the same standard parameters; Pinocchio's own URDF parser builds the
  ``floating`` joint as a ``JointModelFreeFlyer`` and its RNEA equals the project's ``FloatingModel`` (joints
  matched by name).
* MJCF: MuJoCo loads the file (the base body with a ``<freejoint/>``) and ``mj_inverse`` equals the
  ``FloatingModel``'s rows. MuJoCo's free joint differs from the model's (Pinocchio's) conventions, converted
  here (MuJoCo's documentation, "Floating objects"; [F2008] sec. 2.11 for the accelerations): with ``R`` the base
  orientation (base axes -> world axes), ``v, w`` the model's base linear and angular velocity in base axes and
  ``a, dw`` its spatial acceleration in base axes,

  - ``qpos`` = position, quaternion ``w x y z`` (the model's is ``x y z w``), then the joints;
  - ``qvel`` = ``R v`` (linear velocity of the base origin, world axes), ``w`` (body axes), then the joints;
  - ``qacc`` = ``d(R v)/dt = R (a + w x v)`` (the classical acceleration, world axes), ``dw``, then the joints;
  - ``qfrc_inverse`` = the base force in world axes (so the model's force row is ``R^T f``), the moment about the
    base origin in body axes (the model's moment row), then the joint torques.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import symoro_gen
from symoro_gen.cli import main
from symoro_gen.description import parse_robot_text
from symoro_gen.description.mdh import row_transform
from symoro_gen.description.mjcf_export import export_mjcf
from symoro_gen.description.urdf import import_urdf_text
from symoro_gen.description.urdf_export import export_urdf
from symoro_gen.errors import ModelError
from symoro_gen.params import INERTIAL_KINDS
from symoro_gen.workflows import export as export_workflow
from tests.oracles.pinocchio_model import max_relative_error

from .pinocchio_floating import random_floating_parameters, random_floating_states

HERE = Path(__file__).parent
QUADRUPED = HERE / "quadruped.toml"
RTOL = 1e-9


def _rigid_body(rng, mass: float) -> list[float]:
    """``XX XY XZ YY YZ ZZ MX MY MZ M`` of a rigid body (positive second moment of mass ``S``, inertia at the
    centre of mass ``tr(S) 1 - S``, so the triangle inequalities hold), moved to the frame origin by the
    parallel-axis theorem: ``I_O = I_c + m (|c|^2 1 - c c^T)``, first moments ``m c``."""
    c = rng.normal(scale=0.05, size=3)
    A = rng.normal(scale=0.05, size=(3, 3))
    S = A @ A.T + 1e-3 * np.eye(3)
    I_o = np.trace(S) * np.eye(3) - S + mass * (c @ c * np.eye(3) - np.outer(c, c))
    return [I_o[0, 0], I_o[0, 1], I_o[0, 2], I_o[1, 1], I_o[1, 2], I_o[2, 2], *(mass * c), mass]


def _robot_and_values(seed: int = 0, drive: tuple[str, ...] = ("IA", "FV", "FS", "OFF")):
    """The quadruped fixture, random physically consistent parameters (base included, the exporter writes them
    unchanged), the drive terms not in ``drive`` zeroed (URDF and RNEA have none; MuJoCo's frictionloss is a
    constraint)."""
    robot = parse_robot_text(QUADRUPED.read_text(), str(QUADRUPED))
    rng = np.random.default_rng(seed)
    chi = random_floating_parameters(robot, rng)  # the drive terms
    for j in [0] + [r.j for r in robot.joints]:
        body = _rigid_body(rng, 12.0 if j == 0 else rng.uniform(0.5, 2.0))
        for kind, v in zip(("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M"), body):
            chi[robot.standard_names.index(f"{kind}{j}")] = v
    for k, n in enumerate(robot.standard_names):
        if n.startswith(("IA", "FV", "FS", "OFF")) and not n.startswith(drive):
            chi[k] = 0.0
    return robot, chi


@pytest.fixture(scope="module")
def quadruped_model():
    return symoro_gen.load_model(QUADRUPED)


def _pose_at_zero(robot, j: int) -> np.ndarray:
    """4x4 pose of frame ``j`` in frame 0 at q = 0 (the product of the rows' transforms along the chain)."""
    T = np.eye(4)
    while j != 0:
        row = robot.row(j)
        T = row_transform(row, robot.geometry_subs(), q=0.0) @ T
        j = row.ant
    return T


def _moved(p10, E) -> np.ndarray:
    """Standard parameters ``XX .. M`` of a body given in frame A, expressed in frame B, ``E`` = pose of B in A:
    centre of mass ``c_B = R^T (c_A - p)``, inertia at the centre of mass ``R^T I_c R``, then the parallel-axis
    theorem at B's origin."""
    XX, XY, XZ, YY, YZ, ZZ, MX, MY, MZ, M = p10
    R, p = E[:3, :3], E[:3, 3]
    c = np.array([MX, MY, MZ]) / M
    I_c = np.array([[XX, XY, XZ], [XY, YY, YZ], [XZ, YZ, ZZ]]) - M * (c @ c * np.eye(3) - np.outer(c, c))
    cb, Ib = R.T @ (c - p), R.T @ I_c @ R
    Io = Ib + M * (cb @ cb * np.eye(3) - np.outer(cb, cb))
    return np.array([Io[0, 0], Io[0, 1], Io[0, 2], Io[1, 1], Io[1, 2], Io[2, 2], *(M * cb), M])


def test_urdf_round_trip_gives_the_same_standard_parameters():
    """Robot file -> export-urdf -> import-urdf: the base link's ``XX0 .. M0`` come back as written (frame 0 is
    the base link's frame in both); the importer chooses its own MDH frame for a ``-q`` joint or a joint offset
    (a frame turned about or flipped along the joint axis), so each link's parameters are compared after moving
    them to the imported frame (:func:`_moved`, the frames' poses at q = 0, where the URDF joint values, the two
    models' ``q``, are all 0). The importer writes 12 significant digits: relative tolerance 1e-11."""
    robot, chi = _robot_and_values(drive=())
    text = export_urdf(robot, chi)
    assert '<joint name="base_joint" type="floating">' in text and '<link name="world"/>' in text
    back = parse_robot_text(import_urdf_text(text, file="quad.urdf"), "quad.toml")
    assert back.floating and back.n_joints == robot.n_joints and back.nominal is not None
    ref = dict(zip(robot.standard_names, chi))
    frame_of = {r.name: r.j for r in back.rows}  # the importer names frames after the URDF's joints
    err = 0.0
    for j in [0] + [r.j for r in robot.joints]:
        jb = 0 if j == 0 else frame_of[f"joint{j}"]
        orig = [ref[f"{k}{j}"] for k in INERTIAL_KINDS]
        want = orig if j == 0 else _moved(orig, np.linalg.inv(_pose_at_zero(robot, j)) @ _pose_at_zero(back, jb))
        got = np.array([back.nominal.get(f"{k}{jb}", 0.0) for k in INERTIAL_KINDS])
        err = max(err, float(np.max(np.abs(got - want) / np.maximum(1.0, np.abs(want)))))
        if j == 0:
            assert np.array_equal(got, np.array([float(f"{x:.12g}") for x in orig]))  # the base: as written
    print(f"URDF round trip: max standard-parameter difference {err:.2e}")
    assert err < 1e-11


def test_urdf_pinocchio_free_flyer_equals_floating_model(quadruped_model):
    robot, chi = _robot_and_values(seed=1, drive=())
    pmodel = pin.buildModelFromXML(export_urdf(robot, chi))
    assert pmodel.joints[1].shortname() == "JointModelFreeFlyer" and pmodel.nv == 6 + robot.n_joints
    pmodel.gravity.linear = np.asarray(robot.gravity, float)
    data = pmodel.createData()
    names = [f"joint{r.j}" for r in robot.joints]
    idx_q = [pmodel.joints[pmodel.getJointId(nm)].idx_q for nm in names]
    idx_v = [pmodel.joints[pmodel.getJointId(nm)].idx_v for nm in names]
    q, dq, ddq = random_floating_states(robot, 10, np.random.default_rng(2))
    ref = []
    for k in range(q.shape[0]):
        qp, vp, ap = np.zeros(pmodel.nq), np.zeros(pmodel.nv), np.zeros(pmodel.nv)
        qp[:7], vp[:6], ap[:6] = q[k, :7], dq[k, :6], ddq[k, :6]
        qp[idx_q], vp[idx_v], ap[idx_v] = q[k, 7:], dq[k, 6:], ddq[k, 6:]
        tau = pin.rnea(pmodel, data, qp, vp, ap)
        ref.append(np.concatenate([tau[:6], tau[idx_v]]))
    err = max_relative_error(quadruped_model.torque(q, dq, ddq, chi), np.array(ref))
    print(f"export-urdf (floating) vs Pinocchio free-flyer RNEA: max relative error {err:.2e}")
    assert err < RTOL


def _quat_matrix(xyzw) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``x y z w`` (the textbook formula; not the project's)."""
    x, y, z, w = xyzw
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_mjcf_free_joint_mj_inverse_equals_floating_model(quadruped_model):
    mujoco = pytest.importorskip("mujoco", reason="the 'mjcf' extra (mujoco wheel) is not installed")
    robot, chi = _robot_and_values(seed=3, drive=("IA",))  # armature = IA; FV, FS are MuJoCo passive/constraint
    text = export_mjcf(robot, chi)
    assert '<freejoint name="base"/>' in text
    mj = mujoco.MjModel.from_xml_string(text)
    data = mujoco.MjData(mj)
    assert mj.nv == 6 + robot.n_joints and mj.nq == 7 + robot.n_joints
    names = [f"joint{r.j}" for r in robot.joints]
    adr_q = [mj.joint(nm).qposadr[0] for nm in names]
    adr_v = [mj.joint(nm).dofadr[0] for nm in names]
    q, dq, ddq = random_floating_states(robot, 10, np.random.default_rng(4))
    ref = quadruped_model.torque(q, dq, ddq, chi)
    got = []
    for k in range(q.shape[0]):
        R = _quat_matrix(q[k, 3:7])
        v, w, a, dw = dq[k, :3], dq[k, 3:6], ddq[k, :3], ddq[k, 3:6]
        data.qpos[:3], data.qpos[3:7] = q[k, :3], np.roll(q[k, 3:7], 1)  # x y z w -> w x y z
        data.qvel[:3], data.qvel[3:6] = R @ v, w
        data.qacc[:3], data.qacc[3:6] = R @ (a + np.cross(w, v)), dw
        data.qpos[adr_q], data.qvel[adr_v], data.qacc[adr_v] = q[k, 7:], dq[k, 6:], ddq[k, 6:]
        mujoco.mj_inverse(mj, data)
        f = data.qfrc_inverse
        got.append(np.concatenate([R.T @ f[:3], f[3:6], f[adr_v]]))
    err = max_relative_error(np.array(got), ref)
    print(f"export-mjcf (free joint) vs FloatingModel: max relative error {err:.2e}")
    assert err < RTOL


def test_export_params_apply_to_the_base_body():
    """``--params`` (names and values of an identification) replaces the base link's parameters too."""
    robot, chi = _robot_and_values(seed=5, drive=())
    vals = dict(zip(robot.standard_names, chi))
    base = ("XX0", "XY0", "XZ0", "YY0", "YZ0", "ZZ0", "MX0", "MY0", "MZ0", "M0")
    new = {n: (2.0 * v if n in base else v) for n, v in vals.items()}  # a body twice as heavy: still physical
    res = export_workflow.export_urdf(robot, params=new)
    back = parse_robot_text(import_urdf_text(res.text, file="q.urdf"), "q.toml")
    assert back.nominal is not None
    for n in base:
        assert back.nominal.get(n, 0.0) == float(f"{new[n]:.12g}"), n  # the importer writes 12 digits


def test_export_from_a_result_without_floating_relations_is_refused_naming_the_file():
    """``--from`` takes a floating-base identification (its ``floating.relations``; tests/floating/test_cli_floating.py);
    a result without them is refused, naming the source and the robot file."""
    robot, _ = _robot_and_values(drive=())
    for export in (export_workflow.export_urdf, export_workflow.export_mjcf):
        with pytest.raises(ModelError, match=r"result.*no 'floating' relations.*quadruped\.toml"):
            export(robot, from_result={"robot": robot.name, "parameters": {"names": [], "values": []}})


def test_cli_exports_a_floating_robot(tmp_path):
    """``symoro-gen export-urdf`` / ``export-mjcf`` of the robot file write the free root (read back by Pinocchio
    and MuJoCo as a 6-DoF base)."""
    urdf, mjcf = tmp_path / "quad.urdf", tmp_path / "quad.xml"
    assert main(["export-urdf", str(QUADRUPED), "-o", str(urdf)]) == 0
    assert main(["export-mjcf", str(QUADRUPED), "-o", str(mjcf)]) == 0
    model = pin.buildModelFromXML(urdf.read_text())
    assert model.joints[1].shortname() == "JointModelFreeFlyer" and model.nv == 6 + 12
    mujoco = pytest.importorskip("mujoco", reason="the 'mjcf' extra (mujoco wheel) is not installed")
    mj = mujoco.MjModel.from_xml_path(str(mjcf))
    assert mj.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE and mj.nv == 6 + 12
