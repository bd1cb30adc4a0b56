"""The ``symoro-gen`` command.

Errors meant for users print as one line of what is wrong and where (one line per problem when a
file has several), then a ``hint:`` line, and exit with status 2; ``--debug`` also prints the
traceback. Unexpected failures (bugs) exit with status 1. Progress bars go to standard error when
it is a terminal (``SYMORO_PROGRESS=1`` forces them, ``=0`` or ``--quiet`` hides them).
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
import warnings
from pathlib import Path

from . import progress
from .atomic import FORCE_HELP, Target, check_outputs, json_output, write_output_text
from .errors import (
    DataFileError,
    IdentificationError,
    ModelError,
    OptionError,
    RobotFileError,
    ShapeError,
    SymoroError,
)
from .loader import generated_dir, load_model
from .progress import close_all, progress_mode, stage_callback

# The commands import the description/generation stack (sympy, ~1 s) and the sub-commands' modules
# (identification, diagnostics, preprocessing: scipy) inside the functions on purpose: `symoro-gen --help`
# and the light commands start without them (see build_parser and _LIGHT_COMMANDS).

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # as a shell reports a process killed by SIGPIPE


def generation_steps(robot) -> int:
    """Steps of the generation bar: Newton-Euler forward (per frame) and backward (per moving or
    payload frame) passes, base parameters, emission."""
    backward = sum(1 for r in robot.rows if r.is_moving or (robot.payload is not None and r.j == robot.payload))
    return len(robot.rows) + backward + 2


def cmd_generate(args) -> int:
    from .baseparams.regroup import group_base_parameters
    from .description import load_robot
    from .dynamics.newton_euler import build_regressor
    from .emit.package import check_name, check_replaceable, emit_from

    robot = load_robot(args.robot)
    out = Path(args.out) if args.out else generated_dir()
    check_name(robot)
    # the package folder is replaced whole: never over the robot file; and only a package generate wrote
    # from this robot file (emit.package.check_replaceable), before the (long) generation
    check_outputs({"--out": Target(out / robot.name, folder=True, owner="caller")}, [("ROBOT", robot.file)])
    check_replaceable(out / robot.name, robot.name, args.force, robot_file=robot.file)
    # the steps of emit_robot, one bar over them
    # through the module: tests replace progress.progress_bar
    with progress.progress_bar(generation_steps(robot), f"{robot.name}", unit="step") as bar:
        reg = build_regressor(robot, progress=stage_callback(bar, prefix=f"{robot.name}: newton-euler "))
        bar.set_description(f"{robot.name}: base parameters")
        bp = group_base_parameters(reg)
        bar.update(1)
        bar.set_description(f"{robot.name}: emission (NumPy, C, CasADi)")
        m = emit_from(reg, bp, out, force=args.force)
        bar.update(1)
    if not args.quiet:
        print(
            f"{m.robot}: {m.n_standard} standard -> {m.n_base} base parameters; base regressor "
            f"{m.base_ops.mul} mul, {m.base_ops.div} div, {m.base_ops.add} add -> {m.path}"
        )
        if robot.constrained:
            print(f"{m.robot}: {len(robot.loops)} closed loop(s), {len(robot.couplings)} coupled joint(s): this package is the tree model; load_model() "
                  f"projects it on the {len(robot.actuated)} actuated joints (its base parameters: "
                  "model.base_parameters_text())")
    return 0


def cmd_build(args) -> int:
    """Compile the C kernels of a generated package (``symoro-gen build ROBOT``)."""
    m = load_model(args.robot)
    m = getattr(m, "tree", m)  # a closed-loop or coupled robot: the kernels are its tree's package's
    model = getattr(m, "_MODEL", None)
    if model is None:
        raise ModelError(f"{args.robot}: not a generated package with C kernels")
    res = model.build(force=args.force, timeout=args.timeout)
    if not args.quiet:
        print(f"{m.ROBOT}: C kernels {'compiled' if res.compiled else 'already built'} -> {res.path}")
    return 0


def _output(text: str, args, *, robot_file: bool = False) -> int:
    """Write a command's text to ``--output`` (atomically; robot files validated, never overwritten
    without ``--force``; other files only over a file symoro-gen wrote, see :mod:`symoro_gen.atomic`)
    or to standard output."""
    if not args.output:
        sys.stdout.write(text)
        return 0
    if robot_file:
        from .description.par import write_robot_toml

        write_robot_toml(text, args.output, overwrite=args.force)
    else:
        write_output_text(Path(args.output), text, force=args.force, label="-o/--output")
    if not args.quiet:
        print(f"wrote {args.output}")
    return 0


def cmd_import_par(args) -> int:
    from .description.par import import_par

    return _output(import_par(args.file), args, robot_file=True)


def cmd_export_par(args) -> int:
    from .description import load_robot
    from .description.par import export_par

    return _output(export_par(load_robot(args.robot)), args)


def cmd_import_urdf(args) -> int:
    from .description.urdf import import_urdf

    actuated = [a.strip() for a in args.actuated.split(",") if a.strip()] if args.actuated else None
    return _output(import_urdf(args.file, base=args.base, tip=args.tip, name=args.name, actuated=actuated), args,
                   robot_file=True)


def _export_values(args):
    """Robot, standard and payload values, header notes and sidecar content for export-urdf/export-mjcf."""
    import json

    from .description import load_robot
    from .errors import ModelError

    robot = load_robot(args.robot)
    src = getattr(args, "from_result", None)
    if not src:
        return robot, None, None, [], None
    from .identification.physical import standard_set_from_result
    from .loader import model_for

    try:
        result = json.loads(Path(src).read_text())
    except (OSError, ValueError) as exc:
        raise ModelError(f"{src}: not a result of `symoro-gen identify` ({exc})") from None
    if not isinstance(result, dict):
        raise ModelError(f"{src}: not a result of `symoro-gen identify` (a JSON object is expected)")
    _, model = model_for(robot)
    nominal = dict(zip(robot.standard_names, robot.nominal_vector() or ()))
    sb, payload = standard_set_from_result(model, result, nominal, source=src)
    vals = sb.as_dict()
    chi = [vals.get(n, 0.0) for n in robot.standard_names]
    pay = None
    notes = [f"inertial and drive parameters from {Path(src).name}: physically consistent standard set whose "
             f"regrouping {'is exactly' if sb.exact else 'is the closest (least squares) to'} the identified base parameters"]
    if robot.payload is not None:
        if payload:
            pay = [payload[n] for n in robot.payload_names]
            notes.append(f"payload (frame {robot.payload}) as identified in {Path(src).name}")
        else:  # the identified model is the robot without the payload: do not mount the nominal one
            pay = [0.0] * len(robot.payload_names)
            notes.append(f"payload (frame {robot.payload}) not identified in {Path(src).name}: written without mass")
    notes += list(sb.notes)
    moved = [b for b in sb.bodies if "mass_change" in b]
    for b in moved:
        notes.append(f"{b['body']}: mass {b['mass']:.6g} kg ({b['mass_change']:+.3g} from nominal), centre of mass "
                     f"moved {b['com_shift']:.3g} m" + (f", inertia changed {100 * b['inertia_change_rel']:.3g} %"
                                                        if b.get("inertia_change_rel") is not None else ""))
    sidecar = {"robot": robot.name, "from": str(src), "exact": sb.exact, "base_error": sb.base_error,
               "notes": list(sb.notes), "bodies": list(sb.bodies), "active_constraints": list(sb.active_constraints)}
    return robot, chi, pay, notes, sidecar


def _write_export(args, text: str, report: list, sidecar: dict | None, what: str, robot, chi, pay) -> int:
    """Print the notes about changed links, write the text and, with ``--from`` and ``-o``, the sidecar JSON."""
    from .description.urdf_export import drive_terms, link_values

    for msg in report:
        print(f"note: {msg}", file=sys.stderr)
    rc = _output(text, args)
    if args.output and sidecar is not None:
        side = Path(str(args.output) + ".json")
        sidecar["drive"] = drive_terms(robot, link_values(robot, chi, pay))
        sidecar["drive_note"] = ("IA (rotor inertia) and OFF (torque offset) have no URDF field: MuJoCo's armature "
                                 "holds IA; FV, FS are URDF <dynamics damping friction>")
        sidecar["changed_links"] = report
        write_output_text(side, json_output(sidecar, what), force=args.force, label="-o/--output (its .json)")
        if not args.quiet:
            print(f"wrote {side}")
    return rc


def cmd_export_urdf(args) -> int:
    import json

    from .description.urdf_export import export_urdf
    from .errors import ModelError

    robot, chi, pay, notes, sidecar = _export_values(args)
    params = None
    if args.params:
        if chi is not None:
            raise ModelError("export-urdf: give --from RESULT.json or --params RESULT.json, not both")
        try:
            d = json.loads(Path(args.params).read_text())
            p = d["parameters"]
            params = {n: v for n, v in zip(p["names"], p["values"]) if v is not None}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ModelError(f"{args.params}: not a result of `symoro-gen identify` ({exc})") from None
    report: list[str] = []
    text = export_urdf(robot, chi, pay, params=params, notes=notes, report=report)
    return _write_export(args, text, report, sidecar, "export-urdf", robot, chi, pay)


def cmd_export_mjcf(args) -> int:
    from .description.mjcf_export import export_mjcf

    robot, chi, pay, notes, sidecar = _export_values(args)
    report: list[str] = []
    text = export_mjcf(robot, chi, pay, notes=notes, report=report, timestep=args.timestep)
    return _write_export(args, text, report, sidecar, "export-mjcf", robot, chi, pay)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; with ``command`` (the sub-command about to run) the other commands whose
    registration imports heavy modules (identify, diagnose: SciPy...) are left out, which makes a
    light command start in well under a second."""
    p = argparse.ArgumentParser(prog="symoro-gen", description=__doc__.splitlines()[0])
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress, no chatter")
    sub = p.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="MDH robot file -> generated/<robot>/ (NumPy + CasADi regressors)")
    g.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    g.add_argument("--out", help="output folder (default: generated/ of the repository)")
    g.add_argument("--force", action="store_true",
                   help="replace OUT/<robot> even when it is not a package a previous `generate` wrote")
    g.set_defaults(func=cmd_generate)

    b = sub.add_parser("build", help="compile the C kernels of a generated package (otherwise done on first use)")
    b.add_argument("robot", help="robot name, generated package folder, or robot .toml file")
    b.add_argument("--force", action="store_true", help="compile even when a library of this source exists")
    b.add_argument("--timeout", type=float, default=None, help="seconds before the compiler is killed (default 900)")
    b.set_defaults(func=cmd_build)

    ip = sub.add_parser("import-par", help="SYMORO+/OpenSYMORO .par file -> robot .toml")
    ip.add_argument("file")
    ip.add_argument("-o", "--output", help="write the .toml here (default: stdout)")
    ip.add_argument("--force", action="store_true", help="overwrite an existing robot file (never the input)")
    ip.set_defaults(func=cmd_import_par)

    iu = sub.add_parser("import-urdf", help="URDF chain or tree -> robot .toml (MDH + nominal parameters)")
    iu.add_argument("file")
    iu.add_argument("--base", help="base link (default: the URDF root)")
    iu.add_argument("--tip", help="tip link (default: the end of the only chain; a URDF that branches is imported whole, as a tree)")
    iu.add_argument("--name", help="robot name (default: the URDF's)")
    iu.add_argument("--actuated", metavar="J1,J2,...",
                    help="a URDF with <loop_joint> elements: the actuated joints (default: those named by its "
                         "<transmission> elements); the other moving joints are passive")
    iu.add_argument("-o", "--output", help="write the .toml here (default: stdout)")
    iu.add_argument("--force", action="store_true", help="overwrite an existing robot file (never the input)")
    iu.set_defaults(func=cmd_import_urdf)

    eu = sub.add_parser("export-urdf", help="robot .toml (optionally with identified parameters) -> URDF")
    eu.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    eu.add_argument("--params", help="JSON result of `symoro-gen identify` (standard parameters it names are used)")
    eu.add_argument("--from", dest="from_result", metavar="RESULT.json",
                    help="JSON result of `symoro-gen identify`: every body from a physically consistent standard set "
                         "whose regrouping gives its base parameters (needs the 'physical' extra)")
    eu.add_argument("-o", "--output", help="write the URDF here (default: stdout); with --from also OUTPUT.json "
                    "(drive terms, how far each body moved from nominal)")
    eu.add_argument("--force", action="store_true", help=FORCE_HELP)
    eu.set_defaults(func=cmd_export_urdf)

    em = sub.add_parser("export-mjcf", help="robot .toml (optionally with an identification) -> MuJoCo MJCF")
    em.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    em.add_argument("--from", dest="from_result", metavar="RESULT.json",
                    help="JSON result of `symoro-gen identify` (as for export-urdf --from)")
    em.add_argument("--timestep", type=float, default=0.001, help="MuJoCo timestep [s] (default 0.001)")
    em.add_argument("-o", "--output", help="write the MJCF here (default: stdout); with --from also OUTPUT.json")
    em.add_argument("--force", action="store_true", help=FORCE_HELP)
    em.set_defaults(func=cmd_export_mjcf)

    ep = sub.add_parser("export-par", help="robot .toml -> SYMORO+/OpenSYMORO .par file")
    ep.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    ep.add_argument("-o", "--output", help="write the .par here (default: stdout)")
    ep.add_argument("--force", action="store_true", help=FORCE_HELP)
    ep.set_defaults(func=cmd_export_par)

    for extra in _EXTRA_COMMANDS:
        if command is None or _EXTRA_NAMES.get(extra) == command:
            extra(sub)
    for sp_ in sub.choices.values():  # also accepted after the command name
        opts = {o for a in sp_._actions for o in a.option_strings}
        if "--quiet" not in opts:
            sp_.add_argument("--quiet", "-q", action="store_true", default=argparse.SUPPRESS,
                             help="no progress bars, no chatter")
        if "--debug" not in opts:
            sp_.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                             help="show the traceback of an error")
    return p


