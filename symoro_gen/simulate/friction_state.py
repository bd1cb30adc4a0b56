"""Dynamic friction with an internal state: the Dahl and LuGre models, simulated along a velocity history,
and the fit of the pre-sliding stiffness ``sigma0`` on full-rate data.

LuGre (Canudas de Wit, Olsson, Astrom & Lischinsky 1995, eq. 1-4; [OAC1998] sec. 3.5)::

    dz/dt = v - sigma0 |v| z / g(v),     g(v) = Fc + (Fs - Fc) exp(-(v/vs)^2)
    F     = sigma0 z + sigma1 dz/dt + Fv v

Dahl (Dahl 1968; [OAC1998] sec. 3.1, exponent 1) is the case ``Fs = Fc``, ``sigma1 = 0``: the friction
rises with the displacement since the last reversal at the slope ``sigma0`` (the pre-sliding stiffness)
and saturates at ``Fc``; after a reversal it needs a displacement of a few ``Fc / sigma0`` to change sign
(hysteresis), where the static laws switch at once. At constant velocity both give the static law,
``g(v) sign(v) + Fv v`` (the Stribeck law of :mod:`symoro_gen.description.friction_law`): their *sliding
part*.

Integration: for a velocity constant over each sample interval (the mean of its two samples) the state equation is linear in ``z``
and is integrated exactly (``z`` relaxes to ``g(v) sign(v) / sigma0`` at the rate ``sigma0 |v| / g(v)``),
so a stiff ``sigma0`` needs no small step (the same scheme as the LuGre option of
``bench/truthsim.py``). At rest ``z`` holds: the friction keeps the value it had (static friction of a
stopped drive).

Identifiability: the pre-sliding regime lasts a displacement of ``~3 Fc / sigma0`` after each reversal
(milliradians: a few milliseconds at the velocities of an excitation). ``identify`` works on rows filtered
and decimated to the dynamics bandwidth (100-200 Hz, [GB-gains] eq. 14-15), where that transient is one
row or less: it identifies the *sliding part* only. ``sigma0`` is fitted by :func:`fit_presliding` on
full-rate data (>= 1 kHz, fine encoder resolution), docs/friction-dynamic.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

#: identifiable: relative standard deviation of sigma0 below this ...
MAX_REL_STD = 0.5
#: ... and |log(sigma0 / sigma0 at half the rate)| below this ...
MAX_HALF_RATE_CHANGE = 0.2
#: ... and the data sampled at this rate at least [Hz] (docs/friction-dynamic.md: at 100-200 Hz the fit of
#: sigma0 is biased low by a factor 2-5 while its standard deviation and the half-rate check look fine)
MIN_RATE_HZ = 1000.0

__all__ = ["PreslidingFit", "dahl_friction", "fit_presliding", "lugre_friction", "lugre_state"]


def lugre_state(t: np.ndarray, v: np.ndarray, sigma0: float, g: np.ndarray, z0: float = 0.0) -> np.ndarray:
    """Bristle state ``z`` (N,) of the LuGre/Dahl state equation ``dz/dt = v - sigma0 |v| z / g`` along the
    sampled velocity ``v`` (over each interval the mean of its two samples, held; exact integration),
    ``g`` (N,) the sliding level ``g(v) > 0`` (likewise averaged); ``z0`` at ``t[0]``."""
    t, v = np.asarray(t, float), np.asarray(v, float)
    g = np.broadcast_to(np.asarray(g, float), v.shape)
    if not (sigma0 > 0 and np.all(g > 0)):
        raise ValueError(f"lugre_state: sigma0 ({sigma0!r}) and g(v) must be > 0")
    dt = np.diff(t, prepend=t[0])
    vm = np.r_[v[:1], 0.5 * (v[1:] + v[:-1])]          # the interval's mean velocity (exact displacement
    gm = np.r_[g[:1], 0.5 * (g[1:] + g[:-1])]          # for a velocity linear over the interval)
    z = np.empty(v.shape)
    zk = float(z0)
    for k in range(v.size):
        target = gm[k] * np.sign(vm[k]) / sigma0
        zk = target + (zk - target) * math.exp(-sigma0 * abs(vm[k]) * dt[k] / gm[k])
        z[k] = zk
    return z


def lugre_friction(t, v, *, fc: float, fs: float | None = None, vs: float = 0.05, sigma0: float,
                   sigma1: float = 0.0, fv: float = 0.0, z0: float = 0.0) -> np.ndarray:
    """LuGre friction torque (N,) along the velocity ``v`` (module docstring); ``fs`` defaults to ``fc``
    (no Stribeck dip), ``sigma1`` is the bristle damping."""
    v = np.asarray(v, float)
    fs = fc if fs is None else fs
    g = fc + (fs - fc) * np.exp(-(v / vs) ** 2)
    z = lugre_state(t, v, sigma0, g, z0)
    dz = v - sigma0 * np.abs(v) * z / g
    return sigma0 * z + sigma1 * dz + fv * v


def dahl_friction(t, v, *, fc: float, sigma0: float, fv: float = 0.0, z0: float = 0.0) -> np.ndarray:
    """Dahl friction torque (N,) (exponent 1): LuGre with ``Fs = Fc`` and no bristle damping."""
    return lugre_friction(t, v, fc=fc, sigma0=sigma0, fv=fv, z0=z0)


@dataclass(frozen=True)
class PreslidingFit:
    """``sigma0`` fitted on full-rate data, with the sliding part.

    Attributes
    ----------
    sigma0, std : float
        Pre-sliding stiffness and its standard deviation (linearised, log scale); ``std`` NaN when the
        data cannot see it.
    fc, fv : float
        Coulomb level and viscous coefficient fitted with it.
    rms, rms_static : float
        Residual RMS with the state law and with the static law ``Fc sign(v) + Fv v`` on the same samples.
    sigma0_half : float
        The same fit on every other sample (half the rate): a pre-sliding transient the samples resolve
        gives the same ``sigma0``; one they do not resolve gives a smaller one (the state integrated over
        coarser steps and the filtered velocity smear the reversal).
    identifiable : bool
        The data are sampled at :data:`MIN_RATE_HZ` or more, the relative standard deviation of ``sigma0``
        is below :data:`MAX_REL_STD` and the fits at the full and at half the rate agree within
        :data:`MAX_HALF_RATE_CHANGE` (relative, in log). Otherwise only the sliding part (``fc``, ``fv``)
        is meant to be used.
    """

    sigma0: float
    std: float
    fc: float
    fv: float
    rms: float
    rms_static: float
    sigma0_half: float
    identifiable: bool


def _state_columns(t, v, x_ps):
    """Columns ``[phi, v]`` with ``phi = sigma0 z / Fc`` of the Dahl state at ``x_ps = Fc / sigma0``: the
    friction is ``Fc phi + Fv v``, linear in ``Fc`` and ``Fv`` for a fixed pre-sliding displacement."""
    phi = lugre_state(t, v, 1.0 / x_ps, np.ones(np.shape(v))) / x_ps
    return np.column_stack([phi, v])


def fit_presliding(t, v, f, *, x_bounds: tuple[float, float] = (1e-7, 1e-1)) -> PreslidingFit:
    """:func:`_fit_dahl` on all samples and on every other one (see :class:`PreslidingFit`)."""
    t, v, f = (np.asarray(x, float) for x in (t, v, f))
    full = _fit_dahl(t, v, f, x_bounds)
    half = _fit_dahl(t[::2], v[::2], f[::2], x_bounds)
    agree = abs(math.log(full.sigma0 / half.sigma0)) < MAX_HALF_RATE_CHANGE if full.sigma0 > 0 < half.sigma0 else False
    rate = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 0.0
    ok = full.identifiable and agree and rate >= MIN_RATE_HZ * (1 - 1e-6)
    return PreslidingFit(full.sigma0, full.std if ok else math.nan, full.fc, full.fv, full.rms, full.rms_static,
                         half.sigma0, ok)


def _fit_dahl(t, v, f, x_bounds: tuple[float, float]) -> PreslidingFit:
    """Fit the Dahl law ``Fc phi(t; Fc/sigma0) + Fv v`` to a friction torque ``f`` (N,) along the velocity
    ``v`` (N,) sampled at times ``t``: ``Fc``, ``Fv`` linear, the pre-sliding displacement ``Fc / sigma0``
    by a bounded 1-D search in its logarithm (``x_bounds`` [rad or m]); on one sampling rate."""

    def sse(u):
        A = _state_columns(t, v, math.exp(u))
        c = np.linalg.lstsq(A, f, rcond=None)[0]
        r = f - A @ c
        return float(r @ r)

    lo, hi = (math.log(x) for x in x_bounds)
    grid = np.linspace(lo, hi, 25)
    vals = [sse(u) for u in grid]
    i = int(np.argmin(vals))
    res = optimize.minimize_scalar(sse, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]),
                                   method="bounded", options={"xatol": 1e-6})
    u = float(res.x)
    x = math.exp(u)
    A = _state_columns(t, v, x)
    c = np.linalg.lstsq(A, f, rcond=None)[0]
    r = f - A @ c
    h = 1e-4
    dA = (_state_columns(t, v, math.exp(u + h)) - A) / h
    J = np.column_stack([A, dA @ c])
    dof = max(f.size - 3, 1)
    cov = float(r @ r) / dof * np.linalg.pinv(J.T @ J)
    su = math.sqrt(max(cov[2, 2], 0.0))
    As = np.column_stack([np.sign(v), v])
    rs = f - As @ np.linalg.lstsq(As, f, rcond=None)[0]
    fc = float(c[0])
    ok = su < MAX_REL_STD and hi - u > 2 * h and u - lo > 2 * h
    return PreslidingFit(sigma0=fc / x, std=fc / x * su if ok else math.nan, fc=fc, fv=float(c[1]),
                         rms=math.sqrt(float(r @ r) / f.size), rms_static=math.sqrt(float(rs @ rs) / f.size),
                         sigma0_half=math.nan, identifiable=bool(ok))
