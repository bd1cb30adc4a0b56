"""Fleet identification on Dask distributed: one task per log, TSQR tree reductions per robot-day, per
robot and for the fleet, then the per-day, per-robot and fleet estimates (IDIM-WLS, RX-90 paper eq. 22)
and the drift flags (:mod:`symoro_gen.fleet.stats`).

The same code runs on a laptop (``scheduler=None``: a ``LocalCluster``), a workstation
(``"local:N"``: N worker processes) or a cluster (the address of any running scheduler, e.g. one
started by dask-jobqueue or on Kubernetes; the workers need symoro_gen and the generated model).
"""
from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import functools
import logging
import math
import os
import time
import uuid
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..atomic import json_output
from ..description import load_robot
from ..description.model import RobotDescription
from ..diagnostics import DiagnoseSettings, diagnose
from ..errors import SymoroError
from ..identification.estimators import fit_wls
from ..loader import model_for
from ..model import IdentificationModel
from ..observations import AssemblyOptions
from ..preprocessing.readers import DataWarning
from ..report.plots import MissingDependencyError
from ..workflows.base import SCHEMA_VERSION, Results, provenance, torque_limits
from .files import FleetError, LogFile, discover, group_by, plain_format, read_experiments, segments
from .kernel import Partial, error_line, merge_partials, process_file, resolve_model
from .options import DEFAULT_ALPHA, LOCAL_SCHEDULER, SCHEDULER_FORMS, FleetOptions, check_scheduler
from .report import flag_figures, write_fleet_report
from .stats import adjust, dersimonian_laird, hampel_outliers, level_z, line_fit, pooled_dispersion, trend_test
from .worker import FleetWorkerSetup, tune_malloc

__all__ = ["DEFAULT_ALPHA", "SCHEDULER_FORMS", "Z_DAY", "check_scheduler", "Estimate", "FleetOptions", "FleetResult", "FleetWorkerSetup", "identify_fleet",
           "open_client", "tune_malloc"]

#: a day is listed in a flag when its own distance to the fleet exceeds this
Z_DAY = 3.0


def _require_distributed():
    try:
        import distributed
    except ImportError:  # pragma: no cover - depends on the installation
        raise MissingDependencyError("fleet identification needs Dask: pip install 'symoro-gen[fleet]'") from None
    return distributed


def _worker_died(s: str, exc: BaseException, when: str) -> FleetError:
    """The error of a Dask worker that died (``Stream is closed``, ``Nanny failed to start``, a killed worker)."""
    what = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    if len(what) > 160:
        what = what[:157] + "..."
    err = FleetError(f"--scheduler {s}: a Dask worker died {when} ({type(exc).__name__}: {what})")
    m = LOCAL_SCHEDULER.fullmatch(s)
    if m and m.group(1) != "threads":
        fewer = ", or fewer workers (--scheduler local:1)" if m.group(2) is None or int(m.group(2)) > 1 else ""
        err.hint = ("a worker process that dies at once is most often out of memory (each one imports the model and "
                    f"reads a log): try --scheduler threads:2 (threads of this process, no worker process){fewer}, "
                    "or --segment-samples / --chunk-samples to bound a task")
    else:
        err.hint = ("check the memory of the workers (a worker that dies at once is most often out of memory), or "
                    "run in this process with --scheduler threads:2")
    return err


#: seconds between two looks at a running fleet (its lost workers) while its results are awaited
WATCH_S = 1.0
#: seconds a run whose workers all died (and were not replaced) waits for a new one before it is stopped
WORKERLESS_S = 60.0


def _deaths_text(n: int) -> str:
    return "once" if n == 1 else "twice" if n == 2 else f"{n} times"


