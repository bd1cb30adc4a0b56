"""Simulated recordings for the diagnosis tests: a known robot, a known effect injected with the
physical models of :mod:`symoro_gen.diagnostics.inject`, noise on q and torque; only t, q and tau are
given to the tool."""
from __future__ import annotations

import functools

import numpy as np

import symoro_gen
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.diagnostics import inject_effect, stability
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques

#: encoder noise [rad] (m for prismatic joints) and torque noise [N m]
NOISE_Q = 1e-5
NOISE_TAU = 0.05
DURATION = 40.0
DT = 0.002


@functools.cache
def robot_and_model(name: str):
    """``scara``, ``lwr4`` (generated), ``scara_bare`` (SCARA declared without rotor inertias and
    offsets, built in memory: the model that misses ``rotor_inertia`` and ``offset``) or ``tree_toy``
    (the branched toy of :mod:`tests.oracles.test_trees`: joints 2 and 3 both carried by joint 1, joint 3
    prismatic, built in memory)."""
    if name == "tree_toy":
        from tests.oracles.test_trees import toy

        return toy()
    if name == "scara_bare":
        from pathlib import Path

        from symoro_gen.emit.package import build_in_memory

        txt = (Path(__file__).resolve().parents[2] / "robots" / "scara.toml").read_text()
        txt = txt.replace('drive = ["IA", "FV", "FS", "OFF"]', 'drive = ["FV", "FS"]')
        assert 'drive = ["FV", "FS"]' in txt
        robot = parse_robot_text(txt)
        return robot, build_in_memory(robot)
    return load_robot(name), symoro_gen.load_model(name)


def recording(name: str, seed: int, kind: str | None = None, joint: int | None = None, *,
              noise_q: float = NOISE_Q, noise_tau: float = NOISE_TAU, duration: float = DURATION, dt: float = DT,
              lwr_friction: bool = True, extra=None, **params):
    """(model, Trajectory) of robot ``name`` along a random Fourier excitation, with ``kind`` injected.

    ``extra(t, q, dq, ddq, tau) -> (N, n)``: a torque added to the true one (effects built in the test).
    LWR4 simulations use LWR-like friction (FS 0.1-0.5 N m, Table II of the LWR4 paper) unless
    ``lwr_friction`` is False; so do the tree toy's (with the default ranges, 0.1-5 N m, its light
    branches' torques have the sign of their velocity at almost every sample: a torque-dependent friction
    is then a gain error of the joint, see ``test_effects.test_load_friction_on_friction_dominated_joints_is_a_gain``).
    """
    robot, model = robot_and_model(name)
    rng = np.random.default_rng(seed)
    n = model.N_JOINTS
    amp = np.ones(n)
    if name.startswith("scara") or name == "tree_toy":
        amp[2] = 0.1   # prismatic joint [m]
    t, q, dq, ddq = fourier_trajectory(n, duration, dt, rng, base_frequency_hz=0.1, amplitude=amp)
    kw = dict(fs_range=(0.1, 0.5), fv_range=(0.1, 1.0)) if (name in ("lwr4", "tree_toy") and lwr_friction) else {}
    chi = np.asarray(random_physical_parameters(robot, rng, **kw))
    tau = true_torques(model, q, dq, ddq, chi)
    qm, taum = (q, tau) if kind is None else inject_effect(kind, t, q, dq, ddq, tau, joint=joint, **params)
    if extra is not None:   # extra(t, q, dq, ddq, tau) -> (N, n) torque the declared model lacks
        taum = taum + np.asarray(extra(t, q, dq, ddq, tau), float)
    qm = qm + noise_q * rng.standard_normal(q.shape)
    taum = taum + noise_tau * rng.standard_normal(q.shape)
    src = f"{name} seed {seed}" + (f" + {kind}" if kind else "")
    return model, Trajectory(t=t, q=qm, tau=taum, source=src)


def friction_selection_case(seed: int = 11, s: int = 500):
    """A small stacked system for the friction-law selection: 3 joints of ``s`` rows, a random model design
    ``A`` (joint 2's rows without its last two columns), five time blocks, a columns hook that evaluates a
    law on joint 2's velocity rows, and the noise-free measured side: the model part plus a tanh Coulomb and
    a viscous friction on joint 2. Returns ``(J, dq_rows, A, blocks, hook, signal, rng)``; the caller adds
    its noise from ``rng``."""
    rng = np.random.default_rng(seed)
    n = 3
    J = np.repeat(np.arange(n), s)
    t = np.arange(s) * 0.01
    dq = np.column_stack([np.sin(2 * np.pi * 0.3 * t + k) * (1 + 0.2 * k) for k in range(n)])
    dq_rows = dq.T.reshape(-1)
    A = rng.standard_normal((n * s, 6))
    A[J == 1, 4:] = 0.0
    blocks = stability.time_blocks(np.zeros(n * s, int), np.tile(np.arange(s), n), 5)

    def hook(f, p):
        X = np.zeros((n * s, p))
        X[J == 1] = np.asarray(f(dq_rows[J == 1]), float).reshape(-1, p)
        return X

    signal = A @ rng.standard_normal(6) + np.where(J == 1, 0.8 * np.tanh(dq_rows / 0.1) + 0.3 * dq_rows, 0.0)
    return J, dq_rows, A, blocks, hook, signal, rng


def joint_design_case(seed: int, n: int = 4, s: int = 250, k: int = 12):
    """A random stacked design of ``n`` joints of ``s`` rows and ``k`` columns (the last three absent from
    joint 4's rows), row weights in [0.5, 2] and five time blocks, for the blocked least-squares tests.
    Returns ``(rng, joint, A, w, blocks)``; the caller draws more from ``rng``."""
    rng = np.random.default_rng(seed)
    r = n * s
    joint = np.repeat(np.arange(n), s)
    A = rng.standard_normal((r, k))
    A[joint == 3, 9:] = 0.0                      # parameters absent from a joint's rows
    w = rng.uniform(0.5, 2.0, r)
    blocks = stability.time_blocks(np.zeros(r, int), np.tile(np.arange(s), n), 5)
    return rng, joint, A, w, blocks