def _identify_parser(sub):
    importlib.import_module("symoro_gen.commands.identify").add_parser(sub)


def _demo_parser(sub):
    d = sub.add_parser("demo", help="the main job on a built-in simulated example (LWR4 sensor-gain calibration)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--duration", type=float, default=20.0, help="seconds per simulated recording")
    d.set_defaults(func=lambda a: __import__("symoro_gen.demo", fromlist=["run_demo"]).run_demo(a))


def _diagnose_parser(sub):
    importlib.import_module("symoro_gen.commands.diagnose").add_parser(sub)


def _inspect_parser(sub):
    from .preprocessing.inspect import add_inspect_parser

    add_inspect_parser(sub)


def _excite_parser(sub):
    from .excite import add_excite_parser

    add_excite_parser(sub)


def _fleet_parser(sub):
    """``fleet`` (Dask and pyarrow are imported only when this command runs)."""
    from .fleet.cli import add_fleet_parser

    add_fleet_parser(sub)


_EXTRA_COMMANDS: list = [_identify_parser, _diagnose_parser, _inspect_parser, _demo_parser, _excite_parser,
                         _fleet_parser]
_EXTRA_NAMES = {_identify_parser: "identify", _diagnose_parser: "diagnose", _inspect_parser: "inspect",
                _demo_parser: "demo", _excite_parser: "excite", _fleet_parser: "fleet"}