def _lost_log(counts: dict[str, int], labels: dict[str, str], retries: int) -> FleetError:
    """The error of a run stopped because the worker running a log's task died more than ``retries`` times:
    ``counts`` the deaths per task key (Dask's ``suspicious`` count: every task a dying worker was running),
    ``labels`` the log of each per-log task key. Names the log, or the logs that were running together each time
    (a worker runs more than one task: the one that killed it cannot be told apart)."""
    n = max(counts.values())
    worst = sorted(labels[k] for k, c in counts.items() if c == n and k in labels)
    which = worst[0] if len(worst) == 1 else "one of " + ", ".join(worst[:5]) + (
        f" and {len(worst) - 5} more" if len(worst) > 5 else "")
    err = FleetError(f"fleet: {which}: the Dask worker reading it died {_deaths_text(n)} (--retries {retries}): "
                     "the run is stopped instead of re-running it without end")
    err.hint = ("a worker that dies on one log is most often out of memory: bound a task with --segment-samples / "
                "--chunk-samples, run in this process (--scheduler threads:2), or move that log out of the folder "
                "to run without it")
    return err


def _await(cl, futures: list, labels: dict[str, str], retries: int, where: str) -> list:
    """``cl.gather(futures)``, with the run watched every :data:`WATCH_S` seconds so that a log whose worker keeps
    dying cannot hang it: a per-log task that killed its worker more than ``retries`` times (Dask's own count of
    the workers that died running a task, the scheduler's ``suspicious``) stops the run with a :class:`FleetError`
    naming the log; so does a cluster left with no worker for :data:`WORKERLESS_S` seconds after workers died
    (a nanny stops restarting a worker that keeps dying; Dask would then wait for a worker forever)."""
    distributed = _require_distributed()

    def deaths(dask_scheduler=None):  # runs in the scheduler (a closure: pickled by value, any scheduler runs it)
        return {k: int(ts.suspicious) for k, ts in dask_scheduler.tasks.items() if ts.suspicious}

    seen_workers, workerless_since = False, None
    while True:
        try:
            distributed.wait(futures, timeout=WATCH_S)
            break
        except (TimeoutError, asyncio.TimeoutError):  # the same class from Python 3.11 on, not on 3.10
            pass
        try:  # this run's per-log tasks only (a shared scheduler holds other runs' tasks too)
            counts = {k: n for k, n in cl.run_on_scheduler(deaths).items() if k in labels}
        except Exception:  # noqa: BLE001 - a scheduler that refuses to run code: only the workerless bound holds
            counts = {}
        if counts and max(counts.values()) > retries:
            raise _lost_log(counts, labels, retries)
        n_workers = len(cl.scheduler_info().get("workers", {}))
        seen_workers = seen_workers or n_workers > 0
        if n_workers or not seen_workers:
            workerless_since = None
            continue
        workerless_since = workerless_since or time.monotonic()
        if time.monotonic() - workerless_since > WORKERLESS_S:
            err = _worker_died(where, RuntimeError(f"no worker left for {WORKERLESS_S:g} s"), "during the run")
            if counts:
                err = _lost_log(counts, labels, retries)
                err.args = (f"{err.args[0]}; no worker was left for {WORKERLESS_S:g} s",)
            raise err
    try:
        return cl.gather(futures)
    except Exception as exc:
        key = getattr(exc, "task", None) or next((a for a in getattr(exc, "args", ()) if a in labels), None)
        if type(exc).__name__ == "KilledWorker" and key in labels:  # Dask's own bound (allowed-failures)
            raise _lost_log({key: int(getattr(exc, "allowed_failures", 0) or 0) + 1}, labels, retries) from None
        raise


def _dask_failure(exc: BaseException) -> bool:
    """A failure of the Dask cluster itself (a closed connection, a worker or nanny that died), not of a log."""
    mod = type(exc).__module__ or ""
    return mod.startswith(("distributed", "tornado")) or type(exc).__name__ in ("KilledWorker", "CommClosedError")


