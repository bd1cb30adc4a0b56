"""Closed-form base parameters of closed loops whose closure is linear (parallelograms).

Khalil & Bennis 1995 ([KB1995]; [KD2002] sec. 14.5, the SR400) obtain the base parameters of a
closed-loop robot from those of its equivalent tree: the tree's closed-form rules first, then the
groupings the loop constraints bring. When the passive joint variables are **linear** in the actuated
ones, ``q_tree = A q_a + b`` with ``A`` and ``b`` constant (a parallelogram: ``q3 = q5 - q2``,
``q6 = q2 - q5``), these groupings have closed forms in the geometric constants. They are found here
with the energy method of [KB1995] (after Gautier & Khalil's energy model of the base parameters,
[GK1990]):

* the total energy of the closed robot is ``H = sum_b (T_b - U_b) chi_b`` over the tree's base
  parameters, with ``T_b`` (kinetic) and ``U_b`` (potential) the energy functions of the standard
  parameter whose column base parameter ``b`` keeps (``BaseParameterMap.kept``), written in the
  actuated variables by the closure (``q_p = A q_a + b``, ``qd_p = A qd_a``). With a constant ``A``
  they are polynomials in ``sin q_i, cos q_i`` (``q_i`` for prismatic joints) and ``qd_i`` of the actuated
  joints, with coefficients polynomial in the geometric constants and gravity (``G3``);
* the closed model is Lagrange's equations of ``H`` in ``q_a`` (equal to ``G^T tau_tree``, virtual work),
  so a set of parameters has dependent columns iff ``sum_b c_b T_b = 0`` and ``sum_b c_b U_b = const``
  identically ([GK1990]: the null Lagrangians of a mechanical system). In the normal form of the
  polynomials (``cos^2 = 1 - sin^2``), these are linear equations on ``c``, one per monomial: the
  coefficient matrix ``E`` (monomials x tree base parameters) carries every dependency;
* the dependent parameters and the support of each dependency are read from ``E`` evaluated at the robot's
  values (in the tree's base order, each column against the span of the independent ones before it, so a parameter regroups onto earlier ones, as in
  the tree rules); each dependency ``E_S beta = E_d`` is then solved exactly with sympy on ``|S|``
  independent rows and checked on **every** row symbolically. The relation of closed-loop base
  parameter ``b`` in the standard parameters is ``chi_b + sum_d beta_bd chi_d`` with the tree's relations
  ``chi_b, chi_d`` (coefficients in the geometric constants).

Drive terms: ``IA_j`` has the energy ``qd_j^2 / 2``, the offset ``OFF_j`` the potential ``q_j``; viscous and
Coulomb friction columns are never combinations of energy columns and are kept.

The closure is detected numerically (:func:`detect_linear_closure`): the solved passive variables are
fitted by ``A q_a + b`` on random closed states around the reference assembly, ``A`` rounded to small
fractions and ``b`` to fractions of ``pi`` (revolute) and checked to ``1e-9`` on other states. A general
four-bar (the passive angles are not linear in the crank angle) gets ``None``: its groupings stay the
numeric ones of :func:`symoro_gen.closedloop.model.closed_loop_base`.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np
import sympy as sp
from numpy.typing import NDArray
from scipy.linalg import qr as _qr
from sympy.printing.pycode import PythonCodePrinter

from ..description.mdh import constant_rotation, position, rot_z
from ..description.model import FIXED, PRISMATIC, REVOLUTE, RobotDescription, q_symbol
from ..errors import ModelError
from .kinematics import LoopKinematics, independent_columns, sample_states

__all__ = ["LinearClosure", "ClosedFormBase", "coupling_closure", "detect_linear_closure", "closed_form_base", "closed_form_markdown",
           "closed_loop_regressor", "closed_loop_kernel_source"]


@dataclass(frozen=True)
class LinearClosure:
    """``q_tree = A q_a + b`` of a loop closure that is linear in the joint variables.

    Attributes
    ----------
    joints : tuple of int
        Tree joints (frames), tree joint order (the rows of ``A``).
    actuated : tuple of int
        Actuated joints (the columns of ``A``).
    A : sympy Matrix (n_tree, n_a)
        Exact (small fractions; the actuated rows are the identity).
    b : tuple of sympy expressions
        Offsets: fractions of ``pi`` (revolute joints) or small fractions (prismatic ones) when they are,
        else the fitted number; 0 for the actuated joints.
    error : float
        Largest difference between ``A q_a + b`` and the solved closure on the check states (rad or m).
    """

    joints: tuple[int, ...]
    actuated: tuple[int, ...]
    A: sp.Matrix
    b: tuple[sp.Expr, ...]
    error: float

    def numeric(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(A, b)`` as float arrays, shapes (n_tree, n_a) and (n_tree,)."""
        return np.array(self.A.tolist(), float), np.array([float(x) for x in self.b])

    def substitutions(self) -> dict[sp.Symbol, sp.Expr]:
        """``{q_p: sum_i A_pi q_i + b_p}`` for the passive tree joints."""
        qa = [q_symbol(j) for j in self.actuated]
        return {q_symbol(j): sum((self.A[r, c] * qa[c] for c in range(len(qa))), sp.S(0)) + self.b[r]
                for r, j in enumerate(self.joints) if j not in self.actuated}

    def lines(self) -> list[str]:
        """``q3 = -q2 + q5`` per passive joint."""
        return [f"q{j} = {sp.sstr(e)}" for j, e in ((k.name[1:], v) for k, v in self.substitutions().items())]


