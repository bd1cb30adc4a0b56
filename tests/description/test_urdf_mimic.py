"""URDF ``<mimic>`` joints: a gripper-like URDF imports with its second finger and a geared
wrist as coupled joints, whose actuated torques equal Pinocchio's RNEA on the same URDF built with
Pinocchio's own mimic joints (``buildModelFromXML(..., mimic=True)``, ``JointModelMimic``); a robot file
with couplings written by ``export-urdf`` and imported again gives the same actuated torques (different MDH
frames, the same robot), and Pinocchio reads the exported ``<mimic>`` tags alike."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from symoro_gen.closedloop import ClosedLoopModel
from symoro_gen.description import parse_robot_text
from symoro_gen.description.urdf import import_urdf_text, parse_urdf_text
from symoro_gen.description.urdf_export import export_urdf
from symoro_gen.emit.package import build_in_memory
from symoro_gen.simulate.parameters import random_physical_parameters

from ..closedloop.test_couplings import toy_text

_INERTIAL = ('<inertial><origin xyz="{c}" rpy="0.1 -0.2 0.3"/><mass value="{m}"/><inertia ixx="{i}" ixy="{j}" '
             'ixz="0" iyy="{i}" iyz="0" izz="{k}"/></inertial>')


def gripper_urdf() -> str:
    """An arm (shoulder, elbow) with a wrist geared to the elbow (``q = -2 q_elbow + 0.3``) and a parallel
    gripper whose right finger mimics the left one (Panda / Robotiq style: the same stroke, opposite axes)."""
    links = {"arm": ("0.1 0 0.05", 2.0, 0.02, 0.025), "fore": ("0.15 0.02 0", 1.2, 0.01, 0.02),
             "hand": ("0.02 0.01 0.01", 0.8, 0.002, 0.002), "left_finger": ("0 0.01 0.02", 0.1, 1e-4, 5e-5),
             "right_finger": ("0.005 -0.01 0.02", 0.15, 1e-4, 5e-5)}
    out = ['<?xml version="1.0"?>\n<robot name="gripper_arm">\n  <link name="base"/>']
    out += [f'  <link name="{n}">' + _INERTIAL.format(c=c, m=m, i=i, j=i / 10, k=k) + "</link>" for n, (c, m, i, k) in links.items()]

    def joint(name, typ, parent, child, xyz, rpy, axis, extra=""):
        return (f'  <joint name="{name}" type="{typ}"><parent link="{parent}"/><child link="{child}"/>'
                f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>'
                f'<limit lower="-1" upper="1" velocity="2" effort="30"/>{extra}</joint>')
    out += [joint("shoulder", "revolute", "base", "arm", "0 0 0.3", "0 0 0", "0 0 1"),
            joint("elbow", "revolute", "arm", "fore", "0.4 0 0", "1.5707963267948966 0 0", "0 0 1"),
            joint("wrist", "revolute", "fore", "hand", "0.3 0 0", "0 0 0.2", "0 0 1",
                  '<mimic joint="elbow" multiplier="-2" offset="0.3"/>'),
            joint("finger_left", "prismatic", "hand", "left_finger", "0.1 0 0", "0 0 0", "0 1 0"),
            joint("finger_right", "prismatic", "hand", "right_finger", "0.1 0 0", "0 0 0", "0 -1 0",
                  '<mimic joint="finger_left" multiplier="1" offset="0"/>')]
    return "\n".join(out) + "\n</robot>\n"


def pinocchio_mimic_torque(urdf: str, q, dq, ddq):
    pm = pin.buildModelFromXML(urdf, mimic=True)
    data = pm.createData()
    assert pm.nq == q.shape[1]  # one configuration variable per independent joint
    return np.array([pin.rnea(pm, data, a, b, c) for a, b, c in zip(q, dq, ddq)])


def test_gripper_urdf_imports_with_coupled_joints_equal_to_pinocchio_mimic():
    urdf = gripper_urdf()
    toml = import_urdf_text(urdf, file="gripper.urdf")
    robot = parse_robot_text(toml)
    assert [(c.joint, c.source, float(c.multiplier), float(c.offset)) for c in robot.couplings] == [
        (3, 2, -2.0, 0.3), (5, 4, 1.0, 0.0)]
    assert [r.mu for r in robot.joints] == [1, 1, 0, 1, 0]
    assert robot.limits is not None and len(robot.limits.q_min) == 3  # [limits]: the actuated joints only
    assert "wrist follows elbow, finger_right follows finger_left" in toml
    model = ClosedLoopModel(robot, build_in_memory(robot))
    rng = np.random.default_rng(3)
    q, dq, ddq = rng.uniform(-1, 1, (3, 12, 3)) * np.array([1, 1, 0.04])
    ours = model.torque(q, dq, ddq, robot.nominal_vector())
    ref = pinocchio_mimic_torque(urdf, q, dq, ddq)
    np.testing.assert_allclose(ours, ref, atol=1e-9 * np.abs(ref).max())


def test_export_urdf_writes_mimic_and_the_round_trip_keeps_the_actuated_torques():
    robot = parse_robot_text(toy_text(), file="coupled_toy.toml")
    rng = np.random.default_rng(6)
    chi = np.asarray(random_physical_parameters(robot, rng))
    names = robot.standard_names
    for k, n in enumerate(names):  # URDF has no field for the rotor inertia and the torque offset
        if n.startswith(("IA", "OFF")):
            chi[k] = 0.0
    urdf = export_urdf(robot, chi)
    tags = parse_urdf_text(urdf).joints
    assert (tags["joint3"].mimic, tags["joint3"].mimic_multiplier, tags["joint3"].mimic_offset) == (
        "joint2", -2.0, pytest.approx(np.pi / 6, abs=1e-15))
    assert (tags["joint5"].mimic, tags["joint5"].mimic_multiplier) == ("joint4", 0.5)
    back = parse_robot_text(import_urdf_text(urdf, file="coupled_toy.urdf"))
    assert [(c.joint, c.source) for c in back.couplings] == [(3, 2), (5, 4)]
    m1 = ClosedLoopModel(robot, build_in_memory(robot))
    m2 = ClosedLoopModel(back, build_in_memory(back))
    q, dq, ddq = rng.uniform(-1, 1, (3, 12, 3)) * np.array([1, 1, 0.05])
    tau1 = m1.torque(q, dq, ddq, chi)
    tau2 = m2.torque(q, dq, ddq, back.nominal_vector())
    np.testing.assert_allclose(tau2, tau1, atol=1e-9 * np.abs(tau1).max())
    # Pinocchio on the exported URDF, at rest (dq = 0: no friction, sign(0) = 0; IA and OFF are 0 here)
    ref = pinocchio_mimic_torque(urdf, q, 0 * dq, ddq)
    np.testing.assert_allclose(m1.torque(q, 0 * dq, ddq, chi), ref, atol=1e-9 * np.abs(ref).max())
