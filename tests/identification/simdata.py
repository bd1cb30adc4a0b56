"""Simulated identification data with known truth (numeric Newton-Euler regressor).

The regressor of a robot file is evaluated at random states by
:func:`symoro_gen.dynamics.numeric.numeric_regressor` (exact, slow). The base columns are chosen by
a column-pivoted QR of the unit-norm standard columns (deterministic given the seeded states);
the true base parameters are the projection of ``W_std chi_std`` on them (exact, since the other
columns are combinations of the base ones).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from symoro_gen.description import load_robot
from symoro_gen.description.inertia import standard_from_com
from symoro_gen.dynamics.numeric import numeric_regressor
from symoro_gen.identification import ObservationSystem
from symoro_gen.params import INERTIAL_KINDS
from symoro_gen.simulate import random_states

RANK_TOL = 1e-9


def _rot(rng):
    A = rng.normal(size=(3, 3))
    Q, R = np.linalg.qr(A)
    return Q * np.sign(np.diag(R))


def link_inertial(rng: np.random.Generator, m_range=(1.0, 8.0), com_scale=0.15, gyr=(0.04, 0.15)):
    """Physically plausible 10 inertial parameters XX XY XZ YY YZ ZZ MX MY MZ M at the frame origin."""
    m = rng.uniform(*m_range)
    c = rng.uniform(-com_scale, com_scale, 3)
    # principal moments from a random box (triangle inequalities hold)
    a, b, cc = rng.uniform(*gyr, 3)
    Ip = m * np.array([b * b + cc * cc, a * a + cc * cc, a * a + b * b])  # box-like: triangle inequalities hold
    R = _rot(rng)
    return standard_from_com(m, c, R @ np.diag(Ip) @ R.T)


def standard_parameters(robot, rng: np.random.Generator) -> np.ndarray:
    """Random plausible standard parameters in ``robot.standard_names`` order."""
    vals = {}
    for row in robot.joints:
        j = row.j
        p = link_inertial(rng)
        for k, v in zip(INERTIAL_KINDS, p):
            vals[f"{k}{j}"] = v
        vals[f"IA{j}"] = rng.uniform(0.2, 1.5)
        vals[f"FV{j}"] = rng.uniform(1.0, 6.0)
        vals[f"FS{j}"] = rng.uniform(1.0, 6.0)
        vals[f"OFF{j}"] = rng.uniform(-1.0, 1.0)
    return np.array([vals[n] for n in robot.standard_names])


def payload_parameters(mass: float, com=(0.08, -0.07, 0.12), gyr=(0.05, 0.06, 0.04)) -> np.ndarray:
    """Payload 10-vector with sizeable first moments (box inertia about its COM, axes aligned)."""
    c = np.array(com, float)
    a, b, cc = gyr
    return standard_from_com(mass, c, mass * np.diag([b * b + cc * cc, a * a + cc * cc, a * a + b * b]))


def base_columns(W_std: np.ndarray, tol: float = RANK_TOL) -> np.ndarray:
    """Indices (sorted) of independent columns of the stacked regressor (r, n_st)."""
    norms = np.linalg.norm(W_std, axis=0)
    nz = np.flatnonzero(norms > tol * norms.max())
    _, R, piv = scipy.linalg.qr(W_std[:, nz] / norms[nz], mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > tol * d[0]))
    return np.sort(nz[piv[:rank]])


def stack_rows(W3: np.ndarray) -> np.ndarray:
    """(N, n, c) -> (n*N, c), rows grouped per joint (eq. 16)."""
    N, n, c = W3.shape
    return np.transpose(W3, (1, 0, 2)).reshape(n * N, c)


@dataclass(frozen=True, eq=False)
class RobotSim:
    """Regressor of a robot at random states, split into an unloaded and a loaded experiment."""

    robot: object
    names: tuple            # base column names
    base: np.ndarray        # base column indices in standard_names
    chi_std: np.ndarray
    chi_base: np.ndarray    # true base parameters
    payload_names: tuple
    chi_payload: np.ndarray
    Wa: np.ndarray          # (r_a, nb) unloaded, rows grouped per joint
    Wb: np.ndarray          # (r_b, nb) loaded
    WL: np.ndarray          # (r_b, 10) payload columns of the loaded experiment
    tau_a: np.ndarray       # noise-free torques (r_a,)
    tau_b: np.ndarray       # noise-free torques (r_b,) including the payload
    tau_b_robot: np.ndarray  # noise-free torques (r_b,) of the robot alone in the loaded states
    joint_a: np.ndarray
    joint_b: np.ndarray

    @property
    def n_joints(self) -> int:
        return self.robot.n_joints

    def unloaded(self, Y) -> ObservationSystem:
        return ObservationSystem(self.Wa, Y, self.names, self.joint_a)

    def payload_torque(self, chi_payload) -> np.ndarray:
        """Noise-free loaded torques with another payload, shape (r_b,)."""
        return self.tau_b_robot + self.WL @ np.asarray(chi_payload, float)

    def loaded(self, Y) -> ObservationSystem:
        return ObservationSystem(np.column_stack([self.Wb, self.WL]), Y, self.names + self.payload_names,
                                 self.joint_b)


def make_robot_sim(name: str, N_a: int, N_b: int, seed: int, payload_mass: float,
                   payload_com=(0.08, -0.07, 0.12)) -> RobotSim:
    robot = load_robot(name)
    rng = np.random.default_rng(seed)
    n = robot.n_joints
    # one call for both experiments: numeric_regressor's cost is mostly per call, not per sample
    Ws, Wp = numeric_regressor(robot, *random_states(rng, N_a + N_b, n, dq_scale=1.5, ddq_scale=4.0))
    Ws_a, Ws_b, Wp_b = Ws[:N_a], Ws[N_a:], Wp[N_a:]
    Wa_std, Wb_std, WL = stack_rows(Ws_a), stack_rows(Ws_b), stack_rows(Wp_b)
    base = base_columns(np.vstack([Wa_std, Wb_std]))
    chi_std = standard_parameters(robot, rng)
    chi_pay = payload_parameters(payload_mass, payload_com)
    tau_a = Wa_std @ chi_std
    tau_b_robot = Wb_std @ chi_std
    tau_b = tau_b_robot + WL @ chi_pay
    Wa, Wb = Wa_std[:, base], Wb_std[:, base]
    chi_base, *_ = np.linalg.lstsq(np.vstack([Wa, Wb]), np.r_[tau_a, tau_b_robot], rcond=None)
    assert np.allclose(np.vstack([Wa, Wb]) @ chi_base, np.r_[tau_a, tau_b_robot], rtol=0, atol=1e-8), \
        "base columns do not span the standard regressor"
    names = tuple(robot.standard_names[i] for i in base)

    def joint(N):
        return np.repeat(np.arange(n), N)

    return RobotSim(robot, names, base, chi_std, chi_base, robot.payload_names, chi_pay, Wa, Wb, WL,
                    tau_a, tau_b, tau_b_robot, joint(N_a), joint(N_b))


def joint_noise(rng: np.random.Generator, tau: np.ndarray, joint: np.ndarray, rel: float) -> np.ndarray:
    """Gaussian noise with per-joint std = rel * RMS of the joint's torque, shape like tau."""
    n = joint.max() + 1
    rms = np.sqrt(np.bincount(joint, tau ** 2, n) / np.bincount(joint, minlength=n))
    return rel * rms[joint] * rng.normal(size=tau.shape)
