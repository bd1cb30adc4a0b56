"""``export_urdf``, ``export_mjcf``, ``export_par``: a robot (and an identification) -> URDF, MuJoCo MJCF or
SYMORO+ ``.par`` text.

The workflows of ``symoro-gen export-urdf``, ``export-mjcf`` and ``export-par`` as library calls::

    res = symoro_gen.export_urdf("lwr4", from_result="lwr4.json")   # or an IdentifyResults, or its to_dict()
    res.text; res.notes; res.sidecar; res.write("lwr4.urdf")

With ``from_result`` every body comes from a physically consistent standard set whose regrouping gives the
identified base parameters (the 'physical' extra); ``res.sidecar`` then holds the drive terms and how far each
body moved from nominal (written as ``OUT.json`` beside the file). These workflows stay free of SciPy (the light
commands start without it): the identification stack is loaded only when ``from_result`` is given
(:func:`_standard_set_from_result`), and the results are not :class:`~symoro_gen.workflows.base.Results`
(whose module loads the data readers) but offer the same ``summary()``, ``to_dict()`` (with ``schema_version``
and ``provenance``), ``json_text()``, ``_repr_html_()``, ``plot()`` and ``report(path)``.
"""
from __future__ import annotations

import html
import importlib
import json
import math
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..atomic import check_outputs, json_output, write_output_text
from ..description.friction_law import with_identified_laws
from ..description.identity import check_result_robot
from ..description.mjcf_export import export_mjcf as mjcf_text
from ..description.model import RobotDescription
from ..description.par import export_par as par_text
from ..description.urdf_export import drive_terms, link_values
from ..description.urdf_export import export_urdf as urdf_text
from ..errors import ModelError, OptionError, named_options
from ..loader import model_for
from ..report.document import check_report_path, report_targets
from ..report.plots import require_matplotlib
from .base import robot_description
from .export_report import bodies_figure, write_export_report
from .provenance import SCHEMA_VERSION, provenance_block

__all__ = ["ExportResults", "export_mjcf", "export_par", "export_urdf"]

#: an identification result: the path of a ``symoro-gen identify`` JSON, its content, or an ``IdentifyResults``
ResultLike = Any

DRIVE_NOTE = ("IA (rotor inertia) and OFF (torque offset) have no URDF field: MuJoCo's armature holds IA; FV, FS "
              "are URDF <dynamics damping friction>")