@contextlib.contextmanager
def open_client(scheduler: str | None = None):
    """A ``distributed.Client`` for ``scheduler``, closed (with its cluster) on exit.

    ``None`` or ``"local"``: a ``LocalCluster`` of ``min(2, cpus)`` single-threaded worker processes;
    ``"local:N"`` (or ``"processes:N"``): N worker processes; ``"threads:N"``: one in-process worker with N
    threads (no pickling, quick to start: tests, notebooks); ``tcp://host:port``: the address of a running
    scheduler. Anything else is refused at once (:func:`check_scheduler`); a worker that dies at start-up is a
    :class:`FleetError` saying so (memory?), not a ``Stream is closed`` on some file.
    """
    distributed = _require_distributed()
    cluster = None
    s = (scheduler or "local").strip()
    check_scheduler(s)
    m = LOCAL_SCHEDULER.fullmatch(s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Dask's port/dashboard notices
        if m:
            n = int(m.group(2)) if m.group(2) else min(2, os.cpu_count() or 1)
            try:
                if m.group(1) != "threads":
                    cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                       dashboard_address=None, silence_logs=logging.ERROR)
                else:
                    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=n, processes=False,
                                                       dashboard_address=None, silence_logs=logging.ERROR)
                client = distributed.Client(cluster)
            except (RuntimeError, OSError, TimeoutError) as exc:
                if cluster is not None:
                    cluster.close()
                raise _worker_died(s, exc, "at start-up") from None
        else:
            try:
                client = distributed.Client(s, timeout="20s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise FleetError(f"--scheduler {s}: cannot connect ({exc})") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@dataclass(frozen=True)
class Estimate:
    """Parameters with standard deviations (IDIM-WLS on the merged factors)."""

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    rows: int = 0
    samples: int = 0
    files: tuple[str, ...] = ()

    def to_json(self) -> dict:
        return {"names": list(self.names), "values": _floats(self.values),
                "std": _floats(self.std), "rows": int(self.rows), "samples": int(self.samples),
                "files": list(self.files)}


@dataclass(frozen=True, eq=False)
class FleetResult(Results):
    """What a fleet run found: the results object of the ``fleet`` workflow (:meth:`to_dict` is the JSON
    contract, :meth:`summary` the command's text, :meth:`report` and :meth:`figures` the drift plots)."""

    command = "fleet"

    model: str
    names: tuple[str, ...]
    days: dict[str, dict[str, Estimate]]          # robot -> day -> estimate
    robots: dict[str, Estimate]                    # robot -> all its days
    fleet: Estimate
    level: dict                                    # z, p, mean, mean_std, tau: (R, P) arrays
    trend: dict                                    # slope, se, z, p: (R, P) arrays
    flagged: list[dict]
    skipped: list[dict]
    settings: dict = field(default_factory=dict)
    timing: dict = field(default_factory=dict)
    partials: dict = field(default_factory=dict, repr=False)
    diagnoses: dict = field(default_factory=dict)                # robot -> closed-loop diagnosis (``diagnose=True``)
    options: FleetOptions = field(default_factory=FleetOptions, repr=False)
    inputs: tuple[str, ...] = ()                                 # the log files read
    warnings: tuple[str, ...] = ()                               # on the logs: robot, day, log, joint, what to do

    @property
    def robot_names(self) -> list[str]:
        return list(self.robots)

    def series(self, robot: str, parameter: str) -> tuple[list[str], np.ndarray, np.ndarray]:
        """``(days, values, std)`` of one parameter of one robot over its days."""
        k = self.names.index(parameter)
        days = list(self.days[robot])
        return (days, np.array([self.days[robot][d].values[k] for d in days]),
                np.array([self.days[robot][d].std[k] for d in days]))

    @functools.cached_property
    def _provenance(self) -> dict:
        return provenance(self.options, self.inputs)

    def to_dict(self) -> dict:
        """Exactly the JSON of ``symoro-gen fleet --json``: ``generator``, ``schema_version``, ``model``,
        ``robots`` {robot: {``days``: {day: {names, values, std}}, ``estimate``, ``z``, ``z_trend``,
        ``slope_per_day``}}, ``fleet`` {names, values, std, between_robot_std}, ``flagged`` [{robot, parameter, z,
        days, ...}], ``skipped`` [{file, error}], ``warnings`` (on the logs used, as ``identify`` gives them: a joint
        at its noise level, a saturated torque; each naming the robot, the day and the log), ``settings``, ``timing``, with ``diagnose`` ``diagnoses``
        {robot: {day, files, summary, report} or {day, files, error}}, and ``provenance`` (options, every log
        file with its sha256, computed once)."""
        rob = {}
        for i, r in enumerate(self.robots):
            rob[r] = {
                "days": {d: e.to_json() for d, e in self.days[r].items()},
                "estimate": self.robots[r].to_json(),
                "z": _floats(self.level["z"][i]),
                "z_trend": _floats(self.trend["z"][i]),
                "slope_per_day": _floats(self.trend["slope"][i]),
            }
        fleet = self.fleet.to_json()
        tau = self.level.get("tau_all")
        fleet["between_robot_std"] = _floats(tau) if tau is not None else None
        out = {"generator": f"symoro-gen {self.command}", "schema_version": SCHEMA_VERSION, "model": self.model,
               "robots": rob, "fleet": fleet, "flagged": self.flagged, "skipped": self.skipped,
               "warnings": list(self.warnings), "settings": self.settings, "timing": self.timing}
        if self.settings.get("diagnose"):
            out["diagnoses"] = self.diagnoses
        out["provenance"] = self._provenance
        return out

    def json_text(self) -> str:
        """The JSON the command writes (indent 1; a NaN the statistics may give is kept as NaN)."""
        return json_output(self.to_dict(), self.command, indent=1, allow_nan=True)

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """The fleet report (flags, skipped logs, the fleet estimate, every flagged parameter over the days):
        ``.html`` self-contained or ``.md`` with its images beside it (plots: the 'plots' extra)."""
        self.check_output(path, force=force, label="report", report=True)
        return write_fleet_report(path, self, force=force)

    def figures(self) -> list:
        """One figure per flagged parameter: its values over the days for the flagged robot, the other robots
        and the fleet band."""
        return [f.figure for f in flag_figures(self) if f.figure is not None]

    def summary(self) -> str:
        """A few lines for the terminal."""
        nd = sum(len(v) for v in self.days.values())
        lines = [(f"fleet of {len(self.robots)} robot(s) of {self.model}, {nd} robot-day(s), "
                  f"{self.fleet.samples} samples, {len(self.skipped)} log(s) skipped")]
        for s in self.skipped:
            lines.append(f"  skipped {s['file']}: {s['error']}")
        for w in self.warnings:
            lines.append(f"  warning: {w}")
        if not self.flagged:
            lines.append("no robot drifts away from the fleet")
        for f in self.flagged:
            lines.append(f"  FLAG {f['robot']} {f['parameter']}: {f['test']} z = {f['z']:.1f} "
                         f"(p_adj = {f['p_adjusted']:.2g}), days {', '.join(f['days'])}")
        for r, d in self.diagnoses.items():
            head = f"diagnosis of {r} on day {d['day']}"
            if "error" in d:
                lines.append(f"  {head}: not run ({d['error']})")
            else:
                lines.append(f"  {head}:")
                lines += ["    " + x for x in str(d["summary"]).splitlines()]
        return "\n".join(lines)


def _floats(a) -> list:
    return [None if not math.isfinite(float(x)) else float(x) for x in np.asarray(a, float).reshape(-1)]


def _fit(p: Partial, names: Sequence[str], problems: list | None = None, what: str = "") -> Estimate | None:
    """IDIM-WLS on merged factors; None (and a line in ``problems``) when they do not identify the model."""
    if p.acc is None:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = fit_wls(p.acc)
        except Exception as exc:  # noqa: BLE001 - a day too short to identify is reported, not fatal
            if problems is not None:
                problems.append({"file": ", ".join(p.files), "error": f"{what}: not identifiable ({exc})"})
            return None
    return Estimate(tuple(res.names), np.asarray(res.values, float), np.asarray(res.std, float),
                    rows=p.acc.n_rows, samples=p.samples, files=p.files)


def _tree(client, parts: list, key: str, retries: int):
    """Pairwise tree reduction of futures on the cluster (TSQR)."""
    level = 0
    while len(parts) > 1:
        nxt = []
        for i in range(0, len(parts) - 1, 2):
            nxt.append(client.submit(merge_partials, parts[i], parts[i + 1], key=f"{key}-merge{level}-{i}",
                                     retries=retries, pure=False))
        if len(parts) % 2:
            nxt.append(parts[-1])
        parts, level = nxt, level + 1
    return parts[0]


def _ref_name(ref) -> str:
    return os.fspath(ref) if isinstance(ref, (str, os.PathLike)) else str(getattr(ref, "ROBOT", "model"))


def _model_ref(model) -> tuple[object, IdentificationModel, RobotDescription | None]:
    """What the tasks receive, the model and the robot description behind it.

    A robot name or robot file is resolved as ``identify`` resolves it (:func:`~symoro_gen.loader.model_for`:
    the robot file, and the package generated from *that* file, wherever it is), never by the name alone: a
    ``generated/<name>/`` written from another file must not give the fleet another model than ``identify``
    has on the same log. The tasks then receive the folder of that package (workers import it once), or the
    robot file when the model is not a plain package (closed loops: built from the file). A generated package
    folder is used as it is (its drive chain and joint types: ``robots/<ROBOT>.toml``'s, :func:`_robot_file_of`).
    """
    if isinstance(model, (str, os.PathLike)):
        path = os.fspath(model)
        if os.path.isfile(os.path.join(path, "__init__.py")):   # a generated package folder, as given
            return path, resolve_model(path), None
        robot, mdl = model_for(path)
        f = getattr(mdl, "__file__", None)
        if f and os.path.basename(f) == "__init__.py":
            return os.path.dirname(f), mdl, robot
        return (os.path.abspath(robot.file) if robot.file else mdl), mdl, robot
    f = getattr(model, "__file__", None)
    if f and os.path.basename(f) == "__init__.py":
        return os.path.dirname(f), model, None
    return model, model, None


def identify_fleet(model: str | IdentificationModel, logs: Iterable, by: str, options: FleetOptions | None = None,
                   *, client=None, assembly: AssemblyOptions | None = None, load_kw: dict | None = None,
                   kernel: Callable[..., Partial] = process_file) -> FleetResult:
    """Identify every robot of a fleet per day, pool the fleet and flag the robots that drift.

    Parameters
    ----------
    model : str or IdentificationModel
        Robot name, generated package folder or robot file (workers load it), or a model object.
    logs : iterable of str
        Files, globs or folders (CSV, NPZ, MAT, Parquet).
    by : str
        Pattern naming the robot and the day in the end of each path, e.g. ``"{robot}/{day}.parquet"``.
    options : FleetOptions, optional
        Every option of the ``fleet`` command: scheduler (ignored when ``client`` is given), flag level and
        correction, retries, filters and block size, segments, the diagnosis of the flagged robots, and how the
        logs are read (``data_format``). Default: ``FleetOptions()``.
    client : distributed.Client, optional
        An open client to use (not closed here).
    assembly : AssemblyOptions, optional
        Filters and block size in full, instead of those of ``options`` (:meth:`FleetOptions.assembly`).
    load_kw : dict, optional
        More keywords of the log reader (:func:`~symoro_gen.fleet.files.read_experiments`); ``drive_chain``:
        default the robot file's ``[drive_chain]`` (motor-side logs mapped to the joint side, as ``identify``
        does; found from the robot name or file, or ``robots/<ROBOT>.toml`` for a model object), ``None`` to read
        the logs as they are; ``joint_types``: default the same robot file's (each joint's ``sigma``: the joints
        ``--deg`` and ``--mm`` convert).
    kernel : callable
        The per-file task, ``kernel(model_ref, log, options, load_kw) -> Partial`` (default
        :func:`~symoro_gen.fleet.kernel.process_file`).

    Returns
    -------
    FleetResult

    Raises
    ------
    FleetError
        No log could be used.
    """
    fo = FleetOptions() if options is None else options
    opts = fo.assembly() if assembly is None else assembly
    ref, mdl, robot = _model_ref(model)
    if opts.tau_limits is None and robot is not None:
        opts = dataclasses.replace(opts, tau_limits=torque_limits(robot))
    load_kw = {"fmt": fo.data_format, **(load_kw or {})}
    desc = robot if robot is not None else _robot_file_of(mdl)
    if "drive_chain" not in load_kw:
        load_kw["drive_chain"] = desc.drive_chain if desc is not None else None
    if "joint_types" not in load_kw:   # --deg/--mm convert the revolute/prismatic joints, as identify does
        load_kw["joint_types"] = [int(j.sigma) for j in desc.model_joints] if desc is not None else None
    plain = plain_format(load_kw.get("fmt"))
    files = segments(discover(logs, by), fo.segment_samples if plain else None)
    t0 = time.perf_counter()
    ctx = contextlib.nullcontext(client) if client is not None else open_client(fo.scheduler)
    with ctx as cl:
        t_start = time.perf_counter() - t0
        groups = group_by(files)
        # malloc settings and the model once per worker (name per model: idempotent on a shared cluster)
        where = fo.scheduler or ("client" if client is not None else "local")
        try:
            cl.register_plugin(FleetWorkerSetup(ref, os.getpid()), name=f"symoro-fleet-setup-{_ref_name(ref)}")
        except Exception as exc:
            if not _dask_failure(exc):
                raise
            raise _worker_died(where, exc, "at start-up") from None
        try:
            day_p, robot_p, fleet_p, n_workers = _reduce(cl, groups, ref, opts, load_kw, kernel, fo.retries, where)
        except Exception as exc:
            if not _dask_failure(exc):
                raise
            raise _worker_died(where, exc, "during the run") from None
    t_run = time.perf_counter() - t0 - t_start
    skipped = [{"file": f, "error": e} for f, e in fleet_p.skipped]
    for w in fleet_p.warnings:
        warnings.warn(w, DataWarning, stacklevel=2)
    names, fleet, days, robots = _estimates(day_p, robot_p, fleet_p, groups, skipped)
    result = _judge(mdl, names, days, robots, fleet, skipped, fo.alpha, fo.correction)
    fmt = load_kw.get("fmt")
    settings = {"by": by, "scheduler": fo.scheduler or ("client" if client is not None else "local"),
                "alpha": fo.alpha, "correction": fo.correction,
                "segment_samples": fo.segment_samples if plain else None,
                "tasks": len(files), "z_day": Z_DAY, "workers": n_workers,
                "estimator": "IDIM-WLS", "assembly": opts.summary(),
                "data_options": list(fmt.options()) if fmt is not None else [],
                "drive_chain": load_kw.get("drive_chain") is not None, "diagnose": bool(fo.diagnose)}
    diagnoses = {}
    if fo.diagnose:
        t_d = time.perf_counter()
        diagnoses = _diagnose_flagged(mdl, result["flagged"], group_by(files), load_kw, fo.diagnose_method)
        settings["diagnose_method"] = fo.diagnose_method
        settings["diagnose_s"] = round(time.perf_counter() - t_d, 3)
    timing = {"startup_s": round(t_start, 3), "run_s": round(t_run, 3),
              "samples": int(fleet_p.samples), "samples_per_s": fleet_p.samples / t_run if t_run > 0 else None}
    return FleetResult(model=str(getattr(mdl, "ROBOT", ref)), names=names, days=days, robots=robots, fleet=fleet,
                       level=result["level"], trend=result["trend"], flagged=result["flagged"], skipped=skipped,
                       settings=settings, timing=timing,
                       partials={"days": day_p, "robots": robot_p, "fleet": fleet_p}, diagnoses=diagnoses,
                       options=fo, inputs=tuple(dict.fromkeys(f.path for f in files)), warnings=fleet_p.warnings)


def _reduce(cl, groups: dict, ref, opts: AssemblyOptions, load_kw: dict, kernel: Callable[..., Partial],
            retries: int, where: str = "local") -> tuple[dict, dict, Partial, int]:
    """One task per log and the TSQR trees per robot-day, robot and fleet on the cluster: the merged
    partials ``(per (robot, day), per robot, fleet)`` and the number of workers (the workers' setup, malloc
    settings and the model once per worker, is registered before: :func:`identify_fleet`). A log whose worker
    keeps dying stops the run, named (:func:`_await`)."""
    # task keys unique to this run: a scheduler keeps results by key, and another run on the same
    # client (other files, other options, same robot and day names) must never reuse them
    run = f"fleet-{uuid.uuid4().hex[:12]}"
    day_f, robot_f = {}, {}
    labels: dict[str, str] = {}
    for r, days in groups.items():
        for d, logs_rd in days.items():
            file_keys = [f"{run}-file-{r}-{d}-{i}-{os.path.basename(lf.label)}" for i, lf in enumerate(logs_rd)]
            labels.update(zip(file_keys, (lf.label for lf in logs_rd)))
            parts = [cl.submit(kernel, ref, lf, opts, load_kw, key=k, retries=retries, pure=False)
                     for k, lf in zip(file_keys, logs_rd)]
            day_f[r, d] = _tree(cl, parts, f"{run}-day-{r}-{d}", retries)
        robot_f[r] = _tree(cl, [day_f[r, d] for d in days], f"{run}-robot-{r}", retries)
    fleet_f = _tree(cl, list(robot_f.values()), f"{run}-fleet", retries)
    keys = list(day_f)
    got = _await(cl, [day_f[k] for k in keys] + [robot_f[r] for r in groups] + [fleet_f], labels, retries, where)
    n_workers = len(cl.scheduler_info().get("workers", {}))
    return dict(zip(keys, got[:len(keys)])), dict(zip(groups, got[len(keys):-1])), got[-1], n_workers


def _estimates(day_p: dict, robot_p: dict, fleet_p: Partial, groups: dict, skipped: list) -> tuple:
    """``(names, fleet, days, robots)``: IDIM-WLS on the fleet's, each robot's and each robot-day's factors (a
    robot or day that does not identify the model is added to ``skipped``)."""
    if fleet_p.acc is None:
        err = FleetError("fleet: no log could be used; " + "; ".join(s["error"] for s in skipped[:3])
                         + (f"; and {len(skipped) - 3} more" if len(skipped) > 3 else ""))
        err.hint = ("each log needs the columns t, q1..qn, tau1..taun of the robot (or --columns / --format to say "
                    "which are what); see docs/data-files.md")
        raise err
    names = tuple(fleet_p.acc.names)
    fleet = _fit(fleet_p, names)
    if fleet is None:
        raise FleetError("fleet: the pooled logs do not identify the base parameters")
    days: dict[str, dict[str, Estimate]] = {}
    robots: dict[str, Estimate] = {}
    for r in groups:
        e = _fit(robot_p[r], names, skipped, f"robot {r}")
        if e is None:
            continue
        robots[r] = e
        days[r] = {}
        for d in groups[r]:
            ed = _fit(day_p[r, d], names, skipped, f"robot {r}, day {d}")
            if ed is not None:
                days[r][d] = ed
    return names, fleet, days, robots


def _robot_file_of(mdl) -> RobotDescription | None:
    """The description of ``robots/<ROBOT>.toml`` for a model object whose robot file is not known (its drive
    chain and joint types), None when no such file is found."""
    if getattr(mdl, "ROBOT", None):
        try:
            return load_robot(str(mdl.ROBOT))
        except (SymoroError, OSError, ValueError):
            return None
    return None


def _diagnose_flagged(model, flagged: list[dict], groups: dict[str, dict[str, list[LogFile]]], load_kw: dict,
                      method: str) -> dict:
    """``diagnose`` (the public call) on each flagged robot's logs of the last day of its flags."""

    out: dict[str, dict] = {}
    for f in flagged:
        r = f["robot"]
        if r in out:
            continue
        day = sorted(f["days"])[-1]
        logs = groups.get(r, {}).get(day, [])
        entry: dict = {"day": day, "files": [lf.label for lf in logs], "parameters": [
            g["parameter"] for g in flagged if g["robot"] == r]}
        try:
            trajs = [tr for lf in logs for tr in read_experiments(lf.path, int(model.N_JOINTS), start=lf.start,
                                                                   stop=lf.stop, **load_kw)]
            if not trajs:
                raise FleetError("no log of that day")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rep = diagnose(model, trajs, DiagnoseSettings(method=method))
            to_json = getattr(rep, "to_json", None) or rep.to_dict
            entry.update(summary=rep.summary(), report=to_json())
        except Exception as exc:  # noqa: BLE001 - a diagnosis that fails is reported, the fleet result stands
            entry["error"] = error_line(exc)
        out[r] = entry
    return out


def _judge(model, names, days, robots, fleet, skipped, alpha, correction) -> dict:
    """Level and trend tests of every robot and parameter, corrected together, and the flags."""
    rnames = list(robots)
    R, P = len(rnames), len(names)
    theta = np.array([robots[r].values for r in rnames]).reshape(R, P)
    std = np.array([robots[r].std for r in rnames]).reshape(R, P)
    z, p, mean, mstd, tau = level_z(theta, std)
    slope, se, zt, pt = (np.full((R, P), np.nan) for _ in range(4))
    series = {}
    chi2, nu = np.full((R, P), np.nan), np.zeros((R, P), int)
    for i, r in enumerate(rnames):
        dl = list(days[r])
        if len(dl) < 3:
            continue
        x = np.arange(len(dl), dtype=float)
        for k in range(P):
            y = np.array([days[r][d].values[k] for d in dl])
            s = np.array([days[r][d].std[k] for d in dl])
            series[i, k] = (x, y, s)
            _, _, chi2[i, k], nu[i, k] = line_fit(x, y, s)
    # the fleet's excess day-to-day scatter per parameter (pooled over robots) and its degrees of freedom
    pooled = [pooled_dispersion(chi2[:, k], nu[:, k]) for k in range(P)]
    for (i, k), (x, y, s) in series.items():
        slope[i, k], se[i, k], zt[i, k], pt[i, k] = trend_test(x, y, s, dispersion=pooled[k][0], dof=pooled[k][1])
    rej, padj = adjust(np.stack([p, pt]), alpha, correction)
    tau_all = np.array([np.nan] * P)
    if R >= 2:      # the fleet's spread: DerSimonian-Laird on the robots the Hampel screen keeps
        keep = [~hampel_outliers(theta[:, k], std[:, k] ** 2) for k in range(P)]
        tau_all = np.array([np.sqrt(dersimonian_laird(theta[keep[k], k], std[keep[k], k] ** 2)[2])
                            if np.all(np.isfinite(std[:, k])) else np.nan for k in range(P)])
    flagged = []
    for i, r in enumerate(rnames):
        for k in range(P):
            if not (rej[0, i, k] or rej[1, i, k]):
                continue
            use_trend = bool(rej[1, i, k]) and (not rej[0, i, k] or padj[1, i, k] <= padj[0, i, k])
            dl = list(days[r])
            ref_m = mean[i, k] if np.isfinite(mean[i, k]) else fleet.values[k]
            ref_v = (tau[i, k] ** 2 + mstd[i, k] ** 2) if np.isfinite(tau[i, k]) else fleet.std[k] ** 2
            zd = [(days[r][d].values[k] - ref_m) / np.sqrt(days[r][d].std[k] ** 2 + ref_v) for d in dl]
            out_days = [d for d, zz in zip(dl, zd) if abs(zz) > Z_DAY] or dl
            flagged.append({
                "robot": r, "parameter": names[k],
                "z": float(zt[i, k] if use_trend else z[i, k]),
                "days": out_days,
                "test": "trend" if use_trend else "level",
                "p_adjusted": float(padj[1 if use_trend else 0, i, k]),
                "z_level": None if not np.isfinite(z[i, k]) else float(z[i, k]),
                "z_trend": None if not np.isfinite(zt[i, k]) else float(zt[i, k]),
                "slope_per_day": None if not np.isfinite(slope[i, k]) else float(slope[i, k]),
                "fleet_reference": float(ref_m),
            })
    flagged.sort(key=lambda f: -abs(f["z"]))
    return {"level": {"z": z, "p": p, "mean": mean, "mean_std": mstd, "tau": tau, "tau_all": tau_all,
                      "p_adjusted": padj[0]},
            "trend": {"slope": slope, "se": se, "z": zt, "p": pt, "p_adjusted": padj[1],
                      "dispersion": np.array([d for d, _ in pooled]), "dof": np.array([n for _, n in pooled])},
            "flagged": flagged}
