"""Arrays: NumPy ``.npz`` archives and MATLAB ``.mat`` files (one experiment each), and the single
``.npy`` arrays of split recordings.

Arrays are looked up by key: ``t``/``time``/``times``, ``q``/``positions``/``position``/``pos``,
``tau``/``torques``/``torque``/``effort``, optionally ``dq``/``velocities``/``velocity`` and
``ddq``/``accelerations``/``acceleration`` (a ``columns`` mapping names other keys); with ``--columns`` a
role names an array, nested MATLAB structs by dotted names (``q=rec.act_pos``). Arrays are ``(N, n)``;
``(n, N)`` (the MATLAB habit) is transposed when unambiguous. MATLAB files up to v7 (``scipy.io.loadmat``;
v7.3/HDF5 is refused with a hint). A damaged file is one problem naming it (never numpy's advice to
allow pickles).
"""
from __future__ import annotations

import zipfile
import zlib
from collections.abc import Mapping, Sequence

import numpy as np
import scipy.io

from ...errors import DataFileError, Problem
from .common import DEFAULT_KEYS, JOINT_ROLES, ROLES, Column, RawColumns, fmt_names

__all__ = ["ARRAY_SUFFIXES", "load_arrays", "load_mat", "load_npy", "read_array_file"]

ARRAY_SUFFIXES = (".npz", ".mat")
#: what reading a damaged .npz/.npy can raise (zip directory, CRC, truncated or garbled members)
_ARCHIVE_ERRORS = (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------
def _one_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


def _archive_detail(exc: BaseException) -> str:
    """``; damaged: ...`` for archive errors worth naming (CRC, truncation), never numpy's pickle advice."""
    if isinstance(exc, (zipfile.BadZipFile, zlib.error, EOFError)):
        return f"; damaged: {_one_line(exc)}"
    return ""


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


def _npz_member(path: str, z, key: str) -> np.ndarray:
    """One array of an open ``.npz``; an array of Python objects (pickled) is refused by name, never loaded
    (unpickling runs code)."""
    try:
        return np.asarray(z[key])
    except ValueError as exc:
        if "pickle" not in str(exc):
            raise
        raise DataFileError([Problem(path, "", key, "an array of Python objects (pickled), not of numbers; not "
                                     "loaded (unpickling can run code)")],
                            hint="save numeric arrays: numpy.savez(path, t=t, q=q, tau=tau) with each an (N,) or "
                                 "(N, n) float array") from None


def load_arrays(path: str, kind: str) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` (``kind="npz"``) or ``.mat`` file by name."""
    if kind == "npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                return {k: _npz_member(path, z, k) for k in z.files}
        except DataFileError:  # a member named (a ValueError too)
            raise
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


# ---------------------------------------------------------------------------------------------
# roles by key
# ---------------------------------------------------------------------------------------------
def _keys(path: str, arrays: Mapping[str, np.ndarray], columns: Mapping, dt: float | None,
          probs: list[Problem]) -> dict[str, str]:
    """The array of each role: the mapping's key, else the first default key present."""
    keys: dict[str, str] = {}
    for role in ROLES:
        if role in columns:
            k = columns[role]
            if k not in arrays:
                probs.append(Problem(path, "", str(k), f"no such array; the file has {fmt_names(sorted(arrays))}"))
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
                                 f"the file has {fmt_names(sorted(arrays))}"))
    if "t" not in keys and dt is None and "t" not in columns:
        probs.append(Problem(path, "", "t", f"no time array ({', '.join(DEFAULT_KEYS['t'])}) and no dt given"))
    return keys


def _time_vector(path: str, key: str, a: np.ndarray, probs: list[Problem]) -> np.ndarray | None:
    t = a.reshape(-1) if (a.ndim == 2 and 1 in a.shape) else a
    if t.ndim != 1:
        probs.append(Problem(path, "", key, f"time must be a vector, got shape {t.shape}"))
        return None
    return t


def _joint_array(a: np.ndarray, n: int, N_t: int | None) -> np.ndarray:
    """``(N, n)``: a vector of a one-joint robot as a column, ``(n, N)`` transposed when unambiguous."""
    if a.ndim == 1 and n == 1:
        a = a[:, None]
    if a.ndim == 2 and a.shape[1] != n and a.shape[0] == n and (N_t is None or a.shape[1] == N_t):
        a = a.T  # (n, N) as MATLAB users often store it
    return a


def _read_by_keys(path: str, kind: str, n: int, columns: Mapping | None, dt: float | None,
                  probs: list[Problem]) -> RawColumns:
    arrays = load_arrays(path, kind)
    columns = dict(columns or {})
    for k in columns:
        if k not in ROLES:
            raise ValueError(f"unknown role {k!r} in columns mapping (allowed: {', '.join(ROLES)})")
    raw = RawColumns(path, kind)
    keys = _keys(path, arrays, columns, dt, probs)
    N_t = None
    if "t" in keys:
        t = _time_vector(path, keys["t"], np.asarray(arrays[keys["t"]], float), probs)
        if t is not None:
            N_t = t.shape[0]
            raw.cols["t"] = Column(path, [keys["t"]], t[:, None], None)
    for role in JOINT_ROLES:
        if role not in keys:
            continue
        k = keys[role]
        a = np.asarray(arrays[k])
        if not np.issubdtype(a.dtype, np.number):
            probs.append(Problem(path, "", k, f"not numeric (dtype {a.dtype})"))
            continue
        a = _joint_array(a.astype(float), n, N_t)
        if a.ndim != 2:
            probs.append(Problem(path, "", k, f"must be a 2-D (samples x joints) array, got shape {a.shape}"))
            continue
        if a.shape[1] != n:
            probs.append(Problem(path, "", k, f"wrong column count for the robot: {a.shape[1]} columns, "
                                 f"the robot has {n} joints"))
            continue
        raw.cols[role] = Column(path, [f"{k}[joint {j}]" for j in range(1, n + 1)], a, None)
    raw.unused = sorted(set(arrays) - set(keys.values()))
    return raw


# ---------------------------------------------------------------------------------------------
# roles by --columns (dotted names in MATLAB structs)
# ---------------------------------------------------------------------------------------------
def _struct_field(path: str, d: dict, key: str) -> np.ndarray:
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


def _lookup(path: str, kind: str, key: str, arrays: dict[str, np.ndarray] | None) -> np.ndarray:
    """An array by (dotted) name in an .npz, or in a .mat with nested structs."""
    if kind == "npz" or "." not in key:
        arrays = load_arrays(path, kind) if arrays is None else arrays
        if key in arrays:
            return np.asarray(arrays[key])
        raise DataFileError([Problem(path, "", key, f"no such array; the file has {', '.join(sorted(arrays))}")])
    return _struct_field(path, load_mat(path, simplify_cells=True), key)


def _read_selected(path: str, kind: str, n: int, selectors: Sequence[tuple[str, str]], dt: float | None,
                   probs: list[Problem]) -> RawColumns:
    out = RawColumns(path, kind)
    keys = [k for _, k in selectors]
    for role, key in selectors:
        if keys.count(key) > 1 and role == next(r for r, k in selectors if k == key):
            both = [r for r, k in selectors if k == key]
            probs.append(Problem(path, "", ", ".join(both), f"--columns gives the array {key!r} to "
                                 f"{' and '.join(both)}: each array holds one signal"))
    if "t" not in dict(selectors) and dt is None:
        probs.append(Problem(path, "", "t", "no time array in --columns (t=...) and no --dt given"))
    N_t = None
    arrays = None if kind == "mat" and all("." in k for _, k in selectors) else load_arrays(path, kind)
    for role, key in selectors:
        a = _lookup(path, kind, key, arrays)
        if not np.issubdtype(a.dtype, np.number):
            probs.append(Problem(path, "", key, f"not numeric (dtype {a.dtype})"))
            continue
        a = a.astype(float)
        if role == "t":
            t = _time_vector(path, key, a, probs)
            if t is not None:
                N_t = t.shape[0]
                out.cols["t"] = Column(path, [key], t[:, None], None)
            continue
        a = _joint_array(a, n, N_t)
        if a.ndim != 2 or a.shape[1] != n:
            probs.append(Problem(path, "", key, f"shape {a.shape}: expected (samples, {n} joints)"))
            continue
        out.cols[role] = Column(path, [f"{key}[joint {j}]" for j in range(1, n + 1)], a, None)
    return out


def read_array_file(path: str, kind: str, n: int, *, mapping: Mapping | None, selectors: Sequence[tuple[str, str]],
                    dt: float | None, probs: list[Problem]) -> RawColumns:
    """One experiment in an ``.npz`` (``kind="npz"``) or ``.mat`` file: the arrays of its roles, by
    ``--columns`` selectors or by key (defaults, or a ``columns`` mapping role -> key); arrays of
    different lengths are a problem."""
    if selectors:
        raw = _read_selected(path, kind, n, selectors, dt, probs)
    else:
        raw = _read_by_keys(path, kind, n, mapping, dt, probs)
    lens = {r: c.values.shape[0] for r, c in raw.cols.items()}
    if len(set(lens.values())) > 1:
        desc = ", ".join(f"{raw.cols[r].names[0].split('[')[0]}: {m}" for r, m in lens.items())
        probs.append(Problem(path, "", "", f"arrays have different numbers of samples ({desc})"))
    return raw
