"""``symoro-gen export-par ROBOT``: a robot file -> SYMORO+/OpenSYMORO ``.par`` (a leaf over
:func:`symoro_gen.workflows.export.export_par`)."""
from __future__ import annotations

from ..workflows.export import export_par
from .common import ROBOT_HELP, add_output_options, write_export

__all__ = ["add_parser", "run"]


def run(args) -> int:
    """Export the robot; 0 on success."""
    return write_export(export_par(args.robot), args)


def add_parser(sub) -> None:
    """Register ``export-par``."""
    ep = sub.add_parser("export-par", help="robot .toml -> SYMORO+/OpenSYMORO .par file")
    ep.add_argument("robot", help=ROBOT_HELP)
    add_output_options(ep, "write the .par here (default: stdout)")
    ep.set_defaults(func=run)
