"""Close the loop on measured data: residual -> candidate effect -> augmented re-identification.

:func:`diagnose` identifies the declared model (the chosen method, OLS/WLS/TLS), then repeats the steps
below.

**Acceptance data.** The validation data (``validation=``, or the last ``holdout`` share of each
experiment) are never read by any decision: they give only the errors reported before/after. Every
decision is taken on the identification data split once more in time: the candidates are fitted on the
leading part of each identification experiment and *accepted* on its trailing ``acceptance`` share
(:data:`ACCEPTANCE`; the "validation" of the steps below is that acceptance data). A trailing block
rather than interleaved folds keeps the scoring's statistics valid: the HAC ``z`` statistic is computed
on rows the fit never saw, contiguous in time, with no filter edge inside them. The final model is
refitted on all identification data. The friction laws are chosen by their own time-blocked
cross-validation on the identification data; the other changes of the model outside the effect list
(the declared law static (0) in a joint's rest segments, sign(dq) smoothed) are candidates of their
joint tested on the acceptance data (:func:`_accept_notes`) and reported as effects when accepted; on a
joint whose identification data never rest, "static (0) at rest" changes none of their samples and cannot be
tested: it is applied untested as a prior (:func:`_static_prior`, the minimax prediction of a static friction
torque in [-Fs, Fs]) and reported as such, never as an effect.
Last, per joint, the final model may not be worse than the declared one on the acceptance data beyond
the 95 % circular block-bootstrap band of the declared model's error (:func:`_never_worse`,
:mod:`.bootstrap`, Künsch 1989, Politis & Romano 1992): where it is, the changes touching the joint are
removed. On the validation data each joint's error before -> after is reported with its band, and a joint
worse beyond it is flagged.

The steps:

1. weight the rows of joint j by ``1/sigma_j`` (the current residual's standard deviation per joint),
   add *nuisance* columns that absorb what velocity noise does to the Coulomb column at reversals
   (:func:`.candidates.nuisance_columns`; one whose coefficient exceeds ten times its joint's torque range fits
   noise on a few rows and is left out, :func:`_physical_nuisance`), and project every candidate's columns out of the span of
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
   enough rows to give evidence at all, each of its joints has :data:`MIN_ACCEPTANCE_ROWS` acceptance
   rows, and it beats every *placebo* of its joint(s) on both
   statistics (random smooth functions of time, and random combinations of every joint's position,
   velocity and acceleration, drawn with ``rng``: a calibration of the null that does not rest on a
   noise model and that also catches coincidental fits of deterministic artefacts repeated in the
   validation data);
4. the eligible candidate with the best validation score is added - or, among the candidates of its joints
   whose score is within one standard error of the best's, the one with the fewest parameters
   (:func:`_simplest_within_se`, the one-standard-error rule) - (its searched parameter refined
   continuously between grid points), the model re-identified (OLS, :data:`SELECT_METHOD`), the model
   torque and the columns linearised around the fit rebuilt (fixed point), and the loop goes on
   until nothing is eligible or ``max_effects``.

Everything the loop computed is in the :class:`~.report.ResidualReport`.

Known limits
------------
* Candidates are scored with per-joint weighted least squares and the loop re-identifies with OLS
  (:data:`SELECT_METHOD`) whatever ``method``, and the stability stage keeps only the effects that both
  OLS and WLS weights name (the others are reported as ``estimator_dependent``): the named effects are the
  same under ``method="ols"`` and ``"wls"`` by construction. Only the reported identifications (errors
  before/after, effect parameters and %sigma) use ``method``.
* ``gain``: only the gain of one joint relative to the others is identifiable (through the dynamic
  coupling); a common scale of all joints needs a known payload. On robots whose joints are weakly
  coupled (a SCARA) a gain error of one joint looks like that of another.
* ``elasticity`` of a joint carrying most of the gravity torque (LWR4 joint 2) is partly absorbed by
  the gravity parameters; stiffness estimates are biased low there. The Coulomb term of the deflection
  is left out of the column (it gave false positives on noisy data), so large Coulomb friction against
  a soft joint is picked up as ``time_delay`` or ``load_friction`` instead.
* ``position_ripple`` is in the joint angle only, orders 1-32 within the decimated band; a ripple at
  the motor angle (gear ratio times faster) is filtered out by the decimation.
* Hold-out acceptance on a repeated (periodic) excitation accepts deterministic processing
  artefacts as well as physical effects; the motion placebos guard against the coincidental ones.
* The loop fits its candidates on the leading part of the identification data only: an effect that
  appears only in the trailing acceptance share (a step late in the recording), or a condition met only
  there gives no evidence and is not added; rests met only in the validation data get the static prior
  (above), not a tested effect. On short recordings the
  acceptance share holds few decimated rows per joint (10 s at 100 Hz: 16 after the filter edges), too few
  for its HAC ``z``: a change of the model is eligible only with :data:`MIN_ACCEPTANCE_ROWS` acceptance rows
  on each of its joints, so a short recording names nothing (before that rule one of 30 clean simulated
  SCARA seeds got a torque-modulated constant on its prismatic joint, at z = 7.9 on 16 rows).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass, fields, replace

import numpy as np
from scipy import stats as sst
from scipy.optimize import minimize_scalar

from ..errors import IdentificationError
from ..identification.method import identify
from ..identification.result import IdentificationResult
from ..model import IdentificationModel
from ..observations.options import AssemblyOptions
from ..observations.system import ObservationSystem
from ..preprocessing.trajectory import Trajectory
from ..progress import progress_bar
from .bootstrap import LEVEL as BAND_LEVEL
from .bootstrap import rel_err_bands
from .candidates import (
    ALL,
    REVEAL,
    Family,
    FitContext,
    clear_elasticity_cache,
    clear_loop_caches,
    describe_params,
    implausible,
    make_families,
    nuisance_columns,
    placebo_families,
)
from .compose import Composed, RowSignals, as_load_friction, score_composed
from .compose import library as composed_library
from .frame import Experiment, Frame, attach_model_torque, build_frame, common_bandwidth, model_torque, split_holdout
from .friction import (
    COULOMB_LAWS,
    PRESLIDING_LAWS,
    VISCOUS_LAWS,
    FrictionChoice,
    LawFit,
    LawModel,
    LawSearch,
    clear_law_columns,
    coulomb_columns,
    friction_column_indices,
    rest_mask,
    select_friction,
    shape_physical,
    shape_uncertainty,
    sliding_frame,
    sliding_velocity,
    velocity_grid,
    viscous_columns,
)
from .geometry import invisible_zero_note
from .memory import release_freed_memory
from .plausibility import (
    PLAUSIBLE,
    ArmScales,
    Plausibility,
    delay_is_absurd,
    effect_plausibility,
    explains_same,
    fits_like,
    law_alternatives,
    law_plausibility,
    rate_effects,
)
from .report import CandidateScore, Effect, ResidualReport
from .stability import (
    N_FOLDS,
    BlockedLS,
    clear_fold_cache,
    coefficient_ci,
    ols_wls_agreement,
    sided_selection,
    simulated_noise_placebo,
    time_blocks,
)
from .stats import bonferroni, hac_covariance, hac_lag, segments_of, single_threaded_blas, wald_test
from .structure import residual_structure
from .unexplained import joint_weighted_residual, signal_matrix, unexplained_by_joint

__all__ = ["diagnose", "DiagnoseSettings", "SIGNIFICANCE", "MAX_EFFECTS", "HOLDOUT", "ACCEPTANCE", "MIN_REL_IMPROVEMENT",
           "MIN_ACCEPTANCE_ROWS",
           "IDENTIFIABILITY_TOL"]

#: family-wise level of each round (Bonferroni over the candidates)
SIGNIFICANCE = 0.01
#: at most this many effects are added
MAX_EFFECTS = 5
#: share of each experiment held out (its end) when no validation data are given
HOLDOUT = 0.3
#: share of each identification experiment (its end) the loop accepts candidates on (the acceptance data;
#: never the validation data); the final model is refitted on all identification data
ACCEPTANCE = 0.3
#: a candidate must lower the validation error norm of (one of) its joint(s) by this fraction
MIN_REL_IMPROVEMENT = 0.02
#: a change of the model is eligible only when each of its joints has at least this many acceptance rows:
#: the acceptance ``z`` rests on a HAC (Newey-West) variance and a normal approximation, both unreliable in a
#: few dozen autocorrelated rows (the HAC variance is biased low in small samples, Andrews 1991, sec. 8;
#: den Haan & Levin 1997). A short recording then names nothing rather than a coincidental fit.
MIN_ACCEPTANCE_ROWS = 30
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
#: the ``sign(dq)`` of the friction laws is smoothed at this many standard deviations of the velocity
#: noise (:func:`.friction.select_friction` ``v_floor``)
V_FLOOR_NOISE = 3.0
#: a tanh velocity scale below this share of the 95th percentile of |dq_j| is a rounding of sign(dq) at
#: reversals and standstill (applied, reported in ``settings["sign_smoothing"]``, not as an effect)
MIN_LAW_SCALE = 0.01
#: contiguous sub-blocks (per experiment) of the paired test of a friction-law replacement
N_LAW_SUBBLOCKS = 20
#: an accepted effect must be selected in more than this share of the time-blocked folds
MIN_SELECTION_FREQUENCY = 0.5
#: confidence level of the intervals of the accepted effects' coefficients (the joint region must
#: exclude "no effect" at this level)
CI_LEVEL = 0.99
#: estimator of the loop's own re-identifications (the fit the candidates are linearised around, the row
#: weights of the scoring): fixed, so that *what* is named does not depend on ``method`` (stability stage);
#: the stability stage then tests every effect under OLS *and* WLS weights and keeps the common ones, and
#: only the reported identifications (errors before/after, parameters, %sigma) use ``method``
SELECT_METHOD = "ols"


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
    VS: np.ndarray      # (k, rank) V S^-1: the pseudo-inverse of A*w is VS @ U.T (never formed: it is as large as A)
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
    VS = Vt.T / s
    U = Aw @ VS
    theta = VS @ (U.T @ (Y * w))
    e_w = Y * w - Aw @ theta
    del Aw
    e_v = Yv - Av @ theta
    sv = _joint_sigma(e_v, jv, n, 0)
    wv = 1.0 / sv[jv]
    return _Design(tuple(names), A, Av, w, wv, U, VS, theta, e_w, e_v, rank)


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
    score_se: float = math.nan
    score_blocks: np.ndarray | None = None   # the score's shares per acceptance time block (sum = score)


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
        self.vblocks = time_blocks(V.row_experiment, V.row_index, N_SCORE_BLOCKS)
        self.jv = np.asarray(V.system.joint, int)

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
        lev = np.einsum("ij,ij->i", Xp @ Ginv, Xp) + self.lev0   # diag(Xp Ginv Xp^T)
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
        dtheta = -D.VS @ (C @ b)              # change of the current model's coefficients (pinv(Aw) Xw beta)
        dv = D.Av @ dtheta + Xv @ beta
        ev1 = D.e_v - dv
        rv1 = np.bincount(self.V.system.joint, weights=ev1 ** 2, minlength=self.n)
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(self.rv0 > 0, (self.rv0 - rv1) / self.rv0, 0.0)
        score = float(np.sum(frac))
        wv = D.wv
        dec = float(np.sum((D.e_v ** 2 - ev1 ** 2) * wv ** 2))
        # prediction change on validation (weighted) per unit of the scaled coefficients b
        Mv = (Xv * wv[:, None]) / norms - self.Avw @ (D.VS @ C)
        m = float(np.einsum("ij,jk,ik->", Mv, Cb, Mv))
        Sv = hac_covariance(Mv * (ev1 * wv)[:, None], max_lag=self.lag_v, segments=self.gv)
        var = max(float(np.sum(Sv * Cb)), float(np.mean((ev1 * wv) ** 2)) * m)
        z = (dec + m) / (2.0 * math.sqrt(max(var, 1e-300)))
        after = _rel_err(ev1, self.yv, self.V.system.joint, self.n)
        d = self.score_blocks(ev1)
        return _Eval(0, score, pval, float(z), ident, self.rel_before, after, score_se=_block_se(d), score_blocks=d)

    def score_blocks(self, ev1: np.ndarray) -> np.ndarray:
        """The acceptance score of a candidate leaving the acceptance residual ``ev1`` as a sum over
        :data:`N_SCORE_BLOCKS` contiguous time blocks of every experiment's acceptance rows (all joints of a
        sample in one block) of the rows' shares ``(e_i^2 - e1_i^2) / ||rho_j||^2``: the block sums."""
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(self.rv0[self.jv] > 0, (self.D.e_v ** 2 - ev1 ** 2) / self.rv0[self.jv], 0.0)
        return np.bincount(self.vblocks, weights=share, minlength=N_SCORE_BLOCKS)


def _block_se(d: np.ndarray) -> float:
    """Standard error ``sqrt(K) std(d_k)`` of a sum of ``K`` block sums ``d_k`` (blocks long against the
    residual's correlation time are nearly independent, as :func:`.expert.no_worse`)."""
    return float(math.sqrt(d.size) * np.std(d, ddof=1))


# ------------------------------------------------------------------------------------------------
def _affected(fam: Family, n: int) -> list[int]:
    if fam.rows is not None:
        return list(fam.rows)
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
    changes the torque of all, and so does a link length: the torque of every joint it carries; a family that
    declares its rows, those: a contact sensor's, every row its wrench reaches)."""
    if fam.rows is not None:
        return list(fam.rows)
    if fam.joint is None or fam.kind in ("elasticity", "link_length"):
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


#: relative differences of p-values and scores below this are rounding, not evidence: a grid member must beat the
#: best so far by more to replace it (on a flat objective every member scores the same to ~1e-10, and the
#: member reported would otherwise be decided by the last bits of the arithmetic)
MEMBER_TIE_RTOL = 1e-6


def _better_member(one: _Eval, best: _Eval | None) -> bool:
    """Whether grid member ``one`` replaces ``best``: a smaller p-value, or the same p-value and a larger score,
    each beyond :data:`MEMBER_TIE_RTOL`; ties keep the earlier member (deterministic)."""
    if best is None:
        return True
    tol_p = MEMBER_TIE_RTOL * best.p_value
    if one.p_value != best.p_value and abs(one.p_value - best.p_value) > tol_p:
        return one.p_value < best.p_value
    return one.score > best.score + MEMBER_TIE_RTOL * abs(best.score)


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


def _residual_of(res: IdentificationResult) -> np.ndarray:
    """The identification residual of a fit (every fit here is of an observation system: it has one)."""
    assert res.residual is not None
    return res.residual


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
#: the assembly options :func:`.frame.build_frame` sets for the diagnosis' frames
_FRAME_SET = ("dynamics_bandwidth_hz", "payload_columns", "keep_signals")


