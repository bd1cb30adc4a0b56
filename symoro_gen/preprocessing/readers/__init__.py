"""Reading recordings: one front door, :func:`read_recording` (one file, or the files of a split
recording, = one experiment, unless resampling splits it at gaps), for every format.

Formats, one module each: delimited text (:mod:`.text`: ``.csv .txt .tsv .dat``), arrays
(:mod:`.arrays`: ``.npz``, MATLAB ``.mat``), Parquet (:mod:`.parquet`, read by segment of row groups for
the fleet), ROS bags (:mod:`.bag`: ``.mcap .db3 .bag`` or a rosbag2 folder, ``sensor_msgs/JointState``
topics, joints matched by name), split recordings (:mod:`.split`: a spec string
``q=pos.csv,tau=cur.csv,dt=0.0002``). What
they share (roles, column resolution, problems named by rows and lines, checks of values, time and
units) is in :mod:`.common`.

Two readings of the same columns: the plain one (:mod:`.plain`, the file as it is: every problem raised
together, unit mix-ups warned about; :func:`load_trajectory` with a ``columns`` mapping and limits from
Python) and the one with the data options (:mod:`.logs`, a :class:`LogFormat` from :mod:`.options`:
columns by index or name, units, time base, resampling, bad rows dropped, with a :class:`LoadReport`).
:func:`read_recording` takes the plain one when the format changes nothing but ``dt`` (Parquet logs and
segments always take the other).

Default columns of a table with a header: ``t, q1..qn, tau1..taun [, dq1..dqn] [, ddq1..ddqn]``; default
array keys in :mod:`.arrays`. ``drive_chain`` (a :class:`~symoro_gen.description.model.DriveChain`,
usually ``robot.drive_chain``) says the data are motor-side: positions, velocities, accelerations and
torques are mapped to the joint side by :func:`~symoro_gen.preprocessing.drive_chain.motor_to_joint`.
"""
from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ...errors import DataFileError, Problem, check_option_names
from ...progress import progress_updates
from ..trajectory import Trajectory
from .arrays import ARRAY_SUFFIXES, read_array_file
from .bag import BAG_SUFFIXES, is_bag, read_bag
from .common import (
    ABSURD_VALUE,
    DEFAULT_CHECKS,
    LOG_ROLES,
    DataChecks,
    DataWarning,
    RawColumns,
    StepStats,
    step_regime_changes,
    step_stats,
)
from .logs import log_trajectories, time_order_hint
from .options import BAG_KEYS, LoadReport, LogFormat, make_format, parse_columns, read_format_file
from .parquet import PARQUET_SUFFIXES, is_parquet, read_parquet_file
from .plain import plain_trajectory
from .split import DataSpec, parse_data_spec, read_split
from .text import TEXT_SUFFIXES, read_text_file

__all__ = [
    "read_recording", "read_recordings", "load_trajectory", "load_trajectories",
    "LogFormat", "LoadReport", "make_format", "parse_columns", "read_format_file",
    "DataSpec", "parse_data_spec", "DataChecks", "DataWarning", "step_regime_changes",
    "ABSURD_VALUE", "LOG_ROLES", "PARQUET_SUFFIXES", "BAG_SUFFIXES", "is_bag", "StepStats",
]

PathOrSpec = str | os.PathLike | DataSpec
#: the named keywords of :func:`read_recording` (besides the ROS bag options): a misspelt one is named
READ_OPTIONS = ("fmt", "robot", "n_joints", "drive_chain", "loaded", "start", "stop", "base_dir", "joint_types")


def _read_columns(spec: DataSpec, n: int, *, mapping: Mapping | None, selectors: Sequence[tuple[str, str]],
                  dt: float | None, probs: list[Problem], strict: bool, start: int = 0, stop: int = -1,
                  skip_rows: int = 0, reshape: str | None = None) -> RawColumns:
    """The columns of each role, by the reader of the file's format (``strict``: the plain reading;
    ``skip_rows``, ``reshape``: as :class:`LogFormat`)."""
    if spec.is_split:
        if stop >= 0:
            raise ValueError(f"{spec.text}: only Parquet logs are read by segment (start, stop)")
        return read_split(spec, n, dt, probs, strict=strict, skip_rows=skip_rows, reshape=reshape)
    if reshape is not None:
        raise DataFileError([Problem(spec.text, "", "reshape", "--reshape reads the one-value-per-line files of a "
                                     "split recording (q=FILE,tau=FILE,...): a single file holds several roles")])
    raw = _read_file(spec, n, mapping=mapping, selectors=selectors, dt=dt, probs=probs, strict=strict, start=start,
                     stop=stop, skip_rows=skip_rows)
    if skip_rows and raw.fmt != "csv":  # text tables skip while reading (file lines kept)
        if skip_rows >= raw.n_rows:
            raise DataFileError([Problem(spec.text, "", "skip_rows", f"--skip-rows {skip_rows}: the file has only "
                                         f"{raw.n_rows} rows")])
        for role, col in raw.cols.items():
            col.values = col.values[skip_rows:]
            col.lines = col.lines[skip_rows:] if col.lines is not None else None
            if role in raw.unparsable:
                raw.unparsable[role] = raw.unparsable[role][skip_rows:]
        if raw.bad_fields is not None:
            raw.bad_fields = raw.bad_fields[skip_rows:]
        raw.notes.append(f"rows 1-{skip_rows} skipped (--skip-rows {skip_rows})")
    return raw


