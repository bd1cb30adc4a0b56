"""Physically consistent identification and standard parameters from base parameters (one conic machinery).

Two problems share the same variables and constraints, solved by a conic solver through cvxpy
(Clarabel, SCS as fallback; the ``physical`` extra):

* :func:`identify_physical` (``symoro-gen identify --physical``): the (weighted) least-squares
  problem of the inverse dynamic identification model (IDIM, RX-90 paper eq. 16) solved in the
  *standard* parameters ``chi_st``, whose image through the regrouping ``chi_b = K chi_st`` gives
  the base parameters the observation system ``Y = W_b chi_b`` is written in;
* :func:`standard_from_base` (``export-urdf --from``, ``export-mjcf --from``): a standard set with
  ``K chi_st = chi_b`` exactly (identified base parameters), closest to the nominal values.

Constraints (Wensing, Kim & Slotine, "Linear matrix inequalities for physically consistent inertial
parameter identification: a statistical perspective on the mass distribution", IEEE RA-L 3(1), 2018,
eq. 5 and Thm. 1; Sousa & Cortesao 2014 for the drive terms):

* each body's 4x4 pseudo-inertia ``P(chi_j) = [[tr(J)/2 E - J, MS], [MS^T, M]]``, affine in its ten
  standard parameters (:func:`symoro_gen.description.inertia.pseudo_inertia`), is positive definite,
  enforced as ``P >= eps_j E`` with a margin ``eps_j = PSD_MARGIN`` times the body's scale (so the
  result passes :func:`~symoro_gen.description.inertia.check_physical_consistency`: mass > 0, inertia
  at the centre of mass positive definite, triangle inequalities);
* rotor inertias ``IA``, viscous ``FV`` and Coulomb ``FS`` friction coefficients are >= 0;
* optional bounds ``|chi_i - nominal_i| <= tol |nominal_i|`` on every standard parameter with a
  non-zero nominal value (``nominal_tolerance``);
* the payload (``PAYLOAD_NAMES``) is one more body, with known parameters (e.g. its mass) as equalities;
* optional body bounds (``bounded_bodies``, ``identify --physical --bounded-bodies``): each link's mass
  distribution inside the box of its MDH frame origins (:func:`symoro_gen.identification.plausibility.body_boxes`),
  as the three linear slab conditions ``tr(Q_i P) >= 0`` ([WKS2017] bounding-ellipsoid condition applied to
  the box's slabs, the cuboid bound of [SC2019]; they put the centre of mass in the box), and the mass
  within ``[m0 / MASS_FACTOR, MASS_FACTOR m0]`` of a non-zero nominal mass ``m0``
  (:mod:`symoro_gen.identification.plausibility`).

Regularisation: the data only see ``K chi_st``; among the standard sets with the same base
parameters the one closest to the nominal values (robot file; zero when absent) is chosen by adding
``regularization * ||(chi - chi_nom) / s||^2 / p`` to the weighted LS cost divided by its unconstrained
minimum (``s`` a per-parameter scale from the body's nominal mass and size, ``p`` the number of
variables): the pull toward nominal costs at most about ``regularization`` of relative residual
increase (default ``1e-5``), far below the statistical spread of the fit.
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..description.inertia import (
    check_physical_consistency,
    com_from_standard,
    pseudo_inertia,
)
from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.system import ObservationSystem
from ..params import DRIVE_KINDS, INERTIAL_KINDS, split_name
from .plausibility import MASS_FACTOR, BodyBox, slab_rows
from .result import IdentificationResult, json_float, per_joint_rel_err

__all__ = [
    "DEFAULT_REGULARIZATION",
    "PSD_MARGIN",
    "PhysicalResult",
    "StandardFromBase",
    "base_matrix",
    "identify_physical",
    "standard_from_base",
    "standard_set_from_result",
    "status_warnings",
]

#: weight of the pull toward the nominal values (relative to the normalised LS cost)
DEFAULT_REGULARIZATION = 1e-5
#: P_j >= PSD_MARGIN * scale_j * E: strict positive definiteness, robust to solver tolerances
PSD_MARGIN = 1e-6
#: a pseudo-inertia whose smallest eigenvalue is below this many margins is reported as active
ACTIVE_FACTOR = 20.0

_NONNEG = ("IA", "FV", "FS")


def _require_cvxpy():
    try:
        import cvxpy as cp  # heavy optional import (the 'physical' extra)
    except ImportError:  # pragma: no cover - depends on the environment
        raise IdentificationError("physically consistent identification needs cvxpy and clarabel: "
                                  "pip install 'symoro-gen[physical]'") from None
    return cp


def base_matrix(model: IdentificationModel) -> np.ndarray:
    """The regrouping matrix ``K`` with ``chi_b = K chi_st``, shape ``(len(BASE_NAMES), len(STANDARD_NAMES))``.

    ``model.base_parameters`` is linear (Gautier & Khalil 1990, regrouping relations), so its
    columns are its images of the unit vectors.
    """
    n = len(model.STANDARD_NAMES)
    K = np.asarray(model.base_parameters(np.eye(n)), float)
    if K.shape != (n, len(model.BASE_NAMES)):
        raise IdentificationError(f"model.base_parameters returned shape {K.shape} for the {n} unit vectors")
    K = K.T
    # linearity check (an affine map would give K chi + b)
    b0 = np.asarray(model.base_parameters(np.zeros(n)), float)
    if np.any(np.abs(b0) > 1e-12 * max(1.0, np.abs(K).max())):
        raise IdentificationError("model.base_parameters is not linear (non-zero image of zero)")
    return K


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Layout:
    """Variables ``x = [chi_st, chi_payload, other]`` and their bodies."""

    standard: tuple[str, ...]
    payload: tuple[str, ...]
    other: tuple[str, ...]
    bodies: tuple[tuple[str, tuple[int, ...]], ...]  # (label, indices of XX..M in x)

    @property
    def names(self) -> tuple[str, ...]:
        return self.standard + self.payload + self.other

    def index(self) -> dict[str, int]:
        return {n: i for i, n in enumerate(self.names)}


def _layout(model: IdentificationModel, payload: Sequence[str], other: Sequence[str]) -> _Layout:
    st = tuple(model.STANDARD_NAMES)
    pay = tuple(payload)
    names = st + pay
    idx = {n: i for i, n in enumerate(names)}
    frames: dict[int, dict[str, int]] = {}
    for n in names:
        try:
            kind, j, _ = split_name(n)
        except ValueError:
            continue
        if kind in INERTIAL_KINDS:
            frames.setdefault(j, {})[kind] = idx[n]
    bodies = []
    for j in sorted(frames):
        f = frames[j]
        if len(f) == 10:
            label = f"payload (frame {j})" if f"M{j}" in pay else f"link {j}"
            bodies.append((label, tuple(f[k] for k in INERTIAL_KINDS)))
    return _Layout(st, pay, tuple(other), tuple(bodies))


def _pseudo_map() -> np.ndarray:
    """``G`` (16, 10): ``vec(P) = G p10`` (column-major), the affine pseudo-inertia map."""
    return np.stack([pseudo_inertia(e).reshape(-1, order="F") for e in np.eye(10)], axis=1)


def _scales(lay: _Layout, nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-variable scale ``s`` (units of each parameter) and per-body PSD scale."""
    x = np.abs(nominal)
    s = np.ones(len(lay.names))
    body_scale = []
    masses = [nominal[b[9]] for _, b in lay.bodies if nominal[b[9]] > 0]
    m_default = float(np.mean(masses)) if masses else 1.0
    for _, b in lay.bodies:
        m = nominal[b[9]] if nominal[b[9]] > 0 else m_default
        trJ = nominal[b[0]] + nominal[b[3]] + nominal[b[5]]
        L = math.sqrt(trJ / (2 * m)) if trJ > 0 and nominal[b[9]] > 0 else 0.3
        L = min(max(L, 0.05), 2.0)
        for k, i in enumerate(b):
            s[i] = m * L * L if k < 6 else (m * L if k < 9 else m)
        body_scale.append(m * (1.0 + L * L))
    idx = lay.index()
    for kind in DRIVE_KINDS:
        cols = [idx[n] for n in lay.names if _kind(n) == kind]
        if cols:
            typical = float(np.mean(x[cols])) if np.any(x[cols] > 0) else 1.0
            for i in cols:
                s[i] = max(x[i], 0.1 * typical)
    return s, np.array(body_scale)


