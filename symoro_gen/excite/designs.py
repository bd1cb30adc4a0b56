"""Feasible designs: the design that stays at rest (:func:`constant_design`), the scaling of a design into the limits
(:func:`scale_into`, :func:`inside_limits`), and the starts of the optimisation - random designs
(:func:`random_trajectory`) and designs whose joints alternate slow motion and bursts at the velocity limit
(:func:`friction_trajectory`, the friction columns' optimum)."""
from __future__ import annotations

import numpy as np

from .bases import FourierBasis, SplineBasis, basis_eval
from .limits import Limits, check_limits

__all__ = ["constant_design", "friction_trajectory", "inside_limits", "random_trajectory", "scale_into"]


def constant_design(basis, n: int, centre: np.ndarray) -> np.ndarray:
    """Design ``X`` of the motion that stays at ``centre``: the constant term ``q0`` of a Fourier series;
    every control point or via-point at ``centre`` for a spline or point-to-point design (partitions of
    unity). (A least-squares fit of the constant on a few early samples, used before, left a Fourier or
    point-to-point "constant" that drifted away later in the period wherever the range is not centred
    on 0: random designs were then scaled about the wrong centre and left their position range.)"""
    X = np.outer(np.ones(basis.m), centre)
    if isinstance(basis, FourierBasis):
        X[1:] = 0.0
    return X


