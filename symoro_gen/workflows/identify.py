"""``identify``: recordings → identified base parameters (and gains), validated on other recordings.

The workflow of ``symoro-gen identify`` as a library call::

    res = symoro_gen.identify("lwr4", ["a.csv", "c.csv"], validate=["b.csv"], method="wls")
    res.summary(); res.to_dict()["validation"]["rel_err"]; res.report("lwr4.html"); res.plot()

Filtering and parallel decimation ([GB-gains] eq. 14-16), IDIM-OLS/WLS/TLS ([GB-gains] eq. 17-22,
[LWR4-TLS] eq. 8-16), essential parameters, a known payload, drive gains ([GB-gains] eq. 25-27) or
torque-sensor gains ([LWR4-TLS]), IDIM-IV and DIDIM, physically consistent estimates.
"""
from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import Target, check_outputs
from ..description.identity import robot_id
from ..description.par import write_robot_toml
from ..description.rewrite import RobotText, format_number
from ..errors import IdentificationError, OptionError
from ..identification import fit_with_known_payload, identify_with_drive_gains, sensor_gains
from ..identification import identify as fit
from ..identification.didim import identify_didim
from ..identification.elastic import POSITION_SIDES, StiffnessEstimate, estimate_stiffness, link_side
from ..identification.estimators import drop_unexcited, with_unexcited
from ..identification.floating import KINDS as FLOATING_KINDS
from ..identification.floating import WEIGHTINGS
from ..identification.friction_law import LawDeclaredModel, ScaleFit, declared_laws, refine_scales
from ..identification.geometry import (
    GEOMETRY_KINDS,
    GeometryFit,
    GeometryProblem,
    add_lengths,
    add_zeros,
    apply_geometry,
    check_zero_joints,
    fit_geometry,
    length_identifiability,
    parse_lengths,
    zero_identifiability,
)
from ..identification.iv import identify_iv
from ..identification.payload import fit_with_known_payload_factors, identify_payload
from ..identification.physical import identify_physical
from ..identification.plausibility import Plausibility, body_boxes, check_base, check_standard
from ..identification.reference import compare_with_reference, format_comparison, read_reference
from ..identification.render import IdentificationBlocks
from ..identification.result import basis_text, json_float
from ..identification.streaming import STREAM_CHUNK_MB, StreamedAssembly, stream_assembly
from ..identification.systems import stack_systems
from ..model import IdentificationModel
from ..observations.assembly import Assembly, assemble
from ..observations.options import AssemblyOptions
from ..observations.system import ObservationSystem
from ..params import check_payload, payload_mapping
from ..preprocessing.cli import data_text
from ..preprocessing.readers import LoadReport, LogFormat
from ..preprocessing.trajectory import hold_back, note_hold_back
from ..simulate.closed_loop import PIDGains
from .base import (
    SCHEMA_VERSION,
    DataLike,
    Options,
    Results,
    as_trajectories,
    held_still,
    listed,
    provenance,
    recording_warnings,
    refuse_repeated_recordings,
    resolve_robot,
    torque_limits,
)
from .floating import identify_floating_logs, refused_options
from .reporting import ReportContent, build_report, write_report

__all__ = ["IdentifyOptions", "IdentifyResults", "check_payload", "identify", "robot_out_refusal"]

METHODS = ("ols", "wls", "tls", "iv", "didim")