def _kind(name: str) -> str | None:
    try:
        return split_name(name)[0]
    except ValueError:
        return None


def _nominal_vector(lay: _Layout, nominal) -> np.ndarray:
    if nominal is None:
        return np.zeros(len(lay.names))
    if isinstance(nominal, Mapping):
        return np.array([float(nominal.get(n, 0.0)) for n in lay.names])
    v = np.asarray(nominal, float).reshape(-1)
    if v.size == len(lay.standard):
        return np.concatenate([v, np.zeros(len(lay.payload) + len(lay.other))])
    if v.size != len(lay.names):
        raise IdentificationError(f"nominal: {v.size} values for {len(lay.standard)} standard parameters")
    return v


def _box_constraints(cp, x, lay: _Layout, nominal: np.ndarray, boxes: Mapping[int, BodyBox]):
    """The body bounds of the module docstring: slab rows ``A p >= 0`` per link with a box, and the mass
    within a factor of its nominal value."""
    cons: list = []
    labels: list[tuple[str, str, tuple[int, ...] | int, float]] = []
    for label, b in lay.bodies:
        j = split_name(lay.names[b[9]])[1]
        if j in boxes:
            A, _ = slab_rows(boxes[j])
            cons.append(A @ x[list(b)] >= 0)
            labels.append(("box", label, b, float(j)))
        m0 = nominal[b[9]]
        if m0 > 0:
            cons += [x[b[9]] >= m0 / MASS_FACTOR, x[b[9]] <= MASS_FACTOR * m0]
            labels += [("lower", lay.names[b[9]], b[9], m0 / MASS_FACTOR), ("upper", lay.names[b[9]], b[9], MASS_FACTOR * m0)]
    return cons, labels


