"""Close the loop on measured data: residual -> candidate effect -> augmented re-identification.

:func:`diagnose` identifies the declared model (the chosen method, OLS/WLS/TLS), then repeats:

1. weight the rows of joint j by ``1/sigma_j`` (the current residual's standard deviation per joint),
   add *nuisance* columns that absorb what velocity noise does to the Coulomb column at reversals
   (:func:`.candidates.nuisance_columns`), and project every candidate's columns out of the span of
   the current model's columns (a column mostly inside it is "already in the model" and skipped);
2. for each candidate family (:mod:`.candidates`) compute on the *identification* data a Wald test of
   the added coefficients with a heteroscedasticity- and autocorrelation-consistent covariance
   (Newey-West, residuals scaled by ``1/(1 - h_ii)``), keeping the larger of its p-value and of the
   white-noise F test's, with a Bonferroni factor for the family's 1-D search grid; and on the
   *validation* data the decrease of the squared error when the model re-identified with the columns
   predicts it: a score (sum over joints of the fractional decrease of the squared error norm) and a z
   statistic against the null distribution of that decrease when the columns are useless (mean
   ``-m``, ``m`` the expected squared prediction change from the estimation noise; standard deviation
   from the HAC variance of the validation residual along that change);
3. a candidate is *eligible* when its p-value < ``significance / n_candidates`` (Bonferroni over the
   round), ``z > Phi^-1(1 - significance / n_candidates)``, it lowers the validation error norm of its
   joint (of any joint for ``elasticity``) by at least ``min_rel_improvement``, its columns spread over
   enough rows to give evidence at all, and it beats every *placebo* of its joint(s) on both
   statistics (random smooth functions of time, and random combinations of every joint's position,
   velocity and acceleration, drawn with ``rng``: a calibration of the null that does not rest on a
   noise model and that also catches coincidental fits of deterministic artefacts repeated in the
   validation data);
4. the eligible candidate with the best validation score is added (its searched parameter refined
   continuously between grid points), the model re-identified with the chosen method, the model
   torque and the columns linearised around the fit rebuilt (fixed point), and the loop goes on
   until nothing is eligible or ``max_effects``.

Everything the loop computed is in the :class:`~.report.ResidualReport`.

Known limits
------------
* Candidates are scored with per-joint weighted least squares whatever ``method``; the reported
  identifications (errors before/after, effect parameters and %sigma) use ``method``.
* ``gain``: only the gain of one joint relative to the others is identifiable (through the dynamic
  coupling); a common scale of all joints needs a known payload. On robots whose joints are weakly
  coupled (a SCARA) a gain error of one joint looks like that of another.
* ``elasticity`` of a joint carrying most of the gravity torque (LWR4 joint 2) is partly absorbed by
  the gravity parameters; stiffness estimates are biased low there. The Coulomb term of the deflection
  is left out of the column (it gave false positives on noisy data), so large Coulomb friction against
  a soft joint is picked up as ``time_delay`` or ``load_friction`` instead.
* ``position_ripple`` is in the joint angle only, orders 2-32 within the decimated band; a ripple at
  the motor angle (gear ratio times faster) is filtered out by the decimation.
* Hold-out validation on a repeated (periodic) excitation validates deterministic processing
  artefacts as well as physical effects; the motion placebos guard against the coincidental ones.
  Separate validation recordings are better.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats as sst
from scipy.optimize import minimize_scalar

from ..errors import IdentificationError
from ..identification.method import identify
from ..identification.result import IdentificationResult
from ..model import IdentificationModel
from ..observations.system import ObservationSystem
from ..preprocessing.trajectory import Trajectory
from ..progress import progress_bar
from .candidates import (
    _UNSHIFTED,
    ALL,
    REVEAL,
    Family,
    FitContext,
    describe_params,
    make_families,
    nuisance_columns,
    placebo_families,
)
from .frame import Frame, attach_model_torque, build_frame, common_bandwidth, model_torque, split_holdout
from .report import CandidateScore, Effect, ResidualReport
from .stats import bonferroni, hac_covariance, hac_lag, segments_of, wald_test
from .structure import residual_structure

__all__ = ["diagnose", "DiagnoseSettings", "SIGNIFICANCE", "MAX_EFFECTS", "HOLDOUT", "MIN_REL_IMPROVEMENT", "IDENTIFIABILITY_TOL"]

#: family-wise level of each round (Bonferroni over the candidates)
SIGNIFICANCE = 0.01
#: at most this many effects are added
MAX_EFFECTS = 5
#: share of each experiment held out (its end) when no validation data are given
HOLDOUT = 0.3
#: a candidate must lower the validation error norm of (one of) its joint(s) by this fraction
MIN_REL_IMPROVEMENT = 0.02
#: a column with less than this share of its norm outside the model's span is "already in the model"
IDENTIFIABILITY_TOL = 1e-3
#: placebo candidates per joint and round
N_PLACEBO = 3
#: fixed-point passes re-linearising effects that depend on the fit (model torque, elasticity, gain)
RELINEARISE_PASSES = 2
#: a candidate column must spread over at least this many rows (participation ratio (sum x^2)^2 / sum x^4 of
#: its part outside the model's span), and this share of the rows of one joint
MIN_SUPPORT_ROWS = 20
MIN_SUPPORT_SHARE = 0.05
#: floor of 1 - h_ii in the HC3 scaling of the residuals
MIN_ONE_MINUS_LEVERAGE = 0.05
#: structure tests explaining at least this share of a joint's residual are listed in the warnings
STRUCTURE_WARN_ETA2 = 0.2
#: tolerance on log(value) of the continuous refinement of a searched parameter
REFINE_XATOL = 0.02


# ------------------------------------------------------------------------------------------------
def _align(system: ObservationSystem, names: Sequence[str]) -> ObservationSystem:
    """``system`` with columns ``names`` (missing ones zero, e.g. payload columns of unloaded data)."""
    col = {n: i for i, n in enumerate(system.names)}
    extra = [n for n in system.names if n not in set(names)]
    if extra:
        raise IdentificationError(f"validation data have columns {extra} the identification data lack")
    W = np.zeros((system.Y.size, len(names)))
    for i, n in enumerate(names):
        if n in col:
            W[:, i] = system.W[:, col[n]]
    return ObservationSystem(W, system.Y, tuple(names), system.joint)


def _joint_sigma(resid: np.ndarray, joint: np.ndarray, n: int, k: int, floor_rel: float = 1e-9) -> np.ndarray:
    r = resid.size
    rss = np.bincount(joint, weights=resid ** 2, minlength=n)
    cnt = np.bincount(joint, minlength=n).astype(float)
    dof = np.maximum(cnt - k * cnt / max(r, 1), 1.0)
    s = np.sqrt(rss / dof)
    top = s.max() if s.size else 1.0
    return np.maximum(s, floor_rel * max(top, 1e-300))


@dataclass(frozen=True, eq=False)
class _Design:
    """Current augmented model and its weighted projection (one round)."""

    names: tuple
    A: np.ndarray       # (r, k) identification columns (declared + added)
    Av: np.ndarray      # (rv, k)
    w: np.ndarray       # (r,) row weights 1/sigma_j
    wv: np.ndarray      # (rv,)
    U: np.ndarray       # (r, rank) orthonormal basis of A*w
    pinv: np.ndarray    # (k, r) pseudo-inverse of A*w
    theta: np.ndarray   # (k,) weighted LS estimate
    e_w: np.ndarray     # (r,) weighted residual
    e_v: np.ndarray     # (rv,) unweighted validation residual
    rank: int


def _design(names, A, Y, joint, Av, Yv, jv, n, rank_tol=1e-10, w_resid=None) -> _Design:
    k = A.shape[1]
    resid0 = w_resid if w_resid is not None else Y - A @ np.linalg.lstsq(A, Y, rcond=None)[0]
    sig = _joint_sigma(resid0, joint, n, k)
    w = 1.0 / sig[joint]
    Aw = A * w[:, None]
    R = np.linalg.qr(Aw, mode="r")           # Aw = Q R; R = Ur S Vt  =>  Aw Vt' S^-1 = Q Ur (orthonormal)
    _, s, Vt = np.linalg.svd(R)
    rank = int(np.sum(s > rank_tol * s[0]))
    s, Vt = s[:rank], Vt[:rank]
    U = Aw @ (Vt.T / s)
    pinv = (Vt.T / s) @ U.T
    theta = pinv @ (Y * w)
    e_w = Y * w - Aw @ theta
    e_v = Yv - Av @ theta
    sv = _joint_sigma(e_v, jv, n, 0)
    wv = 1.0 / sv[jv]
    return _Design(tuple(names), A, Av, w, wv, U, pinv, theta, e_w, e_v, rank)


@dataclass
class _Eval:
    member: int
    score: float
    p_value: float
    z: float
    ident: float
    rel_before: np.ndarray
    rel_after: np.ndarray
    reason: str = ""


def _rel_err(e, y, joint, n):
    a = np.bincount(joint, weights=e ** 2, minlength=n)
    b = np.bincount(joint, weights=y ** 2, minlength=n)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sqrt(a / b)


class _Scorer:
    """Evaluates candidate columns against the current design.

    Identification: Wald test of the added coefficients with a HAC (Newey-West) covariance, residuals
    scaled by ``1/(1 - h_ii)`` (HC3, robust to columns concentrated on a few high-leverage rows); the
    p-value is the larger of that test and of the white-noise one.
    Validation: decrease ``dec`` of the weighted squared error; under "useless columns" its mean is
    ``-m`` (``m = E||prediction change||^2`` from the estimation noise of the coefficients) and its
    variance ``4 tr(S_v C_b)`` (HAC of the validation residual along the prediction change), so
    ``z = (dec + m) / (2 sqrt(tr(S_v C_b)))``."""

    def __init__(self, D: _Design, F: Frame, V: Frame, n: int, ident_tol: float, min_support: float):
        self.D, self.F, self.V, self.n = D, F, V, n
        self.min_support = min_support
        self.ident_tol = ident_tol
        self.r = F.n_rows
        self.gid = segments_of(F.system.joint * 100000 + F.row_experiment, F.n_rows)
        self.gv = segments_of(V.system.joint * 100000 + V.row_experiment, V.n_rows)
        self.yv = V.system.Y
        self.rv0 = np.bincount(V.system.joint, weights=D.e_v ** 2, minlength=n)
        self.lag = max(hac_lag(D.e_w[F.system.joint == j], F.row_experiment[F.system.joint == j])
                       for j in range(n))
        evw = D.e_v * D.wv
        self.lag_v = max(hac_lag(evw[V.system.joint == j], V.row_experiment[V.system.joint == j])
                         for j in range(n))
        self.rel_before = _rel_err(D.e_v, self.yv, V.system.joint, n)
        self.lev0 = np.einsum("ij,ij->i", D.U, D.U)
        self.Avw = D.Av * D.wv[:, None]

    def rss(self, X: np.ndarray) -> float:
        """Weighted identification residual sum of squares with the columns X added."""
        Xw = X * self.D.w[:, None]
        Xp = Xw - self.D.U @ (self.D.U.T @ Xw)
        b = np.linalg.lstsq(Xp, self.D.e_w, rcond=None)[0]
        e = self.D.e_w - Xp @ b
        return float(e @ e)

    def evaluate(self, X: np.ndarray, Xv: np.ndarray) -> _Eval | str:
        D = self.D
        p = X.shape[1]
        Xw = X * D.w[:, None]
        norms = np.sqrt(np.einsum("ij,ij->j", Xw, Xw))
        if not np.all(norms > 0):
            return "not excited (zero column)"
        Xs = Xw / norms
        C = D.U.T @ Xs
        Xp = Xs - D.U @ C
        ratio = np.sqrt(np.einsum("ij,ij->j", Xp, Xp))
        ident = float(ratio.min())
        if ident < self.ident_tol:
            return f"already in the model (identifiability {ident:.1e})"
        x2 = Xp * Xp
        support = float(np.min(np.sum(x2, axis=0) ** 2 / np.maximum(np.sum(x2 * x2, axis=0), 1e-300)))
        if support < self.min_support:
            return (f"concentrated on too few rows (effective support {support:.0f} < {self.min_support:.0f}): "
                    "no statistical evidence possible")
        G = Xp.T @ Xp
        try:
            Ginv = np.linalg.inv(G)
        except np.linalg.LinAlgError:
            return "its columns are collinear"
        b = Ginv @ (Xp.T @ D.e_w)
        e1 = D.e_w - Xp @ b
        # residuals scaled by 1/(1 - leverage) (HC3): a column concentrated on a few rows would otherwise
        # fit them away and shrink its own variance
        lev = np.einsum("ij,jk,ik->i", Xp, Ginv, Xp) + self.lev0
        e3 = e1 / np.clip(1.0 - lev, MIN_ONE_MINUS_LEVERAGE, 1.0)
        S = hac_covariance(Xp * e3[:, None], max_lag=self.lag, segments=self.gid)
        dof = max(self.r - D.rank - p, 1)
        # HAC covariance, but never smaller than the white-noise one (sigma^2 G^-1): in few effective
        # samples the HAC estimate can be nearly singular and make any direction look significant
        Cb = Ginv @ S @ Ginv * (self.r / dof)
        Ci = Ginv * float(e1 @ e1) / dof
        _, p_hac = wald_test(b, Cb, dof)
        _, p_iid = wald_test(b, Ci, dof)
        pval = max(p_hac, p_iid)
        Cb = Cb if np.trace(Cb @ np.linalg.pinv(Ci)) >= p else Ci
        beta = b / norms                      # coefficients of X
        dtheta = -D.pinv @ (Xw @ beta)        # change of the current model's coefficients
        dv = D.Av @ dtheta + Xv @ beta
        ev1 = D.e_v - dv
        rv1 = np.bincount(self.V.system.joint, weights=ev1 ** 2, minlength=self.n)
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(self.rv0 > 0, (self.rv0 - rv1) / self.rv0, 0.0)
        score = float(np.sum(frac))
        wv = D.wv
        dec = float(np.sum((D.e_v ** 2 - ev1 ** 2) * wv ** 2))
        # prediction change on validation (weighted) per unit of the scaled coefficients b
        Mv = (Xv * wv[:, None]) / norms - self.Avw @ (D.pinv @ Xs)
        m = float(np.einsum("ij,jk,ik->", Mv, Cb, Mv))
        Sv = hac_covariance(Mv * (ev1 * wv)[:, None], max_lag=self.lag_v, segments=self.gv)
        var = max(float(np.sum(Sv * Cb)), float(np.mean((ev1 * wv) ** 2)) * m)
        z = (dec + m) / (2.0 * math.sqrt(max(var, 1e-300)))
        after = _rel_err(ev1, self.yv, self.V.system.joint, self.n)
        return _Eval(0, score, pval, float(z), ident, self.rel_before, after)


# ------------------------------------------------------------------------------------------------
def _affected(fam: Family, n: int) -> list[int]:
    if fam.joint is None:
        return list(range(n))
    if fam.kind == "elasticity":
        return list(range(n))
    out = [fam.joint]
    if fam.partner is not None and fam.variant == "shared":
        out.append(fam.partner)
    return out


def _own(fam: Family, n: int) -> list[int]:
    """Joints whose validation error must improve (the effect's own joints; elasticity of one joint
    changes the torque of all)."""
    if fam.joint is None or fam.kind == "elasticity":
        return list(range(n))
    out = [fam.joint]
    if fam.partner is not None and fam.variant == "shared":
        out.append(fam.partner)
    return out


@dataclass(frozen=True, eq=False)
class _Added:
    family: Family
    value: float | None    # searched parameter (None: no search)
    X: np.ndarray
    Xv: np.ndarray


def _build_one(fam: Family, frame: Frame, ctx: FitContext, value) -> np.ndarray:
    if fam.build_at is not None and value is not None:
        return fam.build_at(frame, ctx, value)
    if fam.grid:
        return fam.build(frame, ctx)[fam.grid.index(value)]
    return fam.build(frame, ctx)[0]


def _refine(fam: Family, member: int, F: Frame, ctx: FitContext, scorer: _Scorer,
            xatol: float = REFINE_XATOL) -> float:
    """Continuous 1-D search (log scale, bounded by the grid neighbours) of the searched parameter,
    minimising the weighted identification residual."""
    v = float(fam.grid[member])
    sgn = 1.0 if v > 0 else -1.0
    same = sorted(abs(x) for x in fam.grid if (x > 0) == (v > 0))
    i = same.index(abs(v))
    lo, hi = math.log(same[max(i - 1, 0)]), math.log(same[min(i + 1, len(same) - 1)])
    if hi <= lo:
        return v

    def rss(x):
        return scorer.rss(fam.build_at(F, ctx, sgn * float(np.exp(x))))

    r = minimize_scalar(rss, bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    return sgn * float(np.exp(r.x)) if r.fun <= rss(math.log(abs(v))) else v


def _fit(system: ObservationSystem, method: str) -> IdentificationResult:
    return identify(system, method=method)


def _as_list(trajectories) -> list[Trajectory]:
    if isinstance(trajectories, Trajectory):
        return [trajectories]
    out = list(trajectories)
    if not out:
        raise ValueError("no trajectory given")
    return out


# ------------------------------------------------------------------------------------------------
# The stages of diagnose(): assemble -> fit baseline -> (score candidates -> accept and re-identify)*
# -> final re-identification -> report. Each stage takes and returns frozen values.
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DiagnoseSettings:
    """The settings of one diagnosis (see :func:`diagnose` for their meaning)."""

    method: str
    candidates: tuple[str, ...]
    significance: float
    max_effects: int
    holdout: float
    min_rel_improvement: float
    n_placebo: int
    identifiability_tol: float
    structure: bool

    def __post_init__(self) -> None:
        if self.method.lower() not in ("ols", "wls", "tls"):
            raise IdentificationError(f"unknown identification method {self.method!r}; use 'ols', 'wls' or 'tls'")
        if not 0 < self.significance < 1:
            raise ValueError(f"significance must lie in (0, 1), got {self.significance!r}")
        object.__setattr__(self, "method", self.method.lower())
        object.__setattr__(self, "candidates", tuple(self.candidates))


@dataclass(frozen=True, eq=False)
class _Data:
    """Stage 1 (assemble): identification and validation frames of the declared model.

    ``F``/``V`` are the identification/validation frames (from the observations stage), ``Vs`` the
    validation system with the identification system's columns, ``decl`` the declared columns."""

    model: IdentificationModel
    F: Frame
    V: Frame
    Vs: ObservationSystem
    decl: tuple[str, ...]
    ident: tuple[Trajectory, ...]
    valid: tuple[Trajectory, ...]
    vdesc: str
    fdyn: float
    held_out: bool

    @property
    def n(self) -> int:
        return self.F.n_joints


