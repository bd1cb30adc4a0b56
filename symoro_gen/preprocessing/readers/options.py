"""The data options: a :class:`LogFormat` (how to read the DATA files: columns, time base, units,
resampling, bad rows), as command-line options or a TOML file with the same keys (see
``docs/data-files.md``)::

    columns = "t=0,q=1:7,tau=13:19"     # 0-based indices, Python slices (headerless files)
    # columns = "q=q_0:q_6,tau=tau_0:tau_6"   # header names; a name range spans the header inclusively
    dt = 0.01                           # sampling period [s] when there is no time column
    dt_overrides_time = false           # dt replaces a time column (without it, both are an error)
    tau_scale = [0.5, 0.5, 0.3]         # logged signal -> N m (one per joint, or one for all)
    deg = false                         # positions (q, q_link, dq, ddq) logged in degrees
    mm = false                          # positions of the prismatic joints logged in millimetres
    resample = false                    # irregular time stamps -> uniform grid at the median step
    max_gap = 0.05                      # [s] longer steps split the file (default 5 median steps)
    drop_bad_rows = false               # drop malformed / non-finite / absurd rows, counted
    skip_rows = 0                       # data rows skipped at the start of each file (garbage rows)
    reshape = "sample-major"            # one value per line: the order of the values (or "joint-major")
    topic = "/joint_states"             # ROS bags: the JointState topic(s) (default: found by type)
    stamp = "header"                    # ROS bags: time from the header stamps or the bag's "log" times
    prefix = "left_"                    # ROS bags: the robot's joints are named prefix + name
    joint_names = ["shoulder", "elbow"] # ROS bags: the bag's names of the robot's joints, in order
    reference_topic = "/reference"      # ROS bags: commanded positions (IV/DIDIM reference)

and the :class:`LoadReport` that says what reading one file did.

Roles: ``t``, ``q``, ``tau`` (``q`` and ``tau`` required), ``dq``, ``ddq``, and ``q_link`` (a second,
link-side position: the model uses it, and the deflection ``q_motor / ratio - q_link`` is kept on
:attr:`Trajectory.deflection`). In ``.npz``/``.mat`` files a role names an array, nested MATLAB
structs with dotted names (``q=rec.act_pos_mot_deg``).
"""
from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

from ...errors import DataFileError, Problem
from .common import LOG_ROLES, StepStats

__all__ = ["LogFormat", "LoadReport", "parse_columns", "read_format_file", "make_format", "FORMAT_KEYS",
           "BAG_KEYS", "STAMPS", "MAX_GAP_STEPS", "RESHAPE_ORDERS"]

#: default ``max_gap`` in median steps
MAX_GAP_STEPS = 5
FORMAT_KEYS = ("columns", "dt", "dt_overrides_time", "tau_scale", "deg", "mm", "resample", "max_gap",
               "drop_bad_rows", "skip_rows", "reshape", "topic", "stamp", "prefix", "joint_names", "reference_topic")
#: the keys that only ROS bags use (:mod:`.bag`)
BAG_KEYS = ("topic", "stamp", "prefix", "joint_names", "reference_topic")
STAMPS = ("header", "log")
#: orders of the values of a one-value-per-line file (``--reshape``): the n joints of sample 1, then of sample
#: 2 ... (``sample-major``), or every sample of joint 1, then of joint 2 ... (``joint-major``, MATLAB's ``M(:)``)
RESHAPE_ORDERS = ("sample-major", "joint-major")