def _constraints(cp, x, lay: _Layout, s: np.ndarray, body_scale: np.ndarray, nominal: np.ndarray,
                 known: Mapping[str, float], nominal_tolerance: float | None):
    """cvxpy constraints on ``x`` (in SI units) with labels for the active-set report."""
    G = _pseudo_map()
    cons = []
    labels: list[tuple[str, str, tuple[int, ...] | int, float]] = []  # kind, name, where, reference value
    for (label, b), bs in zip(lay.bodies, body_scale):
        P = cp.reshape(G @ x[list(b)], (4, 4), order="F")
        cons.append((P + P.T) / 2 >> PSD_MARGIN * bs * np.eye(4))
        labels.append(("psd", label, b, bs))
    idx = lay.index()
    for n in lay.names:
        if _kind(n) in _NONNEG and n not in known:
            cons.append(x[idx[n]] >= 0)
            labels.append(("nonneg", n, idx[n], s[idx[n]]))
    for n, v in known.items():
        if n not in idx:
            raise IdentificationError(f"known parameter {n}: not a parameter of this problem ({', '.join(lay.payload) or 'no payload'})")
        cons.append(x[idx[n]] == float(v))
        labels.append(("known", n, idx[n], 0.0))
    if nominal_tolerance is not None:
        if not nominal_tolerance >= 0:
            raise IdentificationError(f"nominal tolerance must be >= 0, got {nominal_tolerance}")
        for i, n in enumerate(lay.standard + lay.payload):
            if nominal[i] != 0 and n not in known:
                lo, hi = sorted((nominal[i] * (1 - nominal_tolerance), nominal[i] * (1 + nominal_tolerance)))
                cons += [x[i] >= lo, x[i] <= hi]
                labels += [("lower", n, i, lo), ("upper", n, i, hi)]
    return cons, labels


def _active(labels, cons, x: np.ndarray, s: np.ndarray, pull: float,
            boxes: Mapping[int, BodyBox] | None = None) -> tuple[str, ...]:
    """Constraints at their bound. Each is said to be *set by the data* when its Lagrange multiplier,
    in the scaled variables, exceeds ``100 pull`` (the size of the regularisation's gradient), else
    *set by the pull toward nominal* (it costs the fit nothing: e.g. a body without nominal values)."""
    G = _pseudo_map()
    out = []

    def who(force: float) -> str:
        return "set by the data" if force > 100.0 * pull else "set by the pull toward nominal"

    for (kind, name, where, ref), con in zip(labels, cons):
        dual = con.dual_value
        if kind == "psd":
            ev = np.linalg.eigvalsh(pseudo_inertia(x[list(where)]))
            if ev[0] <= ACTIVE_FACTOR * PSD_MARGIN * ref:
                force = float(np.linalg.norm(s[list(where)] * (G.T @ np.asarray(dual).reshape(-1, order="F")))) \
                    if dual is not None else 0.0
                out.append(f"{name}: pseudo-inertia singular (lambda_min {ev[0]:.3g}; {who(force)})")
        elif kind == "box" and boxes is not None:
            A, _ = slab_rows(boxes[int(ref)])
            slack = A @ x[list(where)]
            m = max(float(x[list(where)][9]), 1e-12)
            if np.min(slack) <= 1e-5 * m * boxes[int(ref)].extent ** 2:
                out.append(f"{name}: mass distribution at the boundary of its box along "
                           f"{'xyz'[int(np.argmin(slack))]} (bounded bodies)")
        elif kind == "nonneg" and x[where] <= 1e-6 * ref:
            force = abs(float(dual)) * s[where] if dual is not None else 0.0
            out.append(f"{name} >= 0 ({who(force)})")
        elif kind in ("lower", "upper") and abs(x[where] - ref) <= 1e-6 * max(abs(ref), s[where]):
            force = abs(float(dual)) * s[where] if dual is not None else 0.0
            out.append(f"{name} {'>=' if kind == 'lower' else '<='} {ref:.6g} (nominal bound; {who(force)})")
    return tuple(out)


def _solve(cp, problem, solver: str | None) -> str:
    """Solve with Clarabel, else SCS; returns the solver used. Raises on failure."""
    installed = set(cp.installed_solvers())
    order = [solver.upper()] if solver else [s for s in ("CLARABEL", "SCS") if s in installed]
    if not order:
        raise IdentificationError("no conic solver with semidefinite cones installed: pip install clarabel (or scs)")
    last = None
    for name in order:
        try:
            kw = {"eps": 1e-9, "max_iters": 200_000} if name == "SCS" else {}
            with warnings.catch_warnings():  # "optimal_inaccurate" is reported in the result's status
                warnings.simplefilter("ignore", UserWarning)
                problem.solve(solver=name, **kw)
        except (cp.error.SolverError, ValueError, ArithmeticError) as exc:  # this solver failed: try the next one
            last = f"{name}: {exc}"
            continue
        if problem.status in ("optimal", "optimal_inaccurate"):
            return name
        last = f"{name}: {problem.status}"
        if problem.status in ("infeasible", "infeasible_inaccurate"):
            return name
    raise IdentificationError(f"conic solver failed ({last})")


