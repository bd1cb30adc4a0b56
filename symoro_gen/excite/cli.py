"""``symoro-gen excite``: the command-line part of the excitation design (its options, :func:`add_excite_parser`,
and the run, :func:`cmd_excite`). Nothing else in the package imports this module."""
from __future__ import annotations

import argparse
import dataclasses
from typing import Any

import numpy as np

from ..atomic import FORCE_HELP, json_output, write_output_text
from ..loader import model_for
from ..report import check_report_path
from ..report.document import write_report_files
from ..report.plots import require_matplotlib
from .bases import FourierBasis, PointToPointBasis, SplineBasis
from .criterion import predicted_sigma
from .limits import ExcitationError, limits_of, with_floor
from .optimise import EFFORTS, ExcitationResult, ExciteSettings, optimise_excitation
from .output import (
    excitation_report,
    floor_text,
    joint_numbers,
    passive_ranges,
    passive_text,
    plot_trajectory,
    write_trajectory_csv,
)
from .refine import has_cvxpy

__all__ = ["add_excite_parser", "cmd_excite"]

#: the effort the command runs with unless ``--effort`` says otherwise
DEFAULT_EFFORT = "quick"


def _effort_text(name: str) -> str:
    e = EFFORTS[name]
    return (f"{e['starts']} start(s), IPOPT p = {', '.join(map(str, e['powers']))} ({e['max_iter']} iterations at most "
            f"per stage), {e['refine']} SDPs")


def add_excite_parser(sub) -> None:
    """Register ``symoro-gen excite``."""
    e = sub.add_parser("excite", help="optimal excitation trajectory (Fourier, point-to-point or spline) -> CSV "
                                      "t,q,dq,ddq")
    e.add_argument("robot", help="robot name, robot .toml file (its [limits] are used) or generated package")
    e.add_argument("-o", "--output", required=True, help="CSV to write (header t,q1..qn,dq1..dqn,ddq1..ddqn)")
    e.add_argument("--kind", choices=("fourier", "p2p", "spline"), default="fourier",
                   help="Fourier series, point-to-point via-points, or a cubic B-spline (rest at both ends)")
    e.add_argument("--duration", type=float, default=10.0, help="seconds (Fourier: whole periods of the base frequency)")
    e.add_argument("--harmonics", type=int, default=5, help="Fourier harmonics per joint (>= 2)")
    e.add_argument("--base-frequency", type=float, default=None, help="Fourier base frequency [Hz] (default 1/duration)")
    e.add_argument("--via-points", type=int, default=8, help="p2p: via-points including start and end")
    e.add_argument("--coefficients", type=int, default=None,
                   help="spline: control points per joint (default 6 per second of --duration, at least 7)")
    e.add_argument("--structured-starts", type=int, default=0,
                   help="also draw this many designs whose joints alternate slow motion and bursts at the "
                        "velocity limit (the friction columns' optimum) into the pool of starts")
    e.add_argument("--dwell", type=float, default=0.0, help="p2p: rest at each intermediate via-point [s]")
    e.add_argument("--rate", type=float, default=100.0, help="output sampling rate [Hz]")
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--effort", choices=tuple(EFFORTS), default=DEFAULT_EFFORT,
                   help=f"how long to search: quick ({_effort_text('quick')}; about a minute on a 7-joint arm) or "
                        f"thorough ({_effort_text('thorough')}; what the command ran before, several times as long); "
                        "--starts, --pool, --max-iter and --refine override it (default %(default)s)")
    e.add_argument("--starts", type=int, default=None, help="IPOPT starts (default from --effort)")
    e.add_argument("--pool", type=int, default=None,
                   help="random feasible designs drawn; the --starts best by cond start IPOPT (default from --effort: "
                        "quick 40, thorough 10 x --starts)")
    e.add_argument("--jobs", type=int, default=1,
                   help="run the starts in this many processes at once (0: one per CPU; Linux); the result is the same")
    e.add_argument("--max-iter", type=int, default=None, help="IPOPT iterations per stage (default from --effort)")
    e.add_argument("--samples", type=int, default=None, help="samples of the criterion (default from the size of the problem)")
    e.add_argument("--criterion", choices=("cond", "logdet"), default="cond")
    e.add_argument("--refine", type=int, default=None, metavar="N",
                   help="cond criterion: then at most N sequential-SDP iterations on the true cond (cvxpy + Clarabel, "
                        "trust region) from each start's IPOPT result (default from --effort when cvxpy is "
                        "installed, the 'physical' extra, else 0; 0 skips it)")
    e.add_argument("--noise", type=float, default=1.0, help="torque-noise standard deviation for the predicted %%sigma [N m]")
    e.add_argument("--no-torque-limits", action="store_true", help="ignore tau_max even with nominal parameters")
    e.add_argument("--z-min", type=float, default=None, metavar="Z",
                   help="floor or table plane: every moving frame origin stays at z >= Z [m] in the base frame 0 "
                        "(add the links' radius as clearance)")
    e.add_argument("--json", help="write the figures (cond, limits_ok, predicted sigma...) as JSON here")
    e.add_argument("--plot", help="PNG of the joint trajectories against the limits")
    e.add_argument("--report", help="report (.html self-contained, or .md with its images beside it): trajectories "
                                    "against the limits, cond, limit usage, predicted %%sigma at --noise")
    e.add_argument("--force", action="store_true", help=FORCE_HELP)
    e.set_defaults(func=cmd_excite)


