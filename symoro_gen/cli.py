"""The ``symoro-gen`` command.

Errors meant for users print as one line of what is wrong and where, plus a hint, and
exit with status 2; ``--debug`` shows the traceback instead.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import SymoroError


def _progress(quiet: bool):
    """A per-stage progress callback (tqdm when available and on a TTY), or None."""
    if quiet or not sys.stderr.isatty():
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    bar = tqdm(desc="newton-euler", unit="link", leave=False)

    def cb(stage, j):
        bar.set_description(stage)
        bar.update(1)

    return cb


def cmd_generate(args) -> int:
    from .description import load_robot
    from .emit.package import emit_robot

    robot = load_robot(args.robot)
    out = Path(args.out) if args.out else Path(__file__).resolve().parents[1] / "generated"
    m = emit_robot(robot, out, progress=_progress(args.quiet))
    if not args.quiet:
        print(
            f"{m.robot}: {m.n_standard} standard -> {m.n_base} base parameters; base regressor "
            f"{m.base_ops.mul} mul, {m.base_ops.div} div, {m.base_ops.add} add -> {m.path}"
        )
    return 0


def cmd_import_par(args) -> int:
    from .description.par import import_par, write_robot_toml

    text = import_par(args.file)
    if args.output:
        write_robot_toml(text, args.output, overwrite=args.force)
        if not args.quiet:
            print(f"wrote {args.output}")
    else:
        sys.stdout.write(text)
    return 0


def cmd_export_par(args) -> int:
    from .description import load_robot
    from .description.par import export_par

    text = export_par(load_robot(args.robot))
    if args.output:
        from .emit.package import write_text_atomic

        write_text_atomic(Path(args.output), text)
    else:
        sys.stdout.write(text)
    return 0


def cmd_import_urdf(args) -> int:
    from .description.par import write_robot_toml
    from .description.urdf import import_urdf

    text = import_urdf(args.file, base=args.base, tip=args.tip, name=args.name)
    if args.output:
        write_robot_toml(text, args.output, overwrite=args.force)
        if not args.quiet:
            print(f"wrote {args.output}")
    else:
        sys.stdout.write(text)
    return 0


def cmd_export_urdf(args) -> int:
    import json

    from .description import load_robot
    from .description.urdf_export import export_urdf
    from .errors import ModelError

    robot = load_robot(args.robot)
    params = None
    if args.params:
        try:
            d = json.loads(Path(args.params).read_text())
            p = d["parameters"]
            params = {n: v for n, v in zip(p["names"], p["values"]) if v is not None}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ModelError(f"{args.params}: not a result of `symoro-gen identify` ({exc})") from None
    text = export_urdf(robot, params=params)
    if args.output:
        from .emit.package import write_text_atomic

        write_text_atomic(Path(args.output), text)
    else:
        sys.stdout.write(text)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="symoro-gen", description=__doc__.splitlines()[0])
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress, no chatter")
    sub = p.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="MDH robot file -> generated/<robot>/ (NumPy + CasADi regressors)")
    g.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    g.add_argument("--out", help="output folder (default: generated/ of the repository)")
    g.set_defaults(func=cmd_generate)

    ip = sub.add_parser("import-par", help="SYMORO+/OpenSYMORO .par file -> robot .toml")
    ip.add_argument("file")
    ip.add_argument("-o", "--output", help="write the .toml here (default: stdout)")
    ip.add_argument("--force", action="store_true", help="overwrite an existing output file")
    ip.set_defaults(func=cmd_import_par)

    iu = sub.add_parser("import-urdf", help="serial chain of a URDF -> robot .toml (MDH + nominal parameters)")
    iu.add_argument("file")
    iu.add_argument("--base", help="base link (default: the URDF root)")
    iu.add_argument("--tip", help="tip link (default: the end of the only chain)")
    iu.add_argument("--name", help="robot name (default: the URDF's)")
    iu.add_argument("-o", "--output", help="write the .toml here (default: stdout)")
    iu.add_argument("--force", action="store_true", help="overwrite an existing output file")
    iu.set_defaults(func=cmd_import_urdf)

    eu = sub.add_parser("export-urdf", help="robot .toml (optionally with identified parameters) -> URDF")
    eu.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    eu.add_argument("--params", help="JSON result of `symoro-gen identify` (standard parameters it names are used)")
    eu.add_argument("-o", "--output", help="write the URDF here (default: stdout)")
    eu.set_defaults(func=cmd_export_urdf)

    ep = sub.add_parser("export-par", help="robot .toml -> SYMORO+/OpenSYMORO .par file")
    ep.add_argument("robot", help="robot name in robots/ or path to a robot .toml file")
    ep.add_argument("-o", "--output", help="write the .par here (default: stdout)")
    ep.set_defaults(func=cmd_export_par)

    for extra in _EXTRA_COMMANDS:
        extra(sub)
    return p


def _identify_parser(sub):
    from .identification.cli import add_identify_parser

    add_identify_parser(sub)


def _demo_parser(sub):
    d = sub.add_parser("demo", help="the main job on a built-in simulated example (LWR4 sensor-gain calibration)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--duration", type=float, default=20.0, help="seconds per simulated recording")
    d.set_defaults(func=lambda a: __import__("symoro_gen.demo", fromlist=["run_demo"]).run_demo(a))


def _diagnose_parser(sub):
    try:
        from .diagnostics.cli import add_diagnose_parser
    except ImportError:
        return
    add_diagnose_parser(sub)


_EXTRA_COMMANDS: list = [_identify_parser, _diagnose_parser, _demo_parser]


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except SymoroError as exc:
        if args.debug:
            raise
        msg = str(exc)
        print(f"symoro-gen: error: {msg}", file=sys.stderr)
        hint = getattr(exc, "hint", None)
        if hint:
            print(f"hint: {hint}", file=sys.stderr)
        return 2
    except (FileNotFoundError, PermissionError, IsADirectoryError) as exc:
        if args.debug:
            raise
        print(f"symoro-gen: error: {exc.strerror}: {exc.filename}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
