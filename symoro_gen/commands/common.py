"""Argument helpers the commands share (no command module imports another); light (no SymPy, no SciPy), as
the light commands import it."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..atomic import FORCE_HELP, write_output_text
from ..params import check_payload, parse_payload

if TYPE_CHECKING:  # the export workflows load SymPy: this module stays light
    from ..workflows.export import ExportResults

__all__ = ["ROBOT_HELP", "add_output_options", "emit_text", "parse_payload", "payload_values",
           "write_export"]

ROBOT_HELP = "robot name in robots/ or path to a robot .toml file"


def payload_values(items: Iterable[str] | None, names: Sequence[str]) -> dict[str, float]:
    """``--payload NAME=VALUE ...`` parsed and each name checked against the robot's payload parameters."""
    return check_payload(parse_payload(items), names)


def add_output_options(p: argparse.ArgumentParser, output_help: str, force_help: str = FORCE_HELP) -> None:
    """``-o/--output`` (default: standard output) and ``--force`` of the commands that write one text."""
    p.add_argument("-o", "--output", help=output_help)
    p.add_argument("--force", action="store_true", help=force_help)


def emit_text(text: str, args, write: Callable[[str, Path, bool], object] | None = None) -> int:
    """Write a command's text to ``--output`` (atomically; with ``write(text, path, force)`` when given, e.g. a
    robot file validated and never overwritten without ``--force``; otherwise only over a file symoro-gen
    wrote, see :mod:`symoro_gen.atomic`) or to standard output; 0."""
    if not args.output:
        sys.stdout.write(text)
        return 0
    if write is not None:
        write(text, Path(args.output), bool(args.force))
    else:
        write_output_text(Path(args.output), text, force=args.force, label="-o/--output")
    if not args.quiet:
        print(f"wrote {args.output}")
    return 0


def write_export(res: ExportResults, args) -> int:
    """An export's output: its notes about changed links on standard error, its text to ``--output`` (and the
    sidecar to ``OUTPUT.json``) or to standard output; 0."""
    for msg in res.notes:
        print(f"note: {msg}", file=sys.stderr)
    if not args.output:
        return emit_text(res.text, args)
    written = res.write(args.output, force=bool(args.force))
    if not args.quiet:
        print(f"wrote {args.output}")
        for path in written[1:]:
            print(f"wrote {path}")
    return 0
