"""Base parameters by the closed-form rules of Gautier & Khalil, completed by an exact dependency sweep.

Rules, applied from the terminal links towards the base (geometry kept symbolic), after
Gautier & Khalil (1990), "Direct calculation of minimum set of inertial parameters of serial
robots", IEEE Trans. Robotics and Automation 6(3), and Khalil & Dombre (2002), ch. 12:

* revolute joint j (ant a): YYj, MZj, Mj are regrouped. Link j keeps XXjR = XXj - YYj;
  the rotationally symmetric remainder (inertia diag(YYj, YYj, 0), first moment
  (0, 0, MZj), mass Mj) moves rigidly onto link a through a_T_j (theta_j = 0): its
  inertia about O_a, first moment and mass are added to link a's parameters.
* prismatic joint j: the inertia matrix of link j (XXj..ZZj) moves onto link a,
  rotated by a_R_j (rotation inertia only; first moments and mass stay).
* contributions that reach the base (a = 0) have no effect and vanish.
* parameters whose regressor column is identically zero (links near the base whose
  motion is restricted) have no effect and are eliminated.
* trees ([KK1987]; Khalil & Bennis 1995, [KB1995]): the same rules with ``a = ant(j)`` in place of
  ``j - 1``; a branch's parameters regroup onto its own antecedent (never onto a sibling branch).
  Frames are numbered so that ``ant(j) < j``, so going from the highest frame down visits every
  frame before its antecedent (tests/oracles/test_trees.py).

Whatever dependency remains after these rules (special cases near the base, drive-chain
terms) is found by a seeded numerical sweep over the columns, then written exactly:

1. **Which** columns depend on which: the columns of the remaining parameters are evaluated
   on random states (:mod:`symoro_gen.dynamics.evaluate`, geometry and gravity by value) and
   swept in a fixed *keep order*; a column in the span of the columns kept before it is
   eliminated and regrouped into them.
2. **Keep order** (what is eliminated when a dependency involves several kinds): the
   inertial parameters first, in the standard order (so, as in the closed-form rules, the
   parameter of the link nearer the terminal is the one regrouped onto the link nearer the
   base: MX2R = MX2 + MX3), then the drive terms IA, then FV and FS, then OFF. Hence a
   dependency that involves a drive term eliminates the drive term, in the order OFF first,
   then FS/FV, then IA:

   * OFF (a constant torque) is the least physical column: it is collinear with anything
     constant, e.g. the gravity load of a link on a vertical prismatic joint, and the
     papers model it as a bias, not as a dynamic parameter;
   * FS/FV are friction laws of the drive chain, identified as such, but not properties of
     the rigid body;
   * IA (rotor inertia) is an inertia about the joint axis; when it is collinear with a link
     inertia the papers write it into the link's parameter (ZZ1R = ZZ1 + IA1, Khalil &
     Dombre 2002, sec. 12.5) rather than the converse.

   No drive term is therefore kept while an inertial parameter of the same dependency is
   eliminated.
3. **Exact coefficients**: for each dependency found, the columns involved are evaluated
   exactly (:data:`~symoro_gen.dynamics.evaluate.EXACT`) with the geometric constants and
   the gravity components (``G1, G2, G3``, SYMORO's names) kept as symbols, at random
   rational states (sin and cos of each joint angle rational), and the small linear system
   is solved with sympy. The solution is verified exactly on every equation of every state
   and numerically on the random samples. Relations therefore keep geometry and gravity
   symbolic (``M3R = M3 + M4 - OFF3/G3``). A dependency whose exact solution does not verify
   (e.g. one that holds only for the particular numeric values of the geometry) keeps
   numeric coefficients and is listed in :attr:`BaseParameterMap.numeric`.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from fractions import Fraction
from functools import cmp_to_key
from typing import Any, ClassVar

import numpy as np
import sympy as sp
from mpmath.libmp import bitcount as _bitcount
from mpmath.libmp import normalize as _normalize
from mpmath.libmp import round_nearest as _round_nearest
from mpmath.libmp.backend import MPZ as _MPZ
from sympy.core.basic import ordering_of_classes
from sympy.core.evalf import LG10 as _LG10
from sympy.core.evalf import evalf as _sympy_evalf

from ..description.mdh import constant_rotation, position, rot_z
from ..description.model import PRISMATIC, REVOLUTE, RobotDescription
from ..dynamics.evaluate import EXACT, Arithmetic, evaluate_columns, evaluate_graph
from ..dynamics.floating import BASE_DDQ_NAMES, BASE_DQ_NAMES, BASE_Q_NAMES
from ..dynamics.graph import ExprGraph
from ..dynamics.newton_euler import SymbolicRegressor, build_regressor, gravity_symbols
from ..params import INERTIAL_KINDS, param_name, split_name

_J_KINDS = INERTIAL_KINDS[:6]
_J_INDEX = {"XX": (0, 0), "XY": (0, 1), "XZ": (0, 2), "YY": (1, 1), "YZ": (1, 2), "ZZ": (2, 2)}


@dataclass(frozen=True)
class BaseParameterMap:
    """How the standard parameters regroup into the base parameters.

    Attributes
    ----------
    standard_names : tuple of str
    base_names : tuple of str
        SYMORO names; regrouped ones carry ``R`` (``XX2R``).
    kept : tuple of str
        The standard parameter whose regressor column each base parameter uses.
    relations : dict
        ``base name -> sympy expression`` in the standard-parameter symbols, linear in them, with
        coefficients in the geometric constants and the gravity symbols (``G3``) kept symbolic.
    eliminated : tuple of str
        Standard parameters with no column of their own (regrouped or without effect).
    no_effect : tuple of str
        Standard parameters (or groups) without any effect on the model.
    numeric : tuple of str
        Base parameters whose relation has numeric coefficients (a dependency found by the sweep
        without an exact symbolic form); empty for the usual robots.
    geometry : dict
        Geometric constant symbol -> value.
    gravity : dict
        Gravity component symbol (``G1, G2, G3``) -> value, for the non-zero components.
    swept : tuple of str
        Base parameters whose relation got terms from the dependency sweep (not the closed-form rules).
    """

    standard_names: tuple
    base_names: tuple
    kept: tuple
    relations: dict
    eliminated: tuple
    no_effect: tuple
    numeric: tuple = ()
    geometry: dict = field(default_factory=dict)
    gravity: dict = field(default_factory=dict)
    swept: tuple = ()

    def matrix_symbolic(self) -> sp.Matrix:
        """K (n_base x n_std) with chi_base = K chi_std, entries in the geometry and gravity symbols."""
        idx = {n: i for i, n in enumerate(self.standard_names)}
        K = sp.zeros(len(self.base_names), len(self.standard_names))
        for b, name in enumerate(self.base_names):
            e = sp.expand(self.relations[name])
            for s in e.free_symbols:
                if s.name in idx:
                    K[b, idx[s.name]] = e.coeff(s)
        return K

    def matrix(self, subs: dict | None = None) -> np.ndarray:
        """K (n_base x n_std) with chi_base = K chi_std, geometry substituted by ``subs``.

        The gravity symbols are always substituted by their values (``self.gravity``).
        """
        subs = {**self.gravity, **(self.geometry if subs is None else subs)}
        idx = {n: i for i, n in enumerate(self.standard_names)}
        K = np.zeros((len(self.base_names), len(self.standard_names)))
        to_float = _ProductFloat()
        plain: dict = {}  # per distinct factor: _plain_factor, and whether it has free symbols
        free: dict = {}
        for b, name in enumerate(self.base_names):
            e = self.relations[name].xreplace(subs)
            if not _is_expanded(e, plain):  # expand is the cost for long relations: only when it changes something
                e = sp.expand(e)
            fs = _LazyFreeSymbols(e)
            for s, c in e.as_coefficients_dict().items():
                if s == 1:
                    raise ValueError(f"relation of {name} has a constant term")
                # exact numeric factors such as cos(1/10) stay in the "symbol" part: split them off
                if s.is_Symbol:  # a parameter alone (a term of e: one of its free symbols)
                    num, syms = sp.S.One, s
                else:
                    num, syms = _split_constant(s, fs, free)
                K[b, idx[syms.name]] += to_float(c, num)
        return K


class _ProductFloat:
    """``float(c * num)`` for a rational ``c`` and a product ``num`` of sin/cos (powers) of numbers, bit for
    bit, without building ``c * num``: the steps of sympy's ``Expr.__float__`` -> ``evalf`` -> ``evalf_mul``
    (each factor evaluated at the working precision ``53 + 4 + len(args) + 5``, mantissas multiplied, rounded
    to 57 then to 53 bits) with each factor's evaluation kept across the terms of a K matrix (the same
    ``sin(457/500)**2`` recurs in hundreds of terms). Any other shape takes sympy's own path."""

    _OPTIONS: ClassVar[dict[str, Any]] = {"maxprec": max(53, int(100 * _LG10)), "chop": False, "strict": False, "verbose": False}

    def __init__(self) -> None:
        self._memo: dict[tuple[sp.Expr, int], Any] = {}
        self._is_trig: dict[sp.Expr, bool] = {}  # _trig per distinct factor

    def _ev(self, x: sp.Expr, prec: int):
        key = (x, prec)
        got = self._memo.get(key)
        if got is None:
            got = self._memo[key] = _sympy_evalf(x, prec, dict(self._OPTIONS))
        return got

    @staticmethod
    def _trig(f: sp.Expr) -> bool:
        if f.is_Pow:
            if not (f.exp.is_Integer and f.exp > 0):
                return False
            f = f.base
        return isinstance(f, (sp.sin, sp.cos)) and f.args[0].is_Rational

    def __call__(self, c: sp.Expr, num: sp.Expr) -> float:
        factors = sp.Mul.make_args(num)
        is_trig = self._is_trig
        for f in factors:
            if f not in is_trig:
                is_trig[f] = self._trig(f)
        if not (c.is_Rational and c != 0 and num is not sp.S.One and all(is_trig[f] for f in factors)):
            return float(c * num)
        args = factors if c == 1 else (c,) + factors  # the args of the Mul c * num (number first)
        prec = 53 + 4  # Expr.evalf(15 digits): evalf at prec + 4, then a Float of 53 bits
        if len(args) == 1:
            re, im, acc, _ = self._ev(args[0], prec)
        else:  # evalf_mul, real factors
            wp = prec + len(args) + 5
            man, exp, bc = _MPZ(1), 0, 1
            direction, acc = 0, prec
            for x in args:
                re, im, re_acc, _ = self._ev(x, wp)
                if im or not re:
                    return float(c * num)
                s_, m_, e_, b_ = re
                direction += 2 * s_
                man *= m_
                exp += e_
                bc += b_
                while bc > 3 * wp:
                    man >>= wp
                    exp += wp
                    bc -= wp
                acc = min(acc, re_acc)
            re, im = _normalize((direction & 2) >> 1, man, exp, _bitcount(man), prec, _round_nearest), None
        if im or not re:
            return float(c * num)
        return float(sp.Float._new(re, max(min(53, acc), 1)))


