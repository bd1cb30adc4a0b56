"""The run-time model of a floating-base robot built in memory (NumPy kernels and CasADi functions).

:class:`FloatingModel` evaluates the floating-base Newton-Euler model of :mod:`symoro_gen.dynamics.floating`
through the same optimised graph and the same NumPy kernel printer as a fixed-base package
(:func:`symoro_gen.emit.optimize.optimize`, :func:`symoro_gen.emit.backends.numpy.kernel_source`), loaded
without writing files. Its calls take Pinocchio's free-flyer conventions (``q`` of size ``7 + n`` with the
unit quaternion ``x y z w`` at ``q[3:7]``, ``dq`` and ``ddq`` of size ``6 + n``, base velocities and
accelerations in base axes) and return ``6 + n`` rows per sample, the base wrench first (force, then
moment about the base origin, in base axes). ``FLOATING`` is True. The evaluation, and the contact
frames' poses and Jacobians (:mod:`symoro_gen.emit.floating`), are those of
:class:`~symoro_gen.runtime.floating_package.FloatingContract`, shared with the generated package of the
same robot (``symoro-gen generate``), which ``load_model`` returns when there is one.

Base parameters: the closed-form rules of :func:`symoro_gen.baseparams.regroup.group_base_parameters`
([GK1990]) on the floating tree, where what regroups onto frame 0 stays on the base link (``base_map``: the
relations, with the geometry symbolic). :func:`numeric_base` is the independent numeric reference (the
independent columns of the standard regressor stacked over random states, found in ``STANDARD_NAMES`` order
by Gram-Schmidt, [G1991]).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import sympy as sp
from numpy.typing import NDArray

from ..baseparams.regroup import BaseParameterMap, group_base_parameters
from ..description.model import RobotDescription
from ..dynamics.floating import build_floating_regressor
from ..dynamics.graph import ExprGraph
from ..emit.backends.casadi import casadi_function
from ..emit.backends.numpy import kernel_source, load_kernel
from ..emit.floating import floating_kernels
from ..emit.optimize import optimize
from .batch import evaluate_kernel
from .floating_package import QUATERNION_TOL as QUATERNION_TOL
from .floating_package import FloatingContract
from .floating_package import floating_states as floating_states

#: relative size below which a column's part orthogonal to the columns before it counts as zero
RANK_RTOL = 1e-9


def _kernel(graph: ExprGraph, n_rows: int, names: tuple[str, ...],
            inputs: tuple[tuple[sp.Symbol, ...], tuple[sp.Symbol, ...], tuple[sp.Symbol, ...]],
            func_name: str) -> Callable[..., Any]:
    """The NumPy kernel ``func_name(q, dq, ddq, out)`` of ``graph``, the arrays' rows being ``inputs``."""
    return load_kernel(kernel_source(graph, n_rows, names, func_name, *inputs), func_name)


