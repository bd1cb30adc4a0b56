"""NumPy backend: straight-line vectorised kernels from an :class:`ExprGraph`."""
from __future__ import annotations

import types

import numpy as np
import sympy as sp

from ..dynamics.graph import ExprGraph
from .codegen import print_expr


def kernel_source(graph: ExprGraph, n_rows: int, col_names, func_name: str, inputs_q, inputs_dq, inputs_ddq) -> str:
    """Python source of ``func_name(q, dq, ddq, out)`` filling ``out[i, k, :]``.

    ``q, dq, ddq`` are (n, M) arrays (one row per joint); ``out`` is a zeroed
    (n_rows, len(col_names), M) array; only non-zero entries are written.
    """
    col = {n: k for k, n in enumerate(col_names)}
    lines = [f"def {func_name}(q, dq, ddq, out):"]
    used = graph.used_names()
    for arr, syms in (("q", inputs_q), ("dq", inputs_dq), ("ddq", inputs_ddq)):
        for i, s in enumerate(syms):
            if s.name in used:
                lines.append(f"    {s.name} = {arr}[{i}]")
    for s, e in graph.defs:
        lines.append(f"    {s.name} = {print_expr(e)}")
    for (i, name) in sorted(graph.outputs, key=lambda k: (col[k[1]], k[0])):
        lines.append(f"    out[{i}, {col[name]}] = {print_expr(graph.outputs[(i, name)])}")
    if len(lines) == 1:
        lines.append("    pass")
    return "\n".join(lines) + "\n"


def load_kernel(source: str, func_name: str):
    """Compile kernel source in a private module namespace and return the function."""
    mod = types.ModuleType(f"_symoro_kernel_{func_name}")
    mod.__dict__["np"] = np
    code = compile(source, f"<symoro kernel {func_name}>", "exec")
    exec(code, mod.__dict__)  # noqa: S102 - our own generated code, private namespace
    return mod.__dict__[func_name]


def evaluate(kernel, n_rows: int, n_cols: int, q, dq, ddq, *, chunk: int = 2048) -> np.ndarray:
    """Evaluate a kernel over samples in cache-sized chunks; returns (N, n_rows, n_cols), (n_rows, n_cols) for 1-D inputs."""
    q, dq, ddq = (np.asarray(x, dtype=float) for x in (q, dq, ddq))
    one = q.ndim == 1
    q, dq, ddq = (np.atleast_2d(x) for x in (q, dq, ddq))
    if not (q.shape == dq.shape == ddq.shape) or q.ndim != 2:
        raise ValueError(f"q, dq, ddq must have the same shape (N, n), got {q.shape}, {dq.shape}, {ddq.shape}")
    N = q.shape[0]
    res = np.empty((N, n_rows, n_cols))
    for s in range(0, N, chunk):
        e = min(N, s + chunk)
        b = np.zeros((n_rows, n_cols, e - s))
        kernel(np.ascontiguousarray(q[s:e].T), np.ascontiguousarray(dq[s:e].T), np.ascontiguousarray(ddq[s:e].T), b)
        res[s:e] = b.transpose(2, 0, 1)
    return res[0] if one else res
