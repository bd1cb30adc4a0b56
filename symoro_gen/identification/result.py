"""Immutable identification results: estimates with labels, statistics, summary tables, JSON contract.

The statistics follow the papers:

* ``sigma`` is :math:`\\hat\\sigma_\\rho` (RX-90 paper eq. 19) for OLS/WLS, :math:`\\hat\\sigma_W`
  (LWR4 paper eq. 15) for TLS;
* ``cov`` is :math:`C_{\\hat\\chi\\hat\\chi}` (RX-90 eq. 20, LWR4 eq. 16), ``std`` its diagonal's
  square root and ``rel_std_pct`` :math:`\\%\\sigma_{\\hat\\chi_i} = 100\\,\\sigma_{\\hat\\chi_i}/|\\hat\\chi_i|`
  (eq. 21);
* ``rel_err`` the relative error norms :math:`\\|\\rho^j\\|/\\|Y^j\\|` per joint (LWR4 Table III), on
  the filtered, decimated system (the papers' metric); ``rel_err_raw`` the same norm of the model
  evaluated at full rate on the filtered states against the *raw* measured torque
  (:mod:`symoro_gen.observations.raw`), when the caller attached it (:meth:`IdentificationResult.with_raw_error`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.assembly import Assembly, basis_text, merge_metric_basis
from ..observations.raw import raw_error_sums
from ..observations.system import ObservationSystem
from .accumulate import Accumulator
from .render import gains_html, method_label, result_html
from .streaming import StreamedAssembly

#: summary() lists the known (fixed) parameters one per line up to this many
MAX_FIXED_LISTED = 12


def _frozen(a, dtype=float) -> np.ndarray:
    out = np.array(a, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def relative_std_pct(values, std) -> np.ndarray:
    """Relative standard deviation in percent (eq. 21); ``inf`` where the value is 0.

    Parameters
    ----------
    values, std : array_like, shape (c,)

    Returns
    -------
    ndarray, shape (c,)
    """
    values = np.asarray(values, float)
    std = np.asarray(std, float)
    out = np.full(values.shape, np.inf)
    nz = values != 0
    out[nz] = 100.0 * std[nz] / np.abs(values[nz])
    return out


def json_float(x: float):
    """A float for JSON: the value, or None when it is not finite (JSON has no NaN)."""
    x = float(x)
    return x if math.isfinite(x) else None



def fmt_number(x: float, width: int = 11) -> str:
    """A number right-aligned in ``width`` characters (4 significant digits; scientific outside [1e-3, 1e5))."""
    if not np.isfinite(x):
        return f"{'inf' if x > 0 else ('-inf' if x < 0 else 'nan'):>{width}}"
    return f"{x:>{width}.4g}" if abs(x) >= 1e-3 and abs(x) < 1e5 else f"{x:>{width}.3e}"


@dataclass(frozen=True, eq=False)
class Gains:
    """Identified drive gains (RX-90 paper eq. 27) or torque-sensor gains (LWR4 paper eq. 8-13).

    Attributes
    ----------
    joints : tuple of int
        0-based joint index of each identified gain.
    values, std, rel_std_pct : ndarray, shape (k,)
        Gains (dimensionless, relative to the a-priori gains used to produce ``Y``), standard
        deviations and relative standard deviations [%].
    """

    joints: tuple[int, ...]
    values: np.ndarray
    std: np.ndarray
    rel_std_pct: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "joints", tuple(int(j) for j in self.joints))
        for f in ("values", "std", "rel_std_pct"):
            object.__setattr__(self, f, _frozen(getattr(self, f)).reshape(-1))
        if not (len(self.joints) == self.values.size == self.std.size == self.rel_std_pct.size):
            raise IdentificationError("Gains: joints, values, std and rel_std_pct differ in length")

    @property
    def names(self) -> tuple[str, ...]:
        """``("g1", "g2", ...)`` with 1-based joint numbers."""
        return tuple(f"g{j + 1}" for j in self.joints)

    def as_vector(self, n_joints: int) -> np.ndarray:
        """Gain per joint, shape (n_joints,); joints whose gain was not identified get 1."""
        g = np.ones(n_joints)
        for j, v in zip(self.joints, self.values):
            if j < n_joints:
                g[j] = v
        return g

    def _repr_html_(self) -> str:
        """Jupyter: the gains as an HTML table (gain, joint, value, 2 sigma, %sigma)."""
        return gains_html(self)

    def to_dict(self) -> dict:
        return {
            "names": list(self.names),
            "joints": [j + 1 for j in self.joints],
            "values": [json_float(v) for v in self.values],
            "std": [json_float(v) for v in self.std],
            "rel_std_pct": [json_float(v) for v in self.rel_std_pct],
        }


@dataclass(frozen=True)
class EliminationStep:
    """One step of the essential-parameter procedure (LWR4 paper, Sec. IV-B).

    Attributes
    ----------
    removed : str
        Name of the parameter cancelled at this step (largest %sigma).
    rel_std_pct : float
        Its %sigma just before it was cancelled.
    ratio : float
        ``max %sigma / min %sigma`` of the estimate before the cancellation.
    n_params : int
        Number of parameters estimated before the cancellation.
    """

    removed: str
    rel_std_pct: float
    ratio: float
    n_params: int


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Estimated parameters with their statistics.

    Attributes
    ----------
    method : str
        ``"OLS"``, ``"WLS"``, ``"TLS"``, ``"TLS-W"`` (TLS with per-joint row weighting)...
    names : tuple of str, length c
        Parameter labels (base parameters, unknown payload parameters...).
    values, std, rel_std_pct : ndarray, shape (c,)
        Estimates (SI units of each parameter), standard deviations, %sigma (eq. 21; ``inf`` for 0).
        ``std`` is ``inf`` for parameters involved in a rank deficiency of W.
    cov : ndarray, shape (c, c)
        Covariance of the estimation error (eq. 20 for LS, eq. 16 of the LWR4 paper for TLS).
    cond : float
        Condition number of W as solved (rows weighted when the method weights them).
    cond_scaled : float
        Condition number of W with unit-norm columns (insensitive to parameter units).
    sigma : float
        sigma_rho (eq. 19) of the (weighted) residual for LS; sigma_W (LWR4 eq. 15) for TLS.
    rel_err : ndarray, shape (n_joints,)
        ``||rho_j|| / ||Y_j||`` per joint on the identification data (``Y_j`` scaled by the
        identified gain when gains were identified); ``nan`` for a joint without rows.
    n_rows : int
        Number of equations r.
    residual : ndarray, shape (r,) or None
        ``Y - W chi`` (unweighted; ``g_j Y - W chi`` with gains); None for streamed systems.
    joint_sigma : ndarray, shape (n_groups,) or None
        Per-joint standard deviations used as row weights 1/sigma_j (WLS, weighted TLS).
    gains : Gains or None
        Identified gains.
    fixed : tuple of (str, float)
        Known parameters moved to the left-hand side (e.g. known payload parameters).
    eliminated : tuple of str
        Parameters cancelled by the essential-parameter procedure (their value is 0).
    unexcited : tuple of str
        Parameters left out because their columns of W are zero in the identification data (a joint
        that does not move: ``identify --drop-unexcited``): not identified, no value; predictions use 0
        for them (they contribute nothing on the identification data).
    warnings : tuple of str
        Numbered in :meth:`summary`; ill-conditioning, rank deficiency, poorly identified parameters.
    rel_err_raw : ndarray, shape (n_joints,) or None
        ``||g_j tau_j - IDM_j chi|| / ||g_j tau_j||`` per joint: the model at full rate on the filtered
        states against the raw measured torque of the identification data (None until attached by
        :meth:`with_raw_error`).
    rel_err_basis : dict or None
        What ``rel_err`` and ``rel_err_raw`` are computed on (cut-off, decimation factor, rows,
        samples; :meth:`symoro_gen.observations.Assembly.metric_basis`).
    """

    method: str
    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    rel_std_pct: np.ndarray
    cov: np.ndarray
    cond: float
    cond_scaled: float
    sigma: float
    rel_err: np.ndarray
    n_rows: int
    residual: np.ndarray | None = None
    joint_sigma: np.ndarray | None = None
    gains: Gains | None = None
    fixed: tuple[tuple[str, float], ...] = ()
    eliminated: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    unexcited: tuple[str, ...] = ()
    rel_err_raw: np.ndarray | None = None
    rel_err_basis: dict | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        c = len(self.names)
        for f in ("values", "std", "rel_std_pct"):
            a = _frozen(getattr(self, f)).reshape(-1)
            if a.size != c:
                raise IdentificationError(f"IdentificationResult: {f} has {a.size} entries for {c} names")
            object.__setattr__(self, f, a)
        cov = _frozen(self.cov)
        if cov.shape != (c, c):
            raise IdentificationError(f"IdentificationResult: cov has shape {cov.shape}, expected {(c, c)}")
        object.__setattr__(self, "cov", cov)
        object.__setattr__(self, "rel_err", _frozen(self.rel_err).reshape(-1))
        if self.rel_err_raw is not None:
            object.__setattr__(self, "rel_err_raw", _frozen(self.rel_err_raw).reshape(-1))
        if self.residual is not None:
            object.__setattr__(self, "residual", _frozen(self.residual).reshape(-1))
        if self.joint_sigma is not None:
            object.__setattr__(self, "joint_sigma", _frozen(self.joint_sigma).reshape(-1))
        object.__setattr__(self, "fixed", tuple((str(k), float(v)) for k, v in self.fixed))
        object.__setattr__(self, "eliminated", tuple(self.eliminated))
        object.__setattr__(self, "unexcited", tuple(self.unexcited))
        object.__setattr__(self, "warnings", tuple(self.warnings))
        for f in ("cond", "cond_scaled", "sigma"):
            object.__setattr__(self, f, float(getattr(self, f)))
        object.__setattr__(self, "n_rows", int(self.n_rows))

    # ---- access ---------------------------------------------------------
    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def n_joints(self) -> int:
        return int(self.rel_err.size)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise IdentificationError(f"no parameter {name!r} in this result; parameters are {self.names}") from None

    def value(self, name: str) -> float:
        """Estimate of one parameter (known ``fixed`` and ``eliminated`` ones too)."""
        fixed = dict(self.fixed)
        if name in fixed:
            return fixed[name]
        if name in self.eliminated:
            return 0.0
        if name in self.unexcited and name not in self.names:
            raise IdentificationError(f"{name} was not identified: its column of W is zero in the identification "
                                      "data (not excited)")
        return float(self.values[self.index(name)])

    def parameter_map(self) -> dict[str, float]:
        """All parameters by name: estimated, eliminated (0), unexcited (0) and fixed (known) ones."""
        out = {n: 0.0 for n in self.unexcited}
        out.update({n: float(v) for n, v in zip(self.names, self.values)})
        out.update({n: 0.0 for n in self.eliminated})
        out.update(dict(self.fixed))
        return out

    # ---- cross-validation -----------------------------------------------
    def _columns(self, system: ObservationSystem) -> np.ndarray:
        """Parameter vector aligned with ``system.names`` (eliminated/fixed included)."""
        pm = self.parameter_map()
        unknown = [n for n in system.names if n not in pm]
        if unknown:
            raise IdentificationError(
                f"system has columns {unknown} that this {self.method} result does not know; "
                f"its parameters are {tuple(pm)}")
        return np.array([pm[n] for n in system.names], float)

    def predict(self, system: ObservationSystem) -> np.ndarray:
        """Torques reconstructed by the model, ``W chi`` (IDIM eq. 2), shape (r,).

        Columns of ``system`` are matched by name; parameters of this result that ``system`` lacks
        (e.g. payload parameters on unloaded data) contribute nothing; known (``fixed``) parameters
        contribute their known value.
        """
        return system.W @ self._columns(system)

    def scaled_measurements(self, system: ObservationSystem) -> np.ndarray:
        """``Y`` scaled per joint by the identified gains (eq. 4, ``tau = v g``), shape (r,)."""
        if self.gains is None:
            return system.Y
        g = self.gains.as_vector(max(system.n_joints, self.n_joints))
        return system.Y * g[system.joint]

    def rel_err_on(self, system: ObservationSystem | Accumulator) -> np.ndarray:
        """Relative error norms ``||rho_j|| / ||Y_j||`` per joint on (validation) data, shape (n_joints,).

        ``Y`` is scaled by the identified gains when there are any (LWR4 paper Sec. IV-C). Streamed data
        (an :class:`~.accumulate.Accumulator`): ``||g_j Y_j - W_j chi|| = ||R_j [chi; -g_j]||``.
        """
        if isinstance(system, Accumulator):
            return self._rel_err_on_factors(system)
        y = self.scaled_measurements(system)
        rho = y - self.predict(system)
        return per_joint_rel_err(rho, y, system.joint, system.n_joints)

    def _rel_err_on_factors(self, acc: Accumulator) -> np.ndarray:
        pm = self.parameter_map()
        unknown = [n for n in acc.names if n not in pm]
        if unknown:
            raise IdentificationError(f"system has columns {unknown} that this {self.method} result does not know; "
                                      f"its parameters are {tuple(pm)}")
        x = np.array([pm[n] for n in acc.names], float)
        nj = acc.n_joints
        g = self.gains.as_vector(max(nj, self.n_joints)) if self.gains is not None else np.ones(nj)
        out = np.full(nj, np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            for j in range(nj):
                if acc.rows[j] > 0:
                    out[j] = np.linalg.norm(acc.R[j] @ np.r_[x, -g[j]]) / (abs(g[j]) * math.sqrt(acc.yy[j]))
        return out

    def rel_err_raw_on(self, model: IdentificationModel, *assemblies: Assembly | StreamedAssembly) -> np.ndarray:
        """Raw-torque relative error norms per joint on the full-rate samples of ``assemblies``.

        The identified model ``IDM(q, dq, ddq) chi`` is evaluated at every full-rate sample on the
        assembly's band-pass states and compared with the *unfiltered* measured torque (scaled by the
        identified gains), ``||g_j tau_j - IDM_j chi|| / ||g_j tau_j||``; every sample counts (no row
        selection). Assemblies must keep their signals (``AssemblyOptions.keep_signals``).

        Returns
        -------
        ndarray, shape (n_joints,)
        """
        if not assemblies:
            raise IdentificationError("rel_err_raw_on: no assembly given")
        first = assemblies[0]
        n = first.signals[0].q.shape[1] if isinstance(first, Assembly) and first.signals else self.n_joints
        g = self.gains.as_vector(max(n, self.n_joints))[:n] if self.gains is not None else None
        theta = self.parameter_map()
        rho2, y2 = np.zeros(n), np.zeros(n)
        for a in assemblies:
            r, y = (a.raw_error_sums(model, theta, gains=g) if isinstance(a, StreamedAssembly)
                    else raw_error_sums(model, theta, a, gains=g))
            rho2 += r
            y2 += y
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.sqrt(rho2 / y2)

    def with_raw_error(self, model: IdentificationModel, *assemblies: Assembly | StreamedAssembly
                       ) -> IdentificationResult:
        """A copy with ``rel_err_raw`` on the identification ``assemblies`` and ``rel_err_basis`` (what
        each norm is computed on)."""
        basis = merge_metric_basis(assemblies)
        return replace(self, rel_err_raw=self.rel_err_raw_on(model, *assemblies), rel_err_basis=basis)

    # ---- reporting ------------------------------------------------------
    def summary(self) -> str:
        """Tables like the papers': parameters (value, 2 sigma, %sigma), gains, relative error
        norms per joint, then numbered warnings."""
        lines = [
            f"{method_label(self.method)} identification: {self.n_rows} equations, {self.n_params} parameters",
            f"cond(W) = {self.cond:.4g}  (columns scaled: {self.cond_scaled:.4g})   "
            f"sigma = {self.sigma:.4g}",
            "",
        ]
        if self.gains is not None:
            lines.append(f"{'Gain':<10}{'Value':>11}{'2 sigma':>11}{'%sigma':>9}")
            for n, v, s, p in zip(self.gains.names, self.gains.values, self.gains.std, self.gains.rel_std_pct):
                lines.append(f"{n:<10}{fmt_number(v)}{fmt_number(2 * s)}{p:>9.2f}")
            lines.append("")
        lines.append(f"{'Param.':<10}{'Value':>11}{'2 sigma':>11}{'%sigma':>9}")
        for n, v, s, p in zip(self.names, self.values, self.std, self.rel_std_pct):
            lines.append(f"{n:<10}{fmt_number(v)}{fmt_number(2 * s)}{p:>9.2f}")
        if len(self.fixed) <= MAX_FIXED_LISTED:
            for n, v in self.fixed:
                lines.append(f"{n:<10}{fmt_number(v)}{'known':>11}{'-':>9}")
        else:
            lines.append(f"({len(self.fixed)} known parameters moved to the left-hand side: "
                         f"{', '.join(n for n, _ in self.fixed[:5])}, ...)")
        if self.eliminated:
            lines.append(f"cancelled (essential parameters): {', '.join(self.eliminated)}")
        if self.unexcited:
            lines.append(f"not identified (columns of W zero: not excited by the data): {', '.join(self.unexcited)}")
        lines.append("")
        lines.append("Rel. err. norm ||rho_j||/||Y_j|| on the " + basis_text(self.rel_err_basis))
        lines.append("  ".join(f"joint {j + 1}: {e:.4f}" for j, e in enumerate(self.rel_err)))
        if self.rel_err_raw is not None:
            lines.append("Rel. err. norm on the raw measured torque (model at full rate on the filtered states, "
                         f"{self.rel_err_basis.get('samples', '?') if self.rel_err_basis else '?'} samples per joint)")
            lines.append("  ".join(f"joint {j + 1}: {e:.4f}" for j, e in enumerate(self.rel_err_raw)))
        if self.joint_sigma is not None:
            lines.append("row weights 1/sigma_j with sigma_j = "
                         + ", ".join(f"{s:.3g}" for s in self.joint_sigma))
        if self.warnings:
            lines.append("")
            lines.append("Warnings:")
            lines += [f"[{i}] {w}" for i, w in enumerate(self.warnings, 1)]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """The JSON contract: ``parameters`` {names, values, std, rel_std_pct}, ``rel_err``, ``cond``,
        ``sigma`` and ``gains`` {values, rel_std_pct, ...} when gains were identified; non-finite
        numbers become ``null``."""
        out = {
            "method": self.method,
            "parameters": {
                "names": list(self.names),
                "values": [json_float(v) for v in self.values],
                "std": [json_float(v) for v in self.std],
                "rel_std_pct": [json_float(v) for v in self.rel_std_pct],
            },
            "rel_err": [json_float(v) for v in self.rel_err],
            "cond": json_float(self.cond),
            "cond_scaled": json_float(self.cond_scaled),
            "sigma": json_float(self.sigma),
            "n_rows": self.n_rows,
            "fixed": {k: v for k, v in self.fixed},
            "eliminated": list(self.eliminated),
            "warnings": list(self.warnings),
        }
        if self.unexcited:
            out["unexcited"] = list(self.unexcited)
        if self.rel_err_raw is not None:
            out["rel_err_raw"] = [json_float(v) for v in self.rel_err_raw]
        if self.rel_err_basis is not None:
            out["rel_err_basis"] = self.rel_err_basis
        if self.joint_sigma is not None:
            out["joint_sigma"] = [json_float(v) for v in self.joint_sigma]
        if self.gains is not None:
            out["gains"] = self.gains.to_dict()
        return out

    def _repr_html_(self) -> str:
        """Jupyter: :meth:`summary` as HTML tables (gains, parameters with 2 sigma and %sigma, relative
        error norms per joint, numbered warnings)."""
        return result_html(self)

    def __repr__(self) -> str:
        return (f"IdentificationResult(method={self.method!r}, n_params={self.n_params}, "
                f"n_rows={self.n_rows}, cond={self.cond:.3g}, sigma={self.sigma:.3g}, "
                f"warnings={len(self.warnings)})")


def per_joint_rel_err(rho: np.ndarray, y: np.ndarray, joint: np.ndarray, n_joints: int) -> np.ndarray:
    """``||rho_j|| / ||y_j||`` per joint, shape (n_joints,); ``nan`` for joints without rows."""
    rho2 = np.bincount(joint, weights=np.asarray(rho, float) ** 2, minlength=n_joints)
    y2 = np.bincount(joint, weights=np.asarray(y, float) ** 2, minlength=n_joints)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.sqrt(rho2) / np.sqrt(y2)
    counts = np.bincount(joint, minlength=n_joints)
    out[counts == 0] = np.nan
    return out