@dataclass(frozen=True)
class DiagnoseSettings:
    """The settings of one diagnosis, validated once (the defaults are those of ``symoro-gen diagnose``).

    Attributes
    ----------
    method : {"ols", "wls", "tls"}
        Estimator of the reported identifications (candidate scoring always uses per-joint weighted LS).
    candidates : sequence of str
        Kinds to try (default all, :data:`~.candidates.KINDS`, plus ``"friction_law"`` - the friction-law
        stage - and ``"composed"`` - the composed library); an explicit list runs those two only when it
        names them (unless ``friction_laws``/``composed`` say otherwise). Stored without those two names.
    significance : float
        Family-wise level of each round, in (0, 1).
    max_effects : int
        Most effects added.
    holdout : float
        Share of each identification experiment held out when no validation data are given.
    acceptance : float
        Share of each identification experiment (its end) the loop accepts candidates on; the validation
        data are never read by the acceptance, only for the errors reported.
    min_rel_improvement : float
        Smallest relative decrease of the validation error norm of the effect's joint.
    n_placebo : int
        Placebo candidates per joint and round (0: none).
    identifiability_tol : float
        Candidates with a column (almost) in the span of the model are skipped.
    structure : bool
        Run the residual-structure tests (:func:`.structure.residual_structure`).
    friction_laws : bool, optional
        Stage "friction law" (:func:`_stage_friction`); default (None): with the default ``candidates`` or
        when they name ``"friction_law"``.
    composed : bool, optional
        Composed candidates (effect x modulating signal, :mod:`.compose`) in each round; default (None):
        with the default ``candidates`` or when they name ``"composed"``.
    unexplained : bool
        Stage "unexplained" (:mod:`.unexplained`, needs scikit-learn): structure left in the final residual
        that no candidate explains, tested per joint (out-of-fold boosted trees on that joint's residual,
        null = the same residual block-permuted in time, which keeps its autocorrelation). The stacked
        fit spreads a joint's missing torque over the joints it is coupled to; each joint is therefore
        tested on the residual of the fit that the joints found to carry structure do not move
        (:func:`.unexplained.unexplained_by_joint`), so only the carriers are flagged. Tested in
        ``tests/diagnostics/test_unexplained.py``: a torque ``sin(3.7 q_j) dq_k^2`` (in no candidate
        family) on one SCARA joint is flagged on that joint only (three seeds and joints), a backlash
        hysteresis likewise, and a clean arm flags no joint in at least 19 of 20 seeds.
    stability : bool
        Stage "stability" (:func:`_stage_stability`).
    declared_elastic : tuple of int
        Joints (0-based columns) the robot file declares elastic (``elastic = {K, D}``): their positions are
        link-side or corrected already, so the loop's ``elasticity`` candidate is not offered for them.
    declared_laws : tuple of int
        Joints (0-based columns) whose friction law the robot file declares (``friction_law``; the model is
        then :class:`~symoro_gen.identification.friction_law.LawDeclaredModel` at the scales refined on the
        identification data): the friction-law stage leaves them as declared (no replacement of any kind
        is offered, :func:`_stage_friction`), and the loop's Stribeck candidate is not offered on a joint
        whose declared law has the Stribeck term already (its ``FSS<j>`` column). The loop's other
        candidates still compete there in the rounds (docs/loop-plausibility.md, "Declared friction laws").
    effect_joints : tuple of int, optional
        Joints (0-based columns) the friction-law stage and the candidate families are offered on; default
        (None): every joint. The other joints' rows stay in every fit and in the ``unexplained`` check: a
        floating-base robot's base-wrench rows, diagnosed as the first six "joints" of its rows
        (:class:`~symoro_gen.identification.floating.RowsAsJoints`), have no drive for an effect to act on. A
        family that declares its rows (``Family.rows``: a contact sensor's offset or gain, which the model
        offers, :func:`.candidates.make_families`) is offered on them whatever this says.
    unexplained_weighted : bool
        The ``unexplained`` stage tests each joint on the residual of the final model refitted with each joint's
        rows weighted by the inverse of its own residual standard deviation (the per-joint WLS of [GB-gains]
        eq. 22) instead of the reported fit's residual (:func:`_unexplained`). Where the joints' noise levels
        differ by an order of magnitude, the unweighted fit's estimation error, driven by the noisy joints'
        rows, leaves ``-A_k delta`` (a smooth function of the motion, which the trees predict) on the quiet
        joints' residuals. Off by default; on for a floating-base robot's rows
        (:func:`symoro_gen.workflows.floating.row_loop`), whose base-wrench rows carry the contact sensors'
        noise and, through the base's columns, the IMU's (errors in variables), 10 to 40 times the variance
        of the quiet joint rows (docs/floating-base.md).
    presliding_law : bool
        The friction-law stage also tries the pre-sliding Dahl and LuGre laws (:func:`.friction.dahl_column`,
        :func:`.friction.lugre_columns`) on data sampled at :data:`.friction.DAHL_MIN_RATE_HZ` or more. Off by
        default: on the TX40 recording (5 kHz) they displace the joint-1 friction law the loop names without
        them (joint-1 validation error 0.180 with Dahl and LuGre tried, 0.080 without; docs/friction-dynamic.md).
    """

    method: str = "ols"
    candidates: tuple[str, ...] = ALL
    significance: float = SIGNIFICANCE
    max_effects: int = MAX_EFFECTS
    holdout: float = HOLDOUT
    acceptance: float = ACCEPTANCE
    min_rel_improvement: float = MIN_REL_IMPROVEMENT
    n_placebo: int = N_PLACEBO
    identifiability_tol: float = IDENTIFIABILITY_TOL
    structure: bool = True
    friction_laws: bool | None = None
    composed: bool | None = None
    unexplained: bool = True
    stability: bool = True
    declared_elastic: tuple[int, ...] = ()
    declared_laws: tuple[int, ...] = ()
    presliding_law: bool = False
    effect_joints: tuple[int, ...] | None = None
    unexplained_weighted: bool = False

    def offered(self, j: int) -> bool:
        """Joint ``j`` (0-based) takes the friction-law stage and the candidate families (``effect_joints``)."""
        return self.effect_joints is None or j in self.effect_joints

    def __post_init__(self) -> None:
        if self.method.lower() not in ("ols", "wls", "tls"):
            raise IdentificationError(f"unknown identification method {self.method!r}; use 'ols', 'wls' or 'tls'")
        if not 0 < self.significance < 1:
            raise ValueError(f"significance must lie in (0, 1), got {self.significance!r}")
        if not 0 < self.acceptance < 1:
            raise ValueError(f"acceptance must lie in (0, 1), got {self.acceptance!r}")
        kinds = tuple(self.candidates)
        everything = kinds == tuple(ALL)
        if self.friction_laws is None:
            object.__setattr__(self, "friction_laws", everything or "friction_law" in kinds)
        if self.composed is None:
            object.__setattr__(self, "composed", everything or "composed" in kinds)
        object.__setattr__(self, "method", self.method.lower())
        object.__setattr__(self, "candidates", tuple(k for k in kinds if k not in ("friction_law", "composed")))


@dataclass(frozen=True, eq=False)
class _Data:
    """Stage 1 (assemble): the frames of the declared model.

    The loop's data: ``F`` the leading part of each identification experiment (the candidates are fitted
    on it), ``V`` its trailing part (the *acceptance* data: the held-out test of every change), ``Vs`` the
    acceptance system with the identification system's columns, ``decl`` the declared columns. ``full``
    holds the same for the report: ``F`` all identification data (the final refit), ``V`` the user's
    validation data (errors reported only); ``full.full`` is None."""

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
    fixed: tuple[tuple[str, float], ...] = ()   # known payload parameters (moved to Y)
    doubtful_laws: tuple[dict, ...] = ()   # friction-law replacements that fit but are implausible: not applied
    full: _Data | None = None   # all identification data and the validation data (report)

    @property
    def n(self) -> int:
        return self.F.n_joints

    def theta_of(self, res: IdentificationResult) -> dict:
        """Declared-model parameters of a fit, with the known payload parameters."""
        th = {k: res.value(k) for k in self.decl}
        th.update(dict(self.fixed))
        return th


@dataclass(frozen=True)
class _LawRecord:
    """Stage "friction law" for one joint: the law chosen, whether it was added (joint declared without
    friction) and with an offset, and the share of the time-blocked folds whose held-out block it
    predicts better than the declared law."""

    choice: FrictionChoice
    added: bool
    offset: bool
    frequency: float
    p_value: float
    smoothing: bool = False   # a tanh at a scale below MIN_LAW_SCALE: sign(dq) smoothed, not reported as an effect
    round: int = 0   # the loop's round the replacement won (0: applied before the loop, a joint without friction)
    prior: bool = False   # static (0) at rest applied untested: the identification data never rest (_accept_notes)


@dataclass(frozen=True, eq=False)
class _Baseline:
    """Stage 2 (fit baseline): the declared model identified, its validation error, the candidate
    families and the nuisance columns of the scoring design."""

    res0: IdentificationResult
    val0: np.ndarray
    res_start: IdentificationResult
    laws: tuple[_LawRecord, ...]
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
    stopped_joints: frozenset = frozenset()   # joints where a placebo passed: the loop stopped there
    estimator_dependent: tuple[dict, ...] = ()   # effects named under one weighting only (dropped)
    implausible: tuple[dict, ...] = ()   # eligible candidates not added: they made an effect implausible
    pending: tuple[_LawRecord, ...] = ()   # friction-law replacements competing in the rounds, not applied yet


@dataclass(frozen=True, eq=False)
class _Round:
    """Stage 3 (score candidates) of one round: the scores, and the eligible candidates by score."""

    tried: tuple[CandidateScore, ...]
    placebos: tuple[CandidateScore, ...]
    placebo_hits: tuple[tuple[int | None, int, str, float], ...]
    eligible: tuple[tuple, ...]   # (score, family, _Eval, X, Xv, CandidateScore), best first
    ctx: FitContext
    scorer: _Scorer
    stopped: frozenset = frozenset()


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
    return FitContext(model=data.model, theta={**{k: th[k] for k in data.decl}, **dict(data.fixed)},
                      predictions={id(F): F.system.W @ td, id(V): data.Vs.W @ td})


def _refit(data: _Data, F: Frame, V: Frame, added: Sequence[_Added]
           ) -> tuple[Frame, Frame, tuple[_Added, ...], IdentificationResult, tuple[str, ...], np.ndarray, np.ndarray]:
    """The model with the effects ``added`` re-identified with :data:`SELECT_METHOD` on ``F``, the effects that
    depend on the fit re-linearised around it (fixed point, :data:`RELINEARISE_PASSES`), the model torque of the
    new fit attached to both frames; returns the frames, effects, fit, names and columns."""
    Y, J = F.system.Y, F.system.joint
    names, A, Av = _augmented(data, added)
    res = _fit(ObservationSystem(A, Y, names, J), SELECT_METHOD)
    passes = RELINEARISE_PASSES if any(ad.family.depends_on_fit for ad in added) else 0
    for _ in range(passes):
        F, V, added = _relinearise(data, F, V, added, res)
        names, A, Av = _augmented(data, added)
        res = _fit(ObservationSystem(A, Y, names, J), SELECT_METHOD)
    if not passes:
        F, V, added = _relinearise(data, F, V, added, res)   # model torque of the new fit for the next round
    return F, V, tuple(added), res, names, A, Av


def _relinearise(data: _Data, F: Frame, V: Frame, added: Sequence[_Added], result: IdentificationResult
                 ) -> tuple[Frame, Frame, tuple[_Added, ...]]:
    """Model torque of ``result`` on both frames; the effects that depend on the fit rebuilt around it."""
    names, _, _ = _augmented(data, added)
    theta = np.array([result.value(nm) for nm in names])
    decl_theta = data.theta_of(result)
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


def _move_known(system: ObservationSystem, fixed: dict) -> ObservationSystem:
    """``Y - W_known chi_known`` without the known columns (known payload parameters, identification
    paper on payloads eq. 7: ``Y_b - W_kl chi_kl = [W_b W_ul] [chi; chi_ul]``)."""
    idx = [i for i, nm in enumerate(system.names) if nm in fixed]
    if not idx:
        return system
    Y = system.Y - system.W[:, idx] @ np.array([fixed[system.names[i]] for i in idx])
    keep = [i for i in range(len(system.names)) if i not in set(idx)]
    return ObservationSystem(system.W[:, keep], Y, tuple(system.names[i] for i in keep), system.joint)


def _filter_keywords(assembly: AssemblyOptions) -> dict:
    """The assembly options set away from their defaults, as keywords of :func:`.frame.build_frame` (which
    sets ``dynamics_bandwidth_hz``, ``payload_columns`` and ``keep_signals`` itself)."""
    default = AssemblyOptions()
    return {f.name: getattr(assembly, f.name) for f in fields(assembly)
            if f.name not in _FRAME_SET and getattr(assembly, f.name) != getattr(default, f.name)}


def _stage_assemble(model: IdentificationModel, trajectories, validation, holdout: float,
                    assembly: AssemblyOptions, payload=None, acceptance: float = ACCEPTANCE) -> _Data:
    """Stage 1: split off the validation data (or take the given ones), split each identification
    experiment again into a leading part (fit) and its trailing ``acceptance`` share (the loop's held-out
    test), choose one ``f_dyn`` and assemble every part with the observations stage
    (:func:`.frame.build_frame`); known payload parameters (``payload``) are moved to ``Y`` as in
    ``identify --loaded ... --payload``. Returns the loop's data (fit/acceptance) with the report's
    (all identification/validation) in ``full``."""
    dynamics_bandwidth_hz = assembly.dynamics_bandwidth_hz
    filter_kw = _filter_keywords(assembly)
    ident = _as_list(trajectories)
    fixed = {str(k): float(v) for k, v in dict(payload or {}).items()}
    names_pay = tuple(getattr(model, "PAYLOAD_NAMES", ()))
    bad = [k for k in fixed if k not in names_pay]
    if bad:
        raise IdentificationError(f"payload {bad[0]}: not a payload parameter of {getattr(model, 'ROBOT', 'the model')} "
                                  f"({', '.join(names_pay) or 'none'})")
    if fixed and not any(tr.loaded for tr in ident):
        raise IdentificationError("known payload parameters need recordings with the payload (--loaded)")
    if validation is None:
        ident, valid = split_holdout(ident, holdout)
        vdesc = f"last {100 * holdout:.0f} % of each identification experiment (held out)"
    else:
        valid = _as_list(validation)
        vdesc = ", ".join(tr.source for tr in valid)
    fdyn = dynamics_bandwidth_hz if dynamics_bandwidth_hz is not None else common_bandwidth(ident)
    F = build_frame(model, ident, dynamics_bandwidth_hz=fdyn, **filter_kw)
    pay_cols = bool(set(F.system.names) - set(model.BASE_NAMES))
    V = build_frame(model, valid, dynamics_bandwidth_hz=fdyn, payload_columns=pay_cols, **filter_kw)
    fit, acc = split_holdout(ident, acceptance)
    Ff = build_frame(model, fit, dynamics_bandwidth_hz=fdyn, payload_columns=pay_cols, **filter_kw)
    Fa = build_frame(model, acc, dynamics_bandwidth_hz=fdyn, payload_columns=pay_cols, **filter_kw)
    if fixed:
        F, V, Ff, Fa = (replace(x, system=_move_known(x.system, fixed)) for x in (F, V, Ff, Fa))
    decl = F.system.names
    Ff = replace(Ff, system=_align(Ff.system, decl))
    full = _Data(model=model, F=F, V=V, Vs=_align(V.system, decl), decl=decl, ident=tuple(ident),
                 valid=tuple(valid), vdesc=vdesc, fdyn=float(fdyn), held_out=validation is None,
                 fixed=tuple(sorted(fixed.items())))
    return _Data(model=model, F=Ff, V=Fa, Vs=_align(Fa.system, decl), decl=decl, ident=tuple(fit), valid=tuple(acc),
                 vdesc=f"last {100 * acceptance:.0f} % of each identification experiment (acceptance)",
                 fdyn=float(fdyn), held_out=True, fixed=tuple(sorted(fixed.items())), full=full)


def _stage_friction(data: _Data, cfg: DiagnoseSettings
                    ) -> tuple[_Data, tuple[_LawRecord, ...], tuple[_LawRecord, ...]]:
    """Stage "friction law": for each joint in turn, choose the Coulomb law (sign, tanh
    with searched ``v``, Stribeck) and the viscous law (linear, ``|dq|^delta``) by time-blocked
    cross-validation on the *identification* rows (:func:`.friction.select_friction`: the whole model
    refitted on the training blocks, error of the joint's held-out rows; a law replaces a simpler one
    only when it lowers that error by ``friction.MIN_GAIN``). The expert model's ``tanh`` law is one of
    the candidates, so the loop starts at least as good as the expert in cross-validation. A joint
    declared without friction gets the chosen laws and an offset (the expert's terms). The selection
    uses unit row weights whatever ``cfg.method`` (the choice does not depend on the estimator). A
    replacement that passes its tests but is implausible (:func:`.plausibility.law_plausibility` below
    :data:`.plausibility.PLAUSIBLE`: a Stribeck velocity below the velocity resolution, a viscous exponent
    far from 1) is not applied - it would absorb a delay or a load-dependent friction before the loop tries
    them - and is kept in ``doubtful_laws`` (reported in ``implausible``, round 0, and the warnings).

    A plausible replacement of a declared law is not applied here either: it is *pending*, a candidate of the
    loop's rounds (:func:`_law_family`), scored on the acceptance data with every other family and applied
    when it wins a round - a law that only reshapes what a delay or a gain error leaves at the velocity
    reversals then loses to that effect. Applied here: a joint declared without friction getting its laws,
    and the sign smoothing of the declared law (tested as a note, :func:`_accept_notes`).

    A joint whose law the robot file declares (``cfg.declared_laws``) is skipped: its law is the user's
    statement, identified with its scale refined on the identification data; the stage's replacements
    are measured against ``sign(dq)`` + ``dq``, not against that law, so none is offered there.

    Returns the data with the new columns (model :class:`.friction.LawModel`), what was applied and the
    pending replacements."""
    F = data.F
    n = data.n
    Y, J = F.system.Y, F.system.joint
    blocks = time_blocks(F.row_experiment, F.row_index, N_FOLDS)
    dq_noise = np.max([ex.dq_noise for ex in F.experiments], axis=0)
    names = list(data.decl)
    W = F.system.W
    recs: list[_LawRecord] = []
    pending: list[_LawRecord] = []
    doubtful: list[dict] = []
    scales = ArmScales.of_frame(F)
    for j in range(n):
        if j in cfg.declared_laws or not cfg.offered(j):
            continue   # the robot file declares this joint's law: kept as declared (scales refined already)
        release_freed_memory()   # the previous joint's transients (.memory)
        jf = replace(_joint_friction(F, W, names, j, float(dq_noise[j])), presliding=cfg.presliding_law)
        try:
            ch = select_friction(jf.A, Y, J, j, np.zeros(Y.size), blocks, columns=jf.cols, search=_law_search(F, jf))
        except IdentificationError:
            continue   # the joint does not move: nothing to choose
        if ch.replaced or jf.missing:
            rec, X = _law_replacement(jf, ch, F, blocks, cfg.significance / n)
            pl = law_plausibility(ch, scales, priors_only=True)
            if rec is not None and not (jf.missing or rec.smoothing) and pl.score < PLAUSIBLE:
                # a law that fits but no drive has (a Stribeck velocity below the velocity resolution, an
                # exponent far from 1: a delay or a load-dependent friction seen through the friction
                # columns) must not take first place before the loop tries the real causes: not applied,
                # reported as a doubtful alternative (docs/loop-plausibility.md)
                doubtful.append({"candidate": f"friction_law{j + 1}", "round": 0, "law": ch.describe(),
                                 "reasons": list(pl.reasons),
                                 "plausibility": {"score": float(pl.score), "reasons": list(pl.reasons)}})
                rec = None
            if rec is not None and (jf.missing or rec.smoothing):
                recs.append(rec)
                W = np.hstack([jf.A, X])
                names = jf.an + list(ch.names())
                continue
            if rec is not None:   # competes in the loop's rounds; meanwhile the joint keeps its declared law
                pending.append(rec)
        kr = _declared_law_kept(jf, ch, Y, J, blocks)
        if kr is not None:
            recs.append(kr[0])
            W, names = kr[1], kr[2]
    clear_law_columns()   # the searches' law columns and full-rate pieces (the last joint's)
    if not recs:
        return replace(data, doubtful_laws=tuple(doubtful)), (), tuple(pending)
    return replace(_apply_laws(data, recs), doubtful_laws=tuple(doubtful)), tuple(recs), tuple(pending)


