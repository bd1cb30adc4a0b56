"""Printing sympy expressions of an :class:`~symoro_gen.dynamics.graph.ExprGraph` as code, and
counting their operations.

One printer serves the three backends (NumPy, C, CasADi); they differ only by the names of the
elementary functions (:class:`Dialect`). The output is deterministic: it depends on the expression
and the dialect, never on NumPy's ``repr`` (floats print as ``repr(float(x))``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from ..dynamics.graph import ExprGraph


@dataclass(frozen=True)
class Dialect:
    """Names of the elementary functions in one target language.

    Attributes
    ----------
    funcs : tuple of (str, str)
        ``(sympy function name, printed name)`` for sin, cos, tan, sign.
    power : str
        Name of the general power function (``x**y`` with a non-small exponent).
    pi : str
        Literal of pi.
    """

    funcs: tuple[tuple[str, str], ...]
    power: str
    pi: str

    def func(self, name: str) -> str | None:
        return dict(self.funcs).get(name)


NUMPY = Dialect((("sin", "np.sin"), ("cos", "np.cos"), ("tan", "np.tan"), ("sign", "np.sign")), "np.power", "np.pi")
C_SCALAR = Dialect((("sin", "sin"), ("cos", "cos"), ("tan", "tan"), ("sign", "sym_sign")), "pow", "3.141592653589793")
C_VECTOR = Dialect((("sin", "sym_vsin"), ("cos", "sym_vcos"), ("sign", "sym_vsign")), "", "3.141592653589793")
CASADI = Dialect((("sin", "ca.sin"), ("cos", "ca.cos"), ("tan", "ca.tan"), ("sign", "ca.sign")), "ca.power", "3.141592653589793")


class _Printer(PythonCodePrinter):  # type: ignore[misc]  # sympy is untyped
    """Fallback printer for forms outside the fast path: x**2 as x*x, functions by dialect."""

    def __init__(self, dialect: Dialect):
        super().__init__({"fully_qualified_modules": False, "standard": "python3"})
        self.dialect = dialect

    def _print_Pow(self, expr: sp.Expr, rational: bool = False) -> str:
        if expr.is_number:
            # a constant such as sqrt(3)/2 from alpha = pi/3: one literal in every backend
            # (C vector code has no power function); 17 significant digits round-trip a double
            return repr(float(expr))
        b, e = expr.as_base_exp()
        if e.is_Integer and 1 < int(e) <= 4:
            s = str(self.parenthesize(b, 100))
            return "*".join([s] * int(e))
        if e == -1:
            return "1.0/" + str(self.parenthesize(b, 100))
        if not self.dialect.power:
            raise ValueError(f"expression not printable in this backend: {expr}")
        return f"{self.dialect.power}({self._print(b)}, {self._print(e)})"

    def _print_Function(self, e: sp.Expr) -> str:
        name = self.dialect.func(type(e).__name__)
        if name is None or len(e.args) != 1:
            raise ValueError(f"expression not printable in this backend: {e}")
        return f"{name}({self._print(e.args[0])})"

    _print_sin = _print_cos = _print_tan = _print_sign = _print_Function

    def _print_Pi(self, e: sp.Expr) -> str:
        return self.dialect.pi

    def _print_Float(self, e: sp.Expr) -> str:
        return repr(float(e))

    def _print_Rational(self, e: sp.Expr) -> str:
        return f"{float(e.p)}/{float(e.q)}"

    def _print_Integer(self, e: sp.Expr) -> str:
        return f"{int(e)}.0" if abs(int(e)) < 2**53 else str(int(e))


_PRINTERS: dict[Dialect, _Printer] = {}


def _printer(d: Dialect) -> _Printer:
    p = _PRINTERS.get(d)
    if p is None:
        p = _PRINTERS[d] = _Printer(d)
    return p


def _number(e: sp.Expr, d: Dialect) -> str:
    """``_Printer.doprint`` of a number: what its ``_print_Float`` / ``_print_Integer`` / ``_print_Rational``
    write, without the code printer's per-call set-up (a walk of the expression); others by ``doprint``."""
    if e.is_Float:
        return repr(float(e))
    if e.is_Integer:
        return f"{int(e)}.0" if abs(int(e)) < 2**53 else str(int(e))
    if e.is_Rational:
        return f"{float(e.p)}/{float(e.q)}"
    return str(_printer(d).doprint(e))