def _body_reports(lay: _Layout, x: np.ndarray, nominal: np.ndarray) -> tuple[dict, ...]:
    out = []
    for label, b in lay.bodies:
        p, p0 = x[list(b)], nominal[list(b)]
        m, c, Ic = com_from_standard(p)
        rep = {"body": label, "mass": float(m), "com": [float(v) for v in c],
               "consistent": not check_physical_consistency(p)}
        if np.any(p0):
            m0, c0, I0 = com_from_standard(p0)
            rep["nominal_consistent"] = not check_physical_consistency(p0)
            rep["mass_change"] = float(m - m0)
            rep["com_shift"] = float(np.linalg.norm(c - c0))
            n0 = float(np.linalg.norm(I0))
            rep["inertia_change_rel"] = float(np.linalg.norm(Ic - I0) / n0) if n0 > 0 else None
        out.append(rep)
    return tuple(out)


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PhysicalResult:
    """A physically consistent identification (:func:`identify_physical`).

    Attributes
    ----------
    names, values : tuple of str, ndarray
        Standard parameters (``model.STANDARD_NAMES`` order) of the consistent estimate.
    payload_names, payload_values : tuple of str, ndarray
        Payload parameters (empty without payload columns).
    base_names, base_values : tuple of str, ndarray
        The base parameters it implies, ``K chi_st`` (``model.BASE_NAMES`` order).
    other_names, other_values : tuple of str, ndarray
        Other columns of the system (unconstrained), if any.
    unconstrained : dict
        The unconstrained (weighted) LS estimate of the same columns, ``name -> value``.
    active_constraints : tuple of str
        Constraints at their bound: singular pseudo-inertias, friction/rotor terms at 0, nominal bounds.
    cost, cost_unconstrained : float
        Weighted residual sums of squares on the identification system (no regularisation).
    rel_err, rel_err_unconstrained : ndarray, shape (n_joints,)
        ``||rho_j|| / ||Y_j||`` per joint of both estimates on the identification system.
    bodies : tuple of dict
        Per body: mass, centre of mass, consistency, and how far it is from the nominal body.
    solver, status : str
    regularization : float
    warnings : tuple of str
        A solver status other than ``optimal`` (:func:`status_warnings`).
    bounded : bool
        The bodies were bounded (``boxes``).
    """

    names: tuple[str, ...]
    values: np.ndarray
    payload_names: tuple[str, ...]
    payload_values: np.ndarray
    base_names: tuple[str, ...]
    base_values: np.ndarray
    other_names: tuple[str, ...]
    other_values: np.ndarray
    unconstrained: dict
    active_constraints: tuple[str, ...]
    cost: float
    cost_unconstrained: float
    rel_err: np.ndarray
    rel_err_unconstrained: np.ndarray
    bodies: tuple[dict, ...]
    solver: str
    status: str
    regularization: float
    known: tuple[tuple[str, float], ...] = ()
    warnings: tuple[str, ...] = ()
    bounded: bool = False

    @property
    def residual_increase_pct(self) -> float:
        """Cost of consistency: ``100 (cost / cost_unconstrained - 1)`` [%]."""
        if self.cost_unconstrained <= 0:
            return 0.0 if self.cost <= 0 else math.inf
        return 100.0 * (self.cost / self.cost_unconstrained - 1.0)

    def parameter_map(self) -> dict[str, float]:
        """Base, payload and other parameters by name (what the observation-system columns need)."""
        out = dict(zip(self.base_names, (float(v) for v in self.base_values)))
        out.update(zip(self.payload_names, (float(v) for v in self.payload_values)))
        out.update(zip(self.other_names, (float(v) for v in self.other_values)))
        return out

    def standard_map(self) -> dict[str, float]:
        """Standard (and payload) parameters by name."""
        out = dict(zip(self.names, (float(v) for v in self.values)))
        out.update(zip(self.payload_names, (float(v) for v in self.payload_values)))
        return out

    def as_identification_result(self, unconstrained: IdentificationResult) -> IdentificationResult:
        """``unconstrained`` with the consistent values of its parameters (``method`` + ``-phys``).

        ``std`` and ``cov`` are those of the unconstrained estimate (exact when no constraint is active;
        the constrained estimator's own distribution is not Gaussian), said in the warnings.
        """
        pm = self.parameter_map()
        missing = [n for n in unconstrained.names if n not in pm]
        if missing:
            raise IdentificationError(f"physical estimate lacks parameters {missing}")
        # parameters the essential procedure cancelled are estimated here: listed after the others
        extra = [n for n in unconstrained.eliminated if n in pm]
        names = tuple(unconstrained.names) + tuple(extra)
        vals = np.array([pm[n] for n in names])
        c, k = unconstrained.n_params, len(extra)
        std = np.concatenate([unconstrained.std, np.full(k, np.inf)])
        cov = np.full((c + k, c + k), np.nan)
        cov[:c, :c] = unconstrained.cov
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(vals != 0, 100.0 * std / np.abs(vals), np.inf)
        note = ("physically consistent estimate (identify --physical): std and %sigma are those of the "
                "unconstrained estimate" + (f"; {', '.join(extra)} (cancelled by the essential procedure) "
                                            "are estimated here without statistics" if extra else ""))
        return replace(unconstrained, method=unconstrained.method + "-phys", names=names, values=vals, std=std,
                       rel_std_pct=rel, cov=cov, rel_err=self.rel_err, residual=None, rel_err_raw=None,
                       eliminated=tuple(n for n in unconstrained.eliminated if n not in pm),
                       warnings=(note, *unconstrained.warnings))

    def summary(self) -> str:
        """Consistent base parameters beside the unconstrained ones, the cost of consistency and the
        active constraints."""
        lines = [(f"Physically consistent estimate ({self.solver}, {self.status}; regularisation toward nominal "
                  f"{self.regularization:g}" + ("; bodies bounded by their links' boxes" if self.bounded else "") + ")"),
                 f"{'Param.':<10}{'consistent':>13}{'unconstrained':>15}"]
        for n, v in zip(self.base_names + self.payload_names + self.other_names,
                        np.concatenate([self.base_values, self.payload_values, self.other_values])):
            u = self.unconstrained.get(n)
            lines.append(f"{n:<10}{v:>13.5g}{(f'{u:.5g}' if u is not None else '-'):>15}")
        for n, v in self.known:
            lines.append(f"{n:<10}{v:>13.5g}{'known':>15}")
        lines.append("")
        lines.append(f"Cost of consistency: weighted residual +{self.residual_increase_pct:.3g} % "
                     f"({self.cost:.6g} vs {self.cost_unconstrained:.6g})")
        lines.append("Rel. err. norm per joint, consistent:    "
                     + "  ".join(f"{e:.4f}" for e in self.rel_err))
        lines.append("Rel. err. norm per joint, unconstrained: "
                     + "  ".join(f"{e:.4f}" for e in self.rel_err_unconstrained))
        inc = [b["body"] for b in self.bodies if b.get("nominal_consistent") is False]
        if inc:
            lines.append("Nominal values physically inconsistent for: " + ", ".join(inc))
        lines.append(f"Active constraints ({len(self.active_constraints) or 'none'}):")
        lines += [f"  {a}" for a in self.active_constraints]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """The JSON ``physical`` block: ``names`` (STANDARD_NAMES order), ``values``, ``active_constraints``,
        plus the payload, the implied base parameters and the cost of consistency."""
        return {
            "names": list(self.names),
            "values": [json_float(v) for v in self.values],
            "active_constraints": list(self.active_constraints),
            "payload": {"names": list(self.payload_names), "values": [json_float(v) for v in self.payload_values]},
            "base": {"names": list(self.base_names), "values": [json_float(v) for v in self.base_values]},
            "known": dict(self.known),
            "cost": json_float(self.cost),
            "cost_unconstrained": json_float(self.cost_unconstrained),
            "residual_increase_pct": json_float(self.residual_increase_pct),
            "rel_err": [json_float(v) for v in self.rel_err],
            "rel_err_unconstrained": [json_float(v) for v in self.rel_err_unconstrained],
            "bodies": list(self.bodies),
            "solver": self.solver,
            "status": self.status,
            "regularization": self.regularization,
            "bounded_bodies": self.bounded,
            "warnings": list(self.warnings),
        }


