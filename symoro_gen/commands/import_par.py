"""``symoro-gen import-par FILE``: a SYMORO+/OpenSYMORO ``.par`` file -> robot ``.toml`` (standard output or
``-o``, validated, never over an existing robot file without ``--force``)."""
from __future__ import annotations

from ..description.par import import_par, write_robot_toml
from .common import add_output_options, emit_text

__all__ = ["add_parser", "run"]


def _write_robot_file(text: str, path, force: bool) -> None:
    write_robot_toml(text, path, overwrite=force)


def run(args) -> int:
    """Convert the file; 0 on success."""
    return emit_text(import_par(args.file), args, write=_write_robot_file)


def add_parser(sub) -> None:
    """Register ``import-par``."""
    ip = sub.add_parser("import-par", help="SYMORO+/OpenSYMORO .par file -> robot .toml")
    ip.add_argument("file")
    add_output_options(ip, "write the .toml here (default: stdout)",
                       "overwrite an existing robot file (never the input)")
    ip.set_defaults(func=run)
