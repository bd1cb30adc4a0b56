"""Plain numeric recursive Newton-Euler (an independent reference for the symbolic model).

Works directly from the MDH table with numpy, vectorised over samples; no sympy graph.
The recursion is the textbook one ([KD2002] ch. 9: forward velocities and accelerations, backward
wrenches, projection on the joint axes), with the link inertia at the frame origin ([FO2008]).
"""
from __future__ import annotations

import numpy as np

from ..description.inertia import matrix_from_six
from ..description.mdh import joint_sign, row_values, transform
from ..description.model import PRISMATIC, REVOLUTE, RobotDescription
from ..params import INERTIAL_KINDS


def inverse_dynamics(robot: RobotDescription, q, dq, ddq, chi_std, chi_payload=None):
    """Joint torques by numeric Newton-Euler.

    Parameters
    ----------
    robot : RobotDescription
    q, dq, ddq : array_like, shape (N, n) or (n,)
        Joint positions [rad or m], velocities, accelerations.
    chi_std : array_like, shape (len(robot.standard_names),)
        Standard parameters in ``robot.standard_names`` order.
    chi_payload : array_like, shape (10,), optional
        Payload inertial parameters (XX..M of the payload frame).

    Returns
    -------
    ndarray, shape (N, n) (or (n,) for 1-D inputs)
    """
    q, dq, ddq = (np.asarray(x, float) for x in (q, dq, ddq))
    one = q.ndim == 1
    q, dq, ddq = (np.atleast_2d(x) for x in (q, dq, ddq))
    N = q.shape[0]
    subs = robot.geometry_subs()
    vals = dict(zip(robot.standard_names, np.asarray(chi_std, float)))
    if chi_payload is not None and robot.payload is not None:
        vals.update(zip(robot.payload_names, np.asarray(chi_payload, float)))
    col = {f: i for i, f in enumerate(r.j for r in robot.joints)}

    w, wd, vd, Rs, Ps = {}, {}, {}, {}, {}
    w[0] = np.zeros((N, 3))
    wd[0] = np.zeros((N, 3))
    vd[0] = np.tile(-np.asarray(robot.gravity, float), (N, 1))
    for row in robot.rows:
        j, a = row.j, row.ant
        if row.is_moving:
            sgn = joint_sign(row)
            T = transform(*row_values(row, subs, q[:, col[j]]))
        else:
            T = np.broadcast_to(transform(*row_values(row, subs)), (N, 4, 4))
        R, P = T[:, :3, :3], T[:, :3, 3]  # (N,3,3), (N,3)
        Rs[j], Ps[j] = R, P
        RT = np.transpose(R, (0, 2, 1))
        wa = np.einsum("nij,nj->ni", RT, w[a])
        wda = np.einsum("nij,nj->ni", RT, wd[a])
        acc = vd[a] + np.cross(wd[a], P) + np.cross(w[a], np.cross(w[a], P))
        vj = np.einsum("nij,nj->ni", RT, acc)
        z = np.array([0.0, 0.0, 1.0])
        if row.sigma == REVOLUTE:
            qd, qdd = sgn * dq[:, col[j]], sgn * ddq[:, col[j]]
            w[j] = wa + qd[:, None] * z
            wd[j] = wda + qdd[:, None] * z + np.cross(wa, qd[:, None] * z)
            vd[j] = vj
        elif row.sigma == PRISMATIC:
            qd, qdd = sgn * dq[:, col[j]], sgn * ddq[:, col[j]]
            w[j], wd[j] = wa, wda
            vd[j] = vj + 2 * np.cross(wa, qd[:, None] * z) + qdd[:, None] * z
        else:
            w[j], wd[j], vd[j] = wa, wda, vj

    f = {j: np.zeros((N, 3)) for j in range(len(robot.rows) + 1)}
    n = {j: np.zeros((N, 3)) for j in range(len(robot.rows) + 1)}
    tau = np.zeros((N, robot.n_joints))
    for row in reversed(robot.rows):
        j = row.j
        p = {k: vals.get(f"{k}{j}", 0.0) for k in INERTIAL_KINDS}
        J = matrix_from_six([p[k] for k in INERTIAL_KINDS[:6]])
        MS = np.array([p["MX"], p["MY"], p["MZ"]])
        F = p["M"] * vd[j] + np.cross(wd[j], MS) + np.cross(w[j], np.cross(w[j], MS))
        Nm = (wd[j] @ J.T) + np.cross(w[j], w[j] @ J.T) + np.cross(MS, vd[j])
        fj = F + f[j]
        nj = Nm + n[j]
        if row.is_moving:
            i = col[j]
            t = nj[:, 2] if row.sigma == REVOLUTE else fj[:, 2]
            t = t * joint_sign(row)
            t = t + vals.get(f"IA{j}", 0.0) * ddq[:, i] + vals.get(f"FV{j}", 0.0) * dq[:, i]
            t = t + vals.get(f"FS{j}", 0.0) * np.sign(dq[:, i]) + vals.get(f"OFF{j}", 0.0)
            tau[:, i] = t
        a = row.ant
        fa = np.einsum("nij,nj->ni", Rs[j], fj)
        f[a] = f[a] + fa
        n[a] = n[a] + np.einsum("nij,nj->ni", Rs[j], nj) + np.cross(Ps[j], fa)
    return tau[0] if one else tau


def numeric_regressor(robot: RobotDescription, q, dq, ddq):
    """Standard and payload regressor columns by numeric Newton-Euler (slow; a reference).

    Returns
    -------
    (W_std, W_payload) : ndarrays of shapes (N, n, n_st) and (N, n, 10) (payload one empty
    ``(N, n, 0)`` when the robot has no payload).
    """
    q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
    ns, npay = len(robot.standard_names), len(robot.payload_names)
    cols = []
    for k in range(ns + npay):
        e = np.zeros(ns + npay)
        e[k] = 1.0
        cols.append(inverse_dynamics(robot, q, dq, ddq, e[:ns], e[ns:] if npay else None))
    W = np.stack(cols, axis=-1) if cols else np.zeros(q.shape + (0,))
    return W[..., :ns], W[..., ns:]
