"""``fleet``: the logs of many robots of one model -> per-day, per-robot and fleet estimates and drift flags.

The workflow of ``symoro-gen fleet`` as a library call::

    res = symoro_gen.fleet("scara", ["fleet_logs"], by="{robot}/{day}.parquet", scheduler="threads:2")
    res.summary(); res.to_dict()["flagged"]; res.report("fleet.html"); res.plot()

One Dask task per log, exact TSQR reductions per robot-day, robot and fleet, IDIM-WLS on each, and the
robots whose parameters drift away from the fleet flagged (level and trend tests, Holm- or BH-corrected;
docs/fleet.md). The options (:class:`FleetOptions`) are the ones the engine takes
(:func:`symoro_gen.fleet.engine.identify_fleet`); the results object is the engine's
:class:`~symoro_gen.fleet.engine.FleetResult`, a :class:`~symoro_gen.workflows.base.Results`.
"""
from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterable
from typing import Any

from ..description.model import RobotDescription
from ..errors import OptionError
from ..fleet.engine import FleetResult, identify_fleet
from ..fleet.options import FleetOptions

__all__ = ["FleetOptions", "FleetResults", "fleet"]

#: the results of :func:`fleet` (the engine's result type)
FleetResults = FleetResult


def fleet(robot, logs: str | os.PathLike[str] | Iterable[str | os.PathLike[str]], *, by: str,
          options: FleetOptions | None = None, client=None, **kwargs: Any) -> FleetResults:
    """Identify every robot of a fleet per day from its logs, pool the fleet and flag the robots that drift.

    Parameters
    ----------
    robot : str, path, RobotDescription or model
        A robot name (``robots/``, ``generated/``), a robot file, a description read from a file, a generated
        package folder or a loaded model.
    logs : path or list of paths
        Log files, globs or folders (CSV, NPZ, MAT, Parquet).
    by : str
        How a path names its robot and day, matched against its end, e.g. ``"{robot}/{day}.parquet"``.
    options : FleetOptions, optional
        All options at once; or give them by name (``scheduler="threads:2"``, ``alpha=0.05``...): an unknown
        name raises :class:`~symoro_gen.errors.OptionError` naming the nearest valid one.
    client : distributed.Client, optional
        An open Dask client to run on (not closed here; ``scheduler`` is then not used).

    Returns
    -------
    FleetResults
    """
    if options is None:
        opts = FleetOptions.create("fleet", **kwargs)
    elif kwargs:
        raise OptionError("fleet: give the options either as options= or by name, not both")
    else:
        opts = options
    if isinstance(robot, RobotDescription):
        if not robot.file:
            raise OptionError(f"robot {robot.name!r}: a description without its robot file; give the robot as a "
                              "name or a robot file")
        robot = robot.file
    items = [logs] if isinstance(logs, (str, os.PathLike)) else list(logs)
    return identify_fleet(robot, [os.fspath(x) for x in items], by, opts, client=client)


def options_field_names() -> tuple[str, ...]:
    """The option names of :func:`fleet` (its keywords besides robot, logs, by, options, client)."""
    return tuple(f.name for f in dataclasses.fields(FleetOptions))
