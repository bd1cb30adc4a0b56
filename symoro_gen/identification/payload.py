"""Identification with a payload (LWR4 paper eq. 5 and 7; Khalil, Gautier & Lemoine 2007).

* :func:`fit_with_known_payload`: robot base parameters and the unknown payload parameters from an
  unloaded and a loaded experiment, ``[[W_a, 0, 0], [W_b, W_ul, W_kl]] [chi; chi_ul; chi_kl]``,
  with the known part ``W_kl chi_kl`` moved to the left-hand side.
* :func:`identify_payload`: payload parameters only, the robot model being known
  (LWR4 Table IV, RX-90 Sec. IV: payload mass re-identified with its %sigma).
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg

from ..errors import IdentificationError
from .accumulate import Accumulator
from .estimators import COND_WARN, RANK_TOL, REL_STD_WARN_PCT, ZERO_COL_TOL, Tolerances, tolerance_keywords
from .method import identify
from .observation import ObservationSystem
from .result import IdentificationResult, per_joint_rel_err
from .streaming import fix_known, pad_columns, stack_factors
from .systems import apply_gains, fix_parameters, select_rows, stack_systems

if TYPE_CHECKING:
    from typing_extensions import Unpack


def split_experiments(unloaded: ObservationSystem, loaded: ObservationSystem | None,
                      payload_names: Sequence[str] | None = None
                      ) -> tuple[ObservationSystem, ObservationSystem, tuple[str, ...]]:
    """Bring the two accepted layouts to (unloaded without payload columns, loaded with them).

    Layouts
    -------
    * two systems: ``unloaded`` (robot columns, or robot + all-zero payload columns) and ``loaded``
      (robot + payload columns);
    * one combined system (``loaded=None``), as assembled with payload columns: rows whose payload
      columns are all zero are the unloaded ones. ``payload_names`` is then required.

    Returns
    -------
    (unloaded, loaded, payload_names)
    """
    if loaded is None:
        if payload_names is None:
            raise IdentificationError(
                "a combined (unloaded + loaded) system needs payload_names to tell the payload columns")
        pay = tuple(payload_names)
        bad = [n for n in pay if n not in unloaded.names]
        if bad:
            raise IdentificationError(f"payload parameters {bad} are not columns of the system {unloaded.names}")
        P = unloaded.W[:, [unloaded.names.index(n) for n in pay]]
        is_loaded = np.any(P != 0.0, axis=1)
        if not is_loaded.any():
            raise IdentificationError("the combined system has no loaded row (payload columns all zero)")
        if is_loaded.all():
            raise IdentificationError("the combined system has no unloaded row (payload columns never all zero)")
        combined = unloaded
        unloaded = select_rows(combined, ~is_loaded)
        loaded = select_rows(combined, is_loaded)
    elif payload_names is None:
        pay = tuple(n for n in loaded.names if n not in unloaded.names)
    else:
        pay = tuple(payload_names)
    bad = [n for n in pay if n not in loaded.names]
    if bad:
        raise IdentificationError(f"payload parameters {bad} are not columns of the loaded system")
    if not pay:
        raise IdentificationError(
            "the loaded system has no payload column (columns of the loaded system absent from the "
            "unloaded one); assemble it with the payload regressor or give payload_names")
    in_un = [n for n in pay if n in unloaded.names]
    if in_un:
        idx = [unloaded.names.index(n) for n in in_un]
        if np.any(unloaded.W[:, idx] != 0.0):
            raise IdentificationError(
                f"the unloaded system has non-zero payload columns {in_un}: is it really unloaded?")
        keep = [i for i, n in enumerate(unloaded.names) if n not in in_un]
        unloaded = ObservationSystem(unloaded.W[:, keep], unloaded.Y, tuple(unloaded.names[i] for i in keep),
                                     unloaded.joint, unloaded.weights)
    missing = [n for n in unloaded.names if n not in loaded.names]
    if missing:
        raise IdentificationError(
            f"the loaded system lacks robot columns {missing} of the unloaded one; both must come "
            f"from the same model")
    return unloaded, loaded, pay


def fit_with_known_payload(unloaded: ObservationSystem, loaded: ObservationSystem | None,
                           known: Mapping[str, float], method: str = "wls", *,
                           essential: bool = False, r_sigma: float = 30.0, weighting: str | None = None,
                           payload_names: Sequence[str] | None = None, gains=None, **tolerances: Unpack[Tolerances]
                           ) -> IdentificationResult:
    """Robot base parameters + unknown payload parameters with a partly known payload (eq. 7).

    Parameters
    ----------
    unloaded : ObservationSystem
        ``Y_a = W_a chi``, columns: robot base parameters (payload columns allowed if all zero).
        With ``loaded=None``: the combined system of both experiments (see :func:`split_experiments`).
    loaded : ObservationSystem or None
        ``Y_b = W_b chi + W_L chi_L``, columns: the same robot parameters + the payload's (e.g.
        ``XX8 ... M8``).
    known : mapping name -> value
        Known payload parameters chi_kl (e.g. ``{"M8": 4.6136}``; may be empty).
    method : {"ols", "wls", "tls"}
    essential, r_sigma, weighting
        See :func:`identify`.
    payload_names : sequence of str, optional
        Payload columns; default: columns of ``loaded`` not in ``unloaded``.
    gains : Gains or array_like (n_joints,), optional
        Measurements scaled by these gains first (``tau = g v``).
    **tolerances
        rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol (:class:`~.estimators.Tolerances`).

    Returns
    -------
    IdentificationResult
        Parameters ``chi`` and ``chi_ul``; ``fixed`` holds ``chi_kl``.
    """
    tol_kw = tolerance_keywords("fit_with_known_payload", dict(tolerances))
    unloaded, loaded, pay = split_experiments(unloaded, loaded, payload_names)
    bad = [k for k in known if k not in pay]
    if bad:
        raise IdentificationError(f"known parameters {bad} are not payload columns {pay}")
    if gains is not None:
        unloaded, loaded = apply_gains(unloaded, gains), apply_gains(loaded, gains)
    full = stack_systems(unloaded, loaded)
    system = fix_parameters(full, known)
    res = identify(system, method=method, essential=essential, r_sigma=r_sigma, weighting=weighting, **tol_kw)
    # same residual; error norms relative to the measured torques, not to Y - W_kl chi_kl
    assert res.residual is not None  # identify() on a system keeps its residual
    rel_err = per_joint_rel_err(res.residual, full.Y, full.joint, res.rel_err.size)
    return dataclasses.replace(res, fixed=tuple((k, float(v)) for k, v in known.items()), rel_err=rel_err)


def fit_with_known_payload_factors(unloaded: Accumulator, loaded: Accumulator, known: Mapping[str, float],
                                   method: str = "wls", *, essential: bool = False, r_sigma: float = 30.0,
                                   **tolerances: Unpack[Tolerances]) -> IdentificationResult:
    """:func:`fit_with_known_payload` on streamed data (LWR4 paper eq. 7): the per-joint QR factors of the
    unloaded recordings (robot columns) and of the loaded ones (robot + payload columns), e.g.
    :func:`~.streaming.stream_assembly`'s. The same estimate: the unloaded factors get zero payload columns,
    both are stacked (:func:`~.streaming.stack_factors`), the known columns moved to the right-hand side
    (:func:`~.streaming.fix_known`); the error norms are relative to the measured torques."""
    tol_kw = tolerance_keywords("fit_with_known_payload_factors", dict(tolerances))
    pay = tuple(n for n in loaded.names if n not in unloaded.names)
    missing = [n for n in unloaded.names if n not in loaded.names]
    if missing:
        raise IdentificationError(f"the loaded data lack robot columns {missing} of the unloaded ones; both must "
                                  "come from the same model")
    if not pay:
        raise IdentificationError("the loaded data have no payload column: assemble them with the payload regressor")
    bad = [k for k in known if k not in pay]
    if bad:
        raise IdentificationError(f"known parameters {bad} are not payload columns {pay}")
    full = stack_factors(pad_columns(unloaded, loaded.names), loaded)
    res = identify(fix_known(full, known), method=method, essential=essential, r_sigma=r_sigma, **tol_kw)
    x = np.array([res.parameter_map().get(n, 0.0) for n in full.names] + [-1.0])
    for k, v in known.items():
        x[full.names.index(k)] = float(v)
    rel_err = np.full(full.n_joints, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        for j in range(full.n_joints):
            if full.rows[j] > 0:
                rel_err[j] = np.linalg.norm(full.R[j] @ x) / math.sqrt(full.yy[j])
    return dataclasses.replace(res, fixed=tuple((k, float(v)) for k, v in known.items()), rel_err=rel_err)


def identify_payload(loaded: ObservationSystem, robot: Mapping[str, float] | IdentificationResult,
                     payload_names: Sequence[str] | None = None, *, known: Mapping[str, float] | None = None,
                     gains=None, method: str = "wls", weighting: str | None = None,
                     rank_tol: float = RANK_TOL, cond_warn: float = COND_WARN,
                     rel_std_warn_pct: float = REL_STD_WARN_PCT, zero_col_tol: float = ZERO_COL_TOL
                     ) -> IdentificationResult:
    """Payload parameters with the robot model known (LWR4 Table IV, RX-90 Sec. IV).

    ``Y_b - W_b chi_robot - W_kl chi_kl = W_L' chi_L' + rho``, solved for the identifiable subset
    ``chi_L'`` of the payload parameters (independent payload columns chosen by a column-pivoted QR
    of the unit-norm columns; the others are reported in a warning and left out).

    Parameters
    ----------
    loaded : ObservationSystem
        Loaded experiment: robot columns + payload columns.
    robot : mapping name -> value, or IdentificationResult
        Robot parameters (a result's :meth:`~IdentificationResult.parameter_map`, eliminated ones 0).
        Entries named like payload columns are ignored.
    payload_names : sequence of str, optional
        Payload columns; default: the columns of ``loaded`` not in ``robot``.
    known : mapping, optional
        Known payload parameters, moved to the left-hand side too.
    gains : Gains or array_like (n_joints,), optional
        Measurements scaled by these gains (``tau = g v``, LWR4 Sec. IV-C).
    method : {"ols", "wls", "tls"}

    Returns
    -------
    IdentificationResult
        Payload parameters (e.g. ``M8`` with its %sigma, Table IV); ``fixed`` holds the robot
        values and known payload values used.
    """
    robot_map = robot.parameter_map() if isinstance(robot, IdentificationResult) else dict(robot)
    known = dict(known or {})
    if payload_names is None:
        pay = tuple(n for n in loaded.names if n not in robot_map and n not in known)
    else:
        pay = tuple(payload_names)
        bad = [n for n in pay if n not in loaded.names]
        if bad:
            raise IdentificationError(f"payload parameters {bad} are not columns of the loaded system")
    unknown_pay = tuple(n for n in pay if n not in known)
    if not unknown_pay:
        raise IdentificationError("identify_payload: no payload parameter left to identify")
    robot_cols = [n for n in loaded.names if n not in pay]
    missing = [n for n in robot_cols if n not in robot_map]
    if missing:
        raise IdentificationError(
            f"identify_payload: robot parameter(s) {missing} of the loaded system have no value; "
            f"give them in `robot` (or list them in payload_names)")
    fixed = {n: float(robot_map[n]) for n in robot_cols}
    fixed.update({k: float(v) for k, v in known.items() if k in loaded.names})
    bad = [k for k in known if k not in loaded.names]
    if bad:
        raise IdentificationError(f"known payload parameters {bad} are not columns of the loaded system")
    if gains is not None:
        loaded = apply_gains(loaded, gains)
    system = fix_parameters(loaded, fixed)
    # identifiable subset of the payload columns
    W = system.W
    norms = np.linalg.norm(W, axis=0)
    top = norms.max() if norms.size else 0.0
    zero = norms <= zero_col_tol * top if top > 0 else np.ones(norms.shape, bool)
    warnings = []
    if zero.any():
        warnings.append(f"payload parameter(s) {[system.names[i] for i in np.flatnonzero(zero)]} have no "
                        f"effect on these data and are not identified")
    cand = np.flatnonzero(~zero)
    if cand.size == 0:
        raise IdentificationError("identify_payload: the payload columns of W are all zero "
                                  "(payload not excited by these data)")
    _, Rq, piv = scipy.linalg.qr(W[:, cand] / norms[cand], mode="economic", pivoting=True)
    d = np.abs(np.diag(Rq))
    rank = int(np.sum(d > rank_tol * d[0]))
    chosen = np.sort(cand[piv[:rank]])
    dropped = [system.names[i] for i in cand[piv[rank:]]]
    if dropped:
        warnings.append(f"payload parameter(s) {dropped} are not separately identifiable from these data "
                        f"(their columns depend on the others): left out, the others absorb their effect")
    sub = ObservationSystem(W[:, chosen], system.Y, tuple(system.names[i] for i in chosen), system.joint,
                            system.weights)
    res = identify(sub, method=method, weighting=weighting, rank_tol=rank_tol, cond_warn=cond_warn,
                   rel_std_warn_pct=rel_std_warn_pct, zero_col_tol=zero_col_tol)
    assert res.residual is not None  # identify() on a system keeps its residual
    rel_err = per_joint_rel_err(res.residual, loaded.Y, loaded.joint, res.rel_err.size)
    return dataclasses.replace(res, fixed=tuple(fixed.items()), warnings=tuple(warnings) + res.warnings,
                               rel_err=rel_err)
