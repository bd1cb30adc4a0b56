"""Optimal excitation trajectories.

The trajectory of an identification experiment is chosen so that the base regressor ``W`` stacked
over it is well conditioned: the least-squares estimate of the base parameters is then insensitive
to torque noise and modelling errors (Gautier & Khalil 1992, "Exciting trajectories for the
identification of base inertial parameters of robots", IJRR 11(4); Swevers, Ganseman, Tukel,
De Schutter & Van Brussel 1997, "Optimal robot excitation and identification", IEEE T-RA 13(5)).

Two kinds of motion, both *linear in their design variables* ``X`` (one column per joint)::

    q(t) = Phi(t) X,   dq(t) = Phi'(t) X,   ddq(t) = Phi''(t) X

* :class:`FourierBasis` - Swevers' finite Fourier series
  ``q_j(t) = q0_j + sum_k a_jk/(w k) sin(w k t) - b_jk/(w k) cos(w k t)``; the last harmonic's
  coefficients are eliminated so that every joint starts and ends at rest
  (``dq(0) = sum_k a_jk = 0``, ``ddq(0) = w sum_k k b_jk = 0``; the motion is periodic).
* :class:`PointToPointBasis` - via-points joined by synchronised trapezoidal-acceleration
  (double-S) profiles of one fixed shape, as industrial controllers run them (the RX-90 paper's kind
  of motion): the robot stops at every via-point.
* :class:`SplineBasis` - a clamped cubic B-spline per joint at rest at both ends (Rackl, Lampariello &
  Hirzinger 2012, ICRA); with :func:`friction_trajectory` starts (bursts at the velocity limit between
  slow motion, the friction columns' optimum) it reaches a lower cond than the Fourier series on the
  LWR4 (docs/excitation.md).

Position, velocity and acceleration limits are then *linear* constraints on ``X`` (imposed on a
grid denser than the output one, with a small margin, and verified again on the output samples);
torque limits, when nominal parameters are known, are nonlinear constraints ``|W(q, dq, ddq) chi_b|
<= tau_max`` at the optimisation samples.

The criterion is evaluated with the generated CasADi model of the robot (``casadi_regressor()``)
and minimised by IPOPT through ``casadi.nlpsol`` from several seeded random feasible starts. The
condition number is not smooth (largest over smallest singular value); the default criterion is
the power-mean bound ``(log tr(Mn^p) + log tr(Mn^-p)) / p`` of ``Mn = M / tr M``, ``M = W^T W``, which
satisfies ``cond(W)^2 <= exp(criterion) <= nb^(2/p) cond(W)^2``; ``p`` is raised by continuation
(:data:`COND_POWERS`: 8, then 64 warm-started from the first optimum); ``"logdet"`` minimises
``-log det M`` (D-optimality).

:func:`cond_lower_bound` bounds from below the cond of ANY trajectory within the velocity limits
(whatever its duration and samples): the friction columns ``dq_j, sign dq_j, 1`` cap ``sigma_min``
(:func:`friction_ceiling`), a set of columns with a constant squared norm per sample (the first
moments of a link turning about a fixed horizontal axis: ``g^2``) floors ``sigma_max``.
How low cond can go over distributions of states (a relaxation of every trajectory) is studied in
``research/excite_relaxation.py``, outside the installed package. The value reported, ``cond``, is always the
true, unscaled 2-norm condition number of the base regressor stacked over the output samples, as the field reports it.

The package, one module per concern (this module re-exports their public names):

* :mod:`~symoro_gen.excite.limits` - ``[limits]``, passive ranges of a linear closure, the floor, the limit check;
* :mod:`~symoro_gen.excite.bases` - the Fourier, point-to-point and spline bases and their sampling;
* :mod:`~symoro_gen.excite.designs` - feasible designs: random and friction starts, scaling into the limits;
* :mod:`~symoro_gen.excite.criterion` - cond, its smooth bound, the information matrix, the lower bound;
* :mod:`~symoro_gen.excite.optimise` - the IPOPT multistart (:class:`ExciteSettings`, the efforts :data:`EFFORTS`);
* :mod:`~symoro_gen.excite.refine` - the SDP refinement on the true cond;
* :mod:`~symoro_gen.excite.output` - CSV, figure and report.

The package is also the ``excite`` workflow: ``symoro_gen.excite(robot, duration=20, output="t.csv")`` calls
:func:`symoro_gen.workflows.excite.excite` (so that the library's ``symoro_gen.excite`` is both this package and the
workflow, whichever was imported first); the command is :mod:`symoro_gen.commands.excite`.
"""
from __future__ import annotations