@dataclass(frozen=True)
class IdentifyOptions(Options):
    """Every option of ``identify`` (the command's flags without their dashes; see ``symoro-gen identify --help``).

    Attributes
    ----------
    method : {"ols", "wls", "tls", "iv", "didim"}
    validate_loaded : bool
        The validation recordings carry the payload.
    validate_fraction : float, optional
        Hold back the last share (0 < F < 1) of each identification recording for validation.
    payload : mapping of str to float, or the command's NAME=VALUE items
        Known payload parameters (``{"M8": 4.6136}``).
    gains : {"sensor", "drive"}, optional
        Also identify torque-sensor (IDIM-TLS) or drive gains.
    essential : bool
    r_sigma : float
        Stop ratio of the essential procedure.
    cutoff, decimate : optional
        Butterworth cut-off of q [Hz] and decimation factor (default: the papers' rules).
    min_velocity : float, optional
        Drop identification rows depending on samples slower than this [rad/s].
    drop_unexcited : bool
        Leave out the parameters the data do not excite instead of stopping; a joint whose motion is at the
        noise level is held still first (its own parameters then have zero columns).
    drop_saturated : bool
        Leave out the rows of each joint whose torque is at its limit (``[limits] tau_max`` of the robot file,
        or plateaus at the column's extreme: :func:`~symoro_gen.preprocessing.motion.saturation_mask`).
    reference : path, optional
        Published base-parameter table (CSV) to compare with.
    kp, kd, ki, bandwidth, max_iter, start
        The closed-loop estimators' controller and iterations (``method="iv"|"didim"``).
    physical : bool
        Physically consistent estimate (cvxpy, Clarabel: the 'physical' extra).
    nominal_tolerance : float, optional
        With ``physical``: ``|chi - nominal| <= TOL |nominal|``.
    bounded_bodies : bool
        With ``physical``: each link's mass distribution inside its box and its mass within a factor of its
        nominal one (:mod:`symoro_gen.identification.plausibility`, docs/plausibility.md).
    data_format : LogFormat, optional
        How the files are read (columns, time base, units, resampling: docs/data-files.md).
    geometry : {"joint_zero", "length", "joint_zero,length"}, optional
        Also identify geometric parameters: the zeros of the joints torque data can see and/or the MDH lengths
        ``d``, ``r`` it can see, by Gauss-Newton alternating with the linear fit
        (:mod:`symoro_gen.identification.geometry`); the fit, the validation and everything after use the
        corrected angles and the torques with the length errors' torque taken out. OLS, WLS or TLS, without
        gains.
    geometry_joints : sequence of int, optional
        With ``geometry`` joint_zero: the joints (1-based) whose zero is fitted (default: every visible one); a
        joint whose zero torque data cannot see is refused.
    geometry_frames : sequence of str, optional
        With ``geometry`` length: the lengths fitted, ``3r``, ``4d`` or ``3`` (both of frame 3's visible ones)
        (default: every visible length); an invisible one is refused with the reason.
    positions : {"link", "motor"}
        The logged positions are link-side (default) or motor-side ``q_m / N``: then the declared elastic
        joints' link positions are ``positions - tau / K`` (:func:`symoro_gen.identification.elastic.link_side`).
    kind : {"base", "joints", "both"}, optional
        A floating-base robot only: the rows identified (default ``"both"`` when every log has joint torques,
        else ``"base"``; :mod:`symoro_gen.workflows.floating`).
    weighting : {"kind", "row"}
        A floating-base robot only: the WLS groups, each kind of rows or each row position.
    """

    method: str = "wls"
    validate_loaded: bool = False
    validate_fraction: float | None = None
    payload: Mapping[str, float] = field(default_factory=dict)
    gains: str | None = None
    essential: bool = False
    r_sigma: float = 30.0
    cutoff: float | None = None
    decimate: int | None = None
    min_velocity: float | None = None
    drop_unexcited: bool = False
    drop_saturated: bool = False
    reference: str | os.PathLike[str] | None = None
    kp: Sequence[float] | None = None
    kd: Sequence[float] | None = None
    ki: Sequence[float] | None = None
    bandwidth: float | None = None
    max_iter: int = 20
    start: str = "ols"
    physical: bool = False
    nominal_tolerance: float | None = None
    bounded_bodies: bool = False
    data_format: LogFormat = field(default_factory=LogFormat)
    positions: str = "link"
    geometry: str | None = None
    geometry_joints: Sequence[int] | None = None
    geometry_frames: Sequence[str] | None = None
    kind: str | None = None
    weighting: str = "kind"

    @property
    def geometry_kinds(self) -> tuple[str, ...]:
        """The geometric kinds of ``geometry`` (``"joint_zero,length"`` -> both)."""
        return tuple(k.strip() for k in self.geometry.split(",")) if self.geometry else ()

    def __post_init__(self) -> None:
        if self.positions not in POSITION_SIDES:
            raise OptionError(f"positions {self.positions!r}: one of {', '.join(POSITION_SIDES)}")
        if self.geometry_joints is not None and self.geometry is None:
            raise OptionError("--geometry-joints chooses the joints of --geometry joint_zero: add --geometry joint_zero")
        bad = [k for k in self.geometry_kinds if k not in GEOMETRY_KINDS]
        if bad or (self.geometry is not None and not self.geometry_kinds):
            raise OptionError(f"--geometry {self.geometry!r}: one of {', '.join(GEOMETRY_KINDS)} or both, "
                              "comma-separated (joint_zero,length)")
        if self.geometry_joints is not None and "joint_zero" not in self.geometry_kinds:
            raise OptionError("--geometry-joints chooses the joints of --geometry joint_zero: add joint_zero")
        if self.geometry_frames is not None and "length" not in self.geometry_kinds:
            raise OptionError("--geometry-frames chooses the lengths of --geometry length: add --geometry length")
        if self.geometry is not None and (self.method in ("iv", "didim") or self.gains):
            raise OptionError(f"--geometry {self.geometry} is fitted with IDIM-OLS, -WLS or -TLS without gains: "
                              f"not with {'--gains ' + str(self.gains) if self.gains else '--method ' + self.method}")
        if self.method not in METHODS:
            raise OptionError(f"method {self.method!r}: one of {', '.join(METHODS)}")
        if self.gains not in (None, "sensor", "drive"):
            raise OptionError(f"gains {self.gains!r}: 'sensor' or 'drive'")
        if self.start not in ("ols", "nominal"):
            raise OptionError(f"start {self.start!r}: 'ols' or 'nominal'")
        if self.validate_fraction is not None and not 0 < self.validate_fraction < 1:
            raise OptionError(f"--validate-fraction {self.validate_fraction:g}: must lie between 0 and 1 (a share "
                              "of each recording)")
        if self.nominal_tolerance is not None and not self.physical:
            raise IdentificationError("--nominal-tolerance bounds the --physical estimate: add --physical")
        if self.bounded_bodies and not self.physical:
            raise IdentificationError("--bounded-bodies bounds the --physical estimate: add --physical")
        if self.method not in ("iv", "didim"):
            # options of the closed-loop simulation (IDIM-IV, DIDIM): with any other method they would do nothing
            given = [flag for flag, v in (("--kp", self.kp), ("--kd", self.kd), ("--ki", self.ki),
                                          ("--bandwidth", self.bandwidth), ("--max-iter", self.max_iter != 20 or None),
                                          ("--start", self.start != "ols" or None)) if v]
            if given:
                raise OptionError(f"{', '.join(given)}: only act with --method iv or didim (the closed-loop "
                                  f"simulation), not with --method {self.method}: add --method iv or didim, or "
                                  f"leave {'them' if len(given) > 1 else 'it'} out")
        if self.kind not in (None, *FLOATING_KINDS):
            raise OptionError(f"--kind {self.kind!r}: one of {', '.join(FLOATING_KINDS)} (floating-base robots)")
        if self.weighting not in WEIGHTINGS:
            raise OptionError(f"--weighting {self.weighting!r}: one of {', '.join(WEIGHTINGS)} (floating-base robots)")
        object.__setattr__(self, "payload", payload_mapping(self.payload))
        if self.data_format is None:
            object.__setattr__(self, "data_format", LogFormat())


