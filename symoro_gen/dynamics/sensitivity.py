"""Derivative of the standard regressor with respect to the geometric constants of the MDH table.

The torque is ``tau = Y_std(q, dq, ddq; g) chi_std`` ([KD2002] ch. 9); its sensitivity to a geometric
constant ``g_k`` at the current estimate ``chi_hat`` is the column ``(dY_std/dg_k)(q, dq, ddq; g_0) chi_hat``
(the Gauss-Newton step of a geometric calibration through the dynamic model). This module builds
``dY_std/dg_k`` symbolically, at the nominal geometry ``g_0``:

1. every frame ``j`` of the MDH table [KK1986] gets the perturbations ``d_j + e``, ``r_j + e``,
   ``alpha_j + e``, ``theta_j + e`` (one symbol ``e`` per constant); for a revolute joint the
   ``theta`` perturbation is its joint zero, for a prismatic joint the ``r`` one;
2. the customized Newton-Euler recursion of :mod:`.newton_euler` is built on that table (each
   intermediate variable named, [KK1987]);
3. the graph is differentiated forward mode (each intermediate variable ``x = f(y_1, ...)`` gets the
   tangent ``dx/de = sum_i (df/dy_i) dy_i/de`` for every ``e`` it depends on), all perturbations set to
   zero and the geometry to its nominal values after the differentiation, so that structural zeros of the
   nominal robot prune the tangents; a constant whose derivative is identically zero is dropped.

The graph that results is printed like the regressors (:mod:`symoro_gen.emit.geometry`; without the
rotation-pair and shared-product rewrites of :mod:`symoro_gen.emit.optimize`, which would double its
generation time).
"""
from __future__ import annotations

from dataclasses import dataclass
from dataclasses import replace as dc_replace

import sympy as sp
from sympy.core.add import _addsort
from sympy.core.mul import _mulsort

from ..description.model import RobotDescription
from .graph import ExprGraph, is_trivial
from .newton_euler import build_regressor

#: the MDH fields differentiated, per frame, in this order
GEOMETRY_FIELDS = ("d", "r", "alpha", "theta")


@dataclass(frozen=True)
class GeometrySensitivity:
    """``dY_std/dg`` of one robot as a graph.

    ``graph.outputs`` maps ``(i, (standard name, constant name))`` to the derivative of the entry on
    joint row ``i`` of the standard column with respect to the constant; ``names`` are the constants kept
    (``<field><frame>``, e.g. ``d3``, ``alpha2``, ``theta2``), ``dropped`` those whose derivative is
    identically zero, ``frames`` maps a kept name to ``(frame j, field)``.
    """

    graph: ExprGraph
    names: tuple[str, ...]
    dropped: tuple[str, ...]
    frames: dict[str, tuple[int, str]]


def constant_name(frame: int, fld: str) -> str:
    """``d3``, ``r4``, ``alpha2``, ``theta2``: the name of the MDH constant ``fld`` of frame ``frame``."""
    return f"{fld}{frame}"


def perturbation_symbol(frame: int, fld: str) -> sp.Symbol:
    """The symbol added to field ``fld`` of frame ``frame`` (set to 0 after differentiation)."""
    return sp.Symbol(f"eps_{fld}{frame}", real=True)


def perturbed_symbolic(robot: RobotDescription) -> tuple[RobotDescription, dict[sp.Symbol, tuple[int, str]]]:
    """``robot`` with one perturbation symbol added to every field of :data:`GEOMETRY_FIELDS` of every frame."""
    rows, eps = [], {}
    for row in robot.rows:
        upd = {}
        for fld in GEOMETRY_FIELDS:
            e = perturbation_symbol(row.j, fld)
            eps[e] = (row.j, fld)
            upd[fld] = sp.sympify(getattr(row, fld)) + e
        rows.append(dc_replace(row, **upd))
    return dc_replace(robot, rows=tuple(rows)), eps


def _split(v: sp.Expr, named: dict) -> tuple[float, tuple]:
    """A nominal value as ``(numeric coefficient, non-numeric factors)``; an expression already named in
    the graph (e.g. ``cos(q2)``) becomes its symbol."""
    if v.is_Number:
        return float(v), ()
    if v.is_Symbol:
        return 1.0, (v,)
    hit = named.get(v)
    if hit is not None:
        return 1.0, (hit,)
    if v.is_Mul:
        c, rest = v.as_coeff_Mul()
        if c.is_Number:
            return float(c), tuple(sp.Mul.make_args(rest))
    return 1.0, (v,)


