"""``symoro-gen inspect``: what recordings can give before identifying (text, JSON, report).

A leaf: the arguments become :class:`~symoro_gen.workflows.inspect.InspectOptions`, the workflow
:func:`symoro_gen.workflows.inspect.inspect` runs, its result is written (``--json``: ``to_dict()``, ``--report``)
and printed (``summary()``, also under ``--quiet`` when the data are not usable). Exit 0 when usable, 2 when not.
"""
from __future__ import annotations

from ..atomic import FORCE_HELP
from ..preprocessing.cli import add_data_options, format_from_args
from ..report import check_report_path, require_matplotlib
from ..workflows.inspect import InspectOptions, inspect

__all__ = ["add_parser", "options_from_args", "run"]


def options_from_args(args) -> InspectOptions:
    """The workflow's options from the parsed arguments."""
    return InspectOptions(cutoff=args.cutoff, decimate=args.decimate, data_format=format_from_args(args))


def run(args) -> int:
    """Run ``inspect``; 0 when the data are usable, 2 when not."""
    if args.report:
        check_report_path(args.report)
        require_matplotlib()
    res = inspect(args.robot, list(args.data), options=options_from_args(args))
    force = bool(getattr(args, "force", False))
    if args.json:
        res.write_json(args.json, force=force)
    if args.report:
        res.report(args.report, force=force)
    if not args.quiet or not res.usable:
        print(res.summary())
    return 0 if res.usable else 2


def add_parser(sub) -> None:
    """Register ``inspect``."""
    p = sub.add_parser("inspect", help="what a recording can give: sampling, gaps, bad rows, standstill, "
                                       "saturation, filter cut-off, cond(W), parameters it cannot identify")
    p.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    p.add_argument("data", nargs="+", help="recordings (CSV/NPZ/MAT, or q=..,tau=..,dt=.. spec)")
    p.add_argument("--cutoff", type=float, help="low-pass cut-off of q [Hz] (default: the papers' rule)")
    p.add_argument("--decimate", type=int, help="decimation factor n_d (default: the papers' rule)")
    p.add_argument("--json", help="write the findings as JSON here")
    p.add_argument("--report", metavar="OUT.html|OUT.md", help="write a report with a plot per joint here")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_data_options(p)
    p.set_defaults(func=run)
