"""What the readers of every format share: the roles and their default names, the columns read from a file
(:class:`Column`, :class:`Table`, :class:`RawColumns`), column resolution (default names, ``{j}``
templates, ``--columns`` selectors), problems named by rows and lines, the checks of values, time and
units, bad rows, and the :class:`DataWarning` of values that look like unit mix-ups.

Rows are 1-based data rows; a column's ``lines`` give their file lines (text files; for Parquet, the rows
of the file).
"""
from __future__ import annotations

import bisect
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import DataFileError, Problem

__all__ = [
    "ROLES", "JOINT_ROLES", "LOG_ROLES", "POSITION_ROLES", "DEFAULT_KEYS", "CSV_TEMPLATES", "ABSURD_VALUE",
    "MIN_SAMPLES", "BAD_VALUE_HINT", "TIME_HINT", "DROP_HINT", "RESAMPLE_HINT", "DataWarning", "DataChecks",
    "DEFAULT_CHECKS", "Column", "Table", "RawColumns", "time_conflict", "warn_data", "runs", "number_runs", "fmt_ranges",
    "fmt_names", "open_problem", "not_text_problem", "malformed_problems", "raise_malformed", "resolve_csv_columns",
    "select_columns", "shared_columns", "table_columns", "check_values", "bad_rows", "check_time", "step_regime_changes",
    "unit_checks", "unit_check_names", "StepStats", "step_stats", "out_of_order_rows", "SKIP_HINT",
    "LEADING_ROWS", "leading_rows_hint",
]

#: roles of the plain reading (a ``columns`` mapping, array keys)
ROLES = ("t", "q", "tau", "dq", "ddq")
JOINT_ROLES = ("q", "tau", "dq", "ddq")
#: roles of ``--columns``: ``q_link`` is a second, link-side position
LOG_ROLES = ("t", "q", "tau", "dq", "ddq", "q_link")
#: roles converted by ``--deg``
POSITION_ROLES = ("q", "q_link", "dq", "ddq")
DEFAULT_KEYS: dict[str, tuple[str, ...]] = {
    "t": ("t", "time", "times"),
    "q": ("q", "positions", "position", "pos"),
    "tau": ("tau", "torques", "torque", "effort", "efforts"),
    "dq": ("dq", "velocities", "velocity"),
    "ddq": ("ddq", "accelerations", "acceleration"),
}
CSV_TEMPLATES = {"q": "q{j}", "tau": "tau{j}", "dq": "dq{j}", "ddq": "ddq{j}"}
MAX_RANGES_SHOWN = 5
#: |value| above which a (non-time) sample is absurd: a sensor fault or a logging glitch, not a measurement.
#: Every reading rejects such values (or drops their rows with ``--drop-bad-rows``).
ABSURD_VALUE = 1e6
#: fewest samples of an experiment (filtering needs a few dozen)
MIN_SAMPLES = 32
#: hint of the errors about bad values (non-finite, absurd)
BAD_VALUE_HINT = ("fix or remove these rows; the command line's --drop-bad-rows drops them (counted in the "
                  "output)")
#: hint of the errors about the time column
TIME_HINT = ("the command line's --resample puts irregular time stamps on a uniform grid (gaps longer than "
             "--max-gap split the file); --dt SECONDS --dt-overrides-time ignores the time column")
DROP_HINT = "give --drop-bad-rows to drop such rows (they are counted in the output)"
RESAMPLE_HINT = ("give --resample to resample irregular time stamps on a uniform grid (gaps longer than "
                 "--max-gap split the file)")
SKIP_HINT = "the bad rows are at the start of the file: --skip-rows {k} skips them (also skip_rows in a --format file)"
#: most steps listed by row in :class:`StepStats`
OUTLIERS_SHOWN = 10
#: bad rows all within this many first data rows: garbage before the recording (``--skip-rows``)
LEADING_ROWS = 20
REGIME_WINDOW = 20  #: steps averaged to find the local sampling period
REGIME_TOL = 0.2    #: largest accepted relative change of the local sampling period


class DataWarning(UserWarning):
    """A data value looks wrong (unit mix-up...) but is kept."""


def time_conflict(file: str, column: str, dt: float) -> Problem:
    """The problem of a time column and a sampling period both given (``--dt``, a split spec's ``dt=``/``fs=``)
    without ``dt_overrides_time``."""
    return Problem(file, "", column, f"the file has a time column and dt = {dt:g} s is given (--dt, or dt=/fs= of "
                   "a split spec): leave dt out to use the time column, or give --dt-overrides-time to ignore it")


def warn_data(msg: str) -> None:
    """A :class:`DataWarning` (the value is kept)."""
    warnings.warn(msg, DataWarning, stacklevel=3)