_LIGHT_COMMANDS = ("generate", "build", "import-par", "import-urdf", "export-par", "export-urdf", "export-mjcf")


def _command_of(argv) -> str | None:
    """The sub-command named in ``argv`` (first word after the global flags), if any."""
    for a in argv:
        if a in ("--debug", "--quiet", "-q"):
            continue
        return a if not a.startswith("-") else None
    return None


def _check_options(args) -> None:
    """Option values the commands cannot use, caught before any work (one error per option)."""
    checks = (
        ("cutoff", "--cutoff", lambda v: v > 0, "must be a positive frequency in Hz"),
        ("decimate", "--decimate", lambda v: v >= 1, "must be an integer >= 1"),
        ("r_sigma", "--r-sigma", lambda v: v > 1, "must be > 1 (the ratio max %sigma / min %sigma)"),
        ("duration", "--duration", lambda v: v > 0, "must be a positive number of seconds"),
    )
    for attr, flag, ok, what in checks:
        v = getattr(args, attr, None)
        if v is not None and not ok(v):
            raise OptionError(f"{flag} {v:g}: {what}")


_OUTPUT_OPTIONS = ("output", "out", "json", "report", "plot", "plots")

#: the output options of the commands (attribute -> spelling), checked by :func:`check_command_outputs`
_OUTPUT_FLAGS = {"output": "-o/--output", "json": "--json", "report": "--report", "plot": "--plot"}
#: the options naming files a command reads (attribute -> spelling); DATA-like ones may be q=..,tau=.. specs
_INPUT_FLAGS = {"file": "FILE", "data": "DATA", "validate": "--validate", "loaded": "--loaded", "logs": "LOGS",
                "reference": "--reference", "format": "--format", "params": "--params", "from_result": "--from"}
