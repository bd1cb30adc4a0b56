"""Controller logs as they come: the columns of a file read with a :class:`~.options.LogFormat` (the data
options), and the :class:`~.options.LoadReport` of what was done.

Order of the operations (each one echoed in the report): rows with bad values dropped
(``drop_bad_rows``), degrees -> radians (``deg``: the revolute joints only, by the robot's joint types; with
a drive chain every motor-side position, all angles), millimetres -> metres (``mm``: the prismatic joints'
positions on the joint side), ``tau_scale``, resampling and splitting at gaps, the robot's
drive chain (motor -> joint side), then ``q_link`` replaces ``q``.
"""
from __future__ import annotations

import itertools
import math
import re
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
    LEADING_ROWS,
    MIN_SAMPLES,
    POSITION_ROLES,
    RESAMPLE_HINT,
    SKIP_HINT,
    Column,
    RawColumns,
    bad_rows,
    check_time,
    fmt_ranges,
    leading_rows_hint,
    out_of_order_rows,
    runs,
    step_stats,
    time_conflict,
    unit_check_names,
    unit_checks,
    warn_data,
)
from .options import MAX_GAP_STEPS, LoadReport, LogFormat

__all__ = ["log_trajectories", "resample", "time_order_hint", "ISOLATED_MAX", "LEADING_ROWS"]

#: most rows out of time order called isolated (a logger's stray stamps, dropped by ``--drop-bad-rows``); more
#: is a reset of the clock (the file splits there with ``--resample``)
ISOLATED_MAX = 10


def _order_problem(t: np.ndarray) -> tuple[np.ndarray, str]:
    """(rows to drop, what they are): ``"leading"`` (garbage before the recording: every row up to the last
    one out of order, or up to a gap of more than ``MAX_GAP_STEPS`` median steps after which the rest is in
    order, within the first ``LEADING_ROWS``), ``"isolated"`` (at most ``ISOLATED_MAX`` rows out of order, the
    rest increasing), ``"reset"`` (more: the clock restarts) or ``""`` (in order)."""
    bad = out_of_order_rows(t)
    if not bad.any():
        return bad, ""
    if bad.sum() > ISOLATED_MAX:
        return bad, "reset"
    good = np.flatnonzero(~bad)
    d = np.diff(t[good])
    lead = int(np.argmin(bad)) if not bad.all() else bad.size  # rows out of order from the first one on
    if d.size:
        big = np.flatnonzero(d[:LEADING_ROWS] > MAX_GAP_STEPS * float(np.median(d)))
        if big.size:
            lead = max(lead, int(good[big[-1] + 1]))
    if 0 < lead <= LEADING_ROWS and not bad[lead:].any():
        return np.arange(bad.size) < lead, "leading"
    return bad, "isolated"


def time_order_hint(t: np.ndarray) -> str:
    """The option that fixes a time column that is not strictly increasing: ``--skip-rows`` for garbage rows at
    the start, ``--drop-bad-rows`` for a few isolated ones, ``--resample`` (splits at the reset) for a clock
    that restarts, ``--dt --dt-overrides-time`` for stamps that repeat without ever going back (a clock that
    ticks more coarsely than the samples come)."""
    t = np.asarray(t, float)
    bad, kind = _order_problem(t)
    d = np.diff(t)
    if kind == "reset" and not (d < 0).any():
        period = (t[-1] - t[0]) / (t.size - 1)
        return (f"{int((d == 0).sum())} repeated time stamp(s), none going back: the clock ticks more coarsely "
                f"than the samples come; --dt {period:.3g} --dt-overrides-time times each row by the sampling "
                f"period instead ({period:.3g} s: the file's duration over its rows)")
    if kind == "leading":
        return SKIP_HINT.format(k=int(bad.sum()))
    if kind == "isolated":
        return (f"{int(bad.sum())} isolated row(s) out of time order: --drop-bad-rows drops them (counted in the "
                "output)")
    return ("the clock restarts (time goes back and increases again): --resample splits the file there into "
            "experiments; or split it into separate files")


def _drop_bad_rows(c: RawColumns, fmt: LogFormat) -> tuple[np.ndarray, tuple[str, ...]]:
    """(rows kept, what was dropped and why); bad rows are an error without ``drop_bad_rows``."""
    drop, bad = bad_rows(c)
    if bad and not fmt.drop_bad_rows:
        lead = leading_rows_hint(drop)
        raise DataFileError(bad, hint=f"{lead}; or {DROP_HINT}" if lead else DROP_HINT)
    dropped = tuple(f"{p.where}{', ' + p.field if p.field else ''}: {p.message}" for p in bad)
    if drop.all():
        raise DataFileError([Problem(c.source, f"rows 1-{c.n_rows}", "", "every row is bad")])
    return ~drop, dropped


