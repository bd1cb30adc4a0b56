"""``symoro-gen diagnose``: identify, find what the residual says the model misses, add it, re-identify.

    symoro-gen diagnose ROBOT DATA... [--loaded DATA... [--payload NAME=VALUE...]] [--validate DATA...]
                        [--method ols|wls|tls] [--json OUT]
                        [--report OUT.md|OUT.html] [--plots DIR]

ROBOT is a robot name (robots/, generated/) or a robot .toml file; DATA are recordings the loaders of
:mod:`symoro_gen.preprocessing.readers` read (CSV/NPZ/MAT or a ``q=..,tau=..,dt=..`` spec), mapped to the
joint side by the robot file's drive chain. Without ``--validate`` the last ``--holdout`` share of each
recording is held out for validation. The JSON keys ``before``, ``after`` (``rel_err``,
``validation_rel_err``, ``validation_rel_err_raw``), ``effects`` (``kind``, ``joint``, ``modulation``,
``selection_frequency``, ``params``, ``ci``), ``unexplained`` (``joint``, ``share``, ``signals``) and ``tried``
are a contract. ``--loaded DATA... [--payload NAME=VALUE...]`` as in ``identify``.
"""
from __future__ import annotations

from pathlib import Path

from ..atomic import FORCE_HELP
from ..preprocessing.cli import add_data_options, data_block, data_notes, data_text, load_data

__all__ = ["add_diagnose_parser", "run_diagnose"]


def _check_options(args) -> None:
    from ..cli import OptionError

    checks = (("significance", "--significance", lambda v: 0 < v < 1, "must lie between 0 and 1"),
              ("holdout", "--holdout", lambda v: 0 < v < 1, "must lie between 0 and 1 (a share of each recording)"),
              ("max_effects", "--max-effects", lambda v: v >= 0, "must be >= 0"))
    for attr, flag, ok, what in checks:
        v = getattr(args, attr, None)
        if v is not None and not ok(v):
            raise OptionError(f"{flag} {v:g}: {what}")


def _refuse_still_joints(trajectories) -> None:
    """A joint that stands still in every identification file leaves its drive-chain columns of W zero:
    the loop cannot fit the declared model, so say which files and joints, before the long computation
    (issue 15; ``identify --drop-unexcited`` identifies the other parameters)."""
    from ..errors import IdentificationError
    from ..identification.estimators import still_joints

    trs = list(trajectories)
    per: dict[int, list[tuple[str, float]]] = {}
    for src, j, span in still_joints(trs):
        per.setdefault(j, []).append((src, span))
    still = {j: v for j, v in per.items() if len(v) == len(trs)}  # still in every file
    if not still:
        return
    files = list(dict.fromkeys(src for v in still.values() for src, _ in v))
    shown = ", ".join(files[:3]) + (f" and {len(files) - 3} more" if len(files) > 3 else "")
    why = ", ".join(f"joint {j} does not move (q{j} spans at most {max(s for _, s in v):.3g})"
                    for j, v in sorted(still.items()))
    err = IdentificationError(f"{shown}: {why}: the parameters of its motion (rotor inertia, friction) have no "
                              "effect on these data, and diagnose needs the declared model identifiable")
    err.hint = ("record a trajectory that moves every joint (symoro-gen excite), or identify the other "
                "parameters with `symoro-gen identify ... --drop-unexcited`")
    raise err


def run_diagnose(args) -> dict:
    """Run the command; returns the JSON dictionary."""
    import numpy as np

    from ..loader import model_for
    from .candidates import KINDS
    from .core import diagnose

    _check_options(args)
    if args.report:  # fail before the long computation on a bad suffix
        from ..report import check_report_path

        check_report_path(args.report)
    kinds = KINDS if not args.candidates else tuple(args.candidates)
    from ..commands.common import payload_values

    robot, model = model_for(args.robot)
    data, reports = load_data(args, args.data, robot, loaded=False)
    loaded, rep_l = load_data(args, args.loaded, robot, loaded=True) if args.loaded else (None, ())
    reports += rep_l
    known = payload_values(args.payload, tuple(getattr(model, "PAYLOAD_NAMES", ())))
    if known and not loaded:
        from ..errors import IdentificationError

        raise IdentificationError("--payload needs recordings with the payload: give them with --loaded")
    _refuse_still_joints(data)
    valid, rep_v = load_data(args, args.validate, robot) if args.validate else (None, ())
    reports += rep_v
    filt = {k: v for k, v in (("cutoff_hz", args.cutoff), ("n_d", args.decimate)) if v is not None}
    rep = diagnose(model, data, validation=valid, method=args.method, candidates=kinds,
                   significance=args.significance, max_effects=args.max_effects, holdout=args.holdout,
                   rng=np.random.default_rng(args.seed), loaded=loaded, payload=known, **filt)
    out = rep.to_dict()
    out["data"] = data_block(reports)  # per file: path, rows read, dropped, resampled, experiments
    out["validate"] = [str(p) for p in args.validate or ()]
    out["loaded"] = [str(p) for p in args.loaded or ()]
    force = getattr(args, "force", False)
    if args.json:
        from ..atomic import json_output, write_output_text

        write_output_text(Path(args.json), json_output(out, "diagnose"), force=force)
    if args.plots:
        files = rep.write_plots(args.plots, force=force)
        if not files and not args.quiet:
            print("note: no plots written (matplotlib is not installed: pip install 'symoro_gen[plots]')")
    if args.report:
        from ..workflows.reporting import ReportContent, write_report

        content = ReportContent(robot=robot.name, sources={
            "identification data": [str(p) for p in args.data], "loaded": [str(p) for p in args.loaded or ()],
            "validation data": [str(p) for p in args.validate or ()]}, text=rep.summary(),
            notes=data_notes(reports))
        write_report(args.report, diagnosis=rep, content=content, force=force)
    if not args.quiet:
        print(rep.summary() + "\n\n" + data_text(reports))
    return out


def add_diagnose_parser(subparsers) -> None:
    """Register ``diagnose`` on an argparse sub-parser collection."""
    from .candidates import KINDS
    from .core import HOLDOUT, MAX_EFFECTS, SIGNIFICANCE

    p = subparsers.add_parser("diagnose", help="find the effects the model misses in the residual, add them, "
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
    p.add_argument("--json", help="write the results as JSON here")
    p.add_argument("--report", metavar="OUT.md|OUT.html", help="write a report (tables and plots) here")
    p.add_argument("--plots", metavar="DIR", help="write the plots as PNG files in this folder")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_data_options(p)
    p.set_defaults(func=lambda a: (run_diagnose(a), 0)[1])
