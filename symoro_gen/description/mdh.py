"""The one home of the Khalil-Kleinfinger modified Denavit-Hartenberg (MDH) convention.

Frame j is placed on its antecedent ``a = ant(j)`` by (Khalil & Kleinfinger, "A new geometric
notation for open and closed-loop robots", ICRA 1986, eq. 1 [KK1986]; Khalil & Dombre 2002, eq. 3.6 [KD2002])::

    T(a, j) = Rot(z, gamma) Trans(z, b) Rot(x, alpha) Trans(x, d) Rot(z, theta) Trans(z, r)

so that ``R(a, j) = Rot(z, gamma) Rot(x, alpha) Rot(z, theta)`` and the origin of frame j in frame
a is ``P(a, j) = Rot(z, gamma) [d, -r sin(alpha), b + r cos(alpha)]^T``. The joint variable ``q_j``
enters ``theta`` (revolute, ``sigma = 0``) or ``r`` (prismatic, ``sigma = 1``) linearly, as
``+q_j`` or ``-q_j`` (:func:`joint_sign`); a fixed frame (``sigma = 2``) has none.

This module gives the symbolic (sympy) pieces used by the Newton-Euler model and the regrouping,
and the numeric (numpy) transform used by the numeric reference model, the URDF import and export.

Examples
--------
>>> import sympy as sp
>>> from symoro_gen.description.model import MdhRow, q_symbol
>>> row = MdhRow(j=1, ant=0, sigma=0, mu=1, gamma=sp.S(0), b=sp.S(0), alpha=sp.pi / 2,
...              d=sp.S(0), theta=q_symbol(1), r=sp.S(0))
>>> joint_sign(row)
1
>>> T = row_transform(row, {}, q=0.0)
>>> (np.round(T, 12) + 0.0).tolist()
[[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import sympy as sp
from numpy.typing import ArrayLike, NDArray

from .model import FIXED, PRISMATIC, REVOLUTE, MdhRow, q_symbol

__all__ = [
    "constant_rotation",
    "joint_sign",
    "position",
    "rot_x",
    "rot_z",
    "row_transform",
    "row_values",
    "symbolic_transform",
    "transform",
]


# ---- symbolic -------------------------------------------------------------------------------
def rot_x(a: sp.Expr | float) -> sp.Matrix:
    """Symbolic 3x3 ``Rot(x, a)``."""
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_z(a: sp.Expr | float) -> sp.Matrix:
    """Symbolic 3x3 ``Rot(z, a)``."""
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def constant_rotation(row: MdhRow) -> sp.Matrix:
    """``Rot(z, gamma) Rot(x, alpha)``: the q-independent part of ``R(ant, j)`` (before ``Rot(z, theta)``)."""
    return rot_z(row.gamma) * rot_x(row.alpha)


def position(row: MdhRow, r: sp.Expr | float | None = None) -> sp.Matrix:
    """``P(ant, j) = Rot(z, gamma) [d, -r sin(alpha), b + r cos(alpha)]^T``, origin of frame j in frame ant.

    ``r`` replaces ``row.r`` when given.
    """
    rr = row.r if r is None else r
    return rot_z(row.gamma) * sp.Matrix([row.d, -rr * sp.sin(row.alpha), row.b + rr * sp.cos(row.alpha)])


def symbolic_transform(row: MdhRow) -> sp.Matrix:
    """Symbolic 4x4 ``T(ant, j)`` of a row (joint symbol ``q<j>`` kept).

    Examples
    --------
    >>> from symoro_gen.description.model import MdhRow, q_symbol
    >>> row = MdhRow(2, 1, 1, 1, sp.S(0), sp.S(0), sp.S(0), sp.Symbol("D2"), sp.S(0), q_symbol(2))
    >>> symbolic_transform(row)[:3, 3].T
    Matrix([[D2, 0, q2]])
    """
    T = sp.eye(4)
    T[:3, :3] = constant_rotation(row) * rot_z(row.theta)
    T[:3, 3] = position(row)
    return T


def joint_sign(row: MdhRow) -> int:
    """+1 when the joint variable enters ``theta`` (revolute) or ``r`` (prismatic) as ``+q``, -1 for ``-q``.

    Examples
    --------
    >>> from symoro_gen.description.model import MdhRow, q_symbol
    >>> joint_sign(MdhRow(1, 0, 0, 1, sp.S(0), sp.S(0), sp.S(0), sp.S(0), -q_symbol(1) + sp.pi / 2, sp.S(0)))
    -1
    """
    e = row.theta if row.sigma == REVOLUTE else row.r
    return int(sp.diff(e, q_symbol(row.j)))


# ---- numeric --------------------------------------------------------------------------------
def transform(gamma: ArrayLike, b: ArrayLike, alpha: ArrayLike, d: ArrayLike, theta: ArrayLike,
              r: ArrayLike) -> NDArray[np.float64]:
    """Numeric ``T(ant, j)`` for MDH values; arguments broadcast (e.g. ``theta`` of N samples).

    Returns
    -------
    ndarray, shape ``broadcast_shape + (4, 4)`` (``(4, 4)`` for scalars)

    Examples
    --------
    >>> T = transform(0.0, 0.1, 0.0, 0.2, np.pi / 2, 0.3)
    >>> (np.round(T, 12) + 0.0).tolist()
    [[0.0, -1.0, 0.0, 0.2], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.4], [0.0, 0.0, 0.0, 1.0]]
    >>> transform(0, 0, 0, 0, np.zeros(5), 0).shape
    (5, 4, 4)
    """
    gamma, b, alpha, d, theta, r = np.broadcast_arrays(*(np.asarray(x, float) for x in (gamma, b, alpha, d, theta, r)))
    cg, sg, ca, sa, ct, st = np.cos(gamma), np.sin(gamma), np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    o, z = np.ones_like(theta), np.zeros_like(theta)
    Rg = np.stack([np.stack([cg, -sg, z], -1), np.stack([sg, cg, z], -1), np.stack([z, z, o], -1)], -2)
    Ra = np.stack([np.stack([o, z, z], -1), np.stack([z, ca, -sa], -1), np.stack([z, sa, ca], -1)], -2)
    Rt = np.stack([np.stack([ct, -st, z], -1), np.stack([st, ct, z], -1), np.stack([z, z, o], -1)], -2)
    T = np.zeros(theta.shape + (4, 4))
    T[..., :3, :3] = Rg @ Ra @ Rt
    T[..., :3, 3] = np.einsum("...ij,...j->...i", Rg, np.stack([d, -r * sa, b + r * ca], -1))
    T[..., 3, 3] = 1.0
    return T


def _num(e: sp.Expr | float, subs: Mapping[Any, Any]) -> float:
    return float(e.subs(subs)) if hasattr(e, "subs") else float(e)


def row_values(row: MdhRow, subs: Mapping[Any, Any], q: ArrayLike = 0.0) -> tuple[Any, ...]:
    """Numeric ``(gamma, b, alpha, d, theta, r)`` of a row with geometry ``subs`` and joint value ``q``.

    The joint variable is substituted in ``theta`` (revolute) or ``r`` (prismatic) as
    ``value(q=0) + joint_sign(row) * q`` (it enters linearly); ``q`` may be an array, then
    ``theta`` and ``r`` are arrays of its shape. ``q`` is ignored for a fixed frame.
    """
    gam, b, al, d = (_num(x, subs) for x in (row.gamma, row.b, row.alpha, row.d))
    q = np.asarray(q, float)
    th: float | NDArray[np.float64]
    r: float | NDArray[np.float64]
    if row.sigma in (REVOLUTE, PRISMATIC):
        zero = dict(subs)
        zero[q_symbol(row.j)] = 0
        sgn = joint_sign(row)
    if row.sigma == REVOLUTE:
        th = _num(row.theta, zero) + sgn * q
        r = np.full(q.shape, _num(row.r, subs)) if q.ndim else _num(row.r, subs)
    elif row.sigma == PRISMATIC:
        r = _num(row.r, zero) + sgn * q
        th = np.full(q.shape, _num(row.theta, subs)) if q.ndim else _num(row.theta, subs)
    else:
        assert row.sigma == FIXED
        th, r = _num(row.theta, subs), _num(row.r, subs)
        if q.ndim:
            th, r = np.full(q.shape, th), np.full(q.shape, r)
    if not q.ndim:
        th, r = float(th), float(r)
    return gam, b, al, d, th, r


def row_transform(row: MdhRow, subs: Mapping[Any, Any], q: ArrayLike = 0.0) -> NDArray[np.float64]:
    """Numeric ``T(ant, j)`` of a row at joint value(s) ``q`` (see :func:`row_values`)."""
    return transform(*row_values(row, subs, q))
