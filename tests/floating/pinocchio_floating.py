"""An independent oracle for floating-base robots: Pinocchio with a free-flyer root.

The same construction as :mod:`tests.oracles.pinocchio_model` (joint placements composed from plain numpy
rotations by :func:`~tests.oracles.pinocchio_model.constant_placement`, inertias converted by Pinocchio's
own ``Inertia.FromDynamicParameters``), with ``pin.JointModelFreeFlyer`` as the root joint: frame 0 is the
free-flyer's body, carrying the base link's parameters ``XX0 .. M0``. Nothing here uses symoro_gen's
transforms, Newton-Euler code or quaternion conversion. Drive terms (IA, FV, FS, OFF) are added on the joint
rows as in :func:`~tests.oracles.pinocchio_model.pin_torque`.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from symoro_gen.description.model import FIXED, REVOLUTE, RobotDescription
from symoro_gen.params import INERTIAL_KINDS
from tests.oracles.pinocchio_model import constant_placement, random_inertial, standard_to_inertia


def build_floating_pinocchio(robot: RobotDescription, chi_std, chi_payload=None) -> tuple[pin.Model, pin.Data]:
    """A Pinocchio model of the floating-base ``robot`` (free-flyer root) carrying ``chi_std``
    (``robot.standard_names`` order, the base link's 10 parameters first)."""
    vals = dict(zip(robot.standard_names, np.asarray(chi_std, float)))
    if chi_payload is not None and robot.payload is not None:
        vals.update(zip(robot.payload_names, np.asarray(chi_payload, float)))
    model = pin.Model()
    model.name = robot.name
    model.gravity = pin.Motion(np.asarray(robot.gravity, float), np.zeros(3))
    root = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    holder: dict[int, tuple[int, pin.SE3]] = {0: (root, pin.SE3.Identity())}
    for row in robot.rows:
        placement, sign = constant_placement(robot, row.j)
        parent_id, parent_pl = holder[row.ant]
        where = parent_pl * placement
        if row.sigma == FIXED:
            holder[row.j] = (parent_id, where)
            continue
        axis = np.array([0.0, 0.0, float(sign)])
        if row.sigma == REVOLUTE:
            jm = pin.JointModelRZ() if sign > 0 else pin.JointModelRevoluteUnaligned(axis)
        else:
            jm = pin.JointModelPZ() if sign > 0 else pin.JointModelPrismaticUnaligned(axis)
        holder[row.j] = (model.addJoint(parent_id, jm, where, f"joint{row.j}"), pin.SE3.Identity())
    links = [0] + [r.j for r in robot.rows if r.is_moving or r.j == robot.payload]
    for j in links:
        inertia = standard_to_inertia([vals.get(f"{k}{j}", 0.0) for k in INERTIAL_KINDS])
        if inertia is not None:
            jid, pl = holder[j]
            model.appendBodyToJoint(jid, inertia, pl)
    return model, model.createData()


def pin_floating_torque(robot: RobotDescription, q, dq, ddq, chi_std, chi_payload=None) -> np.ndarray:
    """``(N, 6 + n)``: Pinocchio's RNEA with a free-flyer root (base wrench, then joint torques), plus the
    drive terms ``IA ddq + FV dq + FS sign(dq) + OFF`` on the joint rows."""
    q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
    model, data = build_floating_pinocchio(robot, chi_std, chi_payload)
    vals = dict(zip(robot.standard_names, np.asarray(chi_std, float)))
    frames = [r.j for r in robot.joints]
    IA, FV, FS, OFF = (np.array([vals.get(f"{k}{j}", 0.0) for j in frames]) for k in ("IA", "FV", "FS", "OFF"))
    out = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(q.shape[0])])
    out[:, 6:] += IA * ddq[:, 6:] + FV * dq[:, 6:] + FS * np.sign(dq[:, 6:]) + OFF
    return out


def random_floating_parameters(robot: RobotDescription, rng: np.random.Generator) -> np.ndarray:
    """Physically consistent standard parameters of every link, the base's included (drive terms: IA, FV,
    FS uniform in [0, 1), OFF standard normal), in ``robot.standard_names`` order."""
    vals = dict(zip((f"{k}0" for k in INERTIAL_KINDS), random_inertial(rng, mass=(5.0, 15.0))))
    for row in robot.joints:
        vals.update(zip((f"{k}{row.j}" for k in INERTIAL_KINDS), random_inertial(rng)))
        for kind in row.drive:
            vals[f"{kind}{row.j}"] = rng.normal() if kind == "OFF" else rng.uniform()
    return np.array([vals[n] for n in robot.standard_names])


def random_floating_states(robot: RobotDescription, n_samples: int, rng: np.random.Generator
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q, dq, ddq)`` of shapes ``(N, 7 + n)``, ``(N, 6 + n)``, ``(N, 6 + n)`` in Pinocchio's free-flyer
    conventions: a random base position, a uniformly random unit quaternion (``x y z w``, normalised
    Gaussian), random velocities and accelerations."""
    n = robot.n_joints
    quat = rng.normal(size=(n_samples, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    q = np.hstack([rng.normal(size=(n_samples, 3)), quat, rng.uniform(-np.pi, np.pi, (n_samples, n))])
    dq = rng.normal(size=(n_samples, 6 + n))
    ddq = rng.normal(scale=3.0, size=(n_samples, 6 + n))
    return q, dq, ddq
