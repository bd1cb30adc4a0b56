"""``symoro-gen import-urdf FILE``: a URDF chain or tree (closed loops as ``<loop_joint>``) -> robot ``.toml`` in
MDH notation with the nominal parameters (standard output or ``-o``, never over a robot file without
``--force``)."""
from __future__ import annotations

from ..description.par import write_robot_toml
from ..description.urdf import import_urdf
from .common import add_output_options, emit_text

__all__ = ["add_parser", "run"]


def _write_robot_file(text: str, path, force: bool) -> None:
    write_robot_toml(text, path, overwrite=force)


def run(args) -> int:
    """Convert the URDF; 0 on success."""
    actuated = [a.strip() for a in args.actuated.split(",") if a.strip()] if args.actuated else None
    text = import_urdf(args.file, base=args.base, tip=args.tip, name=args.name, actuated=actuated,
                       floating=args.floating)
    return emit_text(text, args, write=_write_robot_file)


def add_parser(sub) -> None:
    """Register ``import-urdf``."""
    iu = sub.add_parser("import-urdf", help="URDF chain or tree -> robot .toml (MDH + nominal parameters)")
    iu.add_argument("file")
    iu.add_argument("--base", help="base link (default: the URDF root)")
    iu.add_argument("--tip", help="tip link (default: the end of the only chain; a URDF that branches is imported "
                    "whole, as a tree)")
    iu.add_argument("--name", help="robot name (default: the URDF's)")
    iu.add_argument("--actuated", metavar="J1,J2,...",
                    help="a URDF with <loop_joint> elements: the actuated joints (default: those named by its "
                         "<transmission> elements); the other moving joints are passive")
    iu.add_argument("--floating", action="store_true", default=None,
                    help="the base link (default: the root) is a free body, base = \"floating\" (default: only when a "
                         "floating joint carries the root's only child, which becomes the base; docs/floating-base.md)")
    add_output_options(iu, "write the .toml here (default: stdout)",
                       "overwrite an existing robot file (never the input)")
    iu.set_defaults(func=run)
