"""A small expression graph: intermediate variables kept as symbols.

Newton-Euler builds the model as a list of assignments ``x_k = expr(previous symbols)``
plus output expressions; nothing is expanded into one giant expression.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp


def is_trivial(e: sp.Expr) -> bool:
    """Atoms and negated atoms are inlined rather than given a name."""
    if e.is_Atom:
        return True
    return bool(e.is_Mul and len(e.args) == 2 and e.args[0] == -1 and e.args[1].is_Atom)


class GraphBuilder:
    """Accumulates named intermediate assignments."""

    def __init__(self) -> None:
        self.defs: list[tuple[sp.Symbol, sp.Expr]] = []
        self._by_expr: dict[sp.Expr, sp.Symbol] = {}
        # the same expressions keyed by their terms {(rest, coefficient)}: the key of -expr is found
        # by negating the coefficients, without building -expr (sympy's Add.__neg__ is the cost)
        self._by_terms: dict[frozenset, sp.Symbol] = {}
        self._names: set[str] = set()

    def name(self, expr, prefix: str) -> sp.Expr:
        expr = sp.sympify(expr)
        if is_trivial(expr):
            return expr
        hit = self._by_expr.get(expr)
        if hit is not None:
            return hit
        terms = [t.as_coeff_Mul() for t in sp.Add.make_args(expr)]
        hit = self._by_terms.get(frozenset((r, -c) for c, r in terms))
        if hit is not None:  # expr == -(an expression already named)
            return -hit
        base = prefix
        k = 1
        nm = base
        while nm in self._names:
            k += 1
            nm = f"{base}_{k}"
        self._names.add(nm)
        s = sp.Symbol(nm, real=True)
        self.defs.append((s, expr))
        self._by_expr[expr] = s
        self._by_terms[frozenset((r, c) for c, r in terms)] = s
        return s

    def vec(self, exprs, prefix: str, comps: str = "xyz") -> list[sp.Expr]:
        return [self.name(e, f"{prefix}{c}") for e, c in zip(exprs, comps)]


@dataclass(frozen=True)
class ExprGraph:
    """Assignments in dependency order plus named outputs.

    Attributes
    ----------
    inputs : tuple of sympy.Symbol
        Free input symbols (q, dq, ddq, geometric constants).
    defs : tuple of (Symbol, Expr)
        Intermediate variables, each using only inputs and earlier ones.
    outputs : dict
        ``(row, col) -> Expr`` non-zero output entries.
    """

    inputs: tuple
    defs: tuple
    outputs: dict

    def pruned(self, keys=None) -> ExprGraph:
        """Keep only the outputs in ``keys`` and the intermediates they need (dead code removed)."""
        outs = self.outputs if keys is None else {k: v for k, v in self.outputs.items() if k in keys}
        need: set = set()
        for e in outs.values():
            need |= e.free_symbols
        keep = []
        for s, e in reversed(self.defs):
            if s in need:
                keep.append((s, e))
                need |= e.free_symbols
        return ExprGraph(self.inputs, tuple(reversed(keep)), outs)

    def substituted(self, subs: dict) -> ExprGraph:
        """Substitute inputs (e.g. geometric constants by their values)."""
        defs = tuple((s, e.xreplace(subs)) for s, e in self.defs)
        outs = {k: v.xreplace(subs) for k, v in self.outputs.items()}
        inputs = tuple(i for i in self.inputs if i not in subs)
        return ExprGraph(inputs, defs, outs)

    def used_names(self) -> set:
        """Names of all symbols the definitions and outputs use (to load only needed inputs)."""
        cached = self.__dict__.get("_used_names")  # each backend asks; the graph is immutable
        if cached is None:
            used: set = set()
            for _, e in self.defs:
                used |= {x.name for x in e.free_symbols}
            for e in self.outputs.values():
                used |= {x.name for x in e.free_symbols}
            cached = self.__dict__["_used_names"] = frozenset(used)
        return set(cached)

    def inline_all(self) -> dict:
        """Outputs as closed expressions of the inputs (for small checks only)."""
        env: dict = {}
        for s, e in self.defs:
            env[s] = e.xreplace(env)
        return {k: v.xreplace(env) for k, v in self.outputs.items()}
