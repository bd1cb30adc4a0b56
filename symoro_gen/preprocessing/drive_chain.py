"""Motor side <-> joint side mapping of a :class:`~symoro_gen.description.model.DriveChain`.

Convention (``R = diag(ratios) @ coupling``, ``D = diag(directions)``)::

    q_motor   = R @ D @ (q_joint - offsets)
    q_joint   = D @ inv(R) @ q_motor + offsets
    tau_joint = D @ R.T @ tau_motor          (power balance)

Velocities and accelerations map as positions without the offsets.
(Drive-chain calibration: [RG1995]; the measured joint torque as a gain times the control signal,
``tau = g v``: [GB-gains] eq. 4.)
"""
from __future__ import annotations

import numpy as np

from ..description.model import DriveChain

__all__ = ["chain_matrix", "motor_to_joint", "joint_to_motor"]


def chain_matrix(chain: DriveChain) -> np.ndarray:
    """``R = diag(ratios) @ coupling``: motor angles per joint angle, shape (n, n)."""
    return np.diag(np.asarray(chain.ratios, float)) @ np.asarray(chain.coupling, float)


def _check(chain: DriveChain, a, name):
    if a is None:
        return None
    a = np.asarray(a, float)
    n = len(chain.ratios)
    if a.shape[-1] != n:
        raise ValueError(f"{name} has {a.shape[-1]} columns, the drive chain has {n} joints")
    return a


def motor_to_joint(chain: DriveChain, q_motor=None, tau_motor=None, dq_motor=None, ddq_motor=None):
    """Map motor-side samples to the joint side.

    Parameters
    ----------
    chain : DriveChain
    q_motor, dq_motor, ddq_motor : array_like, shape (N, n), optional
        Motor angles [rad], velocities [rad/s], accelerations [rad/s^2].
    tau_motor : array_like, shape (N, n), optional
        Motor torques [N m].

    Returns
    -------
    (q, tau, dq, ddq) : joint-side arrays (None where the input was None)
    """
    R = chain_matrix(chain)
    Rinv = np.linalg.inv(R)
    D = np.asarray(chain.directions, float)
    off = np.asarray(chain.offsets, float)
    q_motor, tau_motor, dq_motor, ddq_motor = (
        _check(chain, a, k) for a, k in ((q_motor, "q"), (tau_motor, "tau"), (dq_motor, "dq"), (ddq_motor, "ddq"))
    )
    q = None if q_motor is None else (q_motor @ Rinv.T) * D + off
    dq = None if dq_motor is None else (dq_motor @ Rinv.T) * D
    ddq = None if ddq_motor is None else (ddq_motor @ Rinv.T) * D
    tau = None if tau_motor is None else (tau_motor @ R) * D
    return q, tau, dq, ddq


def joint_to_motor(chain: DriveChain, q=None, tau=None, dq=None, ddq=None):
    """Inverse of :func:`motor_to_joint` (for simulating motor-side recordings).

    Returns
    -------
    (q_motor, tau_motor, dq_motor, ddq_motor)
    """
    R = chain_matrix(chain)
    Rinv = np.linalg.inv(R)
    D = np.asarray(chain.directions, float)
    off = np.asarray(chain.offsets, float)
    q, tau, dq, ddq = (_check(chain, a, k) for a, k in ((q, "q"), (tau, "tau"), (dq, "dq"), (ddq, "ddq")))
    qm = None if q is None else ((q - off) * D) @ R.T
    dqm = None if dq is None else (dq * D) @ R.T
    ddqm = None if ddq is None else (ddq * D) @ R.T
    taum = None if tau is None else (tau * D) @ Rinv  # R^-T (D tau), as rows
    return qm, taum, dqm, ddqm
