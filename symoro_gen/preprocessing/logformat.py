"""Read controller logs as they come: a :class:`LogFormat` (columns, time base, units, resampling,
bad rows) and the :class:`LoadReport` that says what was done to each file.

A lab writes its log format once, as command-line options or as a TOML file with the same keys
(see ``docs/data-files.md``)::

    columns = "t=0,q=1:7,tau=13:19"     # 0-based indices, Python slices (headerless files)
    # columns = "q=q_0:q_6,tau=tau_0:tau_6"   # header names; a name range spans the header inclusively
    dt = 0.01                           # sampling period [s] when there is no time column
    tau_scale = [0.5, 0.5, 0.3]         # logged signal -> N m (one per joint, or one for all)
    deg = false                         # positions (q, q_link, dq, ddq) logged in degrees
    resample = false                    # irregular time stamps -> uniform grid at the median step
    max_gap = 0.05                      # [s] longer steps split the file (default 5 median steps)
    drop_bad_rows = false               # drop malformed / non-finite / absurd rows, counted

Roles: ``t``, ``q``, ``tau`` (``q`` and ``tau`` required), ``dq``, ``ddq``, and ``q_link`` (a second,
link-side position: the model uses it, and the deflection ``q_motor / ratio - q_link`` is kept on
:attr:`Trajectory.deflection`). In ``.npz``/``.mat`` files a role names an array, nested MATLAB
structs with dotted names (``q=rec.act_pos_mot_deg``).

Order of the operations (each one echoed in :class:`LoadReport`): rows with bad values dropped
(``drop_bad_rows``), degrees -> radians, ``tau_scale``, resampling and splitting at gaps, the robot's
drive chain (motor -> joint side), then ``q_link`` replaces ``q``.
"""
from __future__ import annotations

import itertools
import math
import re
import sys
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.interpolate

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

from ..errors import DataFileError, Problem
from ..progress import progress_updates
from .drive_chain import motor_to_joint
from .load import (
    ABSURD_VALUE,
    DataSpec,
    _check_time,
    _Column,
    _fmt_ranges,
    _load_arrays,
    _read_arrays,
    _resolve_csv_columns,
    _runs,
    _unit_checks,
    _warn,
    load_mat,
    load_npy,
    load_trajectory,
    not_text_problem,
    open_problem,
    parse_data_spec,
)
from .trajectory import Trajectory

__all__ = ["LogFormat", "LoadReport", "parse_columns", "read_format_file", "make_format", "load_log", "load_logs",
           "hold_back", "ABSURD_VALUE", "LOG_ROLES"]

LOG_ROLES = ("t", "q", "tau", "dq", "ddq", "q_link")
POSITION_ROLES = ("q", "q_link", "dq", "ddq")
#: default ``max_gap`` in median steps
MAX_GAP_STEPS = 5
MIN_SAMPLES = 32
FORMAT_KEYS = ("columns", "dt", "tau_scale", "deg", "resample", "max_gap", "drop_bad_rows")
DROP_HINT = "give --drop-bad-rows to drop such rows (they are counted in the output)"
RESAMPLE_HINT = ("give --resample to resample irregular time stamps on a uniform grid (gaps longer than "
                 "--max-gap split the file)")


# ---------------------------------------------------------------------------------------------
# the format
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LogFormat:
    """How to read the DATA files of a command (every file of it).

    Attributes
    ----------
    columns : tuple of (role, spec)
        From ``--columns`` (:func:`parse_columns`); empty: the file's own names (module
        :mod:`~symoro_gen.preprocessing.load` defaults).
    dt : float or None
        Sampling period [s] when the file has no time column.
    tau_scale : tuple of float or None
        Factor(s) turning the logged torque signal into N m (one for all joints, or one per joint);
        applied before the drive chain.
    deg : bool
        Positions logged in degrees.
    resample : bool
        Resample irregular time stamps on a uniform grid at the median step (linear interpolation,
        cubic for positions); steps longer than ``max_gap`` split the file.
    max_gap : float or None
        [s]; default ``MAX_GAP_STEPS`` median steps.
    drop_bad_rows : bool
        Drop rows with a wrong number of fields, unparsable or non-finite numbers, or ``|value| >
        ABSURD_VALUE`` (outside the time column); without it such rows are an error naming them.
    origin : str
        Where the format came from (a TOML file), for messages.
    """

    columns: tuple[tuple[str, str], ...] = ()
    dt: float | None = None
    tau_scale: tuple[float, ...] | None = None
    deg: bool = False
    resample: bool = False
    max_gap: float | None = None
    drop_bad_rows: bool = False
    origin: str = ""

    @property
    def column_map(self) -> dict[str, str]:
        return dict(self.columns)

    @property
    def is_plain(self) -> bool:
        """Nothing beyond ``dt``: the loaders of :mod:`~symoro_gen.preprocessing.load` read the file as is."""
        return not (self.columns or self.tau_scale or self.deg or self.resample or self.drop_bad_rows)

    def options(self) -> tuple[str, ...]:
        """The options that change data, as command-line text (echoed in outputs)."""
        out = []
        if self.columns:
            out.append("--columns " + ",".join(f"{k}={v}" for k, v in self.columns))
        if self.dt is not None:
            out.append(f"--dt {self.dt:g}")
        if self.tau_scale:
            out.append("--tau-scale " + ",".join(f"{v:g}" for v in self.tau_scale))
        if self.deg:
            out.append("--deg")
        if self.resample:
            out.append("--resample" + (f" --max-gap {self.max_gap:g}" if self.max_gap is not None else ""))
        if self.drop_bad_rows:
            out.append("--drop-bad-rows")
        return tuple(out)


