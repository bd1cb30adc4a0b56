"""``inspect``: recordings → what they can and cannot give, before identifying.

The workflow of ``symoro-gen inspect`` as a library call::

    res = symoro_gen.inspect("lwr4", ["a.csv"])
    res.usable; res.summary(); res.to_dict()["unidentifiable"]; res.report("a.html"); res.plot()

Per file the sampling, jitter, gaps and dropped rows; per experiment and joint the standstill and saturation
shares and the papers' filter rule ([GB-gains] eq. 14-16); for all experiments cond(W) and the base parameters
whose predicted relative standard deviation (Gautier 1990; [LWR4-TLS] eq. 11) is too large to identify
(:mod:`symoro_gen.preprocessing.inspect`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import OptionError
from ..model import IdentificationModel
from ..preprocessing.inspect import Inspection, inspect_recordings, inspection_report, signal_figures
from ..preprocessing.readers import LogFormat
from ..preprocessing.trajectory import Trajectory
from ..report.document import write_report_files
from .base import (
    SCHEMA_VERSION,
    DataLike,
    Options,
    Results,
    as_trajectories,
    listed,
    provenance,
    refuse_repeated_recordings,
    resolve_robot,
)

__all__ = ["InspectOptions", "InspectResults", "inspect"]


@dataclass(frozen=True)
class InspectOptions(Options):
    """Every option of ``inspect`` (the command's flags without their dashes).

    Attributes
    ----------
    cutoff, decimate : optional
        Butterworth cut-off of q [Hz] and decimation factor (default: the papers' rules).
    data_format : LogFormat, optional
        How the files are read (columns, time base, units, resampling: docs/data-files.md).
    """

    cutoff: float | None = None
    decimate: int | None = None
    data_format: LogFormat = field(default_factory=LogFormat)

    def __post_init__(self) -> None:
        if self.cutoff is not None and not self.cutoff > 0:
            raise OptionError(f"--cutoff {self.cutoff:g}: must be a positive frequency in Hz")
        if self.decimate is not None and self.decimate < 1:
            raise OptionError(f"--decimate {self.decimate}: must be an integer >= 1")
        if self.data_format is None:
            object.__setattr__(self, "data_format", LogFormat())


@dataclass(frozen=True, eq=False)
class InspectResults(Results):
    """What ``inspect`` found (see :meth:`to_dict` for the JSON contract, docs/json-output.md)."""

    command = "inspect"

    robot: Any
    model: IdentificationModel
    options: InspectOptions
    inspection: Inspection
    trajectories: tuple[Trajectory, ...]
    inputs: tuple[Any, ...] = ()

    @property
    def usable(self) -> bool:
        """False when the recordings cannot identify the robot (the reasons in ``inspection.errors``)."""
        return self.inspection.usable

    def to_dict(self) -> dict:
        """Exactly the JSON of ``symoro-gen inspect --json`` (its ``generator`` mark first)."""
        return {"generator": "symoro-gen inspect", "schema_version": SCHEMA_VERSION, "robot": self.robot.name,
                **self.inspection.to_dict(), "provenance": provenance(self.options, self.inputs)}

    def summary(self) -> str:
        """Exactly the text ``symoro-gen inspect`` prints."""
        return self.inspection.summary()

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """The tables and one plot per joint (q and tau against t), ``.html`` or ``.md``."""
        self.check_output(path, force=force, label="report", report=True)
        write_report_files(inspection_report(self.inspection, self.trajectories, self.robot.name), path, force=force)
        return Path(path)

    def figures(self) -> list:
        """One matplotlib figure per experiment and joint (q and tau against t)."""
        return [fig for _, fig, _ in signal_figures(self.trajectories)]


def inspect(robot, data: DataLike, *, options: InspectOptions | None = None, **kwargs: Any) -> InspectResults:
    """What recordings can give before identifying: sampling, gaps, bad rows, standstill, saturation, the filter
    rule, cond(W), the parameters they cannot identify.

    Parameters
    ----------
    robot : str, path, RobotDescription or model
        A robot name (``robots/``), a robot file, a description or a loaded model.
    data : path, Trajectory, (t, q, tau) arrays, or a list of them
    options : InspectOptions, optional
        All options at once; or give them by name (``cutoff=10``, ``data_format=LogFormat(...)``): an unknown
        name raises :class:`~symoro_gen.errors.OptionError` naming the nearest valid one.

    Returns
    -------
    InspectResults
        ``usable`` is False (and ``inspection.errors`` says why) when the data cannot identify the robot.
    """
    opts = InspectOptions.resolve("inspect", options, kwargs, keywords=("options",))
    desc, model = resolve_robot(robot)
    items = listed(data)
    if not items:
        raise OptionError("inspect: no data given")
    refuse_repeated_recordings(items)
    trajs, reports = as_trajectories(list(items), opts.data_format, desc, loaded=False)
    insp = inspect_recordings(model, trajs, reports, cutoff_hz=opts.cutoff, n_d=opts.decimate)
    return InspectResults(robot=desc, model=model, options=opts, inspection=insp, trajectories=tuple(trajs),
                          inputs=items)
