"""``excite``: a robot and its limits → an optimal excitation trajectory (Fourier, point-to-point or spline).

The workflow of ``symoro-gen excite`` as a library call::

    res = symoro_gen.excite("lwr4", duration=20, seed=1, output="traj.csv")
    res.summary(); res.to_dict()["cond"]; res.t, res.q; res.write_csv("t.csv"); res.report("t.html"); res.plot()

The design minimises the condition number of the stacked base regressor (Gautier & Khalil 1992; Presse &
Gautier 1993) within the robot file's ``[limits]``, through IPOPT on the generated CasADi regressor and a
sequential SDP on the true cond (:mod:`symoro_gen.excite`; Swevers et al. 1997 for the Fourier basis).
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..demo import available_memory, size_text
from ..excite.bases import FourierBasis, PointToPointBasis, SplineBasis
from ..excite.criterion import COND_DEGENERATE, predicted_sigma
from ..excite.limits import ExcitationError, Limits, limits_of, with_floor
from ..excite.optimise import EFFORTS, ExcitationResult, ExciteSettings, optimise_excitation
from ..excite.output import (
    excitation_report,
    floor_text,
    joint_numbers,
    passive_ranges,
    passive_text,
    plot_trajectory,
    trajectory_figure,
    write_trajectory_csv,
)
from ..excite.refine import has_cvxpy
from ..model import IdentificationModel
from ..report.document import write_report_files
from .base import SCHEMA_VERSION, Options, Results, provenance, resolve_robot

__all__ = ["ExciteOptions", "ExciteResults", "check_size", "excite"]

KINDS = ("fourier", "p2p", "spline")

_NO_CVXPY_NOTE = ("note: cvxpy is not installed, the SDP refinement of the true cond was skipped "
                  "(pip install 'symoro-gen[physical]')")


@dataclass(frozen=True)
class ExciteOptions(Options):
    """Every option of ``excite`` (the command's flags without their dashes; see ``symoro-gen excite --help``).

    Attributes
    ----------
    kind : {"fourier", "p2p", "spline"}
        Fourier series, point-to-point via-points, or a cubic B-spline (rest at both ends).
    duration, rate : float
        Seconds (Fourier: whole periods of the base frequency) and the output sampling rate [Hz].
    harmonics, base_frequency
        Fourier harmonics per joint (>= 2) and base frequency [Hz] (default ``1/duration``).
    via_points, dwell
        Point-to-point: via-points including start and end, rest at each intermediate one [s].
    coefficients : int, optional
        Spline: control points per joint (default 6 per second, at least 7).
    structured_starts : int
        Designs alternating slow motion and bursts at the velocity limit added to the pool of starts.
    seed : int
    effort : {"quick", "thorough"}
        How long to search (:data:`~symoro_gen.excite.optimise.EFFORTS`); ``starts``, ``pool``, ``max_iter``
        and ``refine`` override it.
    jobs : int
        Processes the starts run in (0: one per CPU; the result is the same).
    samples : int, optional
        Samples of the criterion.
    criterion : {"cond", "logdet"}
    noise : float
        Torque-noise standard deviation for the predicted %sigma [N m].
    no_torque_limits : bool
        Ignore ``tau_max`` even with nominal parameters.
    z_min : float, optional
        Every moving frame origin stays at ``z >= z_min`` [m] in the base frame.
    """

    kind: str = "fourier"
    duration: float = 10.0
    harmonics: int = 5
    base_frequency: float | None = None
    via_points: int = 8
    coefficients: int | None = None
    structured_starts: int = 0
    dwell: float = 0.0
    rate: float = 100.0
    seed: int = 0
    effort: str = "quick"
    starts: int | None = None
    pool: int | None = None
    jobs: int = 1
    max_iter: int | None = None
    samples: int | None = None
    criterion: str = "cond"
    refine: int | None = None
    noise: float = 1.0
    no_torque_limits: bool = False
    z_min: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ExcitationError(f"--kind {self.kind!r}: one of {', '.join(KINDS)}")
        if self.effort not in EFFORTS:
            raise ExcitationError(f"--effort {self.effort!r}: one of {', '.join(EFFORTS)}")
        if not (self.duration > 0 and self.rate > 0):
            raise ExcitationError("--duration and --rate must be positive")

    def settings(self) -> tuple[ExciteSettings, str | None]:
        """The :class:`ExciteSettings` of these options (the effort and what overrides it), checked, and the note
        to print when the effort's refinement is skipped for want of cvxpy."""
        effort = dict(EFFORTS[self.effort])
        for key in ("starts", "pool", "max_iter", "refine"):
            if getattr(self, key) is not None:
                effort[key] = getattr(self, key)
        if self.starts is not None and self.pool is None and self.effort == "quick":
            effort["pool"] = max(int(effort["pool"]), 10 * int(self.starts))
        note = None
        if self.refine is None and effort["refine"] and not has_cvxpy():
            effort["refine"], note = 0, _NO_CVXPY_NOTE
        cfg = ExciteSettings(criterion=self.criterion, seed=self.seed, samples=self.samples,
                             structured=self.structured_starts, jobs=self.jobs, **effort)
        if cfg.refine and not has_cvxpy():
            raise ExcitationError(f"--refine {cfg.refine} needs cvxpy and clarabel: pip install "
                                  "'symoro-gen[physical]' (or --refine 0)")
        return cfg, note

    def basis(self) -> Any:
        """The design's basis from ``kind`` and its options."""
        if self.kind == "fourier":
            f = self.base_frequency or 1.0 / self.duration
            periods = self.duration * f
            if abs(periods - round(periods)) > 1e-6 or round(periods) < 1:
                raise ExcitationError(f"--duration {self.duration:g} is not a whole number of periods of "
                                      f"--base-frequency {f:g} Hz (the trajectory would not end at rest)")
            return FourierBasis(self.harmonics, f)
        if self.kind == "spline":
            return SplineBasis(self.coefficients or max(7, round(6 * self.duration)), self.duration)
        seg = ((self.duration + self.dwell) / (self.via_points - 1) - self.dwell if self.via_points >= 2 else 1.0)
        if seg <= 0:
            raise ExcitationError(f"--duration {self.duration:g} too short for {self.via_points} via-points with "
                                  f"--dwell {self.dwell:g}")
        return PointToPointBasis(self.via_points, seg, self.dwell)


@dataclass(frozen=True, eq=False)
class ExciteResults(Results):
    """An excitation design and its figures (see :meth:`to_dict` for the JSON contract, docs/json-output.md)."""

    command = "excite"

    robot: Any
    model: IdentificationModel
    options: ExciteOptions
    settings: ExciteSettings
    basis: Any
    limits: Limits
    result: ExcitationResult
    chi_b: np.ndarray | None
    output: str | None = None
    note: str | None = None

    # the samples, as the CSV has them
    @property
    def t(self) -> np.ndarray:
        return self.result.t

    @property
    def q(self) -> np.ndarray:
        return self.result.q

    @property
    def dq(self) -> np.ndarray:
        return self.result.dq

    @property
    def ddq(self) -> np.ndarray:
        return self.result.ddq

    @property
    def cond(self) -> float:
        return float(self.result.cond)

    @property
    def limits_ok(self) -> bool:
        return bool(self.result.limits_ok)

    @property
    def degenerate(self) -> bool:
        """The design's cond is above :data:`COND_DEGENERATE` (or not finite): its regressor is numerically
        rank-deficient, whatever its limits say."""
        return not (math.isfinite(float(self.result.cond)) and float(self.result.cond) <= COND_DEGENERATE)

    @property
    def ok(self) -> bool:
        """Limits respected and the design not degenerate (the command's exit status 0)."""
        return self.limits_ok and not self.degenerate

    def write_csv(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """The trajectory CSV (header ``t,q1..qn,dq1..dqn,ddq1..ddqn``) the controller runs."""
        r = self.result
        self.check_output(path, force=force, label="csv")
        write_trajectory_csv(path, r.t, r.q, r.dq, r.ddq, force=force)
        return Path(path)

    def to_dict(self) -> dict:
        """Exactly the JSON of ``symoro-gen excite --json`` (its ``generator`` mark first)."""
        o, res, lim, model = self.options, self.result, self.limits, self.model
        sig, pct = predicted_sigma(model, res.q, res.dq, res.ddq, o.noise, self.chi_b)
        passive = passive_ranges(model, res.q)
        return {
            "generator": "symoro-gen excite", "schema_version": SCHEMA_VERSION,
            "robot": model.ROBOT, "kind": self.basis.kind, "criterion": res.criterion, "cond": res.cond,
            "limits_ok": res.limits_ok, "degenerate": self.degenerate, "cond_degenerate": COND_DEGENERATE,
            "duration": o.duration, "rate": o.rate, "samples": len(res.t),
            "seed": o.seed, "effort": o.effort, "settings": {k: list(v) if isinstance(v, tuple) else v
                                                               for k, v in dataclasses.asdict(self.settings).items()},
            "limits": lim.as_dict(), "usage": res.usage,
            "torque_limits": bool(self.chi_b is not None and lim.tau_max is not None and not o.no_torque_limits),
            "noise": o.noise, "base_names": list(model.BASE_NAMES), "sigma": sig.tolist(),
            "sigma_pct": None if pct is None else [None if not np.isfinite(v) else float(v) for v in pct],
            "starts": res.starts, "wall_time": res.wall_time, "design": self.basis.coefficients(res.X),
            "joints": list(joint_numbers(model)),
            "workspace": None if lim.workspace is None else {
                "z_min": lim.workspace.z_min, "frames": list(lim.workspace.frames),
                "lowest_z": lim.workspace.heights(res.q).min(0).tolist()},
            "passive_ranges": {str(j): list(r) for j, r in passive.items()},
            "provenance": provenance(self.options, _robot_file(self.robot), {"seed": o.seed}),
        }

    def summary(self) -> str:
        """Exactly the text ``symoro-gen excite`` prints."""
        res, lim, model = self.result, self.limits, self.model
        worst = max(max(v) for v in res.usage.values())
        where = self.output if self.output is not None else "(not written: write_csv(path))"
        lines = [f"{model.ROBOT}: {self.basis.kind} excitation, {len(res.t)} samples at {self.options.rate:g} Hz "
                 f"-> {where}",
                 f"cond = {res.cond:.6g} (base regressor, unscaled; random starts: "
                 f"{', '.join(format(s['cond_start'], '.4g') for s in res.starts)}); limits_ok = {res.limits_ok} "
                 f"(peak usage {worst:.3f}); {res.wall_time:.1f} s"]
        if self.degenerate:
            lines.append(f"DEGENERATE design: cond = {res.cond:.3g} is above {COND_DEGENERATE:g}: its regressor is "
                         "numerically rank-deficient and identifies nothing, limits respected or not; the joints' "
                         "[limits] (q_min/q_max, dq_max, ddq_max) leave them (almost) no motion: widen them")
        refined = [st for st in res.starts if "refine_sdps" in st]
        if refined:
            lines.append("SDP refinement of the true cond: " + "; ".join(
                f"not run ({st['refine_skipped']})" if "refine_skipped" in st else
                f"{st['cond_ipopt']:.4g} -> {st['cond']:.4g} ({st['refine_accepted']} of {st['refine_sdps']} steps)"
                for st in refined))
        if self.note:
            lines.append(self.note)
        passive = passive_ranges(model, res.q)
        if passive:
            lines.append(passive_text(model, passive, lim))
        if lim.workspace is not None:
            lines.append(floor_text(lim.workspace, res.q))
        if lim.defaulted:
            lines.append(f"note: the robot file has no {', '.join(lim.defaulted)} in [limits]; used "
                         f"{lim.defaulted_text()} (give them in [limits] if the robot's differ)")
        return "\n".join(lines)

    def write_plot(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """PNG of every joint's ``q, dq, ddq`` against its limits (``--plot``)."""
        self.check_output(path, force=force, label="plot")
        plot_trajectory(self.result, path, robot=self.model.ROBOT, joints=joint_numbers(self.model), force=force)
        return Path(path)

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """The trajectories against the limits, cond, limit usage, predicted %sigma (``.html`` or ``.md``)."""
        self.check_output(path, force=force, label="report", report=True)
        write_report_files(excitation_report(self.result, self.model, noise=self.options.noise, chi_b=self.chi_b),
                           path, force=force)
        return Path(path)

    def figures(self) -> list:
        """The joint trajectories against the limits (one matplotlib figure)."""
        return [trajectory_figure(self.result, dpi=90, joints=joint_numbers(self.model),
                                  title=f"{self.model.ROBOT}: {self.basis.kind} excitation, cond = {self.cond:.4g}")]


#: bytes per output sample and joint beyond the base regressor's row: q, dq, ddq and the limits' 10x denser check
BYTES_PER_SAMPLE_JOINT = 8 * 3 * 11


def check_size(opts: ExciteOptions, n_joints: int, n_base: int, available: int | None = None) -> None:
    """Refuse, before any work, a design whose output samples would not fit in memory: the stacked base
    regressor (``n_joints`` rows of ``n_base`` per sample, for cond and the predicted sigma) and the samples'
    ``q, dq, ddq`` with the limits checked on a 10x denser resampling."""
    samples = opts.duration * opts.rate + 1
    need = samples * n_joints * (8 * n_base + BYTES_PER_SAMPLE_JOINT)
    available = available_memory() if available is None else available
    if available is not None and need > available:
        longest = max(available / (n_joints * (8 * n_base + BYTES_PER_SAMPLE_JOINT)) - 1, 0) / opts.rate
        raise ExcitationError(f"--duration {opts.duration:g} at --rate {opts.rate:g} Hz: {samples:.4g} output samples "
                              f"would need about {size_text(need)} of memory, {size_text(available)} is available; "
                              f"use --duration {longest:.4g} or less at this rate")


def _robot_file(desc) -> tuple[str, ...]:
    """The robot file a design was made for (an input of the provenance block), when it came from a file."""
    f = getattr(desc, "file", "")
    return (f,) if f and not f.startswith("<") and os.path.isfile(f) else ()


def excite(robot, *, output: str | os.PathLike[str] | None = None, force: bool = False,
           options: ExciteOptions | None = None, **kwargs: Any) -> ExciteResults:
    """Design an excitation trajectory within the robot's limits.

    Parameters
    ----------
    robot : str, path, RobotDescription or model
        A robot name (``robots/``), a robot file (its ``[limits]`` are used), a description or a loaded model.
    output : path, optional
        Write the trajectory CSV here (as ``-o``); else :meth:`ExciteResults.write_csv` writes it later.
    force : bool
        Replace an existing ``output`` symoro-gen did not write.
    options : ExciteOptions, optional
        All options at once; or give them by name (``duration=20``, ``seed=1``...): an unknown name raises
        :class:`~symoro_gen.errors.OptionError` naming the nearest valid one.

    Returns
    -------
    ExciteResults
    """
    opts = ExciteOptions.resolve("excite", options, kwargs, keywords=("output", "force", "options"))
    cfg, note = opts.settings()  # every option checked before the model is loaded
    desc, model = resolve_robot(robot)
    check_size(opts, int(model.N_JOINTS), len(model.BASE_NAMES))
    lim = limits_of(desc, model.N_JOINTS, model)
    if opts.z_min is not None:
        lim = with_floor(lim, desc, model, opts.z_min)
    basis = opts.basis()
    nominal = desc.nominal_vector()
    chi_b = None if nominal is None else np.asarray(model.base_parameters(np.asarray(nominal)), float)
    res = optimise_excitation(model, basis, lim, opts.duration, cfg, rate=opts.rate,
                              chi_b=None if opts.no_torque_limits else chi_b)
    out = ExciteResults(robot=desc, model=model, options=opts, settings=cfg, basis=basis, limits=lim, result=res,
                        chi_b=chi_b, output=None if output is None else os.fspath(output), note=note)
    if output is not None:
        out.write_csv(output, force=force)
    return out
