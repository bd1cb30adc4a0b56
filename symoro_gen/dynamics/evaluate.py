"""Evaluate an :class:`~symoro_gen.dynamics.graph.ExprGraph` without printing code.

The graph's definitions are evaluated in order, then its outputs, by walking the sympy
expression trees node by node (``Add``, ``Mul``, ``Pow``, ``sin``, ``cos``, ``sign``,
symbols and numbers: what the customized Newton–Euler of
:mod:`symoro_gen.dynamics.newton_euler` produces, Khalil & Dombre 2002, ch. 9). Nothing is
printed, ``exec``-ed or lambdified: base-parameter detection and the tests evaluate the
model here, independently of the code emitters.

Two arithmetics share the walker:

* :data:`NUMPY` — float arrays, vectorised over a batch of samples (inputs of shape ``(N,)``
  or scalars, which broadcast);
* :data:`EXACT` — sympy values (exact rationals, symbolic constants such as the geometry and
  gravity), each definition expanded once; used to solve regrouping coefficients exactly.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from functools import reduce
from typing import Any

import numpy as np
import sympy as sp

from .graph import ExprGraph
from .newton_euler import SymbolicRegressor


@dataclass(frozen=True)
class Arithmetic:
    """The operations the walker uses for one kind of value.

    Attributes
    ----------
    number : callable
        Maps a sympy number (``Integer``, ``Rational``, ``Float``, ``pi``, ``sqrt(2)`` ...) to a value.
    add, mul : callable
        Sum and product of a list of values.
    power : callable
        ``power(x, n)`` for an integer ``n`` (negative allowed).
    functions : dict
        sympy function class -> unary callable on values.
    finish : callable
        Applied to the value of each definition and output (e.g. ``sympy.expand``).
    """

    number: Callable[[sp.Expr], Any]
    add: Callable[[list], Any]
    mul: Callable[[list], Any]
    power: Callable[[Any, int], Any]
    functions: Mapping[type, Callable[[Any], Any]]
    finish: Callable[[Any], Any] = lambda v: v


def _np_sum(xs: list) -> Any:
    return reduce(np.add, xs)


def _np_prod(xs: list) -> Any:
    return reduce(np.multiply, xs)


def _np_power(x: Any, n: int) -> Any:
    if n == 1:
        return x
    if n == -1:
        return 1.0 / x
    return np.power(x, float(n)) if n < 0 else x**n


NUMPY = Arithmetic(
    number=float,
    add=_np_sum,
    mul=_np_prod,
    power=_np_power,
    functions={sp.sin: np.sin, sp.cos: np.cos, sp.tan: np.tan, sp.sign: np.sign, sp.Abs: np.abs, sp.sqrt: np.sqrt},
)
"""Float NumPy arithmetic, vectorised over samples."""


def _exact_trig(f: type) -> Callable[[sp.Expr], sp.Expr]:
    def apply(x: sp.Expr) -> sp.Expr:
        return sp.expand(sp.expand_trig(f(x)))

    return apply


def _exact_number(e: sp.Expr) -> sp.Expr:
    return sp.nsimplify(e, rational=True) if e.has(sp.Float) else e


EXACT = Arithmetic(
    number=_exact_number,
    add=lambda xs: sp.Add(*xs),
    mul=lambda xs: sp.Mul(*xs),
    power=lambda x, n: x**n,
    functions={sp.sin: _exact_trig(sp.sin), sp.cos: _exact_trig(sp.cos), sp.sign: sp.sign, sp.Abs: sp.Abs},
    finish=sp.expand,
)
"""Exact sympy arithmetic (values may keep symbols; floats of the graph become the rationals
they print as); ``sin``/``cos`` of a sum are expanded so
that ``sin(Q)``, ``cos(Q)`` of an angle symbol can be replaced by exact values afterwards."""


def evaluate_expr(e: sp.Expr, env: Mapping[sp.Symbol, Any], arith: Arithmetic = NUMPY) -> Any:
    """Value of the sympy expression ``e`` with symbols taken from ``env``.

    Raises
    ------
    KeyError
        A symbol of ``e`` has no value in ``env``.
    TypeError
        ``e`` contains a node the evaluator does not know (named in the message).
    """
    if e.is_Symbol:
        try:
            return env[e]
        except KeyError:
            raise KeyError(f"no value for the graph input {e}") from None
    if e.is_number and not e.free_symbols:
        return arith.number(e)
    if e.is_Add:
        return arith.add([evaluate_expr(a, env, arith) for a in e.args])
    if e.is_Mul:
        return arith.mul([evaluate_expr(a, env, arith) for a in e.args])
    if e.is_Pow:
        base, ex = e.args
        if ex.is_Integer:
            return arith.power(evaluate_expr(base, env, arith), int(ex))
        if ex == sp.S.Half and sp.sqrt in arith.functions:
            return arith.functions[sp.sqrt](evaluate_expr(base, env, arith))
        raise TypeError(f"cannot evaluate the power {e} (only integer exponents and square roots)")
    f = arith.functions.get(e.func)
    if f is not None and len(e.args) == 1:
        return f(evaluate_expr(e.args[0], env, arith))
    raise TypeError(f"cannot evaluate {e.func.__name__} in {e}")


def evaluate_graph(
    graph: ExprGraph,
    values: Mapping[sp.Symbol, Any],
    keys: Iterable | None = None,
    arith: Arithmetic = NUMPY,
) -> dict:
    """Evaluate the definitions of ``graph`` in order, then the outputs ``keys``.

    Parameters
    ----------
    graph : ExprGraph
    values : mapping
        Value of every input symbol the needed definitions use (arrays of shape ``(N,)`` or
        scalars with :data:`NUMPY`; sympy values with :data:`EXACT`).
    keys : iterable, optional
        Output keys to evaluate (default: all); only the definitions they need are evaluated.
    arith : Arithmetic
        :data:`NUMPY` (default) or :data:`EXACT`.

    Returns
    -------
    dict
        ``key -> value`` for the requested outputs.
    """
    g = graph.pruned(set(keys)) if keys is not None else graph.pruned()
    env: dict[sp.Symbol, Any] = dict(values)
    for s, e in g.defs:
        env[s] = arith.finish(evaluate_expr(e, env, arith))
    return {k: arith.finish(evaluate_expr(e, env, arith)) for k, e in g.outputs.items()}


def evaluate_columns(
    graph: ExprGraph,
    n_rows: int,
    names: Iterable[str],
    values: Mapping[sp.Symbol, Any],
    n_samples: int,
) -> np.ndarray:
    """Regressor columns ``names`` of ``graph`` (outputs keyed ``(row, name)``) as an array.

    Parameters
    ----------
    graph : ExprGraph
    n_rows : int
        Number of joint rows.
    names : iterable of str
        Column names, in the order of the result's last axis.
    values : mapping
        Input values, arrays of shape ``(n_samples,)`` or scalars.
    n_samples : int

    Returns
    -------
    numpy.ndarray
        Shape ``(n_samples, n_rows, len(names))``; entries without an output are 0.
    """
    names = list(names)
    col = {n: i for i, n in enumerate(names)}
    keys = [k for k in graph.outputs if k[1] in col]
    W = np.zeros((n_samples, n_rows, len(names)))
    for (i, name), v in evaluate_graph(graph, values, keys).items():
        W[:, i, col[name]] = v
    return W


def regressor_function(reg: SymbolicRegressor) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``f(q, dq, ddq) -> (W_std, W_payload)`` evaluating the regressor graph of ``reg``.

    The geometric constants take their values from ``reg.robot``; nothing is printed or
    compiled (the graph is walked by :func:`evaluate_graph` at each call).

    Returns
    -------
    callable
        ``f(q, dq, ddq)`` with inputs of shape (N, n) (or (n,)) returning arrays of shapes
        (N, n, len(standard_names)) and (N, n, len(payload_names)).
    """
    robot = reg.robot
    n = len(reg.joint_frames)
    names = list(reg.standard_names) + list(reg.payload_names)
    n_std = len(reg.standard_names)
    known = set(robot.q) | set(robot.dq) | set(robot.ddq) | set(robot.geometry_subs())
    leftover = set(reg.graph.inputs) - known
    if leftover:
        raise ValueError(f"graph inputs without values: {sorted(map(str, leftover))}")

    def evaluate(q, dq, ddq):
        q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
        N = q.shape[0]
        values: dict = dict(robot.geometry_subs())
        for k in range(n):
            values[robot.q[k]], values[robot.dq[k]], values[robot.ddq[k]] = q[:, k], dq[:, k], ddq[:, k]
        W = evaluate_columns(reg.graph, n, names, values, N)
        return W[..., :n_std], W[..., n_std:]

    return evaluate
