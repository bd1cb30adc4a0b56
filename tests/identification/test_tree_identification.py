"""Identification and diagnosis of tree-structured robots on simulated data with known truth.

* The SDA10F dual-arm torso (``robots/sda10f.toml``, 15 joints, 156 base parameters): its generated base
  regressor at random states, torques from known standard parameters plus noise; IDIM-OLS and -WLS
  estimates against the true base parameters (the closed-form relations applied to the truth) over
  noise seeds: as many within 1 and 3 standard deviations as a Gaussian gives (eq. 18-22 of
  [GB-gains]).
* The branching toy of :mod:`tests.oracles.test_trees` (a prismatic branch): a whole recording
  (Fourier excitation, recorded derivatives, noisy torque) through the observation assembly
  (filtering, decimation) and ``identify``; then ``diagnose`` adds nothing on clean data and finds the
  effects injected on the joints of the branch (Stribeck friction, a spring).
"""
from __future__ import annotations

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import diagnose, inject_effect
from symoro_gen.identification import ObservationSystem, identify
from symoro_gen.identification.assemble import build_observation
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, random_states, simulate_recording

from .simdata import joint_noise


def _stacked(W3: np.ndarray) -> np.ndarray:
    """(N, n, c) -> (n N, c), rows grouped per joint."""
    N, n, c = W3.shape
    return np.transpose(W3, (1, 0, 2)).reshape(n * N, c)


@pytest.mark.parametrize("method", ["ols", "wls"])
def test_torso_base_parameters_recovered_within_3_sigma(method):
    robot, m = load_robot("sda10f"), symoro_gen.load_model("sda10f")
    rng = np.random.default_rng(31)
    n, N = robot.n_joints, 300
    q, dq, ddq = random_states(rng, N, n, dq_scale=1.5, ddq_scale=4.0)
    W = _stacked(m.regressor(q, dq, ddq))
    joint = np.repeat(np.arange(n), N)
    chi = np.asarray(random_physical_parameters(robot, rng))
    truth = m.base_parameters(chi)
    tau = W @ truth
    z = []
    for seed in range(4):
        nrng = np.random.default_rng(100 + seed)
        if method == "ols":
            noise = 0.02 * np.sqrt(np.mean(tau ** 2)) * nrng.normal(size=tau.shape)
        else:
            noise = joint_noise(nrng, tau, joint, 0.02)
        res = identify(ObservationSystem(W, tau + noise, m.BASE_NAMES, joint), method=method)
        assert res.names == m.BASE_NAMES
        z.append((res.values - truth) / res.std)
    z = np.abs(np.concatenate(z))
    assert np.mean(z < 3) > 0.98, f"{method}: {np.mean(z < 3):.3f} within 3 sigma"
    assert 0.6 < np.mean(z < 1) < 0.77, f"{method}: {np.mean(z < 1):.3f} within 1 sigma"


def _toy_recording(seed: int, duration: float = 60.0, dt: float = 0.004):
    from tests.oracles.test_trees import toy

    robot, m = toy()
    rng = np.random.default_rng(seed)
    amp = np.array([1.0, 1.0, 0.1, 1.0])  # joint 3 prismatic [m]
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, duration, dt, rng, base_frequency_hz=0.1, amplitude=amp)
    chi = np.asarray(random_physical_parameters(robot, rng))
    return robot, m, chi, (t, q, dq, ddq), rng


def test_toy_tree_recording_identified_within_3_sigma():
    """Recorded derivatives, noisy torque: the assembled system's OLS estimates cover the truth."""
    robot, m, chi, (t, q, dq, ddq), rng = _toy_recording(5)
    truth = m.base_parameters(chi)
    z = []
    for k in range(3):
        tr = simulate_recording(m, t, q, dq, ddq, chi, noise_tau=0.05, rng=np.random.default_rng(k),
                                keep_derivatives=True, source=f"toy tree {k}")
        system = build_observation(m, [tr], use_recorded_derivatives=True)
        res = identify(system, method="ols")
        z.append((res.values - truth) / res.std)
    z = np.abs(np.concatenate(z))
    assert np.mean(z < 3) > 0.95, f"{np.mean(z < 3):.3f} within 3 sigma: {np.round(z, 1)}"


@pytest.mark.slow
def test_toy_tree_diagnosis_clean_and_with_effects_on_the_branch():
    robot, m, chi, (t, q, dq, ddq), rng = _toy_recording(7, duration=40.0, dt=0.002)
    tau = m.torque(q, dq, ddq, chi)

    def record(qm, taum, what):
        qm = qm + 1e-5 * rng.standard_normal(q.shape)
        return Trajectory(t=t, q=qm, tau=taum + 0.05 * rng.standard_normal(q.shape), source=f"toy tree {what}")

    clean = diagnose(m, record(q, tau, "clean"))
    assert not clean.effects, [(e.label, e.p_value) for e in clean.effects]
    # Stribeck friction on joint 4 (the revolute joint at the end of the branch), a spring on joint 3
    # (the prismatic joint that starts the branch): each found first, on its joint
    for kind, joint, params in (("stribeck", 3, dict(Fst=1.0, vs=0.1)), ("spring", 2, dict(stiffness=20.0))):
        qm, taum = inject_effect(kind, t, q, dq, ddq, tau, joint=joint, **params)
        rep = diagnose(m, record(qm, taum, kind))
        assert rep.effects, [(c.label, c.score, c.reason) for c in rep.best_tried(1, 4)]
        first = rep.effects[0]
        if first.kind == "friction_law":   # the friction-law stage replaced Coulomb by the Stribeck law
            assert kind == "stribeck" and first.joint == joint and first.variant.startswith("stribeck"), first.label
        else:
            assert (first.kind, first.joint) == (kind, joint), first.label