@dataclass(frozen=True, eq=False)
class _Baseline:
    """Stage 2 (fit baseline): the declared model identified, its validation error, the candidate
    families and the nuisance columns of the scoring design."""

    res0: IdentificationResult
    val0: np.ndarray
    families: tuple[Family, ...]
    N_id: np.ndarray
    N_v: np.ndarray
    nuisance_names: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class _State:
    """The loop's state after a round: frames with the current model torque, the effects added
    (columns linearised around the current fit), the current fit, and what every round recorded."""

    F: Frame
    V: Frame
    added: tuple[_Added, ...]
    res: IdentificationResult
    effects_meta: tuple[dict, ...] = ()
    tried: tuple[CandidateScore, ...] = ()
    placebos: tuple[CandidateScore, ...] = ()
    round_resid: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    placebo_hits: tuple[tuple[int | None, int, str, float], ...] = ()   # (joint, round, variant, score)
    stopped_at_max: bool = False


@dataclass(frozen=True, eq=False)
class _Round:
    """Stage 3 (score candidates) of one round: the scores, and the eligible candidates by score."""

    tried: tuple[CandidateScore, ...]
    placebos: tuple[CandidateScore, ...]
    placebo_hits: tuple[tuple[int | None, int, str, float], ...]
    eligible: tuple[tuple, ...]   # (score, family, _Eval, X, Xv, CandidateScore), best first
    ctx: FitContext
    scorer: _Scorer


