"""The symbolic model of a floating-base robot (``base = "floating"`` in the robot file).

Frame 0 is a free body with 6 degrees of freedom. Its velocity and acceleration are inputs of the
customised Newton-Euler recursion of :mod:`.newton_euler` (the same recursion as for a fixed base, started
from the base's motion instead of rest, [KD2002] ch. 9), every link's wrench is carried back to frame 0,
and the model has ``6 + n`` rows: the base wrench first (force, then moment about the base origin, both in
base axes), then the joint torques. It is linear in the standard parameters, the base link's 10 inertial
parameters (``XX0 .. M0``, frame 0 at its origin) first.

The inputs follow Pinocchio's free-flyer conventions (``pinocchio.JointModelFreeFlyer``, Carpentier et al.,
"The Pinocchio C++ library", SII 2019):

* ``q`` (7 + n): the base position in the world (no effect on the dynamics), the unit quaternion
  ``x y z w`` of the base orientation (base axes -> world axes), then the joints;
* ``dq`` (6 + n): the base's linear then angular velocity, in base axes, then the joint velocities;
* ``ddq`` (6 + n): the derivative of the base's spatial velocity (Pinocchio's spatial acceleration, in
  base axes: the classical acceleration of the base origin is ``a + w x v``), then the joints'.

Gravity (``robot.gravity``, world axes) enters as an upward acceleration of the base, rotated into base
axes by the quaternion: ``vd0 = a + w x v - R(quat)^T g``.
"""
from __future__ import annotations

import sympy as sp

from ..description.model import RobotDescription
from .newton_euler import BaseMotion, SymbolicRegressor, build_regressor

#: names of the base's inputs, in Pinocchio's order: q (position, quaternion x y z w), dq, ddq
BASE_Q_NAMES = ("PX0", "PY0", "PZ0", "QX0", "QY0", "QZ0", "QW0")
BASE_DQ_NAMES = ("VX0", "VY0", "VZ0", "WX0", "WY0", "WZ0")
BASE_DDQ_NAMES = ("AX0", "AY0", "AZ0", "DWX0", "DWY0", "DWZ0")
#: the 6 base-wrench rows, before the joint rows
BASE_ROW_NAMES = ("FX0", "FY0", "FZ0", "MX0", "MY0", "MZ0")


def _symbols(names: tuple[str, ...]) -> tuple[sp.Symbol, ...]:
    return tuple(sp.Symbol(n, real=True) for n in names)


def quaternion_rotation(x: sp.Expr, y: sp.Expr, z: sp.Expr, w: sp.Expr) -> sp.Matrix:
    """The rotation matrix of the unit quaternion ``w + x i + y j + z k`` (base axes -> world axes;
    the Hamilton convention Pinocchio and Eigen use)."""
    return sp.Matrix([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def base_motion(robot: RobotDescription) -> BaseMotion:
    """The motion of the floating base of ``robot`` as the recursion's inputs (module docstring):
    ``w0 = omega``, ``wd0 = domega``, ``vd0 = a + omega x v - R(quat)^T g``."""
    q, dq, ddq = _symbols(BASE_Q_NAMES), _symbols(BASE_DQ_NAMES), _symbols(BASE_DDQ_NAMES)
    R = quaternion_rotation(*q[3:7])
    g = [sp.Float(x) if not float(x).is_integer() else sp.Integer(int(x)) for x in robot.gravity]
    g_base = [sp.expand(sum((R[k, i] * g[k] for k in range(3)), sp.S.Zero)) for i in range(3)]
    v, w = dq[:3], dq[3:]
    a, wd = ddq[:3], ddq[3:]
    wxv = [w[1] * v[2] - w[2] * v[1], w[2] * v[0] - w[0] * v[2], w[0] * v[1] - w[1] * v[0]]
    vd = tuple(a[i] + wxv[i] - g_base[i] for i in range(3))
    return BaseMotion(w=(w[0], w[1], w[2]), wd=(wd[0], wd[1], wd[2]), vd=(vd[0], vd[1], vd[2]),
                      q=q, dq=dq, ddq=ddq)


def build_floating_regressor(robot: RobotDescription, *, progress=None, columns=None) -> SymbolicRegressor:
    """The standard (and payload) regressor of a floating-base robot: ``6 + n`` rows, base wrench first.

    Parameters
    ----------
    robot : RobotDescription
        A robot file with ``base = "floating"``.
    progress, columns
        As for :func:`symoro_gen.dynamics.newton_euler.build_regressor`.

    Returns
    -------
    SymbolicRegressor
        ``graph.outputs[(row, name)]``: rows 0-5 the base wrench (:data:`BASE_ROW_NAMES`), row ``6 + i``
        joint ``i``; ``graph.inputs`` begin with the base's inputs (:data:`BASE_Q_NAMES` ...).

    Raises
    ------
    ValueError
        ``robot`` does not have a floating base (named with its file).
    """
    if not robot.floating:
        raise ValueError(f"{robot.file}: base = {robot.base!r}; a floating-base model needs base = \"floating\"")
    return build_regressor(robot, progress=progress, columns=columns, base=base_motion(robot))
