"""The generated package of a floating-base robot (``base = "floating"``): regressors and contact frames.

The package has the layout of a fixed-base one (:mod:`.package`): ``__init__.py`` (data bound to
:class:`symoro_gen.runtime.floating_package.GeneratedFloatingModel`), ``_kernels.py`` (NumPy),
``_casadi.py`` (CasADi constructions), one C file ``regressor_<robot>.c`` compiled on first use,
``base_parameters.md`` and ``manifest.json`` (with ``"floating": true``). Its kernels take Pinocchio's
free-flyer inputs (``q`` of ``7 + n`` values with the quaternion ``x y z w`` at ``q[3:7]``, ``dq`` and
``ddq`` of ``6 + n``; :mod:`symoro_gen.dynamics.floating`) and fill ``6 + n`` rows, the base wrench first.

Contact frames (the robot file's ``contacts``) get two more kernels each, functions of ``q`` only:

* the frame's pose in the world, ``oMf`` (4 x 4; Pinocchio's ``data.oMf``): the base pose of ``q[:7]``
  composed with the MDH transforms from frame 0 to the frame ([KK1986] eq. 1);
* its Jacobian in its own axes (6 x (6 + n), linear then angular velocity; Pinocchio's
  ``getFrameJacobian(..., LOCAL)``), the convention of
  :class:`symoro_gen.identification.floating.ContactWrench`: the base columns
  ``[[R^T, -R^T [p]x], [0, R^T]]`` (``R, p``: the frame's rotation and origin in base axes; the base twist
  is in base axes), a revolute joint ``k``'s column ``R^T (s_k z_k x (p - p_k), s_k z_k)``, a prismatic
  one's ``R^T (s_k z_k, 0)`` (``z_k, p_k``: joint axis and origin in base axes, ``s_k`` the sign of ``q_k``
  in the MDH row), [KD2002] sec. 5.6, [F2008] sec. 2.8.
"""
from __future__ import annotations

import re
from typing import Any

import sympy as sp

from ..baseparams.regroup import BaseParameterMap
from ..description.mdh import joint_sign, symbolic_transform
from ..description.model import PRISMATIC, RobotDescription, q_symbol
from ..dynamics.floating import BASE_DQ_NAMES, quaternion_rotation
from ..dynamics.graph import ExprGraph, GraphBuilder
from ..dynamics.newton_euler import SymbolicRegressor
from .backends.c import PRELUDE, c_function
from .backends.casadi import casadi_source
from .backends.numpy import MODULE_TAIL, kernel_source
from .optimize import optimize

#: kinds of regressor of a floating package, in the order of its C functions
REGRESSOR_KINDS = ("base", "standard", "payload")
#: a standard parameter's name, ``<kind><frame>``, ``R`` appended when others regroup onto it
_PARAM = re.compile(r"^([A-Z]+)(\d+)R?$")
#: column names of a contact frame's transform (4 x 4)
TRANSFORM_COLUMNS = ("c0", "c1", "c2", "c3")


def floating_inputs(reg: SymbolicRegressor) -> tuple[tuple[sp.Symbol, ...], tuple[sp.Symbol, ...],
                                                      tuple[sp.Symbol, ...]]:
    """The symbols of ``q`` (7 + n), ``dq`` (6 + n) and ``ddq`` (6 + n), in the order of the graph's inputs."""
    n = reg.robot.n_joints
    x = reg.graph.inputs
    return tuple(x[:7 + n]), tuple(x[7 + n:13 + 2 * n]), tuple(x[13 + 2 * n:19 + 3 * n])


def contact_frames(robot: RobotDescription) -> tuple[tuple[str, int], ...]:
    """``((name, frame j), ...)`` of the robot file's ``contacts``: the frame's ``name``, else ``frame<j>``."""
    return tuple((robot.row(j).name or f"frame{j}", j) for j in robot.contacts)


def _named(b: GraphBuilder, M: sp.Matrix, prefix: str) -> sp.Matrix:
    """Every entry of ``M`` expanded and named (``prefix<i><k>``)."""
    return sp.Matrix(M.shape[0], M.shape[1],
                     lambda i, k: b.name(sp.expand(M[i, k]), f"{prefix}{i}{k}"))


def _skew(p: sp.Matrix) -> sp.Matrix:
    return sp.Matrix([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])


