"""The criterion of an excitation design and how low it can go: the true cond of the stacked base regressor
(:func:`stacked_cond`), its smooth power-mean bound that IPOPT minimises (:func:`smooth_criterion`, on the
information matrix :func:`design_information` of the generated CasADi regressor :func:`casadi_regressor`), the
rigorous lower bound over every trajectory within the velocity limits (:func:`cond_lower_bound`,
:func:`friction_ceiling`), and the predicted precision of the base parameters (:func:`predicted_sigma`)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError
from ..model import IdentificationModel
from .limits import ExcitationError, Limits, load_casadi

__all__ = [
    "COND_DEGENERATE",
    "COND_POWER",
    "COND_POWERS",
    "CondBound",
    "casadi_regressor",
    "cond_lower_bound",
    "design_information",
    "friction_ceiling",
    "predicted_sigma",
    "smooth_criterion",
    "stacked_cond",
]

#: cond of the base regressor above which a design is degenerate: beyond ~1e10 the smallest singular value is
#: within a relative 1e-10 of the largest, where the rounding of the regressor's evaluation (~1e-16 x its
#: magnitude, times the growth of the Newton-Euler recursion) decides it: the rank is numerically lost (Golub &
#: Van Loan, Matrix Computations, 4th ed., sec. 5.4.1 on numerical rank). Good designs are below 1e3.
COND_DEGENERATE = 1e10
#: power p of the smooth cond criterion (a power of 2): exp(criterion) is within nb^(2/p) of cond^2
COND_POWER = 8
#: continuation of the cond criterion: IPOPT runs with each power in turn, each stage warm-started
#: from the previous one (a small p is smooth and well scaled far from the optimum, a large p is
#: within nb^(2/p) of cond^2 near it: 64^(1/64) = 1.07 for p = 64)
COND_POWERS = (8, 64)


def stacked_cond(model: IdentificationModel, q, dq, ddq) -> float:
    """Unscaled 2-norm condition number of the base regressor stacked over the samples."""
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
    s = np.linalg.svd(W, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else math.inf


def friction_ceiling(v_max: float) -> float:
    """Largest ``lambda_min`` of ``E[z z^T]``, ``z = (dq, sign dq, 1)``, over every distribution of a
    joint velocity on ``[-v_max, v_max]`` (time samples of any trajectory within the limit).

    By symmetry (``dq -> -dq`` leaves ``lambda_min`` unchanged) and concavity of ``lambda_min`` in the
    moment matrix, a symmetric distribution is optimal, so the moment matrix is
    ``[[a, b], [b, c]] (+) [1]`` with ``b = E|dq|``, ``a = E dq^2 <= v_max b``, ``c = P(dq != 0) <= 1``;
    ``lambda_min`` grows with ``a`` and ``c``: a one-dimensional maximisation over ``b``.
    """
    from scipy.optimize import minimize_scalar

    def neg(b: float) -> float:
        return -min(1.0, float(np.linalg.eigvalsh(np.array([[v_max * b, b], [b, 1.0]]))[0]))

    return -float(minimize_scalar(neg, bounds=(0.0, v_max), method="bounded").fun)


@dataclass(frozen=True)
class CondBound:
    """A lower bound on the condition number of the stacked base regressor over EVERY trajectory
    within the velocity limits (any duration, any number of samples N).

    ``cond(W) = sigma_max / sigma_min`` with
    ``sigma_max^2 >= N smax2`` (a column set whose squared norm per sample is a constant ``k s``:
    ``lambda_max`` of its Gram matrix ``>= N s``) and ``sigma_min^2 <= N smin2`` (the friction columns
    ``dq_j, sign dq_j, 1`` of joint ``j``, restricting the minimising vector to them:
    :func:`friction_ceiling` of ``dq_max_j``). Attributes: ``bound = sqrt(smax2 / smin2)``, and which
    columns give each.
    """

    bound: float
    smax2: float
    smax_columns: tuple[str, ...]
    smin2: float
    smin_joint: int

    def describe(self) -> str:
        return (f"cond >= {self.bound:.4g} for any trajectory within the velocity limits: sigma_max^2/N >= "
                f"{self.smax2:.4g} ({' + '.join(self.smax_columns)}: constant squared norm per sample), "
                f"sigma_min^2/N <= {self.smin2:.4g} (FV{self.smin_joint}, FS{self.smin_joint}, "
                f"OFF{self.smin_joint} at the velocity limit of joint {self.smin_joint})")


def cond_lower_bound(model: IdentificationModel, limits: Limits, *, checks: int = 64, seed: int = 0) -> CondBound | None:
    """:class:`CondBound` of a model under ``limits`` (None when the model has no friction columns).

    The structure the bound rests on is checked on ``checks`` random states (positions across the
    whole circle, velocities and accelerations of both signs): the friction columns of joint ``j``
    are ``dq_j, sign(dq_j), 1`` in row ``j`` only; for ``sigma_max``, single columns and pairs of
    columns that depend on ``q`` only and whose squared norm per sample is the same at every state (the
    offsets: 1; the first moments of a link whose frame origin stays on the fixed base axes: ``g^2``
    for the pair, their torque being ``g (c, s)`` of one angle) are used.
    """
    names = list(model.BASE_NAMES)
    n, nb = int(model.N_JOINTS), len(names)
    rng = np.random.default_rng(seed)
    q = rng.uniform(-math.pi, math.pi, (checks, n))
    dq = rng.uniform(-3, 3, (checks, n))
    ddq = rng.uniform(-10, 10, (checks, n))
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(checks, n, nb)
    W2 = np.asarray(model.regressor(q, 2 * dq + 1, -ddq + 3)).reshape(checks, n, nb)
    tol = 1e-9 * max(1.0, float(np.abs(W).max()))
    smin2, smin_joint = math.inf, 0
    for j in range(n):
        cols = [f"{k}{j + 1}" for k in ("FV", "FS", "OFF")]
        if not all(c in names for c in cols):
            continue
        want = np.zeros((3, checks, n))
        want[0, :, j], want[1, :, j], want[2, :, j] = dq[:, j], np.sign(dq[:, j]), 1.0
        got = np.stack([W[:, :, names.index(c)] for c in cols])
        if np.abs(got - want).max() > tol:
            continue
        c2 = friction_ceiling(float(limits.dq_max[j]))
        if c2 < smin2:
            smin2, smin_joint = c2, j + 1
    if not math.isfinite(smin2):
        return None
    q_only = [i for i in range(nb) if np.abs(W[:, :, i] - W2[:, :, i]).max() <= tol]
    per = {i: (W[:, :, i] ** 2).sum(1) for i in q_only}  # squared norm per sample
    best: tuple[float, tuple[str, ...]] = (0.0, ())
    for a_i, a in enumerate(q_only):
        if np.ptp(per[a]) <= 1e-9 * max(per[a].max(), 1.0) and per[a][0] > best[0]:
            best = (float(per[a][0]), (names[a],))
        for b in q_only[a_i + 1:]:
            tot = per[a] + per[b]
            if np.ptp(tot) <= 1e-9 * max(tot.max(), 1.0) and tot[0] / 2 > best[0]:
                best = (float(tot[0] / 2), (names[a], names[b]))
    if best[0] <= 0:
        return None
    return CondBound(math.sqrt(best[0] / smin2), best[0], best[1], smin2, smin_joint)


def predicted_sigma(model: IdentificationModel, q, dq, ddq, noise: float, chi_b=None) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicted standard deviations of the base parameters for i.i.d. torque noise ``noise``.

    ``cov = noise^2 (W^T W)^-1`` (Gautier 1997, eq. 9, with the noise variance given instead of
    estimated from the residual). Returns ``sigma`` (nb,) and, when ``chi_b`` is given, the relative
    ``%sigma = 100 sigma / |chi_b|`` (NaN where ``chi_b`` is 0, or round-off of the regrouping: below
    1e-9 of the largest ``|chi_b|``, as a URDF's nominal inertias leave - a %sigma of 1e11 says nothing).
    """
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
    cov = noise ** 2 * np.linalg.pinv(W.T @ W)
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if chi_b is None:
        return sig, None
    cb = np.abs(np.asarray(chi_b, float))
    cb = np.where(cb > 1e-9 * cb.max(initial=0.0), cb, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = np.where(cb > 0, 100.0 * sig / np.where(cb > 0, cb, 1.0), np.nan)
    return sig, pct


def casadi_regressor(model: IdentificationModel):
    """The model's CasADi regressor ``(q, dq, ddq) -> Y``, or an :class:`ExcitationError` that says why there is none
    (a closed-loop robot has one when its closure is linear: parallelograms, coupled joints)."""
    if not hasattr(model, "casadi_regressor"):
        raise ExcitationError(f"{model.ROBOT}: the model has no casadi_regressor() (use a generated package: "
                              "symoro_gen.load_model)")
    try:
        return model.casadi_regressor()
    except ModelError as e:
        raise ExcitationError(f"{e}: excite cannot optimise a trajectory for it (identify and diagnose do work "
                              "on it)") from None


def design_information(model: IdentificationModel, basis, x, t: np.ndarray):
    """``W^T W / (n N)`` of the base regressor stacked over the samples ``t`` of the design ``x`` (a CasADi
    column of the design variables, ``X`` column-major: column j = joint j), as a CasADi expression from the
    generated model: the information matrix every criterion of :func:`optimise_excitation` is a function of
    (and the dual ratio that ``bench/bench_excite_mixture.py --price`` maximises)."""
    ca = load_casadi()
    n = int(x.numel()) // int(basis.m)
    qs, dqs, ddqs = ca.MX.sym("q", n), ca.MX.sym("dq", n), ca.MX.sym("ddq", n)
    G = ca.Function("Yt", [qs, dqs, ddqs], [casadi_regressor(model)(qs, dqs, ddqs).T])
    X = ca.reshape(x, basis.m, n)
    P, D, A = (ca.DM(M) for M in basis.matrices(t))
    Z = G.map(len(t))((P @ X).T, (D @ X).T, (A @ X).T)  # (nb, n N): [Y_1^T, Y_2^T, ...]
    return (Z @ Z.T) / (n * len(t))




def smooth_criterion(M, criterion: str, power: int = COND_POWER):
    """The criterion IPOPT minimises, a CasADi expression of the information matrix ``M``.

    ``"cond"``: ``(log tr(Mn^p) + log tr(Mn^-p)) / p`` of ``Mn = M / tr M``, within ``nb^(2/p)`` of ``cond^2``
    (``lambda_max <= tr(M^p)^(1/p) <= nb^(1/p) lambda_max``, alike for ``M^-1``: smooth, tight for large ``p``, a
    power of 2); ``"logdet"``: ``-log det M`` (D-optimality)."""
    ca = load_casadi()
    if criterion == "logdet":
        return -ca.log(ca.det(M))
    if criterion != "cond":
        raise ExcitationError(f"--criterion {criterion!r}: expected cond or logdet")
    if power < 2 or power & (power - 1):
        raise ExcitationError(f"cond criterion power {power}: must be a power of 2")

    def log_tr_power(A):
        # each squaring is renormalised by its trace (log tr(A^2p) = 2 log tr(A^p) + log tr(B^2),
        # B = A^p / tr(A^p)), so that large p neither overflows nor underflows
        lt = ca.log(ca.trace(A))
        B = A / ca.trace(A)
        for _ in range(int(math.log2(power))):
            B2 = B @ B
            t2 = ca.trace(B2)
            lt = 2 * lt + ca.log(t2)
            B = B2 / t2
        return lt

    Mn = M / ca.trace(M)
    return (log_tr_power(Mn) + log_tr_power(ca.inv(Mn))) / power
