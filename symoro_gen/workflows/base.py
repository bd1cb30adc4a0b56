"""What every workflow shares (the library's use cases: identify, diagnose, inspect, excite, fleet, export).

* :class:`Options`: the named options of a workflow, a frozen dataclass validated once; an unknown option
  name raises with the nearest valid one (:func:`check_option_names`).
* :class:`Results`: what a workflow returns (statsmodels' ``fit()`` returning a results object):
  ``summary()`` (the command's text), ``to_dict()`` (exactly the command's JSON), ``_repr_html_()``
  (Jupyter), ``report(path)``, ``plot()`` and ``write_json(path)``.
* :func:`resolve_robot`: a robot given as a name, a robot file, a :class:`RobotDescription` or a loaded model.
* :func:`as_trajectories`: data given as paths, :class:`Trajectory` objects or ``(t, q, tau)`` arrays.
* :func:`provenance`: the JSON's provenance block (package version and commit, options, input hashes, seeds).
"""
from __future__ import annotations

import dataclasses
import html
import json
import os
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..atomic import check_outputs, json_output, same_file, write_output_text
from ..description import load_robot
from ..description.model import RobotDescription
from ..errors import ModelError, OptionError, SymoroError, check_option_names
from ..loader import model_for
from ..model import IdentificationModel
from ..preprocessing.motion import (
    constant_torque_warnings,
    hold_still,
    noise_level_joints,
    saturation_warnings,
    still_warnings,
)
from ..preprocessing.readers import (
    BAG_KEYS,
    DataWarning,
    LoadReport,
    LogFormat,
    make_format,
    parse_data_spec,
    read_recordings,
)
from ..preprocessing.readers.options import FORMAT_KEYS
from ..preprocessing.trajectory import Trajectory
from ..report.document import report_targets
from ..report.plots import require_matplotlib
from .provenance import SCHEMA_VERSION, file_sha256, package_commit, provenance_block

__all__ = ["SCHEMA_VERSION", "DataLike", "Options", "Results", "as_trajectories", "check_option_names", "listed",
           "file_sha256", "package_commit", "provenance", "resolve_robot", "recording_warnings", "held_still",
           "torque_limits"]

#: what a workflow accepts as data: a path, a Trajectory, ``(t, q, tau)`` arrays or a mapping with those keys
DataLike = Any


def _jsonable(x: Any) -> Any:
    """Options as JSON: paths and strings as text, sequences as lists, mappings as objects, LogFormat as its
    command-line options, NumPy numbers as floats."""
    if isinstance(x, LogFormat):
        return list(x.options())
    if isinstance(x, (str, bool, int, float)) or x is None:
        return x
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in x]
    return str(x)


@dataclasses.dataclass(frozen=True)
class Options:
    """Base of the workflows' options (frozen dataclasses; each subclass validates in ``__post_init__``)."""

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def create(cls, what: str, **given: Any):
        """The options from keywords, every name checked (:func:`check_option_names`). A workflow that reads DATA
        files (a ``data_format`` field) also takes the data options by their flags' names (``columns``, ``dt``,
        ``tau_scale``, ``format`` for ``--format FILE.toml``...: :data:`DATA_FORMAT_OPTIONS`), made into its
        ``data_format`` as the commands make it (:func:`~symoro_gen.preprocessing.readers.make_format`)."""
        return cls._from_names(what, given)

    @classmethod
    def _from_names(cls, what: str, given: Mapping[str, Any], keywords: Sequence[str] = ()):
        names = cls.option_names()
        if "data_format" in names:
            given = _with_data_format(what, given)
        # the workflow's own keywords (validate=, loaded=...) never reach here but for a misspelling: named too
        check_option_names(given, names + (DATA_FORMAT_OPTIONS if "data_format" in names else ()) + tuple(keywords),
                           what)
        return cls(**given)

    @classmethod
    def resolve(cls, what: str, options: Options | None, given: Mapping[str, Any], keywords: Sequence[str] = ()):
        """A workflow's options: ``options`` as given, or made from the keywords ``given`` (:meth:`create`);
        both at once is an :class:`OptionError`. ``keywords``: the workflow's own keyword arguments, which a
        misspelt name is matched against as well."""
        if options is None:
            return cls._from_names(what, given, keywords)
        if given:
            check_option_names(given, cls.option_names() + tuple(keywords), what)
            raise OptionError(f"{what}: give the options either as options= or by name, not both")
        return options

    def as_dict(self) -> dict:
        """Every option, JSON-ready (the provenance block's ``options``)."""
        return {f.name: _jsonable(getattr(self, f.name)) for f in dataclasses.fields(self)}


