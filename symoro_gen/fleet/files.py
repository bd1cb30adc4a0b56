"""A fleet's log files: expansion of files and globs, robot and day from each path (``--by``), long Parquet
logs cut into segments, and each log read through the front door of the readers,
:func:`~symoro_gen.preprocessing.readers.read_recording` (CSV, NPZ, MAT, Parquet, ROS bags: ``.mcap``, ``.db3``,
``.bag`` files and rosbag2 folders, one log each; with the data options of the command line, every format),
motor-side data mapped by the robot's drive chain.

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import PARQUET_MARK, check_replaceable
from ..errors import DataFileError, Problem, SymoroError
from ..preprocessing.readers import LogFormat, is_bag, read_recording
from ..preprocessing.readers.parquet import is_parquet, parquet_rows
from ..preprocessing.trajectory import Trajectory
from ..report.plots import MissingDependencyError

__all__ = ["FleetError", "LogFile", "compile_pattern", "discover", "read_log", "require_pyarrow", "write_parquet"]


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


def _in_folder_logs(folder: str) -> list[str]:
    """The logs in a folder, recursively: its files, a rosbag2 folder (``metadata.yaml`` inside) as one log."""
    out: list[str] = []
    for root, dirs, names in os.walk(folder):
        bags = sorted(d for d in dirs if is_bag(os.path.join(root, d)))
        out += [os.path.join(root, d) for d in bags]
        dirs[:] = sorted(d for d in dirs if d not in bags)
        out += [p for p in (os.path.join(root, nm) for nm in names) if os.path.isfile(p)]
    return sorted(out)


def _expand(logs: Iterable) -> list[str]:
    files: list[str] = []
    for item in logs:
        s = os.fspath(item)
        if any(c in s for c in "*?["):
            hits = sorted(glob.glob(s, recursive=True))
            if not hits:
                raise DataFileError([Problem(s, "", "", "no file matches this glob")])
            files += [h for h in hits if os.path.isfile(h) or is_bag(h)]
        elif os.path.isdir(s) and not is_bag(s):
            files += _in_folder_logs(s)
        elif os.path.isfile(s) or (os.path.isdir(s) and is_bag(s)):
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


def require_pyarrow() -> Any:
    """Import :mod:`pyarrow.parquet`, or fail naming the ``fleet`` extra."""
    try:
        import pyarrow.parquet as pq  # type: ignore[import-untyped]
    except ImportError:  # pragma: no cover - depends on the installation
        raise MissingDependencyError("Parquet logs need pyarrow: pip install 'symoro-gen[fleet]'") from None
    return pq


def segments(logs: Sequence[LogFile], samples: int | None) -> list[LogFile]:
    """Parquet logs longer than ``samples`` cut into segments of ``samples`` (one task each, read row group
    by row group: a worker's memory is bounded by the segment, not by the log); other logs unchanged.
    A log whose footer cannot be read is kept whole (its task reports it)."""
    if not samples:
        return list(logs)
    if any(is_parquet(lf.path) for lf in logs):
        require_pyarrow()
    out = []
    for lf in logs:
        if not is_parquet(lf.path):
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


def plain_format(fmt: LogFormat | None) -> bool:
    """Whether logs read with ``fmt`` are read as they are (no column mapping, units, time base or
    resampling): only then are long Parquet logs cut into segments."""
    return fmt is None or (fmt.is_plain and fmt.dt is None)


def read_experiments(path: str, n_joints: int, *, fmt: LogFormat | None = None, drive_chain=None,
                     joint_types: Sequence[int] | None = None, loaded: bool = False, start: int = 0,
                     stop: int = -1) -> tuple[Trajectory, ...]:
    """The experiments of one log, read as ``identify`` reads its DATA files
    (:func:`~symoro_gen.preprocessing.readers.read_recording`).

    ``fmt``: the :class:`~symoro_gen.preprocessing.readers.LogFormat` of the command line's data options
    (``--columns --tau-scale --deg --dt --resample --drop-bad-rows``, docs/data-files.md; a log may then
    split at gaps); ``start``, ``stop``: a segment of a Parquet log; ``drive_chain`` (the robot file's
    ``[drive_chain]``): motor-side data mapped to the joint side, the same function as ``identify``;
    ``joint_types`` (each joint's ``sigma``): which joints ``--deg`` (revolute) and ``--mm`` (prismatic) convert,
    as ``identify`` converts them from the robot file.
    """
    trajs, _ = read_recording(path, fmt, n_joints=n_joints, drive_chain=drive_chain, joint_types=joint_types,
                              loaded=loaded, start=start, stop=stop)
    return trajs


def read_log(path: str, n_joints: int, *, loaded: bool = False, start: int = 0, stop: int = -1,
             drive_chain=None) -> Trajectory:
    """One log file read as it is, as one :class:`Trajectory` (``start``, ``stop``: only those samples of
    a Parquet log); see :func:`read_experiments`.

    Raises
    ------
    DataFileError
        Naming the file (and the column and rows) when it cannot be read.
    """
    (tr,) = read_experiments(str(path), n_joints, drive_chain=drive_chain, loaded=loaded, start=start, stop=stop)
    return tr


def write_parquet(path: str | os.PathLike, recording: Trajectory, *, row_group_size: int = 100_000,
                  force: bool = False) -> None:
    """Write a recording as a Parquet log ``t, q1..qn, tau1..taun`` (read back by :func:`read_log`).

    Written to a temporary name and renamed, so a reader never sees half a file. The file is marked
    (schema metadata :data:`~symoro_gen.atomic.PARQUET_MARK`): an existing file is replaced only when it
    carries that mark (a log written here), otherwise only with ``force`` -- a log is an input of other
    commands (:func:`~symoro_gen.atomic.check_replaceable`).

    Raises
    ------
    OutputError
        ``path`` exists, was not written by symoro-gen and ``force`` is false (nothing written).
    """
    pq = require_pyarrow()
    import pyarrow as pa

    check_replaceable(path, force, label="Parquet log")

    n = recording.q.shape[1]
    cols = {"t": recording.t}
    cols.update({f"q{j + 1}": recording.q[:, j] for j in range(n)})
    cols.update({f"tau{j + 1}": recording.tau[:, j] for j in range(n)})
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    table = pa.table({k: np.ascontiguousarray(v, float) for k, v in cols.items()}).replace_schema_metadata(PARQUET_MARK)
    pq.write_table(table, tmp, row_group_size=row_group_size)
    os.replace(tmp, out)


def group_by(files: Sequence[LogFile]) -> dict[str, dict[str, list[LogFile]]]:
    """``{robot: {day: [files]}}`` with robots and days sorted as strings."""
    out: dict[str, dict[str, list[LogFile]]] = {}
    for f in sorted(files):
        out.setdefault(f.robot, {}).setdefault(f.day, []).append(f)
    return out
