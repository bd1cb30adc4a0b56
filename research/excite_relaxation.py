"""How low can the cond of an excitation design go at all?

A relaxation of every trajectory: the smallest cond of the stacked base regressor over DISTRIBUTIONS of
states ``(q, dq, ddq)`` within the limits, without continuity in time. :func:`relaxation_bracket` brackets
it by column generation on an SDP ([BV2004] sect. 7.5): the upper end is the cond of an explicit
distribution, the lower end a dual estimate by weak duality (as far as the maximisation of the dual ratio
over states, :class:`_DualPricer`, is global; :func:`relaxation_verify` re-prices it on a larger search).
Conditions every design meets restrict the distributions and sharpen the bound:

* ``stationary=True``: the occupation-measure moments of a closed trajectory (periodic, or ending where it
  started), :func:`stationarity_moments` ([LHPT08]);
* ``rest=True``: those of every trajectory at rest at both ends, :class:`RestMoments` (the rates of the
  momentum regressor and of the frame velocities; ``kinetic=`` adds test functions quadratic in ``dq``);
* ``features=K`` (with ``rest``): a cutting plane over the occupation-measure conditions, random test
  functions that vanish at rest (:class:`FeatureMoments`), the ``K`` most violated added every ``cut_every``
  rounds;
* ``braking=True``: only states from which every joint can still stop before the end of its range
  (:func:`braking_speed`);
* ``bandwidth=``: the accelerations a design basis allows (:func:`basis_bandwidth`, an LMI);
* ``transit=L``: the time between speeds that every burst of a joint costs within its range and acceleration
  limit (:class:`TransitInequalities`, linear inequalities on the distribution of each joint's speed).

The rigorous per-sample bound :func:`symoro_gen.excite.cond_lower_bound` and the designs themselves are
:mod:`symoro_gen.excite`'s (this research module imports the package, never the reverse); measurements in
docs/excitation.md.
"""
from __future__ import annotations

import functools
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from symoro_gen.excite import (
    ExcitationError,
    FourierBasis,
    Limits,
    basis_eval,
    casadi_regressor,
    load_casadi,
    mdh_frames,
    random_trajectory,
    sympy_to_casadi,
)
from symoro_gen.model import IdentificationModel

__all__ = [
    "BRAKING_SLACK",
    "FeatureMoments",
    "PERTURB_SCALES",
    "RelaxationBracket",
    "RelaxationRound",
    "RestMoments",
    "TRANSIT_DT",
    "TransitInequalities",
    "basis_bandwidth",
    "feature_dictionary",
    "braking_speed",
    "mixture_cond",
    "mixture_duals",
    "relaxation_bracket",
    "relaxation_dual_bound",
    "relaxation_rows",
    "relaxation_verify",
    "split_saved_atoms",
    "stationarity_moment_names",
    "stationarity_moments",
    "stationarity_scales",
    "transit_friction_ceiling",
]

@dataclass(frozen=True)
class RelaxationRound:
    """One round of :func:`relaxation_bracket`: ``primal`` (cond of the best distribution over the
    round's states), ``dual`` (``sqrt(tr A / (r tr B))``), ``r`` (the largest dual ratio found),
    ``atoms`` (states in the round's SDP), ``kept`` (states with weight above the pruning threshold),
    ``seconds`` (wall time since the start), ``sdp_seconds`` (of which in the round's SDP), ``cuts`` (random
    test functions of :class:`FeatureMoments` in the round's relaxation)."""

    round: int
    atoms: int
    kept: int
    primal: float
    dual: float
    r: float
    seconds: float
    sdp_seconds: float = 0.0
    cuts: int = 0


@dataclass(frozen=True)
class RelaxationBracket:
    """``[lower, upper]`` for the smallest cond of the stacked base regressor over every DISTRIBUTION of
    states within the position, velocity and acceleration limits (no continuity in time: a relaxation
    of every trajectory, of any duration and sampling, including samples at rest).

    ``upper`` is the cond of an explicit distribution (``states``, ``weights``; recomputed with numpy):
    a rigorous upper bound on the relaxation's minimum (not on any trajectory's). ``lower`` is
    ``sqrt(tr A / (r tr B))`` for PSD ``A, B`` and ``r`` the largest ``tr(A G(s)) / tr(B G(s))`` FOUND
    over the state box (random states plus multistart L-BFGS-B): a lower bound on the cond of every
    trajectory if ``r`` is the true maximum, i.e. rigorous only as far as that maximisation is global.
    ``signs``: the ``sign(dq)`` used in each state's Coulomb columns (see :func:`relaxation_rows`).

    With ``stationary`` the distributions are further restricted to those whose stationarity moments
    (:func:`stationarity_moments`, normalised by :func:`stationarity_scales`) are within ``moment_tol``
    of zero, as every periodic trajectory's (and every one that starts and ends at rest at the same
    configuration); ``lam`` and ``c0`` are the multipliers of those constraints in the dual that gives
    ``lower`` (see :class:`_DualPricer`), and ``lower`` then bounds the cond of every such trajectory.
    ``A, B, r, lam, c0`` are those of the round that gave ``lower``. ``rest`` (a :class:`RestMoments`) adds
    the moments of every trajectory that starts and ends at rest to those constraints (``lam`` covers both,
    the closed ones first when ``closed``); ``lower`` then bounds the cond of every such trajectory
    (closed or not, as ``closed`` says).

    With ``bandwidth`` (``rho``, from :func:`basis_bandwidth`) the distributions are further restricted
    by ``E[ddq ddq^T] <= rho E[dq dq^T]`` (an LMI), which every design of a given basis meets on its
    samples; ``C`` is its multiplier (PSD), and ``lower`` then bounds the cond of every design of that
    basis (and, with ``stationary``, that returns to its start).

    With random test functions (``relaxation_bracket(features=K)``), ``features`` are those of the round that
    gave ``lower`` (``lam`` covers them last) and ``upper_features`` those the ``upper`` distribution meets
    (the cuts of its round; the cut set grows, so the two may differ). ``design_sizes``: the whole-trajectory
    atoms of the ``upper`` distribution, the last blocks of ``states`` (each a trajectory's samples in equal
    shares), so that a saved run can continue (``relaxation_bracket(extra_designs=, cuts=)``).

    With ``transit`` (:class:`TransitInequalities`) the distributions also meet ``E[g] <= 0`` (the time
    between speeds that every burst of a design costs); ``eta >= 0`` are their multipliers in the dual that
    gives ``lower``.
    """

    lower: float
    upper: float
    rounds: tuple[RelaxationRound, ...]
    states: np.ndarray
    signs: np.ndarray
    weights: np.ndarray
    A: np.ndarray
    B: np.ndarray
    r: float
    moment_tol: float = 0.0
    lam: np.ndarray | None = None
    c0: float = 0.0
    bandwidth: float | None = None
    C: np.ndarray | None = None
    degree: int = 2
    closed: bool = True
    rest: RestMoments | None = None
    braking: bool = False
    features: FeatureMoments | None = None
    upper_features: FeatureMoments | None = None
    design_sizes: tuple[int, ...] = ()
    transit: TransitInequalities | None = None
    eta: np.ndarray | None = None

    @property
    def stationary(self) -> bool:
        """Whether the stationarity moments of closed trajectories constrained the distributions."""
        return self.lam is not None and self.closed


def _coulomb_columns(model: IdentificationModel) -> list[tuple[int, int]]:
    """``(joint, column)`` of every base column ``FS<j>`` that is ``sign(dq_j)`` in row ``j`` only
    (checked on random states; other Coulomb-like columns are left as the model computes them)."""
    names = list(model.BASE_NAMES)
    n = int(model.N_JOINTS)
    rng = np.random.default_rng(1)
    q, dq, ddq = rng.uniform(-3, 3, (16, n)), rng.uniform(-2, 2, (16, n)), rng.uniform(-5, 5, (16, n))
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(16, n, len(names))
    out = []
    for j in range(n):
        c = f"FS{j + 1}"
        if c not in names:
            continue
        want = np.zeros((16, n))
        want[:, j] = np.sign(dq[:, j])
        if np.abs(W[:, :, names.index(c)] - want).max() <= 1e-12:
            out.append((j, names.index(c)))
    return out


def relaxation_rows(model: IdentificationModel, states: np.ndarray, signs: np.ndarray | None = None,
                    coulomb: list[tuple[int, int]] | None = None) -> np.ndarray:
    """Base regressor rows ``(k, n, nb)`` of states ``(k, 3n)`` = ``(q, dq, ddq)``, with the Coulomb
    column ``FS_j`` set to ``signs[:, j]`` (default ``sign(dq_j)``).

    The state set is taken CLOSED: at ``dq_j = 0`` the sign may be -1, 0 or +1. ``0`` is a sample
    exactly at rest (a trajectory may rest on an interval); ``+-1`` the limit of samples moving at a
    vanishing speed. The infimum of cond over distributions is the same on the set and its closure
    (cond of ``E[G]`` is continuous where finite), so this changes no bound and lets the maximisations
    reach the boundary.
    """
    states = np.atleast_2d(np.asarray(states, float))
    n = int(model.N_JOINTS)
    W = np.asarray(model.regressor(states[:, :n], states[:, n:2 * n], states[:, 2 * n:])).reshape(
        len(states), n, len(model.BASE_NAMES)).copy()
    if signs is not None:
        for j, c in (_coulomb_columns(model) if coulomb is None else coulomb):
            W[:, j, c] = signs[:, j]
    return W


def _cond_sdp(Gn: np.ndarray):
    """The variables and LMIs of the cond SDP over mixtures of the trace-normalised matrices ``Gn``
    (``(k, nb, nb)``): weights ``mu >= 0``, ``kappa``, ``sum mu_i Gn_i >= I`` and ``kappa I >= sum mu_i Gn_i``
    (cond^2 <= kappa; [BV2004] sect. 7.5). Shared by :func:`relaxation_bracket` and :func:`mixture_duals`."""
    import cvxpy as cp

    k, nb = Gn.shape[0], Gn.shape[1]
    mu, kap = cp.Variable(k, nonneg=True), cp.Variable()
    Mx = cp.reshape(Gn.reshape(k, -1).T @ mu, (nb, nb), order="C")
    Mx = (Mx + Mx.T) / 2
    return mu, kap, Mx >> np.eye(nb), kap * np.eye(nb) - Mx >> 0


def mixture_cond(matrices: np.ndarray) -> tuple[float, np.ndarray]:
    """See :func:`mixture_duals` (the same SDP; cond and time fractions only)."""
    c, p, _, _ = mixture_duals(matrices)
    return c, p


