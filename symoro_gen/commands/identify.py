"""``symoro-gen identify``: recorded data -> identified parameters, gains, validation (text, JSON, report).

A leaf: the arguments become :class:`~symoro_gen.workflows.identify.IdentifyOptions`, the workflow
:func:`symoro_gen.workflows.identify.identify` runs, its result is written (``--json``: ``to_dict()``,
``--report``) and printed (``summary()``).
"""
from __future__ import annotations

from ..atomic import FORCE_HELP
from ..description import load_robot
from ..errors import OptionError
from ..preprocessing.cli import add_data_options, format_from_args
from ..report import check_report_path, require_matplotlib
from ..workflows.identify import IdentifyOptions, IdentifyResults, identify, robot_out_refusal
from .common import parse_payload

__all__ = ["add_parser", "options_from_args", "run"]


def options_from_args(args) -> IdentifyOptions:
    """The workflow's options from the parsed arguments."""
    return IdentifyOptions(
        method=args.method, validate_loaded=args.validate_loaded,
        validate_fraction=getattr(args, "validate_fraction", None), payload=parse_payload(args.payload),
        gains=args.gains, essential=args.essential, r_sigma=args.r_sigma, cutoff=args.cutoff,
        decimate=args.decimate, min_velocity=args.min_velocity, drop_unexcited=args.drop_unexcited,
        drop_saturated=args.drop_saturated,
        reference=args.reference, kp=args.kp, kd=args.kd, ki=args.ki, bandwidth=args.bandwidth,
        max_iter=args.max_iter, start=args.start, physical=getattr(args, "physical", False),
        nominal_tolerance=getattr(args, "nominal_tolerance", None),
        bounded_bodies=getattr(args, "bounded_bodies", False), data_format=format_from_args(args),
        geometry=getattr(args, "geometry", None), geometry_joints=getattr(args, "geometry_joints", None),
        geometry_frames=getattr(args, "geometry_frames", None),
        positions=getattr(args, "positions", "link"), kind=getattr(args, "kind", None),
        weighting=getattr(args, "weighting", "kind"))


def run(args) -> int:
    """Run ``identify``: the workflow, then its outputs; 0 on success."""
    if args.report:  # before the long computation: a bad suffix or a missing matplotlib fails at once
        check_report_path(args.report)
        require_matplotlib()
    opts = options_from_args(args)
    robot_out = getattr(args, "robot_out", None)
    if robot_out and not opts.geometry:  # before the long computation: a robot file with nothing to identify
        robot = load_robot(args.robot)
        if not robot.elastic and not robot.friction_laws:
            raise OptionError(robot_out_refusal(robot))
    res: IdentifyResults = identify(args.robot, list(args.data), validate=args.validate, loaded=args.loaded,
                                    options=opts)
    force = bool(getattr(args, "force", False))
    if robot_out:  # first: the JSON records the file written
        res = res.write_robot(robot_out, force=force)
    if args.json:
        res.write_json(args.json, force=force)
    if args.report:
        res.report(args.report, force=force)
    if not args.quiet:
        print(res.summary())
    return 0