_NO_CVXPY_NOTE = ("note: cvxpy is not installed, the SDP refinement of the true cond was skipped "
                  "(pip install 'symoro-gen[physical]')")


def settings_of(args: argparse.Namespace) -> tuple[ExciteSettings, str | None]:
    """The :class:`ExciteSettings` of the command's options (``--effort`` and what overrides it), checked, and the
    note to print when the effort's refinement is skipped for want of cvxpy."""
    if args.duration <= 0 or args.rate <= 0:
        raise ExcitationError("--duration and --rate must be positive")
    effort = dict(EFFORTS[args.effort])
    for key in ("starts", "pool", "max_iter", "refine"):
        if getattr(args, key) is not None:
            effort[key] = getattr(args, key)
    if args.starts is not None and args.pool is None and args.effort == "quick":
        effort["pool"] = max(int(effort["pool"]), 10 * int(args.starts))
    note = None
    if args.refine is None and effort["refine"] and not has_cvxpy():
        effort["refine"], note = 0, _NO_CVXPY_NOTE
    cfg = ExciteSettings(criterion=args.criterion, seed=args.seed, samples=args.samples,
                         structured=args.structured_starts, jobs=args.jobs, **effort)
    if cfg.refine and not has_cvxpy():
        raise ExcitationError(f"--refine {cfg.refine} needs cvxpy and clarabel: pip install 'symoro-gen[physical]' "
                              "(or --refine 0)")
    return cfg, note


def basis_of(args: argparse.Namespace) -> Any:
    """The design's basis from ``--kind`` and its options."""
    if args.kind == "fourier":
        f = args.base_frequency or 1.0 / args.duration
        periods = args.duration * f
        if abs(periods - round(periods)) > 1e-6 or round(periods) < 1:
            raise ExcitationError(f"--duration {args.duration:g} is not a whole number of periods of "
                                  f"--base-frequency {f:g} Hz (the trajectory would not end at rest)")
        return FourierBasis(args.harmonics, f)
    if args.kind == "spline":
        return SplineBasis(args.coefficients or max(7, round(6 * args.duration)), args.duration)
    seg = (args.duration + args.dwell) / (args.via_points - 1) - args.dwell if args.via_points >= 2 else 1.0
    if seg <= 0:
        raise ExcitationError(f"--duration {args.duration:g} too short for {args.via_points} via-points with --dwell {args.dwell:g}")
    return PointToPointBasis(args.via_points, seg, args.dwell)