@dataclass(frozen=True, eq=False)
class IdentifyResults(Results):
    """What ``identify`` found (see :meth:`to_dict` for the JSON contract, docs/json-output.md)."""

    command = "identify"

    robot: Any
    model: IdentificationModel
    options: IdentifyOptions
    result: Any                                  # IdentificationResult (the consistent one with physical)
    data: tuple[Any, ...]
    loaded: tuple[Any, ...]
    validate: tuple[Any, ...]
    reports: tuple[LoadReport, ...]
    systems: Mapping[str, ObservationSystem | None]      # a streamed identification: a thinned copy of the rows
    assemblies: Mapping[str, Assembly | StreamedAssembly | None]
    drive: Any = None
    closed: Any = None
    physical: Any = None
    unconstrained: Any = None
    validation: Mapping[str, Any] | None = None
    reference_rows: tuple[Any, ...] | None = None
    held_back: tuple[str, ...] = ()
    inputs: tuple[Any, ...] = ()
    plausibility: Plausibility | None = None
    geometry: GeometryFit | None = None
    friction_laws: tuple[ScaleFit, ...] = ()
    elasticity: StiffnessEstimate | None = None
    robot_out: Mapping[str, Any] | None = None

    # ---- the JSON ---------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Exactly the JSON of ``symoro-gen identify --json`` (its ``generator`` mark first)."""
        out: dict[str, Any] = {"generator": "symoro-gen identify", "schema_version": SCHEMA_VERSION,
                               "robot": self.robot.name, "robot_id": robot_id(self.robot), "data": [],
                               "loaded": [str(p) for p in self.loaded]}
        if self.physical is not None:
            out["unconstrained"] = self.unconstrained.to_dict()
            out["physical"] = self.physical.to_dict()
        out.update(self.result.to_dict())
        if self.closed is not None:
            out["iterations"] = self.closed.to_dict()
        if self.validation is not None:
            v = self.validation
            out["validation"] = {"data": list(v["data"]), "rel_err": [json_float(x) for x in v["rel_err"]],
                                 "rel_err_raw": [json_float(x) for x in v["rel_err_raw"]],
                                 "rel_err_basis": v["basis"]}
            if self.physical is not None:
                out["unconstrained"]["validation"] = {"rel_err": [json_float(x) for x in v["unconstrained"]],
                                                      "rel_err_raw": [json_float(x) for x in v["unconstrained_raw"]]}
        out["data"] = [r.to_dict() for r in self.reports]
        if self.reference_rows is not None:
            out["reference"] = [
                {"expression": r.expression, "name": r.name, "ref": r.ref, "ref_rel_std_pct": r.ref_rel_std_pct,
                 "agree_2sigma": r.agree_2sigma} for r in self.reference_rows]
        if self.plausibility is not None:
            out["plausibility"] = self.plausibility.to_dict()
            out["warnings"] = list(out["warnings"]) + list(self.plausibility.warnings)
        if self.geometry is not None:
            out["geometry"] = self.geometry.to_dict()
        if self.friction_laws:
            out["friction_laws"] = [f.to_dict() for f in self.friction_laws]
        if self.elasticity is not None:
            out["elasticity"] = self.elasticity.to_dict()
        if self.robot_out is not None:
            out["robot_out"] = {"path": self.robot_out["path"], "robot_file": self.robot_out["robot_file"],
                                "written": {k: list(v) for k, v in self.robot_out["written"].items()}}
        out["provenance"] = provenance(self.options, self.inputs)
        return out

    # ---- the text ---------------------------------------------------------------------------------
    def summary(self) -> str:
        """Exactly the text ``symoro-gen identify`` prints."""
        text = self.result.summary()
        if self.geometry is not None:
            text = self.geometry.summary(self.robot.name) + "\n\n" + text
        if self.friction_laws:
            text += ("\n\nDeclared friction laws (scale refined by Gauss-Newton on the identification data; \u00b1 one "
                     "standard deviation, the magnitudes' with the scale free):\n"
                     + "\n".join(f.summary() for f in self.friction_laws))
        if self.closed is not None:
            text = self.closed.summary() + "\n\n" + text
        v = self.validation
        if v is not None:
            vb = v["basis"]
            text += ("\n\nValidation (relative error norm per joint): every sample, no row selection\n"
                     f"  on the {basis_text(vb)}:\n    " + "  ".join(f"{x:.4f}" for x in v["rel_err"])
                     + f"\n  on the raw measured torque (model at full rate on the filtered states, {vb['samples']} "
                     "samples per joint):\n    " + "  ".join(f"{x:.4f}" for x in v["rel_err_raw"]))
            if self.physical is not None:
                text += ("\n  unconstrained estimate, same data:\n    " + "  ".join(f"{x:.4f}" for x in v["unconstrained"])
                         + "\n    raw: " + "  ".join(f"{x:.4f}" for x in v["unconstrained_raw"]))
        if self.physical is not None:
            text += "\n\n" + self.physical.summary()
        if self.reference_rows is not None:
                text += "\n\nBeside the reference table " + str(self.options.reference) + ":\n" + \
                format_comparison(list(self.reference_rows))
        if self.plausibility is not None and self.plausibility.warnings:
            text += ("\n\nPlausibility of the bodies (nominal values, the links' boxes, signs; docs/plausibility.md):\n"
                     + self.plausibility.summary())
        if self.elasticity is not None:
            text += "\n\n" + self.elasticity.summary()
        if self.robot_out is not None:
            names = {"joint_zero": "joint zeros of joints", "length": "link lengths (frame, field)", "elastic": "elastic K, D of frames",
                     "friction_law": "friction-law scales of frames"}
            text += (f"\n\nRobot file written (-o): {self.robot_out['path']} (from {self.robot_out['robot_file']}): "
                     + "; ".join(f"{names[k]} {', '.join(map(str, v))}" for k, v in self.robot_out["written"].items())
                     + " ([nominal] not written)")
        return text + "\n\n" + data_text(self.reports)

    # ---- the corrected robot file ----------------------------------------------------------------------
    def written_quantities(self) -> dict[str, list]:
        """What ``-o/--robot-out`` writes into the robot file, each only when this run identified it:
        ``joint_zero`` (1-based joints, ``--geometry joint_zero``), ``elastic`` (frames whose ``K``, ``D`` the
        two-encoder fit estimated), ``friction_law`` (frames whose law's scale was fitted)."""
        out: dict[str, list] = {}
        if self.geometry is not None and len(self.geometry.joints):
            out["joint_zero"] = [j + 1 for j in self.geometry.joints]
        if self.geometry is not None and self.geometry.lengths:
            out["length"] = [f"{f}{fl}" for f, fl in self.geometry.lengths]
        if self.elasticity is not None and self.elasticity.joints:
            out["elastic"] = list(self.elasticity.joints)
        laws = [f.law.frame for f in self.friction_laws if f.fitted and f.law.scale_name is not None]
        if laws:
            out["friction_law"] = laws
        return out

    def write_robot(self, path: str | os.PathLike[str], *, force: bool = False) -> IdentifyResults:
        """Write the input robot file with every robot-file quantity this run identified (``-o/--robot-out``):
        the joint zeros added to the frames' ``theta`` (``r``) (``--geometry joint_zero``), ``K`` and ``D`` of
        the elastic joints the two-encoder fit estimated (``elastic = {K, D}``, Spong 1987), the scales of the
        declared friction laws that were fitted (``friction_law = {kind, vs|v|delta}``). The ``[nominal]``
        values are not written (the identified base parameters are not the standard ones). Every other line is
        unchanged (:class:`~symoro_gen.description.rewrite.RobotText`); header comments name the source file,
        what was written and from which data. Never over the input robot file or another input, an existing
        file only with ``force``. Returns these results with the file recorded (JSON ``robot_out``, and
        ``geometry.robot_out`` with zeros)."""
        what = self.written_quantities()
        if not what:
            raise OptionError(robot_out_refusal(self.robot, self.friction_laws))
        check_outputs({"-o/--robot-out": Target(Path(path), owner="never")}, self.input_files(), force=force)
        text = RobotText(str(self.robot.file))
        data = ", ".join(str(getattr(x, "source", x)) for x in self.data)
        head = [f"Written by symoro-gen identify -o from the robot file {text.path} (data: {data}; method "
                f"{self.options.method}):"]
        if "joint_zero" in what:
            assert self.geometry is not None
            bad = [z for z in self.geometry.to_dict()["zeros"] if not z.get("plausible", True)]
            if bad:
                raise IdentificationError(
                    "-o/--robot-out: " + ", ".join(f"joint {z['joint']} zero {z['offset_deg']:+.1f} deg" for z in bad)
                    + " is beyond 20 deg, no encoder zero error (the data or the model explain it otherwise): not "
                    "written into a robot file; fit the other joints only (--geometry-joints)")
            head.append("  joint zeros (--geometry joint_zero) added to theta/r: "
                        + add_zeros(text, self.robot, self.geometry.offset_map()))
        if "length" in what:
            assert self.geometry is not None
            wild = self.geometry.implausible_lengths()
            if wild:
                raise IdentificationError(
                    f"-o/--robot-out: {self.robot.file}: " + ", ".join(f"frame {f} field {fl} error {1e3 * v:+.1f} mm"
                                                                      for f, fl, v in wild)
                    + " is beyond the plausible link-length error (50 mm or 10 % of the reach): not written into a "
                    "robot file; fit the other lengths only (--geometry-frames)")
            head.append("  link-length errors (--geometry length) added to d/r: "
                        + add_lengths(text, self.geometry.length_map()))
        if "elastic" in what:
            est = self.elasticity
            assert est is not None
            parts = []
            for j, k, d, ds in zip(est.joints, est.K, est.D, est.D_std):
                d_w = max(d, 0.0)   # D >= 0 in a robot file: a negative estimate is written as 0
                text.set_inline(j, "elastic", {"K": format_number(k, 6), "D": format_number(d_w, 6)}, create=True)
                parts.append(f"frame {j} K = {k:.6g}, D = {d_w:.6g}" + (f" (estimate {d:.3g} +- {ds:.2g} < 0)"
                                                                        if d < 0 else ""))
            head.append("  elastic K, D (two-encoder fit): " + "; ".join(parts))
        if "friction_law" in what:
            parts = []
            for f in self.friction_laws:
                if f.fitted and f.law.scale_name is not None:
                    text.set_inline(f.law.frame, "friction_law", {f.law.scale_name: format_number(f.scale, 6)})
                    parts.append(f"frame {f.law.frame} {f.law.kind} {f.law.scale_name} = {f.scale:.6g} +- "
                                 f"{f.std:.2g} (declared {f.law.scale:.6g})")
            head.append("  friction_law scales (refined by Gauss-Newton): " + "; ".join(parts))
        head.append("  [nominal] unchanged: the identified base parameters are not the standard ones")
        write_robot_toml(text.text(head), path, overwrite=force)
        out = replace(self, robot_out={"path": str(path), "robot_file": str(text.path), "written": what})
        if "joint_zero" in what or "length" in what:
            assert self.geometry is not None
            out = replace(out, geometry=replace(self.geometry, robot_out=str(path)))
        return out

    # ---- report and figures -------------------------------------------------------------------------
    def report_content(self) -> ReportContent:
        """What the report shows besides the result: the systems, the payload re-identified on loaded validation
        data, drive gains, the reference table, raw errors, notes."""
        model, res = self.model, self.result
        sys_u, sys_l, sys_v = (self.systems.get(k) for k in ("unloaded", "loaded", "validation"))
        loaded = sys_l is not None
        ident = [("identification data" + (" (unloaded)" if loaded else ""), sys_u)]
        if loaded:
            ident.append(("identification data (loaded)", sys_l))
        vl = self.options.validate_loaded
        valid = [("validation data" + (" (loaded)" if vl else ""), sys_v)] if sys_v is not None else []
        raw = [(valid[0][0], self.validation["rel_err_raw"])] if valid and self.validation is not None else []
        payload, notes = None, ["data " + r.summary() for r in self.reports]
        thinned = [a for a in self.assemblies.values() if isinstance(a, StreamedAssembly) and a.stride > 1]
        if thinned:
            notes.append(f"identified in bounded memory: the figures and the tables computed on rows use every "
                         f"{max(a.stride for a in thinned)}-th row of each joint; the result's error norms use them all")
        if self.plausibility is not None:
            notes += [f"warning: {w}" for w in self.plausibility.warnings]
        if self.geometry is not None:
            notes += [line.strip() for line in self.geometry.summary(self.robot.name).splitlines()]
        if sys_v is not None and vl and any(n in sys_v.names for n in model.PAYLOAD_NAMES):
            try:
                payload = identify_payload(sys_v, res, payload_names=[n for n in model.PAYLOAD_NAMES if n in sys_v.names],
                                           gains=res.gains, method=self.options.method)
            except IdentificationError as exc:
                notes.append(f"payload not re-identified on the validation data: {exc}")
        sources = {"identification data": [str(p) for p in self.data], "loaded": [str(p) for p in self.loaded],
                   "validation data": [str(p) for p in self.validate]}
        blocks = IdentificationBlocks(identification=ident, validation=valid, payload_names=model.PAYLOAD_NAMES,
                                      payload=payload, drive=self.drive, raw_errors=raw,
                                      reference=list(self.reference_rows) if self.reference_rows is not None else None)
        return ReportContent(robot=self.robot.name, sources=sources, blocks=blocks, notes=notes,
                             text=self.physical.summary() if self.physical is not None else None)

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """Tables and plots ([GB-gains] and [LWR4-TLS] tables, measured vs reconstructed torques, singular values;
        with loaded validation data the payload re-identified with the robot known), ``.html`` or ``.md``."""
        self.check_output(path, force=force, label="report", report=True)
        return write_report(path, self.result, content=self.report_content(), force=force)

    def figures(self) -> list:
        """Measured and reconstructed torque of every data set, and the scaled singular values of ``W``."""
        rep = build_report(self.result, content=self.report_content())
        return [f.figure for f in rep.figures if f.figure is not None]


