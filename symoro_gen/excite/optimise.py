"""The optimisation of an excitation design: IPOPT through CasADi on the smooth criterion from the best random
feasible designs (:func:`optimise_excitation`, its settings :class:`ExciteSettings` and the named efforts
:data:`EFFORTS`), each start then refined on the true cond (:func:`~symoro_gen.excite.refine.refine_excitation`),
the starts in forked processes when asked."""
from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import IdentificationModel
from ..progress import ProgressCounter
from .bases import FourierBasis, basis_eval, dense_times, output_times
from .criterion import (
    COND_POWER,
    COND_POWERS,
    casadi_regressor,
    design_information,
    smooth_criterion,
    stacked_cond,
)
from .designs import friction_trajectory, inside_limits, random_trajectory, scale_into
from .limits import ExcitationError, Limits, check_limits, load_casadi
from .refine import REFINE_ITERATIONS, REFINE_RATE, refine_excitation

__all__ = ["EFFORTS", "ExcitationResult", "ExciteSettings", "build_nlp", "optimise_excitation", "worker_count"]


@dataclass(frozen=True)
class ExciteSettings:
    """How :func:`optimise_excitation` searches (checked once, when made: a bad value is an
    :class:`ExcitationError` naming the command-line option).

    Attributes
    ----------
    criterion : {"cond", "logdet"}
        The smooth power-mean bound of ``cond(W)^2`` or ``-log det M``.
    starts, seed : int
        IPOPT starts and the seed of the random designs.
    pool : int, optional
        Random feasible designs drawn (default ``10 * starts``); the ``starts`` of lowest ``cond`` are
        the IPOPT starts (a multistart from the best of a random population, as FloBaRoID does).
    structured : int
        Designs of :func:`~symoro_gen.excite.designs.friction_trajectory` added to the pool.
    samples : int, optional
        Samples of the criterion (default ``max(8 nb / n, 20 m)`` up to 200).
    max_iter : int
        IPOPT iterations per stage.
    warm_start : bool
        IPOPT starts at the start design with a small barrier parameter (``warm_start_init_point``, ``mu_init``
        1e-3) instead of first moving towards the middle of the feasible set: from a start within the limits it
        needs fewer iterations (the quick effort's 50 iterations reach what 120 default ones do on the LWR4).
    margin : float
        Fraction by which the limits are tightened in the optimisation (the output is checked
        against the full limits).
    powers : tuple of int, optional
        ``criterion="cond"``: the powers ``p`` of the smooth criterion run in turn from each start, each stage
        warm-started from the previous one (continuation; None: :data:`COND_POWERS`).
    refine : int
        ``criterion="cond"``: at most this many SDP iterations of
        :func:`~symoro_gen.excite.refine.refine_excitation` on each start's IPOPT result; 0 skips it.
    jobs : int, optional
        Processes the starts run in at once (forked workers, Linux; 0: one per CPU this process may use;
        1: in this process). The result is the same whatever ``jobs``.
    """

    criterion: str = "cond"
    starts: int = 4
    seed: int = 0
    pool: int | None = None
    structured: int = 0
    samples: int | None = None
    max_iter: int = 200
    margin: float = 0.01
    powers: tuple[int, ...] | None = None
    refine: int = 0
    jobs: int | None = 1
    warm_start: bool = False

    def __post_init__(self) -> None:
        if self.criterion not in ("cond", "logdet"):
            raise ExcitationError(f"--criterion {self.criterion!r}: expected cond or logdet")
        if self.starts < 1:
            raise ExcitationError(f"--starts {self.starts}: at least one start is needed")
        for name, v in (("--pool", self.pool), ("--structured-starts", self.structured), ("--samples", self.samples),
                        ("--max-iter", self.max_iter)):
            if v is not None and v < 0:
                raise ExcitationError(f"{name} {v}: must be >= 0")
        if not 0.0 <= self.margin < 1.0:
            raise ExcitationError(f"margin {self.margin:g}: must be in [0, 1)")
        if self.powers is not None:
            object.__setattr__(self, "powers", tuple(int(p) for p in self.powers))
            for p in self.powers or ():
                if p < 2 or p & (p - 1):
                    raise ExcitationError(f"cond criterion power {p}: must be a power of 2")
        if self.refine < 0:
            raise ExcitationError(f"--refine {self.refine}: must be a number of iterations >= 0")
        if self.jobs is not None and self.jobs < 0:
            raise ExcitationError(f"--jobs {self.jobs}: must be a number of processes >= 1, or 0 for one per CPU")

    @property
    def stages(self) -> tuple[int, ...]:
        """The powers of the IPOPT stages run from each start (one stage for ``"logdet"``)."""
        if self.criterion != "cond":
            return (COND_POWER,)
        return tuple(COND_POWERS if self.powers is None else self.powers)


