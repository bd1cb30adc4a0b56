"""Safe parsing of the small expression language of robot files (no eval)."""
from __future__ import annotations

import ast

import sympy as sp

_FUNCS = {"sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "sqrt": sp.sqrt, "atan2": sp.atan2}
_CONSTS = {"pi": sp.pi}


class ExprError(ValueError):
    """The expression cannot be parsed; message says why."""


def parse_expression(value, symbols: dict[str, sp.Symbol]) -> sp.Expr:
    """Turn a TOML value (number or string) into a sympy expression.

    Parameters
    ----------
    value : int | float | str
        ``0.4``, ``"pi/2"``, ``"q - pi/2"``, ``"RL3"``.
    symbols : dict
        Names allowed besides ``pi`` and the functions ``sin cos tan sqrt atan2``.

    Raises
    ------
    ExprError
        Unparsable text, unknown name or a construct outside the language.
    """
    if isinstance(value, bool):
        raise ExprError(f"expected a number or an expression string, got {value!r}")
    if isinstance(value, int):
        return sp.Integer(value)
    if isinstance(value, float):
        return sp.Float(value) if value != int(value) else sp.Integer(int(value))
    if not isinstance(value, str):
        raise ExprError(f"expected a number or an expression string, got {type(value).__name__}")
    text = value.strip()
    if not text:
        raise ExprError("empty expression")
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise ExprError(f"cannot parse {value!r}: {exc.msg}") from None
    return _convert(tree.body, symbols, value)


def _convert(node, symbols, src):
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        v = node.value
        return sp.Integer(v) if isinstance(v, int) else sp.Float(v)
    if isinstance(node, ast.Name):
        if node.id in symbols:
            return symbols[node.id]
        if node.id in _CONSTS:
            return _CONSTS[node.id]
        raise ExprError(f"unknown name {node.id!r} in {src!r} (declare it under [values])")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        v = _convert(node.operand, symbols, src)
        return -v if isinstance(node.op, ast.USub) else v
    if isinstance(node, ast.BinOp):
        a = _convert(node.left, symbols, src)
        b = _convert(node.right, symbols, src)
        op = node.op
        if isinstance(op, ast.Add):
            return a + b
        if isinstance(op, ast.Sub):
            return a - b
        if isinstance(op, ast.Mult):
            return a * b
        if isinstance(op, ast.Div):
            if b == 0:
                raise ExprError(f"division by zero in {src!r}")
            return a / b
        if isinstance(op, ast.Pow):
            return a**b
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCS and not node.keywords:
        args = [_convert(a, symbols, src) for a in node.args]
        return _FUNCS[node.func.id](*args)
    raise ExprError(f"unsupported construct in {src!r}: {ast.dump(node)[:60]}")
