"""C backend: the same optimised graph as straight-line C with a batch loop over samples.

Each function ``<name>_batch(N, q, dq, ddq, out)`` reads (N, n) row-major inputs and writes
every entry (structural zeros included) of a row-major (N, n, ncols) output.
"""
from __future__ import annotations

import sympy as sp

from ..dynamics.graph import ExprGraph
from .codegen import print_expr

C_PRELUDE = """#include <math.h>

static inline double sym_sign(double x) { return (double)((x > 0.0) - (x < 0.0)); }
"""


def _c_expr(e: sp.Expr) -> str:
    s = print_expr(e)
    s = s.replace("np.sin(", "sin(").replace("np.cos(", "cos(").replace("np.tan(", "tan(").replace("np.sign(", "sym_sign(")
    if "np." in s:
        raise ValueError(f"expression not printable in C: {e}")
    return s


def trig_defs(graph: ExprGraph) -> list:
    """The sin/cos definitions of a graph (computed outside the C loop, vectorised)."""
    return [(s, e) for s, e in graph.defs if isinstance(e, (sp.sin, sp.cos))]


def c_function(graph: ExprGraph, n_rows: int, col_names, func_name: str, q, dq, ddq, trig: list) -> str:
    """``trig`` lists the (symbol, sin/cos expr) read from the precomputed ``trig`` array."""
    col = {n: k for k, n in enumerate(col_names)}
    nc = len(col_names)
    nt = len(trig)
    tpos = {s: i for i, (s, _) in enumerate(trig)}
    lines = [
        f"void {func_name}(long N, const double* q, const double* dq, const double* ddq, const double* trig, double* out)",
        "{",
        "    for (long s = 0; s < N; ++s) {",
        f"        const double* ts = trig + s * {max(nt, 1)};",
        f"        const double* qs = q + s * {n_rows};",
        f"        const double* dqs = dq + s * {n_rows};",
        f"        const double* ddqs = ddq + s * {n_rows};",
        f"        double* o = out + s * {n_rows * nc};",
    ]
    used = graph.used_names()
    for arr, syms in (("qs", q), ("dqs", dq), ("ddqs", ddq)):
        for i, s in enumerate(syms):
            if s.name in used:
                lines.append(f"        const double {s.name} = {arr}[{i}];")
    for s, e in graph.defs:
        if s in tpos:
            lines.append(f"        const double {s.name} = ts[{tpos[s]}];")
        else:
            lines.append(f"        const double {s.name} = {_c_expr(e)};")
    entries = {(i, col[nm]): e for (i, nm), e in graph.outputs.items()}
    for i in range(n_rows):
        for k in range(nc):
            e = entries.get((i, k))
            lines.append(f"        o[{i * nc + k}] = {_c_expr(e) if e is not None else '0.0'};")
    lines += ["    }", "}", ""]
    return "\n".join(lines)


def trig_source(trig: list, q_syms, func_name: str = "trig") -> str:
    """Python ``trig(qT)``: (n, N) joint positions -> (N, len(trig)) sin/cos values (NumPy SIMD)."""
    lines = [f"def {func_name}(qT):", f"    out = np.empty((qT.shape[1], {max(len(trig), 1)}))"]
    used = set()
    for _, e in trig:
        used |= {x.name for x in e.free_symbols}
    for i, s in enumerate(q_syms):
        if s.name in used:
            lines.append(f"    {s.name} = qT[{i}]")
    for k, (_, e) in enumerate(trig):
        lines.append(f"    out[:, {k}] = {print_expr(e)}")
    lines.append("    return out")
    return "\n".join(lines) + "\n"