def _unit_joints(fmt: LogFormat, n: int, source: str, joint_types: Sequence[int] | None, motor_side: bool,
                roles: Sequence[str]) -> dict[str, tuple[list[int], list[int]]]:
    """Per position role present (``roles``), the 0-based joints ``deg`` converts from degrees and those ``mm``
    converts from millimetres.

    ``deg``: the revolute joints by ``joint_types`` (every joint without them); on the motor side (``motor_side``,
    a drive chain) every joint of ``q``, ``dq``, ``ddq``, which are motor angles, and the revolute ones of the
    link-side ``q_link``. ``mm``: the prismatic joints (``sigma = 1``), of the joint-side roles only (with a drive
    chain, ``q_link``).

    Raises
    ------
    DataFileError
        ``mm`` without joint types, on a robot without a prismatic joint, or with a drive chain and no ``q_link``
        column: the option would convert nothing.
    """
    every = list(range(n))
    types = list(joint_types) if joint_types is not None else None
    revolute = every if types is None else [j for j in every if types[j] == 0]
    prismatic = [] if types is None else [j for j in every if types[j] == 1]
    out: dict[str, tuple[list[int], list[int]]] = {}
    for r in (x for x in POSITION_ROLES if x in roles):
        motor = motor_side and r != "q_link"
        deg = (every if motor else revolute) if fmt.deg else []
        out[r] = (deg, [] if motor or not fmt.mm else prismatic)
    if fmt.mm:
        why = ("the reader was given no robot (its joint types say which joints are prismatic)" if types is None
               else "the robot has no prismatic joint" if not prismatic
               else "the robot's drive chain makes the logged q, dq, ddq motor angles; --mm converts a link-side "
                    "q_link column only, and there is none (give the drive chain's ratio per metre instead)"
               if not any(mm for _, mm in out.values()) else "")
        if why:
            raise DataFileError([Problem(source, "", "mm", f"--mm (prismatic positions in millimetres): {why}")])
    return out


def _convert_units(vals: dict[str, np.ndarray], fmt: LogFormat, n: int, source: str,
                   joints: dict[str, tuple[list[int], list[int]]]) -> None:
    """``deg`` (positions to radians) and ``mm`` (prismatic positions to metres) on the joints of each role
    ``joints`` gives (:func:`_unit_joints`), and ``tau_scale`` (the logged signal to N m), in place."""
    for r, (deg, mm) in joints.items():
        if r in vals and (deg or mm):
            v = np.array(vals[r], float)
            v[:, deg] = np.deg2rad(v[:, deg])
            v[:, mm] = 1e-3 * v[:, mm]
            vals[r] = v
    if fmt.tau_scale:
        s = np.asarray(fmt.tau_scale, float)
        if s.size not in (1, n):
            raise DataFileError([Problem(source, "", "tau_scale", f"{s.size} factors given, the robot has {n} "
                                         "joints: give one per joint or one for all")])
        vals["tau"] = vals["tau"] * s


def _drop_out_of_order(c: RawColumns, keep: np.ndarray, fmt: LogFormat, dt: float | None
                       ) -> tuple[np.ndarray, tuple[str, ...]]:
    """``drop_bad_rows``: the rows whose time is out of order, when they are a few isolated ones (the rest
    increasing; see :func:`~.common.out_of_order_rows`), dropped; a reset of the clock is left to
    :func:`_checked_time`."""
    if not fmt.drop_bad_rows or "t" not in c.cols or dt is not None:
        return keep, ()
    rows = np.flatnonzero(keep)
    bad, kind = _order_problem(c.cols["t"].values[rows, 0])
    if kind not in ("leading", "isolated"):
        return keep, ()
    tcol = c.cols["t"]
    mask = np.zeros(c.n_rows, bool)
    mask[rows[bad]] = True
    keep = keep & ~mask
    what = (f"{tcol.names[0]}: {int(bad.sum())} row(s) whose time is out of order (the rest increases)" if kind ==
            "isolated" else f"{tcol.names[0]}: {int(bad.sum())} leading row(s) whose time is out of order "
            f"(garbage before the recording; --skip-rows {int(rows[np.flatnonzero(bad)[-1]]) + 1} skips them)")
    return keep, (f"{fmt_ranges(runs(mask), tcol.lines)}, {what}",)


def _resets(t: np.ndarray) -> np.ndarray:
    """Steps (indices into ``diff(t)``) where the clock restarts: time goes back, and every stretch between
    two such steps is long enough to filter; empty when a stretch is shorter (then the time is garbage)."""
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size == 0 or _order_problem(t)[1] != "reset":
        return np.zeros(0, int)
    bounds = np.r_[0, back + 1, t.size]
    if np.min(np.diff(bounds)) < MIN_SAMPLES:
        return np.zeros(0, int)
    return back


