"""IDIM-IV: instrumental-variable identification with instruments from a simulated model.

A. Janot, P.-O. Vandanjon, M. Gautier, "A generic instrumental variable approach for industrial robot
identification", IEEE Trans. Control Systems Technology 22(1), 2014 ([JVG2014], docs/references.md).

With noisy positions, the observation matrix ``W`` built from the filtered measured ``q, dq, ddq`` is
correlated with the error ``rho`` of ``Y = W chi + rho`` and IDIM-OLS is biased. IDIM-IV uses as
instruments the observation matrix ``Z`` evaluated on the *simulated* (noise-free) states of the robot
model with the current estimate, driven in closed loop by the same reference
(:func:`symoro_gen.simulate.closed_loop.simulate_closed_loop`), filtered and decimated exactly as ``W``
(same :class:`~symoro_gen.observations.AssemblyOptions` and filter settings):

* ``chi_IV = (Z' W)^-1 Z' Y`` (JVG2014), started from IDIM-OLS and iterated (new simulation with
  the new estimate) until ``|chi_k+1 - chi_k| / |chi_k| < tol`` (JVG2014);
* ``sigma^2 = ||Y - W chi_IV||^2 / (r - c)``, ``C = sigma^2 (Z'W)^-1 Z'Z (W'Z)^-1``,
  ``%sigma_i = 100 sigma_i / |chi_i|``.

Computed with the QR factor of ``Z = Q R``: ``chi = (Q'W)^-1 Q'Y`` and ``C = sigma^2 (Q'W)^-1 (Q'W)^-T``.

The shared machinery of IDIM-IV and DIDIM (:mod:`.didim`) lives here: :class:`ClosedLoopSetup`
(reference, controller gains and filter settings per experiment) and :func:`simulated_system`
(the observation system of a closed-loop simulation, rows aligned with the measured one).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.assembly import Assembly, assemble
from ..observations.options import AssemblyOptions
from ..observations.system import ObservationSystem
from ..preprocessing.filtering import filter_and_differentiate
from ..preprocessing.trajectory import Trajectory
from ..simulate.closed_loop import FRICTION_EPS, PIDGains, default_gains, parameter_vector, simulate_closed_loop
from .estimators import COND_WARN, REL_STD_WARN_PCT, fit_ols
from .physical import base_matrix, standard_from_base
from .result import IdentificationResult, per_joint_rel_err, relative_std_pct

if TYPE_CHECKING:
    from typing_extensions import Unpack

__all__ = ["ClosedLoopSetup", "IterativeIdentification", "LoopOptions", "LoopSettings", "SimulatedOutput",
           "closed_loop_setup", "identify_iv", "iterate", "iv_fit", "physical_projection", "reference_ols", "simulated_output", "simulated_system"]

#: default convergence tolerance on ``|chi_k+1 - chi_k| / |chi_k|``
TOL = 1e-3
#: default maximum number of iterations
MAX_ITER = 20
#: step halvings tried when a new estimate cannot be simulated
MAX_HALVINGS = 4


class LoopOptions(TypedDict, total=False):
    """The keywords of the closed-loop iteration shared by IDIM-IV and DIDIM (:func:`iterate`,
    :func:`identify_iv`, :func:`~.didim.identify_didim`; defaults in :class:`LoopSettings`)."""

    references: Sequence[Any] | None
    gains: PIDGains | Sequence[PIDGains] | None
    bandwidth_hz: float | None
    friction_eps: float
    max_iter: int
    tol: float
    start: Any


@dataclass(frozen=True)
class LoopSettings:
    """The closed-loop iteration's settings: the simulated controller (``references``, ``gains``,
    ``bandwidth_hz``, ``friction_eps``: see :func:`closed_loop_setup`), the first estimate simulated
    (``start``, None: the IDIM-OLS estimate) and the stop (``max_iter`` iterations at most, relative change
    below ``tol``)."""

    references: Sequence[Any] | None = None
    gains: PIDGains | Sequence[PIDGains] | None = None
    bandwidth_hz: float | None = None
    friction_eps: float = FRICTION_EPS
    max_iter: int = MAX_ITER
    tol: float = TOL
    start: Any = None

    @classmethod
    def of(cls, function: str, keywords: Mapping[str, Any]) -> LoopSettings:
        """The settings of the keywords given to ``function`` (an unknown keyword is the TypeError Python
        raises for it)."""
        unknown = [k for k in keywords if k not in cls.__dataclass_fields__]
        if unknown:
            raise TypeError(f"{function}() got an unexpected keyword argument {unknown[0]!r}")
        return cls(**keywords)


@dataclass(frozen=True, eq=False)
class ClosedLoopSetup:
    """What the closed-loop simulations of IDIM-IV and DIDIM share, per experiment.

    Attributes
    ----------
    trajectories : tuple of Trajectory
        The measured experiments.
    references : tuple of (q_ref, dq_ref)
        Reference positions and velocities at the recording's instants, shape (N, n) each.
    reference_source : tuple of str
        ``"recorded"`` (``Trajectory.meta['q_ref']`` or given) or ``"filtered q"``.
    gains : tuple of PIDGains
        Controller gains per experiment.
    options : tuple of AssemblyOptions
        Assembly options of each experiment with its filter settings frozen (so the simulated states
        are filtered and decimated exactly as the measured ones), no row selection.
    measured : Assembly
        The assembly of the measured data (user options).
    friction_eps : float
        Coulomb smoothing of the simulations.
    """

    trajectories: tuple[Trajectory, ...]
    references: tuple[tuple[np.ndarray, np.ndarray], ...]
    reference_source: tuple[str, ...]
    gains: tuple[PIDGains, ...]
    options: tuple[AssemblyOptions, ...]
    measured: Assembly
    friction_eps: float = FRICTION_EPS


def _frozen_options(opts: AssemblyOptions, st) -> AssemblyOptions:
    return replace(opts, cutoff_hz=float(st.cutoff_hz), n_d=int(st.n_d), edge_samples=int(st.edge_samples),
                   dynamics_bandwidth_hz=float(st.dynamics_bandwidth_hz), min_velocity=None, payload_columns=False,
                   keep_signals=False)


def closed_loop_setup(model: IdentificationModel, trajectories: Trajectory | Sequence[Trajectory],
                      options: AssemblyOptions | None, theta0, *, references=None, gains=None,
                      bandwidth_hz: float | None = None, friction_eps: float = FRICTION_EPS,
                      measured: Assembly | None = None) -> ClosedLoopSetup:
    """Reference, gains and frozen filter settings per experiment.

    Parameters
    ----------
    model : IdentificationModel
    trajectories : Trajectory or sequence
        Unloaded recordings.
    options : AssemblyOptions
    theta0 : array_like or mapping
        Base parameters used for the default gains (the IDIM-OLS estimate).
    references : sequence of array_like (N, n) or None, optional
        Recorded reference positions per experiment (None entries: see below).
        Default per experiment: ``Trajectory.meta['q_ref']`` when present, else the measured positions
        low-passed by the experiment's Butterworth filter (its velocity by central differences).
    gains : PIDGains or sequence of PIDGains, optional
        Controller gains; default :func:`~symoro_gen.simulate.closed_loop.default_gains` from ``theta0``
        (PD at ``bandwidth_hz``).
    """
    trajs = (trajectories,) if isinstance(trajectories, Trajectory) else tuple(trajectories)
    if not trajs:
        raise IdentificationError("no trajectory given")
    loaded = [t.source for t in trajs if t.loaded]
    if loaded:
        raise IdentificationError(f"IDIM-IV/DIDIM simulate the robot without payload; loaded recordings {loaded} "
                                  f"are not supported")
    opts = AssemblyOptions() if options is None else options
    if measured is None:
        measured = assemble(model, trajs, replace(opts, payload_columns=False))
    n = int(model.N_JOINTS)
    refs, srcs, gl, ol = [], [], [], []
    if references is not None and len(references) != len(trajs):
        raise IdentificationError(f"{len(references)} references for {len(trajs)} recordings")
    if isinstance(gains, PIDGains) or gains is None:
        gains_list = [gains] * len(trajs)
    else:
        gains_list = list(gains)
        if len(gains_list) != len(trajs):
            raise IdentificationError(f"{len(gains_list)} controller gain sets for {len(trajs)} recordings")
    for i, tr in enumerate(trajs):
        st = measured.experiments[i].settings
        ref = None if references is None else references[i]
        if ref is None:
            ref = tr.meta.get("q_ref") if isinstance(tr.meta, dict) else None
        if ref is not None:
            qr = np.asarray(ref, float)
            if qr.shape != tr.q.shape:
                raise IdentificationError(f"{tr.source}: reference positions have shape {qr.shape}, "
                                          f"the recording {tr.q.shape}")
            dqr = np.gradient(qr, tr.dt, axis=0)
            srcs.append("recorded")
        else:
            qr, dqr, _ = filter_and_differentiate(tr.q, st.fs, st.cutoff_hz, st.order, source=tr.source)
            srcs.append("filtered q")
        refs.append((qr, dqr))
        g = gains_list[i]
        if g is None:
            g = default_gains(model, theta0, qr, tr.dt, bandwidth_hz=bandwidth_hz, friction_eps=friction_eps)
        if g.n_joints != n:
            raise IdentificationError(f"{g.n_joints} controller gains for the {n} joints of {model.ROBOT}")
        gl.append(g)
        ol.append(_frozen_options(opts, st))
    return ClosedLoopSetup(trajs, tuple(refs), tuple(srcs), tuple(gl), tuple(ol), measured, float(friction_eps))


def _row_keys(asm: Assembly, experiment: int | None = None) -> np.ndarray:
    joint = asm.system.joint.astype(np.int64)
    sample = asm.row_sample.astype(np.int64)
    exp = asm.row_experiment.astype(np.int64) if experiment is None else np.full(joint.size, experiment, np.int64)
    return (exp << 40) + (joint << 32) + sample


def _match_rows(setup: ClosedLoopSetup, keys: list, *blocks: list) -> list:
    """The stacked ``blocks`` reordered to the rows of ``setup.measured.system`` (same experiment,
    joint and decimated sample)."""
    allk = np.concatenate(keys)
    want = _row_keys(setup.measured)
    order = np.argsort(allk)
    pos = np.clip(np.searchsorted(allk, want, sorter=order), 0, allk.size - 1)
    idx = order[pos]
    if not np.array_equal(allk[idx], want):
        raise IdentificationError("internal: the simulated observation rows do not match the measured ones")
    return [(np.vstack(b) if b[0].ndim == 2 else np.concatenate(b))[idx] for b in blocks]


def simulated_system(model: IdentificationModel, setup: ClosedLoopSetup, theta) -> tuple[ObservationSystem, list]:
    """The observation system on the closed-loop simulation with parameters ``theta``.

    Each experiment's reference is tracked by the simulated robot (same controller gains); the
    simulated positions replace the measured ones in a copy of the recording (the measured torque
    is kept) that is assembled with the measured experiment's filter settings, and its rows are
    matched with the measured system's rows (same experiment, joint and sample).

    Returns
    -------
    system : ObservationSystem
        ``W`` = the observation matrix on the simulated states (``Z``), ``Y`` = the measured torque,
        rows in the order of ``setup.measured.system``.
    runs : list of ClosedLoopResult
    """
    blocks_w, keys, runs = [], [], []
    y_parts = []
    for i, tr in enumerate(setup.trajectories):
        qr, dqr = setup.references[i]
        run = simulate_closed_loop(model, theta, tr.t, qr, dqr, gains=setup.gains[i],
                                   friction_eps=setup.friction_eps)
        runs.append(run)
        sim = Trajectory(t=tr.t, q=run.q, tau=tr.tau, dq=run.dq, ddq=run.ddq, source=f"{tr.source} (simulated)")
        asm = assemble(model, sim, setup.options[i])
        blocks_w.append(asm.system.W)
        y_parts.append(asm.system.Y)
        keys.append(_row_keys(asm, experiment=i))
    W, Y = _match_rows(setup, keys, blocks_w, y_parts)
    ms = setup.measured.system
    return ObservationSystem(W, Y, ms.names, ms.joint), runs


@dataclass(frozen=True, eq=False)
class SimulatedOutput:
    """The closed-loop simulation of one estimate, in the rows of the measured system.

    Attributes
    ----------
    W : ndarray (r, c)
        The observation matrix on the simulated states, with the simulation's own velocities and
        accelerations (``W chi`` is the simulated torque up to the Coulomb smoothing).
    T : ndarray (r,)
        The simulated torque (the controller's output), filtered and decimated as the measured ``Y``.
    Y : ndarray (r,)
        The measured torque.
    runs : list of ClosedLoopResult
    """

    W: np.ndarray
    T: np.ndarray
    Y: np.ndarray
    runs: list
    W_filtered: np.ndarray | None = None

    @property
    def substeps(self) -> tuple[int, ...]:
        return tuple(int(r.substeps) for r in self.runs)


def simulated_output(model: IdentificationModel, setup: ClosedLoopSetup, theta, *, substeps=None,
                     with_w: bool = True, filtered: bool = False) -> SimulatedOutput:
    """Simulate ``theta`` in closed loop on every experiment; the simulated torque ``T`` (and the
    observation matrix ``W`` on the simulated states) decimated as the measured system, in its rows.
    ``filtered``: also ``W_filtered``, the observation matrix of the simulated positions band-pass
    differentiated as the measured ones (:func:`simulated_system`'s).

    ``substeps`` (one per experiment) fixes the RK4 substeps (the finite-difference sensitivities
    of DIDIM need the same integrator for every perturbed estimate)."""
    blocks_w, blocks_t, blocks_f, keys, keys_f, runs = [], [], [], [], [], []
    for i, tr in enumerate(setup.trajectories):
        qr, dqr = setup.references[i]
        run = simulate_closed_loop(model, theta, tr.t, qr, dqr, gains=setup.gains[i], friction_eps=setup.friction_eps,
                                   substeps=None if substeps is None else int(substeps[i]))
        runs.append(run)
        sim = Trajectory(t=tr.t, q=run.q, tau=run.tau, dq=run.dq, ddq=run.ddq, source=f"{tr.source} (simulated)")
        asm = assemble(model, sim, replace(setup.options[i], use_recorded_derivatives=True))
        blocks_w.append(asm.system.W if with_w else np.zeros((asm.system.Y.size, 0)))
        blocks_t.append(asm.system.Y)
        keys.append(_row_keys(asm, experiment=i))
        if filtered:
            asm_f = assemble(model, sim, setup.options[i])
            blocks_f.append(asm_f.system.W)
            keys_f.append(_row_keys(asm_f, experiment=i))
    W, T = _match_rows(setup, keys, blocks_w, blocks_t)
    W_f = _match_rows(setup, keys_f, blocks_f)[0] if filtered else None
    return SimulatedOutput(W, T, np.asarray(setup.measured.system.Y, float), runs, W_f)


@dataclass(frozen=True, eq=False)
class IterativeIdentification:
    """Result of an iterated estimator (IDIM-IV, DIDIM).

    Attributes
    ----------
    result : IdentificationResult
        The final estimate with its statistics (``method`` = ``"IV"`` or ``"DIDIM"``).
    ols : IdentificationResult
        The IDIM-OLS estimate (the default start of the iterations).
    iterations : int
        Simulations run (one per iteration).
    converged : bool
        ``|chi_k+1 - chi_k| / |chi_k| < tol`` was reached within ``max_iter``.
    history : ndarray, shape (iterations + 1, c)
        The estimates, starting with the start (IDIM-OLS by default).
    changes : ndarray, shape (iterations,)
        Relative change of each iteration.
    setup : ClosedLoopSetup
        References, gains, filter settings.
    tracking_error : ndarray, shape (n,)
        RMS ``q_ref - q`` of the last simulation (all experiments).
    start_source : str
        ``"IDIM-OLS"``, ``"OLS on the reference states"``, ``"physical projection of IDIM-OLS"``
        (fallbacks) or ``"given"``.
    """

    result: IdentificationResult
    ols: IdentificationResult
    iterations: int
    converged: bool
    history: np.ndarray
    changes: np.ndarray
    setup: ClosedLoopSetup
    tracking_error: np.ndarray
    start_source: str = "IDIM-OLS"
    statistics: dict | None = None

    def to_dict(self) -> dict:
        """The ``iterations`` block of the JSON output."""
        return {"method": self.result.method, "iterations": self.iterations, "converged": self.converged,
                "start": self.start_source,
                "changes": [float(c) for c in self.changes], "reference": list(self.setup.reference_source),
                "controller_gains": [g.to_dict() for g in self.setup.gains],
                "tracking_error_rms": [float(x) for x in self.tracking_error],
                **({} if self.statistics is None else {"statistics": self.statistics})}

    def summary(self) -> str:
        st = "converged" if self.converged else "NOT converged"
        return (f"{self.result.method}: {self.iterations} iteration(s) from {self.start_source}, {st} "
                f"(last relative change {self.changes[-1] if self.changes.size else float('nan'):.3g}); "
                f"reference: {', '.join(sorted(set(self.setup.reference_source)))}; closed-loop tracking error "
                f"RMS per joint: {', '.join(f'{x:.3g}' for x in self.tracking_error)}")


def tracking_error_rms(runs) -> np.ndarray:
    """RMS per joint of the closed-loop tracking error ``q_ref - q`` over every simulated run."""
    num = sum(np.sum((r.q_ref - r.q) ** 2, axis=0) for r in runs)
    den = sum(r.q.shape[0] for r in runs)
    return np.sqrt(num / den)


def iv_fit(system: ObservationSystem, instruments: np.ndarray, *, rel_std_warn_pct: float = REL_STD_WARN_PCT,
           cond_warn: float = COND_WARN) -> IdentificationResult:
    """One IV solve ``chi = (Z'W)^-1 Z'Y`` with its covariance (JVG2014).

    Parameters
    ----------
    system : ObservationSystem
        ``W`` (measured states) and ``Y``.
    instruments : ndarray, shape like ``system.W``
        ``Z``.
    """
    W, Y, Z = system.W, system.Y, np.asarray(instruments, float)
    r, c = W.shape
    if Z.shape != W.shape:
        raise IdentificationError(f"instruments {Z.shape} and W {W.shape} differ in shape")
    if r <= c:
        raise IdentificationError(f"IDIM-IV: too few equations: {r} rows for {c} parameters")
    norms = np.linalg.norm(W, axis=0)
    zn = np.linalg.norm(Z, axis=0)
    if np.any(norms == 0) or np.any(zn == 0):
        zero = [system.names[i] for i in np.flatnonzero((norms == 0) | (zn == 0))]
        raise IdentificationError(f"IDIM-IV: column(s) {zero} of W or of the instruments are all zero")
    Q, _ = np.linalg.qr(Z / zn)
    B = Q.T @ (W / norms)
    s = np.linalg.svd(B, compute_uv=False)
    if s[-1] <= 1e-12 * s[0]:
        raise IdentificationError("IDIM-IV: Z'W is singular (the instruments are not correlated with every column of W)")
    x = np.linalg.solve(B, Q.T @ Y)
    values = x / norms
    res = Y - W @ values
    sigma = math.sqrt(float(res @ res) / (r - c))
    Binv = np.linalg.inv(B)
    cov = sigma ** 2 * (Binv @ Binv.T) / np.outer(norms, norms)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    sv = np.linalg.svd(W, compute_uv=False)
    svs = np.linalg.svd(W / norms, compute_uv=False)
    cond, cond_s = float(sv[0] / sv[-1]), float(svs[0] / svs[-1])
    warnings = []
    if cond_s > cond_warn:
        warnings.append(f"W is ill-conditioned: cond = {cond:.3g}, {cond_s:.3g} with unit-norm columns (> {cond_warn:g})")
    pct = relative_std_pct(values, std)
    bad = [f"{n} ({p:.3g}%)" for n, p in zip(system.names, pct) if p > rel_std_warn_pct]
    if bad:
        warnings.append(f"{len(bad)} parameter(s) poorly identified (%sigma > {rel_std_warn_pct:g}): {', '.join(bad)}")
    return IdentificationResult(method="IV", names=system.names, values=values, std=std, rel_std_pct=pct, cov=cov,
                                cond=cond, cond_scaled=cond_s, sigma=sigma,
                                rel_err=per_joint_rel_err(res, Y, system.joint, system.n_joints), n_rows=r,
                                residual=res, warnings=tuple(warnings))


def _rel_change(new: np.ndarray, old: np.ndarray) -> float:
    return float(np.linalg.norm(new - old) / max(np.linalg.norm(old), 1e-300))


def reference_ols(model: IdentificationModel, setup: ClosedLoopSetup) -> IdentificationResult:
    """IDIM-OLS of the measured torque on the observation matrix of the *reference* states (noise-free
    when the reference is recorded): the fallback start when the IDIM-OLS estimate cannot be simulated."""
    systems = []
    for i, tr in enumerate(setup.trajectories):
        qr, dqr = setup.references[i]
        ref = Trajectory(t=tr.t, q=qr, tau=tr.tau, source=f"{tr.source} (reference)")
        systems.append(assemble(model, ref, setup.options[i]).system)
    W = np.vstack([s.W for s in systems])
    order = np.argsort(np.concatenate([s.joint for s in systems]), kind="stable")
    Y = np.concatenate([s.Y for s in systems])
    J = np.concatenate([s.joint for s in systems])
    return fit_ols(ObservationSystem(W[order], Y[order], systems[0].names, J[order]))


def physical_projection(model: IdentificationModel, theta) -> np.ndarray | None:
    """The base parameters of the physically consistent standard set closest to giving ``theta``
    (:func:`~symoro_gen.identification.physical.standard_from_base`: pseudo-inertias positive
    semidefinite, Wensing, Kim & Slotine 2018; ``IA, FV, FS >= 0``), i.e. ``theta`` itself when it is
    physical, else its least-squares projection on the physical set. Among the consistent sets the one
    closest to the robot file's nominal parameters is taken when the model has them (pulled toward
    zero instead, the unidentifiable inertias of a wrist vanish and its inertia matrix is singular:
    it cannot be simulated, seen on the real LWR4). None without cvxpy."""

    nominal = getattr(model, "nominal_parameters", lambda: None)()
    if nominal is not None and not np.any(np.asarray(nominal, float) != 0):
        nominal = None
    try:
        sfb = standard_from_base(model, np.asarray(theta, float), nominal)
    except IdentificationError:
        return None
    return base_matrix(model) @ np.asarray(sfb.values, float)


def _simulable(model: IdentificationModel, setup: ClosedLoopSetup, theta) -> str | None:
    """None when ``theta`` can be simulated on the first experiment, else the reason."""
    tr = setup.trajectories[0]
    qr, dqr = setup.references[0]
    try:
        simulate_closed_loop(model, theta, tr.t, qr, dqr, gains=setup.gains[0], friction_eps=setup.friction_eps)
    except IdentificationError as exc:
        return str(exc)
    return None


def iterate(model: IdentificationModel, trajectories: Trajectory | Sequence[Trajectory], options: AssemblyOptions | None,
            step, label: str, *, simulate=None, **loop: Unpack[LoopOptions]) -> IterativeIdentification:
    """The iteration shared by IDIM-IV and DIDIM: simulate the current estimate in closed loop, assemble
    the simulated states, ``chi_k+1 = step(measured_system, simulated_system)``, until the relative
    change is below ``tol``. ``simulate(model, setup, theta) -> (system, runs)`` builds the simulated
    system (default :func:`simulated_system`).

    The start is ``start`` when given, else the IDIM-OLS estimate; when that one cannot be simulated
    (inertia matrix not positive definite, diverging loop: noisy positions can make OLS non-physical),
    the OLS fit on the reference states (:func:`reference_ols`) is tried, and said in the warnings.
    When neither can, the physically consistent projection of IDIM-OLS (:func:`physical_projection`)
    starts. When a new estimate cannot be simulated, its physically consistent projection is simulated
    instead; when that fails too, the step from the last simulated estimate is halved (up to
    :data:`MAX_HALVINGS` times), as a damped Gauss–Newton iteration does. ``loop``: :class:`LoopSettings`.
    """
    lp = LoopSettings.of("iterate", loop)
    max_iter, tol = lp.max_iter, lp.tol
    opts = AssemblyOptions() if options is None else options
    trajs = (trajectories,) if isinstance(trajectories, Trajectory) else tuple(trajectories)
    sim_fn = simulated_system if simulate is None else simulate
    if int(max_iter) < 1:
        raise IdentificationError(f"max_iter must be >= 1, got {max_iter}")
    measured = assemble(model, trajs, replace(opts, payload_columns=False))
    if tuple(measured.system.names) != tuple(model.BASE_NAMES):
        raise IdentificationError(f"{label} needs the base-parameter columns of the model")
    ols = fit_ols(measured.system)
    notes: list[str] = []
    theta, source, setup = _simulable_start(model, trajs, opts, measured, ols, lp, label, notes)
    history = [theta]
    changes: list[float] = []
    res, runs, converged = ols, [], False
    prev = None
    for _ in range(int(max_iter)):
        ssys, failure, proj = None, "", None
        try:
            ssys, runs = sim_fn(model, setup, theta)
        except IdentificationError as exc:
            if prev is None:
                raise IdentificationError(
                    f"{label} iteration 1: cannot simulate the start: {exc}; filter more (a lower cutoff) or give "
                    f"a physical start (start=...)") from None
            failure = str(exc)
        if ssys is None:
            # the new estimate is not physical (M(q) indefinite) or its closed loop diverges: first its
            # physically consistent projection (Wensing, Kim & Slotine 2018 constraints, physical.py),
            # keeping the information of the step; else the damped step (Gauss-Newton with step halving)
            proj = physical_projection(model, theta)
            if proj is not None:
                try:
                    ssys, runs = sim_fn(model, setup, proj)
                    notes.append(f"{label} iteration {len(changes)}: the estimate could not be simulated "
                                 f"({failure}); replaced by its physically consistent projection")
                except IdentificationError:
                    ssys = None
                # the damped steps below go toward the projection: with a physical last estimate every
                # point between is physical (the constraints are convex, the regrouping linear)
                theta = proj
                history[-1] = theta
        if ssys is None:
            assert prev is not None
            toward = "" if proj is None else " toward its physically consistent projection"
            for halving in range(1, MAX_HALVINGS + 1):
                theta = prev + 0.5 * (theta - prev)
                history[-1] = theta
                try:
                    ssys, runs = sim_fn(model, setup, theta)
                    break
                except IdentificationError as exc:
                    if halving == MAX_HALVINGS:
                        raise IdentificationError(
                            f"{label} iteration {len(changes) + 1}: cannot simulate the current estimate: {exc}; "
                            f"filter more (a lower cutoff) or give a physical start (start=...)") from None
            notes.append(f"{label} iteration {len(changes)}: the full step could not be simulated; step halved{toward}")
        prev = theta
        res = step(measured.system, ssys)
        changes.append(_rel_change(res.values, theta))
        theta = res.values
        history.append(theta)
        if changes[-1] < tol:
            converged = True
            break
    if not converged:
        notes.append(f"{label} did not converge in {max_iter} iterations (last relative change {changes[-1]:.3g} "
                     f">= {tol:g})")
    res = replace(res, warnings=tuple(notes) + res.warnings)
    return IterativeIdentification(res, ols, len(changes), converged, np.array(history), np.array(changes), setup,
                                   tracking_error_rms(runs), source)


def _simulable_start(model: IdentificationModel, trajs: tuple[Trajectory, ...], opts: AssemblyOptions,
                     measured: Assembly, ols: IdentificationResult, lp: LoopSettings, label: str, notes: list[str]
                     ) -> tuple[np.ndarray, str, ClosedLoopSetup]:
    """The first estimate simulated, what it is, and the closed-loop setup (see :func:`iterate`): ``start``
    when given, else IDIM-OLS, else the OLS fit on the reference states, else the physically consistent
    projection of IDIM-OLS (said in ``notes``)."""
    theta = ols.values if lp.start is None else parameter_vector(model, lp.start)
    source = "IDIM-OLS" if lp.start is None else "given"

    def setup_at(theta0: np.ndarray, gains) -> ClosedLoopSetup:
        return closed_loop_setup(model, trajs, opts, theta0, references=lp.references, gains=gains,
                                 bandwidth_hz=lp.bandwidth_hz, friction_eps=lp.friction_eps, measured=measured)

    setup = setup_at(theta, lp.gains)
    if lp.start is not None:
        return theta, source, setup
    why = _simulable(model, setup, theta)
    if why is None:
        return theta, source, setup
    alt = reference_ols(model, setup).values
    if lp.gains is None:  # the default gains came from the rejected estimate
        setup = setup_at(alt, None)
    why2 = _simulable(model, setup, alt)
    if why2 is None:
        notes.append(f"{label} started from the OLS fit on the reference states: the IDIM-OLS estimate cannot "
                     f"be simulated ({why})")
        return alt, "OLS on the reference states", setup
    proj = physical_projection(model, ols.values)
    if proj is not None and lp.gains is None:  # default gains from the start actually simulated
        setup = setup_at(proj, None)
    why3 = "cvxpy is not installed" if proj is None else _simulable(model, setup, proj)
    if proj is None or why3 is not None:
        raise IdentificationError(
            f"{label}: cannot simulate the IDIM-OLS start ({why}), the OLS fit on the reference states "
            f"({why2}) nor the physically consistent projection of IDIM-OLS ({why3}); filter more "
            f"(a lower cutoff) or give a physical start (start=...)")
    notes.append(f"{label} started from the physically consistent projection of the IDIM-OLS estimate "
                 f"(neither it ({why}) nor the OLS fit on the reference states ({why2}) can be simulated)")
    return proj, "physical projection of IDIM-OLS", setup


def identify_iv(model: IdentificationModel, trajectories: Trajectory | Sequence[Trajectory],
                options: AssemblyOptions | None = None, *, references=None, gains=None,
                bandwidth_hz: float | None = None, friction_eps: float = FRICTION_EPS, max_iter: int = MAX_ITER,
                tol: float = TOL, start=None) -> IterativeIdentification:
    """IDIM-IV (JVG2014): instruments from the closed-loop simulation of the current estimate, iterated.

    Parameters
    ----------
    model : IdentificationModel
    trajectories : Trajectory or sequence of Trajectory
        Measured, unloaded recordings (``t, q, tau``).
    options : AssemblyOptions
        Filtering and decimation (as IDIM-OLS); ``min_velocity`` applies to the rows.
    references, gains, bandwidth_hz, friction_eps
        See :func:`closed_loop_setup`.
    max_iter : int
        Iterations (simulations) at most.
    tol : float
        Stop when ``|chi_k+1 - chi_k| / |chi_k| < tol``.
    start : array_like or mapping, optional
        First estimate to simulate (``BASE_NAMES`` order or name -> value); default the IDIM-OLS
        estimate (or, when it cannot be simulated, :func:`reference_ols`; see :func:`iterate`).

    Returns
    -------
    IterativeIdentification
        ``result.method == "IV"``.

    Raises
    ------
    IdentificationError
        No simulable start, diverging simulation, singular ``Z'W``.
    """
    return iterate(model, trajectories, options, lambda measured, sim: iv_fit(measured, sim.W), "IDIM-IV",
                   references=references, gains=gains, bandwidth_hz=bandwidth_hz, friction_eps=friction_eps,
                   max_iter=max_iter, tol=tol, start=start)