def _monomial(f: sp.Expr) -> bool:
    """A product of atoms and integer powers of atoms (``sp.expand`` leaves it unchanged)."""
    return all(x.is_Atom or (x.is_Pow and x.exp.is_Integer and x.base.is_Atom) for x in sp.Mul.make_args(f))


def _plain_factor(f: sp.Expr) -> bool:
    """An atom, a function of monomials (``cos(pi/5)``), or an integer power of one of these."""
    if f.is_Pow and f.exp.is_Integer:
        f = f.base
    return bool(f.is_Atom or (isinstance(f, sp.Function) and all(_monomial(a) for a in f.args)))


def _is_expanded(e: sp.Expr, memo: dict | None = None) -> bool:
    """True when ``sp.expand(e)`` is ``e``: a sum of products of atoms, functions of monomials
    (``cos(pi/5)``) and integer powers of these; a cheap test that saves expanding long relations again.
    ``memo``: :func:`_plain_factor` per distinct factor, kept across calls (factors recur across terms)."""
    if memo is None:
        memo = {}
    for t in sp.Add.make_args(e):
        for f in sp.Mul.make_args(t):
            ok = memo.get(f)
            if ok is None:
                ok = memo[f] = _plain_factor(f)
            if not ok:
                return False
    return True


def _split_constant(term: sp.Expr, fs: set | _LazyFreeSymbols, memo: dict | None = None
                    ) -> tuple[sp.Expr, sp.Expr]:
    """``term.as_independent(*fs, as_Add=False)`` for a term with one symbolic factor, without building
    the set of the relation's free symbols once per term (what ``as_independent`` does with them).
    ``memo``: whether a factor has free symbols, per distinct factor, kept across calls."""
    if term.is_Symbol and term in fs:  # what as_independent gives for a parameter alone
        return sp.S.One, term
    if term.is_Mul:
        if memo is None:
            memo = {}
        has = []
        for f in term.args:
            h = memo.get(f)
            if h is None:
                h = memo[f] = bool(f.free_symbols)
            has.append(h)
        if sum(has) == 1:
            return sp.Mul(*[f for f, h in zip(term.args, has) if not h]), term.args[has.index(True)]
    return term.as_independent(*fs, as_Add=False)