#: the command's ``--effort`` presets, as :class:`ExciteSettings` fields (the other options keep their values).
#: ``quick``, the command's default: the best of 40 random designs through one IPOPT stage (p = 8, 50 iterations,
#: warm-started) and 5 SDPs, about a minute on the LWR4; ``thorough``: what the command ran before (the 4 best of 40
#: through two IPOPT stages of 200 iterations, then 20 SDPs each). Measured against each other by
#: ``bench/bench_excite_defaults.py`` (docs/excitation.md).
EFFORTS: dict[str, dict[str, Any]] = {
    "quick": {"starts": 1, "pool": 40, "max_iter": 50, "powers": (COND_POWER,), "refine": 5, "warm_start": True},
    "thorough": {"starts": 4, "pool": None, "max_iter": 200, "powers": COND_POWERS, "refine": REFINE_ITERATIONS,
                 "warm_start": False},
}


@dataclass
class ExcitationResult:
    """An optimised excitation trajectory and its figures.

    Attributes
    ----------
    t, q, dq, ddq : ndarray
        Output samples (``t`` (N,), the others (N, n)).
    X : ndarray (m, n)
        The design (see the basis).
    cond : float
        Unscaled condition number of the base regressor stacked over the output samples.
    limits_ok : bool
        Every output sample (and a 10x denser resampling) inside every limit.
    starts : list of dict
        Per random start: ``cond`` before and after IPOPT, IPOPT's return status.
    """

    basis: Any
    limits: Limits
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    X: np.ndarray
    cond: float
    limits_ok: bool
    usage: dict
    criterion: str
    starts: list = field(default_factory=list)
    wall_time: float = 0.0
    tau: np.ndarray | None = None


