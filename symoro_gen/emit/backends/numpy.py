"""NumPy backend: straight-line vectorised kernels printed from an :class:`ExprGraph`."""
from __future__ import annotations

import types
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import sympy as sp

from ...dynamics.graph import ExprGraph
from ..printing import NUMPY, print_expr

#: the end of every generated package's ``__init__.py`` (fixed and floating base): the nominal values and
#: ``BACKEND``; a ``str.format`` template like the rest of the module (braces doubled)
MODULE_TAIL = "\n\n" + '''def nominal_parameters():
    """Standard vector of the robot file's nominal values (STANDARD_NAMES order), or None."""
    return None if _NOMINAL is None else _np.array(_NOMINAL, dtype=float)


def nominal_payload():
    """Payload parameters of the robot file's nominal values (PAYLOAD_NAMES order), or None."""
    return None if _NOMINAL_PAYLOAD is None else _np.array(_NOMINAL_PAYLOAD, dtype=float)


def __getattr__(name):
    if name == "BACKEND":
        return _MODEL.backend
    raise AttributeError(f"module {{__name__!r}} has no attribute {{name!r}}")
'''


def kernel_source(graph: ExprGraph, n_rows: int, col_names: Sequence[str], func_name: str,
                  inputs_q: Sequence[sp.Symbol], inputs_dq: Sequence[sp.Symbol],
                  inputs_ddq: Sequence[sp.Symbol], memo: dict[Any, str] | None = None) -> str:
    """Python source of ``func_name(q, dq, ddq, out)`` filling ``out[i, k, :]`` (``memo``: see
    :func:`~symoro_gen.emit.printing.print_expr`).

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
        lines.append(f"    {s.name} = {print_expr(e, NUMPY, memo)}")
    for (i, name) in sorted(graph.outputs, key=lambda k: (col[k[1]], k[0])):
        lines.append(f"    out[{i}, {col[name]}] = {print_expr(graph.outputs[(i, name)], NUMPY, memo)}")
    if len(lines) == 1:
        lines.append("    pass")
    return "\n".join(lines) + "\n"


def load_kernel(source: str, func_name: str) -> Callable[..., Any]:
    """Compile kernel source in a private module namespace and return the function."""
    mod = types.ModuleType(f"_symoro_kernel_{func_name}")
    mod.__dict__["np"] = np
    code = compile(source, f"<symoro kernel {func_name}>", "exec")
    exec(code, mod.__dict__)  # noqa: S102 - our own generated code, private namespace
    fn: Callable[..., Any] = mod.__dict__[func_name]
    return fn
