"""DIDIM: direct and inverse dynamic identification (output error on the torque, closed loop).

M. Gautier, A. Janot, P.-O. Vandanjon, "A new closed-loop output error method for parameter
identification of robot dynamics", IEEE Trans. Control Systems Technology 21(2), 2013 ([GJV2013],
docs/references.md).

The robot with the current estimate ``chi_k`` is simulated in closed loop, driven by the recorded
reference with the controller of the real robot
(:func:`symoro_gen.simulate.closed_loop.simulate_closed_loop`). The output error is the difference
between the measured torque ``Y`` and the *simulated* torque ``T(chi)`` (the simulated controller's
output), both filtered and decimated as IDIM (same assembly options and filter settings). Its
Gauss–Newton step uses the Jacobian ``W_s = IDM(q_s, dq_s, ddq_s)`` on the simulated states (the
sensitivity of the simulated states to ``chi`` is neglected in the step, GJV2013 Sec. III):

* ``chi_k+1 = chi_k + (W_s' W_s)^-1 W_s' (Y - T(chi_k))`` (GJV2013), started from IDIM-OLS and
  iterated until ``|chi_k+1 - chi_k| / |chi_k| < tol``. It is the least-squares fit of
  ``Y - T + W_s chi_k`` on ``W_s``; when ``W_s chi_k = T`` exactly it is GJV2013's
  ``chi_k+1 = argmin ||Y - W_s chi||``. That identity fails on the decimated data (the Coulomb
  smoothing of the simulation, and the band-pass derivatives of the filtered simulated positions if
  they were used): the output error is therefore taken on the simulated torque itself, and ``W_s``
  on the simulation's own velocities and accelerations. (With ``Y - W_s chi`` in its place the
  fixed point is biased: 3–9 sigma on the simulated SCARA of ``bench/bench_iv_didim.py``.) From the
  default start (IDIM-OLS or a fallback, possibly far) the first iterations are GJV2013's re-fit
  ``argmin ||Y - W_s chi||``, robust while the simulated robot tracks badly; the output-error step
  takes over once they move by less than :data:`REFIT_SWITCH` (2 %).
* statistics at the fixed point ``W_s'(Y - T(chi)) = 0``: with ``J = dT/dchi`` (the sensitivity of
  the closed-loop simulated torque, by finite differences of the simulation: GJV2013 Sec. IV uses
  the output-error Jacobian for the covariance) the estimate moves by ``(W_s' J)^-1 W_s' dY`` for a
  change ``dY`` of the measured torque, so
  ``C = (W_s' J)^-1 W_s' Omega W_s (J' W_s)^-1``, with ``W_s' Omega W_s`` the long-run covariance
  of the scores ``W_s,r e_r`` (``e = Y - T(chi)``), summed per decimated sample and estimated with
  Bartlett weights over lags (Newey & West 1987, Econometrica 55(3), eq. 2): the output error of a
  closed-loop model is correlated in time, and ``sigma^2 (W_s'W_s)^-1`` would understate the spread.
  When the finite differences would take too long (``nb + 1`` simulations), ``J = W_s``
  (GJV2013's own approximation) and a warning says so.

Only the measured torque and the reference enter: the noise on the measured positions does not bias it.
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.options import AssemblyOptions
from ..observations.system import ObservationSystem
from ..preprocessing.trajectory import Trajectory
from ..simulate.closed_loop import ForwardDynamics
from .estimators import fit_ols
from .iv import IterativeIdentification, LoopOptions, LoopSettings, iterate, simulated_output, tracking_error_rms
from .physical import identify_physical
from .result import per_joint_rel_err, relative_std_pct

if TYPE_CHECKING:
    from typing_extensions import Unpack

__all__ = ["didim_system", "hac_score_covariance", "identify_didim", "output_error_statistics"]

#: finite-difference sensitivities are computed when ``nb`` simulations would take at most this [s]
#: (measured on the final simulation), else ``J = W_s``
FD_BUDGET_S = 30.0
#: relative step of the finite-difference sensitivities
FD_STEP = 1e-4
#: relative change of the re-fit iterates below which the output-error step takes over
REFIT_SWITCH = 0.02


def didim_system(model: IdentificationModel, setup, theta) -> tuple[ObservationSystem, list]:
    """The DIDIM step as a least-squares system: ``W_s`` and ``Y - T(theta) + W_s theta`` (its
    least-squares solution is ``theta + (W_s'W_s)^-1 W_s'(Y - T(theta))``, GJV2013)."""
    theta = np.asarray(theta, float)
    so = simulated_output(model, setup, theta)
    ms = setup.measured.system
    return ObservationSystem(so.W, so.Y - so.T + so.W @ theta, ms.names, ms.joint), so.runs


def identify_didim(model: IdentificationModel, trajectories: Trajectory | Sequence[Trajectory],
                   options: AssemblyOptions | None = None, *, jacobian: str = "auto",
                   fd_budget_s: float = FD_BUDGET_S, physical: str = "never",
                   nominal_tolerance: float | None = None, **loop: Unpack[LoopOptions]) -> IterativeIdentification:
    """DIDIM (GJV2013): Gauss–Newton on the output error ``Y - T(chi)`` of the closed-loop
    simulation with the current estimate, iterated from IDIM-OLS.

    Parameters
    ----------
    model : IdentificationModel
    trajectories : Trajectory or sequence of Trajectory
        Measured, unloaded recordings (``t, q, tau``).
    options : AssemblyOptions
        Filtering and decimation (as IDIM-OLS). ``min_velocity`` selects rows by the measured velocity.
    jacobian : {"auto", "fd", "simulated"}
        The sensitivity ``J = dT/dchi`` of the covariance: finite differences of the simulation
        (``"fd"``), ``W_s`` (``"simulated"``), or finite differences when they fit in ``fd_budget_s``.
    physical : {"auto", "always", "never"}
        Constrain the Gauss–Newton step to physically consistent parameters (the least squares of the
        step solved by :func:`~symoro_gen.identification.physical.identify_physical` on the simulated
        system: pseudo-inertias positive semidefinite, ``IA, FV, FS >= 0``, pulled toward the robot
        file's nominal values where the data say nothing; Wensing, Kim & Slotine 2018): ``"auto"`` only
        when the unconstrained step gives an inertia matrix that is not positive definite on the
        recorded positions (it could not be simulated: on the real LWR4 every unconstrained step is
        such). Default ``"never"``: the constrained step did not make the real LWR4 converge and, on
        the simulated SCARA from a far start, it led to estimates whose closed loop diverges, where the
        default path (projection of a non-simulable iterate, then step halving) converges. Needs cvxpy.
    nominal_tolerance : float, optional
        With the constrained step: bound every standard parameter with a non-zero nominal value to
        ``|chi - nominal| <= tol |nominal|`` (keeps e.g. the inertia about the last axis away from 0, where
        the simulation of a joint with Coulomb friction becomes infinitely stiff).
    **loop
        The closed-loop iteration (:class:`~symoro_gen.identification.iv.LoopSettings`):

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
        ``result.method == "DIDIM"``; ``result.residual`` is the output error ``Y - T(chi)``.
    """
    lp = LoopSettings.of("identify_didim", loop)
    if jacobian not in ("auto", "fd", "simulated"):
        raise IdentificationError(f"DIDIM jacobian {jacobian!r}: expected auto, fd or simulated")
    if physical not in ("auto", "always", "never"):
        raise IdentificationError(f"DIDIM physical {physical!r}: expected auto, always or never")
    trajs = (trajectories,) if isinstance(trajectories, Trajectory) else tuple(trajectories)
    q_check = np.vstack([tr.q[::max(1, tr.q.shape[0] // 40)] for tr in trajs])
    constrained: list[int] = []

    # far from the solution (start not given), GJV2013's re-fit of Y on W_s is the robust step (it does not
    # rest on T(chi + d) ~ T(chi) + W_s d, poor while the simulated robot tracks badly); once its iterates
    # move by less than REFIT_SWITCH, the output-error step takes over (unbiased fixed point)
    state: dict = {"refit": lp.start is None, "prev": None, "W_filtered": None}

    def simulate(model_, setup, theta):
        theta = np.asarray(theta, float)
        so = simulated_output(model_, setup, theta, filtered=state["refit"])
        state["W_filtered"] = so.W_filtered
        ms = setup.measured.system
        return ObservationSystem(so.W, so.Y - so.T + so.W @ theta, ms.names, ms.joint), so.runs

    def step(measured, sim):
        res = replace(fit_ols(sim), method="DIDIM")
        if state["refit"] and state["W_filtered"] is not None:
            # GJV2013's re-fit, on the simulated positions differentiated as the measured ones
            refit = replace(fit_ols(ObservationSystem(state["W_filtered"], measured.Y, sim.names, sim.joint)),
                            method="DIDIM")
            prev, state["prev"] = state["prev"], refit.values
            if prev is None or np.linalg.norm(refit.values - prev) > REFIT_SWITCH * np.linalg.norm(prev):
                res = refit
            else:
                state["refit"] = False
        if physical == "never" or (physical == "auto" and _inertia_positive(model, res.values, q_check)):
            return res
        nominal = getattr(model, "nominal_parameters", lambda: None)()
        phys = identify_physical(model, sim, nominal=nominal, nominal_tolerance=nominal_tolerance)
        constrained.append(len(constrained) + 1)
        return replace(res, values=np.asarray(phys.base_values, float))

    it = iterate(model, trajs, options, step, "DIDIM", simulate=simulate, **loop)
    if constrained:
        it = replace(it, result=replace(it.result, warnings=it.result.warnings + (
            f"DIDIM: {len(constrained)} of {it.iterations} Gauss-Newton step(s) constrained to physically consistent "
            f"parameters (the unconstrained step's inertia matrix was not positive definite); the covariance "
            f"ignores the active constraints",)))
    it = output_error_statistics(model, it, jacobian=jacobian, fd_budget_s=fd_budget_s)
    if not it.converged:
        worst = int(np.argmax(it.tracking_error))
        src = ", ".join(sorted(set(it.setup.reference_source)))
        it = replace(it, result=replace(it.result, warnings=it.result.warnings + (
            f"DIDIM did not converge: the simulated closed loop does not reproduce the recording (output error "
            f"||Y - T|| / ||Y|| per joint {', '.join(f'{x:.2g}' for x in it.result.rel_err)}; simulated tracking error "
            f"RMS up to {it.tracking_error[worst]:.3g} rad on joint {worst + 1}; reference: {src}; controller: "
            f"{'given' if lp.gains is not None else 'default PD from the start estimate'}). DIDIM needs the real "
            f"controller (--kp/--kd/--ki) and its recorded reference; without them use IDIM (--method ols/wls) or "
            f"IDIM-IV",)))
    return it


def _inertia_positive(model: IdentificationModel, theta, q_check: np.ndarray) -> bool:
    """``M(q)`` positive definite at every position of ``q_check`` (what a simulation needs)."""
    fd = ForwardDynamics(model, theta)
    try:
        return all(float(np.linalg.eigvalsh(fd.mass_matrix(q))[0]) > 0 for q in q_check)
    except (IdentificationError, np.linalg.LinAlgError):
        return False


def _bartlett_lags(e: np.ndarray, groups: list[np.ndarray]) -> int:
    """Bartlett bandwidth: the Newey–West rule ``4 (K/100)^(2/9)``, raised to the first lag where the
    mean autocorrelation of the output error (per joint and experiment) drops below 0.1; at most K/4."""
    K = max(len(g) for g in groups)
    L = int(math.ceil(4 * (K / 100.0) ** (2.0 / 9.0)))
    series = [e[g] for g in groups if len(g) > 8]
    if series:
        lmax = max(1, K // 4)
        acf = np.zeros(lmax + 1)
        for x in series:
            x = x - x.mean()
            d = float(x @ x) or 1.0
            m = min(lmax, len(x) - 1)
            acf[:m + 1] += np.array([float(x[l:] @ x[:len(x) - l]) / d for l in range(m + 1)]) / len(series)
        below = np.flatnonzero(acf < 0.1)
        if below.size:
            L = max(L, int(below[0]))
        else:
            L = lmax
    return int(min(L, max(1, K // 4)))


def hac_score_covariance(scores: np.ndarray, sample_keys: np.ndarray, lags: int) -> np.ndarray:
    """Long-run covariance ``S`` of row scores ``scores`` (r, c) summed per sample key (rows sharing a
    key are one time sample, keys ordered in time within an experiment: ``(experiment << 40) +
    sample``), Bartlett weights ``1 - l / (lags + 1)`` (Newey & West 1987)."""
    keys, inv = np.unique(sample_keys, return_inverse=True)
    G = np.zeros((keys.size, scores.shape[1]))
    np.add.at(G, inv, scores)
    exp = keys >> 40
    S = G.T @ G
    for lag in range(1, int(lags) + 1):
        same = exp[lag:] == exp[:-lag]
        if not np.any(same):
            break
        A = G[lag:][same].T @ G[:-lag][same]
        S += (1.0 - lag / (lags + 1.0)) * (A + A.T)
    return S


def _sensitivity(model: IdentificationModel, setup, chi: np.ndarray, base, substeps) -> np.ndarray:
    """``dT/dchi`` (r, c) by forward differences of the closed-loop simulation (same RK4 substeps)."""
    J = np.empty((base.T.size, chi.size))
    scale = np.linalg.norm(chi) / math.sqrt(chi.size)
    for i in range(chi.size):
        h = FD_STEP * max(abs(chi[i]), 1e-2 * scale, 1e-8)
        th = chi.copy()
        th[i] += h
        J[:, i] = (simulated_output(model, setup, th, substeps=substeps, with_w=False).T - base.T) / h
    return J


def output_error_statistics(model: IdentificationModel, it: IterativeIdentification, *, jacobian: str = "auto",
                            fd_budget_s: float = FD_BUDGET_S) -> IterativeIdentification:
    """DIDIM statistics at the final estimate (module docstring): simulate ``chi``, output error
    ``e = Y - T(chi)``, ``sigma^2 = ||e||^2 / (r - c)``, sensitivity ``J``, and
    ``C = (W_s'J)^-1 S (J'W_s)^-1`` with ``S`` the Bartlett long-run covariance of ``W_s' e``.

    When the final estimate cannot be simulated the statistics of the last LS fit are kept and a
    warning says so."""
    res = it.result
    chi = np.asarray(res.values, float)
    t0 = time.perf_counter()
    try:
        so = simulated_output(model, it.setup, chi)
    except IdentificationError as exc:
        return replace(it, result=replace(res, warnings=res.warnings + (
            f"DIDIM statistics are those of the last least-squares fit: the final estimate cannot be simulated ({exc})",)))
    one = time.perf_counter() - t0
    W, Y = so.W, so.Y
    r, c = W.shape
    e = Y - so.T
    sigma = math.sqrt(float(e @ e) / (r - c))
    notes = []
    use_fd = jacobian == "fd" or (jacobian == "auto" and one * c <= fd_budget_s)
    if use_fd:
        try:
            J = _sensitivity(model, it.setup, chi, so, so.substeps)
        except IdentificationError as exc:
            J, use_fd = W, False
            notes.append(f"DIDIM covariance with J = W_s: a perturbed estimate cannot be simulated ({exc})")
    else:
        J = W
        notes.append(f"DIDIM covariance with J = W_s (GJV2013's approximation): the finite-difference sensitivity "
                     f"would take {c} simulations of ~{one:.0f} s (> {fd_budget_s:g} s; jacobian='fd' forces it)")
    ms = it.setup.measured
    keys = (ms.row_experiment.astype(np.int64) << 40) + ms.row_sample.astype(np.int64)
    groups = [np.flatnonzero((ms.system.joint == j) & (ms.row_experiment == x))
              for x in np.unique(ms.row_experiment) for j in np.unique(ms.system.joint)]
    groups = [g[np.argsort(ms.row_sample[g], kind="stable")] for g in groups if g.size]
    lags = _bartlett_lags(e, groups)
    S = hac_score_covariance(W * e[:, None], keys, lags) * (r / (r - c))
    A = np.linalg.pinv(W.T @ J)
    cov = A @ S @ A.T
    cov = (cov + cov.T) / 2
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    new = replace(res, std=std, cov=cov, sigma=sigma, rel_std_pct=relative_std_pct(chi, std), residual=e,
                  rel_err=per_joint_rel_err(e, Y, ms.system.joint, ms.system.n_joints),
                  warnings=res.warnings + tuple(notes))
    stats = {"jacobian": "finite differences" if use_fd else "W_s", "hac_lags": lags}
    return replace(it, result=new, tracking_error=tracking_error_rms(so.runs), statistics=stats)
