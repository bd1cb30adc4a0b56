"""IDIM-OLS, IDIM-WLS and IDIM-TLS estimators with their statistics.

Equations (RX-90 paper = Gautier & Briot 2011, LWR4 paper = torque-sensor calibration paper):

* OLS (RX-90 eq. 17): ``chi = W^+ Y``; ``sigma_rho^2 = ||Y - W chi||^2 / (r - c)`` (eq. 19);
  ``C = sigma_rho^2 (W'W)^-1`` (eq. 20); ``%sigma_i = 100 sigma_i / |chi_i|`` (eq. 21).
* WLS (RX-90 eq. 22): the rows of joint j are weighted by ``1/sigma_j``, sigma_j from the OLS
  solution of the joint-j equations alone, then OLS on the weighted system.
* TLS (LWR4 eq. 10-16): economy SVD of ``W_tot = [W  -Y]``; the solution is the last right singular
  vector normalised so that its last coefficient is 1; ``sigma_W = s_c / sqrt(r - c)`` (eq. 15);
  ``C ~ sigma_W^2 (1 + ||chi||^2) (What' What)^-1`` (eq. 16) with ``What`` the first c-1 columns of
  ``W_tot - s_c U_c V_c'`` (eq. 13). Optional per-joint row weighting by ``1/sigma_W^j``.

Every estimator accepts an :class:`ObservationSystem` or an :class:`Accumulator` (streamed data)
and gives the same numbers for both: all computations run on per-joint QR factors.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, TypedDict, cast

import numpy as np

from ..errors import IdentificationError
from ..preprocessing.motion import noise_level_joints
from .accumulate import Accumulator, check_finite, factor_system
from .observation import ObservationSystem
from .result import IdentificationResult, per_joint_rel_err, relative_std_pct

#: default tolerances (all overridable by keyword)
RANK_TOL = 1e-10          # singular value / largest one (columns scaled to unit norm) below which W is rank-deficient
COND_WARN = 1e3           # column-scaled condition number above which W is called ill-conditioned
REL_STD_WARN_PCT = 30.0   # %sigma above which a parameter is reported as poorly identified
ZERO_COL_TOL = 1e-12      # column norm / largest column norm below which a column is "all zero"
INVOLVED_TOL = 0.1        # |component| / max |component| of a small singular vector naming a parameter
TLS_GAP_TOL = 1e-6        # (s_{c-1} - s_c) / s_{c-1} below which the TLS solution is called non-unique
TLS_RESIDUAL_WARN = 1.5   # TLS residual norm / LS residual norm above which TLS is reported as unreliable


@dataclass(frozen=True)
class Options:
    """Tolerances shared by the estimators (see the module constants for their meaning)."""

    rank_tol: float = RANK_TOL
    cond_warn: float = COND_WARN
    rel_std_warn_pct: float = REL_STD_WARN_PCT
    zero_col_tol: float = ZERO_COL_TOL
    involved_tol: float = INVOLVED_TOL
    tls_gap_tol: float = TLS_GAP_TOL
    tls_residual_warn: float = TLS_RESIDUAL_WARN


@dataclass(frozen=True, eq=False)
class RawFit:
    """Internal: the estimate on a column subset of an accumulator."""

    method: str
    active: tuple[int, ...]
    values: np.ndarray
    cov: np.ndarray
    std: np.ndarray
    sigma: float
    cond: float
    cond_scaled: float
    joint_sigma: np.ndarray | None
    warnings: tuple[str, ...]

    @property
    def rel_std_pct(self) -> np.ndarray:
        return relative_std_pct(self.values, self.std)


class Tolerances(TypedDict, total=False):
    """The tolerance keywords of the estimators (``fit_ols``, ``fit_wls``, ``fit_tls``: fields of
    :class:`Options`), e.g. passed on through :func:`~.payload.fit_with_known_payload`."""

    rank_tol: float
    cond_warn: float
    rel_std_warn_pct: float
    zero_col_tol: float


def tolerance_keywords(function: str, keywords: dict[str, Any]) -> dict[str, Any]:
    """``keywords`` when they are tolerances (:class:`Tolerances`); otherwise the TypeError Python raises for
    an unexpected keyword argument of ``function``."""
    unknown = [k for k in keywords if k not in Tolerances.__annotations__]
    if unknown:
        raise TypeError(f"{function}() got an unexpected keyword argument {unknown[0]!r}")
    return keywords


# ---------------------------------------------------------------------------- helpers
def as_accumulator(data, use_weights: bool) -> tuple[Accumulator, ObservationSystem | None]:
    """The factored normal equations of ``data`` (an accumulator as is, a system factored) and the system
    (``None`` for an accumulator)."""
    if isinstance(data, Accumulator):
        return data, None
    if isinstance(data, ObservationSystem):
        check_finite(data)
        return factor_system(data, use_weights=use_weights), data
    raise IdentificationError(
        f"expected an ObservationSystem or an Accumulator, got {type(data).__name__}")


def _check_problem(acc: Accumulator, active: Sequence[int], extra_cols: int, what: str) -> None:
    k = len(active)
    if k == 0:
        raise IdentificationError(f"{what}: no parameter to identify")
    r = acc.n_rows
    need = k + extra_cols
    if r <= need:
        raise IdentificationError(
            f"{what}: too few equations: {r} rows for {k} parameters "
            f"(need more than {need} to estimate the parameters and the noise level)")


def _qr_r(M: np.ndarray) -> np.ndarray:
    """The R factor of ``M`` (``numpy.linalg.qr(mode="r")`` returns the bare array)."""
    return cast(np.ndarray, np.linalg.qr(M, mode="r"))


def _column_norms(M: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->j", M, M))


def _check_zero_columns(norms: np.ndarray, names: Sequence[str], opts: Options, what: str) -> None:
    top = norms.max() if norms.size else 0.0
    zero = [names[int(i)] for i in np.flatnonzero(norms <= opts.zero_col_tol * top)] if top > 0 else list(names)
    if zero:
        raise IdentificationError(
            f"{what}: column(s) {zero} of W are all zero: these parameters have no effect on the "
            f"data (not excited, or not base parameters); leave them out with drop_unexcited() "
            f"(`symoro-gen identify --drop-unexcited`) to identify the others")


# ---------------------------------------------------------------------------- unexcited parameters
#: a joint whose position spans less than this [rad or m] in a file "does not move" there (named in messages)
STILL_SPAN = 1e-3


def unexcited_columns(systems: Sequence[ObservationSystem | Accumulator], *, zero_col_tol: float = ZERO_COL_TOL
                      ) -> tuple[str, ...]:
    """Columns that are zero in every system (norm <= ``zero_col_tol`` x the largest column norm), in order.

    The estimators refuse such columns (no data constrain them: ``W'W`` is singular, RX-90 eq. 17);
    a column present in several systems counts with its norm over all of them, as in the stacked system
    the estimators solve (e.g. unloaded and loaded recordings, [GB-gains] eq. 16).
    """
    norm2: dict[str, float] = {}
    for sys_ in systems:
        sq = sys_.column_sq_norms() if isinstance(sys_, Accumulator) else np.einsum("ij,ij->j", sys_.W, sys_.W)
        for name, v in zip(sys_.names, sq):
            norm2[name] = norm2.get(name, 0.0) + float(v)
    if not norm2:
        return ()
    top = math.sqrt(max(norm2.values()))
    return tuple(n for n, v in norm2.items() if math.sqrt(v) <= zero_col_tol * top)


def drop_columns(system: ObservationSystem | Accumulator, names: Sequence[str]) -> ObservationSystem | Accumulator:
    """``system`` without the columns ``names`` (those it lacks are ignored; an accumulator's factors too)."""
    if isinstance(system, Accumulator):
        return system.without(names)
    gone = set(names)
    keep = [i for i, n in enumerate(system.names) if n not in gone]
    return ObservationSystem(system.W[:, keep], system.Y, tuple(system.names[i] for i in keep), system.joint,
                             system.weights)


def still_joints(trajectories, span: float = STILL_SPAN) -> list[tuple[str, int, float]]:
    """``(source, joint (1-based), span of q)`` for every joint whose position spans less than ``span`` or
    moves at the noise level (:func:`~symoro_gen.preprocessing.motion.noise_level_joints`)."""
    out = []
    for tr in trajectories:
        q = np.asarray(tr.q, float)
        if q.size == 0:
            continue
        ptp = np.ptp(q, axis=0)
        still = set(np.flatnonzero(ptp < span).tolist()) | set(noise_level_joints(q))
        out += [(str(tr.source), int(j) + 1, float(ptp[j])) for j in sorted(still)]
    return out


def drop_unexcited(systems: Sequence[ObservationSystem | Accumulator | None], trajectories=(), *, drop: bool = True,
                   zero_col_tol: float = ZERO_COL_TOL, option: str = "--drop-unexcited"
                   ) -> tuple[list[Any], tuple[str, ...]]:
    """Leave out the parameters no recording excites (a joint that stands still), or say which and why.

    Parameters
    ----------
    systems : sequence of ObservationSystem, Accumulator or None
        The systems identified together (None entries are passed through; streamed data as their factors).
    trajectories : sequence of Trajectory
        The recordings behind them: named in the error, with the joints that do not move in each.
    drop : bool
        True: return the systems without those columns. False: raise if there are any.
    option : str
        How the caller turns ``drop`` on (named in the error's hint).

    Returns
    -------
    (systems, unexcited)
        The systems (columns left out when ``drop``) and the names left out, to be reported as not
        identified (:attr:`IdentificationResult.unexcited`).

    Raises
    ------
    IdentificationError
        ``drop`` is False and some columns are zero: names the parameters, the files and the joints
        that do not move in them.
    """
    present = [s for s in systems if s is not None]
    zero = unexcited_columns(present, zero_col_tol=zero_col_tol)
    if not zero:
        return list(systems), ()
    all_names = list(dict.fromkeys(n for s in present for n in s.names))
    if len(zero) == len(all_names):
        drop = False  # nothing would be left to identify
    if not drop:
        trs = list(trajectories)
        files = list(dict.fromkeys(str(tr.source) for tr in trs))
        shown = ", ".join(files[:3]) + (f" and {len(files) - 3} more" if len(files) > 3 else "")
        still = still_joints(trs)
        why = ""
        if still:
            per: dict[int, list[float]] = {}
            for _src, j, span in still:
                per.setdefault(j, []).append(span)
            why = " (" + ", ".join(f"joint {j} does not move: q{j} spans at most {max(v):.3g}"
                                   for j, v in sorted(per.items())) + ")"
        err = IdentificationError(
            f"{shown or 'the data'}: parameter(s) {', '.join(zero)} ({len(zero)} of {len(all_names)}) are not "
            f"excited: their columns of W are all zero{why}, so these data cannot identify them")
        err.hint = (f"give {option} to identify the other parameters and report these as not identified, or "
                    "record a trajectory that moves every joint (symoro-gen excite)"
                    if len(zero) < len(all_names) else "record a trajectory that moves the joints (symoro-gen excite)")
        raise err
    return [drop_columns(s, zero) if s is not None else None for s in systems], zero


def with_unexcited(result: IdentificationResult, unexcited: Sequence[str]) -> IdentificationResult:
    """``result`` reporting ``unexcited`` as not identified (a warning says why and what it means)."""
    if not unexcited:
        return result
    note = (f"{', '.join(unexcited)} not identified: their columns of W are zero in the identification data "
            "(not excited); predictions use 0 for them, so validation data that excite them show the gap")
    return replace(result, unexcited=tuple(unexcited), warnings=(note, *result.warnings))


def _involved(v: np.ndarray, names: Sequence[str], opts: Options) -> list[str]:
    a = np.abs(v)
    idx = np.flatnonzero(a >= opts.involved_tol * a.max())
    idx = idx[np.argsort(-a[idx])]
    return [f"{names[int(i)]} ({v[i]:+.2f})" for i in idx]


def _conditioning(Wsqrt: np.ndarray, names: Sequence[str], opts: Options, what: str):
    """Condition numbers, rank, scaled SVD and warnings for the square-root data of W."""
    norms = _column_norms(Wsqrt)
    _check_zero_columns(norms, names, opts, what)
    s_raw = np.linalg.svd(Wsqrt, compute_uv=False)
    cond = float(s_raw[0] / s_raw[-1]) if s_raw[-1] > 0 else math.inf
    U, s, Vt = np.linalg.svd(Wsqrt / norms, full_matrices=False)
    cond_scaled = float(s[0] / s[-1]) if s[-1] > 0 else math.inf
    rank = int(np.sum(s > opts.rank_tol * s[0]))
    warnings = []
    k = len(names)
    if rank < k:
        for i in range(rank, k):
            warnings.append(
                f"W is rank-deficient (rank {rank} < {k} parameters): the combination "
                f"{' '.join(_involved(Vt[i], names, opts))} is not identifiable "
                f"(singular value {s[i] / s[0]:.2e} of the column-scaled W); its parameters get std = inf "
                f"- regroup them (base parameters) or excite them")
    elif cond_scaled > opts.cond_warn:
        warnings.append(
            f"W is ill-conditioned: cond = {cond:.3g}, {cond_scaled:.3g} with unit-norm columns "
            f"(> {opts.cond_warn:g}); the least identifiable direction involves "
            f"{' '.join(_involved(Vt[-1], names, opts))}")
    return cond, cond_scaled, rank, norms, U, s, Vt, warnings


def _inf_std_for_null(std: np.ndarray, Vt: np.ndarray, rank: int, opts: Options) -> np.ndarray:
    std = std.copy()
    for i in range(rank, Vt.shape[0]):
        a = np.abs(Vt[i])
        std[a >= opts.involved_tol * a.max()] = np.inf
    return std


#: what the poorly-identified warning suggests: the essential parameters of ``identify --essential`` ([LWR4-TLS]
#: Sec. IV-B)
ESSENTIAL_HINT = "consider the essential parameters (--essential)"


def poorly_identified_warnings(names, values, std, opts: Options, keep: Sequence[str] = (),
                               hint: str = ESSENTIAL_HINT) -> list[str]:
    """The warning naming the parameters whose relative standard deviation exceeds the limit (``keep``
    excepted), with ``hint`` (the option that helps; empty: none), or no warning."""
    pct = relative_std_pct(values, std)
    bad = [(n, p) for n, p in zip(names, pct) if p > opts.rel_std_warn_pct and n not in keep]
    if not bad:
        return []
    bad.sort(key=lambda t: -t[1])
    listed = ", ".join(f"{n} ({p:.3g}%)" if math.isfinite(p) else f"{n} (inf)" for n, p in bad)
    return [f"{len(bad)} parameter(s) poorly identified (%sigma > {opts.rel_std_warn_pct:g}): {listed}"
            + (f"; {hint}" if hint else "")]


# ---------------------------------------------------------------------------- cores
def _ols_core(M: np.ndarray, r: int, names: Sequence[str], opts: Options, what: str):
    """OLS on square-root data ``M`` of ``[W Y]`` (r original rows).

    Returns values, cov, std, sigma, cond, cond_scaled, warnings.
    """
    k = M.shape[1] - 1
    R = _qr_r(M)
    if R.shape[0] < k + 1:
        R = np.vstack([R, np.zeros((k + 1 - R.shape[0], k + 1))])
    R11, z, e = R[:k, :k], R[:k, k], R[k, k]
    cond, cond_scaled, rank, norms, U, s, Vt, warnings = _conditioning(R11, names, opts, what)
    Uz = U.T @ z
    y = Vt[:rank].T @ (Uz[:rank] / s[:rank])
    values = y / norms
    res2 = e * e + float(Uz[rank:] @ Uz[rank:])
    dof = r - rank
    sigma = math.sqrt(res2 / dof)
    Vr = Vt[:rank].T / s[:rank]
    cov = sigma ** 2 * (Vr @ Vr.T) / np.outer(norms, norms)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if rank < k:
        std = _inf_std_for_null(std, Vt, rank, opts)
    return values, cov, std, sigma, cond, cond_scaled, warnings


def _tls_core(M: np.ndarray, r: int, names: Sequence[str], opts: Options, what: str):
    """TLS on square-root data ``M`` of ``W_tot = [A  -b]`` (r original rows), solution of A x ~ b.

    Returns values, cov, std, sigma_W, cond, cond_scaled, warnings.
    """
    k = M.shape[1] - 1
    R = _qr_r(M)
    if R.shape[0] < k + 1:
        R = np.vstack([R, np.zeros((k + 1 - R.shape[0], k + 1))])
    cond, cond_scaled, rank, _, _, _, Vts, warnings = _conditioning(R[:, :k], names, opts, what)
    _, s, Vt = np.linalg.svd(R, full_matrices=False)           # eq. 12 (same s, V as W_tot)
    v = Vt[-1]
    scale = np.abs(v).max()
    if abs(v[-1]) <= opts.rank_tol * scale:
        raise IdentificationError(
            f"{what}: TLS problem is nongeneric: the smallest right singular vector of W_tot has a zero "
            f"last coefficient, so it cannot be normalised to 1 (eq. 11); the data do not fix the scale "
            f"(e.g. no known payload term or Y identically explained by W)")
    xtot = v / v[-1]
    values = xtot[:-1]
    c = k + 1
    sigma_w = float(s[-1] / math.sqrt(r - c))                   # eq. 15
    if k >= 1 and s[-2] - s[-1] <= opts.tls_gap_tol * s[-2]:
        warnings.append(
            f"the two smallest singular values of W_tot are (nearly) equal ({s[-2]:.3g}, {s[-1]:.3g}): "
            f"the TLS solution is not unique")
    V = Vt.T
    Va = V[:k, :k]
    # (What' What)_{1:c-1} = Va diag(s_1..s_{c-1})^2 Va'  (What = W_tot - s_c U_c V_c')
    try:
        B = np.linalg.solve(Va.T, np.diag(1.0 / s[:k]))
        inv = B @ B.T
    except np.linalg.LinAlgError:
        G = (Va * s[:k] ** 2) @ Va.T
        inv = np.linalg.pinv(G)
        warnings.append("the corrected matrix What of eq. 13 is singular; covariance from its pseudo-inverse")
    cov = sigma_w ** 2 * (1.0 + float(values @ values)) * inv    # eq. 16
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if rank < k:
        std = _inf_std_for_null(std, Vts, rank, opts)
    return values, cov, std, sigma_w, cond, cond_scaled, warnings


def _joint_ols_sigma(Mj: np.ndarray, rows: int, opts: Options) -> tuple[float, int]:
    """sigma_j of the OLS solution of the joint-j equations alone (eq. 22) and its dof (the residual computed
    as a vector, accurate to rounding whatever the fit: the difference of squared norms is not).

    Columns that are zero for joint j are ignored; rank is taken on unit-norm columns.
    """
    W, y = Mj[:, :-1], Mj[:, -1]
    norms = _column_norms(W)
    top = norms.max() if norms.size else 0.0
    keep = norms > opts.zero_col_tol * top if top > 0 else np.zeros(norms.shape, bool)
    if keep.any():
        Ws = W[:, keep] / norms[keep]
        U, s, Vt = np.linalg.svd(Ws, full_matrices=False)
        rank = int(np.sum(s > opts.rank_tol * s[0]))
        Ur = U[:, :rank]
        r = y - Ur @ (Ur.T @ y)          # the residual itself: y'y - ||U'y||^2 would lose eps ||y||^2 / ||r||^2
        res2 = float(r @ r)
    else:
        rank, res2 = 0, float(y @ y)
    return math.sqrt(max(res2, 0.0) / max(rows - rank, 1)), rows - rank


def _group_sigmas(acc: Accumulator, active, residual_sigma, opts: Options, label: str):
    """Per-group standard deviations with safeguards; returns (sigmas, warnings)."""
    sig = np.array(residual_sigma, float)
    warnings = []
    present = np.array([r > 0 for r in acc.rows])
    pos = sig[present & (sig > 0)]
    floor = (pos.max() if pos.size else 1.0) * np.sqrt(np.finfo(float).eps)
    low = present & (sig < floor)
    if low.any():
        warnings.append(
            f"{label} of joint(s) {[int(j) + 1 for j in np.flatnonzero(low)]} is (nearly) zero; "
            f"floored to {floor:.3g} to weight the rows")
        sig[low] = floor
    sig[~present] = 1.0
    return sig, warnings


# ---------------------------------------------------------------------------- fits on column subsets
def fit_raw(acc: Accumulator, method: str, active: Sequence[int] | None = None,
            opts: Options = Options(), weighting: str | None = None,
            what: str | None = None) -> RawFit:
    """Fit on the columns ``active`` of an accumulator (internal building block)."""
    method = method.lower()
    active = tuple(range(acc.n_params)) if active is None else tuple(int(i) for i in active)
    names = [acc.names[i] for i in active]
    what = what or f"IDIM-{method.upper()}"
    nj = acc.n_joints
    r = acc.n_rows
    if method in ("ols", "wls"):
        _check_problem(acc, active, 0, what)
        blocks = [acc.factor(j, active) for j in range(nj)]
        joint_sigma = None
        pre = []
        if method == "wls":
            sig = []
            for j in range(nj):
                if acc.rows[j] == 0:
                    sig.append(1.0)
                    continue
                s_j, dof_j = _joint_ols_sigma(blocks[j], acc.rows[j], opts)
                if dof_j <= 0:
                    pre.append(f"joint {j + 1}: {acc.rows[j]} equations for {acc.rows[j] - dof_j} "
                               f"independent columns: its sigma_j (eq. 22) is unreliable")
                sig.append(s_j)
            joint_sigma, w = _group_sigmas(acc, active, sig, opts, "sigma_j (eq. 22)")
            pre += w
            blocks = [b / joint_sigma[j] for j, b in enumerate(blocks)]
        M = np.vstack(blocks)
        values, cov, std, sigma, cond, cond_s, warnings = _ols_core(M, r, names, opts, what)
        label = "WLS" if method == "wls" else "OLS"
    elif method == "tls":
        _check_problem(acc, active, 1, what)
        blocks = [acc.factor(j, active) * np.r_[np.ones(len(active)), -1.0] for j in range(nj)]
        joint_sigma = None
        pre = []
        if weighting in ("joint", "joints", True):
            values0, *_ = _tls_core(np.vstack(blocks), r, names, opts, what)
            xtot = np.r_[values0, 1.0]
            c = len(active) + 1
            sig = []
            for j in range(nj):
                if acc.rows[j] == 0:
                    sig.append(1.0)
                    continue
                rho = np.linalg.norm(blocks[j] @ xtot)
                dof = acc.rows[j] * (r - c) / r
                sig.append(rho / (np.linalg.norm(xtot) * math.sqrt(dof)))
            joint_sigma, w = _group_sigmas(acc, active, sig, opts, "sigma_W^j")
            pre += w
            blocks = [b / joint_sigma[j] for j, b in enumerate(blocks)]
        elif weighting not in (None, False, "none"):
            raise IdentificationError(f"{what}: unknown TLS weighting {weighting!r}; use None or 'joint'")
        Mt = np.vstack(blocks)
        values, cov, std, sigma, cond, cond_s, warnings = _tls_core(Mt, r, names, opts, what)
        label = "TLS-W" if joint_sigma is not None else "TLS"
        # TLS residual vs the smallest possible (LS) one on the same (weighted) rows: a large excess
        # means the errors in W are not the i.i.d. ones eq. 14 assumes (e.g. unscaled columns)
        res_tls = np.linalg.norm(Mt @ np.r_[values, 1.0])
        Mls = Mt * np.r_[np.ones(len(active)), -1.0]
        x_ls = np.linalg.lstsq(Mls[:, :-1], Mls[:, -1], rcond=None)[0]
        res_ls = np.linalg.norm(Mls[:, :-1] @ x_ls - Mls[:, -1])
        if res_tls > opts.tls_residual_warn * res_ls:
            warnings.append(
                f"the TLS residual is {res_tls / res_ls:.3g} times the least-squares one on the same rows: "
                f"the errors in W are not i.i.d. with those in Y as TLS assumes (eq. 14); the TLS "
                f"estimate is unreliable - prefer OLS/WLS or scale the columns")
    else:
        raise IdentificationError(f"unknown identification method {method!r}; use 'ols', 'wls' or 'tls'")
    return RawFit(label, active, values, cov, std, sigma, cond, cond_s, joint_sigma, tuple(pre + warnings))


def rel_err_from_factors(acc: Accumulator, active: Sequence[int], values: np.ndarray) -> np.ndarray:
    """``||Y_j - W_j x|| / ||Y_j||`` per joint from the factors, shape (n_joints,)."""
    xt = np.r_[values, -1.0]
    out = np.full(acc.n_joints, np.nan)
    for j in range(acc.n_joints):
        if acc.rows[j] > 0 and acc.yy[j] > 0:
            out[j] = np.linalg.norm(acc.factor(j, active) @ xt) / math.sqrt(acc.yy[j])
    return out


def make_result(raw: RawFit, acc: Accumulator, system: ObservationSystem | None, opts: Options,
                eliminated: Sequence[str] = (), keep: Sequence[str] = (),
                extra_warnings: Sequence[str] = ()) -> IdentificationResult:
    """Wrap a :class:`RawFit` into an :class:`IdentificationResult` (residuals, error norms, warnings)."""
    names = tuple(acc.names[i] for i in raw.active)
    if system is not None:
        residual = system.Y - system.W[:, list(raw.active)] @ raw.values
        rel_err = per_joint_rel_err(residual, system.Y, system.joint, max(system.n_joints, acc.n_joints))
    else:
        residual = None
        rel_err = rel_err_from_factors(acc, raw.active, raw.values)
    warnings = (list(extra_warnings) + list(raw.warnings)
                + poorly_identified_warnings(names, raw.values, raw.std, opts, keep))
    return IdentificationResult(
        method=raw.method, names=names, values=raw.values, std=raw.std,
        rel_std_pct=raw.rel_std_pct, cov=raw.cov, cond=raw.cond, cond_scaled=raw.cond_scaled,
        sigma=raw.sigma, rel_err=rel_err, n_rows=acc.n_rows, residual=residual,
        joint_sigma=raw.joint_sigma, eliminated=tuple(eliminated), warnings=tuple(warnings))


def _opts(rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol) -> Options:
    return Options(rank_tol=rank_tol, cond_warn=cond_warn, rel_std_warn_pct=rel_std_warn_pct,
                   zero_col_tol=zero_col_tol)


# ---------------------------------------------------------------------------- public estimators
def fit_ols(data: ObservationSystem | Accumulator, *, rank_tol: float = RANK_TOL,
            cond_warn: float = COND_WARN, rel_std_warn_pct: float = REL_STD_WARN_PCT,
            zero_col_tol: float = ZERO_COL_TOL) -> IdentificationResult:
    """IDIM-OLS (RX-90 paper eq. 17-21).

    Parameters
    ----------
    data : ObservationSystem or Accumulator
        ``Y (r,) = W (r, c) chi + rho``. Row ``weights`` of the system, when present, are applied
        (each row of W and Y multiplied by its weight); error norms use the unweighted rows.
    rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol : float
        Tolerances (see module constants).

    Returns
    -------
    IdentificationResult
        ``sigma`` is sigma_rho (eq. 19); ``cov`` = sigma_rho^2 (W'W)^-1 (eq. 20).

    Raises
    ------
    IdentificationError
        Non-finite data, all-zero columns, r <= c.
    """
    opts = _opts(rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol)
    acc, system = as_accumulator(data, use_weights=True)
    return make_result(fit_raw(acc, "ols", None, opts), acc, system, opts)


def fit_wls(data: ObservationSystem | Accumulator, *, rank_tol: float = RANK_TOL,
            cond_warn: float = COND_WARN, rel_std_warn_pct: float = REL_STD_WARN_PCT,
            zero_col_tol: float = ZERO_COL_TOL) -> IdentificationResult:
    """IDIM-WLS (RX-90 paper eq. 22): rows of joint j weighted by 1/sigma_j.

    sigma_j is the standard deviation of the OLS solution of the joint-j equations alone
    (``||Y_j - W_j chi_j||^2 / (r_j - rank(W_j))``). Row weights stored in the system are ignored
    (this estimator computes its own); they are reported as ``joint_sigma``.

    Returns
    -------
    IdentificationResult
        ``sigma`` is the standard deviation of the weighted residual (about 1).
    """
    opts = _opts(rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol)
    acc, system = as_accumulator(data, use_weights=False)
    return make_result(fit_raw(acc, "wls", None, opts), acc, system, opts)


def fit_tls(data: ObservationSystem | Accumulator, weighting: str | None = None, *,
            rank_tol: float = RANK_TOL, cond_warn: float = COND_WARN,
            rel_std_warn_pct: float = REL_STD_WARN_PCT, zero_col_tol: float = ZERO_COL_TOL
            ) -> IdentificationResult:
    """IDIM-TLS (LWR4 paper eq. 10-16) of ``W chi ~ Y`` (errors in W and Y).

    Parameters
    ----------
    data : ObservationSystem or Accumulator
    weighting : None or "joint"
        ``"joint"``: each row of joint j is weighted by ``1/sigma_W^j``, where
        ``sigma_W^j = ||W_tot^j x_tot|| / (||x_tot|| sqrt(r_j (r - c) / r))`` is the joint-j noise
        level implied by an unweighted TLS solution (LWR4 paper Sec. III-D).
        Row weights stored in the system are applied when ``weighting`` is None.

    Returns
    -------
    IdentificationResult
        ``sigma`` is sigma_W (eq. 15), ``cov`` eq. 16, ``cond`` that of W.
    """
    opts = _opts(rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol)
    acc, system = as_accumulator(data, use_weights=weighting in (None, False, "none"))
    return make_result(fit_raw(acc, "tls", None, opts, weighting=weighting), acc, system, opts)