@dataclass(frozen=True)
class DataChecks:
    """Limits of the checks of a recording.

    Attributes
    ----------
    time_jitter_tol : float
        Largest accepted relative deviation of a time step from the median step.
    min_samples : int
        Fewest samples accepted (filtering needs a few dozen).
    max_abs_position, max_abs_velocity, max_abs_prismatic, max_abs_torque, max_dt : float
        Thresholds of the unit-mix-up warnings [rad, rad/s, m, N m, s]: revolute positions (degrees?) and
        velocities, prismatic positions (mm?), torques (N mm?), the sampling period (ms?).
    """

    time_jitter_tol: float = 0.5
    min_samples: int = MIN_SAMPLES
    max_abs_position: float = 4 * math.pi
    max_abs_velocity: float = 50.0
    max_abs_prismatic: float = 5.0
    max_abs_torque: float = 1e4
    max_dt: float = 0.1


#: the limits used unless told otherwise
DEFAULT_CHECKS = DataChecks()


# ---------------------------------------------------------------------------------------------
# what a reader returns
# ---------------------------------------------------------------------------------------------
@dataclass
class Column:
    """One role's data as read from one file (before checks)."""

    file: str
    names: list[str]
    values: np.ndarray  # (N, k)
    lines: np.ndarray | None  # (N,) file line of each data row; None for binary files


@dataclass
class Table:
    """A numeric table with every row kept (text or Parquet): bad rows and cells are marked, not dropped.

    ``lines`` holds the file line of each data row (for Parquet, the row of the file); ``bad_text`` the
    first three unparsable texts of each column (by column index), for the messages of the plain reading.
    """

    file: str
    names: list[str] | None
    data: np.ndarray            # (N, k), NaN where unparsable
    lines: np.ndarray           # (N,) file line of each data row
    bad_fields: np.ndarray      # (N,) bool: wrong number of fields
    unparsable: np.ndarray      # (N, k) bool
    bad_text: dict[int, list[str]] = field(default_factory=dict)
    first_line: int = 1         # line of the header (or of the first row when there is none)
    notes: list[str] = field(default_factory=list)  # rows skipped (``skip_rows``)


@dataclass
class RawColumns:
    """Per-role values of one recording (one file or the files of a split recording), rows aligned."""

    source: str
    fmt: str
    cols: dict[str, Column] = field(default_factory=dict)
    unused: list[str] = field(default_factory=list)
    bad_fields: np.ndarray | None = None      # (N,) wrong number of fields
    unparsable: dict[str, np.ndarray] = field(default_factory=dict)  # role -> (N, k) bool
    rows: tuple[int, int] | None = None       # the samples [start, stop) of a Parquet log read by segment
    notes: list[str] = field(default_factory=list)  # what reading did that the load report says (a reshape...)

    @property
    def n_rows(self) -> int:
        return next(iter(self.cols.values())).values.shape[0] if self.cols else 0


# ---------------------------------------------------------------------------------------------
# rows and ranges
# ---------------------------------------------------------------------------------------------
def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """1-based inclusive (start, end) ranges where mask is True."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    starts = np.r_[idx[0], idx[cut + 1]]
    ends = np.r_[idx[cut], idx[-1]]
    return [(int(a) + 1, int(b) + 1) for a, b in zip(starts, ends)]


def number_runs(numbers: Sequence[int] | np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (first, last) ranges of consecutive numbers (sorted, e.g. file lines)."""
    a = np.asarray(numbers, int)
    if a.size == 0:
        return []
    cut = np.flatnonzero(np.diff(a) > 1)
    return [(int(x), int(y)) for x, y in zip(np.r_[a[0], a[cut + 1]], np.r_[a[cut], a[-1]])]


def fmt_ranges(ranges: list[tuple[int, int]], lines: np.ndarray | None = None) -> str:
    """``rows 5-7, 12 (lines 6-8, 13)``: at most ``MAX_RANGES_SHOWN`` ranges of 1-based rows, then how many
    more; ``lines``: the file line of each row."""
    def one(a: int, b: int) -> str:
        return f"{a}" if a == b else f"{a}-{b}"

    shown = ranges[:MAX_RANGES_SHOWN]
    s = "rows " + ", ".join(one(a, b) for a, b in shown)
    if lines is not None:
        s += " (lines " + ", ".join(one(int(lines[a - 1]), int(lines[b - 1])) for a, b in shown) + ")"
    if len(ranges) > MAX_RANGES_SHOWN:
        s += f" and {len(ranges) - MAX_RANGES_SHOWN} more ranges"
    return s


def fmt_names(names: Sequence[str]) -> str:
    return ", ".join(names) if len(names) <= 8 else ", ".join(list(names[:3]) + ["..."] + list(names[-2:]))