# ---- the workflow ---------------------------------------------------------------------------------------
def robot_out_refusal(robot, friction_laws: Sequence[ScaleFit] = ()) -> str:
    """The message refusing ``-o/--robot-out`` when nothing it writes was identified: what each quantity
    needs, for this ``robot`` (its file)."""
    laws = [f"frame {f.law.frame} ({f.note})" for f in friction_laws if not f.fitted]
    return (f"-o/--robot-out writes the robot-file quantities identify identified, and this run identified none "
            f"for {robot.file}: no joint zeros (add --geometry joint_zero), no elastic K, D (needs elastic = {{K = "
            "...} on a frame and recordings with a q_link column: two encoders), no friction-law scale ("
            + ("the declared laws were not fitted: " + "; ".join(laws) if laws
               else "needs friction_law = {kind = ..., vs|v|delta = ...} on a frame")
            + "); the [nominal] values are never written (the base parameters are not the standard ones)")


def identify(robot, data: DataLike, *, validate: DataLike = None, loaded: DataLike = None,
             method: str = "wls", options: IdentifyOptions | None = None, **kwargs: Any) -> Any:
    """Identify a robot's base parameters (and gains) from recordings; validate on others.

    Parameters
    ----------
    robot : str, path, RobotDescription or model
        A robot name (``robots/``), a robot file, a description or a loaded model.
    data : path, Trajectory, (t, q, tau) arrays, or a list of them
        Recordings without payload.
    validate : same as ``data``, optional
        Validation recordings (relative error norms, [LWR4-TLS] Table III).
    loaded : same as ``data``, optional
        Recordings with the payload mounted.
    method : {"ols", "wls", "tls", "iv", "didim"}
    options : IdentifyOptions, optional
        All options at once; or give them by name (``essential=True``, ``cutoff=10``...): an unknown name
        raises :class:`~symoro_gen.errors.OptionError` naming the nearest valid one.

    Returns
    -------
    IdentifyResults
        Or, for a floating-base robot (``base = "floating"``: logs of docs/floating-base.md, ``kind=`` the rows),
        a :class:`~symoro_gen.workflows.floating.FloatingIdentifyResults`.
    """
    opts = IdentifyOptions.resolve("identify", options, dict(kwargs, method=method) if options is None else kwargs,
                                   keywords=("validate", "loaded", "options"))
    if options is not None and method not in ("wls", options.method):
        opts = replace(options, method=method)
    return _run(robot, data, validate, loaded, opts)


