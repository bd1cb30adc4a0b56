"""A fleet's log files: expansion of files and globs, robot and day from each path (``--by``), reading
of one log (CSV, NPZ, MAT through :func:`~symoro_gen.preprocessing.load.load_trajectory`, Parquet
through pyarrow; with the data options of the command line, every format through
:func:`~symoro_gen.preprocessing.logformat.load_log`), motor-side data mapped by the robot's drive chain.

Parquet logs hold one experiment per file; read as they are, with the columns of the CSV format: ``t,
q1..qn, tau1..taun`` (``dq1..``, ``ddq1..`` optional), as :func:`write_parquet` writes them; any other
layout is read with ``--columns`` (names of the Parquet columns, as a CSV header's), ``--tau-scale``...
"""
from __future__ import annotations

import glob
import itertools
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import DataFileError, Problem, SymoroError
from ..preprocessing.drive_chain import motor_to_joint
from ..preprocessing.load import load_trajectory
from ..preprocessing.logformat import LogFormat, load_log
from ..preprocessing.trajectory import Trajectory
from ..report.plots import MissingDependencyError

__all__ = ["FleetError", "LogFile", "compile_pattern", "discover", "read_log", "require_pyarrow", "write_parquet"]

PARQUET_SUFFIXES = (".parquet", ".pq")


class FleetError(SymoroError, ValueError):
    """A fleet run cannot start or finish (bad ``--by`` pattern, no usable log, unknown scheduler...)."""


@dataclass(frozen=True, order=True)
class LogFile:
    """One log of the fleet: ``robot``, ``day`` (as named by the path) and ``path``; with ``stop`` set, only
    the samples ``[start, stop)`` of a Parquet log (a segment: one task, its own experiment)."""

    robot: str
    day: str
    path: str
    start: int = 0
    stop: int = -1

    @property
    def label(self) -> str:
        return self.path if self.stop < 0 else f"{self.path}[{self.start}:{self.stop}]"


def compile_pattern(pattern: str) -> re.Pattern:
    """The regular expression of a ``--by`` pattern, matched against the *end* of a path.

    ``{robot}`` and ``{day}`` match one or more characters other than ``/``; ``*`` matches any part of
    one path element (``{robot}/{day}_*.csv``: several logs per day); every other character is literal;
    ``/`` also matches the separator of the platform.

    >>> compile_pattern("{robot}/{day}.parquet").search("logs/arm07/2026-03-01.parquet").groupdict()
    {'robot': 'arm07', 'day': '2026-03-01'}
    """
    if "{robot}" not in pattern or "{day}" not in pattern:
        raise FleetError(f"--by {pattern!r}: the pattern must contain {{robot}} and {{day}}, "
                          "e.g. '{robot}/{day}.parquet'")

    def literal(text: str) -> str:
        return re.escape(text).replace("/", r"[/\\]").replace(r"\*", r"[^/\\]*")

    out, i = [], 0
    for m in re.finditer(r"\{(robot|day)\}", pattern):
        out.append(literal(pattern[i:m.start()]))
        out.append(f"(?P<{m.group(1)}>[^/\\\\]+?)")
        i = m.end()
    out.append(literal(pattern[i:]))
    return re.compile("(?:^|[/\\\\])" + "".join(out) + "$")


def _expand(logs: Iterable) -> list[str]:
    files: list[str] = []
    for item in logs:
        s = os.fspath(item)
        if any(c in s for c in "*?["):
            hits = sorted(glob.glob(s, recursive=True))
            if not hits:
                raise DataFileError([Problem(s, "", "", "no file matches this glob")])
            files += [h for h in hits if os.path.isfile(h)]
        elif os.path.isdir(s):
            files += sorted(str(p) for p in Path(s).rglob("*") if p.is_file())
        elif os.path.isfile(s):
            files.append(s)
        else:
            raise DataFileError([Problem(s, "", "", "no such file")])
    seen, out = set(), []
    for f in files:
        if f not in seen:
            seen.add(f)
            out.append(f)
    return out