def _apply_laws(data: _Data, recs: Sequence[_LawRecord]) -> _Data:
    """``data`` (the declared model's) with the friction laws ``recs`` in place of the declared ones
    (model :class:`.friction.LawModel`; both frames); ``data`` itself without any."""
    if not recs:
        return data
    law_model = LawModel(data.model, [r.choice for r in recs], [r.choice.joint for r in recs if r.offset])
    pay = tuple(nm for nm in data.decl if nm not in set(data.model.BASE_NAMES))
    new_names = tuple(law_model.BASE_NAMES) + pay
    F2 = replace(data.F, system=_with_friction_laws(data.F, data.F.system, recs, new_names))
    Vs = _with_friction_laws(data.V, data.Vs, recs, new_names)
    return replace(data, model=law_model, F=F2, Vs=Vs, decl=new_names)


@dataclass(frozen=True, eq=False)
class _JointFriction:
    """One joint in the friction-law stage: the design without its friction columns (``A``, names ``an``;
    with an offset column when it is declared without friction, ``off``), the hook building its law
    columns on the sliding velocity, its velocities at full rate and the velocity floor of ``sign``."""

    j: int
    A: np.ndarray
    an: list[str]
    missing: bool
    off: bool
    cols: Callable[[Callable[[np.ndarray], np.ndarray], int], np.ndarray]
    dq_all: np.ndarray
    vf: float
    presliding: bool = False   # the Dahl law is tried (DiagnoseSettings.presliding_law)


def _joint_friction(F: Frame, W: np.ndarray, names: list[str], j: int, dq_noise: float) -> _JointFriction:
    fs, fv = friction_column_indices(names, j)
    missing = not fs and not fv
    A = np.delete(W, fs + fv, axis=1)
    an = [nm for i, nm in enumerate(names) if i not in set(fs + fv)]
    off = missing and f"OFF{j + 1}" not in names
    if off:
        A = np.hstack([A, np.equal(F.system.joint, j).astype(float)[:, None]])
        an.append(f"OFF{j + 1}")
    dq_all = np.concatenate([e_.dq[:, j] for e_ in F.experiments])
    return _JointFriction(j, A, an, missing, off, _sliding_columns(F, j), dq_all,
                          V_FLOOR_NOISE * max(dq_noise, 1e-9))


def _sliding_columns(F: Frame, j: int) -> Callable[[Callable[[np.ndarray], np.ndarray], int], np.ndarray]:
    """The ``columns`` hook of :func:`.friction.select_friction` for joint ``j``: the laws of sliding
    friction, evaluated on the sliding velocity (0 in the joint's rest segments) at full rate. The sliding
    velocity of each experiment is computed once and kept by the hook (the searches evaluate many laws on it,
    and the friction module keeps pieces of the law columns per velocity array)."""
    vel: dict[int, np.ndarray] = {}

    def sliding(e: int, ex: Experiment) -> np.ndarray:
        v = vel.get(e)
        if v is None:
            v = vel[e] = sliding_velocity(ex, j)
            v.setflags(write=False)
        return v

    def cols(f: Callable[[np.ndarray], np.ndarray], p: int) -> np.ndarray:
        return F.full_rate_columns(lambda ex: {j: f(sliding(id(ex), ex))}, p)
    return cols


def _smoothed_declared_law(vf: float | None) -> Callable[[np.ndarray], np.ndarray]:
    """The declared law's columns, ``sign(dq)`` (smoothed at ``vf`` when given) and ``dq``."""
    def law(v: np.ndarray) -> np.ndarray:
        return np.hstack([coulomb_columns("sign", v, None, vf), viscous_columns("linear", v)])
    return law


def _declared_law_kept(jf: _JointFriction, ch: FrictionChoice, Y: np.ndarray, J: np.ndarray, blocks: np.ndarray
                       ) -> tuple[_LawRecord, np.ndarray, list[str]] | None:
    """The declared law with sign(dq) smoothed at the velocity noise floor (what the CV compared
    against): the sign of a velocity that is noise (standstill, reversals) has no meaning, and a
    chattering Coulomb column costs the most where the robot rests (TX40 j4: 0.42 vs 0.17). Where the
    CV prefers the true sign, the declared law itself (still static in the rest segments). None for a
    joint declared without friction."""
    if jf.missing:
        return None
    # only where time-blocked CV does not prefer the true sign (on clean simulated data with the
    # true law sign(dq), smoothing can cost a joint 16 % of its validation error)
    cvk = BlockedLS(jf.A, Y, blocks)
    rows = np.equal(J, jf.j)
    e_s = cvk.oof_residual(jf.cols(_smoothed_declared_law(jf.vf), 2))[rows]
    e_d = cvk.oof_residual(jf.cols(_smoothed_declared_law(None), 2))[rows]
    sm = None if float(e_s @ e_s) > float(e_d @ e_d) else jf.vf
    k = FrictionChoice(jf.j, LawFit("sign", None, ch.declared_cv_rel_err, sm),
                       LawFit("linear", None, ch.declared_cv_rel_err), ch.candidates, {}, ch.n_folds, ch.unit)
    return (_LawRecord(k, False, False, math.nan, math.nan, True), np.hstack([jf.A, jf.cols(k.columns, 2)]),
            jf.an + list(k.names()))


def _law_search(F: Frame, jf: _JointFriction) -> LawSearch:
    """The laws the friction-law stage tries on joint ``jf.j``: every static law, and (``jf.presliding``) the
    pre-sliding Dahl and LuGre laws when every experiment is sampled at one rate of :data:`.friction.DAHL_MIN_RATE_HZ` or
    more (:mod:`.friction`: below it the pre-sliding regime is not resolved)."""
    rates = {float(ex.settings.fs) for ex in F.experiments}
    laws = COULOMB_LAWS + VISCOUS_LAWS + (PRESLIDING_LAWS if jf.presliding else ())
    return LawSearch(laws=laws, v_grid=velocity_grid(jf.dq_all),
                     v_floor=jf.vf, rate_hz=rates.pop() if len(rates) == 1 else None)


def _rounds_sign_off(ch: FrictionChoice, dq_all: np.ndarray) -> bool:
    """A tanh scale below MIN_LAW_SCALE of the joint's speeds (with the linear viscous law) only rounds
    sign(dq) off where the band-pass velocity misses the true reversal or chatters at standstill (seen on
    clean simulated data too)."""
    p95 = float(np.quantile(np.abs(dq_all), 0.95))
    return (ch.viscous.law == "linear" and ch.coulomb.law == "tanh" and ch.coulomb.param is not None
            and float(ch.coulomb.param) < MIN_LAW_SCALE * p95)


def _law_replacement(jf: _JointFriction, ch: FrictionChoice, F: Frame, blocks: np.ndarray, alpha: float
                     ) -> tuple[_LawRecord | None, np.ndarray]:
    """The record of the law ``ch`` chose for the joint and its columns, or None when it does not pass the
    tests against the declared law (``alpha``: the significance level of the joint)."""
    Y, J = F.system.Y, F.system.joint
    # a rounding of sign(dq) is applied when it passes the tests below, but as a smoothing of the declared
    # sign, not as an effect
    smoothing = bool(not jf.missing and _rounds_sign_off(ch, jf.dq_all))
    X = jf.cols(ch.columns, len(ch.names()))
    cv = BlockedLS(jf.A, Y, blocks)
    e_new = cv.oof_residual(X)
    # the reference is the declared law with its sign smoothed at the noise floor (as in the CV
    # selection): smoothing sign(dq) against velocity noise at reversals is not a change of law
    e_old = cv.oof_residual(jf.cols(_smoothed_declared_law(jf.vf), 2) if not jf.missing else None)
    own = np.equal(J, jf.j)
    wins = [float(np.sum(e_new[own & (blocks == b)] ** 2)) < float(np.sum(e_old[own & (blocks == b)] ** 2))
            for b in np.unique(blocks)]
    # noise-aware acceptance: the out-of-fold gain must be consistent over time, not a few lucky
    # samples (e.g. velocity noise at reversals): paired one-sided test of the squared-error decrease
    # over N_LAW_SUBBLOCKS contiguous sub-blocks (:func:`_law_gain_p`), Bonferroni over the joints, and most
    # folds won
    sub = time_blocks(F.row_experiment, F.row_index, N_LAW_SUBBLOCKS)
    d = np.array([float(np.sum(e_old[own & (sub == b)] ** 2) - np.sum(e_new[own & (sub == b)] ** 2))
                  for b in np.unique(sub[own])])
    p_law = _law_gain_p(d, jf.missing)
    passed = float(np.mean(wins)) > MIN_SELECTION_FREQUENCY and p_law < alpha
    if passed and not (jf.missing or smoothing):
        # simulated-noise placebo (stability.simulated_noise_placebo): v, vs, delta and the law were
        # chosen on the folds that judge them; the whole selection re-run on the declared law's fit
        # plus its own residual shifted in time must never claim the observed gain (clean data, seed 510)
        passed = _law_beats_noise(ch, jf, Y, J, blocks, F)[0]
    if not passed:
        return None, X
    return _LawRecord(ch, jf.missing, jf.off, float(np.mean(wins)), p_law, smoothing), X


def _law_gain_p(d: np.ndarray, missing: bool) -> float:
    """One-sided p-value of the paired test that a friction law lowers the squared error of its joint, from the
    decreases ``d`` of the sub-blocks' sums of squared out-of-fold errors.

    A replacement of a declared law reshapes it: the decreases are of comparable size over the sub-blocks, and
    the one-sample t test of their mean applies. A joint declared *without* friction compares the law with no
    friction at all: each decrease is the square of the whole friction torque the law removes, which grows with
    the joint's speed in that sub-block, so the decreases span orders of magnitude (the hopper's knee, 16 s log:
    0.9 to 119 over 20 sub-blocks, all positive); their standard deviation grows with the effect and the t
    test loses its power just when the effect is large (p 0.006 there). The Wilcoxon signed-rank test
    (Wilcoxon 1945; Hollander & Wolfe 1999, sec. 3.1), distribution-free for differences symmetric about 0
    under the null, is used for such a joint instead (p 1e-6 there)."""
    if d.size < 2:
        return 1.0
    if missing:
        if not np.any(d != 0):
            return 1.0
        return float(sst.wilcoxon(d, alternative="greater").pvalue)
    sd = float(np.std(d, ddof=1))
    return float(sst.t.sf(float(np.mean(d)) / (sd / math.sqrt(d.size)), d.size - 1)) if sd > 0 else 1.0


def _with_friction_laws(frame: Frame, system: ObservationSystem, recs: Sequence[_LawRecord],
                        new_names: tuple[str, ...]) -> ObservationSystem:
    """``system`` with the columns of the chosen laws (and offsets) in place of the declared ones."""
    col = {nm: system.W[:, i] for i, nm in enumerate(system.names)}
    for r in recs:
        ch = r.choice
        X = frame.full_rate_columns(_sliding_law_columns(ch), len(ch.names()))
        col.update(zip(ch.names(), X.T))
        if r.offset:
            col[f"OFF{ch.joint + 1}"] = (system.joint == ch.joint).astype(float)
    return ObservationSystem(np.column_stack([col[nm] for nm in new_names]), system.Y, new_names, system.joint)


def _sliding_law_columns(ch: FrictionChoice) -> Callable[[Experiment], dict[int, np.ndarray]]:
    """The chosen laws' columns of an experiment, on the sliding velocity of the joint."""
    def columns(ex: Experiment) -> dict[int, np.ndarray]:
        return {ch.joint: ch.columns(sliding_velocity(ex, ch.joint))}
    return columns


def _law_gain(ch: FrictionChoice, dq_all: np.ndarray) -> float:
    """Relative decrease of the out-of-fold squared error a friction-law replacement claims (0 when the
    declared law is kept or the replacement is only a rounding of sign(dq), see ``MIN_LAW_SCALE``)."""
    if not ch.replaced or _rounds_sign_off(ch, dq_all):
        return 0.0
    return 1.0 - (ch.cv_rel_err / ch.declared_cv_rel_err) ** 2


def _law_beats_noise(ch: FrictionChoice, jf: _JointFriction, Y, J, blocks, F: Frame) -> tuple[bool, list]:
    """Simulated-noise placebo of a friction-law replacement on joint ``j`` (:func:`.stability.
    simulated_noise_placebo`): the declared law (sign smoothed at ``vf``) fitted on all rows, its residual
    shifted in time, the selection ``ch`` came from re-run; its gain must exceed every null one."""
    j = ch.joint
    A, cols, dq_all = jf.A, jf.cols, jf.dq_all
    Xd = cols(_smoothed_declared_law(jf.vf), 2)
    M = np.hstack([A, Xd])
    fitted = M @ np.linalg.lstsq(M, Y, rcond=None)[0]
    search = _law_search(F, jf)

    def gain(y):
        # a replicate's gain needs the choice and its CV errors only, not the chosen laws' coefficients
        return _law_gain(select_friction(A, y, J, j, np.zeros(Y.size), blocks, columns=cols, search=search,
                                         coefficients=False), dq_all)
    return simulated_noise_placebo(gain, fitted, Y - fitted, J * 100000 + F.row_experiment, F.row_experiment,
                                   _law_gain(ch, dq_all), rng=np.random.default_rng(7919 + j))


#: candidate kinds of sliding friction (:mod:`.candidates`): built on the sliding velocity, 0 at rest
SLIDING_KINDS = ("stribeck", "load_friction")


def _static_at_rest_family(fam: Family) -> Family:
    """``fam`` with its columns built on the sliding velocity (:func:`.friction.sliding_frame`): 0 in the
    rest segments of its joint, as the friction laws (the Stribeck dip and the load-dependent Coulomb
    friction are laws of sliding)."""
    build, build_at = fam.build, fam.build_at

    def b(fr, ctx, build=build):
        return build(sliding_frame(fr), ctx)
    b_at = None if build_at is None else (lambda fr, ctx, value, build_at=build_at: build_at(sliding_frame(fr), ctx, value))
    return replace(fam, build=b, build_at=b_at)


def _static_at_rest(data: _Data, V: Frame, laws: Sequence[_LawRecord]) -> list[str]:
    """Per joint with a friction law and any rest: share of the identification and validation samples in
    rest segments (where the law is static, predicted 0)."""
    out = []
    for r in laws:
        j = r.choice.joint
        shares = []
        for fr in (data.F, V):
            tot = sum(ex.n_samples for ex in fr.experiments)
            shares.append(sum(int(rest_mask(ex)[:, j].sum()) for ex in fr.experiments) / max(tot, 1))
        if not any(shares):
            continue
        if r.prior:
            out.append(f"joint {j + 1}: sliding friction static (0) in rest segments, untested (the identification "
                       f"data never rest): {100 * shares[1]:.1f} % of the validation samples rest, outside the "
                       "identification data's domain; the static torque there lies anywhere in [-Fs, Fs] and 0 "
                       "is the prediction of least worst-case error")
            continue
        out.append(f"joint {j + 1}: sliding friction static (0) in rest segments: {100 * shares[0]:.1f} % of the "
                   f"identification samples, {100 * shares[1]:.1f} % of the validation samples")
    return out


#: kind of the loop's candidates that are pending friction-law replacements (:func:`_law_family`)
LAW_KIND = "friction_law"


def _law_columns(ch: FrictionChoice) -> tuple[list[int], tuple[str, ...]]:
    """The columns of the law ``ch`` (indices into :meth:`.friction.FrictionChoice.columns`) that are not the
    declared law's, with their short names: the tanh column, the Stribeck dip ``exp(-(dq/vs)^2) sign(dq)``, the
    power viscous column. Added beside the declared ``sign(dq)`` and ``dq`` columns they span the
    replacement (the Stribeck law's own ``sign(dq)`` is the declared column, smoothed alike)."""
    idx: list[int] = []
    params: list[str] = []
    if ch.coulomb.law == "tanh":
        idx.append(0)
        params.append("FSt")
    elif ch.coulomb.law == "stribeck":
        idx.append(1)
        params.append("FSS")
    elif ch.coulomb.law == "dahl":
        idx.append(0)
        params.append("FSd")
    elif ch.coulomb.law == "lugre":   # the Dahl state and its Stribeck dip (friction.lugre_columns)
        idx += [0, 1]
        params += ["FSl", "FSSl"]
    if ch.viscous.law == "power":
        idx.append(len(ch.names()) - 1)
        params.append("FVp")
    return idx, tuple(params)


