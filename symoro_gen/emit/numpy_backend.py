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
    used = set()
    for _, e in graph.defs:
        used |= {s.name for s in e.free_symbols}
    for e in graph.outputs.values():
        used |= {s.name for s in e.free_symbols}
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


def as_batch(x, n: int, name: str) -> tuple[np.ndarray, bool]:
    """Validate an input of shape (N, n) or (n,); return (N, n) float array and whether it was 1-D."""
    a = np.asarray(x, dtype=float)
    if a.ndim == 1 and a.shape[0] == n:
        return a[None, :], True
    if a.ndim == 2 and a.shape[1] == n:
        return a, False
    raise ValueError(f"{name} must have shape (N, {n}) or ({n},), got {a.shape}")


def evaluate(kernel, n_rows: int, n_cols: int, q, dq, ddq, *, chunk: int = 2048, out=None) -> np.ndarray:
    """Evaluate a kernel over samples in cache-sized chunks; returns (N, n_rows, n_cols)."""
    n = n_rows
    q, one = as_batch(q, q.shape[-1] if hasattr(q, "shape") else len(q), "q")
    n_in = q.shape[1]
    dq, _ = as_batch(dq, n_in, "dq")
    ddq, _ = as_batch(ddq, n_in, "ddq")
    N = q.shape[0]
    if dq.shape[0] != N or ddq.shape[0] != N:
        raise ValueError(f"q, dq, ddq must have the same number of samples, got {N}, {dq.shape[0]}, {ddq.shape[0]}")
    res = np.empty((N, n, n_cols)) if out is None else out
    buf = np.zeros((n, n_cols, min(chunk, max(N, 1))))
    for s in range(0, N, chunk):
        e = min(N, s + chunk)
        m = e - s
        b = buf[:, :, :m] if m != buf.shape[2] else buf
        if m != buf.shape[2]:
            b = np.zeros((n, n_cols, m))
        else:
            b.fill(0.0)
        kernel(q[s:e].T.copy(), dq[s:e].T.copy(), ddq[s:e].T.copy(), b)
        res[s:e] = b.transpose(2, 0, 1)
    return res[0] if one else res
