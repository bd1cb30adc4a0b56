"""The one home of the inertial-parameter conventions.

A rigid link j carries ten *standard inertial parameters*, in frame j at its origin
(Khalil & Kleinfinger 1986; Khalil & Dombre, *Modeling, Identification and Control of Robots*,
2002, Sec. 9.3), in the order of :data:`symoro_gen.params.INERTIAL_KINDS`::

    XX XY XZ YY YZ ZZ MX MY MZ M

``XX..ZZ`` are the six distinct entries of the inertia matrix ``J_O`` about the frame origin
(``J_O = [[XX, XY, XZ], [XY, YY, YZ], [XZ, YZ, ZZ]]``), ``MS = (MX, MY, MZ) = M c`` the first
moments (``c`` the centre of mass in frame j) and ``M`` the mass. The same body described at its
centre of mass is ``(M, c, I_c)``; the two are related by the parallel-axis (Huygens-Steiner)
theorem ``J_O = I_c + M (|c|^2 E - c c^T)``.

Physical consistency (Wensing, Kim & Slotine, "Linear matrix inequalities for physically
consistent inertial parameter identification", IEEE RA-L 2017): the ten parameters are those of a
rigid body with a (non-degenerate) mass distribution iff the 4x4 *pseudo-inertia*
``P = [[Sigma, h], [h^T, M]]``, ``Sigma = tr(J_O)/2 E - J_O``, ``h = MS``, is positive definite;
equivalently ``M > 0``, ``I_c`` positive definite and its principal moments satisfy the triangle
inequalities.

Examples
--------
A 2 kg point-like body 0.5 m along x (no inertia about its centre of mass):

>>> p = standard_from_com(2.0, [0.5, 0.0, 0.0], np.zeros((3, 3)))
>>> p.tolist()
[0.0, 0.0, 0.0, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 2.0]
>>> m, c, I_c = com_from_standard(p)
>>> float(m), c.tolist(), bool(np.allclose(I_c, 0))
(2.0, [0.5, 0.0, 0.0], True)
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..params import INERTIAL_KINDS

__all__ = [
    "INERTIAL_KINDS",
    "check_physical_consistency",
    "com_from_standard",
    "matrix_from_six",
    "parallel_axis",
    "pseudo_inertia",
    "six_from_matrix",
    "standard_from_com",
]


def matrix_from_six(v6: ArrayLike) -> np.ndarray:
    """Symmetric 3x3 inertia matrix from its six entries ``XX XY XZ YY YZ ZZ``.

    Parameters
    ----------
    v6 : array_like, shape (6,) (or the first six of a 10-vector)

    Returns
    -------
    ndarray, shape (3, 3)

    Examples
    --------
    >>> matrix_from_six([1, 2, 3, 4, 5, 6]).tolist()
    [[1.0, 2.0, 3.0], [2.0, 4.0, 5.0], [3.0, 5.0, 6.0]]
    """
    XX, XY, XZ, YY, YZ, ZZ = (float(x) for x in np.asarray(v6, dtype=float)[:6])
    return np.array([[XX, XY, XZ], [XY, YY, YZ], [XZ, YZ, ZZ]])


def six_from_matrix(J: ArrayLike) -> np.ndarray:
    """The six entries ``XX XY XZ YY YZ ZZ`` of a 3x3 inertia matrix (upper triangle, row by row).

    Examples
    --------
    >>> six_from_matrix(matrix_from_six([1, 2, 3, 4, 5, 6])).tolist()
    [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    """
    J = np.asarray(J, float)
    return np.array([J[0, 0], J[0, 1], J[0, 2], J[1, 1], J[1, 2], J[2, 2]])


def parallel_axis(I_c: ArrayLike, m: float, c: ArrayLike) -> np.ndarray:
    """Inertia about a point from the inertia about the centre of mass (parallel-axis theorem).

    ``J_O = I_c + m (|c|^2 E - c c^T)``, with ``c`` the centre of mass seen from ``O``
    ([KD2002] eq. 9.18; [FO2008]). ``parallel_axis(J_O, -m, c)`` is the inverse.

    Examples
    --------
    >>> parallel_axis(np.zeros((3, 3)), 1.0, [0.0, 0.0, 2.0]).diagonal().tolist()
    [4.0, 4.0, 0.0]
    """
    c = np.asarray(c, float)
    return np.asarray(I_c, float) + float(m) * (float(c @ c) * np.eye(3) - np.outer(c, c))


def standard_from_com(m: float, c: ArrayLike, I_c: ArrayLike) -> np.ndarray:
    """The 10 standard parameters at the frame origin from mass, centre of mass, inertia about it.

    Parameters
    ----------
    m : float
        Mass [kg].
    c : array_like, shape (3,)
        Centre of mass in the frame [m].
    I_c : array_like, shape (3, 3)
        Inertia about the centre of mass, frame axes [kg m^2].

    Returns
    -------
    ndarray, shape (10,)
        ``XX XY XZ YY YZ ZZ MX MY MZ M`` (order :data:`~symoro_gen.params.INERTIAL_KINDS`).
    """
    c = np.asarray(c, float)
    return np.concatenate([six_from_matrix(parallel_axis(I_c, m, c)), float(m) * c, [float(m)]])


def com_from_standard(p10: ArrayLike) -> tuple[float, np.ndarray, np.ndarray]:
    """``(M, c, I_c)`` from ``XX XY XZ YY YZ ZZ MX MY MZ M`` (inverse parallel-axis theorem).

    A zero mass gives ``c = 0`` and ``I_c = J_O``.

    Examples
    --------
    >>> m, c, I_c = com_from_standard([0.5, 0, 0, 0.5, 0, 0, 0, 0, 1.0, 2.0])
    >>> float(m), c.tolist(), I_c.diagonal().tolist()
    (2.0, [0.0, 0.0, 0.5], [0.0, 0.0, 0.0])
    """
    p = [float(x) for x in np.asarray(p10, dtype=float)]
    if len(p) != 10:
        raise ValueError(f"expected the 10 inertial parameters {' '.join(INERTIAL_KINDS)}, got {len(p)} values")
    J = matrix_from_six(p[:6])
    M = p[9]
    c = np.array(p[6:9]) / M if M != 0 else np.zeros(3)
    return M, c, parallel_axis(J, -M, c)


def pseudo_inertia(p10: ArrayLike) -> np.ndarray:
    """The 4x4 pseudo-inertia matrix ``[[tr(J)/2 E - J, MS], [MS^T, M]]`` ([WKS2017] eq. 5).

    It is the second-moment matrix ``int [x; 1][x; 1]^T dm`` of the mass distribution, linear in
    the ten parameters; positive definite iff they are physically consistent.

    Examples
    --------
    >>> pseudo_inertia(standard_from_com(2.0, [0.5, 0, 0], np.zeros((3, 3)))).tolist()
    [[0.5, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 2.0]]
    """
    p = [float(x) for x in np.asarray(p10, dtype=float)]
    J = matrix_from_six(p[:6])
    P = np.empty((4, 4))
    P[:3, :3] = 0.5 * np.trace(J) * np.eye(3) - J
    P[:3, 3] = P[3, :3] = p[6:9]
    P[3, 3] = p[9]
    return P


def check_physical_consistency(p10: ArrayLike, *, tol: float = 1e-12) -> list[str]:
    """Reasons why 10 inertial parameters are not those of a rigid body (empty list if they are).

    Checks ``M > 0``, ``I_c`` positive definite, the triangle inequalities of its principal
    moments, and the pseudo-inertia positive definite ([WKS2017] Thm. 1; the
    three first conditions imply the last, which is checked for numerical agreement).

    Parameters
    ----------
    p10 : array_like, shape (10,)
    tol : float
        Relative tolerance on eigenvalues (scaled by the largest one).

    Examples
    --------
    >>> check_physical_consistency(standard_from_com(1.0, [0.1, 0, 0], np.diag([0.01, 0.02, 0.02])))
    []
    >>> check_physical_consistency(standard_from_com(1.0, [0, 0, 0], np.diag([0.01, 0.01, 0.1])))[0][:29]
    'triangle inequality violated '
    """
    M, _, IG = com_from_standard(p10)
    if not M > 0:
        return [f"mass {M} <= 0"]
    out = []
    ev = np.linalg.eigvalsh((IG + IG.T) / 2)
    scale = max(abs(ev).max(), 1e-300)
    if ev.min() <= tol * scale:
        out.append(f"inertia at the centre of mass not positive definite (eigenvalues {ev})")
    for i in range(3):
        if ev[i] > ev[(i + 1) % 3] + ev[(i + 2) % 3] + tol * scale:
            out.append(f"triangle inequality violated by principal moments {ev}")
            break
    if not out:
        # pseudo-inertia about the centre of mass (congruent to P, better conditioned)
        Pc = pseudo_inertia(standard_from_com(M, np.zeros(3), IG))
        evp = np.linalg.eigvalsh(Pc)
        if evp.min() <= -tol * max(abs(evp).max(), 1e-300):
            out.append(f"pseudo-inertia not positive semidefinite (eigenvalues {evp})")
    return out
