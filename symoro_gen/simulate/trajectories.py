"""Exciting trajectories with analytic derivatives.

* :func:`fourier_trajectory` - finite Fourier series per joint ([S1997], Swevers et al.), periodic,
  scaled to respect amplitude, velocity and acceleration bounds.
* :func:`ptp_trajectory` - point-to-point motion through via-points with a *trapezoidal-acceleration*
  (double-S, bounded-jerk) profile as industrial controllers generate them (the LWR4 and RX-90
  papers use such trajectories): the robot stops at each via-point; all joints start and stop
  together (synchronised, straight line in joint space); velocity, acceleration and jerk stay within
  their bounds for every joint; segment durations are rounded up to whole sampling periods so each
  via-point is a sample.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Motion", "FourierSeries", "fourier_trajectory", "ptp_trajectory", "double_s_times", "piecewise_jerk",
           "random_states"]


@dataclass(frozen=True)
class Motion:
    """Sampled joint motion; unpacks as ``t, q, dq, ddq = motion``.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time [s] from 0, uniform step.
    q, dq, ddq : ndarray, shape (N, n)
        Positions [rad or m], velocities, accelerations (exact, not differentiated numerically).
    via_times : ndarray, shape (m,), optional
        Times at which the via-points are reached (PTP only).
    series : FourierSeries, optional
        The scaled series (Fourier only): ``series.evaluate(t)`` samples the same motion at other
        times, e.g. block by block for very long simulated recordings.
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    via_times: np.ndarray | None = None
    series: FourierSeries | None = None

    def __iter__(self):
        return iter((self.t, self.q, self.dq, self.ddq))


@dataclass(frozen=True)
class FourierSeries:
    """``q_j(t) = q0_j + sum_l [a_jl sin(w l t) - b_jl (cos(w l t) - 1)] / (w l)``.

    Attributes
    ----------
    q0 : ndarray (n,)
    a, b : ndarray (n, L)
        Coefficients [rad/s].
    w : float
        Base angular frequency [rad/s].
    """

    q0: np.ndarray
    a: np.ndarray
    b: np.ndarray
    w: float

    def evaluate(self, t) -> Motion:
        """Exact ``q, dq, ddq`` at times ``t`` (shape (N,)) [s]."""
        t = np.asarray(t, float)
        wl = self.w * np.arange(1, self.a.shape[1] + 1)
        S = np.sin(np.outer(t, wl))
        Cc = np.cos(np.outer(t, wl))
        q = (S / wl) @ self.a.T - ((Cc - 1.0) / wl) @ self.b.T + self.q0
        dq = Cc @ self.a.T + S @ self.b.T
        ddq = -(S * wl) @ self.a.T + (Cc * wl) @ self.b.T
        return Motion(t=t, q=q, dq=dq, ddq=ddq, series=self)


def _per_joint(x, n, name) -> np.ndarray:
    a = np.broadcast_to(np.asarray(x, float), (n,)).copy()
    if not (np.all(np.isfinite(a)) and np.all(a > 0)):
        raise ValueError(f"{name} must be positive, got {x!r}")
    return a


