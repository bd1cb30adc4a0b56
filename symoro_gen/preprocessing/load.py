"""Load measured trajectories (one file = one experiment) into :class:`Trajectory`.

Formats
-------
**CSV** (one experiment per file). A header line names the columns; by default::

    t, q1..qn, tau1..taun [, dq1..dqn] [, ddq1..ddqn]

(``,``, ``;``, tab or blank separated). ``columns`` renames them: a mapping from the roles
``"t" "q" "tau" "dq" "ddq"`` to a template with ``{j}`` (the 1-based joint number, e.g.
``{"q": "pos_{j}", "tau": "cur_{j}"}``), to an explicit list of ``n`` names, or for ``"t"`` to one
name. Without a time column give ``dt``. Columns that no role uses are listed in
``Trajectory.meta["unused"]``.

**NPZ** / **MATLAB .mat** (``scipy.io.loadmat``, formats up to v7; v7.3/HDF5 is refused with a hint).
Arrays are looked up by key: ``t``/``time``/``times``, ``q``/``positions``/``position``/``pos``,
``tau``/``torques``/``torque``/``effort``, and optionally ``dq``/``velocities``/``velocity`` and
``ddq``/``accelerations``/``acceleration`` (``columns`` maps a role to another key). Arrays are
``(N, n)``; ``(n, N)`` (MATLAB habit) is transposed when unambiguous. This reads the LWR4
recordings of FloBaRoID (``times/positions/torques``, plus their velocities/accelerations).

**Split recordings: a spec string** (usable from a command line), for data spread over several
files without a time column, like the Staubli TX40 one::

    q=pos_read_data.csv,tau=curr_data.csv,dt=0.0002

Items are ``key=value`` separated by commas: ``q``, ``tau`` (required), ``dq``, ``ddq``, ``t``
are files (CSV/TXT with one column per joint, header line optional, or ``.npy``); ``dt`` (sampling
period [s]) or ``fs`` (sampling frequency [Hz]) give the time base when there is no ``t`` file;
``loaded`` (``true``/``false``) says whether the payload is mounted. Relative paths are resolved
against ``base_dir`` (default: the current directory). A plain path (no ``=``) is a single file.

Drive chain
-----------
``drive_chain`` (a :class:`~symoro_gen.description.model.DriveChain`, usually
``robot.drive_chain``) says the data are motor-side: positions, velocities, accelerations and
torques are mapped to the joint side by :func:`~symoro_gen.preprocessing.drive_chain.motor_to_joint`.

Checks
------
Problems are collected and raised together as one :class:`~symoro_gen.errors.DataFileError` whose
entries name the file, the column and the rows (1-based data rows; for CSV the file lines too):
non-numeric or missing values, NaN/inf, a column count that does not match the robot, files of a
split recording with different lengths, non-increasing time, irregular time steps (deviating more
than ``time_jitter_tol`` x the median step; gaps count), recordings too short to filter. Values that
look like unit mix-ups give a :class:`DataWarning` naming file and column: revolute positions beyond
``max_abs_position`` [rad] or moving faster than ``max_abs_velocity`` [rad/s] (degrees?), prismatic
positions beyond ``max_abs_prismatic`` [m] (mm?), torques beyond ``max_abs_torque`` [N m], a
sampling period above ``max_dt`` [s] (ms?). Nothing is dropped: every row of the file is in the
returned trajectory.
"""
from __future__ import annotations

import math
import os
import re
import warnings
import zipfile
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn

import numpy as np
import scipy.io

from ..errors import DataFileError, Problem
from ..progress import progress_updates
from .drive_chain import motor_to_joint
from .trajectory import Trajectory

__all__ = [
    "DataWarning",
    "DataSpec",
    "parse_data_spec",
    "load_trajectory",
    "load_trajectories",
]

ROLES = ("t", "q", "tau", "dq", "ddq")
JOINT_ROLES = ("q", "tau", "dq", "ddq")
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
#: Every loader (this module's, :mod:`~symoro_gen.preprocessing.logformat`'s) rejects such values.
ABSURD_VALUE = 1e6
#: hint of the errors about bad values (non-finite, absurd)
BAD_VALUE_HINT = ("fix or remove these rows; the command line's --drop-bad-rows drops them (counted in the "
                  "output)")
#: hint of the errors about the time column
TIME_HINT = ("the command line's --resample puts irregular time stamps on a uniform grid (gaps longer than "
             "--max-gap split the file); --dt SECONDS ignores the time column")