def _exact(x: float, unit: sp.Expr, max_den: int) -> sp.Expr | None:
    f = Fraction(x / float(unit)).limit_denominator(max_den)
    if abs(float(f) * float(unit) - x) > 1e-9:
        return None
    return sp.Rational(f.numerator, f.denominator) * unit


def _exact_number(e: sp.Expr, unit: sp.Expr) -> sp.Expr:
    """A robot file's number made exact when it is a simple fraction (of ``unit``) up to rounding
    (``0.5 -> 1/2``, ``1.5707963267948966 -> pi/2``), else kept as it is."""
    if not e.atoms(sp.Float):
        return e
    x = _exact(float(e), unit, 1000 if unit == 1 else 24)
    return x if x is not None and abs(float(x) - float(e)) < 1e-12 * max(1.0, abs(float(e))) else e


def coupling_closure(robot: RobotDescription) -> LinearClosure:
    """The exact closure ``q_tree = A q_a + b`` of a robot whose only constraints are coupled (mimic) joints:
    known by construction (``q_m = multiplier q_s + offset``), no fit."""
    tree = [r.j for r in robot.joints]
    act = [r.j for r in robot.actuated]
    A = sp.zeros(len(tree), len(act))
    b: list[sp.Expr] = [sp.S(0)] * len(tree)
    for r, j in enumerate(tree):
        c = robot.coupling(j)
        if c is None:
            if j in act:
                A[r, act.index(j)] = 1
            continue
        A[r, act.index(c.source)] = _exact_number(c.multiplier, sp.S(1))
        b[r] = _exact_number(c.offset, sp.pi if robot.row(j).sigma == REVOLUTE else sp.S(1))
    return LinearClosure(tuple(tree), tuple(act), A, tuple(b), 0.0)