def _column_map(model: IdentificationModel, lay: _Layout, K: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """``M`` with ``chi_columns = M x`` for the system columns ``names``."""
    bidx = {n: i for i, n in enumerate(model.BASE_NAMES)}
    idx = lay.index()
    M = np.zeros((len(names), len(lay.names)))
    nst = len(lay.standard)
    for r, n in enumerate(names):
        if n in bidx:
            M[r, :nst] = K[bidx[n]]
        else:
            M[r, idx[n]] = 1.0
    return M


def identify_physical(model: IdentificationModel, system: ObservationSystem, *,
                      joint_sigma: Sequence[float] | None = None, known: Mapping[str, float] | None = None,
                      nominal=None, nominal_tolerance: float | None = None,
                      regularization: float = DEFAULT_REGULARIZATION, solver: str | None = None,
                      boxes: Mapping[int, BodyBox] | None = None) -> PhysicalResult:
    """Physically consistent (weighted) least squares in the standard parameters.

    Minimises ``||w (Y - W_b K chi_st - W_L chi_L)||^2 / c_min + regularization ||(chi - chi_nom)/s||^2 / p``
    subject to the constraints of the module docstring (Wensing, Kim & Slotine 2018, eq. 5).

    Parameters
    ----------
    model : IdentificationModel
        Gives ``K`` (:func:`base_matrix`) and the names.
    system : ObservationSystem
        ``Y = W chi`` with base columns (``model.BASE_NAMES``), optionally payload columns
        (``model.PAYLOAD_NAMES``, one more constrained body) and other columns (left free).
        Measurements already scaled by any identified gains.
    joint_sigma : sequence of float, optional
        Per-joint standard deviations: rows weighted by ``1 / sigma_j`` (WLS, RX-90 paper eq. 18).
    known : mapping, optional
        Known parameters (e.g. ``{"M8": 4.6136}``): equality constraints.
    nominal : mapping or array_like, optional
        Nominal standard (and payload) values: regularisation target and bounds centre.
    nominal_tolerance : float, optional
        Bounds ``|chi - nominal| <= tol |nominal|`` on parameters with non-zero nominal values.
    regularization : float
        See the module docstring.
    solver : {"CLARABEL", "SCS"}, optional
    boxes : mapping of int to BodyBox, optional
        Bound the bodies (the module docstring's last item): frame -> box, from
        :func:`symoro_gen.identification.plausibility.body_boxes`.

    Returns
    -------
    PhysicalResult
    """
    cp = _require_cvxpy()
    known = dict(known or {})
    names = tuple(system.names)
    base = set(model.BASE_NAMES)
    pay = tuple(n for n in model.PAYLOAD_NAMES if n in names or n in known)
    other = tuple(n for n in names if n not in base and n not in pay)
    lay = _layout(model, pay, other)
    K = base_matrix(model)
    Mcol = _column_map(model, lay, K, names)
    w = np.ones(system.Y.size)
    if joint_sigma is not None:
        sig = np.asarray(joint_sigma, float)
        if sig.size < system.n_joints or np.any(~(sig > 0)):
            raise IdentificationError(f"joint_sigma must give a positive value for each of the {system.n_joints} joints")
        w = 1.0 / sig[system.joint]
    A = (system.W @ Mcol) * w[:, None]
    y = system.Y * w
    y2 = float(y @ y)
    if not y2 > 0:
        raise IdentificationError("identify --physical: the measured torques are all zero")
    idx = lay.index()
    nominal_v = _nominal_vector(lay, nominal)
    s, body_scale = _scales(lay, nominal_v)

    # unconstrained reference (known parameters moved to the left-hand side), same weights
    free = [i for i, n in enumerate(names) if n not in known]
    kn = np.array([known.get(n, 0.0) for n in names])
    Wc = system.W * w[:, None]
    chi_u = np.linalg.lstsq(Wc[:, free], y - Wc @ kn, rcond=None)[0]
    theta_u = kn.copy()
    theta_u[free] = chi_u
    rho_u = system.Y - system.W @ theta_u
    cost_u = float(np.sum((w * rho_u) ** 2))

    # In the scaled variables u = x / s: ||A x - y||^2 = ||R (u - u_ls)||^2 + min cost (QR of A diag(s),
    # u_ls any unconstrained minimiser); the fit term is normalised by that minimum, so it reads as the
    # relative increase of the weighted residual (solver tolerances then apply to what matters).
    As = A * s[None, :]
    _, R = np.linalg.qr(As, mode="reduced")
    u_ls = np.linalg.lstsq(As, y, rcond=None)[0]
    c_min = float(np.sum((y - As @ u_ls) ** 2))
    c_ref = max(c_min, 1e-12 * y2)
    p = len(lay.names)
    u = cp.Variable(p)  # scaled variables: x = s * u
    x = cp.multiply(s, u)
    reg = regularization / p
    # the whole objective times 1/regularization (same minimiser): the pull toward nominal, which alone
    # decides what the data do not see (e.g. the masses regrouped with others), is then of order 1 and
    # the solver's absolute tolerances (1e-8) resolve it; unscaled, its ~1e-8 value ended as
    # "optimal_inaccurate" with a standard set 100 x further from optimal in that term
    k = 1.0 / regularization if regularization > 0 else 1.0
    obj = k * (cp.sum_squares(R @ (u - u_ls)) / c_ref + reg * cp.sum_squares(u - nominal_v / s))
    cons, labels = _constraints(cp, x, lay, s, body_scale, nominal_v, known, nominal_tolerance)
    if boxes is not None:
        c2, l2 = _box_constraints(cp, x, lay, nominal_v, boxes)
        cons, labels = cons + c2, labels + l2
    prob = cp.Problem(cp.Minimize(obj), cons)
    used = _solve(cp, prob, solver)
    if prob.status not in ("optimal", "optimal_inaccurate"):
        raise IdentificationError(f"identify --physical: the constraints cannot be met ({prob.status}); "
                                  "check the known payload values, --nominal-tolerance and --bounded-bodies")
    xv = np.asarray(s * u.value, float)
    for n, v in known.items():
        xv[idx[n]] = float(v)
    theta = Mcol @ xv
    rho = system.Y - system.W @ theta
    cost = float(np.sum((w * rho) ** 2))
    nj = system.n_joints
    nst, npay = len(lay.standard), len(lay.payload)
    st_vals = xv[:nst]
    return PhysicalResult(
        names=lay.standard, values=_ro(st_vals), payload_names=lay.payload, payload_values=_ro(xv[nst:nst + npay]),
        base_names=tuple(model.BASE_NAMES), base_values=_ro(K @ st_vals),
        other_names=lay.other, other_values=_ro(xv[nst + npay:]),
        unconstrained={n: float(v) for n, v in zip(names, theta_u) if n not in known},
        active_constraints=_active(labels, cons, xv, s, 2 * reg * k, boxes), cost=cost, cost_unconstrained=cost_u,
        rel_err=_ro(per_joint_rel_err(rho, system.Y, system.joint, nj)),
        rel_err_unconstrained=_ro(per_joint_rel_err(rho_u, system.Y, system.joint, nj)),
        bodies=_body_reports(lay, xv, nominal_v), solver=used, status=str(prob.status),
        regularization=float(regularization), known=tuple((k, float(v)) for k, v in known.items()),
        warnings=status_warnings(used, str(prob.status)), bounded=boxes is not None)


def status_warnings(solver: str, status: str) -> tuple[str, ...]:
    """A solver status other than ``optimal`` as a warning (``optimal_inaccurate``: the solver stopped on
    its iteration limit or a loss of accuracy; the constraints and the optimality hold only approximately)."""
    if status == "optimal":
        return ()
    return (f"conic solver {solver} ended with status {status!r}, not 'optimal': the consistent estimate "
            "may violate its constraints or not minimise the cost by more than the solver's tolerances",)


def _ro(a) -> np.ndarray:
    out = np.array(a, float, copy=True)
    out.setflags(write=False)
    return out


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class StandardFromBase:
    """A physically consistent standard set for given base parameters (:func:`standard_from_base`).

    Attributes
    ----------
    names, values : tuple of str, ndarray
        Standard parameters (``model.STANDARD_NAMES`` order).
    exact : bool
        ``K chi_st`` equals the given base parameters (to solver precision); False when no
        consistent set reproduces them and the closest one in the least-squares sense is returned.
    base_error : float
        ``max_i |K chi_st - chi_b|_i / scale_i`` (scaled by the base parameters' typical size).
    bodies : tuple of dict
        Per body: mass, centre of mass and how far it moved from its nominal (mass change [kg],
        centre-of-mass shift [m], relative change of the inertia at the centre of mass), and whether
        the nominal body was itself physically consistent.
    active_constraints : tuple of str
    notes : tuple of str
        What a user should know (infeasible, nominal bodies that were inconsistent).
    """

    names: tuple[str, ...]
    values: np.ndarray
    exact: bool
    base_error: float
    bodies: tuple[dict, ...]
    active_constraints: tuple[str, ...]
    notes: tuple[str, ...] = field(default=())

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.names, (float(v) for v in self.values)))


