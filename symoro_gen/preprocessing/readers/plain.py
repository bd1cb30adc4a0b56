"""The plain reading: a recording as it is, every problem of the file collected and raised together.

Problems (one :class:`~symoro_gen.errors.DataFileError` whose entries name the file, the column and the
rows; for text files the lines too): non-numeric or missing values, NaN/inf, absurd values, a column
count that does not match the robot, files of a split recording with different lengths, non-increasing
time, irregular time steps (deviating more than ``time_jitter_tol`` x the median step; gaps count) or a
change of sampling period, recordings too short to filter. Values that look like unit mix-ups give a
:class:`~.common.DataWarning` naming file and column (limits in :class:`~.common.DataChecks`). Nothing is
dropped: every row of the file is in the returned trajectory.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ...errors import DataFileError, Problem
from ..drive_chain import motor_to_joint
from ..trajectory import Trajectory
from .common import (
    BAD_VALUE_HINT,
    DEFAULT_CHECKS,
    TIME_HINT,
    DataChecks,
    RawColumns,
    check_time,
    check_values,
    time_conflict,
    unit_check_names,
    unit_checks,
    warn_data,
)

__all__ = ["plain_trajectory"]


def _raise_bad_values(probs: list[Problem]) -> None:
    if probs:
        bad_values = any("non-finite" in p.message or "absurd" in p.message for p in probs)
        raise DataFileError(probs, hint=BAD_VALUE_HINT if bad_values else None)


def _time_base(raw: RawColumns, dt: float | None, checks: DataChecks, probs: list[Problem],
               dt_overrides_time: bool = False) -> tuple[np.ndarray, dict, bool]:
    """(t, time statistics, t made from dt): the time column, checked, or ``dt``; both given is an error
    unless ``dt_overrides_time`` (then the time column is ignored, with a warning)."""
    N = raw.n_rows
    if "t" in raw.cols and dt is not None:
        if not dt_overrides_time:
            raise DataFileError([time_conflict(raw.cols["t"].file, raw.cols["t"].names[0], dt)])
        warn_data(f"{raw.cols['t'].file}, column {raw.cols['t'].names[0]}: ignored, the time base is dt = {dt:g} s "
                  "(--dt-overrides-time)")
        del raw.cols["t"]
    if "t" in raw.cols:
        t = raw.cols["t"].values[:, 0]
        return t, check_time(t, raw.cols["t"], checks.time_jitter_tol, probs), False
    if not (dt is not None and dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive number, got {dt!r}")
    return np.arange(N) * float(dt), {"dt_median": float(dt), "dt_max_rel_jitter": 0.0}, True


def plain_trajectory(raw: RawColumns, probs: list[Problem], *, n: int, dt: float | None, loaded: bool,
                     drive_chain=None, joint_types: Sequence[int] | None = None,
                     checks: DataChecks = DEFAULT_CHECKS, dt_overrides_time: bool = False) -> Trajectory:
    """The trajectory of columns read by the plain reading (``probs``: the reader's problems so far).

    Raises
    ------
    DataFileError
        Every problem found (file, column, rows).
    """
    check_values(raw, probs)
    _raise_bad_values(probs)
    N = raw.n_rows
    t, tinfo, t_from_dt = _time_base(raw, dt, checks, probs, dt_overrides_time)
    time_probs = bool(probs)
    if checks.min_samples > N:
        probs.append(Problem(raw.source, f"rows 1-{N}", "", f"too short to filter: {N} samples, at least "
                             f"{checks.min_samples} needed"))
    if probs:
        raise DataFileError(probs, hint=TIME_HINT if time_probs else None)
    q = raw.cols["q"].values
    tau = raw.cols["tau"].values
    dq = raw.cols["dq"].values if "dq" in raw.cols else None
    ddq = raw.cols["ddq"].values if "ddq" in raw.cols else None
    if drive_chain is not None:
        if len(drive_chain.ratios) != n:
            raise ValueError(f"drive chain has {len(drive_chain.ratios)} joints, the robot {n}")
        q, tau, dq, ddq = motor_to_joint(drive_chain, q, tau, dq, ddq)
    src_files = {"t": raw.cols["t"].file if "t" in raw.cols else raw.source,
                 "q": raw.cols["q"].file, "tau": raw.cols["tau"].file}
    for msg in unit_checks(src_files, t, q, tau, joint_types, checks, unit_check_names(raw, "q", drive_chain)):
        warn_data(msg)
    meta = {
        "format": raw.fmt,
        "files": {r: c.file for r, c in raw.cols.items()},
        "columns": {r: list(c.names) for r, c in raw.cols.items()},
        "unused": list(raw.unused),
        "drive_chain": drive_chain is not None,
        "t_from_dt": t_from_dt,
        **tinfo,
    }
    if raw.rows is not None:
        meta["rows"] = raw.rows
    return Trajectory(t=t, q=q, tau=tau, dq=dq, ddq=ddq, source=raw.source, loaded=bool(loaded), meta=meta)