def _read_file(spec: DataSpec, n: int, *, mapping: Mapping | None, selectors: Sequence[tuple[str, str]],
               dt: float | None, probs: list[Problem], strict: bool, start: int, stop: int, skip_rows: int
               ) -> RawColumns:
    """One file's columns, by the reader of its format."""
    file = spec.files["file"]
    if not Path(file).exists():
        raise DataFileError([Problem(file, "", "", "file not found")])
    if is_parquet(file):
        return read_parquet_file(file, n, mapping=mapping, selectors=selectors, dt=dt, probs=probs, strict=strict,
                                 start=start, stop=stop)
    if stop >= 0:
        raise ValueError(f"{file}: only Parquet logs are read by segment (start, stop)")
    suffix = Path(file).suffix.lower()
    if suffix in TEXT_SUFFIXES:
        return read_text_file(file, n, mapping=mapping, selectors=selectors, dt=dt, probs=probs, strict=strict,
                              skip_rows=skip_rows)
    if suffix in ARRAY_SUFFIXES:
        return read_array_file(file, suffix[1:], n, mapping=mapping, selectors=selectors, dt=dt, probs=probs)
    known = ", ".join((*TEXT_SUFFIXES, *ARRAY_SUFFIXES, *PARQUET_SUFFIXES))
    raise DataFileError([Problem(file, "", "", f"unknown data format {suffix!r} (expected {known}, a ROS bag "
                                 f"{'/'.join(BAG_SUFFIXES)} or a q=...,tau=... spec)")])


def _joint_count(robot, n_joints: int | None) -> int:
    if robot is not None and n_joints is None:
        n_joints = len(robot.model_joints)
    if n_joints is None or int(n_joints) < 1:
        raise ValueError("n_joints (or robot) is required")
    return int(n_joints)


def _joint_types(robot) -> list[int] | None:
    return [r.sigma for r in robot.model_joints] if robot is not None else None