def _law_family(rec: _LawRecord) -> Family:
    """A pending friction-law replacement as a candidate family of the loop's rounds (kind :data:`LAW_KIND`,
    one member, fixed columns :func:`_law_columns` on the sliding velocity at full rate): scored by the same
    :class:`_Scorer` on the same acceptance data as every other family, ranked with them by :func:`_rank`."""
    ch = rec.choice
    idx, params = _law_columns(ch)
    p = len(ch.names())

    def build(fr, ctx, ch=ch, idx=idx, p=p):
        return [fr.full_rate_columns(_sliding_law_columns(ch), p)[:, idx]]
    return Family(LAW_KIND, ch.joint, params, build, variant=f"{ch.coulomb.label}+{ch.viscous.label}", reveal="dq",
                  reveal_joint=ch.joint, info=((LAW_KIND, ch.joint),))


def _stage_baseline(data0: _Data, data: _Data, laws: tuple[_LawRecord, ...], cfg: DiagnoseSettings) -> _Baseline:
    """Stage 2: identify the declared model (``cfg.method``) and its validation error ("before", on
    ``data0``), the model with the friction laws chosen (the loop's start, on ``data``), the candidate
    families and the nuisance columns (velocity noise at Coulomb reversals)."""
    res0 = _fit(data0.F.system, cfg.method)
    val0 = res0.rel_err_on(data0.Vs)
    # the loop starts from the selection estimator's fit (the named effects do not depend on cfg.method)
    # (on the loop's own data: the leading part of the identification experiments)
    res_start = _fit(data.F.system, SELECT_METHOD)
    families = make_families(data.F, cfg.candidates, model=data.model)
    # (a family that declares its rows, a contact sensor's, acts where its model says: on the base rows too)
    families = [f for f in families if f.rows is not None or all(cfg.offered(j) for j in _affected(f, data.n))]
    # a joint whose friction-law stage chose a Stribeck law already has the Stribeck column: the loop's
    # Stribeck candidate there would be the same column at a neighbouring vs (collinear, the two
    # coefficients then split the effect between them with opposite signs)
    stribeck_law = {r.choice.joint for r in laws if not r.smoothing and r.choice.coulomb.law in ("stribeck", "lugre")}
    # ... and so has a joint whose declared law (robot file: stribeck, lugre) carries FSS<j>
    stribeck_law |= {j for j in cfg.declared_laws if f"FSS{j + 1}" in data.decl}
    families = [f for f in families if not (f.kind == "stribeck" and f.joint in stribeck_law)]
    # a joint declared elastic in the robot file is modelled as such: no elasticity candidate for it
    families = [f for f in families if not (f.kind == "elasticity" and f.joint in cfg.declared_elastic)]
    # sliding-friction candidates are static (0) in the rest segments, like the friction laws
    # and so is the shared motor's Coulomb friction sign(dq_j + dq_k) of a coupled pair: built on the
    # sliding velocities, it is 0 where both joints rest (was the sign of their velocity noise there)
    families = [_static_at_rest_family(f) if (f.kind in SLIDING_KINDS or (f.kind == "coupling" and f.variant == "shared"))
                else f for f in families]
    dq_noise = np.max([ex.dq_noise for ex in data.F.experiments], axis=0)
    N_id = nuisance_columns(data.F, data.decl, dq_noise)
    N_v = nuisance_columns(data.V, data.decl, dq_noise)
    N_id, N_v = _physical_nuisance(data.F, N_id, N_v)
    return _Baseline(res0=res0, val0=np.asarray(val0), res_start=res_start, laws=laws, families=tuple(families),
                     N_id=N_id, N_v=N_v,
                     nuisance_names=tuple(f"_nuisance{i}" for i in range(N_id.shape[1])))


#: a nuisance column is kept while its coefficient stays within this many torque ranges of its joint: an order of
#: magnitude above anything physical (its coefficient is the joint's Coulomb friction). At 1x the range the rule
#: also dropped columns whose coefficient is large but that still absorb reversal artefacts (the LWR4's joint 1 at
#: 9.6x in the load-dependent-friction case of the truth bench, which then lost its effect): the bound only
#: removes the columns that fit noise on one or two rows (-718 N m, 80x, for joint 3 of the elastic case)
NUISANCE_RANGE_FACTOR = 10.0


