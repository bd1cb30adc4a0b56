"""``symoro-gen identify``: recorded data -> identified parameters, gains, validation (JSON/Markdown)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..atomic import FORCE_HELP
from ..errors import IdentificationError, OptionError
from ..model import IdentificationModel
from ..observations.assembly import assemble
from ..observations.options import AssemblyOptions
from ..observations.system import ObservationSystem
from ..preprocessing.cli import add_data_options, data_block, data_notes, data_text, load_data, split_held_back
from .estimators import drop_unexcited, with_unexcited
from .physical import identify_physical
from .result import _json_float, basis_text
from .systems import stack_systems


def _payload_values(items, names) -> dict:
    out = {}
    for it in items or ():
        if "=" not in it:
            raise IdentificationError(f"--payload {it!r}: expected NAME=VALUE, e.g. M8=4.6136")
        k, v = it.split("=", 1)
        k = k.strip()
        if k not in names:
            raise IdentificationError(f"--payload {k}: not a payload parameter of this robot ({', '.join(names) or 'none'})")
        try:
            out[k] = float(v)
        except ValueError:
            raise IdentificationError(f"--payload {k}={v!r}: value is not a number") from None
    return out


def run_identify(args) -> dict:
    from ..loader import model_for
    from . import fit_with_known_payload, identify, identify_with_drive_gains, sensor_gains

    if args.report:  # before the long computation: a bad suffix or a missing matplotlib fails at once
        from ..report import check_report_path, require_matplotlib

        check_report_path(args.report)
        require_matplotlib()
    if getattr(args, "nominal_tolerance", None) is not None and not getattr(args, "physical", False):
        raise IdentificationError("--nominal-tolerance bounds the --physical estimate: add --physical")
    robot, model = model_for(args.robot)
    unloaded, reports = load_data(args, args.data, robot, loaded=False)
    unloaded, held_back = split_held_back(args, unloaded)
    loaded, rep_l = load_data(args, args.loaded, robot, loaded=True) if args.loaded else ((), ())
    reports += rep_l
    known = _payload_values(args.payload, model.PAYLOAD_NAMES)
    if (args.gains or known) and not loaded:
        raise IdentificationError("--gains and --payload need recordings with the payload: give them with --loaded")
    # --min-velocity (row selection) applies to the identification rows only; validation uses every sample
    opts = AssemblyOptions(cutoff_hz=args.cutoff, n_d=args.decimate, min_velocity=args.min_velocity)
    has_payload = bool(loaded)
    asm_u = assemble(model, unloaded, replace(opts, payload_columns=False))
    asm_l = assemble(model, loaded, replace(opts, payload_columns=True)) if loaded else None
    sys_u = asm_u.system
    sys_l = asm_l.system if asm_l is not None else None
    # a joint that stands still leaves columns of W zero: an error naming the files, or --drop-unexcited
    (sys_u, sys_l), unexcited = drop_unexcited([sys_u, sys_l], (*unloaded, *loaded), drop=args.drop_unexcited)
    if unexcited and args.method in ("iv", "didim"):
        raise OptionError(f"--drop-unexcited is not available with --method {args.method} (it simulates every joint)")
    dg = None
    closed = None
    if args.method in ("iv", "didim"):
        closed = _run_closed_loop(args, model, unloaded, opts, loaded, known)
        res = closed.result
    elif args.gains == "sensor":
        res = sensor_gains(sys_u, sys_l, known, essential=args.essential, r_sigma=args.r_sigma)
    elif args.gains == "drive":
        res, dg = identify_with_drive_gains(sys_u, sys_l, known, method=args.method)
    elif loaded:
        res = fit_with_known_payload(sys_u, sys_l, known, method=args.method, essential=args.essential, r_sigma=args.r_sigma)
    else:
        res = identify(sys_u, method=args.method, essential=args.essential, r_sigma=args.r_sigma)
    res = with_unexcited(res, unexcited).with_raw_error(model, *[a for a in (asm_u, asm_l) if a is not None])
    out = {"robot": robot.name, "data": [], "loaded": [str(p) for p in args.loaded or ()]}
    phys = res_u = None
    if getattr(args, "physical", False):
        phys, res_u, res = _physical(args, robot, model, res, sys_u, sys_l, known, asm_u, asm_l)
        out["unconstrained"] = res_u.to_dict()
        out["physical"] = phys.to_dict()
    out.update(res.to_dict())
    if closed is not None:
        out["iterations"] = closed.to_dict()
    val = val_raw = sys_v = asm_v = None
    if args.validate or held_back:
        vtr, rep_v = load_data(args, args.validate, robot, loaded=args.validate_loaded) if args.validate else ((), ())
        reports += rep_v
        vtr = tuple(held_back) + tuple(vtr)
        asm_v = assemble(model, vtr, replace(opts, min_velocity=None,
                                             payload_columns=bool(args.validate_loaded) or has_payload))
        sys_v = asm_v.system
        val = res.rel_err_on(sys_v)
        val_raw = res.rel_err_raw_on(model, asm_v)
        vnames = [tr.source for tr in held_back] + [str(p) for p in args.validate or ()]
        out["validation"] = {"data": vnames, "rel_err": [_json_float(x) for x in val],
                             "rel_err_raw": [_json_float(x) for x in val_raw],
                             "rel_err_basis": asm_v.metric_basis()}
        if res_u is not None:
            val_u, val_u_raw = res_u.rel_err_on(sys_v), res_u.rel_err_raw_on(model, asm_v)
            out["unconstrained"]["validation"] = {"rel_err": [_json_float(x) for x in val_u],
                                                  "rel_err_raw": [_json_float(x) for x in val_u_raw]}
    out["data"] = data_block(reports)
    if args.reference:
        from .reference import compare_with_reference, format_comparison

        rows = compare_with_reference(res, args.reference)
        out["reference"] = [
            {"expression": r.expression, "name": r.name, "ref": r.ref, "ref_rel_std_pct": r.ref_rel_std_pct,
             "agree_2sigma": r.agree_2sigma} for r in rows
        ]
        ref_text = format_comparison(rows)
    else:
        ref_text = ""
    if args.json:
        from ..atomic import json_output, write_output_text

        write_output_text(Path(args.json), json_output(out, "identify"), force=getattr(args, "force", False))
    text = res.summary()
    if closed is not None:
        text = closed.summary() + "\n\n" + text
    if val is not None:
        vb = asm_v.metric_basis()
        text += ("\n\nValidation (relative error norm per joint): every sample, no row selection\n"
                 f"  on the {basis_text(vb)}:\n    " + "  ".join(f"{x:.4f}" for x in val)
                 + f"\n  on the raw measured torque (model at full rate on the filtered states, {vb['samples']} samples per joint):"
                 "\n    " + "  ".join(f"{x:.4f}" for x in val_raw))
        if res_u is not None:
            text += ("\n  unconstrained estimate, same data:\n    " + "  ".join(f"{x:.4f}" for x in val_u)
                     + "\n    raw: " + "  ".join(f"{x:.4f}" for x in val_u_raw))
    if phys is not None:
        text += "\n\n" + phys.summary()
    if ref_text:
        text += "\n\nBeside the reference table " + str(args.reference) + ":\n" + ref_text
    text += "\n\n" + data_text(reports)
    if args.report:
        _write_report(args, robot, model, res, dg, sys_u, sys_l, sys_v, rows if args.reference else None, val_raw,
                      data_notes(reports), text=phys.summary() if phys is not None else None)
    if not args.quiet:
        print(text)
    return out


def _run_closed_loop(args, model: IdentificationModel, unloaded, opts, loaded, known):
    """``--method iv|didim``: IDIM-IV / DIDIM on the unloaded recordings (closed-loop simulations)."""
    from ..simulate.closed_loop import PIDGains
    from .didim import identify_didim
    from .iv import identify_iv

    if loaded or known or args.gains or args.essential:
        raise IdentificationError(f"--method {args.method} identifies the robot without payload from the DATA "
                                  f"recordings: --loaded, --payload, --gains and --essential are not available with it")
    gains = None
    given = [x for x in (args.kp, args.kd, args.ki) if x]
    if given:
        if not args.kp or not args.kd:
            raise IdentificationError("--kp and --kd go together (--ki is optional): the controller's gains per joint")
        n = model.N_JOINTS
        vals = []
        for name, x in (("--kp", args.kp), ("--kd", args.kd), ("--ki", args.ki or [0.0])):
            if len(x) not in (1, n):
                raise IdentificationError(f"{name}: give 1 value or {n} (one per joint), got {len(x)}")
            vals.append(x * n if len(x) == 1 else x)
        gains = PIDGains(*vals)
    start = None
    if args.start == "nominal":
        nominal = getattr(model, "nominal_parameters", lambda: None)()
        if nominal is None or not any(float(x) != 0 for x in nominal):
            raise IdentificationError(f"--start nominal: the robot file of {model.ROBOT} declares no nominal "
                                      f"inertial parameters")
        start = model.base_parameters(nominal)
    fn = identify_iv if args.method == "iv" else identify_didim
    return fn(model, unloaded, opts, gains=gains, bandwidth_hz=args.bandwidth, max_iter=args.max_iter, start=start)


def _physical(args, robot, model: IdentificationModel, res, sys_u, sys_l, known, asm_u, asm_l):
    """``--physical``: the consistent estimate on the same (gain-scaled, WLS-weighted) rows.

    Returns ``(PhysicalResult, unconstrained result, consistent result)``; the consistent result has the
    implied base parameters in the unconstrained result's names, its raw-torque errors attached.
    """
    system = stack_systems(sys_u, sys_l) if sys_l is not None else sys_u
    system = ObservationSystem(system.W, res.scaled_measurements(system), system.names, system.joint)
    joint_sigma = None
    if res.joint_sigma is not None:  # WLS: weights 1/sigma_j from the unconstrained residual per joint
        rho = system.Y - res.predict(system)
        n_j = np.bincount(system.joint, minlength=system.n_joints)
        joint_sigma = np.sqrt(np.bincount(system.joint, weights=rho ** 2, minlength=system.n_joints) / np.maximum(n_j, 1))
        joint_sigma = np.where(joint_sigma > 0, joint_sigma, 1.0)
    nominal = dict(zip(robot.standard_names, robot.nominal_vector() or ()))
    if robot.payload is not None and robot.nominal_payload() is not None:
        nominal.update(zip(robot.payload_names, robot.nominal_payload()))
    phys = identify_physical(model, system, joint_sigma=joint_sigma, known=known, nominal=nominal,
                             nominal_tolerance=args.nominal_tolerance)
    res_p = phys.as_identification_result(res).with_raw_error(model, *[a for a in (asm_u, asm_l) if a is not None])
    return phys, res, res_p


def _write_report(args, robot, model: IdentificationModel, res, dg, sys_u, sys_l, sys_v, reference, val_raw=None,
                  data_lines=(), text: str | None = None) -> None:
    """``--report OUT.html|OUT.md``: tables, measured vs reconstructed torques, singular values of W;
    with loaded validation data, the payload re-identified with the robot known (Table IV)."""
    from ..report import write_report
    from .payload import identify_payload

    loaded = sys_l is not None
    ident = [("identification data" + (" (unloaded)" if loaded else ""), sys_u)]
    if loaded:
        ident.append(("identification data (loaded)", sys_l))
    valid = [("validation data" + (" (loaded)" if args.validate_loaded else ""), sys_v)] if sys_v is not None else []
    raw = [(valid[0][0], val_raw)] if valid and val_raw is not None else []
    payload, notes = None, list(data_lines)
    pay_in_val = sys_v is not None and args.validate_loaded and any(n in sys_v.names for n in model.PAYLOAD_NAMES)
    if pay_in_val:
        try:
            payload = identify_payload(sys_v, res, payload_names=[n for n in model.PAYLOAD_NAMES if n in sys_v.names],
                                       gains=res.gains, method=args.method)
        except IdentificationError as exc:
            notes.append(f"payload not re-identified on the validation data: {exc}")
    sources = {"identification data": list(args.data), "loaded": list(args.loaded or ()),
               "validation data": list(args.validate or ())}
    write_report(args.report, res, robot=robot.name, sources=sources, identification=ident, validation=valid,
                 payload_names=model.PAYLOAD_NAMES, payload=payload, drive=dg, reference=reference, notes=notes,
                 raw_errors=raw, text=text, force=getattr(args, "force", False))


def add_identify_parser(sub) -> None:
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
                        "that stands still) and report them as not identified, instead of stopping")
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
    p.add_argument("--json", help="write the results as JSON here")
    p.add_argument("--report", metavar="OUT.html|OUT.md",
                   help="write a report here: tables and plots, one self-contained .html page or .md with its "
                        "images in OUT_files/ (plots need the 'plots' extra: matplotlib)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_data_options(p, validate_fraction=True)
    p.set_defaults(func=lambda a: (run_identify(a), 0)[1])