_SPEC_INPUTS = ("data", "validate", "loaded")


def _robot_inputs(robot: str) -> list[tuple[str, str | os.PathLike[str] | None]]:
    """The robot file (and generated package folder) a ROBOT argument names."""
    p = Path(robot)
    if p.exists():
        return [("ROBOT", p)]
    from .description import robots_dir

    out: list[tuple[str, str | os.PathLike[str] | None]] = []
    cand = robots_dir() / f"{robot}.toml"
    if p.suffix != ".toml" and cand.is_file():
        out.append(("ROBOT", cand))
    pkg = generated_dir() / robot
    if p.suffix != ".toml" and (pkg / "manifest.json").is_file():
        out.append(("ROBOT", pkg))
    return out


def command_inputs(args) -> list[tuple[str, str | os.PathLike[str] | None]]:
    """``(option, path)`` of every file or folder the command of ``args`` reads."""
    cmd = getattr(args, "command", "")
    inputs: list[tuple[str, str | os.PathLike[str] | None]] = []
    if getattr(args, "robot", None) and cmd != "build":
        inputs += _robot_inputs(str(args.robot))
    for attr, flag in _INPUT_FLAGS.items():
        v = getattr(args, attr, None)
        if not v:
            continue
        items = v if isinstance(v, (list, tuple)) else [v]
        if attr == "logs" and getattr(args, "by", None):  # fleet: the log files its --by pattern takes
            from .fleet.files import discover

            inputs += [(flag, f.path) for f in discover(items, args.by)]
            continue
        for item in items:
            if attr in _SPEC_INPUTS:
                from .preprocessing.readers import parse_data_spec

                try:
                    files = list(parse_data_spec(item).files.values())
                except SymoroError:
                    files = [item]  # the command says what is wrong with it
                inputs += [(flag, f) for f in files]
            else:
                inputs.append((flag, item))
    return inputs