def _physical_nuisance(F: Frame, N_id: np.ndarray, N_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nuisance columns whose coefficient, fitted with the declared model on the identification data, is
    physical: a column stands for the error velocity noise gives the Coulomb term of its joint, so its
    coefficient is that joint's Coulomb friction, far below :data:`NUISANCE_RANGE_FACTOR` times the joint's
    torque range (the 98th percentile of |Y_j|). At a high sampling rate and low velocity noise the smoothed-sign gap of a joint can be a spike of one
    or two decimated rows; a free column there fits those rows at any coefficient (about -700 N m for the LWR4's
    joint 3 at 500 Hz, whose Coulomb friction is 0.4 N m and torque range 9 N m), and a candidate that touches
    the rows swings it by a thousand, changing the joint's predicted acceptance torque at every reversal (an
    elastic joint 4 then predicted joint 3's acceptance data worse than nothing). Such a column is left out."""
    if N_id.shape[1] == 0:
        return N_id, N_v
    Y, J = F.system.Y, F.system.joint
    coef = np.linalg.lstsq(np.hstack([F.system.W, N_id]), Y, rcond=None)[0][-N_id.shape[1]:]
    keep = np.zeros(N_id.shape[1], bool)
    for i in range(N_id.shape[1]):
        j = int(J[int(np.argmax(np.abs(N_id[:, i])))])   # the joint on whose rows the column lies
        keep[i] = abs(float(coef[i])) <= NUISANCE_RANGE_FACTOR * float(np.quantile(np.abs(Y[np.equal(J, j)]), 0.98))
    return N_id[:, keep], N_v[:, keep]


def _stage_score(data: _Data, base: _Baseline, state: _State, rnd: int, cfg: DiagnoseSettings,
                 rng: np.random.Generator, laws_only: bool = False) -> _Round:
    """Stage 3: score every candidate family not yet added, the pending friction laws (:func:`_law_family`)
    and the placebos, against the current design (:class:`_Scorer`); decide which candidates are eligible
    (p-value, validation z, validation gain of their own joints, better than every placebo of their joints).
    ``laws_only``: the loop's effects reached ``max_effects``, only the pending laws compete (they come on
    top of it, as when the friction-law stage applied them before the loop)."""
    n = data.n
    F, V = state.F, state.V
    Y, J = F.system.Y, F.system.joint
    names, A, Av = _augmented(data, state.added)
    resid_user = Y - A @ np.array([state.res.value(nm) for nm in names])
    D = _design(names + base.nuisance_names, np.hstack([A, base.N_id]), Y, J, np.hstack([Av, base.N_v]),
                data.Vs.Y, data.Vs.joint, n, w_resid=resid_user)
    del A, Av, resid_user   # D holds the design with the nuisance columns: no second copy while scoring
    ctx = _context(data, F, V, names, D.theta[:len(names)])
    scorer = _Scorer(D, F, V, n, cfg.identifiability_tol, max(MIN_SUPPORT_ROWS, MIN_SUPPORT_SHARE * F.n_rows / n))
    done = {ad.family.key for ad in state.added}
    stopped = state.stopped_joints
    fams = [] if laws_only else [f for f in base.families
                                 if f.key not in done and not (set(_own(f, n)) & stopped and f.joint is not None)]
    fams += [_law_family(r) for r in state.pending if r.choice.joint not in stopped]
    plac = placebo_families(F, rng, cfg.n_placebo) if cfg.n_placebo > 0 else []
    evals = []
    bar = progress_bar(len(fams) + len(plac), f"diagnose: round {rnd}", unit="candidate")
    for fam in fams + plac:
        bar.update(1)
        Xs = fam.build(F, ctx)
        Xvs = fam.build(V, ctx)
        best: _Eval | None = None
        reasons: list[str] = []
        for i, (X, Xv) in enumerate(zip(Xs, Xvs)):
            one = scorer.evaluate(X, Xv)
            if isinstance(one, str):
                reasons.append(one)
                continue
            one.member = i
            if _better_member(one, best):
                best = one
        if best is not None:
            best.p_value = bonferroni(best.p_value, fam.n_members)
        # only the best member's columns are kept for the round (an eligible candidate's design): the
        # other members of a grid, and the placebos', are dropped as soon as scored
        m = best.member if best is not None and not fam.placebo else None
        evals.append((fam, best, reasons[0] if reasons and best is None else "",
                      None if m is None else Xs[m], None if m is None else Xvs[m]))
        del Xs, Xvs
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

    eligible: list[tuple] = []
    tried: list[CandidateScore] = []
    placebos: list[CandidateScore] = []
    hits: list[tuple[int | None, int, str, float]] = []
    for fam, ev, why, X_best, Xv_best in evals:
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
                    reason.append(f"acceptance gain {100 * gain:.2f} % < {100 * cfg.min_rel_improvement:g} %")
                few = _few_acceptance_rows(V, own)
                if few:
                    reason.append(few)
                pp, pz = placebo_bounds(own)
                if not reason and (ev.p_value >= pp or ev.z <= pz):
                    reason.append("not better than a placebo")
            cs = CandidateScore(rnd, fam.kind, fam.label, fam.joint, fam.partner, fam.variant, ev.score,
                                ev.p_value, ev.z, thr, ev.ident, not reason and not fam.placebo,
                                "; ".join(reason), search, tuple(float(x) for x in ev.rel_before),
                                tuple(float(x) for x in ev.rel_after), score_se=ev.score_se)
            if cs.eligible:
                eligible.append((ev.score, fam, ev, X_best, Xv_best, cs))
        (placebos if fam.placebo else tried).append(cs)
        if (fam.placebo and ev is not None and ev.p_value < thr and ev.z > zcrit
                and gain_of(ev, _own(fam, n)) >= cfg.min_rel_improvement):
            hits.append((fam.joint, rnd, fam.variant, ev.score))
    if cfg.composed and not laws_only:
        c_tried, c_elig = _score_composed_round(data, base, state, D, ctx, scorer, rnd, cfg, placebo_bounds, gain_of)
        tried += c_tried
        eligible += c_elig
    # placebo stop (stability stage): a joint where a placebo column passed the tests is closed for the
    # rest of the loop, unless a candidate of that joint beat every placebo of it in this round
    owned = {j for _, fam, *_ in eligible for j in _own(fam, n)}
    new_stop = frozenset(int(j) for j, *_ in hits if j is not None and j not in owned and j not in stopped)
    eligible = [e for e in eligible if e[1].joint is None or not (set(_own(e[1], n)) & (stopped | new_stop))]
    eligible, tried = _simplest_within_se(_rank(eligible), tried, n)
    return _Round(tried=tuple(tried), placebos=tuple(placebos), placebo_hits=tuple(hits), eligible=tuple(eligible),
                  ctx=ctx, scorer=scorer, stopped=new_stop)


#: scores that agree to this relative tolerance are one fit under two names (see :func:`_rank`)
TIE_RTOL = 1e-9


def _rank(eligible: list) -> list:
    """The eligible candidates of a round, best score first.

    Candidates whose scores agree to :data:`TIE_RTOL` of the better one are the same fit under two names: a
    composed candidate whose columns span a plain kind's (``constant torque changing with tau_hat`` is the
    column ``tau_hat``, i.e. a ``gain``). Among them the plain, named kind goes first, so that the verdict
    does not hang on the last bits of the two scores (which differ between BLAS builds).
    """
    eligible = sorted(eligible, key=lambda t: -t[0])
    out: list = []
    i = 0
    while i < len(eligible):
        lead = eligible[i][0]
        j = i + 1
        while j < len(eligible) and eligible[j][0] >= lead - TIE_RTOL * abs(lead):
            j += 1
        out += sorted(eligible[i:j], key=lambda t: "composed" in dict(t[1].info))   # stable: plain first
        i = j
    return out


#: contiguous time blocks per experiment of the acceptance data for the standard error of a candidate's score
#: (:meth:`_Scorer.score_se`)
N_SCORE_BLOCKS = 10


def _n_params(fam: Family, X: np.ndarray, cs: CandidateScore) -> int:
    """Parameters a candidate fits: its columns' coefficients and its searched parameters (an order, a
    velocity scale, a step time); a friction-law replacement has one searched shape parameter (tanh ``v``,
    Stribeck ``vs``, Dahl ``vp``, power ``delta``) per column (:func:`_law_columns`)."""
    if fam.kind == LAW_KIND:
        return 2 * int(X.shape[1])
    return int(X.shape[1]) + len(cs.search)


def _simplest_within_se(eligible: list, tried: list, n: int) -> tuple[list, list]:
    """The one-standard-error rule (Hastie, Tibshirani & Friedman 2009, *The Elements of Statistical
    Learning*, sec. 7.10; Breiman et al. 1984): among the eligible candidates whose acceptance score is within
    one standard error of the best's - the standard error of the paired difference of the two scores over the
    acceptance time blocks (:meth:`_Scorer.score_blocks`, as the friction-law stage's rule in
    :mod:`.friction`: both scores are read on the same rows) - and that compete with it for the
    same residual (their own joints overlap the best's, :func:`_own`), the one with the fewest parameters
    (:func:`_n_params`; ties by score) goes first - a smaller answer beats a larger curve fit when the held-out
    data cannot tell them apart. A candidate of other joints is no rival: it competes in the next round. The chosen candidate's record says over which (``chosen_over``);
    ``eligible`` is ranked (:func:`_rank`), ``tried`` holds the same records."""
    if len(eligible) < 2:
        return eligible, tried
    s0, d0 = eligible[0][0], eligible[0][2].score_blocks
    if d0 is None:
        return eligible, tried
    own0 = set(_own(eligible[0][1], n))
    se = [math.inf if e[2].score_blocks is None else _block_se(d0 - e[2].score_blocks) for e in eligible]
    near = [i for i, e in enumerate(eligible) if e[0] >= s0 - se[i] and own0 & set(_own(e[1], n))]
    k = [_n_params(e[1], e[3], e[5]) for e in eligible]
    pick = min(near, key=lambda i: (k[i], -eligible[i][0], i))
    if pick == 0 or k[pick] >= k[0]:
        return eligible, tried
    se0 = se[pick]
    cs0, cs = eligible[0][5], eligible[pick][5]
    note = (f"chosen over {cs0.label}{' ' + cs0.variant if cs0.variant else ''} (score {s0:.3f} vs {cs.score:.3f}, "
            f"within 1 SE {se0:.3f} of the difference; {k[pick]} vs {k[0]} parameters)")
    new = replace(cs, chosen_over=note)
    tried = [new if c is cs else c for c in tried]
    lead = eligible[pick][:5] + (new,)
    return [lead] + [e for i, e in enumerate(eligible) if i != pick], tried


#: non-significant composed candidates kept in the report per round (the best by adjusted p-value)
N_COMPOSED_REPORTED = 10


def _row_sig(fr: Frame) -> RowSignals:
    """Decimated signals of every joint at each row of ``fr`` (with the current model torque)."""
    return RowSignals(fr.system.joint, fr.sig["t"], fr.sig["q"], fr.sig["dq"], fr.sig["ddq"], fr.sig.get("tau_hat"))


def _composed_variant(c: Composed) -> str:
    return f"q_other:q{(c.source or 0) + 1}" if c.signal == "q_other" else c.signal


def _composed_family(c: Composed, plain: bool) -> Family:
    """A composed candidate as a family of the loop: its modulated columns (``c`` with its standardisation
    fixed on the identification rows), and the plain effect's columns when the model lacks them."""
    names = c.names() + (tuple(f"{nm.split('*')[0]}_plain" for nm in c.names()) if plain else ())

    p = len(c.names()) * (2 if plain else 1)

    def full(ex, c=c, plain=plain):
        M = ex.n_samples
        dq = ex.dq
        if c.effect == "coulomb":   # sliding friction: static (0) in the joint's rest segments
            dq = ex.dq.copy()
            dq[:, c.joint] = sliding_velocity(ex, c.joint)
        sig = RowSignals(np.full(M, c.joint), ex.t, ex.q, dq, ex.ddq, ex.tau_hat)
        X = c.columns(sig)
        return {c.joint: np.hstack([X, c.plain_columns(sig)]) if plain else X}

    def build(fr, ctx):
        # evaluated at full rate and decimated in parallel with W (exact, like the plain candidates)
        return [fr.full_rate_columns(full, p)]
    reveal = {"time": "t", "step": "t", "q_own": "q", "q_other": "q", "abs_tau": "tau_hat", "tau": "tau_hat",
              "abs_dq": "dq", "temperature": "t"}.get(c.signal, "t")
    return Family(c.effect, c.joint, names, build, variant=_composed_variant(c), reveal=reveal,
                  reveal_joint=c.source if c.signal == "q_other" else c.joint,
                  depends_on_fit=c.signal in ("abs_tau", "tau"), info=(("composed", c), ("plain", plain)))


def _composed_physical(c: Composed, F: Frame, vals: np.ndarray) -> dict[str, float]:
    """The physical reading of a composed effect with coefficients ``vals`` (its family's names): its ripple order
    or step time, and its magnitude on the rows of ``F`` (:meth:`.compose.Composed.magnitude`, rated by
    :func:`.plausibility.effect_plausibility` against its plain kind's prior)."""
    out = ({"order": float(c.order)} if c.order is not None else {}) | (
        {"t_step": float(c.step_time)} if c.step_time is not None else {})
    return out | c.magnitude(_row_sig(F), vals)


def _composed_v(base: _Baseline, F: Frame) -> list[float]:
    """Velocity scale of the smooth Coulomb effect of each joint: the chosen law's, else the noise floor."""
    dq_noise = np.max([ex.dq_noise for ex in F.experiments], axis=0)
    v = [V_FLOOR_NOISE * max(float(x), 1e-9) for x in dq_noise]
    for r in base.laws:
        c = r.choice.coulomb
        if c.law == "tanh" and c.param:
            v[r.choice.joint] = float(c.param)
        elif c.smooth:
            v[r.choice.joint] = float(c.smooth)
    return v


def _plain_missing(D: _Design, P: np.ndarray, tol: float) -> bool:
    """The plain effect's columns ``P`` have a share > ``tol`` of their (weighted) norm outside the model."""
    Pw = P * D.w[:, None]
    nrm = np.sqrt(np.einsum("ij,ij->j", Pw, Pw))
    if not np.all(nrm > 0):
        return False
    Aw = D.A * D.w[:, None]
    Pp = Pw - Aw @ np.linalg.lstsq(Aw, Pw, rcond=None)[0]   # least squares, not D.U: exact for ill-conditioned A
    return bool(np.min(np.sqrt(np.einsum("ij,ij->j", Pp, Pp)) / nrm) > tol)


def _few_acceptance_rows(V: Frame, joints) -> str:
    """The reason a change of joints ``joints`` is not eligible on the acceptance frame ``V`` (fewer than
    :data:`MIN_ACCEPTANCE_ROWS` rows on one of them), or ''."""
    counts = np.bincount(np.asarray(V.system.joint, int), minlength=V.n_joints)
    few = [(j, int(counts[j])) for j in joints if counts[j] < MIN_ACCEPTANCE_ROWS]
    if not few:
        return ""
    j, k = few[0]
    return f"{k} acceptance rows on joint {j + 1} < {MIN_ACCEPTANCE_ROWS}"


def _score_composed_round(data: _Data, base: _Baseline, state: _State, D: _Design, ctx: FitContext, scorer: _Scorer,
                          rnd: int, cfg: DiagnoseSettings, placebo_bounds, gain_of) -> tuple[list, list]:
    """Composed candidates (effect x modulating signal, :mod:`.compose`) of one round.

    Every family of the library (joints not stopped, not added yet) is tested on the identification rows
    against the current design (declared model, friction laws, effects added, nuisance columns; the plain
    effect partialled out) by :func:`.compose.score_composed`: HAC Wald test, Bonferroni over each family's
    grid, Holm over the families at ``cfg.significance``. The significant ones are then scored on the
    validation data like any candidate; eligible when ``z`` exceeds the Bonferroni critical value over
    the composed families tested, the validation error of their joint drops by ``min_rel_improvement``
    and they beat every placebo of their joint."""
    n = data.n
    F, V = state.F, state.V
    Y, J = F.system.Y, F.system.joint
    sigF = _row_sig(F)
    done = {ad.family.key for ad in state.added}
    lib = composed_library(sigF, joints=[j for j in range(n) if j not in state.stopped_joints],
                           coulomb_v=_composed_v(base, F))
    lib = [fam for fam in lib if fam and (fam[0].effect, fam[0].joint, None, _composed_variant(fam[0])) not in done]
    if not lib:
        return [], []
    results = score_composed(D.A, Y, sigF, weights=D.w, groups=J * 100000 + F.row_experiment, alpha=cfg.significance,
                             families=lib)
    zcrit = float(sst.norm.isf(cfg.significance / max(len(lib), 1)))
    tried, eligible = [], []
    n_rep = 0
    for r in results:
        c = r.candidate.standardised_on(sigF)
        search = {"order": c.order} if c.order is not None else {}
        if c.step_time is not None:
            search["t_step"] = c.step_time
        if not r.significant:
            if n_rep < N_COMPOSED_REPORTED:
                n_rep += 1
                tried.append(CandidateScore(rnd, c.effect, r.description, c.joint, None, _composed_variant(c), None,
                                            r.p_adjusted, None, cfg.significance, 0.0, False,
                                            f"Holm-adjusted p {r.p_adjusted:.1e} >= {cfg.significance:g} "
                                            f"({len(lib)} composed families)", search))
            continue
        fam = _composed_family(c, True)
        X, Xv = fam.build(F, ctx)[0], fam.build(V, ctx)[0]
        m = len(c.names())
        if not _plain_missing(D, X[:, m:], cfg.identifiability_tol):
            fam, X, Xv = _composed_family(c, False), X[:, :m], Xv[:, :m]
        ev = scorer.evaluate(X, Xv)
        if isinstance(ev, str):
            tried.append(CandidateScore(rnd, c.effect, r.description, c.joint, None, fam.variant, None, r.p_adjusted,
                                        None, cfg.significance, 0.0, False, ev, search))
            continue
        ev.p_value = r.p_adjusted
        own = [c.joint]
        gain = gain_of(ev, own)
        reason = []
        if ev.z <= zcrit:
            reason.append(f"z_val {ev.z:.1f} <= {zcrit:.1f}")
        if gain < cfg.min_rel_improvement:
            reason.append(f"acceptance gain {100 * gain:.2f} % < {100 * cfg.min_rel_improvement:g} %")
        few = _few_acceptance_rows(V, own)
        if few:
            reason.append(few)
        _, pz = placebo_bounds(own)
        if not reason and ev.z <= pz:
            reason.append("not better than a placebo")
        cs = CandidateScore(rnd, c.effect, r.description, c.joint, None, fam.variant, ev.score, r.p_adjusted, ev.z,
                            cfg.significance, ev.ident, not reason, "; ".join(reason), search,
                            tuple(float(x) for x in ev.rel_before), tuple(float(x) for x in ev.rel_after),
                            score_se=ev.score_se)
        tried.append(cs)
        if cs.eligible:
            eligible.append((ev.score, fam, ev, X, Xv, cs))
    return tried, eligible


def _stage_accept(data: _Data, state: _State, scored: _Round, rnd: int, cfg: DiagnoseSettings,
                  pick: int = 0) -> _State:
    """Stage 4 (accept, refine, re-identify): add the eligible candidate ``pick`` (0: the best; its searched
    parameter refined continuously), re-identify with :data:`SELECT_METHOD` (whatever ``cfg.method``: the
    loop's path must not depend on the estimator) and re-linearise the effects that depend on the fit
    (fixed point, :data:`RELINEARISE_PASSES`)."""
    F, V = state.F, state.V
    Y = F.system.Y
    _, fam, ev, X, Xv, _cs = scored.eligible[pick]
    value = fam.grid[ev.member] if fam.grid else None
    if fam.build_at is not None and fam.grid:   # (a secant without a grid, joint_zero: its fixed point only)
        value = _refine(fam, ev.member, F, scored.ctx, scored.scorer)
        X, Xv = fam.build_at(F, scored.ctx, value), fam.build_at(V, scored.ctx, value)
    added = state.added + (_Added(fam, value, X, Xv),)
    meta = dict(family=fam, value=value, score=ev.score, p=ev.p_value, z=ev.z, round=rnd,
                chosen_over=_cs.chosen_over)
    F, V, added, res, names, A, Av = _refit(data, F, V, added)
    th = np.array([res.value(nm) for nm in names])
    return replace(state, F=F, V=V, added=added, res=res, effects_meta=state.effects_meta + (meta,),
                   round_resid=state.round_resid + ((Y - A @ th, data.Vs.Y - Av @ th),))


def _stage_loop(data0: _Data, data: _Data, base: _Baseline, cfg: DiagnoseSettings, rng: np.random.Generator,
                pending: Sequence[_LawRecord] = ()) -> tuple[_Data, _Baseline, _State]:
    """Stages 3-4 repeated: score, accept the best, re-identify, until nothing is eligible or ``max_effects``.

    The friction-law stage's pending replacements (``pending``) compete in every round with the other
    candidates; when one wins, it is applied (:func:`_apply_laws` on ``data0``, the loop's data without any
    law) and the loop goes on from the re-identified model. A pending law is judged in each round by the
    round's own eligibility on the current design (a law that only absorbed a delay or a gain error has no
    acceptance gain left once that effect is added). Retiring a pending law on a re-run of its cross-validation
    tests after each effect dropped the TX40's joint-1 law (validation error 0.080 with it, 0.180 without) once
    a joint-2 effect was added. The rounds a law wins do not count against ``max_effects``. Returns the data and baseline with the laws applied, and the loop's state."""
    F, V, added = _relinearise(data, data.F, data.V, (), base.res_start)
    state = _State(F=F, V=V, added=added, res=base.res_start, pending=tuple(pending),
                   round_resid=((_residual_of(base.res_start), data.Vs.Y - base.res_start.predict(data.Vs)),))
    del F, V, added   # held by the state only: a later round's state lets them go
    n_eff = 0
    scales = replace(ArmScales.of_frame(data.F), f_max=data.fdyn)
    for rnd in range(1, cfg.max_effects + len(pending) + 1):
        laws_only = n_eff >= cfg.max_effects
        if laws_only and not state.pending:
            break
        # the elasticity columns' cache holds the previous round's frames, whose fit contexts no round uses again
        clear_elasticity_cache()
        release_freed_memory()   # the previous round's transients (.memory)
        scored = _stage_score(data, base, state, rnd, cfg, rng, laws_only=laws_only)
        state = replace(state, tried=state.tried + scored.tried, placebos=state.placebos + scored.placebos,
                        placebo_hits=state.placebo_hits + scored.placebo_hits,
                        stopped_joints=state.stopped_joints | scored.stopped)
        if not scored.eligible:
            return data, base, replace(state, stopped_at_max=n_eff >= cfg.max_effects)
        # an implausible best candidate gives way to a plausible one that explains the same residual
        first, passed, trials = _plausible_pick(data, state, scored, rnd, cfg, scales)
        if passed is not None:
            state = replace(state, implausible=state.implausible + (passed,))
        if first is None:
            return data, base, replace(state, stopped_at_max=n_eff >= cfg.max_effects)
        if scored.eligible[first][1].kind == LAW_KIND:
            data, base, state = _accept_law(data0, data, base, state, scored.eligible[first][1].joint, rnd)
            del scored, trials   # the round's frames (model torque at full rate) before the next round's
            continue
        new, rejected = _first_possible(data, state, scored, rnd, cfg, first, trials)
        # the round's scorer and trial fits hold frames with their own model torque at full rate (three
        # arrays of the recording's size each): dropped before the next round builds its own (.memory)
        del scored, trials
        state = replace(state if new is None else new,
                        implausible=state.implausible + tuple(rejected))
        if new is None:
            return data, base, state
        n_eff += 1
    return data, base, replace(state, stopped_at_max=n_eff >= cfg.max_effects)


def _first_possible(data: _Data, state: _State, scored: _Round, rnd: int, cfg: DiagnoseSettings, first: int,
                    trials: dict[int, _State]) -> tuple[_State | None, list[dict]]:
    """The state with the best eligible candidate (``first``, then the others by score) whose re-identified
    model leaves every effect physically possible (:func:`.candidates.implausible`: e.g. a gain and a delay of
    one joint fitted jointly into a negative scale and a 0.4 s lead), None when there is none; the ones passed
    over, as records for ``implausible``. ``trials`` holds the re-identifications already computed."""
    rejected: list[dict] = []
    order = [first] + [k for k in range(min(len(scored.eligible), MAX_IMPLAUSIBLE_TRIES)) if k != first]
    for pick in order:
        if scored.eligible[pick][1].kind == LAW_KIND:
            continue
        trial = trials.get(pick) or _stage_accept(data, state, scored, rnd, cfg, pick=pick)
        why = _implausible_effects(data, trial.added, trial.res)
        if not why:
            return trial, rejected
        rejected.append({"candidate": scored.eligible[pick][1].label, "round": rnd, "reasons": why})
    return None, rejected


def _accept_law(data0: _Data, data: _Data, base: _Baseline, state: _State, joint: int, rnd: int
                ) -> tuple[_Data, _Baseline, _State]:
    """The pending friction law of ``joint`` applied after it won round ``rnd`` (in place of the joint's
    declared law or its sign smoothing): the data with the law's columns, the baseline's laws (and no loop
    Stribeck candidate on a joint whose law is Stribeck: the same column at a neighbouring vs), the model
    re-identified with the effects added so far."""
    rec = next(r for r in state.pending if r.choice.joint == joint)
    rec = replace(rec, round=rnd)
    laws = tuple(r for r in base.laws if r.choice.joint != joint) + (rec,)
    data = replace(_apply_laws(data0, laws), doubtful_laws=data.doubtful_laws)
    fams = base.families
    if rec.choice.coulomb.law in ("stribeck", "lugre"):
        fams = tuple(f for f in fams if not (f.kind == "stribeck" and f.joint == joint))
    base = replace(base, laws=laws, families=fams)
    F, V, added, res, _, _, _ = _refit(data, data.F, data.V, state.added)   # frames with the new columns
    return data, base, replace(state, F=F, V=V, added=added, res=res,
                               pending=tuple(r for r in state.pending if r.choice.joint != joint))


#: eligible candidates tried per round before the loop stops when each makes an effect implausible
MAX_IMPLAUSIBLE_TRIES = 5


def _candidate_rating(data: _Data, state: _State, scored: _Round, rnd: int, cfg: DiagnoseSettings, k: int,
                      scales: ArmScales) -> tuple[Plausibility | None, str, _State | None]:
    """The plausibility of the eligible candidate ``k`` of a round as :func:`.plausibility.rate_effects` would
    rate it once added, its reading in words (:func:`.plausibility.fits_like`) and its trial state (the model
    re-identified with it; None for a pending friction law). A friction law is rated on its choice
    (:func:`.plausibility.law_plausibility`), any other effect on its parameters in the re-identified model
    (:func:`.plausibility.effect_plausibility`); the rating is None when the trial leaves an effect physically
    impossible (:func:`_implausible_effects`: the loop's own fallback passes it over)."""
    fam = scored.eligible[k][1]
    if fam.kind == LAW_KIND:
        ch = next(r.choice for r in state.pending if r.choice.joint == fam.joint)
        return law_plausibility(ch, scales), f"joint {fam.joint + 1}'s friction law ({ch.describe()})", None
    trial = _stage_accept(data, state, scored, rnd, cfg, pick=k)
    if _implausible_effects(data, trial.added, trial.res):
        return None, fam.label, trial
    comp = dict(fam.info).get("composed")
    vals = np.array([trial.res.value(nm) for nm in fam.names()])
    if comp is not None:   # a composed effect: its magnitude against its plain kind's prior
        phys = _composed_physical(comp, trial.F, vals)
        pl = effect_plausibility(fam.kind, fam.joint, {}, phys, scales, variant=fam.variant,
                                 modulation=comp.modulation)
        return pl, fits_like(fam.kind, fam.joint, phys, comp.describe(vals[:len(comp.names())])), trial
    ad = trial.added[-1]
    std = np.array([trial.res.std[trial.res.index(nm)] for nm in fam.names()])
    phys = describe_params(fam, ad.value, vals, std)
    delays = [a.family.joint for a in trial.added if a.family.kind == "time_delay"
              and dict(a.family.info).get("composed") is None]
    pl = effect_plausibility(fam.kind, fam.joint, dict(zip(fam.params, (float(v) for v in vals))), phys, scales,
                             variant=fam.variant, delay_joints=delays)
    if fam.kind == "time_delay" and not delay_is_absurd(float(phys.get("delay_s", 0.0)), scales):
        # a delay is at worst doubtful unless absurd (plausibility._delay_verdict): never passed over here
        pl = Plausibility(max(pl.score, PLAUSIBLE), pl.reasons, pl.check)
    one = fam.kind == "time_delay" and fam.joint is not None and data.n > 1 and all(x == fam.joint for x in delays)
    return pl, fits_like(fam.kind, fam.joint, phys, fam.label, one_joint_delay=one), trial


def _plausible_pick(data: _Data, state: _State, scored: _Round, rnd: int, cfg: DiagnoseSettings,
                    scales: ArmScales) -> tuple[int | None, dict | None, dict[int, _State]]:
    """The eligible candidate of a round to add first: the best, unless it would be rated implausible
    (plausibility below :data:`.plausibility.PLAUSIBLE`, :func:`_candidate_rating`) and an eligible plausible
    candidate on its joints explains the same residual (:func:`.plausibility.explains_same`, the rule by which
    :func:`.plausibility.verdict` rejects an effect): then that one - an effect is named as a cause only when
    it is physically plausible and beats its alternatives on held-out data, a smaller true answer beats a
    larger curve fit (``docs/loop-plausibility.md``). An implausible best with no plausible alternative is still
    added first (and rated doubtful), unless its kind is in :data:`NOT_ADDED_WHEN_IMPLAUSIBLE` (then the next
    candidate, None when there is none). Returns the index, the passed-over candidate's record for
    ``implausible`` (None when the best is kept) and the trial states computed (index -> state)."""
    trials: dict[int, _State] = {}
    _, fam0, _, _, _, cs0 = scored.eligible[0]
    pl0, like0, trial0 = _candidate_rating(data, state, scored, rnd, cfg, 0, scales)
    if trial0 is not None:
        trials[0] = trial0
    if pl0 is None or pl0.score >= PLAUSIBLE:
        return 0, None, trials
    for k in range(1, min(len(scored.eligible), MAX_IMPLAUSIBLE_TRIES)):
        cs = scored.eligible[k][5]
        if not explains_same(fam0.kind, fam0.variant, fam0.joint, fam0.partner, cs0.score, cs0, cs, rnd):
            continue
        pl, like, trial = _candidate_rating(data, state, scored, rnd, cfg, k, scales)
        if trial is not None:
            trials[k] = trial
        if pl is None or pl.score < PLAUSIBLE:
            continue
        why = (f"fits like {like0}, implausible ({'; '.join(pl0.reasons)}); {like} explains the same residual "
               f"and is plausible: added instead")
        return k, {"candidate": fam0.label, "round": rnd, "reasons": [why], "plausibility": pl0.to_dict()}, trials
    if fam0.kind in NOT_ADDED_WHEN_IMPLAUSIBLE:
        why = (f"fits like {like0}, implausible ({'; '.join(pl0.reasons)}): not added, as a friction law with "
               "constants no drive has is not applied")
        rec = {"candidate": fam0.label, "round": rnd, "reasons": [why], "plausibility": pl0.to_dict()}
        return (1 if len(scored.eligible) > 1 else None), rec, trials
    return 0, None, trials


#: candidate kinds never added with an implausible rating, with or without a plausible rival: a Stribeck dip
#: at a speed no drive has is a friction law's reshaping of whatever the residual holds at reversals (the
#: friction-law stage does not apply such a law either; docs/loop-plausibility.md)
NOT_ADDED_WHEN_IMPLAUSIBLE = frozenset({"stribeck"})


def _implausible_effects(data: _Data, added: Sequence[_Added], res: IdentificationResult) -> list[str]:
    """Effects of ``added`` whose parameters in ``res`` are physically impossible
    (:func:`.candidates.implausible`), as ``"label: reason"``."""
    out = []
    for ad in added:
        why = implausible(ad.family, [res.value(nm) for nm in ad.family.names()], f_dyn=data.fdyn)
        if why:
            out.append(f"{ad.family.label}: {why}")
    return out


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

    def build(k: str) -> np.ndarray:   # all joints' signals at each row's sample ("t": the row's time)
        full = np.zeros(joint.size) if k == "t" else np.zeros((joint.size, n))
        for e, ex in enumerate(exps):
            m = row_exp == e
            full[m] = getattr(ex, k)[row_idx[m]]
        return full

    tau_own = np.zeros(joint.size)
    for e, ex in enumerate(exps):
        m = row_exp == e
        tau_own[m] = ex.tau[row_idx[m], joint[m]]
    system = ObservationSystem(np.zeros((joint.size, 0)), tau_own, (), joint)
    return Frame(system=system, experiments=exps, row_experiment=row_exp, row_index=row_idx,
                 sig=_LazyRowSignals(tuple(keys) + ("t",), build))


class _LazyRowSignals(Mapping):
    """The row signals of a full-rate frame (:func:`_full_rate_frame`), each built on its first access and kept.

    A full-rate frame has a row per sample *and joint*, so each (r, n) signal holds every full-rate sample
    ``n`` times (``n^2`` values per sample: 50 MB per signal for 7 joints and a minute at 1 kHz); most effect
    columns are built from the experiments' full-rate signals and never read them, so they are built only
    for the columns that do (the same numbers as building them all up front)."""

    def __init__(self, keys: tuple[str, ...], build: Callable[[str], np.ndarray]):
        self._keys = keys
        self._build = build
        self._done: dict[str, np.ndarray] = {}

    def __getitem__(self, k: str) -> np.ndarray:
        if k not in self._keys:
            raise KeyError(k)
        if k not in self._done:
            self._done[k] = self._build(k)
        return self._done[k]

    def __iter__(self):
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)


