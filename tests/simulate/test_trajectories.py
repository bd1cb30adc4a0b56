"""Exciting trajectories: PTP double-S profiles respect their bounds and pass the via-points;
Fourier series derivatives are exact and bounded."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from symoro_gen.simulate import double_s_times, fourier_trajectory, ptp_trajectory

REL = 1e-9  # rounding slack on the bounds


def _check_ptp(m, P, vmax, amax, jmax, dt):
    n = P.shape[1]
    vmax, amax, jmax = (np.broadcast_to(np.asarray(x, float), (n,)) for x in (vmax, amax, jmax))
    # via-points are samples, reached exactly, at rest
    idx = np.rint(m.via_times / dt).astype(int)
    np.testing.assert_array_equal(m.q[idx], P)
    np.testing.assert_array_equal(m.dq[idx], 0.0)
    np.testing.assert_allclose(m.t[idx], m.via_times)
    # bounds on the analytic velocity and acceleration...
    assert np.all(np.abs(m.dq) <= vmax * (1 + REL))
    assert np.all(np.abs(m.ddq) <= amax * (1 + REL))
    # ...and on the jerk: ddq is piecewise linear, so its slope between samples is a mean jerk
    jerk = np.diff(m.ddq, axis=0) / dt
    assert np.all(np.abs(jerk) <= jmax * (1 + 1e-6))
    # the analytic derivatives are consistent with the positions (trapezoid rule)
    np.testing.assert_allclose(np.diff(m.q, axis=0), (m.dq[1:] + m.dq[:-1]) * dt / 2,
                               atol=dt ** 3 * jmax.max() + 1e-12)
    np.testing.assert_allclose(np.diff(m.dq, axis=0), (m.ddq[1:] + m.ddq[:-1]) * dt / 2,
                               atol=dt ** 2 * jmax.max() + 1e-12)
    # between via-points the path is the straight segment (synchronised joints)
    for k in range(len(idx) - 1):
        seg = m.q[idx[k]:idx[k + 1] + 1]
        h = P[k + 1] - P[k]
        if np.any(h):
            s = (seg - P[k]) @ h / (h @ h)
            np.testing.assert_allclose(seg, P[k] + np.outer(s, h), atol=1e-12)
            assert np.all(np.diff(s) >= -1e-12)  # monotonic progress, no overshoot


def test_ptp_three_regimes_and_bounds():
    dt = 0.002
    P = np.array([[0.0, 0.0, 0.0], [1.5, -0.5, 0.2], [1.5, -0.5, 0.2 + 1e-3], [0.2, 0.3, -0.8], [0.25, 0.3, -0.8]])
    vmax, amax, jmax = [1.0, 2.0, 1.5], [3.0, 4.0, 3.0], [20.0, 30.0, 25.0]
    m = ptp_trajectory(P, vmax, amax, jmax, dt, dwell=0.1)
    _check_ptp(m, P, vmax, amax, jmax, dt)
    # the limiting joint of the long first move reaches vmax (time-optimal up to rounding)
    first = slice(0, int(round(m.via_times[1] / dt)) + 1)
    assert np.abs(m.dq[first, 0]).max() > 0.95 * 1.0
    # dwell: the robot rests 0.1 s at each via-point
    i1 = int(round(m.via_times[1] / dt))
    np.testing.assert_array_equal(m.q[i1:i1 + 50], np.repeat(P[1][None], 50, axis=0))


def test_double_s_durations():
    # long move: vmax and amax reached
    Tj, Ta, Tv = double_s_times(10.0, 1.0, 2.0, 10.0)
    assert (Tj, Ta) == pytest.approx((0.2, 0.7)) and Tv == pytest.approx(10.0 - 0.7)
    # short move: amax reached, vmax not
    Tj, Ta, Tv = double_s_times(0.5, 10.0, 2.0, 10.0)
    assert Tv == 0 and Tj == pytest.approx(0.2) and 2.0 * (Ta - Tj) * Ta == pytest.approx(0.5)
    # tiny move: neither
    Tj, Ta, Tv = double_s_times(1e-3, 10.0, 2.0, 10.0)
    assert Tv == 0 and Ta == pytest.approx(2 * Tj) and 2 * 10.0 * Tj ** 3 == pytest.approx(1e-3)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**16), n=st.integers(1, 4), m=st.integers(2, 5))
def test_ptp_random(seed, n, m):
    rng = np.random.default_rng(seed)
    P = rng.uniform(-2, 2, (m, n))
    vmax, amax, jmax = rng.uniform(0.5, 3, n), rng.uniform(1, 10, n), rng.uniform(5, 100, n)
    dt = float(rng.choice([0.001, 0.004, 0.01]))
    _check_ptp(ptp_trajectory(P, vmax, amax, jmax, dt), P, vmax, amax, jmax, dt)


def test_ptp_rejects_bad_input():
    with pytest.raises(ValueError, match="via_points"):
        ptp_trajectory(np.zeros((1, 3)), 1, 1, 1, 0.01)
    with pytest.raises(ValueError, match="jmax must be positive"):
        ptp_trajectory(np.zeros((2, 3)), 1, 1, [1, 0, 1], 0.01)


def test_fourier_bounds_and_derivatives():
    rng = np.random.default_rng(5)
    dt = 1e-3
    m = fourier_trajectory(4, 10.0, dt, rng, n_harmonics=5, q0=[0.1, -0.2, 0.0, 0.5],
                           amplitude=[1.0, 0.5, 2.0, 1.0], vmax=1.5, amax=[4.0, 4.0, 4.0, 100.0])
    t, q, dq, ddq = m  # unpacks as a tuple
    assert t[0] == 0 and t[-1] == pytest.approx(10.0) and q.shape == (10001, 4)
    np.testing.assert_allclose(q[0], [0.1, -0.2, 0.0, 0.5], atol=1e-15)
    np.testing.assert_allclose(q[-1], q[0], atol=1e-9)  # periodic over the duration
    amp = np.abs(q - q[0]).max(0)
    assert np.all(amp <= [1.0, 0.5, 2.0, 1.0 + 1e-12]) and np.all(np.abs(dq) <= 1.5 + 1e-12)
    assert np.all(np.abs(ddq) <= [4, 4, 4, 100 + 1e-9])
    # each joint touches its tightest bound
    tight = np.maximum.reduce([amp / [1.0, 0.5, 2.0, 1.0], np.abs(dq).max(0) / 1.5,
                               np.abs(ddq).max(0) / [4, 4, 4, 100]])
    np.testing.assert_allclose(tight, 1.0)
    # analytic derivatives: compare with central differences
    np.testing.assert_allclose((q[2:] - q[:-2]) / (2 * dt), dq[1:-1], atol=1e-5)
    np.testing.assert_allclose((dq[2:] - dq[:-2]) / (2 * dt), ddq[1:-1], atol=1e-4)
    # the series samples the same motion block by block (long simulated recordings)
    part = m.series.evaluate(t[1234:2345])
    np.testing.assert_allclose(part.q, q[1234:2345], atol=1e-12)
    np.testing.assert_allclose(part.ddq, ddq[1234:2345], atol=1e-10)
