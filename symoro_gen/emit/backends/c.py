"""C backend: the optimised graph as straight-line C with a batch loop over samples.

:func:`c_source` writes the one C file of a generated package, ``regressor_<robot>.c``. Each
function ``<robot>_<kind>_regressor(N, q, dq, ddq, out)`` reads (N, n) row-major inputs and
writes every entry (structural zeros included) of a row-major (N, n, ncols) output. With
GCC/Clang vector extensions, ``LANES`` samples are evaluated together (one SIMD lane each); a
scalar loop does the remainder, and is the whole function for other compilers.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import sympy as sp

from ...dynamics.graph import ExprGraph
from ..printing import C_SCALAR, C_VECTOR, print_expr

#: samples evaluated together in the SIMD loop
LANES = 4

#: kinds of regressor, in the order of the C functions: (kind, Python contract name)
KINDS = (("base", "regressor"), ("standard", "standard_regressor"), ("payload", "payload_regressor"))

PRELUDE = f"""#define _GNU_SOURCE
#include <math.h>

static inline double sym_sign(double x) {{ return (double)((x > 0.0) - (x < 0.0)); }}

#if defined(__GNUC__)
#define SYM_SIMD 1
#define SYM_LANES {LANES}
typedef double sym_vd __attribute__((vector_size(8 * SYM_LANES)));
static inline sym_vd sym_vload(const double* p, long stride)
{{
    sym_vd v;
    for (int k = 0; k < SYM_LANES; ++k) v[k] = p[k * stride];
    return v;
}}
static inline sym_vd sym_vsign(sym_vd x)
{{
    sym_vd r;
    for (int k = 0; k < SYM_LANES; ++k) r[k] = sym_sign(x[k]);
    return r;
}}
static inline void sym_vsincos(sym_vd x, sym_vd* sn, sym_vd* cs)
{{
    for (int k = 0; k < SYM_LANES; ++k) sincos(x[k], &(*sn)[k], &(*cs)[k]);
}}
static inline sym_vd sym_vsin(sym_vd x)
{{
    sym_vd r;
    for (int k = 0; k < SYM_LANES; ++k) r[k] = sin(x[k]);
    return r;
}}
static inline sym_vd sym_vcos(sym_vd x)
{{
    sym_vd r;
    for (int k = 0; k < SYM_LANES; ++k) r[k] = cos(x[k]);
    return r;
}}
#endif
"""


def function_name(robot: str, kind: str) -> str:
    """Exported C symbol of one batch kernel, e.g. ``lwr4_base_regressor``."""
    return f"{robot}_{kind}_regressor"


def _inputs(graph: ExprGraph, q: Sequence[sp.Symbol], dq: Sequence[sp.Symbol], ddq: Sequence[sp.Symbol], ctype: str, load: Callable[[str, int], str]) -> list[str]:
    used = graph.used_names()
    out = []
    for arr, syms in (("q", q), ("dq", dq), ("ddq", ddq)):
        for i, s in enumerate(syms):
            if s.name in used:
                out.append(f"        const {ctype} {s.name} = {load(arr, i)};")
    return out


def _vector_defs(graph: ExprGraph, memo: dict[Any, str] | None = None) -> list[str]:
    """Definitions on vectors; a sin and a cos of the same angle become one sincos per lane."""
    cos_of = {e.args[0]: s for s, e in graph.defs if isinstance(e, sp.cos)}
    sin_of = {e.args[0]: s for s, e in graph.defs if isinstance(e, sp.sin)}
    paired = {a for a in sin_of if a in cos_of}
    lines, done = [], set()
    for s, e in graph.defs:
        if isinstance(e, (sp.sin, sp.cos)) and e.args[0] in paired:
            a = e.args[0]
            if a not in done:
                sn, cs = sin_of[a].name, cos_of[a].name
                lines.append(f"        sym_vd {sn}, {cs};")
                lines.append(f"        sym_vsincos({print_expr(a, C_VECTOR, memo)}, &{sn}, &{cs});")
                done.add(a)
            continue
        value = print_expr(e, C_VECTOR, memo)
        if not e.free_symbols:   # a number (e.g. a length written "RL3 + 0.005"): broadcast to every lane
            value = f"(sym_vd){{0}} + {value}"
        lines.append(f"        const sym_vd {s.name} = {value};")
    return lines


def c_function(graph: ExprGraph, n_rows: int, col_names: Sequence[str], func_name: str, q: Sequence[sp.Symbol],
               dq: Sequence[sp.Symbol], ddq: Sequence[sp.Symbol], memo: dict[Any, str] | None = None, *,
               vector: bool = True, strides: tuple[int, int, int] | None = None) -> str:
    """C source of the batch function ``func_name`` (SIMD loop + scalar remainder; the scalar loop only when
    ``vector`` is False); ``memo``: see :func:`~symoro_gen.emit.printing.print_expr`. ``strides``: the
    sizes of one sample of ``q``, ``dq``, ``ddq`` (default ``n_rows`` each; a floating base's are
    ``7 + n, 6 + n, 6 + n``)."""
    sq, sdq, sddq = (n_rows,) * 3 if strides is None else strides
    size = {"q": sq, "dq": sdq, "ddq": sddq}
    col = {n: k for k, n in enumerate(col_names)}
    nc = len(col_names)
    entries = {(i, col[nm]): e for (i, nm), e in graph.outputs.items()}
    sig = "(long N, const double* q, const double* dq, const double* ddq, double* out)"

    scalar = [f"static void {func_name}_scalar{sig}", "{", "    for (long s = 0; s < N; ++s) {",
              f"        double* o = out + s * {n_rows * nc};"]
    scalar += _inputs(graph, q, dq, ddq, "double", lambda a, i: f"{a}[s * {size[a]} + {i}]")
    scalar += [f"        const double {s.name} = {print_expr(e, C_SCALAR, memo)};" for s, e in graph.defs]
    for i in range(n_rows):
        for k in range(nc):
            e = entries.get((i, k))
            scalar.append(f"        o[{i * nc + k}] = {print_expr(e, C_SCALAR, memo) if e is not None else '0.0'};")
    scalar += ["    }", "}"]
    if not vector:
        scalar[0] = f"void {func_name}{sig}"
        return "\n".join(scalar + [""])

    simd = [f"void {func_name}{sig}", "{", "    long s = 0;", "    for (; s + SYM_LANES <= N; s += SYM_LANES) {"]
    simd += _inputs(graph, q, dq, ddq, "sym_vd", lambda a, i: f"sym_vload({a} + s * {size[a]} + {i}, {size[a]})")
    simd += _vector_defs(graph, memo)
    for (i, k), e in sorted(entries.items()):
        if e.free_symbols:
            simd.append(f"        const sym_vd o{i}_{k} = {print_expr(e, C_VECTOR, memo)};")
    total = n_rows * nc
    simd += ["        for (int l = 0; l < SYM_LANES; ++l) {", f"            double* o = out + (s + l) * {total};"]
    for x in range(total):
        i, k = divmod(x, nc)
        e = entries.get((i, k))
        v = "0.0" if e is None else (f"o{i}_{k}[l]" if e.free_symbols else print_expr(e, C_SCALAR, memo))
        simd.append(f"            o[{x}] = {v};")
    simd += ["        }", "    }",
             f"    {func_name}_scalar(N - s, q + s * {sq}, dq + s * {sdq}, ddq + s * {sddq}, out + s * {n_rows * nc});",
             "}"]
    fallback = [f"void {func_name}{sig}", f"{{ {func_name}_scalar(N, q, dq, ddq, out); }}"]
    return "\n".join(scalar + ["", "#ifdef SYM_SIMD"] + simd + ["#else"] + fallback + ["#endif", ""])


def api_comment(robot: str, n: int, ncols: dict[str, int], header: str) -> str:
    """The documented API block at the top of ``regressor_<robot>.c``."""
    decl = "(long N, const double* q, const double* dq, const double* ddq, double* out);"
    lines = [
        "/*",
        *(f" * {x}" if x else " *" for x in header.splitlines()),
        " *",
        f" * Batch kernels of the identification model of `{robot}`: {n} joints.",
        " *",
        " * API (all arrays are float64, row-major, sample-major; every entry of `out` is written):",
        " *",
    ]
    for kind, pyname in KINDS:
        lines.append(f" *   void {function_name(robot, kind)}{decl}")
        lines.append(f" *       q, dq, ddq: (N, {n});  out: (N, {n}, {ncols[kind]})  columns in the order of "
                     f"{kind.upper()}_NAMES / manifest.json (Python: {pyname})")
    lines += [
        " *",
        " * Inputs are joint positions [rad or m], velocities and accelerations in the MDH convention",
        " * of the robot file. Build a shared library, e.g.:",
        f" *   cc -O3 -march=native -fPIC -shared -o libregressor_{robot}.so regressor_{robot}.c -lm",
        " * (`symoro-gen build` does this for the Python package.)",
        " */",
        "",
    ]
    return "\n".join(lines)


def c_source(robot: str, n: int, graphs: dict[str, ExprGraph], names: Mapping[str, Sequence[str]], q: Sequence[sp.Symbol],
             dq: Sequence[sp.Symbol], ddq: Sequence[sp.Symbol],
             header: str) -> str:
    """The whole ``regressor_<robot>.c``: API comment, prelude, one batch function per kind."""
    parts = [api_comment(robot, n, {k: len(v) for k, v in names.items()}, header), PRELUDE]
    memo: dict[Any, str] = {}  # each expression printed once per dialect across the three functions
    for kind, _ in KINDS:
        parts.append(c_function(graphs[kind], n, names[kind], function_name(robot, kind), q, dq, ddq, memo))
    return "\n".join(parts)