def _validation_rel_err_raw(data: _Data, V: Frame, res: IdentificationResult, added: Sequence[_Added],
                            keep: dict | None = None) -> np.ndarray:
    """Validation ``rel_err_raw`` of ``res`` (declared model + ``added`` effects): the model at full rate
    on the filtered states (the assembly's) against the raw measured torque, per joint, every sample."""
    theta = data.theta_of(res)
    loaded_cols = bool(V.assembly is not None and V.assembly.options.payload_columns)
    R = _full_rate_frame(V)
    pred = np.zeros(R.n_rows)
    for e, ex in enumerate(R.experiments):
        tq = model_torque(data.model, theta, ex.q, ex.dq, ex.ddq, loaded=ex.loaded and loaded_cols)
        if isinstance(data.model, LawModel):   # the chosen laws are static (0) in the rest segments
            rest = rest_mask(ex)
            if rest.any():
                tq -= np.where(rest, data.model.sliding_torque(theta, ex.dq), 0.0)
        m = R.row_experiment == e
        pred[m] = tq[R.row_index[m], R.system.joint[m]]
    if added:
        ctx = FitContext(model=data.model, theta=dict(theta), predictions={id(R): pred.copy()})
        clear_elasticity_cache()   # the elasticity secant caches the unshifted torque by frame identity
        for ad in added:
            X = _build_one(ad.family, R, ctx, ad.value)
            pred += X @ np.array([res.value(nm) for nm in ad.family.names()])
        clear_elasticity_cache()
    if keep is not None:   # per-sample residuals for block-wise comparisons (plot_data["valid_raw"])
        keep.update(e=R.system.Y - pred, y=R.system.Y, joint=R.system.joint, experiment=R.row_experiment,
                    index=R.row_index)
    return _rel_err(R.system.Y - pred, R.system.Y, R.system.joint, data.n)


@dataclass(frozen=True)
class _Stability:
    """Stability of one accepted effect under one weighting: time-blocked selection frequency and the
    confidence region of its coefficients."""

    frequency: float
    ci_low: np.ndarray
    ci_high: np.ndarray
    excludes_zero: bool

    @property
    def named(self) -> bool:
        return self.excludes_zero and self.frequency > MIN_SELECTION_FREQUENCY


#: Stability of the accepted effects: family key -> weighting ("OLS", "WLS") -> :class:`_Stability`
_StabilityInfo = dict[tuple, dict[str, _Stability]]


def _effect_stability(data: _Data, F: Frame, added: Sequence[_Added], k: int, weights: np.ndarray | None,
                      level: float) -> _Stability:
    """Effect ``k`` of ``added`` against the model with every other one: (1) confidence intervals of its
    coefficients on all identification rows (HAC, :func:`.stability.coefficient_ci`); (2) on each of the
    ``N_FOLDS`` time-blocked folds, whether it is *selected*: significant on the fold's training rows
    (joint Wald test at ``1 - level``) and lowering the error of its own joints on the held-out block
    (the whole model refitted on the training rows). The frequency is the share of folds selecting it; for
    a step at ``t_s`` (a composed ``step`` modulation) at most the smaller of the shares judged on the
    held-out rows before ``t_s`` and after it (:func:`.stability.sided_selection`)."""
    Y, J = F.system.Y, F.system.joint
    others = tuple(ad for i, ad in enumerate(added) if i != k)
    _, A, _ = _augmented(data, others)
    X = added[k].X
    groups = J * 100000 + F.row_experiment
    ci = coefficient_ci(A, X, Y, weights=weights, groups=groups, level=level)
    blocks = time_blocks(F.row_experiment, F.row_index, N_FOLDS)
    own = np.isin(J, _own(added[k].family, data.n))
    cv = BlockedLS(A, Y, blocks, weights)
    e1, e0 = cv.oof_residual(X), cv.oof_residual(None)
    w = np.ones(Y.size) if weights is None else weights
    sel, sig_k = [], []
    for f in cv.folds:   # one per block; the fold's basis of A on its training rows is the one the CI needs
        tr = f.train
        cb = coefficient_ci(A[tr], X[tr], Y[tr], weights=w[tr], groups=groups[tr], level=level, basis=(f.U, f.rank))
        te = own & f.test
        sig_k.append(cb.excludes_zero)
        sel.append(cb.excludes_zero and float(np.sum(e1[te] ** 2)) < float(np.sum(e0[te] ** 2)))
    freq = float(np.mean(sel))
    comp = dict(added[k].family.info).get("composed")
    if comp is not None and comp.step_time is not None:
        # a change in time must be confirmed by held-out data on both sides of it (stability.sided_selection)
        freq = min(freq, sided_selection(
            lambda i, rows: sig_k[i] and float(np.sum(e1[rows] ** 2)) < float(np.sum(e0[rows] ** 2)),
            [own & f.test for f in cv.folds], F.sig["t"] < comp.step_time))
    return _Stability(freq, ci.low, ci.high, ci.excludes_zero)


def _stage_stability(data: _Data, state: _State, cfg: DiagnoseSettings) -> tuple[_State, _StabilityInfo, list[str]]:
    """Stage "stability": every effect the loop accepted is re-examined against the final
    model under OLS weights (1) and under WLS weights (``1/sigma_j`` of the final residual): it is *named*
    under a weighting when it is selected in most time-blocked folds (> :data:`MIN_SELECTION_FREQUENCY`)
    and the confidence region of its coefficients excludes "no effect" at :data:`CI_LEVEL`. Only the
    effects named under both are kept (:func:`.stability.ols_wls_agreement` says which depend on the
    estimator, listed in ``estimator_dependent``); the model is re-identified (:data:`SELECT_METHOD`) without
    the others. Since the loop itself runs with :data:`SELECT_METHOD`, the effects kept are the same
    whichever ``method`` the user chose."""
    if not state.added:
        return state, {}, []
    F = state.F
    Y, J = F.system.Y, F.system.joint
    n = data.n
    names, A, _ = _augmented(data, state.added)
    e = Y - A @ np.linalg.lstsq(A, Y, rcond=None)[0]
    w_wls = 1.0 / _joint_sigma(e, J, n, A.shape[1])[J]
    level = max(CI_LEVEL, 1.0 - cfg.significance)
    info: _StabilityInfo = {}
    named: dict[str, list[tuple]] = {"OLS": [], "WLS": []}
    for k, ad in enumerate(state.added):
        st = {"OLS": _effect_stability(data, F, state.added, k, None, level),
              "WLS": _effect_stability(data, F, state.added, k, w_wls, level)}
        info[ad.family.key] = st
        for lab, x in st.items():
            if x.named:
                named[lab].append(ad.family.key)
    labels: dict[Hashable, str] = {
        ad.family.key: (ad.family.label + (f" ({ad.family.variant})" if ad.family.variant else ""))
        for ad in state.added}
    agr = ols_wls_agreement(named["OLS"], named["WLS"], describe=lambda key: labels[key])
    keep = set(agr.common)
    msgs: list[str] = []
    if agr.message:
        msgs.append(agr.message)
    gone = [ad for ad in state.added if ad.family.key not in keep]
    for ad in gone:
        if ad.family.key in set(agr.only_first) | set(agr.only_second):
            continue
        st = info[ad.family.key]
        comp = dict(ad.family.info).get("composed")
        sided = (" (a change in time: judged on the held-out rows before and after it, the smaller share)"
                 if comp is not None and comp.step_time is not None else "")
        msgs.append(f"{labels[ad.family.key]} dropped: not stable (selected in {100 * st['OLS'].frequency:.0f} % / "
                    f"{100 * st['WLS'].frequency:.0f} % of the {N_FOLDS} time-blocked folds under OLS / WLS weights"
                    f"{sided}, confidence region excluding zero: {st['OLS'].excludes_zero} / {st['WLS'].excludes_zero})")
    dep = []
    for ad in state.added:
        key = ad.family.key
        if key in set(agr.only_first) | set(agr.only_second):
            comp = dict(ad.family.info).get("composed")
            dep.append({"kind": ad.family.kind, "joint": None if ad.family.joint is None else ad.family.joint + 1,
                        "modulation": None if comp is None else comp.modulation, "label": labels[key],
                        "named_under": "OLS" if key in set(agr.only_first) else "WLS",
                        "selection_frequency": {lab: float(x.frequency) for lab, x in info[key].items()},
                        "excludes_zero": {lab: bool(x.excludes_zero) for lab, x in info[key].items()}})
    if not gone:
        return state, info, msgs
    added = tuple(ad for ad in state.added if ad.family.key in keep)
    while True:
        names, A, Av = _augmented(data, added)
        res = _fit(ObservationSystem(A, Y, names, J), SELECT_METHOD)
        # the effects that depend on the fit rebuilt around it, and the fit the report starts from
        Fn, Vn, added = _relinearise(data, state.F, state.V, added, res)
        names, A, Av = _augmented(data, added)
        res = _fit(ObservationSystem(A, Y, names, J), SELECT_METHOD)
        # without the dropped effects an effect accepted beside them can become physically impossible
        # (LWR4, 10 effects: a torque-modulated constant on joint 5 accepted while a gain of joint 6 was in
        # the model turns joint 5's delay from 0.07 s into -0.41 s without it): drop the latest effect
        # sharing a joint with the impossible one and added after it (or that one itself), and re-fit
        bad = [(k, why) for k, ad in enumerate(added) if (why := implausible(
            ad.family, [res.value(nm) for nm in ad.family.names()], f_dyn=data.fdyn))]
        if not bad:
            break
        k_bad, why = bad[0]
        own = set(_own(added[k_bad].family, n))
        later = [k for k in range(k_bad + 1, len(added)) if set(_own(added[k].family, n)) & own]
        k_drop = later[-1] if later else k_bad
        msgs.append(f"{labels[added[k_drop].family.key]} dropped: with the unstable effects removed, "
                    + (f"it makes {labels[added[k_bad].family.key]} physically impossible ({why})" if later
                       else f"its parameters are physically impossible ({why})"))
        added = added[:k_drop] + added[k_drop + 1:]
    kept = {ad.family.key for ad in added}
    meta = tuple(m for m in state.effects_meta if m["family"].key in kept)
    return (replace(state, F=Fn, V=Vn, added=added, res=res, effects_meta=meta, estimator_dependent=tuple(dep)),
            info, msgs)


def _unexplained(F: Frame, resid: np.ndarray, A: np.ndarray, seed: int = 0, weighted: bool = False) -> tuple:
    """Stage "unexplained": out-of-fold boosted trees on the final identification residual
    of each joint from every joint's q, dq, ddq, tau_hat and t, made specific to the joints that carry
    the structure (:func:`.unexplained.unexplained_by_joint`: a joint is tested on the residual of the fit
    that the rows of the joints found to carry structure do not move, so the spread of one joint's missing
    torque over the shared parameters is not flagged on the others; threshold
    ``max(MIN_SHARE, max null share + NULL_MARGIN)``, null = that joint's block-permuted residual).

    ``weighted`` (``DiagnoseSettings.unexplained_weighted``): the system and its residual are first weighted
    per joint by the inverse of the joint's residual standard deviation and refitted (the per-joint WLS of
    [GB-gains] eq. 22, its first step the residual of the reported fit), so that the noisy joints' estimation
    error does not leave a smooth ``-A_k delta`` on the quiet joints; the trees' ``R^2`` of a joint does not
    depend on its (constant) weight, and the leave-the-carriers-out refits are weighted the same way."""

    S = F.samples()
    X, names = signal_matrix(S["q"], S["dq"], S["ddq"], S.get("tau_hat"), S["t"])
    if weighted:
        resid, A = joint_weighted_residual(resid, A, F.system.joint)
    res, _carriers = unexplained_by_joint(resid, A, F.system.joint, F.row_experiment, F.row_index, X, names,
                                          seed=seed)
    return tuple(res)


def _law_effect(rec: _LawRecord, res: IdentificationResult, F: Frame | None = None, A: np.ndarray | None = None,
                fit_names: Sequence[str] = ()) -> Effect:
    """The friction-law stage's choice of one joint as an effect of kind ``friction_law``. Given the fit's frame,
    design ``A`` and its column names, the standard deviations are those with the law's searched shape estimated
    too (:func:`.friction.shape_uncertainty`), and the shape's own are reported (:func:`.friction.shape_physical`)."""
    ch = rec.choice
    names = ch.names() + ((f"OFF{ch.joint + 1}",) if rec.offset else ())
    idx = [res.index(nm) for nm in names]
    std, pct = res.std[idx], res.rel_std_pct[idx]
    unc = None
    if F is not None and A is not None and all(nm in fit_names for nm in names):
        w = None if res.joint_sigma is None else 1.0 / np.asarray(res.joint_sigma, float)[F.system.joint]
        unc = shape_uncertainty(ch, lambda c: F.full_rate_columns(_sliding_law_columns(c), len(c.names())), A,
                                [list(fit_names).index(nm) for nm in names], res.values[idx], std, w)
    if unc is not None:
        std = unc.law_std
        with np.errstate(divide="ignore"):
            pct = 100.0 * std / np.abs(res.values[idx])
    phys = {"cv_rel_err_declared": ch.declared_cv_rel_err, "cv_rel_err": ch.cv_rel_err}
    if ch.coulomb.law in ("tanh", "stribeck") and ch.coulomb.param is not None:
        phys["v" if ch.coulomb.law == "tanh" else "vs"] = float(ch.coulomb.param)
    if ch.coulomb.smooth is not None:
        phys["v_sign"] = float(ch.coulomb.smooth)
    if ch.viscous.law == "power" and ch.viscous.param is not None:
        phys["delta"] = float(ch.viscous.param)
    x0 = ch.x0
    if x0 is not None and x0 > 0:   # Dahl: pre-sliding displacement and stiffness sigma0 = Fc / x0
        phys["x0"] = x0
        phys["sigma0"] = abs(float(res.value(ch.names()[0]))) / x0
        if ch.coulomb.law == "lugre":   # LuGre: vs, and sigma0 = Fs / x0 (friction.lugre_columns)
            phys["vs"] = float(ch.coulomb.param or math.nan)
            phys["sigma0"] = abs(float(res.value(ch.names()[0])) + float(res.value(ch.names()[1]))) / x0
    if unc is not None:
        phys.update(shape_physical(ch, unc, res.values[idx]))
    desc = ch.describe()
    if rec.added:
        desc = (f"joint {ch.joint + 1} declared without friction: added {ch.coulomb.label} Coulomb + "
                f"{ch.viscous.label} viscous" + (" + offset" if rec.offset else "") + f" (CV error "
                f"{ch.declared_cv_rel_err:.4g} -> {ch.cv_rel_err:.4g})")
    gain = 1.0 - ch.cv_rel_err / ch.declared_cv_rel_err if ch.declared_cv_rel_err > 0 else 0.0
    return Effect(kind="friction_law", label=f"friction_law{ch.joint + 1}", variant=f"{ch.coulomb.label}+{ch.viscous.label}",
                  joint=ch.joint, partner=None, names=names, values=res.values[idx], std=std,
                  rel_std_pct=pct, physical=phys, score=float(gain), p_value=rec.p_value,
                  z_validation=math.nan, reveal="dq", reveal_joint=ch.joint, modulation=None,
                  selection_frequency=rec.frequency, ci={}, description=desc, round=rec.round)