#: what reading a damaged .npz/.npy can raise (zip directory, CRC, truncated or garbled members)
_ARCHIVE_ERRORS = (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


class DataWarning(UserWarning):
    """A data value looks wrong (unit mix-up...) but is kept."""


# ---------------------------------------------------------------------------------------------
# spec strings
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DataSpec:
    """A parsed data spec (see the module docstring).

    Attributes
    ----------
    files : dict
        Role (``"q"``, ``"tau"``, ``"dq"``, ``"ddq"``, ``"t"``, or ``"file"`` for a single file) -> path.
    dt : float or None
        Sampling period [s].
    loaded : bool or None
        Payload mounted (None: not said).
    text : str
        The original spec.
    """

    files: Mapping[str, str]
    dt: float | None = None
    loaded: bool | None = None
    text: str = ""

    @property
    def is_split(self) -> bool:
        return "file" not in self.files


_SPEC_KEYS = {"q", "tau", "dq", "ddq", "t", "dt", "fs", "loaded", "file"}


def _parse_bool(v: str) -> bool | None:
    v = v.strip().lower()
    if v in ("1", "true", "yes", "y", "on"):
        return True
    if v in ("0", "false", "no", "n", "off"):
        return False
    return None


def parse_data_spec(spec: str | os.PathLike, *, base_dir: str | os.PathLike | None = None) -> DataSpec:
    """Parse ``"q=pos.csv,tau=curr.csv,dt=0.0002"`` (or a plain path) into a :class:`DataSpec`.

    Raises
    ------
    DataFileError
        Unknown key, malformed item, missing ``q`` or ``tau``, bad number.
    """
    text = os.fspath(spec)
    base = Path(base_dir) if base_dir is not None else None

    def resolve(p: str) -> str:
        pp = Path(p.strip())
        return str(base / pp) if (base is not None and not pp.is_absolute()) else str(pp)

    if "=" not in text or Path(text).exists():
        return DataSpec(files={"file": resolve(text)}, text=text)
    files: dict[str, str] = {}
    dt = None
    loaded = None
    probs: list[Problem] = []
    seen_time: set[str] = set()
    empty: set[str] = set()  # keys given without a file (reported once, not again as missing)
    for item in text.split(","):
        if not item.strip():
            continue
        if "=" not in item:
            probs.append(Problem(text, f"item {item!r}", "", "expected key=value"))
            continue
        k, v = (s.strip() for s in item.split("=", 1))
        if k not in _SPEC_KEYS:
            probs.append(Problem(text, f"item {item!r}", k, f"unknown key (allowed: {', '.join(sorted(_SPEC_KEYS))})"))
        elif k in ("dt", "fs"):
            if k in seen_time:
                probs.append(Problem(text, f"item {item!r}", k, f"{k}= given twice; give the time base once"))
            elif seen_time:
                other = next(iter(seen_time))
                probs.append(Problem(text, f"item {item!r}", k, f"conflicts with {other}=: give either dt= "
                                     "(sampling period [s]) or fs= (sampling frequency [Hz]), not both"))
            seen_time.add(k)
            try:
                x = float(v)
            except ValueError:
                x = float("nan")
            if not (x > 0 and math.isfinite(x)):
                probs.append(Problem(text, f"item {item!r}", k, "must be a positive number"))
            else:
                dt = x if k == "dt" else 1.0 / x
        elif k == "loaded":
            b = _parse_bool(v)
            if b is None:
                probs.append(Problem(text, f"item {item!r}", k, "must be true or false"))
            loaded = b
        elif not v:
            probs.append(Problem(text, f"item {item!r}", k, "no file given"))
            empty.add(k)
        else:
            files[k] = resolve(v)
    if "file" in files and len(files) > 1:
        probs.append(Problem(text, "", "file", "'file=' cannot be combined with q=/tau=/... files"))
    if "file" not in files:
        for k in ("q", "tau"):
            if k not in files and k not in empty:
                probs.append(Problem(text, "", k, f"missing: a split recording needs {k}=FILE"))
    if probs:
        raise DataFileError(probs)
    return DataSpec(files=files, dt=dt, loaded=loaded, text=text)


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """1-based inclusive (start, end) ranges where mask is True."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    starts = np.r_[idx[0], idx[cut + 1]]
    ends = np.r_[idx[cut], idx[-1]]
    return [(int(a) + 1, int(b) + 1) for a, b in zip(starts, ends)]


def _fmt_ranges(runs: list[tuple[int, int]], line_offset: int | None = None) -> str:
    def one(a, b):
        return f"{a}" if a == b else f"{a}-{b}"

    shown = runs[:MAX_RANGES_SHOWN]
    s = "rows " + ", ".join(one(a, b) for a, b in shown)
    if line_offset is not None:
        s += " (lines " + ", ".join(one(a + line_offset, b + line_offset) for a, b in shown) + ")"
    if len(runs) > MAX_RANGES_SHOWN:
        s += f" and {len(runs) - MAX_RANGES_SHOWN} more ranges"
    return s


@dataclass
class _Column:
    """One role's data as read from one file (before checks)."""

    file: str
    names: list[str]
    values: np.ndarray  # (N, k)
    line_offset: int | None  # data row r (1-based) is file line r + offset; None for binary files


@dataclass
class _Raw:
    cols: dict[str, _Column] = field(default_factory=dict)
    unused: list[str] = field(default_factory=list)
    fmt: str = ""


def _detect_delimiter(line: str) -> str | None:
    for d in (",", ";", "\t"):
        if d in line:
            return d
    return None


def _split(line: str, delim: str | None) -> list[str]:
    return [s.strip() for s in (line.split(delim) if delim else line.split())]


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


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


def _read_text_table(path: str, *, header_required: bool) -> tuple[list[str] | None, np.ndarray, int]:
    """Read a delimited numeric table. Returns (header names or None, values (N, k), header lines)."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            first = f.readline()
    except OSError as exc:
        raise DataFileError([open_problem(path, exc)]) from None
    except UnicodeDecodeError as exc:
        raise DataFileError([not_text_problem(path, exc)]) from None
    if not first.strip():
        raise DataFileError([Problem(path, "line 1", "", "empty file (no header, no data)")])
    delim = _detect_delimiter(first)
    fields = _split(first.rstrip("\r\n"), delim)
    has_header = not all(_is_number(x) for x in fields)
    if header_required and not has_header:
        raise DataFileError([Problem(path, "line 1", "", "no header line: the columns must be named "
                                     "(t, q1..qn, tau1..taun), or give a columns mapping")])
    names = fields if has_header else None
    skip = 1 if has_header else 0
    ncol = len(fields)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(path, delimiter=delim, skiprows=skip, ndmin=2, dtype=float, encoding="utf-8-sig")
    except UnicodeDecodeError as exc:  # a stray byte further down (a ValueError: before the clause below)
        raise DataFileError([not_text_problem(path, exc)]) from None
    except ValueError:
        data = None
    if data is None or (data.size and data.shape[1] != ncol):
        _raise_parse_problems(path, delim, skip, ncol, names)
    if data.size == 0:
        data = np.zeros((0, ncol))
    return names, data, skip


def _raise_parse_problems(path, delim, skip, ncol, names) -> NoReturn:
    probs: list[Problem] = []
    bad_count: list[int] = []
    bad_value: dict[str, list[tuple[int, str]]] = {}
    try:
        with open(path, encoding="utf-8-sig") as f:
            text_lines = list(f)
    except UnicodeDecodeError as exc:
        raise DataFileError([not_text_problem(path, exc)]) from None
    for lineno, line in enumerate(text_lines, start=1):
        if lineno <= skip or not line.strip():
            continue
        parts = _split(line.rstrip("\r\n"), delim)
        if len(parts) != ncol:
            bad_count.append(lineno)
            continue
        for c, s in enumerate(parts):
            if not _is_number(s):
                col = names[c] if names else f"column {c + 1}"
                bad_value.setdefault(col, []).append((lineno, s))
    if bad_count:
        runs = _runs(np.isin(np.arange(max(bad_count) + 1), bad_count))
        probs.append(Problem(path, _fmt_ranges([(a - 1, b - 1) for a, b in runs]).replace("rows", "lines"), "",
                             f"wrong number of fields (expected {ncol} as on line {skip or 1})"))
    for col, items in bad_value.items():
        lines = [ln for ln, _ in items]
        runs = _runs(np.isin(np.arange(max(lines) + 1), lines))
        shown = ", ".join(repr(s) for _, s in items[:3])
        probs.append(Problem(path, _fmt_ranges([(a - skip - 1, b - skip - 1) for a, b in runs], skip),
                             col, f"{len(items)} missing or non-numeric value(s): {shown}"))
    if not probs:
        probs.append(Problem(path, "", "", "cannot parse the file as a numeric table"))
    raise DataFileError(probs)


def _template_regex(tmpl: str) -> re.Pattern:
    if "{j}" not in tmpl:
        raise ValueError(f"column template {tmpl!r} must contain '{{j}}'")
    a, b = tmpl.split("{j}", 1)
    return re.compile("^" + re.escape(a) + r"(\d+)" + re.escape(b) + "$")


def _fmt_names(names: Sequence[str]) -> str:
    return ", ".join(names) if len(names) <= 8 else ", ".join(list(names[:3]) + ["..."] + list(names[-2:]))


def _resolve_csv_columns(path, names, n, columns, dt, probs) -> tuple[dict[str, list[int]], list[str]]:
    """Column indices per role for a single-file CSV."""
    columns = dict(columns or {})
    for k in columns:
        if k not in ROLES:
            raise ValueError(f"unknown role {k!r} in columns mapping (allowed: {', '.join(ROLES)})")
    where = "header (line 1)"
    pos = {nm: i for i, nm in enumerate(names)}
    out: dict[str, list[int]] = {}
    # time
    tspec = columns.get("t")
    if tspec is not None:
        if tspec not in pos:
            probs.append(Problem(path, where, str(tspec), f"time column not found; columns are {_fmt_names(names)}"))
        else:
            out["t"] = [pos[tspec]]
    else:
        lower = {nm.lower(): i for i, nm in enumerate(names)}
        for cand in DEFAULT_KEYS["t"]:
            if cand in lower:
                out["t"] = [lower[cand]]
                break
    if "t" not in out and dt is None and tspec is None:
        probs.append(Problem(path, where, "t", f"no time column ({', '.join(DEFAULT_KEYS['t'])}) and no dt given"))
    for role in JOINT_ROLES:
        spec = columns.get(role, CSV_TEMPLATES[role])
        required = role in ("q", "tau")
        if isinstance(spec, str):
            rx = _template_regex(spec)
            found = {}
            for i, nm in enumerate(names):
                m = rx.match(nm)
                if m:
                    found[int(m.group(1))] = i
            if not found:
                if required:
                    probs.append(Problem(path, where, spec.replace("{j}", "*"),
                                         f"no {role} columns (expected {spec.format(j=1)}..{spec.format(j=n)}); "
                                         f"columns are {_fmt_names(names)}"))
                continue
            want = set(range(1, n + 1))
            if set(found) != want:
                have = [names[found[j]] for j in sorted(found)]
                missing = [spec.format(j=j) for j in sorted(want - set(found))]
                extra = [spec.format(j=j) for j in sorted(set(found) - want)]
                msg = f"wrong column count for the robot: the robot has {n} joints, the file has {len(found)} " \
                      f"{role} columns ({_fmt_names(have)})"
                if missing:
                    msg += f"; missing {_fmt_names(missing)}"
                if extra:
                    msg += f"; unexpected {_fmt_names(extra)}"
                probs.append(Problem(path, where, spec.replace("{j}", "*"), msg))
                continue
            out[role] = [found[j] for j in range(1, n + 1)]
        else:
            lst = list(spec)
            if len(lst) != n:
                probs.append(Problem(path, where, role, f"wrong column count for the robot: {len(lst)} names "
                                     f"given for {role}, the robot has {n} joints"))
                continue
            miss = [nm for nm in lst if nm not in pos]
            if miss:
                probs.append(Problem(path, where, role, f"columns not found: {_fmt_names(miss)}; "
                                     f"columns are {_fmt_names(names)}"))
                continue
            out[role] = [pos[nm] for nm in lst]
    used = {i for v in out.values() for i in v}
    unused = [nm for i, nm in enumerate(names) if i not in used]
    return out, unused


def _read_csv(path: str, n: int, columns, dt, probs) -> _Raw:
    names, data, skip = _read_text_table(path, header_required=True)
    assert names is not None  # header_required
    idx, unused = _resolve_csv_columns(path, names, n, columns, dt, probs)
    raw = _Raw(fmt="csv", unused=unused)
    for role, ii in idx.items():
        raw.cols[role] = _Column(path, [names[i] for i in ii], data[:, ii], skip)
    return raw


def _load_arrays(path: str, fmt: str) -> dict[str, np.ndarray]:
    if fmt == "npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                return {k: np.asarray(z[k]) for k in z.files}
        except FileNotFoundError:
            raise DataFileError([Problem(path, "", "", "file not found")]) from None
        except _ARCHIVE_ERRORS as exc:
            # never relay numpy's advice to allow pickles: say what the file is instead
            raise DataFileError([Problem(path, "", "", f"not a readable NumPy .npz archive ({_what_file(path)}"
                                         f"{_archive_detail(exc)})")],
                                hint="save arrays with numpy.savez(path, t=..., q=..., tau=...); a text table "
                                     "must end in .csv or .txt") from None
    d = load_mat(path, squeeze_me=False)
    return {k: np.asarray(v) for k, v in d.items() if not k.startswith("__")}


def load_mat(path: str, **kwargs) -> dict:
    """:func:`scipy.io.loadmat` with every failure as a one-line :class:`DataFileError` naming the file.

    scipy's MATLAB reader meets damaged files with whatever its parser hits first (``IndexError``,
    ``struct.error``, ``MatReadError``, ``zlib.error``...), so any exception from it is a bad file.
    """
    try:
        return scipy.io.loadmat(path, **kwargs)
    except FileNotFoundError:
        raise DataFileError([Problem(path, "", "", "file not found")]) from None
    except NotImplementedError:
        raise DataFileError([Problem(path, "", "", "MATLAB v7.3 (HDF5) files are not supported")],
                            hint="save with save(..., '-v7') or export to CSV/NPZ") from None
    except (MemoryError, RecursionError):
        raise DataFileError([Problem(path, "", "", "cannot read as a MATLAB file: its headers declare "
                                     "impossible sizes (damaged?)")]) from None
    except Exception as exc:  # noqa: BLE001 - a damaged file reaches any line of scipy's parser
        raise DataFileError([Problem(path, "", "", f"cannot read as a MATLAB file ({_what_file(path, 'mat')}; "
                                     f"{type(exc).__name__}: {_one_line(exc)})")],
                            hint="save with MATLAB's save(..., '-v7') or scipy.io.savemat, or export to "
                                 "CSV/NPZ") from None


def _one_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


def _archive_detail(exc: BaseException) -> str:
    """``; damaged: ...`` for archive errors worth naming (CRC, truncation), never numpy's pickle advice."""
    if isinstance(exc, (zipfile.BadZipFile, zlib.error, EOFError)):
        return f"; damaged: {_one_line(exc)}"
    return ""