def command_outputs(args) -> dict[str, str | os.PathLike[str] | Target | None]:
    """Option -> path or :class:`~symoro_gen.atomic.Target` of every file the command of ``args`` writes
    (``generate`` checks its package folder itself)."""
    cmd = getattr(args, "command", "")
    outputs: dict[str, str | os.PathLike[str] | Target | None] = {}
    for attr, flag in _OUTPUT_FLAGS.items():
        v = getattr(args, attr, None)
        if not v:
            continue
        if attr == "report":
            from .report.document import report_targets

            outputs.update(report_targets(flag, v))
        elif attr == "output" and cmd in ("import-par", "import-urdf"):  # robot files: never without --force
            outputs[flag] = Target(Path(v), owner="never")
        else:
            outputs[flag] = v
    if cmd in ("export-urdf", "export-mjcf") and getattr(args, "output", None) and getattr(args, "from_result", None):
        outputs["-o/--output (its .json)"] = str(args.output) + ".json"
    if getattr(args, "plots", None):  # diagnose --plots DIR: written into; its diagnosis-*.png replaced or removed
        from .diagnostics.plots import existing_plots

        outputs["--plots"] = Target(Path(args.plots), owner="caller")
        outputs.update({f"--plots ({p.name})": p for p in existing_plots(args.plots)})
    return outputs


def check_command_outputs(args) -> None:
    """The rule of :func:`symoro_gen.atomic.check_outputs` for the command of ``args``, before any work:
    no output is an input, no two outputs are one file, an existing file is replaced only when
    symoro-gen wrote it or with ``--force``."""
    outputs = command_outputs(args)
    if outputs:
        check_outputs(outputs, command_inputs(args), force=bool(getattr(args, "force", False)))


def _os_error_message(exc: OSError, args) -> str:
    """``cannot write OUT: reason`` when the failure is about an output the user named."""
    names = [str(x) for x in (exc.filename, exc.filename2) if x is not None]
    for attr in _OUTPUT_OPTIONS:
        out = getattr(args, attr, None)
        if not out:
            continue
        po = Path(out).absolute()
        for fn in names:
            pf = Path(fn).absolute()
            if pf == po or po in pf.parents or pf in po.parents or (pf.parent == po.parent and po.name in pf.name):
                return f"cannot write {out}: {exc.strerror or exc}"
    reason = exc.strerror or str(exc)
    return f"{names[0]}: {reason}" if names else reason


_DOCS = "docs/"