_INDEX_RX = re.compile(r"^-?\d+(:-?\d*)?$|^:-?\d*$")


def parse_columns(spec: str, *, where: str = "--columns") -> tuple[tuple[str, str], ...]:
    """Parse ``"t=0,q=1:7,tau=13:19"`` or ``"q=q_0:q_6,tau=tau_0:tau_6"`` into (role, selector) pairs.

    Raises
    ------
    DataFileError
        Unknown or repeated role, missing ``=``, empty selector.
    """
    out: dict[str, str] = {}
    for item in str(spec).split(","):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise DataFileError([Problem(where, f"item {item!r}", "", "expected ROLE=COLUMNS, e.g. q=1:7")])
        k, v = (s.strip() for s in item.split("=", 1))
        if k not in LOG_ROLES:
            raise DataFileError([Problem(where, f"item {item!r}", k, f"unknown role (allowed: {', '.join(LOG_ROLES)})")])
        if k in out:
            raise DataFileError([Problem(where, f"item {item!r}", k, "role given twice")])
        if not v:
            raise DataFileError([Problem(where, f"item {item!r}", k, "no column given")])
        out[k] = v
    for k in ("q", "tau"):
        if k not in out:
            raise DataFileError([Problem(where, "", k, f"missing: --columns must say which columns are {k}")])
    return tuple(out.items())


def _floats(v, where, key) -> tuple[float, ...]:
    items = v if isinstance(v, (list, tuple)) else str(v).split(",")
    try:
        out = tuple(float(x) for x in items)
    except (TypeError, ValueError):
        raise DataFileError([Problem(where, "", key, f"{v!r}: expected numbers separated by commas")]) from None
    if not out or not all(math.isfinite(x) and x != 0 for x in out):
        raise DataFileError([Problem(where, "", key, f"{v!r}: factors must be finite and non-zero")])
    return out


def _positive(v, where, key) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        x = float("nan")
    if not (x > 0 and math.isfinite(x)):
        raise DataFileError([Problem(where, "", key, f"{v!r}: must be a positive number of seconds")])
    return x


def read_format_file(path) -> dict:
    """Read a ``--format FILE.toml``: the keys of :class:`LogFormat` (``columns`` as a string or a
    table role -> selector). Unknown keys are an error naming the file and the key."""
    path = str(path)
    try:
        with open(path, "rb") as f:
            d = tomllib.load(f)
    except FileNotFoundError:
        raise DataFileError([Problem(path, "", "", "format file not found")]) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataFileError([Problem(path, "", "", f"not a TOML file: {exc}")]) from None
    bad = [k for k in d if k not in FORMAT_KEYS]
    if bad:
        raise DataFileError([Problem(path, "", bad[0], f"unknown key (allowed: {', '.join(FORMAT_KEYS)})")])
    if isinstance(d.get("columns"), dict):
        d["columns"] = ",".join(f"{k}={v}" for k, v in d["columns"].items())
    for k in ("deg", "resample", "drop_bad_rows"):
        if k in d and not isinstance(d[k], bool):
            raise DataFileError([Problem(path, "", k, f"{d[k]!r}: must be true or false")])
    return d


def make_format(*, columns=None, dt=None, tau_scale=None, deg=None, resample=None, max_gap=None,
                drop_bad_rows=None, format_file=None) -> LogFormat:
    """A :class:`LogFormat` from options (None: not given) over a format file's keys."""
    base = read_format_file(format_file) if format_file else {}
    origin = str(format_file) if format_file else "command line"
    given = dict(columns=columns, dt=dt, tau_scale=tau_scale, deg=deg, resample=resample, max_gap=max_gap,
                 drop_bad_rows=drop_bad_rows)
    where = {k: ("command line" if v is not None else origin) for k, v in given.items()}
    merged = {k: (v if v is not None else base.get(k)) for k, v in given.items()}
    cols = parse_columns(merged["columns"], where=f"{where['columns']}: columns") if merged["columns"] else ()
    return LogFormat(
        columns=cols,
        dt=_positive(merged["dt"], where["dt"], "dt") if merged["dt"] is not None else None,
        tau_scale=_floats(merged["tau_scale"], where["tau_scale"], "tau_scale") if merged["tau_scale"] is not None else None,
        deg=bool(merged["deg"]),
        resample=bool(merged["resample"]),
        max_gap=_positive(merged["max_gap"], where["max_gap"], "max_gap") if merged["max_gap"] is not None else None,
        drop_bad_rows=bool(merged["drop_bad_rows"]),
        origin=str(format_file or ""),
    )