def _print_summary(args: argparse.Namespace, model: Any, basis: Any, res: ExcitationResult, lim: Any,
                   passive: dict, note: str | None) -> None:
    worst = max(max(v) for v in res.usage.values())
    print(f"{model.ROBOT}: {basis.kind} excitation, {len(res.t)} samples at {args.rate:g} Hz -> {args.output}")
    print(f"cond = {res.cond:.6g} (base regressor, unscaled; random starts: "
          f"{', '.join(format(s['cond_start'], '.4g') for s in res.starts)}); limits_ok = {res.limits_ok} "
          f"(peak usage {worst:.3f}); {res.wall_time:.1f} s")
    refined = [st for st in res.starts if "refine_sdps" in st]
    if refined:
        print("SDP refinement of the true cond: " + "; ".join(
            f"{st['cond_ipopt']:.4g} -> {st['cond']:.4g} ({st['refine_accepted']} of {st['refine_sdps']} steps)"
            for st in refined))
    if note:
        print(note)
    if passive:
        print(passive_text(model, passive, lim))
    if lim.workspace is not None:
        print(floor_text(lim.workspace, res.q))
    if lim.defaulted:
        print(f"note: the robot file has no {', '.join(lim.defaulted)} in [limits]; used {lim.defaulted_text()} "
              "(give them in [limits] if the robot's differ)")


def cmd_excite(args) -> int:
    """``symoro-gen excite``: design, write CSV (and JSON, plot), print a summary."""

    if args.report:
        check_report_path(args.report)  # before the long optimisation
    if args.plot or args.report:
        require_matplotlib()  # the same: a missing extra is said before minutes of optimisation, not after
    cfg, note = settings_of(args)  # every option checked before the model is loaded
    robot, model = model_for(args.robot)
    lim = limits_of(robot, model.N_JOINTS, model)
    if args.z_min is not None:
        lim = with_floor(lim, robot, model, args.z_min)
    basis = basis_of(args)
    chi_b = None
    nominal = robot.nominal_vector()
    if nominal is not None:
        chi_b = np.asarray(model.base_parameters(np.asarray(nominal)), float)
    res = optimise_excitation(model, basis, lim, args.duration, cfg, rate=args.rate,
                              chi_b=None if args.no_torque_limits else chi_b)
    force = getattr(args, "force", False)
    write_trajectory_csv(args.output, res.t, res.q, res.dq, res.ddq, force=force)
    sig, pct = predicted_sigma(model, res.q, res.dq, res.ddq, args.noise, chi_b)
    passive = passive_ranges(model, res.q)
    out = {
        "robot": model.ROBOT, "kind": basis.kind, "criterion": res.criterion, "cond": res.cond,
        "limits_ok": res.limits_ok, "duration": args.duration, "rate": args.rate, "samples": len(res.t),
        "seed": args.seed, "effort": args.effort, "settings": dataclasses.asdict(cfg),
        "limits": lim.as_dict(), "usage": res.usage,
        "torque_limits": bool(chi_b is not None and lim.tau_max is not None and not args.no_torque_limits),
        "noise": args.noise, "base_names": list(model.BASE_NAMES), "sigma": sig.tolist(),
        "sigma_pct": None if pct is None else [None if not np.isfinite(v) else float(v) for v in pct],
        "starts": res.starts, "wall_time": res.wall_time, "design": basis.coefficients(res.X),
        "joints": list(joint_numbers(model)),
        "workspace": None if lim.workspace is None else {
            "z_min": lim.workspace.z_min, "frames": list(lim.workspace.frames),
            "lowest_z": lim.workspace.heights(res.q).min(0).tolist()},
        "passive_ranges": {str(j): list(r) for j, r in passive.items()},
    }
    if args.json:
        write_output_text(args.json, json_output(out, "excite"), force=force)
    if args.plot:
        plot_trajectory(res, args.plot, robot=model.ROBOT, joints=joint_numbers(model), force=force)
    if args.report:
        write_report_files(excitation_report(res, model, noise=args.noise, chi_b=chi_b), args.report, force=force)
    if not args.quiet:
        _print_summary(args, model, basis, res, lim, passive, note)
    return 0 if res.limits_ok else 3