def load_npy(path: str) -> np.ndarray:
    """One ``.npy`` array as floats; a missing, damaged or non-numeric file is a :class:`DataFileError`
    naming it (never numpy's advice to allow pickles)."""
    try:
        a = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise DataFileError([Problem(path, "", "", "file not found")]) from None
    except IsADirectoryError:
        raise DataFileError([Problem(path, "", "", "is a folder, not a .npy file")]) from None
    except _ARCHIVE_ERRORS as exc:
        what = _what_file(path)
        if what.startswith("a single .npy"):
            what = "its header is .npy but the data are damaged or cut short"
        detail = "" if "pickle" in str(exc) else f": {_one_line(exc)}"
        raise DataFileError([Problem(path, "", "", f"not a readable NumPy .npy array ({what}{detail})")],
                            hint="save one array with numpy.save(path, array) (samples x joints)") from None
    if isinstance(a, np.lib.npyio.NpzFile):
        a.close()
        raise DataFileError([Problem(path, "", "", "an .npz archive, not a single .npy array")])
    if not np.issubdtype(a.dtype, np.number) and a.dtype != bool:
        raise DataFileError([Problem(path, "", "", f"not numeric (dtype {a.dtype})")])
    a = a.astype(float)
    if a.ndim not in (1, 2):
        raise DataFileError([Problem(path, "", "", f"must be a 1-D or 2-D (samples x joints) array, got shape "
                                     f"{a.shape}")])
    return a