def frame_graphs(robot: RobotDescription, j: int, q: tuple[sp.Symbol, ...]) -> tuple[ExprGraph, ExprGraph]:
    """``(transform, jacobian)`` graphs of frame ``j`` (module docstring), geometry substituted, optimised.

    ``q``: the 7 + n position inputs (:func:`floating_inputs`); the Jacobian's columns are named after
    the base's velocity inputs and the joints' ``q`` symbols.
    """
    subs = robot.geometry_subs()
    b = GraphBuilder()
    R, p = sp.eye(3), sp.zeros(3, 1)
    axes: dict[int, tuple[sp.Matrix, sp.Matrix, int, bool]] = {}
    for f in list(reversed(robot.ancestors(j))) + [j]:
        row = robot.row(f)
        T = symbolic_transform(row).xreplace(subs)
        Tn = _named(b, T[:3, :], f"T{f}_")
        p = _named(b, p + R * Tn[:, 3], f"P{f}_")
        R = _named(b, R * Tn[:, :3], f"R{f}_")
        if row.is_moving:
            axes[f] = (R[:, 2], p, joint_sign(row), row.sigma == PRISMATIC)
    Rq = _named(b, quaternion_rotation(*q[3:7]), "RQ")
    world = sp.zeros(4, 4)
    world[:3, :3] = Rq * R
    world[:3, 3] = sp.Matrix(q[:3]) + Rq * p
    world[3, 3] = 1
    outs_t = {(i, TRANSFORM_COLUMNS[k]): sp.expand(world[i, k]) for i in range(4) for k in range(4)}
    cols = tuple(BASE_DQ_NAMES) + tuple(s.name for s in q[7:])
    J = sp.zeros(6, len(cols))
    J[:3, :3] = R.T
    J[:3, 3:6] = -R.T * _skew(p)
    J[3:, 3:6] = R.T
    for f, (z, pk, sign, prismatic) in axes.items():
        c = 6 + q[7:].index(q_symbol(f))
        lin = sign * z if prismatic else sign * z.cross(p - pk)
        J[:3, c] = R.T * lin
        J[3:, c] = sp.zeros(3, 1) if prismatic else R.T * (sign * z)
    outs_j = {(i, cols[k]): sp.expand(J[i, k]) for i in range(6) for k in range(len(cols))}
    graph = ExprGraph(tuple(q), tuple(b.defs), {})
    out = []
    for outs in (outs_t, outs_j):
        nz = {k: e for k, e in outs.items() if e != 0}
        out.append(optimize(ExprGraph(graph.inputs, graph.defs, nz).pruned()))
    return out[0], out[1]


def jacobian_columns(robot: RobotDescription, q: tuple[sp.Symbol, ...]) -> tuple[str, ...]:
    """Column names of a contact Jacobian: the base's 6 velocities, then the joints (``q`` symbols)."""
    return tuple(BASE_DQ_NAMES) + tuple(s.name for s in q[7:])


def floating_kernels(reg: SymbolicRegressor, graphs: dict[str, ExprGraph], names: dict[str, tuple[str, ...]]
                     ) -> tuple[dict[str, ExprGraph], dict[str, tuple[str, ...]], dict[str, int]]:
    """The regressor graphs plus each contact frame's ``contact<k>_transform`` and ``contact<k>_jacobian``;
    returns ``(graphs, column names, rows)`` keyed by kernel kind."""
    robot = reg.robot
    q, _, _ = floating_inputs(reg)
    graphs, names = dict(graphs), dict(names)
    rows = {k: 6 + robot.n_joints for k in REGRESSOR_KINDS}
    for k, (_, j) in enumerate(contact_frames(robot)):
        graphs[f"contact{k}_transform"], graphs[f"contact{k}_jacobian"] = frame_graphs(robot, j, q)
        names[f"contact{k}_transform"], rows[f"contact{k}_transform"] = TRANSFORM_COLUMNS, 4
        names[f"contact{k}_jacobian"], rows[f"contact{k}_jacobian"] = jacobian_columns(robot, q), 6
    return graphs, names, rows


def c_name(robot: str, kind: str) -> str:
    """Exported C symbol of one kernel: ``<robot>_<kind>_regressor`` for the regressors,
    ``<robot>_contact<k>_transform`` / ``_jacobian`` for the contact frames."""
    return f"{robot}_{kind}_regressor" if kind in REGRESSOR_KINDS else f"{robot}_{kind}"