def numeric_base(W: NDArray[np.float64], rtol: float = RANK_RTOL) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Independent columns of ``W`` (rows: samples x equations) and the relations of the others.

    Returns
    -------
    (kept, K)
        ``kept``: indices of the independent columns, in column order (a column is kept when the norm of
        its part orthogonal to the kept columns before it exceeds ``rtol`` times its own norm; structurally
        zero columns are dropped); ``K`` (len(kept), n_columns): ``W = W[:, kept] @ K``, so that the base
        parameters of standard parameters ``chi`` are ``K @ chi``.
    """
    norms = np.linalg.norm(W, axis=0)
    nonzero = norms > rtol * max(norms.max(initial=0.0), 1e-300)
    kept: list[int] = []
    basis = np.zeros((W.shape[0], 0))
    for c in np.flatnonzero(nonzero):
        x = W[:, c] / norms[c]
        r = x - basis @ (basis.T @ x)
        r -= basis @ (basis.T @ r)  # re-orthogonalised once (Gram-Schmidt twice is enough)
        nr = np.linalg.norm(r)
        if nr > rtol:
            kept.append(int(c))
            basis = np.hstack([basis, (r / nr)[:, None]])
    kept_arr = np.asarray(kept, dtype=np.intp)
    # W[:, kept] = basis @ Rk with Rk upper triangular (Gram-Schmidt): K = Rk^-1 basis^T W
    K = np.linalg.solve(basis.T @ W[:, kept_arr], basis.T @ W)
    K[np.abs(K) < 1e-10 * max(np.abs(K).max(initial=0.0), 1.0)] = 0.0
    return kept_arr, K


class FloatingModel(FloatingContract):
    """The identification model of a floating-base robot (module docstring), built from its description.

    The evaluation is :class:`~symoro_gen.runtime.floating_package.FloatingContract`'s, shared with the
    generated package (:class:`~symoro_gen.runtime.floating_package.GeneratedFloatingModel`).

    Attributes
    ----------
    ROBOT : str
    base_map : BaseParameterMap
        The closed-form relations of the base parameters (geometry symbolic).
    FLOATING : bool
        True.
    N_JOINTS : int
        Number of joints ``n`` (the base's 6 degrees of freedom not counted).
    N_ROWS : int
        ``6 + n``: rows per sample of every regressor (base wrench ``FX0 FY0 FZ0 MX0 MY0 MZ0``, then joints).
    STANDARD_NAMES, BASE_NAMES, PAYLOAD_NAMES : tuple of str
        ``BASE_NAMES``: the kept standard columns, suffixed ``R`` when others are regrouped onto them.
    CONTACT_FRAMES : tuple of str
        The robot file's contact frames (``frame_transform``, ``frame_jacobian``).
    """

    def __init__(self, robot: RobotDescription) -> None:
        if not robot.floating:
            raise ValueError(f"{robot.file}: base = {robot.base!r}; FloatingModel needs base = \"floating\"")
        reg = build_floating_regressor(robot)
        #: the description it was built from (the workflows take the model in place of its robot file)
        self.robot = robot
        self.ROBOT = robot.name
        self.N_JOINTS = robot.n_joints
        self.N_ROWS = 6 + robot.n_joints
        self.STANDARD_NAMES = tuple(reg.standard_names)
        self.PAYLOAD_NAMES = tuple(reg.payload_names)
        full = reg.graph.substituted(robot.geometry_subs())
        n_in = (7 + self.N_JOINTS, 6 + self.N_JOINTS)
        inputs = (full.inputs[:n_in[0]], full.inputs[n_in[0]:n_in[0] + n_in[1]],
                  full.inputs[n_in[0] + n_in[1]:n_in[0] + 2 * n_in[1]])
        memo: dict[Any, Any] = {}
        self._kernels: dict[str, Callable[..., Any]] = {}
        self._inputs = inputs
        graphs: dict[str, ExprGraph] = {}
        names = {"standard": self.STANDARD_NAMES, "payload": self.PAYLOAD_NAMES}
        for key, cols in names.items():
            graphs[key] = optimize(full.pruned({k for k in full.outputs if k[1] in set(cols)}), memo)
        self._standard_graph = graphs["standard"]
        graphs.pop("base", None)
        graphs, names, rows = floating_kernels(reg, graphs, names)
        self._graphs, self._names, self._rows = graphs, names, rows
        for key, g in graphs.items():
            self._kernels[key] = _kernel(g, rows[key], names[key], inputs, f"floating_{key}")
        self.CONTACT_FRAMES = tuple(robot.row(j).name or f"frame{j}" for j in robot.contacts)
        self.base_map: BaseParameterMap = group_base_parameters(reg)
        self.BASE_NAMES = tuple(self.base_map.base_names)
        self._kept = np.array([self.STANDARD_NAMES.index(k) for k in self.base_map.kept], dtype=np.intp)
        self._K = self.base_map.matrix()

    def _fill(self, kind: str, q: NDArray[np.float64], dq: NDArray[np.float64], ddq: NDArray[np.float64],
              res: NDArray[np.float64]) -> None:
        if kind == "base":  # the kept standard columns
            std = np.zeros((q.shape[0], self.N_ROWS, len(self.STANDARD_NAMES)))
            evaluate_kernel(self._kernels["standard"], self.N_ROWS, std.shape[2], q, dq, ddq, std)
            res[...] = std[..., self._kept]
        else:
            evaluate_kernel(self._kernels[kind], res.shape[1], res.shape[2], q, dq, ddq, res)

    def casadi_regressor(self) -> Any:
        """``casadi.Function regressor_<robot>(q, dq, ddq) -> Y``: the base regressor ``(6 + n) x nb`` of one
        sample (``q`` of size ``7 + n``, ``dq`` and ``ddq`` of size ``6 + n``), built from the same graph."""
        kept = [self.STANDARD_NAMES[c] for c in self._kept]
        g = self._standard_graph.pruned({k for k in self._standard_graph.outputs if k[1] in set(kept)})
        return casadi_function(g, self.N_ROWS, kept, f"regressor_{self.ROBOT}", *self._inputs)

    def _casadi_frame(self, what: str, frame: str | int) -> Any:
        import casadi as ca  # heavy; only needed when a CasADi function is asked for

        k = self.contact_index(frame)
        kind = f"contact{k}_{what}"
        name = f"{what}_{self.ROBOT}_contact{k}"
        f = casadi_function(self._graphs[kind], self._rows[kind], self._names[kind], name, *self._inputs)
        q, z = ca.SX.sym("q", 7 + self.N_JOINTS), ca.SX.zeros(6 + self.N_JOINTS)
        return ca.Function(name, [q], [f(q, z, z)], ["q"], ["Y"])

    def casadi_frame_transform(self, frame: str | int) -> Any:
        """``casadi.Function transform_<robot>_contact<k>(q) -> T`` (4 x 4): :meth:`frame_transform`."""
        return self._casadi_frame("transform", frame)

    def casadi_frame_jacobian(self, frame: str | int) -> Any:
        """``casadi.Function jacobian_<robot>_contact<k>(q) -> J`` (6 x (6 + n)): :meth:`frame_jacobian`."""
        return self._casadi_frame("jacobian", frame)
