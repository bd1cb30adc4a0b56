"""Controller logs as they come: the columns of a file read with a :class:`~.options.LogFormat` (the data
options), and the :class:`~.options.LoadReport` of what was done.

Order of the operations (each one echoed in the report): rows with bad values dropped
(``drop_bad_rows``), degrees -> radians (``deg``: the revolute joints only, by the robot's joint types; with
a drive chain every motor-side position, all angles), ``tau_scale``, resampling and splitting at gaps, the robot's
drive chain (motor -> joint side), then ``q_link`` replaces ``q``.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.interpolate

from ...errors import DataFileError, Problem
from ..drive_chain import motor_to_joint
from ..trajectory import Trajectory
from .common import (
    DEFAULT_CHECKS,
    DROP_HINT,
    MIN_SAMPLES,
    POSITION_ROLES,
    RESAMPLE_HINT,
    Column,
    RawColumns,
    bad_rows,
    check_time,
    fmt_ranges,
    runs,
    time_conflict,
    unit_checks,
    warn_data,
)
from .options import MAX_GAP_STEPS, LoadReport, LogFormat

__all__ = ["log_trajectories", "resample"]


def _drop_bad_rows(c: RawColumns, fmt: LogFormat) -> tuple[np.ndarray, tuple[str, ...]]:
    """(rows kept, what was dropped and why); bad rows are an error without ``drop_bad_rows``."""
    drop, bad = bad_rows(c)
    if bad and not fmt.drop_bad_rows:
        raise DataFileError(bad, hint=DROP_HINT)
    dropped = tuple(f"{p.where}{', ' + p.field if p.field else ''}: {p.message}" for p in bad)
    if drop.all():
        raise DataFileError([Problem(c.source, f"rows 1-{c.n_rows}", "", "every row is bad")])
    return ~drop, dropped


def _convert_units(vals: dict[str, np.ndarray], fmt: LogFormat, n: int, source: str,
                   angular: Sequence[int] | None = None) -> None:
    """``deg`` (positions to radians: the joints ``angular``, 0-based, default every joint) and
    ``tau_scale`` (the logged signal to N m), in place."""
    if fmt.deg:
        js = list(range(n)) if angular is None else list(angular)
        for r in POSITION_ROLES:
            if r in vals and js:
                v = np.array(vals[r], float)
                v[:, js] = np.deg2rad(v[:, js])
                vals[r] = v
    if fmt.tau_scale:
        s = np.asarray(fmt.tau_scale, float)
        if s.size not in (1, n):
            raise DataFileError([Problem(source, "", "tau_scale", f"{s.size} factors given, the robot has {n} "
                                         "joints: give one per joint or one for all")])
        vals["tau"] = vals["tau"] * s


def _checked_time(c: RawColumns, t: np.ndarray, keep: np.ndarray, fmt: LogFormat) -> None:
    """The time column of the kept rows: strictly increasing (with ``resample``), else regular."""
    tcol = c.cols["t"]
    rows = np.flatnonzero(keep)
    d = np.diff(t)
    if fmt.resample:
        if (d <= 0).any():
            back = np.flatnonzero(d <= 0)
            where = fmt_ranges(runs(np.isin(np.arange(c.n_rows), rows[back + 1])), tcol.lines)
            raise DataFileError([Problem(tcol.file, where, tcol.names[0], f"time is not strictly increasing "
                                         f"({back.size} step(s) <= 0): resampling cannot order it")])
        return
    shifted = not keep.all()  # rows then count the kept rows: say so, give no file lines
    col = Column(tcol.file, tcol.names, t[:, None], None if shifted else tcol.lines)
    tprobs: list[Problem] = []
    check_time(t, col, DEFAULT_CHECKS.time_jitter_tol, tprobs)
    if tprobs:
        if shifted:
            tprobs = [Problem(p.file, f"{p.where} of the {rows.size} rows kept", p.field, p.message) for p in tprobs]
        raise DataFileError(tprobs, hint=RESAMPLE_HINT)


def _time_base(c: RawColumns, vals: dict[str, np.ndarray], keep: np.ndarray, dt: float | None,
               fmt: LogFormat) -> np.ndarray:
    """The time of the kept rows: the time column (taken out of ``vals``), or ``dt``; both given is an error
    unless ``fmt.dt_overrides_time`` (then the time column is ignored, with a warning)."""
    if "t" in vals and dt is not None:
        if not fmt.dt_overrides_time:
            raise DataFileError([time_conflict(c.cols["t"].file, c.cols["t"].names[0], dt)])
        warn_data(f"{c.cols['t'].file}, column {c.cols['t'].names[0]}: ignored, the time base is dt = {dt:g} s "
                  "(--dt-overrides-time)")
        vals.pop("t")
    if "t" in vals:
        t = vals.pop("t")[:, 0]
        _checked_time(c, t, keep, fmt)
        return t
    assert dt is not None  # without a time column dt is required (checked when the columns were chosen)
    return np.arange(int(keep.sum())) * float(dt)


def resample(t: np.ndarray, arrays: dict[str, np.ndarray], h: float, max_gap: float
             ) -> tuple[list[tuple[np.ndarray, dict[str, np.ndarray]]], int]:
    """Split at steps > max_gap, put each piece on a uniform grid of step ``h``: cubic (positions) or
    linear (the rest) interpolation (:mod:`scipy.interpolate`)."""
    d = np.diff(t)
    cuts = np.flatnonzero(d > max_gap)
    bounds = np.r_[0, cuts + 1, t.size]
    out = []
    for a, b in itertools.pairwise(bounds):
        ts = t[a:b]
        if ts.size < 2:
            continue
        m = int(math.floor((ts[-1] - ts[0]) / h + 1e-9)) + 1
        grid = ts[0] + h * np.arange(m)
        grid = grid[grid <= ts[-1]]
        seg = {}
        for role, v in arrays.items():
            x = v[a:b]
            if role in ("q", "q_link") and ts.size >= 4:
                seg[role] = scipy.interpolate.CubicSpline(ts, x, axis=0)(grid)
            else:
                seg[role] = scipy.interpolate.interp1d(ts, x, axis=0, assume_sorted=True)(grid)
        out.append((grid, seg))
    return out, int(cuts.size)


Piece = tuple[np.ndarray, dict[str, np.ndarray]]


def _long_pieces(pieces: list[Piece], source: str, N: int) -> tuple[list[Piece], list[str]]:
    """The pieces long enough to filter, and a note on each one left out."""
    notes, kept = [], []
    for tt, vv in pieces:
        if tt.size < MIN_SAMPLES:
            notes.append(f"a piece of {tt.size} samples from t = {tt[0]:.6g} s is too short to filter: left out")
            continue
        kept.append((tt, vv))
    if not kept:
        raise DataFileError([Problem(source, f"rows 1-{N}", "", f"too short to filter: no piece of at least "
                                     f"{MIN_SAMPLES} samples")])
    return kept, notes


def _experiments(kept: list[Piece], c: RawColumns, *, n: int, loaded: bool, drive_chain, joint_types,
                 meta: dict[str, Any]) -> list[Trajectory]:
    """One trajectory per piece: drive chain, ``q_link`` for ``q`` (the deflection kept), unit checks."""
    trajs = []
    for k, (tt, vv) in enumerate(kept):
        q, tau, dq, ddq = vv["q"], vv["tau"], vv.get("dq"), vv.get("ddq")
        if drive_chain is not None:
            if len(drive_chain.ratios) != n:
                raise ValueError(f"drive chain has {len(drive_chain.ratios)} joints, the robot {n}")
            q, tau, dq, ddq = motor_to_joint(drive_chain, q, tau, dq, ddq)
        defl = None
        if "q_link" in vv:
            defl = q - vv["q_link"]
            q = vv["q_link"]
        src = c.source if len(kept) == 1 else f"{c.source} [experiment {k + 1}/{len(kept)}]"
        if k == 0:
            files = {"t": c.cols["t"].file if "t" in c.cols else c.source, "q": c.cols["q"].file,
                     "tau": c.cols["tau"].file}
            for msg in unit_checks(files, tt, q, tau, joint_types, DEFAULT_CHECKS):
                warn_data(msg)
        trajs.append(Trajectory(t=tt, q=q, tau=tau, dq=dq, ddq=ddq, source=src, loaded=bool(loaded),
                                meta={**meta, "experiment": k + 1}, deflection=defl))
    return trajs


def log_trajectories(c: RawColumns, fmt: LogFormat, *, n: int, dt: float | None, loaded: bool = False,
                     drive_chain=None, joint_types: Sequence[int] | None = None
                     ) -> tuple[tuple[Trajectory, ...], LoadReport]:
    """The experiments of columns read with the data options ``fmt`` (a file splits at gaps with
    ``resample``), and what was done.

    Raises
    ------
    DataFileError
        One line per problem, naming the file, rows (and file lines) and column.
    """
    N = c.n_rows
    keep, dropped = _drop_bad_rows(c, fmt)
    vals = {r: col.values[keep] for r, col in c.cols.items()}
    # --deg converts angles: the revolute joints (the robot's joint types), or every motor-side position
    angular = None if joint_types is None or drive_chain is not None else [j for j, sg in enumerate(joint_types)
                                                                            if sg == 0]
    _convert_units(vals, fmt, n, c.source, angular)
    t = _time_base(c, vals, keep, dt, fmt)
    d = np.diff(t)
    h = float(np.median(d)) if d.size else float("nan")
    jitter = float(np.abs(d - h).max() / h) if d.size else 0.0
    pieces: list[Piece] = [(t, vals)]
    gaps = 0
    resampled = False
    if fmt.resample and d.size and (jitter > 1e-6):
        pieces, gaps = resample(t, vals, h, fmt.max_gap if fmt.max_gap is not None else MAX_GAP_STEPS * h)
        resampled = True
    kept, notes = _long_pieces(pieces, c.source, N)
    opts = fmt.options()
    meta = {"format": c.fmt, "files": {r: col.file for r, col in c.cols.items()},
            "columns": {r: list(col.names) for r, col in c.cols.items()}, "drive_chain": drive_chain is not None,
            "t_from_dt": "t" not in c.cols or dt is not None, "dt_median": h, "dt_max_rel_jitter": jitter,
            "options": opts}
    if c.rows is not None:
        meta["rows"] = c.rows
    trajs = _experiments(kept, c, n=n, loaded=loaded, drive_chain=drive_chain, joint_types=joint_types, meta=meta)
    rep = LoadReport(file=c.source, rows_read=N, rows_dropped=int((~keep).sum()), dropped=dropped,
                     resampled=resampled, step_from=h, step_to=h if resampled else None, step_jitter=jitter, gaps=gaps,
                     experiments=len(trajs), samples=tuple(tr.n_samples for tr in trajs), options=opts,
                     notes=tuple(notes))
    return tuple(trajs), rep
