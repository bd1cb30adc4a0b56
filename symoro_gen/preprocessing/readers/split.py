"""Split recordings: one file per quantity, named by a spec string usable from a command line, like the
Staubli TX40 recording::

    q=pos_read_data.csv,tau=curr_data.csv,dt=0.0002

Items are ``key=value`` separated by commas: ``q``, ``tau`` (required), ``dq``, ``ddq``, ``t`` are files
(text tables with one column per joint, header line optional, or ``.npy``); ``dt`` (sampling period
[s]) or ``fs`` (sampling frequency [Hz]) give the time base when there is no ``t`` file; ``loaded``
(``true``/``false``) says whether the payload is mounted. Relative paths are resolved against
``base_dir`` (default: the current directory). A plain path (no ``=``) is a single file.
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
from .text import read_table

__all__ = ["DataSpec", "parse_data_spec", "read_split"]


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


def _read_one(path: str, strict: bool
              ) -> tuple[np.ndarray, list[str], np.ndarray | None, np.ndarray, np.ndarray | None]:
    """One file of a split recording: (values (N, k), column names, file line of each row, unparsable
    cells, rows with the wrong number of fields)."""
    if path.endswith(".npy"):
        a = load_npy(path)
        a = a[:, None] if a.ndim == 1 else a
        return a, [f"column {c + 1}" for c in range(a.shape[1])], None, np.zeros(a.shape, bool), None
    tab = read_table(path)
    if strict:
        raise_malformed(tab)
    names = tab.names or [f"column {c + 1}" for c in range(tab.data.shape[1])]
    return tab.data, names, tab.lines, tab.unparsable, tab.bad_fields


def read_split(spec: DataSpec, n: int, dt: float | None, probs: list[Problem], *, strict: bool) -> RawColumns:
    """The files of a split recording, one role each (rows aligned across files). ``strict`` (the plain
    reading): a malformed row of a text file is an error at once; otherwise bad rows are marked."""
    out = RawColumns(spec.text, "split")
    for role, path in spec.files.items():
        a, names, lines, unp, fields = _read_one(path, strict)
        want = 1 if role == "t" else n
        if a.shape[1] != want:
            below_header = lines is not None and lines.size > 0 and lines[0] > 1
            probs.append(Problem(path, "header" if below_header else "", role,
                                 f"wrong column count for the robot: {a.shape[1]} columns ({fmt_names(names)}), "
                                 f"expected {want}" + (f" ({role} of {n} joints)" if role != "t" else " (time)")))
            continue
        out.cols[role] = Column(path, names, a, lines)
        out.unparsable[role] = unp
        if fields is not None:
            bad = out.bad_fields
            out.bad_fields = fields if bad is None or bad.shape != fields.shape else (bad | fields)
    lens = {role: c.values.shape[0] for role, c in out.cols.items()}
    if len(set(lens.values())) > 1:
        desc = ", ".join(f"{spec.files[r]} ({r}): {m} rows" for r, m in lens.items())
        probs.append(Problem(spec.text, "", "", "the files of a split recording must have the same number of rows; "
                             + desc))
    if "t" not in spec.files and dt is None:
        probs.append(Problem(spec.text, "", "dt", "a split recording without a t= file needs dt= (or fs=), or the "
                             "--dt option"))
    return out