def discover(logs: Iterable, pattern: str) -> list[LogFile]:
    """Files (and globs, and folders) -> the fleet's logs, sorted by robot, day (as strings) and path.

    Parameters
    ----------
    logs : iterable of str or PathLike
        Files, globs (``logs/*/*.parquet``, ``**`` allowed) or folders (searched recursively; files that
        do not match the pattern are then ignored).
    pattern : str
        ``--by`` pattern with ``{robot}`` and ``{day}`` (see :func:`compile_pattern`).

    Raises
    ------
    DataFileError
        A named file does not exist, a glob matches nothing, or a named file (not found in a folder)
        does not match the pattern.
    """
    rx = compile_pattern(pattern)
    named = [os.fspath(x) for x in logs]
    if not named:
        raise FleetError("fleet: no log file given")
    out, probs = [], []
    folders = {n for n in named if os.path.isdir(n)}
    for f in _expand(named):
        m = rx.search(f.replace(os.sep, "/"))
        if m is None:
            if not any(f.startswith((d.rstrip("/\\") + os.sep, d.rstrip("/") + "/")) for d in folders):
                probs.append(Problem(f, "", "--by", f"path does not end like the pattern {pattern!r}"))
            continue
        out.append(LogFile(m.group("robot"), m.group("day"), f))
    if probs:
        raise DataFileError(probs)
    if not out:
        raise DataFileError([Problem(", ".join(named), "", "--by", f"no file matches the pattern {pattern!r}")])
    return sorted(out)


def require_pyarrow():
    """Import :mod:`pyarrow.parquet`, or fail naming the ``fleet`` extra."""
    try:
        import pyarrow.parquet as pq
    except ImportError:  # pragma: no cover - depends on the installation
        raise MissingDependencyError("Parquet logs need pyarrow: pip install 'symoro-gen[fleet]'") from None
    return pq


def parquet_rows(path: str) -> int:
    """Number of samples of a Parquet log (from its footer, nothing else is read)."""
    pq = require_pyarrow()
    try:
        return int(pq.ParquetFile(path).metadata.num_rows)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises ArrowInvalid, OSError... on a damaged file
        raise DataFileError([Problem(path, "", "", f"cannot read as Parquet ({type(exc).__name__}: {exc})")]) from None