# ---------------------------------------------------------------------------------------------
# provenance
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LoadReport:
    """What reading one DATA file did (echoed in text, JSON ``data`` blocks and reports).

    Attributes
    ----------
    file : str
        The path or split-file spec.
    rows_read : int
        Data rows in the file.
    rows_dropped : int
        Rows dropped by ``--drop-bad-rows``.
    dropped : tuple of str
        Which rows and why (``"rows 12-14 (lines 13-15): wrong number of fields"``).
    resampled : bool
    step_from, step_to : float or None
        Median step of the file and step of the uniform grid [s] (``step_to`` None when not resampled).
    step_jitter : float
        Largest relative deviation of a time step from the median (0 with ``dt``).
    gaps : int
        Steps longer than ``max_gap`` (splits).
    experiments : int
        Experiments after splitting.
    samples : tuple of int
        Samples per experiment.
    options : tuple of str
        Every option that changed data.
    """

    file: str
    rows_read: int
    rows_dropped: int = 0
    dropped: tuple[str, ...] = ()
    resampled: bool = False
    step_from: float | None = None
    step_to: float | None = None
    step_jitter: float = 0.0
    gaps: int = 0
    experiments: int = 1
    samples: tuple[int, ...] = ()
    options: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"file": self.file, "rows_read": self.rows_read, "rows_dropped": self.rows_dropped,
                "dropped": list(self.dropped), "resampled": self.resampled, "step_from": self.step_from,
                "step_to": self.step_to, "step_jitter": self.step_jitter, "gaps": self.gaps,
                "experiments": self.experiments, "samples": list(self.samples), "options": list(self.options),
                "notes": list(self.notes)}

    def summary(self) -> str:
        """One line: ``file: 1647 rows read, 0 dropped, not resampled, 1 experiment (options)``."""
        s = f"{self.file}: {self.rows_read} rows read, {self.rows_dropped} dropped"
        if self.resampled:
            s += f", resampled {self.step_from:.6g} s -> {self.step_to:.6g} s"
        else:
            s += ", not resampled"
        s += f", {self.experiments} experiment{'s' if self.experiments != 1 else ''}"
        if self.gaps:
            s += f" ({self.gaps} gap{'s' if self.gaps != 1 else ''} split)"
        if self.options:
            s += " [" + " ".join(self.options) + "]"
        return s


# ---------------------------------------------------------------------------------------------
# tolerant table reader
# ---------------------------------------------------------------------------------------------
@dataclass
class _Table:
    file: str
    names: list[str] | None
    data: np.ndarray            # (N, k), NaN where unparsable
    lines: np.ndarray           # (N,) file line of each data row
    bad_fields: np.ndarray      # (N,) bool: wrong number of fields
    unparsable: np.ndarray      # (N, k) bool


#: Parquet tables (columns by name, as a CSV header): read by pyarrow, the ``fleet`` extra
PARQUET_SUFFIXES = (".parquet", ".pq")


def _read_parquet_table(path: str) -> _Table:
    """A Parquet file as a table: its column names as the header, row r (1-based) as "line" r; null or
    non-numeric values marked unparsable (then named by row and column like a CSV's)."""
    try:
        import pyarrow.parquet as pq  # type: ignore[import-untyped]
    except ImportError:  # pragma: no cover - depends on the installation
        raise DataFileError([Problem(path, "", "", "Parquet files need pyarrow: pip install 'symoro-gen[fleet]'")]
                            ) from None
    if not Path(path).exists():
        raise DataFileError([Problem(path, "", "", "file not found")])
    try:
        table = pq.read_table(path)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises ArrowInvalid, OSError... on a damaged file
        raise DataFileError([Problem(path, "", "", f"cannot read as Parquet ({type(exc).__name__}: {exc})")]) from None
    N, names = table.num_rows, list(table.column_names)
    data = np.full((N, len(names)), np.nan)
    unparsable = np.zeros((N, len(names)), bool)
    for k, nm in enumerate(names):
        col = table.column(nm)
        try:
            data[:, k] = col.to_numpy(zero_copy_only=False).astype(float)
        except (TypeError, ValueError):
            unparsable[:, k] = True
            continue
        if col.null_count:
            unparsable[:, k] = np.asarray(col.is_null().to_numpy(zero_copy_only=False), bool)
    return _Table(path, names, data, np.arange(1, N + 1), np.zeros(N, bool), unparsable)


