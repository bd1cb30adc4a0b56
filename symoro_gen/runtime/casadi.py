"""CasADi functions of a generated package, from its printed ``_casadi.py`` construction."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any


def build_function(construct: Callable[..., Any], name: str, n: int, ncols: int) -> Any:
    """``casadi.Function name(q, dq, ddq) -> Y`` (n x ncols) from ``construct(ca, q, dq, ddq, out)``."""
    import casadi as ca  # heavy; only needed when a CasADi function is asked for

    q, dq, ddq = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n)
    out = ca.SX.zeros(n, ncols)
    construct(ca, q, dq, ddq, out)
    return ca.Function(name, [q, dq, ddq], [out], ["q", "dq", "ddq"], ["Y"])


def build_geometry_function(construct: Callable[..., Any], name: str, n: int, n_std: int, n_g: int,
                            pairs: Sequence[tuple[int, int]]) -> Any:
    """``casadi.Function name(q, dq, ddq, chi_std) -> G`` (n x n_g), ``G[:, m] = sum_k D_(k, m) chi_std[k]``
    from ``construct(ca, q, dq, ddq, out)`` filling the (standard column, constant) pairs ``D``."""
    import casadi as ca

    q, dq, ddq, chi = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n), ca.SX.sym("chi_std", n_std)
    d = ca.SX.zeros(n, len(pairs))
    construct(ca, q, dq, ddq, d)
    out = ca.SX.zeros(n, n_g)
    for c, (k, m) in enumerate(pairs):
        out[:, m] = out[:, m] + d[:, c] * chi[k]
    return ca.Function(name, [q, dq, ddq, chi], [out], ["q", "dq", "ddq", "chi_std"], ["G"])
