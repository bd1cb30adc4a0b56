"""``symoro-gen excite``: a robot's limits -> an optimal excitation trajectory (CSV; JSON, plot, report).

A leaf: the arguments become :class:`~symoro_gen.workflows.excite.ExciteOptions`, the workflow
:func:`symoro_gen.workflows.excite.excite` runs and writes the CSV (``-o``), its result is written (``--json``:
``to_dict()``, ``--plot``, ``--report``) and printed (``summary()``). Exit 3 when the design breaks a limit.
"""
from __future__ import annotations

from ..atomic import FORCE_HELP
from ..excite.optimise import EFFORTS
from ..report import check_report_path, require_matplotlib
from ..workflows.excite import ExciteOptions, excite

__all__ = ["add_parser", "options_from_args", "run"]

#: the effort the command runs with unless ``--effort`` says otherwise
DEFAULT_EFFORT = "quick"

#: the options of the workflow that are flags of the command with the same name
_SAME = ("kind", "duration", "harmonics", "base_frequency", "via_points", "coefficients", "structured_starts", "dwell",
         "rate", "seed", "effort", "starts", "pool", "jobs", "max_iter", "samples", "criterion", "refine", "noise",
         "no_torque_limits", "z_min")


def _effort_text(name: str) -> str:
    e = EFFORTS[name]
    return (f"{e['starts']} start(s), IPOPT p = {', '.join(map(str, e['powers']))} ({e['max_iter']} iterations at most "
            f"per stage), {e['refine']} SDPs")


def options_from_args(args) -> ExciteOptions:
    """The workflow's options from the parsed arguments."""
    return ExciteOptions(**{k: getattr(args, k) for k in _SAME})


def run(args) -> int:
    """Run ``excite``: the design (its CSV written), then the other outputs; 0, or 3 when a limit is broken."""
    if args.report:
        check_report_path(args.report)  # before the long optimisation
    if args.plot or args.report:
        require_matplotlib()  # the same: a missing extra is said before minutes of optimisation, not after
    force = bool(getattr(args, "force", False))
    res = excite(args.robot, output=args.output, force=force, options=options_from_args(args))
    if args.json:
        res.write_json(args.json, force=force)
    if args.plot:
        res.write_plot(args.plot, force=force)
    if args.report:
        res.report(args.report, force=force)
    if not args.quiet:
        print(res.summary())
    return 0 if res.ok else 3


def add_parser(sub) -> None:
    """Register ``excite``."""
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
    e.set_defaults(func=run)