def fourier_trajectory(n_joints: int, duration: float, dt: float, rng: np.random.Generator, *,
                       n_harmonics: int = 5, base_frequency_hz: float | None = None, q0=None,
                       amplitude=1.0, vmax=2.0, amax=10.0, decay: float = 1.0) -> Motion:
    """Random finite Fourier series, scaled to the bounds.

    ``q_j(t) = q0_j + sum_l [a_jl sin(w l t) - b_jl (cos(w l t) - 1)] / (w l)`` with ``w = 2 pi f0``, so
    ``q(0) = q0`` and the motion is periodic of period ``1 / f0``.

    Parameters
    ----------
    n_joints : int
    duration, dt : float
        Length and sampling period [s]; ``t = 0, dt, ..., <= duration``.
    rng : numpy.random.Generator
    n_harmonics : int
        Harmonics per joint.
    base_frequency_hz : float, optional
        ``f0``; default ``1 / duration`` (one period over the recording).
    q0 : array_like (n,), optional
        Offset positions (default 0).
    amplitude, vmax, amax : float or array_like (n,)
        Bounds on ``|q - q0|`` [rad], ``|dq|`` [rad/s], ``|ddq|`` [rad/s^2]; each joint's coefficients
        are scaled so that the tightest bound is reached (on the sampled grid).
    decay : float
        Coefficient ``l`` is drawn with standard deviation ``l**-decay``.

    Returns
    -------
    Motion
        With ``series``, the scaled :class:`FourierSeries` (to sample more of the same motion).
    """
    if duration <= 0 or dt <= 0:
        raise ValueError("duration and dt must be positive")
    n = int(n_joints)
    f0 = 1.0 / duration if base_frequency_hz is None else float(base_frequency_hz)
    w = 2 * math.pi * f0
    t = np.arange(int(math.floor(duration / dt + 1e-9)) + 1) * dt
    ls = np.arange(1, n_harmonics + 1)
    scale = ls ** (-float(decay))
    a = rng.standard_normal((n, n_harmonics)) * scale
    b = rng.standard_normal((n, n_harmonics)) * scale
    raw = FourierSeries(q0=np.zeros(n), a=a, b=b, w=w).evaluate(t)
    q, dq, ddq = raw.q, raw.dq, raw.ddq
    amp = _per_joint(amplitude, n, "amplitude")
    vm = _per_joint(vmax, n, "vmax")
    am = _per_joint(amax, n, "amax")
    with np.errstate(divide="ignore"):
        k = np.minimum.reduce([amp / np.abs(q).max(0), vm / np.abs(dq).max(0), am / np.abs(ddq).max(0)])
    k = np.where(np.isfinite(k), k, 0.0)
    q0 = np.zeros(n) if q0 is None else np.broadcast_to(np.asarray(q0, float), (n,)).copy()
    series = FourierSeries(q0=q0, a=a * k[:, None], b=b * k[:, None], w=w)
    return Motion(t=t, q=q * k + q0, dq=dq * k, ddq=ddq * k, series=series)


def double_s_times(h: float, vmax: float, amax: float, jmax: float) -> tuple[float, float, float]:
    """Phase durations ``(Tj, Ta, Tv)`` of the time-optimal rest-to-rest double-S profile.

    ``Tj``: jerk phase, ``Ta``: whole acceleration phase, ``Tv``: constant-velocity phase for a
    displacement ``h > 0`` (Biagiotti & Melchiorri, *Trajectory Planning for Automatic Machines
    and Robots*, 2008, sec. 3.4). Total duration ``2 Ta + Tv``.
    """
    V, A, J = vmax, amax, jmax
    if V * J >= A * A:
        Tj = A / J
        Ta = Tj + V / A
    else:
        Tj = math.sqrt(V / J)
        Ta = 2 * Tj
    Tv = h / V - Ta
    if Tv < 0:
        Tv = 0.0
        if h >= 2 * A ** 3 / J ** 2:
            Tj = A / J
            Ta = Tj / 2 + math.sqrt((Tj / 2) ** 2 + h / A)
        else:
            Tj = (h / (2 * J)) ** (1.0 / 3.0)
            Ta = 2 * Tj
    return Tj, Ta, Tv


def piecewise_jerk(phases, tau):
    """Position, velocity, acceleration at times ``tau`` of a rest-to-rest piecewise-constant-jerk profile, and
    the position at its end: ``(P, V, A, p_end)``; ``phases`` are ``(duration, jerk)`` pairs."""
    p = v = a = 0.0
    starts = []
    t0 = 0.0
    for d, j in phases:
        starts.append((t0, p, v, a, j))
        p += v * d + a * d * d / 2 + j * d ** 3 / 6
        v += a * d + j * d * d / 2
        a += j * d
        t0 += d
    P = np.empty_like(tau)
    Vv = np.empty_like(tau)
    Aa = np.empty_like(tau)
    edges = np.array([s[0] for s in starts])
    idx = np.clip(np.searchsorted(edges, tau, side="right") - 1, 0, len(starts) - 1)
    for i, (ts, p0, v0, a0, j) in enumerate(starts):
        m = idx == i
        u = tau[m] - ts
        Aa[m] = a0 + j * u
        Vv[m] = v0 + a0 * u + j * u * u / 2
        P[m] = p0 + v0 * u + a0 * u * u / 2 + j * u ** 3 / 6
    return P, Vv, Aa, p