def _checked_time(c: RawColumns, t: np.ndarray, keep: np.ndarray, fmt: LogFormat) -> None:
    """The time column of the kept rows: strictly increasing but for resets of the clock (with ``resample``,
    which splits there), else regular."""
    tcol = c.cols["t"]
    rows = np.flatnonzero(keep)
    d = np.diff(t)
    if fmt.resample:
        back = np.flatnonzero(d <= 0)
        if back.size and _resets(t).size != back.size:
            where = fmt_ranges(runs(np.isin(np.arange(c.n_rows), rows[back + 1])), tcol.lines)
            raise DataFileError([Problem(tcol.file, where, tcol.names[0], f"time is not strictly increasing "
                                         f"({back.size} step(s) <= 0): resampling cannot order it")],
                                hint=_shifted_hint(time_order_hint(t), rows))
        return
    shifted = not keep.all()  # rows then count the kept rows: say so, give no file lines
    col = Column(tcol.file, tcol.names, t[:, None], None if shifted else tcol.lines)
    tprobs: list[Problem] = []
    check_time(t, col, DEFAULT_CHECKS.time_jitter_tol, tprobs)
    if tprobs:
        if shifted:
            tprobs = [Problem(p.file, f"{p.where} of the {rows.size} rows kept", p.field, p.message) for p in tprobs]
        hint = _shifted_hint(time_order_hint(t), rows) if (d <= 0).any() else RESAMPLE_HINT
        raise DataFileError(tprobs, hint=hint)


def _shifted_hint(hint: str, rows: np.ndarray) -> str:
    """A ``--skip-rows K`` hint counted in the kept rows, counted in the file's rows."""
    m = re.search(r"--skip-rows (\d+)", hint)
    if m and rows.size:
        k = int(m.group(1))
        hint = hint.replace(m.group(0), f"--skip-rows {int(rows[k - 1]) + 1}")
    return hint


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
    return _dt_time(c, keep, float(dt), fmt)


def _dt_time(c: RawColumns, keep: np.ndarray, dt: float, fmt: LogFormat) -> np.ndarray:
    """The time of the kept rows of a log timed by ``dt``: data row ``k`` is at ``k dt`` (from the first kept
    one), so that rows dropped inside the recording leave a hole, bridged by ``resample`` and an error
    without it (as a gap in a time column is), never closed by moving the later samples one step earlier."""
    rows = np.flatnonzero(keep)
    holes = np.flatnonzero(np.diff(rows) > 1)
    if holes.size and not fmt.resample:
        lines = next((col.lines for col in c.cols.values() if col.lines is not None), None)
        missing = np.zeros(c.n_rows, bool)
        for k in holes:
            missing[rows[k] + 1:rows[k + 1]] = True
        where = fmt_ranges(runs(missing), lines)
        raise DataFileError([Problem(c.source, where, "t", f"{int(missing.sum())} row(s) dropped inside a recording "
                                     f"timed by dt = {dt:g} s (no time column): the samples after them would be "
                                     "shifted one step earlier per row dropped")],
                            hint="give --resample to interpolate across the dropped rows (each sample keeps its time); "
                                 "or fix the rows")
    return (rows - rows[0]) * dt if rows.size else np.zeros(0)


def resample(t: np.ndarray, arrays: dict[str, np.ndarray], h: float, max_gap: float
             ) -> tuple[list[tuple[np.ndarray, dict[str, np.ndarray]]], int]:
    """Split at steps > max_gap (and where the clock restarts), put each piece on a uniform grid of step ``h``: cubic (positions) or
    linear (the rest) interpolation (:mod:`scipy.interpolate`)."""
    d = np.diff(t)
    cuts = np.flatnonzero((d > max_gap) | (d <= 0))  # gaps, and resets of the clock (see _checked_time)
    bounds = np.r_[0, cuts + 1, t.size]
    out = []
    for a, b in itertools.pairwise(bounds):
        ts = t[a:b]
        if ts.size < 2:
            continue
        m = int(math.floor((ts[-1] - ts[0]) / h + 1e-9)) + 1
        grid = ts[0] + h * np.arange(m)
        # the last grid point may pass the last stamp by rounding (ts[0] + h (m - 1) for a stamp written as
        # k h): it is that stamp's sample, not one past the recording
        grid = grid[grid <= ts[-1] + 1e-9 * h]
        at = np.minimum(grid, ts[-1])
        seg = {}
        for role, v in arrays.items():
            x = v[a:b]
            if role in ("q", "q_link") and ts.size >= 4:
                seg[role] = scipy.interpolate.CubicSpline(ts, x, axis=0)(at)
            else:
                seg[role] = scipy.interpolate.interp1d(ts, x, axis=0, assume_sorted=True)(at)
        out.append((grid, seg))
    return out, int((d > max_gap).sum())


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
            qrole = "q_link" if "q_link" in vv else "q"
            files = {"t": c.cols["t"].file if "t" in c.cols else c.source, "q": c.cols[qrole].file,
                     "tau": c.cols["tau"].file}
            for msg in unit_checks(files, tt, q, tau, joint_types, DEFAULT_CHECKS, unit_check_names(c, qrole, drive_chain)):
                warn_data(msg)
        trajs.append(Trajectory(t=tt, q=q, tau=tau, dq=dq, ddq=ddq, source=src, loaded=bool(loaded),
                                meta={**meta, "experiment": k + 1}, deflection=defl))
    return trajs