@dataclass(frozen=True, eq=False)
class ExportResults:
    """The text an export writes, the notes about the links it changed and, from an identification, the sidecar.

    Attributes
    ----------
    command : {"export-urdf", "export-mjcf", "export-par"}
    robot : RobotDescription
    text : str
        The URDF, MJCF or ``.par`` text (what the command writes to ``-o`` or prints).
    notes : tuple of str
        What the exporter changed to write a valid file (the command's ``note:`` lines on standard error).
    sidecar : dict, optional
        With ``from_result``: the robot, the result's file, whether the regrouping is exact, the bodies, the drive
        terms and the changed links (the command's ``OUTPUT.json``, which :meth:`to_dict` is).
    inputs : tuple
        What the export read besides the robot file (an identification result: a path, a mapping or a results
        object; None when not given).
    options : mapping
        The options of the call, JSON-ready (the provenance block's ``options``).
    values : mapping, optional
        ``name -> value`` of every standard (and payload) parameter the export wrote (:meth:`plot`, :meth:`report`).
    """

    command: str
    robot: RobotDescription
    text: str
    notes: tuple[str, ...] = ()
    sidecar: Mapping[str, Any] | None = field(default=None, repr=False)
    inputs: tuple[Any, ...] = ()             # the files read besides the robot file (an identification result)
    options: Mapping[str, Any] = field(default_factory=dict, repr=False)
    values: Mapping[str, float] | None = field(default=None, repr=False)

    def summary(self) -> str:
        """The text (what the command prints without ``-o``)."""
        return self.text

    def __str__(self) -> str:
        return self.summary()

    def _repr_html_(self) -> str:
        return f'<pre class="symoro-gen-{self.command}">{html.escape(self.text)}</pre>'

    def provenance(self) -> dict:
        """The provenance block (:func:`~symoro_gen.workflows.provenance.provenance_block`): package version and
        commit, the options, the robot file and the identification read (each with its sha256; one given in
        memory as ``<in memory>``, hash null)."""
        given = [x for x in self.inputs if x is not None]
        robot_file = getattr(self.robot, "file", None)
        return provenance_block(self.options, [*([robot_file] if robot_file else []), *given])

    def to_dict(self) -> dict:
        """The sidecar as the command writes it (``generator`` first, then ``schema_version``, the sidecar's keys
        and ``provenance`` last); without an identification (no sidecar file), the robot and the changed links
        with the same ``schema_version`` and ``provenance``."""
        body = dict(self.sidecar) if self.sidecar is not None else {"robot": self.robot.name,
                                                                    "changed_links": list(self.notes)}
        return {"generator": f"symoro-gen {self.command}", "schema_version": SCHEMA_VERSION, **body,
                "provenance": self.provenance()}

    def json_text(self) -> str:
        """The sidecar's JSON text (:meth:`to_dict`)."""
        return json_output(self.to_dict(), self.command)

    def _input_files(self) -> list[tuple[str, str | os.PathLike[str]]]:
        robot_file = getattr(self.robot, "file", None)
        inputs: list[tuple[str, str | os.PathLike[str]]] = [
            ("input", x) for x in self.inputs if isinstance(x, (str, os.PathLike))]
        return [*inputs, *([("robot file", robot_file)] if robot_file else [])]

    def write(self, path: str | os.PathLike[str], *, force: bool = False) -> list[Path]:
        """Write the text to ``path`` and, with a sidecar, ``PATH.json``; an existing file symoro-gen did not
        write is replaced only with ``force``; the robot file, or the identification result the export was made
        from, never (resolved: a symlink to one is one). Returns the paths written."""
        outs = {"-o/--output": Path(path)}
        if self.sidecar is not None:
            outs["-o/--output (its .json)"] = Path(str(path) + ".json")
        check_outputs(outs, self._input_files(), force=force)
        write_output_text(Path(path), self.text, force=force, label="-o/--output")
        out = [Path(path)]
        if self.sidecar is not None:
            side = Path(str(path) + ".json")
            write_output_text(side, self.json_text(), force=force, label="-o/--output (its .json)")
            out.append(side)
        return out

    def figures(self) -> list:
        """The figure of :meth:`plot`: every body's mass, centre-of-mass shift and inertia as exported beside the
        robot file's nominal values (:func:`~symoro_gen.workflows.export_report.bodies_figure`)."""
        return [bodies_figure(self).figure]

    def plot(self) -> list:
        """Matplotlib figures of the export (needs the 'plots' extra: without it
        :class:`~symoro_gen.report.MissingDependencyError` names it)."""
        require_matplotlib()
        return self.figures()

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """Write the export's report (``.html`` self-contained or ``.md`` with its image beside it): the bodies
        against nominal (table and figure), the drive terms, the notes and the exported text; needs the 'plots'
        extra. An existing file symoro-gen did not write is replaced only with ``force``; an input never."""
        require_matplotlib()
        check_report_path(path)
        check_outputs(dict(report_targets("report", path)), self._input_files(), force=force)
        return write_export_report(path, self, force=force)


@dataclass(frozen=True)
class _Values:
    """What an export writes beside the robot file's nominal values (all None/empty: the nominal robot)."""

    chi: list[float] | None = None
    payload: list[float] | None = None
    header: tuple[str, ...] = ()
    sidecar: dict | None = None


_RESULT_HINT = "give the JSON file that `symoro-gen identify ROBOT DATA... --json OUT.json` wrote"


def _read_result_file(src: str) -> Any:
    """The JSON content of a result file; a missing file, a folder, unreadable or non-JSON text is an error
    naming the file and what it is instead (the line and column of the first JSON error)."""
    path = Path(src)
    if path.is_dir():
        what = "a folder, not a result file"
    elif not path.exists():
        what = "file not found"
    else:
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            what = f"cannot read: {exc.strerror or exc}"
        except UnicodeDecodeError:
            what = "not JSON (not even UTF-8 text)"
        except json.JSONDecodeError as exc:
            what = f"not JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
    raise _not_a_result(f"{src}: {what}; expected the JSON result of `symoro-gen identify`")