def ptp_trajectory(via_points, vmax, amax, jmax, dt: float, *, dwell: float = 0.0) -> Motion:
    """Point-to-point motion through via-points with synchronised double-S profiles.

    Parameters
    ----------
    via_points : array_like, shape (m, n)
        Joint positions to reach in order (the first one is the start).
    vmax, amax, jmax : float or array_like (n,)
        Per-joint bounds on velocity [rad/s], acceleration [rad/s^2] and jerk [rad/s^3].
    dt : float
        Sampling period [s] (the controller cycle).
    dwell : float
        Rest at each via-point [s] (rounded up to whole periods).

    Returns
    -------
    Motion
        With ``via_times``: the sample times at which each via-point is reached.
    """
    P = np.asarray(via_points, float)
    if P.ndim != 2 or P.shape[0] < 2:
        raise ValueError(f"via_points must be (m >= 2, n), got shape {P.shape}")
    if dt <= 0:
        raise ValueError("dt must be positive")
    n = P.shape[1]
    V, A, J = (_per_joint(x, n, nm) for x, nm in ((vmax, "vmax"), (amax, "amax"), (jmax, "jmax")))
    n_dwell = int(math.ceil(dwell / dt - 1e-9)) if dwell > 0 else 0
    qs, dqs, ddqs = [P[:1].copy()], [np.zeros((1, n))], [np.zeros((1, n))]
    via_idx = [0]
    k_now = 0
    for seg in range(P.shape[0] - 1):
        h = P[seg + 1] - P[seg]
        moving = np.abs(h) > 0
        if moving.any():
            ah = np.abs(h[moving])
            Vs, As, Js = (np.min(X[moving] / ah) for X in (V, A, J))  # bounds of the unit profile s(t)
            Tj, Ta, Tv = double_s_times(1.0, Vs, As, Js)
            phases = [(Tj, Js), (Ta - 2 * Tj, 0.0), (Tj, -Js), (Tv, 0.0), (Tj, -Js), (Ta - 2 * Tj, 0.0), (Tj, Js)]
            phases = [(max(d, 0.0), j) for d, j in phases]
            T = sum(d for d, _ in phases)
            m = int(math.ceil(T / dt - 1e-9))
            lam = m * dt / T  # time stretch >= 1 keeps every bound
            u = np.arange(1, m + 1) * dt / lam
            s, ds, dds, s_end = piecewise_jerk(phases, np.minimum(u, T))
            s, ds, dds = s / s_end, ds / (s_end * lam), dds / (s_end * lam * lam)
            s[-1], ds[-1], dds[-1] = 1.0, 0.0, 0.0
            qs.append(P[seg] + np.outer(s, h))
            dqs.append(np.outer(ds, h))
            ddqs.append(np.outer(dds, h))
            k_now += m
        via_idx.append(k_now)
        if n_dwell:
            qs.append(np.repeat(P[seg + 1][None], n_dwell, axis=0))
            dqs.append(np.zeros((n_dwell, n)))
            ddqs.append(np.zeros((n_dwell, n)))
            k_now += n_dwell
    q = np.concatenate(qs)
    q[via_idx] = P  # exact via-points
    t = np.arange(q.shape[0]) * dt
    return Motion(t=t, q=q, dq=np.concatenate(dqs), ddq=np.concatenate(ddqs), via_times=t[via_idx])


def random_states(rng: np.random.Generator, N: int, n: int, q_range: float = np.pi,
                  dq_scale: float = 2.0, ddq_scale: float = 5.0):
    """Independent random joint states (no trajectory): for sampling a regressor at ``N`` points.

    Parameters
    ----------
    rng : numpy.random.Generator
    N, n : int
        Samples and joints.
    q_range : float
        Positions uniform in ``[-q_range, q_range]`` [rad or m].
    dq_scale, ddq_scale : float
        Standard deviations of the normal velocities and accelerations.

    Returns
    -------
    q, dq, ddq : ndarrays, shape (N, n)
    """
    q = rng.uniform(-q_range, q_range, (N, n))
    dq = rng.normal(0.0, dq_scale, (N, n))
    ddq = rng.normal(0.0, ddq_scale, (N, n))
    return q, dq, ddq