def _fast(e: sp.Expr, d: Dialect) -> str | None:
    """Direct printing of the forms the model produces (sums of signed products of symbols,
    numbers, small powers and sin/cos/sign calls); None for anything else."""
    if e.is_Symbol:
        return str(e.name)
    if e.is_Number:
        return _number(e, d)
    if e.is_Mul:
        coeff, rest = e.as_coeff_Mul()
        parts = []
        for f in sp.Mul.make_args(rest):
            t = _fast(f, d)
            if t is None:
                return None
            if f.is_Add:
                t = f"({t})"
            parts.append(t)
        body = "*".join(parts)
        if coeff == 1:
            return body
        if coeff == -1:
            return "-" + body
        c = _number(coeff, d)
        negative = coeff.p < 0 if coeff.is_Rational else float(coeff) < 0
        return f"({c})*{body}" if negative else f"{c}*{body}"
    if e.is_Add:
        out = ""
        for i, t in enumerate(e.args):
            s = _fast(t, d)
            if s is None:
                return None
            if i == 0:
                out = s
            elif s.startswith("-"):
                out += " - " + s[1:]
            else:
                out += " + " + s
        return out
    if e.is_Pow:
        b, x = e.as_base_exp()
        if x.is_Integer and 1 < int(x) <= 4 and b.is_Symbol:
            return "*".join([b.name] * int(x))
        return None
    if isinstance(e, sp.Function) and len(e.args) == 1:
        name = d.func(type(e).__name__)
        if name is None:
            return None
        a = _fast(e.args[0], d)
        return None if a is None else f"{name}({a})"
    return None


def print_expr(e: sp.Expr, dialect: Dialect = NUMPY, memo: dict[Any, str] | None = None) -> str:
    """Source text of ``e`` in ``dialect`` (raises ValueError for a function the dialect lacks).

    ``memo``: a dict kept by the caller across the graphs of one model (the base, standard and payload graphs
    share most definitions): ``(e, dialect) -> text``, each text printed once; results do not depend on it."""
    if memo is not None:
        key = (e, dialect)
        got = memo.get(key)
        if got is None:
            got = memo[key] = print_expr(e, dialect)
        return got
    s = _fast(e, dialect)
    return s if s is not None else _printer(dialect).doprint(e)


@dataclass(frozen=True)
class OpCount:
    """Operation counts of printed expressions."""

    mul: int = 0
    add: int = 0
    div: int = 0
    func: int = 0

    def __add__(self, o: OpCount) -> OpCount:
        return OpCount(self.mul + o.mul, self.add + o.add, self.div + o.div, self.func + o.func)

    @property
    def mul_div_pow(self) -> int:
        """Multiplications + divisions (powers counted as their multiplications)."""
        return self.mul + self.div

    def as_dict(self) -> dict[str, int]:
        return {"mul": self.mul, "div": self.div, "add": self.add, "func": self.func}


def count_ops(e: sp.Expr) -> OpCount:
    """Operation count of one expression as it will be printed (x**2 = 1 mul, -x = 0)."""
    if e.is_Atom:
        return OpCount()
    c = OpCount()
    if e.is_Add:
        c = c + OpCount(add=len(e.args) - 1)
    elif e.is_Mul:
        coeff, rest = e.as_coeff_Mul()
        factors = sp.Mul.make_args(rest)
        n = len(factors) - 1 + (0 if coeff in (1, -1) else 1)
        c = c + OpCount(mul=max(n, 0))
        for f in factors:
            c = c + count_ops(f)
        return c
    elif e.is_Pow:
        b, ex = e.as_base_exp()
        if ex.is_Integer and ex > 1:
            c = c + OpCount(mul=int(ex) - 1)
        elif ex == -1:
            c = c + OpCount(div=1)
        else:
            c = c + OpCount(func=1)
        return c + count_ops(b)
    elif isinstance(e, sp.Function):
        c = c + OpCount(func=1)
    for a in e.args:
        c = c + count_ops(a)
    return c