def _what_file(path: str, expected: str = "npz") -> str:
    """A few words on what a file that failed to load (as an ``expected`` kind) really is."""
    try:
        with open(path, "rb") as f:
            head = f.read(512)
    except OSError as exc:
        return exc.strerror or "unreadable"
    if not head:
        return "the file is empty"
    if head.startswith(b"\x93NUMPY"):
        return "a single .npy array, not an .npz archive"
    if head.startswith(b"PK"):
        return "a zip archive without readable .npy members" if expected == "npz" else "a zip archive, e.g. an .npz"
    try:
        head.decode("utf-8")
        return "the file is text, e.g. a CSV table"
    except UnicodeDecodeError:
        return "unknown binary content"


def _read_arrays(path: str, fmt: str, n: int, columns, dt, probs) -> _Raw:
    arrays = _load_arrays(path, fmt)
    columns = dict(columns or {})
    for k in columns:
        if k not in ROLES:
            raise ValueError(f"unknown role {k!r} in columns mapping (allowed: {', '.join(ROLES)})")
    raw = _Raw(fmt=fmt)
    keys: dict[str, str] = {}
    for role in ROLES:
        if role in columns:
            k = columns[role]
            if k not in arrays:
                probs.append(Problem(path, "", str(k), f"no such array; the file has {_fmt_names(sorted(arrays))}"))
                continue
            keys[role] = k
        else:
            for cand in DEFAULT_KEYS[role]:
                if cand in arrays:
                    keys[role] = cand
                    break
    for role in ("q", "tau"):
        if role not in keys and role not in columns:
            probs.append(Problem(path, "", role, f"no {role} array (looked for {', '.join(DEFAULT_KEYS[role])}); "
                                 f"the file has {_fmt_names(sorted(arrays))}"))
    if "t" not in keys and dt is None and "t" not in columns:
        probs.append(Problem(path, "", "t", f"no time array ({', '.join(DEFAULT_KEYS['t'])}) and no dt given"))
    N_t = None
    if "t" in keys:
        t = np.asarray(arrays[keys["t"]], float)
        if t.ndim == 2 and 1 in t.shape:
            t = t.reshape(-1)
        if t.ndim != 1:
            probs.append(Problem(path, "", keys["t"], f"time must be a vector, got shape {t.shape}"))
        else:
            N_t = t.shape[0]
            raw.cols["t"] = _Column(path, [keys["t"]], t[:, None], None)
    for role in JOINT_ROLES:
        if role not in keys:
            continue
        k = keys[role]
        a = np.asarray(arrays[k])
        if not np.issubdtype(a.dtype, np.number):
            probs.append(Problem(path, "", k, f"not numeric (dtype {a.dtype})"))
            continue
        a = a.astype(float)
        if a.ndim == 1 and n == 1:
            a = a[:, None]
        if a.ndim != 2:
            probs.append(Problem(path, "", k, f"must be a 2-D (samples x joints) array, got shape {a.shape}"))
            continue
        if a.shape[1] != n and a.shape[0] == n and (N_t is None or a.shape[1] == N_t):
            a = a.T  # (n, N) as MATLAB users often store it
        if a.shape[1] != n:
            probs.append(Problem(path, "", k, f"wrong column count for the robot: {a.shape[1]} columns, "
                                 f"the robot has {n} joints"))
            continue
        raw.cols[role] = _Column(path, [f"{k}[joint {j}]" for j in range(1, n + 1)], a, None)
    raw.unused = sorted(set(arrays) - set(keys.values()))
    return raw


