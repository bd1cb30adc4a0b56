"""The ``symoro-gen`` command.

Errors meant for users print as one line of what is wrong and where (one line per problem when a
file has several), then a ``hint:`` line, and exit with status 2; ``--debug`` also prints the
traceback. Unexpected failures (bugs) exit with status 1. Progress bars go to standard error when
it is a terminal (``SYMORO_PROGRESS=1`` forces them, ``=0`` or ``--quiet`` hides them).
"""
from __future__ import annotations

import argparse
import importlib
import math
import os
import sys
import traceback
import warnings
from pathlib import Path

from .atomic import Target, check_outputs
from .errors import (
    DataFileError,
    IdentificationError,
    ModelError,
    OptionError,
    RobotFileError,
    ShapeError,
    SymoroError,
)
from .loader import generated_dir
from .progress import close_all, progress_mode

# The commands live in symoro_gen.commands (one leaf each) and are imported by build_parser only for the
# command about to run: `symoro-gen --help` aside, a light command (build, the imports and exports) starts
# without the other commands' stacks (identification, diagnostics, preprocessing: scipy).

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # as a shell reports a process killed by SIGPIPE


def _leaf(module: str):
    """The registration of a command whose module is ``symoro_gen.commands.<module>`` (a leaf)."""
    def register(sub) -> None:
        importlib.import_module(f"symoro_gen.commands.{module}").add_parser(sub)

    register.__name__ = f"_{module}_parser"
    return register


#: every sub-command, in the order of ``symoro-gen --help``: its registration, which imports its module (the
#: leaves of symoro_gen.commands, by importlib) only when the command is about to run or the full help is asked
_COMMANDS: dict = {
    "generate": _leaf("generate"), "build": _leaf("build"), "import-par": _leaf("import_par"),
    "import-urdf": _leaf("import_urdf"), "export-urdf": _leaf("export_urdf"), "export-mjcf": _leaf("export_mjcf"),
    "export-par": _leaf("export_par"), "identify": _leaf("identify"), "diagnose": _leaf("diagnose"),
    "inspect": _leaf("inspect"), "demo": _leaf("demo"), "excite": _leaf("excite"),
    "fleet": _leaf("fleet"),  # Dask and pyarrow are imported only when it runs
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; with ``command`` (the sub-command about to run) only that command is registered
    (the others' modules are not imported), which makes a light command start in well under a second."""
    p = argparse.ArgumentParser(prog="symoro-gen", description=__doc__.splitlines()[0])
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress, no chatter")
    sub = p.add_subparsers(dest="command", required=True)
    for name, register in _COMMANDS.items():
        if command is None or name == command:
            register(sub)
    for sp_ in sub.choices.values():  # also accepted after the command name
        opts = {o for a in sp_._actions for o in a.option_strings}
        if "--quiet" not in opts:
            sp_.add_argument("--quiet", "-q", action="store_true", default=argparse.SUPPRESS,
                             help="no progress bars, no chatter")
        if "--debug" not in opts:
            sp_.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                             help="show the traceback of an error")
    return p




def _command_of(argv) -> str | None:
    """The sub-command named in ``argv`` (first word after the global flags), if any."""
    for a in argv:
        if a in ("--debug", "--quiet", "-q"):
            continue
        return a if not a.startswith("-") else None
    return None


#: the largest magnitude of a number given as an option: no time, rate, frequency, gain, torque or length of a
#: robot comes near it, and beyond it the products and squares the commands form leave double precision
MAX_OPTION_MAGNITUDE = 1e12


def _check_options(args) -> None:
    """Option values the commands cannot use, caught before any work (one error per option)."""
    checks = (
        ("cutoff", "--cutoff", lambda v: v > 0, "must be a positive frequency in Hz"),
        ("decimate", "--decimate", lambda v: v >= 1, "must be an integer >= 1"),
        ("r_sigma", "--r-sigma", lambda v: v > 1, "must be > 1 (the ratio max %sigma / min %sigma)"),
        ("duration", "--duration", lambda v: v > 0, "must be a positive number of seconds"),
        ("timestep", "--timestep", lambda v: v > 0, "must be a positive number of seconds (MuJoCo's step)"),
    )
    for attr, v in sorted(vars(args).items()):  # every number given: finite and of a magnitude a quantity can have
        for x in (v if isinstance(v, (list, tuple)) else [v]):
            if isinstance(x, float) and not (math.isfinite(x) and abs(x) <= MAX_OPTION_MAGNITUDE):
                raise OptionError(f"--{attr.replace('_', '-')} {x:g}: not a usable number (finite, |value| <= "
                                  f"{MAX_OPTION_MAGNITUDE:g})")
    for attr, flag, ok, what in checks:
        v = getattr(args, attr, None)
        if v is not None and not ok(v):
            raise OptionError(f"{flag} {v:g}: {what}")


_OUTPUT_OPTIONS = ("output", "out", "json", "report", "plot", "plots", "robot_out")

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
    if getattr(args, "robot_out", None):  # identify -o: a robot file, never replaced without --force
        outputs["-o/--robot-out"] = Target(Path(args.robot_out), owner="never")
    if cmd in ("export-urdf", "export-mjcf") and getattr(args, "output", None) and getattr(args, "from_result", None):
        outputs["-o/--output (its .json)"] = str(args.output) + ".json"
    if getattr(args, "plots", None):  # diagnose --plots DIR: written into; its diagnosis-*.png replaced or removed
        from .diagnostics.plots import existing_plots

        outputs["--plots"] = Target(Path(args.plots), owner="caller", into=True)
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
        parser = build_parser(cmd if cmd in _COMMANDS else None)
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
