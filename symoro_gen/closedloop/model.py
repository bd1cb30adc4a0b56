"""Identification model of a closed-loop robot: the tree model projected on the actuated joints.

Cutting every loop at a passive joint leaves a tree whose model (generated like any robot: the
``[[frames]]`` table, passive joints without drive terms) gives the tree torques
``tau_t = IDM_t(q_t, qd_t, qdd_t) chi``. With the passive joints driven by the loop closure
(:mod:`symoro_gen.closedloop.kinematics`), ``q_t = q_t(q_a)``, ``qd_t = G qd_a``,
``qdd_t = G qdd_a + g(q_a, qd_a)`` with ``G = d q_t / d q_a``, and the principle of virtual work (the
constraint forces do no work along the closed motion; the passive joints have no actuator) gives the
actuated torques ([KD2002] sec. 10.x, dynamic model of closed-loop robots; Khalil & Bennis 1995)::

    tau_a = G^T tau_t = (G^T IDM_t) chi                                                    (*)

so the closed-loop robot is linear in the same standard parameters, with the projected regressor
``G^T IDM_t``. This model is evaluated **numerically**: the generated tree regressor at the solved
tree state, then (*) (it is not emitted as symbolic code).

Base parameters ([KB1995]; [G1991] for the numeric method): starting from the tree's base
parameters (closed-form regrouping of the tree, ``W_t = W_tb K_t``), the loop brings extra
dependencies among the projected columns ``G^T W_tb``. They are found by a QR factorisation without
pivoting of the projected base columns on random closed states around the reference assembly
(columns scaled to unit norm; a column within ``1e-8`` of the span of the previous independent ones
depends on them, :func:`independent_columns`, so a
dependent parameter regroups onto earlier links as in the tree rules); its coefficients come from a
least-squares solve. Base parameter ``b`` is ``chi_b = P K_t chi`` with ``P = [I beta]``; a parameter that
absorbed others is suffixed ``R`` (``[KC1997]``). :func:`closed_loop_base` returns the relations with
their numeric coefficients (geometry substituted), each followed by a closed form in the geometric
constants when a simple one matches (:func:`recognise`, e.g. ``0.318181818182 [= L5/D3]``), recognised
from the numbers. For a closure linear in the joint variables (parallelograms) the groupings are derived
in closed form by :mod:`symoro_gen.closedloop.grouping` ([KB1995], energy method) and written by the
generator to ``closed_loop_base_parameters.md``, which :meth:`ClosedLoopModel.base_parameters_text` shows.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..description.model import RobotDescription
from ..errors import ModelError
from ..model import IdentificationModel
from .grouping import LinearClosure, detect_linear_closure
from .kinematics import ClosedState, ClosureError, LoopKinematics, independent_columns, sample_states

__all__ = ["ClosedLoopBase", "ClosedLoopModel", "closed_loop_base"]


@dataclass(frozen=True, eq=False)
class ClosedLoopBase:
    """Base parameters of a closed-loop robot.

    Attributes
    ----------
    names : tuple of str
        Base parameter names of the closed-loop robot.
    keep : tuple of int
        Tree base columns kept (indices into the tree model's ``BASE_NAMES``).
    P : (nb, nb_tree)
        ``chi_b = P chi_tree_base``.
    K : (nb, n_std)
        ``chi_b = K chi_std``.
    tree_names : tuple of str
        The tree model's base names.
    groupings : tuple of str
        The extra groupings the loops bring, one line per closed-loop base parameter that absorbed
        tree base parameters (``"ZZ2R = ZZ2R + 1 ZZ3R"``, tree base names on the right).
    """

    names: tuple[str, ...]
    keep: tuple[int, ...]
    P: NDArray[np.float64]
    K: NDArray[np.float64]
    tree_names: tuple[str, ...]
    groupings: tuple[str, ...]


def _fmt(c: float) -> str:
    return f"{c:.12g}"


def recognise(c: float, values: dict[str, float], tol: float = 1e-9) -> str | None:
    """A closed form of a numeric coefficient in the robot's geometric constants, when one is simple:
    ``k * a^i * b^j`` with ``a, b`` among ``[values]``, ``i, j`` in ``{-2, -1, 1, 2}`` and ``k`` in
    ``{1, 2, 1/2}`` (signed), or ``k`` alone; matched to ``tol`` (relative). The simplest match wins (fewest
    constants, then the order of ``[values]``). A heuristic (a coincidence of the numbers can match), so
    the printed relations give it next to the number."""
    if c == 0.0:
        return "0"
    ks = (1.0, 2.0, 0.5)
    names = sorted(values)
    exps = (1, -1, 2, -2)

    def close(x: float) -> bool:
        return abs(x - abs(c)) <= tol * max(1.0, abs(c))
    sign = "-" if c < 0 else ""
    for k in ks:
        if close(k):
            return f"{sign}{k:g}"
    for n_sym in (1, 2):
        for combo in itertools.combinations(names, n_sym):
            for es in itertools.product(exps, repeat=n_sym):
                v = 1.0
                for nm, e in zip(combo, es):
                    v *= float(values[nm]) ** e
                for k in ks:
                    if close(k * v):
                        num = [f"{nm}" + (f"^{e}" if e > 1 else "") for nm, e in zip(combo, es) if e > 0]
                        den = [f"{nm}" + (f"^{-e}" if e < -1 else "") for nm, e in zip(combo, es) if e < 0]
                        head = (f"{k:g}*" if k != 1.0 else "") + ("*".join(num) or "1")
                        return sign + head + (f"/{'/'.join(den)}" if den else "")
    return None


def closed_loop_base(kin: LoopKinematics, tree: IdentificationModel, *, n_samples: int = 120,
                     tol: float = 1e-8, seed: int = 0) -> ClosedLoopBase:
    """Base parameters of the closed-loop robot (numeric rank of the projected tree base regressor)."""
    span = 1.0
    for _ in range(6):  # samples that cannot be closed (out of reach, past a singularity) are left out
        q, dq, ddq = sample_states(kin, n_samples, seed, scale=span)
        st = kin.solve(q, dq, ddq, check=False)
        ok = st.residual < 1e-10
        if ok.sum() >= n_samples // 2:
            break
        span /= 2
    else:
        raise ClosureError(f"{kin.robot.name}: the loops cannot be closed around the reference configuration "
                           "(base-parameter sweep); check [[loops]] and [loop_reference]")
    Wt = tree.regressor(st.q[ok], st.dq[ok], st.ddq[ok])
    W = np.einsum("nta,ntp->nap", st.G[ok], Wt).reshape(-1, len(tree.BASE_NAMES))
    norms = np.linalg.norm(W, axis=0)
    live = norms > tol * max(1.0, float(norms.max(initial=0.0)))
    Ws = np.where(live, W / np.where(live, norms, 1.0), 0.0)
    diag = independent_columns(Ws, tol)
    indep = [i for i in range(W.shape[1]) if live[i] and diag[i] > tol]
    dep = [i for i in range(W.shape[1]) if live[i] and diag[i] <= tol]
    beta = np.linalg.lstsq(W[:, indep], W[:, dep], rcond=None)[0] if dep else np.zeros((len(indep), 0))
    beta[np.abs(beta) < 1e-9 * max(1.0, float(np.abs(beta).max(initial=0.0)))] = 0.0
    nbt = W.shape[1]
    P = np.zeros((len(indep), nbt))
    P[np.arange(len(indep)), indep] = 1.0
    if dep:
        P[:, dep] = beta
    tree_names = tuple(tree.BASE_NAMES)
    geometry = {k: float(v) for k, v in kin.robot.values.items()}

    def coef(c: float) -> str:
        form = recognise(c, geometry)
        if form is None or form.lstrip("-") == _fmt(abs(c)):
            return _fmt(abs(c))
        return f"{_fmt(abs(c))} [= {form.lstrip('-')}]"
    names, groupings = [], []
    for b, i in enumerate(indep):
        absorbed = [(tree_names[d], beta[b, k]) for k, d in enumerate(dep) if beta[b, k] != 0.0]
        name = tree_names[i]
        if absorbed and not name.endswith("R"):
            name += "R"
        names.append(name)
        if absorbed:
            groupings.append(f"{name} = {tree_names[i]} " + " ".join(
                f"{'+' if c >= 0 else '-'} {coef(c)} {n}" for n, c in absorbed))
    n_std = len(tree.STANDARD_NAMES)
    Kt = np.asarray(tree.base_parameters(np.eye(n_std)), float).T  # (nb_tree, n_std)
    if len(set(names)) != len(names):  # two kept columns with the same name: keep them apart
        names = [n if names.count(n) == 1 else f"{n}_{k}" for k, n in enumerate(names)]
    return ClosedLoopBase(names=tuple(names), keep=tuple(indep), P=P, K=P @ Kt, tree_names=tree_names,
                          groupings=tuple(groupings))


class ClosedLoopModel:
    """:class:`~symoro_gen.model.IdentificationModel` of a closed-loop robot (joint order: the actuated
    joints ``ACTUATED_JOINTS``, ``q`` of shape (N, n_a)).

    Parameters
    ----------
    robot : RobotDescription
        With ``[[loops]]``.
    tree : IdentificationModel
        The model of its tree (the generated package of the robot file).
    """

    def __init__(self, robot: RobotDescription, tree: IdentificationModel):
        if robot.n_joints != tree.N_JOINTS:
            raise ModelError(f"{robot.name}: the tree model has {tree.N_JOINTS} joints, the robot file "
                             f"{robot.n_joints}: regenerate it")
        self.robot = robot
        self.tree = tree
        self.kinematics = LoopKinematics(robot)
        self.ROBOT = robot.name
        self.ACTUATED_JOINTS = tuple(r.j for r in robot.actuated)
        self.N_JOINTS = len(self.ACTUATED_JOINTS)
        self.STANDARD_NAMES = tuple(tree.STANDARD_NAMES)
        self.PAYLOAD_NAMES = tuple(tree.PAYLOAD_NAMES)
        self.base = closed_loop_base(self.kinematics, tree)
        self.BASE_NAMES = self.base.names
        self._keep = np.array(self.base.keep, int)
        self._cache: tuple[tuple, ClosedState] | None = None
        self._linear: tuple | None = None

    # ---------------------------------------------------------------------------------------------
    def _inputs(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike):
        n = self.N_JOINTS
        arrs = []
        for name, x in (("q", q), ("dq", dq), ("ddq", ddq)):
            a = np.asarray(x, dtype=float)
            if a.ndim == 1 and a.shape[0] == n:
                a = a[None, :]
            elif not (a.ndim == 2 and a.shape[1] == n):
                raise ValueError(f"{self.ROBOT}: {name} must have shape (N, {n}) or ({n},) (the actuated joints "
                                 f"{list(self.ACTUATED_JOINTS)}), got {a.shape}")
            arrs.append(a)
        if not arrs[0].shape[0] == arrs[1].shape[0] == arrs[2].shape[0]:
            raise ValueError(f"{self.ROBOT}: q, dq, ddq have different sample counts {[a.shape[0] for a in arrs]}")
        return arrs, np.ndim(q) == 1

    def closure(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> ClosedState:
        """The solved tree state (every joint, passive ones included) and ``G`` for actuated states."""
        (Q, DQ, DDQ), _ = self._inputs(q, dq, ddq)
        key = (Q.shape, Q.tobytes(), DQ.tobytes(), DDQ.tobytes())
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        st = self.kinematics.solve(Q, DQ, DDQ)
        self._cache = (key, st)
        return st

    def _project(self, kind: str, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        _, one = self._inputs(q, dq, ddq)
        st = self.closure(q, dq, ddq)
        W = getattr(self.tree, kind)(st.q, st.dq, st.ddq)
        if kind == "regressor":
            W = W[:, :, self._keep]
        out = np.einsum("nta,ntp->nap", st.G, W)
        return out[0] if one else out

    def regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """Base regressor of the closed-loop robot, (N, n_a, len(BASE_NAMES))."""
        return self._project("regressor", q, dq, ddq)

    def standard_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """``G^T IDM_t``, (N, n_a, len(STANDARD_NAMES))."""
        return self._project("standard_regressor", q, dq, ddq)

    def payload_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """``G^T`` times the tree's payload regressor, (N, n_a, len(PAYLOAD_NAMES))."""
        return self._project("payload_regressor", q, dq, ddq)

    def linear_closure(self) -> LinearClosure | None:
        """The exact linear closure ``q_tree = A q_a + b``
        (:class:`~symoro_gen.closedloop.grouping.LinearClosure`) of a parallelogram or of coupled joints,
        or ``None`` for a general loop (see :func:`~symoro_gen.closedloop.grouping.detect_linear_closure`);
        found once."""
        if self._linear is None:
            self._linear = (detect_linear_closure(self.kinematics),)
        return self._linear[0]

    def casadi_regressor(self) -> Any:
        """``casadi.Function regressor_<robot>(q, dq, ddq) -> Y`` (n_a x nb base regressor, actuated joints) for
        a **linear** closure: ``Y = A^T W_tree(A q + b, A dq, A ddq)[:, keep]`` with the tree package's CasADi
        regressor (``G = A`` is constant and the closure adds no bias acceleration), the same as
        :meth:`regressor`. A general loop (a four-bar whose passive angles are not linear in the crank's)
        has no closed form: :class:`~symoro_gen.errors.ModelError` says so."""
        lc = self.linear_closure()
        if lc is None:
            raise ModelError(f"{self.ROBOT}: the loop closure is not linear in the actuated joints (a general "
                             "loop, solved numerically), so the model has no CasADi form")
        import casadi as ca  # heavy; only for optimisation

        A, b = lc.numeric()
        tree: Any = self.tree  # a generated package (IdentificationModel does not declare its CasADi form)
        F = tree.casadi_regressor()
        n = self.N_JOINTS
        q, dq, ddq = (ca.SX.sym(s, n) for s in ("q", "dq", "ddq"))
        At = ca.DM(A)
        Yt = F(ca.mtimes(At, q) + ca.DM(b), ca.mtimes(At, dq), ca.mtimes(At, ddq))
        Y = ca.mtimes(At.T, Yt[:, [int(k) for k in self._keep]])
        return ca.Function(f"regressor_{self.ROBOT}", [q, dq, ddq], [Y])

    def base_parameters(self, chi_std: ArrayLike) -> NDArray[np.float64]:
        """Base parameters ``K chi_std`` (see :class:`ClosedLoopBase`), (..., len(BASE_NAMES))."""
        chi = np.asarray(chi_std, dtype=float)
        if chi.shape[-1:] != (len(self.STANDARD_NAMES),):
            raise ValueError(f"{self.ROBOT}: chi_std must end with {len(self.STANDARD_NAMES)} entries "
                             f"(STANDARD_NAMES), got {chi.shape}")
        return chi @ self.base.K.T

    def torque(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike, chi_std: ArrayLike,
               chi_payload: ArrayLike | None = None) -> NDArray[np.float64]:
        """Actuated torques (N, n_a) ``G^T tau_tree`` for standard (and payload) parameters."""
        Y = self.regressor(q, dq, ddq) @ self.base_parameters(chi_std)
        if chi_payload is not None:
            Y = Y + self.payload_regressor(q, dq, ddq) @ np.asarray(chi_payload, float)
        return Y

    def nominal_parameters(self) -> NDArray[np.float64] | None:
        v = self.robot.nominal_vector()
        return None if v is None else np.asarray(v, float)

    def nominal_payload(self) -> NDArray[np.float64] | None:
        v = self.robot.nominal_payload()
        return None if v is None else np.asarray(v, float)

    def closed_form_text(self) -> str | None:
        """The generated ``closed_loop_base_parameters.md`` beside the tree package (the closed-form
        groupings of a linear closure, [KB1995]), or None (an in-memory tree, or an older package)."""
        f = getattr(self.tree, "__file__", None)
        if not f:
            return None
        p = Path(f).parent / "closed_loop_base_parameters.md"
        return p.read_text(encoding="utf-8") if p.is_file() else None

    def base_parameters_text(self) -> str:
        """The base parameters and the extra groupings of the loops, as Markdown lines."""
        lines = [f"# Base parameters of the closed-loop robot `{self.ROBOT}`", "",
                 f"{len(self.BASE_NAMES)} base parameters (tree: {len(self.base.tree_names)}; the loops remove "
                 f"{len(self.base.tree_names) - len(self.BASE_NAMES)}), actuated joints {list(self.ACTUATED_JOINTS)}.",
                 "", "Extra groupings brought by the loops (tree base parameters, numeric coefficients):", ""]
        lines += [f"* `{g}`" for g in self.base.groupings] or ["* none"]
        cf = self.closed_form_text()
        if cf is not None:
            lines += ["", "Closed form (the generated `closed_loop_base_parameters.md`, symoro_gen.closedloop.grouping):",
                      "", *cf.rstrip("\n").splitlines()[4:]]
        lines += ["", "Base parameters in standard ones:", ""]
        for name, row in zip(self.BASE_NAMES, self.base.K):
            terms = [(self.STANDARD_NAMES[k], c) for k, c in enumerate(row) if abs(c) > 1e-12]
            lines.append(f"* `{name} = " + " ".join(
                f"{'+' if c >= 0 else '-'} {_fmt(abs(c))} {n}" for n, c in terms).lstrip("+ ") + "`")
        return "\n".join(lines) + "\n"