def _read_split(spec: DataSpec, n: int, probs) -> _Raw:
    raw = _Raw(fmt="split")
    for role, path in spec.files.items():
        if path.endswith(".npy"):
            a = load_npy(path)
            if a.ndim == 1:
                a = a[:, None]
            names = [f"column {c + 1}" for c in range(a.shape[1])]
            off = None
        else:
            hdr, a, skip = _read_text_table(path, header_required=False)
            names = hdr or [f"column {c + 1}" for c in range(a.shape[1])]
            off = skip
        want = 1 if role == "t" else n
        if a.ndim != 2 or a.shape[1] != want:
            probs.append(Problem(path, "header" if off else "", role,
                                 f"wrong column count for the robot: {a.shape[1] if a.ndim == 2 else a.shape} "
                                 f"columns ({_fmt_names(names)}), expected {want}"
                                 + (f" ({role} of {n} joints)" if role != "t" else " (time)")))
            continue
        raw.cols[role] = _Column(path, names, a, off)
    lens = {role: c.values.shape[0] for role, c in raw.cols.items()}
    if len(set(lens.values())) > 1:
        desc = ", ".join(f"{spec.files[r]} ({r}): {m} rows" for r, m in lens.items())
        probs.append(Problem(spec.text, "", "", f"the files of a split recording must have the same number of rows; {desc}"))
    if "t" not in spec.files and spec.dt is None:
        probs.append(Problem(spec.text, "", "dt", "a split recording without a t= file needs dt= (or fs=)"))
    return raw


