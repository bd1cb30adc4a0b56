"""``symoro-gen demo``: the main job on a built-in simulated example (LWR4 sensor-gain calibration), a leaf over
:func:`symoro_gen.demo.run_demo`."""
from __future__ import annotations

from ..demo import run_demo

__all__ = ["add_parser", "run"]


def run(args) -> int:
    """Run the demonstration; 0 on success."""
    return int(run_demo(args) or 0)


def add_parser(sub) -> None:
    """Register ``demo``."""
    d = sub.add_parser("demo", help="the main job on a built-in simulated example (LWR4 sensor-gain calibration)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--duration", type=float, default=20.0, help="seconds per simulated recording")
    d.set_defaults(func=run)