import importlib
import inspect
import sys
import types
from typing import Any

from .bases import FourierBasis, PointToPointBasis, SplineBasis, basis_eval, dense_times, output_times
from .criterion import (
    COND_POWER,
    COND_POWERS,
    CondBound,
    casadi_regressor,
    cond_lower_bound,
    design_information,
    friction_ceiling,
    predicted_sigma,
    smooth_criterion,
    stacked_cond,
)
from .designs import constant_design, friction_trajectory, inside_limits, random_trajectory, scale_into
from .limits import (
    DEFAULT_LIMITS,
    DEFAULT_PRISMATIC_LIMITS,
    WORKSPACE_MARGIN,
    ExcitationError,
    Limits,
    PassiveRange,
    Workspace,
    check_limits,
    floor_linearisation,
    limits_of,
    load_casadi,
    mdh_frames,
    sympy_to_casadi,
    with_floor,
)
from .optimise import EFFORTS, ExcitationResult, ExciteSettings, build_nlp, optimise_excitation, worker_count
from .output import (
    excitation_report,
    joint_numbers,
    passive_ranges,
    plot_trajectory,
    trajectory_figure_png,
    write_trajectory_csv,
)
from .refine import REFINE_ITERATIONS, REFINE_RATE, Linearisation, RefineSettings, has_cvxpy, refine_excitation

__all__ = [
    "CondBound",
    "DEFAULT_LIMITS",
    "ExcitationResult",
    "FourierBasis",
    "Limits",
    "PointToPointBasis",
    "SplineBasis",
    "basis_eval",
    "check_limits",
    "cond_lower_bound",
    "design_information",
    "friction_ceiling",
    "friction_trajectory",
    "limits_of",
    "optimise_excitation",
    "output_times",
    "predicted_sigma",
    "random_trajectory",
    "refine_excitation",
    "stacked_cond",
    "write_trajectory_csv",
    # the settings of the search and of the refinement
    "EFFORTS",
    "ExciteSettings",
    "RefineSettings",
    "COND_POWER",
    "COND_POWERS",
    "REFINE_ITERATIONS",
    "REFINE_RATE",
    # limits, floor, closed loops
    "DEFAULT_PRISMATIC_LIMITS",
    "WORKSPACE_MARGIN",
    "ExcitationError",
    "PassiveRange",
    "Workspace",
    "floor_linearisation",
    "mdh_frames",
    "with_floor",
    # the pieces the benches and the relaxation research build on
    "Linearisation",
    "build_nlp",
    "casadi_regressor",
    "constant_design",
    "dense_times",
    "has_cvxpy",
    "inside_limits",
    "load_casadi",
    "scale_into",
    "smooth_criterion",
    "sympy_to_casadi",
    "worker_count",
    # output
    "excitation_report",
    "joint_numbers",
    "passive_ranges",
    "plot_trajectory",
    "trajectory_figure_png",
]


class _ExcitePackage(types.ModuleType):
    """This package, callable as the ``excite`` workflow."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """``symoro_gen.excite(robot, **options)``: :func:`symoro_gen.workflows.excite.excite`."""
        return importlib.import_module("symoro_gen.workflows.excite").excite(*args, **kwargs)

    @property
    def __signature__(self) -> inspect.Signature:
        """The workflow's own signature (its named options), for :func:`inspect.signature`, ``help`` and IDEs."""
        return inspect.signature(importlib.import_module("symoro_gen.workflows.excite").excite)


sys.modules[__name__].__class__ = _ExcitePackage