def floating_c_source(robot: RobotDescription, graphs: dict[str, ExprGraph], names: dict[str, tuple[str, ...]],
                      rows: dict[str, int], inputs: tuple[Any, Any, Any], header: str) -> str:
    """``regressor_<robot>.c`` of a floating package: API comment, prelude, one batch function per kernel."""
    n = robot.n_joints
    decl = "(long N, const double* q, const double* dq, const double* ddq, double* out);"
    lines = ["/*", *(f" * {x}" if x else " *" for x in header.splitlines()), " *",
             f" * Batch kernels of the floating-base model of `{robot.name}`: a free-flyer base and {n} joints.",
             " *", " * API (all arrays are float64, row-major, sample-major; every entry of `out` is written):",
             f" *   q: (N, {7 + n}) base position, quaternion x y z w, joints; dq, ddq: (N, {6 + n}) base",
             " *   linear and angular velocity (acceleration) in base axes, joints (Pinocchio's free-flyer).", " *"]
    for kind in graphs:
        lines.append(f" *   void {c_name(robot.name, kind)}{decl}")
        lines.append(f" *       out: (N, {rows[kind]}, {len(names[kind])})")
    lines += [" *", " * The contact kernels read q only. Build a shared library, e.g.:",
              f" *   cc -O3 -march=native -fPIC -shared -o libregressor_{robot.name}.so regressor_{robot.name}.c -lm",
              " * (`symoro-gen build` does this for the Python package.)", " */", ""]
    parts = ["\n".join(lines), PRELUDE]
    memo: dict[Any, str] = {}
    strides = (7 + n, 6 + n, 6 + n)
    for kind, g in graphs.items():
        parts.append(c_function(g, rows[kind], names[kind], c_name(robot.name, kind), *inputs, memo, strides=strides))
    return "\n".join(parts)


_MODULE_TEMPLATE = '''{header}"""Identification model of the floating-base robot `{robot}` (generated package; see
docs/generated-module.md and docs/floating-base.md).

Contract (symoro_gen.runtime.floating_package.FloatingContract; Pinocchio's free-flyer conventions)
-------------------------------------------------------------------------------------------------
q (N, 7 + n): base position, unit quaternion x y z w, joints; dq, ddq (N, 6 + n): base linear and angular
velocity (spatial acceleration) in base axes, then joints. Every regressor has N_ROWS = 6 + n rows per
sample: the base wrench (force, moment about the base origin, base axes), then the joint torques.
ROBOT, N_JOINTS, N_ROWS, FLOATING, STANDARD_NAMES, BASE_NAMES, PAYLOAD_NAMES, CONTACT_FRAMES, GRAVITY
regressor / standard_regressor / payload_regressor(q, dq, ddq) -> (N, 6 + n, ncols)
base_parameters(chi_std), torque(q, dq, ddq, chi_std[, chi_payload]) -> (N, 6 + n)
frame_transform(frame, q) -> (N, 4, 4) pose in the world (Pinocchio's oMf)
frame_jacobian(frame, q)  -> (N, 6, 6 + n) Jacobian in the frame's axes (Pinocchio's LOCAL)
casadi_regressor(), casadi_frame_transform(frame), casadi_frame_jacobian(frame) -> casadi.Function
build() -> compile regressor_{robot}.c now (otherwise on first use; NumPy kernels when that fails)
"""
from pathlib import Path as _Path

import numpy as _np

from symoro_gen.runtime.floating_package import GeneratedFloatingModel as _GeneratedFloatingModel

from . import _casadi, _kernels

ROBOT = {robot!r}
N_JOINTS = {n}
N_ROWS = {n_rows}
FLOATING = True
STANDARD_NAMES = {std!r}
BASE_NAMES = {base!r}
PAYLOAD_NAMES = {payload!r}
CONTACT_FRAMES = {contacts!r}
GEOMETRY = {geometry!r}
GRAVITY = {gravity!r}
ROBOT_FILE_SHA256 = {sha!r}
_NOMINAL = {nominal!r}
_NOMINAL_PAYLOAD = {nominal_payload!r}
# base parameter b = sum(coefficient * chi_std[index]) over ((index, coefficient), ...)
{relations}

_MODEL = _GeneratedFloatingModel(_Path(__file__).resolve().parent, ROBOT, N_JOINTS, STANDARD_NAMES, BASE_NAMES,
                                 PAYLOAD_NAMES, _RELATIONS, _kernels, _casadi, CONTACT_FRAMES)
regressor = _MODEL.regressor
standard_regressor = _MODEL.standard_regressor
payload_regressor = _MODEL.payload_regressor
base_parameters = _MODEL.base_parameters
torque = _MODEL.torque
frame_transform = _MODEL.frame_transform
frame_jacobian = _MODEL.frame_jacobian
casadi_regressor = _MODEL.casadi_regressor
casadi_frame_transform = _MODEL.casadi_frame_transform
casadi_frame_jacobian = _MODEL.casadi_frame_jacobian
build = _MODEL.build
''' + MODULE_TAIL