def standard_from_base(model: IdentificationModel, chi_b, nominal=None, *,
                       base_names: Sequence[str] | None = None, solver: str | None = None,
                       tol: float = 1e-6) -> StandardFromBase:
    """A physically consistent standard set whose regrouping gives ``chi_b``, closest to ``nominal``.

    Solves ``min ||(chi_st - chi_nom) / s||^2`` s.t. ``K chi_st = chi_b`` and the constraints of the
    module docstring (pseudo-inertias positive definite, ``IA, FV, FS >= 0``). When that is
    infeasible (the identified base parameters are not those of any physical robot), returns the
    consistent set minimising ``||(K chi_st - chi_b) / s_b||^2`` (plus a tiny pull toward nominal)
    and says so in ``notes``.

    Parameters
    ----------
    model : IdentificationModel
    chi_b : array_like or mapping
        Base parameters (``model.BASE_NAMES`` order, or ``name -> value``; with ``base_names`` the
        names of the given vector).
    nominal : mapping or array_like, optional
        Nominal standard values (robot file); zero when absent.
    tol : float
        Scaled base-parameter error below which the result counts as exact.

    Returns
    -------
    StandardFromBase
    """
    cp = _require_cvxpy()
    bn = tuple(model.BASE_NAMES)
    if isinstance(chi_b, Mapping):
        missing = [n for n in bn if n not in chi_b]
        if missing:
            raise IdentificationError(f"base parameters missing: {', '.join(missing)}")
        b = np.array([float(chi_b[n]) for n in bn])
    else:
        v = np.asarray(chi_b, float).reshape(-1)
        if base_names is not None:
            d = dict(zip(base_names, v))
            missing = [n for n in bn if n not in d]
            if missing:
                raise IdentificationError(f"base parameters missing: {', '.join(missing)}")
            b = np.array([d[n] for n in bn])
        else:
            if v.size != len(bn):
                raise IdentificationError(f"{v.size} base parameters given, the model has {len(bn)}")
            b = v
    lay = _layout(model, (), ())
    K = base_matrix(model)
    nominal_v = _nominal_vector(lay, nominal)
    s, body_scale = _scales(lay, nominal_v)
    sb = np.abs(K) @ s  # typical size of each base parameter
    sb[sb == 0] = 1.0
    p = len(lay.names)
    u = cp.Variable(p)
    x = cp.multiply(s, u)
    cons, labels = _constraints(cp, x, lay, s, body_scale, nominal_v, {}, None)
    Ks = K / sb[:, None]
    bs = b / sb
    dev = cp.sum_squares(u - nominal_v / s) / p
    prob = cp.Problem(cp.Minimize(dev), cons + [Ks @ x == bs])
    notes: list[str] = []
    try:
        used = _solve(cp, prob, solver)
        ok = prob.status in ("optimal", "optimal_inaccurate")
        if ok:
            notes += status_warnings(used, str(prob.status))
    except IdentificationError:
        ok = False
    xv = np.asarray(s * u.value, float) if ok and u.value is not None else None
    err = float(np.max(np.abs(Ks @ xv - bs))) if xv is not None else math.inf
    if xv is None or err > tol:
        prob2 = cp.Problem(cp.Minimize(cp.sum_squares(Ks @ x - bs) + 1e-8 * dev), cons)
        notes = list(status_warnings(_solve(cp, prob2, solver), str(prob2.status)))
        if prob2.status not in ("optimal", "optimal_inaccurate"):
            raise IdentificationError(f"standard_from_base: solver status {prob2.status}")
        xv = np.asarray(s * u.value, float)
        err = float(np.max(np.abs(Ks @ xv - bs)))
        notes.append(f"no physically consistent standard set reproduces these base parameters exactly: "
                     f"the closest one in the least-squares sense is used (largest scaled base error {err:.3g})")
    bodies = _body_reports(lay, xv, nominal_v)
    bad = [bd["body"] for bd in bodies if bd.get("nominal_consistent") is False]
    if bad:
        notes.append("nominal inertial values physically inconsistent (changed to the closest consistent "
                     "bodies): " + ", ".join(bad))
    return StandardFromBase(names=lay.standard, values=_ro(xv), exact=err <= tol, base_error=err, bodies=bodies,
                            active_constraints=_active(labels, cons, xv, s, 2.0 / p), notes=tuple(notes))


