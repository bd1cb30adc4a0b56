"""``symoro-gen export-urdf ROBOT``: a robot file (optionally with an identification) -> URDF.

A leaf over :func:`symoro_gen.workflows.export.export_urdf`: the notes about changed links go to standard
error, the text to ``-o`` (with ``--from`` also ``OUTPUT.json``, the sidecar) or standard output.
"""
from __future__ import annotations

from ..workflows.export import export_urdf
from .common import ROBOT_HELP, add_output_options, write_export

__all__ = ["add_parser", "run"]


def run(args) -> int:
    """Export the robot; 0 on success."""
    return write_export(export_urdf(args.robot, params=args.params, from_result=args.from_result), args)


def add_parser(sub) -> None:
    """Register ``export-urdf``."""
    eu = sub.add_parser("export-urdf", help="robot .toml (optionally with identified parameters) -> URDF")
    eu.add_argument("robot", help=ROBOT_HELP)
    eu.add_argument("--params", help="JSON result of `symoro-gen identify` (standard parameters it names are used)")
    eu.add_argument("--from", dest="from_result", metavar="RESULT.json",
                    help="JSON result of `symoro-gen identify`: every body from a physically consistent standard set "
                         "whose regrouping gives its base parameters (needs the 'physical' extra)")
    add_output_options(eu, "write the URDF here (default: stdout); with --from also OUTPUT.json (drive terms, how "
                       "far each body moved from nominal)")
    eu.set_defaults(func=run)
