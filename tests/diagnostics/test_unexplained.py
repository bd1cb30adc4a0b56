"""Structure left in the residual that no candidate explains (symoro_gen.diagnostics.unexplained)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("sklearn", reason="scikit-learn (extra 'diagnose') is needed for the unexplained-structure model")

from symoro_gen.diagnostics.unexplained import (
    Unexplained,
    rows_to_samples,
    signal_matrix,
    unexplained_structure,
)
from symoro_gen.simulate import fourier_trajectory

from .test_friction import scara_rows


def play_operator(x: np.ndarray, half_width: float) -> np.ndarray:
    """Backlash (play) hysteresis: the output follows ``x`` only once it has moved ``half_width`` away."""
    out = np.empty_like(x)
    p = x[0]
    for i, v in enumerate(x):
        p = min(max(p, v - half_width), v + half_width)
        out[i] = p
    return out


def test_hysteresis_outside_the_library_is_flagged_on_its_joint():
    d = scara_rows(41, duration=24.0, dt=0.02)
    W, J, q = d["W"], d["J"], d["q"]
    rng = d["rng"]
    y = W @ d["theta"] + 0.05 * rng.standard_normal(W.shape[0])
    # joint 2 (index 1): a backlash hysteresis torque 3 (q - play(q)), play half-width 0.15 rad
    hyst = 3.0 * (q[:, 1] - play_operator(q[:, 1], 0.15))
    y[J == 1] += hyst
    theta = np.linalg.lstsq(W, y, rcond=None)[0]
    resid = (y - W @ theta).reshape(4, -1).T
    X, names = signal_matrix(q, d["dq"], d["ddq"], (W @ theta).reshape(4, -1).T, d["t"])
    out = unexplained_structure(resid, X, names)
    # the least-squares fit spreads part of the missing torque over the base parameters joint 2 shares
    # with the joints it is coupled to: joint 2 must be flagged with the largest share
    flagged = sorted((u for u in out if u.flagged), key=lambda u: -u.share)
    assert flagged and flagged[0].joint == 2, out
    assert all(other.share < 0.8 * flagged[0].share for other in flagged[1:]), out
    u = flagged[0]
    assert 0.2 < u.share <= 1.0 and u.share > u.threshold
    # a periodic excitation makes every signal a proxy of the motion's phase: the signals listed are those
    # the trees used, not necessarily joint 2's own
    assert u.signals and set(u.signals) <= set(names), u.signals
    assert u.to_dict() == {"joint": 2, "share": u.share, "signals": list(u.signals)}


def test_white_noise_residual_is_not_flagged_over_30_seeds():
    rng = np.random.default_rng(5)
    t, q, dq, ddq = fourier_trajectory(2, 12.0, 0.04, rng, base_frequency_hz=0.1)
    X, names = signal_matrix(q, dq, ddq, None, t)
    shares = []
    for seed in range(30):
        e = np.random.default_rng(100 + seed).standard_normal((t.size, 1))
        (u,) = unexplained_structure(e, X, names, seed=seed, n_null=2)
        assert isinstance(u, Unexplained) and u.joint == 1
        assert not u.flagged, (seed, u)
        shares.append(u.share)
    assert np.mean(shares) < 0.02


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_smooth_coloured_noise_is_not_flagged(seed):
    rng = np.random.default_rng(seed)
    t, q, dq, ddq = fourier_trajectory(2, 16.0, 0.02, rng, base_frequency_hz=0.1)
    X, names = signal_matrix(q, dq, ddq, None, t)
    w = rng.standard_normal(t.size + 200)
    e = np.convolve(w, np.hanning(25), "valid")[:t.size]      # low-passed noise, correlated over ~0.25 s
    (u,) = unexplained_structure(e[:, None], X, names, seed=seed)
    assert not u.flagged, u


def test_shape_errors_are_named():
    with pytest.raises(ValueError, match="disagree"):
        unexplained_structure(np.zeros((10, 2)), np.zeros((9, 3)), ["a", "b", "c"])


def test_rows_to_samples_inverts_the_joint_major_stacking():
    # 2 experiments of 4 and 3 samples, 3 joints, rows joint-major then experiment
    exp = np.tile(np.r_[0, 0, 0, 0, 1, 1, 1], 3)
    idx = np.tile(np.r_[0, 1, 2, 3, 0, 1, 2], 3)
    joint = np.repeat(np.arange(3), 7)
    vals = 100 * joint + 10 * exp + idx
    out, e, i = rows_to_samples(vals, joint, exp, idx)
    assert out.shape == (7, 3)
    np.testing.assert_array_equal(e, [0, 0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(i, [0, 1, 2, 3, 0, 1, 2])
    np.testing.assert_array_equal(out, 100 * np.arange(3)[None, :] + (10 * e + i)[:, None])
    with pytest.raises(ValueError, match="lack rows"):
        rows_to_samples(vals[:-1], joint[:-1], exp[:-1], idx[:-1])
