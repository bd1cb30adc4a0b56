"""Fleet identification: many robots of one model, one log per robot and day, identified on
Dask distributed with exact TSQR reductions, pooled into a fleet model, and the robots whose parameters
drift away from the fleet flagged (random-effects distance and trend over days, Holm-corrected).

Needs the ``fleet`` extra (``dask[distributed]``, ``pyarrow``). See docs/fleet.md.

The package is also the ``fleet`` workflow: ``symoro_gen.fleet(robot, logs, by=...)`` calls
:func:`symoro_gen.workflows.fleet.fleet` (so that the library's ``symoro_gen.fleet`` is both this package and the
workflow, whichever was imported first).

The names below are imported on first use (PEP 562): a Dask worker unpickling a task of
:mod:`symoro_gen.fleet.kernel` imports this package first, and must not pay for the engine's imports
(statistics, the closed-loop diagnosis, the robot-file parser and its SymPy), which only the client needs.
"""
from __future__ import annotations

import importlib
import inspect
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .engine import Estimate, FleetResult, identify_fleet, open_client
    from .files import FleetError, LogFile, compile_pattern, discover, read_log, write_parquet
    from .kernel import Partial, merge_accumulators, merge_partials, process_file
    from .options import DEFAULT_ALPHA, FleetOptions
    from .simulate import Drift, FleetTruth, simulate_fleet

_WHERE = {
    "DEFAULT_ALPHA": "options", "FleetOptions": "options",
    "Estimate": "engine", "FleetResult": "engine", "identify_fleet": "engine", "open_client": "engine",
    "FleetError": "files", "LogFile": "files", "compile_pattern": "files", "discover": "files",
    "read_log": "files", "write_parquet": "files",
    "Partial": "kernel", "merge_accumulators": "kernel", "merge_partials": "kernel", "process_file": "kernel",
    "Drift": "simulate", "FleetTruth": "simulate", "simulate_fleet": "simulate",
}

__all__ = ["DEFAULT_ALPHA", "Drift", "Estimate", "FleetError", "FleetOptions", "FleetResult", "FleetTruth", "LogFile",
           "Partial", "compile_pattern", "discover", "identify_fleet", "merge_accumulators", "merge_partials", "open_client",
           "process_file", "read_log", "simulate_fleet", "write_parquet"]


def __getattr__(name: str) -> Any:
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{mod}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _FleetPackage(types.ModuleType):
    """This package, callable as the ``fleet`` workflow."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """``symoro_gen.fleet(robot, logs, by=..., **options)``: :func:`symoro_gen.workflows.fleet.fleet`."""
        return importlib.import_module("symoro_gen.workflows.fleet").fleet(*args, **kwargs)

    @property
    def __signature__(self) -> inspect.Signature:
        """The workflow's own signature (its named options), for :func:`inspect.signature`, ``help`` and IDEs."""
        return inspect.signature(importlib.import_module("symoro_gen.workflows.fleet").fleet)


sys.modules[__name__].__class__ = _FleetPackage