def _stage_report(data: _Data, base: _Baseline, state: _State, cfg: DiagnoseSettings, data0: _Data | None = None,
                  stab: _StabilityInfo | None = None, stab_msgs: Sequence[str] = ()) -> ResidualReport:
    """Stage 5-6 (re-identify, report): the final model identified with every effect, its errors on
    both metrics, the effects with their physical reading, residual structure, warnings."""
    n = data.n
    Y = data.F.system.Y
    data0 = data if data0 is None else data0
    state, res, names, A, Av = _final_fit(data, base, state, cfg)
    val1 = res.rel_err_on(ObservationSystem(Av, data.Vs.Y, names, data.Vs.joint))
    val0_raw = _validation_rel_err_raw(data0, state.V, base.res0, ())
    raw_keep: dict = {}
    val1_raw = _validation_rel_err_raw(data, state.V, res, state.added, keep=raw_keep)
    effects = [_law_effect(r, res, data.F, A, names) for r in base.laws if not r.smoothing]
    effects += _loop_effects(state, res, cfg, stab or {})
    effects.sort(key=lambda e: e.round)   # in the order added (a friction law in the round it won)
    final_bad = _implausible_effects(data, state.added, res)
    # every effect rated against the physical priors and its round's alternatives (cause / doubtful / rejected)
    scales = replace(ArmScales.of_frame(data.F), f_max=data.fdyn)
    impossible = {ad.family.label: why for ad in state.added if (why := implausible(
        ad.family, [res.value(nm) for nm in ad.family.names()], f_dyn=data.fdyn))}
    effects = rate_effects(effects, scales, state.tried, impossible=impossible,
                           law_ratings={r.choice.joint: (law_plausibility(r.choice, scales), law_alternatives(r.choice))
                                        for r in base.laws if not r.smoothing})
    # the composed Coulomb x |tau_hat_j| named in the load-dependent friction's parametrization (mu), rated as found
    composed_of = {m["family"].label: dict(m["family"].info).get("composed") for m in state.effects_meta}
    effects = [as_load_friction(e, composed_of.get(e.label)) for e in effects]
    F = state.F
    final_resid = Y - A @ np.array([res.value(nm) for nm in names])
    unexpl = _unexplained(F, final_resid, A, weighted=cfg.unexplained_weighted) if cfg.unexplained else ()
    s_before = residual_structure(F, _residual_of(base.res0), significance=cfg.significance) if cfg.structure else ()
    s_after = residual_structure(F, Y - A @ np.array([res.value(nm) for nm in names]),
                                 significance=cfg.significance) if cfg.structure else ()
    warnings = _report_warnings(state, res, cfg, stab_msgs, final_bad, unexpl, s_after, effects=effects,
                                doubtful_laws=data.doubtful_laws)
    Vs = data.Vs
    # the plotted residuals are those of the errors reported: "before" is the declared model fitted with the
    # user's estimator (the loop's own rounds run on SELECT_METHOD's fit), "after" the final refit
    e_valid = Vs.Y - Av @ np.array([res.value(nm) for nm in names])
    rounds = list(state.round_resid)
    if base.res0.residual is not None:
        rounds[0] = (np.asarray(base.res0.residual), data0.Vs.Y - base.res0.predict(data0.Vs))
    rounds[-1] = (final_resid, e_valid)
    # round_resid[k] is the residual after the first k effects kept (the stability stage may have dropped some,
    # and a friction law winning a round adds none): the round each of them was named in, to find its pair
    plot_data = {"frame": F, "vframe": state.V, "round_resid": rounds,
                 "effect_rounds": tuple(int(m["round"]) for m in state.effects_meta),
                 "valid_filtered": dict(e=e_valid, y=Vs.Y, joint=Vs.joint,
                                        experiment=state.V.row_experiment, index=state.V.row_index),
                 "valid_raw": raw_keep}
    return ResidualReport(robot=str(getattr(data.model, "ROBOT", "?")), method=cfg.method, n_joints=n,
                          before_rel_err=np.asarray(base.res0.rel_err), before_validation_rel_err=base.val0,
                          after_rel_err=np.asarray(res.rel_err), after_validation_rel_err=np.asarray(val1),
                          effects=tuple(effects), tried=state.tried, placebos=state.placebos,
                          structure_before=s_before, structure_after=s_after, result_before=base.res0,
                          result_after=res, settings=_report_settings(data, base, state, cfg), warnings=warnings,
                          plot_data=plot_data, before_validation_rel_err_raw=np.asarray(val0_raw),
                          after_validation_rel_err_raw=np.asarray(val1_raw), unexplained=unexpl,
                          estimator_dependent=tuple(state.estimator_dependent),
                          implausible=tuple(data.doubtful_laws) + tuple(state.implausible))


def _final_fit(data: _Data, base: _Baseline, state: _State, cfg: DiagnoseSettings
               ) -> tuple[_State, IdentificationResult, tuple[str, ...], np.ndarray, np.ndarray]:
    """The final model identified with the user's estimator (the state with its effects rebuilt around
    that fit), its names and identification/validation columns."""
    Y, J = data.F.system.Y, data.F.system.joint
    names, A, Av = _augmented(data, state.added)
    res = state.res
    if state.added or base.laws or cfg.method != SELECT_METHOD:
        res = _fit(ObservationSystem(A, Y, names, J), cfg.method)
    if cfg.method != SELECT_METHOD and any(ad.family.depends_on_fit for ad in state.added):
        # the effects linearised around the fit (gain, elasticity, |tau_hat|-modulated) rebuilt around the
        # user's estimator (fixed point, as in the loop)
        for _ in range(RELINEARISE_PASSES):
            Fn, Vn, added = _relinearise(data, state.F, state.V, state.added, res)
            state = replace(state, F=Fn, V=Vn, added=added)
            names, A, Av = _augmented(data, state.added)
            res = _fit(ObservationSystem(A, Y, names, J), cfg.method)
    return state, res, names, A, Av


def _loop_effects(state: _State, res: IdentificationResult, cfg: DiagnoseSettings,
                  stab: _StabilityInfo) -> list[Effect]:
    """The effects the loop added, read on the final fit ``res`` (with their stability when examined)."""
    effects = []
    final_value = {ad.family.key: ad.value for ad in state.added}
    wkey = "WLS" if cfg.method == "wls" else "OLS"
    for meta in state.effects_meta:
        fam, mem = meta["family"], final_value.get(meta["family"].key, meta["value"])
        idx = [res.index(nm) for nm in fam.names()]
        vals, std, pct = res.values[idx], res.std[idx], res.rel_std_pct[idx]
        info = dict(fam.info)
        comp = info.get("composed")
        phys = describe_params(fam, mem, vals, std) if comp is None else _composed_physical(comp, state.F, vals)
        st = stab.get(fam.key)
        freq = None if st is None else min(x.frequency for x in st.values())
        ci = {} if st is None else {nm: (float(lo), float(hi)) for nm, lo, hi in
                                    zip(fam.names(), st[wkey].ci_low, st[wkey].ci_high)}
        desc = comp.describe(vals[:len(comp.names())]) if comp is not None else fam.label
        effects.append(Effect(kind=fam.kind, label=fam.label, variant=fam.variant, joint=fam.joint,
                              partner=fam.partner, names=fam.names(), values=vals, std=std, rel_std_pct=pct,
                              physical=phys, score=meta["score"], p_value=meta["p"],
                              z_validation=meta["z"], round=meta["round"], reveal=REVEAL.get(fam.kind, fam.reveal),
                              reveal_joint=fam.reveal_joint if fam.reveal_joint is not None else fam.joint,
                              modulation=None if comp is None else comp.modulation, selection_frequency=freq, ci=ci,
                              description=desc, ci_level=max(CI_LEVEL, 1.0 - cfg.significance) if st else None,
                              chosen_over=meta.get("chosen_over", "")))
    return effects


def _report_warnings(state: _State, res: IdentificationResult, cfg: DiagnoseSettings, stab_msgs: Sequence[str],
                     final_bad: Sequence[str], unexpl: tuple, s_after: tuple, *, effects: Sequence[Effect] = (),
                     doubtful_laws: Sequence[dict] = ()) -> tuple[str, ...]:
    """The report's warnings: the stability stage's messages, the loop's stops, the friction laws not applied
    and the effects not named the cause (:mod:`.plausibility`), the candidates left out as implausible, the
    final fit's impossible effects, placebos that passed, and structure left."""
    warnings: list[str] = list(stab_msgs)
    for d in doubtful_laws:
        warnings.append(f"friction-law stage: {d['law']} fits but is implausible ({'; '.join(d['reasons'])}): not "
                        "applied, the loop tried the other causes first")
    for i, e in enumerate(effects, 1):
        if e.verdict in ("doubtful", "rejected"):
            warnings.append(f"effect {i} ({e.label}) {e.verdict}: {e.verdict_reason}")
    if state.stopped_at_max:
        # max_effects bounds the loop's rounds; the friction-law stage's choices come on top of it (and the
        # stability stage may drop loop effects afterwards): say which count the bound is about
        warnings.append(f"stopped at max_effects = {cfg.max_effects} effects added by the loop (friction-law "
                        f"choices are not counted; {len(state.added)} loop effect(s) kept after the stability stage): "
                        "more effects may be significant")
    # passed over: physically impossible once re-identified, or implausible with a plausible alternative of its
    # round explaining the same residual (_plausible_pick; those carry their plausibility)
    for plaus, head in ((False, "not added, the re-identified model with them physically impossible: "),
                        (True, "not added, implausible and a plausible alternative of the round explains the same "
                               "residual: ")):
        last: dict = {}
        for d in state.implausible:
            if ("plausibility" in d) == plaus:
                last[d["candidate"]] = d
        if last:
            warnings.append(head + "; ".join(f"{c} (round {d['round']}: {'; '.join(d['reasons'])})"
                                             for c, d in last.items()))
    if final_bad:
        warnings.append(f"under {cfg.method.upper()} the final fit has physically impossible effect parameters: "
                        + "; ".join(final_bad))
    if state.stopped_joints:
        warnings.append("placebo columns (random functions of time or of the motion, no physical meaning) passed the "
                        "significance and validation tests on joint(s) "
                        + ", ".join(str(j + 1) for j in sorted(state.stopped_joints))
                        + " and no candidate there beat them: the loop stopped on these joints (their residual holds "
                          "structure the library cannot name specifically; see 'unexplained')")
    warnings += [f"final identification: {w}" for w in res.warnings if "TLS" in w or "rank-deficient" in w]
    hits: dict = {}
    for joint, rnd, variant, score in state.placebo_hits:
        hits.setdefault(joint, []).append((rnd, variant, score))
    hits = {j: h for j, h in hits.items() if j not in state.stopped_joints}
    if hits:
        lst = ", ".join(f"joint {j + 1} (score up to {max(sc for *_, sc in h):.2f})" for j, h in sorted(hits.items()))
        warnings.append(
            f"placebo columns (random combinations of time or motion signals, no physical meaning) passed the "
            f"significance and validation tests on {lst}, and a candidate of the joint beat every placebo there: "
            f"it was added; the loop goes on there only while the candidates beat the placebos")
    flagged = [u for u in unexpl if u.flagged]
    if flagged:
        warnings.append("structure left that no candidate explains: " + "; ".join(
            f"joint {u.joint} ({100 * u.share:.0f} % of its residual variance, depends on {', '.join(u.signals) or '?'})"
            for u in flagged) + " (see 'unexplained')")
    strong = [x for x in s_after if x.significant and x.eta2 >= STRUCTURE_WARN_ETA2]
    if strong:
        top = sorted(strong, key=lambda x: -x.eta2)[:3]
        warnings.append("structure left in the identification residual: " + "; ".join(
            f"joint {x.joint + 1} vs {x.label} ({100 * x.eta2:.0f} % explained)" for x in top)
            + " (see 'structure')")
    return tuple(warnings)


def _report_settings(data: _Data, base: _Baseline, state: _State, cfg: DiagnoseSettings) -> dict:
    """The settings of the diagnosis as the report lists them (data, filter, loop, friction laws)."""
    F = state.F
    st = F.experiments[0].settings
    return {
        "method": cfg.method, "significance": cfg.significance, "max_effects": cfg.max_effects,
        "min_rel_improvement": cfg.min_rel_improvement, "n_placebo": cfg.n_placebo,
        "identifiability_tol": cfg.identifiability_tol, "candidates": list(cfg.candidates),
        "validation": data.vdesc, "holdout": cfg.holdout if data.held_out else None,
        "identification_sources": [tr.source for tr in data.ident], "validation_sources": [tr.source for tr in data.valid],
        "dynamics_bandwidth_hz": data.fdyn, "cutoff_hz": st.cutoff_hz, "n_d": st.n_d,
        "rows_identification": int(F.n_rows), "rows_validation": int(state.V.n_rows),
        "samples_validation": int(sum(ex.n_samples for ex in state.V.experiments)),
        "friction_laws": cfg.friction_laws, "composed": cfg.composed, "stability": cfg.stability,
        "min_selection_frequency": MIN_SELECTION_FREQUENCY, "n_folds": N_FOLDS,
        "stopped_joints": [j + 1 for j in sorted(state.stopped_joints)],
        "known_payload": dict(data.fixed),
        "unexplained_threshold": "max(0.05, largest out-of-fold R^2 of 3 block-permuted residuals + 0.05)"
                                 + (", on the per-joint WLS residual" if cfg.unexplained_weighted else ""),
        "friction_law_choices": [r.choice.describe() for r in base.laws if not r.smoothing],
        "sign_smoothing": [f"joint {r.choice.joint + 1}: sign(dq) smoothed as tanh(dq/v), v = "
                           f"{(r.choice.coulomb.param or r.choice.coulomb.smooth):.3g} (at most the velocity noise "
                           f"floor or {100 * MIN_LAW_SCALE:g} % of the joint's speeds: a processing matter, not a "
                           f"friction law)" for r in base.laws
                           if r.smoothing and (r.choice.coulomb.param or r.choice.coulomb.smooth)],
        "static_at_rest": _static_at_rest(data, state.V, base.laws),
        "joint_zero": invisible_zero_note(data.model) if "joint_zero" in cfg.candidates else [],
    }


# ------------------------------------------------------------------------------------------------
# One acceptance for every change to the model: the notes (friction static at rest, sign smoothing)
# pass the held-out test of the acceptance data like the effects, and the final model may not be worse
# than the declared one on any joint beyond that joint's noise band.
# ------------------------------------------------------------------------------------------------
def _held_out(d: _Data, A: np.ndarray | None = None, Av: np.ndarray | None = None) -> np.ndarray:
    """Acceptance residual of the model with columns ``A``/``Av`` (default the declared ones of ``d``) least-
    squares fitted on the fit part ``d.F``."""
    A = d.F.system.W if A is None else A
    Av = d.Vs.W if Av is None else Av
    th = np.linalg.lstsq(A, d.F.system.Y, rcond=None)[0]
    return d.Vs.Y - Av @ th


def _paired_held_out(e_old: np.ndarray, e_new: np.ndarray, groups: np.ndarray) -> tuple[float, float, float]:
    """Paired held-out test of a change of the model on one joint's acceptance rows (in time order,
    ``groups`` the experiments): the squared-error decrease ``d_i = e_old_i^2 - e_new_i^2`` summed, with the
    HAC (Newey-West, :func:`.stats.hac_covariance`) variance of that sum (the rows are autocorrelated):
    ``z = sum d / sqrt(Var)``; one-sided p-value; ``gain`` the relative decrease of the error norm.

    Two models whose residuals agree to rounding (``1e-9`` of the largest residual: a change that moves
    nothing on these rows, e.g. static friction at rest on rows that never rest) are the same model: ``z = 0``,
    ``p = 0.5``, ``gain = 0`` - not the ratio of two rounding errors."""
    d = e_old ** 2 - e_new ** 2
    if d.size < 2:
        return 0.0, 1.0, 0.0
    if float(np.max(np.abs(e_new - e_old))) <= 1e-9 * float(np.max(np.abs(e_old))):
        return 0.0, 0.5, 0.0
    segs = segments_of(groups, d.size)
    L = hac_lag(d, groups)
    var = float(hac_covariance((d - d.mean())[:, None], max_lag=L, segments=segs)[0, 0])
    tot = float(d.sum())
    z = tot / math.sqrt(var) if var > 0 else (math.inf if tot > 0 else 0.0)
    old = float(e_old @ e_old)
    gain = 1.0 - math.sqrt(float(e_new @ e_new) / old) if old > 0 else 0.0
    return float(z), float(sst.norm.sf(z)), float(gain)