def _run(robot_like, data, validate, loaded_data, opts: IdentifyOptions) -> Any:
    robot, model = resolve_robot(robot_like)
    data, validate, loaded_data = listed(data), listed(validate), listed(loaded_data)
    if not data:
        raise OptionError("identify: no identification data given")
    if robot.floating:
        refused = refused_options(opts, opts.validate_loaded, loaded_data)
        if refused:
            raise OptionError(f"{robot.file or robot.name}: a floating-base robot is identified with --kind, "
                              f"--weighting, --method ols|wls, --cutoff, --decimate and --validate; not with "
                              f"{', '.join(refused)}")
        return identify_floating_logs(robot, model, data, validate, opts)
    if opts.kind is not None or opts.weighting != "kind":
        raise OptionError(f"--kind and --weighting choose the rows of a floating-base robot; {robot.name} has a "
                          "fixed base")
    ref_table = read_reference(opts.reference) if opts.reference else None  # refused before any work
    refuse_repeated_recordings(data, loaded_data, validate)
    unloaded, reports = as_trajectories(list(data), opts.data_format, robot, loaded=False)
    unloaded = _positions(opts, robot, unloaded)
    held_back: tuple = ()
    if opts.validate_fraction is not None:
        unloaded, held_back = hold_back(unloaded, opts.validate_fraction)
        reports = note_hold_back(reports, unloaded, held_back, opts.validate_fraction)
    loaded, rep_l = (as_trajectories(list(loaded_data), opts.data_format, robot, loaded=True)
                     if loaded_data else ((), ()))
    reports += rep_l
    loaded = _positions(opts, robot, loaded)
    known = check_payload(opts.payload, model.PAYLOAD_NAMES)
    elasticity = _elasticity(opts, robot, (*unloaded, *loaded))
    if (opts.gains or known) and not loaded:
        raise IdentificationError("--gains and --payload need recordings with the payload: give them with --loaded")
    notes = recording_warnings(robot, (*unloaded, *loaded), held=opts.drop_unexcited, dropped=opts.drop_saturated)
    if opts.drop_unexcited:  # a joint moving at the noise level is still: its own columns become zero
        unloaded, loaded = held_still(unloaded), held_still(loaded)
    # min_velocity (row selection) applies to the identification rows only; validation uses every sample
    asm_opts = AssemblyOptions(cutoff_hz=opts.cutoff, n_d=opts.decimate, min_velocity=opts.min_velocity,
                               drop_saturated=opts.drop_saturated, tau_limits=torque_limits(robot))
    geo = None
    if opts.geometry:  # the joint zeros first: everything after runs at the corrected angles
        geo = _fit_geometry(opts, robot, model, unloaded, loaded, asm_opts, known)
        unloaded, loaded, held_back = (apply_geometry(model, robot, geo, x, asm_opts)
                                       for x in (unloaded, loaded, held_back))
    streamed = streams(opts)
    model, law_fits = _declared_friction(robot, model, unloaded, replace(asm_opts, payload_columns=False), opts)
    asm_u = _assemble(model, unloaded, replace(asm_opts, payload_columns=False), streamed)
    asm_l = _assemble(model, loaded, replace(asm_opts, payload_columns=True), streamed) if loaded else None
    # a joint that stands still leaves columns of W zero: an error naming the files, or drop_unexcited
    (sys_u, sys_l), unexcited = drop_unexcited([asm_u.system, asm_l.system if asm_l is not None else None],
                                               (*unloaded, *loaded), drop=opts.drop_unexcited)
    assert sys_u is not None  # drop_unexcited returns a system for each system given
    if unexcited and opts.method in ("iv", "didim"):
        raise OptionError(f"--drop-unexcited is not available with --method {opts.method} (it simulates every joint)")
    dg = closed = None
    if opts.method in ("iv", "didim"):
        closed = _run_closed_loop(opts, model, unloaded, asm_opts, loaded, known)
        res = closed.result
    elif opts.gains == "sensor":
        res = sensor_gains(sys_u, sys_l, known, essential=opts.essential, r_sigma=opts.r_sigma)
    elif opts.gains == "drive":
        res, dg = identify_with_drive_gains(sys_u, sys_l, known, method=opts.method)
    elif loaded and streamed:
        res = fit_with_known_payload_factors(sys_u, sys_l, known, method=opts.method, essential=opts.essential,
                                             r_sigma=opts.r_sigma)
    elif loaded:
        res = fit_with_known_payload(sys_u, sys_l, known, method=opts.method, essential=opts.essential,
                                     r_sigma=opts.r_sigma)
    else:
        res = fit(sys_u, method=opts.method, essential=opts.essential, r_sigma=opts.r_sigma)
    res = with_unexcited(res, unexcited).with_raw_error(model, *[a for a in (asm_u, asm_l) if a is not None])
    res = replace(res, warnings=(*notes, *res.warnings))
    phys = res_u = None
    if opts.physical:
        phys, res_u, res = _physical(opts, robot, model, res, sys_u, sys_l, known, asm_u, asm_l)
    plaus = _plausibility(robot, model, res_u if phys is not None else res, phys)
    validation, sys_v, asm_v = _validate(opts, robot, model, res, res_u, validate, held_back, asm_opts,
                                         bool(loaded), streamed, geo)
    if validation is not None:
        reports += validation.pop("reports")
    rows = None
    if ref_table is not None:
        rows = tuple(compare_with_reference(res, ref_table))
    inputs = (*data, *loaded_data, *validate) + ((opts.reference,) if opts.reference else ())
    return IdentifyResults(robot=robot, model=model, options=opts, result=res, data=data, loaded=loaded_data,
                           validate=validate, reports=tuple(reports),
                           systems={"unloaded": _rows(sys_u, asm_u), "loaded": _rows(sys_l, asm_l),
                                    "validation": _rows(sys_v, asm_v)},
                           assemblies={"unloaded": asm_u, "loaded": asm_l, "validation": asm_v}, drive=dg,
                           closed=closed, physical=phys, unconstrained=res_u, validation=validation,
                           reference_rows=rows, held_back=tuple(tr.source for tr in held_back), inputs=inputs,
                           plausibility=plaus, geometry=geo, friction_laws=law_fits,
                           elasticity=elasticity)


