"""Numeric evaluation of a :class:`SymbolicRegressor` graph for the oracle tests.

The tests use the package's graph evaluator (:func:`symoro_gen.dynamics.evaluate.regressor_function`),
which walks the symbolic Newton–Euler graph without printing code: the emitters are not involved,
and the references it is compared with (Pinocchio, :mod:`symoro_gen.dynamics.numeric`) are independent.
"""
from __future__ import annotations

from symoro_gen.dynamics.evaluate import regressor_function as graph_function

__all__ = ["graph_function"]
