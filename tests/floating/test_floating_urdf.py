"""A floating-base URDF imported (``import-urdf``), loaded by ``load_model`` of the robot file, against
Pinocchio's own URDF parser with a free-flyer root (``pin.buildModelFromXML(urdf, JointModelFreeFlyer())``):
an oracle that shares nothing with the importer (not the MDH table, not the inertia conversions), matched
by joint name. The URDF: a trunk with an inertial and a fixed sensor link, four 3-joint legs with generic
origins, rpy and axes, a fixed foot with an inertial at the end of each leg; once with a ``world`` link
and a ``floating`` joint (found by the importer), once as a bare tree imported with ``floating=True``."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import symoro_gen
from symoro_gen.cli import main
from symoro_gen.description import parse_robot_text
from symoro_gen.description.urdf import import_urdf_text
from symoro_gen.errors import RobotFileError
from tests.oracles.pinocchio_model import max_relative_error

from .pinocchio_floating import random_floating_states

RTOL = 1e-9


def _inertial(rng, mass: float) -> str:
    c = rng.normal(scale=0.05, size=3)
    A = rng.normal(scale=0.05, size=(3, 3))
    S = A @ A.T + 1e-3 * np.eye(3)  # a second moment of mass: the inertia of a rigid body (triangle inequality)
    Ic = np.trace(S) * np.eye(3) - S
    rpy = rng.uniform(-0.5, 0.5, 3)
    return (f'<inertial><origin xyz="{c[0]} {c[1]} {c[2]}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
            f'<mass value="{mass}"/><inertia ixx="{Ic[0, 0]}" ixy="{Ic[0, 1]}" ixz="{Ic[0, 2]}" '
            f'iyy="{Ic[1, 1]}" iyz="{Ic[1, 2]}" izz="{Ic[2, 2]}"/></inertial>')


def quadruped_urdf(world: bool, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    parts = ['<robot name="urdf_quadruped">']
    if world:
        parts.append('<link name="world"/>')
        parts.append('<joint name="root" type="floating"><parent link="world"/><child link="trunk"/>'
                     '<origin xyz="0 0 0.5"/></joint>')
    parts.append(f'<link name="trunk">{_inertial(rng, 12.0)}</link>')
    parts.append(f'<link name="imu">{_inertial(rng, 0.3)}</link>')
    parts.append('<joint name="imu_fixed" type="fixed"><parent link="trunk"/><child link="imu"/>'
                 '<origin xyz="0.05 0.01 0.08" rpy="0.1 0 0.2"/></joint>')
    axes = ["1 0 0", "0 1 0", "0 1 0"]
    for k, (sx, sy) in enumerate([(1, 1), (1, -1), (-1, 1), (-1, -1)]):
        parent = "trunk"
        for i in range(3):
            link = f"leg{k}_l{i}"
            xyz = (f"{sx * 0.2} {sy * 0.07} {rng.uniform(-0.02, 0.02)}" if i == 0
                   else f"{rng.uniform(-0.03, 0.03)} {sy * rng.uniform(0.0, 0.05)} {-0.2 - 0.05 * (i == 2)}")
            rpy = " ".join(str(x) for x in rng.uniform(-0.3, 0.3, 3))
            parts.append(f'<link name="{link}">{_inertial(rng, 1.0 + 0.3 * i)}</link>')
            parts.append(f'<joint name="leg{k}_j{i}" type="revolute"><parent link="{parent}"/><child link="{link}"/>'
                         f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axes[i]}"/>'
                         '<limit lower="-3" upper="3" effort="50" velocity="10"/></joint>')
            parent = link
        parts.append(f'<link name="leg{k}_foot">{_inertial(rng, 0.1)}</link>')
        parts.append(f'<joint name="leg{k}_foot_fixed" type="fixed"><parent link="{parent}"/>'
                     f'<child link="leg{k}_foot"/><origin xyz="0 0 -0.22"/></joint>')
    parts.append("</robot>")
    return "\n".join(parts)


def _pinocchio_rows(urdf: str, world: bool, robot, q, dq, ddq) -> np.ndarray:
    """Pinocchio's RNEA on the URDF, its joint rows put in the robot file's joint order: the URDF's floating
    joint is Pinocchio's free-flyer (``world``), else a free-flyer root is added."""
    model = pin.buildModelFromXML(urdf) if world else pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())
    assert model.joints[1].shortname() == "JointModelFreeFlyer" and model.nv == 6 + robot.n_joints
    data = model.createData()
    names = [r.name for r in robot.joints]
    idx_q = [model.joints[model.getJointId(nm)].idx_q for nm in names]
    idx_v = [model.joints[model.getJointId(nm)].idx_v for nm in names]
    assert sorted(idx_v) == list(range(6, 6 + len(names)))
    out = []
    for k in range(q.shape[0]):
        qp, vp, ap = np.zeros(model.nq), np.zeros(model.nv), np.zeros(model.nv)
        qp[:7], vp[:6], ap[:6] = q[k, :7], dq[k, :6], ddq[k, :6]
        qp[idx_q], vp[idx_v], ap[idx_v] = q[k, 7:], dq[k, 6:], ddq[k, 6:]
        tau = pin.rnea(model, data, qp, vp, ap)
        out.append(np.concatenate([tau[:6], tau[idx_v]]))
    return np.array(out)


@pytest.mark.parametrize("world", [True, pytest.param(False, marks=pytest.mark.slow)])
def test_floating_urdf_import_matches_pinocchio(tmp_path, world):
    urdf = quadruped_urdf(world)
    text = import_urdf_text(urdf, file="quad.urdf", floating=None if world else True)
    robot = parse_robot_text(text, "quad.toml")
    assert robot.floating and robot.n_joints == 12
    assert robot.nominal is not None and robot.nominal["M0"] == pytest.approx(12.3)  # trunk + fixed imu
    path = tmp_path / "quad.toml"
    path.write_text(text, encoding="utf-8")
    model = symoro_gen.load_model(path)
    assert model.FLOATING
    chi = np.array(robot.nominal_vector())
    q, dq, ddq = random_floating_states(robot, 10, np.random.default_rng(1))
    ref = _pinocchio_rows(urdf, world, robot, q, dq, ddq)
    err = max_relative_error(model.torque(q, dq, ddq, chi), ref)
    print(f"URDF ({'world + floating joint' if world else 'floating=True'}): max relative error vs Pinocchio {err:.2e}")
    assert err < RTOL


def test_floating_import_options(tmp_path):
    urdf = quadruped_urdf(True)
    with pytest.raises(RobotFileError, match="floating joints cannot be part of"):
        import_urdf_text(urdf, file="quad.urdf", floating=False)  # a fixed base refuses the floating joint
    fixed = parse_robot_text(import_urdf_text(quadruped_urdf(False), file="quad.urdf"), "quad.toml")
    assert not fixed.floating and "M0" not in fixed.standard_names
    (tmp_path / "quad.urdf").write_text(quadruped_urdf(False), encoding="utf-8")
    out = tmp_path / "quad.toml"
    assert main(["import-urdf", str(tmp_path / "quad.urdf"), "--floating", "-o", str(out)]) == 0
    assert 'base = "floating"' in out.read_text()