class _LazyFreeSymbols:
    """``e.free_symbols``, computed on first use (:func:`_split_constant` rarely needs it; a walk of a
    long relation)."""

    def __init__(self, e: sp.Expr) -> None:
        self._e = e
        self._fs: set | None = None

    def _get(self) -> set:
        if self._fs is None:
            self._fs = self._e.free_symbols
        return self._fs

    def __iter__(self):
        return iter(self._get())

    def __contains__(self, x) -> bool:
        return x in self._get()


def _sym(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


def _regroup_closed_form(reg: SymbolicRegressor, alg: _Algebra | None = None):
    """The closed-form rules (module docstring) on the standard parameters of ``reg``.

    ``alg``: the arithmetic of the relations (:class:`_ExprAlgebra`, sympy expressions, or
    :class:`_PolyAlgebra`, exact sparse polynomials; the same relations). Returns ``(cur, eliminated,
    no_effect)`` with ``cur``: kept standard name -> its relation in ``alg``'s representation.
    """
    alg = _ExprAlgebra() if alg is None else alg
    robot = reg.robot
    cur: dict[str, Any] = {n: alg.symbol(n) for n in reg.standard_names}
    eliminated: list[str] = []
    no_effect: list[str] = []

    def add_J(a, dJ):
        for k, (r, c) in _J_INDEX.items():
            cur[param_name(k, a)] = alg.add(cur[param_name(k, a)], dJ[r][c])

    for row in reversed(robot.joints):
        row = _exact_row(row)
        j, a = row.j, row.ant
        R0 = constant_rotation(row)
        if row.sigma == REVOLUTE:
            YY, MZ, M = cur[f"YY{j}"], cur[f"MZ{j}"], cur[f"M{j}"]
            cur[f"XX{j}"] = alg.sub(cur[f"XX{j}"], YY)
            for k in ("YY", "MZ", "M"):
                eliminated.append(f"{k}{j}")
                del cur[f"{k}{j}"]
            if a == 0 and not robot.floating:  # a floating base link keeps what regroups onto it
                no_effect.append(f"YY{j}, MZ{j}, M{j} (regrouped onto the base)")
                continue
            P = position(row)

            def moved(YY, MZ, M, R0=R0, P=P):
                Js = sp.diag(YY, YY, 0)
                s = R0 * sp.Matrix([0, 0, MZ])
                dJ = R0 * Js * R0.T + M * ((P.T * P)[0] * sp.eye(3) - P * P.T)
                dJ += 2 * (P.T * s)[0] * sp.eye(3) - P * s.T - s * P.T
                return dJ.row_join(s + M * P)

            dJMS = alg.linear(moved, (YY, MZ, M))
            add_J(a, dJMS)
            for i, k in enumerate(("MX", "MY", "MZ")):
                cur[f"{k}{a}"] = alg.add(cur[f"{k}{a}"], dJMS[i][3])
            cur[f"M{a}"] = alg.add(cur[f"M{a}"], M)
        elif row.sigma == PRISMATIC:
            Jj = [[cur[param_name(_kind_at(r, c), j)] for c in range(3)] for r in range(3)]
            for k in _J_KINDS:
                eliminated.append(f"{k}{j}")
                del cur[f"{k}{j}"]
            if a == 0 and not robot.floating:
                no_effect.append(f"XX{j}..ZZ{j} (rotation inertia of a link moving in translation from the base)")
                continue
            Rj = constant_rotation(row) * rot_z(row.theta)
            add_J(a, alg.linear(lambda *J, Rj=Rj: Rj * _sym_matrix(J) * Rj.T,
                                tuple(Jj[r][c] for r, c in _J_INDEX.values())))
    return cur, eliminated, no_effect


class _NotPolynomial(Exception):
    """A coefficient outside what :class:`_PolyAlgebra` represents (the sympy path is used instead)."""


class _ExprAlgebra:
    """Relations as sympy expressions, expanded once at the end (the reference arithmetic)."""

    def symbol(self, name: str) -> sp.Expr:
        return _sym(name)

    def add(self, x, y):
        return x + y

    def sub(self, x, y):
        return x - y

    def add_scaled(self, x, coef: sp.Expr, y):
        """``x + coef * y``."""
        return x + coef * y

    def linear(self, build, values: tuple) -> list[list[Any]]:
        m = _expand_linear(build, values)
        return [[m[r, c] for c in range(m.cols)] for r in range(m.rows)]

    def is_symbol(self, x, name: str) -> bool:
        return bool(sp.expand(x) == _sym(name))

    def to_expr(self, x) -> sp.Expr:
        return sp.expand(x)


_Mono = tuple  # ((atom index, exponent), ...) sorted by index, exponents non-zero


class _PolyAlgebra:
    """Relations as exact sparse polynomials: ``{(standard name, monomial): Fraction}``.

    A relation is linear in the standard parameters with coefficients that are polynomials (Laurent, for
    ``1/G3``) with rational coefficients in *atoms*: the geometric and gravity symbols and ``sin``/``cos`` of
    rational or symbolic angles ([GK1990] rules applied to the MDH constants of each row). Products are
    computed on these dictionaries, and the sympy expression of each relation is built once, term by term:
    the same expanded sum as ``sympy.expand`` of the nested sums (sympy's canonical form of the same terms),
    without expanding products of long sums symbol by symbol. A coefficient outside this form (a float, an
    irrational number such as ``sqrt(3)``, a sum in a denominator) raises :class:`_NotPolynomial`.
    """

    def __init__(self) -> None:
        self.atoms: list[sp.Expr] = []
        self.index: dict[sp.Expr, int] = {}
        self._mono: dict[tuple[_Mono, _Mono], _Mono] = {}
        self._pow: dict[tuple[int, int], sp.Expr] = {}

    def symbol(self, name: str) -> dict:
        return {(name, ()): Fraction(1)}

    @staticmethod
    def add(x: dict, y: dict) -> dict:
        out = dict(x)
        for k, c in y.items():
            v = out.get(k, 0) + c
            if v:
                out[k] = v
            else:
                out.pop(k, None)
        return out

    def sub(self, x: dict, y: dict) -> dict:
        return self.add(x, {k: -c for k, c in y.items()})

    def _mono_mul(self, a: _Mono, b: _Mono) -> _Mono:
        if not a:
            return b
        if not b:
            return a
        key = (a, b)
        got = self._mono.get(key)
        if got is None:
            d = dict(a)
            for i, e in b:
                d[i] = d.get(i, 0) + e
            got = self._mono[key] = tuple(sorted((i, e) for i, e in d.items() if e))
        return got

    def _atom(self, b: sp.Expr) -> int:
        i = self.index.get(b)
        if i is None:
            ok = b.is_Symbol or (isinstance(b, (sp.sin, sp.cos)) and all(x.is_Rational or x.is_Symbol for x in b.args))
            if not ok:
                raise _NotPolynomial(str(b))
            i = self.index[b] = len(self.atoms)
            self.atoms.append(b)
        return i

    def poly(self, e: sp.Expr, placeholders: dict | None = None) -> dict:
        """``{(placeholder index or None, monomial): Fraction}`` of the expanded constant expression ``e``."""
        out: dict = {}
        for t in sp.Add.make_args(sp.expand(e)):
            c, rest = t.as_coeff_Mul()
            if not c.is_Rational:
                raise _NotPolynomial(str(t))
            if c == 0:
                continue
            ph = None
            mono: dict[int, int] = {}
            for f in sp.Mul.make_args(rest):
                if f is sp.S.One:
                    continue
                if placeholders is not None and f in placeholders:
                    if ph is not None:
                        raise _NotPolynomial(str(t))
                    ph = placeholders[f]
                    continue
                b, x = f.as_base_exp()
                if not x.is_Integer:
                    raise _NotPolynomial(str(t))
                i = self._atom(b)
                mono[i] = mono.get(i, 0) + int(x)
            key = (ph, tuple(sorted((i, x) for i, x in mono.items() if x)))
            v = out.get(key, 0) + Fraction(c.p, c.q)
            if v:
                out[key] = v
            else:
                out.pop(key, None)
        return out

    def _scaled(self, coef: dict, y: dict, out: dict) -> None:
        """``out += coef * y`` (``coef``: ``{monomial: Fraction}``)."""
        mul = self._mono_mul
        for m1, c1 in coef.items():
            for (p, m2), c2 in y.items():
                k = (p, mul(m1, m2))
                v = out.get(k, 0) + c1 * c2
                if v:
                    out[k] = v
                else:
                    out.pop(k, None)

    def add_scaled(self, x: dict, coef: sp.Expr, y: dict) -> dict:
        out = dict(x)
        self._scaled({m: c for (_, m), c in self.poly(coef).items()}, y, out)
        return out

    def linear(self, build, values: tuple) -> list[list[dict]]:
        ph = sp.symbols(f"_ph0:{len(values)}", cls=sp.Dummy)
        where = {s: i for i, s in enumerate(ph)}
        m = build(*ph)
        rows = []
        for r in range(m.rows):
            row = []
            for c in range(m.cols):
                out: dict = {}
                per: dict[int, dict] = {}
                for (i, mono), q in self.poly(m[r, c], where).items():
                    if i is None:
                        raise _NotPolynomial(str(m[r, c]))  # a constant term: not linear in the values
                    per.setdefault(i, {})[mono] = q
                for i, coef in per.items():
                    self._scaled(coef, values[i], out)
                row.append(out)
            rows.append(row)
        return rows

    def is_symbol(self, x: dict, name: str) -> bool:
        return x == {(name, ()): 1}

    def _power(self, i: int, e: int) -> sp.Expr:
        got = self._pow.get((i, e))
        if got is None:
            got = self._pow[(i, e)] = self.atoms[i] ** e
        return got

    def to_expr(self, x: dict) -> sp.Expr:
        """The sympy sum of the terms of ``x``: ``Add(*[Mul(c, p, *powers)])``, built as ``Mul.flatten`` and
        ``Add.flatten`` build it (:func:`_canonical_sum`)."""
        terms = []
        for (p, mono), c in x.items():
            f = [self._power(i, e) for i, e in mono]
            terms.append((sp.Rational(c.numerator, c.denominator), [_sym(p), *f]))
        return _canonical_sum(terms)


def _class_key(cls: type) -> tuple:
    """The order of ``sympy.core.basic._cmp_name`` on classes, as a key: the classes of
    ``ordering_of_classes`` by position, then the others by name."""
    try:
        return (ordering_of_classes.index(cls.__name__), "")
    except ValueError:
        return (len(ordering_of_classes) + 1, cls.__name__)


def _plain_base(b: sp.Expr) -> bool:
    return b.is_Symbol or (isinstance(b, sp.Function) and all(a.is_Atom for a in b.args))


def _canonical_sum(terms: list) -> sp.Expr:
    """``sympy.Add(*[sympy.Mul(c, *factors) for c, factors in terms])`` without flatten, when every
    ``c`` is a non-zero rational, every factor a symbol, a function of atoms (``sin(457/500)``) or an
    integer power of one of these, the bases distinct within a term and the terms' factor sets distinct
    (so that nothing combines). Each product is then the coefficient (if not 1) and the factors in
    ``_mulsort`` order, and the sum is its terms in ``_addsort`` order; both orders are ``Basic.compare``,
    which on two products compares their classes, then their numbers of args, then their args in turn. Here
    each distinct coefficient and factor is ranked once by ``Basic.compare`` and the products and the sum are
    sorted by these ranks, instead of ``compare`` on every pair of long products. Any other input:
    sympy's ``Mul`` and ``Add``. The same expression either way (tests/baseparams/test_generation_speed.py).
    """
    def slow() -> sp.Expr:
        return sp.Add(*[sp.Mul(c, *f) for c, f in terms])

    if len(terms) < 2:
        return slow()
    distinct: dict = {}
    sets = set()
    for c, f in terms:
        if not (c.is_Rational and c != 0 and f):
            return slow()
        bases = []
        for b in f:
            if b.is_Pow:
                if not (b.exp.is_Integer and _plain_base(b.base)):
                    return slow()
                bases.append(b.base)
            elif _plain_base(b):
                bases.append(b)
            else:
                return slow()
        if len(set(bases)) != len(bases):
            return slow()
        sets.add(frozenset(f))
        distinct[c] = None
        for b in f:
            distinct[b] = None
    if len(sets) != len(terms):
        return slow()
    rank = {x: k for k, x in enumerate(sorted(distinct, key=cmp_to_key(sp.Basic.compare)))}
    mul_key = _class_key(sp.Mul)
    built = []
    for c, f in terms:
        f = sorted(f, key=rank.__getitem__)
        args = f if c == 1 else [c, *f]
        key = tuple(rank[a] for a in args)
        if len(args) == 1:
            built.append(((_class_key(type(args[0])), 0, key), args[0]))
        else:
            built.append(((mul_key, len(args), key), sp.Mul._from_args(args)))
    built.sort(key=lambda t: t[0])
    return sp.Add._from_args([e for _, e in built])


_Algebra = _ExprAlgebra | _PolyAlgebra


def _expand_linear(build, values: tuple) -> sp.Matrix:
    """``build(*values)`` for a ``build`` linear in its arguments, with its coefficients expanded.

    The matrix is built and expanded on placeholder symbols (small expressions in the constants of one
    row), then the placeholders are replaced by ``values`` (the long accumulated parameter sums). The
    result is not expanded in the values: the relations are expanded once at the end
    (:func:`group_base_parameters`), which gives the same canonical sums as expanding at every step,
    without re-expanding the growing sums once per link.
    """
    ph = sp.symbols(f"_ph0:{len(values)}", cls=sp.Dummy)
    coef = build(*ph).applyfunc(sp.expand)
    return coef.xreplace(dict(zip(ph, values)))


def _sym_matrix(J) -> sp.Matrix:
    """The symmetric 3x3 matrix of the six entries ``J`` in :data:`_J_INDEX` order."""
    m = sp.zeros(3, 3)
    for x, (r, c) in zip(J, _J_INDEX.values()):
        m[r, c] = m[c, r] = x
    return m


def _exact_row(row):
    """The MDH row with its float literals written as the rationals they print as (``0.05 -> 1/20``),
    so that relations from literal geometry have exact coefficients."""
    fields = {}
    for k in ("gamma", "b", "alpha", "d", "theta", "r"):
        e = getattr(row, k)
        if e.has(sp.Float):
            fields[k] = e.xreplace({f: sp.nsimplify(f, rational=True) for f in e.atoms(sp.Float)})
    return replace(row, **fields) if fields else row


def _kind_at(r, c):
    for k, (a, b) in _J_INDEX.items():
        if (a, b) == (r, c) or (b, a) == (r, c):
            return k
    raise KeyError((r, c))


def _kind(name: str) -> str:
    return split_name(name)[0]


def keep_rank(name: str) -> int:
    """Keep priority class of a standard parameter: 0 inertial, 1 IA, 2 FV/FS, 3 OFF.

    A dependency eliminates the parameter of the highest class (see the module docstring).
    """
    return _KEEP_RANK.get(_kind(name), 0)


_KEEP_RANK = {"IA": 1, "FV": 2, "FS": 2, "OFF": 3}


def _random_states(robot: RobotDescription, n_samples: int, rng: np.random.Generator) -> dict:
    n = robot.n_joints
    q = rng.uniform(-np.pi, np.pi, (n_samples, n))
    dq = rng.normal(0, 2.0, (n_samples, n))
    ddq = rng.normal(0, 4.0, (n_samples, n))
    values: dict = {}
    for k in range(n):
        values[robot.q[k]] = q[:, k]
        values[robot.dq[k]] = dq[:, k]
        values[robot.ddq[k]] = ddq[:, k]
    if robot.floating:  # the base's inputs (dynamics.floating): a random unit quaternion, velocities, accelerations
        quat = rng.normal(size=(n_samples, 4))
        quat /= np.linalg.norm(quat, axis=1, keepdims=True)
        base = np.hstack([rng.normal(size=(n_samples, 3)), quat, rng.normal(0, 2.0, (n_samples, 6)),
                          rng.normal(0, 4.0, (n_samples, 6))])
        for k, name in enumerate(BASE_Q_NAMES + BASE_DQ_NAMES + BASE_DDQ_NAMES):
            values[_sym(name)] = base[:, k]
    return values


def _sample_columns(reg: SymbolicRegressor, names, n_samples: int, rng: np.random.Generator) -> np.ndarray:
    """Numeric columns (n_samples*n, len(names)) of the standard regressor at random states."""
    robot = reg.robot
    values = {**_random_states(robot, n_samples, rng), **robot.geometry_subs()}
    W = evaluate_columns(reg.graph, robot.n_joints + reg.base_rows, names, values, n_samples)
    return W.reshape(-1, len(names))


def _nice(c: float, tol: float) -> sp.Expr:
    r = sp.nsimplify(c, rational=True, tolerance=tol)
    if abs(float(r) - c) <= tol * max(1.0, abs(c)) and (r.q <= 1000):
        return r
    return sp.Float(float(f"{c:.12g}"))


def _rational_state(robot: RobotDescription, rng: np.random.Generator) -> tuple[dict, dict]:
    """Exact random state: values of q (angle symbols), dq, ddq, and exact sin/cos of the angles.

    sin and cos of each revolute joint angle are rational (t = tan(q/2) rational); a
    prismatic joint variable is rational.
    """
    env: dict = {}
    trig: dict = {}
    for k, row in enumerate(robot.joints):
        t = sp.Rational(int(rng.integers(-9, 10)), int(rng.integers(1, 10)))
        if row.sigma == PRISMATIC:
            env[robot.q[k]] = t
        else:
            A = sp.Dummy(f"A{k}", real=True)
            trig[sp.sin(A)] = 2 * t / (1 + t**2)
            trig[sp.cos(A)] = (1 - t**2) / (1 + t**2)
            env[robot.q[k]] = A
        for sym in (robot.dq[k], robot.ddq[k]):
            v = 0
            while v == 0:
                v = int(rng.integers(-9, 10))
            env[sym] = sp.Rational(v, int(rng.integers(1, 5)))
    return env, trig


def _state_arithmetic(trig: dict) -> Arithmetic:
    def fn(f):
        def apply(x):
            return sp.expand(sp.expand_trig(f(x)).xreplace(trig))

        return apply

    return replace(EXACT, functions={**EXACT.functions, sp.sin: fn(sp.sin), sp.cos: fn(sp.cos)})


#: Budget of the exact solve (deterministic: sizes, not time). Above it the dependency keeps the numeric
#: coefficients of the sweep, marked ``numeric`` in the map and in base_parameters.md. The robots of
#: robots/ need at most 5 support columns and ~200 operations; a pathological random chain (many
#: symbolic lengths and special angles) can make the symbolic elimination swell without end.
EXACT_MAX_SUPPORT = 12
EXACT_MAX_OPS = 4000


class _ExactSolver:
    """Solves ``column(p) = sum_k c_k column(k)`` with symbolic geometry and gravity."""

    def __init__(self, robot: RobotDescription, seed: int = 1) -> None:
        self.robot = robot
        self._graphs: dict[frozenset, ExprGraph] = {}
        self.gravity = gravity_symbols(robot)
        self.constants = {**robot.geometry_subs(), **self.gravity}
        self.seed = seed

    def graph(self, names) -> ExprGraph:
        """The graph of the columns ``names`` only, with symbolic gravity (its exact values are those of
        the full model's columns: only the intermediate naming differs, and the exact evaluation expands)."""
        key = frozenset(names)
        if key not in self._graphs:
            self._graphs[key] = build_regressor(self.robot, symbolic_gravity=True, columns=key).graph
        return self._graphs[key]

    def _rows(self, names: list[str], n_states: int, rng: np.random.Generator) -> sp.Matrix:
        """Exact regressor rows (n_states * n_joints, len(names))."""
        col = {nm: i for i, nm in enumerate(names)}
        graph = self.graph(names)
        keys = [k for k in graph.outputs if k[1] in col]
        base = {s: s for s in self.constants}
        rows = []
        for _ in range(n_states):
            env, trig = _rational_state(self.robot, rng)
            out = evaluate_graph(graph, {**base, **env}, keys, _state_arithmetic(trig))
            M = [[sp.Integer(0)] * len(names) for _ in range(self.robot.n_joints)]
            for (i, nm), v in out.items():
                M[i][col[nm]] = v
            rows.extend(M)
        return sp.Matrix(rows)

    def solve(self, p: str, support: list[str]) -> list[sp.Expr] | None:
        """Exact coefficients of the columns ``support`` giving the column ``p``, or None."""
        rng = np.random.default_rng(self.seed)
        m = len(support)
        if m > EXACT_MAX_SUPPORT:
            return None
        R = self._rows(support + [p], m + 2, rng)
        if sum(sp.count_ops(e) for e in R) > EXACT_MAX_OPS:
            return None
        A, b = R[:, :m], R[:, m]
        An = np.array(A.xreplace(self.constants).evalf(), dtype=float)
        # m independent equations, chosen greedily (Gram-Schmidt on the numeric rows)
        chosen: list[int] = []
        basis = np.zeros((0, m))
        for r in range(An.shape[0]):
            v = An[r] - basis.T @ (basis @ An[r]) if basis.size else An[r]
            if np.linalg.norm(v) > 1e-9 * max(1.0, float(np.linalg.norm(An[r]))):
                chosen.append(r)
                basis = np.vstack([basis, v / np.linalg.norm(v)])
                if len(chosen) == m:
                    break
        if len(chosen) < m:
            return None
        x = A.extract(chosen, list(range(m))).LUsolve(b.extract(chosen, [0]))
        if sum(sp.count_ops(c) for c in x) > 10 * EXACT_MAX_OPS:
            return None
        coefs = [sp.factor_terms(sp.cancel(c)) for c in x]
        for r in range(A.rows):
            if sp.cancel(sum((A[r, k] * coefs[k] for k in range(m)), sp.Integer(0)) - b[r]) != 0:
                return None
        return coefs


def group_base_parameters(
    reg: SymbolicRegressor,
    *,
    rng: np.random.Generator | None = None,
    n_samples: int = 60,
    rank_tol: float = 1e-9,
    dependency_tol: float = 1e-7,
    coefficient_tol: float = 1e-8,
) -> BaseParameterMap:
    """Base parameters of the robot of ``reg`` (closed-form rules + exact dependency sweep).

    Parameters
    ----------
    reg : SymbolicRegressor
    rng : numpy.random.Generator, optional
        For the random samples of the numeric sweep (default: seeded with 0, deterministic).
    n_samples : int
        Random states used by the numeric sweep.
    rank_tol : float
        A column whose norm is below ``rank_tol`` times the largest one has no effect.
    dependency_tol : float
        A column whose distance to the span of the previously kept columns is below
        ``dependency_tol`` times its norm is dependent (regrouped into them).
    coefficient_tol : float
        Numeric regrouping coefficients smaller than this are not part of the dependency;
        when no exact form is found, coefficients within it of a simple rational are
        written exactly.

    Returns
    -------
    BaseParameterMap
    """
    rng = np.random.default_rng(0) if rng is None else rng
    state = rng.bit_generator.state
    try:
        return _group(reg, _PolyAlgebra(), rng, n_samples, rank_tol, dependency_tol, coefficient_tol)
    except _NotPolynomial:  # e.g. sqrt(3)/2 from alpha = pi/3, or a numeric coefficient: sympy's arithmetic
        rng.bit_generator.state = state
        return _group(reg, _ExprAlgebra(), rng, n_samples, rank_tol, dependency_tol, coefficient_tol)


def _group(reg: SymbolicRegressor, alg: _Algebra, rng: np.random.Generator, n_samples: int, rank_tol: float,
           dependency_tol: float, coefficient_tol: float) -> BaseParameterMap:
    robot = reg.robot
    cur, eliminated, no_effect = _regroup_closed_form(reg, alg)

    # zero columns: no effect
    cols_present = {name for (_, name) in reg.graph.outputs}
    for name in list(cur):
        if name not in cols_present:
            no_effect.append(f"{name}R" if not alg.is_symbol(cur[name], name) else name)
            eliminated.append(name)
            del cur[name]

    std_index = {n: i for i, n in enumerate(reg.standard_names)}
    sweep_order = sorted((n for n in reg.standard_names if n in cur), key=lambda n: (keep_rank(n), std_index[n]))
    W = _sample_columns(reg, sweep_order, n_samples, rng)
    norms = np.linalg.norm(W, axis=0)
    accepted: list[int] = []
    swept: list[str] = []
    numeric: list[str] = []
    solver = _ExactSolver(robot)
    gravity = gravity_symbols(robot)
    values = {**robot.geometry_subs(), **gravity}
    Q = np.zeros((W.shape[0], 0))
    for k, name in enumerate(sweep_order):
        c = W[:, k]
        if norms[k] <= rank_tol * max(norms.max(), 1.0):
            no_effect.append(name)
            eliminated.append(name)
            del cur[name]
            continue
        resid = c - Q @ (Q.T @ c) if Q.shape[1] else c
        if np.linalg.norm(resid) > dependency_tol * norms[k]:
            accepted.append(k)
            qv = resid - Q @ (Q.T @ resid) if Q.shape[1] else resid
            Q = np.column_stack([Q, qv / np.linalg.norm(qv)])
            continue
        # dependent: c = W_acc beta; which columns (numeric), then the coefficients (exact)
        # least squares through the orthonormal basis Q of the accepted columns (W_acc = Q R, R = Q^T W_acc
        # triangular): a k x k solve instead of an SVD of the (samples*n) x k block for every dependency
        beta = np.linalg.solve(Q.T @ W[:, accepted], Q.T @ c)
        support = [(sweep_order[kk], float(b)) for kk, b in zip(accepted, beta) if abs(b) > coefficient_tol]
        targets = [t for t, _ in support]
        coefs = solver.solve(name, targets) if not robot.floating else None  # floating: numeric coefficients
        if coefs is not None:
            approx = np.array([float(e.xreplace(values)) for e in coefs])
            cols = [sweep_order.index(t) for t in targets]
            if np.linalg.norm(c - W[:, cols] @ approx) > 10 * dependency_tol * norms[k]:
                coefs = None
        exact = coefs is not None
        if coefs is None:
            coefs = [_nice(b, coefficient_tol) for _, b in support]
        for tgt, coef in zip(targets, coefs):
            if coef == 0:
                continue
            cur[tgt] = alg.add_scaled(cur[tgt], coef, cur[name])
            if tgt not in swept:
                swept.append(tgt)
            if not exact and tgt not in numeric:
                numeric.append(tgt)
        eliminated.append(name)
        del cur[name]

    kept = tuple(n for n in reg.standard_names if n in cur)
    base_names, relations = [], {}
    for n in kept:
        e = alg.to_expr(cur[n])
        bn = n if e == _sym(n) else n + "R"
        base_names.append(bn)
        relations[bn] = e

    def base_of(ns: list[str]) -> tuple[str, ...]:
        return tuple(n + ("R" if (n + "R") in relations else "") for n in reg.standard_names if n in ns and n in cur)

    return BaseParameterMap(
        standard_names=reg.standard_names,
        base_names=tuple(base_names),
        kept=kept,
        relations=relations,
        eliminated=tuple(eliminated),
        no_effect=tuple(no_effect),
        numeric=base_of(numeric),
        geometry=robot.geometry_subs(),
        gravity=gravity,
        swept=base_of(swept),
    )


def numeric_rank(W: np.ndarray, rtol: float = 1e-9) -> int:
    """Numeric rank of W by SVD with relative tolerance ``rtol``."""
    norms = np.linalg.norm(W, axis=0)
    keep = norms > rtol * max(norms.max(initial=0.0), 1e-300)
    s = np.linalg.svd(W[:, keep] / norms[keep], compute_uv=False)
    return int(np.sum(s > rtol * s[0])) if s.size else 0
