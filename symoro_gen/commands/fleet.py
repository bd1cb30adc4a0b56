"""``symoro-gen fleet ROBOT LOGS... --by PATTERN``: identify a fleet on Dask and flag drifting robots.

A leaf: the arguments become :class:`~symoro_gen.fleet.options.FleetOptions`, the workflow
:func:`symoro_gen.workflows.fleet.fleet` runs, its result is written (``--json``: ``to_dict()``, ``--report``)
and printed (``summary()``; the throughput on standard error).
"""
from __future__ import annotations

import argparse
import sys

from ..atomic import FORCE_HELP
from ..fleet.options import DEFAULT_ALPHA
from ..preprocessing.cli import add_data_options, format_from_args
from ..workflows.fleet import FleetOptions, fleet

__all__ = ["add_parser", "options_from_args", "run"]


def options_from_args(args) -> FleetOptions:
    """The workflow's options from the parsed arguments."""
    return FleetOptions(scheduler=args.scheduler, alpha=args.alpha, correction=args.correction, retries=args.retries,
                        cutoff=args.cutoff, decimate=args.decimate, segment_samples=args.segment_samples,
                        chunk_samples=args.chunk_samples, diagnose=args.diagnose,
                        diagnose_method=args.diagnose_method, data_format=format_from_args(args))


def run(args) -> int:
    """Run the command; 0 whether or not robots are flagged (the flags are in the output)."""
    res = fleet(args.robot, args.logs, by=args.by, options=options_from_args(args))
    force = bool(getattr(args, "force", False))
    if args.json:
        res.write_json(args.json, force=force)
    if args.report:
        res.report(args.report, force=force)
    if not getattr(args, "quiet", False):
        print(res.summary())
        t = res.timing
        print(f"{t['samples']} samples in {t['run_s']:.1f} s on {res.settings['workers']} worker(s) "
              f"({t['samples_per_s']:.3g} samples/s)", file=sys.stderr)
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``fleet`` (Dask and pyarrow are imported only when it runs)."""
    p = sub.add_parser("fleet", help="identify many robots of one model from their logs (Dask) and flag drifts",
                       description="Identify every robot of a fleet per day from its logs on a Dask cluster "
                                   "(exact TSQR reductions), pool the fleet, and flag the robots whose parameters "
                                   "drift away from the fleet (docs/fleet.md).")
    p.add_argument("robot", help="robot name (robots/, generated/) or robot .toml file")
    p.add_argument("logs", nargs="+", help="log files, globs or folders (CSV, NPZ, MAT, Parquet)")
    p.add_argument("--by", required=True, metavar="PATTERN",
                   help="how a path names its robot and day, matched against its end, e.g. '{robot}/{day}.parquet' "
                        "('*' matches any part of one path element)")
    p.add_argument("--scheduler", metavar="ADDRESS|local:N|threads:N",
                   help="Dask scheduler address (tcp://host:8786), or local:N (or processes:N) worker processes "
                        "(default local with min(2, cpus)), or threads:N in this process; N >= 1")
    p.add_argument("--json", metavar="OUT.json", help="write the results as JSON here")
    p.add_argument("--report", metavar="OUT.html|OUT.md", help="write a report with the plot of every flagged "
                   "parameter over the days (plots need matplotlib: the 'plots' extra)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--alpha", type=float, default=DEFAULT_ALPHA,
                   help="level of the flags after the multiple-testing correction (default %(default)s)")
    p.add_argument("--correction", choices=("holm", "bh"), default="holm",
                   help="holm: family-wise error rate; bh: Benjamini-Hochberg false-discovery rate")
    p.add_argument("--retries", type=int, default=2, help="times a failed or lost task is re-run")
    p.add_argument("--cutoff", type=float, help="Butterworth cut-off of q [Hz] (default: Gautier's rule per log)")
    p.add_argument("--decimate", type=int, help="decimation factor n_d (default: Gautier's rule per log)")
    p.add_argument("--segment-samples", type=int, metavar="N",
                   help="cut Parquet logs longer than N samples into segments, one task each (a worker's memory "
                        "is bounded by the segment, not by the log; each segment loses its filter edges)")
    p.add_argument("--chunk-samples", type=int, metavar="N",
                   help="full-rate samples per block inside a task (bounds the memory of a worker)")
    p.add_argument("--diagnose", action="store_true",
                   help="close the loop: run the residual diagnosis (symoro-gen diagnose) on each flagged robot's "
                        "logs of the last flagged day; its summary goes to the output, the JSON and the report")
    p.add_argument("--diagnose-method", choices=("ols", "wls", "tls"), default="wls",
                   help="estimator of those diagnoses (default %(default)s)")
    add_data_options(p)
    p.set_defaults(func=run)
    return p