def detect_linear_closure(kin: LoopKinematics, *, n_fit: int = 40, n_check: int = 40, seed: int = 7,
                          tol: float = 1e-9) -> LinearClosure | None:
    """The exact linear closure ``q_tree = A q_a + b`` of ``kin``'s robot, or ``None`` when the closed
    passive variables are not (exactly) linear in the actuated ones around the reference assembly. A robot
    with coupled joints and no loop has it by construction (:func:`coupling_closure`)."""
    robot = kin.robot
    if kin.linear:
        return coupling_closure(robot)
    tree = list(kin.tree_joints)
    nt, na = len(tree), kin.n_a
    out = []
    for k, n in ((0, n_fit), (1, n_check)):
        q, dq, ddq = sample_states(kin, n, seed + k, scale=1.0)
        st = kin.solve(q, dq, ddq, check=False)
        ok = st.residual < 1e-10
        if ok.sum() < max(na + 2, n // 2):
            return None
        out.append((q[ok], st.q[ok]))
    (qa, qt), (qa2, qt2) = out
    X = np.hstack([qa, np.ones((qa.shape[0], 1))])
    coef = np.linalg.lstsq(X, qt, rcond=None)[0]  # (na + 1, nt)
    if np.max(np.abs(X @ coef - qt)) > 1e3 * tol:
        return None
    A = sp.zeros(nt, na)
    b: list[sp.Expr] = []
    for r, j in enumerate(tree):
        for c in range(na):
            e = _exact(float(coef[c, r]), sp.S(1), 12)
            if e is None:
                return None
            A[r, c] = e
        off = float(coef[na, r])
        if abs(off) < tol:
            b.append(sp.S(0))
            continue
        e = _exact(off, sp.pi, 24) if robot.row(j).sigma == REVOLUTE else _exact(off, sp.S(1), 1000)
        # an offset that is no simple fraction (of pi) stays a number: the relations then carry its sine
        # and cosine as numbers (printed), still exact to rounding
        b.append(e if e is not None else sp.Float(round(off, 12), 15))
    closure = LinearClosure(tuple(tree), tuple(kin.actuated), A, tuple(b), 0.0)
    An, bn = closure.numeric()
    err = float(np.max(np.abs(qa2 @ An.T + bn - qt2)))
    return None if err > tol else dataclasses.replace(closure, error=err)


# ---- energy functions in the actuated variables ------------------------------------------------
class _Energies:
    """Energy functions of the standard parameters of a closed robot with a linear closure, as
    polynomials in the state generators (``s_i, c_i`` of revolute actuated joints, ``x_i`` = the actuated
    position itself, ``v_i`` = the actuated velocity) with sympy coefficients in the constants."""

    def __init__(self, robot: RobotDescription, closure: LinearClosure):
        self.robot = robot
        act = closure.actuated
        self.s = {j: sp.Symbol(f"_s{j}") for j in act}
        self.c = {j: sp.Symbol(f"_c{j}") for j in act}
        self.x = {j: sp.Symbol(f"_x{j}") for j in act}
        self.v = {j: sp.Symbol(f"_v{j}") for j in act}
        rev = [j for j in act if robot.row(j).sigma == REVOLUTE]
        self.rev = rev
        self.gens = ([self.s[j] for j in rev] + [self.c[j] for j in rev] + [self.x[j] for j in act]
                     + [self.v[j] for j in act])
        subs = closure.substitutions()
        qa = {j: q_symbol(j) for j in act}
        trig = {}
        for j in rev:
            trig[sp.sin(qa[j])] = self.s[j]
            trig[sp.cos(qa[j])] = self.c[j]
        lin = {qa[j]: self.x[j] for j in act}

        def poly_of(e: sp.Expr) -> sp.Expr:
            e = sp.expand_trig(sp.sympify(e).xreplace(subs))
            e = sp.expand(e.xreplace(trig))
            bad = [f for f in e.atoms(sp.sin, sp.cos) if f.free_symbols & set(qa.values())]
            if bad:
                raise ModelError(f"{robot.name}: closed-form regrouping: a joint variable left in {bad[0]} after "
                                 "the linear closure (a revolute joint turning by a non-integer multiple of an "
                                 "actuated angle, or following a prismatic joint): the groupings stay numeric")
            return e.xreplace(lin)

        def rate(e: sp.Expr) -> sp.Expr:
            """d/dt of a joint expression (theta or r) through the closure."""
            e = sp.sympify(e).xreplace(subs)
            return sp.expand(sum((sp.diff(e, qa[j]) * self.v[j] for j in act), sp.S(0)))

        g = [sp.Symbol(f"G{i + 1}", real=True) if x != 0 else sp.S(0) for i, x in enumerate(robot.gravity)]
        zero = sp.zeros(3, 1)
        w: dict[int, sp.Matrix] = {0: zero}
        V: dict[int, sp.Matrix] = {0: zero}
        R0: dict[int, sp.Matrix] = {0: sp.eye(3)}
        p0: dict[int, sp.Matrix] = {0: zero}
        self.T: dict[str, sp.Expr] = {}
        self.U: dict[str, sp.Expr] = {}
        ez = sp.Matrix([0, 0, 1])
        for row in robot.rows:
            j, a = row.j, row.ant
            R = (constant_rotation(row) * rot_z(row.theta)).applyfunc(poly_of)
            P = position(row).applyfunc(poly_of)
            wa = w[a]
            wj = R.T * wa
            Vj = R.T * (V[a] + wa.cross(P))
            if row.sigma == REVOLUTE:
                wj = wj + rate(row.theta) * ez
            elif row.sigma == PRISMATIC:
                Vj = Vj + rate(row.r) * ez
            w[j], V[j] = wj.applyfunc(sp.expand), Vj.applyfunc(sp.expand)
            R0[j] = (R0[a] * R).applyfunc(sp.expand)
            p0[j] = (p0[a] + R0[a] * P).applyfunc(sp.expand)
            if row.sigma == FIXED:
                continue
            o, vv = w[j], V[j]
            cr = vv.cross(o)
            gR = [-sum((g[i] * R0[j][i, k] for i in range(3)), sp.S(0)) for k in range(3)]
            for name, t, u in (("XX", o[0] ** 2 / 2, 0), ("XY", o[0] * o[1], 0), ("XZ", o[0] * o[2], 0),
                               ("YY", o[1] ** 2 / 2, 0), ("YZ", o[1] * o[2], 0), ("ZZ", o[2] ** 2 / 2, 0),
                               ("MX", cr[0], gR[0]), ("MY", cr[1], gR[1]), ("MZ", cr[2], gR[2]),
                               ("M", vv.dot(vv) / 2, -sum((g[i] * p0[j][i] for i in range(3)), sp.S(0)))):
                self.T[f"{name}{j}"] = sp.expand(t)
                self.U[f"{name}{j}"] = sp.expand(u)
            qd = rate(row.theta if row.sigma == REVOLUTE else row.r)
            self.T[f"IA{j}"] = sp.expand(qd**2 / 2)
            self.U[f"IA{j}"] = sp.S(0)
            self.T[f"OFF{j}"] = sp.S(0)
            self.U[f"OFF{j}"] = poly_of(q_symbol(j))

    def normal_form(self, e: sp.Expr) -> dict[tuple[int, ...], sp.Expr]:
        """``{state monomial: coefficient}`` with every ``c_i^k`` (k >= 2) reduced by ``c^2 = 1 - s^2``."""
        if e == 0:
            return {}
        p = sp.Poly(e, *self.gens)
        n_r = len(self.rev)
        out: dict[tuple[int, ...], sp.Expr] = {}
        todo = list(p.terms())
        while todo:
            m, coef = todo.pop()
            m = tuple(m)
            hi = next((i for i in range(n_r) if m[n_r + i] >= 2), None)
            if hi is None:
                out[m] = out.get(m, sp.S(0)) + coef
                continue
            m1 = list(m)
            m1[n_r + hi] -= 2  # c^k = c^(k-2) (1 - s^2)
            todo.append((tuple(m1), coef))
            m2 = list(m1)
            m2[hi] += 2
            todo.append((tuple(m2), -coef))
        return {k: v for k, v in ((k, sp.expand(v)) for k, v in out.items()) if v != 0}


# ---- the closed-form base parameters -----------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ClosedFormBase:
    """Closed-form base parameters of a closed-loop robot with a linear closure.

    Attributes
    ----------
    closure : LinearClosure
    names : tuple of str
        Closed-loop base parameter names (tree base names, ``R`` added to those that absorbed others).
    keep : tuple of int
        The tree base parameters kept (indices into ``tree_names``).
    kept_standard : tuple of str
        The standard parameter whose (projected) column each closed-loop base parameter keeps.
    relations : dict
        ``name -> sympy expression`` in the standard-parameter symbols (coefficients in the geometric
        constants and gravity symbols).
    groupings : tuple of str
        The groupings the loop brings, in the tree's base parameters: ``"MY3R = MY3R - L5/D3*MX6"``.
    no_effect : tuple of str
        Tree base parameters without effect on the closed-loop model.
    tree_names : tuple of str
    """

    closure: LinearClosure
    names: tuple[str, ...]
    keep: tuple[int, ...]
    kept_standard: tuple[str, ...]
    relations: Mapping[str, sp.Expr]
    groupings: tuple[str, ...]
    no_effect: tuple[str, ...]
    tree_names: tuple[str, ...]
    standard_names: tuple[str, ...]
    values: Mapping[sp.Symbol, float]
    energies: _Energies | None = field(default=None, repr=False)

    def matrix(self) -> NDArray[np.float64]:
        """``K`` (nb, n_std) with ``chi_b = K chi_std``, constants substituted."""
        idx = {n: i for i, n in enumerate(self.standard_names)}
        K = np.zeros((len(self.names), len(self.standard_names)))
        for b, name in enumerate(self.names):
            e = sp.expand(self.relations[name].xreplace(dict(self.values)))
            for s in e.free_symbols:  # linear in the standard parameters; coefficients may be sqrt(3)/2...
                K[b, idx[str(s)]] += float(e.coeff(s))
        return K


def _tidy(x: sp.Expr) -> sp.Expr:
    """Numbers from a numeric closure offset: one that is a simple fraction up to rounding becomes it."""
    rep = {}
    for f in x.atoms(sp.Float):
        r = sp.Rational(f).limit_denominator(1000)
        if abs(float(f) - float(r)) < 1e-12:
            rep[f] = r
    return x.xreplace(rep)


def _term(c: sp.Expr, name: str) -> str:
    """``+ name``, ``- name``, ``- L5/D3*name``."""
    neg = c.could_extract_minus_sign()
    a = -c if neg else c
    return f"{'-' if neg else '+'} " + (name if a == 1 else f"{sp.sstr(a)}*{name}")


def _sym(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


def closed_form_base(robot: RobotDescription, tree_names: Sequence[str], kept: Sequence[str],
                     tree_relations: Mapping[str, sp.Expr], gravity: Mapping[sp.Symbol, float] | None = None,
                     *, kinematics: LoopKinematics | None = None, tol: float = 1e-9) -> ClosedFormBase | None:
    """Closed-form base parameters of ``robot`` (with ``[[loops]]``) from its tree's base parameters
    (``tree_names``, the standard parameter each keeps, ``kept``, and their relations), or ``None`` when
    the loop closure is not linear in the joint variables (see the module docstring).

    ``gravity`` maps the gravity symbols of the relations (``G3``) to their values (default: the robot's)."""
    kin = kinematics or LoopKinematics(robot)
    closure = detect_linear_closure(kin)
    if closure is None:
        return None
    std_names = tuple(robot.standard_names)
    if gravity is None:
        gravity = {_sym(f"G{i + 1}"): float(x) for i, x in enumerate(robot.gravity) if x != 0}
    values: dict[sp.Symbol, float] = {**robot.geometry_subs(), **gravity}
    # the kept standard parameter of each tree base parameter has that base parameter's column
    expanded = {n: sp.expand(tree_relations[n]) for n in tree_names}
    for name, kstd in zip(tree_names, kept):
        for other in tree_names:
            if expanded[other].coeff(_sym(kstd)) != (1 if other == name else 0):
                raise ModelError(f"{robot.name}: tree base parameter {other}: the kept standard parameter {kstd} of "
                                 f"{name} appears in its relation; the closed-form loop grouping needs the tree's "
                                 "base parameters to keep distinct standard columns")
    en = _Energies(robot, closure)
    # energy columns; friction columns are never combinations of energy columns (kept as they are)
    cols = [i for i, k in enumerate(kept) if not (k.startswith("FV") or k.startswith("FS"))]
    T = {i: en.normal_form(en.T[kept[i]]) for i in cols}
    U = {i: en.normal_form(en.U[kept[i]]) for i in cols}
    const = tuple(0 for _ in en.gens)
    rows = sorted({("T",) + m for i in cols for m in T[i]} | {("U",) + m for i in cols for m in U[i] if m != const})
    ridx = {r: k for k, r in enumerate(rows)}
    Esym: dict[tuple[int, int], sp.Expr] = {}
    for i in cols:
        for kind, part in (("T", T[i]), ("U", U[i])):
            for m, c in part.items():
                if kind == "U" and m == const:
                    continue
                Esym[(ridx[(kind,) + m], i)] = c
    nb_t = len(tree_names)
    E = np.zeros((len(rows), nb_t))
    for (r, i), c in Esym.items():
        E[r, i] = float(c.xreplace(values))
    norms = np.linalg.norm(E, axis=0)
    big = float(norms.max(initial=0.0))
    live = [i for i in cols if norms[i] > tol * max(1.0, big)]
    friction = [i for i in range(nb_t) if i not in cols]
    indep: list[int] = []
    dep: list[int] = []
    Es = E / np.where(norms > 0, norms, 1.0)
    if live:
        diag = independent_columns(Es[:, live], tol)
        for k, i in enumerate(live):
            (indep if diag[k] > tol else dep).append(i)
    beta = np.linalg.lstsq(Es[:, indep], Es[:, dep], rcond=None)[0] if dep else np.zeros((len(indep), 0))
    # exact coefficients: E[:, S] beta = E[:, d] on |S| independent rows, checked on every row
    exact: dict[int, dict[int, sp.Expr]] = {}
    for k, d in enumerate(dep):
        S = [indep[t] for t in range(len(indep)) if abs(beta[t, k]) > 1e-9]
        if not S:
            raise ModelError(f"{robot.name}: tree base parameter {tree_names[d]} depends on nothing in the loop "
                             "grouping (tolerance problem)")
        sub = E[:, S]
        _, _, piv = _qr(sub.T, pivoting=True)
        rsel = sorted(piv[:len(S)])
        M = sp.Matrix([[Esym.get((r, i), sp.S(0)) for i in S] for r in rsel])
        rhs = sp.Matrix([Esym.get((r, d), sp.S(0)) for r in rsel])
        sol = [sp.factor(sp.cancel(x)) for x in M.LUsolve(rhs)]
        sol = [_tidy(x) for x in sol]
        used = {r for (r, i) in Esym if i in S or i == d}
        for r in used:
            res = sum((sol[t] * Esym.get((r, i), sp.S(0)) for t, i in enumerate(S)), sp.S(0)) - Esym.get((r, d), sp.S(0))
            res = sp.cancel(sp.together(res))
            if res != 0 and not (res.atoms(sp.Float) and abs(float(res.xreplace(values))) < 1e-9):
                raise ModelError(f"{robot.name}: the closed-form loop grouping of {tree_names[d]} does not hold on "
                                 f"every energy term (row {rows[r]})")
        num = np.array([float(x.xreplace(values)) for x in sol])
        if np.max(np.abs(num - beta[[indep.index(i) for i in S], k] * norms[d] / norms[S])) > 1e-6 * max(1.0, np.abs(num).max()):
            raise ModelError(f"{robot.name}: the exact loop grouping of {tree_names[d]} differs from the numeric one")
        exact[d] = dict(zip(S, sol))
    keep = sorted(indep + friction)
    names, groupings, rel = [], [], {}
    for i in keep:
        absorbed = [(d, exact[d][i]) for d in dep if i in exact[d]]
        name = tree_names[i]
        if absorbed and not name.endswith("R"):
            name += "R"
        names.append(name)
        expr = tree_relations[tree_names[i]] + sum((c * tree_relations[tree_names[d]] for d, c in absorbed), sp.S(0))
        rel[name] = sp.expand(expr)
        if absorbed:
            groupings.append(f"{name} = {tree_names[i]} " + " ".join(_term(c, tree_names[d]) for d, c in absorbed))
    if len(set(names)) != len(names):
        raise ModelError(f"{robot.name}: two closed-loop base parameters with the same name {names}")
    no_effect = tuple(tree_names[i] for i in cols if i not in live)
    return ClosedFormBase(closure=closure, names=tuple(names), keep=tuple(keep),
                          kept_standard=tuple(kept[i] for i in keep), relations=rel, groupings=tuple(groupings),
                          no_effect=no_effect, tree_names=tuple(tree_names), standard_names=std_names,
                          values=values, energies=en)


def closed_form_markdown(robot: RobotDescription, cf: ClosedFormBase | None, n_tree: int, *,
                         reason: str | None = None) -> str:
    """The closed-loop base parameters as a Markdown page (``closed_loop_base_parameters.md``); ``cf`` None:
    the closure is not linear, or (``reason``) the closed form could not be derived."""
    what = "loops" if robot.loops else "couplings"  # coupled (mimic) joints only: the same projection
    lines = [f"# Base parameters of the closed-loop robot `{robot.name}`" if robot.loops else
             f"# Base parameters of the robot with coupled joints `{robot.name}`", "",
             "Generated by symoro_gen (symoro_gen.closedloop.grouping); do not edit. The tree's relations are in "
             "`base_parameters.md`; here the groupings " + ("its loop(s) bring" if robot.loops else
                                                          "its coupled (mimic) joints bring") + " ([KB1995]).", ""]
    act = [r.j for r in robot.actuated]
    if cf is None and reason is not None:
        lines += [f"No closed form: {reason}", ""]
        return "\n".join(lines)
    if cf is None:
        lines += ["The loop closure is not linear in the joint variables (a general loop): the closed-form rules "
                  "for loops do not apply. The extra groupings are the numeric ones of "
                  "`load_model(...).base_parameters_text()` (numeric rank of the projected regressor).", ""]
        return "\n".join(lines)
    how = ("fitted on random closed states and checked to 1e-9 on others" if robot.loops else
           "the coupled (mimic) joints of the robot file, exact by construction")
    lines += [f"Loop closure, linear in the joint variables ({how}; actuated joints {act}):", "", "```",
              *cf.closure.lines(), "```", "",
              f"{len(cf.names)} base parameters (tree: {n_tree}; the {what} remove {n_tree - len(cf.names)}).", "",
              f"## Groupings brought by the {what} (tree base parameters on the right)", "", "```",
              *(cf.groupings or ["(none)"]), "```", ""]
    if cf.no_effect:
        lines += ["Without effect on the closed-loop model: " + ", ".join(cf.no_effect), ""]
    lines += ["## Closed-loop base parameters in the standard ones", "", "```"]
    lines += [f"{n} = {sp.sstr(cf.relations[n], order='none')}" for n in cf.names]
    lines += ["```", ""]
    return "\n".join(lines)


# ---- the closed-loop model in closed form (a linear closure) ----------------------------------
def closed_loop_regressor(cf: ClosedFormBase) -> tuple[sp.Matrix, _Energies]:
    """Base regressor ``Y_a`` (n_a x nb) of the closed robot, ``tau_a = Y_a chi_b``, as sympy expressions in the
    actuated state only: Lagrange's equations of the energy functions in the actuated variables,
    ``Y[:, b] = d/dt dT_b/dqd - dT_b/dq + dU_b/dq`` ([KD2002] ch. 9 and 10; valid because the closure is
    holonomic and ``q_a`` are independent coordinates), plus ``qd_j`` and ``sign(qd_j)`` for the friction
    columns. Symbols: ``_s<j>, _c<j>`` (sine and cosine of revolute actuated joints), ``_x<j>`` (the
    position), ``_v<j>`` (velocity), ``_a<j>`` (acceleration); constants substituted by their values."""
    en = cf.energies
    if en is None:
        raise ModelError("closed_loop_regressor: a ClosedFormBase built by closed_form_base is needed")
    act = cf.closure.actuated
    acc = {j: sp.Symbol(f"_a{j}") for j in act}
    # the constants as exact rationals of their decimal values (0.35 -> 7/20): polynomial arithmetic over QQ
    vals = {k: sp.Rational(repr(float(v))) for k, v in cf.values.items()}
    gens = [*en.gens, *acc.values()]
    ring, *rg = sp.ring(gens, sp.QQ)  # sparse polynomials: fast products and derivatives
    g = dict(zip(gens, rg))

    def P(e: sp.Expr):
        e = sp.expand(sp.sympify(e).xreplace(vals))
        if e == 0:
            return ring.zero
        # coefficients that are not rational (sqrt(3)/2 from a closure offset of pi/6, a float): their value as
        # the exact rational of the double (the generated code is numeric anyway)
        terms = sp.Poly(e, *gens).terms()
        return ring.from_dict({m: sp.Rational(c) if c.is_Rational else sp.Rational(repr(float(c))) for m, c in terms})

    si, ci = [gens.index(en.s[i]) for i in en.rev], [gens.index(en.c[i]) for i in en.rev]

    def dq_(f, j: int):
        out = f.diff(g[en.x[j]])
        if j in en.rev:
            out = out + g[en.c[j]] * f.diff(g[en.s[j]]) - g[en.s[j]] * f.diff(g[en.c[j]])
        return out

    Y = sp.zeros(len(act), len(cf.names))
    for b, k in enumerate(cf.kept_standard):
        if k.startswith("FV") or k.startswith("FS"):
            r = act.index(int(k[2:]))
            Y[r, b] = en.v[act[r]] if k.startswith("FV") else sp.sign(en.v[act[r]])
            continue
        T, U = P(en.T[k]), P(en.U[k])
        for r, j in enumerate(act):
            p = T.diff(g[en.v[j]])
            e = dq_(U, j) - dq_(T, j)
            for i in act:
                e = e + dq_(p, i) * g[en.v[i]] + p.diff(g[en.v[i]]) * g[acc[i]]
            Y[r, b] = _reduce(ring, e, si, ci).as_expr()
    return Y, en


def _reduce(ring, p, si: list[int], ci: list[int]):
    """Normal form of a polynomial in ``sin, cos``: every ``c^k`` (k >= 2) rewritten with ``c^2 = 1 - s^2``."""
    out: dict[tuple[int, ...], object] = {}
    todo = list(p.terms())
    while todo:
        m, coef = todo.pop()
        hi = next((k for k in range(len(ci)) if m[ci[k]] >= 2), None)
        if hi is None:
            out[m] = out.get(m, 0) + coef
            continue
        m1 = list(m)
        m1[ci[hi]] -= 2
        todo.append((tuple(m1), coef))
        m1[si[hi]] += 2
        todo.append((tuple(m1), -coef))
    return ring.from_dict({k: v for k, v in out.items() if v != 0})


def closed_loop_kernel_source(robot: RobotDescription, cf: ClosedFormBase) -> tuple[str, int]:
    """Python/NumPy source of the closed-loop base regressor in the actuated state (``_closed_loop.py`` of
    the generated package) and its operation count (after common subexpressions)."""
    Y, en = closed_loop_regressor(cf)
    act = cf.closure.actuated
    entries = [(r, b, Y[r, b]) for r in range(Y.rows) for b in range(Y.cols)
               if Y[r, b] != 0 and not isinstance(Y[r, b], sp.sign)]
    signs = [(r, b, Y[r, b].args[0]) for r in range(Y.rows) for b in range(Y.cols) if isinstance(Y[r, b], sp.sign)]
    subs, red = sp.cse([e for _, _, e in entries], symbols=sp.numbered_symbols("t"), order="none")
    ops = sum(sp.count_ops(e) for _, e in subs) + sum(sp.count_ops(e) for e in red)
    printer = PythonCodePrinter({"fully_qualified_modules": False})

    def pr(e: sp.Expr) -> str:
        return printer.doprint(e).replace("_", "")

    body = [f"    {i} = q[:, {k}]" for k, i in ((k, f"x{j}") for k, j in enumerate(act))]
    body += [f"    s{j}, c{j} = np.sin(q[:, {k}]), np.cos(q[:, {k}])" for k, j in enumerate(act) if j in en.rev]
    body += [f"    v{j}, a{j} = dq[:, {k}], ddq[:, {k}]" for k, j in enumerate(act)]
    body += [f"    {t!s} = {pr(e)}" for t, e in subs]
    body += [f"    out[:, {r}, {b}] = {pr(e)}" for (r, b, _), e in zip(entries, red)]
    body += [f"    out[:, {r}, {b}] = np.sign({pr(v)})" for r, b, v in signs]
    src = f'''# Generated by symoro_gen (symoro_gen.closedloop.grouping); do not edit.
# Robot file: {Path(robot.file).name} sha256={robot.file_hash}
"""Closed-loop base regressor of `{robot.name}` in the actuated joints only (linear loop closure
{"; ".join(cf.closure.lines())}): Lagrange's equations of the energy functions in the actuated variables,
constants substituted. tau_a = regressor(q, dq, ddq) @ chi_b with chi_b the closed-loop base parameters of
closed_loop_base_parameters.md ({len(cf.names)}); {ops} operations after common subexpressions."""
import numpy as np

ROBOT = {robot.name!r}
ACTUATED_JOINTS = {tuple(act)!r}
BASE_NAMES = {tuple(cf.names)!r}
OPERATIONS = {ops}


def regressor(q, dq, ddq):
    """(N, {len(act)}, {len(cf.names)}) base regressor for actuated q, dq, ddq of shape (N, {len(act)})."""
    q, dq, ddq = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, dq, ddq))
    out = np.zeros((q.shape[0], {len(act)}, {len(cf.names)}))
''' + "\n".join(body) + "\n    return out\n"
    return src, ops