def _fit_geometry(opts: IdentifyOptions, robot, model: IdentificationModel, unloaded, loaded, asm_opts,
                  known) -> GeometryFit:
    """``geometry``: the zeros of the visible joints and/or the visible link lengths by Gauss-Newton alternating
    with the linear fit of the same estimator on the same rows (in memory)."""
    kinds = opts.geometry_kinds
    js: tuple[int, ...] = ()
    if "joint_zero" in kinds:
        js = check_zero_joints(model, zero_identifiability(model),
                               None if opts.geometry_joints is None else [int(j) - 1 for j in opts.geometry_joints])
    ls = parse_lengths(opts.geometry_frames, robot, length_identifiability(robot, model=model)) if "length" in kinds else ()
    trajs = (*unloaded, *loaded)
    problem = GeometryProblem(unloaded=tuple(unloaded), loaded=tuple(loaded), options=asm_opts, joints=js, lengths=ls)

    def assemble_at(tu, tl):
        su = assemble(model, tu, replace(asm_opts, payload_columns=False)).system
        sl = assemble(model, tl, replace(asm_opts, payload_columns=True)).system if tl else None
        return su, sl

    def fit_at(su, sl):
        (su, sl), _ = drop_unexcited([su, sl], trajs, drop=opts.drop_unexcited)
        if sl is not None:
            return fit_with_known_payload(su, sl, known, method=opts.method)
        return fit(su, method=opts.method)

    g = fit_geometry(model, robot, problem, assemble_at, fit_at, kinds=kinds)
    return replace(g, robot_file=str(robot.file))


