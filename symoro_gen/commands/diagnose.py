"""``symoro-gen diagnose``: identify, find what the residual says the model misses, add it, re-identify.

    symoro-gen diagnose ROBOT DATA... [--loaded DATA... [--payload NAME=VALUE...]] [--validate DATA...]
                        [--method ols|wls|tls] [--positions link|motor] [--json OUT]
                        [--report OUT.md|OUT.html] [--plots DIR]

A leaf: the arguments become :class:`~symoro_gen.workflows.diagnose.DiagnoseOptions`, the workflow
:func:`symoro_gen.workflows.diagnose.diagnose` runs, its result is written (``--json``: ``to_dict()``,
``--plots``: PNG files, ``--report``) and printed (``summary()``).

ROBOT is a robot name (robots/, generated/) or a robot .toml file; DATA are recordings the loaders of
:mod:`symoro_gen.preprocessing.readers` read (CSV/NPZ/MAT or a ``q=..,tau=..,dt=..`` spec), mapped to the
joint side by the robot file's drive chain. Without ``--validate`` the last ``--holdout`` share of each
recording is held out for validation. The JSON keys ``before``, ``after`` (``rel_err``,
``validation_rel_err``, ``validation_rel_err_raw``), ``effects`` (``kind``, ``joint``, ``modulation``,
``selection_frequency``, ``params``, ``ci``), ``unexplained`` (``joint``, ``share``, ``signals``) and ``tried``
are a contract (docs/json-output.md).
"""
from __future__ import annotations

from ..atomic import FORCE_HELP
from ..diagnostics.candidates import KINDS
from ..diagnostics.core import HOLDOUT, MAX_EFFECTS, SIGNIFICANCE
from ..preprocessing.cli import add_data_options, format_from_args
from ..report import check_report_path
from ..workflows.diagnose import DiagnoseOptions, DiagnoseResults, diagnose
from .common import parse_payload

__all__ = ["add_parser", "options_from_args", "run"]


def options_from_args(args) -> DiagnoseOptions:
    """The workflow's options from the parsed arguments (checked here, before any file is read)."""
    return DiagnoseOptions(
        method=args.method, candidates=tuple(args.candidates) if args.candidates else None,
        significance=args.significance, max_effects=args.max_effects, holdout=args.holdout, cutoff=args.cutoff,
        decimate=args.decimate, seed=args.seed, payload=parse_payload(args.payload),
        drop_saturated=args.drop_saturated, positions=getattr(args, "positions", "link"),
        data_format=format_from_args(args))


def run(args) -> int:
    """Run ``diagnose``: the workflow, then its outputs; 0 on success."""
    opts = options_from_args(args)
    if args.report:  # before the long computation: a bad suffix fails at once
        check_report_path(args.report)
    res: DiagnoseResults = diagnose(args.robot, list(args.data), validate=args.validate, loaded=args.loaded,
                                    options=opts)
    force = bool(getattr(args, "force", False))
    if args.json:
        res.write_json(args.json, force=force)
    if args.plots:
        files = res.write_plots(args.plots, force=force)
        if not files and not args.quiet:
            print("note: no plots written (matplotlib is not installed: pip install 'symoro_gen[plots]')")
    if args.report:
        res.report(args.report, force=force)
    if not args.quiet:
        print(res.summary())
    return 0


def add_parser(sub) -> None:
    """Register ``diagnose``."""
    p = sub.add_parser("diagnose", help="find the effects the model misses in the residual, add them, "
                                        "re-identify, report errors before/after")
    p.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    p.add_argument("data", nargs="+", help="identification recordings (CSV/NPZ/MAT, or q=..,tau=..,dt=.. spec)")
    p.add_argument("--validate", nargs="+", help="validation recordings (default: hold out the end of each recording)")
    p.add_argument("--loaded", nargs="+", metavar="DATA",
                   help="identification recordings with the payload attached (as in identify --loaded): the "
                        "payload's columns are added to their rows")
    p.add_argument("--payload", nargs="+", metavar="NAME=VALUE",
                   help="known payload parameters (as in identify), e.g. M8=4.6136; needs --loaded")
    p.add_argument("--method", choices=("ols", "wls", "tls"), default="ols")
    p.add_argument("--candidates", nargs="+", choices=KINDS + ("friction_law", "composed"), metavar="KIND",
                   help=f"effect kinds to try (default all: {', '.join(KINDS)}, 'friction_law': the friction law "
                        "of each joint chosen by cross-validation, and 'composed': effect x modulating signal)")
    p.add_argument("--significance", type=float, default=SIGNIFICANCE,
                   help=f"family-wise level of each round (default {SIGNIFICANCE})")
    p.add_argument("--max-effects", type=int, default=MAX_EFFECTS, help=f"most effects added (default {MAX_EFFECTS})")
    p.add_argument("--holdout", type=float, default=HOLDOUT,
                   help=f"share of each recording held out when --validate is not given (default {HOLDOUT})")
    p.add_argument("--cutoff", type=float, help="low-pass cut-off of q [Hz] (default: the papers' rule)")
    p.add_argument("--decimate", type=int, help="decimation factor n_d (default: the papers' rule)")
    p.add_argument("--seed", type=int, default=0, help="seed of the placebo candidates")
    p.add_argument("--drop-saturated", action="store_true",
                   help="leave out the rows of each joint whose torque is saturated: at the robot file's [limits] tau_max, or "
                        "in plateaus of >= 5 samples at the column's extreme (docs/data-files.md)")
    p.add_argument("--positions", choices=("link", "motor"), default="link",
                   help="side of the logged positions: link (default) or motor (q_m/N, e.g. the LWR4's): then the "
                        "declared elastic joints' link positions are q = positions - tau/K, as in identify "
                        "(robot file: elastic = {K = ...}, docs/robot-file.md#elastic-joints)")
    p.add_argument("--json", help="write the results as JSON here")
    p.add_argument("--report", metavar="OUT.md|OUT.html", help="write a report (tables and plots) here")
    p.add_argument("--plots", metavar="DIR", help="write the plots as PNG files in this folder")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_data_options(p)
    p.set_defaults(func=run)
