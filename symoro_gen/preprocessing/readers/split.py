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
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import DataFileError, Problem
from .arrays import load_npy
from .common import Column, RawColumns, fmt_names, raise_malformed, warn_data
from .options import RESHAPE_ORDERS
from .text import read_table

__all__ = ["DataSpec", "parse_data_spec", "read_split", "one_per_line", "roughness", "level_share", "SMOOTH_MAX",
           "ORDER_CONTRAST", "LEVELS_TELL", "LEVELS_NONE"]

#: largest roughness (:func:`roughness`) of signals called smooth
SMOOTH_MAX = 0.1
#: the other order of a one-value-per-line file must be at least this many times rougher
ORDER_CONTRAST = 10.0
#: a one-value-per-line file whose roughness tells no order is in the other files' order unless its joints' levels
#: (:func:`level_share`) explain at least LEVELS_TELL of its variance in the other order and at most LEVELS_NONE
#: in theirs
LEVELS_TELL = 0.9
LEVELS_NONE = 0.01


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


def level_share(x: np.ndarray) -> float:
    """Share of the variance of ``(N, n)`` values that their column means explain (between-column sum of squares
    over the total sum of squares, 0 to 1). Read in its order, a file whose joints sit at distinct levels (torque
    offsets, gravity) has a large share; read in the other order every column holds all the joints alike (a
    share near 0). Used only on files whose :func:`roughness` tells no order (noise about the joints' levels)."""
    x = np.asarray(x, float)
    dev = x - np.nanmean(x)
    tot = float(np.nansum(dev ** 2))
    between = float(np.sum(np.sum(np.isfinite(x), axis=0) * np.nanmean(dev, axis=0) ** 2))
    return between / tot if tot > 0 else 0.0


