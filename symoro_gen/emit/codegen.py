"""Turn an :class:`ExprGraph` into straight-line Python/NumPy source, and count operations."""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter


class _Printer(PythonCodePrinter):
    """Prints x**2 as x*x, sin as np.sin, sign as np.sign; deterministic."""

    def __init__(self):
        super().__init__({"fully_qualified_modules": False, "standard": "python3"})

    def _print_Pow(self, expr, rational=False):
        b, e = expr.as_base_exp()
        if e.is_Integer and 1 < int(e) <= 4:
            s = self.parenthesize(b, 100)
            return "*".join([s] * int(e))
        if e == -1:
            return "1.0/" + self.parenthesize(b, 100)
        return f"np.power({self._print(b)}, {self._print(e)})"

    def _print_sin(self, e):
        return f"np.sin({self._print(e.args[0])})"

    def _print_cos(self, e):
        return f"np.cos({self._print(e.args[0])})"

    def _print_sign(self, e):
        return f"np.sign({self._print(e.args[0])})"

    def _print_Pi(self, e):
        return "np.pi"

    def _print_Float(self, e):
        return repr(float(e))

    def _print_Rational(self, e):
        return f"{float(e.p)}/{float(e.q)}"

    def _print_Integer(self, e):
        return f"{int(e)}.0" if abs(int(e)) < 2**53 else str(int(e))


_printer = _Printer()
_FUNC = {sp.sin: "np.sin", sp.cos: "np.cos", sp.sign: "np.sign", sp.tan: "np.tan"}


def _fast(e) -> str | None:
    """Direct printing of the forms the model produces (sums of signed products of symbols,
    numbers, small powers and sin/cos/sign calls); None for anything else."""
    if e.is_Symbol:
        return e.name
    if e.is_Number:
        return _printer.doprint(e)
    if e.is_Mul:
        coeff, rest = e.as_coeff_Mul()
        parts = []
        for f in sp.Mul.make_args(rest):
            t = _fast(f)
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
        c = _printer.doprint(coeff)
        return f"({c})*{body}" if coeff < 0 else f"{c}*{body}"
    if e.is_Add:
        out = ""
        for i, t in enumerate(e.args):
            s = _fast(t)
            if s is None:
                return None
            if i == 0:
                out = s
            elif s.startswith("-"):
                out += " - " + s[1:]
            elif s.startswith("(-"):
                out += " + " + s
            else:
                out += " + " + s
        return out
    if e.is_Pow:
        b, x = e.as_base_exp()
        if x.is_Integer and 1 < int(x) <= 4 and b.is_Symbol:
            return "*".join([b.name] * int(x))
        return None
    if e.func in _FUNC and len(e.args) == 1:
        a = _fast(e.args[0])
        return None if a is None else f"{_FUNC[e.func]}({a})"
    return None


def print_expr(e: sp.Expr) -> str:
    s = _fast(e)
    return s if s is not None else _printer.doprint(e)


@dataclass(frozen=True)
class OpCount:
    mul: int = 0
    add: int = 0
    div: int = 0
    func: int = 0

    def __add__(self, o: "OpCount") -> "OpCount":
        return OpCount(self.mul + o.mul, self.add + o.add, self.div + o.div, self.func + o.func)

    @property
    def mul_div_pow(self) -> int:
        """Multiplications + divisions (powers counted as their multiplications)."""
        return self.mul + self.div


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