def _split_notes(d: np.ndarray, resets: np.ndarray, max_gap: float, given: bool, rows: np.ndarray,
                 lines: np.ndarray | None, experiments: int, resampled: bool) -> list[str]:
    """Why a file became several experiments: the steps longer than ``--max-gap`` and the resets of the clock,
    by row (and file line)."""
    if not resampled:
        return []
    out = []
    gaps = np.flatnonzero(d > max_gap)

    def where(ks) -> str:
        shown = [f"row {int(rows[k + 1])}" + (f" (line {int(lines[k + 1])})" if lines is not None else "")
                 + f": {d[k]:.6g} s" for k in ks[:5]]
        return "; ".join(shown) + (f"; and {len(ks) - 5} more" if len(ks) > 5 else "")

    if gaps.size:
        what = f"--max-gap {max_gap:.6g} s" + ("" if given else " (the default, 5 median steps)")
        out.append(f"{gaps.size} step(s) longer than {what} split the file ({where(gaps)}); a --max-gap above "
                   f"{d[gaps].max():.6g} s would bridge them (interpolated)")
    if resets.size:
        out.append(f"the clock restarts {resets.size} time(s): the file is split there ({where(resets)})")
    if out:
        out.append(f"{experiments} experiment(s) made of this file")
    return out


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
    keep, more = _drop_out_of_order(c, keep, fmt, dt)
    dropped += more
    vals = {r: col.values[keep] for r, col in c.cols.items()}
    # --deg converts angles: the revolute joints (the robot's joint types), or every motor-side position;
    # --mm the prismatic joints' positions on the joint side
    joints = _unit_joints(fmt, n, c.source, joint_types, drive_chain is not None, tuple(vals))
    _convert_units(vals, fmt, n, c.source, joints)
    t = _time_base(c, vals, keep, dt, fmt)
    d = np.diff(t)
    resets = _resets(t) if fmt.resample else np.zeros(0, int)
    fwd = np.delete(d, resets)
    h = float(np.median(fwd)) if fwd.size else float("nan")
    jitter = float(np.abs(fwd - h).max() / h) if fwd.size else 0.0
    pieces: list[Piece] = [(t, vals)]
    gaps = 0
    resampled = False
    max_gap = fmt.max_gap if fmt.max_gap is not None else MAX_GAP_STEPS * h
    t_lines = c.cols["t"].lines[keep] if "t" in c.cols and c.cols["t"].lines is not None else None
    rows = np.flatnonzero(keep) + 1
    if fmt.resample and d.size and (jitter > 1e-6 or resets.size):
        pieces, gaps = resample(t, vals, h, max_gap)
        resampled = True
    kept, notes = _long_pieces(pieces, c.source, N)
    notes = list(c.notes) + _split_notes(d, resets, max_gap, fmt.max_gap is not None, rows, t_lines, len(kept),
                                         resampled) + notes
    steps = step_stats(np.split(t, resets + 1)[0] if resets.size else t, t_lines, fmt.max_gap)
    opts = fmt.options()
    meta = {"format": c.fmt, "files": {r: col.file for r, col in c.cols.items()},
            "columns": {r: list(col.names) for r, col in c.cols.items()}, "drive_chain": drive_chain is not None,
            "t_from_dt": "t" not in c.cols or dt is not None, "dt_median": h, "dt_max_rel_jitter": jitter,
            "options": opts, "recording": c.source}
    if c.rows is not None:
        meta["rows"] = c.rows
    trajs = _experiments(kept, c, n=n, loaded=loaded, drive_chain=drive_chain, joint_types=joint_types, meta=meta)
    rep = LoadReport(file=c.source, rows_read=N, rows_dropped=int((~keep).sum()), dropped=dropped,
                     resampled=resampled, step_from=h, step_to=h if resampled else None, step_jitter=jitter, gaps=gaps,
                     experiments=len(trajs), samples=tuple(tr.n_samples for tr in trajs), options=opts,
                     notes=tuple(notes), steps=steps)
    return tuple(trajs), rep
