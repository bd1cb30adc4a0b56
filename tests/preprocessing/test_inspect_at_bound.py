"""``inspect``'s "at bound" columns: the share of samples stuck at a column's extreme (a clipped signal), not the
one sample at each extreme every signal has."""
from __future__ import annotations

import numpy as np
import pytest

import symoro_gen


def _recording(clip: float | None):
    t = np.arange(4000) * 0.002
    q = 0.5 * np.sin(np.outer(t, [1.0, 1.3, 0.7, 1.9]) + [0.1, 0.5, 0.9, 1.3])
    q[:, 2] *= 0.1
    tau = np.cos(np.outer(t, [1.1, 0.9, 1.7, 1.2]) + [0.2, 0.4, 0.6, 0.8])
    if clip is not None:   # joint 1's torque clipped at +-clip, as a drive at its current limit
        tau[:, 0] = np.clip(tau[:, 0], -clip, clip)
    return t, q, tau


def test_a_clipped_torque_is_at_bound_and_a_smooth_signal_is_not():
    t, q, tau = _recording(clip=0.8)
    joints = symoro_gen.inspect("scara", (t, q, tau)).to_dict()["experiments"][0]["joints"]
    expected = float(np.mean(np.abs(np.cos(1.1 * t + 0.2)) >= 0.8))
    assert joints[0]["tau_saturated"] == pytest.approx(expected, abs=1e-3) and expected > 0.3
    others = [j["q_saturated"] for j in joints] + [j["tau_saturated"] for j in joints[1:]]
    assert others == [0.0] * 7