def standard_set_from_result(model: IdentificationModel, result: Mapping, nominal=None, *, source: str = "result",
                             solver: str | None = None) -> tuple[StandardFromBase, dict[str, float]]:
    """The standard set (and payload values) an exporter writes for a ``symoro-gen identify`` JSON result.

    With a ``physical`` block (``identify --physical``) its standard values are used as they are
    (consistent, and their regrouping is the result's ``parameters``); otherwise the base
    parameters of ``parameters`` (eliminated ones 0, known ``fixed`` ones included) go through
    :func:`standard_from_base`. Payload values: those of the result when it has all ten and they are
    consistent, else none (the exporter keeps the robot file's).

    Returns
    -------
    (StandardFromBase, dict)
        The standard set with its report, and ``payload name -> value``.
    """
    try:
        par = result["parameters"]
        pm = {n: v for n, v in zip(par["names"], par["values"])}
    except (KeyError, TypeError):
        raise IdentificationError(f"{source}: not a result of `symoro-gen identify` (no 'parameters' names/values)") from None
    pm.update({n: 0.0 for n in result.get("eliminated", ())})
    pm.update(dict(result.get("fixed", {})))
    null = [n for n, v in pm.items() if v is None]
    if null:
        raise IdentificationError(f"{source}: parameters without a finite value: {', '.join(null)}")
    payload = {n: float(pm[n]) for n in model.PAYLOAD_NAMES if n in pm}
    phys = result.get("physical")
    if phys:
        st = dict(zip(phys["names"], phys["values"]))
        missing = [n for n in model.STANDARD_NAMES if st.get(n) is None]
        if missing:
            raise IdentificationError(f"{source}: physical block lacks {', '.join(missing)}")
        x = np.array([float(st[n]) for n in model.STANDARD_NAMES])
        lay = _layout(model, (), ())
        nominal_v = _nominal_vector(lay, nominal)
        sb = StandardFromBase(names=lay.standard, values=_ro(x), exact=True, base_error=0.0,
                              bodies=_body_reports(lay, x, nominal_v), active_constraints=(),
                              notes=(f"standard parameters of the physically consistent estimate in {source}",))
        pl = phys.get("payload", {})
        payload.update({n: float(v) for n, v in zip(pl.get("names", ()), pl.get("values", ())) if v is not None})
    else:
        missing = [n for n in model.BASE_NAMES if n not in pm]
        if missing:
            raise IdentificationError(f"{source}: base parameters missing: {', '.join(missing)}")
        sb = standard_from_base(model, {n: float(pm[n]) for n in model.BASE_NAMES}, nominal, solver=solver)
    if len(payload) != len(model.PAYLOAD_NAMES) or (
            payload and check_physical_consistency([payload[n] for n in model.PAYLOAD_NAMES])):
        payload = {}
    return sb, payload
