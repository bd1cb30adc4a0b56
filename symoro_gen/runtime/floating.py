"""The run-time model of a floating-base robot (first layer: built in memory, NumPy kernels and a CasADi function).

:class:`FloatingModel` evaluates the floating-base Newton-Euler model of :mod:`symoro_gen.dynamics.floating`
through the same optimised graph and the same NumPy kernel printer as a fixed-base package
(:func:`symoro_gen.emit.optimize.optimize`, :func:`symoro_gen.emit.backends.numpy.kernel_source`), loaded
without writing files. Its calls take Pinocchio's free-flyer conventions (``q`` of size ``7 + n`` with the
unit quaternion ``x y z w`` at ``q[3:7]``, ``dq`` and ``ddq`` of size ``6 + n``, base velocities and
accelerations in base axes) and return ``6 + n`` rows per sample, the base wrench first (force, then
moment about the base origin, in base axes). ``FLOATING`` is True.

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
from numpy.typing import ArrayLike, NDArray

from ..baseparams.regroup import BaseParameterMap, group_base_parameters
from ..description.model import RobotDescription
from ..dynamics.floating import build_floating_regressor
from ..dynamics.graph import ExprGraph
from ..emit.backends.casadi import casadi_function
from ..emit.backends.numpy import kernel_source, load_kernel
from ..emit.optimize import optimize
from .batch import evaluate_kernel

#: a unit quaternion's norm may differ from 1 by this much (rounding of logged values)
QUATERNION_TOL = 1e-6
#: relative size below which a column's part orthogonal to the columns before it counts as zero
RANK_RTOL = 1e-9


def floating_states(robot: str, n: int, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike
                    ) -> tuple[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], bool]:
    """``((q, dq, ddq) as (N, 7 + n), (N, 6 + n), (N, 6 + n) float arrays, one_sample)``.

    Raises
    ------
    ValueError
        A shape (naming the robot, the argument and the shape expected), or a quaternion ``q[:, 3:7]``
        that is not of unit norm (naming the first such sample).
    """
    arrs = []
    for name, x, size in (("q", q, 7 + n), ("dq", dq, 6 + n), ("ddq", ddq, 6 + n)):
        a = np.asarray(x, dtype=float)
        if a.ndim == 1 and a.shape[0] == size:
            a = a[None, :]
        elif not (a.ndim == 2 and a.shape[1] == size):
            raise ValueError(f"{robot}: {name} must have shape (N, {size}) or ({size},) for a floating base with "
                             f"{n} joints, got {a.shape}")
        arrs.append(a)
    if not arrs[0].shape[0] == arrs[1].shape[0] == arrs[2].shape[0]:
        raise ValueError(f"{robot}: q, dq, ddq have different sample counts {[a.shape[0] for a in arrs]}")
    norm = np.linalg.norm(arrs[0][:, 3:7], axis=1)
    off = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_TOL)
    if off.size:
        raise ValueError(f"{robot}: q[:, 3:7] must be a unit quaternion (x y z w); sample {off[0]} has norm "
                         f"{norm[off[0]]:.9g}")
    return (arrs[0], arrs[1], arrs[2]), np.ndim(q) == 1


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


class FloatingModel:
    """The identification model of a floating-base robot (module docstring), built from its description.

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
    """

    FLOATING = True

    def __init__(self, robot: RobotDescription) -> None:
        if not robot.floating:
            raise ValueError(f"{robot.file}: base = {robot.base!r}; FloatingModel needs base = \"floating\"")
        reg = build_floating_regressor(robot)
        #: the description it was built from (the workflows take the model in place of its robot file)
        self.robot = robot
        self.ROBOT = robot.name
        self.N_JOINTS = robot.n_joints
        self.N_ROWS = 6 + robot.n_joints
        self.STANDARD_NAMES: tuple[str, ...] = tuple(reg.standard_names)
        self.PAYLOAD_NAMES: tuple[str, ...] = tuple(reg.payload_names)
        full = reg.graph.substituted(robot.geometry_subs())
        n_in = (7 + self.N_JOINTS, 6 + self.N_JOINTS)
        inputs = (full.inputs[:n_in[0]], full.inputs[n_in[0]:n_in[0] + n_in[1]],
                  full.inputs[n_in[0] + n_in[1]:n_in[0] + 2 * n_in[1]])
        memo: dict[Any, Any] = {}
        self._kernels = {}
        self._inputs = inputs
        for key, names in (("standard", self.STANDARD_NAMES), ("payload", self.PAYLOAD_NAMES)):
            g = optimize(full.pruned({k for k in full.outputs if k[1] in set(names)}), memo)
            self._kernels[key] = _kernel(g, self.N_ROWS, names, inputs, f"floating_{key}")
            if key == "standard":
                self._standard_graph = g
        self.base_map: BaseParameterMap = group_base_parameters(reg)
        self.BASE_NAMES: tuple[str, ...] = tuple(self.base_map.base_names)
        self._kept = np.array([self.STANDARD_NAMES.index(k) for k in self.base_map.kept], dtype=np.intp)
        self._K = self.base_map.matrix()

    def _eval(self, key: str, n_cols: int, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        (qa, dqa, ddqa), one = floating_states(self.ROBOT, self.N_JOINTS, q, dq, ddq)
        res = evaluate_kernel(self._kernels[key], self.N_ROWS, n_cols, qa, dqa, ddqa,
                              np.empty((qa.shape[0], self.N_ROWS, n_cols)))
        return res[0] if one else res

    def standard_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """Standard regressor ``(N, 6 + n, n_st)`` (``(6 + n, n_st)`` for 1-D inputs)."""
        return self._eval("standard", len(self.STANDARD_NAMES), q, dq, ddq)

    def payload_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """Payload regressor ``(N, 6 + n, 10)`` (0 columns without payload)."""
        return self._eval("payload", len(self.PAYLOAD_NAMES), q, dq, ddq)

    def regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """Base regressor ``(N, 6 + n, nb)``: the kept standard columns."""
        out: NDArray[np.float64] = self.standard_regressor(q, dq, ddq)[..., self._kept]
        return out

    def base_parameters(self, chi_std: ArrayLike) -> NDArray[np.float64]:
        """Base parameters of standard ones, ``K @ chi_std`` (the closed-form relations, ``base_map``)."""
        out: NDArray[np.float64] = self._K @ np.asarray(chi_std, float)
        return out

    def casadi_regressor(self) -> Any:
        """``casadi.Function regressor_<robot>(q, dq, ddq) -> Y``: the base regressor ``(6 + n) x nb`` of one
        sample (``q`` of size ``7 + n``, ``dq`` and ``ddq`` of size ``6 + n``), built from the same graph."""
        kept = [self.STANDARD_NAMES[c] for c in self._kept]
        g = self._standard_graph.pruned({k for k in self._standard_graph.outputs if k[1] in set(kept)})
        return casadi_function(g, self.N_ROWS, kept, f"regressor_{self.ROBOT}", *self._inputs)

    def torque(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike, chi_std: ArrayLike,
               chi_payload: ArrayLike | None = None) -> NDArray[np.float64]:
        """Base wrench and joint torques ``(N, 6 + n)`` (``(6 + n,)`` for 1-D inputs)."""
        y: NDArray[np.float64] = self.regressor(q, dq, ddq) @ self.base_parameters(chi_std)
        if chi_payload is not None:
            y = y + self.payload_regressor(q, dq, ddq) @ np.asarray(chi_payload, float)
        return y
