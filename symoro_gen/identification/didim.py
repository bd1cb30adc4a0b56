"""DIDIM: direct and inverse dynamic identification (output error on the torque, closed loop).

M. Gautier, A. Janot, P.-O. Vandanjon, "A new closed-loop output error method for parameter
identification of robot dynamics", IEEE Trans. Control Systems Technology 21(2), 2013 ([GJV2013],
docs/references.md).

The robot with the current estimate ``chi_k`` is simulated in closed loop, driven by the recorded
reference with the controller of the real robot
(:func:`symoro_gen.simulate.closed_loop.simulate_closed_loop`); the simulated torque is
``tau_s = IDM(q_s, dq_s, ddq_s) chi``, so the output error ``Y - tau_s`` is linear in ``chi`` for
given simulated states. Its Gauss–Newton step uses the Jacobian ``W_s = IDM(q_s, dq_s, ddq_s)``
(the sensitivity of the simulated states to ``chi`` is neglected, GJV2013), which makes each
iteration an ordinary least-squares fit of the *measured* torque on the observation matrix of the
*simulated* states, filtered and decimated as IDIM (same assembly options and filter settings):

* ``chi_k+1 = argmin ||Y - W_s(chi_k) chi||^2`` (GJV2013), started from IDIM-OLS and
  iterated until ``|chi_k+1 - chi_k| / |chi_k| < tol``;
* statistics of the last LS fit: ``sigma^2 = ||Y - W_s chi||^2 / (r - c)``,
  ``C = sigma^2 (W_s' W_s)^-1`` (GJV2013), ``%sigma``.

Only the measured torque and the reference enter: the noise on the measured positions does not bias it.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.assembly import assemble
from ..observations.options import AssemblyOptions
from ..preprocessing.trajectory import Trajectory
from ..simulate.closed_loop import FRICTION_EPS
from .estimators import fit_ols
from ..simulate.closed_loop import parameter_vector
from .iv import MAX_ITER, TOL, IterativeIdentification, _rel_change, _tracking, closed_loop_setup, simulated_system

__all__ = ["identify_didim"]


def identify_didim(model: IdentificationModel, trajectories: Trajectory | Sequence[Trajectory],
                   options: AssemblyOptions | None = None, *, references=None, gains=None,
                   bandwidth_hz: float | None = None, friction_eps: float = FRICTION_EPS, max_iter: int = MAX_ITER,
                   tol: float = TOL, start=None) -> IterativeIdentification:
    """DIDIM (GJV2013): least squares of the measured torque on the observation matrix of the
    closed-loop simulation with the current estimate, iterated from IDIM-OLS.

    Parameters
    ----------
    model : IdentificationModel
    trajectories : Trajectory or sequence of Trajectory
        Measured, unloaded recordings (``t, q, tau``).
    options : AssemblyOptions
        Filtering and decimation (as IDIM-OLS). ``min_velocity`` selects rows by the measured velocity.
    references : sequence of array_like (N, n) or None
        Recorded reference positions per experiment (default ``Trajectory.meta['q_ref']``, else the
        measured positions low-passed, see :func:`~symoro_gen.identification.iv.closed_loop_setup`).
    gains : PIDGains or sequence of PIDGains, optional
        The real controller's gains (default: PD at ``bandwidth_hz`` from the OLS estimate).
    friction_eps : float
        Coulomb smoothing of the simulation.
    max_iter, tol
        Iterations at most; stop when ``|chi_k+1 - chi_k| / |chi_k| < tol``.
    start : array_like or mapping, optional
        First estimate to simulate; default the IDIM-OLS estimate.

    Returns
    -------
    IterativeIdentification
        ``result.method == "DIDIM"``; ``result.residual`` is the output error ``Y - W_s chi``.
    """
    opts = AssemblyOptions() if options is None else options
    trajs = (trajectories,) if isinstance(trajectories, Trajectory) else tuple(trajectories)
    measured = assemble(model, trajs, replace(opts, payload_columns=False))
    if tuple(measured.system.names) != tuple(model.BASE_NAMES):
        raise IdentificationError("DIDIM needs the base-parameter columns of the model")
    ols = fit_ols(measured.system)
    theta = ols.values if start is None else parameter_vector(model, start)
    setup = closed_loop_setup(model, trajs, opts, theta, references=references, gains=gains,
                              bandwidth_hz=bandwidth_hz, friction_eps=friction_eps, measured=measured)
    history, changes = [theta], []
    res, runs, converged = ols, [], False
    for _ in range(int(max_iter)):
        try:
            ssys, runs = simulated_system(model, setup, theta)
        except IdentificationError as exc:
            first = "the IDIM-OLS start" if start is None and not changes else "the current estimate"
            raise IdentificationError(
                f"DIDIM iteration {len(changes) + 1}: cannot simulate {first}: {exc}; filter more (a lower "
                f"cutoff_hz) or give a physical start (start=...)") from None
        res = replace(fit_ols(ssys), method="DIDIM")
        changes.append(_rel_change(res.values, theta))
        theta = res.values
        history.append(theta)
        if changes[-1] < tol:
            converged = True
            break
    if not converged:
        res = replace(res, warnings=res.warnings + (
            f"DIDIM did not converge in {max_iter} iterations (last relative change {changes[-1]:.3g} >= {tol:g})",))
    return IterativeIdentification(res, ols, len(changes), converged, np.array(history), np.array(changes), setup,
                                   _tracking(runs))