def _not_a_result(message: str) -> ModelError:
    err = ModelError(message)
    err.hint = _RESULT_HINT
    return err


def _result_dict(result: ResultLike) -> tuple[dict, str]:
    """``(JSON content, source name)`` of an identification result given as a path, a mapping or a results
    object (``to_dict()``)."""
    if isinstance(result, (str, os.PathLike)):
        src = os.fspath(result)
        doc = _read_result_file(src)
    else:
        src = "the identification result"
        doc = result.to_dict() if hasattr(result, "to_dict") else result
    if not isinstance(doc, dict):
        raise _not_a_result(f"{src}: not a result of `symoro-gen identify` (a JSON object is expected)")
    return doc, src


def _standard_set_from_result(*args: Any, **kwargs: Any) -> Any:
    """:func:`symoro_gen.identification.physical.standard_set_from_result`, its module (SciPy, the 'physical'
    extra's solver) loaded on this first use only: an export without an identification stays light."""
    return importlib.import_module("symoro_gen.identification.physical").standard_set_from_result(*args, **kwargs)


def _values(robot: RobotDescription, result: ResultLike, command: str) -> _Values:
    """The standard and payload values, header notes and sidecar of an export from an identification (refused
    when it is another robot's: :func:`~symoro_gen.description.identity.check_result_robot`)."""
    doc, src = _result_dict(result)
    check_result_robot(doc, robot, option="--from", source=src, command=command)
    name = Path(src).name if isinstance(result, (str, os.PathLike)) else src
    if robot.floating:  # the identified combinations and their relations K, from the result itself
        model = importlib.import_module("symoro_gen.identification.floating").RelationsModel.from_result(
            robot, doc, src)
    else:
        _, model = model_for(robot)
    nominal = dict(zip(robot.standard_names, robot.nominal_vector() or ()))
    sb, payload = _standard_set_from_result(model, doc, nominal, source=src)
    vals = sb.as_dict()
    chi = [vals.get(n, 0.0) for n in robot.standard_names]
    pay = None
    notes = [f"inertial and drive parameters from {name}: physically consistent standard set whose regrouping "
             f"{'is exactly' if sb.exact else 'is the closest (least squares) to'} the identified base parameters"]
    if robot.payload is not None:
        if payload:
            pay = [payload[n] for n in robot.payload_names]
            notes.append(f"payload (frame {robot.payload}) as identified in {name}")
        else:  # the identified model is the robot without the payload: do not mount the nominal one
            pay = [0.0] * len(robot.payload_names)
            notes.append(f"payload (frame {robot.payload}) not identified in {name}: written without mass")
    notes += list(sb.notes)
    for b in (b for b in sb.bodies if "mass_change" in b):
        notes.append(f"{b['body']}: mass {b['mass']:.6g} kg ({b['mass_change']:+.3g} from nominal), centre of mass "
                     f"moved {b['com_shift']:.3g} m" + (f", inertia changed {100 * b['inertia_change_rel']:.3g} %"
                                                        if b.get("inertia_change_rel") is not None else ""))
    sidecar = {"robot": robot.name, "from": src, "exact": sb.exact, "base_error": sb.base_error,
               "notes": list(sb.notes), "bodies": list(sb.bodies), "active_constraints": list(sb.active_constraints)}
    return _Values(chi, pay, tuple(notes), sidecar)


def _option_json(x: Any) -> Any:
    """An export's option for the provenance block: a path as text, names and values as given, a result given
    in memory (its content or a results object) as ``<in memory>``."""
    if x is None or isinstance(x, (bool, int, float, str)):
        return x
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    if isinstance(x, Mapping) and "parameters" not in x and all(isinstance(v, (int, float)) for v in x.values()):
        return {str(k): float(v) for k, v in x.items()}
    return "<in memory>"


