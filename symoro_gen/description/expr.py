"""Safe parsing of the small expression language of robot files (no eval)."""
from __future__ import annotations

import ast
import math

import sympy as sp

_FUNCS = {"sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "sqrt": sp.sqrt, "atan2": sp.atan2}
_NARGS = {"sin": 1, "cos": 1, "tan": 1, "sqrt": 1, "atan2": 2}
_CONSTS = {"pi": sp.pi}
#: longest expression text accepted (guards the parser and sympy against pathological input)
MAX_EXPRESSION_LENGTH = 400
#: largest absolute exponent accepted in ``a**b``
MAX_EXPONENT = 16
#: largest decimal order of magnitude of a numeric power ``a**b`` evaluated exactly
MAX_POWER_DIGITS = 300


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
        if not math.isfinite(value):
            raise ExprError(f"expected a finite number, got {value!r}")
        return sp.Float(value) if value != int(value) else sp.Integer(int(value))
    if not isinstance(value, str):
        raise ExprError(f"expected a number or an expression string, got {type(value).__name__}")
    text = value.strip()
    if not text:
        raise ExprError("empty expression")
    if len(text) > MAX_EXPRESSION_LENGTH:
        raise ExprError(f"expression longer than {MAX_EXPRESSION_LENGTH} characters")
    try:
        tree = ast.parse(text, mode="eval")
    except (SyntaxError, ValueError) as exc:  # ValueError: e.g. null bytes in the text
        raise ExprError(f"cannot parse {value!r}: {getattr(exc, 'msg', str(exc))}") from None
    except RecursionError:
        raise ExprError(f"cannot parse {value!r}: expression nested too deeply") from None
    result = _convert(tree.body, symbols, value)
    if result.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ExprError(f"{value!r} is not finite")
    if result.has(sp.I):
        raise ExprError(f"{value!r} is not real")
    return result


def _convert(node, symbols, src):
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        v = node.value
        if isinstance(v, float) and not math.isfinite(v):
            raise ExprError(f"number out of range in {src!r}")
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
            return _power(a, b, src)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCS and not node.keywords:
        name = node.func.id
        if len(node.args) != _NARGS[name] or any(isinstance(a, ast.Starred) for a in node.args):
            raise ExprError(f"{name}() takes {_NARGS[name]} argument(s) in {src!r}")
        args = [_convert(a, symbols, src) for a in node.args]
        return _FUNCS[name](*args)
    raise ExprError(f"{_describe(node)} not allowed in {src!r} (allowed: numbers, names, + - * / **, pi, "
                    f"{', '.join(sorted(_FUNCS))})")


def _describe(node) -> str:
    """A short human name for a construct outside the expression language."""
    if isinstance(node, ast.Attribute):
        return f"attribute access '.{node.attr}'"
    if isinstance(node, ast.Call):
        f = node.func
        if isinstance(f, ast.Name):
            return f"call of {f.id!r}" if f.id not in _FUNCS else f"keyword arguments to {f.id}()"
        return "call of a computed function"
    if isinstance(node, ast.Constant):
        return f"constant {node.value!r}"
    names = {ast.Subscript: "indexing", ast.Lambda: "lambda", ast.Compare: "comparison", ast.BoolOp: "boolean operator",
             ast.IfExp: "conditional expression", ast.List: "list", ast.Tuple: "tuple", ast.Dict: "dict",
             ast.Set: "set", ast.NamedExpr: "assignment", ast.JoinedStr: "f-string"}
    for t, n in names.items():
        if isinstance(node, t):
            return n
    if isinstance(node, ast.BinOp):
        return f"operator {type(node.op).__name__}"
    if isinstance(node, ast.UnaryOp):
        return f"operator {type(node.op).__name__}"
    return type(node).__name__


def _power(a: sp.Expr, b: sp.Expr, src) -> sp.Expr:
    """``a**b`` with a bounded numeric exponent (no exact evaluation of astronomically large numbers)."""
    if not b.is_number:
        raise ExprError(f"exponent must be a number in {src!r}")
    bv = complex(sp.N(b))
    if bv.imag != 0 or abs(bv.real) > MAX_EXPONENT:
        raise ExprError(f"exponent {b} out of range (|exponent| <= {MAX_EXPONENT}) in {src!r}")
    if a.is_number and a != 0:
        av = complex(sp.N(a))
        if abs(av) > 0 and abs(math.log10(abs(av)) * bv.real) > MAX_POWER_DIGITS:
            raise ExprError(f"number too large in {src!r}")
    return a**b
