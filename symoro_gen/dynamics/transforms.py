"""Khalil-Kleinfinger transforms, symbolic (sympy) and numeric (numpy)."""
from __future__ import annotations

import numpy as np
import sympy as sp

from ..description.model import MdhRow


def rot_x(a):
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_z(a):
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def constant_rotation(row: MdhRow) -> sp.Matrix:
    """Rot(z, gamma) Rot(x, alpha): the q-independent part of ant_R_j (before Rot(z, theta))."""
    return rot_z(row.gamma) * rot_x(row.alpha)


def position(row: MdhRow, r=None) -> sp.Matrix:
    """ant_P_j, origin of frame j in frame ant."""
    rr = row.r if r is None else r
    return rot_z(row.gamma) * sp.Matrix([row.d, -rr * sp.sin(row.alpha), row.b + rr * sp.cos(row.alpha)])


# ---- numeric ---------------------------------------------------------------
def _nrot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _nrot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def numeric_transform(gamma, b, alpha, d, theta, r):
    """4x4 homogeneous ant_T_j for numeric MDH values."""
    R = _nrot_z(gamma) @ _nrot_x(alpha) @ _nrot_z(theta)
    P = _nrot_z(gamma) @ np.array([d, -r * np.sin(alpha), b + r * np.cos(alpha)])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = P
    return T