def add_parser(sub) -> None:
    """Register ``identify``."""
    p = sub.add_parser("identify", help="identify base parameters (and gains) from recorded data")
    p.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    p.add_argument("data", nargs="+", help="recordings without payload (CSV/NPZ/MAT, or q=..,tau=..,dt=.. spec)")
    p.add_argument("--method", choices=("ols", "wls", "tls", "iv", "didim"), default="wls",
                   help="estimator: IDIM-OLS/WLS/TLS, or the closed-loop ones IDIM-IV and DIDIM (iterated simulations; "
                        "reference = the filtered measured positions, controller = --kp/--kd/--ki or a PD at --bandwidth)")
    p.add_argument("--validate", nargs="+", help="validation recordings (relative error norms, Table III)")
    p.add_argument("--validate-loaded", action="store_true", help="the validation recordings carry the payload")
    p.add_argument("--loaded", nargs="+", help="recordings with the payload mounted")
    p.add_argument("--payload", nargs="+", metavar="NAME=VALUE", help="known payload parameters, e.g. M8=4.6136")
    p.add_argument("--gains", choices=("sensor", "drive"), help="also identify torque-sensor (IDIM-TLS) or drive gains")
    p.add_argument("--essential", action="store_true", help="reduce to the essential parameters")
    p.add_argument("--r-sigma", type=float, default=30.0, help="stop ratio of the essential procedure (default 30)")
    p.add_argument("--cutoff", type=float, help="low-pass cut-off of q [Hz] (default: the papers' rule)")
    p.add_argument("--decimate", type=int, help="decimation factor n_d (default: the papers' rule)")
    p.add_argument("--min-velocity", type=float, help="drop identification rows that depend on samples slower than "
                   "this [rad/s] (Coulomb friction is ill-defined near zero velocity); validation errors use every sample")
    p.add_argument("--drop-unexcited", action="store_true",
                   help="leave out the parameters the data do not excite (their columns of W are zero, e.g. a joint "
                        "that stands still, or moves at its noise level: held still) and report them as not "
                        "identified, instead of stopping")
    p.add_argument("--drop-saturated", action="store_true",
                   help="leave out the rows of each joint whose torque is saturated: at the robot file's [limits] tau_max, or "
                        "in plateaus of >= 5 samples at the column's extreme (docs/data-files.md)")
    p.add_argument("--reference", help="published base-parameter table (CSV: expression, estimate, rel.std%%) to compare with")
    cl = p.add_argument_group("closed-loop estimators (--method iv|didim)")
    cl.add_argument("--kp", type=float, nargs="+", help="position gain(s) of the robot's PID controller, per joint")
    cl.add_argument("--kd", type=float, nargs="+", help="velocity gain(s) of the controller, per joint")
    cl.add_argument("--ki", type=float, nargs="+", help="integral gain(s) of the controller, per joint (default 0)")
    cl.add_argument("--bandwidth", type=float, help="without --kp/--kd: PD gains placing each joint at this "
                    "bandwidth [Hz] (default 10, at most rate/30)")
    cl.add_argument("--max-iter", type=int, default=20, help="iterations at most (default 20)")
    cl.add_argument("--start", choices=("ols", "nominal"), default="ols",
                    help="first estimate simulated: IDIM-OLS (default; the OLS fit on the reference states when it is "
                         "not physical) or the robot file's nominal parameters")


    p.add_argument("--physical", action="store_true",
                   help="physically consistent estimate: LS in the standard parameters with every body's pseudo-inertia "
                        "positive definite and IA, FV, FS >= 0 (needs the 'physical' extra: cvxpy, clarabel); "
                        "'parameters' then holds the base parameters it implies, 'unconstrained' the plain fit. With "
                        "--method iv|didim it is NOT a constrained IV/DIDIM: the IV/DIDIM estimate is reported as "
                        "'unconstrained' and the consistent set is the least-squares fit on the measured-state (IDIM) "
                        "rows, independent of it")
    p.add_argument("--nominal-tolerance", type=float, metavar="TOL",
                   help="with --physical: also bound every standard parameter with a non-zero nominal value to "
                        "|chi - nominal| <= TOL |nominal|")
    p.add_argument("--bounded-bodies", action="store_true",
                   help="with --physical: keep each link's mass distribution inside the box of its frame origins and "
                        "children (plus a margin; so its centre of mass too) and its mass within a factor 3 of a "
                        "non-zero nominal mass (docs/plausibility.md)")
    p.add_argument("--geometry", choices=("joint_zero", "length", "joint_zero,length", "length,joint_zero"),
                   metavar="joint_zero|length|joint_zero,length",
                   help="also identify geometric parameters: joint_zero = the encoder zeros of the joints torque "
                        "data can see, length = the MDH lengths d, r it can see (joint_zero,length: both; "
                        "Gauss-Newton alternating with the linear fit; the others are reported as not "
                        "identifiable); everything after runs at the corrected geometry")
    p.add_argument("--geometry-joints", type=int, nargs="+", metavar="J",
                   help="with --geometry joint_zero: the joints (1-based) whose zero is fitted (default: every joint "
                        "whose zero torque data can see)")
    p.add_argument("--geometry-frames", nargs="+", metavar="FRAME[d|r]",
                   help="with --geometry length: the lengths fitted, e.g. 3r 4d, or 3 for both of frame 3's visible "
                        "ones (default: every length torque data can see)")
    p.add_argument("-o", "--robot-out", metavar="PATH",
                   help="write the robot file with what this run identified here: the joint zeros (--geometry "
                        "joint_zero) added to the frames' theta (r), the link-length errors (--geometry length) added "
                        "to d/r, K and D of the elastic joints the two-encoder fit "
                        "estimated, the fitted friction-law scales; refused when none was identified. The [nominal] "
                        "values are not written (the base parameters are not the standard ones). Never over the input "
                        "robot file; an existing file only with --force")
    p.add_argument("--positions", choices=("link", "motor"), default="link",
                   help="side of the logged positions: link (default) or motor (q_m/N, e.g. the LWR4's): then the "
                        "declared elastic joints' link positions are q = positions - tau/K (robot file: elastic = "
                        "{K = ...}; LWR4 paper eq. 17), velocities and accelerations from them")
    fl = p.add_argument_group("floating-base robots (base = \"floating\"; logs of docs/floating-base.md)")
    fl.add_argument("--kind", choices=("base", "joints", "both"),
                    help="rows identified: the 6 base-wrench rows (no joint torque needed), the joint rows, or both "
                         "(default: both when every log has joint torques, else base)")
    fl.add_argument("--weighting", choices=("kind", "row"), default="kind",
                    help="WLS groups: each kind of rows (default) or each row position")
    p.add_argument("--json", help="write the results as JSON here")
    p.add_argument("--report", metavar="OUT.html|OUT.md",
                   help="write a report here: tables and plots, one self-contained .html page or .md with its "
                        "images in OUT_files/ (plots need the 'plots' extra: matplotlib)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_data_options(p, validate_fraction=True)
    p.set_defaults(func=run)
