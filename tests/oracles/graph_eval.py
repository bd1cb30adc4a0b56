"""Numeric evaluation of a :class:`SymbolicRegressor` graph (a test helper, not the emitter).

The geometric constants are substituted by their values, then the intermediate definitions
are evaluated in order and the outputs assembled into regressor arrays. ``sympy.lambdify``
prints the definitions as the body of one function (its ``cse`` hook receives the graph's
own assignments), so nothing is expanded into one giant expression.
"""
from __future__ import annotations

import numpy as np
import sympy as sp

from symoro_gen.dynamics.newton_euler import SymbolicRegressor


def graph_function(sym: SymbolicRegressor):
    """Compile the regressor graph into ``f(q, dq, ddq) -> (W_std, W_payload)``.

    Returns
    -------
    callable
        ``f(q, dq, ddq)`` with inputs of shape (N, n) returning arrays of shapes
        (N, n, len(standard_names)) and (N, n, len(payload_names)).
    """
    robot = sym.robot
    graph = sym.graph.substituted(robot.geometry_subs())
    defs = list(graph.defs)
    keys = sorted(graph.outputs, key=lambda k: (k[0], k[1]))
    n = len(sym.joint_frames)
    joint_inputs = [*robot.q, *robot.dq, *robot.ddq]
    leftover = set(graph.inputs) - set(joint_inputs)
    if leftover:
        raise ValueError(f"graph inputs without values: {sorted(map(str, leftover))}")
    fn = sp.lambdify(joint_inputs, [graph.outputs[k] for k in keys], modules="numpy", cse=lambda e: (defs, e))
    col_std = {name: i for i, name in enumerate(sym.standard_names)}
    col_pay = {name: i for i, name in enumerate(sym.payload_names)}

    def evaluate(q, dq, ddq):
        q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
        N = q.shape[0]
        vals = fn(*q.T, *dq.T, *ddq.T)
        W = np.zeros((N, n, len(col_std)))
        Wp = np.zeros((N, n, len(col_pay)))
        for (i, name), v in zip(keys, vals):
            v = np.broadcast_to(np.asarray(v, float), (N,))
            if name in col_std:
                W[:, i, col_std[name]] = v
            else:
                Wp[:, i, col_pay[name]] = v
        return W, Wp

    return evaluate