def segments(logs: Sequence[LogFile], samples: int | None) -> list[LogFile]:
    """Parquet logs longer than ``samples`` cut into segments of ``samples`` (one task each, read row group
    by row group: a worker's memory is bounded by the segment, not by the log); other logs unchanged.
    A log whose footer cannot be read is kept whole (its task reports it)."""
    if not samples:
        return list(logs)
    out = []
    for lf in logs:
        if not lf.path.lower().endswith(PARQUET_SUFFIXES):
            out.append(lf)
            continue
        try:
            n = parquet_rows(lf.path)
        except DataFileError:
            out.append(lf)
            continue
        if n <= samples:
            out.append(lf)
            continue
        k = -(-n // samples)
        bounds = np.linspace(0, n, k + 1).round().astype(int)
        out += [LogFile(lf.robot, lf.day, lf.path, int(a), int(b)) for a, b in itertools.pairwise(bounds)]
    return out


def _read_table(path: str, start: int, stop: int):
    """The Parquet table, or only the row groups holding samples ``[start, stop)`` sliced to them."""
    pq = require_pyarrow()
    if stop < 0:
        return pq.read_table(path)
    f = pq.ParquetFile(path)
    groups, first, row = [], None, 0
    for g in range(f.metadata.num_row_groups):
        n = f.metadata.row_group(g).num_rows
        if row + n > start and row < stop:
            groups.append(g)
            first = row if first is None else first
        row += n
    return f.read_row_groups(groups).slice(start - first, stop - start)


def _read_parquet(path: str, n_joints: int, loaded: bool, start: int = 0, stop: int = -1) -> Trajectory:
    try:
        table = _read_table(path, start, stop)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises ArrowInvalid, OSError... on a damaged file
        raise DataFileError([Problem(path, "", "", f"cannot read as Parquet ({type(exc).__name__}: {exc})")]) from None
    cols = set(table.column_names)
    need = ["t"] + [f"q{j}" for j in range(1, n_joints + 1)] + [f"tau{j}" for j in range(1, n_joints + 1)]
    missing = [c for c in need if c not in cols]
    if missing:
        raise DataFileError([Problem(path, "", missing[0], f"missing column(s) {', '.join(missing)} "
                                     f"(expected t, q1..q{n_joints}, tau1..tau{n_joints})")])

    def block(prefix: str):
        names = [f"{prefix}{j}" for j in range(1, n_joints + 1)]
        if not all(c in cols for c in names):
            return None
        return np.column_stack([table.column(c).to_numpy(zero_copy_only=False) for c in names]).astype(float)

    t = table.column("t").to_numpy(zero_copy_only=False).astype(float)
    q, tau = block("q"), block("tau")
    for name, a in (("t", t), ("q", q), ("tau", tau)):
        bad = ~np.isfinite(a)
        if bad.any():
            rows = np.flatnonzero(bad.reshape(a.shape[0], -1).any(axis=1))
            raise DataFileError([Problem(path, f"rows {rows[0] + 1}-{rows[-1] + 1}", name,
                                         f"{rows.size} row(s) with NaN/inf or missing values")])
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise DataFileError([Problem(path, "", "t", "time must be strictly increasing with >= 2 samples")])
    src = path if stop < 0 else f"{path}[{start}:{stop}]"
    return Trajectory(t=t, q=q, tau=tau, dq=block("dq"), ddq=block("ddq"), source=src, loaded=loaded,
                      meta={"format": "parquet", "rows": (start, stop)})


def read_log(path: str, n_joints: int, *, loaded: bool = False, start: int = 0, stop: int = -1,
             drive_chain=None, **load_kw) -> Trajectory:
    """One log file as a :class:`Trajectory` (Parquet here, other formats by ``load_trajectory``);
    ``start``, ``stop``: only those samples of a Parquet log; ``drive_chain``: the data are motor-side
    (mapped to the joint side by :func:`~symoro_gen.preprocessing.drive_chain.motor_to_joint`, as
    ``load_trajectory`` does).

    Raises
    ------
    DataFileError
        Naming the file (and the column and rows) when it cannot be read.
    """
    if str(path).lower().endswith(PARQUET_SUFFIXES):
        tr = _read_parquet(str(path), n_joints, loaded, start, stop)
        if drive_chain is None:
            return tr
        q, tau, dq, ddq = motor_to_joint(drive_chain, tr.q, tr.tau, tr.dq, tr.ddq)
        return replace(tr, q=q, tau=tau, dq=dq, ddq=ddq, meta={**tr.meta, "drive_chain": True})
    return load_trajectory(path, n_joints=n_joints, loaded=loaded, drive_chain=drive_chain, **load_kw)


def plain_format(fmt: LogFormat | None) -> bool:
    """Whether logs read with ``fmt`` are read as they are (no column mapping, units, time base or
    resampling): Parquet logs are then read by this module, row group by row group (segments)."""
    return fmt is None or (fmt.is_plain and fmt.dt is None)


def read_experiments(path: str, n_joints: int, *, fmt: LogFormat | None = None, drive_chain=None, loaded: bool = False,
                     start: int = 0, stop: int = -1, **load_kw) -> tuple[Trajectory, ...]:
    """The experiments of one log, read as ``identify`` reads its DATA files.

    With a :class:`~symoro_gen.preprocessing.logformat.LogFormat` that changes anything (the ``--columns
    --tau-scale --deg --dt --resample --drop-bad-rows`` options, docs/data-files.md) every format, Parquet
    included, is read by :func:`~symoro_gen.preprocessing.logformat.load_log` (a log may then split at
    gaps); otherwise a Parquet log is read here (``start``, ``stop``: a segment) and the others by
    ``load_trajectory`` with ``load_kw``. ``drive_chain`` (the robot file's ``[drive_chain]``): motor-side
    data mapped to the joint side, the same function as ``identify``.
    """
    if plain_format(fmt):
        return (read_log(path, n_joints, loaded=loaded, start=start, stop=stop, drive_chain=drive_chain, **load_kw),)
    if stop >= 0:
        raise FleetError(f"{path}: segments of a log need the plain format (no --columns, units or resampling)")
    return tuple(load_log(path, fmt, n_joints=n_joints, drive_chain=drive_chain, loaded=loaded)[0])


def write_parquet(path, recording: Trajectory, *, row_group_size: int = 100_000) -> None:
    """Write a recording as a Parquet log ``t, q1..qn, tau1..taun`` (read back by :func:`read_log`).

    Written to a temporary name and renamed, so a reader never sees half a file.
    """
    pq = require_pyarrow()
    import pyarrow as pa

    n = recording.q.shape[1]
    cols = {"t": recording.t}
    cols.update({f"q{j + 1}": recording.q[:, j] for j in range(n)})
    cols.update({f"tau{j + 1}": recording.tau[:, j] for j in range(n)})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(pa.table({k: np.ascontiguousarray(v, float) for k, v in cols.items()}), tmp,
                   row_group_size=row_group_size)
    os.replace(tmp, path)


def group_by(files: Sequence[LogFile]) -> dict[str, dict[str, list[LogFile]]]:
    """``{robot: {day: [files]}}`` with robots and days sorted as strings."""
    out: dict[str, dict[str, list[LogFile]]] = {}
    for f in sorted(files):
        out.setdefault(f.robot, {}).setdefault(f.day, []).append(f)
    return out
