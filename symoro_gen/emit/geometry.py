"""Emit the geometry derivative of the standard regressor (``_geometry.py``, ``geometry_<robot>.c``).

The derivative ``dY_std/dg`` at the nominal geometry (:mod:`symoro_gen.dynamics.sensitivity`) is printed
like the regressors: one NumPy kernel and one CasADi construction in ``_geometry.py``, one batch C
function ``<robot>_geometry_derivative`` in its own C file (compiled only when asked for, so the
regressor library is unchanged). The kernels fill the structurally non-zero ``(standard column,
constant)`` pairs only, ``GEOMETRY_PAIRS``; :class:`symoro_gen.runtime.GeneratedModel` scatters them
into the full ``(N, n, n_std, n_g)`` array.
"""
from __future__ import annotations

from typing import Any

from ..description.model import RobotDescription
from ..dynamics.graph import ExprGraph
from ..dynamics.sensitivity import GeometrySensitivity, geometry_sensitivity
from .backends.c import c_function
from .backends.casadi import casadi_source
from .backends.numpy import kernel_source

_C_PRELUDE = """#include <math.h>

static inline double sym_sign(double x) { return (double)((x > 0.0) - (x < 0.0)); }
"""

#: robots with more frames than this get no geometry derivative (generation time and file size). Measured on
#: the largest shipped robot, the SDA10F (15 frames, a tree): 29 282 definitions, generation ~9 s, a 2.9 MB C
#: file compiled in ~8 s at -O0 and a 4 MB ``_geometry.py`` (the LWR4, 8 frames: 3 s, 0.7 MB, 2 s); both well
#: within a minute, so every shipped robot has one; the bound keeps an arm of many more frames from a C file
#: that would take minutes
MAX_FRAMES = 16


def geometry_c_function(robot: str) -> str:
    """Exported C symbol of the geometry derivative, e.g. ``lwr4_geometry_derivative``."""
    return f"{robot}_geometry_derivative"


def geometry_c_file(robot: str) -> str:
    return f"geometry_{robot}.c"


def _pairs(sens: GeometrySensitivity, standard_names: tuple[str, ...]) -> list[tuple[str, str]]:
    """The structurally non-zero ``(standard column, constant)`` pairs, standard-major."""
    nz = {k[1] for k in sens.graph.outputs}
    return [(c, g) for c in standard_names for g in sens.names if (c, g) in nz]


_PY_TEMPLATE = '''{header}"""Derivative of the standard regressor of `{robot}` w.r.t. its geometric constants (generated).

dY_std/dg at the nominal geometry (symoro_gen.dynamics.sensitivity; docs/generated-module.md): entry
[i, k] of GEOMETRY_PAIRS order is d Y_std[row i, column GEOMETRY_PAIRS[k][0]] / d GEOMETRY_NAMES[GEOMETRY_PAIRS[k][1]].
Constants are MDH fields of a frame: d<j>, r<j> [m], alpha<j>, theta<j> [rad]; theta<j> of a revolute
joint and r<j> of a prismatic one are its joint zero.
"""
import numpy as np

GEOMETRY_NAMES = {names!r}
# (frame, MDH field) of each name
GEOMETRY_FRAMES = {frames!r}
# constants whose derivative is identically zero (left out)
GEOMETRY_DROPPED = {dropped!r}
# (standard column index, GEOMETRY_NAMES index) of each kernel column
GEOMETRY_PAIRS = {pairs!r}


{kernel}

{casadi}'''


def geometry_files(robot: RobotDescription, header: str) -> tuple[dict[str, str], dict[str, Any]]:
    """Files ``_geometry.py`` and ``geometry_<robot>.c`` and the manifest entry ``geometry_derivative``.

    A robot with more than :data:`MAX_FRAMES` frames gets none: ``({}, {"omitted": reason})``.
    """
    if len(robot.rows) > MAX_FRAMES:
        return {}, {"omitted": (f"{len(robot.rows)} frames, more than {MAX_FRAMES}: the derivative's generation "
                                "time and size would dominate the package's")}
    sens = geometry_sensitivity(robot)
    std = tuple(robot.standard_names)
    pairs = _pairs(sens, std)
    cols = [f"{c}:{g}" for c, g in pairs]  # the kernels' column names
    graph = ExprGraph(sens.graph.inputs, sens.graph.defs,
                      {(i, f"{c}:{g}"): e for (i, (c, g)), e in sens.graph.outputs.items()})
    n = robot.n_joints
    qs = (robot.q, robot.dq, robot.ddq)
    col = {c: k for k, c in enumerate(std)}
    gi = {g: k for k, g in enumerate(sens.names)}
    files = {"_geometry.py": _PY_TEMPLATE.format(
        header=header, robot=robot.name, names=sens.names, frames=tuple(sens.frames[g] for g in sens.names),
        dropped=sens.dropped, pairs=tuple((col[c], gi[g]) for c, g in pairs),
        kernel=kernel_source(graph, n, cols, "geometry_kernel", *qs).rstrip("\n"),
        casadi=casadi_source(graph, cols, "geometry_casadi", *qs))}
    cname = geometry_c_function(robot.name)
    api = "\n".join([
        "/*", *(f" * {x}" if x else " *" for x in header.replace("# ", "").splitlines()), " *",
        f" * Derivative of the standard regressor of `{robot.name}` w.r.t. its geometric constants, at the",
        " * nominal geometry (GEOMETRY_NAMES, GEOMETRY_PAIRS of _geometry.py / manifest.json):",
        f" *   void {cname}(long N, const double* q, const double* dq, const double* ddq, double* out);",
        f" *       q, dq, ddq: (N, {n});  out: (N, {n}, {len(pairs)}), column k = pair k of GEOMETRY_PAIRS",
        " * float64, row-major, sample-major; every entry of `out` is written.", " */", ""])
    files[geometry_c_file(robot.name)] = "\n".join([api, _C_PRELUDE, c_function(graph, n, cols, cname, *qs, vector=False)])
    manifest = {"names": list(sens.names), "dropped": list(sens.dropped), "pairs": len(pairs),
                "c_file": geometry_c_file(robot.name), "c_function": cname,
                "definitions": len(sens.graph.defs)}
    return files, manifest