def _declared_friction(robot, model: IdentificationModel, trajectories, options: AssemblyOptions,
                       opts: IdentifyOptions) -> tuple[IdentificationModel, tuple[ScaleFit, ...]]:
    """The model with the robot file's declared friction laws (``friction_law``) in place of their joints'
    ``FS``/``FV`` columns, at the scales refined on the identification recordings
    (:func:`~symoro_gen.identification.friction_law.refine_scales`); the model itself without any."""
    laws = declared_laws(robot, model)
    if not laws:
        return model, ()
    if opts.method in ("iv", "didim") or opts.physical:
        given = "--physical" if opts.physical else f"--method {opts.method}"
        raise OptionError(f"{given}: the declared friction laws (friction_law) of {robot.file} are identified with "
                          "--method ols, wls or tls without --physical (the consistent standard set has no "
                          "parameters for their columns); leave the option out, or the laws")
    fits = refine_scales(model, laws, trajectories, options)
    return LawDeclaredModel(model, laws, [f.scale for f in fits]), fits


def _positions(opts: IdentifyOptions, robot, trajectories) -> tuple:
    """The recordings with link-side positions: as read, or (``positions="motor"``) corrected by ``tau / K`` on
    the declared elastic joints ([LWR4-TLS] eq. 17)."""
    if opts.positions == "motor" and trajectories:
        return link_side(robot, trajectories)
    return tuple(trajectories)


def _elasticity(opts: IdentifyOptions, robot, trajectories) -> StiffnessEstimate | None:
    """``K``, ``D`` of the declared elastic joints from the recordings with two encoders (a measured deflection),
    None when the robot declares no elastic joint or no recording has a link-side position."""
    if not robot.elastic or not any(tr.deflection is not None for tr in trajectories):
        return None
    return estimate_stiffness(robot, trajectories, cutoff_hz=opts.cutoff)


def streams(opts: IdentifyOptions) -> bool:
    """Whether ``identify`` runs in bounded memory (:mod:`symoro_gen.identification.streaming`: the system
    folded into per-joint QR factors, the full-rate signals never kept): IDIM-OLS, -WLS and -TLS (the SVD
    of ``[W  -Y]`` is that of the stacked factors, LWR4 paper eq. 12-16), with or without a known payload,
    essential parameters, ``min_velocity``, ``drop_unexcited``, validation. The rows themselves are kept
    (in memory) for identified gains, the physically consistent estimate and ``drop_saturated``; IDIM-IV
    and DIDIM simulate the robot on the whole recordings."""
    return (opts.method in ("ols", "wls", "tls") and opts.gains is None and not opts.physical
            and not opts.drop_saturated)


def _assemble(model: IdentificationModel, trajectories, options: AssemblyOptions, streamed: bool
              ) -> Assembly | StreamedAssembly:
    """The recordings' assembly: streamed into QR factors, or whole (:func:`streams`)."""
    if streamed:
        return stream_assembly(model, trajectories, replace(options, keep_signals=False,
                                                            max_chunk_mb=min(options.max_chunk_mb, STREAM_CHUNK_MB)))
    return assemble(model, trajectories, options)


def _rows(system, assembly) -> ObservationSystem | None:
    """The rows a report shows: the system, or a streamed assembly's thinned copy (every k-th row per joint)."""
    if isinstance(assembly, StreamedAssembly):
        return assembly.sample
    return system