def mixture_duals(matrices: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """The smallest cond over MIXTURES of designs: ``matrices`` ``(k, nb, nb)`` are the information matrices
    ``W_i^T W_i / N_i`` of ``k`` designs (per sample); a mixture runs design ``i`` for a fraction ``p_i`` of
    the time, ``M = sum_i p_i M_i``. Returns ``(cond, p)``: ``sqrt(lambda_max / lambda_min)`` of the best
    mixture (recomputed from the weights, whatever the solver's accuracy) and its time fractions (summing to
    1), and the duals ``A`` (of ``M >= I``) and ``B`` (of ``kappa I >= M``, PSD) that price a new design by
    ``tr(A M) / tr(B M)`` (``bench/bench_excite_mixture.py --price``). The SDP of :func:`relaxation_bracket` with whole designs
    as atoms (cvxpy + Clarabel). Every condition that the relaxations hold for every design (a linear
    moment condition, a set the states keep to) holds for every mixture too, so no such relaxation can bound
    a single design's cond above this value for the designs it is given."""
    import cvxpy as cp

    Ms = np.asarray(matrices, float)
    if Ms.ndim != 3 or Ms.shape[1] != Ms.shape[2] or len(Ms) == 0:
        raise ValueError(f"mixture_cond: matrices must be (k, nb, nb) with k >= 1, not {Ms.shape}")
    k, nb = Ms.shape[0], Ms.shape[1]
    tr = np.trace(Ms, axis1=1, axis2=2)
    Mn = Ms / tr[:, None, None]
    w, kap, c1, c2 = _cond_sdp(Mn)
    prob = cp.Problem(cp.Minimize(kap), [c1, c2])
    with warnings.catch_warnings():  # "optimal_inaccurate": the cond returned is recomputed from the weights
        warnings.simplefilter("ignore", UserWarning)
        prob.solve(solver="CLARABEL")
    if w.value is None:  # no mixture has full rank
        return math.inf, np.full(k, 1.0 / k), np.zeros((nb, nb)), np.zeros((nb, nb))
    wv = np.clip(np.asarray(w.value), 0, None)
    ev = np.linalg.eigvalsh(np.einsum("k,kab->ab", wv, Mn))
    p = wv / tr
    return ((math.sqrt(ev[-1] / ev[0]) if ev[0] > 0 else math.inf), p / p.sum(), _psd(np.asarray(c1.dual_value)),
            _psd(np.asarray(c2.dual_value)))


def relaxation_dual_bound(A: np.ndarray, B: np.ndarray, r: float) -> float:
    """``sqrt(tr A / (r tr B))`` after projecting ``A, B`` on the PSD cone.

    Weak duality, for any PSD ``A, B``: if ``tr(A G(s)) <= r tr(B G(s))`` for every state ``s``,
    then for every distribution ``M = E[G] `` with ``lambda_min I <= M <= lambda_max I``,
    ``lambda_min tr A <= tr(A M) <= r tr(B M) <= r lambda_max tr B``, hence
    ``cond^2 = lambda_max / lambda_min >= tr A / (r tr B)`` (Boyd & Vandenberghe 2004, sect. 5.2 and
    7.5: the dual of the E-/cond-optimal design SDP).
    """
    A, B = _psd(A), _psd(B)
    return math.sqrt(float(np.trace(A)) / (r * float(np.trace(B))))


def _psd(X: np.ndarray) -> np.ndarray:
    X = (X + X.T) / 2
    w, V = np.linalg.eigh(X)
    return (V * np.clip(w, 0, None)) @ V.T


def basis_bandwidth(basis, t: np.ndarray) -> float:
    """``rho``: the largest ``mean((u . ddq)^2) / mean((u . dq)^2)`` over the samples ``t`` of every
    design of ``basis`` and every direction ``u`` of joint space (the largest generalised eigenvalue
    of ``(Phi''^T Phi'', Phi'^T Phi')`` at ``t``: ``u . q(t) = Phi(t) X u`` is itself a design).

    Every design of the basis therefore has ``E[ddq ddq^T] <= rho E[dq dq^T]`` over those samples (an
    LMI that :func:`relaxation_bracket` can impose with ``bandwidth=rho``): its accelerations cannot
    vary faster than the basis allows. For a Fourier series of ``K`` harmonics of ``w``, ``rho`` is
    close to ``(K w)^2``; a distribution of states can have any ratio (accelerations at their limits
    while the velocity stays at its own, which a trajectory can only do by switching the sign of its
    acceleration at a rate no smooth basis has).
    """
    _, D, A = basis.matrices(np.asarray(t, float))
    w, V = np.linalg.eigh(D.T @ D)
    keep = w > 1e-12 * w.max()
    if (~keep).any() and float(np.linalg.norm(A @ V[:, ~keep])) > 1e-8 * float(np.linalg.norm(A)):
        raise ExcitationError("basis_bandwidth: a design with no velocity has an acceleration on these samples")
    Vk = V[:, keep] / np.sqrt(w[keep])
    return float(np.linalg.eigvalsh(Vk.T @ (A.T @ A) @ Vk)[-1])


#: position slack of :func:`braking_speed`, a fraction of each joint's range
BRAKING_SLACK = 1e-3


def braking_speed(limits: Limits, q: np.ndarray, sign: np.ndarray, slack: float = BRAKING_SLACK) -> np.ndarray:
    """The largest speed a joint can have at ``q`` moving in direction ``sign`` (+1 towards ``q_max``, -1
    towards ``q_min``) in a trajectory that stays within its range and acceleration limit and stops before
    it ends (at rest at the end, or turning back): it must be able to brake before the end of its range,
    ``dq^2 <= 2 ddq_max (q_max + d - q)`` (resp. ``(q - q_min + d)``); capped by ``dq_max``. ``d = slack x
    (q_max - q_min)`` covers a sampled design: its limits hold on a grid, between whose points the motion may
    overshoot a range end by a little (a sample at the end itself with a small speed). Every sample of every
    ``excite`` design (at rest at both ends, or periodic) satisfies it; a state of the box near a range end
    at full speed does not (the LWR4's joints need 20-52 deg to stop from their velocity limit, the RX-90's
    50-153 deg)."""
    return _braking(limits, q, sign, slack)[0]


def _braking(limits: Limits, q: np.ndarray, sign: np.ndarray, slack: float = BRAKING_SLACK
             ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`braking_speed` and its derivative with respect to ``q``."""
    d = slack * (limits.q_max - limits.q_min)
    sign = np.asarray(sign)
    room = np.clip(np.where(sign > 0, limits.q_max - q, q - limits.q_min) + d, 0.0, None)
    sq = np.sqrt(2.0 * limits.ddq_max * room)
    dcap = np.where((sq < limits.dq_max) & (sq > 0), -sign * limits.ddq_max / np.maximum(sq, 1e-12), 0.0)
    return np.minimum(limits.dq_max, sq), dcap


def _brake(limits: Limits, X: np.ndarray) -> np.ndarray:
    """The states ``X`` (``(k, 3n)``) with every speed capped by :func:`braking_speed` (directions kept)."""
    n = limits.n
    out = np.array(X, float)
    dq = out[:, n:2 * n]
    out[:, n:2 * n] = np.sign(dq) * np.minimum(np.abs(dq), braking_speed(limits, out[:, :n], np.sign(dq)))
    return out


def _random_states(rng: np.random.Generator, limits: Limits, k: int, braking: bool = False
                   ) -> tuple[np.ndarray, np.ndarray]:
    """States spread over the box with its faces and vertices over-represented: each velocity uniform,
    exactly +-dq_max, exactly 0 (sign -1, 0 or +1) or slow (< 0.1 dq_max), each acceleration uniform or
    exactly +-ddq_max. With ``braking`` each speed is then capped by :func:`braking_speed` (the same draws)."""
    n = limits.n
    q = rng.uniform(limits.q_min, limits.q_max, (k, n))
    mode, sg = rng.integers(0, 4, (k, n)), rng.choice([-1.0, 1.0], (k, n))
    v = np.where(mode == 0, rng.uniform(-1, 1, (k, n)),
                 np.where(mode == 1, sg, np.where(mode == 2, 0.0, sg * rng.uniform(0, 0.1, (k, n)))))
    s = np.where(mode == 2, rng.integers(-1, 2, (k, n)).astype(float), np.sign(v))
    a = np.where(rng.random((k, n)) < 0.5, rng.uniform(-1, 1, (k, n)), rng.choice([-1.0, 1.0], (k, n)))
    X = np.hstack([q, v * limits.dq_max, a * limits.ddq_max])
    return (_brake(limits, X) if braking else X), s


#: the sampling interval [s] the transit inequalities hold for by default: every design sampled at 100 Hz or faster
TRANSIT_DT = 0.01


class TransitInequalities:
    """The time a joint spends between speeds, which a trajectory cannot skip: ``E[g(s)] <= 0`` for every
    design at rest at both ends (or periodic), of any duration, and every mixture of them.

    A *burst* of joint ``j`` in direction ``sigma`` is a maximal interval with ``sigma dq_j >= u1 > 0``
    that reaches ``u2 > u1``. The joint enters it and leaves it from below ``u1`` (the design is at rest at
    both ends), and ``|ddq_j| <= a`` (its acceleration limit), so each crossing of the band ``[u1, u2)``
    lasts at least ``(u2 - u1)/a``; within the burst the joint moves one way, by at most its range ``R``,
    of which at least ``(u2^2 - u1^2)/a`` during the two crossings, so its time at ``sigma dq_j >= u2``
    is at most ``(R - (u2^2 - u1^2)/a)/u2``. Summed over the bursts::

        P(sigma dq_j >= u2) <= kappa P(u1 <= sigma dq_j < u2),
        kappa = ((R - (u2^2 - u1^2)/a)/u2) / (2 (u2 - u1)/a)                       (time average, dt = 0)
        kappa = max(1, ((R - (u2^2 - u1^2)/a)/(u2 - a dt/4) + dt) / (2 ((u2 - u1)/a - dt)))   (samples dt apart)

    The first holds for the time average of every trajectory at rest at both ends (or periodic), of any
    duration, and every mixture of them. The second for the samples every ``dt`` (``kappa`` falls with
    ``dt``, so the rows of ``dt`` hold for every finer sampling) of every such design, whatever its speed does
    within a burst: group a burst's samples at ``>= u2`` into ``m`` runs of consecutive samples. Each crossing
    holds at least ``(u2 - u1)/(a dt) - 1`` samples in the band, and the runs are separated by at least one
    band sample each, so the burst has ``N_B >= 2 ((u2 - u1)/(a dt) - 1) + m - 1`` samples in the band; between
    two consecutive samples of a run the speed is at least ``u2 - a |t - t_k|`` and the joint moves at least
    ``dt (u2 - a dt/4)``, and those steps lie between the two crossings, so a run of ``k`` samples has ``k - 1
    <= (R - (u2^2 - u1^2)/a)/(dt (u2 - a dt/4))`` summed over the runs and ``N_H <= that + 1 + (m - 1)``.
    With ``kappa`` as above, ``kappa N_B >= N_H`` for every ``m`` (the ``max(1, .)`` covers the ``m - 1``
    extra runs). Thresholds ``u = k
    dq_max_j / levels``, ``k = 1..levels``, every pair (bands narrower than ``1.5 a dt`` skipped), both
    directions, every joint: ``g = 1(sigma dq_j >= u2) - kappa 1(u1 <= sigma dq_j < u2)``. A distribution
    that jumps between creeping and the velocity limit (the friction columns' best, which every
    relaxation without this condition picks) violates it: with 8 levels it caps the ``sigma`` of the friction
    block of the LWR4's joints 1-2 at 0.987 and 0.981 of :func:`symoro_gen.excite.friction_ceiling`'s
    (:func:`transit_friction_ceiling`). The moments held by the relaxations (polynomial or oscillating in the
    speeds) barely imply it; test functions ``(q_j - c) h(dq_j)`` with ``h`` a step in speed would, and
    :func:`braking_speed` (a set of states) does not.
    """

    def __init__(self, limits: Limits, levels: int = 8, dt: float = TRANSIT_DT):
        if levels < 2 or not dt >= 0:
            raise ValueError(f"transit inequalities: levels {levels} must be >= 2 and dt {dt} >= 0")
        rows = []  # (joint, sign, u1, u2, kappa)
        for j in range(limits.n):
            V, a, R = float(limits.dq_max[j]), float(limits.ddq_max[j]), float(limits.q_max[j] - limits.q_min[j])
            us = V * np.arange(1, levels + 1) / levels
            for i2 in range(1, levels):
                u2 = float(us[i2])
                for u1 in us[:i2]:
                    du = u2 - float(u1)
                    if du / a <= 1.5 * dt:  # (so u2 > u1 + 1.5 a dt > a dt/4 too)
                        continue
                    kap = (max(R - (u2 ** 2 - float(u1) ** 2) / a, 0.0) / (u2 - a * dt / 4) + dt) / (2 * (du / a - dt))
                    if dt > 0:  # several runs at >= u2 within a burst, each separated by one band sample
                        kap = max(kap, 1.0)
                    for sg in (1.0, -1.0):
                        rows.append((j, sg, float(u1), u2, kap))
        self.levels, self.dt, self.n = int(levels), float(dt), limits.n
        arr = np.array(rows, float).reshape(-1, 5)
        self.joint, self.sign = arr[:, 0].astype(int), arr[:, 1]
        self.u1, self.u2, self.kappa = arr[:, 2], arr[:, 3], arr[:, 4]

    def __len__(self) -> int:
        return len(self.kappa)

    def numpy(self, X: np.ndarray) -> np.ndarray:
        """``g`` (``(k, m)``) at the states ``X`` (``(k, 3n)``); ``E[g] <= 0`` for every design."""
        X = np.atleast_2d(np.asarray(X, float))
        v = X[:, self.n + self.joint] * self.sign  # (k, m): the speed in each row's direction
        hi = v >= self.u2
        band = (v >= self.u1) & ~hi
        return hi.astype(float) - self.kappa * band

    def worst(self, X: np.ndarray, p: np.ndarray | None = None) -> float:
        """The largest ``E[g] / (1 + kappa)`` over the rows, for the states ``X`` in proportions ``p`` (equal
        shares by default): <= 0 for every design; the share of its time a distribution would have to move
        into the bands to meet the conditions."""
        g = self.numpy(X)
        p = np.full(len(g), 1.0 / len(g)) if p is None else np.asarray(p, float) / np.sum(p)
        return float(np.max((p @ g) / (1.0 + self.kappa))) if len(self) else 0.0


def transit_friction_ceiling(limits: Limits, transit: TransitInequalities, grid: int = 400) -> np.ndarray:
    """Per joint, the largest ``lambda_min`` of the friction block ``E[z z^T]``, ``z = (dq, sign dq, 1)``, over
    the velocity distributions on ``[-dq_max, dq_max]`` that meet the joint's rows of ``transit`` (an SDP on a
    grid of ``grid`` speeds per direction plus rest and creeping, cvxpy + Clarabel): the cap of
    :func:`symoro_gen.excite.friction_ceiling` once a burst to the velocity limit costs time at the speeds
    below it. (The grid makes it a slight under-estimate of the supremum; it is a figure, not a bound.)"""
    import cvxpy as cp

    out = np.zeros(limits.n)
    for j in range(limits.n):
        V = float(limits.dq_max[j])
        s = V * np.arange(1, grid + 1) / grid
        v = np.concatenate([[0.0, 0.0, 0.0], s, -s])
        sg = np.concatenate([[0.0, 1.0, -1.0], np.ones(grid), -np.ones(grid)])  # creeping: speed -> 0, sign kept
        Z = np.stack([v, sg, np.ones_like(v)], 1)
        w, t = cp.Variable(len(v), nonneg=True), cp.Variable()
        M = cp.reshape(np.einsum("ka,kb->kab", Z, Z).reshape(len(v), 9).T @ w, (3, 3), order="C")
        cons = [cp.sum(w) == 1, (M + M.T) / 2 - t * np.eye(3) >> 0]
        rows = np.flatnonzero(transit.joint == j)
        if len(rows):
            X = np.zeros((len(v), 3 * limits.n))
            X[:, limits.n + j] = v
            cons.append(transit.numpy(X)[:, rows].T @ w <= 0)
        cp.Problem(cp.Maximize(t), cons).solve(solver="CLARABEL")
        out[j] = float(np.asarray(t.value))
    return out


#: one term of the stationarity moments: (name, ((sign, ((factor, joint), ...)), ...))
_Term = tuple[str, tuple[tuple[int, tuple[tuple[str, int], ...]], ...]]


#: d/dt of each factor of a test function: (sign, factor kinds), of the same joint
_FACTOR_RATE = {"q": (1, ("dq",)), "dq": (1, ("ddq",)), "sin": (1, ("cos", "dq")), "cos": (-1, ("sin", "dq"))}


def _rate_term(factors: tuple[tuple[str, int], ...]) -> _Term:
    """``d/dt`` of the test function ``prod(factors)`` by the product rule (:data:`_FACTOR_RATE`)."""
    name = "d/dt(" + " ".join(f"{kind}{j + 1}" if kind in ("q", "dq") else f"{kind} q{j + 1}"
                              for kind, j in factors) + ")"
    products = []
    for k, (kind, j) in enumerate(factors):
        sign, kinds = _FACTOR_RATE[kind]
        products.append((sign, tuple((kk, j) for kk in kinds) + factors[:k] + factors[k + 1:]))
    return name, tuple(products)


def _degree3_tests(n: int) -> list[tuple[tuple[str, int], ...]]:
    """The test functions of degree 3 (:func:`stationarity_moments` with ``degree=3``): products of two
    trigonometric factors ``t_i t_j`` (``i <= j``; ``cos cos``, ``cos sin``, ``sin cos``, ``sin sin``, only
    ``cos^2`` and ``cos sin`` for ``i = j``) alone and times each ``dq_k``; ``t_i dq_k dq_l``, ``q_i dq_k dq_l``
    (``k <= l``) and ``dq_i dq_j dq_k`` (``i <= j <= k``)."""
    trig = ("cos", "sin")
    out: list[tuple[tuple[str, int], ...]] = []
    for i in range(n):
        for j in range(i, n):
            for a in trig:
                for b in trig:
                    if i == j and a == "sin":  # sin^2 = 1 - cos^2, sin cos = cos sin
                        continue
                    phi = ((a, i), (b, j))
                    out += [phi] + [phi + (("dq", k),) for k in range(n)]
    pairs = [(k, m) for k in range(n) for m in range(k, n)]
    out += [((a, i), ("dq", k), ("dq", m)) for i in range(n) for a in ("cos", "sin", "q") for k, m in pairs]
    out += [(("dq", i), ("dq", j), ("dq", k)) for i in range(n) for j in range(i, n) for k in range(j, n)]
    return out


@functools.cache
def _stationarity_terms(n: int, degree: int = 2) -> tuple[_Term, ...]:
    """The terms of :func:`stationarity_moments`: ``(name, ((sign, factors), ...))``, each a sum of signed
    products of factors ``("q"|"dq"|"ddq"|"sin"|"cos", joint)`` (``sin``/``cos`` of ``q_joint``)."""
    if degree not in (2, 3):
        raise ExcitationError(f"stationarity moments of degree {degree}: 2 or 3")
    out: list[_Term] = []
    for j in range(n):
        J = j + 1
        out += [(f"d/dt(q{J})", ((1, (("dq", j),)),)),
                (f"d/dt(dq{J})", ((1, (("ddq", j),)),)),
                (f"d/dt(dq{J}^2/2)", ((1, (("dq", j), ("ddq", j))),)),
                (f"d/dt(q{J}^2/2)", ((1, (("q", j), ("dq", j))),)),
                (f"d/dt(cos q{J})", ((-1, (("sin", j), ("dq", j))),)),
                (f"d/dt(sin q{J})", ((1, (("cos", j), ("dq", j))),))]
    for i in range(n):
        for j in range(n):
            I, J = i + 1, j + 1
            out += [(f"d/dt(q{I} dq{J})", ((1, (("dq", i), ("dq", j))), (1, (("q", i), ("ddq", j))))),
                    (f"d/dt(cos q{I} dq{J})", ((-1, (("sin", i), ("dq", i), ("dq", j))), (1, (("cos", i), ("ddq", j))))),
                    (f"d/dt(sin q{I} dq{J})", ((1, (("cos", i), ("dq", i), ("dq", j))), (1, (("sin", i), ("ddq", j)))))]
            if i < j:
                out.append((f"d/dt(dq{I} dq{J})", ((1, (("ddq", i), ("dq", j))), (1, (("dq", i), ("ddq", j))))))
    if degree == 3:
        out += [_rate_term(f) for f in _degree3_tests(n)]
    return tuple(out)


def stationarity_moments(q, dq, ddq, lib: Any = np, degree: int = 2):
    """The time derivatives ``d/dt f(q, dq) = f_q dq + f_dq ddq`` of the test functions ``f`` =
    ``q_j``, ``dq_j``, ``dq_j^2/2``, ``q_j^2/2``, ``cos q_j``, ``sin q_j`` (per joint), ``q_i dq_j``,
    ``cos q_i dq_j``, ``sin q_i dq_j`` (every pair) and ``dq_i dq_j`` (``i < j``); with ``degree=3``
    also those of :func:`_degree3_tests` (products of three factors)
    (:func:`stationarity_moment_names` names them, :func:`stationarity_scales` sizes them).

    Over one period of a periodic trajectory, or any trajectory that starts and ends in the same
    state (the Fourier designs of ``excite``; a spline design may end elsewhere), the mean of ``d/dt f``
    is ``(f(end) - f(start)) / T = 0``: the moment conditions that distinguish the sample distribution of a
    trajectory from an arbitrary distribution of states (the occupation-measure constraints of Lasserre, Henrion, Prieur
    and Trelat 2008, [LHPT08]). ``q, dq, ddq``: ``(k, n)`` arrays with ``lib = numpy`` (returns
    ``(k, m)``), or CasADi ``(n, 1)`` vectors with ``lib = casadi`` (returns an ``(m, 1)`` vector).
    """
    if lib is np:
        q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
        n = q.shape[1]
        cols = {"q": q.T, "dq": dq.T, "ddq": ddq.T, "sin": np.sin(q).T, "cos": np.cos(q).T}
    else:
        n = int(q.shape[0])
        cols = {"q": q, "dq": dq, "ddq": ddq, "sin": lib.sin(q), "cos": lib.cos(q)}
    out = []
    for _, products in _stationarity_terms(n, degree):
        total = 0
        for sign, factors in products:
            term = sign
            for kind, j in factors:
                term = term * cols[kind][j]
            total = total + term
        out.append(total)
    return np.stack(out, axis=1) if lib is np else lib.vertcat(*out)


def stationarity_moment_names(n: int, degree: int = 2) -> list[str]:
    """The name ``d/dt(f)`` of each term of :func:`stationarity_moments` (same order), joints from 1."""
    return [name for name, _ in _stationarity_terms(n, degree)]


def stationarity_scales(limits: Limits, degree: int = 2) -> np.ndarray:
    """The size of each term of :func:`stationarity_moments` over the limits' box (the sum over its
    products of the largest magnitude of each factor: ``max |q_j|``, ``dq_max``, ``ddq_max``, 1 for sin
    and cos): the moment ``k`` is held to ``|E[m_k]| <= tol * scale_k``."""
    bound = {"q": np.maximum(np.abs(limits.q_min), np.abs(limits.q_max)), "dq": limits.dq_max,
             "ddq": limits.ddq_max, "sin": np.ones(limits.n), "cos": np.ones(limits.n)}
    return np.array([sum(math.prod(float(bound[kind][j]) for kind, j in factors) for _, factors in products)
                     for _, products in _stationarity_terms(limits.n, degree)])


#: the probe speeds of a speed scan (fractions of ``dq_max``), and the two it checks the cubic through them at
SCAN_PROBES = np.array([-1.0, -1.0 / 3.0, 1.0 / 3.0, 1.0])
_SCAN_CHECKS = np.array([-0.8125, 0.6171875])


def _lagrange(nodes: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(len(t), len(nodes))``: the Lagrange basis of ``nodes`` at ``t`` (the polynomial through values
    ``y`` at the nodes is ``L @ y``)."""
    L = np.ones((len(t), len(nodes)))
    for a, ta in enumerate(nodes):
        for b, tb in enumerate(nodes):
            if a != b:
                L[:, a] *= (t - tb) / (ta - tb)
    return L