_CASADI_TEMPLATE = '''{header}"""CasADi constructions of `{robot}` (generated from the expression graphs).

``<kind>_casadi(ca, q, dq, ddq, out)`` fills the SX matrix ``out`` from SX vectors (q: 7 + n, dq and
ddq: 6 + n); symoro_gen.runtime.floating_package wraps them in ``casadi.Function``s.
"""


{kernels}'''


def floating_package_files(reg: SymbolicRegressor, bp: BaseParameterMap, graphs: dict[str, ExprGraph],
                           names: dict[str, tuple[str, ...]], header: str, relations_code: str
                           ) -> tuple[dict[str, str], dict[str, Any]]:
    """The code files of a floating package (``__init__.py``, ``_kernels.py``, ``_casadi.py``, the C file)
    and the manifest entries proper to it.

    ``graphs``, ``names``: the optimised regressor graphs (:func:`symoro_gen.emit.package.model_graphs`);
    ``relations_code``: the ``_RELATIONS`` table of the package's ``__init__.py``.
    """
    robot = reg.robot
    inputs = floating_inputs(reg)
    graphs, names, rows = floating_kernels(reg, graphs, names)
    printed: dict[Any, str] = {}
    files: dict[str, str] = {}
    files["_kernels.py"] = "".join(
        [header, '"""NumPy kernels (generated): fill out[row, column, sample] from (size, M) inputs."""\n',
         "import numpy as np\n"]
        + ["\n\n" + kernel_source(g, rows[k], names[k], f"{k}_kernel", *inputs, memo=printed)
           for k, g in graphs.items()])
    files[f"regressor_{robot.name}.c"] = floating_c_source(robot, graphs, names, rows, inputs,
                                                           header.replace("# ", ""))
    files["_casadi.py"] = _CASADI_TEMPLATE.format(
        header=header, robot=robot.name,
        kernels="\n\n".join(casadi_source(g, names[k], f"{k}_casadi", *inputs) for k, g in graphs.items()))
    contacts = contact_frames(robot)
    files["__init__.py"] = _MODULE_TEMPLATE.format(
        header=header, robot=robot.name, n=robot.n_joints, n_rows=6 + robot.n_joints,
        std=tuple(reg.standard_names), base=tuple(bp.base_names), payload=tuple(reg.payload_names),
        contacts=tuple(nm for nm, _ in contacts),
        geometry={k: float(v) for k, v in sorted(robot.values.items())},
        gravity=tuple(float(x) for x in robot.gravity), sha=robot.file_hash,
        nominal=robot.nominal_vector(), nominal_payload=robot.nominal_payload(), relations=relations_code)
    manifest: dict[str, Any] = {
        "floating": True,
        "n_rows": 6 + robot.n_joints,
        "input_sizes": {"q": 7 + robot.n_joints, "dq": 6 + robot.n_joints, "ddq": 6 + robot.n_joints},
        "contact_frames": [{"name": nm, "frame": j, "transform": c_name(robot.name, f"contact{k}_transform"),
                            "jacobian": c_name(robot.name, f"contact{k}_jacobian")}
                           for k, (nm, j) in enumerate(contacts)],
        "jacobian_convention": "LOCAL (frame axes; linear then angular velocity)",
        "geometry_derivative": {"omitted": "not generated for a floating base"},
    }
    return files, manifest


def floating_relations_markdown(bp: BaseParameterMap) -> str:
    """The section of ``base_parameters.md`` proper to a floating base."""
    on_base = [n for n in bp.base_names if (m := _PARAM.match(n)) is not None and m.group(2) == "0"]
    return "\n".join([
        "## Floating base", "",
        "Frame 0 is a free body (Pinocchio's free-flyer): its 10 inertial parameters (`XX0 .. M0`) are "
        "unknowns, and what regroups onto frame 0 stays on the base link. Rows: the base wrench "
        "(`FX0 .. MZ0`), then the joint torques. Gravity enters through the base orientation.", "",
        "Base parameters of the base link: " + (", ".join(on_base) or "none") + ".", ""])