def scale_into(basis, limits: Limits, X: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``X0 + k_j (X - X0)`` per joint, with the largest ``k_j`` that keeps joint j inside
    its position, velocity and acceleration limits at the times ``t`` (``X0``: rest at :attr:`Limits.centre`),
    then, with passive ranges, one common factor that keeps the passive joints inside theirs, and with a
    workspace floor, the largest common factor (bisection) that keeps every frame origin above it."""
    P, D, A = basis.matrices(t)
    X0 = constant_design(basis, limits.n, limits.centre)
    up, down = limits.room()
    dX = X - X0
    dev = P @ dX
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.minimum.reduce([np.minimum(up / np.maximum(dev.max(0), 0.0), down / np.maximum(-dev.min(0), 0.0)) if limits.passive
                               else up / np.abs(dev).max(0), limits.dq_max / np.abs(D @ dX).max(0),
                               limits.ddq_max / np.abs(A @ dX).max(0)])
        k = np.where(np.isfinite(k), k, 1.0)
        if limits.passive:  # the passive positions are linear in the actuated ones: one factor for all joints
            C, _, lo, hi = limits.passive_rows()
            p0, pd = limits.passive_positions(limits.centre[None])[0], (dev * k) @ C.T
            s = np.min(np.r_[1.0, (hi - p0) / np.maximum(pd.max(0), 0.0), (p0 - lo) / np.maximum(-pd.min(0), 0.0)])
            k = k * (s if np.isfinite(s) else 1.0)
    X = X0 + dX * k
    if limits.workspace is not None:  # the floor is not linear in q: bisect a common factor towards the rest at the centre
        ws = limits.workspace

        def above(f: float) -> bool:
            return bool(np.all(ws.heights(P @ (X0 + f * (X - X0))) >= ws.z_min))
        if not above(1.0):
            lo_f, hi_f = 0.0, 1.0
            for _ in range(30):
                mid = (lo_f + hi_f) / 2
                lo_f, hi_f = (mid, hi_f) if above(mid) else (lo_f, mid)
            X = X0 + lo_f * (X - X0)
    return X


def inside_limits(basis, limits: Limits, X: np.ndarray, t: np.ndarray) -> bool:
    """The design ``X`` holds every limit (torques aside) at the times ``t``."""
    return bool(check_limits(limits, *basis_eval(basis, X, t))["ok"])


def random_trajectory(basis, limits: Limits, rng: np.random.Generator, t: np.ndarray, *, decay: float = 1.0) -> np.ndarray:
    """A random feasible design ``X`` (m, n): random coefficients (harmonic ``k`` with standard
    deviation ``k**-decay``; uniform via-points), scaled per joint so that the tightest of its
    position, velocity and acceleration limits is reached on the samples ``t`` (the usual random
    baseline of excitation design)."""
    n = limits.n
    centre = limits.centre
    X0 = constant_design(basis, n, centre)
    if isinstance(basis, FourierBasis):
        ks = np.concatenate([np.arange(1, basis.K), np.arange(1, basis.K)]).astype(float)
        R = np.zeros((basis.m, n))
        R[1:] = rng.standard_normal((basis.m - 1, n)) * (ks ** -decay)[:, None]
        R[0] = rng.uniform(-0.3, 0.3, n) * (limits.q_max - limits.q_min) / 2
        X = X0 + R
    elif isinstance(basis, SplineBasis):
        # a random walk of the control points (uniform ones would be all acceleration)
        X = centre + np.cumsum(rng.standard_normal((basis.m, n)), axis=0) * (limits.q_max - limits.q_min) / 8
    else:
        X = rng.uniform(limits.q_min, limits.q_max, (basis.m, n))
    return scale_into(basis, limits, X, t)


def friction_trajectory(basis, limits: Limits, rng: np.random.Generator, t: np.ndarray, duration: float, *,
                        cruise: float = 0.3, creep: float = 0.05) -> np.ndarray:
    """A feasible design whose every joint alternates slow motion and bursts at its velocity limit.

    The velocity distribution that maximises the smallest eigenvalue of a joint's friction block
    ``E[(dq, sign dq, 1)(dq, sign dq, 1)^T]`` (:func:`friction_ceiling`) puts a fraction of the time at
    ``+-dq_max`` and the rest at small nonzero speed. Per joint: the duration is cut into a random
    number of equal slots, each holding one burst of alternating sign at a random offset (the cruise
    fraction ``cruise`` of the duration in all, each burst's travel within the joint range), ramps at
    0.8 of the acceleration limit, ``creep * dq_max`` towards the next burst in between; the position
    is its integral, fitted by least squares in the basis and scaled into the limits
    (:func:`random_trajectory`'s scaling on the samples ``t``).
    """
    n = limits.n
    tt = np.linspace(0.0, duration, 4001)
    dt = tt[1] - tt[0]
    V = np.zeros((len(tt), n))
    for j in range(n):
        v, a = float(limits.dq_max[j]), 0.8 * float(limits.ddq_max[j])
        ramp = v / a
        span = (limits.q_max[j] - limits.q_min[j]) * 0.75  # room for the creeping between bursts
        fits = [k for k in (2, 4, 6, 8) if duration / k >= 2.5 * ramp + 0.2]
        nb = int(rng.choice(fits)) if fits else 2
        slot = duration / nb
        hold = max(0.0, min(cruise * slot, span / v - ramp, slot - 2 * ramp - 0.2))
        burst = hold + ramp  # the rate limiter adds a ramp at each end
        sign0 = float(rng.choice([-1.0, 1.0]))
        target = np.zeros(len(tt))
        for i in range(nb):
            sg = sign0 * (-1) ** i
            lo = i * slot + (0.1 if i else 0.3)
            hi = max(lo, (i + 1) * slot - burst - 2 * ramp - (0.3 if i == nb - 1 else 0.1))
            t0 = rng.uniform(lo, hi)
            target[(tt >= i * slot) & (tt < t0)] = sg * creep * v  # creeping towards this burst's direction
            target[(tt >= t0) & (tt < t0 + burst)] = sg * v
            target[(tt >= t0 + burst) & (tt < (i + 1) * slot)] = -sg * creep * v
        target[tt >= duration - 0.3] = 0.0
        target[tt < 0.1] = 0.0
        # rate-limit the target to the acceleration (ramps), starting and ending at rest
        vel = np.zeros(len(tt))
        for k in range(1, len(tt)):
            vel[k] = vel[k - 1] + np.clip(target[k] - vel[k - 1], -a * dt, a * dt)
        V[:, j] = vel
    Q = np.cumsum(V, axis=0) * dt
    Q += (limits.centre - (Q.max(0) + Q.min(0)) / 2)
    P, _, _ = basis.matrices(tt)
    X, *_ = np.linalg.lstsq(P, Q, rcond=None)
    return scale_into(basis, limits, X, t)
