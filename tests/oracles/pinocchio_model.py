"""An independent oracle: a Pinocchio model built from an MDH table.

Nothing here uses symoro_gen's transforms or Newton-Euler code: the joint placements are
composed from plain numpy rotations, the link inertias are converted by Pinocchio itself
(``pin.Inertia.FromDynamicParameters``), and the torques come from
Pinocchio's RNEA. Only the parsed :class:`RobotDescription` (the MDH table itself) is shared.

Conventions mirrored from the robot file:

* ``T(ant, j) = Rot(z, gamma) Trans(z, b) Rot(x, alpha) Trans(x, d) Rot(z, theta) Trans(z, r)``;
  since ``Rot(z, theta)`` and ``Trans(z, r)`` commute, the constant part (theta and r at
  ``q = 0``) is the joint placement and the joint itself is a rotation (sigma 0) or a
  translation (sigma 1) along the local z axis, by ``+q`` or ``-q`` (a ``-q`` joint is a
  Pinocchio joint about/along ``-z``).
* Standard parameters of link j are given in frame j at its origin: inertia ``J_O`` about
  the origin, first moments ``MS = m c``, mass ``m``.
* Fixed frames (sigma 2) are merged into the body of their nearest moving ancestor; the
  payload frame's inertia (``chi_payload``) is appended to that body.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import sympy as sp

from symoro_gen.description.model import FIXED, PRISMATIC, REVOLUTE, RobotDescription, q_symbol
from symoro_gen.params import INERTIAL_KINDS

#: Masses below this are treated as "no body" (Pinocchio needs m > 0 to place a centre of mass).
MIN_MASS = 1e-12


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _se3(R: np.ndarray, p) -> pin.SE3:
    return pin.SE3(np.asarray(R, float), np.asarray(p, float).reshape(3))


def _value(expr, subs: dict) -> float:
    return float(sp.sympify(expr).subs(subs))


def constant_placement(robot: RobotDescription, j: int) -> tuple[pin.SE3, int]:
    """Placement of frame j in frame ant(j) at ``q = 0`` and the joint sign (+1, -1, 0 if fixed).

    Composed as ``Rot(z,gamma) Trans(z,b) Rot(x,alpha) Trans(x,d) Rot(z,theta0) Trans(z,r0)``
    with 4x4 homogeneous products (no symoro_gen transform code involved).
    """
    row = robot.row(j)
    subs = dict(robot.geometry_subs())
    qj = q_symbol(j)
    subs[qj] = 0
    sign = 0
    if row.sigma == REVOLUTE:
        sign = int(sp.diff(row.theta, qj))
    elif row.sigma == PRISMATIC:
        sign = int(sp.diff(row.r, qj))

    def hom(R=None, p=None):
        T = np.eye(4)
        if R is not None:
            T[:3, :3] = R
        if p is not None:
            T[:3, 3] = p
        return T

    gamma, b, alpha, d, theta, r = (_value(getattr(row, k), subs) for k in ("gamma", "b", "alpha", "d", "theta", "r"))
    T = (
        hom(R=_rz(gamma)) @ hom(p=[0, 0, b]) @ hom(R=_rx(alpha)) @ hom(p=[d, 0, 0])
        @ hom(R=_rz(theta)) @ hom(p=[0, 0, r])
    )
    return _se3(T[:3, :3], T[:3, 3]), sign


#: Pinocchio's dynamic parameters ``[m, mc_x, mc_y, mc_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]`` (inertia
#: about the frame origin) are the standard ``XX XY XZ YY YZ ZZ MX MY MZ M`` taken in this order
PIN_ORDER = np.array([9, 6, 7, 8, 0, 1, 3, 2, 4, 5])


def standard_to_inertia(p10) -> pin.Inertia | None:
    """``XX XY XZ YY YZ ZZ MX MY MZ M`` (frame origin) -> ``pin.Inertia`` (Pinocchio's own conversion).

    The oracle does not use symoro_gen's inertia conversions: the parameters are reordered into
    Pinocchio's dynamic parameters and converted by ``pin.Inertia.FromDynamicParameters`` (which,
    unlike Pinocchio's constructor, accepts non-physical values: the identities tested with this
    oracle are linear in the parameters). Returns None for a massless link whose parameters are
    all zero; raises for a massless link with non-zero first moments or inertia (not
    representable with a centre of mass).
    """
    p = np.asarray([float(x) for x in p10])
    if abs(p[9]) < MIN_MASS:
        if np.any(p != 0):
            raise ValueError("a massless link with non-zero inertia or first moments cannot be given to Pinocchio")
        return None
    return pin.Inertia.FromDynamicParameters(p[PIN_ORDER])


def inertia_to_standard(inertia: pin.Inertia) -> np.ndarray:
    """Inverse of :func:`standard_to_inertia` (Pinocchio's ``toDynamicParameters`` reordered)."""
    out = np.empty(10)
    out[PIN_ORDER] = inertia.toDynamicParameters()
    return out


def build_pinocchio_model(robot: RobotDescription, chi_std, chi_payload=None) -> tuple[pin.Model, pin.Data]:
    """A Pinocchio model of ``robot`` carrying the standard parameters ``chi_std``.

    Parameters
    ----------
    robot : RobotDescription
        Parsed MDH table (serial or tree; fixed frames after the moving ones).
    chi_std : array_like, shape (len(robot.standard_names),)
        Standard parameters in ``robot.standard_names`` order (drive terms are ignored here;
        :func:`pin_torque` adds them).
    chi_payload : array_like, shape (10,), optional
        Payload inertial parameters ``XXk .. Mk`` in the payload frame k at its origin.

    Returns
    -------
    (pin.Model, pin.Data)
        Joint i of the model (1-based, Pinocchio order) is the i-th moving frame of the
        table; its configuration is the robot's ``q_i`` (a ``-q`` joint is modelled about
        ``-z``). ``model.gravity`` is set from ``robot.gravity`` (base frame 0).
    """
    chi_std = np.asarray(chi_std, float)
    vals = dict(zip(robot.standard_names, chi_std))
    if chi_payload is not None and robot.payload is not None:
        vals.update(zip(robot.payload_names, np.asarray(chi_payload, float)))

    model = pin.Model()
    model.name = robot.name
    model.gravity = pin.Motion(np.asarray(robot.gravity, float), np.zeros(3))
    # frame number -> (pinocchio joint id holding it, placement of the frame in that joint)
    holder: dict[int, tuple[int, pin.SE3]] = {0: (0, pin.SE3.Identity())}
    for row in robot.rows:
        j = row.j
        placement, sign = constant_placement(robot, j)
        parent_id, parent_pl = holder[row.ant]
        where = parent_pl * placement
        if row.sigma == FIXED:
            holder[j] = (parent_id, where)
            continue
        axis = np.array([0.0, 0.0, float(sign)])
        if row.sigma == REVOLUTE:
            jm = pin.JointModelRZ() if sign > 0 else pin.JointModelRevoluteUnaligned(axis)
        else:
            jm = pin.JointModelPZ() if sign > 0 else pin.JointModelPrismaticUnaligned(axis)
        jid = model.addJoint(parent_id, jm, where, f"joint{j}")
        holder[j] = (jid, pin.SE3.Identity())

    for row in robot.rows:
        j = row.j
        is_payload = robot.payload is not None and j == robot.payload
        if not row.is_moving and not is_payload:
            continue
        inertia = standard_to_inertia([vals.get(f"{k}{j}", 0.0) for k in INERTIAL_KINDS])
        jid, pl = holder[j]
        if inertia is None or jid == 0:
            continue  # nothing to carry, or a body fixed to the ground (no torque)
        model.appendBodyToJoint(jid, inertia, pl)
    return model, model.createData()


def pin_torque(robot: RobotDescription, q, dq, ddq, chi_std, chi_payload=None):
    """Joint torques by Pinocchio: RNEA + IA ddq + FV dq + FS sign(dq) + OFF.

    Parameters
    ----------
    robot : RobotDescription
    q, dq, ddq : array_like, shape (N, n) or (n,)
        Joint positions [rad or m], velocities, accelerations (robot joint order).
    chi_std : array_like, shape (len(robot.standard_names),)
    chi_payload : array_like, shape (10,), optional

    Returns
    -------
    ndarray, shape (N, n) (or (n,) for 1-D inputs) [N m or N]
    """
    q, dq, ddq = (np.asarray(x, float) for x in (q, dq, ddq))
    one = q.ndim == 1
    q, dq, ddq = (np.atleast_2d(x) for x in (q, dq, ddq))
    model, data = build_pinocchio_model(robot, chi_std, chi_payload)
    vals = dict(zip(robot.standard_names, np.asarray(chi_std, float)))
    n = robot.n_joints
    frames = [r.j for r in robot.joints]
    IA = np.array([vals.get(f"IA{j}", 0.0) for j in frames])
    FV = np.array([vals.get(f"FV{j}", 0.0) for j in frames])
    FS = np.array([vals.get(f"FS{j}", 0.0) for j in frames])
    OFF = np.array([vals.get(f"OFF{j}", 0.0) for j in frames])
    tau = np.empty((q.shape[0], n))
    for k in range(q.shape[0]):
        tau[k] = pin.rnea(model, data, q[k], dq[k], ddq[k])
    tau += IA * ddq + FV * dq + FS * np.sign(dq) + OFF
    return tau[0] if one else tau


def random_inertial(rng: np.random.Generator, *, mass=(0.5, 3.0), com_scale=0.2, inertia_scale=0.1) -> np.ndarray:
    """Physically consistent ``XX XY XZ YY YZ ZZ MX MY MZ M`` of one body (frame-origin values).

    Mass uniform in ``mass`` [kg], centre of mass normal with ``com_scale`` [m], inertia about
    the centre of mass ``A A^T + 0.01 inertia_scale^2 E`` with ``A`` normal (``inertia_scale``).
    """
    m = rng.uniform(*mass)
    c = rng.normal(scale=com_scale, size=3)
    A = rng.normal(scale=inertia_scale, size=(3, 3))
    I_c = A @ A.T + 0.01 * inertia_scale**2 * np.eye(3)
    return inertia_to_standard(pin.Inertia(m, c, I_c))


def random_parameters(robot: RobotDescription, rng: np.random.Generator):
    """Random physically consistent standard parameters (and payload ones when the robot has a payload).

    Drive terms: IA, FV, FS uniform in [0, 1), OFF standard normal.

    Returns
    -------
    (chi_std, chi_payload) : ndarray (len(standard_names),), ndarray (10,) or None
    """
    vals: dict[str, float] = {}
    for row in robot.joints:
        vals.update(zip((f"{k}{row.j}" for k in INERTIAL_KINDS), random_inertial(rng)))
        for kind in row.drive:
            vals[f"{kind}{row.j}"] = rng.normal() if kind == "OFF" else rng.uniform()
    chi = np.array([vals[n] for n in robot.standard_names])
    pay = random_inertial(rng) if robot.payload is not None else None
    return chi, pay


def max_relative_error(a, b) -> float:
    """``max |a - b| / max |b|`` (error relative to the largest reference value)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = np.abs(b).max()
    return float(np.abs(a - b).max() / scale) if scale > 0 else float(np.abs(a).max())
