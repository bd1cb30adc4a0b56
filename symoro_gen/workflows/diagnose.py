"""``diagnose``: recordings → what the residual says the declared model misses, added, re-identified.

The workflow of ``symoro-gen diagnose`` as a library call::

    res = symoro_gen.diagnose("rx90", "spring1.csv", validate="spring2.csv", candidates=("spring", "offset"))
    res.summary(); res.to_dict()["effects"]; res.report("rx90.html"); res.plot()

The declared model is identified (IDIM-OLS/WLS/TLS on the filtered, decimated system, [GB-gains] eq. 14-22),
its residual is tested for structure, candidate effects are scored as extra columns of ``W`` (HAC Wald test on
the identification data, validation-error drop, placebo columns), the best is added and the model
re-identified, until nothing is significant (:func:`symoro_gen.diagnostics.diagnose`).
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..description.identity import robot_id
from ..diagnostics.candidates import KINDS
from ..diagnostics.core import HOLDOUT, MAX_EFFECTS, SIGNIFICANCE, DiagnoseSettings
from ..diagnostics.core import diagnose as run_loop
from ..diagnostics.frame import split_holdout
from ..diagnostics.friction import LawDeclaration, law_declarations
from ..diagnostics.render import diagnosis_blocks, diagnosis_html
from ..diagnostics.report import ResidualReport
from ..errors import IdentificationError, OptionError
from ..identification.elastic import (
    POSITION_SIDES,
    ElasticDeclaration,
    elastic_columns,
    elastic_declarations,
    link_side,
)
from ..identification.estimators import still_joints
from ..identification.friction_law import LawDeclaredModel, ScaleFit, declared_laws, refine_scales
from ..model import IdentificationModel
from ..observations.options import AssemblyOptions
from ..params import payload_mapping
from ..preprocessing.cli import data_notes, data_text
from ..preprocessing.readers import LoadReport, LogFormat
from ..report import Figure, require_matplotlib
from .base import (
    SCHEMA_VERSION,
    DataLike,
    Options,
    Results,
    as_trajectories,
    listed,
    provenance,
    recording_warnings,
    refuse_repeated_recordings,
    resolve_robot,
    torque_limits,
)
from .floating import diagnose_floating_logs
from .identify import check_payload
from .reporting import ReportContent, write_report

__all__ = ["CANDIDATE_KINDS", "METHODS", "DiagnoseOptions", "DiagnoseResults", "diagnose", "refuse_still_joints"]

METHODS = ("ols", "wls", "tls")
#: what ``candidates`` may name: the effect kinds, the friction-law stage and the composed library
CANDIDATE_KINDS = (*KINDS, "friction_law", "composed")


@dataclass(frozen=True)
class DiagnoseOptions(Options):
    """Every option of ``diagnose`` (the command's flags without their dashes; see ``symoro-gen diagnose --help``).

    Attributes
    ----------
    method : {"ols", "wls", "tls"}
        Estimator of the reported identifications (the loop scores and selects with OLS/WLS weights).
    candidates : sequence of str, optional
        Effect kinds to try (default all: :data:`~symoro_gen.diagnostics.KINDS`, the friction law of each
        joint chosen by cross-validation and the composed effects); ``"friction_law"`` and ``"composed"`` run
        those stages only when named.
    significance : float
        Family-wise level of each round, in (0, 1).
    max_effects : int
        Most effects added (>= 0).
    holdout : float
        Share of each recording held out for validation when no validation data are given, in (0, 1).
    cutoff, decimate : optional
        Butterworth cut-off of q [Hz] and decimation factor (default: the papers' rules, [GB-gains] eq. 14-16).
    seed : int
        Seed of the placebo candidates.
    payload : mapping of str to float, or the command's NAME=VALUE items
        Known payload parameters (``{"M8": 4.6136}``); needs ``loaded`` recordings.
    drop_saturated : bool
        Leave out the rows of each joint whose torque is at its limit (``[limits] tau_max`` of the robot file,
        or plateaus at the column's extreme: :func:`~symoro_gen.preprocessing.motion.saturation_mask`).
    data_format : LogFormat, optional
        How the files are read (columns, time base, units, resampling: docs/data-files.md).
    positions : {"link", "motor"}
        The logged positions are link-side (default) or motor-side ``q_m / N``: then the declared elastic
        joints' link positions are ``positions - tau / K`` ([LWR4-TLS] eq. 17), as in ``identify --positions``
        (:func:`symoro_gen.identification.elastic.link_side`), in every recording (identification, loaded,
        validation).
    """

    method: str = "ols"
    candidates: Sequence[str] | None = None
    significance: float = SIGNIFICANCE
    max_effects: int = MAX_EFFECTS
    holdout: float = HOLDOUT
    cutoff: float | None = None
    decimate: int | None = None
    seed: int = 0
    payload: Mapping[str, float] = field(default_factory=dict)
    data_format: LogFormat = field(default_factory=LogFormat)
    drop_saturated: bool = False
    positions: str = "link"

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise OptionError(f"method {self.method!r}: one of {', '.join(METHODS)}")
        if self.positions not in POSITION_SIDES:
            raise OptionError(f"--positions {self.positions!r}: one of {', '.join(POSITION_SIDES)}")
        if self.candidates is not None:
            object.__setattr__(self, "candidates", tuple(self.candidates))
            for k in self.candidates:
                if k not in CANDIDATE_KINDS:
                    raise OptionError(f"candidates: unknown kind {k!r}; one of {', '.join(CANDIDATE_KINDS)}")
        checks = (("significance", "--significance", lambda v: 0 < v < 1, "must lie between 0 and 1"),
                  ("holdout", "--holdout", lambda v: 0 < v < 1, "must lie between 0 and 1 (a share of each recording)"),
                  ("max_effects", "--max-effects", lambda v: v >= 0, "must be >= 0"),
                  ("cutoff", "--cutoff", lambda v: v > 0, "must be a positive frequency in Hz"),
                  ("decimate", "--decimate", lambda v: v >= 1, "must be an integer >= 1"))
        for attr, flag, ok, what in checks:
            v = getattr(self, attr)
            if v is not None and not ok(v):
                raise OptionError(f"{flag} {v:g}: {what}")
        object.__setattr__(self, "payload", payload_mapping(self.payload))
        if self.data_format is None:
            object.__setattr__(self, "data_format", LogFormat())

    def settings(self) -> DiagnoseSettings:
        """The loop's settings (:class:`~symoro_gen.diagnostics.core.DiagnoseSettings`)."""
        kinds = KINDS if self.candidates is None else tuple(self.candidates)
        return DiagnoseSettings(method=self.method, candidates=kinds, significance=self.significance,
                                max_effects=self.max_effects, holdout=self.holdout)

    def assembly(self, tau_limits: tuple[float, ...] | None = None) -> AssemblyOptions:
        """The assembly's filter settings (``cutoff``, ``decimate``; the rest by the papers' rules) and row
        selection (``drop_saturated`` with the robot's torque limits ``tau_limits``: the samples where a torque is
        saturated, every joint's rows, since the loop needs every joint on every sample)."""
        return AssemblyOptions(cutoff_hz=self.cutoff, n_d=self.decimate, drop_saturated=self.drop_saturated,
                               saturated_all_joints=True, tau_limits=tau_limits)


def _names(items: Sequence[Any]) -> list[str]:
    """Paths as given, Trajectory objects by their source, arrays as ``<array k>`` (as they are loaded)."""
    return [os.fspath(p) if isinstance(p, (str, os.PathLike)) else str(getattr(p, "source", f"<array {k + 1}>"))
            for k, p in enumerate(items)]


@dataclass(frozen=True, eq=False)
class DiagnoseResults(Results):
    """What ``diagnose`` found (see :meth:`to_dict` for the JSON contract, docs/json-output.md).

    ``residual`` is the loop's :class:`~symoro_gen.diagnostics.ResidualReport` (effects, candidates tried,
    errors before and after, the identification results before and after).
    """

    command = "diagnose"

    robot: Any
    model: IdentificationModel
    options: DiagnoseOptions
    residual: ResidualReport
    data: tuple[Any, ...]
    loaded: tuple[Any, ...]
    validate: tuple[Any, ...]
    reports: tuple[LoadReport, ...]
    inputs: tuple[Any, ...] = ()
    friction_laws: tuple[ScaleFit, ...] = ()

    def to_dict(self) -> dict:
        """Exactly the JSON of ``symoro-gen diagnose --json`` (its ``generator`` mark first)."""
        out: dict[str, Any] = {"generator": "symoro-gen diagnose", "schema_version": SCHEMA_VERSION}
        for k, v in self.residual.to_dict().items():
            out[k] = v
            if k == "robot":  # the robot's identity beside its name
                out["robot_id"] = robot_id(self.robot)
        out["data"] = [r.to_dict() for r in self.reports]  # per file: path, rows read, dropped, resampled
        out["validate"] = _names(self.validate)
        out["loaded"] = _names(self.loaded)
        out["robot_file"] = [d.to_dict() for d in self.declarations()]
        out["declared_friction_laws"] = [f.to_dict() for f in self.friction_laws]
        out["provenance"] = provenance(self.options, self.inputs, seeds={"seed": self.options.seed})
        return out

    def declarations(self) -> list[ElasticDeclaration | LawDeclaration]:
        """The robot-file lines that declare what the loop found as a property of the robot: the stiffness of
        each ``elasticity`` effect (``elastic = {K = ...}`` on its joint's frame,
        :func:`~symoro_gen.identification.elastic.elastic_declarations`), then the friction law of each
        friction-law or Stribeck effect (``friction_law = {kind = ..., vs = ...}``,
        :func:`~symoro_gen.diagnostics.friction.law_declarations`)."""
        return [*elastic_declarations(self.robot, self.residual.effects),
                *law_declarations(self.robot, self.residual.effects)]

    def declaration_text(self) -> str:
        """The text blocks of the declared friction laws the loop started from and of :meth:`declarations`
        (empty when there is none)."""
        decl = self.declarations()
        elastic = [d for d in decl if isinstance(d, ElasticDeclaration)]
        laws = [d for d in decl if isinstance(d, LawDeclaration)]
        blocks = []
        if self.friction_laws:
            blocks.append("Declared friction laws (robot file): the loop starts from them, scales refined on the "
                          "identification data (never the validation data); no friction-law replacement is "
                          "offered on these joints:\n" + "\n".join(f.summary() for f in self.friction_laws))
        if elastic:
            blocks.append("To the robot file (declared, the joint is modelled as elastic and its elasticity candidate "
                          "is no longer offered; with one motor-side encoder run with --positions motor, "
                          "docs/robot-file.md#elastic-joints):\n" + "\n".join(f"  {d.text()}" for d in elastic))
        if laws:
            blocks.append("To the robot file (declared, diagnose starts from the law, its scale refined on the "
                          "identification data, and no longer offers it; docs/robot-file.md#friction-laws):\n"
                          + "\n".join(f"  {d.text()}" for d in laws))
        return "\n\n".join(blocks)

    def summary(self) -> str:
        """Exactly the text ``symoro-gen diagnose`` prints."""
        block = self.declaration_text()
        return self.residual.summary() + "\n\n" + (block + "\n\n" if block else "") + data_text(self.reports)

    def _repr_html_(self) -> str:
        """The diagnosis' tables (Jupyter)."""
        return diagnosis_html(self.residual)

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """Errors before/after, the effects with their parameters, the candidates of each round, the residual
        before and after each effect against the signal that revealed it; ``.html`` or ``.md``."""
        sources = {"identification data": _names(self.data), "loaded": _names(self.loaded),
                   "validation data": _names(self.validate)}
        block = self.declaration_text()
        content = ReportContent(robot=self.robot.name, sources=sources,
                                text=self.residual.summary() + ("\n\n" + block if block else ""),
                                notes=data_notes(self.reports))
        self.check_output(path, force=force, label="report", report=True)
        return write_report(path, diagnosis=self.residual, content=content, force=force)

    def figures(self) -> list:
        """Relative error norms before/after, the residual before and after each effect against the signal that
        revealed it, measured and reconstructed torques of the final model."""
        require_matplotlib()
        blocks = diagnosis_blocks(self.residual, [], plots=True)
        return [b.figure for b in blocks if isinstance(b, Figure) and b.figure is not None]

    def write_plots(self, folder: str | os.PathLike[str], *, force: bool = False) -> list[Path]:
        """The figures as ``diagnosis-*.png`` files in ``folder`` (:meth:`ResidualReport.write_plots`; empty
        without matplotlib)."""
        return self.residual.write_plots(folder, force=force)


def refuse_still_joints(trajectories) -> None:
    """A joint that stands still in every identification recording leaves its drive-chain columns of W zero:
    the loop cannot fit the declared model, so say which files and joints, before the long computation
    (``identify --drop-unexcited`` identifies the other parameters)."""
    trs = list(trajectories)
    per: dict[int, list[tuple[str, float]]] = {}
    for src, j, span in still_joints(trs):
        per.setdefault(j, []).append((src, span))
    still = {j: v for j, v in per.items() if len(v) == len(trs)}  # still in every file
    if not still:
        return
    files = list(dict.fromkeys(src for v in still.values() for src, _ in v))
    shown = ", ".join(files[:3]) + (f" and {len(files) - 3} more" if len(files) > 3 else "")
    why = ", ".join(f"joint {j} does not move (q{j} spans at most {max(s for _, s in v):.3g})"
                    for j, v in sorted(still.items()))
    err = IdentificationError(f"{shown}: {why}: the parameters of its motion (rotor inertia, friction) have no "
                              "effect on these data, and diagnose needs the declared model identifiable")
    err.hint = ("record a trajectory that moves every joint (symoro-gen excite), or identify the other "
                "parameters with `symoro-gen identify ... --drop-unexcited`")
    raise err


# ---- the workflow ---------------------------------------------------------------------------------------
def diagnose(robot, data: DataLike, *, validate: DataLike = None, loaded: DataLike = None, method: str = "ols",
             options: DiagnoseOptions | None = None, **kwargs: Any) -> Any:
    """Find what the declared model misses in the residual, add it, re-identify, report errors before/after.

    Parameters
    ----------
    robot : str, path, RobotDescription or model
        A robot name (``robots/``), a robot file, a description or a loaded model.
    data : path, Trajectory, (t, q, tau) arrays, or a list of them
        Identification recordings without payload.
    validate : same as ``data``, optional
        Validation recordings; default: the last ``holdout`` share of each identification recording.
    loaded : same as ``data``, optional
        Identification recordings with the payload mounted (its columns added to their rows).
    method : {"ols", "wls", "tls"}
        Estimator of the reported identifications.
    options : DiagnoseOptions, optional
        All options at once; or give them by name (``candidates=("spring",)``, ``max_effects=2``...): an
        unknown name raises :class:`~symoro_gen.errors.OptionError` naming the nearest valid one.

    Returns
    -------
    DiagnoseResults
        Or, for a floating-base robot, :class:`~symoro_gen.workflows.floating.FloatingDiagnoseResults` (the
        contact-sensor offsets and gains per kind of rows).
    """
    opts = DiagnoseOptions.resolve("diagnose", options, dict(kwargs, method=method) if options is None else kwargs,
                                   keywords=("validate", "loaded", "options"))
    if options is not None and method not in ("ols", options.method):
        opts = replace(options, method=method)
    return _run(robot, data, validate, loaded, opts)


def _run(robot_like, data, validate, loaded_data, opts: DiagnoseOptions) -> Any:
    robot, model = resolve_robot(robot_like)
    data, validate, loaded_data = listed(data), listed(validate), listed(loaded_data)
    if not data:
        raise OptionError("diagnose: no identification data given")
    if robot.floating:  # the contact-sensor checks per kind of rows (workflows/floating.py)
        if validate or loaded_data or opts.payload:
            raise OptionError(f"{robot.file or robot.name}: diagnose of a floating-base robot takes its logs, "
                              "--cutoff, --decimate, --significance and the outputs --json, --report, --plots; "
                              "not --validate (the loop validates on the last share of each log), --loaded or "
                              "--payload (the logs have no payload columns)")
        return diagnose_floating_logs(robot, model, data, opts)
    refuse_repeated_recordings(data, loaded_data, validate)
    ident, reports = as_trajectories(list(data), opts.data_format, robot, loaded=False)
    loaded, rep_l = (as_trajectories(list(loaded_data), opts.data_format, robot, loaded=True)
                     if loaded_data else ((), ()))
    reports += rep_l
    known = check_payload(opts.payload, tuple(getattr(model, "PAYLOAD_NAMES", ())))
    if known and not loaded:
        raise IdentificationError("--payload needs recordings with the payload: give them with --loaded")
    refuse_still_joints(ident)
    notes = recording_warnings(robot, (*ident, *loaded), held=False, dropped=opts.drop_saturated,
                               unexcited_option=False)
    valid, rep_v = as_trajectories(list(validate), opts.data_format, robot) if validate else ((), ())
    reports += rep_v
    if opts.positions == "motor":  # motor-side positions: the link side of the declared elastic joints
        ident, loaded, valid = (link_side(robot, trs) if trs else tuple(trs) for trs in (ident, loaded, valid))
    loop_model, law_fits = _declared_law_model(robot, model, ident, valid if validate else None, opts)
    settings = replace(opts.settings(), declared_elastic=tuple(i for i, _ in elastic_columns(robot)),
                       declared_laws=tuple(f.joint for f in law_fits))
    residual = run_loop(loop_model, ident, settings, validation=valid if validate else None,
                        loaded=loaded if loaded_data else None, payload=known,
                        rng=np.random.default_rng(opts.seed), assembly=opts.assembly(torque_limits(robot)))
    residual = replace(residual, warnings=(*notes, *residual.warnings))
    return DiagnoseResults(robot=robot, model=model, options=opts, residual=residual, data=data,
                           loaded=loaded_data, validate=validate, reports=tuple(reports),
                           inputs=(*data, *loaded_data, *validate), friction_laws=law_fits)


def _declared_law_model(robot, model: IdentificationModel, ident, valid, opts: DiagnoseOptions
                        ) -> tuple[IdentificationModel, tuple[ScaleFit, ...]]:
    """The loop's declared model: with the robot file's friction laws (``friction_law``) in place of their joints'
    ``FS``/``FV`` columns (:class:`~symoro_gen.identification.friction_law.LawDeclaredModel`, as ``identify``),
    their scales refined (:func:`~symoro_gen.identification.friction_law.refine_scales`) on the identification
    recordings without payload only: without validation recordings, on the leading part the loop identifies on
    (its held-out validation share, :func:`~symoro_gen.diagnostics.frame.split_holdout`, is never read). The
    model itself without any declared law."""
    laws = declared_laws(robot, model)
    if not laws:
        return model, ()
    data = list(ident) if valid is not None else split_holdout(list(ident), opts.holdout)[0]
    fits = refine_scales(model, laws, data, opts.assembly(torque_limits(robot)))
    return LawDeclaredModel(model, laws, [f.scale for f in fits]), fits
