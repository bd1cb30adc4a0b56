"""The kinds of motion an excitation design is made of, each *linear in its design variables* ``X`` (one column
per joint): ``q(t) = Phi(t) X``, ``dq(t) = Phi'(t) X``, ``ddq(t) = Phi''(t) X`` (``matrices(t)``).

* :class:`FourierBasis` - Swevers' finite Fourier series at rest at both ends (periodic);
* :class:`PointToPointBasis` - via-points joined by synchronised double-S profiles (the robot stops at each);
* :class:`SplineBasis` - a clamped cubic B-spline per joint at rest at both ends (Rackl et al. 2012).

With the sampling helpers: :func:`basis_eval` (``q, dq, ddq`` of a design), :func:`output_times` (the output
samples) and :func:`dense_times` (the 10x denser resampling the limits are checked on)."""
from __future__ import annotations

import math

import numpy as np

from ..simulate.trajectories import piecewise_jerk
from .limits import ExcitationError

__all__ = ["FourierBasis", "PointToPointBasis", "SplineBasis", "basis_eval", "dense_times", "output_times"]


class FourierBasis:
    """Swevers' finite Fourier series with rest at ``t = 0`` (and at every period) built in.

    Per joint ``q_j(t) = q0_j + sum_{k=1..K} a_jk/(w k) sin(w k t) - b_jk/(w k) cos(w k t)``
    (Swevers et al. 1997, eq. 7), ``w = 2 pi f`` the base frequency. The design variables of a joint
    are ``x = (q0, a_1..a_{K-1}, b_1..b_{K-1})``; ``a_K = -sum_{k<K} a_k`` and
    ``b_K = -sum_{k<K} k b_k / K`` make ``dq(0) = ddq(0) = 0`` (hence at ``t = m / f`` too).

    Parameters
    ----------
    harmonics : int
        ``K >= 2``.
    base_frequency : float
        ``f`` [Hz].
    """

    kind = "fourier"

    def __init__(self, harmonics: int, base_frequency: float):
        if harmonics < 2:
            raise ExcitationError(f"--harmonics {harmonics}: at least 2 harmonics are needed to start and end at rest")
        if not base_frequency > 0:
            raise ExcitationError(f"--base-frequency {base_frequency:g}: must be a positive frequency in Hz")
        self.K = int(harmonics)
        self.w = 2 * math.pi * float(base_frequency)
        self.m = 2 * self.K - 1

    def matrices(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``Phi, Phi', Phi''`` at times ``t``, each (N, m)."""
        t = np.asarray(t, float)
        K, w = self.K, self.w
        k = np.arange(1, K + 1)
        S, C = np.sin(np.outer(t, w * k)), np.cos(np.outer(t, w * k))
        N = len(t)
        P, D, A = (np.zeros((N, self.m)) for _ in range(3))
        P[:, 0] = 1.0
        wk, wK = w * k[:-1], w * K
        # a_k (k < K), with a_K = -sum a_k
        P[:, 1:K] = S[:, :-1] / wk - S[:, -1:] / wK
        D[:, 1:K] = C[:, :-1] - C[:, -1:]
        A[:, 1:K] = -S[:, :-1] * wk + S[:, -1:] * wK
        # b_k (k < K), with b_K = -sum k b_k / K
        r = k[:-1] / K
        P[:, K:] = -C[:, :-1] / wk + r * C[:, -1:] / wK
        D[:, K:] = S[:, :-1] - r * S[:, -1:]
        A[:, K:] = C[:, :-1] * wk - r * C[:, -1:] * wK
        return P, D, A

    def coefficients(self, X: np.ndarray) -> dict:
        """``q0`` (n,), ``a``, ``b`` (n, K) of a design ``X`` (m, n) (eliminated harmonic included)."""
        K = self.K
        a = X[1:K].T
        b = X[K:].T
        ks = np.arange(1, K)
        aK = -a.sum(1)
        bK = -(b * ks).sum(1) / K
        return {"q0": X[0].tolist(), "a": np.column_stack([a, aK]).tolist(), "b": np.column_stack([b, bK]).tolist(),
                "base_frequency": self.w / (2 * math.pi)}


class PointToPointBasis:
    """Via-points joined by synchronised trapezoidal-acceleration (double-S) segments.

    Segment ``i`` (duration ``T``) moves every joint from via-point ``P_i`` to ``P_{i+1}`` along
    ``q = P_i + s(u) (P_{i+1} - P_i)``, ``u = (t - i T) / T``, with ``s`` the unit double-S profile of
    seven phases (jerk, constant acceleration, jerk, cruise, jerk, constant deceleration, jerk) of
    durations ``phases`` (fractions of ``T``); velocity and acceleration are zero at every via-point.
    The design variables of a joint are its via-points ``x = (P_0, ..., P_{m-1})``.

    Parameters
    ----------
    via_points : int
        ``m >= 2`` (the first is the start, the last the end).
    segment_time : float
        ``T`` [s].
    dwell : float
        Rest at each intermediate via-point [s].
    """

    kind = "p2p"
    PHASES = (0.1, 0.1, 0.1, 0.4, 0.1, 0.1, 0.1)

    def __init__(self, via_points: int, segment_time: float, dwell: float = 0.0):
        if via_points < 2:
            raise ExcitationError(f"--via-points {via_points}: at least 2 via-points are needed")
        self.m = int(via_points)
        self.T = float(segment_time)
        self.dwell = float(dwell)
        jerks = (1.0, 0.0, -1.0, 0.0, -1.0, 0.0, 1.0)
        self._phases = list(zip(self.PHASES, jerks))

    @property
    def duration(self) -> float:
        return (self.m - 1) * (self.T + self.dwell) - self.dwell

    def _unit(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        P, V, A, p_end = piecewise_jerk(self._phases, np.clip(u, 0.0, 1.0))
        return P / p_end, V / p_end, A / p_end

    def matrices(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, float)
        N = len(t)
        P, D, A = (np.zeros((N, self.m)) for _ in range(3))
        period = self.T + self.dwell
        seg = np.clip(np.floor(t / period + 1e-12).astype(int), 0, self.m - 2)
        u = np.clip((t - seg * period) / self.T, 0.0, 1.0)
        s, ds, dds = self._unit(u)
        rows = np.arange(N)
        P[rows, seg] = 1 - s
        P[rows, seg + 1] = s
        D[rows, seg] = -ds / self.T
        D[rows, seg + 1] = ds / self.T
        A[rows, seg] = -dds / self.T ** 2
        A[rows, seg + 1] = dds / self.T ** 2
        return P, D, A

    def coefficients(self, X: np.ndarray) -> dict:
        return {"via_points": X.tolist(), "segment_time": self.T, "dwell": self.dwell,
                "phases": list(self.PHASES)}


class SplineBasis:
    """Clamped cubic B-spline of ``coefficients`` control points per joint over ``[0, duration]``,
    at rest (``dq = ddq = 0``) at both ends (Rackl, Lampariello & Hirzinger 2012, "Robot excitation
    trajectories for dynamic parameter estimation using optimized B-splines", ICRA).

    Uniform knots with the end knots repeated four times; the first three control points are equal
    (``dq(0) = ddq(0) = 0``) and so are the last three. The design variables of a joint are
    ``x = (c_start, c_3, ..., c_{M-4}, c_end)``, ``M - 4`` of them. Unlike a Fourier series of a few
    harmonics, a spline can hold a joint near rest and then at its velocity limit, the velocity
    distribution the friction columns want (:func:`friction_ceiling`).

    Parameters
    ----------
    coefficients : int
        ``M >= 7`` control points per joint.
    duration : float
        [s].
    """

    kind = "spline"
    degree = 3

    def __init__(self, coefficients: int, duration: float):
        if coefficients < 7:
            raise ExcitationError(f"--coefficients {coefficients}: at least 7 control points are needed")
        if not duration > 0:
            raise ExcitationError(f"--duration {duration:g}: must be positive")
        self.M = int(coefficients)
        self.duration = float(duration)
        k = self.degree
        inner = np.linspace(0.0, self.duration, self.M - k + 1)
        self.knots = np.concatenate([[0.0] * k, inner, [self.duration] * k])
        self.m = self.M - 4
        # full control points = E @ x (the tied end points)
        E = np.zeros((self.M, self.m))
        E[:3, 0] = 1.0
        E[3:self.M - 3, 1:self.m - 1] = np.eye(self.M - 6)
        E[self.M - 3:, self.m - 1] = 1.0
        self._E = E

    def matrices(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from scipy.interpolate import BSpline

        t = np.clip(np.asarray(t, float), 0.0, self.duration)
        out = []
        for d in range(3):
            B = np.zeros((len(t), self.M))
            for i in range(self.M):
                c = np.zeros(self.M)
                c[i] = 1.0
                spl = BSpline(self.knots, c, self.degree)
                B[:, i] = spl(t) if d == 0 else spl.derivative(d)(t)
            out.append(B @ self._E)
        return out[0], out[1], out[2]

    def coefficients(self, X: np.ndarray) -> dict:
        return {"control_points": (self._E @ X).tolist(), "knots": self.knots.tolist(), "degree": self.degree}


def basis_eval(basis, X: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``q, dq, ddq`` (N, n) of the design ``X`` at times ``t``."""
    P, D, A = basis.matrices(t)
    return P @ X, D @ X, A @ X


def output_times(duration: float, rate: float) -> np.ndarray:
    """``0, 1/rate, ..., duration`` (the last sample at ``duration``)."""
    N = round(duration * rate)
    return np.arange(N + 1) / rate


def dense_times(t_out: np.ndarray, duration: float, basis=None) -> np.ndarray:
    """Ten times denser than the output samples (for the limit checks), with the knots of a spline basis
    (the acceleration of a cubic spline is piecewise linear: its extremes are at the knots)."""
    t = np.linspace(0.0, duration, 10 * (len(t_out) - 1) + 1)
    knots = getattr(basis, "knots", None)
    return t if knots is None else np.union1d(t, np.clip(knots, 0.0, duration))
