"""An elastic LWR4 joint simulated independently of the project's simulator: Pinocchio's dynamics (the truth
bench's ``bench/truthsim.py``) and Spong's flexible-joint transmission.

Spong 1987 ("Modeling and control of elastic joint robots", eq. 3-4): the link side obeys the rigid-body
dynamics ``M(q) ddq + c(q, dq) + g(q) + f(dq) = tau_J`` (here Pinocchio's RNEA along a sum-of-sines link
trajectory, plus the truth bench's Coulomb + viscous joint friction), the transmitted (joint-sensor) torque
is ``tau_J = K (theta - q) + D (dtheta - dq)``, ``theta`` the motor position on the joint side. So the
deflection ``delta = theta - q`` obeys ``D ddelta/dt + K delta = tau_J``: integrated here exactly for a torque
linear between samples (``scipy.signal.lsim``), from the static deflection ``tau_J(0) / K`` (``D = 0``: the
static deflection ``tau_J / K`` throughout).

A *two-encoder* log has the motor position ``theta``, the link position ``q`` and ``tau_J``; the *one-encoder*
log (case 8 of the truth bench: the LWR4's own ``positions``) has ``theta`` and ``tau_J`` only.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

from symoro_gen.description import load_robot
from symoro_gen.paths import robots_dir

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
try:
    import truthsim as ts  # type: ignore[import-not-found]
finally:
    sys.path.remove(str(ROOT / "bench"))

#: the elastic joint of the truth bench's case 8 (0-based: LWR4 joint 4) and its stiffness [N m/rad]
JOINT = 3
K_TRUE = 3000.0
#: its damping [N m s/rad]: a time constant D/K of 5 ms
D_TRUE = 15.0
#: encoder noise [rad] (a 21-bit encoder: step 3e-6 rad, sigma = step / sqrt(12)) and torque noise [N m]
SIGMA_Q = 1e-6
SIGMA_TAU = 0.05


@dataclass(frozen=True)
class ElasticLog:
    """One simulated recording: ``t``, the motor side ``theta`` (every joint: the link position plus the
    deflection on the elastic joint), the link side ``q_link``, the joint torque ``tau`` (measured, noisy), the
    true deflection and torque."""

    t: np.ndarray
    theta: np.ndarray
    q_link: np.ndarray
    tau: np.ndarray
    delta: np.ndarray
    tau_true: np.ndarray


def elastic_log(seed: int, seconds: float = 20.0, rate: float = 250.0, *, K: float = K_TRUE, D: float = D_TRUE,
                joint: int = JOINT) -> ElasticLog:
    """An LWR4 recording (nominal parameters of robots/lwr4.toml, friction of the truth bench) with joint
    ``joint`` elastic (``K``, ``D``); the other joints rigid."""
    robot = load_robot("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rigid = ts.Rigid(robot, chi)
    rng = np.random.default_rng(seed)
    exc = ts.sum_of_sines(robot, rng)
    truth = ts.Truth(FV=ts.drive_values(robot, chi, "FV"), FS=ts.drive_values(robot, chi, "FS"),
                     OFF=ts.drive_values(robot, chi, "OFF"), sigma_tau=SIGMA_TAU)
    t = np.arange(int(round(seconds * rate))) / rate
    q, dq, ddq = exc.at(t)
    tau_r = rigid(q, dq, ddq)
    tau = tau_r + truth.friction(t, dq, tau_r, float(t[-1]))
    delta = np.zeros_like(q)
    tj = tau[:, joint]
    if D > 0:
        sys_ = signal.StateSpace([[-K / D]], [[1.0 / D]], [[1.0]], [[0.0]])
        _, y, _ = signal.lsim(sys_, tj, t, X0=[tj[0] / K])
        delta[:, joint] = y
    else:   # no damping: the static deflection
        delta[:, joint] = tj / K
    theta = q + delta + SIGMA_Q * rng.standard_normal(q.shape)
    q_link = q + SIGMA_Q * rng.standard_normal(q.shape)
    tau_meas = tau + SIGMA_TAU * rng.standard_normal(tau.shape)
    return ElasticLog(t=t, theta=theta, q_link=q_link, tau=tau_meas, delta=delta, tau_true=tau)


def write_csv(log: ElasticLog, path: Path, *, two_encoders: bool) -> str:
    """The log as CSV (``t, qm1..7, tau1..7[, ql1..7]``); returns the ``--columns`` mapping that reads it."""
    n = log.theta.shape[1]
    cols = [log.t[:, None], log.theta, log.tau] + ([log.q_link] if two_encoders else [])
    head = ["t"] + [f"qm{i + 1}" for i in range(n)] + [f"tau{i + 1}" for i in range(n)]
    if two_encoders:
        head += [f"ql{i + 1}" for i in range(n)]
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(head), comments="", fmt="%.12g")
    spec = f"t=t,q=qm1:qm{n},tau=tau1:tau{n}"
    return spec + (f",q_link=ql1:ql{n}" if two_encoders else "")


def lwr4_elastic_file(path: Path, K: float, D: float | None = None, joint: int = JOINT) -> Path:
    """robots/lwr4.toml with frame ``joint + 1`` declared elastic (``elastic = {K, D}``), written to ``path``."""
    text = (robots_dir() / "lwr4.toml").read_text().replace('name = "lwr4"', 'name = "lwr4_elastic"', 1)
    parts = text.split("[[frames]]")
    decl = f"elastic = {{K = {K:g}" + (f", D = {D:g}" if D is not None else "") + "}\n"
    assert "r = " in parts[joint + 1]
    parts[joint + 1] = parts[joint + 1].replace("r = ", decl + "r = ", 1)
    path.write_text("[[frames]]".join(parts))
    return path
