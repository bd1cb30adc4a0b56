"""CasADi backend: the optimised graph as CasADi ``SX`` operations.

Two forms of the same walk over the graph:

* :func:`casadi_source` prints a Python function ``name(ca, q, dq, ddq, out)`` that applies
  CasADi operations (``ca.sin``...) to ``SX`` inputs; a generated package ships it as
  ``_casadi.py`` and :mod:`symoro_gen.runtime.casadi` turns it into a ``casadi.Function``;
* :func:`casadi_function` builds the ``casadi.Function`` directly from the sympy expressions
  (used by :class:`~symoro_gen.emit.package.InMemoryModel` and to check the printed form).

No NumPy source is involved in either.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy as sp

from ...dynamics.graph import ExprGraph
from ..printing import CASADI, print_expr


def casadi_source(graph: ExprGraph, col_names: Sequence[str], func_name: str, q: Sequence[sp.Symbol],
                  dq: Sequence[sp.Symbol], ddq: Sequence[sp.Symbol]) -> str:
    """Python source of ``func_name(ca, q, dq, ddq, out)``: ``out[i, k] = ...`` on ``casadi.SX``."""
    col = {n: k for k, n in enumerate(col_names)}
    lines = [f"def {func_name}(ca, q, dq, ddq, out):"]
    used = graph.used_names()
    for arr, syms in (("q", q), ("dq", dq), ("ddq", ddq)):
        for i, s in enumerate(syms):
            if s.name in used:
                lines.append(f"    {s.name} = {arr}[{i}]")
    for s, e in graph.defs:
        lines.append(f"    {s.name} = {print_expr(e, CASADI)}")
    for (i, name) in sorted(graph.outputs, key=lambda k: (col[k[1]], k[0])):
        lines.append(f"    out[{i}, {col[name]}] = {print_expr(graph.outputs[(i, name)], CASADI)}")
    if len(lines) == 1:
        lines.append("    pass")
    return "\n".join(lines) + "\n"


def _to_sx(e: sp.Expr, env: dict[sp.Symbol, Any], ca: Any) -> Any:
    """sympy expression -> casadi SX, with ``env`` mapping symbols to SX values."""
    if e.is_Symbol:
        return env[e]
    if e.is_Number:
        return float(e)
    if e is sp.pi:
        return float(sp.pi)
    args = [_to_sx(a, env, ca) for a in e.args]
    if e.is_Add:
        out = args[0]
        for a in args[1:]:
            out = out + a
        return out
    if e.is_Mul:
        out = args[0]
        for a in args[1:]:
            out = out * a
        return out
    if e.is_Pow:
        x = e.as_base_exp()[1]
        if x.is_Integer:
            return args[0] ** int(x)
        return ca.power(args[0], args[1])
    fn = {sp.sin: ca.sin, sp.cos: ca.cos, sp.tan: ca.tan, sp.sign: ca.sign}.get(type(e))
    if fn is None:
        raise ValueError(f"expression not representable in CasADi: {e}")
    return fn(*args)


def casadi_function(graph: ExprGraph, n_rows: int, col_names: Sequence[str], name: str, q: Sequence[sp.Symbol],
                    dq: Sequence[sp.Symbol], ddq: Sequence[sp.Symbol]) -> Any:
    """``casadi.Function name(q, dq, ddq) -> Y`` (n_rows x len(col_names)) built from the graph."""
    import casadi as ca  # optional at run time: only needed for CasADi functions

    Q, DQ, DDQ = ca.SX.sym("q", len(q)), ca.SX.sym("dq", len(dq)), ca.SX.sym("ddq", len(ddq))  # floating: 7+n, 6+n
    env: dict[sp.Symbol, Any] = {}
    for arr, syms in ((Q, q), (DQ, dq), (DDQ, ddq)):
        for i, s in enumerate(syms):
            env[s] = arr[i]
    for s, e in graph.defs:
        env[s] = _to_sx(e, env, ca)
    col = {c: k for k, c in enumerate(col_names)}
    out = ca.SX.zeros(n_rows, len(col_names))
    for (i, c), e in graph.outputs.items():
        out[i, col[c]] = _to_sx(e, env, ca)
    return ca.Function(name, [Q, DQ, DDQ], [out], ["q", "dq", "ddq"], ["Y"])
