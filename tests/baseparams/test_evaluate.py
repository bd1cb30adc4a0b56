"""The numeric graph evaluator (symoro_gen.dynamics.evaluate) against independent references.

* NUMPY evaluation of the symbolic Newton–Euler graph x random parameters == numeric Newton–Euler
  (:func:`symoro_gen.dynamics.numeric.inverse_dynamics`, written without sympy) for the robots in robots/;
* EXACT evaluation at a rational state agrees with the NUMPY one;
* base-parameter detection does not import the code emitters.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from symoro_gen.description import load_robot
from symoro_gen.description.parse import robots_dir
from symoro_gen.dynamics.evaluate import (
    EXACT,
    NUMPY,
    evaluate_expr,
    evaluate_graph,
    regressor_function,
)
from symoro_gen.dynamics.graph import ExprGraph
from symoro_gen.dynamics.newton_euler import build_regressor
from symoro_gen.dynamics.numeric import inverse_dynamics

ROBOTS = sorted(p.stem for p in robots_dir().glob("*.toml"))


@pytest.mark.parametrize("name", ROBOTS)
def test_graph_evaluation_matches_numeric_newton_euler(name):
    robot = load_robot(name)
    rng = np.random.default_rng(5)
    n = robot.n_joints
    q, dq, ddq = rng.uniform(-np.pi, np.pi, (30, n)), rng.normal(0, 2, (30, n)), rng.normal(0, 5, (30, n))
    W, Wp = regressor_function(build_regressor(robot))(q, dq, ddq)
    chi = rng.normal(size=len(robot.standard_names))
    pay = rng.normal(size=len(robot.payload_names)) if robot.payload_names else None
    tau = W @ chi + (Wp @ pay if pay is not None else 0.0)
    ref = inverse_dynamics(robot, q, dq, ddq, chi, pay)
    assert np.max(np.abs(tau - ref)) <= 1e-9 * max(1.0, np.abs(ref).max())


def test_exact_and_numpy_arithmetics_agree():
    x, y = sp.symbols("x y", real=True)
    a = sp.Symbol("a", real=True)
    graph = ExprGraph((x, y), ((a, x * sp.sin(y) ** 2 - sp.cos(x + sp.pi / 3) / y),), {(0, "c"): 3 * a**2 + sp.sign(y) - x**-2})
    vals = {x: sp.Rational(3, 7), y: sp.Rational(-5, 2)}
    exact = evaluate_graph(graph, vals, arith=EXACT)[(0, "c")]
    num = evaluate_graph(graph, {k: np.array([float(v)]) for k, v in vals.items()})[(0, "c")]
    assert float(exact) == pytest.approx(num[0], rel=1e-13)
    ref = float((3 * a**2 + sp.sign(y) - x**-2).xreplace({a: graph.defs[0][1]}).xreplace(vals))
    assert num[0] == pytest.approx(ref, rel=1e-13)


def test_unknown_node_and_missing_input_are_named():
    x = sp.Symbol("x", real=True)
    with pytest.raises(TypeError, match="exp"):
        evaluate_expr(sp.exp(x), {x: 1.0}, NUMPY)
    with pytest.raises(KeyError, match="x"):
        evaluate_expr(x + 1, {}, NUMPY)


def test_baseparams_does_not_import_the_emitters():
    code = "import sys, symoro_gen.baseparams.regroup; print(sorted(m for m in sys.modules if m.startswith('symoro_gen.emit')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=Path(__file__).parents[2]).stdout.strip()
    assert out == "[]"