@dataclass(frozen=True)
class LogFormat:
    """How to read the DATA files of a command (every file of it).

    Attributes
    ----------
    columns : tuple of (role, spec)
        From ``--columns`` (:func:`parse_columns`); empty: the file's own names (the default names of
        :mod:`~symoro_gen.preprocessing.readers`).
    dt : float or None
        Sampling period [s] when the file has no time column.
    dt_overrides_time : bool
        ``dt`` replaces the file's time column (ignored, with a warning); without it a time column and ``dt``
        both given are an error naming the file and the column.
    tau_scale : tuple of float or None
        Factor(s) turning the logged torque signal into N m (one for all joints, or one per joint);
        applied before the drive chain.
    deg : bool
        Revolute joints' positions (and velocities, accelerations) logged in degrees; prismatic joints'
        stay in metres.
    mm : bool
        Prismatic joints' positions (and velocities, accelerations) logged in millimetres (mm/s, mm/s^2);
        revolute joints' stay as they are, and the force column of a prismatic joint is not touched
        (``tau_scale`` rescales it). Needs the robot's joint types; with a drive chain only ``q_link`` (the
        link side) is converted, the motor-side positions being motor angles.
    resample : bool
        Resample irregular time stamps on a uniform grid at the median step (linear interpolation,
        cubic for positions); steps longer than ``max_gap`` split the file.
    max_gap : float or None
        [s]; default ``MAX_GAP_STEPS`` median steps.
    drop_bad_rows : bool
        Drop rows with a wrong number of fields, unparsable or non-finite numbers, or ``|value| >
        ABSURD_VALUE`` (outside the time column); without it such rows are an error naming them.
    origin : str
        Where the format came from (a TOML file), for messages.
    topic : str
        ROS bags: the ``JointState`` topic(s), separated by commas ("": every one carrying the robot's joints).
    stamp : {"header", "log"}
        ROS bags: the time of a message, its header stamp or the bag's log time.
    prefix : str
        ROS bags: the robot's joints are named ``prefix + name`` (several robots in one bag).
    joint_names : tuple of str
        ROS bags: the bag's names of the robot's joints, in the robot's order (default: the robot file's).
    reference_topic : str
        ROS bags: commanded positions, kept as ``Trajectory.meta['q_ref']`` (IV/DIDIM reference).
    skip_rows : int
        Data rows skipped at the start of every file (below the header): garbage a logger writes before the
        recording starts.
    reshape : str or None
        A file with one value per line holds ``n`` values per sample in this order (``RESHAPE_ORDERS``); None:
        found from the data when exactly one order gives smooth signals (see :func:`.split.one_per_line`).
    """

    columns: tuple[tuple[str, str], ...] = ()
    dt: float | None = None
    tau_scale: tuple[float, ...] | None = None
    deg: bool = False
    mm: bool = False
    resample: bool = False
    max_gap: float | None = None
    drop_bad_rows: bool = False
    origin: str = ""
    dt_overrides_time: bool = False
    topic: str = ""
    stamp: str = "header"
    prefix: str = ""
    joint_names: tuple[str, ...] = ()
    reference_topic: str = ""
    skip_rows: int = 0
    reshape: str | None = None

    @property
    def column_map(self) -> dict[str, str]:
        return dict(self.columns)

    @property
    def is_plain(self) -> bool:
        """Nothing beyond ``dt``: the plain reading (:func:`~symoro_gen.preprocessing.readers.load_trajectory`)
        reads the file as is."""
        return not (self.columns or self.tau_scale or self.deg or self.mm or self.resample or self.drop_bad_rows
                    or self.skip_rows or self.reshape)

    def options(self) -> tuple[str, ...]:
        """The options that change data, as command-line text (echoed in outputs)."""
        out = []
        if self.columns:
            out.append("--columns " + ",".join(f"{k}={v}" for k, v in self.columns))
        if self.dt is not None:
            out.append(f"--dt {self.dt:g}" + (" --dt-overrides-time" if self.dt_overrides_time else ""))
        if self.tau_scale:
            out.append("--tau-scale " + ",".join(f"{v:g}" for v in self.tau_scale))
        if self.deg:
            out.append("--deg")
        if self.mm:
            out.append("--mm")
        if self.resample:
            out.append("--resample" + (f" --max-gap {self.max_gap:g}" if self.max_gap is not None else ""))
        if self.drop_bad_rows:
            out.append("--drop-bad-rows")
        if self.topic:
            out.append(f"--topic {self.topic}")
        if self.stamp != "header":
            out.append(f"--stamp {self.stamp}")
        if self.prefix:
            out.append(f"--prefix {self.prefix}")
        if self.joint_names:
            out.append("--joint-names " + ",".join(self.joint_names))
        if self.reference_topic:
            out.append(f"--reference-topic {self.reference_topic}")
        if self.skip_rows:
            out.append(f"--skip-rows {self.skip_rows}")
        if self.reshape:
            out.append(f"--reshape {self.reshape}")
        return tuple(out)


def parse_columns(spec: str, *, where: str = "--columns") -> tuple[tuple[str, str], ...]:
    """Parse ``"t=0,q=1:7,tau=13:19"`` or ``"q=q_0:q_6,tau=tau_0:tau_6"`` into (role, selector) pairs.

    Raises
    ------
    DataFileError
        Unknown or repeated role, missing ``=``, empty selector.
    """
    out: dict[str, str] = {}
    for item in str(spec).split(","):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise DataFileError([Problem(where, f"item {item!r}", "", "expected ROLE=COLUMNS, e.g. q=1:7")])
        k, v = (s.strip() for s in item.split("=", 1))
        if k not in LOG_ROLES:
            raise DataFileError([Problem(where, f"item {item!r}", k,
                                         f"unknown role (allowed: {', '.join(LOG_ROLES)})")])
        if k in out:
            raise DataFileError([Problem(where, f"item {item!r}", k, "role given twice")])
        if not v:
            raise DataFileError([Problem(where, f"item {item!r}", k, "no column given")])
        out[k] = v
    for k in ("q", "tau"):
        if k not in out:
            raise DataFileError([Problem(where, "", k, f"missing: --columns must say which columns are {k}")])
    return tuple(out.items())