class _DualPricer:
    """The dual ratio of the relaxation SDP at duals ``A, B`` (and, with the stationarity constraints,
    their multipliers ``lam`` and ``c0``)::

        N(s) / D(s),  N(s) = tr(A G(s)) - lam . m(s) / scale + c0 + rho dq^T C dq - ddq^T C ddq - eta . g(s),
        D(s) = tr(B G(s))

    Weak duality: if ``N(s) <= r D(s)`` for every state ``s`` of the box, then for every distribution
    ``M = E[G]`` with ``|E[m]| <= tol scale`` (and ``c0 >= tol sum |lam|``), ``lambda_min tr A <= tr(A M)
    <= E[N] <= r tr(B M) <= r lambda_max tr B``: ``cond >= sqrt(tr A / (r tr B))``
    (:func:`relaxation_dual_bound`); the bandwidth term (``C`` PSD) has ``E >= 0`` for every distribution
    with ``E[ddq ddq^T] <= rho E[dq dq^T]``, so the same holds for those; the transit term (``eta >= 0``,
    ``g`` of :class:`TransitInequalities`) has ``E >= 0`` for every distribution with ``E[g] <= 0``. ``ratio`` evaluates it on
    states; ``local_max`` maximises it by L-BFGS-B in the box from a state with its velocity signs held,
    gradients from the generated CasADi model.
    """

    def __init__(self, model: IdentificationModel, limits: Limits, A: np.ndarray, B: np.ndarray,
                 lam: np.ndarray | None = None, c0: float = 0.0, *, rho: float | None = None,
                 C: np.ndarray | None = None, degree: int = 2, closed: bool = True, rest: RestMoments | None = None,
                 coulomb=None, jac=None, braking: bool = False, features: FeatureMoments | None = None,
                 transit: TransitInequalities | None = None, eta: np.ndarray | None = None):
        self.model, self.A, self.B = model, A, B
        self.transit = transit if transit is not None and eta is not None and len(transit) else None
        self.eta = None if self.transit is None else np.clip(np.asarray(eta, float), 0.0, None)
        self.limits, self.braking = limits, braking
        self.lam, self.c0 = lam, float(c0)
        self.rho: float | None = None if rho is None or C is None else float(rho)
        self.C: np.ndarray | None = None if rho is None or C is None else _psd(np.asarray(C, float))
        self.n = limits.n
        self.coul = _coulomb_columns(model) if coulomb is None else coulomb
        self.moments = _MomentSet(limits, degree if closed else None, rest, features) if lam is not None else None
        self.jac = jac if jac is not None else self.casadi_jacobian(model, self.n, self.moments)
        self.lo = np.concatenate([limits.q_min, -limits.dq_max, -limits.ddq_max])
        self.hi = np.concatenate([limits.q_max, limits.dq_max, limits.ddq_max])

    @staticmethod
    def casadi_jacobian(model: IdentificationModel, n: int, moments: _MomentSet | None):
        try:
            F = casadi_regressor(model)
        except ExcitationError:  # priced without gradients (random states only)
            return None
        ca = load_casadi()
        z = ca.SX.sym("z", 3 * n)
        Y = F(z[:n], z[n:2 * n], z[2 * n:])
        out = [Y, ca.jacobian(ca.vec(Y), z)]  # vec: column-major
        if moments is not None:
            m = moments.casadi(z)
            out += [m, ca.jacobian(m, z)]
        return ca.Function("ratio_rows", [z], out)

    def num_den(self, X: np.ndarray, S: np.ndarray, W: np.ndarray | None = None, rest: np.ndarray | None = None):
        """``N, D`` at the states ``X`` with the velocity signs ``S``; ``W`` their regressor rows and ``rest``
        their rest moments when the caller has them (:meth:`_speed_scan`)."""
        X = np.atleast_2d(X)
        if W is None:
            W = relaxation_rows(self.model, X, S, self.coul)
        num = np.einsum("kia,kia->k", W @ self.A, W)  # tr(A W^T W) per state, through BLAS
        den = np.einsum("kia,kia->k", W @ self.B, W)
        n = self.n
        if self.moments is not None:
            num = num - self.moments.numpy(X, rest) / self.moments.scale @ self.lam + self.c0
        if self.transit is not None:
            num = num - self.transit.numpy(X) @ self.eta
        if self.C is not None:
            dq, ddq = X[:, n:2 * n], X[:, 2 * n:]
            num = num + self.rho * np.einsum("ki,ij,kj->k", dq, self.C, dq) - np.einsum("ki,ij,kj->k", ddq, self.C, ddq)
        return num, den

    def ratio(self, X: np.ndarray, S: np.ndarray, W: np.ndarray | None = None, rest: np.ndarray | None = None) -> np.ndarray:
        num, den = self.num_den(X, S, W, rest)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.where(num > 0, np.inf, 0.0))

    def _braked(self, zz: np.ndarray, s0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """With ``braking``: the box point ``zz`` with its speeds rescaled from ``[0, dq_max]`` to ``[0,
        braking_speed(q)]``, the factor ``d|dq|/d|dq_box|`` and ``d dq/d q`` of that map (per joint)."""
        n, lim = self.n, self.limits
        frac = np.abs(zz[n:2 * n]) / lim.dq_max
        cap, dcap = _braking(lim, zz[:n], s0)
        out = zz.copy()
        out[n:2 * n] = s0 * cap * frac
        return out, cap / lim.dq_max, s0 * frac * dcap

    def local_max(self, x0: np.ndarray, s0: np.ndarray) -> tuple[np.ndarray, float]:
        """Maximise the ratio from ``x0`` with the velocity signs ``s0`` (``dq_j`` in ``[0, dq_max]`` for
        +1, ``[-dq_max, 0]`` for -1, ``0`` for 0; with ``braking``, ``dq_max`` replaced by
        :func:`braking_speed` at ``q``, through a change of variables that keeps the box); with transit
        inequalities, see :meth:`local_max_with_signs` (the signs may change). Returns ``(state, ratio)``."""
        x, _, r = self.local_max_with_signs(x0, s0)
        return x, r

    def local_max_with_signs(self, x0: np.ndarray, s0: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """:meth:`local_max`, returning ``(state, signs, ratio)``. The transit term is piecewise constant in
        the speeds (no gradient there, and L-BFGS-B cannot cross its steps), so with transit inequalities the
        smooth search alternates with scans of each joint's speed over ``[-dq_max, dq_max]`` (both signs at
        rest; the other coordinates held), each followed by the smooth search from the best point found, until
        a scan gains nothing."""
        x, r = self._local_max_signed(x0, s0)
        s = np.array(s0, float)
        if self.transit is None:
            return x, s, r
        for _ in range(4):
            x2, s2, r2 = self._speed_scan(x, s, r)
            if not r2 > r * (1 + 1e-9):
                break
            x3, r3 = self._local_max_signed(x2, s2)
            x, s, r = (x3, s2, r3) if r3 >= r2 else (x2, s2, r2)
        return x, s, r

    def _speed_scan(self, x: np.ndarray, s: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray, float]:
        """One sweep over the joints: each joint's speed set to the best of a grid (32 points per transit
        level and direction, and rest with either sign) with the others held."""
        assert self.transit is not None
        n, lim = self.n, self.limits
        x, s = np.array(x, float), np.array(s, float)
        grid = np.linspace(-1.0, 1.0, 64 * self.transit.levels + 1)
        if self.braking:  # the scan moves speeds only: the caps at the state's positions hold for the whole sweep
            up, down = braking_speed(lim, x[:n], np.ones(n)), braking_speed(lim, x[:n], -np.ones(n))
        for j in range(n):
            v = np.concatenate([grid * lim.dq_max[j], [0.0, 0.0]])
            sg = np.concatenate([np.sign(grid), [1.0, -1.0]])
            if self.braking:  # only the speeds a design can have there
                keep = np.abs(v) <= np.where(sg > 0, up[j], down[j])
                v, sg = v[keep], sg[keep]
            Xc, Sc = np.tile(x, (len(v), 1)), np.tile(s, (len(v), 1))
            Xc[:, n + j], Sc[:, j] = v, sg
            rc = self.ratio(Xc, Sc, *self._scan_rows(x, s, j, v, Sc))
            k = int(np.argmax(rc))
            if rc[k] > r * (1 + 1e-12):
                x, s, r = Xc[k], Sc[k], float(rc[k])
        return x, s, r

    def _scan_rows(self, x: np.ndarray, s: np.ndarray, j: int, v: np.ndarray, S: np.ndarray):
        """The regressor rows (Coulomb columns from the signs ``S``) and the rest moments of the state ``x``
        with joint ``j``'s speed set to each of ``v``, from :data:`SCAN_PROBES`: the rows of a Newton-Euler
        regressor are quadratic in one joint's speed (the others held) and the rest moments at most cubic
        (rates of test functions at most quadratic in ``dq``), so the cubic through four probes gives them on
        the whole scan. Checked at two more speeds; a model whose rows are not polynomial in the speed (e.g. a
        smooth friction term) gets ``(None, None)`` and is evaluated state by state."""
        n, vmax = self.n, float(self.limits.dq_max[j])
        t = np.concatenate([SCAN_PROBES, _SCAN_CHECKS])
        P, Sp = np.tile(x, (len(t), 1)), np.tile(s, (len(t), 1))
        P[:, n + j], Sp[:, j] = t * vmax, 1.0  # the Coulomb columns are set below
        L = _lagrange(SCAN_PROBES, np.concatenate([_SCAN_CHECKS, v / vmax]))
        nc = len(_SCAN_CHECKS)
        out: list[np.ndarray | None] = []
        for vals in (relaxation_rows(self.model, P, Sp, self.coul),
                     self.moments.rest.numpy(P[:, :n], P[:, n:2 * n], P[:, 2 * n:])
                     if self.moments is not None and self.moments.rest is not None else None):
            if vals is None:
                out.append(None)
                continue
            fit = np.tensordot(L, vals[:len(SCAN_PROBES)], axes=1)
            size = max(float(np.abs(vals).max()), 1e-300)
            if not np.abs(fit[:nc] - vals[len(SCAN_PROBES):]).max() <= 1e-9 * size:
                return None, None
            out.append(fit[nc:])
        W = out[0]
        assert W is not None
        for jj, col in self.coul:
            W[:, jj, col] = S[:, jj]
        return W, out[1]

    def _local_max_signed(self, x0: np.ndarray, s0: np.ndarray) -> tuple[np.ndarray, float]:
        from scipy.optimize import minimize

        n, lo, hi = self.n, self.lo, self.hi
        lo_s, hi_s = lo.copy(), hi.copy()
        lo_s[n:2 * n] = np.where(s0 >= 0, 0.0, lo[n:2 * n])
        hi_s[n:2 * n] = np.where(s0 <= 0, 0.0, hi[n:2 * n])
        c, h = (hi_s + lo_s) / 2, np.maximum((hi_s - lo_s) / 2, 0.0)
        free = h > 0
        A, B, jac = self.A, self.B, self.jac
        braking = self.braking
        if braking:  # start from the box point that maps to x0
            x0 = np.array(x0, float)
            cap0 = braking_speed(self.limits, x0[:n], s0)
            x0[n:2 * n] = s0 * np.where(cap0 > 0, np.abs(x0[n:2 * n]) / np.where(cap0 > 0, cap0, 1.0), 0.0) \
                * self.limits.dq_max

        def f(u):
            zz = c + h * u
            if braking:
                zz, dv, dqq = self._braked(zz, s0)
            if jac is None:
                return -float(self.ratio(zz[None], s0[None])[0])
            res = jac(zz)
            w, J = np.array(res[0]), np.array(res[1])
            for j, col in self.coul:
                w[j, col] = s0[j]
                J[col * n + j, :] = 0.0
            num, den = float(np.sum(w * (w @ A))), float(np.sum(w * (w @ B)))
            gnum = J.T @ (2 * (w @ A)).ravel(order="F")
            gden = J.T @ (2 * (w @ B)).ravel(order="F")
            if self.moments is not None:
                lw = self.lam / self.moments.scale
                num += -float(np.array(res[2]).ravel() @ lw) + self.c0
                gnum = gnum - np.array(res[3]).T @ lw
            if self.transit is not None:  # piecewise constant in dq: no gradient
                num -= float(self.transit.numpy(zz[None])[0] @ self.eta)
            if self.C is not None:
                Cv, Ca = self.rho * (self.C @ zz[n:2 * n]), self.C @ zz[2 * n:]
                num += float(zz[n:2 * n] @ Cv - zz[2 * n:] @ Ca)
                gnum = gnum + np.concatenate([np.zeros(n), 2 * Cv, -2 * Ca])
            den = max(den, 1e-300)
            g = gnum / den - num / den ** 2 * gden
            if braking:  # chain rule through the speed map
                g = np.concatenate([g[:n] + g[n:2 * n] * dqq, g[n:2 * n] * dv, g[2 * n:]])
            return -num / den, -g * h

        u0 = np.where(free, np.clip((x0 - c) / np.where(free, h, 1.0), -1, 1), 0.0)
        bnds = [(-1.0, 1.0) if fr else (0.0, 0.0) for fr in free]
        res = minimize(f, u0, jac=jac is not None, bounds=bnds, method="L-BFGS-B", options={"maxiter": 300})
        x = c + h * res.x
        if braking:
            x = self._braked(x, s0)[0]
        return x, float(self.ratio(x[None], s0[None])[0])


class RestMoments:
    """The moment conditions of every trajectory that starts and ends at rest (every design of ``excite``:
    Fourier, spline, point-to-point) or returns to its starting state: ``E[d/dt f(q, dq)] = 0`` for test
    functions ``f`` that vanish at rest (``f(q, 0) = 0``), since the mean of ``d/dt f`` over the experiment is
    ``(f(end) - f(start)) / T`` (the occupation-measure argument of [LHPT08], without the return to the
    starting configuration that :func:`stationarity_moments` need).

    The test functions are the robot's own: the entries of the momentum regressor
    ``Y_p(q, dq) = W(q, 0, dq) - W(q, 0, 0)`` (``M(q) dq = Y_p chi``, the generalised momentum linear in the
    base parameters) and, with ``robot``, the base-frame velocities of every frame origin and rotation
    matrix (``dp_j/dt``, ``dR_j/dt`` of the MDH transforms). Their rates are the accelerations the
    regressor's inertial and first-moment columns carry: a distribution of states whose arm accelerates
    downwards on average (the LWR4's plain relaxation optimum does: its first-moment columns then cancel
    part of gravity) can meet the stationarity moments of degree 2, not these. Rates from the generated CasADi
    model (``jtimes``); the entries that vanish on ``samples`` random states of the limits (seeded) are
    dropped, and each kept one is scaled by its largest magnitude on them (``scale``; the tolerance of
    :func:`relaxation_bracket` is relative to it). ``numpy(q, dq, ddq)`` gives ``(k, m)``, ``casadi`` an
    ``(m, 1)`` expression; ``names`` name each ``d/dt f``.

    ``kinetic`` adds test functions quadratic in ``dq``: ``"energy"`` the entries of the kinetic-energy
    regressor ``T_b = dq^T Y_p[:, b] / 2`` (whose rates are each column's power ``sum_j dq_j (W_jb(q, dq, ddq) -
    W_jb(q, 0, 0))``, Gautier's energy model), ``"joint"`` every ``dq_j Y_p[j, b]``. Measured on the LWR4 and
    the SCARA, they do not move the relaxation (docs/excitation.md).
    """

    def __init__(self, model: IdentificationModel, limits: Limits, robot: Any = None, *, samples: int = 20_000,
                 seed: int = 0, kinetic: str | None = None):
        ca = load_casadi()
        n = limits.n
        q, dq, ddq = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n)
        F = casadi_regressor(model)
        zero = ca.SX.zeros(n)
        Yp = F(q, zero, dq) - F(q, zero, zero)
        f = [ca.vec(Yp)]  # column-major: joint fastest
        names = [f"d/dt(Yp[{j + 1}, {b}])" for b in model.BASE_NAMES for j in range(n)]
        if kinetic == "energy":
            f.append(0.5 * ca.mtimes(Yp.T, dq))
            names += [f"d/dt(T[{b}])" for b in model.BASE_NAMES]
        elif kinetic == "joint":
            f.append(ca.vec(ca.mtimes(ca.diag(dq), Yp)))
            names += [f"d/dt(dq{j + 1} Yp[{j + 1}, {b}])" for b in model.BASE_NAMES for j in range(n)]
        elif kinetic is not None:
            raise ValueError(f"kinetic must be None, 'energy' or 'joint', not {kinetic!r}")
        if robot is not None:
            kin, kin_names = _frame_kinematics(robot, model, n, q)
            f.append(ca.jtimes(kin, q, dq))
            names += [f"d/dt(d/dt {s})" for s in kin_names]
        fv = ca.vertcat(*f)
        rate = ca.jtimes(fv, q, dq) + ca.jtimes(fv, dq, ddq)
        X, _ = _random_states(np.random.default_rng(seed), limits, samples)
        V = np.array(ca.Function("rate", [q, dq, ddq], [rate]).map(len(X))(X[:, :n].T, X[:, n:2 * n].T,
                                                                            X[:, 2 * n:].T)).T
        size = np.abs(V).max(axis=0)
        keep = np.flatnonzero(size > 1e-9 * max(float(size.max()), 1e-300))
        self.n = n
        self.names = [names[k] for k in keep]
        self.scale = size[keep]
        self._f = ca.Function("rest_moments", [q, dq, ddq], [rate[[int(k) for k in keep]]])

    def numpy(self, q, dq, ddq) -> np.ndarray:
        q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
        return np.array(self._f.map(len(q))(q.T, dq.T, ddq.T)).T.reshape(len(q), len(self.names))

    def casadi(self, q, dq, ddq):
        return self._f(q, dq, ddq)


class FeatureMoments:
    """Random test functions that vanish at rest, for a cutting plane over test functions::

        f_k(q, dq) = dq_{j_k} cos(omega_k . q + nu_k . dq + phi_k),
        d/dt f_k   = ddq_{j_k} c_k - dq_{j_k} s_k (omega_k . dq + nu_k . ddq),

    ``c_k, s_k`` the cosine and sine of the phase. Every trajectory at rest at both ends has ``E[d/dt f_k] =
    0`` over its samples (to quadrature accuracy), as for :class:`RestMoments`; unlike those (the robot's own
    test functions, a few hundred) this is a dictionary as large as wanted, from which
    :func:`relaxation_bracket` (``features=K``) adds each round the ``K`` that its current best distribution
    violates most — the separation step of a cutting plane over the occupation-measure conditions
    ([LHPT08]: ``E[d/dt f] = 0`` for *every* smooth ``f`` vanishing at rest). Each feature involves 1 to 3
    joints' positions (frequencies ``2 pi g s / range``, ``g`` standard normal, ``s`` in ``scales``) and 0 to 2
    joints' velocities (``2 pi g s / (2 dq_max)``); seeded. ``scale`` is the analytic bound of ``|d/dt f_k|``
    over the limits' box, ``ddq_max_j + dq_max_j (|omega_k| . dq_max + |nu_k| . ddq_max)``, to which the
    relaxation's tolerance is relative.
    """

    def __init__(self, limits: Limits, count: int, *, seed: int = 0, scales: tuple[float, ...] = (0.5, 1.0, 2.0),
                 _arrays: tuple[np.ndarray, ...] | None = None):
        n = limits.n
        if _arrays is None:
            ids = np.arange(count)
            rng = np.random.default_rng(seed)
            span = np.where(np.isfinite(limits.q_max - limits.q_min), limits.q_max - limits.q_min, 2 * np.pi)
            joint = rng.integers(0, n, count)
            omega, nu = np.zeros((count, n)), np.zeros((count, n))
            for k in range(count):
                s = rng.choice(scales)
                for i in rng.choice(n, rng.integers(1, min(3, n) + 1), replace=False):
                    omega[k, i] = 2 * np.pi * s * rng.standard_normal() / span[i]
                for i in rng.choice(n, rng.integers(0, min(2, n) + 1), replace=False):
                    nu[k, i] = 2 * np.pi * s * rng.standard_normal() / (2 * limits.dq_max[i])
            phase = rng.uniform(0, 2 * np.pi, count)
        else:
            ids, joint, omega, nu, phase = _arrays
        self.n, self.ids, self.joint, self.omega, self.nu, self.phase = n, ids, joint, omega, nu, phase
        self.scale = limits.ddq_max[joint] + limits.dq_max[joint] * (
            np.abs(omega) @ limits.dq_max + np.abs(nu) @ limits.ddq_max)
        self.names = [f"d/dt(dq{j + 1} cos(feature {k}))" for k, j in zip(ids, joint)]
        self._limits = limits

    def __len__(self) -> int:
        return len(self.joint)

    def subset(self, index) -> FeatureMoments:
        """The features ``index`` (an index array), as a new set."""
        index = np.asarray(index, int)
        return FeatureMoments(self._limits, 0, _arrays=tuple(a[index] for a in self._all()))

    def _all(self) -> tuple[np.ndarray, ...]:
        return self.ids, self.joint, self.omega, self.nu, self.phase

    def numpy(self, q, dq, ddq) -> np.ndarray:
        """``(k, m)`` rates at the states ``q, dq, ddq`` (each ``(k, n)``)."""
        q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
        arg = q @ self.omega.T + dq @ self.nu.T + self.phase
        return ddq[:, self.joint] * np.cos(arg) - dq[:, self.joint] * np.sin(arg) * (dq @ self.omega.T + ddq @ self.nu.T)

    def weighted_sum(self, X: np.ndarray, p: np.ndarray, chunk: int = 1000) -> np.ndarray:
        """``p @ rates(X)`` for the states ``X`` (``(k, 3n)``) and weights ``p`` (``(k,)``), ``chunk`` features
        at a time (a large dictionary over many states would not fit in memory at once)."""
        n = self.n
        return np.concatenate([p @ self.subset(np.arange(k, min(k + chunk, len(self)))).numpy(
            X[:, :n], X[:, n:2 * n], X[:, 2 * n:]) for k in range(0, len(self), chunk)]) if len(self) else np.zeros(0)

    def casadi(self, q, dq, ddq):
        """``(m, 1)`` CasADi expression of the rates."""
        ca = load_casadi()
        if not len(self):
            return ca.SX.zeros(0, 1)
        Om, Nu = ca.DM(self.omega), ca.DM(self.nu)
        arg = ca.mtimes(Om, q) + ca.mtimes(Nu, dq) + ca.DM(self.phase)
        sel = [int(j) for j in self.joint]
        return ddq[sel] * ca.cos(arg) - dq[sel] * ca.sin(arg) * (ca.mtimes(Om, dq) + ca.mtimes(Nu, ddq))

    def __add__(self, other: FeatureMoments) -> FeatureMoments:
        return FeatureMoments(self._limits, 0, _arrays=tuple(np.concatenate([a, b]) for a, b in zip(
            self._all(), other._all())))


def feature_dictionary(limits: Limits, count: int, seed: int = 0) -> FeatureMoments:
    """The dictionary of random test functions :func:`relaxation_bracket` draws its cuts from for its ``seed``
    (``count`` = its ``dictionary``)."""
    return FeatureMoments(limits, count, seed=seed + 1)


def split_saved_atoms(states: np.ndarray, signs: np.ndarray, design_sizes: Sequence[int]
                      ) -> tuple[np.ndarray, np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """A saved distribution (:attr:`RelaxationBracket.states`, ``signs``, ``design_sizes``) as the arguments
    that continue it: ``(extra_states, extra_signs, extra_designs)`` of :func:`relaxation_bracket` - the plain
    states first, then one ``(states, signs)`` block per whole-trajectory atom."""
    plain = cut = len(states) - int(sum(design_sizes))
    designs = []
    for k in map(int, design_sizes):
        designs.append((states[cut:cut + k], signs[cut:cut + k]))
        cut += k
    return states[:plain], signs[:plain], designs


def _frame_kinematics(robot: Any, model: Any, n: int, q) -> tuple[Any, list[str]]:
    """The base-frame origin ``p_j`` and rotation ``R_j`` (row by row) of every frame of ``robot``
    (:func:`mdh_frames`; a closed-loop robot's through its ``model``'s linear closure) as a CasADi expression
    in the design's joint positions ``q`` (SX, ``n``), with their names."""
    lc = model.linear_closure() if hasattr(model, "linear_closure") else None
    qa, frames, sub = mdh_frames(robot, n, None if lc is None else lc.numeric())
    exprs, names = [], []
    for j, T in frames.items():
        exprs += [e.subs(sub) for e in list(T[:3, 3]) + list(T[:3, :3])]
        names += [f"p{j}.{c}" for c in "xyz"] + [f"R{j}[{a},{b}]" for a in range(1, 4) for b in range(1, 4)]
    return sympy_to_casadi(qa, exprs, q), names



class _MomentSet:
    """The moment conditions a relaxation holds: the closed-trajectory ones of :func:`stationarity_moments`
    (``degree``, or None), the rest-to-rest ones of a :class:`RestMoments` (or None) and the random ones of a
    :class:`FeatureMoments` (or None), concatenated."""

    def __init__(self, limits: Limits, degree: int | None, rest: RestMoments | None,
                 features: FeatureMoments | None = None):
        self.degree, self.rest, self.n = degree, rest, limits.n
        self.features = features if features is not None and len(features) else None
        parts = ([stationarity_scales(limits, degree)] if degree is not None else []) + (
            [rest.scale] if rest is not None else []) + ([self.features.scale] if self.features is not None else [])
        self.scale = np.concatenate(parts) if parts else np.zeros(0)
        self.names = (stationarity_moment_names(limits.n, degree) if degree is not None else []) + (
            list(rest.names) if rest is not None else []) + (
            list(self.features.names) if self.features is not None else [])

    def _parts(self, z, lib: Any, rest: np.ndarray | None = None) -> list:
        n = self.n
        q, dq, ddq = (z[:, :n], z[:, n:2 * n], z[:, 2 * n:]) if lib is np else (z[:n], z[n:2 * n], z[2 * n:])
        out = [stationarity_moments(q, dq, ddq, lib=lib, degree=self.degree)] if self.degree is not None else []
        for part in (self.rest, self.features):
            if part is not None:
                if part is self.rest and rest is not None:
                    out.append(rest)
                else:
                    out.append(part.numpy(q, dq, ddq) if lib is np else part.casadi(q, dq, ddq))
        return out

    def numpy(self, X: np.ndarray, rest: np.ndarray | None = None) -> np.ndarray:
        """``(k, m)`` for the states ``X`` (``(k, 3n)``); ``rest``: their rest moments, if already known."""
        parts = self._parts(X, np, rest)
        return np.hstack(parts) if parts else np.zeros((len(X), 0))

    def casadi(self, z):
        """``(m, 1)`` for the CasADi state vector ``z`` (``3n``)."""
        return load_casadi().vertcat(*self._parts(z, load_casadi()))


#: samples of one period of a trajectory atom (relaxation_bracket with features): the uniform mean of the
#: random test functions' rates over them is exact to aliasing beyond this harmonic
_DESIGN_SAMPLES = 1000


def _trajectory_states(limits: Limits, rng: np.random.Generator, k: int, samples: int = 50
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The samples of ``k`` random Fourier trajectories (5 harmonics, 10 s, ``samples`` per period)
    within the limits: states whose uniform distribution satisfies the stationarity moments."""
    basis = FourierBasis(5, 0.1)
    t = np.arange(samples) * (10.0 / samples)
    Xs = []
    for _ in range(k):
        q, dq, ddq = basis_eval(basis, random_trajectory(basis, limits, rng, t), t)
        Xs.append(np.hstack([q, dq, ddq]))
    X = np.vstack(Xs) if Xs else np.zeros((0, 3 * limits.n))
    return X, np.sign(X[:, limits.n:2 * limits.n])


def relaxation_bracket(model: IdentificationModel, limits: Limits, *, atoms: int = 400, rounds: int = 30,
                       fresh: int = 30_000, starts: int = 40, add: int = 60, prune: float = 1e-6,
                       tol: float = 0.02, time_budget: float = math.inf, seed: int = 0,
                       extra_states: np.ndarray | None = None, extra_signs: np.ndarray | None = None,
                       stationary: bool = False,
                       moment_tol: float = 0.01, degree: int = 2, trajectories: int = 0,
                       bandwidth: float | None = None, rest: bool = False, robot: Any = None,
                       kinetic: str | None = None, braking: bool = False, features: int = 0,
                       dictionary: int = 20_000, cut_every: int = 1, cut_at: tuple[int, ...] | None = None,
                       cuts: Sequence[int] = (), extra_designs: Sequence[tuple[np.ndarray, np.ndarray]] = (),
                       transit: int = 0, transit_dt: float = TRANSIT_DT, perturb: int = 0,
                       progress=None) -> RelaxationBracket:
    """Bracket the smallest cond over distributions of states within ``limits`` (see
    :class:`RelaxationBracket`) by column generation on the SDP (Boyd & Vandenberghe 2004, sect. 7.5;
    cond^2 is scale-free, so fix ``lambda_min >= 1``)::

        min kappa  s.t.  sum_i mu_i G_i >= I,  kappa I - sum_i mu_i G_i >= 0,  mu >= 0,
        G_i = W(s_i)^T W(s_i) / tr(W(s_i)^T W(s_i))

    and, with ``stationary``, ``|sum_i mu_i m(s_i) / (tr_i scale)| <= moment_tol sum_i mu_i / tr_i``
    (the stationarity moments of :func:`stationarity_moments`: every closed trajectory - periodic, or
    ending where it started - satisfies them, an arbitrary distribution of states does not), and with ``bandwidth``
    (``rho``) ``sum_i mu_i (rho dq_i dq_i^T - ddq_i ddq_i^T) / tr_i >= 0`` (every design of a basis of
    that :func:`basis_bandwidth` meets it). ``degree=3`` adds the test functions of degree 3 to the moments.
    With ``rest`` the moments of :class:`RestMoments` (the momentum regressor's and, with ``robot``, the frame
    velocities' rates) join them, held the same way: every trajectory that starts and ends at rest - every
    design of ``excite``, a spline that ends elsewhere included - satisfies them; ``rest`` alone bounds all of
    those, ``rest`` with ``stationary`` the closed ones; ``kinetic`` (``"energy"`` or ``"joint"``) adds test
    functions quadratic in ``dq`` to them (:class:`RestMoments`). With ``rest`` and ``features=K``, every
    ``cut_every`` rounds (or after each round listed in ``cut_at``) the ``K`` random test functions of a seeded
    dictionary of ``dictionary`` (:class:`FeatureMoments`) that the round's best distribution violates most
    (beyond ``moment_tol``) join the moments for the following rounds - a cutting plane over the conditions
    ``E[d/dt f] = 0`` that every trajectory at rest at both ends meets for every ``f`` vanishing at rest; the
    ``trajectories`` then join as whole-trajectory atoms (the mean over one period sampled 1000 times, as in
    :func:`mixture_cond`), which meet every cut and keep the SDP feasible; the upper end restarts with each
    batch of cuts (the relaxation got tighter), and every round's lower end still bounds every such
    trajectory. With ``braking`` every state keeps to
    :func:`braking_speed` (the random ones, the pricer's local searches and the given ones), as every design's
    samples do. With ``transit=L`` (levels) the distributions meet the :class:`TransitInequalities` of
    ``L`` speed levels per joint, with the sampling terms of ``transit_dt`` (see there for the designs covered): every burst of a joint to
    a speed costs it time at the speeds below. Solved by cvxpy + Clarabel on a finite set of states, whose duals ``A`` (of the first constraint),
    ``B`` (of the second, ``tr B = 1``) and the moment multipliers price new states
    (:class:`_DualPricer`): a state with ratio > 1 would lower the objective. Each round keeps the
    states of weight > ``prune`` x the largest (plus the new ones), and adds the ``add`` best of
    ``fresh`` random states and the local maxima of the ratio from the ``starts`` best random states
    and ``starts // 4`` random ones; with ``perturb=K`` also from the ``starts`` best of ``K`` random perturbations
    of every kept state at each scale of :data:`PERTURB_SCALES` (as :func:`relaxation_verify`). Stops when ``primal / dual - 1 <= tol``, after ``rounds`` rounds
    or past ``time_budget`` seconds. ``extra_states`` (``(k, 3n)``, e.g. a trajectory's samples or a saved
    distribution's states, with their Coulomb signs ``extra_signs``, default ``sign(dq)``) and the samples of
    ``trajectories`` random Fourier trajectories join the first round (with ``stationary`` or ``rest`` they
    make it feasible). ``cuts`` (ids in the dictionary, e.g. a saved run's :attr:`RelaxationBracket.upper_features`
    ``.ids``) are held from the first round on, and ``extra_designs`` (``(states, signs)`` of whole trajectories,
    e.g. a saved distribution's design blocks, :attr:`RelaxationBracket.design_sizes`) join as whole-trajectory
    atoms: with both, a saved run continues where it stopped.
    """
    import cvxpy as cp

    n = limits.n
    rng = np.random.default_rng(seed)
    coul = _coulomb_columns(model)
    X, S = _random_states(rng, limits, atoms, braking)
    if extra_states is not None:
        ex = np.asarray(extra_states, float)
        sg = np.sign(ex[:, n:2 * n]) if extra_signs is None else np.asarray(extra_signs, float)
        X, S = np.vstack([X, ex]), np.vstack([S, sg])
    if (features or len(cuts)) and not rest:
        raise ValueError("features= and cuts= need rest=True (the random test functions vanish at rest)")
    with_cuts = bool(features or len(cuts))
    # whole trajectories as atoms: the given ones, and with cuts the random ones below
    designs: list[tuple[np.ndarray, np.ndarray]] = [(np.asarray(x, float), np.asarray(s_, float))
                                                    for x, s_ in extra_designs]
    if trajectories:
        per = _DESIGN_SAMPLES if with_cuts else 50
        Xt, St = _trajectory_states(limits, rng, trajectories, samples=per)
        if with_cuts:
            designs = [(Xt[k * per:(k + 1) * per], St[k * per:(k + 1) * per]) for k in range(trajectories)]
        else:
            X, S = np.vstack([X, Xt]), np.vstack([S, St])
    if braking:  # the given and trajectory states too (a sampled trajectory may exceed it by its sampling error)
        X = _brake(limits, X)
        designs = [(_brake(limits, x), s) for x, s in designs]
    rest_m = RestMoments(model, limits, robot, kinetic=kinetic) if rest else None
    pool = feature_dictionary(limits, dictionary, seed) if with_cuts else None
    if len(cuts) and (min(cuts) < 0 or max(cuts) >= dictionary):
        raise ValueError(f"cuts= must be ids in the dictionary of {dictionary} test functions")
    held = pool.subset(sorted(set(int(k) for k in cuts))) if pool is not None else None
    moments = _MomentSet(limits, degree if stationary else None, rest_m, held) if stationary or rest else None
    jac = _DualPricer.casadi_jacobian(model, n, moments)
    trans = TransitInequalities(limits, transit, transit_dt) if transit else None
    # a design atom: the mean information matrix of a trajectory's samples (one full period) and its trace
    nb = len(model.BASE_NAMES)
    dG = np.zeros((len(designs), nb, nb))
    for d, (x, s) in enumerate(designs):
        Wd = relaxation_rows(model, x, s, coul)
        dG[d] = np.einsum("kia,kib->ab", Wd, Wd) / len(x)
    dtr = np.trace(dG, axis1=1, axis2=2)
    # the design atoms' transit means: fixed, computed once
    dtrans = np.array([trans.numpy(x).mean(0) for x, _ in designs]).reshape(len(designs), len(trans)) \
        if trans is not None else np.zeros((len(designs), 0))
    dpool = np.array([pool.weighted_sum(x, np.full(len(x), 1.0 / len(x))) for x, _ in designs]) \
        if pool is not None and designs else None

    t0 = time.perf_counter()
    hist: list[RelaxationRound] = []
    best_lower, best_upper = 0.0, math.inf
    best: dict[str, Any] = {}
    dual_of: dict[str, Any] = {}
    for rd in range(rounds + 1):
        W = relaxation_rows(model, X, S, coul)
        G = np.einsum("kia,kib->kab", W, W)
        tr = np.trace(G, axis1=1, axis2=2)
        ok = tr > 0
        X, S, W, G, tr = X[ok], S[ok], W[ok], G[ok], tr[ok]
        k_s = len(X)  # the states; the design atoms follow them
        Gn = np.concatenate([G / tr[:, None, None], dG / dtr[:, None, None]]) if designs else G / tr[:, None, None]
        tr_all = np.concatenate([tr, dtr])
        t_sdp = time.perf_counter()
        mu, kap, c1, c2 = _cond_sdp(Gn)
        cons = [c1, c2]
        if moments is not None:
            H = moments.numpy(X)
            if designs:
                H = np.vstack([H] + [moments.numpy(x).mean(0) for x, _ in designs])
            H = H / moments.scale / tr_all[:, None]
            mass = (1.0 / tr_all) @ mu
            cp_pos, cp_neg = H.T @ mu - moment_tol * mass <= 0, -H.T @ mu - moment_tol * mass <= 0
            cons += [cp_pos, cp_neg]
        if trans is not None:
            Tg = trans.numpy(X)
            if designs:
                Tg = np.vstack([Tg, dtrans])
            c_tr = (Tg / tr_all[:, None]).T @ mu <= 0
            cons.append(c_tr)
        if bandwidth is not None:
            dq_, ddq_ = X[:, n:2 * n], X[:, 2 * n:]
            K = (bandwidth * np.einsum("ki,kj->kij", dq_, dq_) - np.einsum("ki,kj->kij", ddq_, ddq_)) / tr[:, None, None]
            if designs:
                K = np.concatenate([K] + [(bandwidth * x[:, n:2 * n].T @ x[:, n:2 * n] - x[:, 2 * n:].T @ x[:, 2 * n:])[None]
                                          / len(x) / t_ for (x, _), t_ in zip(designs, dtr)])
            Kx = cp.reshape(K.reshape(len(K), -1).T @ mu, (n, n), order="C")
            c3 = (Kx + Kx.T) / 2 >> 0
            cons.append(c3)
        prob = cp.Problem(cp.Minimize(kap), cons)
        try:
            prob.solve(solver="CLARABEL")
        except cp.error.SolverError as e:
            raise ExcitationError(f"{model.ROBOT}: the relaxation SDP failed on round {rd} ({len(X)} states): {e}") \
                from None
        if mu.value is None:
            raise ExcitationError(f"{model.ROBOT}: the relaxation SDP failed on round {rd} ({len(X)} states): "
                                  f"{prob.status}" + (" (no distribution of these states meets the stationarity "
                                                      "moments: add trajectories=)" if moments is not None else ""))
        t_sdp = time.perf_counter() - t_sdp
        w_all = np.clip(np.asarray(mu.value), 0, None)
        w, w_d = w_all[:k_s], w_all[k_s:]
        ev = np.linalg.eigvalsh(np.einsum("k,kab->ab", w_all, Gn))
        primal = math.sqrt(ev[-1] / ev[0]) if ev[0] > 0 else math.inf
        A, B = _psd(np.asarray(c1.dual_value)), _psd(np.asarray(c2.dual_value))
        lam, c0 = None, 0.0
        if moments is not None:
            nu_p = np.clip(np.asarray(cp_pos.dual_value, float), 0, None)
            nu_n = np.clip(np.asarray(cp_neg.dual_value, float), 0, None)
            lam, c0 = nu_p - nu_n, moment_tol * float(np.sum(nu_p + nu_n))
        C = _psd(np.asarray(c3.dual_value)) if bandwidth is not None else None
        eta = np.clip(np.asarray(c_tr.dual_value, float), 0, None) if trans is not None else None
        pricer = _DualPricer(model, limits, A, B, lam, c0, rho=bandwidth, C=C, degree=degree, closed=stationary,
                             rest=rest_m, coulomb=coul, jac=jac, braking=braking, features=held, transit=trans, eta=eta)
        # pricing: the dual ratio over the current states, fresh random states and local maxima
        Xf, Sf = _random_states(rng, limits, fresh, braking)
        rf = pricer.ratio(Xf, Sf)
        r_atoms = float(pricer.ratio(X, S, W).max())
        order = np.argsort(-rf)
        picks = list(order[:starts]) + list(rng.choice(len(Xf), starts // 4, replace=False))
        loc = [pricer.local_max_with_signs(Xf[i], Sf[i]) for i in picks]
        r = max(r_atoms, float(rf.max()), max(v for *_, v in loc))
        keep = w > prune * w_all.max()
        if perturb:  # around the kept atoms, where the ratio is largest (complementary slackness)
            PX, PS, PR = _perturbed_states(pricer, X[keep], S[keep], rng, perturb)
            loc += [pricer.local_max_with_signs(PX[i], PS[i]) for i in np.argsort(-PR)[:starts]]
            r = max(r, float(PR.max()), max(v for *_, v in loc))
        dual = relaxation_dual_bound(A, B, r) if np.isfinite(r) and r > 0 else 0.0
        hist.append(RelaxationRound(rd, len(X), int(keep.sum()), primal, dual, r, time.perf_counter() - t0,
                                    t_sdp, 0 if held is None else len(held)))
        if progress is not None:
            progress(hist[-1])
        if dual > best_lower or not dual_of:
            best_lower = max(best_lower, dual)
            dual_of = {"A": A, "B": B, "r": r, "lam": lam, "c0": c0, "C": C, "features": held, "eta": eta}
        if primal < best_upper:
            best_upper = primal
            pos = w > 0
            used = [d for d in range(len(designs)) if w_d[d] > 0]  # a design atom: its samples, equal shares
            best = {"states": np.vstack([X[pos]] + [designs[d][0] for d in used]),
                    "signs": np.vstack([S[pos]] + [designs[d][1] for d in used]),
                    "weights": np.concatenate([w[pos] / tr[pos]] + [np.full(len(designs[d][0]), w_d[d] / dtr[d]
                                                                             / len(designs[d][0])) for d in used]),
                    "features": held, "design_sizes": tuple(len(designs[d][0]) for d in used)}
        if best_upper <= best_lower * (1 + tol) or hist[-1].seconds > time_budget or rd == rounds:
            break
        if pool is not None and features and held is not None and (rd in cut_at if cut_at is not None else (rd + 1) % cut_every == 0):
            # separation: the features the best distribution violates most
            p, p_d = w / tr, (w_d / dtr if designs else np.zeros(0))
            v = pool.weighted_sum(X, p) + (p_d @ dpool if dpool is not None else 0.0)
            viol = np.abs(v / pool.scale) / (p.sum() + p_d.sum())
            viol[held.ids] = 0.0
            new = [int(k) for k in np.argsort(-viol)[:features] if viol[k] > moment_tol]
            if new:
                held = held + pool.subset(new)
                moments = _MomentSet(limits, degree if stationary else None, rest_m, held)
                jac = _DualPricer.casadi_jacobian(model, n, moments)
                best_upper = math.inf  # a tighter relaxation: its upper end starts again
        good = [(x, s_) for x, s_, v in loc if v > 1.0]
        newX = [X[keep], Xf[order[:add]]] + ([np.array([x for x, _ in good])] if good else [])
        newS = [S[keep], Sf[order[:add]]] + ([np.array([s for _, s in good])] if good else [])
        X, S = np.vstack(newX), np.vstack(newS)
    return RelaxationBracket(best_lower, best_upper, tuple(hist), best["states"], best["signs"], best["weights"],
                             dual_of["A"], dual_of["B"], dual_of["r"], moment_tol if moments is not None else 0.0,
                             dual_of["lam"], dual_of["c0"], bandwidth, dual_of["C"], degree, stationary, rest_m,
                             braking, dual_of["features"], best["features"], best["design_sizes"], trans, dual_of["eta"])


def relaxation_verify(model: IdentificationModel, limits: Limits, bracket: RelaxationBracket, *,
                      states: int = 300_000, starts: int = 200, seed: int = 1, batch: int = 20_000,
                      perturb: int = 0) -> tuple[float, float]:
    """Re-price the duals that gave ``bracket.lower`` on a search the bracket never ran: ``states``
    fresh random states (another seed) and L-BFGS-B from the ``starts`` best of them. Returns
    ``(r, bound)``: the largest ratio found (at least ``bracket.r``) and ``sqrt(tr A / (r tr B))``.
    A ``bound`` well below ``bracket.lower`` says the bracket's search for ``r`` was not global.

    ``perturb=K`` adds a search of another kind, with its own ``starts`` local searches: ``K`` random
    perturbations of every atom of the bracket's distribution (weight above ``1e-6`` of the largest) at each
    scale of :data:`PERTURB_SCALES` (fractions of the box), each coordinate moved with a probability drawn per
    sample (velocity signs follow the speeds; a joint left at rest keeps its sign). Where the distribution is
    optimal for the duals, the dual ratio is at its largest at its atoms (complementary slackness), so the
    larger values that the pricing missed are likely near them. ``states=0`` runs it alone.
    (Differential evolution over the box, tried as a third kind, converged into one basin below the pricing's
    own ratio on the LWR4 and the SCARA: not kept.)
    """
    pricer = _DualPricer(model, limits, bracket.A, bracket.B, bracket.lam, bracket.c0, rho=bracket.bandwidth,
                         C=bracket.C, degree=bracket.degree, closed=bracket.closed, rest=bracket.rest,
                         braking=bracket.braking, features=bracket.features, transit=bracket.transit, eta=bracket.eta)
    rng = np.random.default_rng(seed)
    best_r = bracket.r
    pools: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    if states:
        pool_X, pool_S, pool_r = [], [], []
        for k0 in range(0, states, batch):
            Xf, Sf = _random_states(rng, limits, min(batch, states - k0), bracket.braking)
            rf = pricer.ratio(Xf, Sf)
            top = np.argsort(-rf)[:starts]
            pool_X.append(Xf[top])
            pool_S.append(Sf[top])
            pool_r.append(rf[top])
        pools.append((np.vstack(pool_X), np.vstack(pool_S), np.concatenate(pool_r)))
    if perturb:
        keep = bracket.weights > 1e-6 * bracket.weights.max()
        pools.append(_perturbed_states(pricer, bracket.states[keep], bracket.signs[keep], rng, perturb))
    for PX, PS, PR in pools:
        best_r = max(best_r, float(PR.max()))
        for i in np.argsort(-PR)[:starts]:
            best_r = max(best_r, pricer.local_max(PX[i], PS[i])[1])
    bound = relaxation_dual_bound(bracket.A, bracket.B, best_r) if np.isfinite(best_r) else 0.0
    return best_r, bound


#: the perturbations of :func:`relaxation_verify` ``perturb=``, as fractions of the box's widths
PERTURB_SCALES = (0.01, 0.03, 0.1, 0.3)


def _perturbed_states(pricer: _DualPricer, X0: np.ndarray, S0: np.ndarray, rng: np.random.Generator, k: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The best of ``k`` random perturbations of every state of ``X0`` (signs ``S0``) at every scale of
    :data:`PERTURB_SCALES`: ``(states, signs, ratios)``, one row per state and scale."""
    n = pricer.n
    lo, hi = pricer.lo, pricer.hi
    out_X, out_S, out_r = [], [], []
    for scale in PERTURB_SCALES:
        for x0, s0 in zip(X0, S0):
            move = rng.random((k, 3 * n)) < rng.uniform(0.0, 1.0, (k, 1))
            X = np.clip(x0 + move * rng.normal(0.0, scale, (k, 3 * n)) * (hi - lo), lo, hi)
            if pricer.braking:
                X = _brake(pricer.limits, X)
            dq = X[:, n:2 * n]
            S = np.where(dq != 0, np.sign(dq), s0)
            r = pricer.ratio(X, S)
            i = int(np.argmax(r))
            out_X.append(X[i])
            out_S.append(S[i])
            out_r.append(r[i])
    return np.array(out_X), np.array(out_S), np.array(out_r)
