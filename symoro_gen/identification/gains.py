"""Drive gains (RX-90 paper eq. 25-27) and torque-sensor gains (LWR4 paper eq. 8-16).

Both use an unloaded experiment ``(a)`` and a loaded one ``(b)`` with a (partly) known payload.
``Y`` holds the measured signal ``v`` (current references or sensor outputs in the a-priori units
of the controller, i.e. ``tau = g v`` with a-priori gains 1): the identified gains are relative
to the a-priori ones.

* :func:`drive_gains`: for each joint j separately (eq. 27),
  ``V^j = [[W_a^j, 0], [W_b^j, W_L^j chi_L]] [chi^{j,n}/g_j; 1/g_j] + rho^j/g_j``, using only the
  columns that are non-zero in the joint-j equations; weighted LS with the unloaded and loaded
  equations weighted by their own error standard deviation; ``g_j = 1 / x_last`` and
  ``%sigma(g_j) = %sigma(1/g_j)`` (first-order propagation ``sigma_g = g^2 sigma_{1/g}``).
* :func:`sensor_gains`: all gains and parameters at once by IDIM-TLS (eq. 8-13):
  ``W_tot = [[V_a, -W_a, 0, 0], [V_b, -W_b, -W_ul, -W_kl chi_kl]]``, solution normalised so that
  its last coefficient is 1, statistics eq. 14-16, rows of joint j weighted by ``1/sigma_W^j``.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..errors import IdentificationError
from .accumulate import check_finite, factor_system
from .essential import essential_raw
from .estimators import (
    COND_WARN,
    RANK_TOL,
    REL_STD_WARN_PCT,
    ZERO_COL_TOL,
    Options,
    fit_ols,
    fit_raw,
    fit_wls,
    poorly_identified_warnings,
)
from .observation import ObservationSystem
from .payload import fit_with_known_payload, split_experiments
from .render import drive_gains_html
from .result import Gains, IdentificationResult, fmt_number, per_joint_rel_err, relative_std_pct

#: ||W_L^j chi_L|| / ||V_b^j|| below which the payload does not excite joint j (gain not identifiable)
PAYLOAD_EXCITATION_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class DriveGainsResult:
    """Per-joint drive gains (RX-90 paper Table 4).

    Attributes
    ----------
    gains : Gains
        ``g_j`` with std and %sigma for the joints that could be identified.
    per_joint : tuple of IdentificationResult
        The weighted LS solution of eq. 27 for each identified joint; parameters are
        ``<name>/g<j>`` and ``1/g<j>``; its ``rel_err`` has two entries: unloaded and loaded equations.
    warnings : tuple of str
    """

    gains: Gains
    per_joint: tuple[IdentificationResult, ...]
    warnings: tuple[str, ...] = ()

    def summary(self) -> str:
        lines = ["Drive gains, per-joint weighted LS with a known payload (eq. 27)", "",
                 f"{'':<10}" + "".join(f"{'joint ' + str(j + 1):>12}" for j in self.gains.joints),
                 f"{'g':<10}" + "".join(fmt_number(v, 12) for v in self.gains.values),
                 f"{'2 sigma':<10}" + "".join(fmt_number(2 * s, 12) for s in self.gains.std),
                 f"{'%sigma':<10}" + "".join(f"{p:>12.2f}" for p in self.gains.rel_std_pct),
                 f"{'cond(W)':<10}" + "".join(fmt_number(r.cond, 12) for r in self.per_joint)]
        if self.warnings:
            lines += ["", "Warnings:"] + [f"[{i}] {w}" for i, w in enumerate(self.warnings, 1)]
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """Jupyter: the gains with 2 sigma, %sigma and cond(W) per joint as an HTML table, then warnings."""
        return drive_gains_html(self)

    def to_dict(self) -> dict:
        return {"gains": self.gains.to_dict(), "warnings": list(self.warnings),
                "per_joint": [{"joint": j + 1, "cond": r.cond, "sigma": r.sigma,
                               "rel_err": [float(e) for e in r.rel_err]}
                              for j, r in zip(self.gains.joints, self.per_joint)]}


def _robot_and_payload(unloaded, loaded, payload_names):
    check_finite(unloaded, "unloaded system")
    if loaded is not None:
        check_finite(loaded, "loaded system")
    unloaded, loaded, pay = split_experiments(unloaded, loaded, payload_names)
    robot = [n for n in loaded.names if n not in pay]
    return unloaded, loaded, robot, pay


def drive_gains(unloaded: ObservationSystem, loaded: ObservationSystem | None, payload: Mapping[str, float],
                joints: Sequence[int] | None = None, *, weighted: bool = True,
                payload_names: Sequence[str] | None = None,
                rank_tol: float = RANK_TOL, zero_col_tol: float = ZERO_COL_TOL,
                payload_excitation_tol: float = PAYLOAD_EXCITATION_TOL,
                rel_std_warn_pct: float = REL_STD_WARN_PCT) -> DriveGainsResult:
    """Drive gain of each joint with a known payload (RX-90 paper eq. 25-27).

    Parameters
    ----------
    unloaded : ObservationSystem
        ``V_a = W_a chi / g`` (rows of every joint; ``Y`` = measured signal v). With ``loaded=None``:
        the combined system of both experiments (payload columns zero on unloaded rows, see
        :func:`~symoro_gen.identification.payload.split_experiments`; needs ``payload_names``).
    loaded : ObservationSystem or None
        Same robot columns + payload columns.
    payload : mapping name -> value
        All payload parameters appearing in ``loaded`` (CAD or measured values, SI units).
    joints : sequence of int, optional
        0-based joints whose gain is wanted (default: every joint present in both systems).
    weighted : bool
        Weight the unloaded and loaded equations of joint j by the inverse of their own OLS error
        standard deviation (eq. 22 applied to the two experiments); False: OLS.
    payload_names : sequence of str, optional
        Payload columns (default: columns of ``loaded`` absent from ``unloaded``).
    rank_tol, zero_col_tol : float
        Column selection: columns with norm <= zero_col_tol * max in the joint-j equations are
        dropped (chi^{j,n}: parameters of links j..n only), and columns dependent within the joint-j
        equations (column-pivoted QR, relative tolerance rank_tol) are left out.
    payload_excitation_tol : float
        Minimum ``||W_L^j chi_L|| / ||V_b^j||`` for the gain of joint j to be identifiable.

    Returns
    -------
    DriveGainsResult
    """
    unloaded, loaded, robot, pay = _robot_and_payload(unloaded, loaded, payload_names)
    missing = [n for n in pay if n not in payload]
    if missing:
        raise IdentificationError(f"drive gains need every payload parameter; missing values for {missing}")
    unknown = [n for n in payload if n not in pay]
    if unknown:
        raise IdentificationError(f"payload parameters {unknown} are not columns of the loaded system {loaded.names}")
    chi_l = np.array([float(payload[n]) for n in pay])
    ia = [unloaded.names.index(n) for n in robot]
    ib = [loaded.names.index(n) for n in robot]
    il = [loaded.names.index(n) for n in pay]
    if joints is None:
        joints = sorted(set(unloaded.joint.tolist()) & set(loaded.joint.tolist()))
    warnings, results, gj, gv, gs, gp = [], [], [], [], [], []
    for j in joints:
        j = int(j)
        ra, rb = unloaded.joint == j, loaded.joint == j
        if not ra.any() or not rb.any():
            raise IdentificationError(
                f"joint {j + 1}: needs equations in both the unloaded ({int(ra.sum())} rows) and the "
                f"loaded ({int(rb.sum())} rows) experiments")
        Wa = unloaded.W[ra][:, ia]
        Wb = loaded.W[rb][:, ib]
        wl = loaded.W[rb][:, il] @ chi_l
        Va, Vb = unloaded.Y[ra], loaded.Y[rb]
        nvb = np.linalg.norm(Vb)
        if np.linalg.norm(wl) <= payload_excitation_tol * max(nvb, np.finfo(float).tiny):
            warnings.append(f"joint {j + 1}: the known payload does not act on this joint "
                            f"(||W_L chi_L|| / ||V_b|| = {np.linalg.norm(wl) / max(nvb, 1e-300):.2e}); "
                            f"its gain is not identified")
            continue
        Wr = np.vstack([Wa, Wb])
        norms = np.linalg.norm(Wr, axis=0)
        top = norms.max() if norms.size else 0.0
        nz = np.flatnonzero(norms > zero_col_tol * top) if top > 0 else np.array([], int)
        # independent robot columns within the joint-j equations, once the payload column is accounted for
        gcol = np.r_[np.zeros(Va.size), wl]
        q = gcol / np.linalg.norm(gcol)
        P = Wr[:, nz] / norms[nz]
        P = P - np.outer(q, q @ P)
        chosen = nz
        if nz.size:
            _, Rq, piv = scipy.linalg.qr(P, mode="economic", pivoting=True)
            d = np.abs(np.diag(Rq))
            rank = int(np.sum(d > rank_tol * max(d[0], rank_tol))) if d.size and d[0] > 0 else 0
            chosen = np.sort(nz[piv[:rank]])
            dropped = [robot[i] for i in nz[piv[rank:]]]
            if dropped:
                warnings.append(f"joint {j + 1}: columns {dropped} depend on the others within the joint-{j + 1} "
                                f"equations and are left out (their effect is regrouped)")
        names = tuple(f"{robot[i]}/g{j + 1}" for i in chosen) + (f"1/g{j + 1}",)
        W = np.column_stack([Wr[:, chosen], gcol])
        system = ObservationSystem(W, np.r_[Va, Vb], names,
                                   np.r_[np.zeros(Va.size, int), np.ones(Vb.size, int)])
        if W.shape[0] <= W.shape[1]:
            raise IdentificationError(f"joint {j + 1}: too few equations ({W.shape[0]}) for {W.shape[1]} unknowns")
        fit = (fit_wls if weighted else fit_ols)(system, rank_tol=rank_tol, zero_col_tol=zero_col_tol,
                                                 rel_std_warn_pct=math.inf)
        x, sx = fit.values[-1], fit.std[-1]
        if not x > 0 and not x < 0:
            warnings.append(f"joint {j + 1}: 1/g estimated as 0; gain not identified")
            continue
        g = 1.0 / x
        results.append(fit)
        gj.append(j)
        gv.append(g)
        gs.append(sx * g * g)
        gp.append(float(relative_std_pct([x], [sx])[0]))
        if gp[-1] > rel_std_warn_pct:
            warnings.append(f"joint {j + 1}: drive gain poorly identified (%sigma = {gp[-1]:.3g}); "
                            f"a payload with larger effect on this joint is needed")
        warnings += [f"joint {j + 1}: {w}" for w in fit.warnings]
    if not gj:
        raise IdentificationError("no drive gain could be identified: " + "; ".join(warnings))
    return DriveGainsResult(Gains(tuple(gj), np.asarray(gv), np.asarray(gs), np.asarray(gp)), tuple(results),
                            tuple(warnings))


def identify_with_drive_gains(unloaded: ObservationSystem, loaded: ObservationSystem | None,
                              payload: Mapping[str, float], joints: Sequence[int] | None = None,
                              method: str = "wls", *, reidentify_payload: bool = True,
                              payload_names: Sequence[str] | None = None, **tolerances
                              ) -> tuple[IdentificationResult, DriveGainsResult]:
    """Drive gains (eq. 27), then robot (and payload) parameters with the torques ``g v``
    (RX-90 paper Table 3, case 2).

    Parameters
    ----------
    reidentify_payload : bool
        True: payload parameters re-estimated with the robot (a check of the gains, Table 3);
        False: the known payload values are kept on the left-hand side (eq. 7).

    Returns
    -------
    (IdentificationResult, DriveGainsResult)
        The parameter result carries the gains (``result.gains``).
    """
    dg = drive_gains(unloaded, loaded, payload, joints, payload_names=payload_names)
    known = {} if reidentify_payload else dict(payload)
    res = fit_with_known_payload(unloaded, loaded, known, method=method, payload_names=payload_names,
                                 gains=dg.gains, **tolerances)
    return dataclasses.replace(res, gains=dg.gains, warnings=dg.warnings + res.warnings), dg


def sensor_gains(unloaded: ObservationSystem, loaded: ObservationSystem | None, known: Mapping[str, float],
                 weighting: str | None = "joint", *, essential: bool = False, r_sigma: float = 30.0,
                 payload_names: Sequence[str] | None = None, rank_tol: float = RANK_TOL,
                 cond_warn: float = COND_WARN, rel_std_warn_pct: float = REL_STD_WARN_PCT,
                 zero_col_tol: float = ZERO_COL_TOL) -> IdentificationResult:
    """Global identification of the torque-sensor gains, robot and unknown payload parameters by
    IDIM-TLS (LWR4 paper eq. 8-16).

    Parameters
    ----------
    unloaded : ObservationSystem
        ``Y_a`` = sensor signals v, columns: robot base parameters. With ``loaded=None``: the
        combined system of both experiments (needs ``payload_names``).
    loaded : ObservationSystem or None
        Same robot columns + payload columns.
    known : mapping name -> value
        Known payload parameters chi_kl (at least one, e.g. ``{"M8": 4.6136}``: it fixes the scale).
    weighting : None or "joint"
        Rows of joint j weighted by ``1/sigma_W^j`` (LWR4 Sec. III-D; default).
    essential : bool
        Reduce to the essential parameters (gains are never cancelled nor counted in the ratio).
    r_sigma : float
    payload_names : sequence of str, optional

    Returns
    -------
    IdentificationResult
        ``gains`` holds g_j with std and %sigma (eq. 16); parameters are chi and chi_ul; ``fixed``
        holds chi_kl; ``cov`` is the parameter block of eq. 16; ``rel_err`` is
        ``||g_j v_j - W_j chi|| / ||g_j v_j||``; ``cond`` is that of ``[V, -W, -W_ul]``.
    """
    opts = Options(rank_tol=rank_tol, cond_warn=cond_warn, rel_std_warn_pct=rel_std_warn_pct,
                   zero_col_tol=zero_col_tol)
    unloaded, loaded, robot, pay = _robot_and_payload(unloaded, loaded, payload_names)
    bad = [k for k in known if k not in pay]
    if bad:
        raise IdentificationError(f"known parameters {bad} are not payload columns {pay}")
    if not known:
        raise IdentificationError(
            "sensor gains need at least one known payload parameter (e.g. its weighed mass): without it "
            "gains and parameters are only determined up to a common scale (eq. 11)")
    ul = [n for n in pay if n not in known]
    n = max(unloaded.n_joints, loaded.n_joints)
    ra, rb = unloaded.Y.size, loaded.Y.size
    joint = np.r_[unloaded.joint, loaded.joint]
    Y = np.r_[unloaded.Y, loaded.Y]
    V = np.zeros((ra + rb, n))
    V[np.arange(ra + rb), joint] = Y                                   # eq. 9
    Wr = np.vstack([unloaded.W[:, [unloaded.names.index(c) for c in robot]],
                    loaded.W[:, [loaded.names.index(c) for c in robot]]])
    Wul = np.vstack([np.zeros((ra, len(ul))), loaded.W[:, [loaded.names.index(c) for c in ul]]])
    kl = list(known)
    b = np.r_[np.zeros(ra), loaded.W[:, [loaded.names.index(c) for c in kl]] @ np.array([float(known[c]) for c in kl])]
    gnames = tuple(f"g{j + 1}" for j in range(n))
    A = np.column_stack([V, -Wr, -Wul])                              # W_tot = [A  -b]  (eq. 10)
    system = ObservationSystem(A, b, gnames + tuple(robot) + tuple(ul), joint)
    acc = factor_system(system)
    what = "IDIM-TLS sensor gains"
    if essential:
        raw, _, history = essential_raw(acc, "tls", r_sigma, gnames, opts, weighting, what=what)
    else:
        raw, history = fit_raw(acc, "tls", None, opts, weighting=weighting, what=what), ()
    active = list(raw.active)
    gpos = [k for k, a in enumerate(active) if a < n]
    ppos = [k for k, a in enumerate(active) if a >= n]
    g = raw.values[gpos]
    gstd = raw.std[gpos]
    x = raw.values[ppos]
    pnames = tuple(acc.names[active[k]] for k in ppos)
    residual = A[:, active] @ raw.values - b                         # g v - W chi - W_kl chi_kl
    y = Y * g[joint]
    rel_err = per_joint_rel_err(residual, y, joint, n)
    gains = Gains(tuple(range(n)), g, gstd, relative_std_pct(g, gstd))
    warnings = list(raw.warnings) + poorly_identified_warnings(pnames, x, raw.std[ppos], opts)
    badg = [f"g{j + 1} ({p:.3g}%)" for j, p in enumerate(gains.rel_std_pct) if p > opts.rel_std_warn_pct]
    if badg:
        warnings.append(f"gains poorly identified: {', '.join(badg)}")
    return IdentificationResult(
        method=raw.method, names=pnames, values=x, std=raw.std[ppos],
        rel_std_pct=relative_std_pct(x, raw.std[ppos]), cov=raw.cov[np.ix_(ppos, ppos)],
        cond=raw.cond, cond_scaled=raw.cond_scaled, sigma=raw.sigma, rel_err=rel_err,
        n_rows=acc.n_rows, residual=residual, joint_sigma=raw.joint_sigma, gains=gains,
        fixed=tuple((k, float(known[k])) for k in kl), eliminated=tuple(s.removed for s in history),
        warnings=tuple(warnings))