def build_nlp(model: IdentificationModel, basis, limits: Limits, t_obj: np.ndarray, t_con: np.ndarray,
              criterion: str, chi_b: np.ndarray | None, margin: float, power: int = COND_POWER) -> tuple[Any, dict]:
    """The NLP IPOPT solves (``{"x", "f", "g"}`` and the bounds ``{"lbg", "ubg"}`` of ``g``): the smooth criterion
    (:func:`~symoro_gen.excite.criterion.smooth_criterion`) on the samples ``t_obj``; the limits tightened by
    ``margin`` on the grid ``t_con`` (passive ranges and a floor included) and, with ``chi_b`` and torque limits,
    the torques on ``t_obj``."""
    ca = load_casadi()
    n, m = limits.n, basis.m
    x = ca.MX.sym("x", m * n)
    X = ca.reshape(x, m, n)  # column-major: column j = design of joint j
    f = smooth_criterion(design_information(model, basis, x, t_obj), criterion, power)
    lim = limits.shrunk(margin)
    Pc, Dc, Ac = basis.matrices(t_con)
    Nc = len(t_con)
    g = [ca.vec(ca.DM(Pc) @ X), ca.vec(ca.DM(Dc) @ X), ca.vec(ca.DM(Ac) @ X)]
    lbg = [np.repeat(lim.q_min, Nc), np.repeat(-lim.dq_max, Nc), np.repeat(-lim.ddq_max, Nc)]
    ubg = [np.repeat(lim.q_max, Nc), np.repeat(lim.dq_max, Nc), np.repeat(lim.ddq_max, Nc)]
    if lim.passive:  # passive joints of a linear closure: C q + offset within [lo, hi]
        Cp, off, lo, hi = lim.passive_rows()
        g.append(ca.vec(ca.DM(Pc) @ X @ ca.DM(Cp.T)))
        lbg.append(np.repeat(lo - off, Nc))
        ubg.append(np.repeat(hi - off, Nc))
    if lim.workspace is not None:  # every moving frame origin above the floor at every grid sample
        Hz = lim.workspace.casadi().map(Nc)((ca.DM(Pc) @ X).T)  # (frames, Nc)
        g.append(ca.vec(Hz))
        lbg.append(np.full(Hz.numel(), lim.workspace.z_min))
        ubg.append(np.full(Hz.numel(), np.inf))
    if chi_b is not None and lim.tau_max is not None:
        qs, dqs, ddqs = ca.MX.sym("q", n), ca.MX.sym("dq", n), ca.MX.sym("ddq", n)
        Hq = ca.Function("tau", [qs, dqs, ddqs], [casadi_regressor(model)(qs, dqs, ddqs) @ ca.DM(chi_b)])
        Po, Do, Ao = (ca.DM(M) for M in basis.matrices(t_obj))
        T = Hq.map(len(t_obj))((Po @ X).T, (Do @ X).T, (Ao @ X).T)  # (n, No)
        g.append(ca.vec(T.T))
        lbg.append(np.repeat(-lim.tau_max, len(t_obj)))
        ubg.append(np.repeat(lim.tau_max, len(t_obj)))
    nlp = {"x": x, "f": f, "g": ca.vertcat(*g)}
    return nlp, {"lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg)}


class _IpoptIterations:
    """IPOPT's iterations as they happen (the nlpsol option ``iteration_callback``, a CasADi callback): ``report(k)``
    is called after iteration ``k`` of the running stage when set (the command's progress bar), nothing otherwise."""

    def __init__(self) -> None:
        self.report: Any = None
        self.count = 0
        self._callback: Any = None

    def __call__(self) -> None:
        self.count += 1
        if self.report is not None:
            self.report(self.count)

    def options(self, nx: int, ng: int) -> dict:
        """The nlpsol options that call this object once per IPOPT iteration (the callback is built once)."""
        if self._callback is None:
            self._callback = _iteration_callback(nx, ng, self)
        return {"iteration_callback": self._callback, "iteration_callback_ignore_errors": True}


def _iteration_callback(nx: int, ng: int, notify) -> Any:
    """A ``casadi.Callback`` taking nlpsol's outputs (``x``, ``f``, ``g``, multipliers) that calls ``notify()``."""
    ca: Any = load_casadi()

    class Iterations(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("excite_iterations", {})

        def get_n_in(self) -> int:
            return ca.nlpsol_n_out()

        def get_n_out(self) -> int:
            return 1

        def get_name_in(self, i: int) -> str:
            return ca.nlpsol_out(i)

        def get_name_out(self, i: int) -> str:
            return "ret"

        def get_sparsity_in(self, i: int) -> Any:
            name = ca.nlpsol_out(i)
            if name == "f":
                return ca.Sparsity.scalar()
            if name in ("x", "lam_x"):
                return ca.Sparsity.dense(nx)
            if name in ("g", "lam_g"):
                return ca.Sparsity.dense(ng)
            return ca.Sparsity(0, 0)

        def eval(self, arg: Any) -> list:
            notify()
            return [0]

    return Iterations()


@dataclass(frozen=True, eq=False)
class _Start:
    """What every start of :func:`optimise_excitation` shares: the model, the design's basis and limits, the IPOPT
    stages (``solvers`` with their ``bounds``), the sample grids and the settings. Calling it runs one start."""

    model: IdentificationModel
    basis: Any
    limits: Limits
    solvers: list
    bounds: dict
    t_out: np.ndarray
    t_con: np.ndarray
    period: float
    duration: float
    cb: np.ndarray | None
    cfg: ExciteSettings
    iterations: _IpoptIterations

    @property
    def refine(self) -> int:
        return int(self.cfg.refine) if self.cfg.refine and self.cfg.criterion == "cond" else 0

    def __call__(self, X_init: np.ndarray, *, step, rec: dict, describe=None) -> tuple[float, np.ndarray]:
        """One start: the IPOPT stages in turn, then at most ``refine`` SDP iterations of :func:`refine_excitation`;
        ``step(k)`` reports ``k`` more of those steps done, ``rec`` (holding the start's ``cond_start``) receives
        the start's record, ``describe(text)`` (optional) what is running. Returns the start's cond on ``t_out`` and its design, never worse than the start's own
        (IPOPT minimises a smooth bound of cond, which can fall while cond rises)."""
        model, basis, limits, t_out = self.model, self.basis, self.limits, self.t_out
        n = limits.n
        x = X_init.T.reshape(-1)
        stage_conds, iters, status = [], 0, ""
        x_best, c_best = x, math.inf
        torques_ok = True
        if self.cb is not None and limits.tau_max is not None:
            tau = np.asarray(model.regressor(*basis_eval(basis, X_init, t_out))) @ self.cb
            torques_ok = bool(np.all(np.abs(tau) <= limits.tau_max * (1 + 1e-9)))
        if torques_ok and inside_limits(basis, limits, X_init, self.t_con):
            c_best = rec["cond_start"]  # a start within every limit, torques included, is a result too
        for p, solver in zip(self.cfg.stages, self.solvers):
            self.iterations.count = 0
            self.iterations.report = None if describe is None else functools.partial(self._ipopt_iteration, describe, p)
            sol = solver(x0=x, lbg=self.bounds["lbg"], ubg=self.bounds["ubg"])
            self.iterations.report = None
            step(1)
            stats = solver.stats()
            status, iters = stats.get("return_status", ""), iters + stats.get("iter_count", 0)
            x = np.asarray(sol["x"]).reshape(-1)
            stage_conds.append(stacked_cond(model, *basis_eval(basis, x.reshape(n, basis.m).T, t_out)))
            # a failed stage (e.g. IPOPT's Error_In_Step_Computation at a large p) can end worse than it
            # started: the start's result is its best feasible stage
            if stage_conds[-1] < c_best and inside_limits(basis, limits, x.reshape(n, basis.m).T, self.t_con):
                x_best, c_best = x, stage_conds[-1]
            elif stage_conds[-1] >= c_best:
                x = x_best
        X = (x_best if math.isfinite(c_best) else x).reshape(n, basis.m).T
        dense = dense_times(t_out, self.duration, basis)
        if not inside_limits(basis, limits, X, dense):
            X = scale_into(basis, limits, X, dense)
        c = stacked_cond(model, *basis_eval(basis, X, t_out))
        rec.update(cond=c, status=status, iterations=iters, cond_stages=stage_conds)
        if self.refine:
            c, X = self._refine(X, c, step=step, rec=rec, describe=describe)
        return c, X

    def _refine(self, X: np.ndarray, c: float, *, step, rec: dict, describe=None) -> tuple[float, np.ndarray]:
        tr = time.perf_counter()
        t_out = self.t_out
        # a periodic design repeats its samples every period: the refinement works on the first one (a design
        # of period 10 s over 60 s costs as much as over 10 s); the cond kept is recomputed on all of t_out
        t_ref = t_out[t_out <= self.period * (1 + 1e-12)] if self.period < self.duration else t_out
        # ... and on at most REFINE_RATE samples per second: its linearisation grows with the samples (2 GB at
        # 1 kHz on a 7-joint arm), a smooth design's cond does not (it is recomputed on every output sample)
        t_ref = np.union1d(t_ref[::max(1, int(round(1.0 / (REFINE_RATE * float(t_out[1] - t_out[0])))))], t_ref[-1:])
        X_r, hist = refine_excitation(self.model, self.basis, self.limits, X, t_ref, self.t_con,
                                      iterations=self.refine, margin=self.cfg.margin, chi_b=self.cb,
                                      check_times=dense_times(t_ref, float(t_ref[-1]), self.basis),
                                      progress=functools.partial(self._sdp_done, step, describe))
        step(self.refine - (len(hist) - 1))  # one record per SDP and a final one: the SDPs not run count as done
        c_r = stacked_cond(self.model, *basis_eval(self.basis, X_r, t_out))
        rec.update(cond_ipopt=c, cond=min(c, c_r), refine_sdps=len(hist) - 1,
                   refine_accepted=sum(1 for h in hist if h.get("accepted")),
                   refine_conds=[h["cond"] for h in hist],
                   refine_time=time.perf_counter() - tr)
        if "skipped" in hist[-1]:
            rec["refine_skipped"] = hist[-1]["skipped"]
        return (c_r, X_r) if c_r < c else (c, X)

    def _ipopt_iteration(self, describe, power: int, calls: int) -> None:
        # IPOPT calls back at its iteration 0 (the start) too
        describe(f"IPOPT p = {power}, iteration {calls - 1}/{self.cfg.max_iter}")

    def _sdp_done(self, step, describe, rec: dict) -> None:
        step(1)
        if describe is not None:
            describe(f"SDP {rec['iteration'] + 1}/{self.refine}, cond {rec['cond']:.4g}")


#: the inputs of every start, for forked workers (:func:`optimise_excitation` with ``jobs > 1``): set just before
#: the pool forks and cleared after it, inherited by the children, never pickled (CasADi solvers do not pickle)
_FORKED: dict[str, Any] = {}


def _forked_start(s: int) -> tuple[float, np.ndarray, dict]:
    """Start ``s`` of :func:`optimise_excitation` in a forked worker: ``(cond, design, record)``."""
    f = _FORKED
    rec = dict(f["records"][s])
    c, X = f["run"](f["inits"][s], step=lambda k: None, rec=rec)
    return c, X, rec


def worker_count(jobs: int | None, starts: int) -> int:
    """Processes for ``starts`` starts: ``jobs`` (0: one per CPU this process may use), at most one per
    start; 1 where processes cannot be forked (the starts' CasADi solvers cannot be sent to spawned ones)."""
    import multiprocessing as mp
    import os

    if jobs is not None and jobs < 0:
        raise ExcitationError(f"--jobs {jobs}: must be a number of processes >= 1, or 0 for one per CPU")
    if jobs is None or jobs == 1 or starts <= 1 or "fork" not in mp.get_all_start_methods():
        return 1
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(starts, cpus if jobs == 0 else jobs))


def _draw_starts(model: IdentificationModel, basis, limits: Limits, cfg: ExciteSettings, t_out: np.ndarray,
                 t_con: np.ndarray, duration: float, cb: np.ndarray | None, initial) -> list[tuple[float, np.ndarray]]:
    """``(cond, design)`` of the IPOPT starts: the ``initial`` designs, ``structured`` friction designs and ``pool``
    random feasible ones, the ``starts`` of lowest cond (those within the torque limits first)."""
    nb, n = len(model.BASE_NAMES), limits.n
    rng = np.random.default_rng(cfg.seed)
    lim_start = limits.shrunk(cfg.margin)
    n_pool = max(int(cfg.starts), 10 * int(cfg.starts) if cfg.pool is None else int(cfg.pool))
    candidates: list[tuple[float, float, int, np.ndarray]] = []
    inits = [np.asarray(X, float) for X in initial]
    for i_pool in range(n_pool + int(cfg.structured) + len(inits)):
        if i_pool < len(inits):
            X_init = inits[i_pool]
        elif i_pool < len(inits) + int(cfg.structured):
            X_init = friction_trajectory(basis, lim_start, rng, t_con, duration)
        else:
            X_init = random_trajectory(basis, lim_start, rng, t_con)
        Wc = np.asarray(model.regressor(*basis_eval(basis, X_init, t_out))).reshape(-1, nb)
        sv = np.linalg.svd(Wc, compute_uv=False)
        # with torque limits, designs within them (the random ones are not held to them) rank first
        excess = 0.0
        if cb is not None and lim_start.tau_max is not None:
            tau0 = (Wc @ cb).reshape(-1, n)
            excess = max(0.0, float((np.abs(tau0) / lim_start.tau_max).max()) - 1.0)
        candidates.append((excess, float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf, len(candidates), X_init))
    candidates.sort(key=lambda c: (c[0], c[1], c[2]))
    return [(cond0, X0) for _, cond0, _, X0 in candidates[:int(cfg.starts)]]


def _run_starts(run: _Start, inits: list[np.ndarray], records: list[dict], jobs: int | None, progress,
                robot: str) -> list[tuple[float, np.ndarray]]:
    """Every start's ``(cond, design)``, in this process or in forked workers, with a progress bar (one step per
    IPOPT stage and per SDP iteration) labelled with the starts done and the best cond so far."""
    outcome: list[tuple[float, np.ndarray] | None] = [None] * len(inits)
    per_start = len(run.solvers) + run.refine
    counter = ProgressCounter(progress, total=len(inits) * per_start, desc=f"excite {robot}", unit="step")

    def label(what: str) -> str:
        got = [o[0] for o in outcome if o is not None]
        return f"excite {robot}: {what}" + (f", best cond {min(got):.4g}" if got else "")

    try:
        n_jobs = worker_count(jobs, len(inits))
        if n_jobs > 1:
            import concurrent.futures as cf
            import multiprocessing as mp

            # forked workers inherit the CasADi solvers and the model (neither pickles); each returns its start
            _FORKED.update(run=run, inits=inits, records=records)
            try:
                with cf.ProcessPoolExecutor(n_jobs, mp_context=mp.get_context("fork")) as pool_:
                    futures = {pool_.submit(_forked_start, s): s for s in range(len(inits))}
                    counter.describe(label(f"{len(inits)} starts in {n_jobs} processes"))
                    for k, fut in enumerate(cf.as_completed(futures), 1):
                        s = futures[fut]
                        c, X, records[s] = fut.result()
                        outcome[s] = (c, X)
                        counter.step(per_start)
                        counter.describe(label(f"{k}/{len(inits)} starts done"))
            finally:
                _FORKED.clear()
        else:
            for s, X_init in enumerate(inits):
                start = f"start {s + 1}/{len(inits)}"
                counter.describe(label(start))
                outcome[s] = run(X_init, step=counter.step, rec=records[s],
                                 describe=functools.partial(_describe, counter, label, start))
    finally:
        counter.close()
    assert all(o is not None for o in outcome)
    return [o for o in outcome if o is not None]


def _describe(counter: ProgressCounter, label, start: str, what: str) -> None:
    counter.describe(label(f"{start}, {what}"))


def optimise_excitation(model: IdentificationModel, basis, limits: Limits, duration: float,
                        settings: ExciteSettings | None = None, *, rate: float = 100.0, chi_b=None, initial=(),
                        progress=None, **options: Any) -> ExcitationResult:
    """Optimise an excitation trajectory (IPOPT from ``starts`` seeded random feasible designs).

    Parameters
    ----------
    model : IdentificationModel
        With ``casadi_regressor()`` (a generated package).
    basis : FourierBasis, PointToPointBasis or SplineBasis
    limits : Limits
    duration : float
        Length of the output trajectory [s] (for a Fourier design, a whole number of periods).
    settings : ExciteSettings, optional
        How to search (default ``ExciteSettings()``); any of its fields may be given as a keyword instead or on
        top of it (``criterion=``, ``starts=``, ``seed=``, ``pool=``, ``structured=``, ``samples=``,
        ``max_iter=``, ``margin=``, ``powers=``, ``refine=``, ``jobs=``, ``warm_start=``).
    rate : float
        Output sampling rate [Hz].
    chi_b : array_like (nb,), optional
        Nominal base parameters: with ``limits.tau_max``, torque limits are imposed.
    initial : sequence of ndarray (m, n)
        Designs added to the pool of starts.
    progress : None, bool or callable
        Feedback (as in :func:`symoro_gen.progress.progress_updates`; None: a bar when the command line
        asks for one): one step per IPOPT stage and per SDP iteration of every start, the bar labelled
        with the starts done and the best cond so far.

    With ``jobs`` above 1 the starts run in forked processes; the result is the same whatever ``jobs``: each
    start is computed alone from its own design, and the first start of the lowest cond is kept.

    Returns
    -------
    ExcitationResult
        The best start by the true unscaled ``cond`` over the output samples.
    """
    ca = load_casadi()
    cfg = dataclasses.replace(settings or ExciteSettings(), **options)
    t0 = time.perf_counter()
    n, nb = limits.n, len(model.BASE_NAMES)
    if n != model.N_JOINTS:
        raise ExcitationError(f"{model.ROBOT}: limits for {n} joints, the model has {model.N_JOINTS}")
    if not (duration > 0 and rate > 0):
        raise ExcitationError("--duration and --rate must be positive")
    t_out = output_times(duration, rate)
    if len(t_out) * n < nb:
        raise ExcitationError(f"{model.ROBOT}: {len(t_out)} samples x {n} joints < {nb} base parameters; "
                              "increase --duration or --rate")
    samples = cfg.samples if cfg.samples is not None else int(min(200, max(8 * nb // n + 1, 20 * basis.m, 40)))
    fourier = isinstance(basis, FourierBasis)
    period = 2 * math.pi / basis.w if fourier else duration
    t_obj = np.arange(samples) * period / samples if fourier else np.linspace(0, duration, samples)
    n_con = int(min(400, max(2 * samples, 40 * (basis.K if fourier else 8))))
    t_con = np.linspace(0.0, period, n_con)
    cb = None if chi_b is None else np.asarray(chi_b, float)
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": int(cfg.max_iter),
            "ipopt.hessian_approximation": "limited-memory", "ipopt.tol": 1e-6, "ipopt.acceptable_tol": 1e-4,
            "ipopt.sb": "yes"}
    if cfg.warm_start:
        opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-3})
    iterations = _IpoptIterations()
    solvers: list = []
    bounds: dict = {}
    for p in cfg.stages:
        nlp, bounds = build_nlp(model, basis, limits, t_obj, t_con, cfg.criterion, cb, cfg.margin, power=int(p))
        nx, ng = int(nlp["x"].numel()), int(nlp["g"].numel())
        solvers.append(ca.nlpsol(f"excite_p{p}", "ipopt", nlp, {**opts, **iterations.options(nx, ng)}))
    chosen = _draw_starts(model, basis, limits, cfg, t_out, t_con, duration, cb, initial)
    records = [{"start": s, "cond_start": cond0, "powers": list(cfg.stages)} for s, (cond0, _) in enumerate(chosen)]
    run = _Start(model, basis, limits, solvers, bounds, t_out, t_con, period, duration, cb, cfg, iterations)
    outcome = _run_starts(run, [X0 for _, X0 in chosen], records, cfg.jobs, progress, model.ROBOT)
    best = None
    for o in outcome:  # the first of the lowest cond, whatever order the starts ended in
        if best is None or o[0] < best[0]:
            best = o
    assert best is not None
    cond, X = best
    q, dq, ddq = basis_eval(basis, X, t_out)
    tau = None if (cb is None or limits.tau_max is None) else np.asarray(model.regressor(q, dq, ddq)) @ cb
    chk = check_limits(limits, q, dq, ddq, tau)
    chk_dense = check_limits(limits, *basis_eval(basis, X, dense_times(t_out, duration, basis)))
    return ExcitationResult(basis=basis, limits=limits, t=t_out, q=q, dq=dq, ddq=ddq, X=X, cond=cond,
                            limits_ok=bool(chk["ok"] and chk_dense["ok"]), usage=chk["usage"], criterion=cfg.criterion,
                            starts=records, wall_time=time.perf_counter() - t0, tau=tau)