def _floats(v, where, key) -> tuple[float, ...]:
    items = v if isinstance(v, (list, tuple)) else str(v).split(",")
    try:
        out = tuple(float(x) for x in items)
    except (TypeError, ValueError):
        raise DataFileError([Problem(where, "", key, f"{v!r}: expected numbers separated by commas")]) from None
    if not out or not all(math.isfinite(x) and x != 0 for x in out):
        raise DataFileError([Problem(where, "", key, f"{v!r}: factors must be finite and non-zero")])
    return out


def _positive(v, where, key) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        x = float("nan")
    if not (x > 0 and math.isfinite(x)):
        raise DataFileError([Problem(where, "", key, f"{v!r}: must be a positive number of seconds")])
    return x


def _skip_rows(v, where) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, str)) or not str(v).strip().isdigit():
        raise DataFileError([Problem(where, "", "skip_rows", f"{v!r}: must be a whole number of rows (0 or more)")])
    return int(v)


def _reshape(v, where) -> str:
    if v not in RESHAPE_ORDERS:
        raise DataFileError([Problem(where, "", "reshape", f"{v!r}: must be one of {', '.join(RESHAPE_ORDERS)}")])
    return str(v)


def read_format_file(path) -> dict:
    """Read a ``--format FILE.toml``: the keys of :class:`LogFormat` (``columns`` as a string or a
    table role -> selector). Unknown keys are an error naming the file and the key."""
    path = str(path)
    try:
        with open(path, "rb") as f:
            d = tomllib.load(f)
    except FileNotFoundError:
        raise DataFileError([Problem(path, "", "", "format file not found")]) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataFileError([Problem(path, "", "", f"not a TOML file: {exc}")]) from None
    bad = [k for k in d if k not in FORMAT_KEYS]
    if bad:
        raise DataFileError([Problem(path, "", bad[0], f"unknown key (allowed: {', '.join(FORMAT_KEYS)})")])
    if isinstance(d.get("columns"), dict):
        d["columns"] = ",".join(f"{k}={v}" for k, v in d["columns"].items())
    for k in ("deg", "mm", "resample", "drop_bad_rows", "dt_overrides_time"):
        if k in d and not isinstance(d[k], bool):
            raise DataFileError([Problem(path, "", k, f"{d[k]!r}: must be true or false")])
    return d


def _names(v, where, key) -> tuple[str, ...]:
    items = v if isinstance(v, (list, tuple)) else str(v).split(",")
    out = tuple(str(x).strip() for x in items)
    if not out or not all(out) or len(set(out)) != len(out):
        raise DataFileError([Problem(where, "", key, f"{v!r}: expected distinct names separated by commas")])
    return out


