"""CasADi functions of a generated package, from its printed ``_casadi.py`` construction."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any


def build_function(construct: Callable[..., Any], name: str, n: int, ncols: int) -> Any:
    """``casadi.Function name(q, dq, ddq) -> Y`` (n x ncols) from ``construct(ca, q, dq, ddq, out)``."""
    import casadi as ca  # heavy; only needed when a CasADi function is asked for

    q, dq, ddq = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n)
    out = ca.SX.zeros(n, ncols)
    construct(ca, q, dq, ddq, out)
    return ca.Function(name, [q, dq, ddq], [out], ["q", "dq", "ddq"], ["Y"])