def _delimiter(line: str) -> str | None:
    for d in (",", ";", "\t"):
        if d in line:
            return d
    return None


def _num(s: str) -> float | None:
    try:
        return float(s)
    except ValueError:
        return None


def read_table(path: str) -> _Table:
    """Read a delimited numeric text table, keeping every row (bad ones marked, by file line).

    The header (first line with a non-numeric field) is optional. Fast path: :func:`numpy.loadtxt`;
    when it fails, line by line so that every bad row can be named.
    """
    if str(path).lower().endswith(PARQUET_SUFFIXES):
        return _read_parquet_table(path)
    try:
        with open(path, encoding="utf-8-sig") as f:
            text = f.read()
    except OSError as exc:
        raise DataFileError([open_problem(path, exc)]) from None
    except UnicodeDecodeError as exc:
        raise DataFileError([not_text_problem(path, exc)]) from None
    lines = text.splitlines()
    first_i = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first_i is None:
        raise DataFileError([Problem(path, "line 1", "", "empty file (no header, no data)")])
    delim = _delimiter(lines[first_i])

    def split(ln):
        return [s.strip() for s in (ln.split(delim) if delim else ln.split())]

    head = split(lines[first_i])
    has_header = not all(_num(x) is not None for x in head)
    names = head if has_header else None
    ncol = len(head)
    start = first_i + 1 if has_header else first_i
    body = [(i + 1, ln) for i, ln in enumerate(lines[start:], start=start) if ln.strip()]
    N = len(body)
    data = np.full((N, ncol), np.nan)
    unparsable = np.zeros((N, ncol), bool)
    bad_fields = np.zeros(N, bool)
    line_no = np.array([ln for ln, _ in body], int)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fast = np.loadtxt([ln for _, ln in body], delimiter=delim, ndmin=2, dtype=float) if N else None
        if fast is not None and fast.shape == (N, ncol):
            data = fast
            return _Table(path, names, data, line_no, bad_fields, unparsable)
    except ValueError:
        pass
    for r, (_, ln) in enumerate(body):
        parts = split(ln)
        if len(parts) != ncol:
            bad_fields[r] = True
            continue
        for c, s in enumerate(parts):
            x = _num(s)
            if x is None:
                unparsable[r, c] = True
            else:
                data[r, c] = x
    return _Table(path, names, data, line_no, bad_fields, unparsable)


# ---------------------------------------------------------------------------------------------
# column selection
# ---------------------------------------------------------------------------------------------
def _select(table: _Table, sel: str, role: str) -> list[int]:
    """Column indices of a selector: ``3``, ``1:7`` (0-based, Python slice) or ``q_0:q_6`` / ``name``."""
    k = table.data.shape[1]
    where = "header (line 1)" if table.names else ""
    if _INDEX_RX.match(sel):
        if ":" in sel:
            a, b = sel.split(":", 1)
            if (a and not -k <= int(a) < k) or (b and int(b) > k):
                raise DataFileError([Problem(table.file, where, role, f"columns {sel}: the file has {k} columns "
                                             f"(0-based indices 0..{k - 1})")])
            idx = list(range(k))[slice(int(a) if a else None, int(b) if b else None)]
        else:
            i = int(sel)
            idx = [i if i >= 0 else k + i] if -k <= i < k else []
        if not idx or max(idx) >= k:
            raise DataFileError([Problem(table.file, where, role, f"columns {sel}: the file has {k} columns "
                                         f"(0-based indices 0..{k - 1})")])
        return idx
    if table.names is None:
        raise DataFileError([Problem(table.file, "line 1", role, f"column name {sel!r} given, but the file has no "
                                     "header line: select columns by 0-based index, e.g. q=1:7")])
    pos = {nm: i for i, nm in enumerate(table.names)}
    parts = sel.split(":")
    if len(parts) == 1:
        if sel not in pos:
            raise DataFileError([Problem(table.file, where, role, f"no column named {sel!r}; columns are "
                                         f"{', '.join(table.names[:12])}{' ...' if k > 12 else ''}")])
        return [pos[sel]]
    if len(parts) != 2:
        raise DataFileError([Problem(table.file, where, role, f"{sel!r}: expected FIRST:LAST column names")])
    a, b = parts
    for nm in (a, b):
        if nm not in pos:
            raise DataFileError([Problem(table.file, where, role, f"no column named {nm!r}; columns are "
                                         f"{', '.join(table.names[:12])}{' ...' if k > 12 else ''}")])
    if pos[b] < pos[a]:
        raise DataFileError([Problem(table.file, where, role, f"{sel!r}: {b} comes before {a} in the header")])
    return list(range(pos[a], pos[b] + 1))


