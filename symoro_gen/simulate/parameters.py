"""Random but physically consistent dynamic parameters (the "truth" of simulated recordings).

Each link is a random solid ellipsoid: mass ``M > 0``, centre of mass ``c`` in a ball, principal
moments ``M/5 (b^2 + c^2, ...)`` (so the inertia at the centre of mass is positive definite and
satisfies the triangle inequalities strictly), random orientation; the standard parameters are
expressed in frame j at its origin (Khalil-Kleinfinger): ``J_O = I_G + M (|c|^2 1 - c c^T)``,
``MS = M c`` (:func:`symoro_gen.description.inertia.standard_from_com`). Drive terms (rotor inertia, viscous and Coulomb friction, offset) are drawn in
plausible ranges for an industrial arm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..description.inertia import check_physical_consistency, com_from_standard, standard_from_com
from ..description.model import RobotDescription
from ..params import DRIVE_KINDS, INERTIAL_KINDS

__all__ = ["ParameterSet", "random_physical_parameters", "random_payload", "random_link_inertial",
           "inertial_at_com", "check_physical_consistency"]


@dataclass(frozen=True)
class ParameterSet:
    """A labelled parameter vector; ``np.asarray(ps)`` gives the values.

    Attributes
    ----------
    names : tuple of str
    values : ndarray, shape (len(names),)
    """

    names: tuple[str, ...]
    values: np.ndarray

    def __post_init__(self) -> None:
        v = np.array(self.values, dtype=float, copy=True).reshape(-1)
        if v.shape[0] != len(self.names):
            raise ValueError(f"{len(self.names)} names for {v.shape[0]} values")
        v.setflags(write=False)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "values", v)

    def __array__(self, dtype=None, copy=None):
        return np.array(self.values, dtype=dtype, copy=True)

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.names, (float(x) for x in self.values)))


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def random_link_inertial(rng: np.random.Generator, *, mass_range: tuple[float, float] = (0.5, 10.0),
                         com_radius: float = 0.15, size_range: tuple[float, float] = (0.03, 0.25)) -> np.ndarray:
    """The 10 inertial parameters ``XX XY XZ YY YZ ZZ MX MY MZ M`` of a random solid ellipsoid.

    Parameters
    ----------
    mass_range : (float, float)
        Uniform mass range [kg].
    com_radius : float
        The centre of mass is uniform in a ball of this radius around the frame origin [m].
    size_range : (float, float)
        Uniform range of the ellipsoid semi-axes [m].

    Returns
    -------
    ndarray, shape (10,)
        Inertia at the frame origin [kg m^2], first moments [kg m], mass [kg].
    """
    m = rng.uniform(*mass_range)
    d = rng.standard_normal(3)
    c = d / np.linalg.norm(d) * com_radius * rng.uniform() ** (1.0 / 3.0)
    a, b, cc = rng.uniform(*size_range, size=3)
    Ip = m / 5.0 * np.array([b * b + cc * cc, a * a + cc * cc, a * a + b * b])
    R = _random_rotation(rng)
    IG = R @ np.diag(Ip) @ R.T
    return standard_from_com(m, c, IG)


#: ``(M, c, I_G)`` from the 10 inertial parameters (kept name; see :mod:`symoro_gen.description.inertia`)
inertial_at_com = com_from_standard


def random_physical_parameters(robot: RobotDescription, rng: np.random.Generator, *, mass_range=(0.5, 10.0),
                               com_radius: float = 0.15, size_range=(0.03, 0.25), ia_range=(0.01, 0.5),
                               fv_range=(0.1, 5.0), fs_range=(0.1, 5.0), off_range=(-1.0, 1.0)) -> ParameterSet:
    """Physically consistent standard parameters for ``robot`` (names ``robot.standard_names``).

    Parameters
    ----------
    robot : RobotDescription
    rng : numpy.random.Generator
    mass_range, com_radius, size_range
        See :func:`random_link_inertial`.
    ia_range, fv_range, fs_range, off_range : (float, float)
        Uniform ranges of rotor inertia [kg m^2], viscous [N m s/rad] and Coulomb [N m] friction,
        torque offset [N m] (N, N s/m for prismatic joints).

    Returns
    -------
    ParameterSet
        In ``robot.standard_names`` order (payload excluded: see :func:`random_payload`).
    """
    ranges = {"IA": ia_range, "FV": fv_range, "FS": fs_range, "OFF": off_range}
    vals: dict[str, float] = {}
    for row in robot.joints:
        p = random_link_inertial(rng, mass_range=mass_range, com_radius=com_radius, size_range=size_range)
        vals.update({f"{k}{row.j}": float(x) for k, x in zip(INERTIAL_KINDS, p)})
        for k in DRIVE_KINDS:
            vals[f"{k}{row.j}"] = float(rng.uniform(*ranges[k]))
    names = robot.standard_names
    return ParameterSet(names, np.array([vals[nm] for nm in names]))


def random_payload(rng: np.random.Generator, *, robot: RobotDescription | None = None, mass_range=(0.5, 5.0),
                   com_radius: float = 0.1, size_range=(0.02, 0.15)) -> ParameterSet:
    """Inertial parameters of a random payload (a solid ellipsoid) in its frame.

    Names are ``robot.payload_names`` when a robot with a payload frame is given, else ``XXL..ML``.

    Returns
    -------
    ParameterSet
        ``XX XY XZ YY YZ ZZ MX MY MZ M`` [kg m^2, kg m, kg].
    """
    p = random_link_inertial(rng, mass_range=mass_range, com_radius=com_radius, size_range=size_range)
    if robot is not None and robot.payload_names:
        names = robot.payload_names
    else:
        names = tuple(f"{k}L" for k in INERTIAL_KINDS)
    return ParameterSet(names, p)