def _written_values(robot: RobotDescription, v: _Values, params: dict[str, float] | None = None) -> dict:
    """Every standard and payload parameter the export writes (the exporter itself warns about ignored names)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return link_values(robot, v.chi, v.payload, params=params)


def _finish(command: str, robot: RobotDescription, text: str, changed: list[str], v: _Values,
            inputs: tuple[Any, ...] = (), options: Mapping[str, Any] | None = None,
            params: dict[str, float] | None = None) -> ExportResults:
    sidecar = None
    vals = _written_values(robot, v, params)
    if v.sidecar is not None:
        sidecar = dict(v.sidecar, drive=drive_terms(robot, link_values(robot, v.chi, v.payload)),
                       drive_note=DRIVE_NOTE, changed_links=list(changed))
    opts = {k: _option_json(x) for k, x in (options or {}).items()}
    return ExportResults(command, robot, text, tuple(changed), sidecar, inputs=inputs, options=opts, values=vals)


def _identified_parameters(params: ResultLike, robot: RobotDescription) -> dict[str, float]:
    """``name -> value`` of an identify result's ``parameters`` (a mapping without that key is taken as the
    names and values themselves); a result of another robot is refused
    (:func:`~symoro_gen.description.identity.check_result_robot`)."""
    if isinstance(params, Mapping) and "parameters" not in params:
        return {str(n): float(v) for n, v in params.items() if v is not None}
    doc, src = _result_dict(params)
    check_result_robot(doc, robot, option="--params", source=src, command="export-urdf")
    try:
        p = doc["parameters"]
        return {n: v for n, v in zip(p["names"], p["values"]) if v is not None}
    except (KeyError, TypeError) as exc:
        raise _not_a_result(f"{src}: not a result of `symoro-gen identify` (no {exc})") from None


@named_options
def export_urdf(robot, *, params: ResultLike = None, from_result: ResultLike = None) -> ExportResults:
    """The robot as URDF (``symoro-gen export-urdf``).

    Parameters
    ----------
    robot : str, path or RobotDescription
        A robot name (``robots/``), a robot file or a description.
    params : path, mapping or IdentifyResults, optional
        An identification whose standard parameters (those it names) replace the nominal ones.
    from_result : path, mapping or IdentifyResults, optional
        An identification: every body from a physically consistent standard set whose regrouping gives its
        base parameters (the 'physical' extra); fills :attr:`ExportResults.sidecar`.
    """
    desc = robot_description(robot)
    if params is not None and from_result is not None:
        raise ModelError("export-urdf: give --from RESULT.json or --params RESULT.json, not both")
    v = _values(desc, from_result, "export-urdf") if from_result is not None else _Values()
    named = _identified_parameters(params, desc) if params is not None else None
    changed: list[str] = []
    text = urdf_text(desc, v.chi, v.payload, params=named, notes=v.header, report=changed)
    return _finish("export-urdf", desc, text, changed, v, inputs=(from_result, params),
                   options={"params": params, "from_result": from_result}, params=named)


@named_options
def export_mjcf(robot, *, from_result: ResultLike = None, timestep: float = 0.001) -> ExportResults:
    """The robot as a MuJoCo MJCF model (``symoro-gen export-mjcf``); ``from_result`` as for :func:`export_urdf`,
    ``timestep`` MuJoCo's [s]."""
    if not (math.isfinite(timestep) and timestep > 0):
        raise OptionError(f"export_mjcf: timestep {timestep!r}: must be a positive number of seconds (MuJoCo's step)")
    desc = robot_description(robot)
    v = _values(desc, from_result, "export-mjcf") if from_result is not None else _Values()
    if from_result is not None:     # the friction-law scales the identification fitted
        desc = with_identified_laws(desc, _result_dict(from_result)[0])
    changed: list[str] = []
    text = mjcf_text(desc, v.chi, v.payload, notes=v.header, report=changed, timestep=timestep)
    return _finish("export-mjcf", desc, text, changed, v, inputs=(from_result,),
                   options={"from_result": from_result, "timestep": timestep})


@named_options
def export_par(robot) -> ExportResults:
    """The robot as a SYMORO+/OpenSYMORO ``.par`` file (``symoro-gen export-par``)."""
    desc = robot_description(robot)
    return _finish("export-par", desc, par_text(desc), [], _Values())
