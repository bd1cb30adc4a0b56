"""Compare identified base parameters with a published reference table (e.g. the TX40 one of
figaroh-plus: ``expression, estimate, rel.std%, estimate (2nd method), rel.std%``)."""
from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import DataFileError, Problem

_KIND = {"ixx": "XX", "ixy": "XY", "ixz": "XZ", "iyy": "YY", "iyz": "YZ", "izz": "ZZ", "mx": "MX", "my": "MY",
         "mz": "MZ", "m": "M", "ia": "IA", "fv": "FV", "fs": "FS", "off": "OFF"}


@dataclass(frozen=True)
class ReferenceRow:
    expression: str
    name: str | None  # our base-parameter name, None when we have no such parameter
    ours: float
    ours_rel_std_pct: float
    ref: float
    ref_rel_std_pct: float
    agree_2sigma: bool | None


def _our_name(expr: str, names) -> str | None:
    m = re.match(r"\s*([A-Za-z]+?)(\d+)\b", expr)
    if not m:
        return None
    kind = _KIND.get(m.group(1).lower())
    if kind is None:
        return None
    for cand in (f"{kind}{m.group(2)}R", f"{kind}{m.group(2)}"):
        if cand in names:
            return cand
    return None


REFERENCE_HINT = ("the --reference table is CSV, one line per base parameter: 'expression, estimate, rel.std%' "
                  "(more columns ignored; the TX40 table of figaroh-plus); see docs/tutorial-identification.md")


@dataclass(frozen=True)
class ReferenceEntry:
    """One line of a reference table: the published expression, its estimate and relative std [%]."""

    line: int
    expression: str
    estimate: float
    rel_std_pct: float


def _table_error(path: Path, where: str, message: str) -> DataFileError:
    return DataFileError([Problem(str(path), where, "", message)], hint=REFERENCE_HINT)


def read_reference(path) -> tuple[ReferenceEntry, ...]:
    """The rows of a published base-parameter table (``expression, estimate, rel.std%, ...``), read before any
    work: a missing file, a folder, a line without two numbers after its expression, or a table without rows is
    a :class:`~symoro_gen.errors.DataFileError` naming the file and the line."""
    path = Path(path)
    if path.is_dir():
        raise _table_error(path, "", "a folder, not a reference table")
    if not path.exists():
        raise _table_error(path, "", "file not found")
    rows = []
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            for k, rec in enumerate(csv.reader(fh), start=1):
                if not rec or not "".join(rec).strip():
                    continue
                try:
                    rows.append(ReferenceEntry(k, rec[0], float(rec[1]), float(rec[2])))
                except (IndexError, ValueError):
                    raise _table_error(path, f"line {k}", "expected 'expression, estimate, rel.std%, ...', got "
                                       f"{','.join(rec)[:80]!r}") from None
    except UnicodeDecodeError as exc:
        raise _table_error(path, "", f"not UTF-8 text ({exc.reason})") from None
    except OSError as exc:
        raise _table_error(path, "", f"cannot read: {exc.strerror or exc}") from None
    if not rows:
        raise _table_error(path, "", "no rows: the table is empty")
    return tuple(rows)


def compare_with_reference(result, path, *, n_sigma: float = 2.0) -> list[ReferenceRow]:
    """Rows of the reference table (a path, or the rows :func:`read_reference` read) beside our estimates;
    agreement when ``|ours - ref| <= n_sigma * sqrt(sigma_ours^2 + sigma_ref^2)``."""
    table = path if isinstance(path, tuple) else read_reference(path)
    rows = []
    for e in table:
        expr, ref, rs = e.expression, e.estimate, e.rel_std_pct
        name = _our_name(expr, result.names)
        if name is None:
            rows.append(ReferenceRow(expr, None, math.nan, math.nan, ref, rs, None))
            continue
        i = result.names.index(name)
        v, s = float(result.values[i]), float(result.std[i])
        s_ref = abs(ref) * rs / 100.0
        agree = abs(v - ref) <= n_sigma * math.hypot(s, s_ref)
        rows.append(ReferenceRow(expr, name, v, float(result.rel_std_pct[i]), ref, rs, bool(agree)))
    return rows


def format_comparison(rows) -> str:
    lines = [f"{'reference expression':<48} {'ours':>8} {'value':>10} {'%sig':>7} {'ref':>10} {'%sig':>7}  2-sigma",]
    for r in rows:
        e = r.expression if len(r.expression) <= 48 else r.expression[:45] + "..."
        if r.name is None:
            lines.append(f"{e:<48} {'-':>8} {'':>10} {'':>7} {r.ref:>10.4g} {r.ref_rel_std_pct:>7.2f}  (not in our model)")
        else:
            lines.append(f"{e:<48} {r.name:>8} {r.ours:>10.4g} {r.ours_rel_std_pct:>7.2f} {r.ref:>10.4g} "
                         f"{r.ref_rel_std_pct:>7.2f}  {'yes' if r.agree_2sigma else 'no'}")
    n = sum(r.agree_2sigma is not None for r in rows)
    a = sum(bool(r.agree_2sigma) for r in rows)
    lines.append(f"{a} of {n} comparable parameters agree within 2 sigma")
    return "\n".join(lines)
