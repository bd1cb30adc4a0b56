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
* statistics of the output-error estimate at convergence (GJV2013, Gauss-Newton covariance): the
  robot is simulated once more with the final ``chi``; the output error ``e = Y - W_s(chi) chi`` of
  that simulation gives ``sigma^2 = ||e||^2 / (r - c)`` and the Gauss-Newton Jacobian ``W_s(chi)``
  gives ``C = sigma^2 (W_s' W_s)^-1``, ``%sigma`` (the residual of the last LS fit, on the states of
  the previous simulation, would understate sigma).

Only the measured torque and the reference enter: the noise on the measured positions does not bias it.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.options import AssemblyOptions
from ..preprocessing.trajectory import Trajectory
from ..simulate.closed_loop import FRICTION_EPS
from .estimators import fit_ols
from .iv import MAX_ITER, TOL, IterativeIdentification, _tracking, iterate, simulated_system
from .result import per_joint_rel_err, relative_std_pct

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
        First estimate to simulate; default the IDIM-OLS estimate (or, when it cannot be simulated, the
        OLS fit on the reference states; :func:`~symoro_gen.identification.iv.iterate`).

    Returns
    -------
    IterativeIdentification
        ``result.method == "DIDIM"``; ``result.residual`` is the output error ``Y - W_s chi``.
    """
    it = iterate(model, trajectories, options, lambda measured, sim: replace(fit_ols(sim), method="DIDIM"), "DIDIM",
                 references=references, gains=gains, bandwidth_hz=bandwidth_hz, friction_eps=friction_eps,
                 max_iter=max_iter, tol=tol, start=start)
    return output_error_statistics(model, it)


def output_error_statistics(model: IdentificationModel, it: IterativeIdentification) -> IterativeIdentification:
    """DIDIM statistics at the final estimate (GJV2013): simulate ``chi``, output error
    ``e = Y - W_s(chi) chi``, ``sigma^2 = ||e||^2 / (r - c)``, ``C = sigma^2 (W_s' W_s)^-1``.

    When the final estimate cannot be simulated the statistics of the last LS fit are kept and a
    warning says so."""
    res = it.result
    chi = np.asarray(res.values, float)
    try:
        ssys, runs = simulated_system(model, it.setup, chi)
    except IdentificationError as exc:
        return replace(it, result=replace(res, warnings=res.warnings + (
            f"DIDIM statistics are those of the last least-squares fit: the final estimate cannot be simulated ({exc})",)))
    W, Y = ssys.W, ssys.Y
    r, c = W.shape
    e = Y - W @ chi
    sigma = math.sqrt(float(e @ e) / (r - c))
    cov = sigma ** 2 * np.linalg.pinv(W.T @ W)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    new = replace(res, std=std, cov=cov, sigma=sigma, rel_std_pct=relative_std_pct(chi, std), residual=e,
                  rel_err=per_joint_rel_err(e, Y, ssys.joint, ssys.n_joints))
    return replace(it, result=new, tracking_error=_tracking(runs))
