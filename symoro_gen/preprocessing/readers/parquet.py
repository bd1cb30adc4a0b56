"""Parquet logs (``.parquet``, ``.pq``; pyarrow, the ``fleet`` extra): one experiment per file, columns by
name as a CSV header's (``t, q1..qn, tau1..taun`` by default, any other layout with ``--columns``).

A long log can be read by segment, the samples ``[start, stop)``: only the row groups holding them are
read (a fleet task's memory is bounded by its segment, not by the log). Null or non-numeric values are
marked like a text file's unparsable cells, named by row (the "line" of a Parquet row is its row in the
file).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import DataFileError, Problem
from .common import RawColumns, Table, raise_malformed, table_columns

__all__ = ["PARQUET_SUFFIXES", "is_parquet", "parquet_rows", "read_parquet_table", "read_parquet_file"]

PARQUET_SUFFIXES = (".parquet", ".pq")


def is_parquet(path: str) -> bool:
    return str(path).lower().endswith(PARQUET_SUFFIXES)


def _pyarrow_parquet(path: str) -> Any:
    try:
        import pyarrow.parquet as pq  # type: ignore[import-untyped]
    except ImportError:  # pragma: no cover - depends on the installation
        raise DataFileError([Problem(path, "", "", "Parquet files need pyarrow: pip install 'symoro-gen[fleet]'")]
                            ) from None
    return pq


def _damaged(path: str, exc: Exception) -> DataFileError:
    return DataFileError([Problem(path, "", "", f"cannot read as Parquet ({type(exc).__name__}: {exc})")])


def parquet_rows(path: str) -> int:
    """Number of samples of a Parquet log (from its footer, nothing else is read)."""
    pq = _pyarrow_parquet(path)
    try:
        return int(pq.ParquetFile(path).metadata.num_rows)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises ArrowInvalid, OSError... on a damaged file
        raise _damaged(path, exc) from None


def _read_rows(pq: Any, path: str, start: int, stop: int) -> Any:
    """The pyarrow table, or only the row groups holding samples ``[start, stop)`` sliced to them."""
    if stop < 0:
        return pq.read_table(path)
    f = pq.ParquetFile(path)
    groups: list[int] = []
    first, row = 0, 0
    for g in range(f.metadata.num_row_groups):
        n = f.metadata.row_group(g).num_rows
        if row + n > start and row < stop:
            if not groups:
                first = row
            groups.append(g)
        row += n
    return f.read_row_groups(groups).slice(start - first, stop - start)


def read_parquet_table(path: str, start: int = 0, stop: int = -1) -> Table:
    """A Parquet file (or its samples ``[start, stop)``, ``stop < 0``: the whole file) as a table: its
    column names as the header, row r (1-based, of the file) as "line" r; null or non-numeric values
    marked unparsable (then named by row and column like a CSV's)."""
    pq = _pyarrow_parquet(path)
    if not Path(path).exists():
        raise DataFileError([Problem(path, "", "", "file not found")])
    try:
        table = _read_rows(pq, path, start, stop)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises ArrowInvalid, OSError... on a damaged file
        raise _damaged(path, exc) from None
    N, names = table.num_rows, list(table.column_names)
    first = start if stop >= 0 else 0
    tab = Table(path, names, np.full((N, len(names)), np.nan), np.arange(first + 1, first + N + 1),
                np.zeros(N, bool), np.zeros((N, len(names)), bool))
    for k, nm in enumerate(names):
        col = table.column(nm)
        try:
            tab.data[:, k] = col.to_numpy(zero_copy_only=False).astype(float)
        except (TypeError, ValueError):
            tab.unparsable[:, k] = True
            tab.bad_text[k] = [f"<{col.type}>"]
            continue
        if col.null_count:
            tab.unparsable[:, k] = np.asarray(col.is_null().to_numpy(zero_copy_only=False), bool)
            tab.bad_text[k] = ["null"]
    return tab


def read_parquet_file(path: str, n: int, *, mapping: Mapping | None, selectors: Sequence[tuple[str, str]],
                      dt: float | None, probs: list[Problem], strict: bool, start: int = 0, stop: int = -1
                      ) -> RawColumns:
    """One experiment in a Parquet log (or a segment of it, named ``path[start:stop]``): the columns of
    its roles. ``strict`` (the plain reading): a null or non-numeric value is an error at once."""
    tab = read_parquet_table(path, start, stop)
    if strict:
        raise_malformed(tab)
    raw = table_columns(tab, "parquet", n, mapping=mapping, selectors=selectors, dt=dt, probs=probs)
    if stop >= 0:
        raw.source = f"{path}[{start}:{stop}]"
        raw.rows = (start, stop)
    return raw