# ---------------------------------------------------------------------------------------------
# files that cannot be read
# ---------------------------------------------------------------------------------------------
def not_text_problem(path: str, exc: UnicodeDecodeError) -> Problem:
    """The problem of a text file that is not UTF-8: the line of the first bad byte, how much is bad."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError:
        raw = b""
    line = raw[:exc.start].count(b"\n") + 1
    where = f"line {line}" if raw else ""
    bad = raw.decode("utf-8", errors="replace").count("\ufffd") if raw else 0
    what = "not a text file" if bad > max(8, len(raw) // 100) else "not UTF-8 text here"
    return Problem(path, where, "", f"{what} (byte 0x{raw[exc.start]:02x}: {exc.reason})" if raw else
                   f"{what} ({exc.reason})")


def open_problem(path: str, exc: OSError) -> Problem:
    """A data file that cannot be opened: missing, a folder, unreadable."""
    if isinstance(exc, FileNotFoundError):
        return Problem(path, "", "", "file not found")
    if isinstance(exc, IsADirectoryError):
        return Problem(path, "", "", "is a folder, not a data file")
    return Problem(path, "", "", f"cannot read: {exc.strerror or exc}")


def malformed_problems(tab: Table) -> list[Problem]:
    """The rows of a table with the wrong number of fields (named by file line) and its missing or
    non-numeric values (by column, rows and lines, the first texts shown): the errors of the plain reading."""
    probs: list[Problem] = []
    if tab.bad_fields.any():
        where = fmt_ranges(number_runs(tab.lines[tab.bad_fields])).replace("rows", "lines")
        probs.append(Problem(tab.file, where, "", f"wrong number of fields (expected {tab.data.shape[1]} as on "
                                                  f"line {tab.first_line})"))
    unp = tab.unparsable & ~tab.bad_fields[:, None]
    cols = np.flatnonzero(unp.any(axis=0))
    for c in sorted(cols, key=lambda c: (int(np.argmax(unp[:, c])), int(c))):  # as met reading the file
        rows = unp[:, c]
        name = tab.names[c] if tab.names else f"column {c + 1}"
        shown = ", ".join(repr(s) for s in tab.bad_text.get(int(c), [])[:3])
        probs.append(Problem(tab.file, fmt_ranges(runs(rows), tab.lines), name,
                             f"{int(rows.sum())} missing or non-numeric value(s): {shown}"))
    return probs


def raise_malformed(tab: Table) -> None:
    """The plain reading: malformed rows are an error at once (see :func:`malformed_problems`)."""
    probs = malformed_problems(tab)
    if probs:
        bad = tab.bad_fields | tab.unparsable.any(axis=1)
        raise DataFileError(probs, hint=leading_rows_hint(bad))


def leading_rows_hint(bad: np.ndarray) -> str | None:
    """``--skip-rows K`` when every bad row (a mask of the data rows) lies among the first ``LEADING_ROWS``:
    the garbage a logger writes before the recording; else None."""
    idx = np.flatnonzero(bad)
    if idx.size == 0 or idx[-1] >= LEADING_ROWS:
        return None
    return SKIP_HINT.format(k=int(idx[-1]) + 1)


# ---------------------------------------------------------------------------------------------
# column resolution
# ---------------------------------------------------------------------------------------------
def template_regex(tmpl: str) -> re.Pattern:
    if "{j}" not in tmpl:
        raise ValueError(f"column template {tmpl!r} must contain '{{j}}'")
    a, b = tmpl.split("{j}", 1)
    return re.compile("^" + re.escape(a) + r"(\d+)" + re.escape(b) + "$")


def _check_roles(columns: Mapping) -> None:
    for k in columns:
        if k not in ROLES:
            raise ValueError(f"unknown role {k!r} in columns mapping (allowed: {', '.join(ROLES)})")


def _time_column(path: str, names: list[str], tspec: Any, dt: float | None, probs: list[Problem]) -> list[int]:
    where = "header (line 1)"
    if tspec is not None:
        pos = {nm: i for i, nm in enumerate(names)}
        if tspec in pos:
            return [pos[tspec]]
        probs.append(Problem(path, where, str(tspec), f"time column not found; columns are {fmt_names(names)}"))
        return []
    lower = {nm.lower(): i for i, nm in enumerate(names)}
    for cand in DEFAULT_KEYS["t"]:
        if cand in lower:
            return [lower[cand]]
    if dt is None:
        probs.append(Problem(path, where, "t", f"no time column ({', '.join(DEFAULT_KEYS['t'])}) and no dt given"))
    return []


def _template_columns(path: str, names: list[str], n: int, role: str, spec: str, probs: list[Problem]
                      ) -> list[int] | None:
    where = "header (line 1)"
    rx = template_regex(spec)
    found: dict[int, int] = {}
    repeated: list[str] = []
    for i, nm in enumerate(names):
        m = rx.match(nm)
        if m:
            j = int(m.group(1))
            if j in found:   # which of the two is the joint's? the file cannot say: neither is read
                repeated.append(f"{spec.format(j=j)} (columns {found[j] + 1} and {i + 1})")
            found[j] = i
    if repeated:
        probs.append(Problem(path, where, spec.replace("{j}", "*"),
                             f"the header names a {role} column twice: {', '.join(repeated)}"))
        return None
    if not found:
        if role in ("q", "tau"):
            probs.append(Problem(path, where, spec.replace("{j}", "*"),
                                 f"no {role} columns (expected {spec.format(j=1)}..{spec.format(j=n)}); "
                                 f"columns are {fmt_names(names)}"))
        return None
    want = set(range(1, n + 1))
    if set(found) != want:
        have = [names[found[j]] for j in sorted(found)]
        missing = [spec.format(j=j) for j in sorted(want - set(found))]
        extra = [spec.format(j=j) for j in sorted(set(found) - want)]
        msg = f"wrong column count for the robot: the robot has {n} joints, the file has {len(found)} " \
              f"{role} columns ({fmt_names(have)})"
        if missing:
            msg += f"; missing {fmt_names(missing)}"
        if extra:
            msg += f"; unexpected {fmt_names(extra)}"
        probs.append(Problem(path, where, spec.replace("{j}", "*"), msg))
        return None
    return [found[j] for j in range(1, n + 1)]


def _listed_columns(path: str, names: list[str], n: int, role: str, lst: list[str], probs: list[Problem]
                    ) -> list[int] | None:
    where = "header (line 1)"
    pos = {nm: i for i, nm in enumerate(names)}
    if len(lst) != n:
        probs.append(Problem(path, where, role, f"wrong column count for the robot: {len(lst)} names "
                             f"given for {role}, the robot has {n} joints"))
        return None
    miss = [nm for nm in lst if nm not in pos]
    if miss:
        probs.append(Problem(path, where, role, f"columns not found: {fmt_names(miss)}; "
                             f"columns are {fmt_names(names)}"))
        return None
    return [pos[nm] for nm in lst]


def resolve_csv_columns(path: str, names: list[str], n: int, columns: Mapping | None, dt: float | None,
                        probs: list[Problem]) -> tuple[dict[str, list[int]], list[str]]:
    """Column indices per role of a table with a header: the default names (``t``/``time``/``times``,
    ``q1..qn``, ``tau1..taun``, ``dq1..``, ``ddq1..``), or a ``columns`` mapping role -> ``{j}`` template,
    list of ``n`` names, or (``t``) one name. Returns (indices per role, names no role uses)."""
    columns = dict(columns or {})
    _check_roles(columns)
    out: dict[str, list[int]] = {}
    t = _time_column(path, names, columns.get("t"), dt, probs)
    if t:
        out["t"] = t
    for role in JOINT_ROLES:
        spec = columns.get(role, CSV_TEMPLATES[role])
        if isinstance(spec, str):
            idx = _template_columns(path, names, n, role, spec, probs)
        else:
            idx = _listed_columns(path, names, n, role, list(spec), probs)
        if idx is not None:
            out[role] = idx
    used = {i for v in out.values() for i in v}
    unused = [nm for i, nm in enumerate(names) if i not in used]
    return out, unused


_INDEX_RX = re.compile(r"^-?\d+(:-?\d*)?$|^:-?\d*$")


def _index_columns(table: Table, sel: str, role: str, where: str) -> list[int]:
    k = table.data.shape[1]
    bad = DataFileError([Problem(table.file, where, role, f"columns {sel}: the file has {k} columns "
                                 f"(0-based indices 0..{k - 1})")])
    if ":" in sel:
        a, b = sel.split(":", 1)
        if (a and not -k <= int(a) < k) or (b and int(b) > k):
            raise bad
        idx = list(range(k))[slice(int(a) if a else None, int(b) if b else None)]
    else:
        i = int(sel)
        idx = [i if i >= 0 else k + i] if -k <= i < k else []
    if not idx or max(idx) >= k:
        raise bad
    return idx


def select_columns(table: Table, sel: str, role: str) -> list[int]:
    """Column indices of a ``--columns`` selector: ``3``, ``1:7`` (0-based, Python slice) or
    ``q_0:q_6`` / ``name`` (header names, a range inclusive)."""
    k = table.data.shape[1]
    where = "header (line 1)" if table.names else ""
    if _INDEX_RX.match(sel):
        return _index_columns(table, sel, role, where)
    if table.names is None:
        raise DataFileError([Problem(table.file, "line 1", role, f"column name {sel!r} given, but the file has no "
                                     "header line: select columns by 0-based index, e.g. q=1:7")])
    pos = {nm: i for i, nm in enumerate(table.names)}
    parts = sel.split(":")
    if len(parts) > 2:
        raise DataFileError([Problem(table.file, where, role, f"{sel!r}: expected FIRST:LAST column names")])
    for nm in parts:
        if nm not in pos:
            raise DataFileError([Problem(table.file, where, role, f"no column named {nm!r}; columns are "
                                         f"{', '.join(table.names[:12])}{' ...' if k > 12 else ''}")])
    if len(parts) == 1:
        return [pos[sel]]
    a, b = parts
    if pos[b] < pos[a]:
        raise DataFileError([Problem(table.file, where, role, f"{sel!r}: {b} comes before {a} in the header")])
    return list(range(pos[a], pos[b] + 1))


def shared_columns(file: str, sel: Mapping[str, Sequence[int]], names: Sequence[str] | None,
                   given: Mapping[str, str]) -> list[Problem]:
    """One problem per pair of roles whose ``--columns`` selectors share columns (each column holds one
    signal: ``q=1:5,tau=1:5`` would identify the positions against themselves)."""
    out = []
    roles = list(sel)
    for i, a in enumerate(roles):
        for b in roles[i + 1:]:
            common = sorted(set(sel[a]) & set(sel[b]))
            if not common:
                continue
            shown = ", ".join(names[c] if names else str(c) for c in common[:8]) + (" ..." if len(common) > 8 else "")
            out.append(Problem(file, "", f"{a}, {b}", f"--columns {a}={given.get(a, '?')} and {b}={given.get(b, '?')} "
                               f"share column(s) {shown}: each column holds one signal"))
    return out


def table_columns(tab: Table, fmt: str, n: int, *, mapping: Mapping | None, selectors: Sequence[tuple[str, str]],
                  dt: float | None, probs: list[Problem]) -> RawColumns:
    """The roles' columns of a table: by ``--columns`` selectors, else by the header (default names or a
    ``columns`` mapping, see :func:`resolve_csv_columns`)."""
    out = RawColumns(tab.file, fmt, bad_fields=tab.bad_fields)
    if selectors:
        sel = {role: select_columns(tab, s, role) for role, s in selectors}
        probs += shared_columns(tab.file, sel, tab.names, dict(selectors))
        if "t" not in sel and dt is None:
            probs.append(Problem(tab.file, "", "t", "no time column in --columns (t=...) and no --dt given"))
    else:
        assert tab.names is not None  # the readers refuse a table without a header here
        sel, out.unused = resolve_csv_columns(tab.file, tab.names, n, mapping, dt, probs)
    for role, idx in sel.items():
        if len(idx) != (1 if role == "t" else n):
            probs.append(Problem(tab.file, "header (line 1)" if tab.names else "", role,
                                 f"{len(idx)} column(s) selected, the robot has {n} joints"
                                 + (" (t is one column)" if role == "t" else "")))
            continue
        names = [tab.names[i] if tab.names else f"column {i}" for i in idx]
        out.cols[role] = Column(tab.file, names, tab.data[:, idx], tab.lines)
        out.unparsable[role] = tab.unparsable[:, idx]
    return out


# ---------------------------------------------------------------------------------------------
# checks of values
# ---------------------------------------------------------------------------------------------
def check_values(raw: RawColumns, probs: list[Problem]) -> None:
    """Non-finite values anywhere, absurd ones (``|value| > ABSURD_VALUE``) outside the time column:
    one problem per column, naming its rows (the plain reading; :func:`bad_rows` with the data options)."""
    for role, c in raw.cols.items():
        bad = ~np.isfinite(c.values)
        for k in np.flatnonzero(bad.any(axis=0)):
            col = bad[:, k]
            v = c.values[col, k]
            kinds = [s for s, m in (("NaN", np.isnan(v)), ("+inf", v == np.inf), ("-inf", v == -np.inf)) if m.any()]
            probs.append(Problem(c.file, fmt_ranges(runs(col), c.lines), c.names[k],
                                 f"{int(col.sum())} non-finite value(s) ({', '.join(kinds)})"))
        if role == "t":
            continue
        with np.errstate(invalid="ignore"):
            absurd = np.isfinite(c.values) & (np.abs(c.values) > ABSURD_VALUE)
        for k in np.flatnonzero(absurd.any(axis=0)):
            col = absurd[:, k]
            worst = float(np.max(np.abs(c.values[col, k])))
            probs.append(Problem(c.file, fmt_ranges(runs(col), c.lines), c.names[k],
                                 f"{int(col.sum())} absurd value(s) (|value| > {ABSURD_VALUE:g}, up to {worst:.3g}): "
                                 "a sensor fault or a logging glitch, not a measurement"))


def bad_rows(c: RawColumns) -> tuple[np.ndarray, list[Problem]]:
    """Rows with a wrong field count, unparsable, non-finite or absurd values; one Problem per kind and column
    (the reading with the data options: such rows are dropped with ``--drop-bad-rows``)."""
    N = c.n_rows
    drop = np.zeros(N, bool)
    probs: list[Problem] = []
    fields = c.bad_fields if c.bad_fields is not None and c.bad_fields.shape == (N,) else None
    if fields is not None and fields.any():
        drop |= fields
        f = next(iter(c.cols.values()))
        probs.append(Problem(f.file, fmt_ranges(runs(fields), f.lines), "",
                             f"{int(fields.sum())} row(s) with the wrong number of fields"))
    for role, col in c.cols.items():
        v = col.values
        unp = c.unparsable.get(role, np.zeros(v.shape, bool))
        if fields is not None:
            unp = unp & ~fields[:, None]
        nonfin = ~np.isfinite(v) & ~unp
        if fields is not None:
            nonfin &= ~fields[:, None]
        absurd = np.zeros(v.shape, bool) if role == "t" else (np.abs(np.nan_to_num(v)) > ABSURD_VALUE)
        for mask, what in ((unp, "unparsable value(s)"), (nonfin, "non-finite value(s) (NaN/inf)"),
                           (absurd, f"absurd value(s) (|value| > {ABSURD_VALUE:g})")):
            for k in np.flatnonzero(mask.any(axis=0)):
                rows = mask[:, k]
                drop |= rows
                probs.append(Problem(col.file, fmt_ranges(runs(rows), col.lines), col.names[k],
                                     f"{int(rows.sum())} {what}"))
    return drop, probs


# ---------------------------------------------------------------------------------------------
# time
# ---------------------------------------------------------------------------------------------
def check_time(t: np.ndarray, col: Column, jitter_tol: float, probs: list[Problem]) -> dict:
    """Strictly increasing time, regular steps (within ``jitter_tol`` of the median step), one sampling
    period throughout; returns the median step and the largest relative jitter."""
    info: dict = {}
    if t.size < 2:
        return info
    d = np.diff(t)
    name = col.names[0]
    nonincr = d <= 0
    if nonincr.any():
        later = [(a + 1, b + 1) for a, b in runs(nonincr)]  # row of the later sample
        probs.append(Problem(col.file, fmt_ranges(later, col.lines), name,
                             f"time is not strictly increasing ({int(nonincr.sum())} step(s) <= 0)"))
        return info
    med = float(np.median(d))
    dev = np.abs(d - med) / med
    info["dt_median"] = med
    info["dt_max_rel_jitter"] = float(dev.max())
    irr = dev > jitter_tol
    if irr.any():
        later = [(a + 1, b + 1) for a, b in runs(irr)]
        worst = float(d[irr][np.argmax(dev[irr])])
        probs.append(Problem(col.file, fmt_ranges(later, col.lines), name,
                             f"irregular sampling: {int(irr.sum())} time step(s) deviate more than "
                             f"{100 * jitter_tol:g} % from the median step {med:.6g} s (e.g. {worst:.6g} s); "
                             "gaps or resets must be split into separate files, or resampled (--resample)"))
    for a, b, local in step_regime_changes(t, irr):
        inside = np.zeros(d.size, bool)
        inside[max(a - 2, 0):b - 1] = True  # steps ending at rows a..b (1-based)
        other = float(np.median(d[~inside])) if (~inside).any() else med
        probs.append(Problem(col.file, fmt_ranges([(a, b)], col.lines), name,
                             f"the sampling period changes: about {local:.6g} s per step in these rows, "
                             f"{other:.6g} s elsewhere; a recording must keep one period: resample it (--resample) "
                             "or split it into separate files"))
    return info


@dataclass(frozen=True)
class StepStats:
    """The time steps of a file as logged (before resampling): what ``inspect`` shows of them.

    Attributes
    ----------
    p50, p99, max : float
        Median, 99th percentile and largest step [s].
    outliers : tuple of (row, line, step)
        The first ``OUTLIERS_SHOWN`` steps deviating more than ``tol`` from the median: the 1-based row of the
        later sample, its file line (None for binary files) and the step [s].
    n_outliers : int
        How many steps deviate so.
    max_gap : float
        The ``--max-gap`` in force [s] (the option, else ``MAX_GAP_STEPS`` median steps).
    max_gap_given : bool
        ``--max-gap`` was given (else the default).
    over_gap : int
        Steps longer than ``max_gap``: where ``--resample`` splits the file.
    tol : float
        Relative deviation from the median above which a step is an outlier.
    jitter : float
        Largest relative deviation from the median of the other steps (the jitter of the clock, outliers aside).
    """

    p50: float
    p99: float
    max: float
    outliers: tuple[tuple[int, int | None, float], ...]
    n_outliers: int
    max_gap: float
    max_gap_given: bool
    over_gap: int
    tol: float
    jitter: float = 0.0

    def to_dict(self) -> dict:
        return {"p50": self.p50, "p99": self.p99, "max": self.max, "jitter": self.jitter,
                "n_outliers": self.n_outliers,
                "outliers": [{"row": r, "line": ln, "step": h} for r, ln, h in self.outliers],
                "max_gap": self.max_gap, "max_gap_given": self.max_gap_given, "over_gap": self.over_gap}

    def max_gap_effect(self, resampled: bool) -> str:
        """What ``--max-gap`` does (or would do with ``--resample``) with the outlier steps."""
        if not self.n_outliers:
            return "no outlier step"
        what = f"--max-gap {self.max_gap:.6g} s" + ("" if self.max_gap_given else " (the default, 5 median steps)")
        if not self.over_gap:
            return f"{what} bridges them all (interpolated{'' if resampled else ' with --resample'})"
        verb = "splits" if resampled else "would split (with --resample)"
        return (f"{what} {verb} the file at the {self.over_gap} step(s) longer than it into {self.over_gap + 1} "
                f"experiments; --max-gap {1.01 * self.max:.3g} would bridge them all")


def step_stats(t: np.ndarray, lines: np.ndarray | None, max_gap: float | None, tol: float = 0.5) -> StepStats | None:
    """The :class:`StepStats` of a time column (None with fewer than two samples or time not increasing).

    ``max_gap`` None: ``MAX_GAP_STEPS`` (5) median steps, the default of ``--max-gap``."""
    t = np.asarray(t, float)
    d = np.diff(t)
    if d.size < 1 or not (d > 0).all():
        return None
    med = float(np.median(d))
    gap = float(max_gap) if max_gap is not None else 5 * med
    dev = np.abs(d - med) / med
    out = np.flatnonzero(dev > tol)
    inl = dev[dev <= tol]
    shown = tuple((int(k) + 2, int(lines[k + 1]) if lines is not None else None, float(d[k]))
                  for k in out[:OUTLIERS_SHOWN])
    return StepStats(p50=med, p99=float(np.percentile(d, 99)), max=float(d.max()), outliers=shown,
                     n_outliers=int(out.size), max_gap=gap, max_gap_given=max_gap is not None,
                     over_gap=int((d > gap).sum()), tol=tol, jitter=float(inl.max()) if inl.size else 0.0)


def out_of_order_rows(t: np.ndarray) -> np.ndarray:
    """Rows whose time breaks the order: the complement of the longest strictly increasing subsequence of
    ``t`` (patience sorting, O(N log N)). A few isolated rows (a logger's stray stamps) leave the rest
    increasing; a reset of the clock leaves a whole stretch out."""
    t = np.asarray(t, float)
    N = t.size
    tails: list[float] = []
    tail_idx: list[int] = []
    prev = np.full(N, -1, int)

    for i, x in enumerate(t):
        k = bisect.bisect_left(tails, x)
        if k == len(tails):
            tails.append(x)
            tail_idx.append(i)
        else:
            tails[k] = x
            tail_idx[k] = i
        prev[i] = tail_idx[k - 1] if k > 0 else -1
    keep = np.zeros(N, bool)
    i = tail_idx[-1] if tail_idx else -1
    while i >= 0:
        keep[i] = True
        i = prev[i]
    return ~keep


def step_regime_changes(t, irregular=None, *, window: int = REGIME_WINDOW, tol: float = REGIME_TOL
                        ) -> list[tuple[int, int, float]]:
    """Stretches whose local sampling period differs from the median step (a change of step regime).

    The local period is the mean of ``window`` consecutive steps: time-stamp jitter averages out (a
    short step followed by a long one), a change of regime (2 ms -> 4 ms) does not, even when both
    steps lie within the tolerance of the median. Windows holding an individually irregular step (a
    gap, already reported) are not counted.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing time [s].
    irregular : ndarray of bool, shape (N - 1,), optional
        Steps already reported as irregular.

    Returns
    -------
    list of (first_row, last_row, local_step)
        1-based rows (the later sample of each step) and the mean step there [s].
    """
    t = np.asarray(t, float)
    d = np.diff(t)
    if d.size < 4:
        return []
    w = int(min(window, max(2, d.size // 4)))
    med = float(np.median(d))
    c = np.r_[0.0, np.cumsum(d)]
    local = (c[w:] - c[:-w]) / w  # window k: steps k..k+w-1
    ok = np.ones(local.size, bool)
    if irregular is not None:
        ci = np.r_[0, np.cumsum(np.asarray(irregular, bool))]
        ok = (ci[w:] - ci[:-w]) == 0
    out = []
    for bad in ((local > (1 + tol) * med) & ok, (local < (1 - tol) * med) & ok):  # slower, faster regimes
        if not bad.any():
            continue
        steps = np.zeros(d.size, bool)
        for k in np.flatnonzero(bad):
            steps[k:k + w] = True
        for a, b in runs(steps):  # 1-based step indices; step i ends at row i + 1
            out.append((a + 1, b + 1, float(np.median(d[a - 1:b]))))
    return sorted(out)


# ---------------------------------------------------------------------------------------------
# units
# ---------------------------------------------------------------------------------------------
def _column_label(role: str, j: int, names: Sequence[str] | None) -> str:
    """How a warning names joint ``j``'s (0-based) column of a role: the file's own name of it (``pos_0
    (joint 1)``; an array's ``positions[joint 1]``), ``q1`` when the file calls it so or when the values are
    not one column of the file (the drive chain mixed them)."""
    own = f"{role}{j + 1}"
    if names is None or j >= len(names) or names[j] == own:
        return own
    return names[j] if "joint" in names[j] else f"{names[j]} (joint {j + 1})"


def _position_checks(file: str, t: np.ndarray, q: np.ndarray, types: list[int], dt: float, lim: DataChecks,
                     names: Sequence[str] | None = None) -> list[str]:
    msgs: list[str] = []
    for j in range(q.shape[1]):
        col = _column_label("q", j, names)
        qa = np.abs(q[:, j])
        if types[j] == 1:
            if qa.max() > lim.max_abs_prismatic:
                msgs.append(f"{file}, column {col}: max |q| = {qa.max():.4g} > {lim.max_abs_prismatic:g} m "
                            "for a prismatic joint: positions in mm? (expected m; --mm reads millimetres)")
            continue
        if qa.max() > lim.max_abs_position:
            msgs.append(f"{file}, column {col}: max |q| = {qa.max():.4g} > {lim.max_abs_position:.4g} rad: "
                        "positions in degrees (or motor-side without a drive chain)? (expected rad, joint side; "
                        "--deg reads degrees)")
        elif t.size > 2 and dt > 0:
            v = np.abs(np.diff(q[:, j])) / dt
            v99 = float(np.percentile(v, 99))
            if v99 > lim.max_abs_velocity:
                msgs.append(f"{file}, column {col}: velocity {v99:.4g} rad/s (99th percentile) > "
                            f"{lim.max_abs_velocity:g} rad/s: positions in degrees (--deg) or t not in seconds?")
    return msgs


def unit_check_names(c: RawColumns, qrole: str = "q", drive_chain=None) -> dict[str, list[str]]:
    """The file's names of the columns :func:`unit_checks` sees (its ``names``): ``t``, ``q`` (read from the role
    ``qrole``, ``q`` or ``q_link``) and ``tau``; none for ``q`` and ``tau`` after a drive chain, whose joint values
    mix the motor columns (``q_link`` is not mapped)."""
    roles = {"t": "t", "q": qrole, "tau": "tau"}
    if drive_chain is not None:
        roles = {k: v for k, v in roles.items() if k == "t" or v == "q_link"}
    return {k: c.cols[v].names for k, v in roles.items() if v in c.cols}


def unit_checks(src_files: Mapping[str, str], t: np.ndarray, q: np.ndarray, tau: np.ndarray,
                joint_types: Sequence[int] | None, lim: DataChecks,
                names: Mapping[str, Sequence[str]] | None = None) -> list[str]:
    """Messages of the values that look like unit mix-ups (warned about, kept), naming file and column.

    ``names``: the file's own names of the ``q`` and ``tau`` columns (a ``--columns`` mapping, a split file's
    header, an array's key), used in the messages; without them the columns are called ``q1``, ``tau1``...
    """
    names = names or {}
    msgs: list[str] = []
    n = q.shape[1]
    types = list(joint_types) if joint_types is not None else [0] * n
    dt = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    if t.size > 1 and dt > lim.max_dt:
        tcol = (names.get("t") or ["t"])[0]
        msgs.append(f"{src_files['t']}, column {tcol}: median sampling period {dt:.6g} s > {lim.max_dt:g} s: "
                    "time in milliseconds or in samples? (expected seconds)")
    msgs += _position_checks(src_files["q"], t, q, types, dt, lim, names.get("q"))
    ta = np.abs(tau).max(axis=0) if tau.size else np.zeros(n)
    for j in range(n):
        if ta[j] > lim.max_abs_torque:
            col = _column_label("tau", j, names.get("tau"))
            msgs.append(f"{src_files['tau']}, column {col}: max |tau| = {ta[j]:.4g} > {lim.max_abs_torque:g} N m: "
                        "torques in N mm or mN m? (expected N m or N; --tau-scale rescales)")
    return msgs