@dataclass(frozen=True)
class _NoteTest:
    """The held-out test of one change the friction-law stage makes outside its reported laws (the declared
    law kept, but static (0) in the joint's rest segments and/or ``sign(dq)`` smoothed)."""

    record: _LawRecord
    kind: str              # "static_friction_at_rest" or "sign_smoothing"
    z: float
    p_value: float
    gain: float
    accepted: bool
    rest_share: tuple[float, float]   # share of the fit / acceptance samples at rest
    prior: bool = False   # not accepted, but its static (0) at rest applied untested (no rest to test it on)

    def to_dict(self) -> dict:
        j = self.record.choice.joint
        return {"kind": self.kind, "joint": j + 1, "z": self.z, "p_value": self.p_value, "gain": self.gain,
                "accepted": self.accepted, "rest_share_fit": self.rest_share[0],
                "rest_share_acceptance": self.rest_share[1], "prior": self.prior}


def _rest_share(fr: Frame, j: int) -> float:
    tot = sum(ex.n_samples for ex in fr.experiments)
    return sum(int(rest_mask(ex)[:, j].sum()) for ex in fr.experiments) / max(tot, 1)


def _accept_notes(data0: _Data, laws: Sequence[_LawRecord], cfg: DiagnoseSettings
                  ) -> tuple[tuple[_LawRecord, ...], tuple[_NoteTest, ...]]:
    """The friction-law stage's changes that are not reported laws (``smoothing`` records: the declared law
    on the sliding velocity, static (0) in the joint's rest segments, its sign perhaps smoothed) as
    candidates of their joint: kept only when the model with the change predicts the joint's acceptance
    rows better than the model without it (:func:`_paired_held_out`: ``z`` above the Bonferroni critical
    value over the joints at ``cfg.significance``, and the error norm lowered by ``min_rel_improvement``,
    the effects' thresholds). A rejected one leaves the joint's declared law as declared - unless the joint
    never rests in the identification data (fit and acceptance parts): then its static (0) at rest is
    untestable, and applied without test as a prior (:func:`_static_prior`), its sign smoothing left out."""
    notes = [r for r in laws if r.smoothing]
    if not notes:
        return tuple(laws), ()
    n = data0.n
    zcrit = float(sst.norm.isf(cfg.significance / n))
    kept = list(laws)
    out = []
    for r in notes:
        j = r.choice.joint
        d_new = _apply_laws(data0, kept)
        d_old = _apply_laws(data0, [x for x in kept if x is not r])
        rows = np.equal(d_new.Vs.joint, j)
        z, p, gain = _paired_held_out(_held_out(d_old)[rows], _held_out(d_new)[rows], d_new.V.row_experiment[rows])
        ok = bool(z > zcrit and gain >= cfg.min_rel_improvement and not _few_acceptance_rows(d_new.V, [j]))
        shares = (_rest_share(data0.F, j), _rest_share(data0.V, j))
        prior = not ok and shares == (0.0, 0.0)
        if prior:
            kept[kept.index(r)] = _static_prior(r)
        elif not ok:
            kept.remove(r)
        kind = "static_friction_at_rest" if shares[0] > 0 or shares[1] > 0 or prior else "sign_smoothing"
        out.append(_NoteTest(r, kind, z, p, gain, ok, shares, prior))
    return tuple(kept), tuple(out)


def _static_prior(r: _LawRecord) -> _LawRecord:
    """The note ``r`` reduced to its static (0) at rest, applied without test on a joint whose identification
    data never rest: the declared law on the sliding velocity (``sign(dq)`` not smoothed).

    At standstill Coulomb friction is set-valued: the torque it holds lies anywhere in ``[-Fs, Fs]`` and is not
    a function of the velocity (Armstrong-Hélouvry, Dupont & Canudas de Wit 1994, sec. 2.1). Identification
    data without a rest say nothing of it: a prediction there is outside their domain and the data cannot
    choose it. The declared ``Fs sign(dq)`` of a velocity that is noise predicts ``+Fs`` or ``-Fs`` at
    random, an error up to ``2 Fs``; ``0`` is the minimax prediction (worst-case error ``Fs``, the centre of
    the set; the expert's ``tanh(dq/v)`` is 0 there too). On data without rests the two columns are equal, so
    the prior changes nothing identified and nothing on the acceptance data (the never-worse guard holds by
    construction); it changes only the predictions at rest, which the report lists as such
    (``settings["static_at_rest"]``, the note's ``prior``)."""
    ch = r.choice
    return replace(r, choice=replace(ch, coulomb=replace(ch.coulomb, smooth=None)), prior=True)


def _note_effect(t: _NoteTest, res: IdentificationResult) -> Effect:
    """An accepted note as an effect of its joint (kind ``static_friction_at_rest`` or ``sign_smoothing``)."""
    ch = t.record.choice
    j = ch.joint
    names = ch.names()
    idx = [res.index(nm) for nm in names]
    v = ch.coulomb.param or ch.coulomb.smooth
    phys = {"rest_share_identification": t.rest_share[0]}
    parts = []
    if t.kind == "static_friction_at_rest":
        parts.append("sliding friction static (0) in the joint's rest segments")
    if v:
        phys["v_sign"] = float(v)
        parts.append(f"sign(dq) smoothed as tanh(dq/v), v = {float(v):.3g}")
    desc = (f"joint {j + 1}: " + " and ".join(parts or ["declared friction law on the sliding velocity"])
            + f" (held-out acceptance error -{100 * t.gain:.1f} %, z = {t.z:.1f})")
    return Effect(kind=t.kind, label=f"{t.kind}{j + 1}", variant=f"{ch.coulomb.label}+{ch.viscous.label}", joint=j,
                  partner=None, names=names, values=res.values[idx], std=res.std[idx],
                  rel_std_pct=res.rel_std_pct[idx], physical=phys, score=float(t.gain), p_value=t.p_value,
                  z_validation=t.z, round=0, reveal="dq", reveal_joint=j, description=desc)


@dataclass(frozen=True)
class _Guard:
    """Never worse than declared: per joint the acceptance error of the declared and of the final model (both
    fitted on the fit part), the declared one's 95 % block-bootstrap band, the changes removed."""

    declared: np.ndarray
    final: np.ndarray
    band: np.ndarray
    removed: tuple[tuple[str, tuple[int, ...]], ...] = ()
    worse: tuple[int, ...] = ()


def _never_worse(data0: _Data, data: _Data, laws: tuple[_LawRecord, ...], state: _State
                 ) -> tuple[_Data, tuple[_LawRecord, ...], _State, _Guard]:
    """Per joint, the final model's acceptance error may not exceed the declared model's beyond the upper
    end of that joint's noise band (the 95 % circular block-bootstrap interval of the declared model's
    error, :func:`.bootstrap.rel_err_bands`, Künsch 1989, Politis & Romano 1992). Where it does, the changes
    touching the joint are removed (the loop's effects first, then the joint's friction law) until no joint
    is worse or nothing is left to remove (then reported)."""
    n = data.n
    e_d = _held_out(data0)
    y, J = data0.Vs.Y, data0.Vs.joint
    band = rel_err_bands(e_d, y, J, n)
    r_d = _rel_err(e_d, y, J, n)
    removed: list[tuple[str, tuple[int, ...]]] = []
    worse: list[int] = []
    r_f = r_d
    for _ in range(n + len(state.added) + len(laws) + 1):
        _, A, Av = _augmented(data, state.added)
        r_f = _rel_err(_held_out(data, A, Av), data.Vs.Y, data.Vs.joint, n)
        worse = [j for j in range(n) if r_f[j] > band[j, 1]]
        if not worse:
            break
        S = set(worse)
        drop = {ad.family.key: ad.family for ad in state.added if set(_affected(ad.family, n)) & S}
        if drop:
            state = replace(state, added=tuple(ad for ad in state.added if ad.family.key not in drop),
                            effects_meta=tuple(m for m in state.effects_meta if m["family"].key not in drop))
            removed += [(f.label + (f" ({f.variant})" if f.variant else ""), tuple(sorted(S))) for f in drop.values()]
            continue
        lw = [r for r in laws if r.choice.joint in S]
        if not lw:
            break
        laws = tuple(r for r in laws if r.choice.joint not in S)
        data = _apply_laws(data0, laws)
        removed += [(f"friction law of joint {r.choice.joint + 1}", (r.choice.joint,)) for r in lw]
    return data, laws, state, _Guard(np.asarray(r_d), np.asarray(r_f), band, tuple(removed), tuple(worse))


def _transfer(full: _Data, state: _State) -> _State:
    """The loop's model on the report's data: every effect rebuilt on all identification data and on the
    validation data (searched parameters kept), refitted (:data:`SELECT_METHOD`) on all identification
    data and re-linearised (fixed point); the per-round residuals recomputed there."""
    Y = full.F.system.Y
    names, _, _ = _augmented(full, ())
    names += tuple(nm for ad in state.added for nm in ad.family.names())
    res = state.res
    theta = np.array([res.value(nm) for nm in names])
    F = attach_model_torque(full.F, full.model, full.theta_of(res))
    V = attach_model_torque(full.V, full.model, full.theta_of(res))
    ctx = _context(full, F, V, names, theta)
    clear_elasticity_cache()
    added = tuple(_Added(ad.family, ad.value, _build_one(ad.family, F, ctx, ad.value),
                         _build_one(ad.family, V, ctx, ad.value)) for ad in state.added)
    F, V, added, res, names, A, Av = _refit(full, F, V, added)
    rounds = []
    for k in range(len(added) + 1):
        _, Ak, Avk = _augmented(full, added[:k])
        th = np.linalg.lstsq(Ak, Y, rcond=None)[0]
        rounds.append((Y - Ak @ th, full.Vs.Y - Avk @ th))
    return replace(state, F=F, V=V, added=added, res=res, round_resid=tuple(rounds))


def _with_acceptance(report: ResidualReport, full0: _Data, data0: _Data, notes: Sequence[_NoteTest],
                     guard: _Guard, cfg: DiagnoseSettings) -> ResidualReport:
    """The report with the accepted notes as effects, the acceptance record (notes tested, never-worse
    guard) and, on the validation data, every joint's error band (95 % circular block bootstrap of the
    declared and of the final model's validation residual); a joint whose final validation error lies
    above the declared one's band is flagged."""
    n = report.n_joints
    res0, res = report.result_before, report.result_after
    Vs = full0.Vs
    e0 = Vs.Y - res0.predict(Vs)
    band0 = rel_err_bands(e0, Vs.Y, Vs.joint, n)
    pv = report.plot_data.get("valid_filtered") if isinstance(report.plot_data, dict) else None
    band1 = rel_err_bands(pv["e"], pv["y"], pv["joint"], n) if pv else np.full((n, 2), math.nan)
    after = np.asarray(report.after_validation_rel_err)
    worse_val = [j for j in range(n) if np.isfinite(band0[j, 1]) and after[j] > band0[j, 1]]
    warnings = list(report.warnings)
    if guard.removed:
        warnings.append("never worse than declared: removed " + "; ".join(
            f"{lab} (joint(s) {', '.join(str(j + 1) for j in js)} worse than the declared model on the acceptance "
            f"data beyond the {100 * BAND_LEVEL:.0f} % band)" for lab, js in guard.removed))
    if guard.worse:
        warnings.append("never worse than declared: on the acceptance data joint(s) "
                        + ", ".join(str(j + 1) for j in guard.worse)
                        + " stay worse than the declared model beyond their band with nothing left to remove")
    if worse_val:
        warnings.append("on the validation data joint(s) " + ", ".join(
            f"{j + 1} ({report.before_validation_rel_err[j]:.4g} -> {after[j]:.4g}, {100 * BAND_LEVEL:.0f} % band "
            f"[{band0[j, 0]:.4g}, {band0[j, 1]:.4g}])" for j in worse_val)
            + " got worse beyond the declared model's noise band")
    accepted = [t for t in notes if t.accepted]
    effects = list(report.effects)
    # the notes (friction static at rest, sign smoothing: processing matters of the declared law, applied before
    # the loop) after the effects, whose order is the order the loop named them (a friction law in its round)
    effects += [_note_effect(t, res) for t in accepted]
    acc = {"share": cfg.acceptance, "data": data0.vdesc,
           "rows_fit": int(data0.F.n_rows), "rows_acceptance": int(data0.V.n_rows),
           "band_level": BAND_LEVEL, "band_method": "circular block bootstrap (Politis & Romano 1992), block length "
                                                    "of Politis & White 2004",
           "declared_rel_err": [float(x) for x in guard.declared], "final_rel_err": [float(x) for x in guard.final],
           "declared_rel_err_band": [[float(a), float(b)] for a, b in guard.band],
           "removed": [{"change": lab, "joints": [j + 1 for j in js]} for lab, js in guard.removed],
           "worse": [j + 1 for j in guard.worse], "notes": [t.to_dict() for t in notes],
           "validation_worse": [j + 1 for j in worse_val]}
    return replace(report, effects=tuple(effects), warnings=tuple(warnings), acceptance=acc,
                   before_validation_rel_err_band=band0, after_validation_rel_err_band=band1)


@single_threaded_blas
def diagnose(model: IdentificationModel, trajectories, settings: DiagnoseSettings | None = None, *,
             validation=None, loaded=None, payload=None, rng: np.random.Generator | None = None,
             assembly: AssemblyOptions | None = None) -> ResidualReport:
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
    settings : DiagnoseSettings, optional
        Method, candidate kinds, significance, most effects, hold-out share, stages run (default: the
        defaults of :class:`DiagnoseSettings`, those of ``symoro-gen diagnose``).
    validation : Trajectory or sequence of Trajectory, optional
        Validation experiments; default: the last ``settings.holdout`` share of each identification experiment.
    loaded : Trajectory or sequence of Trajectory, optional
        Identification experiments with the payload (``identify --loaded``): marked loaded, the payload's
        columns (``PAYLOAD_NAMES``) are added to their rows.
    payload : mapping name -> value, optional
        Known payload parameters (``identify --payload M8=4.6``): moved to ``Y`` ([LWR4-TLS] eq. 7), the
        others identified.
    rng : numpy.random.Generator, optional
        Draws the placebos (default ``np.random.default_rng(0)``: reproducible).
    assembly : AssemblyOptions, optional
        Filter and decimation of the assembly ([GB-gains] eq. 14-16: ``cutoff_hz``, ``n_d``, ``order``,
        ``ftype``...); ``dynamics_bandwidth_hz`` is ``f_dyn`` of the filter rules, default the largest
        estimate over the identification data, the same value for every experiment (identification and
        validation). The frames keep their signals and set their payload columns themselves.

    Returns
    -------
    ResidualReport
        Errors before/after on the filtered, decimated system (``*_rel_err``, the papers' metric) and,
        on validation data, on the raw measured torque (``*_validation_rel_err_raw``).
    """
    cfg = DiagnoseSettings() if settings is None else settings
    rng = np.random.default_rng(0) if rng is None else rng
    trajs = _as_list(trajectories)
    if loaded is not None:
        trajs += [replace(tr, loaded=True) for tr in _as_list(loaded)]
    data0 = _stage_assemble(model, trajs, validation, cfg.holdout, assembly or AssemblyOptions(), payload,
                            cfg.acceptance)
    assert data0.full is not None
    full0 = data0.full
    # the friction laws are chosen by their own time-blocked cross-validation on all identification data
    # (never the validation data); the notes they bring pass the acceptance test below
    # (a replacement that fits but is implausible is not applied: kept in doubtful_laws for the report)
    # (a plausible replacement of a declared law is pending: it competes in the loop's rounds)
    # the heap's freed pages go back to the system after each stage (.memory: the resident set follows the
    # arrays alive, not the transients of the stages before)
    release_freed_memory()
    chosen, laws, pending = _stage_friction(full0, cfg) if cfg.friction_laws else (full0, (), ())
    doubtful = chosen.doubtful_laws
    del chosen
    release_freed_memory()
    laws, notes = _accept_notes(data0, laws, cfg)
    data = _apply_laws(data0, laws)
    base = _stage_baseline(full0, data, laws, cfg)
    release_freed_memory()
    data, base, state = _stage_loop(data0, data, base, cfg, rng, pending)
    release_freed_memory()
    laws = base.laws
    stab: _StabilityInfo = {}
    msgs: list[str] = []
    if cfg.stability:
        state, stab, msgs = _stage_stability(data, state, cfg)
    data, laws, state, guard = _never_worse(data0, data, laws, state)
    del data    # the loop's frames with their model torque: the report's are rebuilt on all the data
    clear_loop_caches()   # the joint-zero tangents kept on the loop's frames (.candidates)
    notes = tuple(replace(t, accepted=t.accepted and any(t.record is r for r in laws)) for t in notes)
    full = replace(_apply_laws(full0, laws), doubtful_laws=doubtful)
    clear_fold_cache()   # the loop's fold bases: the report's designs are other ones
    state = _transfer(full, state)
    release_freed_memory()
    report = _stage_report(full, replace(base, laws=laws), state, cfg, data0=full0, stab=stab, stab_msgs=msgs)
    report = _with_acceptance(report, full0, data0, notes, guard, cfg)
    clear_fold_cache()   # nothing of the diagnosis is kept once it returns
    clear_loop_caches()
    return report