class _Tangents:
    """Forward-mode state: nominal values and tangents of the graph's symbols."""

    def __init__(self, nominal: dict, tang: dict) -> None:
        self.nominal = nominal
        self.tang = tang
        self.named: dict = {}  # nominal value -> the def symbol holding it

    def value(self, e: sp.Expr) -> tuple[float, tuple]:
        v = self.nominal.get(e, e) if e.is_Symbol else e.xreplace(self.nominal)
        return _split(v, self.named)

    def dual(self, e: sp.Expr, acc: dict, coef: float, factors: tuple) -> None:
        """Add ``coef * prod(factors) * d e / d g`` to ``acc[g]`` (terms ``(coefficient, factors)``) for
        every perturbation ``g`` (product, chain and power rules, each factor at the nominal point)."""
        if e.is_Symbol:
            for g, (c, f) in self.tang.get(e, {}).items():
                acc.setdefault(g, []).append((coef * c, factors + f))
        elif e.is_Add:
            for a in e.args:
                self.dual(a, acc, coef, factors)
        elif e.is_Mul:
            args = e.args
            vals = [self.value(a) for a in args]
            for k, a in enumerate(args):
                if a.is_number:
                    continue
                c, f = coef, factors
                for v in vals[:k] + vals[k + 1:]:
                    c, f = c * v[0], f + v[1]
                if c != 0.0:
                    self.dual(a, acc, c, f)
        elif e.is_Pow and e.exp.is_Integer and int(e.exp) > 1:
            n = int(e.exp)
            bc, bf = self.value(e.base)
            if bc != 0.0:
                self.dual(e.base, acc, coef * n * bc ** (n - 1), factors + bf * (n - 1))
        elif isinstance(e, (sp.sin, sp.cos)):
            a = e.args[0]
            v = a.xreplace(self.nominal)
            d = sp.cos(v) if isinstance(e, sp.sin) else -sp.sin(v)
            c, f = _split(d, self.named)
            if c != 0.0:
                self.dual(a, acc, coef * c, factors + f)
        elif e.is_number or isinstance(e, sp.sign):
            return
        else:  # pragma: no cover - the recursion builds no other kind of expression
            raise ValueError(f"cannot differentiate {e}")

    def tangent(self, e: sp.Expr) -> dict:
        """``{perturbation: (d e / d perturbation)}`` at the nominal point, non-zero entries only, each as
        an expression."""
        acc: dict = {}
        self.dual(e, acc, 1.0, ())
        out = {}
        for g in sorted(acc, key=lambda s: s.name):
            t = _sum(acc[g])
            if t != 0:
                out[g] = t
        return out


def _key(f: sp.Expr) -> str:
    return f.name if f.is_Symbol else sp.srepr(f)


def _number(c: float) -> sp.Expr:
    return sp.Integer(int(c)) if float(c).is_integer() else sp.Float(c)


def _sum(terms: list) -> sp.Expr:
    """``sum(coefficient * prod(factors))`` with like terms combined; the products of distinct symbols are
    built directly in sympy's canonical order (no flatten: a new Float's facts are costly, see
    :mod:`.newton_euler`)."""
    comb: dict = {}
    for c, f in terms:
        k = tuple(sorted(f, key=_key))
        comb[k] = comb.get(k, 0.0) + c
    out = []
    for k, c in comb.items():
        if c == 0.0:
            continue
        if k and all(x.is_Symbol for x in k) and len(set(k)) == len(k):
            syms = list(k)
            _mulsort(syms)
            if c == 1.0:
                out.append(syms[0] if len(syms) == 1 else sp.Mul._from_args(syms))
            else:
                out.append(sp.Mul._from_args([_number(c), *syms]))
        else:
            out.append(sp.Mul(_number(c), *k))
    if len(out) > 1 and all(not t.is_Number and not t.is_Add for t in out):
        _addsort(out)
        return sp.Add._from_args(out)
    return sp.Add(*out)


def forward_tangents(graph: ExprGraph, eps: dict[sp.Symbol, str], subs: dict) -> tuple[ExprGraph, set]:
    """Forward-mode derivative of every output of ``graph`` with respect to each perturbation of ``eps``
    (symbol -> constant name), evaluated with the perturbations at zero and ``subs`` (the geometry).

    Returns the graph of outputs ``(i, (col, name))`` and the set of constant names with a non-zero output.
    """
    nominal: dict = {e: sp.S.Zero for e in eps}
    nominal.update({k: sp.sympify(v) for k, v in subs.items()})
    st = _Tangents(nominal, {e: {e: (1.0, ())} for e in eps})
    for s, e in graph.defs:  # the derivative of a named sine is the named cosine, defined later
        if isinstance(e, (sp.sin, sp.cos)):
            v = e.xreplace(nominal)
            if not v.is_number:
                st.named.setdefault(v, s)
    defs: list = []
    for s, e in graph.defs:
        t = st.tangent(e)
        val = e.xreplace(nominal)
        if is_trivial(val) or val.is_number:
            nominal[s] = val  # inlined: structural zeros and constants of the nominal robot
        else:
            defs.append((s, val))
            st.named.setdefault(val, s)
        if not t:
            continue
        st.tang[s] = {}
        for g, te in t.items():
            if te.is_number:
                st.tang[s][g] = (float(te), ())
            elif te.is_Symbol:
                st.tang[s][g] = (1.0, (te,))
            else:
                ts = sp.Symbol(f"{s.name}_{eps[g]}", real=True)
                defs.append((ts, te))
                st.tang[s][g] = (1.0, (ts,))
    outputs, used = {}, set()
    for (i, col), e in graph.outputs.items():
        for g, te in st.tangent(e).items():
            outputs[(i, (col, eps[g]))] = te
            used.add(eps[g])
    return ExprGraph(graph.inputs, tuple(defs), outputs).pruned(), used


def geometry_sensitivity(robot: RobotDescription) -> GeometrySensitivity:
    """``dY_std/dg`` of ``robot`` at its nominal geometry (see the module docstring)."""
    pert, eps = perturbed_symbolic(robot)
    reg = build_regressor(pert, columns=set(robot.standard_names))
    names = {e: constant_name(*jf) for e, jf in eps.items()}
    graph, used = forward_tangents(reg.graph, names, robot.geometry_subs())
    order = [constant_name(j, f) for j, f in eps.values()]
    kept = tuple(n for n in order if n in used)
    dropped = tuple(n for n in order if n not in used)
    inputs = robot.q + robot.dq + robot.ddq
    graph = ExprGraph(inputs, graph.defs, graph.outputs)
    return GeometrySensitivity(graph, kept, dropped, {constant_name(j, f): (j, f) for j, f in eps.values()
                                                       if constant_name(j, f) in used})
