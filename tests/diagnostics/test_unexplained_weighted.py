"""The ``unexplained`` check on joints of unequal noise (symoro_gen.diagnostics.unexplained.joint_weighted_residual).

A SCARA along a Fourier excitation with torque noise 1 N m on joints 1-2 and 0.02 on joints 3-4 (the ratio of a
floating-base robot's base-wrench rows to its quiet joint rows, docs/floating-base.md): the unweighted fit's
estimation error, driven by the noisy joints, leaves a smooth residual on the quiet joint 4 that the trees predict;
on the per-joint weighted refit nothing is flagged, and a torque no candidate names on a quiet joint still is."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("sklearn", reason="scikit-learn (extra 'diagnose') is needed for the unexplained-structure model")

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics.expert import stacked_regressor
from symoro_gen.diagnostics.unexplained import (
    joint_weighted_residual,
    signal_matrix,
    unexplained_by_joint,
)
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters

NOISE = (1.0, 1.0, 0.02, 0.02)


def _arm(seed: int, extra=None):
    """Stacked rows of the SCARA with the torque noise ``NOISE`` per joint, fitted by unweighted least squares;
    ``extra(q, dq) -> (N, n)`` a torque the model lacks."""
    robot, model = load_robot("scara"), symoro_gen.load_model("scara")
    rng = np.random.default_rng(seed)
    n = model.N_JOINTS
    amp = np.ones(n)
    amp[2] = 0.1   # prismatic joint [m]
    t, q, dq, ddq = fourier_trajectory(n, 24.0, 0.02, rng, base_frequency_hz=0.1, amplitude=amp)
    theta = np.asarray(model.base_parameters(np.asarray(random_physical_parameters(robot, rng))))
    W, J, S = stacked_regressor(model, q, dq, ddq)
    y = W @ theta + np.asarray(NOISE)[J] * rng.standard_normal(W.shape[0])
    if extra is not None:
        y += np.asarray(extra(q, dq), float).T.reshape(-1)
    th = np.linalg.lstsq(W, y, rcond=None)[0]
    X, names = signal_matrix(q, dq, ddq, (W @ th).reshape(n, -1).T, t)
    return y - W @ th, W, J, S, X, names


def test_weighted_residual_is_the_wls_fit():
    """The refit is the least-squares fit with each joint's rows divided by its residual's RMS (independent
    reference: the weighted system solved from the measurements), weighted; the shapes are checked."""
    rng = np.random.default_rng(2)
    n, s, p = 3, 150, 7
    J = np.repeat(np.arange(n), s)
    A = rng.standard_normal((n * s, p))
    y = A @ rng.standard_normal(p) + np.array([2.0, 0.05, 0.3])[J] * rng.standard_normal(n * s)
    r = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
    rms = np.array([np.sqrt(np.mean(r[np.equal(J, j)] ** 2)) for j in range(n)])
    w = 1.0 / rms[J]
    ref = w * y - (A * w[:, None]) @ np.linalg.lstsq(A * w[:, None], w * y, rcond=None)[0]
    rw, Aw = joint_weighted_residual(r, A, J)
    np.testing.assert_allclose(rw, ref, atol=1e-10)
    np.testing.assert_allclose(Aw, A * w[:, None])
    # each joint's refitted residual keeps its own level, the quiet one is not raised by the noisy ones' spread
    assert np.sqrt(np.mean((rw / w)[J == 1] ** 2)) <= rms[1]
    with pytest.raises(ValueError, match="disagree"):
        joint_weighted_residual(r[:-1], A, J)


@pytest.mark.slow
def test_quiet_joint_is_not_flagged_on_the_weighted_residual():
    """Clean data (seed 101): the unweighted residual flags the quiet joint 4 (the noisy joints' estimation error
    spread onto it); the weighted residual flags no joint."""
    r, W, J, S, X, names = _arm(101)
    plain, _ = unexplained_by_joint(r, W, J, np.zeros_like(J), S, X, names, seed=1, n_null=2)
    assert [u.joint for u in plain if u.flagged] == [4], plain
    rw, Aw = joint_weighted_residual(r, W, J)
    out, carriers = unexplained_by_joint(rw, Aw, J, np.zeros_like(J), S, X, names, seed=1, n_null=2)
    assert not any(u.flagged for u in out), out
    assert carriers == ()


@pytest.mark.slow
def test_unnameable_torque_on_a_quiet_joint_is_still_flagged():
    """``sin(3.7 q4) dq2^2`` N m (in no candidate family) on the quiet joint 4 (seed 1): flagged on joint 4 only,
    joint 4 the one carrier."""
    def extra(q, dq):
        out = np.zeros_like(q)
        out[:, 3] = np.sin(3.7 * q[:, 3]) * dq[:, 1] ** 2
        return out
    r, W, J, S, X, names = _arm(1, extra)
    rw, Aw = joint_weighted_residual(r, W, J)
    out, carriers = unexplained_by_joint(rw, Aw, J, np.zeros_like(J), S, X, names, seed=1)
    assert [u.joint for u in out if u.flagged] == [4], out
    assert carriers == (3,)
    assert out[3].share > 0.5