# ---------------------------------------------------------------------------------------------
# checks
# ---------------------------------------------------------------------------------------------
def _check_values(raw: _Raw, probs: list[Problem]) -> None:
    """Non-finite values anywhere, absurd ones (``|value| > ABSURD_VALUE``) outside the time column:
    one problem per column, naming its rows (the same rule as ``logformat``'s loader)."""
    for role, c in raw.cols.items():
        bad = ~np.isfinite(c.values)
        for k in np.flatnonzero(bad.any(axis=0)):
            col = bad[:, k]
            v = c.values[col, k]
            kinds = [s for s, m in (("NaN", np.isnan(v)), ("+inf", v == np.inf), ("-inf", v == -np.inf)) if m.any()]
            probs.append(Problem(c.file, _fmt_ranges(_runs(col), c.line_offset), c.names[k],
                                 f"{int(col.sum())} non-finite value(s) ({', '.join(kinds)})"))
        if role == "t":
            continue
        with np.errstate(invalid="ignore"):
            absurd = np.isfinite(c.values) & (np.abs(c.values) > ABSURD_VALUE)
        for k in np.flatnonzero(absurd.any(axis=0)):
            col = absurd[:, k]
            worst = float(np.max(np.abs(c.values[col, k])))
            probs.append(Problem(c.file, _fmt_ranges(_runs(col), c.line_offset), c.names[k],
                                 f"{int(col.sum())} absurd value(s) (|value| > {ABSURD_VALUE:g}, up to {worst:.3g}): "
                                 "a sensor fault or a logging glitch, not a measurement"))


def _check_time(t: np.ndarray, col: _Column, jitter_tol: float, probs: list[Problem]) -> dict:
    info: dict = {}
    if t.size < 2:
        return info
    d = np.diff(t)
    name = col.names[0]
    nonincr = d <= 0
    if nonincr.any():
        runs = [(a + 1, b + 1) for a, b in _runs(nonincr)]  # row of the later sample
        probs.append(Problem(col.file, _fmt_ranges(runs, col.line_offset), name,
                             f"time is not strictly increasing ({int(nonincr.sum())} step(s) <= 0)"))
        return info
    med = float(np.median(d))
    dev = np.abs(d - med) / med
    info["dt_median"] = med
    info["dt_max_rel_jitter"] = float(dev.max())
    irr = dev > jitter_tol
    if irr.any():
        runs = [(a + 1, b + 1) for a, b in _runs(irr)]
        worst = float(d[irr][np.argmax(dev[irr])])
        probs.append(Problem(col.file, _fmt_ranges(runs, col.line_offset), name,
                             f"irregular sampling: {int(irr.sum())} time step(s) deviate more than "
                             f"{100 * jitter_tol:g} % from the median step {med:.6g} s (e.g. {worst:.6g} s); "
                             "gaps or resets must be split into separate files, or resampled (--resample)"))
    for a, b, local in step_regime_changes(t, irr):
        inside = np.zeros(d.size, bool)
        inside[max(a - 2, 0):b - 1] = True  # steps ending at rows a..b (1-based)
        other = float(np.median(d[~inside])) if (~inside).any() else med
        probs.append(Problem(col.file, _fmt_ranges([(a, b)], col.line_offset), name,
                             f"the sampling period changes: about {local:.6g} s per step in these rows, "
                             f"{other:.6g} s elsewhere; a recording must keep one period: resample it (--resample) "
                             "or split it into separate files"))
    return info