def make_format(*, format_file=None, bag: Mapping | None = None, **options: Any) -> LogFormat:
    """A :class:`LogFormat` from the data options by key (None: not given) over a format file's keys.

    ``options``: the keys of :data:`FORMAT_KEYS` but the ROS bag ones (``columns``, ``dt``, ``dt_overrides_time``,
    ``tau_scale``, ``deg``, ``mm``, ``resample``, ``max_gap``, ``drop_bad_rows``, ``skip_rows``, ``reshape``; an
    unknown name raises :class:`TypeError` naming the allowed ones); ``bag``: the ROS bag options by key
    (:data:`BAG_KEYS`: ``topic``, ``stamp``, ``prefix``, ``joint_names``, ``reference_topic``)."""
    data_keys = [k for k in FORMAT_KEYS if k not in BAG_KEYS]
    unknown = [k for k in options if k not in data_keys]
    if unknown:
        raise TypeError(f"make_format: unknown option(s) {', '.join(unknown)} (allowed: {', '.join(data_keys)})")
    bag = dict(bag or {})
    unknown = [k for k in bag if k not in BAG_KEYS]
    if unknown:
        raise TypeError(f"unknown ROS bag option(s) {', '.join(unknown)} (allowed: {', '.join(BAG_KEYS)})")
    base = read_format_file(format_file) if format_file else {}
    origin = str(format_file) if format_file else "command line"
    given = {**{k: options.get(k) for k in data_keys}, **{k: bag.get(k) for k in BAG_KEYS}}
    where = {k: ("command line" if v is not None else origin) for k, v in given.items()}
    merged = {k: (v if v is not None else base.get(k)) for k, v in given.items()}
    cols = parse_columns(merged["columns"], where=f"{where['columns']}: columns") if merged["columns"] else ()
    if merged["dt_overrides_time"] and merged["dt"] is None:
        raise DataFileError([Problem(where["dt_overrides_time"], "", "dt_overrides_time",
                                     "--dt-overrides-time replaces the time column by --dt: give --dt SECONDS")])
    st = str(merged["stamp"]) if merged["stamp"] is not None else "header"
    if st not in STAMPS:
        raise DataFileError([Problem(where["stamp"], "", "stamp", f"{st!r}: expected header or log")])
    return LogFormat(
        columns=cols,
        dt=_positive(merged["dt"], where["dt"], "dt") if merged["dt"] is not None else None,
        tau_scale=(_floats(merged["tau_scale"], where["tau_scale"], "tau_scale") if merged["tau_scale"] is not None
                   else None),
        deg=bool(merged["deg"]),
        mm=bool(merged["mm"]),
        resample=bool(merged["resample"]),
        max_gap=_positive(merged["max_gap"], where["max_gap"], "max_gap") if merged["max_gap"] is not None else None,
        drop_bad_rows=bool(merged["drop_bad_rows"]),
        origin=str(format_file or ""),
        dt_overrides_time=bool(merged["dt_overrides_time"]),
        topic=str(merged["topic"] or ""),
        stamp=st,
        prefix=str(merged["prefix"] or ""),
        joint_names=(_names(merged["joint_names"], where["joint_names"], "joint_names") if merged["joint_names"]
                     else ()),
        reference_topic=str(merged["reference_topic"] or ""),
        skip_rows=_skip_rows(merged["skip_rows"], where["skip_rows"]) if merged["skip_rows"] is not None else 0,
        reshape=_reshape(merged["reshape"], where["reshape"]) if merged["reshape"] is not None else None,
    )


@dataclass(frozen=True)
class LoadReport:
    """What reading one DATA file did (echoed in text, JSON ``data`` blocks and reports).

    Attributes
    ----------
    file : str
        The path or split-file spec.
    rows_read : int
        Data rows in the file.
    rows_dropped : int
        Rows dropped by ``--drop-bad-rows``.
    dropped : tuple of str
        Which rows and why (``"rows 12-14 (lines 13-15): wrong number of fields"``).
    resampled : bool
    step_from, step_to : float or None
        Median step of the file and step of the uniform grid [s] (``step_to`` None when not resampled).
    step_jitter : float
        Largest relative deviation of a time step from the median (0 with ``dt``).
    gaps : int
        Steps longer than ``max_gap`` (splits).
    experiments : int
        Experiments after splitting.
    samples : tuple of int
        Samples per experiment.
    options : tuple of str
        Every option that changed data.
    notes : tuple of str
        What else reading did (rows skipped, a one-value-per-line file reshaped, why the file was split).
    steps : StepStats or None
        The time steps as logged (percentiles, outliers by row, what ``--max-gap`` does with them): shown by
        ``inspect``, not in the ``data`` block of the other commands.
    """

    file: str
    rows_read: int
    rows_dropped: int = 0
    dropped: tuple[str, ...] = ()
    resampled: bool = False
    step_from: float | None = None
    step_to: float | None = None
    step_jitter: float = 0.0
    gaps: int = 0
    experiments: int = 1
    samples: tuple[int, ...] = ()
    options: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    steps: StepStats | None = None

    def to_dict(self) -> dict:
        return {"file": self.file, "rows_read": self.rows_read, "rows_dropped": self.rows_dropped,
                "dropped": list(self.dropped), "resampled": self.resampled, "step_from": self.step_from,
                "step_to": self.step_to, "step_jitter": self.step_jitter, "gaps": self.gaps,
                "experiments": self.experiments, "samples": list(self.samples), "options": list(self.options),
                "notes": list(self.notes)}

    def summary(self) -> str:
        """One line: ``file: 1647 rows read, 0 dropped, not resampled, 1 experiment (options)``."""
        s = f"{self.file}: {self.rows_read} rows read, {self.rows_dropped} dropped"
        if self.resampled:
            s += f", resampled {self.step_from:.6g} s -> {self.step_to:.6g} s"
        else:
            s += ", not resampled"
        s += f", {self.experiments} experiment{'s' if self.experiments != 1 else ''}"
        if self.gaps:
            s += f" ({self.gaps} gap{'s' if self.gaps != 1 else ''} split)"
        if self.options:
            s += " [" + " ".join(self.options) + "]"
        return s