def _augmented(data: _Data, added: Sequence[_Added]) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Names and identification/validation columns of the declared model plus the added effects."""
    names = list(data.decl)
    A, Av = [data.F.system.W], [data.Vs.W]
    for ad in added:
        names += list(ad.family.names())
        A.append(ad.X)
        Av.append(ad.Xv)
    return tuple(names), np.hstack(A), np.hstack(Av)


def _context(data: _Data, F: Frame, V: Frame, names: Sequence[str], theta: np.ndarray) -> FitContext:
    """The fit the candidates are linearised around (declared parameters and predictions of the
    declared model alone: the gain column scales it, ``Y_j = (1 + gamma) W_j chi``)."""
    th = dict(zip(names, theta))
    td = np.array([th[k] for k in data.decl])
    return FitContext(model=data.model, theta={k: th[k] for k in data.decl},
                      predictions={id(F): F.system.W @ td, id(V): data.Vs.W @ td})


def _relinearise(data: _Data, F: Frame, V: Frame, added: Sequence[_Added], result: IdentificationResult
                 ) -> tuple[Frame, Frame, tuple[_Added, ...]]:
    """Model torque of ``result`` on both frames; the effects that depend on the fit rebuilt around it."""
    names, _, _ = _augmented(data, added)
    theta = np.array([result.value(nm) for nm in names])
    decl_theta = {k: result.value(k) for k in data.decl}
    F = attach_model_torque(F, data.model, decl_theta)
    V = attach_model_torque(V, data.model, decl_theta)
    ctx = _context(data, F, V, names, theta)
    new = []
    for ad in added:
        if not ad.family.depends_on_fit:
            new.append(ad)
            continue
        value = ad.value
        if ad.family.self_consistent:   # secant column: rebuild it at the fitted coefficient
            b = result.value(ad.family.names()[0])
            if b != 0.0 and np.isfinite(b):
                value = float(b)
        new.append(_Added(ad.family, value, _build_one(ad.family, F, ctx, value), _build_one(ad.family, V, ctx, value)))
    return F, V, tuple(new)


def _stage_assemble(model: IdentificationModel, trajectories, validation, holdout: float,
                    dynamics_bandwidth_hz: float | None, filter_kw: dict) -> _Data:
    """Stage 1: split off the validation data (or take the given ones), choose one ``f_dyn`` and
    assemble both with the observations stage (:func:`.frame.build_frame`)."""
    ident = _as_list(trajectories)
    if validation is None:
        ident, valid = split_holdout(ident, holdout)
        vdesc = f"last {100 * holdout:.0f} % of each identification experiment (held out)"
    else:
        valid = _as_list(validation)
        vdesc = ", ".join(tr.source for tr in valid)
    fdyn = dynamics_bandwidth_hz if dynamics_bandwidth_hz is not None else common_bandwidth(ident)
    F = build_frame(model, ident, dynamics_bandwidth_hz=fdyn, **filter_kw)
    V = build_frame(model, valid, dynamics_bandwidth_hz=fdyn, payload_columns=bool(
        set(F.system.names) - set(model.BASE_NAMES)), **filter_kw)
    decl = F.system.names
    return _Data(model=model, F=F, V=V, Vs=_align(V.system, decl), decl=decl, ident=tuple(ident),
                 valid=tuple(valid), vdesc=vdesc, fdyn=float(fdyn), held_out=validation is None)


def _stage_baseline(data: _Data, cfg: DiagnoseSettings) -> _Baseline:
    """Stage 2: identify the declared model (``cfg.method``), its validation error, the candidate
    families and the nuisance columns (velocity noise at Coulomb reversals)."""
    res0 = _fit(data.F.system, cfg.method)
    val0 = res0.rel_err_on(data.Vs)
    families = make_families(data.F, cfg.candidates)
    dq_noise = np.max([ex.dq_noise for ex in data.F.experiments], axis=0)
    N_id = nuisance_columns(data.F, data.decl, dq_noise)
    N_v = nuisance_columns(data.V, data.decl, dq_noise)
    return _Baseline(res0=res0, val0=np.asarray(val0), families=tuple(families), N_id=N_id, N_v=N_v,
                     nuisance_names=tuple(f"_nuisance{i}" for i in range(N_id.shape[1])))


def _stage_score(data: _Data, base: _Baseline, state: _State, rnd: int, cfg: DiagnoseSettings,
                 rng: np.random.Generator) -> _Round:
    """Stage 3: score every candidate family not yet added, and the placebos, against the current
    design (:class:`_Scorer`); decide which candidates are eligible (p-value, validation z, validation
    gain of their own joints, better than every placebo of their joints)."""
    n = data.n
    F, V = state.F, state.V
    Y, J = F.system.Y, F.system.joint
    names, A, Av = _augmented(data, state.added)
    resid_user = Y - A @ np.array([state.res.value(nm) for nm in names])
    D = _design(names + base.nuisance_names, np.hstack([A, base.N_id]), Y, J, np.hstack([Av, base.N_v]),
                data.Vs.Y, data.Vs.joint, n, w_resid=resid_user)
    ctx = _context(data, F, V, names, D.theta[:len(names)])
    scorer = _Scorer(D, F, V, n, cfg.identifiability_tol, max(MIN_SUPPORT_ROWS, MIN_SUPPORT_SHARE * F.n_rows / n))
    done = {ad.family.key for ad in state.added}
    fams = [f for f in base.families if f.key not in done]
    plac = placebo_families(F, rng, cfg.n_placebo) if cfg.n_placebo > 0 else []
    evals = []
    bar = progress_bar(len(fams) + len(plac), f"diagnose: round {rnd}", unit="candidate")
    for fam in fams + plac:
        bar.update(1)
        Xs = fam.build(F, ctx)
        Xvs = fam.build(V, ctx)
        best, reasons = None, []
        for i, (X, Xv) in enumerate(zip(Xs, Xvs)):
            ev = scorer.evaluate(X, Xv)
            if isinstance(ev, str):
                reasons.append(ev)
                continue
            ev.member = i
            if best is None or ev.p_value < best.p_value or (ev.p_value == best.p_value and ev.score > best.score):
                best = ev
        if best is not None:
            best.p_value = bonferroni(best.p_value, fam.n_members)
        evals.append((fam, best, reasons[0] if reasons and best is None else "", Xs, Xvs))
    bar.close()
    tested = [e for e in evals if e[1] is not None and not e[0].placebo]
    thr = cfg.significance / max(len(tested), 1)
    zcrit = float(sst.norm.isf(thr))
    pl = [(f, e) for f, e, *_ in evals if f.placebo and e is not None]

    def placebo_bounds(own):
        ps = [e for f, e in pl if f.joint in own]
        if not ps:
            return 1.0, -math.inf
        return min(e.p_value for e in ps), max(e.z for e in ps)

    def gain_of(ev, own):
        return max(float((ev.rel_before[j] - ev.rel_after[j]) / ev.rel_before[j])
                   if ev.rel_before[j] > 0 else 0.0 for j in own)

    eligible, tried, placebos, hits = [], [], [], []
    for fam, ev, why, Xs, Xvs in evals:
        search = {fam.grid_label: fam.grid[ev.member]} if (ev is not None and fam.grid) else {}
        if ev is None:
            cs = CandidateScore(rnd, fam.kind, fam.label, fam.joint, fam.partner, fam.variant, None, None, None,
                                thr, 0.0, False, why or "not evaluated", search)
        else:
            own = _own(fam, n)
            gain = gain_of(ev, own)
            reason = []
            if not fam.placebo:
                if ev.p_value >= thr:
                    reason.append(f"p {ev.p_value:.1e} >= {thr:.1e}")
                if ev.z <= zcrit:
                    reason.append(f"z_val {ev.z:.1f} <= {zcrit:.1f}")
                if gain < cfg.min_rel_improvement:
                    reason.append(f"validation gain {100 * gain:.2f} % < {100 * cfg.min_rel_improvement:g} %")
                pp, pz = placebo_bounds(own)
                if not reason and (ev.p_value >= pp or ev.z <= pz):
                    reason.append("not better than a placebo")
            cs = CandidateScore(rnd, fam.kind, fam.label, fam.joint, fam.partner, fam.variant, ev.score,
                                ev.p_value, ev.z, thr, ev.ident, not reason and not fam.placebo,
                                "; ".join(reason), search, tuple(float(x) for x in ev.rel_before),
                                tuple(float(x) for x in ev.rel_after))
            if cs.eligible:
                eligible.append((ev.score, fam, ev, Xs[ev.member], Xvs[ev.member], cs))
        (placebos if fam.placebo else tried).append(cs)
        if (fam.placebo and ev is not None and ev.p_value < thr and ev.z > zcrit
                and gain_of(ev, _own(fam, n)) >= cfg.min_rel_improvement):
            hits.append((fam.joint, rnd, fam.variant, ev.score))
    eligible.sort(key=lambda t: -t[0])
    return _Round(tried=tuple(tried), placebos=tuple(placebos), placebo_hits=tuple(hits), eligible=tuple(eligible),
                  ctx=ctx, scorer=scorer)


def _stage_accept(data: _Data, state: _State, scored: _Round, rnd: int, cfg: DiagnoseSettings) -> _State:
    """Stage 4 (accept, refine, re-identify): add the best eligible candidate (its searched parameter
    refined continuously), re-identify with ``cfg.method`` and re-linearise the effects that depend on
    the fit (fixed point, :data:`RELINEARISE_PASSES`)."""
    F, V = state.F, state.V
    Y, J = F.system.Y, F.system.joint
    _, fam, ev, X, Xv, _cs = scored.eligible[0]
    value = fam.grid[ev.member] if fam.grid else None
    if fam.build_at is not None:
        value = _refine(fam, ev.member, F, scored.ctx, scored.scorer)
        X, Xv = fam.build_at(F, scored.ctx, value), fam.build_at(V, scored.ctx, value)
    added = state.added + (_Added(fam, value, X, Xv),)
    meta = dict(family=fam, value=value, score=ev.score, p=ev.p_value, z=ev.z, round=rnd)
    names, A, Av = _augmented(data, added)
    res = _fit(ObservationSystem(A, Y, names, J), cfg.method)
    passes = RELINEARISE_PASSES if any(ad.family.depends_on_fit for ad in added) else 0
    for _ in range(passes):
        F, V, added = _relinearise(data, F, V, added, res)
        names, A, Av = _augmented(data, added)
        res = _fit(ObservationSystem(A, Y, names, J), cfg.method)
    if not passes:
        F, V, added = _relinearise(data, F, V, added, res)   # model torque of the new fit for the next round
    th = np.array([res.value(nm) for nm in names])
    return replace(state, F=F, V=V, added=added, res=res, effects_meta=state.effects_meta + (meta,),
                   round_resid=state.round_resid + ((Y - A @ th, data.Vs.Y - Av @ th),))


def _stage_loop(data: _Data, base: _Baseline, cfg: DiagnoseSettings, rng: np.random.Generator) -> _State:
    """Stages 3-4 repeated: score, accept the best, re-identify, until nothing is eligible or
    ``max_effects``."""
    F, V, added = _relinearise(data, data.F, data.V, (), base.res0)
    state = _State(F=F, V=V, added=added, res=base.res0,
                   round_resid=((base.res0.residual, data.Vs.Y - base.res0.predict(data.Vs)),))
    for rnd in range(1, cfg.max_effects + 1):
        scored = _stage_score(data, base, state, rnd, cfg, rng)
        state = replace(state, tried=state.tried + scored.tried, placebos=state.placebos + scored.placebos,
                        placebo_hits=state.placebo_hits + scored.placebo_hits)
        if not scored.eligible:
            return state
        state = _stage_accept(data, state, scored, rnd, cfg)
    return replace(state, stopped_at_max=True)


def _full_rate_frame(V: Frame) -> Frame:
    """``V`` at full rate: one row per full-rate sample and joint, no decimation (the experiments'
    ``decimate`` is the identity), the signals of the assembly (``tau`` raw). Effect columns built on
    it are the effects at full rate."""
    exps = tuple(replace(ex, settings=replace(ex.settings, n_d=1), n_rows=ex.n_samples) for ex in V.experiments)
    n = V.n_joints
    keys = [k for k in ("q", "dq", "ddq", "tau", "tau_hat", "dtau_hat", "ddtau_hat")
            if getattr(exps[0], k, None) is not None]
    J, E, R = [], [], []
    for j in range(n):
        for e, ex in enumerate(exps):
            J.append(np.full(ex.n_samples, j))
            E.append(np.full(ex.n_samples, e))
            R.append(np.arange(ex.n_samples))
    joint, row_exp, row_idx = np.concatenate(J), np.concatenate(E), np.concatenate(R)
    sig = {}
    for k in keys:   # all joints' signals at each row's sample
        full = np.zeros((joint.size, n))
        for e, ex in enumerate(exps):
            m = row_exp == e
            full[m] = getattr(ex, k)[row_idx[m]]
        sig[k] = full
    t = np.zeros(joint.size)
    for e, ex in enumerate(exps):
        m = row_exp == e
        t[m] = ex.t[row_idx[m]]
    sig["t"] = t
    tau_own = sig["tau"][np.arange(joint.size), joint]
    system = ObservationSystem(np.zeros((joint.size, 0)), tau_own, (), joint)
    return Frame(system=system, experiments=exps, row_experiment=row_exp, row_index=row_idx, sig=sig)


def _validation_rel_err_raw(data: _Data, V: Frame, res: IdentificationResult, added: Sequence[_Added]
                            ) -> np.ndarray:
    """Validation ``rel_err_raw`` of ``res`` (declared model + ``added`` effects): the model at full rate
    on the filtered states (the assembly's) against the raw measured torque, per joint, every sample."""
    theta = {k: res.value(k) for k in data.decl}
    loaded_cols = bool(V.assembly is not None and V.assembly.options.payload_columns)
    R = _full_rate_frame(V)
    pred = np.zeros(R.n_rows)
    for e, ex in enumerate(R.experiments):
        tq = model_torque(data.model, theta, ex.q, ex.dq, ex.ddq, loaded=ex.loaded and loaded_cols)
        m = R.row_experiment == e
        pred[m] = tq[R.row_index[m], R.system.joint[m]]
    if added:
        ctx = FitContext(model=data.model, theta=dict(theta), predictions={id(R): pred.copy()})
        _UNSHIFTED.clear()   # the elasticity secant caches the unshifted torque by frame identity
        for ad in added:
            X = _build_one(ad.family, R, ctx, ad.value)
            pred += X @ np.array([res.value(nm) for nm in ad.family.names()])
        _UNSHIFTED.clear()
    return _rel_err(R.system.Y - pred, R.system.Y, R.system.joint, data.n)


def _stage_report(data: _Data, base: _Baseline, state: _State, cfg: DiagnoseSettings) -> ResidualReport:
    """Stage 5-6 (re-identify, report): the final model identified with every effect, its errors on
    both metrics, the effects with their physical reading, residual structure, warnings."""
    n = data.n
    Y, J = data.F.system.Y, data.F.system.joint
    names, A, Av = _augmented(data, state.added)
    res = state.res
    if state.added:
        res = _fit(ObservationSystem(A, Y, names, J), cfg.method)
    val1 = res.rel_err_on(ObservationSystem(Av, data.Vs.Y, names, data.Vs.joint))
    val0_raw = _validation_rel_err_raw(data, state.V, base.res0, ())
    val1_raw = _validation_rel_err_raw(data, state.V, res, state.added)
    warnings: list[str] = []
    if state.stopped_at_max:
        warnings.append(f"stopped at max_effects = {cfg.max_effects}: more effects may be significant")
    effects = []
    final_value = {ad.family.key: ad.value for ad in state.added}
    for meta in state.effects_meta:
        fam, mem = meta["family"], final_value.get(meta["family"].key, meta["value"])
        idx = [res.index(nm) for nm in fam.names()]
        vals, std, pct = res.values[idx], res.std[idx], res.rel_std_pct[idx]
        effects.append(Effect(kind=fam.kind, label=fam.label, variant=fam.variant, joint=fam.joint,
                              partner=fam.partner, names=fam.names(), values=vals, std=std, rel_std_pct=pct,
                              physical=describe_params(fam, mem, vals, std), score=meta["score"], p_value=meta["p"],
                              z_validation=meta["z"], round=meta["round"], reveal=REVEAL.get(fam.kind, "t"),
                              reveal_joint=fam.reveal_joint if fam.reveal_joint is not None else fam.joint))
    F = state.F
    s_before = residual_structure(F, base.res0.residual, significance=cfg.significance) if cfg.structure else ()
    s_after = residual_structure(F, Y - A @ np.array([res.value(nm) for nm in names]),
                                 significance=cfg.significance) if cfg.structure else ()
    warnings += [f"final identification: {w}" for w in res.warnings if "TLS" in w or "rank-deficient" in w]
    hits: dict = {}
    for joint, rnd, variant, score in state.placebo_hits:
        hits.setdefault(joint, []).append((rnd, variant, score))
    if hits:
        lst = ", ".join(f"joint {j + 1} (score up to {max(sc for *_, sc in h):.2f})" for j, h in sorted(hits.items()))
        warnings.append(
            f"placebo columns (random combinations of time or motion signals, no physical meaning) pass the "
            f"significance and validation tests on {lst}: there the residual holds structure that the library "
            f"does not describe specifically (an effect outside the library, or an error of the declared model "
            f"such as its geometry or a joint zero); a candidate on such a joint is added only when it beats "
            f"every placebo")
    strong = [x for x in s_after if x.significant and x.eta2 >= STRUCTURE_WARN_ETA2]
    if strong:
        top = sorted(strong, key=lambda x: -x.eta2)[:3]
        warnings.append("structure left in the identification residual: " + "; ".join(
            f"joint {x.joint + 1} vs {x.label} ({100 * x.eta2:.0f} % explained)" for x in top)
            + " (see 'structure')")
    st = F.experiments[0].settings
    settings = {
        "method": cfg.method, "significance": cfg.significance, "max_effects": cfg.max_effects,
        "min_rel_improvement": cfg.min_rel_improvement, "n_placebo": cfg.n_placebo,
        "identifiability_tol": cfg.identifiability_tol, "candidates": list(cfg.candidates),
        "validation": data.vdesc, "holdout": cfg.holdout if data.held_out else None,
        "identification_sources": [tr.source for tr in data.ident], "validation_sources": [tr.source for tr in data.valid],
        "dynamics_bandwidth_hz": data.fdyn, "cutoff_hz": st.cutoff_hz, "n_d": st.n_d,
        "rows_identification": int(F.n_rows), "rows_validation": int(state.V.n_rows),
        "samples_validation": int(sum(ex.n_samples for ex in state.V.experiments)),
    }
    plot_data = {"frame": F, "vframe": state.V, "round_resid": list(state.round_resid)}
    return ResidualReport(robot=str(getattr(data.model, "ROBOT", "?")), method=cfg.method, n_joints=n,
                          before_rel_err=np.asarray(base.res0.rel_err), before_validation_rel_err=base.val0,
                          after_rel_err=np.asarray(res.rel_err), after_validation_rel_err=np.asarray(val1),
                          effects=tuple(effects), tried=state.tried, placebos=state.placebos,
                          structure_before=s_before, structure_after=s_after, result_before=base.res0,
                          result_after=res, settings=settings, warnings=tuple(warnings), plot_data=plot_data,
                          before_validation_rel_err_raw=np.asarray(val0_raw),
                          after_validation_rel_err_raw=np.asarray(val1_raw))


def diagnose(model: IdentificationModel, trajectories, *, validation=None, method: str = "ols",
             candidates: Sequence[str] = ALL, significance: float = SIGNIFICANCE, max_effects: int = MAX_EFFECTS,
             holdout: float = HOLDOUT, min_rel_improvement: float = MIN_REL_IMPROVEMENT, n_placebo: int = N_PLACEBO,
             identifiability_tol: float = IDENTIFIABILITY_TOL, rng: np.random.Generator | None = None,
             dynamics_bandwidth_hz: float | None = None, structure: bool = True, **filter_kw) -> ResidualReport:
    """Find what the declared model misses, add it, and measure the gain on validation data.

    The stages (each a function over frozen values): :func:`_stage_assemble` (observations stage:
    identification and validation frames) -> :func:`_stage_baseline` (declared model identified) ->
    :func:`_stage_loop` (:func:`_stage_score` the candidates, :func:`_stage_accept` the best, re-identify;
    repeated) -> :func:`_stage_report` (final re-identification, errors on both metrics, report).

    Parameters
    ----------
    model : IdentificationModel
        Generated model (``symoro_gen.load_model(name)``, ``build_in_memory(robot)``): ``N_JOINTS``,
        ``BASE_NAMES``, ``regressor(q, dq, ddq) -> (N, n, nb)`` (and ``PAYLOAD_NAMES``,
        ``payload_regressor`` for loaded experiments).
    trajectories : Trajectory or sequence of Trajectory
        Identification experiments (only ``t``, ``q`` and ``tau`` are used).
    validation : Trajectory or sequence of Trajectory, optional
        Validation experiments; default: the last ``holdout`` share of each identification experiment.
    method : {"ols", "wls", "tls"}
        Estimator of the reported identifications (candidate scoring always uses per-joint weighted LS).
    candidates : sequence of str
        Kinds to try (default all, :data:`~.candidates.KINDS`).
    significance : float
        Family-wise level of each round.
    max_effects : int
        Most effects added.
    holdout : float
        Share held out when ``validation`` is None.
    min_rel_improvement : float
        Smallest relative decrease of the validation error norm of the effect's joint.
    n_placebo : int
        Placebo candidates per joint and round (0: none).
    identifiability_tol : float
        Candidates with a column (almost) in the span of the model are skipped.
    rng : numpy.random.Generator, optional
        Draws the placebos (default ``np.random.default_rng(0)``: reproducible).
    dynamics_bandwidth_hz : float, optional
        ``f_dyn`` of the filter rules, default the largest estimate over the identification data;
        the same value is used for every experiment (identification and validation).
    structure : bool
        Run the residual-structure tests (:func:`.structure.residual_structure`).
    **filter_kw
        ``cutoff_hz``, ``n_d``, ``order``, ``ftype`` for the assembly
        (:class:`~symoro_gen.observations.AssemblyOptions`).

    Returns
    -------
    ResidualReport
        Errors before/after on the filtered, decimated system (``*_rel_err``, the papers' metric) and,
        on validation data, on the raw measured torque (``*_validation_rel_err_raw``).
    """
    cfg = DiagnoseSettings(method=method, candidates=tuple(candidates), significance=significance,
                           max_effects=max_effects, holdout=holdout, min_rel_improvement=min_rel_improvement,
                           n_placebo=n_placebo, identifiability_tol=identifiability_tol, structure=structure)
    rng = np.random.default_rng(0) if rng is None else rng
    data = _stage_assemble(model, trajectories, validation, holdout, dynamics_bandwidth_hz, filter_kw)
    base = _stage_baseline(data, cfg)
    state = _stage_loop(data, base, cfg, rng)
    return _stage_report(data, base, state, cfg)