REGIME_WINDOW = 20  #: steps averaged to find the local sampling period
REGIME_TOL = 0.2    #: largest accepted relative change of the local sampling period


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
        for a, b in _runs(steps):  # 1-based step indices; step i ends at row i + 1
            out.append((a + 1, b + 1, float(np.median(d[a - 1:b]))))
    return sorted(out)


def _warn(msg: str) -> None:
    warnings.warn(msg, DataWarning, stacklevel=3)


def _unit_checks(src_files: dict[str, str], t, q, tau, joint_types, *, max_abs_position, max_abs_velocity,
                 max_abs_prismatic, max_abs_torque, max_dt) -> list[str]:
    msgs: list[str] = []
    n = q.shape[1]
    types = list(joint_types) if joint_types is not None else [0] * n
    dt = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    if t.size > 1 and dt > max_dt:
        msgs.append(f"{src_files['t']}, column t: median sampling period {dt:.6g} s > {max_dt:g} s: "
                    "time in milliseconds or in samples? (expected seconds)")
    for j in range(n):
        qa = np.abs(q[:, j])
        if types[j] == 1:
            if qa.max() > max_abs_prismatic:
                msgs.append(f"{src_files['q']}, column q{j + 1}: max |q| = {qa.max():.4g} > {max_abs_prismatic:g} m "
                            "for a prismatic joint: positions in mm? (expected m)")
            continue
        if qa.max() > max_abs_position:
            msgs.append(f"{src_files['q']}, column q{j + 1}: max |q| = {qa.max():.4g} > {max_abs_position:.4g} rad: "
                        "positions in degrees (or motor-side without a drive chain)? (expected rad, joint side; "
                        "--deg reads degrees)")
        elif t.size > 2 and dt > 0:
            v = np.abs(np.diff(q[:, j])) / dt
            v99 = float(np.percentile(v, 99))
            if v99 > max_abs_velocity:
                msgs.append(f"{src_files['q']}, column q{j + 1}: velocity {v99:.4g} rad/s (99th percentile) > "
                            f"{max_abs_velocity:g} rad/s: positions in degrees (--deg) or t not in seconds?")
    ta = np.abs(tau).max(axis=0) if tau.size else np.zeros(n)
    for j in range(n):
        if ta[j] > max_abs_torque:
            msgs.append(f"{src_files['tau']}, column tau{j + 1}: max |tau| = {ta[j]:.4g} > {max_abs_torque:g} N m: "
                        "torques in N mm or mN m? (expected N m or N; --tau-scale rescales)")
    return msgs