def _mat_lookup(path: str, fmt: str, key: str):
    """An array by (dotted) name in an .npz, or in a .mat with nested structs."""
    if fmt == "npz" or "." not in key:
        arrays = _load_arrays(path, fmt)
        if key in arrays:
            return np.asarray(arrays[key])
        raise DataFileError([Problem(path, "", key, f"no such array; the file has {', '.join(sorted(arrays))}")])
    d = load_mat(path, simplify_cells=True)
    cur = d
    walked: list[str] = []
    for part in key.split("."):
        if not isinstance(cur, dict) or part not in cur:
            have = sorted(k for k in cur if not k.startswith("__")) if isinstance(cur, dict) else []
            at = ".".join(walked) or "the file"
            raise DataFileError([Problem(path, "", key, f"no field {part!r} in {at}"
                                         + (f" (fields: {', '.join(have)})" if have else " (not a struct)"))])
        cur = cur[part]
        walked.append(part)
    return np.asarray(cur)


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------
@dataclass
class _Cols:
    """Per-role values of one file (rows aligned across roles)."""

    source: str
    fmt: str
    cols: dict[str, _Column] = field(default_factory=dict)
    bad_fields: np.ndarray | None = None      # (N,) wrong number of fields
    unparsable: dict[str, np.ndarray] = field(default_factory=dict)  # role -> (N, k) bool
    lines: np.ndarray | None = None

    @property
    def n_rows(self) -> int:
        return next(iter(self.cols.values())).values.shape[0] if self.cols else 0


def _want(role: str, n: int) -> int:
    return 1 if role == "t" else n


def _read_single_text(path: str, n: int, fmt: LogFormat, dt, probs) -> _Cols:
    tab = read_table(path)
    out = _Cols(path, "csv", bad_fields=tab.bad_fields, lines=tab.lines)
    if fmt.columns:
        sel = {role: _select(tab, s, role) for role, s in fmt.columns}
        if "t" not in sel and dt is None:
            probs.append(Problem(path, "", "t", "no time column in --columns (t=...) and no --dt given"))
    else:
        if tab.names is None:
            raise DataFileError([Problem(path, "line 1", "", "no header line: say which columns are what with "
                                         "--columns, e.g. t=0,q=1:7,tau=7:13 (0-based indices)")])
        sel, _unused = _resolve_csv_columns(path, tab.names, n, None, dt, probs)
    for role, idx in sel.items():
        if len(idx) != _want(role, n):
            probs.append(Problem(path, "header (line 1)" if tab.names else "", role,
                                 f"{len(idx)} column(s) selected, the robot has {n} joints"
                                 + (" (t is one column)" if role == "t" else "")))
            continue
        names = [tab.names[i] if tab.names else f"column {i}" for i in idx]
        off = int(tab.lines[0] - 1) if tab.lines.size else 0
        out.cols[role] = _Column(path, names, tab.data[:, idx], off)
        out.unparsable[role] = tab.unparsable[:, idx]
    return out


def _read_single_arrays(path: str, kind: str, n: int, fmt: LogFormat, dt, probs) -> _Cols:
    out = _Cols(path, kind)
    if not fmt.columns:
        raw = _read_arrays(path, kind, n, None, dt, probs)
        out.cols = dict(raw.cols)
        return out
    cm = fmt.column_map
    if "t" not in cm and dt is None:
        probs.append(Problem(path, "", "t", "no time array in --columns (t=...) and no --dt given"))
    N_t = None
    for role, key in fmt.columns:
        a = _mat_lookup(path, kind, key)
        if not np.issubdtype(a.dtype, np.number):
            probs.append(Problem(path, "", key, f"not numeric (dtype {a.dtype})"))
            continue
        a = a.astype(float)
        if role == "t":
            a = a.reshape(-1) if (a.ndim == 2 and 1 in a.shape) else a
            if a.ndim != 1:
                probs.append(Problem(path, "", key, f"time must be a vector, got shape {a.shape}"))
                continue
            N_t = a.shape[0]
            out.cols["t"] = _Column(path, [key], a[:, None], None)
            continue
        if a.ndim == 1 and n == 1:
            a = a[:, None]
        if a.ndim == 2 and a.shape[1] != n and a.shape[0] == n and (N_t is None or a.shape[1] == N_t):
            a = a.T
        if a.ndim != 2 or a.shape[1] != n:
            probs.append(Problem(path, "", key, f"shape {a.shape}: expected (samples, {n} joints)"))
            continue
        out.cols[role] = _Column(path, [f"{key}[joint {j}]" for j in range(1, n + 1)], a, None)
    lens = {r: c.values.shape[0] for r, c in out.cols.items()}
    if len(set(lens.values())) > 1:
        probs.append(Problem(path, "", "", "arrays have different numbers of samples ("
                             + ", ".join(f"{out.cols[r].names[0].split('[')[0]}: {m}" for r, m in lens.items()) + ")"))
    return out