def load_trajectory(path: PathOrSpec, *, n_joints: int | None = None, columns: Mapping | None = None,
                    dt: float | None = None, loaded: bool | None = None, drive_chain=None, robot=None,
                    base_dir=None, checks: DataChecks = DEFAULT_CHECKS, dt_overrides_time: bool = False
                    ) -> Trajectory:
    """Read one experiment as it is (the plain reading; see the package docstring for formats and
    :mod:`.plain` for the checks).

    Parameters
    ----------
    path : str or PathLike or DataSpec
        A ``.csv``/``.txt``, ``.npz``, ``.mat`` or ``.parquet`` file, or a spec string
        ``"q=a.csv,tau=b.csv,dt=0.0002"``.
    n_joints : int
        Number of joints of the robot (default ``robot.n_joints``).
    columns : mapping, optional
        Role (``t q tau dq ddq``) -> column name template with ``{j}`` (the 1-based joint number, e.g.
        ``{"q": "pos_{j}"}``), list of ``n`` names, or for ``"t"`` one name (tables); array key (NPZ/MAT).
    dt : float, optional
        Sampling period [s] when the data have no time; with a time column an error unless
        ``dt_overrides_time``.
    dt_overrides_time : bool
        ``dt`` replaces the time column (ignored, with a warning).
    loaded : bool, optional
        Payload mounted during this experiment (default: the spec's ``loaded=``, else False).
    drive_chain : DriveChain, optional
        The data are motor-side; map them to the joint side.
    robot : RobotDescription, optional
        Supplies ``n_joints`` and the joint types used by the unit checks.
    base_dir : path, optional
        Base of the relative paths in a spec string.
    checks : DataChecks
        Limits of the time checks, of the length and of the unit-mix-up warnings.

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
    n = _joint_count(robot, n_joints)
    spec = parse_data_spec(path, base_dir=base_dir)
    dt = spec.dt if dt is None else dt
    if loaded is None:
        loaded = bool(spec.loaded) if spec.loaded is not None else False
    if spec.is_split and columns:
        raise ValueError("columns cannot be used with a split-file spec (each file holds one role)")
    if not spec.is_split and is_bag(spec.files["file"]):  # a ROS bag: its joints by name, one experiment
        (tr,), _ = read_bag(spec.files["file"], LogFormat(dt=dt, dt_overrides_time=dt_overrides_time), n=n,
                            robot=robot, dt=dt, loaded=loaded, drive_chain=drive_chain, joint_types=_joint_types(robot))
        return tr
    probs: list[Problem] = []
    raw = _read_columns(spec, n, mapping=columns, selectors=(), dt=dt, probs=probs, strict=True)
    return plain_trajectory(raw, probs, n=n, dt=dt, loaded=loaded, drive_chain=drive_chain,
                            joint_types=_joint_types(robot), checks=checks, dt_overrides_time=dt_overrides_time)


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


def read_recording(path: PathOrSpec, fmt: LogFormat | None = None, *, robot=None, n_joints: int | None = None,
                   drive_chain=None, loaded: bool = False, start: int = 0, stop: int = -1, base_dir=None,
                   joint_types: Sequence[int] | None = None, **bag: Any) -> tuple[tuple[Trajectory, ...], LoadReport]:
    """Read one DATA file (or split-file spec) with a :class:`LogFormat`.

    Parameters
    ----------
    path : str or PathLike or DataSpec
        A ``.csv``/``.txt``/``.npz``/``.mat``/``.parquet`` file or a ``q=..,tau=..,dt=..`` spec.
    fmt : LogFormat, optional
        Default: the file's own names (the plain reading, as :func:`load_trajectory`).
    robot, n_joints, drive_chain, base_dir
        As for :func:`load_trajectory`.
    joint_types : sequence of int, optional
        Each joint's MDH ``sigma`` (0 revolute, 1 prismatic), which ``--deg`` and ``--mm`` convert; default the
        robot's (none without a robot). For a caller that has the joint types but not the robot description
        (the fleet's workers).
    loaded : bool
        Payload mounted during this experiment.
    start, stop : int
        Only the samples ``[start, stop)`` of a Parquet log (``stop < 0``: the whole file), read row
        group by row group; the experiment is named ``path[start:stop]``.
    **bag
        ROS bags (:mod:`.bag`): ``topic``, ``stamp``, ``prefix``, ``joint_names``, ``reference_topic`` override the
        fields of the same names of ``fmt`` (None: not given); any other name raises
        :class:`~symoro_gen.errors.OptionError` naming the nearest option.

    Returns
    -------
    (trajectories, report)
        One trajectory per experiment (a file splits at gaps with ``resample``), and what was done.

    Raises
    ------
    DataFileError
        One line per problem, naming the file, rows (and file lines) and column.
    """
    fmt = fmt or LogFormat()
    if bag:
        check_option_names(bag, (*READ_OPTIONS, *BAG_KEYS), "read_recording")
        fmt = _with_bag_options(fmt, bag)
    if robot is None and n_joints is None:
        raise TypeError("read_recording: give n_joints or robot")
    n = _joint_count(robot, n_joints)
    types = _joint_types(robot) if joint_types is None else [int(s) for s in joint_types]
    if len(types or ()) not in (0, n):
        raise ValueError(f"read_recording: {len(types or ())} joint types given for {n} joints")
    spec = parse_data_spec(path, base_dir=base_dir)
    if not spec.is_split and is_bag(spec.files["file"]):
        if stop >= 0:
            raise ValueError(f"{spec.text}: only Parquet logs are read by segment (start, stop)")
        return read_bag(spec.files["file"], fmt, n=n, robot=robot, dt=fmt.dt, loaded=loaded,
                        drive_chain=drive_chain, joint_types=types)
    if spec.dt is not None and fmt.dt is not None and not math.isclose(spec.dt, fmt.dt, rel_tol=1e-12):
        raise DataFileError([Problem(spec.text, "", "dt", f"the spec says dt = {spec.dt:g} s, --dt {fmt.dt:g}: "
                                     "give the sampling period once")])
    dt = fmt.dt if fmt.dt is not None else spec.dt
    if spec.is_split and "t" in spec.files and dt is not None and not fmt.dt_overrides_time:
        key = "--dt" if fmt.dt is not None else ("dt=" if "dt=" in spec.text else "fs=")
        given = "--dt" if fmt.dt is not None else f"the spec's {key}"
        raise DataFileError([Problem(spec.files["t"], "", "t", f"the t= file of the split recording gives the time "
                                     f"and {given} gives a sampling period ({dt:g} s): leave {key} out to use the "
                                     "t= file, or give --dt-overrides-time to ignore the t= file")],
                            hint="--dt is the sampling period of files without time stamps")
    if fmt.is_plain and stop < 0 and (spec.is_split or not is_parquet(spec.files["file"])):
        probs: list[Problem] = []
        raw = _read_columns(spec, n, mapping=None, selectors=(), dt=dt, probs=probs, strict=True)
        t_raw = raw.cols["t"].values[:, 0] if "t" in raw.cols and not fmt.dt_overrides_time else None
        t_lines = raw.cols["t"].lines if t_raw is not None else None
        try:
            tr = plain_trajectory(raw, probs, n=n, dt=dt, loaded=loaded, drive_chain=drive_chain,
                                  joint_types=types, dt_overrides_time=fmt.dt_overrides_time)
        except DataFileError as exc:  # time out of order: the option that fixes it (--skip-rows ...)
            if t_raw is None or not any("not strictly increasing" in p.message for p in exc.problems):
                raise
            raise DataFileError(exc.problems, hint=time_order_hint(t_raw)) from None
        rep = LoadReport(file=tr.source, rows_read=tr.n_samples, step_from=tr.meta.get("dt_median"),
                         step_jitter=float(tr.meta.get("dt_max_rel_jitter", 0.0)), samples=(tr.n_samples,),
                         options=fmt.options(), notes=tuple(raw.notes),
                         steps=step_stats(t_raw if t_raw is not None else tr.t, t_lines, fmt.max_gap))
        return (tr,), _ignored_bag_options(rep, fmt)
    if spec.is_split and fmt.columns:
        raise DataFileError([Problem(spec.text, "", "columns", "--columns cannot be used with a split-file "
                                     "spec (each file holds one role)")])
    probs = []
    raw = _read_columns(spec, n, mapping=None, selectors=fmt.columns, dt=dt, probs=probs, strict=False,
                        start=start, stop=stop, skip_rows=fmt.skip_rows, reshape=fmt.reshape)
    if probs:
        raise DataFileError(probs)
    trajs, rep = log_trajectories(raw, fmt, n=n, dt=dt, loaded=loaded, drive_chain=drive_chain,
                                  joint_types=types)
    return trajs, _ignored_bag_options(rep, fmt)


def _ignored_bag_options(rep: LoadReport, fmt: LogFormat) -> LoadReport:
    """A file that is not a ROS bag read with bag options (a command's options apply to all its files): the
    report says they were not used for it."""
    given = [o for o in fmt.options() if o.split()[0] in ("--topic", "--stamp", "--prefix", "--joint-names",
                                                         "--reference-topic")]
    if not given:
        return rep
    return dataclasses.replace(rep, notes=(*rep.notes, f"{', '.join(o.split()[0] for o in given)}: options of ROS "
                                                       "bags, not used for this file"))


def _with_bag_options(fmt: LogFormat, opts: Mapping) -> LogFormat:
    """``fmt`` with the bag options given to :func:`read_recording` (checked as on the command line)."""
    given = {k: v for k, v in opts.items() if v is not None}
    checked = make_format(bag=opts)  # unknown keys: a TypeError naming them; values checked as on the command line
    return dataclasses.replace(fmt, **{k: getattr(checked, k) for k in given})


def read_recordings(paths: Iterable, fmt: LogFormat | None = None, *, progress=None, **kwargs
                    ) -> tuple[tuple[Trajectory, ...], tuple[LoadReport, ...]]:
    """:func:`read_recording` on several files; the problems of all files are raised together.

    ``progress``: as for :func:`load_trajectories` (a per-file bar on the command line)."""
    paths = list(paths)
    trajs: list[Trajectory] = []
    reps: list[LoadReport] = []
    probs: list[Problem] = []
    hint = None
    with progress_updates(progress, total=len(paths), desc="loading data", unit="file") as step:
        for p in paths:
            try:
                tr, rep = read_recording(p, fmt, **kwargs)
            except DataFileError as exc:
                probs.extend(exc.problems)
                hint = hint or exc.hint
                step(1)
                continue
            trajs.extend(tr)
            reps.append(rep)
            step(1)
    if probs:
        raise DataFileError(probs, hint=hint)
    return tuple(trajs), tuple(reps)