#: the data options of the commands (``--format --columns --dt``... and the ROS bag options), by their Python names
DATA_FORMAT_OPTIONS = ("format", *FORMAT_KEYS)


def _with_data_format(what: str, given: Mapping[str, Any]) -> dict[str, Any]:
    """``given`` with its data options (:data:`DATA_FORMAT_OPTIONS`) made into ``data_format``."""
    flags = {k: v for k, v in given.items() if k in DATA_FORMAT_OPTIONS}
    if not flags:
        return dict(given)
    if given.get("data_format") is not None:
        raise OptionError(f"{what}: give the data options either by name ({', '.join(flags)}) or as data_format=, "
                          "not both")
    rest = {k: v for k, v in given.items() if k not in DATA_FORMAT_OPTIONS}
    cols = flags.pop("columns", None)
    if isinstance(cols, Mapping):
        cols = ",".join(f"{role}={sel}" for role, sel in cols.items())
    bag = {k: flags.pop(k) for k in BAG_KEYS if k in flags}
    rest["data_format"] = make_format(columns=cols, format_file=flags.pop("format", None), bag=bag, **flags)
    return rest


class Results:
    """Base of the workflows' results: a subclass sets :attr:`command` and implements :meth:`to_dict`,
    :meth:`summary`, and where it has them :meth:`report` and :meth:`figures`."""

    __slots__ = ()   # no state of its own: a subclass is a frozen dataclass, or a tuple (RecordingResults)
    command: ClassVar[str] = ""

    def to_dict(self) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    def summary(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def __str__(self) -> str:
        return self.summary()

    def _repr_html_(self) -> str:
        """The summary as preformatted HTML (Jupyter)."""
        return f'<pre class="symoro-gen-{self.command}">{html.escape(self.summary())}</pre>'

    def json_text(self) -> str:
        """The JSON the command writes (``to_dict()``, its ``generator`` mark first)."""
        return json_output(self.to_dict(), self.command)

    def input_files(self) -> tuple[tuple[str, str | os.PathLike[str]], ...]:
        """``(label, path)`` of the files this result was computed from (its data, its robot file): never an
        output of its writers, even with ``force``."""
        out: list[tuple[str, str | os.PathLike[str]]] = [
            ("input", x) for x in (getattr(self, "inputs", ()) or ()) if _is_path(x)]
        robot = getattr(self, "robot", None)
        f = getattr(robot, "file", None) if robot is not None and not _is_path(robot) else robot
        if f and os.path.isfile(f):
            out.append(("robot file", f))
        return tuple(out)

    def check_output(self, path: str | os.PathLike[str], *, force: bool = False, label: str = "output",
                     report: bool = False) -> None:
        """The rule of the command line's outputs (:func:`~symoro_gen.atomic.check_outputs`) for a writer of this
        result: ``path`` (with ``report``, a report's image folder too) is not one of :meth:`input_files`
        (resolved: a symlink to one is one), and an existing file symoro-gen did not write is replaced only with
        ``force``."""
        if report:
            outs: dict = dict(report_targets(label, path))
        else:
            outs = {label: path}
        check_outputs(outs, self.input_files(), force=force)

    def write_json(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """Write :meth:`json_text` to ``path`` (an existing file symoro-gen did not write only with ``force``; an
        input of the result never)."""
        self.check_output(path, force=force, label="json")
        write_output_text(path, self.json_text(), force=force)
        return Path(path)

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """Write a report (``.html`` self-contained or ``.md`` with its images beside it)."""
        raise OptionError(f"{type(self).__name__}: no report for this result")

    def figures(self) -> list:
        """The figures of :meth:`plot` (matplotlib figures)."""
        return []

    def plot(self) -> list:
        """Matplotlib figures of the result (needs the 'plots' extra)."""
        require_matplotlib()
        return self.figures()


def robot_description(robot) -> RobotDescription:
    """The description of ``robot`` as the workflows take it: a :class:`RobotDescription`, a name or robot file
    (read, no model loaded), or a model (its description, :func:`resolve_robot`)."""
    if isinstance(robot, RobotDescription):
        return robot
    if isinstance(robot, (str, os.PathLike)):
        return load_robot(robot)
    return resolve_robot(robot)[0]


def resolve_robot(robot) -> tuple[RobotDescription, IdentificationModel]:
    """``(RobotDescription, model)`` for a robot name, a robot file, a :class:`RobotDescription` or a loaded
    model (its robot file: ``robots/<ROBOT>.toml``, or the one its package was generated from)."""
    if isinstance(robot, (str, os.PathLike, RobotDescription)):
        return model_for(robot)
    if isinstance(robot, IdentificationModel) or hasattr(robot, "BASE_NAMES"):
        desc = getattr(robot, "robot", None) or getattr(robot, "description", None)
        if isinstance(desc, RobotDescription):
            return desc, robot
        try:
            d, _ = model_for(str(robot.ROBOT))
        except SymoroError as exc:
            raise ModelError(f"model {getattr(robot, 'ROBOT', '?')!r}: its robot file is not found ({exc}); give "
                             "the robot as a name, a robot file or a RobotDescription") from None
        return d, robot
    raise OptionError(f"robot: expected a robot name, a robot file, a RobotDescription or a model, "
                      f"got {type(robot).__name__}")


def _in_memory_report(tr: Trajectory) -> LoadReport:
    d = np.diff(tr.t)
    h = float(np.median(d)) if d.size else None
    return LoadReport(file=tr.source, rows_read=tr.n_samples, step_from=h,
                      step_jitter=float(np.abs(d - h).max() / h) if h else 0.0, samples=(tr.n_samples,))


def _trajectory_of(item, n: int, loaded: bool, k: int) -> Trajectory:
    """A Trajectory from a Trajectory, a mapping ``{"t", "q", "tau"}`` or a ``(t, q, tau)`` tuple."""
    if isinstance(item, Trajectory):
        return item if item.loaded == loaded else dataclasses.replace(item, loaded=loaded)
    if isinstance(item, Mapping):
        missing = [key for key in ("t", "q", "tau") if key not in item]
        if missing:
            raise OptionError(f"data item {k + 1}: a mapping needs the keys t, q, tau (missing {', '.join(missing)})")
        t, q, tau = item["t"], item["q"], item["tau"]
    elif isinstance(item, tuple) and len(item) == 3:
        t, q, tau = item
    else:
        hint = (": a list is read as several recordings; give one recording's arrays as a (t, q, tau) tuple"
                if isinstance(item, np.ndarray) else "")
        raise OptionError(f"data item {k + 1}: expected a path, a Trajectory, a (t, q, tau) tuple or a mapping "
                          f"with those keys, got {type(item).__name__}{hint}")
    t, q, tau = (np.asarray(a, float) for a in (t, q, tau))
    q, tau = (a.reshape(-1, 1) if a.ndim == 1 else a for a in (q, tau))
    if t.ndim != 1 or q.shape != (t.size, n) or tau.shape != (t.size, n):
        raise OptionError(f"data item {k + 1}: t must have shape (N,), q and tau (N, {n}) for this robot; got "
                          f"{t.shape}, {q.shape}, {tau.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
        raise OptionError(f"data item {k + 1}: t must be finite and strictly increasing")
    return Trajectory(t=t, q=q, tau=tau, source=f"<array {k + 1}>", loaded=loaded)


def _is_path(item) -> bool:
    return isinstance(item, (str, os.PathLike))


def listed(x) -> tuple:
    """Data given as one item (a path, a Trajectory, a ``(t, q, tau)`` tuple) or a list of them, as a tuple."""
    if x is None:
        return ()
    if _is_path(x) or not isinstance(x, (list, tuple)) or (
            isinstance(x, tuple) and len(x) == 3 and not all(_is_path(i) for i in x)):
        return (x,)
    return tuple(x)


def _recording_key(item) -> tuple[str, Any]:
    """What identifies a recording: the file (a split recording's ``q=`` file: two recordings may share a ``t=``
    file), or the object given in memory."""
    if not _is_path(item):
        return ("object", id(item))
    try:
        return ("file", str(parse_data_spec(item).files.get("q", item)))
    except SymoroError:
        return ("file", str(item))  # the reader says what is wrong with it


def _same_recording(a: tuple[str, Any], b: tuple[str, Any]) -> bool:
    if a[0] != b[0]:
        return False
    return a[1] == b[1] if a[0] == "object" else (Path(a[1]).exists() and same_file(a[1], b[1]))


def refuse_repeated_recordings(data: Sequence, loaded: Sequence = (), validate: Sequence = ()) -> None:
    """One recording given twice among the identification and the loaded data (a shell glob and the name typed
    again, one in-memory recording listed twice) would count its equations twice and its standard deviations
    come out sqrt(2) too small: refused before it is read. A validation recording that is also an identification
    one is no held-out validation: warned about."""
    ident = [("identification", it, _recording_key(it), k) for k, it in enumerate(data)]
    ident += [("loaded", it, _recording_key(it), k) for k, it in enumerate(loaded)]

    def shown(k: int) -> str:
        what, item, _, pos = ident[k]
        return f"{what} data " + (str(item) if _is_path(item) else f"item {pos + 1} (in memory)")

    for i, (_, _, ka, _) in enumerate(ident):
        for j in range(i + 1, len(ident)):
            if _same_recording(ka, ident[j][2]):
                raise OptionError(f"{shown(j)}: that recording is given twice (also as {shown(i)}): its equations "
                                  "would count twice and the standard deviations come out sqrt(2) too small")
    for v in validate:
        kv = _recording_key(v)
        if any(_same_recording(ka, kv) for _, _, ka, _ in ident):
            warnings.warn(f"validation recording {v if _is_path(v) else '(in memory)'} is also an identification "
                          "recording: its errors are not on held-out data", DataWarning, stacklevel=3)


def as_trajectories(data, fmt: LogFormat | None, robot, *, loaded: bool = False
                    ) -> tuple[tuple[Trajectory, ...], tuple[LoadReport, ...]]:
    """The experiments and load reports of ``data``: one path, Trajectory or ``(t, q, tau)``, or a list of them
    (files read with ``fmt`` and the robot's drive chain, as the commands read their DATA)."""
    if data is None:
        return (), ()
    items = [data] if _is_path(data) or isinstance(data, (Trajectory, Mapping)) or (
        isinstance(data, tuple) and len(data) == 3 and not all(_is_path(x) for x in data)) else list(data)
    n = len(robot.model_joints)
    trajs: list[Trajectory] = []
    reports: list[LoadReport] = []
    paths = [it for it in items if _is_path(it)]
    read, reps = read_recordings(paths, fmt, n_joints=n, robot=robot, drive_chain=robot.drive_chain,
                           loaded=loaded) if paths else ((), ())
    by_file = iter(zip(reps, _group(read, reps)))
    for k, it in enumerate(items):
        if _is_path(it):
            rep, trs = next(by_file)
            trajs += trs
            reports.append(rep)
        else:
            tr = _trajectory_of(it, n, loaded, k)
            trajs.append(tr)
            reports.append(_in_memory_report(tr))
    return tuple(trajs), tuple(reports)


def torque_limits(robot) -> tuple[float, ...] | None:
    """The robot file's ``[limits] tau_max`` (one per joint of the model), or None."""
    lim = getattr(robot, "limits", None)
    tau_max = getattr(lim, "tau_max", None) if lim is not None else None
    return tuple(float(x) for x in tau_max) if tau_max else None


def recording_warnings(robot, trajectories: Sequence[Trajectory], *, held: bool, dropped: bool,
                       unexcited_option: bool = True) -> tuple[str, ...]:
    """The warnings on recordings a workflow identifies from: joints that move at the noise level, torques at
    their limit and torques that never change (:mod:`symoro_gen.preprocessing.motion`), each naming the file,
    the joint and the option that fixes it (``held``: ``--drop-unexcited`` given; ``dropped``: ``--drop-saturated`` given;
    ``unexcited_option`` False: the command has no ``--drop-unexcited``). Each is also
    issued as a :class:`~symoro_gen.preprocessing.readers.DataWarning` (printed by the command line)."""
    msgs = (*still_warnings(trajectories, held=held, option=unexcited_option),
            *saturation_warnings(trajectories, torque_limits(robot), dropped=dropped),
            *constant_torque_warnings(trajectories))
    for m in msgs:
        warnings.warn(m, DataWarning, stacklevel=3)
    return msgs


def held_still(trajectories: Sequence[Trajectory]) -> tuple[Trajectory, ...]:
    """The recordings with every joint that moves at the noise level held still
    (:func:`~symoro_gen.preprocessing.motion.hold_still`: ``--drop-unexcited``)."""
    return tuple(hold_still(tr, noise_level_joints(tr.q)) for tr in trajectories)


def _group(trajs: Sequence[Trajectory], reps: Sequence[LoadReport]) -> list[list[Trajectory]]:
    """The experiments of each file (a report counts its file's experiments)."""
    out, i = [], 0
    for r in reps:
        out.append(list(trajs[i:i + r.experiments]))
        i += r.experiments
    return out


def provenance(options: Options, inputs: Iterable = (), seeds: Mapping[str, Any] | None = None) -> dict:
    """The JSON's provenance block (:func:`~symoro_gen.workflows.provenance.provenance_block`) of a workflow's
    options: package version and commit, every option, each input file with its sha256 (in-memory data as its
    source name, hash null), the seeds used."""
    return provenance_block(options.as_dict(), inputs, seeds)


def dumps(obj: Mapping) -> str:
    """JSON text as the commands write it (indent 2)."""
    return json.dumps(obj, indent=2) + "\n"