def _read_split_files(spec: DataSpec, n: int, probs) -> _Cols:
    out = _Cols(spec.text, "split")
    bad = None
    for role, path in spec.files.items():
        if path.endswith(".npy"):
            a = load_npy(path)
            a = a[:, None] if a.ndim == 1 else a
            names, off, unp, bf = [f"column {c}" for c in range(a.shape[1])], None, np.zeros(a.shape, bool), None
        else:
            tab = read_table(path)
            a, unp, bf = tab.data, tab.unparsable, tab.bad_fields
            names = tab.names or [f"column {c}" for c in range(a.shape[1])]
            off = int(tab.lines[0] - 1) if tab.lines.size else 0
        if a.shape[1] != _want(role, n):
            probs.append(Problem(path, "header" if off else "", role, f"{a.shape[1]} columns, expected "
                                 f"{_want(role, n)}" + (f" ({role} of {n} joints)" if role != "t" else " (time)")))
            continue
        out.cols[role] = _Column(path, names, a, off)
        out.unparsable[role] = unp
        if bf is not None:
            bad = bf if bad is None or bad.shape != bf.shape else (bad | bf)
    lens = {r: c.values.shape[0] for r, c in out.cols.items()}
    if len(set(lens.values())) > 1:
        probs.append(Problem(spec.text, "", "", "the files of a split recording must have the same number of rows; "
                             + ", ".join(f"{spec.files[r]} ({r}): {m} rows" for r, m in lens.items())))
    out.bad_fields = bad
    return out


def _bad_rows(c: _Cols, n: int) -> tuple[np.ndarray, list[Problem]]:
    """Rows with a wrong field count, unparsable, non-finite or absurd values; one Problem per kind and column."""
    N = c.n_rows
    drop = np.zeros(N, bool)
    probs: list[Problem] = []
    if c.bad_fields is not None and c.bad_fields.shape == (N,) and c.bad_fields.any():
        drop |= c.bad_fields
        f = next(iter(c.cols.values()))
        probs.append(Problem(f.file, _fmt_ranges(_runs(c.bad_fields), f.line_offset), "",
                             f"{int(c.bad_fields.sum())} row(s) with the wrong number of fields"))
    for role, col in c.cols.items():
        v = col.values
        unp = c.unparsable.get(role, np.zeros(v.shape, bool))
        if c.bad_fields is not None and c.bad_fields.shape == (N,):
            unp = unp & ~c.bad_fields[:, None]
        nonfin = ~np.isfinite(v) & ~unp
        if c.bad_fields is not None and c.bad_fields.shape == (N,):
            nonfin &= ~c.bad_fields[:, None]
        absurd = np.zeros(v.shape, bool) if role == "t" else (np.abs(np.nan_to_num(v)) > ABSURD_VALUE)
        for mask, what in ((unp, "unparsable value(s)"), (nonfin, "non-finite value(s) (NaN/inf)"),
                           (absurd, f"absurd value(s) (|value| > {ABSURD_VALUE:g})")):
            for k in np.flatnonzero(mask.any(axis=0)):
                rows = mask[:, k]
                drop |= rows
                probs.append(Problem(col.file, _fmt_ranges(_runs(rows), col.line_offset), col.names[k],
                                     f"{int(rows.sum())} {what}"))
    return drop, probs