def _default_hint(exc: BaseException, args) -> str:
    """A hint for errors that carry none."""
    cmd = getattr(args, "command", "") or ""
    text = str(exc)
    if isinstance(exc, RobotFileError):
        if cmd == "import-par":
            return f"the input must be a SYMORO+/OpenSYMORO .par file (geometric table Ant, Sigma, d, R, Alpha, Theta); see {_DOCS}tutorial-model.md"
        if cmd == "import-urdf":
            return (f"the URDF must hold a chain or tree of revolute, prismatic or fixed joints (--base/--tip pick it), "
                    f"closed loops as <loop_joint> with <transmission> or --actuated (see {_DOCS}robot-file.md)")
        if "no such robot" in text or "file not found" in text:
            return "give a robot name from robots/ (e.g. lwr4) or the path of a robot .toml file"
        return f"every problem is listed above; the robot-file format is described in {_DOCS}robot-file.md"
    if isinstance(exc, DataFileError):
        return (f"data files: CSV with header t,q1..qn,tau1..taun, NPZ/MAT arrays, or q=FILE,tau=FILE,dt=SECONDS "
                f"for split recordings; see {_DOCS}data-files.md")
    if isinstance(exc, OptionError):
        return f"see `symoro-gen {cmd} --help`"
    if isinstance(exc, ShapeError):
        return "the data do not match the robot: check its number of joints and the file's columns"
    if isinstance(exc, ModelError):
        return "(re)generate the model with `symoro-gen generate ROBOT`; see " + _DOCS + "generated-module.md"
    if isinstance(exc, IdentificationError):
        page = "tutorial-diagnosis.md" if cmd == "diagnose" else "tutorial-identification.md"
        return f"see `symoro-gen {cmd} --help` and {_DOCS}{page}"
    if isinstance(exc, OSError):
        return "check that the path exists, is the right kind (file or folder) and that its folder is writable"
    return f"check the options of `symoro-gen {cmd} --help`; --debug shows where it failed"


def _message(exc: BaseException, args) -> str:
    problems = getattr(exc, "problems", None)
    if problems and len(problems) == 1:
        return str(problems[0])  # one problem: one line
    if isinstance(exc, OSError):
        return _os_error_message(exc, args)
    if isinstance(exc, SymoroError):
        return str(exc)
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


def _format_warning(message, category, filename, lineno, line=None) -> str:
    """Warnings as ``symoro-gen: warning: ...`` lines (no source line of the library)."""
    return f"symoro-gen: warning: {message}\n"


def _report_error(exc: BaseException, args, internal: bool) -> None:
    close_all()
    if getattr(args, "debug", False):
        traceback.print_exception(exc, file=sys.stderr)
    if internal:
        print(f"symoro-gen: internal error: {type(exc).__name__}: {_message(exc, args)}", file=sys.stderr)
        print("hint: this is a bug in symoro-gen; rerun with --debug and report the traceback", file=sys.stderr)
        return
    print(f"symoro-gen: error: {_message(exc, args)}", file=sys.stderr)
    print(f"hint: {getattr(exc, 'hint', None) or _default_hint(exc, args)}", file=sys.stderr)


def _interrupted_by_ctypes(exc: BaseException) -> bool:
    """A Ctrl-C that lands while ctypes converts the arguments of a C call arrives wrapped in a
    ``ctypes.ArgumentError`` ("argument 3: KeyboardInterrupt: "): it is an interrupt, not a bug."""
    import ctypes

    return isinstance(exc, ctypes.ArgumentError) and "KeyboardInterrupt" in str(exc)


def main(argv=None) -> int:
    try:  # building the parser imports the command modules (scipy, sympy): a Ctrl-C there is clean too
        cmd = _command_of(sys.argv[1:] if argv is None else argv)
        light = cmd in _LIGHT_COMMANDS or cmd in _EXTRA_NAMES.values()
        parser = build_parser(cmd if light else None)
    except KeyboardInterrupt:
        print("symoro-gen: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.formatwarning = _format_warning
            _check_options(args)
            check_command_outputs(args)
            with progress_mode("off" if args.quiet else "auto"):
                status = int(args.func(args) or 0)
            sys.stdout.flush()
            return status
    except BrokenPipeError:  # the reader went away (`symoro-gen ... | head`): stop quietly
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        except (OSError, ValueError, AttributeError):  # stdout is not a real file (tests)
            pass
        return EXIT_BROKEN_PIPE
    except (SymoroError, OSError, ValueError, TypeError) as exc:
        # bad input: robot or data files, options, paths (ValueError/TypeError: the library's checks
        # of arguments it was handed)
        _report_error(exc, args, internal=False)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        close_all()
        print("symoro-gen: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - last resort: one line and a hint instead of a raw traceback
        if _interrupted_by_ctypes(exc):
            close_all()
            print("symoro-gen: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        _report_error(exc, args, internal=True)
        return EXIT_INTERNAL_ERROR


if __name__ == "__main__":
    sys.exit(main())
