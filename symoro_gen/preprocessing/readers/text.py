"""Delimited text tables (``.csv``, ``.txt``, ``.tsv``, ``.dat``): ``,``, ``;``, tab or blank separated, a
header line (the first line with a non-numeric field) optional, ``#`` comment lines skipped.

One reader, :func:`read_table`, keeps every row and marks the bad ones (wrong number of fields,
missing or non-numeric values) by file line. The plain reading stops at them
(:func:`~.common.raise_malformed`); the reading with the data options drops them or names them with the
other bad values.
"""
from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence

import numpy as np

from ...errors import DataFileError, Problem
from .common import RawColumns, Table, not_text_problem, open_problem, raise_malformed, table_columns

__all__ = ["TEXT_SUFFIXES", "read_table", "read_text_file"]

TEXT_SUFFIXES = (".csv", ".txt", ".tsv", ".dat")


def _delimiter(line: str) -> str | None:
    for d in (",", ";", "\t"):
        if d in line:
            return d
    return None


def _unquoted(s: str) -> str:
    """A field without the double quotes RFC 4180 allows around it (``"q1"`` -> ``q1``)."""
    return s[1:-1].replace('""', '"').strip() if len(s) >= 2 and s[0] == s[-1] == '"' else s


def _number(s: str) -> float | None:
    try:
        return float(_unquoted(s))
    except ValueError:
        return None


def _trailing_delimiter(lines: list[str], delim: str | None) -> bool:
    """The first line (the header, or the first row) and most rows end with the delimiter: a logger's trailing
    ``,`` (or ``;``, tab) after the last field, not an empty last column. It is then taken off every line
    that has it (a truncated row without it stays a row with too few fields). With blanks as separators a
    trailing blank is no field at all."""
    if delim is None or not lines:
        return False
    ends = [ln.rstrip(" \r").endswith(delim) for ln in lines]
    return ends[0] and 2 * sum(ends[1:]) > len(ends) - 1


def _without_trailing(ln: str, delim: str | None) -> str:
    s = ln.rstrip(" \r")
    return s[:-1] if delim and s.endswith(delim) else ln


def _read_lines(path: str) -> list[str]:
    try:
        with open(path, encoding="utf-8-sig") as f:
            return f.read().split("\n")
    except OSError as exc:
        raise DataFileError([open_problem(path, exc)]) from None
    except UnicodeDecodeError as exc:
        raise DataFileError([not_text_problem(path, exc)]) from None


def _parse_rows(tab: Table, body: list[str], split) -> None:
    """Field by field, marking rows with the wrong number of fields and unparsable cells."""
    ncol = tab.data.shape[1]
    for r, ln in enumerate(body):
        parts = split(ln)
        if len(parts) != ncol:
            tab.bad_fields[r] = True
            continue
        for c, s in enumerate(parts):
            x = _number(s)
            if x is None:
                tab.unparsable[r, c] = True
                shown = tab.bad_text.setdefault(c, [])
                if len(shown) < 3:
                    shown.append(s)
            else:
                tab.data[r, c] = x


def read_table(path: str, skip_rows: int = 0) -> Table:
    """Read a delimited numeric text table, keeping every row (bad ones marked, by file line).

    The header (a first line with a non-numeric field) is optional. ``skip_rows``: data rows left out at the
    start (below the header; the garbage some loggers write before the recording starts), said in
    ``Table.notes``. Fast path: :func:`numpy.loadtxt`; when it fails, field by field so that every bad row can
    be named.
    """
    lines = _read_lines(path)
    first_i = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first_i is None:
        raise DataFileError([Problem(path, "line 1", "", "empty file (no header, no data)")])
    delim = _delimiter(lines[first_i])
    rows = [(i + 1, ln) for i, ln in enumerate(lines[first_i:], start=first_i)
            if ln.strip() and (i == first_i or not ln.lstrip().startswith("#"))]
    trailing = _trailing_delimiter([ln for _, ln in rows], delim)

    def fields(ln: str) -> list[str]:
        return [s.strip() for s in (ln.split(delim) if delim else ln.split())]

    def split(ln: str) -> list[str]:
        return fields(_without_trailing(ln, delim) if trailing else ln)

    head = split(lines[first_i])
    has_header = not all(_number(x) is not None for x in head)
    if has_header:
        head = [_unquoted(x) for x in head]
        rows = rows[1:]
        if not rows:
            raise DataFileError([Problem(path, f"header (line {first_i + 1})", "", "no data rows: the file has a "
                                         "header line and nothing below it (blank and # comment lines aside)")])
    ncol = len(head)
    notes = []
    if skip_rows:
        if skip_rows >= len(rows):
            raise DataFileError([Problem(path, "", "skip_rows", f"--skip-rows {skip_rows}: the file has only "
                                         f"{len(rows)} data row(s)")])
        a, b = rows[0][0], rows[skip_rows - 1][0]
        notes.append(f"rows 1-{skip_rows} (lines {a}-{b}) skipped (--skip-rows {skip_rows})" if skip_rows > 1 else
                     f"row 1 (line {a}) skipped (--skip-rows 1)")
        rows = rows[skip_rows:]
        if not has_header:  # the skipped rows do not set the number of fields
            ncol = len(split(rows[0][1]))
    N = len(rows)
    body = [_without_trailing(ln, delim) if trailing else ln for _, ln in rows]
    tab = Table(path, head if has_header else None, np.full((N, ncol), np.nan), np.array([i for i, _ in rows], int),
                np.zeros(N, bool), np.zeros((N, ncol), bool), first_line=first_i + 1 if has_header or not N
                else int(rows[0][0]), notes=notes)
    if not N:
        return tab
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fast = np.loadtxt(body, delimiter=delim, ndmin=2, dtype=float)
        if fast.shape == (N, ncol):
            tab.data = fast
            return tab
    except ValueError:
        pass
    _parse_rows(tab, body, fields)
    return tab


def read_text_file(path: str, n: int, *, mapping: Mapping | None, selectors: Sequence[tuple[str, str]],
                   dt: float | None, probs: list[Problem], strict: bool, skip_rows: int = 0) -> RawColumns:
    """One experiment in a text table: the columns of its roles.

    ``strict`` (the plain reading): the header must name the columns (``t, q1..qn, tau1..taun`` or a
    ``columns`` mapping) and a malformed row is an error at once; otherwise bad rows are marked for the
    caller, and a file without a header is read by ``--columns`` indices.
    """
    tab = read_table(path, skip_rows)
    if strict:
        if tab.names is None:
            raise DataFileError([Problem(path, "line 1", "", "no header line: the columns must be named "
                                         "(t, q1..qn, tau1..taun), or give a columns mapping")])
        raise_malformed(tab)
    elif tab.names is None and not selectors:
        raise DataFileError([Problem(path, "line 1", "", "no header line: say which columns are what with "
                                     "--columns, e.g. t=0,q=1:7,tau=7:13 (0-based indices)")])
    out = table_columns(tab, "csv", n, mapping=mapping, selectors=selectors, dt=dt, probs=probs)
    out.notes += tab.notes
    return out