def _resample(t: np.ndarray, arrays: dict[str, np.ndarray], h: float, max_gap: float
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


def load_log(path, fmt: LogFormat | None = None, *, n_joints: int | None = None, robot=None, drive_chain=None,
             loaded: bool = False, base_dir=None) -> tuple[tuple[Trajectory, ...], LoadReport]:
    """Read one DATA file (or split-file spec) with a :class:`LogFormat`.

    Parameters
    ----------
    path : str or PathLike
        A ``.csv``/``.txt``/``.npz``/``.mat`` file or a ``q=..,tau=..,dt=..`` spec.
    fmt : LogFormat, optional
        Default: the file's own names (plain reading by :func:`~symoro_gen.preprocessing.load.load_trajectory`).
    n_joints, robot, drive_chain, loaded, base_dir
        As for :func:`~symoro_gen.preprocessing.load.load_trajectory`.

    Returns
    -------
    (trajectories, report)
        One trajectory per experiment (a file splits at gaps with ``resample``), and what was done.

    Raises
    ------
    DataFileError
        One line per problem, naming the file, rows (and file lines) and column.
    """
    fmt = fmt or LogFormat()
    if robot is not None and n_joints is None:
        n_joints = len(robot.model_joints)
    if n_joints is None:
        raise TypeError("load_log: give n_joints or robot")
    n = int(n_joints)
    spec = path if isinstance(path, DataSpec) else parse_data_spec(path, base_dir=base_dir)
    if spec.dt is not None and fmt.dt is not None and not math.isclose(spec.dt, fmt.dt, rel_tol=1e-12):
        raise DataFileError([Problem(spec.text, "", "dt", f"the spec says dt = {spec.dt:g} s, --dt {fmt.dt:g}: "
                                     "give the sampling period once")])
    dt = fmt.dt if fmt.dt is not None else spec.dt
    if fmt.is_plain and not (not spec.is_split and spec.files["file"].lower().endswith(PARQUET_SUFFIXES)):
        tr = load_trajectory(spec, n_joints=n, robot=robot, drive_chain=drive_chain, loaded=loaded, dt=dt)
        rep = LoadReport(file=tr.source, rows_read=tr.n_samples, step_from=tr.meta.get("dt_median"),
                         step_jitter=float(tr.meta.get("dt_max_rel_jitter", 0.0)), samples=(tr.n_samples,),
                         options=fmt.options())
        return (tr,), rep
    probs: list[Problem] = []
    if spec.is_split:
        if fmt.columns:
            raise DataFileError([Problem(spec.text, "", "columns", "--columns cannot be used with a split-file "
                                         "spec (each file holds one role)")])
        c = _read_split_files(spec, n, probs)
        if "t" not in spec.files and dt is None:
            probs.append(Problem(spec.text, "", "dt", "a split recording without a t= file needs dt= (or --dt)"))
    else:
        file = spec.files["file"]
        if not Path(file).exists():
            raise DataFileError([Problem(file, "", "", "file not found")])
        suffix = Path(file).suffix.lower()
        if suffix in (".csv", ".txt", ".tsv", ".dat", *PARQUET_SUFFIXES):
            c = _read_single_text(file, n, fmt, dt, probs)
        elif suffix in (".npz", ".mat"):
            c = _read_single_arrays(file, suffix[1:], n, fmt, dt, probs)
        else:
            raise DataFileError([Problem(file, "", "", f"unknown data format {suffix!r} "
                                         "(expected .csv, .txt, .npz, .mat, .parquet or a q=...,tau=... spec)")])
    if probs:
        raise DataFileError(probs)
    source = c.source
    N = c.n_rows
    drop, bad = _bad_rows(c, n)
    dropped_txt: tuple[str, ...] = ()
    if bad:
        if not fmt.drop_bad_rows:
            raise DataFileError(bad, hint=DROP_HINT)
        dropped_txt = tuple(f"{p.where}{', ' + p.field if p.field else ''}: {p.message}" for p in bad)
    keep = ~drop
    vals = {r: col.values[keep] for r, col in c.cols.items()}
    if not keep.any():
        raise DataFileError([Problem(source, f"rows 1-{N}", "", "every row is bad")])
    opts = list(fmt.options())
    # units
    if fmt.deg:
        for r in POSITION_ROLES:
            if r in vals:
                vals[r] = np.deg2rad(vals[r])
    if fmt.tau_scale:
        s = np.asarray(fmt.tau_scale, float)
        if s.size not in (1, n):
            raise DataFileError([Problem(source, "", "tau_scale", f"{s.size} factors given, the robot has {n} "
                                         "joints: give one per joint or one for all")])
        vals["tau"] = vals["tau"] * s
    # time base
    if "t" in vals and dt is not None:
        _warn(f"{c.cols['t'].file}, column {c.cols['t'].names[0]}: ignored, the time base is dt = {dt:g} s")
        vals.pop("t")
    rows = np.flatnonzero(keep)
    if "t" in vals:
        t = vals.pop("t")[:, 0]
        tcol = c.cols["t"]
        d = np.diff(t)
        tprobs: list[Problem] = []
        if fmt.resample:
            if (d <= 0).any():
                back = np.flatnonzero(d <= 0)
                raise DataFileError([Problem(tcol.file, _fmt_ranges(_runs(np.isin(np.arange(N), rows[back + 1])),
                                                                    tcol.line_offset), tcol.names[0],
                                             f"time is not strictly increasing ({back.size} step(s) <= 0): "
                                             "resampling cannot order it")])
        else:
            shifted = bool(drop.any())  # rows then count the kept rows: say so, give no file lines
            col = _Column(tcol.file, tcol.names, t[:, None], None if shifted else tcol.line_offset)
            _check_time(t, col, 0.5, tprobs)
            if tprobs:
                if shifted:
                    tprobs = [Problem(p.file, f"{p.where} of the {rows.size} rows kept", p.field, p.message)
                              for p in tprobs]
                raise DataFileError(tprobs, hint=RESAMPLE_HINT)
    else:
        assert dt is not None  # without a time column dt is required (checked when the columns were chosen)
        t = np.arange(rows.size) * float(dt)
        d = np.diff(t)
    h = float(np.median(d)) if d.size else float("nan")
    jitter = float(np.abs(d - h).max() / h) if d.size else 0.0
    pieces = [(t, vals)]
    gaps = 0
    resampled = False
    if fmt.resample and d.size and (jitter > 1e-6):
        max_gap = fmt.max_gap if fmt.max_gap is not None else MAX_GAP_STEPS * h
        pieces, gaps = _resample(t, vals, h, max_gap)
        resampled = True
    notes = []
    kept = []
    for tt, vv in pieces:
        if tt.size < MIN_SAMPLES:
            notes.append(f"a piece of {tt.size} samples from t = {tt[0]:.6g} s is too short to filter: left out")
            continue
        kept.append((tt, vv))
    if not kept:
        raise DataFileError([Problem(source, f"rows 1-{N}", "", f"too short to filter: no piece of at least "
                                     f"{MIN_SAMPLES} samples")])
    trajs = []
    joint_types = [r.sigma for r in robot.model_joints] if robot is not None else None
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
        src = source if len(kept) == 1 else f"{source} [experiment {k + 1}/{len(kept)}]"
        if k == 0:
            files = {"t": c.cols["t"].file if "t" in c.cols else source, "q": c.cols["q"].file,
                     "tau": c.cols["tau"].file}
            for msg in _unit_checks(files, tt, q, tau, joint_types, max_abs_position=4 * math.pi,
                                    max_abs_velocity=50.0, max_abs_prismatic=5.0, max_abs_torque=1e4, max_dt=0.1):
                _warn(msg)
        meta = {"format": c.fmt, "files": {r: col.file for r, col in c.cols.items()},
                "columns": {r: list(col.names) for r, col in c.cols.items()}, "drive_chain": drive_chain is not None,
                "t_from_dt": "t" not in c.cols or dt is not None, "dt_median": h, "dt_max_rel_jitter": jitter,
                "options": tuple(opts), "experiment": k + 1}
        trajs.append(Trajectory(t=tt, q=q, tau=tau, dq=dq, ddq=ddq, source=src, loaded=bool(loaded), meta=meta,
                                deflection=defl))
    rep = LoadReport(file=source, rows_read=N, rows_dropped=int(drop.sum()), dropped=dropped_txt,
                     resampled=resampled, step_from=h, step_to=h if resampled else None, step_jitter=jitter, gaps=gaps,
                     experiments=len(trajs), samples=tuple(tr.n_samples for tr in trajs), options=tuple(opts),
                     notes=tuple(notes))
    return tuple(trajs), rep


def load_logs(paths: Iterable, fmt: LogFormat | None = None, *, progress=None, **kwargs
              ) -> tuple[tuple[Trajectory, ...], tuple[LoadReport, ...]]:
    """:func:`load_log` on several files; the problems of all files are raised together.

    ``progress``: as for :func:`~symoro_gen.preprocessing.load.load_trajectories` (a per-file bar
    on the command line)."""
    paths = list(paths)
    trajs: list[Trajectory] = []
    reps: list[LoadReport] = []
    probs: list[Problem] = []
    hint = None
    with progress_updates(progress, total=len(paths), desc="loading data", unit="file") as step:
        for p in paths:
            try:
                tr, rep = load_log(p, fmt, **kwargs)
            except DataFileError as exc:
                probs.extend(exc.problems)
                hint = hint or exc.hint
                step(1)
                continue
            trajs.extend(tr)
            reps.append(rep)
            step(1)
    if probs:
        raise DataFileError(probs, hint=hint)
    return tuple(trajs), tuple(reps)


def hold_back(trajectories: Sequence[Trajectory], fraction: float
              ) -> tuple[tuple[Trajectory, ...], tuple[Trajectory, ...]]:
    """Split each experiment in time: the first ``1 - fraction`` for identification, the last
    ``fraction`` for validation (a held-back part of the same recording)."""
    if not 0 < fraction < 1:
        raise ValueError(f"the held-back fraction must lie between 0 and 1, got {fraction:g}")
    ident, valid = [], []
    for tr in trajectories:
        k = int(round(tr.n_samples * (1 - fraction)))

        def part(a, b, tag, tr=tr):
            cut = {f: (getattr(tr, f)[a:b] if getattr(tr, f) is not None else None)
                   for f in ("t", "q", "tau", "dq", "ddq", "deflection")}
            return replace(tr, **cut, source=f"{tr.source} [{tag}]", meta={**tr.meta, "part": tag})

        ident.append(part(0, k, f"first {100 * (1 - fraction):.3g} %"))
        valid.append(part(k, tr.n_samples, f"last {100 * fraction:.3g} %"))
    return tuple(ident), tuple(valid)