def _repeated_stamps(path: str, a, lines, unp, fields, n: int, orders: Mapping[str, str], probs: list[Problem]):
    """A one-column ``t=`` file holding each sample's stamp once per joint, in one of the other files' orders (the
    one whose ``n`` copies agree): ``(a, lines, unp, fields, note)``, or None with a problem."""
    for order in dict.fromkeys(orders.values()):
        x = _order(a[:, 0], n, order)
        spread = float(np.nanmax(np.abs(x - x[:, :1]))) if x.size else 0.0
        scale = float(np.nanmax(np.abs(x))) if x.size else 0.0
        if spread <= 1e-9 * max(scale, 1.0):
            break
    else:
        probs.append(Problem(path, f"rows 1-{a.shape[0]}", "t", f"one value per line like the other "
                             f"files ({order}), but the {n} stamps of a sample differ (by up to "
                             f"{spread:.3g}): expected one stamp per sample, repeated for each joint"))
        return None
    take = slice(None, None, n) if order == "sample-major" else slice(0, a.shape[0] // n)
    lines = lines[take] if lines is not None else None
    unp = _order(unp[:, 0], n, order)[:, :1]
    fields = np.asarray(_order(fields, n, order).any(axis=1), bool) if fields is not None else None
    note = f"{path} (t): one value per line, the stamp of each sample repeated for the {n} joints ({order}, as the " \
           "other files)"
    return x[:, :1], lines, unp, fields, note


def _read_pending(out: RawColumns, pending: list[tuple], orders: dict[str, str], n: int, probs: list[Problem]
                  ) -> None:
    """One-value-per-line files whose roughness tells no order: the order of the other files, when they agree,
    unless the file's joints' levels (:func:`level_share`) say the other order beyond doubt (at least
    ``LEVELS_TELL`` of its variance in that order, at most ``LEVELS_NONE`` in the others'): a file of another
    layout, read in its own (:func:`_check_layouts` then warns)."""
    known = set(orders.values())
    for role, path, a, names, lines, unp, fields in pending:
        if len(known) != 1:
            _reshaped(role, path, a, names, lines, unp, fields, n, None, "", probs)
            continue
        (order,) = known
        how = f"as {', '.join(f'{r}=' for r in orders)}: its own data do not tell"
        if a.shape[0] % n == 0:
            other = next(o for o in RESHAPE_ORDERS if o != order)
            share = {o: level_share(_order(a[:, 0], n, o)) for o in (order, other)}
            if share[other] >= LEVELS_TELL and share[order] <= LEVELS_NONE:
                how = (f"found from the levels of its joints: their means explain {100 * share[other]:.3g} % of its "
                       f"variance in this order, {100 * share[order]:.2g} % in the other; not {order} as "
                       f"{', '.join(f'{r}=' for r in orders)}")
                order = other
        got = _reshaped(role, path, a, names, lines, unp, fields, n, order, how, probs)
        if got is not None:
            x, nm, ln, up, fl, note, orders[role] = got
            out.notes.append(note)
            _add(out, role, path, x, nm, ln, up, fl)


def _joint_numbers(names: list[str]) -> list[int] | None:
    """The joint number in each of a header's names (``q1 .. q6``, ``tau_0 .. tau_5``, ``j3_pos``): the one number
    that differs from name to name, when every name has the same count of numbers and those are distinct."""
    nums = [[int(x) for x in re.findall(r"\d+", nm)] for nm in names]
    if len(names) < 2 or not nums[0] or any(len(x) != len(nums[0]) for x in nums):
        return None
    varying = [k for k in range(len(nums[0])) if len({x[k] for x in nums}) > 1]
    if len(varying) != 1:
        return None
    out = [x[varying[0]] for x in nums]
    return out if len(set(out)) == len(out) else None


def _check_layouts(spec: DataSpec, orders: Mapping[str, str], headers: Mapping[str, tuple[str, list[str]]],
                   probs: list[Problem]) -> None:
    """Files of one recording in different layouts, where the files themselves tell: one-value-per-line files
    found (each from its own data) in different orders, a warning naming each file and its order (each is read
    in its own); headers numbering the joints in different orders, a problem naming both files and orders
    (every file's columns are read in order, joint 1 first)."""
    if len(set(orders.values())) > 1:
        warn_data(f"{spec.text}: the files of this split recording have different layouts: "
                  + ", ".join(f"{spec.files[r]} ({r}) {o}" for r, o in orders.items())
                  + "; each is read in the order its own data show (the load report's notes say how), but a "
                  "logger writes its dumps one way: check the files (a noisy file whose joints sit at distinct "
                  "levels can look smooth in the wrong order); --reshape ORDER reads every file in one order")
    ranked = {r: (path, nm, np.argsort(nums).tolist()) for r, (path, nm) in headers.items()
              if (nums := _joint_numbers(nm)) is not None}
    if len({tuple(rk) for _, _, rk in ranked.values()}) > 1:
        probs.append(Problem(spec.text, "header", ", ".join(ranked), "the files' headers number the joints in "
                             "different orders: " + "; ".join(f"{path} ({r}): {', '.join(nm)}" for r, (path, nm, _)
                                                             in ranked.items())
                             + ": the columns of every file are read in order (joint 1 first): put each file's "
                             "columns in the robot's joint order"))


def read_split(spec: DataSpec, n: int, dt: float | None, probs: list[Problem], *, strict: bool,
               skip_rows: int = 0, reshape: str | None = None) -> RawColumns:
    """The files of a split recording, one role each (rows aligned across files). ``strict`` (the plain
    reading): a malformed row of a text file is an error at once; otherwise bad rows are marked.
    ``skip_rows``: data rows skipped at the start of every file; ``reshape``: the order of the values of
    one-value-per-line files (None: found from the data, see :func:`one_per_line`)."""
    out = RawColumns(spec.text, "split")
    orders: dict[str, str] = {}
    pending: list[tuple] = []
    headers: dict[str, tuple[str, list[str]]] = {}
    roles = sorted(spec.files, key=lambda r: r == "t")  # the t= file last: it follows the others' layout
    for role in roles:
        path = spec.files[role]
        a, names, lines, unp, fields, notes = _read_one(path, strict, skip_rows)
        out.notes += [f"{path}: {x}" for x in notes]
        if role == "t" and a.shape[1] == 1 and names == ["column 1"]:
            names = ["t"]  # a headerless t= file: its one column is the time (named so in messages)
        if role != "t" and names != [f"column {c + 1}" for c in range(len(names))]:
            headers[role] = (path, list(names))
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
                got_t = _repeated_stamps(path, a, lines, unp, fields, n, orders, probs)
                if got_t is None:
                    continue
                a, lines, unp, fields, note = got_t
                out.notes.append(note)
        if a.shape[1] != want:
            below_header = lines is not None and lines.size > 0 and lines[0] > 1
            probs.append(Problem(path, "header" if below_header else "", role,
                                 f"wrong column count for the robot: {a.shape[1]} columns ({fmt_names(names)}), "
                                 f"expected {want}" + (f" ({role} of {n} joints)" if role != "t" else " (time)")))
            continue
        _add(out, role, path, a, names, lines, unp, fields)
    _read_pending(out, pending, orders, n, probs)
    _check_layouts(spec, orders, headers, probs)
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
