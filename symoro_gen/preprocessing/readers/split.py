"""Split recordings: one file per quantity, named by a spec string usable from a command line, like the
Staubli TX40 recording::

    q=pos_read_data.csv,tau=curr_data.csv,dt=0.0002

Items are ``key=value`` separated by commas: ``q``, ``tau`` (required), ``dq``, ``ddq``, ``t`` are files
(text tables with one column per joint, header line optional, or ``.npy``); ``dt`` (sampling period
[s]) or ``fs`` (sampling frequency [Hz]) give the time base when there is no ``t`` file; ``loaded``
(``true``/``false``) says whether the payload is mounted. Relative paths are resolved against
``base_dir`` (default: the current directory). A plain path (no ``=``) is a single file.

One value per line (the dumps of several robot SDKs' loggers, MATLAB's ``writematrix`` of a column): a file
of one column whose ``n x N`` lines hold the ``n`` joint values of ``N`` samples is reshaped to ``(N, n)``
(:func:`one_per_line`), in the order ``--reshape`` names or, without it, the one order in which the signals
are smooth; a ``t=`` file in the same layout (its stamp repeated for each joint) is reshaped alike.
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import DataFileError, Problem
from .arrays import load_npy
from .common import Column, RawColumns, fmt_names, raise_malformed
from .options import RESHAPE_ORDERS
from .text import read_table

__all__ = ["DataSpec", "parse_data_spec", "read_split", "one_per_line", "roughness", "SMOOTH_MAX",
           "ORDER_CONTRAST"]

#: largest roughness (:func:`roughness`) of signals called smooth
SMOOTH_MAX = 0.1
#: the other order of a one-value-per-line file must be at least this many times rougher
ORDER_CONTRAST = 10.0


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


def _time_base(text: str, item: str, k: str, v: str, seen: set[str], probs: list[Problem]) -> float | None:
    """The sampling period of a ``dt=`` or ``fs=`` item (None when it is bad)."""
    if k in seen:
        probs.append(Problem(text, f"item {item!r}", k, f"{k}= given twice; give the time base once"))
    elif seen:
        other = next(iter(seen))
        probs.append(Problem(text, f"item {item!r}", k, f"conflicts with {other}=: give either dt= "
                             "(sampling period [s]) or fs= (sampling frequency [Hz]), not both"))
    seen.add(k)
    try:
        x = float(v)
    except ValueError:
        x = float("nan")
    if not (x > 0 and math.isfinite(x)):
        probs.append(Problem(text, f"item {item!r}", k, "must be a positive number"))
        return None
    return x if k == "dt" else 1.0 / x


def parse_data_spec(spec: str | os.PathLike | DataSpec, *, base_dir: str | os.PathLike | None = None) -> DataSpec:
    """Parse ``"q=pos.csv,tau=curr.csv,dt=0.0002"`` (or a plain path) into a :class:`DataSpec`.

    Raises
    ------
    DataFileError
        Unknown key, malformed item, missing ``q`` or ``tau``, bad number.
    """
    if isinstance(spec, DataSpec):
        return spec
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
            x = _time_base(text, item, k, v, seen_time, probs)
            dt = x if x is not None else dt
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


def _read_one(path: str, strict: bool, skip_rows: int = 0
              ) -> tuple[np.ndarray, list[str], np.ndarray | None, np.ndarray, np.ndarray | None, list[str]]:
    """One file of a split recording: (values (N, k), column names, file line of each row, unparsable
    cells, rows with the wrong number of fields, notes)."""
    if path.endswith(".npy"):
        a = load_npy(path)
        a = a[:, None] if a.ndim == 1 else a
        note = []
        if skip_rows:
            a, note = a[skip_rows:], [f"rows 1-{skip_rows} skipped (--skip-rows {skip_rows})"]
        return a, [f"column {c + 1}" for c in range(a.shape[1])], None, np.zeros(a.shape, bool), None, note
    tab = read_table(path, skip_rows)
    if strict:
        raise_malformed(tab)
    names = tab.names or [f"column {c + 1}" for c in range(tab.data.shape[1])]
    return tab.data, names, tab.lines, tab.unparsable, tab.bad_fields, tab.notes


def _order(v: np.ndarray, n: int, order: str) -> np.ndarray:
    """The ``(N, n)`` view of ``n x N`` values in ``order`` (see ``RESHAPE_ORDERS``)."""
    N = v.size // n
    return v.reshape(N, n) if order == "sample-major" else v.reshape(n, N).T


def roughness(x: np.ndarray) -> float:
    """Sum of squared first differences over the sum of squared deviations from the mean, all columns
    together: about ``(2 pi f dt)^2`` for a sampled sine of frequency ``f``, 2 for white noise. Smooth
    signals read in the wrong order jump from joint to joint (sample-major read as joint-major) or lose a
    factor ``n`` of sampling (joint-major read as sample-major: ``n^2`` times rougher)."""
    x = np.asarray(x, float)
    num = float(np.nansum(np.diff(x, axis=0) ** 2))
    den = float(np.nansum((x - np.nanmean(x, axis=0)) ** 2))
    return num / den if den > 0 else float("inf")


def one_per_line(v: np.ndarray, n: int, order: str | None) -> tuple[np.ndarray | None, str | None, dict[str, float]]:
    """Reshape ``n x N`` values (one per line) to ``(N, n)``.

    ``order`` given: that order. Else the order whose :func:`roughness` is at most ``SMOOTH_MAX`` while the
    other's is at least ``min(ORDER_CONTRAST, n^2 / 2)`` times larger (joint-major values read sample-major
    are about ``n^2`` times rougher: with 2 or 3 joints the contrast cannot reach 10); none (None, None,
    roughness by order) when neither or both orders are smooth.
    """
    v = np.asarray(v, float).reshape(-1)
    if order is not None:
        return _order(v, n, order), order, {}
    r = {o: roughness(_order(v, n, o)) for o in RESHAPE_ORDERS}
    best, other = sorted(RESHAPE_ORDERS, key=lambda o: r[o])
    if r[best] <= SMOOTH_MAX and r[other] >= min(ORDER_CONTRAST, n * n / 2) * r[best]:
        return _order(v, n, best), best, r
    return None, None, r


def _reshaped(role: str, path: str, a, names, lines, unp, fields, n: int, order: str | None, how: str,
              probs: list[Problem]):
    """A one-column file of a joint role reshaped to ``n`` columns (or a problem naming ``--reshape``)."""
    M = a.shape[0]
    if M % n:
        probs.append(Problem(path, f"rows 1-{M}", role, f"wrong column count for the robot: 1 column "
                             f"({fmt_names(names)}), expected {n} ({role} of {n} joints); read as one value per "
                             f"line, its {M} rows are not a multiple of the {n} joints"))
        return None
    x, got, r = one_per_line(a[:, 0], n, order)
    if x is None:
        probs.append(Problem(path, f"rows 1-{M}", role, f"one value per line ({M} rows = {M // n} samples x {n} "
                             f"joints), but the order is not clear from the data (roughness sample-major "
                             f"{r['sample-major']:.3g}, joint-major {r['joint-major']:.3g}; smooth signals are "
                             f"below {SMOOTH_MAX:g} in one order only): give --reshape sample-major or --reshape "
                             "joint-major"))
        return None
    assert got is not None
    N = M // n
    take = slice(None, None, n) if got == "sample-major" else slice(0, N)
    lines2 = lines[take] if lines is not None else None
    unp2 = _order(unp[:, 0], n, got)
    fields2 = np.asarray(_order(fields, n, got).any(axis=1), bool) if fields is not None else None
    why = f"{how}" if how else (f"found from the data: roughness {r[got]:.2g} in this order, "
                                f"{r[next(o for o in r if o != got)]:.2g} in the other")
    note = f"{path} ({role}): one value per line, {M} rows reshaped to {N} samples x {n} joints, {got} ({why})"
    return x, [f"joint {j + 1}" for j in range(n)], lines2, unp2, fields2, note, got


def _add(out: RawColumns, role: str, path: str, a, names, lines, unp, fields) -> None:
    out.cols[role] = Column(path, names, a, lines)
    out.unparsable[role] = unp
    if fields is not None:
        bad = out.bad_fields
        out.bad_fields = fields if bad is None or bad.shape != fields.shape else (bad | fields)


def read_split(spec: DataSpec, n: int, dt: float | None, probs: list[Problem], *, strict: bool,
               skip_rows: int = 0, reshape: str | None = None) -> RawColumns:
    """The files of a split recording, one role each (rows aligned across files). ``strict`` (the plain
    reading): a malformed row of a text file is an error at once; otherwise bad rows are marked.
    ``skip_rows``: data rows skipped at the start of every file; ``reshape``: the order of the values of
    one-value-per-line files (None: found from the data, see :func:`one_per_line`)."""
    out = RawColumns(spec.text, "split")
    orders: dict[str, str] = {}
    pending: list[tuple] = []
    roles = sorted(spec.files, key=lambda r: r == "t")  # the t= file last: it follows the others' layout
    for role in roles:
        path = spec.files[role]
        a, names, lines, unp, fields, notes = _read_one(path, strict, skip_rows)
        out.notes += [f"{path}: {x}" for x in notes]
        if role == "t" and a.shape[1] == 1 and names == ["column 1"]:
            names = ["t"]  # a headerless t= file: its one column is the time (named so in messages)
        want = 1 if role == "t" else n
        if role != "t" and a.shape[1] == 1 and n > 1:
            got = _reshaped(role, path, a, names, lines, unp, fields, n, reshape, "--reshape" if reshape else "",
                            [])
            if got is None and reshape is None:
                pending.append((role, path, a, names, lines, unp, fields))
                continue
            if got is None:
                _reshaped(role, path, a, names, lines, unp, fields, n, reshape, "--reshape", probs)
                continue
            a, names, lines, unp, fields, note, orders[role] = got
            out.notes.append(note)
        if role == "t" and orders and a.shape[1] == 1:
            sizes = {c.values.shape[0] for c in out.cols.values()}
            if len(sizes) == 1 and a.shape[0] == n * sizes.pop():
                order = next(iter(orders.values()))
                x = _order(a[:, 0], n, order)
                spread = float(np.nanmax(np.abs(x - x[:, :1]))) if x.size else 0.0
                scale = float(np.nanmax(np.abs(x))) if x.size else 0.0
                if spread > 1e-9 * max(scale, 1.0):
                    probs.append(Problem(path, f"rows 1-{a.shape[0]}", "t", f"one value per line like the other "
                                         f"files ({order}), but the {n} stamps of a sample differ (by up to "
                                         f"{spread:.3g}): expected one stamp per sample, repeated for each joint"))
                    continue
                take = slice(None, None, n) if order == "sample-major" else slice(0, a.shape[0] // n)
                lines = lines[take] if lines is not None else None
                unp = _order(unp[:, 0], n, order)[:, :1]
                fields = np.asarray(_order(fields, n, order).any(axis=1), bool) if fields is not None else None
                a = x[:, :1]
                out.notes.append(f"{path} (t): one value per line, the stamp of each sample repeated for the {n} "
                                 f"joints ({order}, as the other files)")
        if a.shape[1] != want:
            below_header = lines is not None and lines.size > 0 and lines[0] > 1
            probs.append(Problem(path, "header" if below_header else "", role,
                                 f"wrong column count for the robot: {a.shape[1]} columns ({fmt_names(names)}), "
                                 f"expected {want}" + (f" ({role} of {n} joints)" if role != "t" else " (time)")))
            continue
        _add(out, role, path, a, names, lines, unp, fields)
    if pending:  # one-value-per-line files whose order the data do not tell: the order of the others, if one
        known = set(orders.values())
        for role, path, a, names, lines, unp, fields in pending:
            if len(known) == 1:
                order = known.pop()
                known.add(order)
                got = _reshaped(role, path, a, names, lines, unp, fields, n, order,
                                f"as {', '.join(f'{r}=' for r in orders)}: its own data do not tell", probs)
                if got is not None:
                    x, nm, ln, up, fl, note, _ = got
                    out.notes.append(note)
                    _add(out, role, path, x, nm, ln, up, fl)
            else:
                _reshaped(role, path, a, names, lines, unp, fields, n, None, "", probs)
    out.cols = {r: out.cols[r] for r in spec.files if r in out.cols}  # in the order of the spec
    lens = {role: c.values.shape[0] for role, c in out.cols.items()}
    if len(set(lens.values())) > 1:
        desc = ", ".join(f"{spec.files[r]} ({r}): {m} rows" for r, m in lens.items())
        probs.append(Problem(spec.text, "", "", "the files of a split recording must have the same number of rows; "
                             + desc))
    if "t" not in spec.files and dt is None:
        probs.append(Problem(spec.text, "", "dt", "a split recording without a t= file needs dt= (or fs=), or the "
                             "--dt option"))
    return out