def _plausibility(robot, model: IdentificationModel, res, phys) -> Plausibility:
    """The plausibility checks after the fit: sign rules (and nominal rotor inertias) of the unconstrained
    base parameters; with ``physical`` the bodies of the consistent standard set against the nominal values
    and the links' boxes, and the solver's status."""
    nominal = dict(robot.nominal or {})
    findings = check_base(model, res.names, res.values, res.std, payload=robot.payload, nominal=nominal)
    boxes = body_boxes(robot)
    notes: tuple[str, ...] = ()
    if phys is not None:
        findings += check_standard(robot, phys.standard_map(), nominal=nominal, boxes=boxes)
        notes = tuple(phys.warnings)
    return Plausibility(findings=tuple(findings), boxes=tuple(boxes.values()), notes=notes)


def _validate(opts: IdentifyOptions, robot, model, res, res_u, validate, held_back, asm_opts, has_payload,
              streamed: bool = False, geometry: GeometryFit | None = None):
    """Relative errors on the validation recordings and the held-back parts (None without either); with
    ``geometry`` the validation recordings at the corrected angles (the held-back parts already are)."""
    if not (validate or held_back):
        return None, None, None
    vtr, rep_v = (as_trajectories(list(validate), opts.data_format, robot, loaded=opts.validate_loaded)
                  if validate else ((), ()))
    vtr = tuple(_positions(opts, robot, vtr))
    if geometry is not None:
        vtr = apply_geometry(model, robot, geometry, vtr, asm_opts)
    vtr = tuple(held_back) + tuple(vtr)
    asm_v = _assemble(model, vtr, replace(asm_opts, min_velocity=None,
                                          payload_columns=bool(opts.validate_loaded) or has_payload), streamed)
    sys_v = asm_v.system
    out: dict[str, Any] = {"data": [tr.source for tr in held_back] + [str(p) if isinstance(p, (str, os.PathLike))
                                                                       else getattr(p, "source", "<array>")
                                                                       for p in validate],
                           "rel_err": res.rel_err_on(sys_v), "rel_err_raw": res.rel_err_raw_on(model, asm_v),
                           "basis": asm_v.metric_basis(), "reports": tuple(rep_v)}
    if res_u is not None:
        out["unconstrained"] = res_u.rel_err_on(sys_v)
        out["unconstrained_raw"] = res_u.rel_err_raw_on(model, asm_v)
    return out, sys_v, asm_v


def _run_closed_loop(opts: IdentifyOptions, model: IdentificationModel, unloaded, asm_opts, loaded, known):
    """``method="iv"|"didim"``: IDIM-IV / DIDIM on the unloaded recordings (closed-loop simulations)."""
    if loaded or known or opts.gains or opts.essential:
        raise IdentificationError(f"--method {opts.method} identifies the robot without payload from the DATA "
                                  f"recordings: --loaded, --payload, --gains and --essential are not available with it")
    gains = None
    given = [x for x in (opts.kp, opts.kd, opts.ki) if x]
    if given:
        if not opts.kp or not opts.kd:
            raise IdentificationError("--kp and --kd go together (--ki is optional): the controller's gains per joint")
        n = model.N_JOINTS
        vals = []
        for name, x in (("--kp", list(opts.kp)), ("--kd", list(opts.kd)), ("--ki", list(opts.ki or [0.0]))):
            if len(x) not in (1, n):
                raise IdentificationError(f"{name}: give 1 value or {n} (one per joint), got {len(x)}")
            vals.append(np.asarray(x * n if len(x) == 1 else x, float))
        gains = PIDGains(*vals)
    start = None
    if opts.start == "nominal":
        nominal = getattr(model, "nominal_parameters", lambda: None)()
        if nominal is None or not any(float(x) != 0 for x in nominal):
            raise IdentificationError(f"--start nominal: the robot file of {model.ROBOT} declares no nominal "
                                      f"inertial parameters")
        start = model.base_parameters(nominal)
    fn = identify_iv if opts.method == "iv" else identify_didim
    return fn(model, unloaded, asm_opts, gains=gains, bandwidth_hz=opts.bandwidth, max_iter=opts.max_iter,
              start=start)


def _physical(opts: IdentifyOptions, robot, model: IdentificationModel, res, sys_u, sys_l, known, asm_u, asm_l):
    """``physical``: the consistent estimate on the same (gain-scaled, WLS-weighted) rows.

    Returns ``(PhysicalResult, unconstrained result, consistent result)``; the consistent result has the
    implied base parameters in the unconstrained result's names, its raw-torque errors attached.
    """
    system = stack_systems(sys_u, sys_l) if sys_l is not None else sys_u
    system = ObservationSystem(system.W, res.scaled_measurements(system), system.names, system.joint)
    joint_sigma: list[float] | None = None
    if res.joint_sigma is not None:  # WLS: weights 1/sigma_j from the unconstrained residual per joint
        rho = system.Y - res.predict(system)
        n_j = np.bincount(system.joint, minlength=system.n_joints)
        s_j = np.sqrt(np.bincount(system.joint, weights=rho ** 2, minlength=system.n_joints) / np.maximum(n_j, 1))
        joint_sigma = np.where(s_j > 0, s_j, 1.0).tolist()
    nominal = dict(zip(robot.standard_names, robot.nominal_vector() or ()))
    if robot.payload is not None and robot.nominal_payload() is not None:
        nominal.update(zip(robot.payload_names, robot.nominal_payload()))
    phys = identify_physical(model, system, joint_sigma=joint_sigma, known=known, nominal=nominal,
                             nominal_tolerance=opts.nominal_tolerance,
                             boxes=body_boxes(robot) if opts.bounded_bodies else None)
    res_p = phys.as_identification_result(res).with_raw_error(model, *[a for a in (asm_u, asm_l) if a is not None])
    return phys, res, res_p


def options_field_names() -> tuple[str, ...]:
    """The option names of :func:`identify` (its keywords besides robot, data, validate, loaded, options)."""
    return tuple(f.name for f in dataclasses.fields(IdentifyOptions))
