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


def print_expr(e: sp.Expr) -> str:
    return _printer.doprint(e)


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
