"""``symoro-gen export-mjcf ROBOT``: a robot file (optionally with an identification) -> MuJoCo MJCF.

A leaf over :func:`symoro_gen.workflows.export.export_mjcf` (notes on standard error, the text to ``-o``, with
``--from`` also ``OUTPUT.json``, or to standard output).
"""
from __future__ import annotations

from ..workflows.export import export_mjcf
from .common import ROBOT_HELP, add_output_options, write_export

__all__ = ["add_parser", "run"]


def run(args) -> int:
    """Export the robot; 0 on success."""
    return write_export(export_mjcf(args.robot, from_result=args.from_result, timestep=args.timestep), args)


def add_parser(sub) -> None:
    """Register ``export-mjcf``."""
    em = sub.add_parser("export-mjcf", help="robot .toml (optionally with an identification) -> MuJoCo MJCF")
    em.add_argument("robot", help=ROBOT_HELP)
    em.add_argument("--from", dest="from_result", metavar="RESULT.json",
                    help="JSON result of `symoro-gen identify` (as for export-urdf --from)")
    em.add_argument("--timestep", type=float, default=0.001, help="MuJoCo timestep [s] (default 0.001)")
    add_output_options(em, "write the MJCF here (default: stdout); with --from also OUTPUT.json")
    em.set_defaults(func=run)