def graph_ops(graph: ExprGraph, memo: dict[Any, OpCount] | None = None) -> OpCount:
    """Operation count of a whole graph (definitions and outputs). ``memo``: a dict kept by the caller
    across the graphs of one model, expression -> its count; results do not depend on it."""
    memo = {} if memo is None else memo
    c = OpCount()
    for e in [e for _, e in graph.defs] + list(graph.outputs.values()):
        n = memo.get(e)
        if n is None:
            n = memo[e] = count_ops(e)
        c = c + n
    return c


def _sstr_factor(f: sp.Expr) -> str | None:
    """``sp.sstr`` of one factor of a relation term (symbol, sin/cos of a rational or a symbol, a positive
    integer power of these), or None for anything else."""
    if f.is_Symbol:
        return str(f.name)
    if isinstance(f, (sp.sin, sp.cos)):
        (x,) = f.args
        if x.is_Symbol:
            return f"{type(f).__name__}({x.name})"
        if x.is_Rational and x.p > 0:  # (x > 0 for a Rational, without sympy's comparison)
            return f"{type(f).__name__}({x.p}/{x.q})" if x.q != 1 else f"{type(f).__name__}({x.p})"
        return None
    if f.is_Pow and f.exp.is_Integer and f.exp.p > 1 and not f.base.is_Pow:
        b = _sstr_factor(f.base)
        return None if b is None else f"{b}**{int(f.exp)}"
    return None


def _sstr_term(t: sp.Expr, memo: dict[sp.Expr, str | None] | None = None) -> str | None:
    """``sp.sstr(t, order="none")`` of a product ``c * symbols * functions`` (StrPrinter._print_Mul's
    numerator/denominator split for a rational ``c`` and ``1/G`` factors), or None for other shapes.
    ``memo``: :func:`_sstr_factor` per distinct factor, kept across terms."""
    if t.is_Symbol:
        return str(t.name)
    if not t.is_Mul:
        return None
    args = t.args
    num: list[str] = []
    den: list[str] = []
    sign = ""
    if args[0].is_Rational:
        c, args = args[0], args[1:]
        if c.p < 0:  # c < 0
            sign, c = "-", -c
        if c.p != 1:
            num.append(str(c.p))
        if c.q != 1:
            den.append(str(c.q))
    for f in args:
        if f.is_Pow and f.exp == -1 and f.base.is_Symbol:
            den.append(str(f.base.name))
            continue
        if memo is None:
            s = _sstr_factor(f)
        else:
            if f in memo:
                s = memo[f]
            else:
                s = memo[f] = _sstr_factor(f)
        if s is None:
            return None
        num.append(s)
    body = "*".join(num or ["1"])
    if not den:
        return sign + body
    return sign + body + ("/" + den[0] if len(den) == 1 else "/(" + "*".join(den) + ")")


def relation_text(e: sp.Expr, memo: dict[sp.Expr, str | None] | None = None) -> str:
    """``sp.sstr(e, order="none")`` of a base-parameter relation, written directly for the sums of products the
    relations are (rational coefficient, parameter symbol, sin/cos of constants, symbols, ``1/G3``) and by
    sympy's printer for any other form; the same text (tests/baseparams/test_generation_speed.py).
    ``memo``: a dict shared by the relations of one robot (each factor's text, printed once)."""
    if memo is None:
        memo = {}
    parts: list[str] = []
    for t in sp.Add.make_args(e):
        s = _sstr_term(t, memo)
        if s is None:
            return str(sp.sstr(e, order="none"))
        if s.startswith("-"):
            parts += ["-", s[1:]]
        else:
            parts += ["+", s]
    if parts and parts[0] == "+":
        parts.pop(0)
    elif parts:
        parts[0:2] = ["-" + parts[1]]
    return " ".join(parts)
