"""A model object with the generated-module interface, built from the numeric Newton-Euler.

Slow (one inverse-dynamics pass per parameter) but exact and independent of the symbolic
pipeline: handy in tests and to simulate robots that have not been generated. Its "base"
columns are the standard ones (no regrouping), so its regressor is rank deficient.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..description import load_robot
from ..description.model import RobotDescription
from ..dynamics.numeric import inverse_dynamics, numeric_regressor

__all__ = ["NumericModel", "numeric_model"]


@dataclass(frozen=True)
class NumericModel:
    """Generated-module look-alike: ``ROBOT N_JOINTS STANDARD_NAMES BASE_NAMES PAYLOAD_NAMES``,
    ``regressor``, ``standard_regressor``, ``payload_regressor``, ``torque``, ``base_parameters``.

    Attributes
    ----------
    robot : RobotDescription
    """

    robot: RobotDescription

    def _both(self, q, dq, ddq):
        """Standard and payload columns from one pass, cached for the last inputs (the assembly asks
        for both on the same samples)."""
        q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
        key = (q.shape, q.ctypes.data, dq.ctypes.data, ddq.ctypes.data, float(q.sum()), float(dq.sum()),
               float(ddq.sum()))
        cache = self.__dict__.get("_cache")
        if cache is not None and cache[0] == key:
            return cache[1]
        res = numeric_regressor(self.robot, q, dq, ddq)
        object.__setattr__(self, "_cache", (key, res))
        return res

    @property
    def ROBOT(self) -> str:  # noqa: N802 - module-constant style of the generated interface
        return self.robot.name

    @property
    def N_JOINTS(self) -> int:  # noqa: N802
        return self.robot.n_joints

    @property
    def STANDARD_NAMES(self) -> tuple[str, ...]:  # noqa: N802
        return tuple(self.robot.standard_names)

    @property
    def BASE_NAMES(self) -> tuple[str, ...]:  # noqa: N802
        return tuple(self.robot.standard_names)

    @property
    def PAYLOAD_NAMES(self) -> tuple[str, ...]:  # noqa: N802
        return tuple(self.robot.payload_names)

    def standard_regressor(self, q, dq, ddq):
        """Standard regressor, shape (N, n, n_st)."""
        return self._both(q, dq, ddq)[0]

    def regressor(self, q, dq, ddq):
        """Same as :meth:`standard_regressor` (no regrouping), shape (N, n, n_st)."""
        return self.standard_regressor(q, dq, ddq)

    def payload_regressor(self, q, dq, ddq):
        """Payload regressor, shape (N, n, 10) (``(N, n, 0)`` without payload frame)."""
        if self.robot.payload is None:
            q = np.atleast_2d(np.asarray(q, float))
            return np.zeros(q.shape + (0,))
        return self._both(q, dq, ddq)[1]

    def base_parameters(self, chi_std):
        """Identity (base columns are the standard ones)."""
        return np.asarray(chi_std, float).copy()

    def torque(self, q, dq, ddq, chi_std, chi_payload=None):
        """Joint torques by numeric Newton-Euler, shape (N, n)."""
        return inverse_dynamics(self.robot, q, dq, ddq, chi_std, chi_payload)

    def nominal_parameters(self):
        v = self.robot.nominal_vector()
        return None if v is None else np.asarray(v, float)


def numeric_model(robot: RobotDescription | str) -> NumericModel:
    """:class:`NumericModel` of a robot description (or of a robot name/path)."""
    if not isinstance(robot, RobotDescription):
        robot = load_robot(robot)
    return NumericModel(robot)