# ---------------------------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------------------------
def load_trajectory(
    path,
    *,
    n_joints: int | None = None,
    columns: Mapping | None = None,
    dt: float | None = None,
    loaded: bool | None = None,
    drive_chain=None,
    robot=None,
    base_dir=None,
    time_jitter_tol: float = 0.5,
    min_samples: int = 32,
    max_abs_position: float = 4 * math.pi,
    max_abs_velocity: float = 50.0,
    max_abs_prismatic: float = 5.0,
    max_abs_torque: float = 1e4,
    max_dt: float = 0.1,
) -> Trajectory:
    """Load one experiment (see the module docstring for formats and checks).

    Parameters
    ----------
    path : str or PathLike or DataSpec
        A ``.csv``/``.txt``, ``.npz`` or ``.mat`` file, or a spec string ``"q=a.csv,tau=b.csv,dt=0.0002"``.
    n_joints : int
        Number of joints of the robot (default ``robot.n_joints``).
    columns : mapping, optional
        Role (``t q tau dq ddq``) -> column name template/list (CSV) or array key (NPZ/MAT).
    dt : float, optional
        Sampling period [s] when the data have no time; overrides a time column (with a warning).
    loaded : bool, optional
        Payload mounted during this experiment (default: the spec's ``loaded=``, else False).
    drive_chain : DriveChain, optional
        The data are motor-side; map them to the joint side.
    robot : RobotDescription, optional
        Supplies ``n_joints`` and the joint types used by the unit checks.
    base_dir : path, optional
        Base of the relative paths in a spec string.
    time_jitter_tol : float
        Largest accepted relative deviation of a time step from the median step.
    min_samples : int
        Fewest samples accepted (filtering needs a few dozen).
    max_abs_position, max_abs_velocity, max_abs_prismatic, max_abs_torque, max_dt : float
        Thresholds of the unit-mix-up warnings [rad, rad/s, m, N m, s].

    Returns
    -------
    Trajectory
        Joint-side ``t`` [s], ``q``, ``tau`` (and ``dq``, ``ddq`` when present), ``source`` = the path
        or spec, ``meta`` with the format, files, column names, unused columns and time statistics.

    Raises
    ------
    DataFileError
        Listing every problem found (file, column, rows).
    """
    if robot is not None and n_joints is None:
        n_joints = len(robot.model_joints)
    if n_joints is None or int(n_joints) < 1:
        raise ValueError("n_joints (or robot) is required")
    n = int(n_joints)
    joint_types = [r.sigma for r in robot.model_joints] if robot is not None else None
    spec = path if isinstance(path, DataSpec) else parse_data_spec(path, base_dir=base_dir)
    if dt is None:
        dt = spec.dt
    if loaded is None:
        loaded = bool(spec.loaded) if spec.loaded is not None else False
    probs: list[Problem] = []
    if not spec.is_split:
        file = spec.files["file"]
        if not Path(file).exists():
            raise DataFileError([Problem(file, "", "", "file not found")])
        suffix = Path(file).suffix.lower()
        if suffix in (".csv", ".txt", ".tsv", ".dat"):
            raw = _read_csv(file, n, columns, dt, probs)
        elif suffix == ".npz":
            raw = _read_arrays(file, "npz", n, columns, dt, probs)
        elif suffix == ".mat":
            raw = _read_arrays(file, "mat", n, columns, dt, probs)
        else:
            raise DataFileError([Problem(file, "", "", f"unknown data format {suffix!r} "
                                         "(expected .csv, .txt, .npz, .mat or a q=...,tau=... spec)")])
        source = file
    else:
        if columns:
            raise ValueError("columns cannot be used with a split-file spec (each file holds one role)")
        raw = _read_split(spec, n, probs)
        source = spec.text
    # row counts across roles of one file (npz/mat arrays may differ)
    lens = {r: c.values.shape[0] for r, c in raw.cols.items()}
    if raw.fmt in ("npz", "mat") and len(set(lens.values())) > 1:
        desc = ", ".join(f"{raw.cols[r].names[0].split('[')[0]}: {m}" for r, m in lens.items())
        probs.append(Problem(source, "", "", f"arrays have different numbers of samples ({desc})"))
    _check_values(raw, probs)
    N = max(lens.values()) if lens else 0
    if probs:
        bad_values = any("non-finite" in p.message or "absurd" in p.message for p in probs)
        raise DataFileError(probs, hint=BAD_VALUE_HINT if bad_values else None)
    # time base
    tinfo: dict = {}
    t_from_dt = False
    if "t" in raw.cols and dt is not None:
        _warn(f"{raw.cols['t'].file}, column {raw.cols['t'].names[0]}: ignored, the time base is dt = {dt:g} s")
        del raw.cols["t"]
    if "t" in raw.cols:
        t = raw.cols["t"].values[:, 0]
        tinfo = _check_time(t, raw.cols["t"], time_jitter_tol, probs)
    else:
        if not (dt is not None and dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a positive number, got {dt!r}")
        t = np.arange(N) * float(dt)
        t_from_dt = True
        tinfo = {"dt_median": float(dt), "dt_max_rel_jitter": 0.0}
    time_probs = bool(probs)
    if min_samples > N:
        probs.append(Problem(source, f"rows 1-{N}", "", f"too short to filter: {N} samples, at least "
                             f"{min_samples} needed"))
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
    src_files = {"t": raw.cols["t"].file if "t" in raw.cols else source,
                 "q": raw.cols["q"].file, "tau": raw.cols["tau"].file}
    for msg in _unit_checks(src_files, t, q, tau, joint_types, max_abs_position=max_abs_position,
                            max_abs_velocity=max_abs_velocity, max_abs_prismatic=max_abs_prismatic,
                            max_abs_torque=max_abs_torque, max_dt=max_dt):
        _warn(msg)
    meta = {
        "format": raw.fmt,
        "files": {r: c.file for r, c in raw.cols.items()},
        "columns": {r: list(c.names) for r, c in raw.cols.items()},
        "unused": list(raw.unused),
        "drive_chain": drive_chain is not None,
        "t_from_dt": t_from_dt,
        **tinfo,
    }
    return Trajectory(t=t, q=q, tau=tau, dq=dq, ddq=ddq, source=source, loaded=bool(loaded), meta=meta)


def load_trajectories(paths: Iterable, *, progress=None, **kwargs) -> tuple[Trajectory, ...]:
    """Load several experiments (one per path/spec); same keyword arguments as :func:`load_trajectory`.

    Problems of all files are reported together in one :class:`DataFileError`.

    ``progress``: None shows a per-file bar when the ambient mode allows it (the command line, see
    :mod:`symoro_gen.progress`), False none, a callable is called with 1 after each file.
    """
    paths = list(paths)
    out: list[Trajectory] = []
    probs: list[Problem] = []
    with progress_updates(progress, total=len(paths), desc="loading data", unit="file") as step:
        for p in paths:
            try:
                out.append(load_trajectory(p, **kwargs))
            except DataFileError as exc:
                probs.extend(exc.problems)
            step(1)
    if probs:
        raise DataFileError(probs)
    return tuple(out)
